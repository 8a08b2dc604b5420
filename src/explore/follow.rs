//! [`PathFollower`]: velocity commands that take a holonomic base along a
//! planned path and turn it to the goal's heading.
//!
//! The LMS200 sees only the half-plane in front of the robot, so while far
//! from the goal the base turns to face where it drives and slows down
//! while it is turned away (it never drives blind more than 60° off its
//! heading); within `face_distance` of the goal it turns to the goal's
//! heading while still closing in, which a holonomic base can do.

use clsmap_base::Twist;
use serde::{Deserialize, Serialize};

use crate::geometry::{Pose2, wrap_angle};

/// How the base is driven along a path. Speeds in m/s and rad/s, lengths
/// in m, angles in rad, times in s.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DriveConfig {
    /// Cruise speed (default 0.5 m/s, half the XR4000's assumed limit:
    /// at 37.5 scans/s the robot moves under 14 mm between scans).
    pub speed: f64,
    /// Largest turn rate commanded (default 1.0 rad/s).
    pub turn_rate: f64,
    /// Proportional gain of the heading control (default 2.0 1/s).
    pub heading_gain: f64,
    /// Proportional gain of the approach speed on the remaining distance
    /// (default 1.0 1/s): the base slows down over its last half metre.
    pub approach_gain: f64,
    /// The goal is reached within this distance (default 0.05 m) …
    pub position_tolerance: f64,
    /// … and this heading error (default 0.05 rad ≈ 3°).
    pub heading_tolerance: f64,
    /// A waypoint counts as passed within this distance (default 0.15 m).
    pub waypoint_tolerance: f64,
    /// Farther than this from the goal the base faces its direction of
    /// travel; closer, the goal's heading (default 0.6 m).
    pub face_distance: f64,
    /// Standstill after each goal before the next is chosen (default
    /// 0.5 s): a few scans at the goal update the map first.
    pub settle_time: f64,
    /// A goal not reached within `timeout_factor` × (path length / speed +
    /// half a turn at `turn_rate`) + `timeout_slack` is abandoned (default
    /// 3.0 and 10 s); VLSP then picks again.
    pub timeout_factor: f64,
    pub timeout_slack: f64,
}

impl Default for DriveConfig {
    fn default() -> Self {
        DriveConfig {
            speed: 0.5,
            turn_rate: 1.0,
            heading_gain: 2.0,
            approach_gain: 1.0,
            position_tolerance: 0.05,
            heading_tolerance: 0.05,
            waypoint_tolerance: 0.15,
            face_distance: 0.6,
            settle_time: 0.5,
            timeout_factor: 3.0,
            timeout_slack: 10.0,
        }
    }
}

impl DriveConfig {
    /// Every value finite and positive (the tolerances and times may be 0).
    pub fn is_valid(&self) -> bool {
        let positive = [
            self.speed,
            self.turn_rate,
            self.heading_gain,
            self.approach_gain,
            self.timeout_factor,
        ];
        let non_negative = [
            self.position_tolerance,
            self.heading_tolerance,
            self.waypoint_tolerance,
            self.face_distance,
            self.settle_time,
            self.timeout_slack,
        ];
        // At most 1e6, as every configuration number: more is a typo (and
        // overflows the goal's timeout).
        positive
            .iter()
            .all(|v| v.is_finite() && *v > 0.0 && *v <= 1e6)
            && non_negative
                .iter()
                .all(|v| v.is_finite() && (0.0..=1e6).contains(v))
    }

    /// Time (s) allowed to reach a goal `path_length` metres away.
    pub fn timeout(&self, path_length: f64) -> f64 {
        self.timeout_factor * (path_length / self.speed + std::f64::consts::PI / self.turn_rate)
            + self.timeout_slack
    }
}

/// What the follower wants now.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FollowStep {
    /// Send this velocity (robot frame).
    Drive(Twist),
    /// The goal pose is reached: stop.
    Arrived,
}

/// Follows one path to one goal.
#[derive(Debug, Clone, PartialEq)]
pub struct PathFollower {
    path: Vec<[f64; 2]>,
    goal: Pose2,
    /// Index of the waypoint driven to.
    next: usize,
}

impl PathFollower {
    /// The map moved under the path (a loop closure): path and goal follow
    /// it, `new = correction ∘ old`.
    pub fn reframe(&mut self, correction: &Pose2) {
        for p in &mut self.path {
            *p = correction.transform_point(*p);
        }
        self.goal = correction.compose(&self.goal);
    }

    /// Follows `path` (map frame, from the robot to the goal's position)
    /// and turns to `goal.theta` at its end.
    pub fn new(path: Vec<[f64; 2]>, goal: Pose2) -> PathFollower {
        let mut path = path;
        if path.last() != Some(&[goal.x, goal.y]) {
            path.push([goal.x, goal.y]);
        }
        PathFollower {
            path,
            goal,
            next: 0,
        }
    }

    pub fn goal(&self) -> Pose2 {
        self.goal
    }

    /// The planned path's points (map frame, m), the goal last.
    pub fn path(&self) -> &[[f64; 2]] {
        &self.path
    }

    /// Length (m) of the path still ahead of `pose`.
    pub fn remaining(&self, pose: &Pose2) -> f64 {
        let mut from = [pose.x, pose.y];
        let mut total = 0.0;
        for w in &self.path[self.next.min(self.path.len())..] {
            total += (w[0] - from[0]).hypot(w[1] - from[1]);
            from = *w;
        }
        total
    }

    /// The command for a robot at `pose` (map frame).
    pub fn step(&mut self, pose: &Pose2, cfg: &DriveConfig) -> FollowStep {
        if ![pose.x, pose.y, pose.theta].iter().all(|v| v.is_finite()) {
            // No way to steer from nowhere; and no waypoint is passed.
            return FollowStep::Drive(Twist::ZERO);
        }
        let last = self.path.len() - 1;
        while self.next < last {
            let w = self.path[self.next];
            if (w[0] - pose.x).hypot(w[1] - pose.y) > cfg.waypoint_tolerance {
                break;
            }
            self.next += 1;
        }
        let target = self.path[self.next.min(last)];
        let remaining = self.remaining(pose);
        let (dx, dy) = (target[0] - pose.x, target[1] - pose.y);
        let to_target = dx.hypot(dy);
        let facing_goal = remaining <= cfg.face_distance;
        let wanted_heading = if facing_goal || to_target < 1e-6 {
            self.goal.theta
        } else {
            dy.atan2(dx)
        };
        let heading_error = wrap_angle(wanted_heading - pose.theta);
        if remaining <= cfg.position_tolerance && heading_error.abs() <= cfg.heading_tolerance {
            return FollowStep::Arrived;
        }
        let mut speed = cfg.speed.min(cfg.approach_gain * remaining);
        if !facing_goal {
            // Turned away from the direction of travel: slow down, and
            // beyond 60° turn on the spot.
            let alignment = (heading_error.cos() - 0.5).max(0.0) / 0.5;
            speed *= alignment;
        }
        if remaining <= cfg.position_tolerance || to_target < 1e-9 {
            speed = 0.0;
        }
        let (ux, uy) = if to_target < 1e-9 {
            (0.0, 0.0)
        } else {
            (dx / to_target, dy / to_target)
        };
        // World-frame velocity into the robot frame.
        let (s, c) = pose.theta.sin_cos();
        let (wx, wy) = (ux * speed, uy * speed);
        let omega = (cfg.heading_gain * heading_error).clamp(-cfg.turn_rate, cfg.turn_rate);
        FollowStep::Drive(Twist::new(c * wx + s * wy, -s * wx + c * wy, omega))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// Integrates the follower's commands on a perfect holonomic base.
    fn drive(mut f: PathFollower, mut pose: Pose2, cfg: &DriveConfig) -> (Pose2, f64, f64) {
        let dt = 0.02;
        let mut t = 0.0;
        let mut max_side_speed: f64 = 0.0;
        while t < 120.0 {
            match f.step(&pose, cfg) {
                FollowStep::Arrived => return (pose, t, max_side_speed),
                FollowStep::Drive(tw) => {
                    let (s, c) = pose.theta.sin_cos();
                    if f.remaining(&pose) > cfg.face_distance + 0.2 {
                        max_side_speed = max_side_speed.max(tw.vy.abs());
                    }
                    pose = Pose2::new(
                        pose.x + (c * tw.vx - s * tw.vy) * dt,
                        pose.y + (s * tw.vx + c * tw.vy) * dt,
                        wrap_angle(pose.theta + tw.omega * dt),
                    );
                }
            }
            t += dt;
        }
        panic!("not arrived: {pose:?}");
    }

    /// After a loop closure moved the map, the follower drives to the goal
    /// in the new frame: where the old goal is now.
    #[test]
    fn a_reframed_path_leads_to_the_moved_goal() {
        let cfg = DriveConfig::default();
        let goal = Pose2::new(4.0, 0.0, 0.0);
        let mut f = PathFollower::new(vec![[0.0, 0.0], [4.0, 0.0]], goal);
        let c = Pose2::new(0.5, -0.3, 0.1);
        f.reframe(&c);
        let moved = c.compose(&goal);
        assert_eq!(f.goal(), moved);
        let (end, _, _) = drive(f, c, &cfg);
        assert!(
            (end.x - moved.x).abs() <= 0.05 && (end.y - moved.y).abs() <= 0.05,
            "{end:?}"
        );
    }

    #[test]
    fn follows_an_l_shaped_path_and_ends_at_the_goal_heading() {
        let cfg = DriveConfig::default();
        let goal = Pose2::new(4.0, 3.0, std::f64::consts::FRAC_PI_2);
        let f = PathFollower::new(vec![[0.0, 0.0], [4.0, 0.0], [4.0, 3.0]], goal);
        assert!((f.remaining(&Pose2::IDENTITY) - 7.0).abs() < 1e-12);
        // Starts facing away: turns first, then drives.
        let (end, t, side) = drive(f, Pose2::new(0.0, 0.0, 3.0), &cfg);
        assert!((end.x - 4.0).abs() <= 0.05 && (end.y - 3.0).abs() <= 0.05);
        assert!(wrap_angle(end.theta - goal.theta).abs() <= cfg.heading_tolerance);
        // 7 m at 0.5 m/s is 14 s; turns and the approach add a few.
        assert!(t > 14.0 && t < 30.0, "{t}");
        // Away from the goal it drives forward, not sideways.
        assert!(side < 0.3, "side speed {side}");
    }

    #[test]
    fn a_robot_at_the_goal_has_arrived_and_speeds_stay_in_limits() {
        let cfg = DriveConfig::default();
        let goal = Pose2::new(1.0, 1.0, 0.5);
        let mut f = PathFollower::new(vec![[1.0, 1.0]], goal);
        assert_eq!(f.step(&goal, &cfg), FollowStep::Arrived);
        let mut f = PathFollower::new(vec![[0.0, 0.0], [10.0, 0.0]], Pose2::new(10.0, 0.0, 0.0));
        let FollowStep::Drive(tw) = f.step(&Pose2::new(0.0, 0.0, 0.0), &cfg) else {
            panic!()
        };
        assert!((tw.linear_speed() - cfg.speed).abs() < 1e-9 && tw.omega.abs() < 1e-9);
        let FollowStep::Drive(tw) = f.step(&Pose2::new(0.0, 0.0, 2.0), &cfg) else {
            panic!()
        };
        assert!(tw.linear_speed() < 1e-9, "turned away: turn on the spot");
        assert!((tw.omega + cfg.turn_rate).abs() < 1e-9);
        assert!(cfg.is_valid());
        assert!(!DriveConfig { speed: 0.0, ..cfg }.is_valid());
        // A pose that is not finite stops the base and skips no waypoint.
        let before = f.clone();
        let nan = Pose2::new(f64::NAN, 0.0, 0.0);
        assert_eq!(f.step(&nan, &cfg), FollowStep::Drive(Twist::ZERO));
        assert_eq!(f, before);
    }
}
