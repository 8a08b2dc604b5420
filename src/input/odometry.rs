//! Odometry samples and their interpolation at a scan's time.
//!
//! Bases report odometry at their own rate, not at scan times; the mapper
//! needs the odometry pose at the instant of each scan. Poses between two
//! samples are interpolated linearly (heading along the short arc), which is
//! exact for a constant-velocity straight or turning-in-place motion and
//! within a few millimetres for the 10–50 Hz odometry rates of real bases.

use std::collections::VecDeque;

use crate::geometry::{Pose2, RangeScan};
use thiserror::Error;

use super::ScanRecord;

/// One odometry reading of a track: time (s) and pose in the odometry
/// frame (m, rad). (A base's own readings are `clsmap_base::OdometrySample`.)
#[derive(Debug, Clone, Copy, PartialEq)]
struct Sample {
    t: f64,
    pose: Pose2,
}

/// Why a sample was refused by [`OdometryTrack::push`].
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum OdometryError {
    #[error("odometry time {t} s is not finite")]
    NonFiniteTime { t: f64 },
    #[error("odometry sample at {t} s is older than the previous one at {last} s")]
    OutOfOrder { t: f64, last: f64 },
    #[error("odometry sample at {t} s has a non-finite pose")]
    NonFinitePose { t: f64 },
}

/// A time-ordered run of odometry samples.
#[derive(Debug, Clone, Default)]
pub struct OdometryTrack {
    samples: Vec<Sample>,
}

impl OdometryTrack {
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends a sample; times must not decrease (equal times are kept, the
    /// later sample wins on lookup).
    pub fn push(&mut self, t: f64, pose: Pose2) -> Result<(), OdometryError> {
        if !t.is_finite() {
            return Err(OdometryError::NonFiniteTime { t });
        }
        if !(pose.x.is_finite() && pose.y.is_finite() && pose.theta.is_finite()) {
            return Err(OdometryError::NonFinitePose { t });
        }
        if let Some(last) = self.samples.last()
            && t < last.t
        {
            return Err(OdometryError::OutOfOrder { t, last: last.t });
        }
        self.samples.push(Sample { t, pose });
        Ok(())
    }

    pub fn len(&self) -> usize {
        self.samples.len()
    }

    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Time of the newest sample (s).
    pub fn last_time(&self) -> Option<f64> {
        self.samples.last().map(|s| s.t)
    }

    /// Whether `t` lies within the span of the samples, so that [`Self::at`]
    /// interpolates rather than holds an end value.
    pub fn covers(&self, t: f64) -> bool {
        match (self.samples.first(), self.samples.last()) {
            (Some(a), Some(b)) => a.t <= t && t <= b.t,
            _ => false,
        }
    }

    /// The odometry pose at time `t`: interpolated between the two samples
    /// around `t` (binary search), or the nearest end sample held constant
    /// outside the track (extrapolating a velocity would invent motion the
    /// base never reported). `None` only for an empty track.
    pub fn at(&self, t: f64) -> Option<Pose2> {
        let first = self.samples.first()?;
        // Index of the first sample strictly after t.
        let after = self.samples.partition_point(|s| s.t <= t);
        if after == 0 {
            return Some(first.pose);
        }
        let before = &self.samples[after - 1];
        let Some(next) = self.samples.get(after) else {
            return Some(before.pose);
        };
        let span = next.t - before.t;
        if span <= 0.0 {
            return Some(before.pose);
        }
        Some(before.pose.interpolate(&next.pose, (t - before.t) / span))
    }

    /// Drops samples no longer needed to answer queries at times ≥ `t`:
    /// everything before the last sample at or before `t`. Keeps streaming
    /// readers at constant memory.
    pub fn discard_before(&mut self, t: f64) {
        let after = self.samples.partition_point(|s| s.t <= t);
        if after > 1 {
            self.samples.drain(..after - 1);
        }
    }
}

/// Scans held until the odometry reaches their time, then given out in
/// order with the odometry interpolated there (or with the pose their own
/// record carried). Memory stays bounded by the scans between two
/// odometry samples; samples older than the scan given out are dropped
/// (later scans are later: a reader refuses one out of order).
#[derive(Debug, Clone, Default)]
pub struct ScansAwaitingOdometry {
    /// `None` odometry: still to interpolate.
    pending: VecDeque<(RangeScan, Option<Pose2>)>,
    odometry: OdometryTrack,
}

impl ScansAwaitingOdometry {
    /// Queues a scan; `own` is the odometry its record carried, if any.
    pub fn push_scan(&mut self, scan: RangeScan, own: Option<Pose2>) {
        self.pending.push_back((scan, own));
    }

    /// Adds an odometry sample; see [`OdometryTrack::push`].
    pub fn push_odometry(&mut self, t: f64, pose: Pose2) -> Result<(), OdometryError> {
        self.odometry.push(t, pose)
    }

    /// The front scan, if it can be given out: it has its own pose, or
    /// the odometry has reached its time, or no more odometry will come
    /// (`complete`).
    pub fn pop(&mut self, complete: bool) -> Option<ScanRecord> {
        let (scan, own) = self.pending.front()?;
        let odometry = match own {
            Some(p) => Some(*p),
            None => {
                let reached = self.odometry.last_time().is_some_and(|last| last >= scan.t);
                if !reached && !complete {
                    return None;
                }
                self.odometry.at(scan.t)
            }
        };
        let (scan, _) = self.pending.pop_front()?;
        self.odometry.discard_before(scan.t);
        Some(ScanRecord { scan, odometry })
    }

    /// Whether any odometry sample came.
    pub fn has_odometry(&self) -> bool {
        !self.odometry.is_empty()
    }

    /// Scans waiting.
    pub fn waiting(&self) -> usize {
        self.pending.len()
    }

    /// Drops the scans waiting (the input ended in an error).
    pub fn clear(&mut self) {
        self.pending.clear();
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::geometry::wrap_angle;
    use proptest::prelude::*;

    fn track(samples: &[(f64, Pose2)]) -> OdometryTrack {
        let mut tr = OdometryTrack::new();
        for (t, p) in samples {
            tr.push(*t, *p).unwrap();
        }
        tr
    }

    #[test]
    fn interpolates_between_samples() {
        let tr = track(&[
            (1.0, Pose2::new(0.0, 0.0, 0.0)),
            (2.0, Pose2::new(1.0, 2.0, 0.5)),
            (3.0, Pose2::new(1.0, 2.0, 1.5)),
        ]);
        let p = tr.at(1.25).unwrap();
        assert!((p.x - 0.25).abs() < 1e-12 && (p.y - 0.5).abs() < 1e-12);
        assert!((p.theta - 0.125).abs() < 1e-12);
        let q = tr.at(2.5).unwrap();
        assert!((q.theta - 1.0).abs() < 1e-12);
        assert_eq!(tr.at(2.0).unwrap(), Pose2::new(1.0, 2.0, 0.5));
    }

    #[test]
    fn interpolates_heading_across_pi() {
        let tr = track(&[
            (0.0, Pose2::new(0.0, 0.0, 3.0)),
            (1.0, Pose2::new(0.0, 0.0, -3.0)),
        ]);
        let p = tr.at(0.5).unwrap();
        assert!(wrap_angle(p.theta - std::f64::consts::PI).abs() < 1e-9);
    }

    #[test]
    fn holds_ends_outside_the_track() {
        let a = Pose2::new(1.0, 1.0, 0.1);
        let b = Pose2::new(2.0, 1.0, 0.2);
        let tr = track(&[(1.0, a), (2.0, b)]);
        assert_eq!(tr.at(0.0), Some(a));
        assert_eq!(tr.at(5.0), Some(b));
        assert!(!tr.covers(0.5) && tr.covers(1.5));
        assert_eq!(OdometryTrack::new().at(1.0), None);
    }

    #[test]
    fn refuses_out_of_order_and_non_finite_samples() {
        let mut tr = track(&[(2.0, Pose2::IDENTITY)]);
        assert_eq!(
            tr.push(1.0, Pose2::IDENTITY),
            Err(OdometryError::OutOfOrder { t: 1.0, last: 2.0 })
        );
        assert!(matches!(
            tr.push(f64::NAN, Pose2::IDENTITY),
            Err(OdometryError::NonFiniteTime { .. })
        ));
        // Equal times are accepted; the later one answers.
        let later = Pose2::new(5.0, 0.0, 0.0);
        tr.push(2.0, later).unwrap();
        assert_eq!(tr.at(2.0), Some(later));
    }

    #[test]
    fn discard_keeps_what_later_queries_need() {
        let mut tr = track(&[
            (0.0, Pose2::new(0.0, 0.0, 0.0)),
            (1.0, Pose2::new(1.0, 0.0, 0.0)),
            (2.0, Pose2::new(2.0, 0.0, 0.0)),
            (3.0, Pose2::new(3.0, 0.0, 0.0)),
        ]);
        let before = tr.at(1.5);
        tr.discard_before(1.5);
        assert_eq!(tr.len(), 3);
        assert_eq!(tr.at(1.5), before);
    }

    proptest! {
        /// On a constant-velocity motion, interpolation reproduces the
        /// motion exactly wherever it is sampled.
        #[test]
        fn constant_velocity_is_reproduced(
            vx in -2.0f64..2.0, vy in -2.0f64..2.0, w in -1.0f64..1.0,
            t in 0.0f64..10.0,
        ) {
            let mut tr = OdometryTrack::new();
            for k in 0..=20 {
                let tk = k as f64 * 0.5;
                tr.push(tk, Pose2::new(vx * tk, vy * tk, w * tk)).unwrap();
            }
            let p = tr.at(t).unwrap();
            prop_assert!((p.x - vx * t).abs() < 1e-9);
            prop_assert!((p.y - vy * t).abs() < 1e-9);
            prop_assert!(wrap_angle(p.theta - w * t).abs() < 1e-9);
        }
    }
}
