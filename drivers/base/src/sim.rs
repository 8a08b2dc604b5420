//! Deterministic simulated holonomic base.
//!
//! The true pose follows the commanded twist after [`Limits`] are applied
//! (sub-stepped at most every 10 ms). Odometry integrates the same motion with
//! a linear scale error and a heading drift proportional to distance travelled.

use crate::adapter::{BaseAdapter, BaseError, Health, OdometrySample};
use crate::kinematics::{BasePose, Limits, Twist, integrate, limit};

/// Maximum integration sub-step, s.
const MAX_STEP: f64 = 0.01;

/// Simulated base implementing [`BaseAdapter`].
#[derive(Debug, Clone)]
pub struct SimBase {
    limits: Limits,
    scale_error: f64,
    heading_drift_per_m: f64,
    true_pose: BasePose,
    odom_pose: BasePose,
    commanded: Twist,
    applied: Twist,
    now: Option<f64>,
    last_reported: Option<f64>,
    odometry_frozen: bool,
}

impl SimBase {
    /// A base at the origin with `limits` and perfect odometry.
    #[must_use]
    pub fn new(limits: Limits) -> Self {
        Self {
            limits,
            scale_error: 0.0,
            heading_drift_per_m: 0.0,
            true_pose: BasePose::default(),
            odom_pose: BasePose::default(),
            commanded: Twist::ZERO,
            applied: Twist::ZERO,
            now: None,
            last_reported: None,
            odometry_frozen: false,
        }
    }

    /// Odometry error: measured linear distance = true × (1 + `scale_error`);
    /// heading drift in rad per metre of true travel (CCW+).
    #[must_use]
    pub fn with_odometry_error(mut self, scale_error: f64, heading_drift_per_m: f64) -> Self {
        self.scale_error = scale_error;
        self.heading_drift_per_m = heading_drift_per_m;
        self
    }

    /// Sets both true and odometry pose (e.g. before the first `advance`).
    pub fn reset_pose(&mut self, pose: BasePose) {
        self.true_pose = pose;
        self.odom_pose = pose;
    }

    /// Fault injection: the robot is carried to `pose` (a kidnap); the
    /// odometry does not notice.
    pub fn teleport(&mut self, pose: BasePose) {
        self.true_pose = pose;
    }

    /// Ground-truth pose (m, m, rad).
    #[must_use]
    pub fn true_pose(&self) -> BasePose {
        self.true_pose
    }

    /// Twist currently executed after limiting (robot frame).
    #[must_use]
    pub fn applied_twist(&self) -> Twist {
        self.applied
    }

    /// Fault injection: while frozen, [`BaseAdapter::odometry`] returns `None`.
    pub fn set_odometry_frozen(&mut self, frozen: bool) {
        self.odometry_frozen = frozen;
    }

    /// Advances the simulation to `now` (s). The first call only sets the
    /// clock; times that do not move forward are ignored.
    pub fn advance(&mut self, now: f64) {
        if !now.is_finite() {
            return;
        }
        let Some(mut t) = self.now else {
            self.now = Some(now);
            return;
        };
        while now > t {
            let h = (now - t).min(MAX_STEP);
            self.applied = limit(&self.limits, self.applied, self.commanded, h);
            let a = self.applied;
            self.true_pose = integrate(self.true_pose, a, h);
            let k = 1.0 + self.scale_error;
            let odom_twist = Twist::new(
                a.vx * k,
                a.vy * k,
                a.omega + self.heading_drift_per_m * a.linear_speed(),
            );
            self.odom_pose = integrate(self.odom_pose, odom_twist, h);
            t += h;
        }
        self.now = Some(t.max(now));
    }
}

impl BaseAdapter for SimBase {
    fn advance(&mut self, now: f64) {
        SimBase::advance(self, now);
    }

    fn odometry(&mut self) -> Option<OdometrySample> {
        let t = self.now?;
        if self.odometry_frozen || self.last_reported == Some(t) {
            return None;
        }
        self.last_reported = Some(t);
        Some(OdometrySample {
            t,
            pose: self.odom_pose,
        })
    }

    fn command(&mut self, twist: Twist, now: f64) -> Result<(), BaseError> {
        self.advance(now);
        if !twist.is_finite() {
            self.commanded = Twist::ZERO;
            return Err(BaseError::InvalidCommand(format!(
                "non-finite twist {twist:?}; stopping"
            )));
        }
        self.commanded = twist;
        Ok(())
    }

    fn stop(&mut self, now: f64) -> Result<(), BaseError> {
        self.advance(now);
        self.commanded = Twist::ZERO;
        Ok(())
    }

    fn health(&self) -> Health {
        if self.odometry_frozen {
            Health::Degraded("odometry frozen (fault injection)".to_owned())
        } else {
            Health::Ok
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn drive(sim: &mut SimBase, twist: Twist, from: f64, to: f64) {
        let mut t = from;
        while t < to - 1e-9 {
            sim.command(twist, t).expect("command");
            t += 0.05;
        }
        sim.advance(to);
    }

    #[test]
    fn perfect_odometry_tracks_truth_and_respects_limits() {
        let mut sim = SimBase::new(Limits::default());
        sim.advance(0.0);
        drive(&mut sim, Twist::new(5.0, 0.0, 0.0), 0.0, 3.0);
        // Accelerates at 1 m/s² to 1 m/s in 1 s: 0.5 m + 2 m.
        let p = sim.true_pose();
        assert!((p.x - 2.5).abs() < 0.02, "{p:?}");
        assert!(p.y.abs() < 1e-12);
        assert!((sim.applied_twist().vx - 1.0).abs() < 1e-12);
        let o = sim.odometry().expect("sample");
        assert_eq!(o.pose, p);
        assert!((o.t - 3.0).abs() < 1e-9);
        assert!(sim.odometry().is_none(), "same sample is returned once");
        sim.stop(3.0).expect("stop");
        sim.advance(5.0);
        assert_eq!(sim.applied_twist(), Twist::ZERO);
    }

    #[test]
    fn odometry_drift() {
        let mut sim = SimBase::new(Limits::default()).with_odometry_error(0.02, 0.01);
        sim.advance(0.0);
        drive(&mut sim, Twist::new(0.5, 0.0, 0.0), 0.0, 11.0);
        let truth = sim.true_pose();
        let odom = sim.odometry().expect("sample").pose;
        let dist = truth.x; // straight along +x
        assert!(dist > 5.0);
        assert!(truth.theta.abs() < 1e-12);
        // Heading drift 0.01 rad/m.
        assert!((odom.theta - 0.01 * dist).abs() < 1e-9, "{odom:?}");
        // Distance scaled by 1.02.
        assert!(
            (odom.x.hypot(odom.y) - 1.02 * dist).abs() < 1e-3 * dist,
            "{odom:?}"
        );
        assert!(odom.y > 0.0, "CCW drift curves left");
    }

    #[test]
    fn nan_command_stops_and_frozen_odometry() {
        let mut sim = SimBase::new(Limits::default());
        sim.advance(0.0);
        sim.command(Twist::new(0.5, 0.0, 0.0), 0.0)
            .expect("command");
        sim.advance(2.0);
        assert!(sim.command(Twist::new(f64::NAN, 0.0, 0.0), 2.0).is_err());
        sim.advance(4.0);
        assert_eq!(sim.applied_twist(), Twist::ZERO);
        assert!(sim.true_pose().x.is_finite());
        sim.set_odometry_frozen(true);
        sim.advance(4.5);
        assert!(sim.odometry().is_none());
        assert!(matches!(sim.health(), Health::Degraded(_)));
    }
}
