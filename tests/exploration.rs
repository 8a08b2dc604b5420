//! Exploration by Virtual Line Segment Pursuit in the simulator: from a
//! start pose the robot scans (LMS200 180°/0.5°, σ = 1 cm, true poses),
//! grows the CLS map, asks `next_step` for the next frontier, drives the
//! planned path in ~0.3 m steps scanning at every step, and repeats until
//! the map is complete. Checked: completion within the cap, every goal
//! reached by a collision-free path, the map covering the world with its
//! walls on real walls and no long frontier left.
//!
//! `cargo test --test exploration -- --nocapture` prints the figures; the
//! pictures go to `target/tmp/exploration-*.svg`.

#![allow(clippy::unwrap_used)]

mod common;

use clsmap::explore::pursuit::long_frontiers;
use clsmap::explore::{
    ExplorationConfig, ExplorationMemory, FreeSpace, NextStep, PlanError, next_step, path_length,
    plan_path,
};
use clsmap::geometry::{ExtractionConfig, Pose2, extract_lines};
use clsmap::map::SegmentMap;
use clsmap::map::cls::{ClsLoop, ClsMap, ClsMapConfig, ClsSegment, ClsShape, SegmentMode};
use clsmap::render::picture;
use clsmap::sim::{Rng, ScanSpec, World, WorldFile, cast_scan};
use common::point_segment_distance;
use proptest::prelude::*;

const COV: [[f64; 3]; 3] = [[1e-6, 0.0, 0.0], [0.0, 1e-6, 0.0], [0.0, 0.0, 1e-7]];
/// Driving step between scans (m).
const STEP: f64 = 0.3;
/// Goals before the run counts as failed.
const MAX_GOALS: usize = 80;

fn wall_distance(world: &World, p: [f64; 2]) -> f64 {
    world
        .walls()
        .iter()
        .map(|&[a, b]| point_segment_distance(p, a, b))
        .fold(f64::INFINITY, f64::min)
}

fn segments_cross(p: [f64; 2], q: [f64; 2], a: [f64; 2], b: [f64; 2]) -> bool {
    let o = |u: [f64; 2], v: [f64; 2], w: [f64; 2]| {
        (v[0] - u[0]) * (w[1] - u[1]) - (v[1] - u[1]) * (w[0] - u[0])
    };
    (o(p, q, a) > 0.0) != (o(p, q, b) > 0.0) && (o(a, b, p) > 0.0) != (o(a, b, q) > 0.0)
}

/// Free floor connected to `start` (flood fill on a `cell` grid, steps
/// that cross no wall): the centres of the cells.
fn reachable_cells(world: &World, start: [f64; 2], cell: f64) -> Vec<[f64; 2]> {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for &[a, b] in world.walls() {
        for p in [a, b] {
            lo = [lo[0].min(p[0]), lo[1].min(p[1])];
            hi = [hi[0].max(p[0]), hi[1].max(p[1])];
        }
    }
    let nx = ((hi[0] - lo[0]) / cell).ceil() as usize;
    let ny = ((hi[1] - lo[1]) / cell).ceil() as usize;
    let centre = |i: usize, j: usize| {
        [
            lo[0] + (i as f64 + 0.5) * cell,
            lo[1] + (j as f64 + 0.5) * cell,
        ]
    };
    let si = ((start[0] - lo[0]) / cell) as usize;
    let sj = ((start[1] - lo[1]) / cell) as usize;
    let mut seen = vec![false; nx * ny];
    let mut stack = vec![(si, sj)];
    seen[sj * nx + si] = true;
    let mut out = Vec::new();
    while let Some((i, j)) = stack.pop() {
        let c = centre(i, j);
        out.push(c);
        let mut next = Vec::new();
        if i > 0 {
            next.push((i - 1, j));
        }
        if j > 0 {
            next.push((i, j - 1));
        }
        if i + 1 < nx {
            next.push((i + 1, j));
        }
        if j + 1 < ny {
            next.push((i, j + 1));
        }
        for (a, b) in next {
            let d = centre(a, b);
            if !seen[b * nx + a]
                && !world
                    .walls()
                    .iter()
                    .any(|&[p, q]| segments_cross(c, d, p, q))
            {
                seen[b * nx + a] = true;
                stack.push((a, b));
            }
        }
    }
    out
}

/// The simulated robot and its map.
struct Explorer<'a> {
    world: &'a World,
    map: ClsMap,
    walls: SegmentMap,
    pose: Pose2,
    rng: Rng,
    spec: ScanSpec,
    ecfg: ExtractionConfig,
    trajectory: Vec<Pose2>,
    scans: usize,
    failed_updates: usize,
    driven: f64,
    /// Smallest distance (m) of any driven point from a real wall.
    closest_wall: f64,
}

impl<'a> Explorer<'a> {
    fn new(world: &'a World, start: Pose2, seed: u64) -> Self {
        let mut e = Explorer {
            world,
            map: ClsMap::new(ClsMapConfig::default()),
            walls: SegmentMap::default(),
            pose: start,
            rng: Rng::new(seed),
            spec: ScanSpec::lms200_half_degree(0.01),
            ecfg: ExtractionConfig::default(),
            trajectory: Vec::new(),
            scans: 0,
            failed_updates: 0,
            driven: 0.0,
            closest_wall: wall_distance(world, [start.x, start.y]),
        };
        e.scan();
        e
    }

    /// Scans at the current (true) pose and updates the map.
    fn scan(&mut self) {
        let mount = self.map.config().local.mount;
        let scan = cast_scan(
            self.world,
            &self.pose.compose(&mount),
            &self.spec,
            self.scans as f64,
            &mut self.rng,
        );
        let lines = extract_lines(&scan, &mount, &self.ecfg);
        if self
            .map
            .update(&mut self.walls, &lines, &scan, self.pose, COV)
            .is_err()
        {
            self.failed_updates += 1;
        }
        self.map.check_invariants().unwrap();
        self.scans += 1;
        self.trajectory.push(self.pose);
    }

    /// Drives along `path` in steps of about `STEP`, facing the next
    /// waypoint, scanning after every step; then turns to `heading` and
    /// scans.
    fn drive(&mut self, path: &[[f64; 2]], heading: f64) {
        for w in path.windows(2) {
            let (a, b) = (w[0], w[1]);
            let len = (b[0] - a[0]).hypot(b[1] - a[1]);
            let n = (len / STEP).ceil().max(1.0) as usize;
            let dir = (b[1] - a[1]).atan2(b[0] - a[0]);
            // Collision check of the whole leg, every centimetre.
            let samples = (len / 0.01).ceil().max(1.0) as usize;
            for k in 0..=samples {
                let t = k as f64 / samples as f64;
                let p = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
                self.closest_wall = self.closest_wall.min(wall_distance(self.world, p));
            }
            for k in 1..=n {
                let t = k as f64 / n as f64;
                self.pose = Pose2::new(a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), dir);
                self.scan();
            }
            self.driven += len;
        }
        self.pose = Pose2::new(self.pose.x, self.pose.y, heading);
        self.scan();
    }
}

struct Outcome {
    goals: usize,
    complete: bool,
    given_up: usize,
}

fn explore(name: &str, world: &World, start: Pose2, seed: u64) {
    let cfg = ExplorationConfig::default();
    let mut memory = ExplorationMemory::default();
    let mut robot = Explorer::new(world, start, seed);
    let mut outcome = Outcome {
        goals: 0,
        complete: false,
        given_up: 0,
    };
    while outcome.goals < MAX_GOALS {
        match next_step(&robot.map, robot.pose, &cfg, &mut memory).unwrap() {
            NextStep::Complete { given_up } => {
                outcome.complete = true;
                outcome.given_up = given_up.len();
                break;
            }
            NextStep::Goal { goal, path, .. } => {
                outcome.goals += 1;
                assert_eq!(
                    path.first(),
                    Some(&[robot.pose.x, robot.pose.y]),
                    "from the robot"
                );
                assert_eq!(
                    path.last(),
                    Some(&[goal.x, goal.y]),
                    "the path ends at the goal"
                );
                robot.drive(&path, goal.theta);
            }
        }
    }
    let cells = reachable_cells(world, [start.x, start.y], 0.05);
    let covered = cells.iter().filter(|&&c| robot.map.contains(c)).count();
    let coverage = covered as f64 / cells.len() as f64;
    let free_area = cells.len() as f64 * 0.05 * 0.05;
    let on_walls = {
        let (mut good, mut total) = (0usize, 0usize);
        for s in robot.map.actual_segments() {
            let n = (s.length() / 0.01).ceil().max(1.0) as usize;
            for k in 0..n {
                let t = (k as f64 + 0.5) / n as f64;
                let (a, b) = (s.start(), s.end());
                let p = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
                total += 1;
                good += usize::from(wall_distance(world, p) <= 0.05);
            }
        }
        good as f64 / total.max(1) as f64
    };
    let long_left = long_frontiers(&robot.map, cfg.min_frontier_length);
    let svg =
        std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("exploration-{name}.svg"));
    std::fs::write(
        &svg,
        picture(&robot.map, Some(&robot.trajectory), Some(robot.pose)).to_svg(),
    )
    .unwrap();
    println!(
        "{name}: complete={} after {} goals, {:.1} m driven, {} scans ({} updates refused), \
         map {:.1} m² of {:.1} m² free in reach (coverage {:.1} %), {:.1} % of wall length on real walls, \
         {} long frontiers left ({} given up), closest approach to a wall {:.3} m; picture {}",
        outcome.complete,
        outcome.goals,
        robot.driven,
        robot.scans,
        robot.failed_updates,
        robot.map.area(),
        free_area,
        100.0 * coverage,
        100.0 * on_walls,
        long_left.len(),
        outcome.given_up,
        robot.closest_wall,
        svg.display()
    );
    for f in &long_left {
        println!("  left: {:?} -> {:?} ({:.2} m)", f.start, f.end, f.length());
    }
    assert!(
        outcome.complete,
        "{name}: not complete after {MAX_GOALS} goals"
    );
    assert!(
        robot.closest_wall >= cfg.robot_radius - 0.01,
        "{name}: the robot came within {:.3} m of a wall",
        robot.closest_wall
    );
    assert!(coverage >= 0.9, "{name}: coverage {coverage:.3}");
    assert!(
        on_walls >= 0.95,
        "{name}: walls on real walls {on_walls:.3}"
    );
    // Every long frontier closed, or at most one given up (the face of a
    // box close to a wall, which no pose in reach sees) with nearly all of
    // the free space covered.
    assert!(
        long_left.is_empty() || (long_left.len() <= outcome.given_up.min(1) && coverage >= 0.99),
        "{name}: long frontiers left: {long_left:?}"
    );
}

#[test]
fn explores_the_room_with_boxes() {
    let world = World::room_with_boxes();
    explore("room", &world, Pose2::new(4.5, 3.0, 0.0), 7);
    explore("room-b", &world, Pose2::new(6.8, 4.5, -2.5), 8);
}

#[test]
fn explores_the_corridor_with_doors() {
    let world = World::corridor_with_doors();
    explore("corridor", &world, Pose2::new(1.5, 0.0, 0.0), 7);
    explore("corridor-b", &world, Pose2::new(15.0, 0.3, 1.0), 8);
}

#[test]
fn explores_the_loop_around_a_block() {
    let world = World::loop_around_block();
    explore(
        "loop",
        &world,
        Pose2::new(1.0, 5.0, std::f64::consts::FRAC_PI_2),
        7,
    );
    explore("loop-b", &world, Pose2::new(6.0, 9.0, 0.0), 8);
}

#[test]
fn explores_the_paper_lab() {
    let lab = WorldFile::builtin("lab").unwrap();
    explore("lab", &lab.world, lab.start, 7);
    explore("lab-b", &lab.world, Pose2::new(8.0, 4.0, 3.0), 8);
}

#[test]
fn explores_the_corridor_with_rooms() {
    let office = WorldFile::builtin("office").unwrap();
    explore("office", &office.world, office.start, 7);
    explore("office-b", &office.world, Pose2::new(10.0, 0.0, 0.0), 8);
}

// ---------------------------------------------------------------------
// The planner on hand-made maps.

/// A loop through `points` (all walls).
fn walls(points: &[[f64; 2]]) -> ClsLoop {
    let n = points.len();
    ClsLoop::new(
        (0..n)
            .map(|i| {
                let mut s = ClsSegment::virtual_between(points[i], points[(i + 1) % n]);
                s.mode = SegmentMode::Actual;
                s
            })
            .collect(),
    )
}

/// A map of one outer polygon (counter-clockwise) and holes (clockwise).
fn map_with(outer: &[[f64; 2]], holes: &[Vec<[f64; 2]>]) -> ClsMap {
    let shape = ClsShape {
        outer: walls(outer),
        holes: holes.iter().map(|h| walls(h)).collect(),
    };
    ClsMap::from_shapes(ClsMapConfig::default(), vec![shape]).unwrap()
}

/// A clockwise box (an obstacle) centred at `c` with half sizes `h`,
/// turned by `a`.
fn obstacle(c: [f64; 2], h: [f64; 2], a: f64) -> Vec<[f64; 2]> {
    let (s, co) = a.sin_cos();
    [(-1.0, -1.0), (-1.0, 1.0), (1.0, 1.0), (1.0, -1.0)]
        .iter()
        .map(|&(u, v)| {
            [
                c[0] + co * u * h[0] - s * v * h[1],
                c[1] + s * u * h[0] + co * v * h[1],
            ]
        })
        .collect()
}

/// Smallest distance (m) from the polyline `path` (sampled every 5 mm) to
/// any boundary segment of `map`, and whether every sample is in the map.
fn clearance_of(map: &ClsMap, path: &[[f64; 2]]) -> (f64, bool) {
    let mut closest = f64::INFINITY;
    let mut inside = true;
    for w in path.windows(2) {
        let (a, b) = (w[0], w[1]);
        let n = (((b[0] - a[0]).hypot(b[1] - a[1])) / 0.005).ceil().max(1.0) as usize;
        for k in 0..=n {
            let t = k as f64 / n as f64;
            let p = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
            inside &= map.contains(p);
            for s in map.segments() {
                closest = closest.min(point_segment_distance(p, s.start(), s.end()));
            }
        }
    }
    (closest, inside)
}

const L_CORRIDOR: [[f64; 2]; 6] = [
    [0.0, 0.0],
    [6.0, 0.0],
    [6.0, 1.2],
    [1.2, 1.2],
    [1.2, 6.0],
    [0.0, 6.0],
];

#[test]
fn plans_around_the_corner_of_an_l_shaped_corridor() {
    let map = map_with(&L_CORRIDOR, &[]);
    let r = 0.32;
    let path = plan_path(&map, [5.5, 0.6], [0.6, 5.5], r).unwrap();
    assert_eq!(path.first(), Some(&[5.5, 0.6]));
    assert_eq!(path.last(), Some(&[0.6, 5.5]));
    // It bends round the inner corner (1.2, 1.2) of the L at the radius:
    // every bend on the offset's arc (chords kept outside the circle).
    let step_factor = 1.0 / 0.15f64.cos();
    for v in &path[1..path.len() - 1] {
        let d = (v[0] - 1.2).hypot(v[1] - 1.2);
        assert!(d >= r - 1e-9 && d <= r * step_factor + 1e-6, "{v:?} at {d}");
    }
    let (closest, inside) = clearance_of(&map, &path);
    assert!(inside && closest >= r - 1e-3, "clearance {closest}");
    // Shorter than the two straight legs through the mitred corner
    // (1.2 − r, 1.2 − r), longer than the legs tangent to the exact arc.
    let miter = (5.5f64 - 0.88).hypot(0.88 - 0.6) + (0.88f64 - 0.6).hypot(5.5 - 0.88);
    let exact = around_disc([5.5, 0.6], [0.6, 5.5], [1.2, 1.2], r);
    let length = path_length(&path);
    assert!(
        length < miter && length >= exact - 1e-9,
        "{length} vs {exact}..{miter}"
    );
    assert!(length - exact < 0.01, "{length} vs {exact}");
}

/// Length of the shortest way from `a` to `b` round the far side of the
/// disc of radius `r` at `c` (the side the straight line from `a` to `b`
/// does not pass): both tangent legs and the arc between them.
fn around_disc(a: [f64; 2], b: [f64; 2], c: [f64; 2], r: f64) -> f64 {
    let leg = |p: [f64; 2]| {
        let d = (p[0] - c[0]).hypot(p[1] - c[1]);
        (
            (d * d - r * r).sqrt(),
            (p[1] - c[1]).atan2(p[0] - c[0]),
            (r / d).acos(),
        )
    };
    let (la, aa, ta) = leg(a);
    let (lb, ab, tb) = leg(b);
    let between = std::f64::consts::TAU - clsmap::geometry::wrap_angle(ab - aa).abs();
    la + lb + r * (between - ta - tb).max(0.0)
}

#[test]
fn plans_around_a_hole() {
    let outer = [[0.0, 0.0], [8.0, 0.0], [8.0, 4.0], [0.0, 4.0]];
    let hole = obstacle([4.0, 2.0], [1.0, 1.2], 0.0);
    let map = map_with(&outer, &[hole]);
    let r = 0.32;
    let path = plan_path(&map, [1.0, 2.0], [7.0, 2.0], r).unwrap();
    // Round the box by two of its corners, each bend on the offset's arc.
    let corners = [[3.0, 0.8], [5.0, 0.8], [3.0, 3.2], [5.0, 3.2]];
    let step_factor = 1.0 / 0.15f64.cos();
    for v in &path[1..path.len() - 1] {
        let d = corners
            .iter()
            .map(|c| (v[0] - c[0]).hypot(v[1] - c[1]))
            .fold(f64::INFINITY, f64::min);
        assert!(
            d >= r - 1e-9 && d <= r * step_factor + 1e-6,
            "{v:?} at {d}: {path:?}"
        );
    }
    let (closest, inside) = clearance_of(&map, &path);
    assert!(inside && closest >= r - 1e-3, "clearance {closest}");
    // Both ways round are equally long. The exact detour: tangent to the
    // first corner's circle, along the box's side, tangent away from the
    // second; the chords add at most a few millimetres.
    let (a, c1): ([f64; 2], [f64; 2]) = ([1.0, 2.0], [3.0, 0.8]);
    let d = (a[0] - c1[0]).hypot(a[1] - c1[1]);
    let tangent = (d * d - r * r).sqrt();
    let to_corner = (c1[1] - a[1]).atan2(c1[0] - a[0]);
    let leg_dir = to_corner - (r / d).asin();
    let turn = clsmap::geometry::wrap_angle(0.0 - leg_dir).abs();
    let exact = 2.0 * (tangent + r * turn) + 2.0;
    let length = path_length(&path);
    assert!(
        length >= exact - 1e-6 && length - exact < 0.01,
        "{length} vs {exact}"
    );
}

#[test]
fn a_gap_narrower_than_the_robot_is_a_typed_error() {
    // Two 3 m × 3 m rooms joined by a 0.5 m gap in the wall at x = 3.
    let outer = [
        [0.0, 0.0],
        [3.0, 0.0],
        [3.0, 1.25],
        [3.2, 1.25],
        [3.2, 0.0],
        [6.2, 0.0],
        [6.2, 3.0],
        [3.2, 3.0],
        [3.2, 1.75],
        [3.0, 1.75],
        [3.0, 3.0],
        [0.0, 3.0],
    ];
    let map = map_with(&outer, &[]);
    assert_eq!(
        plan_path(&map, [1.5, 1.5], [4.7, 1.5], 0.32),
        Err(PlanError::Unreachable)
    );
    // A thinner robot (radius 0.2 m) fits through the 0.5 m gap.
    let path = plan_path(&map, [1.5, 1.5], [4.7, 1.5], 0.2).unwrap();
    assert_eq!(path.len(), 2);
    // A goal in the wall's clearance band is refused as such.
    assert_eq!(
        plan_path(&map, [1.5, 1.5], [1.5, 0.1], 0.32),
        Err(PlanError::GoalOutside([1.5, 0.1]))
    );
    assert!(matches!(
        plan_path(&map, [1.5, 1.5], [1.5, 2.0], f64::NAN),
        Err(PlanError::FreeSpace(_))
    ));
}

/// A 12 m × 8 m room with one turned box per 4 m × 4 m cell (so boxes
/// never overlap): `(u, v)` place it in its cell, `(hx, hy)` are its half
/// sizes, `a` its angle.
fn box_field(boxes: &[(f64, f64, f64, f64, f64)]) -> ClsMap {
    let outer = [[0.0, 0.0], [12.0, 0.0], [12.0, 8.0], [0.0, 8.0]];
    let holes: Vec<_> = boxes
        .iter()
        .enumerate()
        .map(|(i, &(u, v, hx, hy, a))| {
            let cell = [(i % 3) as f64 * 4.0, (i / 3) as f64 * 4.0];
            obstacle(
                [cell[0] + 1.2 + 1.6 * u, cell[1] + 1.2 + 1.6 * v],
                [hx, hy],
                a,
            )
        })
        .collect();
    map_with(&outer, &holes)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Any planned path in a room with up to six turned boxes keeps the
    /// clearance from every wall: it lies in the shrunk region.
    #[test]
    fn planned_paths_stay_inside_the_shrunk_region(
        boxes in proptest::collection::vec(
            (0.0f64..1.0, 0.0f64..1.0, 0.15f64..0.6, 0.15f64..0.6, 0.0f64..3.2),
            0..6,
        ),
        start in (0.3f64..11.7, 0.3f64..7.7),
        goal in (0.3f64..11.7, 0.3f64..7.7),
    ) {
        let map = box_field(&boxes);
        let r = 0.32;
        let free = FreeSpace::from_map(&map, r).unwrap();
        let (s, g) = ([start.0, start.1], [goal.0, goal.1]);
        prop_assume!(free.contains(s) && free.contains(g));
        let path = plan_path(&map, s, g, r).unwrap();
        prop_assert_eq!(path.first(), Some(&s));
        prop_assert_eq!(path.last(), Some(&g));
        for w in path.windows(2) {
            prop_assert!(free.segment_inside(w[0], w[1]));
        }
        let (closest, inside) = clearance_of(&map, &path);
        prop_assert!(inside);
        prop_assert!(closest >= r - 1e-3, "clearance {} on {:?}", closest, path);
        prop_assert!(path_length(&path) >= (g[0] - s[0]).hypot(g[1] - s[1]) - 1e-9);
    }
}

/// Shortest path length (m) from `s` to `g` by plain Dijkstra over every
/// vertex of `free`, every pair joined when the step stays inside: the
/// reference for the planner's reduced graph and A*.
fn brute_force_length(free: &FreeSpace, s: [f64; 2], g: [f64; 2]) -> Option<f64> {
    let mut nodes = vec![s, g];
    nodes.extend(free.contours().iter().flatten().copied());
    let n = nodes.len();
    let mut dist = vec![f64::INFINITY; n];
    let mut done = vec![false; n];
    dist[0] = 0.0;
    loop {
        let u = (0..n)
            .filter(|&i| !done[i] && dist[i].is_finite())
            .min_by(|&a, &b| dist[a].total_cmp(&dist[b]))?;
        if u == 1 {
            return Some(dist[1]);
        }
        done[u] = true;
        for v in 0..n {
            let d = dist[u] + (nodes[v][0] - nodes[u][0]).hypot(nodes[v][1] - nodes[u][1]);
            if !done[v] && d < dist[v] && free.segment_inside(nodes[u], nodes[v]) {
                dist[v] = d;
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// The planner's paths are as short as the full visibility graph's.
    #[test]
    fn planned_paths_are_shortest(
        boxes in proptest::collection::vec(
            (0.0f64..1.0, 0.0f64..1.0, 0.15f64..0.6, 0.15f64..0.6, 0.0f64..3.2),
            1..6,
        ),
        start in (0.3f64..11.7, 0.3f64..7.7),
        goal in (0.3f64..11.7, 0.3f64..7.7),
    ) {
        let map = box_field(&boxes);
        let r = 0.32;
        let free = FreeSpace::from_map(&map, r).unwrap();
        let (s, g) = ([start.0, start.1], [goal.0, goal.1]);
        prop_assume!(free.contains(s) && free.contains(g));
        let reference = brute_force_length(&free, s, g);
        match plan_path(&map, s, g, r) {
            Ok(path) => {
                let reference = reference.unwrap();
                prop_assert!((path_length(&path) - reference).abs() < 1e-6,
                    "planned {} vs {}", path_length(&path), reference);
            }
            Err(e) => {
                prop_assert_eq!(e, PlanError::Unreachable);
                prop_assert!(reference.is_none());
            }
        }
    }
}
