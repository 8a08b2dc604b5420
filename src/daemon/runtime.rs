//! The real-time loop on tokio: the sensor thread, the base, the mapper,
//! the explorer, checkpoints, status and systemd, wired together.
//!
//! One current-thread runtime runs the loop; the serial driver runs on its
//! own thread (it blocks on the port) and hands over only the newest scan;
//! checkpoints are written on a blocking thread. The loop reacts to: a new
//! scan (localize, maybe grow the map), a base tick (poll odometry,
//! command the base, ping the watchdog), a status tick, a checkpoint tick
//! and its completion, sensor reports, a reload request and the shutdown
//! future. On shutdown it stops the base, stops the sensor, saves the map.

use std::future::Future;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use clsmap_base::{BaseAdapter, LineBase, ReplayBase};
use lms200::link::Event;
use lms200::pty::PtyEmulator;
use serde::Serialize;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;
use tokio::time::MissedTickBehavior;
use tracing::{error, info, info_span, warn};

use super::base_driver::{BaseConnector, BaseDriver};
use super::checkpoint::CheckpointFailed;
use super::config::{BaseKind, DaemonConfig, SensorSource};
use super::latency::StageSummary;
use super::live::{LiveMapper, LiveStatus};
use super::notify::Notifier;
use super::sensor::{ScanSlot, SensorOptions, SensorReport, SensorThread};
use super::simulation::{emulated_sensor, simulated_robot};
use crate::error_chain;
use crate::geometry::Pose2;
use crate::graph::OptimisationResult;
use crate::input::lms200::range_scan;
use crate::sim::SimRobot;

/// Why the daemon could not start or finish.
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    #[error("cannot write to {path}")]
    OutputDir {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot load the simulated world {0:?}")]
    World(String, #[source] crate::sim::world_file::WorldFileError),
    #[error("no built-in world is called {0:?} (built in: {1})")]
    UnknownWorld(String, String),
    #[error("cannot start the emulated LMS200")]
    Emulator(#[from] lms200::pty::PtyError),
    #[error("cannot read the odometry to replay from {path}")]
    Replay {
        path: PathBuf,
        #[source]
        source: crate::input::InputError,
    },
    #[error("the odometry to replay is unusable: {0}")]
    ReplayOdometry(String),
    #[error("cannot start the sensor thread")]
    Thread(#[source] std::io::Error),
    #[error("cannot start the async runtime")]
    Runtime(#[source] std::io::Error),
    #[error("the map could not be saved anywhere; tried {tried}")]
    Save { tried: String },
    #[error("cannot start from the map {path} (on_bad_map = \"refuse\")")]
    Map {
        path: PathBuf,
        #[source]
        source: crate::pipeline::PipelineError,
    },
}

/// Why the loop ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum StopReason {
    /// The shutdown future completed (SIGTERM, SIGINT, a test).
    Shutdown,
    /// Exploration completed and `exit_when_complete` is set.
    ExplorationComplete,
    /// `max_run_time` passed.
    TimeLimit,
    /// The sensor thread ended on its own (a bug): the map was saved and
    /// the daemon exits with an error for systemd to restart it.
    SensorThreadEnded,
}

/// What the loop reports after each scan (for live progress).
#[derive(Debug, Clone, PartialEq)]
pub struct ScanProgress {
    /// Seconds since the daemon started.
    pub t: f64,
    /// The estimate (map frame).
    pub pose: Pose2,
    /// Where the simulated robot truly was (world frame); `None` on a real
    /// robot.
    pub truth: Option<Pose2>,
    pub localized: bool,
    pub status: LiveStatus,
}

/// What a run did.
#[derive(Debug, Clone, Serialize)]
pub struct RunSummary {
    pub reason: StopReason,
    /// Where the map was saved; `None` when nothing was mapped.
    pub out_dir: Option<PathBuf>,
    /// Why the map went to a rescue directory instead of its own, if it did.
    pub rescued_because: Option<String>,
    pub status: LiveStatus,
    /// Scans the loop took up, and scans replaced in the mailbox before it
    /// could (latest scan wins).
    pub scans: u64,
    pub scans_skipped: u64,
    pub odometry_refused: u64,
    pub latencies: Vec<StageSummary>,
    /// Seconds from start to the first scan.
    pub first_scan_after: Option<f64>,
    pub run_time: f64,
}

/// A callback after every scan.
pub type ScanHook<'a> = Box<dyn FnMut(&ScanProgress) + 'a>;

/// How a run is hooked up to the outside.
pub struct Hooks<'a> {
    /// Completes when the daemon should stop (SIGTERM/SIGINT in `main`).
    pub shutdown: std::pin::Pin<Box<dyn Future<Output = ()> + 'a>>,
    /// Each message asks for a reload of the tunables (SIGHUP).
    pub reload: Option<mpsc::UnboundedReceiver<()>>,
    /// Re-read on reload; `None` keeps the configuration.
    pub config_path: Option<PathBuf>,
    /// Write the map here instead of a new run directory in the state dir.
    pub out_dir: Option<PathBuf>,
    /// Called after every scan.
    pub on_scan: Option<ScanHook<'a>>,
}

impl std::fmt::Debug for Hooks<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Hooks")
            .field("config_path", &self.config_path)
            .field("out_dir", &self.out_dir)
            .finish_non_exhaustive()
    }
}

impl<'a> Hooks<'a> {
    /// Runs until `shutdown` completes, with no other hook.
    pub fn until(shutdown: impl Future<Output = ()> + 'a) -> Hooks<'a> {
        Hooks {
            shutdown: Box::pin(shutdown),
            reload: None,
            config_path: None,
            out_dir: None,
            on_scan: None,
        }
    }
}

/// Runs the daemon on a new current-thread tokio runtime.
pub fn run_blocking(config: DaemonConfig, hooks: Hooks<'_>) -> Result<RunSummary, DaemonError> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(DaemonError::Runtime)?;
    runtime.block_on(run(config, hooks))
}

/// A name for a run's directory: `run-YYYYmmddTHHMMSSZ-<pid>` (UTC; the
/// process id keeps names apart on a robot whose clock restarts at the
/// same time after every boot).
fn run_dir_name(prefix: &str) -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let (days, rem) = (secs / 86_400, secs % 86_400);
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{prefix}-{y:04}{m:02}{d:02}T{:02}{:02}{:02}Z-{}",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60,
        std::process::id()
    )
}

/// A new directory below `parent`, never an existing one.
fn new_dir(parent: &Path, prefix: &str) -> std::io::Result<PathBuf> {
    std::fs::create_dir_all(parent)?;
    let base = run_dir_name(prefix);
    for k in 0..10_000 {
        let dir = parent.join(if k == 0 {
            base.clone()
        } else {
            format!("{base}-{k}")
        });
        match std::fs::create_dir(&dir) {
            Ok(()) => return Ok(dir),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
            Err(e) => return Err(e),
        }
    }
    Err(std::io::Error::new(
        std::io::ErrorKind::AlreadyExists,
        "every run directory name is taken",
    ))
}

/// Fails early, before the sensor is touched, when `dir` cannot be
/// written: a map that cannot be saved is worse than no start.
fn check_writable(dir: &Path) -> Result<(), DaemonError> {
    let fail = |source| DaemonError::OutputDir {
        path: dir.to_owned(),
        source,
    };
    std::fs::create_dir_all(dir).map_err(fail)?;
    crate::durable::check_writable(dir).map_err(fail)
}

/// The mapper the run starts with: a new map, or `[map] load` in its mode.
/// A map that cannot be loaded stops the start with the reason, or with
/// `on_bad_map = "new"` is warned about and a new map started.
pub(crate) fn start_map(
    config: &DaemonConfig,
    exploration: Option<(
        crate::explore::ExplorationConfig,
        crate::explore::DriveConfig,
    )>,
) -> Result<LiveMapper, DaemonError> {
    let Some(path) = &config.map.load else {
        return Ok(LiveMapper::new(config.mapper, exploration, 0.0));
    };
    let mode = config
        .map
        .mode()
        .unwrap_or(crate::pipeline::MapMode::Localize);
    // A map that does not grow never closes its frontiers: exploring it
    // would chase them for ever.
    let explore_loaded = match (mode, exploration) {
        (crate::pipeline::MapMode::Localize, Some(_)) => {
            warn!("[map] mode = \"localize\": exploration is off (the map does not grow)");
            None
        }
        (_, exploration) => exploration,
    };
    let loaded = crate::map::file::load(path)
        .map_err(crate::pipeline::PipelineError::from)
        .and_then(|m| LiveMapper::from_map(config.mapper, m.contents, mode, explore_loaded, 0.0));
    match loaded {
        Ok(live) => {
            info!(map = %path.display(), ?mode, "starting from a saved map; finding the robot in it");
            Ok(live)
        }
        Err(e) if config.map.new_on_bad_map() => {
            warn!(
                map = %path.display(),
                "cannot start from the map ({}); starting a new one (on_bad_map = \"new\")",
                error_chain(&e)
            );
            Ok(LiveMapper::new(config.mapper, exploration, 0.0))
        }
        Err(e) => Err(DaemonError::Map {
            path: path.clone(),
            source: e,
        }),
    }
}

/// Everything the loop owns besides the mapper.
struct Rig {
    base: Option<BaseConnector>,
    robot: Option<SimRobot>,
    /// Keeps the emulator's pty open while the daemon runs.
    _pty: Option<PtyEmulator>,
    sensor_port: PathBuf,
}

fn build_rig(config: &DaemonConfig, t0: Instant) -> Result<Rig, DaemonError> {
    let mut robot = None;
    let mut pty = None;
    let mut sensor_port = config.sensor.port.clone();
    let base: Option<BaseConnector> = match config.base.adapter {
        BaseKind::Sim => {
            let (sim, world) = simulated_robot(config)?;
            if config.sensor.source == SensorSource::Emulator {
                let emulator = emulated_sensor(config, &world, &sim, t0);
                let p = PtyEmulator::spawn(emulator, None)?;
                sensor_port = p.tty_path().to_owned();
                pty = Some(p);
            }
            let base = sim.base();
            robot = Some(sim);
            Some(BaseDriver::once(Box::new(base)))
        }
        // Connected by the loop, and again after a failure: a bridge that
        // starts after the daemon is picked up.
        BaseKind::Tcp => {
            let address = config.base.address.clone();
            Some(Box::new(move || {
                LineBase::connect_tcp(&address, Duration::from_millis(300))
                    .map(|b| Box::new(b) as Box<dyn BaseAdapter + Send>)
                    .map_err(|e| e.to_string())
            }))
        }
        BaseKind::Serial => {
            let (port, baud) = (config.base.port.clone(), config.base.baud);
            Some(Box::new(move || {
                LineBase::open_serial(&port, baud)
                    .map(|b| Box::new(b) as Box<dyn BaseAdapter + Send>)
                    .map_err(|e| e.to_string())
            }))
        }
        BaseKind::Replay => {
            let path = config.base.replay.clone().unwrap_or_default();
            let samples = replay_samples(&path).map_err(|source| DaemonError::Replay {
                path: path.clone(),
                source,
            })?;
            let base =
                ReplayBase::new(samples).map_err(|e| DaemonError::ReplayOdometry(e.to_string()))?;
            Some(BaseDriver::once(Box::new(base)))
        }
        BaseKind::None => None,
    };
    Ok(Rig {
        base,
        robot,
        _pty: pty,
        sensor_port,
    })
}

/// The odometry of a recording or CARMEN log, for the replay adapter.
fn replay_samples(
    path: &Path,
) -> Result<Vec<clsmap_base::OdometrySample>, crate::input::InputError> {
    let mut samples = Vec::new();
    for record in crate::input::open_log(path)? {
        let record = record?;
        if let Some(p) = record.odometry {
            samples.push(clsmap_base::OdometrySample {
                t: record.scan.t,
                pose: clsmap_base::BasePose::new(p.x, p.y, p.theta),
            });
        }
    }
    Ok(samples)
}

fn status_line(s: &LiveStatus, rate: f64, sensor: &str) -> String {
    let pose = s.pose.map_or_else(
        || "no pose yet".to_string(),
        |p| {
            format!(
                "pose ({:.2}, {:.2}, {:.0}°)",
                p.x,
                p.y,
                p.theta.to_degrees()
            )
        },
    );
    let pose = match s.map_search {
        Some(crate::pipeline::MapSearch::Finding(n)) => {
            format!("localizing in the loaded map ({n} hypotheses)")
        }
        Some(crate::pipeline::MapSearch::Lost(n)) => {
            format!("LOST in the loaded map ({n} hypotheses), {pose}")
        }
        None => pose,
    };
    let exploring = if s.exploration_complete {
        ", exploration complete"
    } else if s.exploring {
        ", exploring"
    } else {
        ""
    };
    format!(
        "{sensor} {rate:.1} scans/s, {} scans ({} localized), map {} walls {} frontiers {} loops, {} loop closures, {pose}{exploring}",
        s.scans, s.localized, s.walls, s.frontiers, s.loops, s.loops_closed
    )
}

fn tick_every(seconds: f64) -> tokio::time::Interval {
    let period =
        Duration::try_from_secs_f64(seconds.max(1e-3)).unwrap_or(Duration::from_secs(3600));
    let mut i = tokio::time::interval(period);
    i.set_missed_tick_behavior(MissedTickBehavior::Skip);
    i
}

/// The loop's state.
struct Daemon {
    config: DaemonConfig,
    t0: Instant,
    live: LiveMapper,
    base: BaseDriver,
    notifier: Notifier,
    robot: Option<SimRobot>,
    mode: lms200::MeasuringMode,
    /// The run's directory: given, or made at the first checkpoint.
    out_dir: Option<PathBuf>,
    state_dir: PathBuf,
    last_seq: u64,
    skipped: u64,
    last_scan_at: Option<f64>,
    first_scan_after: Option<f64>,
    silence_logged: bool,
    /// The sensor thread's last failure, for the status line.
    sensor_trouble: Option<String>,
    scans_at_last_status: u64,
    last_status_t: f64,
}

impl Daemon {
    fn clock(&self) -> f64 {
        self.t0.elapsed().as_secs_f64()
    }

    fn sensor_ok(&self, now: f64) -> bool {
        self.last_scan_at
            .is_some_and(|t| now - t <= self.config.sensor.silence_stop)
    }

    fn on_scan(&mut self, slot: &ScanSlot, hook: &mut Option<ScanHook<'_>>) {
        self.skipped += slot.seq.saturating_sub(self.last_seq + 1);
        self.last_seq = slot.seq;
        let now = self.clock();
        self.base.poll(now, &mut self.live);
        let t = slot
            .scan
            .timestamp
            .saturating_duration_since(self.t0)
            .as_secs_f64();
        let Some(scan) = range_scan(&slot.scan.scan, t, self.mode) else {
            return;
        };
        let queued = slot.scan.received_at.elapsed();
        let outcome = self.live.on_scan(scan, Some(queued));
        if self.first_scan_after.is_none() {
            self.first_scan_after = Some(now);
            info!(after_s = now, "first scan mapped; ready");
            let _ = self.notifier.ready();
        }
        if self.silence_logged {
            info!("scans are back");
            self.silence_logged = false;
        }
        self.sensor_trouble = None;
        self.last_scan_at = Some(now);
        if let Some(hook) = hook.as_mut() {
            hook(&ScanProgress {
                t: now,
                pose: outcome.pose,
                truth: self.robot.as_ref().map(|r| r.true_pose_at(t)),
                localized: outcome.localized,
                status: self.live.status(),
            });
        }
    }

    /// Polls and commands the base; returns why to stop, if it is time.
    fn on_base_tick(&mut self) -> Option<StopReason> {
        let _span = info_span!("control").entered();
        let now = self.clock();
        self.notifier.loop_alive(Instant::now());
        if self.first_scan_after.is_none()
            && now >= self.config.daemon.ready_after
            && self.notifier.ready()
        {
            warn!(
                after_s = now,
                "no scan yet: ready anyway, still waiting for the sensor"
            );
        }
        self.base.poll(now, &mut self.live);
        let sensor_ok = self.sensor_ok(now);
        if !sensor_ok && self.last_scan_at.is_some() && !self.silence_logged {
            warn!(
                silent_s = self.config.sensor.silence_stop,
                "no scan: the base stops until scans return"
            );
            self.silence_logged = true;
        }
        // A robot not (or no longer) found in a loaded map does not drive.
        let placed = self.live.mapper().map_search().is_none();
        self.base
            .control(&mut self.live, sensor_ok && placed, now, None);
        if self.config.exploration.exit_when_complete && self.live.exploration_complete() {
            return Some(StopReason::ExplorationComplete);
        }
        let limit = self.config.daemon.max_run_time;
        (limit > 0.0 && now >= limit).then_some(StopReason::TimeLimit)
    }

    fn on_status_tick(&mut self) {
        let now = self.clock();
        let status = self.live.status();
        let rate = (status.scans - self.scans_at_last_status) as f64
            / (now - self.last_status_t).max(1e-3);
        self.scans_at_last_status = status.scans;
        self.last_status_t = now;
        let sensor = match (&self.sensor_trouble, self.sensor_ok(now)) {
            (_, true) => "streaming".to_string(),
            (Some(why), false) => format!("SENSOR FAILING ({why})"),
            (None, false) if self.last_scan_at.is_none() => "waiting for the sensor".to_string(),
            (None, false) => "SENSOR SILENT".to_string(),
        };
        let line = status_line(&status, rate, &sensor);
        info!(skipped = self.skipped, "{line}");
        let latency = self.live.latencies().line();
        if !latency.is_empty() {
            info!("latency µs p50/p99/max: {latency}");
        }
        self.notifier.status(&line);
    }

    /// The run's directory, made on first use (a run that never saw a scan
    /// leaves no empty directory behind).
    fn out_dir(&mut self) -> std::io::Result<PathBuf> {
        if let Some(dir) = &self.out_dir {
            return Ok(dir.clone());
        }
        let dir = new_dir(&self.state_dir, "run")?;
        info!(dir = %dir.display(), "maps of this run are saved here");
        self.out_dir = Some(dir.clone());
        Ok(dir)
    }

    /// Starts writing a checkpoint on a blocking thread.
    fn start_checkpoint(&mut self) -> Option<JoinHandle<Result<(), CheckpointFailed>>> {
        if self.live.scans() == 0 {
            return None;
        }
        let dir = match self.out_dir() {
            Ok(dir) => dir,
            Err(e) => {
                error!("cannot make the run directory, the map stays in memory: {e}");
                return None;
            }
        };
        let checkpoint = self.live.begin_checkpoint(&dir);
        Some(tokio::task::spawn_blocking(move || checkpoint.write()))
    }

    fn checkpoint_done(
        &mut self,
        result: Result<Result<(), CheckpointFailed>, tokio::task::JoinError>,
    ) {
        match result {
            Ok(Ok(())) => {}
            Ok(Err(failed)) => {
                let e = self.live.checkpoint_failed(failed);
                error!(
                    "checkpoint failed, the map stays in memory: {}",
                    error_chain(&e)
                );
            }
            Err(e) => error!("the checkpoint writer failed: {e}"),
        }
    }

    /// Takes in a background optimisation's result; a job whose thread
    /// failed is abandoned, so the next one takes its loops in.
    fn optimisation_done(&mut self, result: Result<OptimisationResult, tokio::task::JoinError>) {
        match result {
            Ok(result) => self.live.apply_optimisation(result),
            Err(e) => {
                error!("the loop-closure optimiser failed: {e}");
                self.live.abandon_optimisation();
            }
        }
    }

    fn reload(&mut self, path: &Option<PathBuf>) {
        let Some(path) = path else {
            info!("reload asked for, but no configuration file to re-read");
            return;
        };
        let new = match DaemonConfig::load(path) {
            Ok(new) => new,
            Err(e) => {
                error!(
                    path = %path.display(),
                    "reload refused, the running configuration stays: {}",
                    error_chain(&e)
                );
                return;
            }
        };
        let old = &self.config;
        let mut restart: Vec<String> = self
            .live
            .retune(new.mapper)
            .iter()
            .map(|k| format!("mapper.{k}"))
            .collect();
        let mut base_fixed = new.base.clone();
        base_fixed.max_speed = old.base.max_speed;
        base_fixed.max_turn_rate = old.base.max_turn_rate;
        base_fixed.max_acceleration = old.base.max_acceleration;
        base_fixed.max_angular_acceleration = old.base.max_angular_acceleration;
        base_fixed.stale_odometry = old.base.stale_odometry;
        for (name, changed) in [
            ("sensor", new.sensor != old.sensor),
            ("base", base_fixed != old.base),
            ("sim", new.sim != old.sim),
            ("daemon", new.daemon != old.daemon),
        ] {
            if changed {
                restart.push(name.to_string());
            }
        }
        self.base.retune(new.base.limits(), new.base.stale_odometry);
        let exploration = new
            .exploration
            .enabled
            .then_some((new.exploration.planner, new.exploration.drive));
        let now = self.clock();
        self.live.set_exploration(exploration, now);
        if !new.exploration.enabled {
            self.base.halt(now);
        }
        let config = &mut self.config;
        config.mapper = new.mapper;
        config.base.stale_odometry = new.base.stale_odometry;
        config.base.max_speed = new.base.max_speed;
        config.base.max_turn_rate = new.base.max_turn_rate;
        config.base.max_acceleration = new.base.max_acceleration;
        config.base.max_angular_acceleration = new.base.max_angular_acceleration;
        config.exploration = new.exploration;
        if restart.is_empty() {
            info!(path = %path.display(), "configuration reloaded");
        } else {
            warn!(
                path = %path.display(),
                "configuration reloaded; these changes need a restart and are not applied: {}",
                restart.join(", ")
            );
        }
    }

    fn on_report(&mut self, report: &SensorReport) {
        if let SensorReport::Failed { error, .. } = report {
            self.sensor_trouble = Some(error.clone());
        }
        log_report(report);
    }

    /// Saves the map into the run's directory; if that fails, into a
    /// rescue directory beside it, then under the system's temporary
    /// directory. Returns where it went and, if rescued, why.
    fn save(&mut self) -> Result<(Option<PathBuf>, Option<String>), DaemonError> {
        if self.live.scans() == 0 {
            info!("no scan was mapped: nothing to save");
            return Ok((None, None));
        }
        let first = match self.out_dir() {
            Ok(dir) => match self.live.checkpoint(&dir) {
                Ok(()) => return Ok((Some(dir), None)),
                Err(e) => format!("{}: {}", dir.display(), error_chain(&e)),
            },
            Err(e) => format!("{}: {e}", self.state_dir.display()),
        };
        error!("cannot save the map in {first}");
        let mut tried = vec![first.clone()];
        // Beside the run's directory, then beside the state directory: not
        // under $TMPDIR, which the unit's PrivateTmp= empties at stop.
        let mut parents = vec![self.state_dir.clone()];
        if let Some(up) = self
            .state_dir
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
        {
            parents.push(up.to_path_buf());
        }
        let earlier = self
            .out_dir
            .as_ref()
            .map(|d| d.join(crate::pipeline::TRAJECTORY_FILE));
        for parent in parents {
            let rescue = match new_dir(&parent, "rescue") {
                Ok(dir) => dir,
                Err(e) => {
                    tried.push(format!("{}: {e}", parent.display()));
                    continue;
                }
            };
            // The rescue is whole: the poses the run's directory holds
            // already come first, then the ones not written yet.
            let copied = match &earlier {
                Some(path) if path.is_file() => {
                    std::fs::copy(path, rescue.join(crate::pipeline::TRAJECTORY_FILE)).map(|_| ())
                }
                _ => Ok(()),
            };
            match copied
                .map_err(|e| e.to_string())
                .and_then(|()| self.live.checkpoint(&rescue).map_err(|e| error_chain(&e)))
            {
                Ok(()) => {
                    error!(dir = %rescue.display(), "map saved to a rescue directory instead");
                    return Ok((Some(rescue), Some(first)));
                }
                Err(e) => {
                    tried.push(format!("{}: {e}", rescue.display()));
                    // Nothing half-written is left behind.
                    let _ = std::fs::remove_dir_all(&rescue);
                }
            }
        }
        Err(DaemonError::Save {
            tried: tried.join("; "),
        })
    }
}

/// Runs the daemon until the shutdown future completes, exploration ends
/// (with `exit_when_complete`) or the time limit passes; then stops the
/// base and the sensor and saves the map.
pub async fn run(config: DaemonConfig, hooks: Hooks<'_>) -> Result<RunSummary, DaemonError> {
    let t0 = Instant::now();
    let state_dir = config.state_dir();
    let out_dir = match &hooks.out_dir {
        Some(dir) => {
            check_writable(dir)?;
            Some(dir.clone())
        }
        None => {
            check_writable(&state_dir)?;
            None
        }
    };
    // The map first: a saved map that cannot be used stops the start
    // before the sensor and the base are touched.
    let exploration = config
        .exploration
        .enabled
        .then_some((config.exploration.planner, config.exploration.drive));
    // Loop-closure optimisations and rebuilds run on a blocking thread; the
    // loop goes on localizing against the old map meanwhile.
    let mut live = start_map(&config, exploration)?;
    live.set_background_optimisation(true);
    let rig = build_rig(&config, t0)?;
    let link = config.link();
    let (scan_tx, mut scan_rx) = watch::channel::<Option<ScanSlot>>(None);
    let (report_tx, mut report_rx) = mpsc::unbounded_channel();
    let sensor = SensorThread::spawn(
        SensorOptions {
            port: rig.sensor_port.clone(),
            link: link.clone(),
            retry_initial: Duration::from_secs_f64(config.sensor.retry_initial),
            retry_max: Duration::from_secs_f64(config.sensor.retry_max),
            record: config.sensor.record.clone(),
        },
        scan_tx,
        report_tx,
    )
    .map_err(DaemonError::Thread)?;
    info!(port = %rig.sensor_port.display(), "sensor thread started");
    let notifier = Notifier::from_env();
    if let Some(w) = notifier.watchdog() {
        info!(interval_s = w.as_secs_f64(), "systemd watchdog enabled");
    }
    let mut d = Daemon {
        live,
        base: BaseDriver::new(
            rig.base,
            config.base.limits(),
            config.base.stale_odometry,
            config.sensor.retry_initial,
            config.sensor.retry_max,
        ),
        notifier,
        robot: rig.robot.clone(),
        mode: link.measuring_mode,
        out_dir,
        state_dir,
        t0,
        last_seq: 0,
        skipped: 0,
        last_scan_at: None,
        first_scan_after: None,
        silence_logged: false,
        sensor_trouble: None,
        scans_at_last_status: 0,
        last_status_t: 0.0,
        config,
    };
    let mut base_tick = tick_every(1.0 / d.config.base.rate);
    let mut status_tick = tick_every(d.config.daemon.status_interval);
    let checkpoints = d.config.daemon.checkpoint_interval > 0.0;
    let mut checkpoint_tick = tick_every(d.config.daemon.checkpoint_interval.max(1.0));
    checkpoint_tick.reset();
    let mut writing: Option<JoinHandle<Result<(), CheckpointFailed>>> = None;
    let mut optimising: Option<JoinHandle<OptimisationResult>> = None;
    let Hooks {
        shutdown: mut shutdown_signal,
        mut reload,
        config_path,
        mut on_scan,
        ..
    } = hooks;
    let reason = loop {
        tokio::select! {
            () = &mut shutdown_signal => break StopReason::Shutdown,
            Some(()) = async {
                match reload.as_mut() {
                    Some(r) => r.recv().await,
                    None => std::future::pending().await,
                }
            } => d.reload(&config_path),
            changed = scan_rx.changed() => {
                if changed.is_err() {
                    error!("the sensor thread ended; saving the map and stopping");
                    break StopReason::SensorThreadEnded;
                }
                let slot = scan_rx.borrow_and_update().clone();
                if let Some(slot) = slot {
                    d.on_scan(&slot, &mut on_scan);
                }
                if optimising.is_none() {
                    optimising = d
                        .live
                        .take_optimisation()
                        .map(|job| tokio::task::spawn_blocking(move || job.run()));
                }
            }
            result = async {
                match optimising.as_mut() {
                    Some(task) => task.await,
                    None => std::future::pending().await,
                }
            } => {
                optimising = None;
                d.optimisation_done(result);
            }
            Some(report) = report_rx.recv() => d.on_report(&report),
            _ = base_tick.tick() => {
                if let Some(reason) = d.on_base_tick() {
                    break reason;
                }
            }
            _ = status_tick.tick() => d.on_status_tick(),
            _ = checkpoint_tick.tick(), if checkpoints && writing.is_none() => {
                writing = d.start_checkpoint();
            }
            result = async {
                match writing.as_mut() {
                    Some(task) => task.await,
                    None => std::future::pending().await,
                }
            } => {
                writing = None;
                d.checkpoint_done(result);
            }
        }
    };
    info!(?reason, "stopping");
    d.notifier.stopping();
    let now = d.clock();
    d.base.stop(now);
    // Stop streaming while the map is saved; closing the link (stop the
    // output, back to 9600 Bd) takes a moment and the save does not wait.
    sensor.request_stop();
    if let Some(task) = writing.take() {
        let result = task.await;
        d.checkpoint_done(result);
    }
    if let Some(task) = optimising.take() {
        let result = task.await;
        d.optimisation_done(result);
    }
    // Loops that agreed with the graph but were not optimised yet are
    // taken in before the last save.
    d.live.finish();
    let saved = d.save();
    let joined = tokio::task::spawn_blocking(move || sensor.stop()).await;
    if joined.is_err() {
        warn!("the sensor thread did not stop cleanly");
    }
    while let Ok(report) = report_rx.try_recv() {
        d.on_report(&report);
    }
    let (out_dir, rescued_because) = saved?;
    let status = d.live.status();
    info!("{}", status_line(&status, 0.0, "stopped:"));
    Ok(RunSummary {
        reason,
        out_dir,
        rescued_because,
        scans: status.scans,
        status,
        scans_skipped: d.skipped,
        odometry_refused: d.base.odometry_refused(),
        latencies: d.live.latencies().summaries(),
        first_scan_after: d.first_scan_after,
        run_time: d.clock(),
    })
}

fn log_report(report: &SensorReport) {
    match report {
        SensorReport::Failed { error, retry_in } => error!(
            retry_in_s = retry_in.as_secs_f64(),
            "sensor: {error}; the map is kept, trying again"
        ),
        SensorReport::Link(event) => match event {
            Event::Connected {
                baud,
                variant,
                units,
                device_type,
                firmware,
            } => info!(
                baud = baud.bits_per_second(),
                ?variant,
                ?units,
                device_type,
                firmware,
                "sensor streaming"
            ),
            Event::SensorRestarted => warn!("sensor restarted (power-up telegram)"),
            Event::SensorSilent => warn!("sensor silent: no scan within the watchdog time"),
            Event::Reinitializing {
                reason: lms200::link::ReinitReason::Start,
            } => info!("sensor link starting: finding the line speed"),
            Event::Reinitializing { reason } => warn!(?reason, "sensor link starting over"),
            Event::CommandRejected { command } => warn!(?command, "sensor rejected a command"),
            Event::Error(e) => warn!("sensor link: {e}"),
            Event::Closed => info!("sensor link closed"),
            Event::Scan(_) => {}
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::MapSearch;

    #[test]
    fn the_status_line_says_where_the_robot_stands_in_a_loaded_map() {
        let mut s = LiveStatus {
            pose: Some(Pose2::new(1.0, 2.0, 0.0)),
            ..LiveStatus::default()
        };
        assert!(status_line(&s, 37.5, "streaming").contains("pose (1.00, 2.00, 0°)"));
        s.map_search = Some(MapSearch::Finding(3));
        let line = status_line(&s, 37.5, "streaming");
        assert!(
            line.contains("localizing in the loaded map (3 hypotheses)"),
            "{line}"
        );
        s.map_search = Some(MapSearch::Lost(0));
        let line = status_line(&s, 37.5, "streaming");
        assert!(
            line.contains("LOST in the loaded map (0 hypotheses), pose"),
            "{line}"
        );
    }
}
