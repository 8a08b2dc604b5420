//! Helpers shared by the integration tests: scripted paths and distances
//! to the simulated worlds' walls.

// Each test binary uses only some of these.
#![allow(dead_code)]

use clsmap::geometry::Pose2;

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

pub use clsmap::geometry::point_segment_distance;
