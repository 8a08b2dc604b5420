//! `clsmap demo` end to end through a real pseudo-terminal, at the
//! sensor's real pace: the emulated LMS200 measures the simulated world
//! from the simulated base, the serial driver streams at 500 kBd, and the
//! daemon's loop localizes, maps and explores until no frontier is left.

#![allow(clippy::unwrap_used)]

use clsmap::daemon::StopReason;
use clsmap::demo::{DemoStop, demo_config, run_demo};
use clsmap::map::cls::{ClsMap, ClsMapConfig};

#[test]
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
