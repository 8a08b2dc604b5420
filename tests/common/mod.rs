//! Helpers shared by the integration tests: scripted paths and distances
//! to the simulated worlds' walls.

// Each test binary uses only some of these.
#![allow(dead_code)]

use clsmap::geometry::{Pose2, wrap_angle};
use clsmap::sim::Rng;

/// Poses every `step` metres along the polyline through `waypoints`, each
/// facing along its leg.
pub fn path(waypoints: &[[f64; 2]], step: f64) -> Vec<Pose2> {
    let mut out = Vec::new();
    for w in waypoints.windows(2) {
        let (a, b) = (w[0], w[1]);
        let len = (b[0] - a[0]).hypot(b[1] - a[1]);
        let heading = (b[1] - a[1]).atan2(b[0] - a[0]);
        let n = (len / step).ceil() as usize;
        for k in 0..n {
            let t = k as f64 / n as f64;
            out.push(Pose2::new(
                a[0] + t * (b[0] - a[0]),
                a[1] + t * (b[1] - a[1]),
                heading,
            ));
        }
    }
    out
}

/// Poses every `step` m along the corridor centre line, turning in place
/// at the corners, `laps` times round.
pub fn tour(corners: &[[f64; 2]], laps: usize, step: f64) -> Vec<Pose2> {
    let mut truth = vec![Pose2::new(corners[0][0], corners[0][1], 0.0)];
    for _ in 0..laps {
        for w in corners.windows(2) {
            let heading = (w[1][1] - w[0][1]).atan2(w[1][0] - w[0][0]);
            let mut p = *truth.last().unwrap();
            while wrap_angle(heading - p.theta).abs() > 1e-9 {
                let turn = wrap_angle(heading - p.theta).clamp(-0.15, 0.15);
                p = Pose2::new(p.x, p.y, p.theta + turn);
                truth.push(p);
            }
            let length = (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]);
            let steps = (length / step).round() as usize;
            for k in 1..=steps {
                let f = k as f64 / steps as f64;
                truth.push(Pose2::new(
                    w[0][0] + f * (w[1][0] - w[0][0]),
                    w[0][1] + f * (w[1][1] - w[0][1]),
                    heading,
                ));
            }
        }
    }
    truth
}

/// Odometry along `truth` with a scale error and a heading drift per
/// metre, plus a little noise, started in a frame of its own.
pub fn drifting_odometry(
    truth: &[Pose2],
    scale: f64,
    drift_per_m: f64,
    rng: &mut Rng,
) -> Vec<Pose2> {
    let mut odo = vec![Pose2::new(-3.0, 5.0, 1.0)];
    for w in truth.windows(2) {
        let d = w[0].between(&w[1]);
        let dist = d.x.hypot(d.y);
        let biased = Pose2::new(
            scale * d.x + rng.normal(0.002),
            scale * d.y + rng.normal(0.002),
            d.theta + drift_per_m * dist + rng.normal(0.002),
        );
        odo.push(odo.last().unwrap().compose(&biased));
    }
    odo
}

#[allow(unused_imports)]
pub use clsmap::geometry::point_segment_distance;

/// The directory of the real CSAIL log (`../shared/datasets/mit-csail`
/// beside the repository), or `None` when it is missing: the tests that
/// need it are skipped on a machine without it, saying so, but fail under
/// CI (`CI` set, and not `false` or `0`), where a silent skip would pass
/// them untested.
pub fn csail_dir() -> Option<std::path::PathBuf> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/datasets/mit-csail");
    if dir.join("mit-csail.clf").is_file() && dir.join("mit-csail.relations").is_file() {
        return Some(dir);
    }
    let missing = format!(
        "CSAIL dataset not found at {} (expected mit-csail.clf and mit-csail.relations)",
        dir.display()
    );
    let under_ci = std::env::var("CI").is_ok_and(|v| !v.is_empty() && v != "false" && v != "0");
    assert!(!under_ci, "{missing}: CI must run the tests that need it");
    eprintln!("SKIPPED: {missing}");
    None
}
