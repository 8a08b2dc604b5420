//! Configuration of the offline mapper (`clsmap map`): one TOML document
//! with a section per stage. Every section and field has a documented
//! default, so an empty document is a complete configuration, and unknown
//! keys are refused so a typo is never silently ignored.
//!
//! ```toml
//! laser_mount = { x = 0.0, y = 0.0, theta = 0.0 }
//! max_correction_sigmas = inf
//! odometry_time_offset = 0.0
//! max_scan_lag = 0.3
//! update_map_when_unlocalized = false
//! [extraction]            # geometry::ExtractionConfig
//! [localizer]             # localize::LocalizerConfig
//! [localizer.correspondence]   # matching gates for localization
//! [map]                   # map::SegmentMapConfig
//! [map.fusion]            # correspondence gates for fusing into the map
//! [keyframes]             # map::KeyframeConfig
//! [odometry]              # OdometryNoise
//! ```

use crate::geometry::CorrespondenceConfig;
use crate::geometry::{ExtractionConfig, Pose2};
use crate::graph::LoopClosureConfig;
use crate::localize::LocalizerConfig;
use crate::map::cls::{ClsMapConfig, RegionConfig};
use crate::map::{KeyframeConfig, SegmentMapConfig};
use serde::{Deserialize, Serialize};

/// How uncertain an odometry increment is: standard deviations that grow
/// with the motion, plus a floor per scan. Sets how strongly odometry holds
/// the pose against the line matches (the prior of localization), and how
/// far the correspondence gates open.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OdometryNoise {
    /// Translation σ per metre travelled (m/m). Default 0.03: over one to
    /// three scans the CSAIL odometry agrees with the reference relations
    /// to about 3 cm, and a looser prior lets wrong line matches drag the
    /// pose (measured: 0.1 gave larger relation errors).
    pub translation_per_metre: f64,
    /// Translation σ per radian turned (m/rad). Default 0.02.
    pub translation_per_radian: f64,
    /// Rotation σ per radian turned (rad/rad). Default 0.25: odometry
    /// headings lag in fast turns (CSAIL: errors up to 20° over 0.4 s), so
    /// the lines must be free to correct them.
    pub rotation_per_radian: f64,
    /// Rotation σ per metre travelled (rad/m). Default 0.02 (≈1.1°/m).
    pub rotation_per_metre: f64,
    /// Translation σ floor per scan (m; see `floor_period`). Default
    /// 0.01: keeps the prior finite when the robot stands still.
    pub min_translation: f64,
    /// Rotation σ floor per scan (rad; see `floor_period`). Default 0.005.
    pub min_rotation: f64,
    /// Scan period (s) at and above which the two floors hold as written;
    /// over a shorter period they shrink with √(period / this), so that
    /// they add up to the same spread per second at any scan rate. 0 =
    /// per scan at any rate. Default 0.2 (CSAIL's period is 0.21 s): at
    /// the LMS200's 37.5 Hz, 1 cm per scan is 6 cm per second, far beyond
    /// a base's odometry, and the pose then follows every noisy wall end.
    pub floor_period: f64,
    /// Translation σ of a scan without usable odometry (none, or frozen)
    /// predicted at constant velocity (m). Default 0.3: the gates must then
    /// cover a change of pace over a scan period.
    pub missing_translation: f64,
    /// Rotation σ of a scan without usable odometry (rad). Default 0.15.
    pub missing_rotation: f64,
    /// Widest factor on the heading σ learnt from how far localization
    /// corrects the odometry's heading (the running mean of the squared
    /// corrections against the model's variance over about 30 scans);
    /// 1 keeps the model as written. Default 3: a robot's odometry may be
    /// worse than these defaults, and a heading σ too narrow lets no line
    /// through the gates.
    pub max_heading_scale: f64,
    /// Widest correction of the odometry's distances learnt from the
    /// scans localization placed (the factor stays within 1 ± this); 0
    /// takes the odometry's distances as read. Wheel diameters and tyre
    /// wear put a base's distances off by a few per cent, and where
    /// nothing constrains the motion along a corridor the pose is dead
    /// reckoned on them. Default 0.1: over 30 seeds of the simulated
    /// worlds (2 % long odometry) the loop world's mean pose error went
    /// from 31 to 14 mm. CSAIL learns ×1.004 dense and ×1.015–1.019
    /// thinned (its scans are stamped late against it); its relation errors move by
    /// a few millimetres, the sum over 28 thinned variants by +4 %.
    pub max_scale_correction: f64,
    /// Largest heading drift (rad/m) learnt from the scans localization
    /// placed and taken out of the odometry's turns; 0 takes the turns as
    /// read. Wheels of slightly different diameters turn a base a little
    /// on every metre it drives straight; localization corrects each
    /// scan, but the walls each fix adds to the map turn with the drift.
    /// Default 0.02 (1.1°/m): with the simulated bases' 0.01 rad/m, the
    /// long loop driven twice went from 4.7 to 3.3 cm RMSE (8 seeds) and
    /// the daemon's corridor world from 34 to 27 mm (30 seeds); CSAIL's
    /// steps scatter too much for a drift to stand out, and its figures
    /// are unchanged.
    pub max_heading_drift: f64,
}

impl Default for OdometryNoise {
    fn default() -> Self {
        OdometryNoise {
            translation_per_metre: 0.03,
            translation_per_radian: 0.02,
            rotation_per_radian: 0.25,
            rotation_per_metre: 0.02,
            min_translation: 0.01,
            min_rotation: 0.005,
            floor_period: 0.2,
            missing_translation: 0.3,
            missing_rotation: 0.15,
            max_heading_scale: 3.0,
            max_scale_correction: 0.1,
            max_heading_drift: 0.02,
        }
    }
}

impl OdometryNoise {
    /// Covariance (x, y, θ; map-frame axes) of an odometry increment of
    /// `delta` (robot frame) over `period` seconds; `None` = no odometry
    /// for this step. The translation noise is isotropic, as suits a
    /// holonomic base.
    pub fn increment_covariance(&self, delta: Option<&Pose2>, period: f64) -> [[f64; 3]; 3] {
        let (sigma_t, sigma_r) = match delta {
            Some(d) => {
                let dist = d.x.hypot(d.y);
                let turn = d.theta.abs();
                let floor = self.floor_fraction(period);
                (
                    (self.translation_per_metre * dist + self.translation_per_radian * turn)
                        .max(floor * self.min_translation),
                    (self.rotation_per_radian * turn + self.rotation_per_metre * dist)
                        .max(floor * self.min_rotation),
                )
            }
            None => (self.missing_translation, self.missing_rotation),
        };
        let vt = sigma_t * sigma_t;
        [
            [vt, 0.0, 0.0],
            [0.0, vt, 0.0],
            [0.0, 0.0, sigma_r * sigma_r],
        ]
    }

    /// The share (0–1] of the floors that holds over `period` seconds; the
    /// whole floors for an unknown (not positive, not finite) period.
    fn floor_fraction(&self, period: f64) -> f64 {
        if self.floor_period > 0.0 && period > 0.0 && period < self.floor_period {
            (period / self.floor_period).sqrt()
        } else {
            1.0
        }
    }
}

/// `laser_mount` with any of its fields left out (0), unknown ones refused.
fn mount_fields<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Pose2, D::Error> {
    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Fields {
        #[serde(default)]
        x: f64,
        #[serde(default)]
        y: f64,
        #[serde(default)]
        theta: f64,
    }
    let f = Fields::deserialize(d)?;
    Ok(Pose2::new(f.x, f.y, f.theta))
}

/// Everything the offline mapper needs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MapperConfig {
    /// Laser pose in the robot frame (m, rad). Default: the identity, as in
    /// the CSAIL log whose laser pose equals its odometry pose; a
    /// configuration that leaves it out maps a log that declares its
    /// laser's pose with that pose ([`super::take_declared_mount`]). Each
    /// of `x`, `y`, `theta` may be left out (0).
    #[serde(deserialize_with = "mount_fields")]
    pub laser_mount: Pose2,
    pub extraction: ExtractionConfig,
    pub localizer: LocalizerConfig,
    pub map: SegmentMapConfig,
    pub keyframes: KeyframeConfig,
    pub odometry: OdometryNoise,
    /// A localization whose correction of the odometry prediction exceeds
    /// this many standard deviations of the prediction (Mahalanobis
    /// distance over x, y, θ) is refused and the prediction kept: line
    /// matches that drag the pose that far are far likelier to be wrong
    /// associations than odometry errors. Default: infinite (off). On
    /// CSAIL every finite gate tried (5σ, 8σ) refused more good fixes than
    /// bad ones, because the odometry's own outliers (headings lagging in
    /// fast turns, lumped jumps after freezes) are what the lines correct;
    /// the localizer's validation and jump limits already catch wrong
    /// associations. TOML accepts `inf`.
    pub max_correction_sigmas: f64,
    /// Time offset (s) added to a scan's time to read its odometry: the
    /// odometry pose used for a scan at `t` is the one interpolated at
    /// `t + odometry_time_offset` from the odometry of the scans so far.
    /// Compensates a latency between the laser and odometry clocks; only
    /// offsets ≤ 0 can be honoured while streaming (a positive offset
    /// holds the newest odometry). Default 0. Estimate it
    /// without ground truth by comparing the heading steps of localized
    /// scans with the odometry's at shifted times: on CSAIL they agree best
    /// at −0.5 to −0.6 scan periods, about −0.1 s. It is learnt so (see
    /// `max_scan_lag`); this is the offset until then.
    pub odometry_time_offset: f64,
    /// Longest lag (s) of the laser's time stamps behind the odometry's
    /// learnt from the localized scans: the offset becomes the one in
    /// `[−this, 0]` whose odometry heading steps fit those of consecutive
    /// localized scans best, once they have turned 6 rad (see
    /// `OdometryFeed::learning`); 0 keeps `odometry_time_offset` as set.
    /// Default 0.3 s, a scan period and a half at the LMS200's slowest
    /// line speed. CSAIL learns −0.12 s dense, −0.09 to −0.13 s thinned;
    /// its 38 thinned logs driven forwards lost 23 % of their clipped
    /// relation error, and driven backwards (odometry stamped late) learn
    /// 0, as they must.
    pub max_scan_lag: f64,
    /// Whether a keyframe whose localization failed for a reason other
    /// than too few matches (an inconsistent, non-converged or implausible
    /// fix) still updates the map at the predicted pose. Default false:
    /// such poses are doubtful and wrong walls in the map mislead every
    /// later scan; scans of unmapped space (too few matches) update from
    /// the second such scan in a row (the first is more often odometry gone
    /// wrong in a fast turn), or at once when they hold hardly a line.
    pub update_map_when_unlocalized: bool,
    /// When the map offers too few matches, localize against the previous
    /// scan's lines instead (line scan matching). Default true.
    pub previous_scan_fallback: bool,
    /// An odometry step that the scans' own step (this scan's points
    /// matched to the last scan's) puts more than this many standard
    /// deviations of the prediction away (Mahalanobis over x, y, θ), and
    /// farther than the lines' matches reach (half the localizer's
    /// correspondence gates), is replaced by the scans' step before
    /// localization; 0 = never. Default 5. Freiburg 079's odometry counts
    /// every backward step forwards: the prediction then runs up to
    /// 0.2 m a scan the wrong way, further than the lines can pull it
    /// back along a corridor, and the map there came out 1–3 m off.
    pub odometry_check_sigmas: f64,
    /// A fix resting on three lines or fewer that turns the heading by
    /// more than this many standard deviations of the prediction's
    /// heading, while those lines leave the heading's σ above half the
    /// prediction's, is refused and the prediction kept, unless the fix
    /// before asked for the same turn (then the odometry is what is
    /// wrong); 0 = never.
    /// Default 3. Two lines along a corridor turned single scans 6–7° where
    /// the odometry was right, and the walls mapped from them carried the
    /// error on (the Infinite Corridor, 0.37 → 0.05 m).
    pub few_lines_turn_sigmas: f64,
    /// The Closed Line Segment map grown on keyframes.
    pub cls: ClsTuning,
    /// Loop closure and the keyframe pose graph.
    pub loop_closure: LoopClosureConfig,
}

impl Default for MapperConfig {
    fn default() -> Self {
        MapperConfig {
            laser_mount: Pose2::IDENTITY,
            extraction: ExtractionConfig::default(),
            localizer: LocalizerConfig::default(),
            map: SegmentMapConfig::default(),
            keyframes: KeyframeConfig::default(),
            odometry: OdometryNoise::default(),
            max_correction_sigmas: f64::INFINITY,
            odometry_time_offset: 0.0,
            max_scan_lag: 0.3,
            update_map_when_unlocalized: false,
            previous_scan_fallback: true,
            odometry_check_sigmas: 5.0,
            few_lines_turn_sigmas: 3.0,
            cls: ClsTuning::default(),
            loop_closure: LoopClosureConfig::default(),
        }
    }
}

/// What is tunable in the CLS map. The rest of its configuration comes
/// from the mapper's: the laser mounting (`laser_mount`), the range limits
/// (`[extraction]`) and the fusion gates (`[map]`), so the region, the lines
/// and both maps always agree on the beams and on what a wall is.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ClsTuning {
    /// See [`LocalMapConfig::point_tolerance`](crate::map::cls::LocalMapConfig).
    pub point_tolerance: f64,
    /// See [`LocalMapConfig::max_wedge`](crate::map::cls::LocalMapConfig).
    pub max_wedge: f64,
    /// Snapping and sliver limits of the region union.
    pub region: RegionConfig,
    /// See [`ClsMapConfig::clip_to_window`].
    pub clip_to_window: bool,
}

impl Default for ClsTuning {
    fn default() -> Self {
        let cls = ClsMapConfig::default();
        ClsTuning {
            point_tolerance: cls.local.point_tolerance,
            max_wedge: cls.local.max_wedge,
            region: cls.region,
            clip_to_window: cls.clip_to_window,
        }
    }
}

impl MapperConfig {
    /// The CLS map's full configuration, assembled from this one.
    pub fn cls_map(&self) -> ClsMapConfig {
        let mut cls = ClsMapConfig {
            region: self.cls.region,
            fusion: self.map,
            clip_to_window: self.cls.clip_to_window,
            ..ClsMapConfig::default()
        };
        cls.local.mount = self.laser_mount;
        cls.local.min_range = self.extraction.min_range;
        cls.local.max_range = self.extraction.max_range;
        cls.local.point_tolerance = self.cls.point_tolerance;
        cls.local.max_wedge = self.cls.max_wedge;
        cls
    }

    /// Parses a TOML document and checks every value's range; syntax and
    /// unknown-key errors carry line and column, range errors the key.
    pub fn from_toml(text: &str) -> Result<MapperConfig, ConfigError> {
        let config: MapperConfig = toml::from_str(text)?;
        config.validate().map_err(|e| match e {
            ConfigError::Range {
                key, value, rule, ..
            } => {
                // `[section] key` as the dotted path TOML spells.
                let dotted = match key.strip_prefix('[').and_then(|k| k.split_once("] ")) {
                    Some((section, name)) => format!("{section}.{name}"),
                    None => key.clone(),
                };
                ConfigError::Range {
                    line: line_of_key(text, &dotted),
                    key,
                    value,
                    rule,
                }
            }
            other => other,
        })?;
        Ok(config)
    }

    /// Checks that every value is a number the mapper can work with: no
    /// NaN, no infinity (but for `max_correction_sigmas`), no negative
    /// lengths, no zero where the value divides or bounds a search.
    pub fn validate(&self) -> Result<(), ConfigError> {
        use Rule::{AtLeast, Finite, NonNegative, Positive, Wedge, Within};
        let (e, l, m, o, c) = (
            &self.extraction,
            &self.localizer,
            &self.map,
            &self.odometry,
            &self.cls,
        );
        let v = Validator;
        // inf is allowed here (the gate off); NaN, zero and below are not.
        if self.max_correction_sigmas.is_nan() || self.max_correction_sigmas <= 0.0 {
            return Err(v.refuse(
                "",
                "max_correction_sigmas",
                self.max_correction_sigmas,
                "> 0 (inf = off)",
            ));
        }
        v.check(
            "",
            "odometry_time_offset",
            self.odometry_time_offset,
            Finite,
        )?;
        v.check("", "max_scan_lag", self.max_scan_lag, Within(0.0, 2.0))?;
        v.check(
            "",
            "odometry_check_sigmas",
            self.odometry_check_sigmas,
            NonNegative,
        )?;
        v.check(
            "",
            "few_lines_turn_sigmas",
            self.few_lines_turn_sigmas,
            NonNegative,
        )?;
        v.check("laser_mount", "x", self.laser_mount.x, Finite)?;
        v.check("laser_mount", "y", self.laser_mount.y, Finite)?;
        v.check("laser_mount", "theta", self.laser_mount.theta, Finite)?;
        let x = "extraction";
        v.check(x, "split_threshold", e.split_threshold, Positive)?;
        v.check(x, "merge_threshold", e.merge_threshold, Positive)?;
        v.check(x, "max_fit_chi2", e.max_fit_chi2, Positive)?;
        v.check(x, "min_points", e.min_points as f64, AtLeast(2.0))?;
        v.check(x, "min_span", e.min_span, NonNegative)?;
        v.check(x, "min_length", e.min_length, NonNegative)?;
        v.check(x, "max_point_gap", e.max_point_gap, Positive)?;
        v.check(x, "min_range", e.min_range, NonNegative)?;
        v.check(x, "max_range", e.max_range, AtLeast(e.min_range.max(0.0)))?;
        v.check(x, "max_range", e.max_range, Positive)?;
        v.check(x, "end_trim_sigmas", e.end_trim_sigmas, NonNegative)?;
        v.check(x, "end_trim_floor", e.end_trim_floor, NonNegative)?;
        v.check("extraction.range_noise", "a", e.range_noise.a, NonNegative)?;
        v.check("extraction.range_noise", "b", e.range_noise.b, NonNegative)?;
        let x = "localizer";
        v.check(x, "gate_sigmas", l.gate_sigmas, NonNegative)?;
        v.check(x, "min_matches", l.min_matches as f64, AtLeast(1.0))?;
        v.check(
            x,
            "max_iterations",
            l.max_iterations as f64,
            Within(1.0, 1000.0),
        )?;
        v.check(
            x,
            "heading_search",
            l.heading_search as f64,
            Within(0.0, 20.0),
        )?;
        v.check(
            x,
            "converged_translation",
            l.converged_translation,
            Positive,
        )?;
        v.check(x, "converged_rotation", l.converged_rotation, Positive)?;
        v.check(x, "max_translation_jump", l.max_translation_jump, Positive)?;
        v.check(x, "max_rotation_jump", l.max_rotation_jump, Positive)?;
        v.check(x, "min_sigma_c", l.min_sigma_c, Positive)?;
        v.check(x, "min_sigma_theta", l.min_sigma_theta, Positive)?;
        v.check(x, "max_observable_sigma", l.max_observable_sigma, Positive)?;
        v.check(
            x,
            "validation_gate_sigmas",
            l.validation_gate_sigmas,
            NonNegative,
        )?;
        v.check(x, "robust_kernel_scale", l.robust_kernel_scale, NonNegative)?;
        v.gates("localizer.correspondence", &l.correspondence)?;
        v.check("map", "merge_gap", m.merge_gap, NonNegative)?;
        v.check("map", "min_sigma_c", m.min_sigma_c, Positive)?;
        v.check("map", "min_sigma_theta", m.min_sigma_theta, Positive)?;
        v.gates("map.fusion", &m.fusion)?;
        let k = &self.keyframes;
        v.check("keyframes", "min_travel", k.min_travel, NonNegative)?;
        v.check("keyframes", "min_rotation", k.min_rotation, NonNegative)?;
        let x = "odometry";
        v.check(
            x,
            "translation_per_metre",
            o.translation_per_metre,
            NonNegative,
        )?;
        v.check(
            x,
            "translation_per_radian",
            o.translation_per_radian,
            NonNegative,
        )?;
        v.check(x, "rotation_per_radian", o.rotation_per_radian, NonNegative)?;
        v.check(x, "rotation_per_metre", o.rotation_per_metre, NonNegative)?;
        v.check(x, "min_translation", o.min_translation, Positive)?;
        v.check(x, "min_rotation", o.min_rotation, Positive)?;
        v.check(x, "floor_period", o.floor_period, NonNegative)?;
        v.check(x, "missing_translation", o.missing_translation, Positive)?;
        v.check(x, "missing_rotation", o.missing_rotation, Positive)?;
        v.check(x, "max_heading_scale", o.max_heading_scale, AtLeast(1.0))?;
        v.check(
            x,
            "max_scale_correction",
            o.max_scale_correction,
            Within(0.0, 0.5),
        )?;
        v.check(
            x,
            "max_heading_drift",
            o.max_heading_drift,
            Within(0.0, 0.2),
        )?;
        v.check("cls", "point_tolerance", c.point_tolerance, NonNegative)?;
        v.check("cls", "max_wedge", c.max_wedge, Wedge)?;
        // A grid finer than 10 µm loses the polygon union to rounding; one
        // coarser than 10 cm is no map.
        v.check("cls.region", "grid", c.region.grid, Within(1e-5, 0.1))?;
        v.check("cls.region", "min_edge", c.region.min_edge, NonNegative)?;
        v.check(
            "cls.region",
            "min_loop_area",
            c.region.min_loop_area,
            NonNegative,
        )?;
        v.check(
            "cls.region",
            "sliver_width",
            c.region.sliver_width,
            NonNegative,
        )?;
        let (x, lc) = ("loop_closure", &self.loop_closure);
        for (key, value) in [
            ("min_travel", lc.min_travel),
            ("search_margin", lc.search_margin),
            ("drift_per_metre", lc.drift_per_metre),
            ("max_search_radius", lc.max_search_radius),
            ("heading_margin", lc.heading_margin),
            ("heading_drift_per_metre", lc.heading_drift_per_metre),
            (
                "vote_heading_drift_per_metre",
                lc.vote_heading_drift_per_metre,
            ),
            ("min_matched_length", lc.min_matched_length),
            ("max_free_space_conflict", lc.max_free_space_conflict),
            ("free_space_tolerance", lc.free_space_tolerance),
            ("chain_sigma_xy_per_metre", lc.chain_sigma_xy_per_metre),
            (
                "chain_sigma_theta_per_metre",
                lc.chain_sigma_theta_per_metre,
            ),
            (
                "chain_sigma_theta_per_radian",
                lc.chain_sigma_theta_per_radian,
            ),
            ("optimize_above_chi2", lc.optimize_above_chi2),
            ("revisit_distance", lc.revisit_distance),
            ("revisit_angle", lc.revisit_angle),
        ] {
            v.check(x, key, value, NonNegative)?;
        }
        for (key, value) in [
            ("loop_sigma_xy", lc.loop_sigma_xy),
            ("loop_sigma_theta", lc.loop_sigma_theta),
            ("chain_sigma_xy", lc.chain_sigma_xy),
            ("chain_sigma_theta", lc.chain_sigma_theta),
        ] {
            v.check(x, key, value, Positive)?;
        }
        v.check(x, "ambiguity_ratio", lc.ambiguity_ratio, Positive)?;
        v.check(
            x,
            "max_candidates",
            lc.max_candidates as f64,
            Within(1.0, 100.0),
        )?;
        v.check(x, "min_matches", lc.min_matches as f64, Within(2.0, 100.0))?;
        v.check(x, "vote_every", lc.vote_every as f64, Within(1.0, 1000.0))?;
        v.check(
            x,
            "reference_keyframes",
            lc.reference_keyframes as f64,
            Within(0.0, 100.0),
        )?;
        let (x, oc) = ("loop_closure.optimizer", &lc.optimizer);
        v.check(
            x,
            "max_iterations",
            oc.max_iterations as f64,
            Within(1.0, 10_000.0),
        )?;
        v.check(x, "converged_step", oc.converged_step, Positive)?;
        v.check(x, "loop_kernel", oc.loop_kernel, NonNegative)?;
        Ok(())
    }
}

/// Largest magnitude any configuration number may have unless its rule
/// says otherwise: a million metres, radians, seconds or sigmas is a typo
/// (and `1e300` overflows the arithmetic it feeds).
pub const MAX_CONFIG_VALUE: f64 = 1e6;

/// What a configuration value must be: the one set of rules for the
/// mapper's and the daemon's configuration files.
#[derive(Debug, Clone, Copy)]
pub enum Rule {
    /// Finite, within ±[`MAX_CONFIG_VALUE`].
    Finite,
    /// In (0, [`MAX_CONFIG_VALUE`]].
    Positive,
    /// In [0, [`MAX_CONFIG_VALUE`]].
    NonNegative,
    /// In [min, [`MAX_CONFIG_VALUE`]].
    AtLeast(f64),
    /// A correspondence angle gate: in (0, π/2), so opposite faces of a
    /// wall never match.
    Gate,
    /// An envelope wedge: in (0, π].
    Wedge,
    /// Within `[lo, hi]`: beyond, a value is a typo or stalls the mapper.
    Within(f64, f64),
}

impl Rule {
    /// Whether `v` keeps the rule.
    pub fn holds(self, v: f64) -> bool {
        use std::f64::consts::{FRAC_PI_2, PI};
        let bounded = v.abs() <= MAX_CONFIG_VALUE;
        v.is_finite()
            && match self {
                Rule::Finite => bounded,
                Rule::Positive => v > 0.0 && bounded,
                Rule::NonNegative => v >= 0.0 && bounded,
                Rule::AtLeast(min) => v >= min && bounded,
                Rule::Gate => v > 0.0 && v < FRAC_PI_2,
                Rule::Wedge => v > 0.0 && v <= PI,
                Rule::Within(lo, hi) => (lo..=hi).contains(&v),
            }
    }

    /// The rule in words, for an error message.
    pub fn text(self) -> String {
        match self {
            Rule::Finite => format!("finite, within ±{MAX_CONFIG_VALUE:e}"),
            Rule::Positive => format!("in (0, {MAX_CONFIG_VALUE:e}]"),
            Rule::NonNegative => format!("in [0, {MAX_CONFIG_VALUE:e}]"),
            Rule::AtLeast(min) => format!("in [{min}, {MAX_CONFIG_VALUE:e}]"),
            Rule::Gate => "in (0, π/2)".into(),
            Rule::Wedge => "in (0, π]".into(),
            Rule::Within(lo, hi) => format!("in [{lo}, {hi}]"),
        }
    }
}

/// Checks values one by one and names the first that breaks its rule.
struct Validator;

impl Validator {
    fn refuse(&self, section: &str, key: &str, value: f64, rule: impl Into<String>) -> ConfigError {
        ConfigError::Range {
            key: if section.is_empty() {
                key.to_string()
            } else {
                format!("[{section}] {key}")
            },
            value,
            rule: rule.into(),
            line: None,
        }
    }

    fn check(&self, section: &str, key: &str, value: f64, rule: Rule) -> Result<(), ConfigError> {
        if rule.holds(value) {
            Ok(())
        } else {
            Err(self.refuse(section, key, value, rule.text()))
        }
    }

    fn gates(&self, section: &str, g: &CorrespondenceConfig) -> Result<(), ConfigError> {
        self.check(section, "max_angle_diff", g.max_angle_diff, Rule::Gate)?;
        self.check(
            section,
            "max_centre_distance",
            g.max_centre_distance,
            Rule::Positive,
        )?;
        self.check(
            section,
            "extent_tolerance",
            g.extent_tolerance,
            Rule::NonNegative,
        )
    }
}

/// Why a mapper configuration was refused.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// Not TOML, an unknown key or a value of the wrong type; the message
    /// names the line and column.
    #[error(transparent)]
    Parse(#[from] toml::de::Error),
    /// A value outside the range the mapper can work with; `line` where
    /// it is written, when the TOML text is known.
    #[error("{key}{} = {value}: must be {rule}", line.map(|l| format!(" (line {l})")).unwrap_or_default())]
    Range {
        key: String,
        value: f64,
        rule: String,
        line: Option<usize>,
    },
}

/// The line (1-based) where the dotted `key` is written in the TOML
/// `text`, or where its table is, if the key itself is not written.
pub fn line_of_key(text: &str, key: &str) -> Option<usize> {
    let doc = toml::de::DeTable::parse(text).ok()?;
    let mut table = doc.get_ref();
    let mut found = None;
    let parts: Vec<&str> = key.split('.').collect();
    for (i, part) in parts.iter().enumerate() {
        let (k, v) = table.get_key_value(*part)?;
        found = Some(k.span().start);
        if i + 1 < parts.len() {
            match v.get_ref() {
                toml::de::DeValue::Table(t) => table = t,
                _ => break,
            }
        }
    }
    found.map(|offset| text[..offset.min(text.len())].matches('\n').count() + 1)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn empty_document_gives_the_defaults() {
        assert_eq!(
            MapperConfig::from_toml("").unwrap(),
            MapperConfig::default()
        );
    }

    /// Range errors name the key and the line it is on, as the daemon's do.
    #[test]
    fn range_errors_name_their_line() {
        let e =
            MapperConfig::from_toml("# x\n[localizer]\ngate_sigmas = 3.0\nmax_iterations = 0\n")
                .unwrap_err()
                .to_string();
        assert!(e.contains("[localizer] max_iterations (line 4)"), "{e}");
    }

    /// `config/mapper.toml` says every key is optional: so is each field
    /// of the laser mount, and a misspelt one is still refused.
    #[test]
    fn a_partial_laser_mount_takes_zero_for_the_rest() {
        let cfg = MapperConfig::from_toml("[laser_mount]\nx = 0.12\n").unwrap();
        assert_eq!(cfg.laser_mount, Pose2::new(0.12, 0.0, 0.0));
        let cfg = MapperConfig::from_toml("laser_mount = { theta = 0.5 }\n").unwrap();
        assert_eq!(cfg.laser_mount, Pose2::new(0.0, 0.0, 0.5));
        assert!(MapperConfig::from_toml("[laser_mount]\nz = 1.0\n").is_err());
    }

    #[test]
    fn sections_override_single_fields() {
        let cfg = MapperConfig::from_toml(
            "[keyframes]\nmin_travel = 1.5\n[map.fusion]\nmax_centre_distance = 0.2\n",
        )
        .unwrap();
        assert_eq!(cfg.keyframes.min_travel, 1.5);
        assert_eq!(
            cfg.keyframes.min_rotation,
            KeyframeConfig::default().min_rotation
        );
        assert_eq!(cfg.map.fusion.max_centre_distance, 0.2);
    }

    #[test]
    fn unknown_keys_are_refused_with_their_line() {
        let err = MapperConfig::from_toml("[keyframes]\nmin_travel = 1.0\nmin_travle = 2.0\n")
            .unwrap_err();
        let text = err.to_string();
        assert!(text.contains("min_travle") && text.contains('3'), "{text}");
    }

    #[test]
    fn increment_noise_grows_with_motion_and_has_floors() {
        let n = OdometryNoise::default();
        let period = n.floor_period;
        let still = n.increment_covariance(Some(&Pose2::IDENTITY), period);
        assert_eq!(still[0][0], n.min_translation.powi(2));
        assert_eq!(still[2][2], n.min_rotation.powi(2));
        let walk = n.increment_covariance(Some(&Pose2::new(1.0, 0.0, 0.0)), period);
        assert!(walk[0][0] > still[0][0] && walk[2][2] > still[2][2]);
        let none = n.increment_covariance(None, period);
        assert_eq!(none[1][1], n.missing_translation.powi(2));
    }

    /// Standing still for a second spreads the prior as much at 37.5 Hz
    /// as at 5 Hz; longer periods and unknown ones keep the floors whole.
    #[test]
    fn the_floors_add_up_to_the_same_spread_per_second_at_any_rate() {
        let n = OdometryNoise::default();
        let still = |period: f64| n.increment_covariance(Some(&Pose2::IDENTITY), period);
        let per_second = |period: f64| still(period)[0][0] / period;
        let (slow, fast) = (per_second(n.floor_period), per_second(1.0 / 37.5));
        assert!((fast / slow - 1.0).abs() < 1e-9, "{fast} vs {slow}");
        let heading = |period: f64| still(period)[2][2] / period;
        assert!((heading(1.0 / 37.5) / heading(n.floor_period) - 1.0).abs() < 1e-9);
        for period in [1.0, 0.0, -0.1, f64::NAN] {
            assert_eq!(still(period)[0][0], n.min_translation.powi(2), "{period}");
        }
        let per_scan = OdometryNoise {
            floor_period: 0.0,
            ..n
        };
        let fast = per_scan.increment_covariance(Some(&Pose2::IDENTITY), 1.0 / 37.5);
        assert_eq!(fast[0][0], n.min_translation.powi(2));
    }
}

#[cfg(test)]
mod documented_defaults {
    use super::*;

    /// `config/mapper.toml` lists every key with its default: it must
    /// parse, and give exactly the defaults, so the two never drift apart.
    #[test]
    fn the_documented_config_is_the_default() {
        let text = include_str!("../../config/mapper.toml");
        let parsed = MapperConfig::from_toml(text).unwrap();
        assert_eq!(parsed, MapperConfig::default());
        // And it names every key: serialise the defaults and look for each.
        let defaults = toml::to_string(&MapperConfig::default()).unwrap();
        for line in defaults.lines() {
            if let Some((key, _)) = line.split_once(" = ") {
                assert!(
                    text.lines().any(|l| l
                        .trim_start()
                        .trim_start_matches("# ")
                        .starts_with(&format!("{key} ="))),
                    "config/mapper.toml does not document `{key}`"
                );
            }
        }
    }

    #[test]
    fn out_of_range_values_are_refused_by_name() {
        for (text, key) in [
            (
                "[extraction]\nmax_point_gap = 0.0\n",
                "[extraction] max_point_gap",
            ),
            (
                "[localizer]\ngate_sigmas = inf\n",
                "[localizer] gate_sigmas",
            ),
            ("odometry_time_offset = nan\n", "odometry_time_offset"),
            (
                "[map.fusion]\nmax_angle_diff = 2.0\n",
                "[map.fusion] max_angle_diff",
            ),
            ("[cls.region]\ngrid = -0.001\n", "[cls.region] grid"),
            ("[cls.region]\ngrid = 1e-300\n", "[cls.region] grid"),
            ("[cls.region]\ngrid = 1e300\n", "[cls.region] grid"),
            (
                "[localizer]\nmax_iterations = 4000000000\n",
                "[localizer] max_iterations",
            ),
            // Every number has a bound, not just a sign.
            ("[map]\nmerge_gap = 1e300\n", "[map] merge_gap"),
            (
                "[loop_closure]\nmin_travel = 1e7\n",
                "[loop_closure] min_travel",
            ),
            ("odometry_time_offset = -1e9\n", "odometry_time_offset"),
        ] {
            let err = MapperConfig::from_toml(text).unwrap_err().to_string();
            assert!(err.starts_with(key), "{text:?}: {err}");
        }
        assert!(MapperConfig::from_toml("max_correction_sigmas = inf\n").is_ok());
    }

    #[test]
    fn the_csail_config_parses() {
        let text = include_str!("../../config/csail.toml");
        let cfg = MapperConfig::from_toml(text).unwrap();
        assert!(cfg.odometry_time_offset < 0.0);
    }
}
