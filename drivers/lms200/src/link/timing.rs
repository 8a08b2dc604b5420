//! When a scan was measured, from when its last byte arrived.
//!
//! Model (all host clock, no sensor clock exists on the LMS200):
//!
//! ```text
//!  turn 1        turn 2  (0.5°: 2 turns; 0.25°: 4; 1°: 1)
//! |==fov==|.....|==fov==|---- telegram on the wire ----|
//! ^first beam       ^end of sweep                     ^last byte received
//!         <-- window --->
//!     ^ mid-sweep = the scan's timestamp
//! ```
//!
//! - The mirror turns at 75 Hz (13.32 ms per 360°); a field of view of
//!   `fov` degrees is swept in `13.32 ms × fov / 360`. A scan of `n` turns
//!   measures during `window = (n − 1) × 13.32 ms + 13.32 ms × fov / 360`.
//! - The sensor starts the telegram when the sweep ends (TL gives no
//!   processing latency; the emulator follows the same assumption, so a
//!   real sensor's fixed latency would show up as a constant offset).
//! - Each byte takes 10 bit times (8N1): the first byte left
//!   `frame_len × 10 / baud` before the last one arrived.
//!
//! So `timestamp = t_last_byte − wire_time(frame_len) − window / 2`. The
//! middle of the window is the best single time for a scan whose beams were
//! measured over `window`; beam-level motion skew (up to ±window/2,
//! 10 ms at 0.5°) is left to the consumer, which knows the beam order.

use std::time::{Duration, Instant};

use crate::{Baud, Variant};

use super::config::{MIRROR_TURN, turns_per_scan};

/// Time `bytes` bytes take on the wire at `baud` (10 bits per byte).
pub fn wire_time(bytes: usize, baud: Baud) -> Duration {
    let nanos = (bytes as u128) * 10 * 1_000_000_000 / u128::from(baud.bits_per_second());
    Duration::from_nanos(u64::try_from(nanos).unwrap_or(u64::MAX))
}

/// How long the beams of one `variant` scan took to measure.
pub fn measurement_window(variant: Variant) -> Duration {
    let turns = turns_per_scan(variant);
    let sweep = MIRROR_TURN * u32::from(variant.fov_deg()) / 360;
    MIRROR_TURN * (turns - 1) + sweep
}

/// From the middle of the measurement window to the end of the sweep.
pub fn mid_sweep_to_end(variant: Variant) -> Duration {
    measurement_window(variant) / 2
}

/// Host time of the middle of the sweep of a scan whose `frame_len`-byte
/// telegram ended at `last_byte_at`. Saturates at `last_byte_at` if the
/// subtraction would go before the clock's origin.
pub fn scan_timestamp(
    last_byte_at: Instant,
    frame_len: usize,
    baud: Baud,
    variant: Variant,
) -> Instant {
    let back = wire_time(frame_len, baud) + mid_sweep_to_end(variant);
    last_byte_at.checked_sub(back).unwrap_or(last_byte_at)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_per_variant() {
        let us = |v| measurement_window(v).as_micros();
        assert_eq!(us(Variant::Fov180Res100), 6_660);
        assert_eq!(us(Variant::Fov180Res50), 19_980);
        assert_eq!(us(Variant::Fov100Res100), 3_700);
        assert_eq!(us(Variant::Fov100Res50), 17_020);
        assert_eq!(us(Variant::Fov100Res25), 43_660);
    }

    #[test]
    fn timestamp_subtracts_wire_and_half_window() {
        let t0 = Instant::now();
        let end = t0 + Duration::from_secs(1);
        let ts = scan_timestamp(end, 732, Baud::B500000, Variant::Fov180Res50);
        assert_eq!(end - ts, Duration::from_micros(14_640 + 9_990));
        let ts = scan_timestamp(end, 732, Baud::B38400, Variant::Fov180Res50);
        assert_eq!(end - ts, Duration::from_nanos(190_625_000 + 9_990_000));
    }
}
