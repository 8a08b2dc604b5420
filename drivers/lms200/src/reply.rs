//! LMS → host replies (reply code = command + 0x80, TL §7).
//!
//! ```text
//! 02 ADR LEN_lo LEN_hi CODE DATA[n] STATUS CRC_lo CRC_hi     LEN = 1 + n + 1
//! ```
//! [`Reply`] is the typed CODE + DATA; the address and status byte travel
//! beside it in a [`ReplyFrame`].

use crate::config_block::ConfigBlock;
use crate::error::{EncodeError, ParseError};
use crate::frame::encode_frame;
use crate::scan::Scan;
use crate::variant::{Status, Variant};

/// Reply code of a `B0` scan telegram.
pub const SCAN_CODE: u8 = 0xB0;

/// Reply codes handled here.
mod code {
    pub const POWER_ON: u8 = 0x90;
    pub const RESET_ACK: u8 = 0x91;
    pub const INVALID_COMMAND: u8 = 0x92;
    pub const MODE_CHANGED: u8 = 0xA0;
    pub const STATUS: u8 = 0xB1;
    pub const ERRORS: u8 = 0xB2;
    pub const DEVICE_TYPE: u8 = 0xBA;
    pub const VARIANT: u8 = 0xBB;
    pub const PERMANENT_BAUD: u8 = 0xE6;
    pub const CONFIG: u8 = 0xF4;
    pub const CONFIG_WRITTEN: u8 = 0xF7;
}

/// Length of the firmware version at the start of a `B1` status reply
/// (e.g. `V02.30 `).
const FIRMWARE_VERSION_LEN: usize = 7;

/// Result byte of an `A0` mode-change reply (TL Table 7-19).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ModeChangeResult {
    /// `00`: the mode was changed.
    Success,
    /// `01`: wrong password.
    WrongPassword,
    /// `02`: LMS fault (TL prints `01` twice; rl uses `02`).
    LmsFault,
    /// Any other byte, kept as sent.
    Unknown(u8),
}

impl ModeChangeResult {
    /// The result byte.
    pub const fn code(self) -> u8 {
        match self {
            ModeChangeResult::Success => 0x00,
            ModeChangeResult::WrongPassword => 0x01,
            ModeChangeResult::LmsFault => 0x02,
            ModeChangeResult::Unknown(byte) => byte,
        }
    }

    /// Inverse of [`ModeChangeResult::code`].
    pub const fn from_code(code: u8) -> ModeChangeResult {
        match code {
            0x00 => ModeChangeResult::Success,
            0x01 => ModeChangeResult::WrongPassword,
            0x02 => ModeChangeResult::LmsFault,
            other => ModeChangeResult::Unknown(other),
        }
    }
}

/// One entry of a `B2` error list.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ErrorEntry {
    /// Error type byte (severity class, TL §8).
    pub kind: u8,
    /// Error number.
    pub number: u8,
}

/// The body of a reply: code and data, typed.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Reply {
    /// `90`: power-on / reset complete; ASCII text as sent.
    PowerOn(Vec<u8>),
    /// `91`: the reset request was accepted.
    ResetAck,
    /// `92`: a correct frame with a command the LMS does not accept.
    InvalidCommand,
    /// `A0`: answer to `20 xx`.
    ModeChanged(ModeChangeResult),
    /// `B0`: measured values.
    ScanData(Scan),
    /// `B1`: status; raw bytes, see [`Reply::firmware_version`].
    Status(Vec<u8>),
    /// `B2`: error list, pairs of (type, number).
    ErrorList(Vec<ErrorEntry>),
    /// `BA`: device type, ASCII as sent (e.g. `LMS200;S18063;V02.19 `).
    DeviceType(Vec<u8>),
    /// `BB`: answer to `3B`.
    VariantChanged {
        /// `true` if the new variant is active, `false` if the old one stays.
        accepted: bool,
        /// Field of view now active, whole degrees.
        fov_deg: u16,
        /// Resolution now active, 1/100°.
        resolution_centideg: u16,
    },
    /// `E6`: answer to `66 xx`.
    PermanentBaud {
        /// Whether the setting was stored.
        accepted: bool,
        /// The `66` data byte echoed.
        setting: u8,
    },
    /// `F4`: the configuration block.
    Config(ConfigBlock),
    /// `F7`: answer to `77`; the block now active (the old one if refused).
    ConfigWritten {
        /// Whether the new configuration was accepted.
        accepted: bool,
        /// The configuration the LMS now runs.
        config: ConfigBlock,
    },
    /// Any other reply code, kept raw.
    Other {
        /// Reply code.
        code: u8,
        /// Data bytes between the code and the status byte.
        data: Vec<u8>,
    },
}

/// A complete reply as it came over the line.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct ReplyFrame {
    /// Address byte: request address with bit 7 set (`80` for broadcast).
    pub address: u8,
    /// Status byte closing the telegram.
    pub status: Status,
    /// Code and data.
    pub reply: Reply,
}

impl ReplyFrame {
    /// The complete frame `02 ADR LEN CODE DATA STATUS CRC`.
    pub fn encode(&self) -> Result<Vec<u8>, EncodeError> {
        self.reply.encode(self.address, self.status)
    }
}

/// Reads the 0/1 "accepted" byte of `BB`, `E6` and `F7`.
fn flag(code: u8, value: u8) -> Result<bool, ParseError> {
    match value {
        0 => Ok(false),
        1 => Ok(true),
        _ => Err(ParseError::FlagByte { code, value }),
    }
}

/// A data-length mismatch for `code`.
fn length_error(code: u8, expected: usize, actual: usize) -> ParseError {
    ParseError::DataLength {
        code,
        expected,
        actual,
    }
}

impl Reply {
    /// The variant a `BB` reply reports, if legal.
    pub fn variant(&self) -> Option<Variant> {
        match self {
            Reply::VariantChanged {
                fov_deg,
                resolution_centideg,
                ..
            } => Variant::from_wire(*fov_deg, *resolution_centideg),
            _ => None,
        }
    }

    /// Firmware version of a `B1` status reply (its first 7 bytes, e.g.
    /// `V02.30`), trimmed, if they are printable ASCII.
    pub fn firmware_version(&self) -> Option<&str> {
        let Reply::Status(bytes) = self else {
            return None;
        };
        let version = bytes.get(..FIRMWARE_VERSION_LEN)?;
        if !version.iter().all(|b| b.is_ascii_graphic() || *b == b' ') {
            return None;
        }
        std::str::from_utf8(version).ok().map(str::trim)
    }

    /// Text of a `90` or `BA` reply, with non-ASCII bytes replaced.
    pub fn text(&self) -> Option<String> {
        match self {
            Reply::PowerOn(bytes) | Reply::DeviceType(bytes) => {
                Some(String::from_utf8_lossy(bytes).trim_end().to_owned())
            }
            _ => None,
        }
    }

    /// The reply code.
    pub const fn code(&self) -> u8 {
        match self {
            Reply::PowerOn(_) => code::POWER_ON,
            Reply::ResetAck => code::RESET_ACK,
            Reply::InvalidCommand => code::INVALID_COMMAND,
            Reply::ModeChanged(_) => code::MODE_CHANGED,
            Reply::ScanData(_) => SCAN_CODE,
            Reply::Status(_) => code::STATUS,
            Reply::ErrorList(_) => code::ERRORS,
            Reply::DeviceType(_) => code::DEVICE_TYPE,
            Reply::VariantChanged { .. } => code::VARIANT,
            Reply::PermanentBaud { .. } => code::PERMANENT_BAUD,
            Reply::Config(_) => code::CONFIG,
            Reply::ConfigWritten { .. } => code::CONFIG_WRITTEN,
            Reply::Other { code, .. } => *code,
        }
    }

    /// Data bytes between the code and the status byte.
    pub fn data(&self) -> Result<Vec<u8>, EncodeError> {
        Ok(match self {
            Reply::ResetAck | Reply::InvalidCommand => Vec::new(),
            Reply::PowerOn(text) | Reply::DeviceType(text) => text.clone(),
            Reply::Status(raw) => raw.clone(),
            Reply::Other { data, .. } => data.clone(),
            Reply::ModeChanged(result) => vec![result.code()],
            Reply::ScanData(scan) => scan.encode_data()?,
            Reply::ErrorList(entries) => entries.iter().flat_map(|e| [e.kind, e.number]).collect(),
            Reply::VariantChanged {
                accepted,
                fov_deg,
                resolution_centideg,
            } => {
                let mut data = vec![u8::from(*accepted)];
                data.extend_from_slice(&fov_deg.to_le_bytes());
                data.extend_from_slice(&resolution_centideg.to_le_bytes());
                data
            }
            Reply::PermanentBaud { accepted, setting } => vec![u8::from(*accepted), *setting],
            Reply::Config(block) => block.as_bytes().to_vec(),
            Reply::ConfigWritten { accepted, config } => {
                [&[u8::from(*accepted)][..], config.as_bytes()].concat()
            }
        })
    }

    /// The complete frame `02 ADR LEN CODE DATA STATUS CRC`.
    pub fn encode(&self, address: u8, status: Status) -> Result<Vec<u8>, EncodeError> {
        let mut out = Vec::new();
        self.encode_into(address, status, &mut out)?;
        Ok(out)
    }

    /// Appends the complete frame to `out`.
    pub fn encode_into(
        &self,
        address: u8,
        status: Status,
        out: &mut Vec<u8>,
    ) -> Result<(), EncodeError> {
        encode_frame(
            address,
            &[&[self.code()], &self.data()?],
            Some(status.0),
            out,
        )
    }

    /// Parses a reply code and its data (status excluded).
    pub fn parse(code: u8, data: &[u8]) -> Result<Reply, ParseError> {
        let exact = |expected: usize| {
            if data.len() == expected {
                Ok(())
            } else {
                Err(length_error(code, expected, data.len()))
            }
        };
        Ok(match code {
            code::POWER_ON => Reply::PowerOn(data.to_vec()),
            code::RESET_ACK => {
                exact(0)?;
                Reply::ResetAck
            }
            code::INVALID_COMMAND => {
                exact(0)?;
                Reply::InvalidCommand
            }
            code::MODE_CHANGED => {
                exact(1)?;
                Reply::ModeChanged(ModeChangeResult::from_code(data[0]))
            }
            SCAN_CODE => Reply::ScanData(Scan::parse(data)?),
            code::STATUS => Reply::Status(data.to_vec()),
            code::ERRORS => {
                if !data.len().is_multiple_of(2) {
                    return Err(length_error(code, data.len() + 1, data.len()));
                }
                Reply::ErrorList(
                    data.chunks_exact(2)
                        .map(|pair| ErrorEntry {
                            kind: pair[0],
                            number: pair[1],
                        })
                        .collect(),
                )
            }
            code::DEVICE_TYPE => Reply::DeviceType(data.to_vec()),
            code::VARIANT => {
                exact(5)?;
                Reply::VariantChanged {
                    accepted: flag(code, data[0])?,
                    fov_deg: u16::from_le_bytes([data[1], data[2]]),
                    resolution_centideg: u16::from_le_bytes([data[3], data[4]]),
                }
            }
            code::PERMANENT_BAUD => {
                exact(2)?;
                Reply::PermanentBaud {
                    accepted: flag(code, data[0])?,
                    setting: data[1],
                }
            }
            code::CONFIG => Reply::Config(ConfigBlock::from_bytes(data)?),
            code::CONFIG_WRITTEN => {
                let (&accepted, block) =
                    data.split_first()
                        .ok_or(length_error(code, 33, data.len()))?;
                Reply::ConfigWritten {
                    accepted: flag(code, accepted)?,
                    config: ConfigBlock::from_bytes(block)?,
                }
            }
            _ => Reply::Other {
                code,
                data: data.to_vec(),
            },
        })
    }

    /// Parses the CODE + DATA bytes of a reply frame (status excluded).
    pub fn from_body(body: &[u8]) -> Result<Reply, ParseError> {
        let (&code, data) = body.split_first().ok_or(ParseError::Empty)?;
        Reply::parse(code, data)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may unwrap: a panic is a failure
mod tests {
    use super::*;
    use crate::test_util::hex;

    /// The reply vectors of section 1.3 (rows 23–28) with their typed form.
    fn golden() -> Vec<(ReplyFrame, Vec<u8>)> {
        let zeros21 = " 00".repeat(21);
        let config = hex(&format!("00 00 70 00 00 04 01 00 00 02 02{zeros21} 02 00"));
        let frame = |address, reply| ReplyFrame {
            address,
            status: Status(0x10),
            reply,
        };
        vec![
            (
                frame(0x80, Reply::ModeChanged(ModeChangeResult::Success)),
                hex("02 80 03 00 A0 00 10 16 0A"),
            ),
            (
                frame(0x81, Reply::ModeChanged(ModeChangeResult::Success)),
                hex("02 81 03 00 A0 00 10 36 1A"),
            ),
            (
                frame(
                    0x80,
                    Reply::VariantChanged {
                        accepted: true,
                        fov_deg: 180,
                        resolution_centideg: 50,
                    },
                ),
                hex("02 80 07 00 BB 01 B4 00 32 00 10 03 9D"),
            ),
            (frame(0x80, Reply::ResetAck), hex("02 80 02 00 91 10 79 30")),
            (
                frame(0x80, Reply::InvalidCommand),
                hex("02 80 02 00 92 10 7F 33"),
            ),
            (
                frame(0x80, Reply::DeviceType(b"LMS200;S18063;V02.19 ".to_vec())),
                hex(
                    "02 80 17 00 BA 4C 4D 53 32 30 30 3B 53 31 38 30 36 33 3B 56 30 32 2E 31 39 \
                     20 10 85 6A",
                ),
            ),
            (
                frame(
                    0x80,
                    Reply::Config(ConfigBlock::from_bytes(&config).unwrap()),
                ),
                [hex("02 80 24 00 F4"), config, hex("10 36 FE")].concat(),
            ),
        ]
    }

    #[test]
    fn every_reply_vector_of_section_1_3_encodes_exactly() {
        for (frame, bytes) in golden() {
            assert_eq!(frame.encode().unwrap(), bytes, "{frame:?}");
        }
    }

    #[test]
    fn every_reply_vector_parses_back() {
        for (frame, bytes) in golden() {
            let body = &bytes[4..bytes.len() - 3];
            assert_eq!(Reply::from_body(body).unwrap(), frame.reply);
        }
    }

    #[test]
    fn accessors() {
        let (variant, _) = &golden()[2];
        assert_eq!(variant.reply.variant(), Some(Variant::Fov180Res50));
        let (device, _) = &golden()[5];
        assert_eq!(device.reply.text().as_deref(), Some("LMS200;S18063;V02.19"));
        let mut status = b"V02.30 ".to_vec();
        status.extend([0u8; 145]);
        assert_eq!(Reply::Status(status).firmware_version(), Some("V02.30"));
        assert_eq!(Reply::Status(vec![0xFF; 152]).firmware_version(), None);
        assert_eq!(Reply::Status(vec![b'V'; 3]).firmware_version(), None);
    }

    #[test]
    fn malformed_bodies_are_typed_errors() {
        assert!(matches!(
            Reply::parse(0xA0, &[]),
            Err(ParseError::DataLength { .. })
        ));
        assert!(matches!(
            Reply::parse(0x91, &[0]),
            Err(ParseError::DataLength { .. })
        ));
        assert!(matches!(
            Reply::parse(0xBB, &[2, 0xB4, 0, 0x32, 0]),
            Err(ParseError::FlagByte { .. })
        ));
        assert!(matches!(
            Reply::parse(0xB2, &[1, 2, 3]),
            Err(ParseError::DataLength { .. })
        ));
        assert!(matches!(
            Reply::parse(0xF4, &[0; 33]),
            Err(ParseError::ConfigLength(33))
        ));
        assert!(matches!(
            Reply::parse(0xF7, &[]),
            Err(ParseError::DataLength { .. })
        ));
        assert_eq!(Reply::from_body(&[]), Err(ParseError::Empty));
        assert_eq!(
            Reply::parse(0xC5, &[1, 2]),
            Ok(Reply::Other {
                code: 0xC5,
                data: vec![1, 2]
            })
        );
    }

    #[test]
    fn config_written_and_error_list_round_trip() {
        let replies = [
            Reply::ConfigWritten {
                accepted: false,
                config: ConfigBlock::tl_default(),
            },
            Reply::ErrorList(vec![ErrorEntry {
                kind: 3,
                number: 0x11,
            }]),
            Reply::PermanentBaud {
                accepted: true,
                setting: 0,
            },
            Reply::PowerOn(b"LMS200 V02.30 ready".to_vec()),
        ];
        for reply in replies {
            let bytes = reply.encode(0x80, Status::OK).unwrap();
            assert_eq!(Reply::from_body(&bytes[4..bytes.len() - 3]).unwrap(), reply);
        }
    }
}
