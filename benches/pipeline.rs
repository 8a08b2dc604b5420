//! The whole offline pipeline (predict, extract, localize, map update) per
//! scan on the first scans of the MIT CSAIL log, loaded once outside the
//! timed loop. Target ≥ 500× real time: CSAIL is 424 s for 1988 scans, so
//! ≤ ~0.43 ms per scan (one core, release).
//!
//! `cargo bench --bench pipeline -- --warm-up-time 1 --measurement-time 3`
//!
//! Without the dataset (`../shared/datasets/mit-csail/`), a simulated run
//! around the loop world is timed instead.

use std::hint::black_box;
use std::path::PathBuf;

use clsmap::geometry::Pose2;
use clsmap::input::{ScanRecord, open_log};
use clsmap::pipeline::Mapper;
use clsmap::pipeline::config::MapperConfig;
use clsmap::sim::{Rng, ScanSpec, World, cast_scan};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

/// Scans per timed run: the first 90 s of the log, long enough for the map
/// to hold a few hundred segments.
const SCANS: usize = 400;

fn csail_scans() -> Option<Vec<ScanRecord>> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/datasets/mit-csail/mit-csail.clf");
    let log = open_log(&path).ok()?;
    log.take(SCANS).collect::<Result<Vec<_>, _>>().ok()
}

/// A robot going round the loop world in 0.1 m steps, exact odometry.
fn simulated_scans() -> Vec<ScanRecord> {
    let world = World::loop_around_block();
    let spec = ScanSpec::lms200_half_degree(0.01);
    let mut rng = Rng::new(3);
    (0..SCANS)
        .map(|k| {
            let x = 1.0 + 0.1 * (k % 100) as f64;
            let pose = Pose2::new(x, 1.0, 0.0);
            ScanRecord {
                scan: cast_scan(&world, &pose, &spec, 0.2 * k as f64, &mut rng),
                odometry: Some(pose),
            }
        })
        .collect()
}

fn bench_pipeline(c: &mut Criterion) {
    let (name, records) = match csail_scans() {
        Some(r) => ("csail_first_400_scans", r),
        None => {
            eprintln!("CSAIL log not found: timing a simulated run instead");
            ("simulated_400_scans", simulated_scans())
        }
    };
    let config = MapperConfig::default();
    let mut group = c.benchmark_group("offline_pipeline");
    group.sample_size(10);
    group.throughput(Throughput::Elements(records.len() as u64));
    group.bench_function(name, |b| {
        b.iter(|| {
            let mut mapper = Mapper::new(config);
            for r in &records {
                black_box(mapper.process(black_box(r)));
            }
            mapper.map().len()
        })
    });
    group.finish();
}

criterion_group!(benches, bench_pipeline);
criterion_main!(benches);
