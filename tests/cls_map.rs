//! The CLS map built from simulated scans along scripted paths (true
//! poses): the map stays valid after every update, its walls lie on the
//! real walls and cover what the robot saw, and it survives the disk.
//!
//! `cargo test --test cls_map -- --nocapture` prints the quality figures;
//! with `CLS_PICTURES=DIR` the room and loop maps are also drawn to SVG.

#![allow(clippy::unwrap_used)]

mod common;

use clsmap::geometry::{ExtractionConfig, Pose2, extract_lines, scan_points};
use clsmap::map::SegmentMap;
use clsmap::map::cls::{
    ClsError, ClsMap, ClsMapConfig, GridConfig, LocalMapConfig, SegmentMode, StoreError,
    occupancy_grid,
};
use clsmap::render::picture;
use clsmap::sim::{ROOM_WITH_BOXES_TOUR, Rng, ScanSpec, World, cast_scan};
use common::{path, point_segment_distance};

const COV: [[f64; 3]; 3] = [[1e-6, 0.0, 0.0], [0.0, 1e-6, 0.0], [0.0, 0.0, 1e-7]];

fn mount() -> Pose2 {
    Pose2::new(0.1, 0.0, 0.0)
}

fn config() -> ClsMapConfig {
    ClsMapConfig {
        local: LocalMapConfig {
            mount: mount(),
            ..LocalMapConfig::default()
        },
        ..ClsMapConfig::default()
    }
}

fn samples(a: [f64; 2], b: [f64; 2], step: f64) -> impl Iterator<Item = [f64; 2]> {
    let n = (((b[0] - a[0]).hypot(b[1] - a[1]) / step).ceil() as usize).max(1);
    (0..n).map(move |k| {
        let t = (k as f64 + 0.5) / n as f64;
        [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
    })
}

/// A run: the map after every pose, checked after each update, and every
/// valid range point in the map frame.
struct Run {
    map: ClsMap,
    points: Vec<[f64; 2]>,
    updates: usize,
    /// Updates that clipped long loops to a window around the scan.
    clipped: usize,
}

fn drive(world: &World, poses: &[Pose2], seed: u64) -> Run {
    let mut map = ClsMap::new(config());
    let mut walls = SegmentMap::default();
    let spec = ScanSpec::lms200_half_degree(0.005);
    let ecfg = ExtractionConfig::default();
    let mut rng = Rng::new(seed);
    let mut points = Vec::new();
    let mut updates = 0;
    let mut clipped = 0;
    for pose in poses {
        let scan = cast_scan(world, &pose.compose(&mount()), &spec, 0.0, &mut rng);
        let lines = extract_lines(&scan, &mount(), &ecfg);
        points.extend(
            scan_points(&scan, &mount(), &ecfg)
                .into_iter()
                .map(|p| pose.transform_point(p)),
        );
        if let Ok(stats) = map.update(&mut walls, &lines, &scan, *pose, COV) {
            updates += 1;
            clipped += usize::from(stats.clipped);
        }
        map.check_invariants().unwrap();
    }
    Run {
        map,
        points,
        updates,
        clipped,
    }
}

/// Fraction of the actual segments' length within `tol` of a real wall.
fn on_walls(map: &ClsMap, world: &World, tol: f64) -> f64 {
    let (mut good, mut total) = (0usize, 0usize);
    for s in map.actual_segments() {
        for p in samples(s.start(), s.end(), 0.01) {
            total += 1;
            if world
                .walls()
                .iter()
                .any(|&[a, b]| point_segment_distance(p, a, b) <= tol)
            {
                good += 1;
            }
        }
    }
    good as f64 / total.max(1) as f64
}

/// Fraction of the wall length the robot saw (some range point within
/// 5 cm) that an actual segment covers (within 5 cm).
fn coverage(run: &Run, world: &World) -> f64 {
    let actual: Vec<_> = run
        .map
        .actual_segments()
        .map(|s| (s.start(), s.end()))
        .collect();
    let (mut seen, mut covered) = (0usize, 0usize);
    for &[a, b] in world.walls() {
        for p in samples(a, b, 0.02) {
            if !run
                .points
                .iter()
                .any(|q| (q[0] - p[0]).hypot(q[1] - p[1]) <= 0.05)
            {
                continue;
            }
            seen += 1;
            if actual
                .iter()
                .any(|&(s, e)| point_segment_distance(p, s, e) <= 0.05)
            {
                covered += 1;
            }
        }
    }
    covered as f64 / seen.max(1) as f64
}

/// The frontier is exactly the virtual segments, and each one is a real
/// frontier: explored space just on its left, none just on its right.
fn assert_frontier(map: &ClsMap) {
    let items = map.items();
    let virtual_count = items
        .iter()
        .filter(|i| i.mode == SegmentMode::Virtual)
        .count();
    assert_eq!(map.virtual_segments().count(), virtual_count);
    assert_eq!(map.actual_segments().count() + virtual_count, items.len());
    for s in map.virtual_segments() {
        assert_eq!(s.mode, SegmentMode::Virtual);
        if s.length() < 0.05 {
            continue;
        }
        let (a, b) = (s.start(), s.end());
        let mid = [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])];
        let n = [-(b[1] - a[1]) / s.length(), (b[0] - a[0]) / s.length()];
        let left = [mid[0] + 0.005 * n[0], mid[1] + 0.005 * n[1]];
        let right = [mid[0] - 0.005 * n[0], mid[1] - 0.005 * n[1]];
        assert!(map.contains(left) && !map.contains(right), "{s:?}");
    }
}

fn assert_quality(name: &str, run: &Run, world: &World) {
    let on = on_walls(&run.map, world, 0.05);
    let cov = coverage(run, world);
    eprintln!(
        "{name}: {} updates ({} clipped), {} segments ({} actual), area {:.1} m², on walls {:.3}, coverage {:.3}",
        run.updates,
        run.clipped,
        run.map.len(),
        run.map.actual_segments().count(),
        run.map.area(),
        on,
        cov
    );
    assert!(
        on >= 0.95,
        "{name}: only {on:.3} of the actual length lies on walls"
    );
    assert!(
        cov >= 0.90,
        "{name}: only {cov:.3} of the seen walls are covered"
    );
    assert_frontier(&run.map);
}

#[test]
fn room_with_boxes_and_chair_legs() {
    let world = World::room_with_boxes();
    let poses = path(&ROOM_WITH_BOXES_TOUR, 0.3);
    let run = drive(&world, &poses, 11);
    assert!(run.updates >= poses.len() * 9 / 10);
    assert_quality("room", &run, &world);
    assert_eq!(run.map.shapes().len(), 1, "one connected region");
    // The room is 8 m × 6 m less a cut corner; the explored part is most of it.
    assert!(
        run.map.area() > 25.0 && run.map.area() < 48.0,
        "{}",
        run.map.area()
    );
    for pose in &poses {
        assert!(
            run.map.contains([pose.x, pose.y]),
            "the path is explored space"
        );
    }
    assert!(!run.map.contains([6.3, 1.2]), "inside a box");
    assert!(!run.map.contains([9.0, 3.0]), "outside the room");
    if let Ok(dir) = std::env::var("CLS_PICTURES") {
        let svg = picture(&run.map, Some(&poses), poses.last().copied()).to_svg();
        std::fs::write(std::path::Path::new(&dir).join("room.svg"), svg).unwrap();
    }
}

#[test]
fn corridor_with_doors() {
    let world = World::corridor_with_doors();
    let poses = path(&[[1.0, 0.0], [29.0, 0.0]], 0.4);
    let run = drive(&world, &poses, 12);
    assert_quality("corridor", &run, &world);
    // Once the corridor is longer than a scan's window, updates stay local.
    assert!(
        run.clipped >= run.updates / 2,
        "{} of {}",
        run.clipped,
        run.updates
    );
    assert_eq!(run.map.shapes().len(), 1);
    assert!(run.map.contains([15.0, 0.8]) && run.map.contains([15.0, -0.8]));
}

#[test]
fn loop_around_a_block_closes_with_an_inner_loop() {
    let world = World::loop_around_block();
    let poses = path(
        &[
            [1.0, 1.0],
            [11.0, 1.0],
            [11.0, 9.0],
            [1.0, 9.0],
            [1.0, 1.0],
            [5.0, 1.0],
        ],
        0.4,
    );
    let run = drive(&world, &poses, 13);
    assert_quality("loop", &run, &world);
    let shapes = run.map.shapes();
    assert_eq!(shapes.len(), 1);
    assert_eq!(
        shapes[0].holes.len(),
        1,
        "the block is an obstacle loop inside the region"
    );
    let hole = &shapes[0].holes[0];
    assert!(hole.signed_area() < 0.0, "obstacle loops are clockwise");
    assert!(!run.map.contains([6.0, 5.0]), "the block is not free space");
    // All of the block's faces were seen: the hole is mostly wall.
    let wall: f64 = hole
        .segments()
        .iter()
        .filter(|s| s.is_actual())
        .map(|s| s.length())
        .sum();
    let total: f64 = hole.segments().iter().map(|s| s.length()).sum();
    assert!(wall / total > 0.9, "{wall} of {total} m");
    if let Ok(dir) = std::env::var("CLS_PICTURES") {
        let svg = picture(&run.map, Some(&poses), poses.last().copied()).to_svg();
        std::fs::write(std::path::Path::new(&dir).join("loop.svg"), svg).unwrap();
    }
}

#[test]
fn the_map_survives_the_disk_and_exports() {
    let world = World::room_with_boxes();
    let poses = path(&[[2.0, 2.0], [6.0, 3.0]], 0.5);
    let run = drive(&world, &poses, 14);
    let dir = std::env::temp_dir().join(format!("clsmap-cls-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("map.json");
    run.map.save(&file).unwrap();
    let back = ClsMap::load(&file, config()).unwrap();
    assert_eq!(back.len(), run.map.len());
    assert_eq!(back.items().len(), run.map.items().len());
    // Numbers come back within a unit in the last place (serde_json's
    // default float parser); structure and modes exactly.
    for (a, b) in back.items().iter().zip(run.map.items()) {
        assert_eq!((a.index, a.next, a.mode), (b.index, b.next, b.mode));
        let close = |x: f64, y: f64| (x - y).abs() <= 1e-12 * x.abs().max(1.0);
        let (pa, pb) = (
            [a.line.start, a.line.end].concat(),
            [b.line.start, b.line.end].concat(),
        );
        assert!(
            pa.iter().zip(&pb).all(|(x, y)| close(*x, *y)),
            "{a:?} vs {b:?}"
        );
        assert!(close(a.line.theta, b.line.theta) && close(a.line.sigma_c, b.line.sigma_c));
    }
    assert!((back.area() - run.map.area()).abs() < 1e-9);

    // A corrupt copy is refused with the reason; the good file still loads.
    let text = std::fs::read_to_string(&file).unwrap();
    let bad = dir.join("bad.json");
    std::fs::write(&bad, &text[..text.len() - 10]).unwrap();
    assert!(matches!(
        ClsMap::load(&bad, config()),
        Err(StoreError::Truncated(_))
    ));
    let pos = text.find("\"xc\":").unwrap() + 5;
    let mut tampered = text.clone();
    tampered.replace_range(
        pos..pos + 1,
        if &text[pos..pos + 1] == "9" { "8" } else { "9" },
    );
    std::fs::write(&bad, tampered).unwrap();
    let err = ClsMap::load(&bad, config()).unwrap_err();
    assert!(
        matches!(err, StoreError::Checksum { .. } | StoreError::Parse(_)),
        "{err}"
    );

    let grid = occupancy_grid(&run.map, &GridConfig::default()).unwrap();
    grid.write(&dir, "map").unwrap();
    let pgm = std::fs::read(dir.join("map.pgm")).unwrap();
    assert!(pgm.starts_with(format!("P5\n{} {}\n255\n", grid.width, grid.height).as_bytes()));
    assert!(grid.cells.contains(&0) && grid.cells.contains(&254) && grid.cells.contains(&205));
    let svg = picture(&run.map, Some(&poses), poses.last().copied()).to_svg();
    assert!(svg.contains("stroke-dasharray"));
    std::fs::remove_dir_all(&dir).unwrap();
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(24))]
    /// Random furnished rooms and random walks: every update leaves a valid
    /// map, whether loops are clipped to the window or unioned whole.
    #[test]
    fn random_walks_keep_the_map_valid(
        seed in 0u64..10_000,
        boxes in proptest::collection::vec((1.0..11.0f64, 1.0..7.0f64, 0.05..0.6f64, 0.05..0.6f64, 0.0..3.0f64), 0..6),
        steps in proptest::collection::vec((0.2..0.8f64, -1.0..1.0f64), 3..12),
        clip in proptest::bool::ANY,
    ) {
        let mut world = World::new();
        world.add_polyline(&[[0.0, 0.0], [12.0, 0.0], [12.0, 8.0], [0.0, 8.0]], true);
        for (x, y, hx, hy, a) in boxes {
            world.add_box([x, y], [hx, hy], a);
        }
        let mut map = ClsMap::new(ClsMapConfig { clip_to_window: clip, ..config() });
        let mut walls = SegmentMap::default();
        let spec = ScanSpec::lms200_half_degree(0.01);
        let ecfg = ExtractionConfig::default();
        let mut rng = Rng::new(seed);
        let mut pose = Pose2::new(6.0, 4.0, 0.0);
        for (forward, turn) in steps {
            pose = pose.compose(&Pose2::new(forward, 0.0, turn));
            // Stay inside the room.
            pose.x = pose.x.clamp(0.5, 11.5);
            pose.y = pose.y.clamp(0.5, 7.5);
            let scan = cast_scan(&world, &pose.compose(&mount()), &spec, 0.0, &mut rng);
            let lines = extract_lines(&scan, &mount(), &ecfg);
            let result = map.update(&mut walls, &lines, &scan, pose, COV);
            proptest::prop_assert!(
                !matches!(result, Err(ClsError::Invariant(_) | ClsError::LostHole | ClsError::Region(_))),
                "{:?}",
                result
            );
            proptest::prop_assert_eq!(map.check_invariants(), Ok(()));
            proptest::prop_assert!(map.area() >= 0.0);
        }
    }
}
