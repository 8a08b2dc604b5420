//! The pose prediction from odometry: time alignment, frozen odometry, and
//! the covariance of the prediction.
//!
//! Logs show odometry freezing for several scans and then jumping by the
//! motion of the whole gap (CSAIL at 68.5 s, 170.3 s and 337.2 s: four
//! scans of unchanged odometry, then up to 0.9 m and 50° at once). A
//! reading identical to the previous one is therefore not taken as "no
//! motion": such scans, and scans without odometry, are predicted at
//! constant velocity with the no-odometry noise (but for odometry that
//! had come to rest before it repeated itself: a robot standing still).
//! When odometry moves
//! again, either localization tracked the robot through the whole gap —
//! then the tracked pose is kept and the odometry merely re-anchored — or
//! it did not, and the odometry increment since the last fresh scan is
//! applied from that scan's pose, with the noise of the missed scans
//! added, so no motion is counted twice or lost.

use crate::geometry::{Pose2, wrap_angle};
use crate::input::OdometryTrack;
use crate::pipeline::config::OdometryNoise;
use nalgebra::Matrix3;

/// Covariance of a pose (x, y, θ; m², m·rad, rad²).
pub type Covariance = [[f64; 3]; 3];

/// The odometry to use for one scan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum OdometryReading {
    /// No odometry, or odometry unchanged since the previous scan.
    Stale,
    /// Odometry at the (shifted) scan time, interpolated across a freeze:
    /// it holds part of a lumped jump.
    Lumped(Pose2),
    /// Odometry at the (shifted) scan time from regularly moving samples.
    Fresh(Pose2),
}

/// Turns each scan's logged odometry into an [`OdometryReading`]: drops
/// unchanged samples and, with a time offset, interpolates the remaining
/// ones at the scan time plus the offset.
#[derive(Debug, Default)]
pub struct OdometryFeed {
    offset: f64,
    /// Learns the offset from the localized scans, when enabled.
    lag: Option<LagFit>,
    /// Samples that moved, by scan time.
    track: OdometryTrack,
    last_raw: Option<Pose2>,
    /// Whether samples were unchanged since the last moving one.
    in_gap: bool,
    /// Time of the first moving sample after a freeze: interpolation
    /// before it spreads the lumped jump.
    lump_until: Option<f64>,
    /// Whether a sample equal to the previous one means the robot stood
    /// still (a live base whose samples carry their own times) rather than
    /// frozen odometry (a log's repeated value).
    unchanged_is_standstill: bool,
}

impl OdometryFeed {
    /// `offset` (s) is added to scan times to read the odometry; only
    /// offsets ≤ 0 can be honoured while streaming (a positive one holds
    /// the newest sample).
    pub fn new(offset: f64) -> Self {
        OdometryFeed {
            offset,
            ..Self::default()
        }
    }

    /// The same feed, learning its offset within `[−max_lag, 0]` s (see
    /// [`Self::localized`]); `max_lag` 0 keeps it as given.
    pub fn learning(mut self, max_lag: f64) -> Self {
        self.lag = (max_lag > 0.0).then(|| LagFit::new(max_lag));
        self
    }

    /// The offset (s) now added to scan times to read the odometry.
    pub fn offset(&self) -> f64 {
        self.offset
    }

    /// Tells the feed the scan it read last, at `t`, was localized at
    /// heading `theta` (rad) from a fresh reading: with the localized scan
    /// before it, one more pair for the lag fit, and the offset becomes
    /// the fit's lag once the pairs have turned enough.
    pub fn localized(&mut self, t: f64, theta: f64) {
        let Some(lag) = &mut self.lag else {
            return;
        };
        if let Some(best) = lag.pair(&self.track, t, theta) {
            self.offset = best;
        }
    }

    /// Tells the feed the scan it read last was not localized, or not from
    /// a fresh reading: the lag fit's next pair starts afresh.
    pub fn unlocalized(&mut self) {
        if let Some(lag) = &mut self.lag {
            lag.last_fix = None;
        }
    }

    /// Forgets every sample: the odometry starts over in a new frame (a
    /// base reconnected after a restart), keeping the offset and the
    /// standstill rule.
    pub fn restart(&mut self) {
        *self = OdometryFeed {
            offset: self.offset,
            lag: self.lag.take().map(LagFit::restarted),
            unchanged_is_standstill: self.unchanged_is_standstill,
            ..OdometryFeed::default()
        };
    }

    /// Takes an unchanged sample as standing still, not as frozen
    /// odometry: right for a live base polled for fresh, timestamped
    /// samples (a stream that stops delivering gives no reading at all).
    pub fn trust_unchanged(&mut self, yes: bool) {
        self.unchanged_is_standstill = yes;
    }

    /// The reading for a scan at `t` (s) whose record carries `raw`.
    pub fn reading(&mut self, t: f64, raw: Option<Pose2>) -> OdometryReading {
        let Some(raw) = raw else {
            return OdometryReading::Stale;
        };
        if self.last_raw == Some(raw) && !self.unchanged_is_standstill {
            self.in_gap = true;
            if let Some(lag) = &mut self.lag {
                lag.frozen_at = t;
            }
            return OdometryReading::Stale;
        }
        self.last_raw = Some(raw);
        // An out-of-order time restarts the track rather than failing.
        if self.track.push(t, raw).is_err() {
            self.track = OdometryTrack::new();
            self.lump_until = None;
            if self.track.push(t, raw).is_err() {
                return OdometryReading::Stale;
            }
        }
        if std::mem::take(&mut self.in_gap) {
            self.lump_until = Some(t);
        }
        let shifted = t + self.offset.min(0.0);
        let Some(pose) = self.track.at(shifted) else {
            return OdometryReading::Stale;
        };
        // The lag fit reads the odometry back to its pair's first scan.
        let keep = match &self.lag {
            Some(lag) => shifted.min(t - LAG_MAX_PAIR - lag.max),
            None => shifted,
        };
        self.track.discard_before(keep);
        match self.lump_until {
            Some(end) if shifted < end => OdometryReading::Lumped(pose),
            _ => {
                self.lump_until = None;
                OdometryReading::Fresh(pose)
            }
        }
    }
}

/// Steps (s) between the odometry lags the fit compares.
const LAG_STEP: f64 = 0.01;
/// Localized turning (rad) over the fitted pairs before a lag is taken:
/// driving straight, every lag fits alike, and the first turns' fits
/// scatter (2 rad: CSAIL's first choices ranged over 0.1–0.3 s).
const LAG_EVIDENCE: f64 = 6.0;
/// A pair's heading misfit (rad) counts at most this much: a wrong fix
/// must not pull the lag.
const LAG_CLIP: f64 = 0.1;
/// Longest time (s) between the two scans of a pair.
const LAG_MAX_PAIR: f64 = 2.0;
/// The lag taken is the shortest whose misfit is within this share of the
/// best one's. Between scans far apart the odometry is interpolated over
/// the whole gap, and a longer lag then also smooths a weaving path: the
/// best fit lies 0.05–0.1 s beyond the lag the dense log shows (CSAIL
/// thinned to 0.5 m or 0.5 rad: 0.18 s against 0.12 s), and read 0.18 s
/// back that log lost its map (1 m of relation error). With 3 % every
/// thinned CSAIL log driven forwards learns 0.09–0.13 s, as the whole log
/// does; with none, three of them lost their maps.
const LAG_TOLERANCE: f64 = 0.03;

/// The fit of the scans' lag behind the odometry: for each candidate
/// offset, how far the heading steps between consecutive localized scans
/// miss the odometry's heading steps read that much earlier.
///
/// A scan is stamped when its telegram has arrived, a sweep and a transfer
/// after the light left (an LMS200 needs 0.19 s for 361 readings at
/// 38.4 kBd), and a base's odometry when it is read: the odometry then
/// runs ahead of the scans, most visibly in turns. Read at the scan's
/// stamp, CSAIL's odometry turns 10–30 % off in a fast turn's scans;
/// between scans thinned to 0.3–1.5 m or 0.3–0.6 rad apart that left the
/// heading to the lines alone, and some of those logs lost their maps.
/// Offsets are ≤ 0 only: a later reading would hold each scan until the
/// next odometry arrived.
#[derive(Debug, Clone)]
struct LagFit {
    /// Longest lag tried (s).
    max: f64,
    /// Clipped squared misfit (rad²) summed over the pairs, per candidate
    /// offset `−k × LAG_STEP`.
    costs: Vec<f64>,
    /// Localized turning (rad) summed over the pairs.
    turned: f64,
    /// The last localized scan read fresh: time (s) and heading (rad).
    last_fix: Option<(f64, f64)>,
    /// Time (s) of the last frozen odometry sample: pairs reading the
    /// odometry across it are left out.
    frozen_at: f64,
}

impl LagFit {
    fn new(max: f64) -> LagFit {
        let candidates = (max / LAG_STEP).round() as usize + 1;
        LagFit {
            max,
            costs: vec![0.0; candidates],
            turned: 0.0,
            last_fix: None,
            frozen_at: f64::NEG_INFINITY,
        }
    }

    /// The fit so far, with no pair open: the odometry starts over.
    fn restarted(self) -> LagFit {
        LagFit {
            last_fix: None,
            frozen_at: f64::NEG_INFINITY,
            ..self
        }
    }

    /// Adds the pair from the last fix to the fix at `t`, heading `theta`,
    /// reading the odometry from `track`; then the lag to take, once the
    /// pairs have turned [`LAG_EVIDENCE`].
    fn pair(&mut self, track: &OdometryTrack, t: f64, theta: f64) -> Option<f64> {
        let (t0, theta0) = self.last_fix.replace((t, theta))?;
        let earliest = t0 - self.max;
        if !(t > t0 && t - t0 <= LAG_MAX_PAIR)
            || self.frozen_at >= earliest
            || !(track.covers(earliest) && track.covers(t))
        {
            return None;
        }
        let step = wrap_angle(theta - theta0);
        // The track covers the pair's whole span, so every read is there.
        let heading = |s: f64| track.at(s).map_or(0.0, |p| p.theta);
        for (k, cost) in self.costs.iter_mut().enumerate() {
            let lag = -(k as f64) * LAG_STEP;
            let odometry_step = wrap_angle(heading(t + lag) - heading(t0 + lag));
            let miss = wrap_angle(step - odometry_step).abs().min(LAG_CLIP);
            *cost += miss * miss;
        }
        self.turned += step.abs();
        if self.turned < LAG_EVIDENCE {
            return None;
        }
        let best = self.costs.iter().copied().fold(f64::INFINITY, f64::min);
        let k = self
            .costs
            .iter()
            .position(|&c| c <= best * (1.0 + LAG_TOLERANCE))?;
        Some(-(k as f64) * LAG_STEP)
    }
}

/// The last scan that had usable odometry, with its final estimate.
#[derive(Debug, Clone, Copy)]
struct Anchor {
    /// Time of the scan it was taken at (s).
    t: f64,
    odometry: Pose2,
    pose: Pose2,
    cov: Covariance,
    /// Scans since whose odometry was stale (or only partly lumped).
    stale_scans: usize,
    /// Whether every one of those scans was localized.
    gap_tracked: bool,
}

/// A prediction and what the predictor needs to know about it afterwards.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prediction {
    pub pose: Pose2,
    pub cov: Covariance,
    /// Whether the prediction rests on odometry (not constant velocity).
    pub from_odometry: bool,
}

/// How much worse the odometry's heading is than its noise model says,
/// learnt from the scans localization corrected: the running mean of the
/// squared heading corrections over the running mean of the variances the
/// model predicted for them. A model that fits gives about 1; logged
/// odometry whose heading lags in turns gave several times that, and its
/// too-narrow gates then let no line match.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadingFit {
    squared_error: f64,
    model_variance: f64,
    samples: usize,
}

impl HeadingFit {
    /// Weight of the newest scan in the running means: about the last 30.
    const RATE: f64 = 1.0 / 30.0;
    /// Scans before the fit is used.
    const WARM_UP: usize = 10;
    /// One correction counts as at most this many model σ (a wrong fix
    /// should not widen every later gate by itself).
    const CLIP_SIGMAS: f64 = 5.0;

    const fn new() -> Self {
        HeadingFit {
            squared_error: 0.0,
            model_variance: 0.0,
            samples: 0,
        }
    }

    fn observe(&mut self, error: f64, model_variance: f64) {
        if !(error.is_finite() && model_variance.is_finite() && model_variance > 0.0) {
            return;
        }
        let e2 = (error * error).min(Self::CLIP_SIGMAS * Self::CLIP_SIGMAS * model_variance);
        let k = if self.samples == 0 { 1.0 } else { Self::RATE };
        self.squared_error += k * (e2 - self.squared_error);
        self.model_variance += k * (model_variance - self.model_variance);
        self.samples += 1;
    }

    /// Factor (≥ 1, ≤ `max`) on the model's heading σ.
    pub fn sigma_scale(&self, max: f64) -> f64 {
        if self.samples < Self::WARM_UP || self.model_variance <= 0.0 {
            return 1.0;
        }
        (self.squared_error / self.model_variance)
            .sqrt()
            .clamp(1.0, max.max(1.0))
    }
}

impl Default for HeadingFit {
    fn default() -> Self {
        Self::new()
    }
}

/// The odometry's systematic errors, learnt from the scans localization
/// placed: its distance scale and its heading drift per metre, the two a
/// base's wheels make on every step alike (a diameter a little off, or
/// two that differ).
///
/// The scale is the least-squares factor `k` in `localized step ≈ k ·
/// odometry step` (translations, each in its scan's robot frame). Where
/// the lines do not constrain the motion (along a bare corridor, between
/// wall ends out of reach) the pose is dead reckoned on those steps, and a
/// 2 % error is 12 cm over 6 m. The steps a degenerate fix dead reckoned
/// count too: each adds `k · |step|²` on both sides, and the fix that
/// ends the stretch carries the whole correction in one step, so the sums
/// still compare the localized with the odometric displacement. A wrong
/// fix and the fixes after it cancel the same way.
///
/// The drift is the least-squares `d` in `localized turn − odometry turn ≈
/// d · |odometry step|` (rad/m), over steps that turn less than
/// `OdometryBias::STRAIGHT` (in turns the odometry's heading lags by
/// more than any drift), less `OdometryBias::SIGNIFICANCE` of its
/// standard errors. Localization corrects the heading of each scan, but
/// its prior carries the drift, and the walls each fix adds to the map
/// turn with it: on a simulated loop with 0.01 rad/m of drift the whole
/// map came out turned by 0.2°.
///
/// Both forget over about the last `OdometryBias::MEMORY` metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OdometryBias {
    /// Σ localized · odometry (m²), decayed with distance.
    along: f64,
    /// Σ |odometry|² (m²), decayed with distance.
    squared: f64,
    /// Odometry distance seen (m), decayed with distance.
    travelled: f64,
    /// Σ (localized − odometry turn) · |odometry| over straight steps
    /// (rad·m), decayed with distance.
    turned: f64,
    /// Σ (localized − odometry turn)² over straight steps (rad²), decayed
    /// with distance.
    turned_squared: f64,
    /// Σ |odometry|² over straight steps (m²), decayed with distance.
    straight_squared: f64,
    /// Straight steps seen, decayed with distance.
    straight_steps: f64,
    /// Odometry distance of straight steps seen (m), decayed with distance.
    straight_travelled: f64,
}

impl OdometryBias {
    /// Metres of odometry over which the fit forgets by 1/e: a systematic
    /// error changes with the load or the floor, not from one room to the
    /// next.
    const MEMORY: f64 = 100.0;
    /// Odometry distance (m) before the fit is used.
    const WARM_UP: f64 = 2.0;
    /// Largest turn (rad) of a step the drift is learnt from.
    const STRAIGHT: f64 = 0.1;
    /// The drift applied is what the fit exceeds this many of its own
    /// standard errors by. Real odometry's heading errors come in bursts
    /// (CSAIL thinned: fits of up to 0.02 rad/m after a few metres, and of
    /// ±0.01 rad/m for a minute at a time; applied as fitted, the relation
    /// errors summed over 64 thinned variants rose by 3–4 %, and are
    /// unchanged so); a base's drift is steady.
    const SIGNIFICANCE: f64 = 2.0;

    const fn new() -> Self {
        OdometryBias {
            along: 0.0,
            squared: 0.0,
            travelled: 0.0,
            turned: 0.0,
            turned_squared: 0.0,
            straight_squared: 0.0,
            straight_steps: 0.0,
            straight_travelled: 0.0,
        }
    }

    fn observe(&mut self, odometry: &Pose2, localized: &Pose2) {
        let length = odometry.x.hypot(odometry.y);
        let along = localized.x * odometry.x + localized.y * odometry.y;
        let turn = crate::geometry::wrap_angle(localized.theta - odometry.theta);
        if !(length.is_finite() && along.is_finite() && turn.is_finite()) {
            return;
        }
        let keep = (-length / Self::MEMORY).exp();
        self.along = keep * self.along + along;
        self.squared = keep * self.squared + length * length;
        self.travelled = keep * self.travelled + length;
        self.turned *= keep;
        self.turned_squared *= keep;
        self.straight_squared *= keep;
        self.straight_steps *= keep;
        self.straight_travelled *= keep;
        if odometry.theta.abs() <= Self::STRAIGHT {
            self.turned += turn * length;
            self.turned_squared += turn * turn;
            self.straight_squared += length * length;
            self.straight_steps += 1.0;
            self.straight_travelled += length;
        }
    }

    /// The factor (within `1 ± max_correction`) on the odometry's
    /// distances; 1 until the fit has seen `OdometryBias::WARM_UP` metres.
    pub fn scale(&self, max_correction: f64) -> f64 {
        if self.travelled < Self::WARM_UP || self.squared <= 0.0 {
            return 1.0;
        }
        let m = max_correction.max(0.0);
        (self.along / self.squared).clamp(1.0 - m, 1.0 + m)
    }

    /// The heading drift (rad/m, within `± max_drift`) to add to the
    /// odometry's turns; 0 until the fit has seen
    /// `OdometryBias::WARM_UP` metres of straight steps.
    pub fn heading_drift(&self, max_drift: f64) -> f64 {
        if self.straight_travelled < Self::WARM_UP || self.straight_steps <= 2.0 {
            return 0.0;
        }
        let d = self.turned / self.straight_squared;
        // The fit's standard error from the steps' scatter about it.
        let residual = (self.turned_squared - d * self.turned).max(0.0);
        let variance = residual / (self.straight_steps - 1.0) / self.straight_squared;
        let significant = (d.abs() - Self::SIGNIFICANCE * variance.sqrt()).max(0.0);
        let m = max_drift.max(0.0);
        (d.signum() * significant).clamp(-m, m)
    }
}

impl Default for OdometryBias {
    fn default() -> Self {
        Self::new()
    }
}

/// How the estimate of a scan came about, for [`MotionPredictor::record`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Estimate {
    /// Localization placed the scan.
    Localized,
    /// The prediction was kept.
    Predicted,
    /// The robot was found again elsewhere: the step to here is a jump,
    /// not motion.
    Jumped,
}

/// Predicts each scan's pose from the previous results and odometry.
#[derive(Debug, Default)]
pub struct MotionPredictor {
    anchor: Option<Anchor>,
    /// Pose and covariance after the previous scan.
    last: Option<(Pose2, Covariance)>,
    /// Estimated motion over the previous scan interval (robot frame).
    last_step: Option<Pose2>,
    /// The odometry's own last fresh step (unscaled): a log's odometry
    /// that had come to rest and then repeats its reading is a robot
    /// standing still, not frozen odometry.
    last_odometry_step: Option<Pose2>,
    /// The reading of the scan being processed, until `record`.
    pending: Option<(f64, OdometryReading)>,
    /// The odometry step (from the anchor, unscaled) of the pending
    /// prediction, until `record`.
    pending_step: Option<Pose2>,
    /// Heading of the pending prediction from odometry and its variance by
    /// the unscaled model, until `observe_heading` or `record`.
    pending_heading: Option<(f64, f64)>,
    heading_fit: HeadingFit,
    bias: OdometryBias,
}

fn add_scaled(q: &mut Covariance, other: &Covariance, k: f64) {
    for (row, orow) in q.iter_mut().zip(other) {
        for (v, o) in row.iter_mut().zip(orow) {
            *v += k * o;
        }
    }
}

/// `base ∘ step` with covariance `J Σbase Jᵀ + Q`, `J = ∂(base ∘ step)/∂base`.
/// `Q` needs no rotation into the map frame: its translation part is
/// isotropic.
pub(crate) fn compose(
    base: &Pose2,
    base_cov: &Covariance,
    step: &Pose2,
    q: &Covariance,
) -> (Pose2, Covariance) {
    let pose = base.compose(step);
    let (dx, dy) = (pose.x - base.x, pose.y - base.y);
    let j = Matrix3::new(1.0, 0.0, -dy, 0.0, 1.0, dx, 0.0, 0.0, 1.0);
    let base_cov = Matrix3::from_fn(|r, c| base_cov[r][c]);
    let cov = j * base_cov * j.transpose() + Matrix3::from_fn(|r, c| q[r][c]);
    (
        pose,
        std::array::from_fn(|r| std::array::from_fn(|c| cov[(r, c)])),
    )
}

impl MotionPredictor {
    /// Forgets the odometry anchor (the odometry starts over in a new
    /// frame); the next scan is predicted at constant velocity and anchors
    /// the new odometry.
    pub fn forget_odometry(&mut self) {
        self.anchor = None;
    }

    /// Moves the poses the predictor holds into a corrected map frame:
    /// `correction ∘ pose` (after a loop closure moved the map under the
    /// robot). The covariances are kept; the correction's rotation is small
    /// next to their own uncertainty.
    pub fn reframe(&mut self, correction: &Pose2) {
        if let Some((pose, _)) = &mut self.last {
            *pose = correction.compose(pose);
        }
        if let Some(anchor) = &mut self.anchor {
            anchor.pose = correction.compose(&anchor.pose);
        }
    }

    /// The prediction for the scan at time `t` (s). The first scan defines
    /// the map frame: the identity, known up to the floor that keeps the
    /// prior invertible.
    pub fn predict(
        &mut self,
        t: f64,
        reading: OdometryReading,
        noise: &OdometryNoise,
    ) -> Prediction {
        self.pending = Some((t, reading));
        self.pending_heading = None;
        self.pending_step = None;
        let Some((prev, prev_cov)) = self.last else {
            return Prediction {
                pose: Pose2::IDENTITY,
                cov: noise.increment_covariance(Some(&Pose2::IDENTITY), noise.floor_period),
                from_odometry: true,
            };
        };
        let constant_velocity = || {
            // Odometry that had come to rest: the robot stands still (the
            // ACES log repeats a standstill's reading for 6 s, and the
            // scans' last steps, a few centimetres of noise, carried on at
            // constant velocity took the pose 12 m down a corridor).
            let at_rest = self.last_odometry_step.is_some_and(|o| {
                o.x.hypot(o.y) < noise.min_translation && o.theta.abs() < noise.min_rotation
            });
            let step = if at_rest {
                Pose2::IDENTITY
            } else {
                self.last_step.unwrap_or(Pose2::IDENTITY)
            };
            let q = noise.increment_covariance(None, noise.floor_period);
            let (pose, cov) = compose(&prev, &prev_cov, &step, &q);
            Prediction {
                pose,
                cov,
                from_odometry: false,
            }
        };
        let (odometry, anchor) = match (reading, &self.anchor) {
            (OdometryReading::Stale, _) | (_, None) => return constant_velocity(),
            (OdometryReading::Lumped(_), Some(a)) if a.gap_tracked => return constant_velocity(),
            (OdometryReading::Fresh(_), Some(a)) if a.stale_scans > 0 && a.gap_tracked => {
                return constant_velocity();
            }
            (OdometryReading::Lumped(o) | OdometryReading::Fresh(o), Some(a)) => (o, a),
        };
        let raw = anchor.odometry.between(&odometry);
        self.pending_step = Some(raw);
        let k = self.bias.scale(noise.max_scale_correction);
        let drift = self.bias.heading_drift(noise.max_heading_drift);
        let step = Pose2::new(k * raw.x, k * raw.y, raw.theta + drift * raw.x.hypot(raw.y));
        let period = t - anchor.t;
        let mut q = noise.increment_covariance(Some(&step), period);
        add_scaled(
            &mut q,
            &noise.increment_covariance(None, period),
            anchor.stale_scans as f64,
        );
        self.pending_heading = Some((anchor.pose.theta + step.theta, anchor.cov[2][2] + q[2][2]));
        let scale = self.heading_fit.sigma_scale(noise.max_heading_scale);
        q[2][2] *= scale * scale;
        let (pose, cov) = compose(&anchor.pose, &anchor.cov, &step, &q);
        Prediction {
            pose,
            cov,
            from_odometry: true,
        }
    }

    /// Localization placed the scan last predicted at heading `theta`
    /// (rad, before any loop closure moved it): how far the odometry's
    /// heading was off, for [`HeadingFit`].
    pub fn observe_heading(&mut self, theta: f64) {
        if let Some((predicted, variance)) = self.pending_heading.take() {
            self.heading_fit
                .observe(crate::geometry::wrap_angle(theta - predicted), variance);
        }
    }

    /// The factor the odometry's heading σ is widened by at present.
    pub fn heading_scale(&self, noise: &OdometryNoise) -> f64 {
        self.heading_fit.sigma_scale(noise.max_heading_scale)
    }

    /// The heading drift added to the odometry's turns at present (rad/m;
    /// 0 until learnt).
    pub fn odometry_heading_drift(&self, noise: &OdometryNoise) -> f64 {
        self.bias.heading_drift(noise.max_heading_drift)
    }

    /// The factor on the odometry's distances at present (1 until learnt).
    pub fn odometry_scale(&self, noise: &OdometryNoise) -> f64 {
        self.bias.scale(noise.max_scale_correction)
    }

    /// Records the final estimate of the scan last predicted. After a
    /// jump there is no velocity to extrapolate, and the odometry is
    /// anchored afresh at the next scan that has it.
    pub fn record(&mut self, pose: Pose2, cov: Covariance, estimate: Estimate) {
        let localized = estimate != Estimate::Predicted;
        if let (Some(step), Some(anchor)) = (self.pending_step.take(), &self.anchor) {
            if matches!(self.pending, Some((_, OdometryReading::Fresh(_)))) {
                self.last_odometry_step = Some(step);
            }
            if estimate == Estimate::Localized {
                self.bias.observe(&step, &anchor.pose.between(&pose));
            }
        }
        if estimate == Estimate::Jumped {
            self.pending = None;
            self.last_step = None;
            self.anchor = None;
            self.last = Some((pose, cov));
            return;
        }
        if let Some((prev, _)) = self.last {
            self.last_step = Some(prev.between(&pose));
        }
        self.last = Some((pose, cov));
        let reanchor = match (self.pending.take(), &mut self.anchor) {
            (Some((t, OdometryReading::Fresh(o))), _) => Some((t, o)),
            (Some((t, OdometryReading::Lumped(o))), Some(a)) if !a.gap_tracked => Some((t, o)),
            (Some((t, OdometryReading::Lumped(o))), None) => Some((t, o)),
            (_, Some(a)) => {
                a.stale_scans += 1;
                a.gap_tracked &= localized;
                None
            }
            (_, None) => None,
        };
        if let Some((t, odometry)) = reanchor {
            self.anchor = Some(Anchor {
                t,
                odometry,
                pose,
                cov,
                stale_scans: 0,
                gap_tracked: true,
            });
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    const NOISE: OdometryNoise = OdometryNoise {
        translation_per_metre: 0.1,
        translation_per_radian: 0.02,
        rotation_per_radian: 0.2,
        rotation_per_metre: 0.02,
        min_translation: 0.01,
        min_rotation: 0.005,
        floor_period: 0.2,
        missing_translation: 0.3,
        missing_rotation: 0.15,
        max_heading_scale: 1.0,
        max_scale_correction: 0.1,
        max_heading_drift: 0.0,
    };

    fn run(
        odometry: &[Option<Pose2>],
        localized: impl Fn(usize) -> bool,
        offset: f64,
    ) -> Vec<Prediction> {
        let mut feed = OdometryFeed::new(offset);
        let mut predictor = MotionPredictor::default();
        let mut out = Vec::new();
        for (k, o) in odometry.iter().enumerate() {
            let t = 0.2 * k as f64;
            let p = predictor.predict(t, feed.reading(t, *o), &NOISE);
            // Pretend localization confirmed the prediction.
            let estimate = if localized(k) {
                Estimate::Localized
            } else {
                Estimate::Predicted
            };
            predictor.record(p.pose, p.cov, estimate);
            out.push(p);
        }
        out
    }

    fn x(v: f64) -> Option<Pose2> {
        Some(Pose2::new(v, 0.0, 0.0))
    }

    #[test]
    fn odometry_increments_move_the_pose() {
        let p = run(&[x(5.0), x(5.1), x(5.3)], |_| true, 0.0);
        assert_eq!(p[0].pose, Pose2::IDENTITY);
        assert!((p[2].pose.x - 0.3).abs() < 1e-12);
        assert!(p[2].cov[0][0] > p[1].cov[0][0], "uncertainty grows");
    }

    /// Moving 0.1 m per scan; odometry frozen for three scans, then the
    /// whole motion at once.
    fn freeze_odometry() -> [Option<Pose2>; 8] {
        [
            x(0.0),
            x(0.1),
            x(0.2),
            x(0.2),
            x(0.2),
            x(0.2),
            x(0.6),
            x(0.7),
        ]
    }

    #[test]
    fn odometry_come_to_rest_and_repeated_is_standing_still() {
        let mut feed = OdometryFeed::new(0.0);
        let mut predictor = MotionPredictor::default();
        // Slowing to a stop: 0.1 m, then 2 mm, then the same reading on.
        let odometry = [x(0.0), x(0.1), x(0.102), x(0.102), x(0.102)];
        // Localization put the scans 5 cm apart at the stop (noise).
        let localized = [0.0, 0.1, 0.15];
        let mut predicted = Vec::new();
        for (k, o) in odometry.iter().enumerate() {
            let t = 0.2 * k as f64;
            let p = predictor.predict(t, feed.reading(t, *o), &NOISE);
            let pose = localized
                .get(k)
                .map_or(p.pose, |&v| Pose2::new(v, 0.0, 0.0));
            predictor.record(pose, p.cov, Estimate::Localized);
            predicted.push(p);
        }
        // Not the scans' last 5 cm carried on: the robot stands.
        assert!(!predicted[3].from_odometry);
        assert!(
            (predicted[3].pose.x - 0.15).abs() < 1e-12,
            "{:?}",
            predicted[3].pose
        );
        assert!((predicted[4].pose.x - 0.15).abs() < 1e-12);
        // Moving odometry that freezes is still carried on (below).
    }

    #[test]
    fn an_untracked_freeze_keeps_the_lumped_jump_once() {
        // Localization fails during the freeze.
        let odo = freeze_odometry();
        let p = run(&odo, |k| !(3..=5).contains(&k), 0.0);
        // Constant velocity during the freeze...
        assert!((p[3].pose.x - 0.3).abs() < 1e-12 && !p[3].from_odometry);
        // ...then the odometry from the last fresh scan: the truth again.
        assert!((p[6].pose.x - 0.6).abs() < 1e-12 && p[6].from_odometry);
        assert!((p[7].pose.x - 0.7).abs() < 1e-12);
        // The resumed prediction carries the missed scans' noise.
        assert!(p[6].cov[0][0] > 3.0 * NOISE.missing_translation.powi(2));
    }

    #[test]
    fn a_tracked_freeze_keeps_the_tracked_poses() {
        let odo = freeze_odometry();
        let p = run(&odo, |_| true, 0.0);
        // Constant velocity through the gap and on resumption (0.1 m per
        // scan), then odometry increments again from the re-anchor.
        assert!((p[6].pose.x - 0.6).abs() < 1e-12 && !p[6].from_odometry);
        assert!((p[7].pose.x - 0.7).abs() < 1e-12 && p[7].from_odometry);
    }

    #[test]
    fn a_time_offset_interpolates_and_spreads_a_lump() {
        let odo = [x(0.0), x(0.1), x(0.2), x(0.3), x(0.4)];
        let p = run(&odo, |_| true, -0.1);
        // Half a scan earlier: 0.05 m behind the logged odometry.
        assert!((p[3].pose.x - 0.25).abs() < 1e-12, "{:?}", p[3].pose);

        let mut feed = OdometryFeed::new(-0.1);
        let readings: Vec<_> = [x(0.0), x(0.1), x(0.1), x(0.1), x(0.4), x(0.5)]
            .iter()
            .enumerate()
            .map(|(k, o)| feed.reading(0.2 * k as f64, *o))
            .collect();
        assert_eq!(readings[2], OdometryReading::Stale);
        // 0.7 s lies between the samples at 0.2 s and 0.8 s: lumped.
        assert_eq!(
            readings[4],
            OdometryReading::Lumped(Pose2::new(0.35, 0.0, 0.0))
        );
        assert!(matches!(readings[5], OdometryReading::Fresh(_)));
    }

    #[test]
    fn missing_odometry_is_stale() {
        let mut feed = OdometryFeed::new(0.0);
        assert_eq!(feed.reading(0.0, None), OdometryReading::Stale);
        assert_eq!(
            feed.reading(0.2, x(1.0)),
            OdometryReading::Fresh(Pose2::new(1.0, 0.0, 0.0))
        );
    }

    /// Heading errors of `sigma` times the model's σ, alternately either
    /// way, against model variances that vary from scan to scan.
    fn fitted(sigma: f64, scans: usize) -> HeadingFit {
        let mut fit = HeadingFit::default();
        for k in 0..scans {
            let model_sigma = 0.01 + 0.01 * (k % 3) as f64;
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            fit.observe(sign * sigma * model_sigma, model_sigma * model_sigma);
        }
        fit
    }

    #[test]
    fn heading_fit_learns_how_much_worse_the_odometry_is() {
        assert_eq!(
            fitted(2.0, 5).sigma_scale(3.0),
            1.0,
            "not before the warm-up"
        );
        let fits = fitted(1.0, 2000).sigma_scale(3.0);
        assert!(fits < 1.1, "a model that fits stays about 1: {fits}");
        let worse = fitted(2.0, 2000).sigma_scale(3.0);
        assert!((1.8..2.2).contains(&worse), "{worse}");
        let better = fitted(0.5, 2000).sigma_scale(3.0);
        assert_eq!(better, 1.0, "never narrower than the model");
        assert_eq!(fitted(5.0, 2000).sigma_scale(3.0), 3.0, "capped");
        assert_eq!(fitted(2.0, 2000).sigma_scale(1.0), 1.0, "off");
    }

    #[test]
    fn one_wild_heading_error_does_not_widen_the_gates_by_itself() {
        let mut fit = fitted(1.0, 200);
        let before = fit.sigma_scale(3.0);
        fit.observe(1.0, 0.02 * 0.02); // 50 σ: a wrong fix
        fit.observe(f64::NAN, 0.02 * 0.02);
        fit.observe(0.01, 0.0);
        let after = fit.sigma_scale(3.0);
        assert!(after < 1.6 && after >= before, "{before} -> {after}");
    }

    #[test]
    fn predictions_widen_their_heading_sigma_by_the_fit() {
        let noise = OdometryNoise {
            max_heading_scale: 3.0,
            ..NOISE
        };
        let mut feed = OdometryFeed::new(0.0);
        let mut predictor = MotionPredictor::default();
        let mut narrow = None;
        for k in 0..40 {
            let t = 0.2 * k as f64;
            let p = predictor.predict(t, feed.reading(t, x(0.1 * k as f64)), &noise);
            if k == 1 {
                narrow = Some(p.cov[2][2]);
            }
            // Localization keeps turning the heading 3 model σ away.
            let off = if k % 2 == 0 { 0.03 } else { -0.03 };
            let fixed = Pose2::new(p.pose.x, p.pose.y, p.pose.theta + off);
            predictor.observe_heading(fixed.theta);
            predictor.record(
                fixed,
                [[1e-4, 0.0, 0.0], [0.0, 1e-4, 0.0], [0.0, 0.0, 1e-6]],
                Estimate::Localized,
            );
        }
        let scale = predictor.heading_scale(&noise);
        assert!(scale > 2.0, "{scale}");
        let p = predictor.predict(8.0, feed.reading(8.0, x(4.0)), &noise);
        assert!(
            p.cov[2][2] > 4.0 * narrow.unwrap(),
            "{} vs {:?}",
            p.cov[2][2],
            narrow
        );
    }

    /// Drives `steps` of 0.1 m straight along +x whose odometry turns by
    /// `drift` rad/m plus `noise` rad (σ) per step, each scan placed at
    /// the truth; returns the predictor and the heading error (rad) of the
    /// last prediction.
    fn straight_drive(
        drift: f64,
        noise: f64,
        noise_model: &OdometryNoise,
    ) -> (MotionPredictor, f64) {
        let mut rng = crate::sim::Rng::new(3);
        let mut feed = OdometryFeed::new(0.0);
        let mut predictor = MotionPredictor::default();
        let cov = [[1e-4, 0.0, 0.0], [0.0, 1e-4, 0.0], [0.0, 0.0, 1e-6]];
        let mut odometry = Pose2::new(2.0, -1.0, 0.5);
        let mut error = 0.0;
        for k in 0..300 {
            let t = 0.2 * k as f64;
            if k > 0 {
                odometry = odometry.compose(&Pose2::new(0.1, 0.0, drift * 0.1 + rng.normal(noise)));
            }
            let p = predictor.predict(t, feed.reading(t, Some(odometry)), noise_model);
            error = p.pose.theta;
            predictor.record(
                Pose2::new(0.1 * k as f64, 0.0, 0.0),
                cov,
                Estimate::Localized,
            );
        }
        (predictor, error)
    }

    /// Odometry that turns 0.01 rad per metre driven straight: the fit
    /// learns the drift, and the predictions no longer turn with it.
    #[test]
    fn a_steady_heading_drift_is_learnt_and_taken_out_of_the_turns() {
        let noise = OdometryNoise {
            max_heading_drift: 0.02,
            ..NOISE
        };
        let (predictor, error) = straight_drive(0.01, 0.0003, &noise);
        let drift = predictor.odometry_heading_drift(&noise);
        assert!((drift + 0.01).abs() < 0.001, "{drift}");
        // Read as is, each 0.1 m step turns by 1 mrad.
        assert!(error.abs() < 0.0005, "{error}");
        let (_, error) = straight_drive(0.01, 0.0003, &NOISE);
        assert!((error - 0.001).abs() < 0.0005, "{error}");
        // Never beyond the configured bound.
        let narrow = OdometryNoise {
            max_heading_drift: 0.004,
            ..NOISE
        };
        assert_eq!(predictor.odometry_heading_drift(&narrow), -0.004);
    }

    /// Heading noise without a drift teaches none, however the noise falls.
    #[test]
    fn heading_noise_without_a_drift_teaches_none() {
        let noise = OdometryNoise {
            max_heading_drift: 0.02,
            ..NOISE
        };
        for sigma in [0.001, 0.005, 0.02] {
            let (predictor, _) = straight_drive(0.0, sigma, &noise);
            assert_eq!(predictor.odometry_heading_drift(&noise), 0.0, "σ {sigma}");
        }
    }

    /// Odometry 3 % long (true steps 0.1 m, read 0.103 m) along +x. Where
    /// localization places the scans, the fit learns the factor; a stretch
    /// it only dead reckons and the fix that ends it leave it unbiased.
    #[test]
    fn odometry_read_long_is_learnt_from_the_fixes_and_scaled_back() {
        let noise = OdometryNoise {
            max_scale_correction: 0.1,
            ..NOISE
        };
        let mut feed = OdometryFeed::new(0.0);
        let mut predictor = MotionPredictor::default();
        let cov = [[1e-4, 0.0, 0.0], [0.0, 1e-4, 0.0], [0.0, 0.0, 1e-6]];
        let mut last = None;
        for k in 0..150 {
            let t = 0.2 * k as f64;
            let p = predictor.predict(t, feed.reading(t, x(0.103 * k as f64)), &noise);
            // Scans 60-89 see nothing that fixes the position along x:
            // the prediction is kept; scan 90 is placed again.
            let truth = Pose2::new(0.1 * k as f64, 0.0, 0.0);
            let dead_reckoned = (60..90).contains(&k);
            let (pose, estimate) = if dead_reckoned {
                (p.pose, Estimate::Localized)
            } else {
                (truth, Estimate::Localized)
            };
            if k == 89 {
                last = Some(pose.x - truth.x);
            }
            predictor.record(pose, cov, estimate);
        }
        let scale = predictor.odometry_scale(&noise);
        assert!((scale - 1.0 / 1.03).abs() < 0.002, "{scale}");
        // Learnt before the stretch: 3 m dead reckoned, a few mm off
        // (unscaled, 9 cm).
        assert!(last.unwrap().abs() < 0.01, "{last:?}");
        // The next step is predicted at the true length.
        let p = predictor.predict(30.0, feed.reading(30.0, x(0.103 * 150.0)), &noise);
        assert!((p.pose.x - 15.0).abs() < 0.005, "{}", p.pose.x);
        // Never beyond the configured bound, and off when it is 0.
        let off = OdometryNoise {
            max_scale_correction: 0.0,
            ..NOISE
        };
        assert_eq!(predictor.odometry_scale(&off), 1.0);
        let narrow = OdometryNoise {
            max_scale_correction: 0.01,
            ..NOISE
        };
        assert_eq!(predictor.odometry_scale(&narrow), 0.99);
    }

    /// A jump (the robot found again elsewhere) is not motion: it teaches
    /// the fit nothing, and nothing is extrapolated across it.
    #[test]
    fn a_jump_is_no_odometry_step() {
        let mut feed = OdometryFeed::new(0.0);
        let mut predictor = MotionPredictor::default();
        for k in 0..60 {
            let t = 0.2 * k as f64;
            let p = predictor.predict(t, feed.reading(t, x(0.1 * k as f64)), &NOISE);
            let estimate = if k == 40 {
                Estimate::Jumped
            } else {
                Estimate::Localized
            };
            let pose = if k >= 40 {
                Pose2::new(p.pose.x + if k == 40 { 5.0 } else { 0.0 }, 0.0, 0.0)
            } else {
                p.pose
            };
            predictor.record(pose, p.cov, estimate);
        }
        // Counted as motion, 5 m in a 0.1 m step would pin the factor at
        // its bound (1.1).
        let scale = predictor.odometry_scale(&NOISE);
        assert!((scale - 1.0).abs() < 1e-9, "{scale}");
    }

    /// A robot weaving as it drives, heading 0.4 sin(2t) rad; scans every
    /// 0.2 s, each with the odometry `ahead` s later than its stamp (ahead
    /// of the scan when positive), and localized exactly. Frozen odometry
    /// every `freeze`th scan when given. The offset learnt.
    fn learnt_offset(ahead: f64, scans: usize, freeze: Option<usize>) -> f64 {
        let heading = |t: f64| 0.4 * (2.0 * t).sin();
        let mut feed = OdometryFeed::new(0.0).learning(0.3);
        let mut last = Pose2::IDENTITY;
        for k in 0..scans {
            let t = 0.2 * k as f64;
            let frozen = freeze.is_some_and(|n| k % n == n - 1);
            if !frozen {
                let s = t + ahead;
                last = Pose2::new(0.3 * s, 0.0, heading(s));
            }
            match feed.reading(t, Some(last)) {
                OdometryReading::Fresh(_) => feed.localized(t, heading(t)),
                _ => feed.unlocalized(),
            }
        }
        feed.offset()
    }

    #[test]
    fn odometry_ahead_of_the_scans_is_read_that_much_earlier() {
        for ahead in [0.05, 0.1, 0.2] {
            let offset = learnt_offset(ahead, 300, None);
            assert!((offset + ahead).abs() <= 0.015, "{ahead}: {offset}");
        }
        // Frozen samples every seventh scan: the pairs reading across
        // them are left out, and the rest still find the lag.
        let offset = learnt_offset(0.1, 300, Some(7));
        assert!((offset + 0.1).abs() <= 0.015, "{offset}");
    }

    #[test]
    fn odometry_on_time_or_behind_is_read_at_the_scans_stamps() {
        assert_eq!(learnt_offset(0.0, 300, None), 0.0);
        // Behind, only a later reading would fit: none is taken.
        assert_eq!(learnt_offset(-0.1, 300, None), 0.0);
    }

    #[test]
    fn too_little_turning_teaches_no_lag() {
        // 20 scans turn about 2 rad in all, under the 6 rad asked.
        assert_eq!(learnt_offset(0.1, 20, None), 0.0);
        let mut feed = OdometryFeed::new(-0.05);
        for k in 0..300 {
            let t = 0.2 * k as f64;
            let o = Pose2::new(0.1 * k as f64, 0.0, (2.0 * t).sin());
            feed.reading(t, Some(o));
            feed.localized(t, (2.0 * t).sin());
        }
        assert_eq!(feed.offset(), -0.05, "not learning: kept as set");
    }
}
