//! A base that plays back recorded odometry, for running the daemon on logs.
//!
//! Playback is anchored at the first time the replay learns the daemon's
//! clock, i.e. the first [`BaseAdapter::advance`], [`BaseAdapter::command`] or
//! [`BaseAdapter::stop`] call: the first recorded sample maps to that `now`
//! and the recording then runs in real time (sample `i` becomes available at
//! `now₀ + (tᵢ − t₀)`). Returned samples carry that shifted time, so they share
//! the daemon's clock. Before the anchor, [`BaseAdapter::odometry`] returns
//! `None`.
//!
//! A recorded robot cannot be driven: commands are accepted and ignored, and
//! [`BaseAdapter::health`] says so once a non-zero velocity was commanded.

use crate::adapter::{BaseAdapter, BaseError, Health, OdometrySample};
use crate::kinematics::Twist;

/// Why a recording cannot be replayed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReplayError {
    /// The recording holds no samples.
    #[error("replay: the recording holds no odometry samples")]
    Empty,
    /// A sample has a non-finite time or pose component.
    #[error("replay: sample {index} has a non-finite time or pose")]
    NonFinite {
        /// Index of the offending sample.
        index: usize,
    },
    /// A sample is older than the one before it.
    #[error("replay: sample {index} at {t} s is earlier than sample {} at {previous} s", index - 1)]
    Backwards {
        /// Index of the offending sample (≥ 1).
        index: usize,
        /// Its time, s.
        t: f64,
        /// Time of the sample before it, s.
        previous: f64,
    },
}

/// Plays back recorded odometry in real time on the daemon's clock.
#[derive(Debug, Clone)]
pub struct ReplayBase {
    samples: Vec<OdometrySample>,
    /// Daemon time the first sample maps to, s; `None` until anchored.
    anchor: Option<f64>,
    /// Latest daemon time seen, s.
    now: Option<f64>,
    /// Index of the first sample not yet returned or skipped.
    next: usize,
    skipped: u64,
    commands_ignored: bool,
}

impl ReplayBase {
    /// Validates `samples` (non-empty, all finite, times non-decreasing).
    ///
    /// # Errors
    /// [`ReplayError`] naming the first offending sample.
    pub fn new(samples: Vec<OdometrySample>) -> Result<Self, ReplayError> {
        if samples.is_empty() {
            return Err(ReplayError::Empty);
        }
        for (index, s) in samples.iter().enumerate() {
            if ![s.t, s.pose.x, s.pose.y, s.pose.theta]
                .iter()
                .all(|v| v.is_finite())
            {
                return Err(ReplayError::NonFinite { index });
            }
            if index > 0 {
                let previous = samples[index - 1].t;
                if s.t < previous {
                    return Err(ReplayError::Backwards {
                        index,
                        t: s.t,
                        previous,
                    });
                }
            }
        }
        Ok(Self {
            samples,
            anchor: None,
            now: None,
            next: 0,
            skipped: 0,
            commands_ignored: false,
        })
    }

    /// Moves the playback clock to `now` (s, daemon clock). The first call
    /// anchors playback; non-finite times and times that do not move forward
    /// are ignored.
    pub fn advance(&mut self, now: f64) {
        if !now.is_finite() {
            return;
        }
        match self.now {
            None => {
                self.anchor = Some(now);
                self.now = Some(now);
            }
            Some(t) if now > t => self.now = Some(now),
            Some(_) => {}
        }
    }

    /// Daemon time the first recorded sample maps to, s (`None` before the
    /// first `advance`/`command`/`stop`).
    #[must_use]
    pub fn anchor(&self) -> Option<f64> {
        self.anchor
    }

    /// Samples passed over because a newer one was already due when
    /// [`BaseAdapter::odometry`] was called.
    #[must_use]
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    /// Samples not yet returned or skipped.
    #[must_use]
    pub fn remaining(&self) -> usize {
        self.samples.len() - self.next
    }

    /// True once every sample was returned or skipped.
    #[must_use]
    pub fn finished(&self) -> bool {
        self.next >= self.samples.len()
    }

    /// Length of the recording (last minus first sample time), s.
    #[must_use]
    pub fn duration(&self) -> f64 {
        match (self.samples.first(), self.samples.last()) {
            (Some(a), Some(b)) => b.t - a.t,
            _ => 0.0,
        }
    }
}

impl BaseAdapter for ReplayBase {
    fn advance(&mut self, now: f64) {
        ReplayBase::advance(self, now);
    }

    fn odometry(&mut self) -> Option<OdometrySample> {
        let (anchor, now) = (self.anchor?, self.now?);
        let t0 = self.samples.first()?.t;
        // Compare elapsed times so the first sample is due exactly at the anchor.
        let elapsed = now - anchor;
        let due = self.samples[self.next..]
            .iter()
            .take_while(|s| s.t - t0 <= elapsed)
            .count();
        if due == 0 {
            return None;
        }
        let index = self.next + due - 1;
        self.skipped += (due - 1) as u64;
        self.next = index + 1;
        let s = self.samples[index];
        Some(OdometrySample {
            t: anchor + (s.t - t0),
            pose: s.pose,
        })
    }

    fn command(&mut self, twist: Twist, now: f64) -> Result<(), BaseError> {
        self.advance(now);
        if !twist.is_finite() {
            return Err(BaseError::InvalidCommand(format!(
                "non-finite twist {twist:?} (replay: ignored)"
            )));
        }
        if twist != Twist::ZERO {
            self.commands_ignored = true;
        }
        Ok(())
    }

    fn stop(&mut self, now: f64) -> Result<(), BaseError> {
        self.advance(now);
        Ok(())
    }

    fn health(&self) -> Health {
        if self.finished() {
            Health::Failed("replay finished".to_owned())
        } else if self.commands_ignored {
            Health::Degraded("replay: commands are ignored".to_owned())
        } else {
            Health::Ok
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::kinematics::BasePose;

    fn sample(t: f64, x: f64) -> OdometrySample {
        OdometrySample {
            t,
            pose: BasePose::new(x, -x, 0.1 * x),
        }
    }

    /// Samples every 0.1 s from t = 100 s, x = index.
    fn recording(n: usize) -> Vec<OdometrySample> {
        (0..n)
            .map(|i| sample(100.0 + 0.1 * i as f64, i as f64))
            .collect()
    }

    #[test]
    fn rejects_bad_recordings_naming_the_index() {
        assert_eq!(ReplayBase::new(Vec::new()).unwrap_err(), ReplayError::Empty);

        let mut r = recording(5);
        r[3].pose.y = f64::NAN;
        assert_eq!(
            ReplayBase::new(r).unwrap_err(),
            ReplayError::NonFinite { index: 3 }
        );
        let mut r = recording(5);
        r[0].t = f64::INFINITY;
        assert_eq!(
            ReplayBase::new(r).unwrap_err(),
            ReplayError::NonFinite { index: 0 }
        );

        let mut r = recording(5);
        r[2].t = 100.05;
        let e = ReplayBase::new(r).unwrap_err();
        assert!(
            matches!(e, ReplayError::Backwards { index: 2, t, previous } if t == 100.05 && previous == 100.1),
            "{e:?}"
        );
        let text = e.to_string();
        assert!(
            text.contains("sample 2") && text.contains("sample 1"),
            "{text}"
        );

        // Equal times are not backwards.
        let mut r = recording(3);
        r[2].t = r[1].t;
        assert!(ReplayBase::new(r).is_ok());
    }

    #[test]
    fn anchored_at_first_advance_and_played_in_real_time() {
        let mut b = ReplayBase::new(recording(10)).unwrap();
        assert_eq!(b.odometry(), None, "nothing before the anchor");
        assert_eq!(b.anchor(), None);
        assert!((b.duration() - 0.9).abs() < 1e-9);

        b.advance(5000.3);
        assert_eq!(b.anchor(), Some(5000.3));
        let s = b.odometry().unwrap();
        assert_eq!(s.t, 5000.3, "first sample maps exactly to the anchor");
        assert_eq!(s.pose, recording(10)[0].pose);
        assert_eq!(b.odometry(), None, "a sample is returned once");

        b.advance(5000.35);
        assert_eq!(b.odometry(), None, "sample 1 is due at +0.1 s");
        b.advance(5000.41);
        let s = b.odometry().unwrap();
        assert_eq!(s.pose.x, 1.0);
        assert!((s.t - 5000.4).abs() < 1e-9, "{}", s.t);
        assert_eq!(b.skipped(), 0);
        assert_eq!(b.remaining(), 8);
    }

    #[test]
    fn newest_due_sample_wins_and_skips_are_counted() {
        let mut b = ReplayBase::new(recording(10)).unwrap();
        b.advance(0.0);
        b.advance(0.55); // samples 0..=5 are due
        let s = b.odometry().unwrap();
        assert_eq!(s.pose.x, 5.0);
        assert_eq!(b.skipped(), 5);
        assert_eq!(b.odometry(), None);
        b.advance(0.2); // backwards: ignored
        b.advance(f64::NAN);
        assert_eq!(b.odometry(), None);
        b.advance(0.61);
        assert_eq!(b.odometry().unwrap().pose.x, 6.0);
        assert_eq!(b.skipped(), 5);
    }

    #[test]
    fn finishes_after_the_last_sample() {
        let mut b = ReplayBase::new(recording(3)).unwrap();
        b.stop(10.0).unwrap(); // anchors like advance
        assert_eq!(b.anchor(), Some(10.0));
        assert_eq!(b.odometry().unwrap().pose.x, 0.0);
        assert_eq!(b.health(), Health::Ok);
        b.advance(10.15);
        assert_eq!(b.odometry().unwrap().pose.x, 1.0);
        assert_eq!(b.health(), Health::Ok, "one sample still to come");
        b.advance(10.25);
        let last = b.odometry().unwrap();
        assert_eq!(last.pose.x, 2.0);
        assert!((last.t - 10.2).abs() < 1e-9);
        assert!(b.finished());
        assert_eq!(b.health(), Health::Failed("replay finished".to_owned()));
        b.advance(20.0);
        assert_eq!(b.odometry(), None);
    }

    #[test]
    fn trait_advance_drives_playback() {
        let mut b: Box<dyn BaseAdapter + Send> = Box::new(ReplayBase::new(recording(3)).unwrap());
        b.advance(2.0);
        assert_eq!(b.odometry().unwrap().t, 2.0);
        b.advance(2.1);
        assert_eq!(b.odometry().unwrap().pose.x, 1.0);
    }

    #[test]
    fn commands_are_accepted_and_ignored() {
        let mut b: Box<dyn BaseAdapter + Send> = Box::new(ReplayBase::new(recording(4)).unwrap());
        b.command(Twist::ZERO, 1.0).unwrap();
        b.stop(1.0).unwrap();
        assert_eq!(b.health(), Health::Ok, "zero commands do not degrade");
        assert!(matches!(
            b.command(Twist::new(f64::NAN, 0.0, 0.0), 1.0),
            Err(BaseError::InvalidCommand(_))
        ));
        assert_eq!(b.health(), Health::Ok);
        b.command(Twist::new(0.0, 0.0, 0.2), 1.02).unwrap();
        assert_eq!(
            b.health(),
            Health::Degraded("replay: commands are ignored".to_owned())
        );
        // The command anchored the clock at 1.0 s; odometry is not affected.
        let s = b.odometry().unwrap();
        assert_eq!((s.t, s.pose.x), (1.0, 0.0));
    }
}
