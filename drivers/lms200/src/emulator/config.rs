//! How an emulated LMS200 starts and behaves.

use std::time::Duration;

use crate::{Baud, ConfigBlock, Status, Variant};

use super::faults::FaultConfig;

/// Start-up state and personality of an [`Emulator`](super::Emulator).
#[derive(Debug, Clone, PartialEq)]
pub struct EmulatorConfig {
    /// Line speed at start. Default 9600 (power-on); another value emulates a
    /// sensor a previous run left at that speed (or one with `66 01` stored).
    pub start_baud: Baud,
    /// Speed after a power cycle or reset: 9600 unless `66 01` stored
    /// another (the "stuck at 500k" units of the protocol notes §2.1).
    pub power_on_baud: Baud,
    /// Start in continuous output (`20 24`) as a previous run left it.
    pub start_streaming: bool,
    /// Delay from power-up until the sensor is ready and sends `90`;
    /// `None`: the sensor has been on for a while (no `90`, ready at once).
    /// Real units need up to 60 s (TL §7.3.1); default 1 s keeps emulated
    /// start-ups quick.
    pub power_on_delay: Option<Duration>,
    /// Delay from a reset's `91` to its `90`. Default 1 s (real: ≤ 60 s).
    pub reset_delay: Duration,
    /// Variant at start. Default 180°/0.5°.
    pub variant: Variant,
    /// Configuration block at start; its length (34, or 32 for firmware
    /// older than V2.10) is what `74` returns and what `77` must match.
    /// Default: the TL defaults (34 bytes, mm, mode 00, no indices).
    pub config: ConfigBlock,
    /// The `3A` type string. Default `LMS200;30106;V02.10 ` (20 bytes).
    pub type_string: String,
    /// The sensor's own address (`01`..`7F`); it also answers `00`.
    /// Replies carry the request's address with bit 7 set. Default `01`.
    pub address: u8,
    /// Status byte closing every reply. Default `0x10` (ok, LMS type 6);
    /// `0x11` emulates the info status real units send routinely.
    pub status: Status,
    /// Time from the end of a request to the start of the `06` and reply.
    /// Default 2 ms (TL: ACK within 60 ms).
    pub response_delay: Duration,
    /// Seed of the fault-injection generator.
    pub seed: u64,
    /// Faults active from the start.
    pub faults: FaultConfig,
    /// How many sent scans to keep for tests to compare against. Default 4096.
    pub scan_log_capacity: usize,
    /// Command bytes this firmware does not know: answered `92` (e.g. a
    /// device without `3B`). Default none.
    pub unsupported_commands: Vec<u8>,
    /// Whether `3B` may change the variant; `false` answers `BB` with
    /// ok = 0 and keeps the old variant (a device fixed to one variant).
    /// Default true.
    pub variant_change_allowed: bool,
}

impl Default for EmulatorConfig {
    fn default() -> Self {
        Self {
            start_baud: Baud::B9600,
            power_on_baud: Baud::B9600,
            start_streaming: false,
            power_on_delay: Some(Duration::from_secs(1)),
            reset_delay: Duration::from_secs(1),
            variant: Variant::Fov180Res50,
            config: ConfigBlock::tl_default(),
            type_string: "LMS200;30106;V02.10 ".to_owned(),
            address: 0x01,
            status: Status::OK,
            response_delay: Duration::from_millis(2),
            seed: 0x5EED,
            faults: FaultConfig::default(),
            scan_log_capacity: 4096,
            unsupported_commands: Vec::new(),
            variant_change_allowed: true,
        }
    }
}

impl EmulatorConfig {
    /// A sensor with firmware older than V2.10: 32-byte configuration block.
    pub fn old_firmware() -> Self {
        let block = ConfigBlock::tl_default();
        let short = ConfigBlock::from_bytes(&block.as_bytes()[..32]).unwrap_or(block);
        Self {
            config: short,
            type_string: "LMS200;30106;V01.10 ".to_owned(),
            ..Self::default()
        }
    }

    /// A sensor that has been running (no power-on telegram pending), left
    /// at `baud`, streaming or not.
    pub fn left_running(baud: Baud, streaming: bool) -> Self {
        Self {
            start_baud: baud,
            start_streaming: streaming,
            power_on_delay: None,
            ..Self::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn old_firmware_has_a_32_byte_block() {
        assert_eq!(EmulatorConfig::old_firmware().config.as_bytes().len(), 32);
        assert_eq!(EmulatorConfig::default().config.as_bytes().len(), 34);
    }
}
