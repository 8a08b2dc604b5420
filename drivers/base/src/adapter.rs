//! The [`BaseAdapter`] trait the daemon drives, and the stale-odometry guard.

use crate::kinematics::{BasePose, Twist};

/// One odometry reading: time `t` in seconds (adapter clock, same clock as the
/// `now` passed to commands) and the pose in the odometry frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometrySample {
    /// Sample time, s.
    pub t: f64,
    /// Pose in the odometry frame (m, m, rad).
    pub pose: BasePose,
}

/// Health of a base.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Health {
    /// Fully operational.
    Ok,
    /// Operational with a problem worth reporting.
    Degraded(String),
    /// Not operational; commands will not move the robot.
    Failed(String),
}

/// Errors from a base adapter.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BaseError {
    /// The link to the base (serial, TCP, ...) failed.
    #[error("base link error: {0}")]
    Link(String),
    /// The base reported a fault.
    #[error("base fault: {0}")]
    Fault(String),
    /// The command was rejected (e.g. non-finite values); the base was stopped.
    #[error("invalid command: {0}")]
    InvalidCommand(String),
}

/// A mobile base the daemon can drive. Times are seconds on one monotonic clock.
pub trait BaseAdapter {
    /// Tells the adapter the time is `now` (s): a simulated or replayed
    /// base moves its clock, a bridged base stamps what arrived with it.
    /// Called by the daemon before every poll; the default does nothing.
    fn advance(&mut self, now: f64) {
        let _ = now;
    }
    /// Newest odometry sample not yet returned, or `None`; never blocks.
    fn odometry(&mut self) -> Option<OdometrySample>;
    /// Commands a robot-frame velocity (m/s, m/s, rad/s) at time `now` (s).
    fn command(&mut self, twist: Twist, now: f64) -> Result<(), BaseError>;
    /// Commands a stop at time `now` (s).
    fn stop(&mut self, now: f64) -> Result<(), BaseError>;
    /// Current health.
    fn health(&self) -> Health;
    /// The newest pose hint (map frame) the base passed on and not yet
    /// returned, if any: an operator's or a dock's "the robot is here".
    /// Default: none.
    fn pose_hint(&mut self) -> Option<BasePose> {
        None
    }
    /// Whether the link to the base is lost for good (a bridge that hung
    /// up, a port that vanished): the daemon then connects anew. A base
    /// that reports a fault over a working link is held, not reconnected,
    /// since a new connection would forget the fault. Default: never.
    fn link_lost(&self) -> bool {
        false
    }
}

/// Decides when the odometry stream is too old to keep commanding motion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StaleGuard {
    /// Maximum odometry age, s.
    pub max_age: f64,
}

impl Default for StaleGuard {
    /// 0.5 s.
    fn default() -> Self {
        Self { max_age: 0.5 }
    }
}

impl StaleGuard {
    /// Creates a guard with `max_age` seconds.
    #[must_use]
    pub const fn new(max_age: f64) -> Self {
        Self { max_age }
    }

    /// True when commands must be replaced by a stop: no odometry yet, the
    /// last sample is older than `max_age`, more than `max_age` in the future
    /// (clock trouble), or any time is non-finite.
    #[must_use]
    pub fn must_stop(&self, last_odometry_t: Option<f64>, now: f64) -> bool {
        match last_odometry_t {
            None => true,
            Some(t) => !(-self.max_age..=self.max_age).contains(&(now - t)),
        }
    }

    /// `wanted` if odometry is fresh, otherwise [`Twist::ZERO`].
    #[must_use]
    pub fn filter(&self, last_odometry_t: Option<f64>, now: f64, wanted: Twist) -> Twist {
        if self.must_stop(last_odometry_t, now) {
            Twist::ZERO
        } else {
            wanted
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stale_guard() {
        let g = StaleGuard::new(0.5);
        assert!(g.must_stop(None, 1.0));
        assert!(!g.must_stop(Some(1.0), 1.0));
        assert!(!g.must_stop(Some(1.0), 1.5));
        assert!(g.must_stop(Some(1.0), 1.6));
        assert!(g.must_stop(Some(3.0), 1.0));
        assert!(g.must_stop(Some(f64::NAN), 1.0));
        assert!(g.must_stop(Some(1.0), f64::INFINITY));
        let w = Twist::new(0.3, 0.0, 0.0);
        assert_eq!(g.filter(Some(1.0), 1.2, w), w);
        assert_eq!(g.filter(Some(1.0), 2.0, w), Twist::ZERO);
    }
}
