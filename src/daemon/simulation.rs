//! The simulated robot of `[sim]`, and [`VirtualRobot`]: the daemon's loop
//! on a virtual clock.
//!
//! The live daemon (`clsmap run`, `clsmap demo`) puts the emulated LMS200
//! on a pseudo-terminal and runs at the sensor's real pace. `VirtualRobot`
//! wires the same pieces — emulator, serial link state machine, simulated
//! base, [`LiveMapper`], [`BaseDriver`] — through
//! [`VirtualLine`] instead, so the
//! telegrams, the link's timing, the odometry and the exploration all run
//! as they would, only as fast as the CPU allows: an hour of robot time in
//! a minute or two, for tests and soak runs.

use std::path::Path;
use std::time::{Duration, Instant};

use clsmap_base::{BaseAdapter, SimBase, Twist};
use lms200::Units;
use lms200::emulator::{Emulator, EmulatorConfig};
use lms200::link::Event;
use lms200::virtual_line::VirtualLine;

use super::base_driver::BaseDriver;
use super::config::{DaemonConfig, SensorSource};
use super::core::Core;
use super::live::LiveMapper;
use super::runtime::DaemonError;
use crate::geometry::Pose2;
use crate::sim::world_file::WorldFile;
use crate::sim::{LMS200_MAX_RANGE_CM_MODE, LMS200_MAX_RANGE_MM_MODE, SimRobot, WorldRangeSource};

/// The world of `[sim] world`: a built-in name or a world file.
pub fn load_world(name: &str) -> Result<WorldFile, DaemonError> {
    if let Some(w) = WorldFile::builtin(name) {
        return Ok(w);
    }
    let path = Path::new(name);
    if path.exists() || name.contains('/') || name.contains('.') {
        return WorldFile::load(path).map_err(|e| DaemonError::World(name.into(), e));
    }
    Err(DaemonError::UnknownWorld(
        name.into(),
        WorldFile::BUILTIN_NAMES.join(", "),
    ))
}

/// The robot of `[sim]` and `[base]`, standing at its start in its world.
pub fn simulated_robot(config: &DaemonConfig) -> Result<(SimRobot, WorldFile), DaemonError> {
    let world = load_world(&config.sim.world)?;
    let start = config.sim.start.unwrap_or(world.start);
    let base = SimBase::new(config.base.limits()).with_odometry_error(
        config.sim.odometry_scale_error,
        config.sim.odometry_heading_drift,
    );
    Ok((SimRobot::new(base, start), world))
}

/// An emulated LMS200 on `robot` measuring `world`; its clock starts at
/// `t0`, which must be the daemon's, so scan times and robot poses agree.
pub fn emulated_sensor(
    config: &DaemonConfig,
    world: &WorldFile,
    robot: &SimRobot,
    t0: Instant,
) -> Emulator {
    let max_range = match config.units() {
        Some(Units::Cm) => LMS200_MAX_RANGE_CM_MODE,
        _ => LMS200_MAX_RANGE_MM_MODE,
    };
    let source = WorldRangeSource::new(
        world.world.clone(),
        robot.clone(),
        config.mapper.laser_mount,
        max_range,
        config.sim.range_sigma,
        config.sim.seed,
    );
    let sensor = EmulatorConfig {
        // Powered and ready, as a sensor switched on before the daemon.
        power_on_delay: None,
        // Nothing compares the sent scans: keep no log of them.
        scan_log_capacity: 0,
        ..EmulatorConfig::default()
    };
    Emulator::with_range_source(sensor, Box::new(source), t0)
}

/// What a virtual run measured.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize)]
pub struct VirtualStats {
    /// Virtual seconds run.
    pub t: f64,
    pub scans: u64,
    /// Position error (m) of the estimate against the truth, both in the
    /// map frame (the robot's pose at the first scan).
    pub mean_error: f64,
    pub max_error: f64,
    /// Largest heading error (rad).
    pub max_heading_error: f64,
    /// Metres the robot drove (truth).
    pub driven: f64,
    /// Link events other than scans (connects, silences, errors).
    pub link_events: Vec<String>,
    /// Checkpoints due that could not be written.
    pub checkpoint_errors: Vec<String>,
}

/// The daemon's loop on a virtual clock; see the module doc.
pub struct VirtualRobot {
    t0: Instant,
    /// Virtual seconds since `t0`.
    now: f64,
    line: VirtualLine,
    robot: SimRobot,
    world: WorldFile,
    core: Core,
    tick: f64,
    /// World pose at the first scan: the map frame.
    origin: Option<Pose2>,
    last_truth: Option<Pose2>,
    error_sum: f64,
    stats: VirtualStats,
    /// Where checkpoints are written when due, if anywhere.
    checkpoint_dir: Option<std::path::PathBuf>,
}

impl std::fmt::Debug for VirtualRobot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VirtualRobot")
            .field("now", &self.now)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl VirtualRobot {
    /// The robot of `config` (`[sim]`, `[base]`, `[mapper]`,
    /// `[exploration]`); `[sensor]` is the emulated LMS200 whatever it says.
    pub fn new(config: &DaemonConfig) -> Result<VirtualRobot, DaemonError> {
        let t0 = Instant::now();
        let mut config = config.clone();
        config.sensor.source = SensorSource::Emulator;
        // No one to show a live view to.
        config.web.enabled = false;
        let (robot, world) = simulated_robot(&config)?;
        let emulator = emulated_sensor(&config, &world, &robot, t0);
        let link = config.link();
        let exploration = config
            .exploration
            .enabled
            .then_some((config.exploration.planner, config.exploration.drive));
        let mut live = super::runtime::start_map(&config, exploration)?;
        live.set_background_loop_closure(true);
        let base = BaseDriver::new(
            Some(BaseDriver::once(Box::new(robot.base()))),
            config.base.limits(),
            config.base.stale_odometry,
            config.sensor.retry_initial,
            config.sensor.retry_max,
        );
        Ok(VirtualRobot {
            t0,
            now: 0.0,
            line: VirtualLine::new(link, emulator, t0),
            tick: 1.0 / config.base.rate,
            core: Core::new(config, live, base),
            robot,
            world,
            origin: None,
            last_truth: None,
            error_sum: 0.0,
            stats: VirtualStats::default(),
            checkpoint_dir: None,
        })
    }

    /// Virtual seconds since the start.
    pub fn now(&self) -> f64 {
        self.now
    }

    pub fn live(&self) -> &LiveMapper {
        self.core.live()
    }

    /// The loop's core, as the tokio daemon runs it.
    pub fn core(&self) -> &Core {
        &self.core
    }

    pub fn robot(&self) -> &SimRobot {
        &self.robot
    }

    pub fn world(&self) -> &WorldFile {
        &self.world
    }

    pub fn line_mut(&mut self) -> &mut VirtualLine {
        &mut self.line
    }

    pub fn stats(&self) -> &VirtualStats {
        &self.stats
    }

    /// The world pose of the map frame's origin (the robot at the first
    /// scan), once there was a scan.
    pub fn map_origin(&self) -> Option<Pose2> {
        self.origin
    }

    /// The instant `t` virtual seconds after the start.
    pub fn instant(&self, t: f64) -> Instant {
        self.t0 + Duration::from_secs_f64(t.max(0.0))
    }

    /// One control period: the line runs to the end of it, scans are
    /// mapped, then the core's timers run (the base is polled and
    /// commanded), as the daemon's loop does.
    pub fn tick(&mut self) {
        self.tick_with(|_, _| None);
    }

    /// [`tick`](Self::tick) with another controller: `drive(live, now)`
    /// returning a velocity replaces the explorer's for this period (the
    /// safety stops still apply).
    pub fn tick_with(&mut self, drive: impl FnOnce(&LiveMapper, f64) -> Option<Twist>) {
        let next = self.now + self.tick;
        let until = self.instant(next);
        let mut scans = Vec::new();
        let mut events = Vec::new();
        self.line.advance_to(until, |_, event| match event {
            Event::Scan(s) => scans.push(s),
            other => events.push(format!("{other:?}")),
        });
        self.stats.link_events.extend(events);
        self.now = next;
        for timed in scans {
            let t = timed
                .timestamp
                .saturating_duration_since(self.t0)
                .as_secs_f64();
            let Some(outcome) = self.core.handle_scan(self.now, t, &timed.scan, None) else {
                continue;
            };
            // Before the robot is found in a loaded map it has no pose.
            if outcome.rejection != Some(crate::pipeline::RejectionKind::NotFoundInTheMapYet) {
                self.score(t, outcome.pose);
            }
            // The daemon runs the loop search and the optimisation on
            // blocking threads and takes the results in when they are done;
            // here they are done at once, so runs stay deterministic on the
            // virtual clock.
            if let Some(job) = self.core.poll_loop_search() {
                let result = job.run();
                self.core.handle_loop_search_done(Some(result));
            }
            if let Some(job) = self.core.poll_optimisation() {
                let result = job.run();
                self.core.handle_optimisation_done(Some(result));
            }
        }
        let manual = drive(self.core.live(), self.now);
        self.core.handle_tick(self.now, manual);
        // Nothing here to tell (systemd); checkpoints are written when due
        // if a directory was given, on this thread (the daemon writes them
        // on a blocking one while the loop goes on).
        self.core.poll_ready();
        self.core.poll_status();
        if self.core.poll_checkpoint()
            && let Some(dir) = &self.checkpoint_dir
        {
            let written = self.core.begin_checkpoint(dir).write();
            if let Err(e) = self.core.handle_checkpoint_done(written) {
                self.stats.checkpoint_errors.push(e.to_string());
            }
        }
    }

    /// The end of a run, as the daemon's stop does it: the last
    /// optimisation and rebuild, then the last save into `dir`.
    pub fn save(&mut self, dir: &Path) -> Result<(), crate::pipeline::PipelineError> {
        self.core.finish();
        self.core.checkpoint(dir)
    }

    /// Writes a checkpoint into `dir` whenever one is due
    /// (`checkpoint_interval`), as the daemon does.
    pub fn checkpoint_into(&mut self, dir: &Path) {
        self.checkpoint_dir = Some(dir.to_owned());
    }

    fn score(&mut self, t: f64, estimate: Pose2) {
        let truth = self.robot.true_pose_at(t);
        let origin = *self.origin.get_or_insert(truth);
        if let Some(last) = self.last_truth {
            self.stats.driven += (truth.x - last.x).hypot(truth.y - last.y);
        }
        self.last_truth = Some(truth);
        let truth_map = origin.between(&truth);
        let e = (estimate.x - truth_map.x).hypot(estimate.y - truth_map.y);
        self.error_sum += e;
        self.stats.scans += 1;
        self.stats.mean_error = self.error_sum / self.stats.scans as f64;
        self.stats.max_error = self.stats.max_error.max(e);
        self.stats.max_heading_error = self
            .stats
            .max_heading_error
            .max(crate::geometry::wrap_angle(estimate.theta - truth_map.theta).abs());
        self.stats.t = self.now;
    }

    /// The map frame is the world pose `origin` (a loaded map's, made by
    /// a run that started there), not this run's first pose.
    pub fn set_map_origin(&mut self, origin: Pose2) {
        self.origin = Some(origin);
    }

    /// Ticks until `done` holds or `limit` virtual seconds have passed;
    /// returns whether `done` held.
    pub fn run_until(&mut self, limit: f64, mut done: impl FnMut(&VirtualRobot) -> bool) -> bool {
        while self.now < limit {
            if done(self) {
                return true;
            }
            self.tick();
        }
        done(self)
    }

    /// Writes a checkpoint of the map and trajectory into `dir`, as the
    /// daemon does every `checkpoint_interval`.
    pub fn checkpoint(&mut self, dir: &Path) -> Result<(), crate::pipeline::PipelineError> {
        self.core.checkpoint(dir)
    }

    /// A pose hint (map frame) now, as the base link or the live view
    /// passes one on.
    pub fn hint_pose(&mut self, pose: Pose2) {
        self.core.handle_pose_hint(self.now, pose, "the test");
    }

    /// Carries the robot to `pose` (world frame) now, its odometry unaware.
    pub fn kidnap(&mut self, pose: Pose2) {
        self.robot.kidnap(pose);
        self.last_truth = None;
    }

    /// Stops the base (the robot coasts to a halt within its limits).
    pub fn stop_base(&mut self) {
        self.core.stop_base(self.now);
        let _ = self.robot.base().stop(self.now);
    }
}
