//! A virtual serial line: the sans-IO [`Link`] and the sans-IO [`Emulator`]
//! back to back on a virtual clock, faster than real time.
//!
//! The line models what sits between the host's tty and the sensor's UART:
//!
//! - host bytes take their wire time (10 bits per byte) at the host's line
//!   speed and queue behind each other; the sensor receives each frame when
//!   its last byte has arrived;
//! - the emulator paces its own output at the sensor's speed and hands the
//!   link whatever has arrived;
//! - [`Output::SetBaud`] from the link sets the host speed and tells the
//!   emulator ([`Emulator::set_host_baud`]), which garbles bytes both ways
//!   while the two speeds differ;
//! - the clock jumps to the earliest of the link's deadlines, the emulator's
//!   deadlines and the next host frame's arrival. Nothing reads a real clock:
//!   time is whatever the caller passes in.
//!
//! [`VirtualLine`] owns both peers and is what a simulation loop drives, one
//! [`VirtualLine::advance_to`] per control tick. [`Wire`] is the same line
//! without the peers, for owners that must keep the link and the emulator
//! themselves (a test harness that moves the emulator on to a second link).
//!
//! Nothing accumulates in the line: events go to the caller's callback as
//! they happen, and the only queue holds host frames still on the wire (the
//! link has one request out at a time). The emulator's own log of sent scans
//! is bounded by [`EmulatorConfig::scan_log_capacity`](crate::emulator::EmulatorConfig::scan_log_capacity);
//! set it to 0 for long soak runs that do not compare scans.

use std::collections::VecDeque;
use std::time::Instant;

use crate::Baud;
use crate::emulator::Emulator;
use crate::link::timing::wire_time;
use crate::link::{Event, Link, LinkConfig, Output};

/// What the host side of the line did, as its owner sees it.
#[derive(Debug, Clone, PartialEq)]
pub enum HostOutput<'a> {
    /// The link wrote this frame to the line; it reaches the sensor after its
    /// wire time at the host's speed.
    Transmit(&'a [u8]),
    /// The link asked for this host line speed (ignored while the host is
    /// stuck at 9600 Bd).
    SetBaud(Baud),
    /// Something the link reported.
    Event(Event),
    /// Bytes from the sensor's line as they reached the host's tty (after
    /// the line's noise), just before the link was handed them.
    Received(&'a [u8]),
}

/// The line between a [`Link`] and an [`Emulator`] that live elsewhere: the
/// virtual clock, the host's line speed and the host frames on the wire.
///
/// Every method takes the two peers; pass the same ones every time.
#[derive(Debug)]
pub struct Wire {
    now: Instant,
    /// The host tty's speed.
    host_baud: Baud,
    /// When the host's transmitter is free again.
    host_tx_free: Instant,
    /// Host frames on their way to the sensor: (arrival of the last byte,
    /// bytes), in arrival order.
    in_flight: VecDeque<(Instant, Vec<u8>)>,
    /// Ignore `SetBaud`: the host tty stays where it is.
    host_stuck_at_9600: bool,
    /// Everything due at `now` has been moved and `now` is not a deadline
    /// (the clock stopped at a tick boundary), so bytes the emulator released
    /// meanwhile wait for the next deadline. This keeps results independent
    /// of the tick length.
    settled: bool,
}

impl Wire {
    /// A host tty at 9600 Bd (the power-on speed) attached to `emulator` at
    /// `now`.
    pub fn connect(emulator: &mut Emulator, now: Instant) -> Self {
        emulator.set_host_baud(Baud::B9600);
        Self {
            now,
            host_baud: Baud::B9600,
            host_tx_free: now,
            in_flight: VecDeque::new(),
            host_stuck_at_9600: false,
            settled: false,
        }
    }

    /// The virtual clock.
    pub fn now(&self) -> Instant {
        self.now
    }

    /// The host tty's line speed.
    pub fn host_baud(&self) -> Baud {
        self.host_baud
    }

    /// Whether the host ignores `SetBaud` (see [`Self::set_host_stuck_at_9600`]).
    pub fn host_stuck_at_9600(&self) -> bool {
        self.host_stuck_at_9600
    }

    /// Emulates a shell that forgets to change its tty's speed: from now on
    /// `SetBaud` is ignored, so the host stays at its current speed (9600 Bd
    /// when set before the link's first speed change).
    pub fn set_host_stuck_at_9600(&mut self, stuck: bool) {
        self.host_stuck_at_9600 = stuck;
    }

    /// Puts everything the link has written on the wire, applies its speed
    /// changes and hands each output to `on_output` with the current time.
    pub fn flush(
        &mut self,
        link: &mut Link,
        emulator: &mut Emulator,
        mut on_output: impl FnMut(Instant, HostOutput<'_>),
    ) {
        while let Some(output) = link.poll_output() {
            match output {
                Output::Transmit(bytes) => {
                    let start = self.now.max(self.host_tx_free);
                    let arrival = start + wire_time(bytes.len(), self.host_baud);
                    self.host_tx_free = arrival;
                    on_output(self.now, HostOutput::Transmit(&bytes));
                    self.in_flight.push_back((arrival, bytes));
                }
                Output::SetBaud(baud) => {
                    if !self.host_stuck_at_9600 {
                        self.host_baud = baud;
                        emulator.set_host_baud(baud);
                    }
                    on_output(self.now, HostOutput::SetBaud(baud));
                }
                Output::Event(event) => on_output(self.now, HostOutput::Event(event)),
            }
        }
    }

    /// Moves everything that is due now, then advances the clock once, to the
    /// next deadline of either peer or the next host frame's arrival.
    /// Returns false when neither side has anything left to do.
    pub fn step(
        &mut self,
        link: &mut Link,
        emulator: &mut Emulator,
        mut on_output: impl FnMut(Instant, HostOutput<'_>),
    ) -> bool {
        self.flush(link, emulator, &mut on_output);
        if let Some(bytes) = emulator.poll_transmit(self.now) {
            on_output(self.now, HostOutput::Received(&bytes));
            link.handle_input(&bytes, self.now);
            return true;
        }
        match self.next_deadline(link, emulator) {
            Some(next) => {
                self.run_due(next, link, emulator);
                true
            }
            None => false,
        }
    }

    /// Runs every step due up to `until`, then sets the clock to `until`
    /// (never beyond it; an `until` in the past leaves the clock alone).
    /// Each output goes to `on_output` with the time it happened.
    ///
    /// Sensor bytes reach the link when the emulator's telegram completes
    /// or at a deadline, not at `until`, so the outcome does not depend on
    /// how the caller slices time.
    pub fn advance_to(
        &mut self,
        link: &mut Link,
        emulator: &mut Emulator,
        until: Instant,
        mut on_output: impl FnMut(Instant, HostOutput<'_>),
    ) {
        loop {
            self.flush(link, emulator, &mut on_output);
            if !self.settled
                && let Some(bytes) = emulator.poll_transmit(self.now)
            {
                on_output(self.now, HostOutput::Received(&bytes));
                link.handle_input(&bytes, self.now);
                continue;
            }
            match self.next_deadline(link, emulator) {
                Some(next) if next <= until => self.run_due(next, link, emulator),
                _ => break,
            }
        }
        if until > self.now {
            self.now = until;
            self.settled = true;
        }
    }

    /// The earliest deadline of either peer or host frame arrival.
    fn next_deadline(&self, link: &Link, emulator: &mut Emulator) -> Option<Instant> {
        let arrival = self.in_flight.front().map(|(t, _)| *t);
        [link.poll_timeout(), emulator.poll_timeout(), arrival]
            .into_iter()
            .flatten()
            .min()
    }

    /// Moves the clock to `next` (never backwards) and runs what is due:
    /// host frames reach the sensor at their arrival times, then both
    /// peers' timers fire.
    fn run_due(&mut self, next: Instant, link: &mut Link, emulator: &mut Emulator) {
        self.now = self.now.max(next);
        self.settled = false;
        while self.in_flight.front().is_some_and(|(t, _)| *t <= self.now) {
            if let Some((arrival, bytes)) = self.in_flight.pop_front() {
                emulator.handle_input(&bytes, arrival);
            }
        }
        emulator.handle_timeout(self.now);
        link.handle_timeout(self.now);
    }
}

/// A [`Link`] talking to an [`Emulator`] over a [`Wire`]: the whole driver
/// and sensor on a virtual clock. See the module documentation.
#[derive(Debug)]
pub struct VirtualLine {
    link: Link,
    emulator: Emulator,
    wire: Wire,
}

impl VirtualLine {
    /// A new link configured by `link`, starting at `now` against
    /// `emulator` (a fresh sensor, or one a previous link left behind).
    pub fn new(link: LinkConfig, mut emulator: Emulator, now: Instant) -> Self {
        let wire = Wire::connect(&mut emulator, now);
        Self {
            link: Link::new(link, now),
            emulator,
            wire,
        }
    }

    /// The virtual clock.
    pub fn now(&self) -> Instant {
        self.wire.now()
    }

    /// Moves everything that is due now, then advances the clock once.
    /// Link events go to `on_event` with their time. Returns false when
    /// neither side has anything left to do.
    pub fn step(&mut self, mut on_event: impl FnMut(Instant, Event)) -> bool {
        self.wire
            .step(&mut self.link, &mut self.emulator, |at, output| {
                if let HostOutput::Event(event) = output {
                    on_event(at, event);
                }
            })
    }

    /// Runs everything due up to `until` and stops the clock there (never
    /// beyond it), handing each link event with its time to `on_event`.
    /// A simulation loop calls this once per control tick; the outcome does
    /// not depend on the tick length.
    pub fn advance_to(&mut self, until: Instant, mut on_event: impl FnMut(Instant, Event)) {
        self.wire
            .advance_to(&mut self.link, &mut self.emulator, until, |at, output| {
                if let HostOutput::Event(event) = output {
                    on_event(at, event);
                }
            });
    }

    /// The driver side.
    pub fn link(&self) -> &Link {
        &self.link
    }

    /// The driver side, to close it, say. Outputs it queues are handled at
    /// the next step.
    pub fn link_mut(&mut self) -> &mut Link {
        &mut self.link
    }

    /// The emulated sensor.
    pub fn emulator(&self) -> &Emulator {
        &self.emulator
    }

    /// The emulated sensor, to inject faults, silence it or power-cycle it
    /// (pass [`Self::now`] as the time).
    pub fn emulator_mut(&mut self) -> &mut Emulator {
        // A change may release sensor bytes at the current time.
        self.wire.settled = false;
        &mut self.emulator
    }

    /// The host tty's line speed.
    pub fn host_baud(&self) -> Baud {
        self.wire.host_baud()
    }

    /// Whether the host ignores `SetBaud`.
    pub fn host_stuck_at_9600(&self) -> bool {
        self.wire.host_stuck_at_9600()
    }

    /// Emulates a shell that forgets to change its tty's speed (see
    /// [`Wire::set_host_stuck_at_9600`]).
    pub fn set_host_stuck_at_9600(&mut self, stuck: bool) {
        self.wire.set_host_stuck_at_9600(stuck);
    }

    /// The two peers, to run the sensor on with a new link (a driver
    /// restart). Host frames still on the wire are lost.
    pub fn into_parts(self) -> (Link, Emulator) {
        (self.link, self.emulator)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use std::time::Duration;

    use super::*;
    use crate::Variant;
    use crate::emulator::{EmulatorConfig, FaultConfig};
    use crate::link::{LinkError, TimedScan};

    fn line(link: LinkConfig, emulator: EmulatorConfig, t0: Instant) -> VirtualLine {
        VirtualLine::new(link, Emulator::new(emulator, t0), t0)
    }

    /// Advances in `tick` steps until `done` holds or `limit` has passed;
    /// returns every event with its time.
    fn run(
        line: &mut VirtualLine,
        tick: Duration,
        limit: Duration,
        mut done: impl FnMut(&VirtualLine, &[(Instant, Event)]) -> bool,
    ) -> Vec<(Instant, Event)> {
        let end = line.now() + limit;
        let mut log = Vec::new();
        while line.now() < end && !done(line, &log) {
            let until = (line.now() + tick).min(end);
            line.advance_to(until, |at, event| log.push((at, event)));
        }
        log
    }

    fn scans(log: &[(Instant, Event)]) -> Vec<&TimedScan> {
        log.iter()
            .filter_map(|(_, e)| match e {
                Event::Scan(scan) => Some(scan),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn streams_at_the_rate_the_variant_and_line_speed_allow() {
        // Mirror at 75 Hz (13.32 ms per turn); a complete scan takes 1, 2 or
        // 4 turns; while the line carries a telegram longer than a scan
        // period, ceil(wire time / period) scans are lost after it (TL Table
        // 10-17: 732 bytes at 38400 Bd take 191 ms, so one 180°/0.5° scan in
        // 9 goes out).
        let table = [
            (Variant::Fov180Res100, Baud::B500000, 75.075),
            (Variant::Fov180Res50, Baud::B500000, 37.538),
            (Variant::Fov100Res25, Baud::B500000, 18.769),
            (Variant::Fov180Res50, Baud::B38400, 4.171),
        ];
        for (variant, baud, expected_hz) in table {
            let config = LinkConfig {
                variant,
                target_baud: baud,
                ..LinkConfig::default()
            };
            let t0 = Instant::now();
            let mut line = line(config, EmulatorConfig::default(), t0);
            // A 50 Hz control loop.
            let tick = Duration::from_millis(20);
            let setup = run(&mut line, tick, Duration::from_secs(30), |l, _| {
                l.link().is_streaming()
            });
            assert!(
                line.link().is_streaming(),
                "{variant:?} {baud:?}: {setup:?}"
            );
            assert!(
                setup
                    .iter()
                    .any(|(_, e)| matches!(e, Event::Connected { baud: b, .. } if *b == baud)),
                "{variant:?} {baud:?}"
            );
            let log = run(&mut line, tick, Duration::from_secs(10), |_, _| false);
            let scans = scans(&log);
            assert!(scans.len() > 40, "{variant:?} {baud:?}: {}", scans.len());
            assert!(scans.iter().all(|s| s.variant == variant));
            let span = scans[scans.len() - 1].timestamp - scans[0].timestamp;
            let rate_hz = (scans.len() - 1) as f64 / span.as_secs_f64();
            assert!(
                (rate_hz - expected_hz).abs() < 0.005,
                "{variant:?} {baud:?}: {rate_hz} Hz"
            );
            // Evenly spaced: no scan lost or late.
            let period = Duration::from_secs_f64(1.0 / expected_hz);
            for pair in scans.windows(2) {
                let gap = pair[1].timestamp - pair[0].timestamp;
                let error = gap.abs_diff(period);
                assert!(
                    error < Duration::from_micros(100),
                    "{variant:?} {baud:?}: gap {gap:?}"
                );
            }
            assert_eq!(line.link().stats().lost_telegrams, 0);
        }
    }

    #[test]
    fn advance_to_never_moves_past_until() {
        let t0 = Instant::now();
        let mut line = line(LinkConfig::default(), EmulatorConfig::default(), t0);
        let ticks_us = [1, 999, 13_320, 7, 250_000, 40_000, 3, 1_000_000];
        let mut last_event_at = t0;
        let mut events = 0;
        for i in 0..600 {
            let before = line.now();
            let until = before + Duration::from_micros(ticks_us[i % ticks_us.len()]);
            line.advance_to(until, |at, _| {
                assert!(at >= before && at <= until, "event at {:?}", at - t0);
                assert!(at >= last_event_at, "events out of order");
                last_event_at = at;
                events += 1;
            });
            assert_eq!(line.now(), until);
        }
        assert!(line.link().is_streaming());
        assert!(events > 100, "{events}");
        // A time in the past leaves the clock alone.
        let now = line.now();
        line.advance_to(now - Duration::from_millis(5), |at, _| {
            assert!(at <= now);
        });
        assert_eq!(line.now(), now);
    }

    #[test]
    fn the_outcome_does_not_depend_on_the_tick() {
        let emulator = EmulatorConfig {
            faults: FaultConfig {
                nak_every_nth_request: Some(3),
                bit_flip_per_byte: 0.0002,
                ..FaultConfig::default()
            },
            seed: 11,
            ..EmulatorConfig::default()
        };
        let t0 = Instant::now();
        let limit = Duration::from_secs(15);
        let mut logs = Vec::new();
        for tick_us in [500, 13_320, 20_000, 333_333, 15_000_000] {
            let mut line = line(LinkConfig::default(), emulator.clone(), t0);
            let log = run(&mut line, Duration::from_micros(tick_us), limit, |_, _| {
                false
            });
            assert_eq!(line.now(), t0 + limit);
            logs.push((tick_us, log));
        }
        let (_, reference) = &logs[0];
        assert!(scans(reference).len() > 200, "{}", scans(reference).len());
        for (tick_us, log) in &logs[1..] {
            assert_eq!(log.len(), reference.len(), "tick {tick_us} µs");
            assert!(log == reference, "tick {tick_us} µs");
        }
    }

    #[test]
    fn a_long_run_keeps_every_queue_small() {
        // One virtual minute at 37.5 Hz, with a power cycle and a silence
        // that make the link set the sensor up twice more.
        let emulator = EmulatorConfig {
            scan_log_capacity: 8,
            ..EmulatorConfig::default()
        };
        let t0 = Instant::now();
        let mut line = line(LinkConfig::default(), emulator, t0);
        let tick = Duration::from_millis(10);
        let mut scans = 0usize;
        let mut transmits_max = 0;
        let mut capacity_max = 0;
        while line.now() < t0 + Duration::from_secs(60) {
            let now = line.now();
            if now == t0 + Duration::from_secs(20) {
                line.emulator_mut().power_cycle(now);
            }
            if now == t0 + Duration::from_secs(40) {
                line.emulator_mut().silence(now, Duration::from_secs(1));
            }
            line.advance_to(now + tick, |_, event| {
                if matches!(event, Event::Scan(_)) {
                    scans += 1;
                }
            });
            transmits_max = transmits_max.max(line.wire.in_flight.len());
            capacity_max = capacity_max.max(line.wire.in_flight.capacity());
            assert!(
                line.link_mut().poll_output().is_none(),
                "output left behind"
            );
        }
        assert!(line.link().is_streaming());
        let stats = line.link().stats();
        assert!(stats.reinits >= 2, "{stats:?}");
        // Three set-ups of a few seconds each; the rest streamed.
        assert!(scans > 1800, "{scans} scans");
        assert!(transmits_max <= 2, "{transmits_max} frames on the wire");
        assert!(capacity_max <= 8, "queue capacity {capacity_max}");
        assert_eq!(line.emulator().sent_scans().count(), 8);
    }

    #[test]
    fn a_restarted_link_finds_the_sensor_as_the_first_one_left_it() {
        let t0 = Instant::now();
        let mut first = line(LinkConfig::default(), EmulatorConfig::default(), t0);
        run(
            &mut first,
            Duration::from_millis(20),
            Duration::from_secs(30),
            |l, _| l.link().is_streaming(),
        );
        assert!(first.link().is_streaming());
        // The default link turns on the real-time indices: one EEPROM write.
        assert_eq!(first.emulator().eeprom_writes(), 1);
        let now = first.now();
        first.link_mut().close(now);
        let log = run(
            &mut first,
            Duration::from_millis(20),
            Duration::from_secs(10),
            |l, _| l.link().is_closed(),
        );
        assert!(log.iter().any(|(_, e)| *e == Event::Closed));
        assert_eq!(first.host_baud(), Baud::B9600);
        let now = first.now() + Duration::from_millis(100);
        let (_, emulator) = first.into_parts();
        assert_eq!(emulator.baud(), Baud::B9600);

        let mut second = VirtualLine::new(LinkConfig::default(), emulator, now);
        let log = run(
            &mut second,
            Duration::from_millis(20),
            Duration::from_secs(30),
            |_, log| scans(log).len() >= 3,
        );
        assert_eq!(scans(&log).len(), 3);
        assert_eq!(second.host_baud(), Baud::B500000);
        assert_eq!(second.emulator().eeprom_writes(), 1);
        assert_eq!(second.link().stats().config_writes, 0);
    }

    #[test]
    fn a_host_stuck_at_9600_never_streams() {
        let t0 = Instant::now();
        let mut line = line(LinkConfig::default(), EmulatorConfig::default(), t0);
        line.set_host_stuck_at_9600(true);
        assert!(line.host_stuck_at_9600());
        let log = run(
            &mut line,
            Duration::from_millis(20),
            Duration::from_secs(10),
            |_, _| false,
        );
        assert!(scans(&log).is_empty());
        assert_eq!(line.host_baud(), Baud::B9600);
        // The sensor switched to 500 kBd and heard garbage from then on; the
        // link found nobody at any speed.
        assert_eq!(line.emulator().baud(), Baud::B500000);
        assert!(line.emulator().stats().garbled_input_bytes > 0);
        assert!(
            log.iter()
                .any(|(_, e)| matches!(e, Event::Error(LinkError::NoAnswer { .. })))
        );
    }

    #[test]
    fn step_runs_until_nothing_is_left() {
        // A closed link and an idle sensor have no deadlines.
        let t0 = Instant::now();
        let emulator = EmulatorConfig::left_running(Baud::B9600, false);
        let mut line = line(LinkConfig::default(), emulator, t0);
        let now = line.now();
        line.link_mut().close(now);
        let mut events = Vec::new();
        let mut steps = 0;
        while line.step(|_, event| events.push(event)) {
            steps += 1;
            assert!(steps < 1000, "never idle");
        }
        assert!(line.link().is_closed());
        assert!(events.contains(&Event::Closed));
    }
}
