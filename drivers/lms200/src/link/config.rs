//! What the link sets the sensor up for, and how patient it is.

use std::time::Duration;

use crate::{Baud, LMS_PASSWORD, MeasuringMode, Units, Variant};

/// Target set-up and timing of a [`Link`](super::Link).
///
/// Each default says where it comes from; times are host-side and exclude the
/// wire time of the telegrams, which the link adds at the current line speed.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkConfig {
    /// Field of view and resolution. Default 180°/0.5°: the widest view at the
    /// finest resolution the firmware allows over 180° (361 beams, 26.64 ms).
    pub variant: Variant,
    /// Raw range units. Default mm: clsmap maps rooms, and 8.183 m at 1 mm
    /// resolution beats 81.83 m at 1 cm there; use cm for halls and outdoors.
    pub units: Units,
    /// Measuring mode (config block D). Default `00`: 13-bit distances, the
    /// power-on mode of every LMS200, so no EEPROM write is needed for it.
    pub measuring_mode: MeasuringMode,
    /// Line speed while streaming. Default 500 000 Bd, the only rate that
    /// carries every 180°/0.5° scan (37.5 Hz, TL Table 10-17); it needs RS-422
    /// and a UART that does 500 kBd (Linux termios2). Use 38400 (4.2 Hz)
    /// where the adapter cannot.
    pub target_baud: Baud,
    /// Ask for the real-time scan and telegram indices in every `B0` (config
    /// block C bit 1). Default on: they let the link count lost telegrams and
    /// skipped scans, at a cost of 2 bytes per telegram.
    pub real_time_indices: bool,
    /// Line speeds tried by auto-baud, in order, after [`Self::baud_hint`].
    /// Default: 9600 (power-on), 38400, 500 000, 19200 (least used last).
    pub probe_bauds: Vec<Baud>,
    /// The speed the sensor was last seen at, tried first. Default none.
    pub baud_hint: Option<Baud>,
    /// Wait for the `06` after a request has left the host. The sensor sends
    /// it within 60 ms (TL §4.3); default 100 ms leaves margin for USB latency.
    pub ack_timeout: Duration,
    /// Wait for a reply telegram after the ACK, on top of its wire time.
    /// Default 500 ms (MRPT's figure; TL: measured values within 60 ms).
    pub reply_timeout: Duration,
    /// Wait for the `A0` of a mode change (`20 xx`). Default 3 s (TL §2.5:
    /// "mode change up to 3 s").
    pub mode_change_timeout: Duration,
    /// Wait for the `F7` of a configuration write, which goes to EEPROM.
    /// Default 7 s (QM figure, quoted in the protocol notes §2.5).
    pub config_write_timeout: Duration,
    /// Sends of one request before it counts as failed. Default 3
    /// (sicktoolbox, MRPT).
    pub max_tries: u8,
    /// Pause after a NAK (or a lost answer) before resending. TL p24 demands
    /// at least 30 ms; default 30 ms.
    pub resend_delay: Duration,
    /// Pause after the host changed its line speed before talking at the new
    /// rate. Default 100 ms (sicktoolbox 250 ms, MRPT 500 ms; the sensor
    /// switches within its ACK window, so less is enough).
    pub baud_settle: Duration,
    /// No byte for this long while streaming means the sensor went silent;
    /// bytes without a valid scan are tolerated
    /// [`GARBLED_STREAM_FACTOR`](super::GARBLED_STREAM_FACTOR) times longer.
    /// `None` (default): derived from the variant and line speed, see
    /// [`LinkConfig::scan_watchdog_for`].
    pub scan_watchdog: Option<Duration>,
    /// First pause before a re-initialisation attempt; doubles per failed
    /// attempt up to [`Self::reinit_backoff_max`]. Default 100 ms.
    pub reinit_backoff_min: Duration,
    /// Cap of the re-initialisation back-off. Default 5 s (MRPT's round time).
    pub reinit_backoff_max: Duration,
    /// Give up a clean shutdown after this long. Default 3 s.
    pub close_timeout: Duration,
    /// Installation-mode password. Default `SICK_LMS`.
    pub password: [u8; 8],
}

impl Default for LinkConfig {
    fn default() -> Self {
        Self {
            variant: Variant::Fov180Res50,
            units: Units::Mm,
            measuring_mode: MeasuringMode::Bits13FieldsAbDazzle,
            target_baud: Baud::B500000,
            real_time_indices: true,
            probe_bauds: vec![Baud::B9600, Baud::B38400, Baud::B500000, Baud::B19200],
            baud_hint: None,
            ack_timeout: Duration::from_millis(100),
            reply_timeout: Duration::from_millis(500),
            mode_change_timeout: Duration::from_secs(3),
            config_write_timeout: Duration::from_secs(7),
            max_tries: 3,
            resend_delay: Duration::from_millis(30),
            baud_settle: Duration::from_millis(100),
            scan_watchdog: None,
            reinit_backoff_min: Duration::from_millis(100),
            reinit_backoff_max: Duration::from_secs(5),
            close_timeout: Duration::from_secs(3),
            password: LMS_PASSWORD,
        }
    }
}

/// Mirror period of the LMS200: 75 Hz, 13.32 ms per turn (TL §3.4).
pub const MIRROR_TURN: Duration = Duration::from_micros(13_320);

/// Mirror turns that make one complete scan: 1° = 1, 0.5° = 2, 0.25° = 4.
pub const fn turns_per_scan(variant: Variant) -> u32 {
    match variant.resolution_centideg() {
        25 => 4,
        50 => 2,
        _ => 1,
    }
}

/// Time between two complete scans of `variant` (13.32 ms × turns).
pub fn scan_period(variant: Variant) -> Duration {
    MIRROR_TURN * turns_per_scan(variant)
}

/// Bytes of a `B0` telegram for `variant` (STX through CRC).
pub const fn scan_frame_len(variant: Variant, real_time_indices: bool) -> usize {
    // STX ADR LEN(2) CMD COUNT(2) values STATUS CRC(2) [+ 2 indices]
    10 + 2 * variant.value_count() as usize + if real_time_indices { 2 } else { 0 }
}

impl LinkConfig {
    /// The watchdog for the given line speed: the configured one, or four
    /// times the interval at which complete scans can arrive (one scan
    /// period, or more when the telegram takes longer on the wire than a scan
    /// and the sensor skips scans), plus 100 ms for host scheduling.
    pub fn scan_watchdog_for(&self, baud: Baud) -> Duration {
        if let Some(watchdog) = self.scan_watchdog {
            return watchdog;
        }
        let wire = crate::link::timing::wire_time(
            scan_frame_len(self.variant, self.real_time_indices),
            baud,
        );
        let period = scan_period(self.variant);
        // The sensor sends the first scan completed after the line is free.
        let interval = wire + period;
        interval * 4 + Duration::from_millis(100)
    }

    /// Auto-baud order: the hint first, then `probe_bauds`, without repeats.
    pub fn probe_order(&self) -> Vec<Baud> {
        let mut order: Vec<Baud> = Vec::with_capacity(self.probe_bauds.len() + 1);
        for baud in self
            .baud_hint
            .into_iter()
            .chain(self.probe_bauds.iter().copied())
        {
            if !order.contains(&baud) {
                order.push(baud);
            }
        }
        if order.is_empty() {
            order.push(Baud::B9600);
        }
        order
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_lengths_match_the_telegram_listing() {
        let table = [
            (Variant::Fov180Res100, 372, 374),
            (Variant::Fov180Res50, 732, 734),
            (Variant::Fov100Res100, 212, 214),
            (Variant::Fov100Res50, 412, 414),
            (Variant::Fov100Res25, 812, 814),
        ];
        for (variant, plain, indexed) in table {
            assert_eq!(scan_frame_len(variant, false), plain, "{variant:?}");
            assert_eq!(scan_frame_len(variant, true), indexed, "{variant:?}");
        }
    }

    #[test]
    fn probe_order_puts_the_hint_first_without_repeats() {
        let config = LinkConfig {
            baud_hint: Some(Baud::B38400),
            ..LinkConfig::default()
        };
        assert_eq!(
            config.probe_order(),
            [Baud::B38400, Baud::B9600, Baud::B500000, Baud::B19200]
        );
        let empty = LinkConfig {
            probe_bauds: vec![],
            ..LinkConfig::default()
        };
        assert_eq!(empty.probe_order(), [Baud::B9600]);
    }

    #[test]
    fn watchdog_grows_with_wire_time() {
        let config = LinkConfig::default();
        let fast = config.scan_watchdog_for(Baud::B500000);
        let slow = config.scan_watchdog_for(Baud::B9600);
        assert!(slow > fast);
        // At 9600 Bd a 734-byte telegram takes 764.6 ms on the wire.
        assert!(slow > Duration::from_millis(3000));
        let fixed = LinkConfig {
            scan_watchdog: Some(Duration::from_secs(1)),
            ..config
        };
        assert_eq!(fixed.scan_watchdog_for(Baud::B9600), Duration::from_secs(1));
    }
}
