//! What a mapping run did ([`MappingSummary`]) and how long each stage
//! took ([`StageTimes`], [`LastScanTimes`]).

use std::collections::BTreeMap;
use std::time::Duration;

use serde::Serialize;

use crate::graph::LoopStats;

/// Accumulated wall-clock time of one stage.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct StageClock {
    total: Duration,
    runs: usize,
    /// Time in the last scan processed, if the stage ran in it.
    last: Option<Duration>,
}

impl StageClock {
    pub(super) fn add(&mut self, d: Duration) {
        self.total += d;
        self.runs += 1;
        self.last = Some(d);
    }

    fn mean_us(&self) -> f64 {
        if self.runs == 0 {
            0.0
        } else {
            self.total.as_secs_f64() * 1e6 / self.runs as f64
        }
    }
}

/// The clock of each stage of [`super::Mapper::process`].
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct StageClocks {
    pub predict: StageClock,
    pub extract: StageClock,
    pub localize: StageClock,
    pub map_update: StageClock,
    pub cls_update: StageClock,
    /// Matching the scan's points against the last scan's.
    pub scan_match: StageClock,
    /// The whole of `process`.
    pub whole: StageClock,
}

impl StageClocks {
    /// A new scan: no stage has run in it yet.
    pub(super) fn start_scan(&mut self) {
        for clock in [
            &mut self.predict,
            &mut self.extract,
            &mut self.localize,
            &mut self.map_update,
            &mut self.cls_update,
            &mut self.scan_match,
            &mut self.whole,
        ] {
            clock.last = None;
        }
    }

    /// Mean time per run of each stage.
    pub(super) fn means(&self) -> StageTimes {
        StageTimes {
            predict_us: self.predict.mean_us(),
            extract_us: self.extract.mean_us(),
            localize_us: self.localize.mean_us(),
            map_update_us: self.map_update.mean_us(),
            cls_update_us: self.cls_update.mean_us(),
            scan_match_us: self.scan_match.mean_us(),
            per_scan_us: self.whole.mean_us(),
        }
    }

    /// Each stage's time in the last scan.
    pub(super) fn last(&self) -> LastScanTimes {
        LastScanTimes {
            predict: self.predict.last,
            extract: self.extract.last,
            localize: self.localize.last,
            map_update: self.map_update.last,
            cls_update: self.cls_update.last,
            whole: self.whole.last,
        }
    }
}

/// Mean time per run of each stage (µs).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct StageTimes {
    /// Odometry prediction, per scan.
    pub predict_us: f64,
    /// Line extraction, per scan.
    pub extract_us: f64,
    /// Localization, per scan that had a map to localize against.
    pub localize_us: f64,
    /// Segment map update, per keyframe.
    pub map_update_us: f64,
    /// CLS map update (local map, region union, fusion), per keyframe.
    pub cls_update_us: f64,
    /// Matching a scan's points against the last scan's, per scan matched
    /// (an offline run's; 0 when none was).
    pub scan_match_us: f64,
    /// Whole pipeline, per scan.
    pub per_scan_us: f64,
}

/// Wall-clock time of each stage in the last scan processed; `None` for
/// a stage that did not run in it (no map yet, not a keyframe).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LastScanTimes {
    pub predict: Option<Duration>,
    pub extract: Option<Duration>,
    pub localize: Option<Duration>,
    pub map_update: Option<Duration>,
    pub cls_update: Option<Duration>,
    pub whole: Option<Duration>,
}

/// Summary of a mapping run.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct MappingSummary {
    pub scans: usize,
    pub keyframes: usize,
    /// Segments in the final map.
    pub segments: usize,
    /// Actual and virtual segments and loops of the final CLS map.
    pub cls_actual: usize,
    pub cls_virtual: usize,
    pub cls_loops: usize,
    /// Scans whose lines left a direction unobservable (corridors).
    pub degenerate_scans: usize,
    /// Scans whose localization failed; the prediction was used.
    pub rejected_localizations: usize,
    /// The failures by kind (`TooFewMatches`, `ImplausibleJump`, ...).
    pub rejections_by_kind: BTreeMap<String, usize>,
    /// Scans with too few matches kept out of the map: the first after a
    /// localized scan whose lines were enough to match (more likely
    /// odometry gone wrong than new territory).
    pub held_back: usize,
    /// Where a recording broke off, when it did (the scans before were mapped).
    pub input_broken: Option<String>,
    /// Input items skipped (malformed lines, bad odometry samples, damaged
    /// recording records, scans out of time order), and the first few.
    pub skipped_input: usize,
    pub skipped_examples: Vec<String>,
    /// Scans whose odometry was not finite: mapped as scans without it.
    pub scans_with_bad_odometry: usize,
    /// Scans before the robot was found in a loaded map (no pose).
    pub scans_before_start: usize,
    /// Times the robot was found again in a loaded map after it was lost.
    pub relocalizations: usize,
    /// Pose hints taken (each restarts the search for the robot).
    pub pose_hints: usize,
    /// Keyframes whose CLS map update was refused (the map kept as it was).
    pub cls_rejected: usize,
    /// Scans that carried no odometry.
    pub scans_without_odometry: usize,
    /// Scans whose logged odometry an offline run wrote beside the
    /// trajectory (`odometry.tum`), the baseline to score it against.
    pub logged_odometry: usize,
    /// Scans whose odometry equalled the previous scan's (standing still,
    /// or odometry frozen); predicted at constant velocity.
    pub scans_with_unchanged_odometry: usize,
    /// Factor on the odometry's heading σ learnt at the end of the run
    /// (1: the noise model fits; see `OdometryNoise::max_heading_scale`).
    pub odometry_heading_scale: f64,
    /// Factor on the odometry's distances learnt at the end of the run
    /// (1: taken as read; see `OdometryNoise::max_scale_correction`).
    pub odometry_scale: f64,
    /// The heading drift added to the odometry's turns (rad/m; 0: taken
    /// as read; see `OdometryNoise::max_heading_drift`).
    pub odometry_heading_drift: f64,
    /// The time offset (s) the odometry was read at by the end of the run:
    /// learnt, or as configured (see `MapperConfig::max_scan_lag`).
    pub odometry_time_offset: f64,
    /// Scans localized from a searched heading because nothing matched
    /// from the odometry's (see `LocalizerConfig::heading_search`).
    pub heading_searches: usize,
    /// Scans predicted from the scans' own step because it contradicted
    /// the odometry's (see `MapperConfig::odometry_check_sigmas`).
    pub odometry_steps_overruled: usize,
    /// Loop closure: searches, loops accepted and rejected, optimisations.
    pub loops: LoopStats,
    pub mean_time: StageTimes,
}
