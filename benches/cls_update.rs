//! Global CLS map update (local map → fusion → union) as the map grows to
//! about 100, 1,000 and 5,000 segments (target ≤ 1 ms at 1,000, release).
//!
//! Two growth patterns:
//! - `corridor`: one long corridor with doors, driven end to end; the map
//!   is a single connected shape with one long outer loop, which each
//!   update clips to a window around the scan.
//! - `corridor_whole_loops`: the same with `clip_to_window = false`, so
//!   the union takes the whole touched loop (for comparison).
//! - `rooms`: a row of closed rooms each scanned from inside; the map is
//!   many shapes and an update touches only the room it is in (the bounding
//!   box test keeps the rest out of the union).
//!
//! `cargo bench --bench cls_update -- --warm-up-time 1 --measurement-time 3`

use std::hint::black_box;

use clsmap::geometry::{ExtractionConfig, Pose2, RangeScan, extract_lines};
use clsmap::map::SegmentMap;
use clsmap::map::cls::{ClsMap, ClsMapConfig};
use clsmap::sim::{Rng, ScanSpec, World, cast_scan};
use criterion::{BatchSize, BenchmarkId, Criterion, criterion_group, criterion_main};

const SIZES: [usize; 3] = [100, 1_000, 5_000];
const COV: [[f64; 3]; 3] = [[1e-4, 0.0, 0.0], [0.0, 1e-4, 0.0], [0.0, 0.0, 1e-5]];

struct Scene {
    world: World,
    poses: Vec<Pose2>,
}

/// A corridor long enough for the largest map, poses every 0.5 m.
fn corridor() -> Scene {
    let length = 3_000.0;
    let world = World::corridor(length, 2.0, Some(2.5));
    let poses = (0..((length - 2.0) / 0.5) as usize)
        .map(|i| {
            Pose2::new(
                1.0 + 0.5 * i as f64,
                0.1 * ((i % 7) as f64 - 3.0) / 3.0,
                0.0,
            )
        })
        .collect();
    Scene { world, poses }
}

/// A row of furnished 8 m × 6 m rooms, 1 m apart, each seen from three poses.
fn rooms() -> Scene {
    let room = World::room_with_boxes();
    let mut walls = Vec::new();
    let mut poses = Vec::new();
    for i in 0..400 {
        let dx = 9.0 * i as f64;
        walls.extend(
            room.walls()
                .iter()
                .map(|&[a, b]| [[a[0] + dx, a[1]], [b[0] + dx, b[1]]]),
        );
        for (x, y, t) in [(4.0, 3.0, 0.3), (3.0, 2.5, 2.6), (5.0, 3.5, -1.9)] {
            poses.push(Pose2::new(dx + x, y, t));
        }
    }
    Scene {
        world: World::from_segments(walls),
        poses,
    }
}

fn observe(
    scene: &Scene,
    pose: &Pose2,
    rng: &mut Rng,
) -> (Vec<clsmap::geometry::CogLine>, RangeScan) {
    let scan = cast_scan(
        &scene.world,
        pose,
        &ScanSpec::lms200_half_degree(0.005),
        0.0,
        rng,
    );
    let lines = extract_lines(&scan, &Pose2::IDENTITY, &ExtractionConfig::default());
    (lines, scan)
}

fn bench_growth(c: &mut Criterion, name: &str, scene: &Scene, config: ClsMapConfig) {
    let mut group = c.benchmark_group(format!("cls_update/{name}"));
    let mut rng = Rng::new(7);
    let mut map = ClsMap::new(config);
    let mut walls = SegmentMap::default();
    let mut next = 0;
    for target in SIZES {
        while map.len() < target && next + 1 < scene.poses.len() {
            let (lines, scan) = observe(scene, &scene.poses[next], &mut rng);
            // A scan the map cannot use is skipped, as the pipeline would.
            let _ = map.update(&mut walls, &lines, &scan, scene.poses[next], COV);
            next += 1;
        }
        // The measured scan revisits the newest part of the map (a little
        // ahead of the last pose), so the union has work to do.
        let last = scene.poses[next.saturating_sub(1)];
        let pose = last.compose(&Pose2::new(0.2, 0.05, 0.1));
        let (lines, scan) = observe(scene, &pose, &mut rng);
        let segments = map.len();
        let mut probe = (map.clone(), walls.clone());
        let stats = probe.0.update(&mut probe.1, &lines, &scan, pose, COV);
        eprintln!("{name}: {segments} segments, update of the measured scan: {stats:?}");
        group.bench_with_input(BenchmarkId::from_parameter(segments), &segments, |b, _| {
            b.iter_batched(
                || (map.clone(), walls.clone()),
                |(mut m, mut w)| black_box(m.update(&mut w, &lines, &scan, pose, COV)),
                BatchSize::LargeInput,
            )
        });
    }
    group.finish();
}

fn bench_cls_update(c: &mut Criterion) {
    let clipped = ClsMapConfig::default();
    let whole = ClsMapConfig {
        clip_to_window: false,
        ..clipped
    };
    let corridor = corridor();
    bench_growth(c, "corridor", &corridor, clipped);
    bench_growth(c, "corridor_whole_loops", &corridor, whole);
    bench_growth(c, "rooms", &rooms(), clipped);
}

criterion_group!(benches, bench_cls_update);
criterion_main!(benches);
