//! `clsmap demo`: the whole chain on one machine, at real line speed.
//!
//! An emulated LMS200 on a pseudo-terminal measures a built-in floor plan by
//! ray casting while a simulated holonomic base drives a scripted tour; the
//! real serial driver opens the pty, auto-bauds, configures the sensor and
//! streams at 500 kBd; each scan is converted to SI, paired with drifting
//! simulated odometry, localized against the map and fused into it. At the
//! end the map, its picture and the trajectory are written, and the
//! estimate is scored against the simulator's ground truth.

use std::io;
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::time::Instant;

use lms200::driver::{DriverError, SerialDriver};
use lms200::emulator::{Emulator, EmulatorConfig};
use lms200::link::{Event, LinkConfig, LinkStats};
use lms200::pty::{PtyEmulator, PtyError};
use serde::Serialize;

use crate::geometry::{Pose2, wrap_angle};
use crate::input::ScanRecord;
use crate::input::lms200::range_scan;
use crate::mapping_config::MapperConfig;
use crate::pipeline::{OfflineMapper, PipelineError, write_outputs};
use crate::sim::{LMS200_MAX_RANGE_MM_MODE, Rng, Tour, World, WorldRangeSource};

/// Why the demo failed.
#[derive(Debug, thiserror::Error)]
pub enum DemoError {
    #[error("cannot start the emulated LMS200")]
    Emulator(#[from] PtyError),
    #[error("the serial driver failed")]
    Driver(#[from] DriverError),
    #[error("the sensor delivered no scan (link: {0})")]
    NoScans(String),
    #[error("cannot write the results")]
    Output(#[from] PipelineError),
    #[error("cannot write {path}")]
    Io {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
}

/// A world and the tour the robot drives through it.
#[derive(Debug, Clone)]
pub struct Scenario {
    pub name: String,
    pub world: World,
    pub tour: Tour,
}

impl Scenario {
    /// The built-in default: once around a 2 m wide corridor loop around a
    /// central 8 m × 6 m block, and on past the start so the loop closes.
    pub fn loop_around_block(speed: f64) -> Scenario {
        use std::f64::consts::{FRAC_PI_2, PI};
        let waypoints = vec![
            Pose2::new(1.0, 1.0, 0.0),
            Pose2::new(11.0, 1.0, 0.0),
            Pose2::new(11.0, 1.0, FRAC_PI_2),
            Pose2::new(11.0, 9.0, FRAC_PI_2),
            Pose2::new(11.0, 9.0, PI),
            Pose2::new(1.0, 9.0, PI),
            Pose2::new(1.0, 9.0, -FRAC_PI_2),
            Pose2::new(1.0, 1.0, -FRAC_PI_2),
            Pose2::new(1.0, 1.0, 0.0),
            Pose2::new(5.0, 1.0, 0.0),
        ];
        Scenario {
            name: "loop around a block".into(),
            world: World::loop_around_block(),
            tour: Tour::new(waypoints, speed, FRAC_PI_2),
        }
    }
}

/// How the demo runs.
#[derive(Debug, Clone)]
pub struct DemoOptions {
    pub out_dir: PathBuf,
    /// Seed of the range noise and the odometry errors.
    pub seed: u64,
    /// Range noise of the emulated sensor (m); the LMS200's is about 1 cm.
    pub range_sigma: f64,
    /// Odometry scale error (fraction of the distance travelled).
    pub odometry_scale_error: f64,
    /// Odometry heading drift (rad per metre travelled).
    pub odometry_heading_drift: f64,
    /// Time the robot waits before driving, while the driver connects (s).
    pub start_delay: f64,
    pub mapper: MapperConfig,
}

impl DemoOptions {
    pub fn new(out_dir: impl Into<PathBuf>) -> Self {
        DemoOptions {
            out_dir: out_dir.into(),
            seed: 7,
            range_sigma: 0.01,
            odometry_scale_error: 0.02,
            odometry_heading_drift: 0.01,
            start_delay: 1.5,
            mapper: MapperConfig::default(),
        }
    }
}

/// Live progress, reported after every scan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DemoProgress {
    /// Seconds into the tour.
    pub t: f64,
    pub tour_duration: f64,
    pub scans: usize,
    pub segments: usize,
    /// Distance of the estimate from the truth (m).
    pub error: f64,
    /// Distance of the odometry from the truth (m).
    pub odometry_error: f64,
}

/// What the demo did and how well.
#[derive(Debug, Clone, Serialize)]
pub struct DemoSummary {
    pub scenario: String,
    pub scans: usize,
    pub segments: usize,
    /// Actual and virtual segments and loops of the CLS map.
    pub cls_actual: usize,
    pub cls_virtual: usize,
    pub cls_loops: usize,
    pub connected_baud: Option<u32>,
    pub dropped_frames: u64,
    /// Mean and largest position error of the estimate against the truth (m).
    pub mean_error_m: f64,
    pub max_error_m: f64,
    /// Largest heading error of the estimate (deg).
    pub max_heading_error_deg: f64,
    /// Position error of the odometry alone at the end (m).
    pub odometry_final_error_m: f64,
    /// Position error of the estimate at the end (m).
    pub final_error_m: f64,
    pub out_dir: PathBuf,
}

/// Integrates the true motion with scale error, heading drift and noise,
/// as wheel odometry does.
#[derive(Debug)]
struct SimulatedOdometry {
    last_truth: Option<Pose2>,
    pose: Pose2,
    scale_error: f64,
    heading_drift: f64,
    rng: Rng,
}

impl SimulatedOdometry {
    fn step(&mut self, truth: Pose2) -> Pose2 {
        if let Some(last) = self.last_truth {
            let d = last.between(&truth);
            let dist = d.x.hypot(d.y);
            let noisy = Pose2::new(
                d.x * (1.0 + self.scale_error) + self.rng.normal(0.002 * dist),
                d.y * (1.0 + self.scale_error) + self.rng.normal(0.002 * dist),
                d.theta + self.heading_drift * dist + self.rng.normal(0.002 * dist),
            );
            self.pose = self.pose.compose(&noisy);
        } else {
            self.pose = truth;
        }
        self.last_truth = Some(truth);
        self.pose
    }
}

/// Runs the demo to the end of the scenario's tour.
pub fn run_demo(
    scenario: &Scenario,
    options: &DemoOptions,
    mut on_progress: impl FnMut(&DemoProgress),
) -> Result<DemoSummary, DemoError> {
    let t0 = Instant::now();
    // The tour's clock starts `start_delay` after the emulator's.
    let delay = options.start_delay.max(0.0);
    let shifted_tour = scenario.tour.delayed(delay);
    let source = WorldRangeSource::new(
        scenario.world.clone(),
        shifted_tour.clone(),
        Pose2::IDENTITY,
        LMS200_MAX_RANGE_MM_MODE,
        options.range_sigma,
        options.seed,
    );
    let sensor = EmulatorConfig {
        power_on_delay: None,
        ..EmulatorConfig::default()
    };
    let emulator = Emulator::with_range_source(sensor, Box::new(source), t0);
    let pty = PtyEmulator::spawn(emulator, None)?;
    let link = LinkConfig::default();
    let mode = link.measuring_mode;
    let mut driver = SerialDriver::open(pty.tty_path(), link)?;

    let mut mapper = OfflineMapper::new(options.mapper);
    let mut odometry = SimulatedOdometry {
        last_truth: None,
        pose: Pose2::IDENTITY,
        scale_error: options.odometry_scale_error,
        heading_drift: options.odometry_heading_drift,
        rng: Rng::new(options.seed ^ 0x0D0),
    };
    let end = shifted_tour.duration() + 0.3;
    let mut truth_origin: Option<(Pose2, Pose2)> = None;
    let mut errors = Vec::new();
    let mut heading_errors = Vec::new();
    let mut last_odometry_error = 0.0;
    let mut connected_baud = None;
    let mut link_errors = Vec::new();
    driver.run(
        || t0.elapsed().as_secs_f64() > end + 30.0,
        |event| {
            match event {
                Event::Connected { baud, .. } => connected_baud = Some(baud.bits_per_second()),
                Event::Error(e) => link_errors.push(e.to_string()),
                Event::Scan(timed) => {
                    let t = timed.timestamp.saturating_duration_since(t0).as_secs_f64();
                    if t < delay {
                        // Still parked while the link came up: nothing to map yet.
                        return ControlFlow::Continue(());
                    }
                    let Some(scan) = range_scan(&timed.scan, t, mode) else {
                        return ControlFlow::Continue(());
                    };
                    let truth = shifted_tour.pose_at(t);
                    let odo = odometry.step(truth);
                    mapper.process(&ScanRecord {
                        scan,
                        odometry: Some(odo),
                    });
                    let (truth0, odo0) = *truth_origin.get_or_insert((truth, odo));
                    let truth_map = truth0.between(&truth);
                    let odo_map = odo0.between(&odo);
                    if let Some((_, est)) = mapper.trajectory().last() {
                        let e = (est.x - truth_map.x).hypot(est.y - truth_map.y);
                        errors.push(e);
                        heading_errors.push(wrap_angle(est.theta - truth_map.theta).abs());
                        last_odometry_error =
                            (odo_map.x - truth_map.x).hypot(odo_map.y - truth_map.y);
                        on_progress(&DemoProgress {
                            t: t - delay,
                            tour_duration: scenario.tour.duration(),
                            scans: mapper.trajectory().len(),
                            segments: mapper.map().len(),
                            error: e,
                            odometry_error: last_odometry_error,
                        });
                    }
                    if t > end {
                        return ControlFlow::Break(());
                    }
                }
                _ => {}
            }
            ControlFlow::Continue(())
        },
    )?;
    let stats: LinkStats = driver.stats();
    drop(driver);
    drop(pty);
    if errors.is_empty() {
        return Err(DemoError::NoScans(
            link_errors
                .last()
                .cloned()
                .unwrap_or_else(|| "no error reported".into()),
        ));
    }
    write_outputs(&options.out_dir, &mapper)?;
    let summary = DemoSummary {
        scenario: scenario.name.clone(),
        scans: mapper.trajectory().len(),
        segments: mapper.map().len(),
        cls_actual: mapper.cls_map().actual_segments().count(),
        cls_virtual: mapper.cls_map().virtual_segments().count(),
        cls_loops: mapper.cls_map().loops().count(),
        connected_baud,
        dropped_frames: stats.dropped_frames,
        mean_error_m: errors.iter().sum::<f64>() / errors.len() as f64,
        max_error_m: errors.iter().copied().fold(0.0, f64::max),
        max_heading_error_deg: heading_errors
            .iter()
            .copied()
            .fold(0.0, f64::max)
            .to_degrees(),
        odometry_final_error_m: last_odometry_error,
        final_error_m: errors.last().copied().unwrap_or(0.0),
        out_dir: options.out_dir.clone(),
    };
    let path = options.out_dir.join("demo.json");
    let text = serde_json::to_string_pretty(&summary).map_err(io::Error::from);
    text.and_then(|t| crate::durable::write_atomically(&path, (t + "\n").as_bytes()))
        .map_err(|source| DemoError::Io { path, source })?;
    Ok(summary)
}
