//! Loop closure on a 1,000-keyframe map: the search for one keyframe,
//! the optimisation of the whole graph after a closure, and the rebuild
//! of walls and CLS region from every keyframe.
//!
//! The map comes from the simulated long loop (`World::long_loop`, 68 m a
//! lap) driven until it holds 1,000 keyframes, on odometry with 2 % scale
//! error and 0.01 rad/m heading drift, so its graph carries real loops;
//! revisit merging and loop-edge spacing are off, so every keyframe is
//! kept and every loop found is an edge (the worst case).
//!
//! `cargo bench --bench loop_closure -- --warm-up-time 1 --measurement-time 5`

use std::hint::black_box;

use clsmap::geometry::Pose2;
use clsmap::graph::{LoopQuery, close_loop};
use clsmap::input::ScanRecord;
use clsmap::localize::global::GlobalConfig;
use clsmap::pipeline::Mapper;
use clsmap::pipeline::config::MapperConfig;
use clsmap::sim::{Rng, ScanSpec, Tour, World, cast_scan};
use criterion::{BatchSize, Criterion, criterion_group, criterion_main};

const KEYFRAMES: usize = 1000;

/// The mapper after driving the long loop until it has `KEYFRAMES`.
fn mapped_loop() -> Mapper {
    let world = World::long_loop();
    let corners: [[f64; 2]; 4] = [[1.0, 1.0], [23.0, 1.0], [23.0, 17.0], [1.0, 17.0]];
    let mut waypoints = Vec::new();
    for _ in 0..10 {
        for (i, c) in corners.iter().enumerate() {
            let next = corners[(i + 1) % 4];
            let heading = (next[1] - c[1]).atan2(next[0] - c[0]);
            waypoints.push(Pose2::new(c[0], c[1], heading));
        }
    }
    let tour = Tour::new(waypoints, 1.0, 1.0);
    let spec = ScanSpec::lms200_half_degree(0.01);
    let mut rng = Rng::new(9);
    // Every keyframe kept and every loop an edge: the densest graph the
    // defaults' revisit merging and loop spacing would otherwise thin.
    let mut config = MapperConfig::default();
    config.loop_closure.revisit_distance = 0.0;
    config.loop_closure.agreeing_loop_spacing = 1;
    let mut mapper = Mapper::new(config);
    let (mut odo, mut prev) = (Pose2::new(-3.0, 5.0, 1.0), tour.pose_at(0.0));
    let mut t = 0.0;
    while mapper.keyframe_graph().len() < KEYFRAMES && t < tour.duration() {
        let truth = tour.pose_at(t);
        let d = prev.between(&truth);
        let dist = d.x.hypot(d.y);
        odo = odo.compose(&Pose2::new(1.02 * d.x, 1.02 * d.y, d.theta + 0.01 * dist));
        prev = truth;
        let scan = cast_scan(&world, &truth, &spec, 100.0 + t, &mut rng);
        mapper.process(&ScanRecord {
            scan,
            odometry: Some(odo),
        });
        t += 0.2;
    }
    mapper.settle();
    mapper
}

fn bench_loop_closure(c: &mut Criterion) {
    let mapper = mapped_loop();
    let config = *mapper.config();
    let kg = mapper.keyframe_graph().clone();
    let loops = kg.graph().loop_edges().count();
    eprintln!(
        "{} keyframes, {} loop edges, {} walls",
        kg.len(),
        loops,
        mapper.map().len()
    );

    let mut group = c.benchmark_group("loop_closure");
    group.sample_size(10);
    let global = GlobalConfig::default();
    group.bench_function("search one keyframe (1,000 keyframes)", |b| {
        let current = kg.len() - 1;
        b.iter(|| {
            // The paths through the graph are part of each search.
            let paths = kg.drift_paths(current, &config.loop_closure);
            let query = LoopQuery {
                keyframes: kg.keyframes(),
                poses: kg.poses(),
                current,
                paths: &paths,
                allow_voting: true,
            };
            black_box(close_loop(
                &query,
                &config.map,
                &config.localizer,
                &global,
                &config.loop_closure,
            ))
        })
    });
    // The graph as it stood before its loops: each pose off by the drift
    // the chain alone carries, which the loops then take out.
    group.bench_function("optimise 1,000 keyframes", |b| {
        b.iter_batched(
            || {
                let mut graph = kg.graph().clone();
                for i in 1..graph.poses().len() {
                    let p = graph.poses()[i];
                    let f = i as f64 / KEYFRAMES as f64;
                    graph.set_pose(
                        i,
                        Pose2::new(p.x + 0.5 * f, p.y - 0.3 * f, p.theta + 0.02 * f),
                    );
                }
                graph
            },
            |mut graph| black_box(graph.optimize(&config.loop_closure.optimizer)),
            BatchSize::LargeInput,
        )
    });
    group.bench_function("rebuild walls from 1,000 keyframes", |b| {
        b.iter_batched(
            || kg.clone(),
            |mut kg| black_box(kg.rebuild_walls(config.map).len()),
            BatchSize::LargeInput,
        )
    });
    group.bench_function("rebuild walls and CLS map from 1,000 keyframes", |b| {
        b.iter_batched(
            || kg.clone(),
            |mut kg| black_box(kg.rebuild_maps(config.map, config.cls_map()).2),
            BatchSize::LargeInput,
        )
    });
    group.finish();
}

criterion_group!(benches, bench_loop_closure);
criterion_main!(benches);
