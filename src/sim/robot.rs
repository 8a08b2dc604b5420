//! [`SimRobot`]: one simulated holonomic robot seen from two sides — the
//! daemon drives it as a base adapter, the emulated LMS200 rides on it.
//!
//! The daemon commands velocities and reads odometry (with the base's scale
//! error and heading drift) through [`SimRobotBase`]; the emulator, on its
//! own thread, asks where the robot truly was at each scan's mid-sweep
//! ([`Carrier`]). Both share one [`SimBase`] behind a mutex. The emulator's
//! mid-sweep times lie a few milliseconds behind the daemon's clock, so the
//! true poses of the last seconds are kept and interpolated rather than
//! read from the base's present state.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex, MutexGuard};

use clsmap_base::{BaseAdapter, BaseError, BasePose, Health, OdometrySample, SimBase, Twist};

use super::laser::Carrier;
use crate::geometry::Pose2;

/// How much true-pose history is kept (s): far more than the ~40 ms by
/// which a scan's mid-sweep trails the daemon's clock.
const HISTORY: f64 = 5.0;

#[derive(Debug)]
struct Shared {
    base: SimBase,
    /// True poses after each advance: (t, pose), oldest first.
    history: VecDeque<(f64, Pose2)>,
}

impl Shared {
    fn advance(&mut self, now: f64) {
        self.base.advance(now);
        let p = self.base.true_pose();
        let pose = Pose2::new(p.x, p.y, p.theta);
        match self.history.back() {
            Some(&(t, _)) if now <= t => {}
            _ => self.history.push_back((now, pose)),
        }
        while self.history.len() > 2
            && self
                .history
                .front()
                .is_some_and(|(t, _)| *t < now - HISTORY)
        {
            self.history.pop_front();
        }
    }

    fn pose_at(&mut self, t: f64) -> Pose2 {
        if self.history.back().is_none_or(|(last, _)| t > *last) {
            self.advance(t);
        }
        let after = self.history.partition_point(|(ti, _)| *ti <= t);
        match (
            after.checked_sub(1).map(|i| self.history[i]),
            self.history.get(after),
        ) {
            (Some((ta, a)), Some(&(tb, b))) if tb > ta => a.interpolate(&b, (t - ta) / (tb - ta)),
            (Some((_, a)), _) => a,
            (None, Some(&(_, b))) => b,
            (None, None) => {
                let p = self.base.true_pose();
                Pose2::new(p.x, p.y, p.theta)
            }
        }
    }
}

/// A simulated robot shared by the daemon (as its base) and the emulated
/// sensor (as its carrier). Cloning gives another handle to the same robot.
#[derive(Debug, Clone)]
pub struct SimRobot {
    shared: Arc<Mutex<Shared>>,
}

impl SimRobot {
    /// A robot whose base (limits, odometry error) is `base`, standing at
    /// `start` (world frame); its odometry starts at `start` too.
    pub fn new(mut base: SimBase, start: Pose2) -> SimRobot {
        base.reset_pose(BasePose::new(start.x, start.y, start.theta));
        SimRobot {
            shared: Arc::new(Mutex::new(Shared {
                base,
                history: VecDeque::new(),
            })),
        }
    }

    fn lock(&self) -> MutexGuard<'_, Shared> {
        // A panic while holding the lock leaves plain numbers behind, which
        // are still a valid robot state.
        self.shared.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The true pose (world frame) at `t` seconds: interpolated within the
    /// last few seconds, the oldest kept pose before them, and the robot
    /// moved on to `t` after them.
    pub fn true_pose_at(&self, t: f64) -> Pose2 {
        self.lock().pose_at(t)
    }

    /// The base adapter the daemon drives.
    pub fn base(&self) -> SimRobotBase {
        SimRobotBase {
            robot: self.clone(),
        }
    }

    /// Fault injection: while frozen the base reports no odometry.
    pub fn set_odometry_frozen(&self, frozen: bool) {
        self.lock().base.set_odometry_frozen(frozen);
    }

    /// Fault injection: the robot is carried to `pose` (world frame) at
    /// once, its odometry unaware (a kidnap); scans after now see it there.
    pub fn kidnap(&self, pose: Pose2) {
        let mut shared = self.lock();
        shared
            .base
            .teleport(BasePose::new(pose.x, pose.y, pose.theta));
        let last = shared.history.back().map(|(t, _)| *t);
        shared.history.clear();
        if let Some(t) = last {
            shared.history.push_back((t, pose));
        }
    }

    /// The velocity the base executes now, after its limits (robot frame).
    pub fn applied_twist(&self) -> Twist {
        self.lock().base.applied_twist()
    }
}

impl Carrier for SimRobot {
    fn pose_at(&mut self, t: f64) -> Pose2 {
        self.true_pose_at(t)
    }
}

/// [`SimRobot`] as a [`BaseAdapter`].
#[derive(Debug, Clone)]
pub struct SimRobotBase {
    robot: SimRobot,
}

impl BaseAdapter for SimRobotBase {
    fn advance(&mut self, now: f64) {
        self.robot.lock().advance(now);
    }

    fn odometry(&mut self) -> Option<OdometrySample> {
        self.robot.lock().base.odometry()
    }

    fn command(&mut self, twist: Twist, now: f64) -> Result<(), BaseError> {
        let mut shared = self.robot.lock();
        shared.advance(now);
        shared.base.command(twist, now)
    }

    fn stop(&mut self, now: f64) -> Result<(), BaseError> {
        let mut shared = self.robot.lock();
        shared.advance(now);
        shared.base.stop(now)
    }

    fn health(&self) -> Health {
        self.robot.lock().base.health()
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use clsmap_base::Limits;

    #[test]
    fn the_sensor_sees_the_pose_the_base_was_driven_to() {
        let robot = SimRobot::new(SimBase::new(Limits::default()), Pose2::new(1.0, 2.0, 0.0));
        let mut base = robot.base();
        base.advance(0.0);
        base.command(Twist::new(0.5, 0.0, 0.0), 0.0).unwrap();
        for k in 1..=300 {
            base.advance(k as f64 * 0.01);
        }
        // After 3 s at up to 0.5 m/s (1 m/s² ramp: 0.125 m lost to it).
        let end = robot.true_pose_at(3.0);
        assert!((end.x - (1.0 + 1.5 - 0.125)).abs() < 0.01, "{end:?}");
        // A time in the past is interpolated, not the present pose.
        let mid = robot.clone().pose_at(2.0);
        assert!((mid.x - (1.0 + 1.0 - 0.125)).abs() < 0.01, "{mid:?}");
        // Odometry started at the start pose and follows the motion.
        let odo = base.odometry().unwrap();
        assert!((odo.pose.x - end.x).abs() < 1e-9 && odo.t == 3.0);
        // A time ahead moves the robot on.
        let ahead = robot.true_pose_at(4.0);
        assert!((ahead.x - (end.x + 0.5)).abs() < 0.01);
    }

    #[test]
    fn frozen_odometry_reports_nothing_but_the_robot_moves() {
        let robot = SimRobot::new(SimBase::new(Limits::default()), Pose2::IDENTITY);
        let mut base = robot.base();
        base.advance(0.0);
        base.command(Twist::new(0.0, 0.3, 0.0), 0.0).unwrap();
        robot.set_odometry_frozen(true);
        base.advance(1.0);
        assert!(base.odometry().is_none());
        assert!(matches!(base.health(), Health::Degraded(_)));
        assert!(robot.true_pose_at(1.0).y > 0.2);
        assert!(robot.applied_twist().vy > 0.29);
    }
}
