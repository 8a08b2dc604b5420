//! The driver-side link state machine (sans-IO, in the style of quinn-proto).
//!
//! [`Link`] takes an LMS200 from any state — any line speed, streaming or
//! not, freshly powered — to streaming the configured variant, then streams
//! and recovers. It never reads a clock, sleeps or touches a port:
//!
//! - inputs: [`Link::handle_input`] (bytes read from the line, with the time
//!   the last of them arrived) and [`Link::handle_timeout`];
//! - outputs, in order: [`Link::poll_output`] ([`Output::Transmit`],
//!   [`Output::SetBaud`], [`Output::Event`]) and [`Link::poll_timeout`], the
//!   earliest of a small table of named deadlines.
//!
//! ```text
//!  Probing(rate i) --20 25/31/3A answered--> Login --A0--> ReadConfig --F4-->
//!   [WriteConfig --F7-->] SetVariant --BB--> [SwitchBaud --A0, SetBaud,
//!   settle--> ConfirmBaud --B1-->] StartOutput --A0--> Streaming
//!  any failure: Error event, back-off (capped doubling), Probing again
//!  90 (power-on), scan watchdog: event, Probing again
//!  close(): StopOutput --A0--> [to 9600 --A0, SetBaud(9600)-->] Closed
//! ```
//!
//! Requests go out one at a time. Each waits for its `06` (ACK timer), then
//! for its reply (reply timer); a NAK or a timeout waits ≥ 30 ms (resend
//! timer) and resends, up to `max_tries` sends. `66 01` (permanent baud) is
//! never sent.

mod config;
mod event;
mod init;
mod stream;
#[cfg(test)]
mod tests;
mod timers;
pub mod timing;

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use crate::{Baud, ConfigBlock, Decoder, Request};

pub use config::{LinkConfig, MIRROR_TURN, scan_frame_len, scan_period, turns_per_scan};
pub use event::{Command, Event, LinkError, LinkStats, Output, ReinitReason, TimedScan};
pub use stream::GARBLED_STREAM_FACTOR;

use timers::{Timer, TimerTable};

/// Where the link is in its life.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    /// Auto-baud: probing `order[index]` at step `step` of the probe sequence.
    Probing { index: usize, step: ProbeStep },
    /// Installation mode login.
    Login,
    /// Reading the configuration block.
    ReadConfig,
    /// Writing the changed configuration block.
    WriteConfig,
    /// Setting the variant.
    SetVariant,
    /// Waiting for the `A0` of the line speed change.
    SwitchBaud,
    /// Host speed changed; waiting before talking at the new rate.
    BaudSettle,
    /// Confirming the new speed with a status request.
    ConfirmBaud,
    /// Starting continuous output.
    StartOutput,
    /// Streaming scans.
    Streaming,
    /// Waiting for the re-initialisation back-off to expire.
    BackOff,
    /// Shutdown: stopping output.
    CloseStop,
    /// Shutdown: returning the sensor to 9600 Bd.
    CloseBaud,
    /// Done; the link ignores everything.
    Closed,
}

/// The probe sequence at one line speed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ProbeStep {
    /// `20 25`: stop a stream left running (its `A0` is the first answer).
    Stop,
    /// `31`: status (second answer).
    Status,
    /// `3A`: type string (third answer; names the device and firmware).
    DeviceType,
}

/// The request in flight.
#[derive(Debug, Clone)]
struct Pending {
    command: Command,
    frame: Vec<u8>,
    /// Reply code a well-behaved sensor answers with.
    reply_code: u8,
    /// Sends so far.
    tries: u8,
    /// The `06` came.
    acked: bool,
    /// NAKs received for this request.
    naks: u8,
}

/// The driver-side LMS200 link. See the module documentation.
#[derive(Debug)]
pub struct Link {
    config: LinkConfig,
    phase: Phase,
    timers: TimerTable,
    decoder: Decoder,
    outputs: VecDeque<Output>,
    /// The host's line speed as last set.
    host_baud: Baud,
    pending: Option<Pending>,
    stats: LinkStats,
    /// Auto-baud order for the current round.
    probe_order: Vec<Baud>,
    /// Valid scans seen at the rate being probed (evidence of a stream).
    probe_scans: u8,
    /// The current rate is being probed a second time because of scans.
    probe_retried: bool,
    /// Speed the sensor was last confirmed at.
    sensor_baud: Option<Baud>,
    device_type: String,
    firmware: String,
    /// The configuration block the sensor runs.
    sensor_config: Option<ConfigBlock>,
    /// Consecutive failed initialisations (back-off exponent).
    failures: u32,
    /// Real-time indices of the last scan, for gap counting.
    last_indices: Option<crate::RealTimeIndices>,
    /// When the last bytes arrived (to tell a silent line from a garbled one).
    last_input_at: Option<Instant>,
    /// When the last valid scan arrived (or streaming started).
    last_scan_at: Option<Instant>,
}

impl Link {
    /// A link that starts auto-baud at `now`. Poll outputs right away.
    pub fn new(config: LinkConfig, now: Instant) -> Self {
        let mut link = Self {
            probe_order: config.probe_order(),
            host_baud: config.probe_order().first().copied().unwrap_or(Baud::B9600),
            config,
            phase: Phase::BackOff,
            timers: TimerTable::default(),
            decoder: Decoder::new(),
            outputs: VecDeque::new(),
            pending: None,
            stats: LinkStats::default(),
            probe_scans: 0,
            probe_retried: false,
            sensor_baud: None,
            device_type: String::new(),
            firmware: String::new(),
            sensor_config: None,
            failures: 0,
            last_indices: None,
            last_input_at: None,
            last_scan_at: None,
        };
        link.event(Event::Reinitializing {
            reason: ReinitReason::Start,
        });
        link.start_probing(now);
        link
    }

    /// Bytes read from the line; `now` is when the last of them arrived.
    pub fn handle_input(&mut self, bytes: &[u8], now: Instant) {
        if self.phase == Phase::Closed {
            return;
        }
        self.feed_decoder(bytes, now);
    }

    /// Runs every deadline that has passed by `now`.
    pub fn handle_timeout(&mut self, now: Instant) {
        while let Some(timer) = self.timers.take_expired(now) {
            self.on_timer(timer, now);
        }
    }

    /// The next thing for the shell to do, in order.
    pub fn poll_output(&mut self) -> Option<Output> {
        self.outputs.pop_front()
    }

    /// The earliest armed deadline; call `handle_timeout` then.
    pub fn poll_timeout(&self) -> Option<Instant> {
        self.timers.next()
    }

    /// Counters since creation.
    pub fn stats(&self) -> LinkStats {
        self.stats
    }

    /// The host line speed the link last asked for.
    pub fn host_baud(&self) -> Baud {
        self.host_baud
    }

    /// Whether scans are flowing (set-up complete, not closing).
    pub fn is_streaming(&self) -> bool {
        self.phase == Phase::Streaming
    }

    /// Whether `close` has finished.
    pub fn is_closed(&self) -> bool {
        self.phase == Phase::Closed
    }

    /// Clean shutdown: stop output (`20 25`) and return the sensor and the
    /// host to 9600 Bd (`20 42`, then `SetBaud(9600)`), so the next start
    /// finds the power-on state. Emits [`Event::Closed`] when done, or after
    /// `close_timeout` at the latest. When the sensor's speed is not known
    /// (no sensor found yet) there is nothing to undo and it closes at once.
    pub fn close(&mut self, now: Instant) {
        if matches!(
            self.phase,
            Phase::Closed | Phase::CloseStop | Phase::CloseBaud
        ) {
            return;
        }
        self.timers.stop_all();
        self.pending = None;
        let known = !matches!(self.phase, Phase::Probing { .. } | Phase::BackOff);
        if !known || self.sensor_baud.is_none() {
            self.finish_close();
            return;
        }
        self.timers
            .set(Timer::Close, now + self.config.close_timeout);
        self.phase = Phase::CloseStop;
        self.send(Command::StopOutput, Request::ValuesOnRequest, now);
    }

    fn finish_close(&mut self) {
        self.timers.stop_all();
        self.pending = None;
        self.phase = Phase::Closed;
        self.event(Event::Closed);
    }

    fn event(&mut self, event: Event) {
        self.outputs.push_back(Output::Event(event));
    }

    /// Changes the host line speed and forgets any partial frame read at the
    /// old one.
    fn set_host_baud(&mut self, baud: Baud) {
        self.host_baud = baud;
        self.decoder = Decoder::new();
        self.outputs.push_back(Output::SetBaud(baud));
    }

    /// Sends `request` as the one request in flight.
    fn send(&mut self, command: Command, request: Request, now: Instant) {
        let reply_code = request.reply_code();
        match request.encode() {
            Ok(frame) => {
                self.pending = Some(Pending {
                    command,
                    frame,
                    reply_code,
                    tries: 0,
                    acked: false,
                    naks: 0,
                });
                self.transmit_pending(now);
            }
            // Only a configuration block read from the sensor can make a
            // request too long, and those are at most 34 bytes; treat it as
            // a failed step rather than panicking.
            Err(_) => self.step_failed(LinkError::NoReply { command, tries: 0 }, now),
        }
    }

    /// (Re)transmits the request in flight and arms its ACK timer.
    fn transmit_pending(&mut self, now: Instant) {
        let Some(pending) = self.pending.as_mut() else {
            return;
        };
        pending.tries += 1;
        pending.acked = false;
        let frame = pending.frame.clone();
        // The sensor cuts whatever it is sending when a request arrives
        // (protocol notes §2.5): a partial telegram buffered now will never
        // complete.
        self.decoder.abandon_incomplete();
        let on_wire = timing::wire_time(frame.len(), self.host_baud);
        self.outputs.push_back(Output::Transmit(frame));
        self.timers.stop(Timer::Reply);
        self.timers.stop(Timer::Resend);
        self.timers
            .set(Timer::Ack, now + on_wire + self.config.ack_timeout);
    }

    /// How long to wait for the reply to `command` after its ACK: the
    /// configured time for the kind of request plus the reply's wire time.
    fn reply_wait(&self, command: Command) -> Duration {
        let (base, reply_bytes) = match command {
            Command::StopOutput | Command::Login | Command::SetBaud(_) | Command::StartOutput => {
                (self.config.mode_change_timeout, 9)
            }
            Command::WriteConfig => (self.config.config_write_timeout, 45),
            Command::Status => (self.config.reply_timeout, 160),
            Command::DeviceType | Command::ReadConfig | Command::SetVariant(_) => {
                (self.config.reply_timeout, 64)
            }
        };
        // A scan cut by the request may still be draining: allow one more.
        let drain = scan_frame_len(self.config.variant, true);
        base + timing::wire_time(reply_bytes + drain, self.host_baud)
    }

    fn on_timer(&mut self, timer: Timer, now: Instant) {
        match timer {
            Timer::Ack | Timer::Reply => {
                // No answer: wait the resend pause, then resend or give up.
                self.timers
                    .set(Timer::Resend, now + self.config.resend_delay);
            }
            Timer::Resend => self.resend_or_fail(now),
            Timer::BaudSettle => self.on_baud_settled(now),
            Timer::ScanWatchdog => self.on_scan_watchdog(now),
            Timer::Reinit => self.start_probing(now),
            Timer::Close => self.finish_close(),
        }
    }

    fn resend_or_fail(&mut self, now: Instant) {
        let Some(pending) = self.pending.as_ref() else {
            return;
        };
        if pending.tries < self.config.max_tries.max(1) {
            self.stats.resends += 1;
            self.transmit_pending(now);
        } else {
            // Refused every time: say so, the line (or speed) is the suspect.
            let error = if pending.naks >= pending.tries {
                LinkError::Nacked {
                    command: pending.command,
                    naks: pending.naks,
                }
            } else {
                LinkError::NoReply {
                    command: pending.command,
                    tries: pending.tries,
                }
            };
            self.pending = None;
            self.step_failed(error, now);
        }
    }

    /// A step of set-up or shutdown failed for good.
    fn step_failed(&mut self, error: LinkError, now: Instant) {
        self.timers.stop(Timer::Ack);
        self.timers.stop(Timer::Reply);
        self.timers.stop(Timer::Resend);
        self.pending = None;
        match self.phase {
            Phase::Probing { index, .. } => {
                // Silence is expected at the wrong speeds; NAKs are not.
                if matches!(error, LinkError::Nacked { .. }) {
                    self.event(Event::Error(error));
                }
                self.probe_failed(index, now);
            }
            Phase::CloseStop => self.close_to_default_baud(now),
            Phase::CloseBaud => {
                self.set_host_baud(Baud::B9600);
                self.finish_close();
            }
            Phase::Closed => {}
            _ => {
                self.event(Event::Error(error.clone()));
                self.back_off(ReinitReason::InitFailed(error), now);
            }
        }
    }

    /// Starts over after the back-off delay (capped doubling).
    fn back_off(&mut self, reason: ReinitReason, now: Instant) {
        let exponent = self.failures.min(16);
        let delay = self
            .config
            .reinit_backoff_min
            .saturating_mul(1u32 << exponent)
            .min(self.config.reinit_backoff_max);
        self.failures = self.failures.saturating_add(1);
        self.stats.reinits += 1;
        self.event(Event::Reinitializing { reason });
        self.timers.stop_all();
        self.pending = None;
        self.phase = Phase::BackOff;
        self.timers.set(Timer::Reinit, now + delay);
    }

    /// Starts over at once (sensor restarted or silent): these are not
    /// failures of the link, so no back-off for the first attempt.
    fn reinit_now(&mut self, reason: ReinitReason, now: Instant) {
        self.stats.reinits += 1;
        self.event(Event::Reinitializing { reason });
        self.timers.stop_all();
        self.pending = None;
        self.start_probing(now);
    }
}
