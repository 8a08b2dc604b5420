//! Line extraction per 361-beam LMS200 scan (target ≤ 50 µs, release).
//!
//! `cargo bench --bench extraction -- --warm-up-time 1 --measurement-time 3`

use std::hint::black_box;

use clsmap::geometry::{ExtractionConfig, LineExtractor, Pose2, extract_lines};
use clsmap::sim::{Rng, ScanSpec, World, cast_scan};
use criterion::{Criterion, criterion_group, criterion_main};

fn bench_extraction(c: &mut Criterion) {
    let world = World::room_with_boxes();
    let mount = Pose2::new(0.1, 0.0, 0.0);
    let cfg = ExtractionConfig::default();
    let mut rng = Rng::new(11);
    let scans: Vec<_> = [
        Pose2::new(4.0, 3.0, 0.3),
        Pose2::new(2.0, 2.0, 1.2),
        Pose2::new(6.0, 4.0, -2.5),
    ]
    .iter()
    .map(|p| {
        cast_scan(
            &world,
            &p.compose(&mount),
            &ScanSpec::lms200_half_degree(0.01),
            0.0,
            &mut rng,
        )
    })
    .collect();

    let mut group = c.benchmark_group("extraction_361_beams");
    group.bench_function("line_extractor_reused", |b| {
        let mut extractor = LineExtractor::new();
        let mut out = Vec::new();
        let mut i = 0;
        b.iter(|| {
            i = (i + 1) % scans.len();
            extractor.extract(black_box(&scans[i]), &mount, &cfg, &mut out);
            black_box(out.len())
        })
    });
    group.bench_function("extract_lines_fresh", |b| {
        let mut i = 0;
        b.iter(|| {
            i = (i + 1) % scans.len();
            black_box(extract_lines(black_box(&scans[i]), &mount, &cfg).len())
        })
    });
    group.finish();
}

criterion_group!(benches, bench_extraction);
criterion_main!(benches);
