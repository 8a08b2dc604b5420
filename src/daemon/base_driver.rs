//! [`BaseDriver`]: the loop's side of the base adapter — odometry in,
//! limited velocity commands out, and the safety stops.
//!
//! Motion is commanded only while the base is healthy, its odometry fresh
//! and the loop has no reason to hold; otherwise the base gets `STOP` at
//! once (not a ramp: a real base brakes by itself, and every metre driven
//! blind is one too many), repeated once a second. A base that fails (a
//! bridge that hangs up, a port that vanishes) is dropped and connected
//! again with back-off, so a base switched on after the daemon, or
//! restarted under it, is picked up without a restart of the daemon.

use clsmap_base::{BaseAdapter, Health, Limits, StaleGuard, Twist, limit};
use lms200::recording::{Record, RecordQueue};
use tracing::{error, info, warn};

use super::live::LiveMapper;
use crate::geometry::Pose2;

/// Makes the base adapter (connects to a bridge, opens a port, hands over
/// a simulated base); called again after the base failed.
pub type BaseConnector = Box<dyn FnMut() -> Result<Box<dyn BaseAdapter + Send>, String> + Send>;

/// Seconds between repeated warnings about the same base trouble.
const WARN_EVERY: f64 = 10.0;

/// The base side of the loop: odometry in, commands out, safety stops.
pub struct BaseDriver {
    connector: Option<BaseConnector>,
    adapter: Option<Box<dyn BaseAdapter + Send>>,
    ever_connected: bool,
    /// When to try connecting next, and the wait after that (s).
    next_connect: f64,
    retry: f64,
    retry_initial: f64,
    retry_max: f64,
    guard: StaleGuard,
    limits: Limits,
    last_command: Twist,
    last_command_at: Option<f64>,
    /// Whether the last thing sent was a stop, and when.
    stopped: bool,
    last_stop_sent: f64,
    last_warning: f64,
    odometry_refused: u64,
    last_health: Option<Health>,
    pose_hint: Option<Pose2>,
    /// Where odometry samples go for the sensor's recording, if anywhere.
    recording: Option<RecordQueue>,
}

impl std::fmt::Debug for BaseDriver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BaseDriver")
            .field("connected", &self.adapter.is_some())
            .field("limits", &self.limits)
            .field("last_command", &self.last_command)
            .field("odometry_refused", &self.odometry_refused)
            .finish_non_exhaustive()
    }
}

impl BaseDriver {
    /// Drives the base `connector` makes (none: no base) within `limits`,
    /// stopping when odometry is older than `stale_odometry` seconds, and
    /// connecting again after `retry_initial` … `retry_max` seconds (the
    /// wait doubling) when it fails.
    pub fn new(
        connector: Option<BaseConnector>,
        limits: Limits,
        stale_odometry: f64,
        retry_initial: f64,
        retry_max: f64,
    ) -> BaseDriver {
        BaseDriver {
            connector,
            adapter: None,
            ever_connected: false,
            next_connect: f64::NEG_INFINITY,
            retry: retry_initial,
            retry_initial,
            retry_max,
            guard: StaleGuard::new(stale_odometry),
            limits,
            last_command: Twist::ZERO,
            last_command_at: None,
            stopped: false,
            last_stop_sent: f64::NEG_INFINITY,
            last_warning: f64::NEG_INFINITY,
            odometry_refused: 0,
            last_health: None,
            pose_hint: None,
            recording: None,
        }
    }

    /// Puts every odometry sample taken in into `queue` too, for the
    /// sensor's recording (see [`RecordQueue`]), so a recorded run
    /// replays with its odometry.
    pub fn record_odometry_into(&mut self, queue: RecordQueue) {
        self.recording = Some(queue);
    }

    /// A connector that hands over `adapter` once (a simulated or replayed
    /// base cannot be made again).
    pub fn once(adapter: Box<dyn BaseAdapter + Send>) -> BaseConnector {
        let mut adapter = Some(adapter);
        Box::new(move || {
            adapter
                .take()
                .ok_or_else(|| "this base cannot be started again".to_string())
        })
    }

    /// Takes new limits (SIGHUP). A lower speed limit applies at once.
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

    /// Whether motion may be commanded now: a connected, not failed base
    /// whose newest odometry (at `last_odometry`) is fresh.
    pub fn can_drive(&self, now: f64, last_odometry: Option<f64>) -> bool {
        let healthy = self
            .adapter
            .as_ref()
            .is_some_and(|b| !matches!(b.health(), Health::Failed(_)));
        healthy && !self.guard.must_stop(last_odometry, now)
    }

    /// The newest pose hint (map frame) the base passed on since the last
    /// call, if any.
    pub fn take_pose_hint(&mut self) -> Option<Pose2> {
        self.pose_hint.take()
    }

    /// Connects when due, moves the adapter's clock, hands new odometry to
    /// `live`, keeps the newest pose hint, and drops a failed base (to
    /// connect again later).
    pub fn poll(&mut self, now: f64, live: &mut LiveMapper) {
        self.connect_if_due(now, live);
        let Some(base) = self.adapter.as_mut() else {
            return;
        };
        base.advance(now);
        while let Some(sample) = base.odometry() {
            let p = sample.pose;
            if !live.on_odometry(sample.t, Pose2::new(p.x, p.y, p.theta)) {
                self.odometry_refused += 1;
            } else if let Some(queue) = &self.recording {
                // On the recordings' clock: as long before its reading now
                // as the sample is before `now` on the daemon's.
                let age_us = ((now - sample.t).max(0.0) * 1e6).round() as i64;
                queue.push(Record::Odometry {
                    t_us: lms200::driver::recording_micros() - age_us,
                    x: p.x,
                    y: p.y,
                    theta: p.theta,
                });
            }
        }
        if let Some(h) = base.pose_hint() {
            self.pose_hint = Some(Pose2::new(h.x, h.y, h.theta));
        }
        let health = base.health();
        if self.last_health.as_ref() != Some(&health) {
            match &health {
                Health::Ok => info!("base healthy"),
                Health::Degraded(why) => warn!("base degraded: {why}"),
                Health::Failed(why) => error!("base failed: {why}; held"),
            }
            self.last_health = Some(health.clone());
        }
        // A lost link is connected anew; a base reporting a fault over a
        // working link is held (commands become stops) until it reports
        // OK: a new connection would forget the fault.
        if base.link_lost() {
            // Try to leave it standing, then let it go.
            let _ = base.stop(now);
            self.adapter = None;
            self.stopped = false;
            self.last_command = Twist::ZERO;
            self.next_connect = now + self.retry;
            self.retry = (self.retry * 2.0).min(self.retry_max);
        }
    }

    fn connect_if_due(&mut self, now: f64, live: &mut LiveMapper) {
        if self.adapter.is_some() || now < self.next_connect {
            return;
        }
        let Some(connect) = self.connector.as_mut() else {
            return;
        };
        match connect() {
            Ok(adapter) => {
                info!("base connected");
                if self.ever_connected {
                    // A restarted base counts its odometry from zero again.
                    live.odometry_restarted();
                    if let Some(queue) = &self.recording {
                        queue.push(Record::Note {
                            t_us: lms200::driver::recording_micros(),
                            text: lms200::recording::ODOMETRY_RESTARTED_NOTE.into(),
                        });
                    }
                }
                self.ever_connected = true;
                self.adapter = Some(adapter);
                self.retry = self.retry_initial;
                self.last_health = None;
            }
            Err(e) => {
                error!(retry_in_s = self.retry, "cannot connect the base: {e}");
                self.next_connect = now + self.retry;
                self.retry = (self.retry * 2.0).min(self.retry_max);
            }
        }
    }

    /// Sends `wanted` within the limits, or a stop when `hold` is set, the
    /// odometry is stale or the base is not healthy.
    pub fn command(&mut self, wanted: Twist, hold: bool, now: f64, last_odometry: Option<f64>) {
        if hold || wanted == Twist::ZERO || !self.can_drive(now, last_odometry) {
            self.halt(now);
            return;
        }
        let Some(base) = self.adapter.as_mut() else {
            return;
        };
        let dt = self
            .last_command_at
            .map_or(0.0, |t| (now - t).clamp(0.0, 0.5));
        let twist = limit(&self.limits, self.last_command, wanted, dt);
        let result = base.command(twist, now);
        self.stopped = false;
        self.last_command_at = Some(now);
        match result {
            Ok(()) => self.last_command = twist,
            Err(e) => {
                self.last_command = Twist::ZERO;
                self.warn(now, &format!("base command failed: {e}"));
            }
        }
    }

    /// Commands a stop now, repeated at most once a second while held.
    pub fn halt(&mut self, now: f64) {
        self.last_command = Twist::ZERO;
        self.last_command_at = Some(now);
        if self.stopped && now - self.last_stop_sent < 1.0 {
            return;
        }
        let Some(base) = self.adapter.as_mut() else {
            return;
        };
        let result = base.stop(now);
        self.stopped = true;
        self.last_stop_sent = now;
        if let Err(e) = result {
            self.warn(now, &format!("cannot stop the base: {e}"));
        }
    }

    /// Stops the base for good (shutdown): sent whatever was sent before,
    /// and once more if the first attempt failed.
    pub fn stop(&mut self, now: f64) {
        let Some(base) = self.adapter.as_mut() else {
            return;
        };
        if let Err(first) = base.stop(now)
            && let Err(e) = base.stop(now)
        {
            error!("cannot stop the base: {first}; again: {e}");
        }
        self.last_command = Twist::ZERO;
        self.stopped = true;
    }

    /// One control step of the loop at `now` (s): the explorer's command
    /// (or `manual`'s, when given) while the sensor streams (`sensor_ok`)
    /// and the base can drive; otherwise a stop. Without an explorer or a
    /// manual command the base is left alone unless it must be stopped.
    pub fn control(
        &mut self,
        live: &mut LiveMapper,
        sensor_ok: bool,
        now: f64,
        manual: Option<Twist>,
    ) {
        let last_odometry = live.last_odometry_time();
        let can = sensor_ok && self.can_drive(now, last_odometry);
        if manual.is_none() && live.explorer().is_none() {
            if !sensor_ok {
                self.halt(now);
            }
            return;
        }
        let twist = match manual {
            Some(twist) => twist,
            None if can => live.control(now).0,
            None => {
                live.hold_exploration(now);
                Twist::ZERO
            }
        };
        self.command(twist, !can, now, last_odometry);
    }

    fn warn(&mut self, now: f64, text: &str) {
        if now - self.last_warning >= WARN_EVERY {
            self.last_warning = now;
            warn!("{text}");
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use std::sync::{Arc, Mutex};

    use clsmap_base::{BaseError, OdometrySample};

    use super::*;
    use crate::pipeline::config::MapperConfig;

    /// A base that records what it is told and fails on request.
    struct Probe {
        log: Arc<Mutex<Vec<String>>>,
        health: Arc<Mutex<Health>>,
        lost: Arc<Mutex<bool>>,
        now: f64,
    }

    impl BaseAdapter for Probe {
        fn advance(&mut self, now: f64) {
            self.now = now;
        }
        fn odometry(&mut self) -> Option<OdometrySample> {
            None
        }
        fn command(&mut self, twist: Twist, _now: f64) -> Result<(), BaseError> {
            self.log
                .lock()
                .unwrap()
                .push(format!("vel {:.2}", twist.vx));
            Ok(())
        }
        fn stop(&mut self, _now: f64) -> Result<(), BaseError> {
            self.log.lock().unwrap().push("stop".into());
            Ok(())
        }
        fn health(&self) -> Health {
            self.health.lock().unwrap().clone()
        }
        fn link_lost(&self) -> bool {
            *self.lost.lock().unwrap()
        }
    }

    impl Probe {
        fn new() -> Probe {
            Probe {
                log: Arc::default(),
                health: Arc::new(Mutex::new(Health::Ok)),
                lost: Arc::default(),
                now: 0.0,
            }
        }
    }

    #[test]
    fn stops_at_once_on_stale_odometry_and_reconnects_a_failed_base() {
        let log = Arc::new(Mutex::new(Vec::new()));
        let health = Arc::new(Mutex::new(Health::Ok));
        let connects = Arc::new(Mutex::new(0));
        let lost = Arc::new(Mutex::new(false));
        let (l, h, c, k) = (log.clone(), health.clone(), connects.clone(), lost.clone());
        let connector: BaseConnector = Box::new(move || {
            *c.lock().unwrap() += 1;
            // A new connection's link is whole.
            *k.lock().unwrap() = false;
            Ok(Box::new(Probe {
                log: l.clone(),
                health: h.clone(),
                lost: k.clone(),
                now: 0.0,
            }) as Box<dyn BaseAdapter + Send>)
        });
        let mut live = LiveMapper::new(MapperConfig::default(), None, 0.0);
        let mut d = BaseDriver::new(Some(connector), Limits::default(), 0.5, 1.0, 4.0);
        let recording = RecordQueue::default();
        d.record_odometry_into(recording.clone());
        d.poll(0.0, &mut live);
        assert_eq!(*connects.lock().unwrap(), 1);
        let go = Twist::new(0.5, 0.0, 0.0);
        d.command(go, false, 0.1, Some(0.1));
        d.command(go, false, 0.2, Some(0.2));
        assert!(d.last_command().vx > 0.0);
        // Odometry 0.6 s old: a stop at once, not a ramp; repeated only
        // once a second.
        d.command(go, false, 0.8, Some(0.2));
        d.command(go, false, 0.9, Some(0.2));
        assert_eq!(d.last_command(), Twist::ZERO);
        assert_eq!(
            log.lock().unwrap().iter().filter(|e| *e == "stop").count(),
            1
        );
        // The base reports a fault: held (no motion), not reconnected.
        *health.lock().unwrap() = Health::Failed("bumper pressed".into());
        d.poll(0.95, &mut live);
        assert!(!d.can_drive(0.95, Some(0.95)));
        d.command(go, false, 0.96, Some(0.96));
        assert_eq!(d.last_command(), Twist::ZERO);
        assert_eq!(*connects.lock().unwrap(), 1);
        // The link is lost: stopped, dropped, connected again after 1 s.
        *lost.lock().unwrap() = true;
        d.poll(1.0, &mut live);
        assert!(!d.can_drive(1.0, Some(1.0)));
        *health.lock().unwrap() = Health::Ok;
        d.poll(1.5, &mut live);
        assert_eq!(*connects.lock().unwrap(), 1, "back-off");
        d.poll(2.1, &mut live);
        assert_eq!(*connects.lock().unwrap(), 2);
        assert!(d.can_drive(2.1, Some(2.1)));
        // The recording is told the odometry starts anew, once: a replay
        // must not read the step back to zero as motion.
        let restarts = recording
            .take()
            .into_iter()
            .filter(|r| {
                matches!(r, Record::Note { text, .. }
                    if text == lms200::recording::ODOMETRY_RESTARTED_NOTE)
            })
            .count();
        assert_eq!(restarts, 1);
        // No base at all: nothing to drive, nothing breaks.
        let mut none = BaseDriver::new(None, Limits::default(), 0.5, 1.0, 4.0);
        none.poll(0.0, &mut live);
        none.command(go, false, 0.0, Some(0.0));
        assert!(!none.can_drive(0.0, Some(0.0)));
        // A base handed over once cannot be made again.
        let mut once = BaseDriver::once(Box::new(Probe::new()));
        assert!(once().is_ok());
        assert!(once().is_err());
    }
}
