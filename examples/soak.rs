//! An hour (or more) of robot time on a virtual clock, to measure memory.
//!
//! The daemon's loop — emulated LMS200, serial link state machine,
//! simulated base, mapper, explorer — explores the demo world by Virtual
//! Line Segment Pursuit and then patrols it, driving between random
//! reachable places for the rest of the run, so scans keep being
//! localized and keyframes keep updating the map. Checkpoints go to a
//! temporary directory every 30 s of robot time, as the daemon's default.
//! Prints the process's resident memory and the map's size every simulated
//! ten minutes.
//!
//!     cargo run --release --example soak -- [HOURS] [WORLD]

use std::f64::consts::PI;

use clsmap::daemon::simulation::VirtualRobot;
use clsmap::demo::demo_config;
use clsmap::explore::{FollowStep, PathFollower, plan_path};
use clsmap::geometry::Pose2;
use clsmap::sim::Rng;

/// Resident and peak resident memory (KiB) from /proc/self/status.
fn memory_kib() -> (u64, u64) {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let field = |name: &str| {
        status
            .lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|v| v.split_whitespace().next())
            .and_then(|v| v.parse().ok())
            .unwrap_or(0)
    };
    (field("VmRSS:"), field("VmHWM:"))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let hours: f64 = args.next().map_or(Ok(1.0), |h| h.parse())?;
    let mut config = demo_config()?;
    if let Some(world) = args.next() {
        config.sim.world = world;
    }
    let end = hours * 3600.0;
    let mut robot = VirtualRobot::new(&config)?;
    let started = std::time::Instant::now();
    println!(
        "virtual s | wall s | scans | keyframes (kept) | loop closures | walls | frontiers | RSS MiB | peak MiB"
    );
    let mut report_at = 0.0;
    let dir = std::env::temp_dir().join(format!("clsmap-soak-{}", std::process::id()));
    robot.checkpoint_into(&dir);
    let mut rng = Rng::new(11);
    let mut route: Option<PathFollower> = None;
    let radius = config.exploration.planner.clearance();
    let drive = config.exploration.drive;
    while robot.now() < end {
        if robot.now() >= report_at {
            let status = robot.live().status();
            let (rss, peak) = memory_kib();
            println!(
                "{:9.0} | {:6.1} | {:5} | {:9} ({:5}) | {:13} | {:5} | {:9} | {:7.1} | {:8.1}",
                robot.now(),
                started.elapsed().as_secs_f64(),
                status.scans,
                status.keyframes,
                status.graph_keyframes,
                status.loops_closed,
                status.walls,
                status.frontiers,
                rss as f64 / 1024.0,
                peak as f64 / 1024.0
            );
            report_at += 600.0;
        }
        if !robot.live().exploration_complete() {
            robot.tick();
            continue;
        }
        // Patrol: a new random reachable goal whenever the last is reached.
        if route.is_none()
            && let Some(pose) = robot.live().pose_now()
        {
            let map = robot.live().mapper().cls_map();
            let (lo, hi) = map.loops().flat_map(|l| l.segments().iter()).fold(
                ([f64::MAX; 2], [f64::MIN; 2]),
                |(lo, hi), s| {
                    let p = s.start();
                    (
                        [lo[0].min(p[0]), lo[1].min(p[1])],
                        [hi[0].max(p[0]), hi[1].max(p[1])],
                    )
                },
            );
            for _ in 0..50 {
                let goal = [
                    rng.uniform_range(lo[0], hi[0]),
                    rng.uniform_range(lo[1], hi[1]),
                ];
                if let Ok(path) = plan_path(map, [pose.x, pose.y], goal, radius) {
                    let heading = rng.uniform_range(-PI, PI);
                    route = Some(PathFollower::new(
                        path,
                        Pose2::new(goal[0], goal[1], heading),
                    ));
                    break;
                }
            }
        }
        robot.tick_with(|live, _| {
            let follower = route.as_mut()?;
            let pose = live.pose_now()?;
            match follower.step(&pose, &drive) {
                FollowStep::Drive(twist) => Some(twist),
                FollowStep::Arrived => {
                    route = None;
                    Some(clsmap_base::Twist::ZERO)
                }
            }
        });
    }
    let stats = robot.stats();
    let (rss, peak) = memory_kib();
    println!(
        "end: {:.0} s virtual in {:.1} s, {} scans, {:.0} m driven, mean error {:.3} m, max {:.3} m; RSS {:.1} MiB, peak {:.1} MiB",
        robot.now(),
        started.elapsed().as_secs_f64(),
        stats.scans,
        stats.driven,
        stats.mean_error,
        stats.max_error,
        rss as f64 / 1024.0,
        peak as f64 / 1024.0
    );
    let loops = robot.live().mapper().summary().loops;
    let status = robot.live().status();
    println!(
        "keyframes: {} taken, {} kept; loop closure: {} loops, {} revisits merged, {} optimisations in {:.2} s, rebuilds {:.2} s, search {:.2} s",
        status.keyframes,
        status.graph_keyframes,
        loops.accepted,
        loops.revisits_merged,
        loops.optimisations,
        loops.optimise_s,
        loops.rebuild_s,
        loops.search_s
    );
    let saving = std::time::Instant::now();
    robot.save(&dir)?;
    let trajectory = std::fs::metadata(dir.join("trajectory.tum"))?.len();
    println!(
        "last save {:.2} s ({} trajectory rewrites in the corrected frame, trajectory.tum {:.1} MB); \
         checkpoints in {}",
        saving.elapsed().as_secs_f64(),
        robot.live().mapper().reframes(),
        trajectory as f64 / 1e6,
        dir.display()
    );
    if !robot.stats().checkpoint_errors.is_empty() {
        return Err(format!("checkpoints failed: {:?}", robot.stats().checkpoint_errors).into());
    }
    Ok(())
}
