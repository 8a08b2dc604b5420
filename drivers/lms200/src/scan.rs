//! The `B0` scan telegram (TL §7.5.2, Tables 7-25/7-26).
//!
//! ```text
//! 02 ADR LEN_lo LEN_hi  B0  CNT_lo CNT_hi  V[1]_lo V[1]_hi … V[n]_lo V[n]_hi
//!                            [SCAN_IDX TEL_IDX]  STATUS  CRC_lo CRC_hi
//!
//! CNT  bits 0–9   n, number of values
//!      bit  10    unused
//!      bits 11–12 partial-scan raster: 00 x.00°, 01 x.25°, 10 x.50°, 11 x.75°
//!      bit  13    partial (interlaced) scan
//!      bits 14–15 units: 00 cm, 01 mm, 1x reserved
//! V[i] raw value word, ascending angle; the measuring mode splits it into
//!      distance (raw cm or mm) and flag bits
//! ```
//! The struct keeps raw integers as sent; units and SI conversion live in
//! accessors so a recording decodes to exactly what the line carried.

use crate::error::{EncodeError, Implausibility, ParseError};
use crate::frame::frame_len;
use crate::variant::{MeasuringMode, SpecialCode, Units, ValueFlags, Variant};

/// Bits 0–9 of the count word.
const COUNT_MASK: u16 = 0x03FF;
/// Bit 13 of the count word.
const PARTIAL_BIT: u16 = 1 << 13;
/// Shift of the raster bits 11–12.
const RASTER_SHIFT: u16 = 11;
/// Shift of the unit bits 14–15.
const UNITS_SHIFT: u16 = 14;

/// The count word opening every `B0` telegram.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CountWord(pub u16);

impl CountWord {
    /// The count word of a complete scan of `count` values.
    pub const fn complete(count: u16, units: Units) -> CountWord {
        CountWord((count & COUNT_MASK) | (units.count_bits() << UNITS_SHIFT))
    }

    /// The count word of an interlaced partial scan; `raster` in quarter
    /// degrees (0–3) is the start offset of this mirror turn.
    pub const fn partial(count: u16, raster: u8, units: Units) -> CountWord {
        CountWord(
            (count & COUNT_MASK)
                | (((raster & 0b11) as u16) << RASTER_SHIFT)
                | PARTIAL_BIT
                | (units.count_bits() << UNITS_SHIFT),
        )
    }

    /// Number of values (bits 0–9).
    pub const fn count(self) -> u16 {
        self.0 & COUNT_MASK
    }

    /// Whether this is one mirror turn of an interlaced scan (bit 13).
    pub const fn is_partial(self) -> bool {
        self.0 & PARTIAL_BIT != 0
    }

    /// Start offset of a partial scan in quarter degrees (bits 11–12).
    pub const fn raster(self) -> u8 {
        ((self.0 >> RASTER_SHIFT) & 0b11) as u8
    }

    /// Units (bits 14–15); `None` for the reserved `1x`.
    pub const fn units(self) -> Option<Units> {
        Units::from_count_bits(self.0 >> UNITS_SHIFT)
    }
}

/// Real-time indices, present only when configuration block C bit 1 is set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct RealTimeIndices {
    /// Mirror turn counter, modulo 256.
    pub scan: u8,
    /// Telegram counter, modulo 256.
    pub telegram: u8,
}

/// One value word read under a measuring mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Measurement {
    /// A distance, raw in the scan's units (cm or mm).
    Distance(u16),
    /// A special code: no distance was measured; never a range.
    Special(SpecialCode),
    /// A distance field above the mode's maximum that is no special code.
    /// A healthy sensor does not send it.
    Undefined(u16),
    /// A reflectivity (energy) value, measuring mode `3F`.
    Reflectivity(u16),
}

impl Measurement {
    /// Reads a raw value word under `mode`; flag bits are masked off.
    pub fn from_value(value: u16, mode: MeasuringMode) -> Measurement {
        if !mode.is_distance() {
            return Measurement::Reflectivity(value);
        }
        let field = value & mode.distance_mask();
        if let Some(code) = mode.special_code(field) {
            return Measurement::Special(code);
        }
        match mode.max_distance() {
            Some(max) if field > max => Measurement::Undefined(field),
            _ => Measurement::Distance(field),
        }
    }
}

/// A decoded `B0` telegram body: raw integers as sent.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct Scan {
    /// The count word; its count equals `values.len()`.
    pub count_word: CountWord,
    /// Raw value words, ascending angle (right to left).
    pub values: Vec<u16>,
    /// Scan and telegram indices, when the configuration enables them.
    pub indices: Option<RealTimeIndices>,
}

impl Scan {
    /// A complete scan in `units` with the count word filled in.
    pub fn complete(values: Vec<u16>, units: Units, indices: Option<RealTimeIndices>) -> Scan {
        let count = u16::try_from(values.len()).unwrap_or(u16::MAX);
        Scan {
            count_word: CountWord::complete(count, units),
            values,
            indices,
        }
    }

    /// Parses the data bytes after the `B0` code (status excluded). Whether
    /// indices are present follows from the byte count.
    pub fn parse(data: &[u8]) -> Result<Scan, ParseError> {
        let Some((count_bytes, rest)) = data.split_first_chunk::<2>() else {
            return Err(ParseError::DataLength {
                code: crate::reply::SCAN_CODE,
                expected: 2,
                actual: data.len(),
            });
        };
        let count_word = CountWord(u16::from_le_bytes(*count_bytes));
        let value_bytes = 2 * usize::from(count_word.count());
        let indices = match rest.len().checked_sub(value_bytes) {
            Some(0) => None,
            Some(2) => Some(RealTimeIndices {
                scan: rest[value_bytes],
                telegram: rest[value_bytes + 1],
            }),
            _ => {
                return Err(ParseError::ScanCount {
                    count: count_word.count(),
                    data_bytes: data.len(),
                });
            }
        };
        let values = rest[..value_bytes]
            .chunks_exact(2)
            .map(|pair| u16::from_le_bytes([pair[0], pair[1]]))
            .collect();
        Ok(Scan {
            count_word,
            values,
            indices,
        })
    }

    /// Data bytes after the `B0` code: count word, values, indices.
    pub(crate) fn encode_data(&self) -> Result<Vec<u8>, EncodeError> {
        if usize::from(self.count_word.count()) != self.values.len() {
            return Err(EncodeError::ScanCount {
                count: self.count_word.count(),
                values: self.values.len(),
            });
        }
        let mut data = Vec::with_capacity(2 + 2 * self.values.len() + 2);
        data.extend_from_slice(&self.count_word.0.to_le_bytes());
        for value in &self.values {
            data.extend_from_slice(&value.to_le_bytes());
        }
        if let Some(indices) = self.indices {
            data.push(indices.scan);
            data.push(indices.telegram);
        }
        Ok(data)
    }

    /// Units from the count word; `None` if the reserved bits are set.
    pub const fn units(&self) -> Option<Units> {
        self.count_word.units()
    }

    /// Value `index` read under `mode`.
    pub fn measurement(&self, index: usize, mode: MeasuringMode) -> Option<Measurement> {
        self.values
            .get(index)
            .map(|&value| Measurement::from_value(value, mode))
    }

    /// All values read under `mode`, in scan order.
    pub fn measurements(&self, mode: MeasuringMode) -> impl Iterator<Item = Measurement> + '_ {
        self.values
            .iter()
            .map(move |&value| Measurement::from_value(value, mode))
    }

    /// Flag bits of value `index` under `mode`.
    pub fn flags(&self, index: usize, mode: MeasuringMode) -> Option<ValueFlags> {
        self.values.get(index).map(|&value| mode.flags(value))
    }

    /// Range of value `index` in metres, or `None` when it is no distance
    /// (special code, undefined, reflectivity) or the units are reserved.
    pub fn range_m(&self, index: usize, mode: MeasuringMode) -> Option<f64> {
        let units = self.units()?;
        match self.measurement(index, mode)? {
            Measurement::Distance(raw) => Some(f64::from(raw) * units.metres_per_unit()),
            Measurement::Special(_) | Measurement::Undefined(_) | Measurement::Reflectivity(_) => {
                None
            }
        }
    }
}

/// What a `B0` telegram must look like under the current configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ScanShape {
    /// Angular range and resolution (`3B`).
    pub variant: Variant,
    /// Range units (config block E).
    pub units: Units,
    /// Whether scan and telegram indices are appended (config block C bit 1).
    pub real_time_indices: bool,
    /// Measuring mode (config block D).
    pub mode: MeasuringMode,
}

impl ScanShape {
    /// LEN field of a complete scan: code, count word, values, indices, status.
    pub const fn len_field(&self) -> u16 {
        let indices = if self.real_time_indices { 2 } else { 0 };
        1 + 2 + 2 * self.variant.value_count() + indices + 1
    }

    /// Frame length of a complete scan, STX through CRC.
    pub const fn frame_len(&self) -> usize {
        frame_len(self.len_field())
    }

    /// The count word of a complete scan.
    pub const fn count_word(&self) -> CountWord {
        CountWord::complete(self.variant.value_count(), self.units)
    }

    /// Plausibility of a CRC-valid scan under this shape: the count word must
    /// be the shape's, and in the modes with flag bits no distance field may
    /// lie between the maximum and the special codes (the CRC misses some
    /// two-byte errors, these checks catch many of them).
    pub fn check(&self, scan: &Scan) -> Result<(), Implausibility> {
        let expected = self.count_word();
        if scan.count_word != expected {
            return Err(Implausibility::CountWord {
                expected: expected.0,
                actual: scan.count_word.0,
            });
        }
        let mode = self.mode;
        // Mode 0F carries no flags and its special codes are not documented;
        // mode 3F carries reflectivity, not distances: nothing to check.
        if matches!(
            mode,
            MeasuringMode::Bits16Immediate | MeasuringMode::Reflectivity
        ) {
            return Ok(());
        }
        let Some(max) = mode.max_distance() else {
            return Ok(());
        };
        let mask = mode.distance_mask();
        for (index, &value) in scan.values.iter().enumerate() {
            let field = value & mask;
            if field > max && mode.special_code(field).is_none() {
                return Err(Implausibility::Value {
                    index: index as u16,
                    value,
                });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may unwrap: a panic is a failure
mod tests {
    use super::*;

    #[test]
    fn count_words_of_the_protocol_notes() {
        assert_eq!(CountWord::complete(361, Units::Mm), CountWord(0x4169));
        assert_eq!(CountWord::complete(361, Units::Cm), CountWord(0x0169));
        assert_eq!(CountWord::partial(181, 0, Units::Cm), CountWord(0x20B5));
        assert_eq!(CountWord::partial(180, 1, Units::Cm), CountWord(0x28B4));
        assert_eq!(CountWord::partial(180, 2, Units::Cm), CountWord(0x30B4));
        assert_eq!(CountWord::partial(180, 3, Units::Mm), CountWord(0x78B4));
        let word = CountWord(0x78B4);
        assert_eq!(
            (word.count(), word.raster(), word.is_partial()),
            (180, 3, true)
        );
        assert_eq!(CountWord(0x8169).units(), None);
        assert_eq!(CountWord(0xC169).units(), None);
    }

    #[test]
    fn parse_with_and_without_indices() {
        let plain = [0x02, 0x40, 0x10, 0x00, 0xFF, 0x1F];
        let scan = Scan::parse(&plain).unwrap();
        assert_eq!(scan.values, vec![0x0010, 0x1FFF]);
        assert_eq!(scan.indices, None);
        assert_eq!(scan.encode_data().unwrap(), plain);

        let indexed = [0x02, 0x40, 0x10, 0x00, 0xFF, 0x1F, 0x07, 0x09];
        let scan = Scan::parse(&indexed).unwrap();
        assert_eq!(
            scan.indices,
            Some(RealTimeIndices {
                scan: 7,
                telegram: 9
            })
        );
        assert_eq!(scan.encode_data().unwrap(), indexed);
    }

    #[test]
    fn parse_refuses_count_length_disagreement() {
        for data in [
            &[0x02, 0x40, 0x10][..],
            &[0x02, 0x40, 0, 0, 0, 0, 0],
            &[0x01],
            &[],
        ] {
            assert!(Scan::parse(data).is_err(), "{data:02X?}");
        }
    }

    #[test]
    fn measurements_separate_distances_from_special_codes() {
        let mode = MeasuringMode::Bits13FieldsAbDazzle;
        // 1234 mm with field A set; dazzling; not valid with dazzle flag;
        // 8185 (above max, not special).
        let scan = Scan::complete(vec![0x2000 | 1234, 0x1FFE, 0x9FFF, 8185], Units::Mm, None);
        let got: Vec<_> = scan.measurements(mode).collect();
        assert_eq!(
            got,
            vec![
                Measurement::Distance(1234),
                Measurement::Special(SpecialCode::Dazzling),
                Measurement::Special(SpecialCode::NotValid),
                Measurement::Undefined(8185),
            ]
        );
        assert_eq!(scan.range_m(0, mode), Some(1.234));
        assert_eq!(scan.range_m(1, mode), None);
        assert_eq!(scan.range_m(4, mode), None);
        assert_eq!(
            scan.flags(0, mode),
            Some(ValueFlags::Fields {
                a: true,
                b: false,
                c: false,
                dazzle: false
            })
        );
    }

    #[test]
    fn the_same_word_means_different_things_per_mode() {
        // 9007 from the section-5 real scan: flags+distance in 13-bit modes,
        // a plain 9.007 m in the 16 m modes.
        let scan = Scan::complete(vec![9007], Units::Mm, None);
        assert_eq!(
            scan.measurement(0, MeasuringMode::Bits13FieldsAbDazzle),
            Some(Measurement::Distance(9007 & 0x1FFF))
        );
        assert_eq!(scan.range_m(0, MeasuringMode::Bits14FieldsAb), Some(9.007));
        assert_eq!(
            scan.measurement(0, MeasuringMode::Reflectivity),
            Some(Measurement::Reflectivity(9007))
        );
    }

    #[test]
    fn centimetre_ranges() {
        let scan = Scan::complete(vec![150], Units::Cm, None);
        assert_eq!(
            scan.range_m(0, MeasuringMode::Bits13FieldsAbDazzle),
            Some(1.5)
        );
    }

    #[test]
    fn encode_refuses_inconsistent_count() {
        let scan = Scan {
            count_word: CountWord::complete(3, Units::Mm),
            values: vec![1, 2],
            indices: None,
        };
        assert_eq!(
            scan.encode_data(),
            Err(EncodeError::ScanCount {
                count: 3,
                values: 2
            })
        );
    }
}
