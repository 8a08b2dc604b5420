//! SICK LMS200 laser rangefinder: sans-IO telegram codec, link state
//! machine, emulator, serial transport and recordings.
//!
//! # Codec API (stable; the link and emulator build on it)
//!
//! ```text
//! crc          Crc16::{new, update(&[u8]), value() -> u16}; crc16(&[u8]) -> u16
//! frame        STX ACK NAK BROADCAST_ADDRESS REPLY_ADDRESS_BIT HEADER_LEN CRC_LEN
//!              MAX_FRAME_LEN MAX_LEN_FIELD; Direction; frame_len(u16) -> usize
//! variant      Variant {Fov100Res100, Fov100Res50, Fov100Res25, Fov180Res100, Fov180Res50}
//!                ::{ALL, from_wire(deg, centideg), fov_deg, fov_centideg, resolution_centideg,
//!                   value_count, first_beam_centideg, beam_angle_rad(i)}
//!              Units {Cm, Mm}; MeasuringMode (code, from_code, distance_mask, flags,
//!              special_code, special_value, max_distance); ValueFlags; SpecialCode;
//!              Baud {B9600, B19200, B38400, B500000} (mode_code, bits_per_second);
//!              Status(u8) (severity, polluted, implausible_values, needs_attention); Severity
//! config_block ConfigBlock::{from_bytes, tl_default, as_bytes, format, real_time_indices,
//!              set_real_time_indices, measuring_mode, set_measuring_mode, units, set_units};
//!              ConfigFormat {Short32, Long34}::byte_len
//! command      Request {Reset, InstallationMode{password}, DiagnosticMode, ContinuousAllValues,
//!              ValuesOnRequest, ContinuousInterlaced, TestPassword{password}, SetBaud(Baud),
//!              OneScan, PartialScan, Status, ErrorList, DeviceType,
//!              SetVariant{fov_deg, resolution_centideg}, PermanentBaud(PermanentBaud),
//!              ReadConfig, WriteConfig(ConfigBlock), Other{code, data}}
//!                ::{encode() -> Result<Vec<u8>, EncodeError>, encode_into(addr, &mut Vec),
//!                   parse(code, data), from_body, code, reply_code, set_variant(Variant)}
//! reply        Reply {PowerOn(Vec<u8>), ResetAck, InvalidCommand, ModeChanged(ModeChangeResult),
//!              ScanData(Scan), Status(Vec<u8>), ErrorList(Vec<ErrorEntry>), DeviceType(Vec<u8>),
//!              VariantChanged{accepted, fov_deg, resolution_centideg},
//!              PermanentBaud{accepted, setting}, Config(ConfigBlock),
//!              ConfigWritten{accepted, config}, Other{code, data}}
//!                ::{encode(addr, Status), encode_into, parse(code, data), from_body, code,
//!                   variant, firmware_version, text}
//!              ReplyFrame {address, status, reply}::encode()
//! scan         Scan {count_word: CountWord, values: Vec<u16>, indices: Option<RealTimeIndices>}
//!                ::{complete, parse, units, measurement(i, mode), measurements(mode),
//!                   flags(i, mode), range_m(i, mode)}; CountWord(u16); Measurement;
//!              ScanShape {variant, units, real_time_indices, mode}::{len_field, frame_len,
//!                count_word, check(&Scan)}
//! decoder      Decoder::{new, with_expectation(ScanShape), set_expectation(Option<ScanShape>),
//!                push(&[u8]) -> usize, poll() -> Option<DecodeEvent>, feed(&[u8], FnMut),
//!                abandon_incomplete, clear, buffered, stats}
//!              DecodeEvent {Ack, Nak, Reply(ReplyFrame), Dropped{reason: DropReason, bytes}}
//!              RequestDecoder (same, poll() -> Option<RequestEvent>)
//!              RequestEvent {Request{address, request}, Dropped{reason, bytes}}
//!              DecoderStats (bytes_in = bytes_accounted() + buffered)
//! error        ParseError, EncodeError, DropReason {BadCrc, ImpossibleLength{len},
//!              LengthMismatch{expected, actual}, Implausible(Implausibility), Truncated,
//!              UnexpectedByte}, Implausibility
//! ```
//!
//! # Link, emulator and shells
//!
//! ```text
//! link         Link: sans-IO state machine from any sensor state to streaming
//! emulator     Emulator: sans-IO LMS200 that speaks the protocol byte for byte
//! serial       SerialTransport: the tty, opened exclusively, paced host bytes
//! driver       SerialDriver: the Link on a SerialTransport, optionally recorded
//! pty          PtyEmulator: the Emulator behind a pseudo-terminal, in a thread
//! recording    RecordingWriter, RecordingReader: raw bytes both ways, versioned
//! virtual_line VirtualLine::{new, now, step, advance_to, link(_mut), emulator(_mut),
//!                host_baud, set_host_stuck_at_9600, into_parts}: Link and Emulator
//!              back to back on a virtual clock; Wire (the same without owning them)
//! ```

pub mod command;
pub mod config_block;
pub mod crc;
pub mod decoder;
pub mod error;
pub mod frame;
pub mod reply;
pub mod scan;
pub mod variant;

pub mod driver;
pub mod emulator;
pub mod link;
pub mod pty;
pub mod recording;
pub mod serial;
pub mod virtual_line;

#[cfg(test)]
mod test_util;

pub use command::{LMS_PASSWORD, PermanentBaud, Request};
pub use config_block::{ConfigBlock, ConfigFormat};
pub use crc::{Crc16, crc16};
pub use decoder::{
    DecodeEvent, Decoder, DecoderStats, DropReason, Implausibility, RequestDecoder, RequestEvent,
    ScanShape,
};
pub use error::{EncodeError, ParseError};
pub use reply::{ErrorEntry, ModeChangeResult, Reply, ReplyFrame};
pub use scan::{CountWord, Measurement, RealTimeIndices, Scan};
pub use variant::{Baud, MeasuringMode, Severity, SpecialCode, Status, Units, ValueFlags, Variant};
