//! A scripted tour for the simulated holonomic base: waypoints driven at a
//! constant speed, translating and turning at once as an XR4000 can.

use crate::geometry::{Pose2, wrap_angle};

/// Waypoints and the speeds between them; a pure function of time, so the
/// simulated laser and the simulated odometry agree on where the robot was.
#[derive(Debug, Clone)]
pub struct Tour {
    waypoints: Vec<Pose2>,
    /// Start time of each leg (s from the first move); one more entry
    /// than legs, the last being the time of the last move's end.
    leg_starts: Vec<f64>,
    /// Time parked at the first waypoint before moving (s).
    delay: f64,
}

impl Tour {
    /// A tour through `waypoints` at `speed` (m/s) and `turn_rate` (rad/s);
    /// each leg takes as long as the slower of its translation and turn.
    /// Non-positive speeds are taken as 1 m/s and 1 rad/s.
    pub fn new(waypoints: Vec<Pose2>, speed: f64, turn_rate: f64) -> Tour {
        let speed = if speed > 0.0 { speed } else { 1.0 };
        let turn_rate = if turn_rate > 0.0 { turn_rate } else { 1.0 };
        let mut leg_starts = vec![0.0];
        for w in waypoints.windows(2) {
            let d = (w[1].x - w[0].x).hypot(w[1].y - w[0].y);
            let a = wrap_angle(w[1].theta - w[0].theta).abs();
            let last = leg_starts.last().copied().unwrap_or(0.0);
            leg_starts.push(last + (d / speed).max(a / turn_rate));
        }
        Tour {
            waypoints,
            leg_starts,
            delay: 0.0,
        }
    }

    /// The same tour, parked at its first waypoint for `delay` seconds
    /// more before it moves (negative delays count as zero).
    pub fn delayed(&self, delay: f64) -> Tour {
        Tour {
            delay: self.delay + delay.max(0.0),
            ..self.clone()
        }
    }

    /// Time the whole tour takes, waiting included (s).
    pub fn duration(&self) -> f64 {
        self.delay + self.leg_starts.last().copied().unwrap_or(0.0)
    }

    /// Where the robot is `t` seconds after the start; before the start it
    /// waits at the first waypoint, after the end at the last.
    pub fn pose_at(&self, t: f64) -> Pose2 {
        let (Some(first), Some(last)) = (self.waypoints.first(), self.waypoints.last()) else {
            return Pose2::IDENTITY;
        };
        let t = t - self.delay;
        if t.is_nan() || t <= 0.0 {
            return *first;
        }
        let leg = self.leg_starts.partition_point(|&s| s <= t);
        if leg >= self.leg_starts.len() {
            return *last;
        }
        // leg >= 1 because leg_starts[0] = 0 < t.
        let (t0, t1) = (self.leg_starts[leg - 1], self.leg_starts[leg]);
        let f = if t1 > t0 { (t - t0) / (t1 - t0) } else { 1.0 };
        self.waypoints[leg - 1].interpolate(&self.waypoints[leg], f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn legs_take_the_slower_of_driving_and_turning() {
        let tour = Tour::new(
            vec![
                Pose2::new(0.0, 0.0, 0.0),
                Pose2::new(2.0, 0.0, 0.0),
                Pose2::new(2.0, 0.0, std::f64::consts::FRAC_PI_2),
            ],
            1.0,
            std::f64::consts::FRAC_PI_4,
        );
        assert!((tour.duration() - 4.0).abs() < 1e-12);
        let p = tour.pose_at(1.0);
        assert!((p.x - 1.0).abs() < 1e-12 && p.y == 0.0);
        let p = tour.pose_at(3.0);
        assert!((p.theta - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
        assert_eq!(tour.pose_at(-1.0), Pose2::new(0.0, 0.0, 0.0));
        assert_eq!(tour.pose_at(99.0).x, 2.0);
        assert_eq!(tour.pose_at(f64::NAN), Pose2::new(0.0, 0.0, 0.0));
    }

    #[test]
    fn a_delayed_tour_waits_first() {
        let tour = Tour::new(
            vec![Pose2::new(0.0, 0.0, 0.0), Pose2::new(1.0, 0.0, 0.0)],
            1.0,
            1.0,
        )
        .delayed(2.0);
        assert_eq!(tour.duration(), 3.0);
        assert_eq!(tour.pose_at(1.9).x, 0.0);
        assert!((tour.pose_at(2.5).x - 0.5).abs() < 1e-12);
    }

    #[test]
    fn empty_tour_stays_at_the_origin() {
        let tour = Tour::new(Vec::new(), 1.0, 1.0);
        assert_eq!(tour.duration(), 0.0);
        assert_eq!(tour.pose_at(1.0), Pose2::IDENTITY);
    }
}
