//! The link's named deadlines.
//!
//! Timers are data, not sleeps: each named deadline is an `Option<Instant>`
//! that the state machine arms and disarms; the shell asks for the earliest
//! one with `poll_timeout` and calls `handle_timeout` when it has passed.

use std::time::Instant;

/// The deadlines the link uses, one slot each.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Timer {
    /// The single-byte ACK (`06`) for the last request has not come.
    Ack,
    /// The reply telegram for the last acknowledged request has not come.
    Reply,
    /// After a NAK (or before a resend) the host must wait ≥ 30 ms.
    Resend,
    /// After the host changed its line speed, let the sensor settle.
    BaudSettle,
    /// No scan for too long while streaming.
    ScanWatchdog,
    /// Wait before the next initialisation attempt (capped doubling).
    Reinit,
    /// Whole shutdown sequence gave up.
    Close,
}

const TIMER_COUNT: usize = 7;

impl Timer {
    const ALL: [Timer; TIMER_COUNT] = [
        Timer::Ack,
        Timer::Reply,
        Timer::Resend,
        Timer::BaudSettle,
        Timer::ScanWatchdog,
        Timer::Reinit,
        Timer::Close,
    ];

    fn index(self) -> usize {
        self as usize
    }
}

/// A table of named deadlines.
#[derive(Debug, Clone, Default)]
pub(crate) struct TimerTable {
    deadlines: [Option<Instant>; TIMER_COUNT],
}

impl TimerTable {
    pub fn set(&mut self, timer: Timer, at: Instant) {
        self.deadlines[timer.index()] = Some(at);
    }

    pub fn stop(&mut self, timer: Timer) {
        self.deadlines[timer.index()] = None;
    }

    pub fn get(&self, timer: Timer) -> Option<Instant> {
        self.deadlines[timer.index()]
    }

    /// Stops every timer (state reset).
    pub fn stop_all(&mut self) {
        self.deadlines = [None; TIMER_COUNT];
    }

    /// The earliest armed deadline.
    pub fn next(&self) -> Option<Instant> {
        self.deadlines.iter().flatten().min().copied()
    }

    /// Disarms and returns the first timer (in table order) expired at `now`.
    pub fn take_expired(&mut self, now: Instant) -> Option<Timer> {
        let timer = Timer::ALL
            .into_iter()
            .find(|t| self.get(*t).is_some_and(|d| d <= now))?;
        self.stop(timer);
        Some(timer)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn next_is_the_earliest_and_expiry_disarms() {
        let t0 = Instant::now();
        let mut table = TimerTable::default();
        assert_eq!(table.next(), None);
        table.set(Timer::Reply, t0 + Duration::from_millis(50));
        table.set(Timer::Ack, t0 + Duration::from_millis(60));
        assert_eq!(table.next(), Some(t0 + Duration::from_millis(50)));
        assert_eq!(table.take_expired(t0 + Duration::from_millis(10)), None);
        assert_eq!(
            table.take_expired(t0 + Duration::from_millis(70)),
            Some(Timer::Ack)
        );
        assert_eq!(
            table.take_expired(t0 + Duration::from_millis(70)),
            Some(Timer::Reply)
        );
        assert_eq!(table.take_expired(t0 + Duration::from_millis(70)), None);
        assert_eq!(table.next(), None);
    }

    #[test]
    fn stop_all_clears() {
        let t0 = Instant::now();
        let mut table = TimerTable::default();
        table.set(Timer::ScanWatchdog, t0);
        table.set(Timer::Close, t0);
        table.stop_all();
        assert_eq!(table.next(), None);
    }
}
