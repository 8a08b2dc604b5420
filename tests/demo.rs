//! `clsmap demo` end to end through a real pseudo-terminal, at the
//! sensor's real pace: the emulated LMS200 measures the simulated world
//! from the simulated base, the serial driver streams at 500 kBd, and the
//! daemon's loop localizes, maps and explores until no frontier is left.

#![allow(clippy::unwrap_used)]

use clsmap::daemon::StopReason;
use clsmap::demo::{DemoStop, demo_config, run_demo};
use clsmap::map::cls::{ClsMap, ClsMapConfig};

#[test]
#[ignore = "a minute of real time; CI runs it: cargo test --test demo -- --ignored"]
fn the_demo_world_is_explored_to_completion_through_the_pty() {
    // Exactly what `clsmap demo` runs (about a minute of real time).
    let config = demo_config().unwrap();
    let out = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("demo-{}", std::process::id()));
    let mut reports = 0u64;
    let summary = run_demo(config, &out, DemoStop::TimeLimit, |_| reports += 1).unwrap();
    println!("{}", serde_json::to_string_pretty(&summary).unwrap());
    assert_eq!(
        summary.reason,
        StopReason::ExplorationComplete,
        "{summary:?}"
    );
    assert!(summary.exploration_complete);
    assert_eq!(reports, summary.scans);
    assert!(summary.scans > 100, "{summary:?}");
    assert!(summary.walls_on_world > 0.9, "{summary:?}");
    assert!(summary.mean_error_m < 0.05, "{summary:?}");
    let latency = summary
        .latencies
        .iter()
        .find(|l| l.stage == clsmap::daemon::Stage::Pose)
        .unwrap();
    assert_eq!(latency.count, summary.scans);
    assert!(summary.max_heading_error_deg < 1.0, "{summary:?}");
    // The saved map loads, is valid and closed: no frontier worth a goal.
    let map = ClsMap::load(&out.join("map.json"), ClsMapConfig::default()).unwrap();
    map.check_invariants().unwrap();
    assert!(clsmap::explore::pursuit::long_frontiers(&map, 0.74).is_empty());
    for file in ["map.svg", "trajectory.tum", "demo.json"] {
        assert!(out.join(file).is_file(), "{file} missing");
    }
}

/// Hardening: when the run's directory stops taking the map (here
/// `map.json` replaced by a directory mid-run), the last save goes to a
/// rescue directory beside the run's, inside the state directory — not
/// under `$TMPDIR`, which the unit's `PrivateTmp=` empties at stop — and
/// the rescue is whole: every pose of the run, including those written to
/// the run's directory before it failed.
#[test]
fn a_rescued_map_is_whole_and_kept_in_the_state_directory() {
    let dir = std::env::temp_dir().join(format!("clsmap-rescue-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut config = clsmap::demo::demo_config().unwrap();
    config.daemon.max_run_time = 6.0;
    config.daemon.checkpoint_interval = 1.0;
    config.daemon.state_dir = Some(dir.join("state"));
    config.exploration.exit_when_complete = false;
    let run_dir = dir.join("state").join("run");
    let blocked = run_dir.join("map.json");
    let mut hooks = clsmap::daemon::Hooks::until(std::future::pending());
    hooks.out_dir = Some(run_dir.clone());
    let mut broke = false;
    hooks.on_scan = Some(Box::new(move |_| {
        // Once a checkpoint has written the map there (scans before it
        // are in the run's trajectory), the directory stops taking it.
        if !broke && blocked.is_file() {
            std::fs::remove_file(&blocked).unwrap();
            std::fs::create_dir_all(blocked.join("in-the-way")).unwrap();
            broke = true;
        }
    }));
    let summary = clsmap::daemon::run_blocking(config, hooks).unwrap();
    let why = summary
        .rescued_because
        .clone()
        .expect("the map was rescued");
    let rescue = summary.out_dir.clone().unwrap();
    assert!(why.contains("map.json") || why.contains("run"), "{why}");
    assert_eq!(
        rescue.parent(),
        Some(dir.join("state").as_path()),
        "{rescue:?}"
    );
    let poses = std::fs::read_to_string(rescue.join("trajectory.tum"))
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .count() as u64;
    assert_eq!(poses, summary.scans, "every pose of the run in the rescue");
    clsmap::map::file::load(&rescue.join("map.json")).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
}
