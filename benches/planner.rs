//! Exploration planning on synthetic maps of about 100, 1,000 and 4,000
//! segments: a hall with a grid of turned boxes (holes) whose outer wall
//! is cut into 1 m pieces, every fifth a frontier. `plan_path` plans
//! corner to corner; `next_step` shrinks the region, places a goal in
//! front of every long frontier and searches them all.
//!
//! `cargo bench --bench planner -- --warm-up-time 1 --measurement-time 3`

use std::hint::black_box;

use clsmap::explore::{ExplorationConfig, ExplorationMemory, next_step, plan_path};
use clsmap::geometry::Pose2;
use clsmap::map::cls::{ClsLoop, ClsMap, ClsMapConfig, ClsSegment, ClsShape, SegmentMode};
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};

/// A loop through `points`; segment `i` is virtual when `open(i)`.
fn ring(points: &[[f64; 2]], open: impl Fn(usize) -> bool) -> ClsLoop {
    let n = points.len();
    ClsLoop::new(
        (0..n)
            .map(|i| {
                let mut s = ClsSegment::virtual_between(points[i], points[(i + 1) % n]);
                if !open(i) {
                    s.mode = SegmentMode::Actual;
                }
                s
            })
            .collect(),
    )
}

/// A `k × k` grid of 3 m cells, each with a turned box in the middle.
fn hall(k: usize) -> ClsMap {
    let size = 3.0 * k as f64;
    let mut outer = Vec::new();
    let steps = (size as usize).max(1);
    for side in 0..4 {
        for i in 0..steps {
            let t = i as f64;
            outer.push(match side {
                0 => [t, 0.0],
                1 => [size, t],
                2 => [size - t, size],
                _ => [0.0, size - t],
            });
        }
    }
    let holes = (0..k * k)
        .map(|i| {
            let c = [3.0 * (i % k) as f64 + 1.5, 3.0 * (i / k) as f64 + 1.5];
            let a = 0.1 * i as f64;
            let (s, co) = a.sin_cos();
            let pts: Vec<[f64; 2]> = [(-1.0, -1.0), (-1.0, 1.0), (1.0, 1.0), (1.0, -1.0)]
                .iter()
                .map(|&(u, v)| {
                    [
                        c[0] + co * u * 0.6 - s * v * 0.4,
                        c[1] + s * u * 0.6 + co * v * 0.4,
                    ]
                })
                .collect();
            ring(&pts, |_| false)
        })
        .collect();
    let shape = ClsShape {
        outer: ring(&outer, |i| i % 5 == 2),
        holes,
    };
    match ClsMap::from_shapes(ClsMapConfig::default(), vec![shape]) {
        Ok(map) => map,
        Err(e) => panic!("bench map is invalid: {e}"),
    }
}

fn planner(c: &mut Criterion) {
    let cfg = ExplorationConfig::default();
    let mut group = c.benchmark_group("plan_path");
    let maps: Vec<(usize, ClsMap)> = [4, 15, 31]
        .iter()
        .map(|&k| {
            let m = hall(k);
            (m.len(), m)
        })
        .collect();
    for (n, map) in &maps {
        let size = map.shapes()[0].outer.bounds().1[0];
        group.bench_with_input(BenchmarkId::from_parameter(n), map, |b, map| {
            b.iter(|| plan_path(black_box(map), [0.6, 0.6], [size - 0.6, size - 0.6], 0.37))
        });
    }
    group.finish();
    let mut group = c.benchmark_group("next_step");
    group.sample_size(10);
    for (n, map) in &maps {
        group.bench_with_input(BenchmarkId::from_parameter(n), map, |b, map| {
            b.iter(|| {
                let mut memory = ExplorationMemory::default();
                next_step(black_box(map), Pose2::new(0.6, 0.6, 0.0), &cfg, &mut memory)
            })
        });
    }
    group.finish();
}

criterion_group!(benches, planner);
criterion_main!(benches);
