//! Line and sensor faults the emulator can inject, switchable at runtime.
//!
//! Byte faults (garbage, bit flips, drops) hit both directions of the line,
//! as noise on a real cable would: corrupted requests earn a NAK from the
//! sensor, corrupted replies are the driver's problem. All randomness comes
//! from the emulator's seeded [`FaultRng`], so a fault run is reproducible.

use super::prng::FaultRng;

/// Per-byte line faults and sensor misbehaviour. `Default` is a clean line.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FaultConfig {
    /// Probability that a random byte is inserted before a byte on the line.
    pub garbage_per_byte: f64,
    /// Probability that one bit of a byte is flipped.
    ///
    /// Byte faults of every kind are kept at least two bytes apart: damage
    /// to two neighbouring bytes can cancel in the LMS checksum (a flip of
    /// bit k in one byte and bit k+1 in the next always does, protocol notes
    /// §1.3), and a drop next to an inserted byte is such a two-byte change
    /// whenever the inserted value happens to fit, about one time in 256.
    /// No receiver can tell those from a good telegram, so the injected
    /// noise stays within what the checksum is specified to detect.
    pub bit_flip_per_byte: f64,
    /// Probability that a byte is lost.
    pub drop_per_byte: f64,
    /// Answer every Nth valid request (1-based count) with a NAK as if its
    /// checksum had been wrong. `None` or `Some(0)`: never.
    pub nak_every_nth_request: Option<u32>,
}

impl FaultConfig {
    /// True when no byte-level fault is active (fast path).
    pub fn line_is_clean(&self) -> bool {
        self.garbage_per_byte <= 0.0 && self.bit_flip_per_byte <= 0.0 && self.drop_per_byte <= 0.0
    }
}

/// Applies the byte faults of a [`FaultConfig`] to a stream of bytes.
#[derive(Debug, Clone, Default)]
pub(crate) struct LineNoise {
    /// Bytes since the last fault of any kind; faults need at least 2 in
    /// between (see [`FaultConfig::bit_flip_per_byte`]).
    since_fault: usize,
}

/// Counts of injected faults, so tests can check the driver saw them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FaultCounts {
    /// Random bytes inserted.
    pub garbage_bytes: u64,
    /// Bits flipped.
    pub bit_flips: u64,
    /// Bytes dropped.
    pub dropped_bytes: u64,
    /// Valid requests answered with a NAK on purpose.
    pub forced_naks: u64,
}

impl LineNoise {
    /// Passes `input` through the line, appending what arrives to `out`.
    pub fn apply(
        &mut self,
        input: &[u8],
        faults: &FaultConfig,
        rng: &mut FaultRng,
        counts: &mut FaultCounts,
        out: &mut Vec<u8>,
    ) {
        if faults.line_is_clean() {
            out.extend_from_slice(input);
            return;
        }
        for &byte in input {
            self.since_fault = self.since_fault.saturating_add(1);
            if self.since_fault <= 2 {
                out.push(byte);
                continue;
            }
            if rng.chance(faults.garbage_per_byte) {
                out.push(rng.next_u8());
                out.push(byte);
                counts.garbage_bytes += 1;
            } else if rng.chance(faults.drop_per_byte) {
                counts.dropped_bytes += 1;
            } else if rng.chance(faults.bit_flip_per_byte) {
                out.push(byte ^ (1 << rng.below(8)));
                counts.bit_flips += 1;
            } else {
                out.push(byte);
                continue;
            }
            self.since_fault = 0;
        }
    }
}

/// Garbles bytes as a UART at the wrong line speed would: the receiver
/// samples the wrong bit cells, so it sees different byte values, sometimes
/// framing errors (byte lost) and sometimes two bytes where one was sent.
pub(crate) fn garble_wrong_baud(input: &[u8], rng: &mut FaultRng, out: &mut Vec<u8>) {
    for &byte in input {
        match rng.below(8) {
            0 | 1 => {} // framing error: byte lost
            2 => {
                out.push((byte ^ rng.next_u8()) | 0x80);
                out.push(rng.next_u8());
            }
            _ => out.push(byte ^ (rng.next_u8() | 0x01)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clean_line_passes_bytes_unchanged() {
        let mut noise = LineNoise::default();
        let mut rng = FaultRng::new(1);
        let mut counts = FaultCounts::default();
        let mut out = Vec::new();
        noise.apply(
            &[1, 2, 3],
            &FaultConfig::default(),
            &mut rng,
            &mut counts,
            &mut out,
        );
        assert_eq!(out, [1, 2, 3]);
        assert_eq!(counts, FaultCounts::default());
    }

    #[test]
    fn flips_are_never_in_adjacent_bytes() {
        let mut noise = LineNoise::default();
        let mut rng = FaultRng::new(9);
        let mut counts = FaultCounts::default();
        let faults = FaultConfig {
            bit_flip_per_byte: 0.9,
            ..FaultConfig::default()
        };
        let input = vec![0u8; 10_000];
        let mut out = Vec::new();
        noise.apply(&input, &faults, &mut rng, &mut counts, &mut out);
        assert_eq!(out.len(), input.len());
        let flipped: Vec<usize> = out
            .iter()
            .enumerate()
            .filter(|(_, b)| **b != 0)
            .map(|(i, _)| i)
            .collect();
        assert!(flipped.len() > 1000);
        assert!(flipped.windows(2).all(|w| w[1] - w[0] >= 3));
        assert!(out.iter().all(|b| b.count_ones() <= 1));
        assert_eq!(counts.bit_flips as usize, flipped.len());
    }

    #[test]
    fn faults_of_different_kinds_are_never_in_neighbouring_bytes() {
        let mut noise = LineNoise::default();
        let mut rng = FaultRng::new(11);
        let mut counts = FaultCounts::default();
        let faults = FaultConfig {
            garbage_per_byte: 0.3,
            drop_per_byte: 0.3,
            bit_flip_per_byte: 0.9,
            ..FaultConfig::default()
        };
        // Byte by byte (the noise keeps its spacing across calls): a clean
        // byte comes out as itself, a dropped one as nothing, a flipped one
        // changed, and one with garbage before it as two bytes.
        let damaged: Vec<usize> = (0..20_000)
            .filter(|_| {
                let mut piece = Vec::new();
                noise.apply(&[0x00], &faults, &mut rng, &mut counts, &mut piece);
                piece != [0x00]
            })
            .collect();
        assert!(counts.garbage_bytes > 500 && counts.dropped_bytes > 500 && counts.bit_flips > 500);
        assert_eq!(
            damaged.len() as u64,
            counts.garbage_bytes + counts.dropped_bytes + counts.bit_flips
        );
        assert!(damaged.windows(2).all(|w| w[1] - w[0] >= 3));
    }

    #[test]
    fn drops_and_garbage_change_the_length_and_are_counted() {
        let mut noise = LineNoise::default();
        let mut rng = FaultRng::new(5);
        let mut counts = FaultCounts::default();
        let faults = FaultConfig {
            garbage_per_byte: 0.1,
            drop_per_byte: 0.2,
            ..FaultConfig::default()
        };
        let mut out = Vec::new();
        noise.apply(&[0x55; 1000], &faults, &mut rng, &mut counts, &mut out);
        assert!(counts.garbage_bytes > 0 && counts.dropped_bytes > 0);
        assert_eq!(
            out.len() as u64,
            1000 + counts.garbage_bytes - counts.dropped_bytes
        );
    }

    #[test]
    fn wrong_baud_never_passes_a_telegram_intact() {
        let mut rng = FaultRng::new(3);
        let input = [0x02, 0x80, 0x03, 0x00, 0xA0, 0x00, 0x10, 0x16, 0x0A];
        for _ in 0..100 {
            let mut out = Vec::new();
            garble_wrong_baud(&input, &mut rng, &mut out);
            assert_ne!(out, input);
        }
    }
}
