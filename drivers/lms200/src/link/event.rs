//! What the link tells its owner: outputs, events, errors, counters.

use std::fmt;
use std::time::Instant;

use crate::{Baud, Scan, Units, Variant};

/// The next thing the shell must do, in order.
#[derive(Debug, Clone, PartialEq)]
pub enum Output {
    /// Write these bytes to the serial line (pace them ≥ 55 µs apart at
    /// 500 kBd, see `serial::HOST_BYTE_GAP`).
    Transmit(Vec<u8>),
    /// Set the host's line speed now. The link emits it only after the
    /// sensor acknowledged the change (its `A0` came at the old rate), or when
    /// auto-baud moves on to the next rate to probe.
    SetBaud(Baud),
    /// Something the owner should know.
    Event(Event),
}

/// A request the link sends, named for error messages.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// `20 25`: request mode (stops continuous output).
    StopOutput,
    /// `31`: status.
    Status,
    /// `3A`: device type string.
    DeviceType,
    /// `20 00` + password: installation mode.
    Login,
    /// `74`: read the configuration block.
    ReadConfig,
    /// `77`: write the configuration block (EEPROM).
    WriteConfig,
    /// `3B`: field of view and resolution.
    SetVariant(Variant),
    /// `20 40/41/42/48`: line speed.
    SetBaud(Baud),
    /// `20 24`: continuous output of all values.
    StartOutput,
}

impl Command {
    /// The command bytes that identify the request on the wire.
    pub fn code_bytes(self) -> Vec<u8> {
        match self {
            Command::StopOutput => vec![0x20, 0x25],
            Command::Status => vec![0x31],
            Command::DeviceType => vec![0x3A],
            Command::Login => vec![0x20, 0x00],
            Command::ReadConfig => vec![0x74],
            Command::WriteConfig => vec![0x77],
            Command::SetVariant(_) => vec![0x3B],
            Command::SetBaud(baud) => vec![0x20, baud.mode_code()],
            Command::StartOutput => vec![0x20, 0x24],
        }
    }
}

impl fmt::Display for Command {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let bytes: Vec<String> = self
            .code_bytes()
            .iter()
            .map(|b| format!("{b:02X}"))
            .collect();
        let name = match self {
            Command::StopOutput => "stop output / request mode".to_owned(),
            Command::Status => "status".to_owned(),
            Command::DeviceType => "device type".to_owned(),
            Command::Login => "installation mode login".to_owned(),
            Command::ReadConfig => "read configuration".to_owned(),
            Command::WriteConfig => "write configuration".to_owned(),
            Command::SetVariant(v) => {
                format!(
                    "variant {}°/{}°",
                    v.fov_deg(),
                    f64::from(v.resolution_centideg()) / 100.0
                )
            }
            Command::SetBaud(b) => format!("line speed {} Bd", b.bits_per_second()),
            Command::StartOutput => "start continuous output".to_owned(),
        };
        write!(f, "{} ({name})", bytes.join(" "))
    }
}

/// Why the link starts over from auto-baud.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ReinitReason {
    /// First start after `Link::new`.
    Start,
    /// No byte within the scan watchdog time while streaming.
    SensorSilent,
    /// Bytes but no valid scan for [`GARBLED_STREAM_FACTOR`](super::GARBLED_STREAM_FACTOR)
    /// watchdog times.
    NoValidScans,
    /// The sensor sent its power-on telegram (`90`).
    SensorRestarted,
    /// A step of the initialisation failed.
    InitFailed(LinkError),
    /// No answer at any line speed; retrying after back-off.
    NoAnswer,
}

/// Typed failures the link reports (and recovers from by re-initialising).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LinkError {
    /// Auto-baud found no sensor.
    #[error("no answer from the LMS200 at {}", format_bauds(.bauds_tried))]
    NoAnswer {
        /// Line speeds probed, in order.
        bauds_tried: Vec<Baud>,
    },
    /// A request got no usable answer after all tries.
    #[error("{command}: no answer after {tries} tries")]
    NoReply {
        /// The request.
        command: Command,
        /// Sends made.
        tries: u8,
    },
    /// Every send of a request was refused with a NAK (bad checksum as the
    /// sensor received it: a noisy line or a wrong speed).
    #[error("{command}: refused with NAK {naks} times")]
    Nacked {
        /// The request.
        command: Command,
        /// NAKs received.
        naks: u8,
    },
    /// The sensor answered `92`: it does not accept the request.
    #[error("{command}: rejected by the sensor (92, invalid command)")]
    Rejected {
        /// The request.
        command: Command,
    },
    /// The sensor refused the installation-mode password.
    #[error("installation mode password refused (A0 result {result:#04X})")]
    PasswordRefused {
        /// The `A0` result byte.
        result: u8,
    },
    /// A mode change answered with a non-zero `A0` result.
    #[error("{command}: mode change failed (A0 result {result:#04X})")]
    ModeChangeFailed {
        /// The request.
        command: Command,
        /// The `A0` result byte.
        result: u8,
    },
    /// The sensor refused the configuration block (`F7` ok = 0).
    #[error("configuration write refused by the sensor (F7 ok = 0)")]
    ConfigRefused,
    /// The sensor refused the variant (`BB` ok = 0): the old one stays.
    #[error("variant {}°/{}° refused by the sensor (BB ok = 0)", .0.fov_deg(), f64::from(.0.resolution_centideg()) / 100.0)]
    VariantRefused(Variant),
    /// A reply that does not fit the request (wrong code or layout).
    #[error("{command}: unexpected reply {reply_code:#04X}")]
    UnexpectedReply {
        /// The request.
        command: Command,
        /// The reply code received.
        reply_code: u8,
    },
}

fn format_bauds(bauds: &[Baud]) -> String {
    let list: Vec<String> = bauds
        .iter()
        .map(|b| b.bits_per_second().to_string())
        .collect();
    format!("{} Bd", list.join(", "))
}

/// One scan as the link delivers it: the telegram as sent, and when it was
/// measured on the host clock (see [`super::timing`] for the model).
#[derive(Debug, Clone, PartialEq)]
pub struct TimedScan {
    /// The decoded `B0` telegram, raw values.
    pub scan: Scan,
    /// Middle of the measurement sweep, host clock.
    pub timestamp: Instant,
    /// When the telegram's last byte arrived.
    pub received_at: Instant,
    /// The variant the sensor was set to.
    pub variant: Variant,
    /// The units of the raw values.
    pub units: Units,
}

/// Things that happened on the link.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// Streaming started with this set-up.
    Connected {
        /// Line speed in use.
        baud: Baud,
        /// Field of view and resolution.
        variant: Variant,
        /// Units of the raw values.
        units: Units,
        /// Device type from the `3A` string (e.g. `LMS200`).
        device_type: String,
        /// Firmware version from the `3A` string (e.g. `V02.10`).
        firmware: String,
    },
    /// A complete scan.
    Scan(TimedScan),
    /// The sensor announced a power-up or reset (`90`).
    SensorRestarted,
    /// No scan within the watchdog time.
    SensorSilent,
    /// The link starts over from auto-baud.
    Reinitializing {
        /// Why.
        reason: ReinitReason,
    },
    /// The sensor answered `92` to a request.
    CommandRejected {
        /// The request.
        command: Command,
    },
    /// A failure; the link recovers on its own.
    Error(LinkError),
    /// `close` finished (or gave up); the link is idle.
    Closed,
}

/// Counters since the link was created.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Scans delivered.
    pub scans: u64,
    /// Frames the decoder dropped (bad checksum, impossible length, ...).
    pub dropped_frames: u64,
    /// Telegrams lost on the line, from gaps in the telegram index.
    pub lost_telegrams: u64,
    /// Scans the sensor measured but did not send (the line was busy), from
    /// gaps in the scan index beyond what lost telegrams explain.
    pub skipped_scans: u64,
    /// NAKs received while a request was outstanding.
    pub naks: u64,
    /// Requests resent after a NAK or a timeout.
    pub resends: u64,
    /// Requests answered with `92`.
    pub rejected_commands: u64,
    /// Re-initialisations started (not counting the first start).
    pub reinits: u64,
    /// Power-on telegrams seen.
    pub sensor_restarts: u64,
    /// Scan watchdog expiries.
    pub silences: u64,
    /// Configuration blocks written (EEPROM writes caused).
    pub config_writes: u64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_name_the_command_and_bauds() {
        let e = LinkError::NoAnswer {
            bauds_tried: vec![Baud::B9600, Baud::B500000],
        };
        assert_eq!(
            e.to_string(),
            "no answer from the LMS200 at 9600, 500000 Bd"
        );
        let e = LinkError::Rejected {
            command: Command::SetBaud(Baud::B38400),
        };
        assert_eq!(
            e.to_string(),
            "20 40 (line speed 38400 Bd): rejected by the sensor (92, invalid command)"
        );
        let e = LinkError::NoReply {
            command: Command::ReadConfig,
            tries: 3,
        };
        assert_eq!(
            e.to_string(),
            "74 (read configuration): no answer after 3 tries"
        );
    }
}
