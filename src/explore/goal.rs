//! The goal pose in front of a frontier (a virtual segment): on its free
//! side (the LEFT, as for every CLS segment), facing along its normal into
//! the unexplored side (its RIGHT), so the 180° laser looks straight
//! through the gap.

use serde::Serialize;

use crate::geometry::Pose2;

use super::free_space::FreeSpace;

/// A frontier: a virtual segment of the map, directed as in its loop
/// (explored free space on its left).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Frontier {
    /// Start point (m, map frame).
    pub start: [f64; 2],
    /// End point (m, map frame).
    pub end: [f64; 2],
}

impl Frontier {
    pub fn length(&self) -> f64 {
        (self.end[0] - self.start[0]).hypot(self.end[1] - self.start[1])
    }

    /// The midpoint (m).
    pub fn midpoint(&self) -> [f64; 2] {
        [
            0.5 * (self.start[0] + self.end[0]),
            0.5 * (self.start[1] + self.end[1]),
        ]
    }

    /// Direction from start to end (rad).
    pub fn direction(&self) -> f64 {
        (self.end[1] - self.start[1]).atan2(self.end[0] - self.start[0])
    }

    /// Unit normal pointing to the explored (left) side; zero for a
    /// degenerate segment.
    pub fn left_normal(&self) -> [f64; 2] {
        let len = self.length();
        if !(len > 0.0 && len.is_finite()) {
            return [0.0, 0.0];
        }
        [
            -(self.end[1] - self.start[1]) / len,
            (self.end[0] - self.start[0]) / len,
        ]
    }

    /// The point at fraction `along` (0 = start, 1 = end) of the segment,
    /// moved `standoff` (m) to its left, with the heading that faces
    /// through the segment (its right normal).
    pub fn pose_in_front(&self, along: f64, standoff: f64) -> Pose2 {
        let n = self.left_normal();
        let base = [
            self.start[0] + along * (self.end[0] - self.start[0]),
            self.start[1] + along * (self.end[1] - self.start[1]),
        ];
        Pose2::new(
            base[0] + standoff * n[0],
            base[1] + standoff * n[1],
            (-n[1]).atan2(-n[0]),
        )
    }
}

/// Where along the frontier (fractions) and how far back (multiples of the
/// standoff) a goal straight in front of it is tried, in order: in front
/// of the middle first; then farther back (a frontier in a narrow gap),
/// then off-centre (a frontier whose middle is crowded by an obstacle).
const FRONT_TRIALS: [(f64, f64); 7] = [
    (0.5, 1.0),
    (0.5, 1.5),
    (0.5, 2.0),
    (0.3, 1.0),
    (0.7, 1.0),
    (0.3, 1.5),
    (0.7, 1.5),
];

/// Oblique goals, tried when no goal straight in front fits: angles (rad)
/// off the normal and distances (multiples of the standoff) from the
/// midpoint. A frontier along an obstacle in a gap too narrow for the robot
/// (the underside of a box near a wall) can still be seen from the side,
/// at a grazing angle, from where the gap opens up.
const OBLIQUE_ANGLES: [f64; 5] = [0.35, 0.7, 1.05, 1.22, 1.4];
const OBLIQUE_DISTANCES: [f64; 5] = [1.0, 1.5, 2.0, 3.0, 4.0];

/// Sampling step (m) of the line of sight from an oblique goal.
const SIGHT_STEP: f64 = 0.05;

/// The goal pose for `frontier`: the first pose in front of it (see
/// `FRONT_TRIALS`), facing through it, whose position lies in `free` (the
/// region the robot fits in); failing those, the first oblique pose (see
/// `OBLIQUE_ANGLES`) in `free` that sees the frontier's midpoint through
/// explored space (`sees`), facing that midpoint. `None` when no pose
/// fits: the robot cannot look through this frontier.
pub fn frontier_goal(
    frontier: &Frontier,
    free: &FreeSpace,
    standoff: f64,
    sees: impl Fn([f64; 2]) -> bool,
) -> Option<Pose2> {
    let len = frontier.length();
    if !(len > 0.0 && len.is_finite() && standoff.is_finite()) {
        return None;
    }
    let straight = FRONT_TRIALS
        .iter()
        .map(|&(along, k)| frontier.pose_in_front(along, k * standoff))
        .find(|g| free.contains([g.x, g.y]));
    if straight.is_some() {
        return straight;
    }
    let m = frontier.midpoint();
    let n = frontier.left_normal();
    let normal_angle = n[1].atan2(n[0]);
    for &a in &OBLIQUE_ANGLES {
        for &k in &OBLIQUE_DISTANCES {
            for side in [1.0, -1.0] {
                let dir = normal_angle + side * a;
                let d = k * standoff;
                let p = [m[0] + d * dir.cos(), m[1] + d * dir.sin()];
                if !free.contains(p) {
                    continue;
                }
                // The line of sight to the midpoint, short of the frontier
                // itself, must stay in explored space.
                let steps = (d / SIGHT_STEP).floor() as usize;
                let clear = (0..steps).all(|i| {
                    let t = i as f64 * SIGHT_STEP;
                    sees([p[0] - t * dir.cos(), p[1] - t * dir.sin()])
                });
                if clear {
                    return Some(Pose2::new(p[0], p[1], dir + std::f64::consts::PI));
                }
            }
        }
    }
    None
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::geometry::wrap_angle;

    #[test]
    fn goal_is_in_front_on_the_free_side_facing_the_unexplored_side() {
        // Frontier along +y at x = 4: its left (free side) is −x.
        let f = Frontier {
            start: [4.0, 0.0],
            end: [4.0, 2.0],
        };
        let g = f.pose_in_front(0.5, 0.6);
        assert!((g.x - 3.4).abs() < 1e-12 && (g.y - 1.0).abs() < 1e-12);
        assert!(
            wrap_angle(g.theta).abs() < 1e-12,
            "faces +x, through the gap"
        );
        // Reversed segment: free side is +x, goal beyond it, facing −x.
        let r = Frontier {
            start: f.end,
            end: f.start,
        };
        let g = r.pose_in_front(0.5, 0.6);
        assert!((g.x - 4.6).abs() < 1e-12);
        assert!((wrap_angle(g.theta - std::f64::consts::PI)).abs() < 1e-12);
        // The heading is the right normal: looking from the goal along it
        // reaches the segment's midpoint after `standoff`.
        let ahead = [g.x + 0.6 * g.theta.cos(), g.y + 0.6 * g.theta.sin()];
        assert!((ahead[0] - 4.0).abs() < 1e-12 && (ahead[1] - 1.0).abs() < 1e-12);
    }

    #[test]
    fn goal_falls_back_when_the_middle_is_blocked_and_fails_when_all_are() {
        // Free region x ∈ [0, 4], y ∈ [0, 2] except a post at (3.4, 1).
        let outer = vec![[0.0, 0.0], [4.0, 0.0], [4.0, 2.0], [0.0, 2.0]];
        let post = vec![[3.3, 0.9], [3.3, 1.1], [3.5, 1.1], [3.5, 0.9]];
        let free = FreeSpace::from_contours(vec![outer, post]);
        let f = Frontier {
            start: [4.0, 0.0],
            end: [4.0, 2.0],
        };
        let g = frontier_goal(&f, &free, 0.6, |_| true).unwrap();
        assert!((g.x - 3.1).abs() < 1e-12 && (g.y - 1.0).abs() < 1e-12);
        let tiny = FreeSpace::from_contours(vec![vec![[0.0, 0.0], [0.1, 0.0], [0.1, 0.1]]]);
        assert_eq!(frontier_goal(&f, &tiny, 0.6, |_| true), None);
    }

    #[test]
    fn oblique_goal_looks_along_a_frontier_the_robot_cannot_stand_in_front_of() {
        // The frontier runs along the underside of a box (y = 1, free side
        // below); the robot fits only in the strip x ≤ 4, y ≤ 0.6.
        let f = Frontier {
            start: [6.0, 1.0],
            end: [5.0, 1.0],
        };
        let strip =
            FreeSpace::from_contours(vec![vec![[0.0, 0.0], [4.0, 0.0], [4.0, 0.6], [0.0, 0.6]]]);
        let g = frontier_goal(&f, &strip, 0.6, |_| true).unwrap();
        assert!(strip.contains([g.x, g.y]));
        // It faces the frontier's midpoint, from below and to the left.
        let m = f.midpoint();
        let bearing = (m[1] - g.y).atan2(m[0] - g.x);
        assert!(wrap_angle(g.theta - bearing).abs() < 1e-9);
        assert!(g.theta > 0.0 && g.theta < std::f64::consts::FRAC_PI_2);
        // No line of sight through explored space: no goal.
        assert_eq!(frontier_goal(&f, &strip, 0.6, |_| false), None);
    }
}
