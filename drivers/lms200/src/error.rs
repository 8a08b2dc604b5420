//! Typed errors of the telegram layer.

/// A telegram body (the bytes between LEN and STATUS/CRC) that does not have
/// the structure its command code promises.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ParseError {
    /// The body has the wrong number of data bytes for its code.
    #[error("telegram {code:#04X}: {actual} data bytes, expected {expected}")]
    DataLength {
        /// Command or reply code.
        code: u8,
        /// What the code's layout needs (for variable layouts, the minimum).
        expected: usize,
        /// What the telegram carried.
        actual: usize,
    },
    /// A configuration block that is neither the 32- nor the 34-byte format.
    #[error("configuration block of {0} bytes (expected 32 or 34)")]
    ConfigLength(usize),
    /// A yes/no byte (accepted flag) that is neither 0 nor 1.
    #[error("telegram {code:#04X}: flag byte {value:#04X} is neither 0 nor 1")]
    FlagByte {
        /// Reply code.
        code: u8,
        /// The offending byte.
        value: u8,
    },
    /// A `B0` scan whose count word disagrees with the number of value bytes.
    #[error("scan count word says {count} values but the telegram has {data_bytes} data bytes")]
    ScanCount {
        /// Values announced in bits 0–9 of the count word.
        count: u16,
        /// Data bytes after the reply code.
        data_bytes: usize,
    },
    /// The telegram is empty (no command byte).
    #[error("telegram without a command byte")]
    Empty,
}

/// Why a value cannot be put on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum EncodeError {
    /// The frame would be longer than the LMS200 accepts or sends.
    #[error("telegram of {len} bytes is longer than the {max}-byte maximum")]
    TooLong {
        /// Frame length that would result, STX through CRC.
        len: usize,
        /// The maximum frame length.
        max: usize,
    },
    /// A scan whose count word does not describe its values.
    #[error("scan count word says {count} values but {values} are present")]
    ScanCount {
        /// Values announced in bits 0–9 of the count word.
        count: u16,
        /// Values in the scan.
        values: usize,
    },
}

/// Why a telegram with a valid CRC (or a CRC that was never reached) is not
/// believed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum Implausibility {
    /// The address byte cannot come from this direction (bit 7).
    #[error("address {0:#04X} has the wrong bit 7 for this direction")]
    Address(u8),
    /// The count word's unit bits are the reserved `1x`.
    #[error("scan count word {0:#06X} has reserved unit bits")]
    ReservedUnits(u16),
    /// The count word differs from the configured scan shape.
    #[error("scan count word {actual:#06X}, expected {expected:#06X}")]
    CountWord {
        /// Count word of the configured shape.
        expected: u16,
        /// Count word received.
        actual: u16,
    },
    /// A distance field above the mode's maximum that is no special code.
    #[error("scan value {index} is {value:#06X}, neither a distance nor a special code")]
    Value {
        /// Index of the value in the scan.
        index: u16,
        /// The raw value word.
        value: u16,
    },
    /// The body does not have the layout its code promises.
    #[error("malformed body: {0}")]
    Malformed(ParseError),
}

/// Why bytes were dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DropReason {
    /// The CRC does not match.
    #[error("bad CRC")]
    BadCrc,
    /// LEN below the minimum or above the longest telegram.
    #[error("impossible LEN {len}")]
    ImpossibleLength {
        /// The LEN field.
        len: u16,
    },
    /// A `B0` whose LEN is not the configured scan shape's.
    #[error("scan LEN {actual}, the configured variant expects {expected}")]
    LengthMismatch {
        /// LEN of the configured [`ScanShape`](crate::ScanShape).
        expected: u16,
        /// The LEN field.
        actual: u16,
    },
    /// CRC right but content not believable.
    #[error("implausible telegram: {0}")]
    Implausible(Implausibility),
    /// A telegram cut off: a complete valid telegram starts inside it (the
    /// host interrupted streaming), or it was given up with
    /// [`abandon_incomplete`](crate::Decoder::abandon_incomplete) or
    /// [`clear`](crate::Decoder::clear).
    #[error("truncated telegram")]
    Truncated,
    /// Bytes between telegrams that are neither STX, ACK nor NAK.
    #[error("unexpected bytes between telegrams")]
    UnexpectedByte,
}
