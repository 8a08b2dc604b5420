//! A log file (CARMEN or recording) mapped from start to end, its outputs
//! written, and scored against a relations file.

use std::path::Path;

use tracing::warn;

use super::output::{write_odometry, write_outputs};
use super::start::MapMode;
use super::summary::MappingSummary;
use super::{Mapper, PipelineError};
use crate::eval::{EvalError, RelationErrors, evaluate_relations as evaluate_against};
use crate::files::trajectory::StampedPose;
use crate::geometry::Pose2;
use crate::input::{
    DeclaredMount, InputError, LogOptions, declared_laser_mount, no_return_code, open_log_with,
};
use crate::map::file::ChecksumCheck;
use crate::pipeline::config::MapperConfig;

/// Progress of [`run_offline_mapping`], reported after every scan.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Progress {
    pub scans: usize,
    /// Bytes of the input consumed so far.
    pub bytes_read: u64,
    /// Size of the input (bytes).
    pub bytes_total: u64,
}

/// How [`run_offline_mapping`] runs.
#[derive(Debug, Clone, Copy, Default)]
pub struct MapRunOptions<'a> {
    /// Draw the accepted loop closures on the picture.
    pub draw_loops: bool,
    /// Stop at the first input item that cannot be used.
    pub strict: bool,
    /// Go on from a saved map, localizing in it or extending it, instead
    /// of starting a new one.
    pub start_from: Option<(&'a Path, MapMode)>,
    /// How the saved map's checksum is checked.
    pub checksum: ChecksumCheck,
    /// How the input is read (a bag's topics); the defaults when `None`.
    pub log: Option<&'a LogOptions>,
}

/// How many skipped input items are named one by one (the rest counted).
pub const SKIPPED_EXAMPLES: usize = 5;

/// Maps a log file offline and writes its outputs (see [`write_outputs`])
/// and the log's own odometry (see [`write_odometry`]) into `out_dir`
/// (created if needed). Input items that cannot be used (a
/// malformed line, a bad odometry sample, a damaged recording record, a
/// scan out of time order) are skipped, counted and the first few named
/// (see [`crate::input`]); with `strict` the first one ends the run with
/// its error and nothing is written. A recording cut short (a killed
/// recorder, a power loss) is mapped up to the break; the summary says
/// where it broke.
pub fn run_offline_mapping(
    input: &Path,
    out_dir: &Path,
    config: &MapperConfig,
    options: &MapRunOptions<'_>,
    progress: &mut dyn FnMut(Progress),
) -> Result<MappingSummary, PipelineError> {
    let MapRunOptions {
        draw_loops,
        strict,
        start_from,
        checksum,
        log,
    } = *options;
    let mut mapper = match start_from {
        Some((map, mode)) => {
            let loaded = crate::map::file::load_with(map, checksum)?;
            Mapper::from_map(*config, loaded.contents, mode)?
        }
        None => Mapper::new(*config),
    };
    let mut log = open_log_with(input, log.unwrap_or(&LogOptions::default()))?;
    mapper.defer_cls_rebuild();
    mapper.measure_scan_steps();
    let mut input_broken = None;
    let (mut skipped, mut examples) = (0, Vec::new());
    // The log's own odometry at each mapped scan: the baseline.
    let mut odometry: Vec<StampedPose> = Vec::new();
    while let Some(record) = log.next() {
        let record = match record {
            Ok(r) => r,
            Err(e) if e.is_skipped_item() && !strict => {
                skipped += 1;
                if examples.len() < SKIPPED_EXAMPLES {
                    warn!("skipped: {e}");
                    examples.push(e.to_string());
                }
                continue;
            }
            Err(e) if e.is_break() && !strict => {
                warn!("{e}: mapping the scans before the break");
                input_broken = Some(e.to_string());
                break;
            }
            Err(e) => return Err(e.into()),
        };
        mapper.process(&record);
        if let Some(o) = record.odometry.filter(Pose2::is_finite) {
            odometry.push((record.scan.t, o));
        }
        progress(Progress {
            scans: mapper.summary.scans,
            bytes_read: log.bytes_read(),
            bytes_total: log.size(),
        });
    }
    if mapper.trajectory().is_empty() {
        if mapper.summary.scans_before_start > 0 {
            return Err(PipelineError::StartMap(format!(
                "the robot was not found in the map in any of the {} scans",
                mapper.summary.scans_before_start
            )));
        }
        return Err(PipelineError::NoScans);
    }
    mapper.settle();
    let mut summary = mapper.summary();
    summary.input_broken = input_broken;
    summary.skipped_input = skipped;
    summary.skipped_examples = examples;
    if skipped > SKIPPED_EXAMPLES {
        warn!("{skipped} input items skipped in all");
    }
    if summary.rejected_localizations > 0 {
        warn!(
            rejected = summary.rejected_localizations,
            scans = summary.scans,
            by_kind = ?summary.rejections_by_kind,
            "localization failed on some scans; their odometry prediction was used"
        );
    }
    summary.logged_odometry = odometry.len();
    write_outputs(out_dir, &mapper, draw_loops)?;
    write_odometry(out_dir, &odometry)?;
    Ok(summary)
}

/// Takes the laser's mounting on the robot from the log at `input` where
/// it declares one (CARMEN ROBOTLASER1 lines give the laser's pose beside
/// the robot's, a bag its `/tf_static`): for a configuration that leaves
/// `laser_mount` out. Mapped
/// as if it sat at the robot's centre, a laser 0.25 m ahead of it swings
/// through every turn on the spot: in a simulated loop the relations came
/// out 0.032 m off on average against 0.003 m (`tests/mapping.rs`).
/// Returns what the log declared.
pub fn take_declared_mount(
    config: &mut MapperConfig,
    input: &Path,
    options: &LogOptions,
) -> Result<DeclaredMount, InputError> {
    let declared = declared_laser_mount(input, options)?;
    if let DeclaredMount::Fixed(mount) = declared {
        config.laser_mount = mount;
    }
    Ok(declared)
}

/// Takes a log's own code for no return out of the ranges used: where the
/// log at `input` writes one below the SICK codes (see
/// [`crate::input::carmen::repeated_no_return`]), `extraction.max_range`
/// comes down to just under it, for a configuration that leaves it out.
/// Read as echoes, such codes draw arcs of phantom points at their range:
/// in a simulated loop logged with 20 m for no return, walls along the arcs
/// took the relations from 0.004 to 0.082 m off, and with 50 m the CLS map
/// took free space through its walls (`tests/mapping.rs`). Returns the
/// code found.
pub fn take_no_return_code(
    config: &mut MapperConfig,
    input: &Path,
) -> Result<Option<f64>, InputError> {
    let code = no_return_code(input)?;
    if let Some(code) = code {
        config.extraction.max_range = config.extraction.max_range.min(code - NO_RETURN_MARGIN);
    }
    Ok(code)
}

/// How much wider than the scatter a log shows the range noise model is
/// kept. The default 1 cm holds the LMS200's 5 mm statistical error with
/// room for its ±15 mm systematic one and for walls not quite flat; every
/// SICK log measured scatters 4–7.3 mm (CSAIL 5.8 mm; CSAIL thinned, up to
/// 6.1 mm), which it serves as it is. A log scattering more than 8 mm
/// gets a model 1.25 times its scatter.
const NOISE_MODEL_MARGIN: f64 = 1.25;

/// The range noise a log shows and what the configuration was scaled by
/// for it ([`take_wall_scatter`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseScaling {
    pub scatter: crate::geometry::WallScatter,
    /// Factor on the range noise model and the line split and merge
    /// thresholds (> 1).
    pub factor: f64,
}

/// Widens the range noise model to the noise the log at `input` shows,
/// when that is more than the model allows (`NOISE_MODEL_MARGIN`): the
/// model (`extraction.range_noise`) and the line split and merge
/// thresholds, which are a few σ of it, scale alike. Some public logs'
/// ranges scatter four times as much as an LMS200's (ACES, on a 5 cm
/// grid): with the LMS200's thresholds their walls broke into pieces whose
/// ends read as jambs, and the mapping went 1.7 m wrong (0.39 m with the
/// standstill read right); scaled, 0.05 m.
/// Returns what was found and done, `None` when nothing changed.
pub fn take_wall_scatter(
    config: &mut MapperConfig,
    input: &Path,
    options: &LogOptions,
) -> Result<Option<NoiseScaling>, InputError> {
    let Some(scatter) = crate::input::wall_scatter(input, options)? else {
        return Ok(None);
    };
    let extraction = &mut config.extraction;
    let factor = NOISE_MODEL_MARGIN * scatter.sigma / extraction.range_noise.a;
    if !(factor > 1.0 && factor.is_finite()) {
        return Ok(None);
    }
    extraction.range_noise.a *= factor;
    extraction.range_noise.b *= factor;
    extraction.split_threshold *= factor;
    extraction.merge_threshold *= factor;
    Ok(Some(NoiseScaling { scatter, factor }))
}

/// How far under a log's code for no return (m) the ranges used end: a
/// millimetre, below any range resolution.
const NO_RETURN_MARGIN: f64 = 1e-3;

/// The relation metric of a trajectory against a relations file; see
/// [`crate::eval`].
pub fn evaluate_relations(
    trajectory: &[StampedPose],
    relations_path: &Path,
) -> Result<RelationErrors, EvalError> {
    evaluate_against(trajectory, relations_path)
}
