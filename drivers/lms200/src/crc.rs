//! The SICK LMS2xx telegram checksum (TL §9).
//!
//! Not a Rocksoft-model CRC: the 16-bit register is shifted once per *byte*
//! (not per bit) through the polynomial x^16 + x^15 + x^2 + 1 (0x8005), and
//! then XORed with a 16-bit window made of the previous and the current byte.
//! [`Crc16`] does exactly that, one shift per byte. [`crc16`] computes the
//! same value eight bytes per step with a 256-entry table built at compile
//! time, because decoding throughput is bounded by this loop.
//!
//! It is weak: byte i (k bytes before the end) contributes `b·x^k·(x + x^8)
//! mod G`, so an error `e` in byte i and `e << 1` (= `e·x`) in byte i+1 add
//! the same term twice and cancel (unless byte i+1 is the last one, whose
//! second window never comes). The decoder therefore adds plausibility
//! checks on top of it; the `weakness_*` test pins the pattern.

/// Generator polynomial x^16 + x^15 + x^2 + 1 without the x^16 term.
const POLYNOMIAL: u16 = 0x8005;

/// Streaming form of the checksum, for data that arrives in pieces.
///
/// Feeding the same bytes in any split gives the same result as [`crc16`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Crc16 {
    register: u16,
    previous: u8,
}

impl Crc16 {
    /// A checksum over no bytes yet (register 0, previous byte 0).
    pub const fn new() -> Self {
        Self {
            register: 0,
            previous: 0,
        }
    }

    /// Adds `bytes` to the checksum.
    #[inline]
    pub fn update(&mut self, bytes: &[u8]) {
        let mut register = self.register;
        let mut previous = self.previous;
        for &byte in bytes {
            register = step(register, previous, byte);
            previous = byte;
        }
        self.register = register;
        self.previous = previous;
    }

    /// The checksum of everything fed so far (sent low byte first).
    pub const fn value(&self) -> u16 {
        self.register
    }
}

/// One byte of the checksum: shift once, fold in the polynomial if the top
/// bit fell out, then XOR the (previous, current) byte window.
#[inline(always)]
const fn step(register: u16, previous: u8, byte: u8) -> u16 {
    times_x(register) ^ (((previous as u16) << 8) | byte as u16)
}

/// `h(x)·x^16 mod G` for every byte `h`: multiplies the register by x^8 in
/// one lookup.
const TIMES_X16: [u16; 256] = {
    let mut table = [0u16; 256];
    let mut h = 0;
    while h < 256 {
        let mut register = h as u16;
        let mut shift = 0;
        while shift < 16 {
            register = times_x(register);
            shift += 1;
        }
        table[h] = register;
        h += 1;
    }
    table
};

/// `r·x mod G`.
#[inline(always)]
const fn times_x(register: u16) -> u16 {
    (register << 1) ^ (0u16.wrapping_sub(register >> 15) & POLYNOMIAL)
}

/// `r·x^8 mod G`.
#[inline(always)]
const fn times_x8(register: u16) -> u16 {
    (register << 8) ^ TIMES_X16[(register >> 8) as usize]
}

/// `Σ b_i·x^(7-i)` for eight bytes: each byte shifted one bit less than the
/// one before, XORed together (at most 15 bits, so no reduction needed).
/// Pairwise in a u64: bytes to 9-bit pairs, to 11-bit quads, to 15 bits.
#[inline(always)]
const fn block_term(block: &[u8; 8]) -> u16 {
    let v = u64::from_le_bytes(*block);
    let pairs = ((v & 0x00FF_00FF_00FF_00FF) << 1) ^ ((v >> 8) & 0x00FF_00FF_00FF_00FF);
    let quads = ((pairs & 0x0000_FFFF_0000_FFFF) << 2) ^ ((pairs >> 16) & 0x0000_FFFF_0000_FFFF);
    (((quads & 0xFFFF_FFFF) << 4) ^ (quads >> 32)) as u16
}

/// The checksum of `bytes` in one call (STX through the last byte before the
/// CRC field).
///
/// Eight bytes per step instead of one: unrolling the per-byte recurrence
/// `r' = r·x + (p·x^8 + b)` gives `crc = (x + x^8)·S + b_last (mod G)` with
/// `S = Σ b_j·x^(n-2-j)` over all bytes but the last, and `S` takes eight
/// bytes at a time as `S' = S·x^8 + Σ b_i·x^(7-i)`. Equal to [`Crc16`] on
/// every input (tested against it and a reference).
#[inline]
pub fn crc16(bytes: &[u8]) -> u16 {
    let Some((&last, body)) = bytes.split_last() else {
        return 0;
    };
    let mut sum = 0u16;
    let mut rest = body;
    while let Some((block, tail)) = rest.split_first_chunk::<8>() {
        sum = times_x8(sum) ^ block_term(block);
        rest = tail;
    }
    for &byte in rest {
        sum = times_x(sum) ^ u16::from(byte);
    }
    times_x(sum) ^ times_x8(sum) ^ u16::from(last)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may unwrap: a panic is a failure
mod tests {
    use super::*;
    use crate::test_util::hex;

    /// Checks that the last two bytes of `frame` are the CRC (lo, hi) of the rest.
    fn assert_frame_crc(frame: &[u8]) {
        let (body, crc) = frame.split_at(frame.len() - 2);
        let expected = u16::from_le_bytes([crc[0], crc[1]]);
        assert_eq!(crc16(body), expected, "frame {frame:02X?}");
    }

    /// Every telegram of section 1.3 (rows 1–29) of the protocol notes; the
    /// `06` ACK of row 23 is not part of the telegram.
    fn section_1_3_vectors() -> Vec<Vec<u8>> {
        let zeros21 = " 00".repeat(21);
        vec![
            hex("02 00 01 00 31 15 12"),
            hex("02 00 02 00 20 24 34 08"),
            hex("02 00 02 00 20 25 35 08"),
            hex("02 00 02 00 20 42 52 08"),
            hex("02 00 02 00 20 41 51 08"),
            hex("02 00 02 00 20 40 50 08"),
            hex("02 00 02 00 20 48 58 08"),
            hex("02 00 05 00 3B B4 00 32 00 3B 1F"),
            hex("02 00 05 00 3B B4 00 64 00 97 49"),
            hex("02 00 05 00 3B 64 00 64 00 1D 0F"),
            hex("02 00 05 00 3B 64 00 32 00 B1 59"),
            hex("02 00 05 00 3B 64 00 19 00 E7 72"),
            hex("02 00 0A 00 20 00 53 49 43 4B 5F 4C 4D 53 BE C5"),
            hex("02 00 02 00 30 01 31 18"),
            hex("02 00 01 00 3A 1E 12"),
            hex("02 00 01 00 74 50 12"),
            hex(&format!(
                "02 00 21 00 77 00 00 00 00 00 00 01 00 00 02 02{zeros21} FC 7E"
            )),
            hex(&format!(
                "02 00 21 00 77 00 00 00 00 00 00 00 00 00 02 02{zeros21} E8 72"
            )),
            hex(
                "02 00 23 00 77 00 00 46 00 00 00 01 00 00 02 02 02 00 00 0A 0A 50 64 00 \
                 0A 0A 50 80 00 0A 0A 50 64 00 00 00 00 02 00 7B 4B",
            ),
            hex("02 00 02 00 66 01 9D 4E"),
            hex("02 00 02 00 66 02 9E 4E"),
            hex("02 00 01 00 10 34 12"),
            hex("02 80 03 00 A0 00 10 16 0A"),
            hex("02 81 03 00 A0 00 10 36 1A"),
            hex("02 80 07 00 BB 01 B4 00 32 00 10 03 9D"),
            hex("02 80 02 00 91 10 79 30"),
            hex("02 80 02 00 92 10 7F 33"),
            hex(
                "02 80 17 00 BA 4C 4D 53 32 30 30 3B 53 31 38 30 36 33 3B 56 30 32 2E 31 39 \
                 20 10 85 6A",
            ),
            hex(&format!(
                "02 80 24 00 F4 00 00 70 00 00 04 01 00 00 02 02{zeros21} 02 00 10 36 FE"
            )),
            hex("02 00 03 00 45 01 00 A6 D2"),
            hex("02 00 02 00 41 00 D2 69"),
        ]
    }

    #[test]
    fn every_section_1_3_vector_checks() {
        let vectors = section_1_3_vectors();
        assert_eq!(vectors.len(), 31);
        for frame in &vectors {
            assert_frame_crc(frame);
        }
    }

    #[test]
    fn streaming_matches_one_shot_for_every_split() {
        for frame in section_1_3_vectors() {
            let body = &frame[..frame.len() - 2];
            for split in 0..=body.len() {
                let mut crc = Crc16::new();
                crc.update(&body[..split]);
                crc.update(&body[split..]);
                assert_eq!(crc.value(), crc16(body));
            }
        }
    }

    #[test]
    fn block_form_equals_byte_form_for_every_length() {
        let data: Vec<u8> = (0..300u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
            .collect();
        for len in 0..data.len() {
            let mut streaming = Crc16::new();
            streaming.update(&data[..len]);
            assert_eq!(crc16(&data[..len]), streaming.value(), "length {len}");
        }
    }

    #[test]
    fn check_value_of_123456789() {
        assert_eq!(crc16(b"123456789"), 0xA656);
    }

    #[test]
    fn one_byte_message_is_its_own_checksum() {
        for byte in 0..=255u8 {
            assert_eq!(crc16(&[byte]), u16::from(byte));
        }
    }

    #[test]
    fn empty_message_is_zero() {
        assert_eq!(crc16(&[]), 0);
        assert_eq!(Crc16::new().value(), 0);
    }

    #[test]
    fn section_5_real_scan_crc_is_consistent_with_its_tail() {
        // Section 5 gives the real 180°/0.5° scan only by its head and tail;
        // the CRC (0x4764, bytes `64 47`) closes the telegram after status 0x10.
        // We can check the head fields and that the quoted CRC bytes are the
        // little-endian form of the quoted value.
        let head = hex("02 80 D6 02 B0 69 41");
        assert_eq!(u16::from_le_bytes([head[2], head[3]]), 726);
        assert_eq!(u16::from_le_bytes([head[5], head[6]]) & 0x03FF, 361);
        assert_eq!(u16::from_le_bytes([0x64, 0x47]), 0x4764);
    }

    /// Documents the weakness: bit 0 of byte i plus bit 1 of byte i+1 is an
    /// error pattern the checksum never sees.
    #[test]
    fn weakness_bit0_then_bit1_of_next_byte_is_not_detected() {
        let frame = hex("02 80 07 00 BB 01 B4 00 32 00 10 03 9D");
        let body = &frame[..frame.len() - 2];
        let good = crc16(body);
        // Every pair except the one ending on the last byte, which lacks the
        // following window that would cancel it.
        for i in 0..body.len() - 2 {
            let mut corrupted = body.to_vec();
            corrupted[i] ^= 0x01;
            corrupted[i + 1] ^= 0x02;
            assert_eq!(crc16(&corrupted), good, "pattern at byte {i}");
        }
        let last = body.len() - 2;
        let mut corrupted = body.to_vec();
        corrupted[last] ^= 0x01;
        corrupted[last + 1] ^= 0x02;
        assert_ne!(crc16(&corrupted), good);
        // A single flipped bit is always caught.
        for i in 0..body.len() {
            for bit in 0..8 {
                let mut corrupted = body.to_vec();
                corrupted[i] ^= 1 << bit;
                assert_ne!(crc16(&corrupted), good, "bit {bit} of byte {i}");
            }
        }
    }
}
