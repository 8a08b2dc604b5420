//! How the emulated sensor answers each request of table 2.1.

use std::time::{Duration, Instant};

use crate::command::{LMS_PASSWORD, PermanentBaud};
use crate::frame::{ACK, NAK, REPLY_ADDRESS_BIT};
use crate::{
    Baud, ConfigBlock, DropReason, ModeChangeResult, Reply, Request, RequestEvent, Units, Variant,
};

use super::wire::{AfterSent, SegmentKind, wire_time};
use super::{Emulator, OperatingMode};

/// Length of the `B1` status data (TL Table 7-33; the real frame is 160 bytes).
const STATUS_DATA_LEN: usize = 152;

/// Field offsets in a `B1` status reply, counted from the first byte after
/// the reply code; 16-bit words little-endian.
mod status {
    pub const DEVICE_STATUS: usize = 8;
    pub const VARIANT: usize = 17;
    pub const MEASURING_MODE: usize = 101;
    /// Scan angle, whole degrees (u16).
    pub const SCAN_ANGLE: usize = 106;
    /// Angular resolution, 1/100° (u16).
    pub const RESOLUTION: usize = 108;
    /// 0: 9600 Bd after power-on; 1: the speed stored with `66 01`.
    pub const PERMANENT_BAUD: usize = 118;
    pub const ADDRESS: usize = 119;
    /// 0x00 cm, 0x01 mm, as in the configuration block.
    pub const UNITS: usize = 121;
}

/// Longest pause between two bytes of one request (TL §4.3).
const MAX_REQUEST_BYTE_GAP: Duration = Duration::from_millis(6);

impl Emulator {
    /// Bytes from the host reached the sensor's UART at `now`.
    pub(super) fn receive(&mut self, bytes: &[u8], now: Instant) {
        if bytes.is_empty() {
            return;
        }
        // The LMS ignores a request with more than 6 ms between its bytes.
        let first_byte_at = now
            .checked_sub(wire_time(bytes.len(), self.baud.bits_per_second()))
            .unwrap_or(now);
        if let Some(last) = self.last_rx_at
            && first_byte_at.saturating_duration_since(last) > MAX_REQUEST_BYTE_GAP
        {
            self.rx.abandon_incomplete();
        }
        self.last_rx_at = Some(now);
        let mut events = Vec::new();
        self.rx.feed(bytes, |event| events.push(event));
        for event in events {
            match event {
                RequestEvent::Request { address, request } => {
                    self.on_request(address, Some(request), now)
                }
                RequestEvent::Dropped {
                    reason: DropReason::BadCrc,
                    ..
                } => self.on_request(0, None, now),
                RequestEvent::Dropped { .. } => {}
            }
        }
    }

    /// A complete host frame arrived at `now`: `request` is `None` when its
    /// checksum was wrong (then its address cannot be trusted either).
    fn on_request(&mut self, address: u8, request: Option<Request>, now: Instant) {
        if address != 0 && address != self.config.address {
            return; // another sensor on the bus: silence (TL p23)
        }
        // Any host telegram cuts the telegram on the line (protocol notes §2.5).
        self.release_until(now);
        match self.tx.interrupt() {
            Some(SegmentKind::Scan) => self.stats.scans_cut += 1,
            Some(SegmentKind::Reply) => self.stats.replies_cut += 1,
            None => {}
        }
        let ready_at = now + self.config.response_delay;
        let Some(request) = request else {
            self.stats.naks += 1;
            self.queue_control_byte(NAK, ready_at);
            return;
        };
        self.stats.requests += 1;
        if let Some(n) = self.faults.nak_every_nth_request
            && n > 0
            && self.stats.requests.is_multiple_of(u64::from(n))
        {
            self.stats.naks += 1;
            self.fault_counts.forced_naks += 1;
            self.queue_control_byte(NAK, ready_at);
            return;
        }
        self.queue_control_byte(ACK, ready_at);
        self.answer(&request, address | REPLY_ADDRESS_BIT, ready_at);
    }

    /// Queues the reply telegram(s) for a valid, acknowledged request.
    fn answer(&mut self, request: &Request, address: u8, at: Instant) {
        let mut after = AfterSent::Nothing;
        if self.config.unsupported_commands.contains(&request.code()) {
            self.stats.invalid_commands += 1;
            self.queue_reply(&Reply::InvalidCommand, address, at, after);
            return;
        }
        let reply = match request {
            Request::Reset => {
                // The 91 leaves at the current speed, then the sensor reboots.
                self.queue_reply(&Reply::ResetAck, address, at, AfterSent::Reboot);
                return;
            }
            Request::InstallationMode { password } => {
                if *password == LMS_PASSWORD {
                    self.installation = true;
                    Reply::ModeChanged(ModeChangeResult::Success)
                } else {
                    Reply::ModeChanged(ModeChangeResult::WrongPassword)
                }
            }
            Request::TestPassword { password } => {
                Reply::ModeChanged(if *password == LMS_PASSWORD {
                    ModeChangeResult::Success
                } else {
                    ModeChangeResult::WrongPassword
                })
            }
            Request::DiagnosticMode => self.change_mode(OperatingMode::Diagnostic, at),
            Request::ContinuousAllValues => self.change_mode(OperatingMode::ContinuousAll, at),
            Request::ValuesOnRequest => self.change_mode(OperatingMode::OnRequest, at),
            Request::ContinuousInterlaced => {
                self.change_mode(OperatingMode::ContinuousInterlaced, at)
            }
            Request::SetBaud(baud) => {
                after = AfterSent::SwitchBaud(baud.bits_per_second());
                Reply::ModeChanged(ModeChangeResult::Success)
            }
            Request::OneScan | Request::PartialScan => {
                // Answered with the next scan the mirror completes (≤ 60 ms).
                let partial = matches!(request, Request::PartialScan);
                let period = if partial {
                    super::MIRROR_TURN
                } else {
                    self.scan_period()
                };
                let done = self.next_boundary(at, period);
                self.queue_scan(done, partial, SegmentKind::Reply);
                return;
            }
            Request::Status => Reply::Status(self.status_data()),
            Request::ErrorList => Reply::ErrorList(Vec::new()),
            Request::DeviceType => Reply::DeviceType(self.config.type_string.as_bytes().to_vec()),
            Request::SetVariant {
                fov_deg,
                resolution_centideg,
            } => {
                let wanted = Variant::from_wire(*fov_deg, *resolution_centideg)
                    .filter(|_| self.config.variant_change_allowed);
                let accepted = match wanted {
                    Some(variant) => {
                        self.variant = variant;
                        if self.tick_period().is_some() {
                            self.set_mode(self.mode, at);
                        }
                        true
                    }
                    None => false,
                };
                Reply::VariantChanged {
                    accepted,
                    fov_deg: self.variant.fov_deg(),
                    resolution_centideg: self.variant.resolution_centideg(),
                }
            }
            Request::PermanentBaud(setting) => {
                if self.installation {
                    match setting {
                        PermanentBaud::PowerOn9600 => self.power_on_baud = Baud::B9600,
                        PermanentBaud::KeepCurrent => self.power_on_baud = self.baud,
                        PermanentBaud::KeepLmsType => {}
                    }
                    self.eeprom_writes += 1;
                }
                Reply::PermanentBaud {
                    accepted: self.installation,
                    setting: setting.code(),
                }
            }
            Request::ReadConfig => Reply::Config(self.block),
            Request::WriteConfig(block) => {
                let accepted = self.installation && self.write_config(block);
                Reply::ConfigWritten {
                    accepted,
                    config: self.block,
                }
            }
            Request::Other { .. } => {
                self.stats.invalid_commands += 1;
                Reply::InvalidCommand
            }
        };
        self.queue_reply(&reply, address, at, after);
    }

    /// `20 xx` mode changes leave installation mode.
    fn change_mode(&mut self, mode: OperatingMode, at: Instant) -> Reply {
        self.installation = false;
        self.set_mode(mode, at);
        Reply::ModeChanged(ModeChangeResult::Success)
    }

    /// Stores a `77` block if its units and mode are legal. A block of the
    /// other length is accepted as the firmware does: surplus bytes ignored,
    /// missing ones kept (TL p31/p33).
    fn write_config(&mut self, block: &ConfigBlock) -> bool {
        if Units::from_config_code(block.units_code()).is_none() || block.measuring_mode().is_none()
        {
            return false;
        }
        let mut stored = self.block.as_bytes().to_vec();
        let n = stored.len().min(block.as_bytes().len());
        stored[..n].copy_from_slice(&block.as_bytes()[..n]);
        match ConfigBlock::from_bytes(&stored) {
            Ok(new_block) => {
                self.block = new_block;
                self.eeprom_writes += 1;
                true
            }
            Err(_) => false,
        }
    }

    /// `B1` data: the firmware version (bytes 0–6, from the type string) and
    /// the operating mode byte (7) as TL lays them out; the remaining
    /// calibration and counter fields are zero.
    fn status_data(&self) -> Vec<u8> {
        let mut data = vec![0u8; STATUS_DATA_LEN];
        let version = self
            .config
            .type_string
            .rsplit(';')
            .next()
            .unwrap_or("")
            .trim();
        let version = format!("{version:<7}");
        for (slot, byte) in data.iter_mut().zip(version.bytes().take(7)) {
            *slot = byte;
        }
        data[7] = if self.installation {
            0x00
        } else {
            match self.mode {
                OperatingMode::OnRequest => 0x25,
                OperatingMode::ContinuousAll => 0x24,
                OperatingMode::ContinuousInterlaced => 0x2A,
                OperatingMode::Diagnostic => 0x10,
            }
        };
        // Offsets after the B1 code, as hosts read them (sicktoolbox's
        // status parse). Fields a host never reads (the
        // pollution and calibration values, counters) stay zero, and so does
        // the line-speed word, whose encoding the notes do not give (hosts
        // find the speed by trying it).
        data[status::DEVICE_STATUS] = 0x00; // ok
        data[status::VARIANT] = 0x00; // standard device (type 6)
        data[status::MEASURING_MODE] = self.block.measuring_mode_code();
        let put_u16 = |data: &mut [u8], at: usize, v: u16| {
            data[at..at + 2].copy_from_slice(&v.to_le_bytes());
        };
        put_u16(&mut data, status::SCAN_ANGLE, self.variant.fov_deg());
        put_u16(
            &mut data,
            status::RESOLUTION,
            self.variant.resolution_centideg(),
        );
        data[status::PERMANENT_BAUD] = u8::from(self.power_on_baud != Baud::B9600);
        data[status::ADDRESS] = self.config.address;
        // The same code as the configuration block's (00 cm, 01 mm).
        data[status::UNITS] = self.block.units().unwrap_or(Units::Mm).config_code();
        data
    }
}
