//! Wires a `Link` to an `Emulator` on a virtual clock.
//!
//! Host bytes take their wire time at the host's line speed to reach the
//! sensor; the emulator paces its own output. `SetBaud` from the link sets
//! the harness's host speed and tells the emulator (`set_host_baud`), which
//! garbles bytes while the two speeds differ. The clock jumps to the earliest
//! of both sides' deadlines and the next host byte arrival.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use lms200::Baud;
use lms200::emulator::{Emulator, EmulatorConfig, SentScan};
use lms200::link::{Event, Link, LinkConfig, LinkError, Output, TimedScan};

/// Both peers and the line between them.
pub struct Harness {
    pub now: Instant,
    pub link: Link,
    pub emulator: Emulator,
    /// The host tty's speed.
    pub host_baud: Baud,
    /// Host bytes on their way to the sensor: (arrival time, bytes).
    in_flight: VecDeque<(Instant, Vec<u8>)>,
    /// When the host's transmitter is free again.
    host_tx_free: Instant,
    /// Every event the link emitted, with the time.
    pub log: Vec<(Instant, Event)>,
    /// Every frame the link sent, with the time it was handed to the port.
    pub transmits: Vec<(Instant, Vec<u8>)>,
    /// Ignore `SetBaud`: the host tty stays at 9600 (a shell that forgot to
    /// change the line speed).
    pub host_stuck_at_9600: bool,
}

/// Time `bytes` bytes take at `baud`, 10 bits each.
fn wire_time(bytes: usize, baud: Baud) -> Duration {
    Duration::from_nanos((bytes as u64) * 10 * 1_000_000_000 / u64::from(baud.bits_per_second()))
}

impl Harness {
    pub fn new(link: LinkConfig, emulator: EmulatorConfig) -> Self {
        let t0 = Instant::now();
        Self::with_emulator(link, Emulator::new(emulator, t0), t0)
    }

    /// A new link (a second run of the driver) against an existing sensor.
    pub fn with_emulator(link: LinkConfig, mut emulator: Emulator, now: Instant) -> Self {
        emulator.set_host_baud(Baud::B9600);
        Self {
            now,
            link: Link::new(link, now),
            emulator,
            host_baud: Baud::B9600,
            in_flight: VecDeque::new(),
            host_tx_free: now,
            log: Vec::new(),
            transmits: Vec::new(),
            host_stuck_at_9600: false,
        }
    }

    /// Moves everything that is due now, then advances the clock once.
    /// Returns false when neither side has anything left to do.
    pub fn step(&mut self) -> bool {
        self.drain_link_outputs();
        if let Some(bytes) = self.emulator.poll_transmit(self.now) {
            self.link.handle_input(&bytes, self.now);
            return true;
        }
        let arrival = self.in_flight.front().map(|(t, _)| *t);
        let next = [
            self.link.poll_timeout(),
            self.emulator.poll_timeout(),
            arrival,
        ]
        .into_iter()
        .flatten()
        .min();
        let Some(next) = next else {
            return false;
        };
        self.now = self.now.max(next);
        while let Some((t, _)) = self.in_flight.front()
            && *t <= self.now
        {
            let (t, bytes) = self.in_flight.pop_front().unwrap();
            self.emulator.handle_input(&bytes, t);
        }
        self.emulator.handle_timeout(self.now);
        self.link.handle_timeout(self.now);
        true
    }

    fn drain_link_outputs(&mut self) {
        while let Some(output) = self.link.poll_output() {
            match output {
                Output::Transmit(bytes) => {
                    let start = self.now.max(self.host_tx_free);
                    let arrival = start + wire_time(bytes.len(), self.host_baud);
                    self.host_tx_free = arrival;
                    self.transmits.push((self.now, bytes.clone()));
                    self.in_flight.push_back((arrival, bytes));
                }
                Output::SetBaud(baud) => {
                    if !self.host_stuck_at_9600 {
                        self.host_baud = baud;
                        self.emulator.set_host_baud(baud);
                    }
                }
                Output::Event(event) => self.log.push((self.now, event)),
            }
        }
    }

    /// Runs until `done` holds or `limit` of virtual time has passed.
    pub fn run_until(&mut self, limit: Duration, mut done: impl FnMut(&Harness) -> bool) {
        let deadline = self.now + limit;
        while self.now < deadline && !done(self) {
            if !self.step() {
                break;
            }
        }
        self.drain_link_outputs();
    }

    /// Runs until `n` scans arrived; fails the test if they do not.
    pub fn run_until_scans(&mut self, n: usize, limit: Duration) {
        self.run_until(limit, |h| h.scans().count() >= n);
        let got = self.scans().count();
        assert!(
            got >= n,
            "only {got} of {n} scans; events: {:?}",
            self.brief_log()
        );
    }

    /// Closes the link and runs until it reports `Closed`.
    pub fn close_and_wait(&mut self) {
        let now = self.now;
        self.link.close(now);
        self.run_until(Duration::from_secs(10), |h| h.link.is_closed());
        // Let the last bytes reach the sensor.
        let settle = self.now + Duration::from_millis(50);
        self.run_until(Duration::from_millis(50), |h| h.now >= settle);
        assert!(self.link.is_closed(), "not closed: {:?}", self.brief_log());
    }

    pub fn events(&self) -> impl Iterator<Item = &Event> {
        self.log.iter().map(|(_, e)| e)
    }

    pub fn scans(&self) -> impl Iterator<Item = &TimedScan> {
        self.events().filter_map(|e| match e {
            Event::Scan(scan) => Some(scan),
            _ => None,
        })
    }

    /// The last `Connected` as (baud, variant, units).
    pub fn connected(&self) -> Option<(Baud, lms200::Variant, lms200::Units)> {
        self.events()
            .filter_map(|e| match e {
                Event::Connected {
                    baud,
                    variant,
                    units,
                    ..
                } => Some((*baud, *variant, *units)),
                _ => None,
            })
            .last()
    }

    /// Times between successive "no answer" errors.
    pub fn backoff_pauses(&self) -> Vec<Duration> {
        let times: Vec<Instant> = self
            .log
            .iter()
            .filter(|(_, e)| matches!(e, Event::Error(LinkError::NoAnswer { .. })))
            .map(|(t, _)| *t)
            .collect();
        times.windows(2).map(|w| w[1] - w[0]).collect()
    }

    /// Every scan the link delivered was sent by the emulator, unchanged and
    /// in order.
    pub fn assert_scans_match_emulator(&self) {
        let sent: Vec<&SentScan> = self.emulator.sent_scans().collect();
        let mut cursor = 0;
        for scan in self.scans() {
            let found = sent[cursor..]
                .iter()
                .position(|s| s.values == scan.scan.values && s.indices == scan.scan.indices);
            let Some(offset) = found else {
                panic!("the link delivered a scan the emulator never sent (after sent #{cursor})");
            };
            cursor += offset + 1;
        }
    }

    /// Events without scans, for failure messages.
    pub fn brief_log(&self) -> Vec<String> {
        self.log
            .iter()
            .filter(|(_, e)| !matches!(e, Event::Scan(_)))
            .map(|(_, e)| format!("{e:?}"))
            .take(40)
            .collect()
    }
}
