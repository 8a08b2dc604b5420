//! Local localization of one scan's lines against a map of about 100
//! segments (target ≤ 30 µs, release), and against about 1,000 to show how
//! the cost grows with the map (the BVH keeps it near-constant).
//!
//! Also one scan's points matched against the last scan's (point-to-line
//! ICP, as `clsmap map` does for its smoothed trajectory).
//!
//! `cargo bench --bench localization -- --warm-up-time 1 --measurement-time 3`

use std::hint::black_box;

use clsmap::geometry::SegmentIndex;
use clsmap::geometry::scan_match::{ScanPoints, align};
use clsmap::geometry::{CogLine, ExtractionConfig, Pose2, extract_lines};
use clsmap::localize::{LocalizerConfig, localize};
use clsmap::sim::{Rng, ScanSpec, World, cast_scan};
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};

/// Copies of the furnished room on a `nx` × `ny` grid, 1 m apart, and the
/// offset of each copy.
fn rooms(nx: usize, ny: usize) -> (World, Vec<[f64; 2]>) {
    let room = World::room_with_boxes();
    let mut walls = Vec::new();
    let mut offsets = Vec::new();
    for i in 0..nx {
        for j in 0..ny {
            let o = [9.0 * i as f64, 7.0 * j as f64];
            offsets.push(o);
            walls.extend(
                room.walls()
                    .iter()
                    .map(|&[a, b]| [[a[0] + o[0], a[1] + o[1]], [b[0] + o[0], b[1] + o[1]]]),
            );
        }
    }
    (World::from_segments(walls), offsets)
}

struct Setup {
    map: SegmentIndex,
    local: Vec<CogLine>,
    predicted: Pose2,
}

/// A map from one scan per room, and a scan in one of the rooms with a
/// prediction 14 cm and 6° off.
fn setup(nx: usize, ny: usize) -> Setup {
    let (world, offsets) = rooms(nx, ny);
    let mount = Pose2::new(0.1, 0.0, 0.0);
    let cfg = ExtractionConfig::default();
    let spec = ScanSpec::lms200_half_degree(0.01);
    let mut rng = Rng::new(5);
    let mut map = SegmentIndex::new();
    for o in &offsets {
        let p = Pose2::new(o[0] + 4.0, o[1] + 3.0, 0.4);
        let scan = cast_scan(&world, &p.compose(&mount), &spec, 0.0, &mut rng);
        for l in extract_lines(&scan, &mount, &cfg) {
            map.insert(l.transformed(&p));
        }
    }
    let o = offsets[offsets.len() / 2];
    let truth = Pose2::new(o[0] + 4.3, o[1] + 2.8, 0.6);
    let scan = cast_scan(&world, &truth.compose(&mount), &spec, 0.0, &mut rng);
    let local = extract_lines(&scan, &mount, &cfg);
    let predicted = Pose2::new(truth.x + 0.12, truth.y - 0.08, truth.theta + 0.1);
    let prior = [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]];
    // Benchmark a case that works: the pose must come back within 5 mm.
    match localize(&local, &map, predicted, &prior, &LocalizerConfig::default()) {
        Ok(r) => assert!(
            (r.pose.x - truth.x).hypot(r.pose.y - truth.y) < 0.005,
            "{:?} vs {truth:?}",
            r.pose
        ),
        Err(e) => panic!("localization failed: {e}"),
    }
    Setup {
        map,
        local,
        predicted,
    }
}

fn bench_localization(c: &mut Criterion) {
    let prior = [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]];
    let cfg = LocalizerConfig::default();
    let mut group = c.benchmark_group("localize");
    for (nx, ny) in [(4, 3), (12, 10)] {
        let s = setup(nx, ny);
        let id = BenchmarkId::new("map_segments", s.map.len());
        group.bench_with_input(id, &s, |b, s| {
            b.iter(|| {
                let r = localize(
                    black_box(&s.local),
                    &s.map,
                    black_box(s.predicted),
                    &prior,
                    &cfg,
                );
                black_box(r.map(|r| r.pose))
            })
        });
    }
    group.finish();
}

/// Two scans 0.2 m and 3° apart in the furnished room, matched from a
/// start 3 cm and 1° off.
fn bench_scan_match(c: &mut Criterion) {
    let world = World::room_with_boxes();
    let spec = ScanSpec::lms200_half_degree(0.01);
    let mut rng = Rng::new(9);
    let a = Pose2::new(4.0, 3.0, 0.3);
    let b = Pose2::new(4.19, 3.06, 0.35);
    let points = |p: &Pose2, rng: &mut Rng| {
        ScanPoints::new(&cast_scan(&world, p, &spec, 0.0, rng), 0.05, 80.0)
    };
    let (pa, pb) = (points(&a, &mut rng), points(&b, &mut rng));
    let truth = a.between(&b);
    let start = truth.compose(&Pose2::new(0.03, -0.02, 0.017));
    // Benchmark a case that works: the motion must come back within 5 mm.
    let found = align(&pa, &pb, &start).expect("the scans match");
    let e = truth.between(&found.pose);
    assert!(e.x.hypot(e.y) < 0.005, "{found:?} vs {truth:?}");
    c.bench_function("scan_match/consecutive_scans", |bench| {
        bench.iter(|| black_box(align(&pa, black_box(&pb), black_box(&start))))
    });
}

criterion_group!(benches, bench_localization, bench_scan_match);
criterion_main!(benches);
