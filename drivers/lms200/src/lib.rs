//! SICK LMS200 laser rangefinder: the telegram protocol as a sans-IO
//! library, and the shells that put it on a wire.
//!
//! # The core (no features, nothing but std)
//!
//! - [`crc`], [`frame`]: the telegram's CRC-16 and framing.
//! - [`variant`], [`config_block`], [`scan`]: angular variants, units,
//!   measuring modes, the configuration block, scan values.
//! - [`command`], [`reply`]: every request and reply, encoded and parsed.
//! - [`decoder`]: bytes in, telegrams out, with resynchronisation after
//!   damage; [`error`] names every reason a byte run was dropped.
//! - [`link`]: the host's state machine from any sensor state to
//!   streaming scans (baud search, mode changes, watchdog) — bytes and
//!   time in, bytes, timers and events out.
//! - [`recording`]: the raw bytes both ways, versioned and checksummed.
//!
//! # Shells (features)
//!
//! - `serial`: `serial::SerialTransport` (the tty, opened exclusively) and
//!   `driver::SerialDriver` (the link on it, optionally recorded).
//! - `emulator`: `emulator::Emulator`, a sans-IO LMS200 that speaks the
//!   protocol byte for byte, and `virtual_line::VirtualLine`, the link and
//!   the emulator back to back on a virtual clock.
//! - `pty`: `pty::PtyEmulator`, the emulator behind a pseudo-terminal.

pub mod command;
pub mod config_block;
pub mod crc;
pub mod decoder;
pub mod error;
pub mod frame;
pub mod reply;
pub mod scan;
pub mod variant;

#[cfg(feature = "serial")]
pub mod driver;
#[cfg(feature = "emulator")]
pub mod emulator;
pub mod link;
#[cfg(feature = "pty")]
pub mod pty;
pub mod recording;
#[cfg(feature = "serial")]
pub mod serial;
#[cfg(feature = "emulator")]
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
