//! The mapper: scans with odometry in, a trajectory, a map of
//! actual segments (what localization matches against) and the Closed Line
//! Segment map (the explored region, walls and frontiers) out.
//!
//! Per scan: the odometry increment since the previous scan predicts the
//! pose (see [`MotionPredictor`] for frozen or missing odometry); lines are
//! extracted; the pose is localized against the map (a failed or
//! implausible fix is replaced by the prediction and counted); on
//! keyframes the map is updated; the pose is recorded with the scan's own
//! timestamp. The map frame is the robot pose at the first scan.
//!
//! The map learns only from poses worth trusting: localized ones, the
//! first scan, and scans of unmapped space (too few matches) predicted
//! from real odometry. A fix refused for any other reason, or a pose
//! guessed at constant velocity, leaves the map alone: one wrongly placed
//! wall misleads every later scan that sees it.
//!
//! Only this layer reads a clock (`Instant`, for the per-stage timing);
//! the algorithms it calls take none, so runs are deterministic.
//!
//! - [`config`]: [`MapperConfig`], every tunable of the mapper, as the
//!   `[mapper]` table and `clsmap map --config` read it.
//! - [`mapper`]: [`Mapper`], one scan at a time (offline and live alike).
//! - [`prediction`]: the odometry's prediction of each scan's pose.
//! - [`start`]: where a run starts in a loaded map, and finding it again.
//! - [`rejection`]: why a scan's localization was not used, by kind.
//! - [`summary`]: what a run did and how long each stage took.
//! - [`output`]: the files a run writes (trajectory, map, picture).
//! - [`offline`]: a log file mapped from start to end.

use std::path::PathBuf;

use serde::Serialize;
use thiserror::Error;

use crate::files::trajectory::TrajectoryError;
use crate::geometry::Pose2;
use crate::input::InputError;

pub mod config;
mod jambs;
pub mod mapper;
pub mod offline;
pub mod output;
pub mod prediction;
pub mod rejection;
pub mod smoothing;
pub mod start;
pub mod summary;

pub use config::MapperConfig;
pub use mapper::Mapper;
pub use offline::{
    MapRunOptions, NoiseScaling, Progress, SKIPPED_EXAMPLES, evaluate_relations,
    run_offline_mapping, take_declared_mount, take_no_return_code, take_wall_scatter,
};
pub use output::{
    MAP_FILE, ODOMETRY_FILE, PICTURE_FILE, TRAJECTORY_FILE, create_output_dir, write_maps,
    write_odometry, write_outputs,
};
pub use prediction::{MotionPredictor, OdometryFeed, OdometryReading, Prediction};
pub use rejection::RejectionKind;
pub use start::{MapMode, StartSearch};
pub use summary::{LastScanTimes, MappingSummary, StageTimes};

#[derive(Debug, Error)]
pub enum PipelineError {
    #[error("cannot read the input")]
    Input(#[from] InputError),
    #[error("the input holds no scans")]
    NoScans,
    #[error("cannot write {}", path.display())]
    Output {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot encode the trajectory")]
    Trajectory(#[from] TrajectoryError),
    #[error("cannot encode the segment map")]
    Json(#[from] serde_json::Error),
    #[error("cannot save the map")]
    Store(#[from] crate::map::cls::StoreError),
    #[error("cannot start from the map: {0}")]
    StartMap(String),
    #[error(
        "a pose hint is taken in a loaded map only (run --map): a new map's frame starts where the robot started"
    )]
    HintWithoutMap,
    #[error("the pose hint is not a finite pose: {0:?}")]
    BadHint(Pose2),
}

/// What happened to one scan.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanOutcome {
    /// Robot pose in the map frame.
    pub pose: Pose2,
    /// Whether localization succeeded (else `pose` is the prediction).
    pub localized: bool,
    /// Whether the lines left a translation direction unobservable (the
    /// prediction was kept along it).
    pub degenerate: bool,
    /// Whether the scan updated the map.
    pub keyframe: bool,
    /// Lines extracted from the scan.
    pub lines: usize,
    /// Lines matched to the map.
    pub matches: usize,
    /// Why localization was not used, if it was not (the kinds counted in
    /// [`MappingSummary::rejections_by_kind`]).
    pub rejection: Option<RejectionKind>,
    /// Whether the pose came from the previous scan's lines because the
    /// map offered too few matches.
    pub by_previous_scan: bool,
    /// Whether the map's lines were matched from the heading the last
    /// scan's points gave, because neither the map's lines nor the last
    /// scan's matched enough from the prediction.
    pub by_last_scan_points: bool,
}

/// A search for the robot in a loaded map, with its hypotheses so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum MapSearch {
    /// Not found yet since the start.
    Finding(usize),
    /// Lost after being found; being looked for again.
    Lost(usize),
}
