//! Streaming: scans out, counters, the scan watchdog.

use std::time::Instant;

use crate::{RealTimeIndices, Scan};

use super::config::turns_per_scan;
use super::event::{Event, ReinitReason, TimedScan};
use super::timers::Timer;
use super::{Link, Phase, timing};

/// How many watchdog periods a line that carries bytes but no valid scan is
/// tolerated before the link starts over.
pub const GARBLED_STREAM_FACTOR: u32 = 8;

impl Link {
    /// Continuous output started: report the set-up and arm the watchdog.
    pub(super) fn on_streaming(&mut self, now: Instant) {
        self.phase = Phase::Streaming;
        self.failures = 0;
        self.last_indices = None;
        self.last_scan_at = Some(now);
        let shape = self.scan_shape();
        let baud = self.host_baud;
        self.event(Event::Connected {
            baud,
            variant: shape.variant,
            units: shape.units,
            device_type: self.device_type.clone(),
            firmware: self.firmware.clone(),
        });
        self.timers.set(
            Timer::ScanWatchdog,
            now + self.config.scan_watchdog_for(baud),
        );
    }

    /// A `B0` arrived; its last byte at `at`.
    pub(super) fn on_scan(&mut self, scan: Scan, at: Instant, now: Instant) {
        match self.phase {
            Phase::Probing { .. } => self.probe_saw_scan(),
            Phase::Streaming => self.deliver_scan(scan, at, now),
            // Scans still draining during set-up or shutdown are expected.
            _ => {}
        }
    }

    fn deliver_scan(&mut self, scan: Scan, at: Instant, now: Instant) {
        let shape = self.scan_shape();
        // The decoder checks the shape; a partial scan cannot match it, but
        // an unconfigured decoder would let one through, so check again.
        if scan.count_word != shape.count_word() {
            self.stats.dropped_frames += 1;
            return;
        }
        if let Some(indices) = scan.indices {
            self.count_index_gaps(indices);
        }
        let frame_len = shape.frame_len();
        let timestamp = timing::scan_timestamp(at, frame_len, self.host_baud, shape.variant);
        self.stats.scans += 1;
        self.last_scan_at = Some(now);
        self.timers.set(
            Timer::ScanWatchdog,
            now + self.config.scan_watchdog_for(self.host_baud),
        );
        self.event(Event::Scan(TimedScan {
            scan,
            timestamp,
            received_at: at,
            variant: shape.variant,
            units: shape.units,
        }));
    }

    /// Telegram index gaps are telegrams lost on the line; scan index gaps
    /// beyond those are scans the sensor measured but could not send.
    fn count_index_gaps(&mut self, indices: RealTimeIndices) {
        if let Some(last) = self.last_indices {
            let telegrams = u64::from(indices.telegram.wrapping_sub(last.telegram));
            let lost = telegrams.saturating_sub(1);
            let turns = u64::from(indices.scan.wrapping_sub(last.scan));
            let per_scan = u64::from(turns_per_scan(self.config.variant));
            let scans = turns / per_scan.max(1);
            self.stats.lost_telegrams += lost;
            self.stats.skipped_scans += scans.saturating_sub(1).saturating_sub(lost);
        }
        self.last_indices = Some(indices);
    }

    /// The scan watchdog expired. A silent line for the watchdog time means
    /// the sensor went away (unplugged, power loss, reset into request mode
    /// at another speed...). A line that still carries bytes but no valid
    /// scan is given [`GARBLED_STREAM_FACTOR`] times longer, since noise
    /// costs scans, not the connection; after that the link starts over
    /// too (the sensor may be streaming at another speed).
    pub(super) fn on_scan_watchdog(&mut self, now: Instant) {
        if self.phase != Phase::Streaming {
            return;
        }
        let watchdog = self.config.scan_watchdog_for(self.host_baud);
        let last_scan = self.last_scan_at.unwrap_or(now);
        let last_bytes = self.last_input_at.map_or(last_scan, |t| t.max(last_scan));
        let silent_at = last_bytes + watchdog;
        let garbled_at = last_scan + watchdog * GARBLED_STREAM_FACTOR;
        if now >= silent_at {
            self.stats.silences += 1;
            self.event(Event::SensorSilent);
            self.reinit_now(ReinitReason::SensorSilent, now);
        } else if now >= garbled_at {
            self.reinit_now(ReinitReason::NoValidScans, now);
        } else {
            self.timers
                .set(Timer::ScanWatchdog, silent_at.min(garbled_at));
        }
    }
}
