//! Wires a `Link` to an `Emulator` on a virtual clock: the library's
//! [`Wire`] (see `lms200::virtual_line` for the line's semantics) plus a log
//! of everything the link emitted and sent, for the tests to inspect.
//!
//! The harness owns the two peers as fields (a test moves the emulator on to
//! a second link), so it drives a `Wire` rather than a `VirtualLine`.

use std::time::{Duration, Instant};

use lms200::emulator::{Emulator, EmulatorConfig, FaultCounts, SentScan};
use lms200::link::{Event, Link, LinkConfig, LinkError, TimedScan};
use lms200::virtual_line::{HostOutput, Wire};
use lms200::{Baud, Reply, Scan, crc16};

/// Both peers and the line between them.
pub struct Harness {
    /// The virtual clock (mirrors the wire after every step).
    pub now: Instant,
    pub link: Link,
    pub emulator: Emulator,
    /// The host tty's speed (mirrors the wire after every step).
    pub host_baud: Baud,
    wire: Wire,
    /// Every event the link emitted, with the time.
    pub log: Vec<(Instant, Event)>,
    /// Every frame the link sent, with the time it was handed to the port.
    pub transmits: Vec<(Instant, Vec<u8>)>,
    /// Every byte the host received, in order (line noise included).
    pub received: Vec<u8>,
    /// Ignore `SetBaud`: the host tty stays at 9600 (a shell that forgot to
    /// change the line speed). Applied at every step.
    pub host_stuck_at_9600: bool,
}

impl Harness {
    pub fn new(link: LinkConfig, emulator: EmulatorConfig) -> Self {
        let t0 = Instant::now();
        Self::with_emulator(link, Emulator::new(emulator, t0), t0)
    }

    /// A new link (a second run of the driver) against an existing sensor.
    pub fn with_emulator(link: LinkConfig, mut emulator: Emulator, now: Instant) -> Self {
        let wire = Wire::connect(&mut emulator, now);
        Self {
            now,
            link: Link::new(link, now),
            emulator,
            host_baud: wire.host_baud(),
            wire,
            log: Vec::new(),
            transmits: Vec::new(),
            received: Vec::new(),
            host_stuck_at_9600: false,
        }
    }

    /// Moves everything that is due now, then advances the clock once.
    /// Returns false when neither side has anything left to do.
    pub fn step(&mut self) -> bool {
        self.wire.set_host_stuck_at_9600(self.host_stuck_at_9600);
        let (log, transmits, received) = (&mut self.log, &mut self.transmits, &mut self.received);
        let more = self
            .wire
            .step(&mut self.link, &mut self.emulator, |at, output| {
                record(log, transmits, received, at, output)
            });
        self.sync();
        more
    }

    fn drain_link_outputs(&mut self) {
        self.wire.set_host_stuck_at_9600(self.host_stuck_at_9600);
        let (log, transmits, received) = (&mut self.log, &mut self.transmits, &mut self.received);
        self.wire
            .flush(&mut self.link, &mut self.emulator, |at, output| {
                record(log, transmits, received, at, output)
            });
        self.sync();
    }

    /// Copies the wire's clock and host speed into the public fields.
    fn sync(&mut self) {
        self.now = self.wire.now();
        self.host_baud = self.wire.host_baud();
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
    /// in order, but for a damaged telegram whose 16-bit checksum matched by
    /// chance (about one in 65,536 damaged telegrams; no receiver can tell
    /// it from a good one). Such a scan must have been framed on the line as
    /// the link read it, and there may be at most one per run: more means
    /// the link put one together rather than the line.
    pub fn assert_scans_match_emulator(&self) {
        let sent: Vec<&SentScan> = self.emulator.sent_scans().collect();
        let mut cursor = 0;
        let mut chance_matches = 0;
        for scan in self.scans() {
            let found = sent[cursor..]
                .iter()
                .position(|s| s.values == scan.scan.values && s.indices == scan.scan.indices);
            match found {
                Some(offset) => cursor += offset + 1,
                None => {
                    assert!(
                        self.emulator.fault_counts() != FaultCounts::default()
                            && framed_on_the_line(&self.received, &scan.scan),
                        "the link delivered a scan the emulator never sent and the line never \
                         carried (after sent #{cursor})"
                    );
                    chance_matches += 1;
                }
            }
        }
        assert!(
            chance_matches <= 1,
            "{chance_matches} scans the emulator never sent passed their checksum"
        );
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

/// Keeps what the tests inspect: events and transmitted frames.
fn record(
    log: &mut Vec<(Instant, Event)>,
    transmits: &mut Vec<(Instant, Vec<u8>)>,
    received: &mut Vec<u8>,
    at: Instant,
    output: HostOutput<'_>,
) {
    match output {
        HostOutput::Transmit(bytes) => transmits.push((at, bytes.to_vec())),
        HostOutput::SetBaud(_) => {}
        HostOutput::Event(event) => log.push((at, event)),
        HostOutput::Received(bytes) => received.extend_from_slice(bytes),
    }
}

/// Whether `scan` was a telegram on the host's side of the line whose
/// checksum matched: its code and data occur in `received` framed by an STX
/// three bytes before and, after the status byte, the checksum of it all.
fn framed_on_the_line(received: &[u8], scan: &Scan) -> bool {
    let Ok(data) = Reply::ScanData(scan.clone()).data() else {
        return false;
    };
    let body: Vec<u8> = [&[0xB0][..], &data].concat();
    let end = |at: usize| at + body.len() + 1;
    received
        .windows(body.len())
        .enumerate()
        .filter(|(at, w)| *w == body.as_slice() && *at >= 4)
        .any(|(at, _)| {
            let start = at - 4;
            let frame = received.get(start..end(at));
            let crc = received.get(end(at)..end(at) + 2);
            match (frame, crc) {
                (Some(frame), Some(crc)) => {
                    frame[0] == 0x02 && crc16(frame).to_le_bytes() == [crc[0], crc[1]]
                }
                _ => false,
            }
        })
}
