//! Global localization of one scan with no prediction (target ≤ 5 ms on a
//! 1,000-segment map, release; the paper: 17 ms on a 51-segment map).
//!
//! The map is the CLS map of the furnished room built from one run with
//! true poses (60 actual segments), alone and tiled 5 × 4 (1,200). The
//! tiles are identical, so the big map is also the hardest case for the
//! vote: every scan line has twenty equally good partners.
//!
//! With the MIT CSAIL log at hand (`../shared/datasets/mit-csail/`), also
//! the whole log's map (its walls, default mapper) and scan 1,000 of it,
//! and that scan's hypotheses tracked one scan on (`disambiguate`), judged
//! by the walls alone and by the free space the map explored as well.
//!
//! `cargo bench --bench global_localization -- --warm-up-time 1 --measurement-time 3`

use std::hint::black_box;

use clsmap::geometry::{CogLine, ExtractionConfig, Pose2, extract_lines};
use clsmap::input::open_log;
use clsmap::localize::global::{GlobalConfig, GlobalMap, disambiguate, global_localize};
use clsmap::map::SegmentMap;
use clsmap::map::cls::{ClsMap, ClsMapConfig};
use clsmap::pipeline::Mapper;
use clsmap::pipeline::config::MapperConfig;
use clsmap::sim::{ROOM_WITH_BOXES_TOUR, Rng, ScanSpec, World, cast_scan};
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};

const COV: [[f64; 3]; 3] = [[1e-6, 0.0, 0.0], [0.0, 1e-6, 0.0], [0.0, 0.0, 1e-7]];

/// The room's actual segments after a run round its furniture.
fn room_lines(world: &World) -> Vec<CogLine> {
    let waypoints = ROOM_WITH_BOXES_TOUR;
    let spec = ScanSpec::lms200_half_degree(0.01);
    let ecfg = ExtractionConfig::default();
    let mut rng = Rng::new(3);
    let mut map = ClsMap::new(ClsMapConfig::default());
    let mut walls = SegmentMap::default();
    for w in waypoints.windows(2) {
        let (a, b) = (w[0], w[1]);
        let heading = (b[1] - a[1]).atan2(b[0] - a[0]);
        let n = ((b[0] - a[0]).hypot(b[1] - a[1]) / 0.3).ceil() as usize;
        for k in 0..n {
            let t = k as f64 / n as f64;
            let pose = Pose2::new(a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), heading);
            let scan = cast_scan(world, &pose, &spec, 0.0, &mut rng);
            let lines = extract_lines(&scan, &Pose2::IDENTITY, &ecfg);
            let _ = map.update(&mut walls, &lines, &scan, pose, COV);
        }
    }
    map.actual_segments().map(|s| s.line).collect()
}

/// The walls and CLS map of the whole CSAIL log's map and the lines of its
/// scan 1,000 (robot frame), if the log is there.
fn csail() -> Option<(Vec<CogLine>, ClsMap, Vec<CogLine>)> {
    let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/datasets/mit-csail/mit-csail.clf");
    let records = open_log(&path).ok()?.collect::<Result<Vec<_>, _>>().ok()?;
    let config = MapperConfig::default();
    let mut mapper = Mapper::new(config);
    mapper.defer_cls_rebuild();
    for r in &records {
        mapper.process(r);
    }
    mapper.settle();
    let walls = mapper.contents().walls.iter().map(|w| w.line).collect();
    let scan = &records.get(1000)?.scan;
    let lines = extract_lines(scan, &config.laser_mount, &config.extraction);
    Some((walls, mapper.cls_map().clone(), lines))
}

/// `lines` copied onto an `nx` × `ny` grid of rooms 9 m × 7 m apart.
fn tiled(lines: &[CogLine], nx: usize, ny: usize) -> Vec<CogLine> {
    let mut out = Vec::with_capacity(lines.len() * nx * ny);
    for i in 0..nx {
        for j in 0..ny {
            let shift = Pose2::new(9.0 * i as f64, 7.0 * j as f64, 0.0);
            out.extend(lines.iter().map(|l| l.transformed(&shift)));
        }
    }
    out
}

fn bench_global(c: &mut Criterion) {
    let world = World::room_with_boxes();
    let lines = room_lines(&world);
    let mut rng = Rng::new(4);
    let truth = Pose2::new(4.3, 2.8, 0.6);
    let scan = cast_scan(
        &world,
        &truth,
        &ScanSpec::lms200_half_degree(0.01),
        0.0,
        &mut rng,
    );
    let local = extract_lines(&scan, &Pose2::IDENTITY, &ExtractionConfig::default());
    let cfg = GlobalConfig::default();
    let mut group = c.benchmark_group("global_localize");
    for (nx, ny) in [(1, 1), (5, 4)] {
        let map = GlobalMap::new(tiled(&lines, nx, ny));
        // Benchmark a case that works: the truth (in some tile) is found.
        match global_localize(&local, &map, &cfg) {
            Ok(r) => assert!(
                r.hypotheses.iter().any(|h| {
                    let (dx, dy) = (h.pose.x - truth.x, h.pose.y - truth.y);
                    (dx / 9.0 - (dx / 9.0).round()).abs() * 9.0 < 0.1
                        && (dy / 7.0 - (dy / 7.0).round()).abs() * 7.0 < 0.1
                }),
                "{r:?}"
            ),
            Err(e) => panic!("global localization failed: {e}"),
        }
        let id = BenchmarkId::new("map_segments", map.len());
        group.bench_with_input(id, &map, |b, map| {
            b.iter(|| black_box(global_localize(black_box(&local), map, &cfg).map(|r| r.ambiguous)))
        });
    }
    match csail() {
        Some((walls, cls, local)) => {
            let map = GlobalMap::new(walls);
            let id = BenchmarkId::new("csail_map_segments", map.len());
            group.bench_with_input(id, &map, |b, map| {
                b.iter(|| {
                    black_box(global_localize(black_box(&local), map, &cfg).map(|r| r.ambiguous))
                })
            });
            let found = global_localize(&local, &map, &cfg).ok();
            let with_free = map.clone().with_free_space(&cls);
            for (name, map) in [
                ("csail_walls", &map),
                ("csail_walls_free_space", &with_free),
            ] {
                let Some(found) = found.as_ref() else { break };
                let id = BenchmarkId::new(format!("disambiguate_{name}"), found.hypotheses.len());
                group.bench_with_input(id, map, |b, map| {
                    b.iter(|| {
                        black_box(
                            disambiguate(found, black_box(&local), Pose2::IDENTITY, map, &cfg)
                                .map(|r| r.hypotheses.len()),
                        )
                    })
                });
            }
        }
        None => eprintln!("CSAIL log not found: no CSAIL case"),
    }
    group.finish();
}

criterion_group!(benches, bench_global);
criterion_main!(benches);
