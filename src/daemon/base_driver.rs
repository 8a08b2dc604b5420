//! [`BaseDriver`]: the loop's side of the base adapter — odometry in,
//! limited velocity commands out, and the safety stops: a stale odometry
//! stream or a silent sensor replaces every command by a stop.

use clsmap_base::{BaseAdapter, Health, Limits, StaleGuard, Twist, limit};
use tracing::{error, info, warn};

use super::live::LiveMapper;
use crate::geometry::Pose2;

/// The base side of the loop: odometry in, commands out, safety stops.
pub struct BaseDriver {
    adapter: Option<Box<dyn BaseAdapter + Send>>,
    guard: StaleGuard,
    limits: Limits,
    last_command: Twist,
    last_command_at: Option<f64>,
    /// Whether the last thing sent was a stop.
    stopped: bool,
    last_stop_sent: f64,
    odometry_refused: u64,
    last_health: Option<Health>,
}

impl std::fmt::Debug for BaseDriver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BaseDriver")
            .field("limits", &self.limits)
            .field("last_command", &self.last_command)
            .field("odometry_refused", &self.odometry_refused)
            .finish_non_exhaustive()
    }
}

impl BaseDriver {
    /// Drives `adapter` (none: nothing to drive) within `limits`, stopping
    /// when odometry is older than `stale_odometry` seconds.
    pub fn new(
        adapter: Option<Box<dyn BaseAdapter + Send>>,
        limits: Limits,
        stale_odometry: f64,
    ) -> BaseDriver {
        BaseDriver {
            adapter,
            guard: StaleGuard::new(stale_odometry),
            limits,
            last_command: Twist::ZERO,
            last_command_at: None,
            stopped: false,
            last_stop_sent: f64::NEG_INFINITY,
            odometry_refused: 0,
            last_health: None,
        }
    }

    /// Takes new limits (SIGHUP).
    pub fn retune(&mut self, limits: Limits, stale_odometry: f64) {
        self.limits = limits;
        self.guard = StaleGuard::new(stale_odometry);
    }

    /// Odometry samples refused as out of order so far.
    pub fn odometry_refused(&self) -> u64 {
        self.odometry_refused
    }

    /// The last velocity sent (robot frame).
    pub fn last_command(&self) -> Twist {
        self.last_command
    }

    /// Moves the adapter's clock and hands new odometry to `live`.
    pub fn poll(&mut self, now: f64, live: &mut LiveMapper) {
        let Some(base) = self.adapter.as_mut() else {
            return;
        };
        base.advance(now);
        while let Some(sample) = base.odometry() {
            let p = sample.pose;
            if !live.on_odometry(sample.t, Pose2::new(p.x, p.y, p.theta)) {
                self.odometry_refused += 1;
            }
        }
        let health = base.health();
        if self.last_health.as_ref() != Some(&health) {
            match &health {
                Health::Ok => info!("base healthy"),
                Health::Degraded(why) => warn!("base degraded: {why}"),
                Health::Failed(why) => error!("base failed: {why}"),
            }
            self.last_health = Some(health);
        }
    }

    /// Sends `wanted` (limited), or a stop when `hold` or the odometry is
    /// stale. Stops are repeated once a second, motion every tick.
    pub fn command(&mut self, wanted: Twist, hold: bool, now: f64, last_odometry: Option<f64>) {
        let Some(base) = self.adapter.as_mut() else {
            return;
        };
        let wanted = if hold {
            Twist::ZERO
        } else {
            self.guard.filter(last_odometry, now, wanted)
        };
        let dt = self
            .last_command_at
            .map_or(0.0, |t| (now - t).clamp(0.0, 0.5));
        let twist = limit(&self.limits, self.last_command, wanted, dt);
        let result = if twist == Twist::ZERO && wanted == Twist::ZERO {
            if self.stopped && now - self.last_stop_sent < 1.0 {
                return;
            }
            self.stopped = true;
            self.last_stop_sent = now;
            base.stop(now)
        } else {
            self.stopped = false;
            base.command(twist, now)
        };
        self.last_command = if result.is_ok() { twist } else { Twist::ZERO };
        self.last_command_at = Some(now);
        if let Err(e) = result {
            warn!("base command failed: {e}");
        }
    }

    pub fn stop(&mut self, now: f64) {
        if let Some(base) = self.adapter.as_mut()
            && let Err(e) = base.stop(now)
        {
            warn!("cannot stop the base: {e}");
        }
    }
}
