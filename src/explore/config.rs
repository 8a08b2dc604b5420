//! [`ExplorationConfig`]: the robot's size and the pursuit's thresholds.

use serde::{Deserialize, Serialize};

/// XR4000 base radius (m): the round Nomadic XR4000 is 0.64 m across.
pub const XR4000_RADIUS: f64 = 0.32;

/// Tuning of Virtual Line Segment Pursuit. Every length is in metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExplorationConfig {
    /// Radius of the robot's footprint (default 0.32 m, the XR4000).
    pub robot_radius: f64,
    /// Extra clearance kept from every map boundary on top of the radius
    /// (default 0.05 m): the shrunk free region uses `robot_radius +
    /// clearance_margin`, which absorbs map noise (σ ≈ 1 cm on walls) and
    /// the corner approximation of the offset.
    pub clearance_margin: f64,
    /// Shortest virtual segment worth pursuing (default 0.74 m = robot
    /// width 0.64 m + 0.10 m): a shorter gap is one the robot could not
    /// drive through, and behind which it could see little; when no longer
    /// frontier is left the map is complete.
    pub min_frontier_length: f64,
    /// Distance of the goal from the frontier's midpoint, along its normal
    /// into the explored side (default 0.6 m: beyond the clearance, so the
    /// goal lies in the shrunk region when the frontier's side is open,
    /// and close enough that the laser sees far through the gap).
    pub goal_standoff: f64,
    /// How far (m) the start may lie outside the shrunk region and still be
    /// joined to it by a straight step (default 0.6 m). After a scan the
    /// robot sits on the closing segments through the sensor centre, i.e.
    /// on the map's boundary, so it is never strictly inside.
    pub start_snap: f64,
    /// Goals issued for one frontier before it is given up (default 2):
    /// a frontier that survives two visits cannot be seen through (grazing
    /// walls, glass, beyond range) and must not be chased forever.
    pub max_attempts: u32,
    /// Two frontiers are the same (for the memory) when their midpoints
    /// lie within this distance (default 0.5 m) …
    pub match_distance: f64,
    /// … and their directions within this angle (rad, default 0.5 ≈ 29°).
    pub match_angle: f64,
}

impl ExplorationConfig {
    /// Clearance (m) the planner keeps from every map boundary.
    pub fn clearance(&self) -> f64 {
        self.robot_radius + self.clearance_margin
    }

    /// Whether every value is finite and in range.
    pub fn is_valid(&self) -> bool {
        let lengths = [
            self.robot_radius,
            self.clearance_margin,
            self.min_frontier_length,
            self.goal_standoff,
            self.start_snap,
            self.match_distance,
            self.match_angle,
        ];
        // At most 1e6, as every configuration number: more is a typo.
        lengths
            .iter()
            .all(|v| v.is_finite() && (0.0..=1e6).contains(v))
            && self.robot_radius > 0.0
            && self.goal_standoff > 0.0
    }
}

impl Default for ExplorationConfig {
    fn default() -> Self {
        ExplorationConfig {
            robot_radius: XR4000_RADIUS,
            clearance_margin: 0.05,
            min_frontier_length: 2.0 * XR4000_RADIUS + 0.10,
            goal_standoff: 0.6,
            start_snap: 0.6,
            max_attempts: 2,
            match_distance: 0.5,
            match_angle: 0.5,
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn defaults_round_trip_and_unknown_keys_are_refused() {
        let cfg = ExplorationConfig::default();
        assert!(cfg.is_valid());
        assert!((cfg.min_frontier_length - 0.74).abs() < 1e-12);
        let json = serde_json::to_string(&cfg).unwrap();
        let back: ExplorationConfig = serde_json::from_str(&json).unwrap();
        assert_eq!(back, cfg);
        let partial: ExplorationConfig = serde_json::from_str(r#"{"robot_radius":0.25}"#).unwrap();
        assert_eq!(partial.goal_standoff, cfg.goal_standoff);
        assert!(serde_json::from_str::<ExplorationConfig>(r#"{"radius":0.25}"#).is_err());
        let bad = ExplorationConfig {
            robot_radius: f64::NAN,
            ..cfg
        };
        assert!(!bad.is_valid());
    }
}
