//! Auto-baud and the set-up sequence: from any sensor state to streaming.

use std::time::Instant;

use crate::{
    Baud, ConfigBlock, DecodeEvent, DropReason, ModeChangeResult, Reply, ReplyFrame, Request,
    ScanShape,
};

use super::event::{Command, Event, LinkError, ReinitReason};
use super::timers::Timer;
use super::{Link, Phase, ProbeStep, timing};

impl Link {
    /// Feeds bytes that arrived by `now` to the decoder and acts on every
    /// event, with the arrival time of each telegram's last byte (bytes
    /// after it in the same read are taken off at the line rate). Read
    /// times are the host's, so no inter-byte timing is judged here: a
    /// telegram cut short is detected by the decoder when the next one
    /// arrives, or abandoned when the link sends a request (see
    /// `transmit_pending`).
    pub(super) fn feed_decoder(&mut self, bytes: &[u8], now: Instant) {
        if bytes.is_empty() {
            return;
        }
        self.last_input_at = Some(now);
        let mut rest = bytes;
        loop {
            let taken = self.decoder.push(rest);
            rest = &rest[taken..];
            while let Some(event) = self.decoder.poll() {
                let stats = self.decoder.stats();
                let unconsumed = stats.bytes_in.saturating_sub(stats.bytes_accounted());
                let trailing = usize::try_from(unconsumed)
                    .unwrap_or(usize::MAX)
                    .saturating_add(rest.len());
                let at = now
                    .checked_sub(timing::wire_time(trailing, self.host_baud))
                    .unwrap_or(now);
                self.on_decode_event(event, at, now);
                if self.phase == Phase::Closed {
                    return;
                }
            }
            // Each round drains the decoder, so the next push takes bytes;
            // a push that takes none would only spin.
            if rest.is_empty() || taken == 0 {
                return;
            }
        }
    }

    fn on_decode_event(&mut self, event: DecodeEvent, at: Instant, now: Instant) {
        match event {
            DecodeEvent::Ack => self.on_ack(now),
            DecodeEvent::Nak => self.on_nak(now),
            DecodeEvent::Reply(frame) => self.on_reply(frame, at, now),
            DecodeEvent::Dropped {
                reason: DropReason::UnexpectedByte,
                ..
            } => {}
            DecodeEvent::Dropped { .. } => self.stats.dropped_frames += 1,
        }
    }

    fn on_ack(&mut self, now: Instant) {
        let Some(pending) = self.pending.as_mut() else {
            return;
        };
        if pending.acked || self.timers.get(Timer::Resend).is_some() {
            return;
        }
        pending.acked = true;
        let command = pending.command;
        self.timers.stop(Timer::Ack);
        self.timers
            .set(Timer::Reply, now + self.reply_wait(command));
    }

    fn on_nak(&mut self, now: Instant) {
        // A lone 15 with nothing asked is line noise, not a NAK.
        if let Some(pending) = self.pending.as_mut() {
            self.stats.naks += 1;
            pending.naks = pending.naks.saturating_add(1);
            // TL p24: wait at least 30 ms before resending.
            self.timers.stop(Timer::Ack);
            self.timers.stop(Timer::Reply);
            self.timers
                .set(Timer::Resend, now + self.config.resend_delay);
        }
    }

    fn on_reply(&mut self, frame: ReplyFrame, at: Instant, now: Instant) {
        let ReplyFrame { reply, .. } = frame;
        match reply {
            Reply::PowerOn(_) => {
                self.stats.sensor_restarts += 1;
                self.event(Event::SensorRestarted);
                if matches!(self.phase, Phase::CloseStop | Phase::CloseBaud) {
                    // It is back at 9600 in request mode: what close wanted.
                    self.set_host_baud(Baud::B9600);
                    self.finish_close();
                    return;
                }
                self.sensor_baud = Some(Baud::B9600);
                self.config.baud_hint = Some(Baud::B9600);
                self.reinit_now(ReinitReason::SensorRestarted, now);
            }
            Reply::ScanData(scan) => self.on_scan(scan, at, now),
            Reply::InvalidCommand => {
                let Some(pending) = self.pending.take() else {
                    return;
                };
                self.stats.rejected_commands += 1;
                self.event(Event::CommandRejected {
                    command: pending.command,
                });
                self.step_failed(
                    LinkError::Rejected {
                        command: pending.command,
                    },
                    now,
                );
            }
            reply => {
                let Some(pending) = self.pending.as_ref() else {
                    return; // stale: nothing asked
                };
                if reply.code() != pending.reply_code {
                    return; // stale reply to an earlier request
                }
                let command = pending.command;
                self.pending = None;
                self.timers.stop(Timer::Ack);
                self.timers.stop(Timer::Reply);
                self.timers.stop(Timer::Resend);
                self.on_answer(command, reply, now);
            }
        }
    }

    /// The awaited reply to `command` arrived: next step.
    fn on_answer(&mut self, command: Command, reply: Reply, now: Instant) {
        match (self.phase, reply) {
            (Phase::Probing { index, step }, reply) => {
                self.on_probe_answer(index, step, reply, now)
            }
            (Phase::Login, Reply::ModeChanged(ModeChangeResult::Success)) => {
                self.phase = Phase::ReadConfig;
                self.send(Command::ReadConfig, Request::ReadConfig, now);
            }
            (Phase::Login, Reply::ModeChanged(result)) => {
                self.step_failed(
                    LinkError::PasswordRefused {
                        result: result.code(),
                    },
                    now,
                );
            }
            (Phase::ReadConfig, Reply::Config(block)) => self.on_config_read(block, now),
            (
                Phase::WriteConfig,
                Reply::ConfigWritten {
                    accepted: true,
                    config,
                },
            ) => {
                self.stats.config_writes += 1;
                self.sensor_config = Some(config);
                self.set_variant(now);
            }
            (
                Phase::WriteConfig,
                Reply::ConfigWritten {
                    accepted: false, ..
                },
            ) => {
                self.step_failed(LinkError::ConfigRefused, now);
            }
            (Phase::SetVariant, reply @ Reply::VariantChanged { accepted, .. }) => {
                if accepted && reply.variant() == Some(self.config.variant) {
                    self.switch_baud(now);
                } else {
                    self.step_failed(LinkError::VariantRefused(self.config.variant), now);
                }
            }
            (Phase::SwitchBaud, Reply::ModeChanged(ModeChangeResult::Success)) => {
                // The A0 came at the old rate; now the host follows.
                let target = self.config.target_baud;
                self.sensor_baud = Some(target);
                self.config.baud_hint = Some(target);
                self.set_host_baud(target);
                self.phase = Phase::BaudSettle;
                self.timers
                    .set(Timer::BaudSettle, now + self.config.baud_settle);
            }
            (Phase::ConfirmBaud, Reply::Status(_)) => self.start_output(now),
            (Phase::StartOutput, Reply::ModeChanged(ModeChangeResult::Success)) => {
                self.on_streaming(now)
            }
            (Phase::CloseStop, _) => self.close_to_default_baud(now),
            (Phase::CloseBaud, _) => {
                self.sensor_baud = Some(Baud::B9600);
                self.set_host_baud(Baud::B9600);
                self.finish_close();
            }
            (_, Reply::ModeChanged(result)) => {
                self.step_failed(
                    LinkError::ModeChangeFailed {
                        command,
                        result: result.code(),
                    },
                    now,
                );
            }
            (_, reply) => {
                self.step_failed(
                    LinkError::UnexpectedReply {
                        command,
                        reply_code: reply.code(),
                    },
                    now,
                );
            }
        }
    }

    /// Starts an auto-baud round at the first rate of the probe order.
    pub(super) fn start_probing(&mut self, now: Instant) {
        self.probe_order = self.config.probe_order();
        self.decoder.set_expectation(None);
        self.last_indices = None;
        self.probe_next_rate(0, now);
    }

    /// Probes rate `index` of the order, or reports that nothing answered.
    pub(super) fn probe_next_rate(&mut self, index: usize, now: Instant) {
        let Some(&baud) = self.probe_order.get(index) else {
            let error = LinkError::NoAnswer {
                bauds_tried: self.probe_order.clone(),
            };
            self.event(Event::Error(error));
            self.back_off(ReinitReason::NoAnswer, now);
            return;
        };
        self.probe_scans = 0;
        self.probe_retried = false;
        self.sensor_baud = None;
        self.set_host_baud(baud);
        self.phase = Phase::Probing {
            index,
            step: ProbeStep::Stop,
        };
        self.send(Command::StopOutput, Request::ValuesOnRequest, now);
    }

    /// A valid scan at the rate being probed: evidence that the sensor is
    /// streaming at this rate. It cannot replace the answers (which prove
    /// the sensor hears us), but it keeps auto-baud at this rate for one
    /// more probe when the requests got lost in the stream.
    pub(super) fn probe_saw_scan(&mut self) {
        self.probe_scans = self.probe_scans.saturating_add(1);
    }

    /// The probe at rate `index` failed: try it once more if scans showed
    /// the sensor is there, else move on to the next rate.
    pub(super) fn probe_failed(&mut self, index: usize, now: Instant) {
        if self.probe_scans > 0 && !self.probe_retried {
            self.probe_next_rate(index, now);
            self.probe_retried = true;
        } else {
            self.probe_next_rate(index + 1, now);
        }
    }

    fn on_probe_answer(&mut self, index: usize, step: ProbeStep, reply: Reply, now: Instant) {
        match (step, reply) {
            (ProbeStep::Stop, Reply::ModeChanged(_)) => {
                self.phase = Phase::Probing {
                    index,
                    step: ProbeStep::Status,
                };
                self.send(Command::Status, Request::Status, now);
            }
            (ProbeStep::Status, Reply::Status(_)) => {
                self.phase = Phase::Probing {
                    index,
                    step: ProbeStep::DeviceType,
                };
                self.send(Command::DeviceType, Request::DeviceType, now);
            }
            (ProbeStep::DeviceType, reply @ Reply::DeviceType(_)) => {
                // Three answers in a row (A0, B1, BA), each matched to its
                // request, make the rate trustworthy: a single stale reply
                // from before a speed change cannot pass.
                let text = reply.text().unwrap_or_default();
                let mut fields = text.split(';').map(str::trim);
                self.device_type = fields.next().unwrap_or_default().to_owned();
                self.firmware = fields.next_back().unwrap_or_default().to_owned();
                let baud = self
                    .probe_order
                    .get(index)
                    .copied()
                    .unwrap_or(self.host_baud);
                self.sensor_baud = Some(baud);
                self.config.baud_hint = Some(baud);
                self.phase = Phase::Login;
                let password = self.config.password;
                self.send(Command::Login, Request::InstallationMode { password }, now);
            }
            _ => self.probe_failed(index, now),
        }
    }

    /// Changes only the bytes that differ from the target; writes the block
    /// back with its own length, or skips the EEPROM write when equal.
    fn on_config_read(&mut self, block: ConfigBlock, now: Instant) {
        let mut wanted = block;
        wanted.set_units(self.config.units);
        wanted.set_measuring_mode(self.config.measuring_mode);
        wanted.set_real_time_indices(self.config.real_time_indices);
        self.sensor_config = Some(block);
        if wanted == block {
            self.set_variant(now);
        } else {
            self.phase = Phase::WriteConfig;
            self.send(Command::WriteConfig, Request::WriteConfig(wanted), now);
        }
    }

    fn set_variant(&mut self, now: Instant) {
        self.phase = Phase::SetVariant;
        let variant = self.config.variant;
        self.send(
            Command::SetVariant(variant),
            Request::set_variant(variant),
            now,
        );
    }

    fn switch_baud(&mut self, now: Instant) {
        let target = self.config.target_baud;
        if self.sensor_baud == Some(target) {
            self.start_output(now);
            return;
        }
        self.phase = Phase::SwitchBaud;
        self.send(Command::SetBaud(target), Request::SetBaud(target), now);
    }

    /// The host runs at the new rate and the sensor had time to switch.
    pub(super) fn on_baud_settled(&mut self, now: Instant) {
        if self.phase != Phase::BaudSettle {
            return;
        }
        self.phase = Phase::ConfirmBaud;
        self.send(Command::Status, Request::Status, now);
    }

    fn start_output(&mut self, now: Instant) {
        self.phase = Phase::StartOutput;
        let shape = self.scan_shape();
        self.decoder.set_expectation(Some(shape));
        self.send(Command::StartOutput, Request::ContinuousAllValues, now);
    }

    /// What `B0` telegrams look like once the configuration is written.
    pub(super) fn scan_shape(&self) -> ScanShape {
        let block = self.sensor_config;
        ScanShape {
            variant: self.config.variant,
            units: block.and_then(|b| b.units()).unwrap_or(self.config.units),
            real_time_indices: block
                .map_or(self.config.real_time_indices, |b| b.real_time_indices()),
            mode: block
                .and_then(|b| b.measuring_mode())
                .unwrap_or(self.config.measuring_mode),
        }
    }

    /// Shutdown step 2: back to 9600 Bd unless already there.
    pub(super) fn close_to_default_baud(&mut self, now: Instant) {
        if self.sensor_baud == Some(Baud::B9600) || self.sensor_baud.is_none() {
            if self.host_baud != Baud::B9600 {
                self.set_host_baud(Baud::B9600);
            }
            self.finish_close();
            return;
        }
        self.phase = Phase::CloseBaud;
        self.send(
            Command::SetBaud(Baud::B9600),
            Request::SetBaud(Baud::B9600),
            now,
        );
    }
}
