//! A software LMS200 that speaks the serial protocol byte for byte (sans-IO).
//!
//! The emulator never reads a clock or touches a port: bytes from the host
//! come in through [`Emulator::handle_input`], time passes through
//! [`Emulator::handle_timeout`], and bytes for the host leave through
//! [`Emulator::poll_transmit`] only once their wire time has come (10 bits per
//! byte at the sensor's line speed). [`Emulator::poll_timeout`] says when the
//! next thing happens. A pty shell (`clsmap emulate`) and the back-to-back
//! tests drive the same core.
//!
//! What it emulates (protocol notes §1–2): power-up at 9600 Bd in request
//! mode with a `90` telegram; `06` + reply for every valid request, `15` for
//! a bad checksum, `92` for a command it does not accept, silence for another
//! address; the baud switch answered at the old rate; installation mode for
//! `77` and `66`; a 32- or 34-byte configuration block whose writes are
//! counted as EEPROM writes; `B0` streaming at the mirror rate, skipping the
//! scans that do not fit the line (TL Table 10-17); any host request cuts
//! the telegram on the line. The sub-range, mean-value and reflectivity streams (`20 26`–`29`,
//! `20 2B`) are not emulated and get `92`.

mod commands;
mod config;
mod faults;
mod prng;
mod range_source;
mod scans;
mod stream;
#[cfg(test)]
mod tests;
mod wire;

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use crate::{Baud, ConfigBlock, Reply, RequestDecoder, Variant};

pub use config::EmulatorConfig;
pub use faults::{FaultConfig, FaultCounts};
pub use prng::FaultRng;
pub use range_source::{RangeSource, RoomRangeSource};
pub use scans::SentScan;

use faults::{LineNoise, garble_wrong_baud};
use wire::{AfterSent, PacedTx, Segment, SegmentKind};

/// Mirror period: 75 Hz, 13.32 ms per turn (TL §3.4).
const MIRROR_TURN: Duration = Duration::from_micros(13_320);

/// The sensor's operating mode (`20 xx`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OperatingMode {
    /// `20 25`: values on request (power-on default).
    OnRequest,
    /// `20 24`: every complete scan streamed as `B0`.
    ContinuousAll,
    /// `20 2A`: every mirror turn streamed as a partial `B0`.
    ContinuousInterlaced,
    /// `20 10`: diagnostic mode.
    Diagnostic,
}

/// Counters of what the emulator did, for tests.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EmulatorStats {
    /// Valid requests received (right address and checksum).
    pub requests: u64,
    /// NAKs sent (bad checksum or forced by a fault).
    pub naks: u64,
    /// `92` replies sent.
    pub invalid_commands: u64,
    /// Scan telegrams queued for the line.
    pub scans_sent: u64,
    /// Complete scans measured while the line was busy, so not sent.
    pub scans_skipped: u64,
    /// Scan telegrams cut short by a host request.
    pub scans_cut: u64,
    /// Reply telegrams cut short by a host request.
    pub replies_cut: u64,
    /// Bytes received while host and sensor speeds differed.
    pub garbled_input_bytes: u64,
    /// Power-on telegrams sent.
    pub power_ons: u64,
}

/// Why the emulator does not listen right now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Power {
    /// Booting; ready (and sending `90`) at the given time.
    Booting { ready_at: Instant },
    /// Answering requests.
    Ready,
}

/// An emulated LMS200. See the module documentation.
pub struct Emulator {
    config: EmulatorConfig,
    rng: FaultRng,
    faults: FaultConfig,
    noise_to_host: LineNoise,
    noise_to_sensor: LineNoise,
    fault_counts: FaultCounts,
    ranges: Box<dyn RangeSource>,
    /// Mirror phase reference: the mirror turns since this instant.
    epoch: Instant,
    power: Power,
    baud: Baud,
    /// What the host's UART is set to.
    host_baud: Baud,
    /// Speed after power-on (`66 00` → 9600, `66 01` → the speed then).
    power_on_baud: Baud,
    mode: OperatingMode,
    installation: bool,
    variant: Variant,
    block: ConfigBlock,
    eeprom_writes: u64,
    /// Next scan (or partial scan) completion while streaming.
    next_tick: Option<Instant>,
    /// Scans completing before this are lost after the last one sent.
    stream_resumes_at: Option<Instant>,
    /// Running number of streamed telegrams (the telegram index mod 256).
    telegram_sequence: u64,
    rx: RequestDecoder,
    tx: PacedTx,
    /// Bytes released to the host, waiting for `poll_transmit`.
    released: Vec<u8>,
    silent_until: Option<Instant>,
    /// When the last host byte arrived (for the 6 ms inter-byte rule).
    last_rx_at: Option<Instant>,
    sent_scans: VecDeque<SentScan>,
    stats: EmulatorStats,
}

impl std::fmt::Debug for Emulator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Emulator")
            .field("power", &self.power)
            .field("baud", &self.baud)
            .field("host_baud", &self.host_baud)
            .field("mode", &self.mode)
            .field("installation", &self.installation)
            .field("variant", &self.variant)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl Emulator {
    /// A sensor switched on at `now`, measuring the default room.
    pub fn new(config: EmulatorConfig, now: Instant) -> Self {
        Self::with_range_source(config, Box::new(RoomRangeSource::default()), now)
    }

    /// A sensor switched on at `now`, measuring what `ranges` says.
    pub fn with_range_source(
        config: EmulatorConfig,
        ranges: Box<dyn RangeSource>,
        now: Instant,
    ) -> Self {
        let power = match config.power_on_delay {
            Some(delay) => Power::Booting {
                ready_at: now + delay,
            },
            None => Power::Ready,
        };
        let mut emulator = Self {
            rng: FaultRng::new(config.seed),
            faults: config.faults.clone(),
            noise_to_host: LineNoise::default(),
            noise_to_sensor: LineNoise::default(),
            fault_counts: FaultCounts::default(),
            ranges,
            epoch: now,
            power,
            baud: config.start_baud,
            host_baud: Baud::B9600,
            power_on_baud: config.power_on_baud,
            mode: OperatingMode::OnRequest,
            installation: false,
            variant: config.variant,
            block: config.config,
            eeprom_writes: 0,
            next_tick: None,
            stream_resumes_at: None,
            telegram_sequence: 0,
            rx: RequestDecoder::new(),
            tx: PacedTx::new(),
            released: Vec::new(),
            silent_until: None,
            last_rx_at: None,
            sent_scans: VecDeque::new(),
            stats: EmulatorStats::default(),
            config,
        };
        if emulator.config.start_streaming {
            emulator.set_mode(OperatingMode::ContinuousAll, now);
        }
        emulator
    }

    /// Bytes from the host arrived (their last byte at `now`).
    pub fn handle_input(&mut self, bytes: &[u8], now: Instant) {
        self.advance(now);
        if self.power != Power::Ready || self.is_silent(now) {
            return;
        }
        let mut line = Vec::with_capacity(bytes.len());
        if self.host_baud != self.baud {
            self.stats.garbled_input_bytes += bytes.len() as u64;
            garble_wrong_baud(bytes, &mut self.rng, &mut line);
        } else {
            line.extend_from_slice(bytes);
        }
        let mut received = Vec::with_capacity(line.len());
        self.noise_to_sensor.apply(
            &line,
            &self.faults,
            &mut self.rng,
            &mut self.fault_counts,
            &mut received,
        );
        self.receive(&received, now);
    }

    /// Time passed; runs everything due by `now`.
    pub fn handle_timeout(&mut self, now: Instant) {
        self.advance(now);
    }

    /// Bytes that have reached the host by `now`, if any.
    pub fn poll_transmit(&mut self, now: Instant) -> Option<Vec<u8>> {
        self.advance(now);
        if self.released.is_empty() {
            None
        } else {
            Some(std::mem::take(&mut self.released))
        }
    }

    /// The next time something happens (a byte is due, a scan completes, the
    /// sensor finishes booting, a silence ends).
    pub fn poll_timeout(&mut self) -> Option<Instant> {
        let bps = self.baud.bits_per_second();
        let booting = match self.power {
            Power::Booting { ready_at } => Some(ready_at),
            Power::Ready => None,
        };
        [
            self.tx.next_completion(bps),
            self.next_tick,
            booting,
            self.silent_until,
        ]
        .into_iter()
        .flatten()
        .min()
    }

    /// The speed the host's UART really runs at (the pty shell reads it from
    /// the termios of its end). While it differs from the sensor's speed,
    /// bytes are garbled both ways, as between two UARTs at different rates.
    pub fn set_host_baud(&mut self, baud: Baud) {
        self.host_baud = baud;
    }

    /// Replaces the active faults (takes effect for the next byte).
    pub fn set_faults(&mut self, faults: FaultConfig) {
        self.faults = faults;
    }

    /// The sensor neither listens nor sends for `duration` from `now`
    /// (streaming resumes afterwards).
    pub fn silence(&mut self, now: Instant, duration: Duration) {
        self.advance(now);
        self.tx.clear(now);
        self.silent_until = Some(now + duration);
    }

    /// Power loss and power-up at `now`: back to the power-on speed (9600
    /// unless `66 01` stored another) in request mode; `90` follows after
    /// the configured power-on delay (1 s if none is configured).
    pub fn power_cycle(&mut self, now: Instant) {
        self.advance(now);
        let delay = self.config.power_on_delay.unwrap_or(Duration::from_secs(1));
        self.reboot(now, delay);
    }

    /// The sensor's current line speed.
    pub fn baud(&self) -> Baud {
        self.baud
    }

    /// The current operating mode.
    pub fn operating_mode(&self) -> OperatingMode {
        self.mode
    }

    /// Whether installation mode (`20 00` + password) is active.
    pub fn installation_mode(&self) -> bool {
        self.installation
    }

    /// Whether the sensor is booting (ignoring input until its `90`).
    pub fn is_booting(&self) -> bool {
        matches!(self.power, Power::Booting { .. })
    }

    /// The active variant.
    pub fn variant(&self) -> Variant {
        self.variant
    }

    /// The configuration block (as stored in EEPROM).
    pub fn config_block(&self) -> ConfigBlock {
        self.block
    }

    /// Accepted `77` writes since start: each one wears the EEPROM.
    pub fn eeprom_writes(&self) -> u64 {
        self.eeprom_writes
    }

    /// The most recent scans queued for the line, oldest first (bounded by
    /// [`EmulatorConfig::scan_log_capacity`]).
    pub fn sent_scans(&self) -> impl Iterator<Item = &SentScan> {
        self.sent_scans.iter()
    }

    /// What the emulator did so far.
    pub fn stats(&self) -> EmulatorStats {
        self.stats
    }

    /// Faults injected so far.
    pub fn fault_counts(&self) -> FaultCounts {
        self.fault_counts
    }

    fn is_silent(&mut self, now: Instant) -> bool {
        match self.silent_until {
            Some(until) if now < until => true,
            Some(_) => {
                self.silent_until = None;
                false
            }
            None => false,
        }
    }

    fn reboot(&mut self, now: Instant, delay: Duration) {
        self.tx.clear(now);
        self.rx = RequestDecoder::new();
        self.power = Power::Booting {
            ready_at: now + delay,
        };
        self.baud = self.power_on_baud;
        self.mode = OperatingMode::OnRequest;
        self.installation = false;
        self.next_tick = None;
        self.stream_resumes_at = None;
        self.epoch = now;
    }

    /// Runs the sensor up to `now`: bytes leave, scans complete, booting ends.
    fn advance(&mut self, now: Instant) {
        loop {
            let bps = self.baud.bits_per_second();
            let booting_done = match self.power {
                Power::Booting { ready_at } if ready_at <= now => Some(ready_at),
                _ => None,
            };
            let tx_done = self.tx.next_completion(bps).filter(|t| *t <= now);
            let tick = self.next_tick.filter(|t| *t <= now);
            let silence_end = self.silent_until.filter(|t| *t <= now);
            let Some(at) = [booting_done, tx_done, tick, silence_end]
                .into_iter()
                .flatten()
                .min()
            else {
                break;
            };
            if tx_done == Some(at) {
                self.release_until(at);
            } else if booting_done == Some(at) {
                self.finish_boot(at);
            } else if silence_end == Some(at) {
                self.silent_until = None;
            } else {
                self.release_until(at);
                self.on_tick(at);
            }
        }
        self.release_until(now);
    }

    /// Moves every byte due by `at` to the host side, applying what follows
    /// a completed segment (a baud switch) before pacing the next one.
    fn release_until(&mut self, at: Instant) {
        let mut wire_bytes = Vec::new();
        loop {
            let bps = self.baud.bits_per_second();
            let mut chunk = Vec::new();
            let finished = self.tx.release_head(at, bps, &mut chunk);
            self.deliver(&chunk, &mut wire_bytes);
            match finished {
                Some(done) => match done.after {
                    AfterSent::SwitchBaud(bps) => {
                        if let Some(baud) = Baud::from_bits_per_second(bps) {
                            self.baud = baud;
                        }
                    }
                    AfterSent::Reboot => {
                        let ended = self.tx.line_free_at().unwrap_or(at);
                        self.reboot(ended, self.config.reset_delay);
                    }
                    AfterSent::Nothing => {}
                },
                None => break,
            }
        }
        self.released.extend_from_slice(&wire_bytes);
    }

    /// Bytes leaving the sensor's UART as the host receives them.
    fn deliver(&mut self, bytes: &[u8], out: &mut Vec<u8>) {
        if bytes.is_empty() {
            return;
        }
        let mut noisy = Vec::with_capacity(bytes.len());
        self.noise_to_host.apply(
            bytes,
            &self.faults,
            &mut self.rng,
            &mut self.fault_counts,
            &mut noisy,
        );
        if self.host_baud != self.baud {
            garble_wrong_baud(&noisy, &mut self.rng, out);
        } else {
            out.extend_from_slice(&noisy);
        }
    }

    fn finish_boot(&mut self, at: Instant) {
        self.power = Power::Ready;
        self.stats.power_ons += 1;
        let text = self.config.type_string.as_bytes().to_vec();
        self.queue_reply(&Reply::PowerOn(text), 0x80, at, AfterSent::Nothing);
    }

    fn queue_reply(&mut self, reply: &Reply, address: u8, ready_at: Instant, after: AfterSent) {
        self.queue_frame(reply, address, ready_at, SegmentKind::Reply, after);
    }

    fn queue_frame(
        &mut self,
        reply: &Reply,
        address: u8,
        ready_at: Instant,
        kind: SegmentKind,
        after: AfterSent,
    ) {
        // Every reply the emulator builds fits a frame; an encoding error
        // would be a bug here, and the sensor then stays silent.
        if let Ok(bytes) = reply.encode(address, self.config.status) {
            self.tx.push(Segment {
                bytes,
                kind,
                after,
                ready_at,
            });
        }
    }

    fn queue_control_byte(&mut self, byte: u8, ready_at: Instant) {
        self.tx.push(Segment {
            bytes: vec![byte],
            kind: SegmentKind::Reply,
            after: AfterSent::Nothing,
            ready_at,
        });
    }
}
