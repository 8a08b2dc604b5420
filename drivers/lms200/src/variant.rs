//! Scan variants, range units, measuring modes, line speeds and the status
//! byte: the small enumerations every telegram refers to.

/// One of the five angular range / resolution combinations the LMS200
/// accepts in the `3B` command (TL Table 7-58).
///
/// Beam `i` of a 180° scan lies at `i × resolution` in the 180° frame (0° =
/// right, 180° = left); the 100° variants cover 40°…140° of that frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Variant {
    /// 100° field of view, 1° steps, 101 values.
    Fov100Res100,
    /// 100° field of view, 0.5° steps, 201 values.
    Fov100Res50,
    /// 100° field of view, 0.25° steps, 401 values.
    Fov100Res25,
    /// 180° field of view, 1° steps, 181 values.
    Fov180Res100,
    /// 180° field of view, 0.5° steps, 361 values.
    Fov180Res50,
}

impl Variant {
    /// All legal variants, for table-driven code and tests.
    pub const ALL: [Variant; 5] = [
        Variant::Fov100Res100,
        Variant::Fov100Res50,
        Variant::Fov100Res25,
        Variant::Fov180Res100,
        Variant::Fov180Res50,
    ];

    /// The variant named by the `3B`/`BB` fields (angle in whole degrees,
    /// resolution in 1/100°), or `None` for a combination the sensor rejects.
    pub fn from_wire(fov_deg: u16, resolution_centideg: u16) -> Option<Variant> {
        Variant::ALL
            .into_iter()
            .find(|v| v.fov_deg() == fov_deg && v.resolution_centideg() == resolution_centideg)
    }

    /// Field of view in whole degrees, as the `3B` command carries it.
    pub const fn fov_deg(self) -> u16 {
        match self {
            Variant::Fov100Res100 | Variant::Fov100Res50 | Variant::Fov100Res25 => 100,
            Variant::Fov180Res100 | Variant::Fov180Res50 => 180,
        }
    }

    /// Field of view in 1/100°.
    pub const fn fov_centideg(self) -> u16 {
        self.fov_deg() * 100
    }

    /// Angular step between beams in 1/100°, as the `3B` command carries it.
    pub const fn resolution_centideg(self) -> u16 {
        match self {
            Variant::Fov100Res100 | Variant::Fov180Res100 => 100,
            Variant::Fov100Res50 | Variant::Fov180Res50 => 50,
            Variant::Fov100Res25 => 25,
        }
    }

    /// Values in one complete scan (both ends included).
    pub const fn value_count(self) -> u16 {
        self.fov_centideg() / self.resolution_centideg() + 1
    }

    /// Angle of the first beam in the 180° frame, 1/100° (0 = right).
    pub const fn first_beam_centideg(self) -> u16 {
        (18000 - self.fov_centideg()) / 2
    }

    /// Angle of beam `index` in the sensor frame (x forward, counter-clockwise
    /// positive), radians: `-fov/2 + index × resolution`.
    pub fn beam_angle_rad(self, index: usize) -> f64 {
        let centideg = index as f64 * f64::from(self.resolution_centideg())
            - f64::from(self.fov_centideg()) / 2.0;
        (centideg / 100.0).to_radians()
    }
}

/// Unit of the raw range values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Units {
    /// Centimetres (range up to 81.83 m in the 13-bit modes).
    Cm,
    /// Millimetres (the power-on default; range up to 8.183 m in 13-bit modes).
    Mm,
}

impl Units {
    /// Both units, for table-driven code and tests.
    pub const ALL: [Units; 2] = [Units::Cm, Units::Mm];

    /// Metres per raw unit.
    pub const fn metres_per_unit(self) -> f64 {
        match self {
            Units::Cm => 0.01,
            Units::Mm => 0.001,
        }
    }

    /// The units byte (block E) of the configuration: `00` cm, `01` mm.
    pub const fn config_code(self) -> u8 {
        match self {
            Units::Cm => 0x00,
            Units::Mm => 0x01,
        }
    }

    /// Inverse of [`Units::config_code`]; `02` (reserved) and above give `None`.
    pub const fn from_config_code(code: u8) -> Option<Units> {
        match code {
            0x00 => Some(Units::Cm),
            0x01 => Some(Units::Mm),
            _ => None,
        }
    }

    /// Bits 14–15 of a scan count word: `00` cm, `01` mm; `1x` is reserved.
    pub const fn from_count_bits(bits: u16) -> Option<Units> {
        match bits & 0b11 {
            0b00 => Some(Units::Cm),
            0b01 => Some(Units::Mm),
            _ => None,
        }
    }

    /// The two unit bits of a scan count word (before shifting to 14–15).
    pub const fn count_bits(self) -> u16 {
        match self {
            Units::Cm => 0b00,
            Units::Mm => 0b01,
        }
    }
}

/// Configuration block D: how a 16-bit value word splits into distance and
/// flag bits (TL p98).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum MeasuringMode {
    /// `00` (default): 13 distance bits; bit 13 field A, 14 field B, 15 dazzle.
    Bits13FieldsAbDazzle,
    /// `01`: 13 distance bits; bits 13–15 reflector level 0–7.
    Bits13Reflector8,
    /// `02`: 13 distance bits; bit 13 field A, 14 field B, 15 field C.
    Bits13FieldsAbc,
    /// `03`: 14 distance bits (16 m); bits 14–15 reflector level 0–3.
    Bits14Reflector4,
    /// `04`: 14 distance bits (16 m); bit 14 field A, 15 field B.
    Bits14FieldsAb,
    /// `05`: 15 distance bits (32 m); bit 15 reflector.
    Bits15Reflector,
    /// `06`: 15 distance bits (32 m); bit 15 field A.
    Bits15FieldA,
    /// `0F`: immediate output, 16 bits, no flags; special codes taken as the
    /// 15-bit ones since the range is still 32 m (TL does not list them).
    Bits16Immediate,
    /// `3F`: reflectivity (energy) values instead of distances.
    Reflectivity,
}

/// What a value word's flag bits mean in a given measuring mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ValueFlags {
    /// Field infringement bits and the dazzle bit (modes 00, 02, 04, 06).
    Fields {
        /// Field A infringed.
        a: bool,
        /// Field B infringed.
        b: bool,
        /// Field C infringed (mode 02).
        c: bool,
        /// Dazzled (mode 00).
        dazzle: bool,
    },
    /// Reflector level (modes 01: 0–7, 03: 0–3, 05: 0–1).
    ReflectorLevel(u8),
    /// The mode carries no flag bits.
    None,
}

/// The special codes a distance field carries instead of a distance
/// (TL §10.8); never to be used as a range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SpecialCode {
    /// No stop signal: nothing measured (all ones).
    NotValid,
    /// The receiver was dazzled.
    Dazzling,
    /// Operation overflow.
    Overflow,
    /// Signal-to-noise ratio too small.
    SignalToNoiseTooSmall,
    /// Error reading channel 1.
    ChannelError,
    /// Measured value above the maximum of the mode.
    AboveMaximum,
}

impl SpecialCode {
    /// All special codes.
    pub const ALL: [SpecialCode; 6] = [
        SpecialCode::NotValid,
        SpecialCode::Dazzling,
        SpecialCode::Overflow,
        SpecialCode::SignalToNoiseTooSmall,
        SpecialCode::ChannelError,
        SpecialCode::AboveMaximum,
    ];

    /// Distance of the code below the all-ones value of the distance field.
    const fn offset_below_all_ones(self) -> u16 {
        match self {
            SpecialCode::NotValid => 0,
            SpecialCode::Dazzling => 1,
            SpecialCode::Overflow => 2,
            SpecialCode::SignalToNoiseTooSmall => 4,
            SpecialCode::ChannelError => 5,
            SpecialCode::AboveMaximum => 8,
        }
    }
}

impl MeasuringMode {
    /// All documented modes.
    pub const ALL: [MeasuringMode; 9] = [
        MeasuringMode::Bits13FieldsAbDazzle,
        MeasuringMode::Bits13Reflector8,
        MeasuringMode::Bits13FieldsAbc,
        MeasuringMode::Bits14Reflector4,
        MeasuringMode::Bits14FieldsAb,
        MeasuringMode::Bits15Reflector,
        MeasuringMode::Bits15FieldA,
        MeasuringMode::Bits16Immediate,
        MeasuringMode::Reflectivity,
    ];

    /// Block D byte of the configuration.
    pub const fn code(self) -> u8 {
        match self {
            MeasuringMode::Bits13FieldsAbDazzle => 0x00,
            MeasuringMode::Bits13Reflector8 => 0x01,
            MeasuringMode::Bits13FieldsAbc => 0x02,
            MeasuringMode::Bits14Reflector4 => 0x03,
            MeasuringMode::Bits14FieldsAb => 0x04,
            MeasuringMode::Bits15Reflector => 0x05,
            MeasuringMode::Bits15FieldA => 0x06,
            MeasuringMode::Bits16Immediate => 0x0F,
            MeasuringMode::Reflectivity => 0x3F,
        }
    }

    /// Inverse of [`MeasuringMode::code`]; reserved codes give `None`.
    pub fn from_code(code: u8) -> Option<MeasuringMode> {
        MeasuringMode::ALL.into_iter().find(|m| m.code() == code)
    }

    /// Number of low bits that carry the distance (or reflectivity).
    pub const fn distance_bits(self) -> u32 {
        match self {
            MeasuringMode::Bits13FieldsAbDazzle
            | MeasuringMode::Bits13Reflector8
            | MeasuringMode::Bits13FieldsAbc => 13,
            MeasuringMode::Bits14Reflector4 | MeasuringMode::Bits14FieldsAb => 14,
            MeasuringMode::Bits15Reflector | MeasuringMode::Bits15FieldA => 15,
            MeasuringMode::Bits16Immediate | MeasuringMode::Reflectivity => 16,
        }
    }

    /// Mask of the distance bits of a value word.
    pub const fn distance_mask(self) -> u16 {
        match self.distance_bits() {
            16 => 0xFFFF,
            bits => (1u16 << bits) - 1,
        }
    }

    /// Whether the value words are distances (every mode but `3F`).
    pub const fn is_distance(self) -> bool {
        !matches!(self, MeasuringMode::Reflectivity)
    }

    /// The all-ones value of the field special codes count down from.
    const fn special_base(self) -> Option<u16> {
        match self {
            MeasuringMode::Reflectivity => None,
            MeasuringMode::Bits16Immediate => Some(0x7FFF),
            _ => Some(self.distance_mask()),
        }
    }

    /// The raw distance field that stands for `code` in this mode.
    pub const fn special_value(self, code: SpecialCode) -> Option<u16> {
        match self.special_base() {
            Some(base) => Some(base - code.offset_below_all_ones()),
            None => None,
        }
    }

    /// The special code a masked distance field stands for, if any.
    pub fn special_code(self, distance_field: u16) -> Option<SpecialCode> {
        let base = self.special_base()?;
        let below = base.checked_sub(distance_field)?;
        SpecialCode::ALL
            .into_iter()
            .find(|c| c.offset_below_all_ones() == below)
    }

    /// Largest real distance the mode can report (raw units): just below the
    /// "above maximum" code. Values between it and the all-ones code that are
    /// not special codes are never sent by a healthy sensor.
    pub const fn max_distance(self) -> Option<u16> {
        match self.special_value(SpecialCode::AboveMaximum) {
            Some(above) => Some(above - 1),
            None => None,
        }
    }

    /// The flag bits of `value` as this mode defines them.
    pub fn flags(self, value: u16) -> ValueFlags {
        let bit = |n: u32| value & (1 << n) != 0;
        match self {
            MeasuringMode::Bits13FieldsAbDazzle => ValueFlags::Fields {
                a: bit(13),
                b: bit(14),
                c: false,
                dazzle: bit(15),
            },
            MeasuringMode::Bits13Reflector8 => ValueFlags::ReflectorLevel((value >> 13) as u8),
            MeasuringMode::Bits13FieldsAbc => ValueFlags::Fields {
                a: bit(13),
                b: bit(14),
                c: bit(15),
                dazzle: false,
            },
            MeasuringMode::Bits14Reflector4 => ValueFlags::ReflectorLevel((value >> 14) as u8),
            MeasuringMode::Bits14FieldsAb => ValueFlags::Fields {
                a: bit(14),
                b: bit(15),
                c: false,
                dazzle: false,
            },
            MeasuringMode::Bits15Reflector => ValueFlags::ReflectorLevel((value >> 15) as u8),
            MeasuringMode::Bits15FieldA => ValueFlags::Fields {
                a: bit(15),
                b: false,
                c: false,
                dazzle: false,
            },
            MeasuringMode::Bits16Immediate | MeasuringMode::Reflectivity => ValueFlags::None,
        }
    }
}

/// Serial line speeds the LMS200 supports, with their `20 xx` mode codes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Baud {
    /// 9600 Bd, the power-on default.
    B9600,
    /// 19200 Bd.
    B19200,
    /// 38400 Bd.
    B38400,
    /// 500000 Bd (RS-422 only).
    B500000,
}

impl Baud {
    /// All supported speeds, slowest first.
    pub const ALL: [Baud; 4] = [Baud::B9600, Baud::B19200, Baud::B38400, Baud::B500000];

    /// Bits per second.
    pub const fn bits_per_second(self) -> u32 {
        match self {
            Baud::B9600 => 9600,
            Baud::B19200 => 19200,
            Baud::B38400 => 38400,
            Baud::B500000 => 500_000,
        }
    }

    /// Second byte of the `20 xx` command that switches to this speed.
    pub const fn mode_code(self) -> u8 {
        match self {
            Baud::B9600 => 0x42,
            Baud::B19200 => 0x41,
            Baud::B38400 => 0x40,
            Baud::B500000 => 0x48,
        }
    }

    /// Inverse of [`Baud::mode_code`].
    pub fn from_mode_code(code: u8) -> Option<Baud> {
        Baud::ALL.into_iter().find(|b| b.mode_code() == code)
    }

    /// The speed for a bits-per-second figure, if the LMS200 supports it.
    pub fn from_bits_per_second(bps: u32) -> Option<Baud> {
        Baud::ALL.into_iter().find(|b| b.bits_per_second() == bps)
    }
}

/// Severity in bits 0–2 of the status byte (TL Table 8-1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Severity {
    /// No error.
    Ok,
    /// Information; real sensors send `0x11` routinely, so it is normal.
    Info,
    /// Warning.
    Warning,
    /// Error.
    Error,
    /// Fatal error: the sensor needs a reset.
    Fatal,
    /// Codes 5–7, undefined in TL.
    Undefined(u8),
}

/// The status byte closing every reply (TL §8).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Status(pub u8);

impl Status {
    /// The status a healthy LMS200 sends (`0x10`: ok, LMS type 6).
    pub const OK: Status = Status(0x10);

    /// Severity (bits 0–2).
    pub const fn severity(self) -> Severity {
        match self.0 & 0b111 {
            0 => Severity::Ok,
            1 => Severity::Info,
            2 => Severity::Warning,
            3 => Severity::Error,
            4 => Severity::Fatal,
            other => Severity::Undefined(other),
        }
    }

    /// Device kind bits 3–4 (`0b10` LMS type 6, `0b11` special device).
    pub const fn device_kind_bits(self) -> u8 {
        (self.0 >> 3) & 0b11
    }

    /// Level of the RESTART input (bit 5).
    pub const fn restart_input(self) -> bool {
        self.0 & 0x20 != 0
    }

    /// The sensor flags its measured values as implausible (bit 6).
    pub const fn implausible_values(self) -> bool {
        self.0 & 0x40 != 0
    }

    /// The front screen is polluted (bit 7).
    pub const fn polluted(self) -> bool {
        self.0 & 0x80 != 0
    }

    /// Error or fatal: the reply is still delivered, but the link should act.
    pub const fn needs_attention(self) -> bool {
        matches!(self.severity(), Severity::Error | Severity::Fatal)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may unwrap: a panic is a failure
mod tests {
    use super::*;

    #[test]
    fn variant_counts_and_first_beams() {
        let table = [
            (Variant::Fov100Res100, 101, 4000),
            (Variant::Fov100Res50, 201, 4000),
            (Variant::Fov100Res25, 401, 4000),
            (Variant::Fov180Res100, 181, 0),
            (Variant::Fov180Res50, 361, 0),
        ];
        for (variant, count, first) in table {
            assert_eq!(variant.value_count(), count, "{variant:?}");
            assert_eq!(variant.first_beam_centideg(), first, "{variant:?}");
            assert_eq!(
                Variant::from_wire(variant.fov_deg(), variant.resolution_centideg()),
                Some(variant)
            );
        }
        assert_eq!(Variant::from_wire(180, 25), None);
    }

    #[test]
    fn beam_angles_span_the_field_of_view_symmetrically() {
        let v = Variant::Fov180Res50;
        assert!((v.beam_angle_rad(0) + std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!(v.beam_angle_rad(180).abs() < 1e-12);
        let last = usize::from(v.value_count()) - 1;
        assert!((v.beam_angle_rad(last) - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn special_codes_per_bit_width() {
        use MeasuringMode as M;
        use SpecialCode as S;
        let table = [
            (
                M::Bits13FieldsAbDazzle,
                [8191, 8190, 8189, 8187, 8186, 8183],
            ),
            (
                M::Bits14FieldsAb,
                [16383, 16382, 16381, 16379, 16378, 16375],
            ),
            (M::Bits15FieldA, [32767, 32766, 32765, 32763, 32762, 32759]),
        ];
        for (mode, values) in table {
            for (code, value) in S::ALL.into_iter().zip(values) {
                assert_eq!(mode.special_value(code), Some(value));
                assert_eq!(mode.special_code(value), Some(code));
            }
            assert_eq!(mode.special_code(values[5] - 1), None);
            assert_eq!(mode.max_distance(), Some(values[5] - 1));
        }
        assert_eq!(M::Reflectivity.special_code(0xFFFF), None);
    }

    #[test]
    fn mode_codes_round_trip_and_masks() {
        for mode in MeasuringMode::ALL {
            assert_eq!(MeasuringMode::from_code(mode.code()), Some(mode));
        }
        assert_eq!(MeasuringMode::from_code(0x0A), None);
        assert_eq!(MeasuringMode::Bits13FieldsAbDazzle.distance_mask(), 0x1FFF);
        assert_eq!(MeasuringMode::Bits14Reflector4.distance_mask(), 0x3FFF);
        assert_eq!(MeasuringMode::Bits15Reflector.distance_mask(), 0x7FFF);
        assert_eq!(MeasuringMode::Bits16Immediate.distance_mask(), 0xFFFF);
    }

    #[test]
    fn flags_follow_the_mode_table() {
        let v = 0b1010_0000_0000_0101;
        assert_eq!(
            MeasuringMode::Bits13FieldsAbDazzle.flags(v),
            ValueFlags::Fields {
                a: true,
                b: false,
                c: false,
                dazzle: true
            }
        );
        assert_eq!(
            MeasuringMode::Bits13Reflector8.flags(v),
            ValueFlags::ReflectorLevel(5)
        );
        assert_eq!(
            MeasuringMode::Bits14Reflector4.flags(v),
            ValueFlags::ReflectorLevel(2)
        );
        assert_eq!(
            MeasuringMode::Bits15Reflector.flags(v),
            ValueFlags::ReflectorLevel(1)
        );
        assert_eq!(MeasuringMode::Bits16Immediate.flags(v), ValueFlags::None);
    }

    #[test]
    fn baud_codes() {
        let table = [
            (Baud::B9600, 0x42),
            (Baud::B19200, 0x41),
            (Baud::B38400, 0x40),
            (Baud::B500000, 0x48),
        ];
        for (baud, code) in table {
            assert_eq!(baud.mode_code(), code);
            assert_eq!(Baud::from_mode_code(code), Some(baud));
            assert_eq!(
                Baud::from_bits_per_second(baud.bits_per_second()),
                Some(baud)
            );
        }
    }

    #[test]
    fn status_byte_fields() {
        assert_eq!(Status(0x10).severity(), Severity::Ok);
        assert_eq!(Status(0x11).severity(), Severity::Info);
        assert!(!Status(0x11).needs_attention());
        assert!(Status(0x13).needs_attention());
        assert!(Status(0x14).needs_attention());
        assert_eq!(Status(0x17).severity(), Severity::Undefined(7));
        assert!(Status(0x80).polluted());
        assert!(Status(0x40).implausible_values());
        assert_eq!(Status(0x10).device_kind_bits(), 0b10);
    }
}
