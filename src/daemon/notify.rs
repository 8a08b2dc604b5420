//! systemd's notification protocol (`Type=notify`): READY once the laser
//! streams (or after `ready_after` without it), WATCHDOG pings from the
//! loop, STATUS lines, STOPPING.
//!
//! Outside systemd (`NOTIFY_SOCKET` unset) every call does nothing. The
//! watchdog is pinged by [`Notifier::loop_alive`], which the loop calls
//! each time it comes round — never by a timer of its own, which would
//! keep pinging while the loop is stuck.

use std::time::{Duration, Instant};

use sd_notify::NotifyState;
use tracing::warn;

/// Sends notifications, rate-limiting the watchdog pings.
#[derive(Debug)]
pub struct Notifier {
    /// Half the watchdog interval systemd asked for, if it asked.
    ping_every: Option<Duration>,
    last_ping: Option<Instant>,
    ready: bool,
    warned: bool,
}

impl Notifier {
    /// Reads the watchdog interval from the environment systemd set.
    pub fn from_env() -> Notifier {
        Notifier {
            ping_every: sd_notify::watchdog_enabled().map(|d| d / 2),
            last_ping: None,
            ready: false,
            warned: false,
        }
    }

    /// The watchdog interval systemd set, if any.
    pub fn watchdog(&self) -> Option<Duration> {
        self.ping_every.map(|d| d * 2)
    }

    fn send(&mut self, states: &[NotifyState]) {
        if let Err(e) = sd_notify::notify(states)
            && !self.warned
        {
            self.warned = true;
            warn!("cannot notify systemd: {e}");
        }
    }

    /// READY=1, once; true the first time.
    pub fn ready(&mut self) -> bool {
        if self.ready {
            return false;
        }
        self.ready = true;
        self.send(&[NotifyState::Ready]);
        true
    }

    /// STATUS=… (one line).
    pub fn status(&mut self, text: &str) {
        self.send(&[NotifyState::Status(text)]);
    }

    /// WATCHDOG=1 if half the interval has passed since the last ping.
    pub fn loop_alive(&mut self, now: Instant) {
        let Some(every) = self.ping_every else {
            return;
        };
        if self
            .last_ping
            .is_none_or(|t| now.duration_since(t) >= every)
        {
            self.last_ping = Some(now);
            self.send(&[NotifyState::Watchdog]);
        }
    }

    /// STOPPING=1.
    pub fn stopping(&mut self) {
        self.send(&[NotifyState::Stopping]);
    }
}
