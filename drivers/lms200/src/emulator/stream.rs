//! Streaming: scans completing on the mirror's phase, paced onto the line.
//!
//! While a telegram is on the line the sensor loses the scans completing
//! meanwhile, and it loses the first one completing after the line is free
//! too: TL Table 10-17 counts `ceil(wire time / scan period)` lost scans
//! between two sent ones whenever the wire time exceeds a scan period (one
//! 180°/0.5° scan in 9 at 38400 Bd, 4.2 Hz; one in 30 at 9600), and none
//! when the line keeps up (500 kBd).

use std::time::{Duration, Instant};

use crate::{CountWord, MeasuringMode, RealTimeIndices, Reply, Scan, Units};

use super::scans::{self, SentScan};
use super::wire::{AfterSent, SegmentKind};
use super::{Emulator, MIRROR_TURN, OperatingMode, Power};

impl Emulator {
    /// Enters `mode`; streaming modes start ticking on the mirror phase.
    pub(super) fn set_mode(&mut self, mode: OperatingMode, now: Instant) {
        self.mode = mode;
        self.stream_resumes_at = None;
        self.next_tick = self
            .tick_period()
            .map(|period| self.next_boundary(now, period));
    }

    /// Time between streamed telegrams in the current mode.
    pub(super) fn tick_period(&self) -> Option<Duration> {
        match self.mode {
            OperatingMode::ContinuousAll => Some(self.scan_period()),
            OperatingMode::ContinuousInterlaced => Some(MIRROR_TURN),
            OperatingMode::OnRequest | OperatingMode::Diagnostic => None,
        }
    }

    /// Mirror turns per complete scan: 1° = 1, 0.5° = 2, 0.25° = 4.
    fn turns_per_scan(&self) -> u32 {
        match self.variant.resolution_centideg() {
            25 => 4,
            50 => 2,
            _ => 1,
        }
    }

    pub(super) fn scan_period(&self) -> Duration {
        MIRROR_TURN * self.turns_per_scan()
    }

    /// The first multiple of `period` after the epoch that is later than `now`.
    pub(super) fn next_boundary(&self, now: Instant, period: Duration) -> Instant {
        let since = now.saturating_duration_since(self.epoch).as_nanos();
        let p = period.as_nanos().max(1);
        let k = since / p + 1;
        self.epoch + Duration::from_nanos(u64::try_from(k * p).unwrap_or(u64::MAX))
    }

    /// Mirror turns completed at `at`, mod 256: the real-time scan index.
    fn scan_index(&self, at: Instant) -> u8 {
        let turns = at.saturating_duration_since(self.epoch).as_nanos() / MIRROR_TURN.as_nanos();
        (turns % 256) as u8
    }

    /// A streamed scan completed at `at`: send it if the line is free.
    pub(super) fn on_tick(&mut self, at: Instant) {
        let Some(period) = self.tick_period() else {
            self.next_tick = None;
            return;
        };
        self.next_tick = Some(at + period);
        if self.power != Power::Ready || self.silent_until.is_some_and(|t| at < t) {
            return;
        }
        if !self.tx.is_idle(at) || self.stream_resumes_at.is_some_and(|t| at < t) {
            self.stats.scans_skipped += 1;
            return;
        }
        let partial = self.mode == OperatingMode::ContinuousInterlaced;
        self.queue_scan(at, partial, SegmentKind::Scan);
        self.stream_resumes_at = self
            .tx
            .next_completion(self.baud.bits_per_second())
            .and_then(|done| first_sendable_tick(at, done, period));
    }

    /// Measures and queues a scan that completed at `at` (streamed, or the
    /// answer to `30 01`/`30 08`).
    pub(super) fn queue_scan(&mut self, at: Instant, partial: bool, kind: SegmentKind) {
        let units = self.block.units().unwrap_or(Units::Mm);
        let mode = self
            .block
            .measuring_mode()
            .unwrap_or(MeasuringMode::Bits13FieldsAbDazzle);
        let (angles, raster, window) = if partial {
            let turn = u64::from(self.scan_index(at));
            let rasters = u64::from(self.turns_per_scan());
            // 1° → x.00 only; 0.5° → x.00, x.50; 0.25° → x.00 … x.75.
            let raster = ((turn % rasters) * (4 / rasters)) as u8;
            (scans::partial_scan_angles(raster), raster, MIRROR_TURN / 2)
        } else {
            let sweep = MIRROR_TURN * u32::from(self.variant.fov_deg()) / 360;
            (
                scans::full_scan_angles(self.variant),
                0,
                MIRROR_TURN * (self.turns_per_scan() - 1) + sweep,
            )
        };
        // The whole scan is measured from where the sensor was at mid-sweep,
        // the instant the driver's timestamp model assigns to it.
        let mid_sweep = at.checked_sub(window / 2).unwrap_or(at);
        let time_s = mid_sweep
            .saturating_duration_since(self.epoch)
            .as_secs_f64();
        let values: Vec<u16> = self
            .ranges
            .ranges_m(time_s, &angles)
            .into_iter()
            .map(|r| scans::raw_value(r, units, mode))
            .collect();
        let indices = self.block.real_time_indices().then(|| RealTimeIndices {
            scan: self.scan_index(at),
            telegram: (self.telegram_sequence % 256) as u8,
        });
        let mut scan = Scan::complete(values, units, indices);
        if partial {
            scan.count_word = CountWord::partial(scan.count_word.count(), raster, units);
        }
        self.telegram_sequence += 1;
        self.stats.scans_sent += 1;
        let log = SentScan {
            sequence: self.telegram_sequence,
            values: scan.values.clone(),
            indices,
            partial,
            completed_at: at,
            mid_sweep,
        };
        if self.config.scan_log_capacity > 0 {
            if self.sent_scans.len() >= self.config.scan_log_capacity {
                self.sent_scans.pop_front();
            }
            self.sent_scans.push_back(log);
        }
        self.queue_frame(&Reply::ScanData(scan), 0x80, at, kind, AfterSent::Nothing);
    }
}

/// The first scan completion that can be sent after a telegram queued at
/// `sent` whose last byte leaves at `done`, on a grid of `period` (TL
/// Table 10-17): `None` when the telegram fits in one period.
fn first_sendable_tick(sent: Instant, done: Instant, period: Duration) -> Option<Instant> {
    let wire = done.saturating_duration_since(sent).as_nanos();
    let p = period.as_nanos().max(1);
    if wire <= p {
        return None;
    }
    let lost = wire.div_ceil(p);
    let offset = u64::try_from((lost + 1) * p).ok()?;
    Some(sent + Duration::from_nanos(offset))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emulator::wire::wire_time;

    /// Lost scans between two sent ones, as TL Table 10-17 lists them.
    fn lost(frame_bytes: usize, bps: u32, period_ms: f64) -> u128 {
        let t0 = Instant::now();
        let period = Duration::from_secs_f64(period_ms / 1000.0);
        let done = t0 + wire_time(frame_bytes, bps);
        match first_sendable_tick(t0, done, period) {
            None => 0,
            Some(t) => (t - t0).as_nanos() / period.as_nanos() - 1,
        }
    }

    #[test]
    fn lost_scans_follow_the_telegram_listing() {
        // (frame bytes, scan period ms): 180°/1°, 180°/0.5°, 100°/0.25°.
        let rows = [
            ((372, 13.32), [30, 15, 8, 0]),
            ((732, 26.64), [29, 15, 8, 0]),
            ((812, 53.28), [16, 8, 4, 0]),
        ];
        for ((bytes, period), expected) in rows {
            for (bps, want) in [9600, 19200, 38400, 500_000].into_iter().zip(expected) {
                assert_eq!(lost(bytes, bps, period), want, "{bytes} bytes at {bps} Bd");
            }
        }
    }
}
