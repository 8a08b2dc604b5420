//! Building the emulator's scan telegrams from ranges in metres.

use std::time::Instant;

use crate::{MeasuringMode, RealTimeIndices, SpecialCode, Units, Variant};

/// One scan the emulator put on the line (or started to), for tests that
/// check the driver delivered exactly what was sent.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SentScan {
    /// Running number of scan telegrams since power-up (not wrapped).
    pub sequence: u64,
    /// Raw value words as sent.
    pub values: Vec<u16>,
    /// The real-time indices, when the configuration enables them.
    pub indices: Option<RealTimeIndices>,
    /// Interlaced partial scan (`20 2A`, `30 08`) rather than a complete one.
    pub partial: bool,
    /// When the sweep ended and the telegram was queued.
    pub completed_at: Instant,
    /// Middle of the measurement window, the time a driver should stamp.
    pub mid_sweep: Instant,
}

/// Beam angles (radians, sensor frame) of a complete `variant` scan.
pub(crate) fn full_scan_angles(variant: Variant) -> Vec<f64> {
    (0..usize::from(variant.value_count()))
        .map(|i| variant.beam_angle_rad(i))
        .collect()
}

/// Beam angles of an interlaced partial scan with raster `raster`
/// (0 = x.00°, 1 = x.25°, 2 = x.50°, 3 = x.75°): 1° steps over 180°, 181
/// beams for x.00 and 180 otherwise (TL p46–47).
pub(crate) fn partial_scan_angles(raster: u8) -> Vec<f64> {
    let offset_deg = 0.25 * f64::from(raster & 0b11);
    let count = if raster & 0b11 == 0 { 181 } else { 180 };
    (0..count)
        .map(|i| (offset_deg + f64::from(i) - 90.0).to_radians())
        .collect()
}

/// The value word a healthy sensor sends for a range of `range_m` metres:
/// the distance in `units`, or the special code for "no echo" (not finite or
/// not positive) and "above maximum"; no flag bits set.
pub(crate) fn raw_value(range_m: f64, units: Units, mode: MeasuringMode) -> u16 {
    if !mode.is_distance() {
        // Reflectivity mode: an energy figure falling with distance.
        return if range_m.is_finite() && range_m > 0.0 {
            (2000.0 / (1.0 + range_m)) as u16
        } else {
            0
        };
    }
    let not_valid = mode.special_value(SpecialCode::NotValid).unwrap_or(0x1FFF);
    if !range_m.is_finite() || range_m <= 0.0 {
        return not_valid;
    }
    let raw = (range_m / units.metres_per_unit()).round();
    match mode.max_distance() {
        Some(max) if raw > f64::from(max) => mode
            .special_value(SpecialCode::AboveMaximum)
            .unwrap_or(not_valid),
        _ => raw as u16,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_become_raw_units_or_special_codes() {
        let m = MeasuringMode::Bits13FieldsAbDazzle;
        assert_eq!(raw_value(1.234, Units::Mm, m), 1234);
        assert_eq!(raw_value(1.234, Units::Cm, m), 123);
        assert_eq!(raw_value(9.0, Units::Mm, m), 8183);
        assert_eq!(raw_value(f64::INFINITY, Units::Mm, m), 8191);
        assert_eq!(raw_value(f64::NAN, Units::Cm, m), 8191);
        assert_eq!(
            raw_value(9.0, Units::Mm, MeasuringMode::Bits14FieldsAb),
            9000
        );
    }

    #[test]
    fn partial_scans_have_181_or_180_beams() {
        assert_eq!(partial_scan_angles(0).len(), 181);
        assert_eq!(partial_scan_angles(1).len(), 180);
        assert!((partial_scan_angles(2)[0] - (-89.5f64).to_radians()).abs() < 1e-12);
    }

    #[test]
    fn full_scans_have_the_variant_count() {
        for v in Variant::ALL {
            assert_eq!(full_scan_angles(v).len(), usize::from(v.value_count()));
        }
    }
}
