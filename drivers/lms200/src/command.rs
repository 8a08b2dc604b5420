//! Host → LMS requests (TL §7, table 2.1 of the protocol notes).
//!
//! ```text
//! 02 00 LEN_lo LEN_hi CMD DATA[n] CRC_lo CRC_hi      LEN = 1 + n, no status byte
//! ```

use crate::config_block::ConfigBlock;
use crate::error::{EncodeError, ParseError};
use crate::frame::{BROADCAST_ADDRESS, encode_frame};
use crate::variant::{Baud, Variant};

/// Command codes of table 2.1.
mod code {
    pub const RESET: u8 = 0x10;
    pub const SET_MODE: u8 = 0x20;
    pub const REQUEST_VALUES: u8 = 0x30;
    pub const STATUS: u8 = 0x31;
    pub const ERRORS: u8 = 0x32;
    pub const DEVICE_TYPE: u8 = 0x3A;
    pub const SET_VARIANT: u8 = 0x3B;
    pub const PERMANENT_BAUD: u8 = 0x66;
    pub const READ_CONFIG: u8 = 0x74;
    pub const WRITE_CONFIG: u8 = 0x77;
}

/// Second byte of `20 xx` (operating mode), except the baud rates.
mod mode {
    pub const INSTALLATION: u8 = 0x00;
    pub const DIAGNOSTIC: u8 = 0x10;
    pub const CONTINUOUS_ALL: u8 = 0x24;
    pub const ON_REQUEST: u8 = 0x25;
    pub const CONTINUOUS_INTERLACED: u8 = 0x2A;
    pub const TEST_PASSWORD: u8 = 0x30;
}

/// Second byte of `30 xx`.
mod values {
    pub const ONE_SCAN: u8 = 0x01;
    pub const PARTIAL_SCAN: u8 = 0x08;
}

/// The installation-mode password of the LMS200 (`SICK_LMS`).
pub const LMS_PASSWORD: [u8; 8] = *b"SICK_LMS";

/// What `66 xx` stores as the line speed used after power-on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PermanentBaud {
    /// `00`: 9600 Bd after power-on (the factory setting).
    PowerOn9600,
    /// `01`: keep the current speed after power-on. Never send this: units
    /// have been found stuck at 500 kBd because of it. Encodable only so the
    /// emulator and tests can speak the whole protocol.
    KeepCurrent,
    /// `02`: keep the LMS type configuration.
    KeepLmsType,
}

impl PermanentBaud {
    /// Data byte of `66 xx`.
    pub const fn code(self) -> u8 {
        match self {
            PermanentBaud::PowerOn9600 => 0x00,
            PermanentBaud::KeepCurrent => 0x01,
            PermanentBaud::KeepLmsType => 0x02,
        }
    }

    /// Inverse of [`PermanentBaud::code`].
    pub const fn from_code(code: u8) -> Option<PermanentBaud> {
        match code {
            0x00 => Some(PermanentBaud::PowerOn9600),
            0x01 => Some(PermanentBaud::KeepCurrent),
            0x02 => Some(PermanentBaud::KeepLmsType),
            _ => None,
        }
    }
}

/// A request the host sends to the LMS.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub enum Request {
    /// `10`: software reset; the LMS answers `91`, then `90` when ready.
    Reset,
    /// `20 00` + password: installation mode, needed before `77` and `66`.
    InstallationMode {
        /// 8 ASCII bytes, [`LMS_PASSWORD`] for an LMS200.
        password: [u8; 8],
    },
    /// `20 10`: diagnostic mode.
    DiagnosticMode,
    /// `20 24`: stream every complete scan as `B0`.
    ContinuousAllValues,
    /// `20 25`: values on request only (power-on default); stops streaming.
    ValuesOnRequest,
    /// `20 2A`: stream each mirror turn as a partial `B0`.
    ContinuousInterlaced,
    /// `20 30` + password: test a password.
    TestPassword {
        /// 8 ASCII bytes.
        password: [u8; 8],
    },
    /// `20 40/41/42/48`: switch line speed (answered at the old speed).
    SetBaud(Baud),
    /// `30 01`: one complete scan.
    OneScan,
    /// `30 08`: the current interlaced partial scan.
    PartialScan,
    /// `31`: status (`B1`).
    Status,
    /// `32`: error list (`B2`).
    ErrorList,
    /// `3A`: device type string (`BA`).
    DeviceType,
    /// `3B`: angular range and resolution; raw, because the sensor answers
    /// illegal pairs too (with "aborted").
    SetVariant {
        /// Field of view, whole degrees (100 or 180).
        fov_deg: u16,
        /// Resolution, 1/100° (25, 50 or 100).
        resolution_centideg: u16,
    },
    /// `66 xx`: permanent line speed; see [`PermanentBaud::KeepCurrent`].
    PermanentBaud(PermanentBaud),
    /// `74`: read the configuration (`F4`).
    ReadConfig,
    /// `77`: write the configuration (needs installation mode).
    WriteConfig(ConfigBlock),
    /// Any other command (or a known one with another layout), kept raw.
    Other {
        /// Command byte.
        code: u8,
        /// Data bytes after it.
        data: Vec<u8>,
    },
}

impl Request {
    /// `3B` for a legal variant.
    pub const fn set_variant(variant: Variant) -> Request {
        Request::SetVariant {
            fov_deg: variant.fov_deg(),
            resolution_centideg: variant.resolution_centideg(),
        }
    }

    /// Installation mode with the LMS200 password.
    pub const fn installation_mode() -> Request {
        Request::InstallationMode {
            password: LMS_PASSWORD,
        }
    }

    /// The command byte.
    pub const fn code(&self) -> u8 {
        match self {
            Request::Reset => code::RESET,
            Request::InstallationMode { .. }
            | Request::DiagnosticMode
            | Request::ContinuousAllValues
            | Request::ValuesOnRequest
            | Request::ContinuousInterlaced
            | Request::TestPassword { .. }
            | Request::SetBaud(_) => code::SET_MODE,
            Request::OneScan | Request::PartialScan => code::REQUEST_VALUES,
            Request::Status => code::STATUS,
            Request::ErrorList => code::ERRORS,
            Request::DeviceType => code::DEVICE_TYPE,
            Request::SetVariant { .. } => code::SET_VARIANT,
            Request::PermanentBaud(_) => code::PERMANENT_BAUD,
            Request::ReadConfig => code::READ_CONFIG,
            Request::WriteConfig(_) => code::WRITE_CONFIG,
            Request::Other { code, .. } => *code,
        }
    }

    /// The reply code a well-behaved LMS answers with (command + 0x80).
    pub const fn reply_code(&self) -> u8 {
        self.code().wrapping_add(0x80)
    }

    /// The data bytes after the command byte.
    pub fn data(&self) -> Vec<u8> {
        match self {
            Request::Reset
            | Request::Status
            | Request::ErrorList
            | Request::DeviceType
            | Request::ReadConfig => Vec::new(),
            Request::InstallationMode { password } => {
                [&[mode::INSTALLATION][..], password].concat()
            }
            Request::TestPassword { password } => [&[mode::TEST_PASSWORD][..], password].concat(),
            Request::DiagnosticMode => vec![mode::DIAGNOSTIC],
            Request::ContinuousAllValues => vec![mode::CONTINUOUS_ALL],
            Request::ValuesOnRequest => vec![mode::ON_REQUEST],
            Request::ContinuousInterlaced => vec![mode::CONTINUOUS_INTERLACED],
            Request::SetBaud(baud) => vec![baud.mode_code()],
            Request::OneScan => vec![values::ONE_SCAN],
            Request::PartialScan => vec![values::PARTIAL_SCAN],
            Request::SetVariant {
                fov_deg,
                resolution_centideg,
            } => [fov_deg.to_le_bytes(), resolution_centideg.to_le_bytes()].concat(),
            Request::PermanentBaud(setting) => vec![setting.code()],
            Request::WriteConfig(block) => block.as_bytes().to_vec(),
            Request::Other { data, .. } => data.clone(),
        }
    }

    /// The complete frame `02 00 LEN CMD DATA CRC` to the broadcast address.
    pub fn encode(&self) -> Result<Vec<u8>, EncodeError> {
        let mut out = Vec::new();
        self.encode_into(BROADCAST_ADDRESS, &mut out)?;
        Ok(out)
    }

    /// Appends the frame to `out`, addressed to `address` (`00`..`7F`).
    pub fn encode_into(&self, address: u8, out: &mut Vec<u8>) -> Result<(), EncodeError> {
        encode_frame(address, &[&[self.code()], &self.data()], None, out)
    }

    /// The request a command byte and its data stand for. Unknown commands
    /// and known ones with another layout become [`Request::Other`], so the
    /// emulator can answer them as the sensor would (`92`).
    pub fn parse(code: u8, data: &[u8]) -> Request {
        Request::parse_known(code, data).unwrap_or_else(|| Request::Other {
            code,
            data: data.to_vec(),
        })
    }

    fn parse_known(code: u8, data: &[u8]) -> Option<Request> {
        let request = match (code, data) {
            (code::RESET, []) => Request::Reset,
            (code::SET_MODE, [mode::INSTALLATION, password @ ..]) => Request::InstallationMode {
                password: password.try_into().ok()?,
            },
            (code::SET_MODE, [mode::TEST_PASSWORD, password @ ..]) => Request::TestPassword {
                password: password.try_into().ok()?,
            },
            (code::SET_MODE, [mode::DIAGNOSTIC]) => Request::DiagnosticMode,
            (code::SET_MODE, [mode::CONTINUOUS_ALL]) => Request::ContinuousAllValues,
            (code::SET_MODE, [mode::ON_REQUEST]) => Request::ValuesOnRequest,
            (code::SET_MODE, [mode::CONTINUOUS_INTERLACED]) => Request::ContinuousInterlaced,
            (code::SET_MODE, [speed]) => Request::SetBaud(Baud::from_mode_code(*speed)?),
            (code::REQUEST_VALUES, [values::ONE_SCAN]) => Request::OneScan,
            (code::REQUEST_VALUES, [values::PARTIAL_SCAN]) => Request::PartialScan,
            (code::STATUS, []) => Request::Status,
            (code::ERRORS, []) => Request::ErrorList,
            (code::DEVICE_TYPE, []) => Request::DeviceType,
            (code::SET_VARIANT, [a0, a1, r0, r1]) => Request::SetVariant {
                fov_deg: u16::from_le_bytes([*a0, *a1]),
                resolution_centideg: u16::from_le_bytes([*r0, *r1]),
            },
            (code::PERMANENT_BAUD, [setting]) => {
                Request::PermanentBaud(PermanentBaud::from_code(*setting)?)
            }
            (code::READ_CONFIG, []) => Request::ReadConfig,
            (code::WRITE_CONFIG, block) => {
                Request::WriteConfig(ConfigBlock::from_bytes(block).ok()?)
            }
            _ => return None,
        };
        Some(request)
    }

    /// Parses the CMD + DATA bytes of a host frame.
    pub fn from_body(body: &[u8]) -> Result<Request, ParseError> {
        let (&code, data) = body.split_first().ok_or(ParseError::Empty)?;
        Ok(Request::parse(code, data))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may unwrap: a panic is a failure
mod tests {
    use super::*;
    use crate::test_util::hex;

    /// Every host vector of section 1.3, with the request that must encode to it.
    fn golden() -> Vec<(Request, Vec<u8>)> {
        let zeros21 = " 00".repeat(21);
        let config_mm = hex(&format!("00 00 00 00 00 00 01 00 00 02 02{zeros21}"));
        let mut config_cm = config_mm.clone();
        config_cm[6] = 0x00;
        let config_34 = hex("00 00 46 00 00 00 01 00 00 02 02 02 00 00 0A 0A 50 64 00 \
             0A 0A 50 80 00 0A 0A 50 64 00 00 00 00 02 00");
        vec![
            (Request::Status, hex("02 00 01 00 31 15 12")),
            (Request::ContinuousAllValues, hex("02 00 02 00 20 24 34 08")),
            (Request::ValuesOnRequest, hex("02 00 02 00 20 25 35 08")),
            (
                Request::SetBaud(Baud::B9600),
                hex("02 00 02 00 20 42 52 08"),
            ),
            (
                Request::SetBaud(Baud::B19200),
                hex("02 00 02 00 20 41 51 08"),
            ),
            (
                Request::SetBaud(Baud::B38400),
                hex("02 00 02 00 20 40 50 08"),
            ),
            (
                Request::SetBaud(Baud::B500000),
                hex("02 00 02 00 20 48 58 08"),
            ),
            (
                Request::set_variant(Variant::Fov180Res50),
                hex("02 00 05 00 3B B4 00 32 00 3B 1F"),
            ),
            (
                Request::set_variant(Variant::Fov180Res100),
                hex("02 00 05 00 3B B4 00 64 00 97 49"),
            ),
            (
                Request::set_variant(Variant::Fov100Res100),
                hex("02 00 05 00 3B 64 00 64 00 1D 0F"),
            ),
            (
                Request::set_variant(Variant::Fov100Res50),
                hex("02 00 05 00 3B 64 00 32 00 B1 59"),
            ),
            (
                Request::set_variant(Variant::Fov100Res25),
                hex("02 00 05 00 3B 64 00 19 00 E7 72"),
            ),
            (
                Request::installation_mode(),
                hex("02 00 0A 00 20 00 53 49 43 4B 5F 4C 4D 53 BE C5"),
            ),
            (Request::OneScan, hex("02 00 02 00 30 01 31 18")),
            (Request::DeviceType, hex("02 00 01 00 3A 1E 12")),
            (Request::ReadConfig, hex("02 00 01 00 74 50 12")),
            (
                Request::WriteConfig(ConfigBlock::from_bytes(&config_mm).unwrap()),
                [hex("02 00 21 00 77"), config_mm.clone(), hex("FC 7E")].concat(),
            ),
            (
                Request::WriteConfig(ConfigBlock::from_bytes(&config_cm).unwrap()),
                [hex("02 00 21 00 77"), config_cm, hex("E8 72")].concat(),
            ),
            (
                Request::WriteConfig(ConfigBlock::from_bytes(&config_34).unwrap()),
                [hex("02 00 23 00 77"), config_34, hex("7B 4B")].concat(),
            ),
            (
                Request::PermanentBaud(PermanentBaud::KeepCurrent),
                hex("02 00 02 00 66 01 9D 4E"),
            ),
            (
                Request::PermanentBaud(PermanentBaud::KeepLmsType),
                hex("02 00 02 00 66 02 9E 4E"),
            ),
            (Request::Reset, hex("02 00 01 00 10 34 12")),
            (
                Request::Other {
                    code: 0x45,
                    data: vec![0x01, 0x00],
                },
                hex("02 00 03 00 45 01 00 A6 D2"),
            ),
            (
                Request::Other {
                    code: 0x41,
                    data: vec![0x00],
                },
                hex("02 00 02 00 41 00 D2 69"),
            ),
        ]
    }

    #[test]
    fn every_host_vector_of_section_1_3_encodes_exactly() {
        for (request, frame) in golden() {
            assert_eq!(request.encode().unwrap(), frame, "{request:?}");
        }
    }

    #[test]
    fn every_host_vector_parses_back_to_its_request() {
        for (request, frame) in golden() {
            let body = &frame[4..frame.len() - 2];
            assert_eq!(Request::from_body(body).unwrap(), request);
        }
    }

    #[test]
    fn the_tl_default_block_is_the_34_byte_vector() {
        let frame = Request::WriteConfig(ConfigBlock::tl_default())
            .encode()
            .unwrap();
        assert_eq!(&frame[frame.len() - 2..], &[0x7B, 0x4B]);
    }

    #[test]
    fn odd_layouts_stay_raw() {
        assert_eq!(
            Request::parse(0x3B, &[0xB4, 0x00, 0x32]),
            Request::Other {
                code: 0x3B,
                data: vec![0xB4, 0x00, 0x32]
            }
        );
        assert_eq!(
            Request::parse(0x20, &[0x99]),
            Request::Other {
                code: 0x20,
                data: vec![0x99]
            }
        );
        assert_eq!(
            Request::parse(0x66, &[0x07]),
            Request::Other {
                code: 0x66,
                data: vec![0x07]
            }
        );
        assert_eq!(Request::from_body(&[]), Err(ParseError::Empty));
        assert_eq!(Request::Status.reply_code(), 0xB1);
    }

    #[test]
    fn oversized_other_is_refused() {
        let request = Request::Other {
            code: 0x50,
            data: vec![0; 900],
        };
        assert!(matches!(request.encode(), Err(EncodeError::TooLong { .. })));
    }
}
