//! Configuration of the offline mapper (`clsmap map`): one TOML document
//! with a section per stage. Every section and field has a documented
//! default, so an empty document is a complete configuration, and unknown
//! keys are refused so a typo is never silently ignored.
//!
//! ```toml
//! laser_mount = { x = 0.0, y = 0.0, theta = 0.0 }
//! max_correction_sigmas = inf
//! odometry_time_offset = 0.0
//! update_map_when_unlocalized = false
//! [extraction]            # geometry::ExtractionConfig
//! [localizer]             # localize::LocalizerConfig
//! [localizer.correspondence]   # matching gates for localization
//! [map]                   # map::SegmentMapConfig
//! [map.fusion]            # correspondence gates for fusing into the map
//! [keyframes]             # map::KeyframeConfig
//! [odometry]              # OdometryNoise
//! ```

use crate::geometry::{ExtractionConfig, Pose2};
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
    /// Translation σ floor per scan (m). Default 0.01: keeps the prior
    /// finite when the robot stands still.
    pub min_translation: f64,
    /// Rotation σ floor per scan (rad). Default 0.005.
    pub min_rotation: f64,
    /// Translation σ of a scan without usable odometry (none, or frozen)
    /// predicted at constant velocity (m). Default 0.3: the gates must then
    /// cover a change of pace over a scan period.
    pub missing_translation: f64,
    /// Rotation σ of a scan without usable odometry (rad). Default 0.15.
    pub missing_rotation: f64,
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
            missing_translation: 0.3,
            missing_rotation: 0.15,
        }
    }
}

impl OdometryNoise {
    /// Covariance (x, y, θ; map-frame axes) of an odometry increment of
    /// `delta` (robot frame); `None` = no odometry for this step. The
    /// translation noise is isotropic, as suits a holonomic base.
    pub fn increment_covariance(&self, delta: Option<&Pose2>) -> [[f64; 3]; 3] {
        let (sigma_t, sigma_r) = match delta {
            Some(d) => {
                let dist = d.x.hypot(d.y);
                let turn = d.theta.abs();
                (
                    (self.translation_per_metre * dist + self.translation_per_radian * turn)
                        .max(self.min_translation),
                    (self.rotation_per_radian * turn + self.rotation_per_metre * dist)
                        .max(self.min_rotation),
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
}

/// Everything the offline mapper needs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MapperConfig {
    /// Laser pose in the robot frame (m, rad). Default: the identity, as in
    /// the CSAIL log whose laser pose equals its odometry pose.
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
    /// holds the newest odometry). Default 0 (trust the log). Estimate it
    /// without ground truth by comparing the heading steps of localized
    /// scans with the odometry's at shifted times: on CSAIL they agree best
    /// at −0.5 to −0.6 scan periods, about −0.1 s (see config/csail.toml).
    pub odometry_time_offset: f64,
    /// Whether a keyframe whose localization failed for a reason other
    /// than too few matches (an inconsistent, non-converged or implausible
    /// fix) still updates the map at the predicted pose. Default false:
    /// such poses are doubtful and wrong walls in the map mislead every
    /// later scan; scans of unmapped space (too few matches) always update.
    pub update_map_when_unlocalized: bool,
    /// When the map offers too few matches, localize against the previous
    /// scan's lines instead (line scan matching). Default true.
    pub previous_scan_fallback: bool,
    /// The Closed Line Segment map grown on keyframes.
    pub cls: ClsTuning,
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
            update_map_when_unlocalized: false,
            previous_scan_fallback: true,
            cls: ClsTuning::default(),
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

    /// Parses a TOML document; errors carry line and column.
    pub fn from_toml(text: &str) -> Result<MapperConfig, toml::de::Error> {
        toml::from_str(text)
    }
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
        let still = n.increment_covariance(Some(&Pose2::IDENTITY));
        assert_eq!(still[0][0], n.min_translation.powi(2));
        assert_eq!(still[2][2], n.min_rotation.powi(2));
        let walk = n.increment_covariance(Some(&Pose2::new(1.0, 0.0, 0.0)));
        assert!(walk[0][0] > still[0][0] && walk[2][2] > still[2][2]);
        let none = n.increment_covariance(None);
        assert_eq!(none[1][1], n.missing_translation.powi(2));
    }
}

#[cfg(test)]
mod documented_defaults {
    use super::*;

    /// `config/mapper.toml` lists every key with its default: it must
    /// parse, and give exactly the defaults, so the two never drift apart.
    #[test]
    fn the_documented_config_is_the_default() {
        let text = include_str!("../config/mapper.toml");
        let parsed = MapperConfig::from_toml(text).unwrap();
        assert_eq!(parsed, MapperConfig::default());
        // And it names every key: serialise the defaults and look for each.
        let defaults = toml::to_string(&MapperConfig::default()).unwrap();
        for line in defaults.lines() {
            if let Some((key, _)) = line.split_once(" = ") {
                assert!(
                    text.lines()
                        .any(|l| l.trim_start().starts_with(&format!("{key} ="))),
                    "config/mapper.toml does not document `{key}`"
                );
            }
        }
    }

    #[test]
    fn the_csail_config_parses() {
        let text = include_str!("../config/csail.toml");
        let cfg = MapperConfig::from_toml(text).unwrap();
        assert!(cfg.odometry_time_offset < 0.0);
    }
}
