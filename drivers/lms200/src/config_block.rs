//! The configuration block of `74`/`F4` (read) and `77`/`F7` (write).
//!
//! Kept as raw bytes because the driver must write back exactly what it read
//! with only the needed bytes changed (TL p31/p33): older firmware uses 32
//! bytes, V2.10 and later 34, and newer firmware ignores surplus bytes.
//!
//! ```text
//! off  block  meaning
//! 0-1  A      blanking, cm (u16 LE)
//! 2-3  B      stop threshold / peak threshold or sensitivity
//! 4    C      availability: bit0 level 3, bit1 real-time indices, bit2 level 2
//! 5    D      measuring mode (see MeasuringMode)
//! 6    E      units: 00 cm, 01 mm
//! 7-31 F..A3  fields, contours, restart, evaluation (kept as is)
//! 32-33 A4    multiple evaluation of dazzling (34-byte format only)
//! ```

use crate::error::ParseError;
use crate::variant::{MeasuringMode, Units};

/// Offset of block C, the availability byte.
const AVAILABILITY: usize = 4;
/// Offset of block D, the measuring mode.
const MEASURING_MODE: usize = 5;
/// Offset of block E, the units.
const UNITS: usize = 6;
/// Bit of block C that makes `B0` carry the scan and telegram indices.
const REAL_TIME_INDICES_BIT: u8 = 0x02;

/// Length of a configuration block, as the sensor reported it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ConfigFormat {
    /// 32 bytes: firmware before V2.10.
    Short32,
    /// 34 bytes: firmware V2.10 and later.
    Long34,
}

impl ConfigFormat {
    /// Number of bytes of a block in this format.
    pub const fn byte_len(self) -> usize {
        match self {
            ConfigFormat::Short32 => 32,
            ConfigFormat::Long34 => 34,
        }
    }

    /// The format of a block of `len` bytes.
    pub const fn from_len(len: usize) -> Option<ConfigFormat> {
        match len {
            32 => Some(ConfigFormat::Short32),
            34 => Some(ConfigFormat::Long34),
            _ => None,
        }
    }
}

/// A configuration block of 32 or 34 bytes; the length is kept as read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ConfigBlock {
    bytes: [u8; 34],
    format: ConfigFormat,
}

impl ConfigBlock {
    /// The block carried by a `F4` reply or a `77` request.
    pub fn from_bytes(bytes: &[u8]) -> Result<ConfigBlock, ParseError> {
        let format =
            ConfigFormat::from_len(bytes.len()).ok_or(ParseError::ConfigLength(bytes.len()))?;
        let mut block = [0u8; 34];
        block[..bytes.len()].copy_from_slice(bytes);
        Ok(ConfigBlock {
            bytes: block,
            format,
        })
    }

    /// The TL defaults (34 bytes, LMS200, as TL Table 7-123 writes them):
    /// stop threshold 70, mode 00, mm, no indices.
    pub fn tl_default() -> ConfigBlock {
        let bytes: [u8; 34] = [
            0x00, 0x00, 0x46, 0x00, 0x00, 0x00, 0x01, 0x00, 0x00, 0x02, 0x02, 0x02, 0x00, 0x00,
            0x0A, 0x0A, 0x50, 0x64, 0x00, 0x0A, 0x0A, 0x50, 0x80, 0x00, 0x0A, 0x0A, 0x50, 0x64,
            0x00, 0x00, 0x00, 0x00, 0x02, 0x00,
        ];
        ConfigBlock {
            bytes,
            format: ConfigFormat::Long34,
        }
    }

    /// The block as sent on the wire (32 or 34 bytes).
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes[..self.format.byte_len()]
    }

    /// Length format, as read.
    pub const fn format(&self) -> ConfigFormat {
        self.format
    }

    /// Blanking distance (block A), cm.
    pub const fn blanking_cm(&self) -> u16 {
        u16::from_le_bytes([self.bytes[0], self.bytes[1]])
    }

    /// Raw availability byte (block C).
    pub const fn availability(&self) -> u8 {
        self.bytes[AVAILABILITY]
    }

    /// Whether `B0` scans carry the scan and telegram indices (block C bit 1).
    pub const fn real_time_indices(&self) -> bool {
        self.bytes[AVAILABILITY] & REAL_TIME_INDICES_BIT != 0
    }

    /// Turns the real-time indices on or off, leaving the other bits alone.
    pub fn set_real_time_indices(&mut self, on: bool) {
        if on {
            self.bytes[AVAILABILITY] |= REAL_TIME_INDICES_BIT;
        } else {
            self.bytes[AVAILABILITY] &= !REAL_TIME_INDICES_BIT;
        }
    }

    /// Raw measuring mode byte (block D).
    pub const fn measuring_mode_code(&self) -> u8 {
        self.bytes[MEASURING_MODE]
    }

    /// Measuring mode (block D); `None` for reserved codes.
    pub fn measuring_mode(&self) -> Option<MeasuringMode> {
        MeasuringMode::from_code(self.measuring_mode_code())
    }

    /// Sets block D.
    pub fn set_measuring_mode(&mut self, mode: MeasuringMode) {
        self.bytes[MEASURING_MODE] = mode.code();
    }

    /// Raw units byte (block E).
    pub const fn units_code(&self) -> u8 {
        self.bytes[UNITS]
    }

    /// Units (block E); `None` for the reserved code `02` and above.
    pub const fn units(&self) -> Option<Units> {
        Units::from_config_code(self.units_code())
    }

    /// Sets block E.
    pub fn set_units(&mut self, units: Units) {
        self.bytes[UNITS] = units.config_code();
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may unwrap: a panic is a failure
mod tests {
    use super::*;

    /// Data of section 1.3 row 28: the real F4 config reply (34 bytes).
    fn real_f4_block() -> Vec<u8> {
        let mut block = vec![
            0x00, 0x00, 0x70, 0x00, 0x00, 0x04, 0x01, 0x00, 0x00, 0x02, 0x02,
        ];
        block.extend([0u8; 21]);
        block.extend([0x02, 0x00]);
        block
    }

    #[test]
    fn real_block_fields() {
        let block = ConfigBlock::from_bytes(&real_f4_block()).unwrap();
        assert_eq!(block.format(), ConfigFormat::Long34);
        assert_eq!(block.measuring_mode(), Some(MeasuringMode::Bits14FieldsAb));
        assert_eq!(block.units(), Some(Units::Mm));
        assert!(!block.real_time_indices());
        assert_eq!(block.as_bytes(), &real_f4_block()[..]);
    }

    #[test]
    fn setters_change_only_their_byte_and_keep_length() {
        let mut short = real_f4_block();
        short.truncate(32);
        let original = ConfigBlock::from_bytes(&short).unwrap();
        let mut block = original;
        block.set_units(Units::Cm);
        block.set_real_time_indices(true);
        block.set_measuring_mode(MeasuringMode::Bits13FieldsAbDazzle);
        assert_eq!(block.as_bytes().len(), 32);
        let changed: Vec<usize> = (0..32)
            .filter(|&i| block.as_bytes()[i] != original.as_bytes()[i])
            .collect();
        assert_eq!(changed, vec![AVAILABILITY, MEASURING_MODE, UNITS]);
        assert!(block.real_time_indices());
        block.set_real_time_indices(false);
        assert_eq!(block.availability(), original.availability());
    }

    #[test]
    fn other_lengths_are_refused() {
        for len in [0, 7, 31, 33, 35] {
            assert_eq!(
                ConfigBlock::from_bytes(&vec![0; len]),
                Err(ParseError::ConfigLength(len))
            );
        }
    }

    #[test]
    fn tl_default_is_mm_mode_0() {
        let block = ConfigBlock::tl_default();
        assert_eq!(block.units(), Some(Units::Mm));
        assert_eq!(
            block.measuring_mode(),
            Some(MeasuringMode::Bits13FieldsAbDazzle)
        );
        assert_eq!(block.as_bytes().len(), 34);
    }
}
