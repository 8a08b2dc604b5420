//! The real-time loop on tokio: the sensor thread, the base, the mapper,
//! the explorer, checkpoints, status and systemd, wired together.
//!
//! One current-thread runtime runs the loop; the serial driver runs on its
//! own thread (it blocks on the port) and hands over only the newest scan.
//! The loop reacts to: a new scan (localize, maybe grow the map), a base
//! tick (poll odometry, command the base), a status tick, a checkpoint
//! tick, sensor reports, a reload request and the shutdown future. On
//! shutdown it stops the base, closes the sensor link and saves the map.

use std::future::Future;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use clsmap_base::{BaseAdapter, LineBase, ReplayBase, Twist};
use lms200::link::{Event, LinkStats};
use lms200::pty::PtyEmulator;
use serde::Serialize;
use tokio::sync::{mpsc, watch};
use tokio::time::MissedTickBehavior;
use tracing::{error, info, info_span, warn};

use super::base_driver::BaseDriver;
use super::config::{BaseKind, DaemonConfig, SensorSource};
use super::latency::StageSummary;
use super::live::{LiveMapper, LiveStatus};
use super::notify::Notifier;
use super::sensor::{ScanSlot, SensorOptions, SensorReport, SensorThread, error_chain};
use super::simulation::{emulated_sensor, simulated_robot};
use crate::geometry::Pose2;
use crate::input::lms200::range_scan;
use crate::sim::SimRobot;

/// Why the daemon could not start or finish.
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    #[error("cannot create the output directory {path}")]
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
    #[error("cannot start the base adapter: {0}")]
    Base(String),
    #[error("cannot read the odometry to replay from {path}")]
    Replay {
        path: PathBuf,
        #[source]
        source: crate::input::InputError,
    },
    #[error("cannot start the sensor thread")]
    Thread(#[source] std::io::Error),
    #[error("cannot start the async runtime")]
    Runtime(#[source] std::io::Error),
    #[error("the map could not be saved in {tried}: {error}")]
    Save { tried: String, error: String },
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
    pub out_dir: PathBuf,
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

/// A name for this run's directory: `run-YYYYmmddTHHMMSSZ` (UTC).
fn run_dir_name() -> String {
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
        "run-{y:04}{m:02}{d:02}T{:02}{:02}{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

/// A new directory for this run below `state`: never an existing one.
fn new_run_dir(state: &Path) -> Result<PathBuf, DaemonError> {
    let base = run_dir_name();
    let mut last_error = None;
    for k in 0..100 {
        let name = if k == 0 {
            base.clone()
        } else {
            format!("{base}-{k}")
        };
        let dir = state.join(name);
        if let Err(source) = std::fs::create_dir_all(state) {
            return Err(DaemonError::OutputDir {
                path: state.to_owned(),
                source,
            });
        }
        match std::fs::create_dir(&dir) {
            Ok(()) => return Ok(dir),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
            Err(e) => last_error = Some((dir, e)),
        }
    }
    let (path, source) = last_error.unwrap_or_else(|| {
        (
            state.join(base),
            std::io::Error::new(std::io::ErrorKind::AlreadyExists, "every name is taken"),
        )
    });
    Err(DaemonError::OutputDir { path, source })
}

/// Everything the loop owns besides the mapper.
struct Rig {
    base: Option<Box<dyn BaseAdapter + Send>>,
    robot: Option<SimRobot>,
    /// Keeps the emulator's pty open while the daemon runs.
    _pty: Option<PtyEmulator>,
    sensor_port: PathBuf,
}

fn build_rig(config: &DaemonConfig, t0: Instant) -> Result<Rig, DaemonError> {
    let mut robot = None;
    let mut pty = None;
    let mut sensor_port = config.sensor.port.clone();
    let base: Option<Box<dyn BaseAdapter + Send>> = match config.base.adapter {
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
            Some(Box::new(base))
        }
        BaseKind::Tcp => Some(Box::new(
            LineBase::connect_tcp(&config.base.address, Duration::from_secs(5))
                .map_err(|e| DaemonError::Base(e.to_string()))?,
        )),
        BaseKind::Serial => Some(Box::new(
            LineBase::open_serial(&config.base.port, config.base.baud)
                .map_err(|e| DaemonError::Base(e.to_string()))?,
        )),
        BaseKind::Replay => {
            let path = config.base.replay.clone().unwrap_or_default();
            let samples = replay_samples(&path).map_err(|source| DaemonError::Replay {
                path: path.clone(),
                source,
            })?;
            Some(Box::new(
                ReplayBase::new(samples).map_err(|e| DaemonError::Base(e.to_string()))?,
            ))
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

/// Saves the map into `dir`; if that fails, into a rescue directory under
/// the system's temporary directory, so a full or read-only state
/// directory does not cost the map.
fn save(live: &mut LiveMapper, dir: &Path) -> Result<PathBuf, DaemonError> {
    match live.checkpoint(dir) {
        Ok(()) => Ok(dir.to_owned()),
        Err(first) => {
            let first = error_chain(&first);
            error!(dir = %dir.display(), "cannot save the map: {first}");
            let rescue = std::env::temp_dir().join(format!("clsmap-rescue-{}", run_dir_name()));
            match live.checkpoint(&rescue) {
                Ok(()) => {
                    error!(dir = %rescue.display(), "map saved to a rescue directory instead");
                    Ok(rescue)
                }
                Err(second) => Err(DaemonError::Save {
                    tried: format!("{} and {}", dir.display(), rescue.display()),
                    error: format!("{first}; {}", error_chain(&second)),
                }),
            }
        }
    }
}

fn status_line(s: &LiveStatus, rate: f64, sensor_ok: bool) -> String {
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
    let exploring = if s.exploration_complete {
        ", exploration complete"
    } else if s.exploring {
        ", exploring"
    } else {
        ""
    };
    format!(
        "{} {:.1} scans/s, {} scans ({} localized), map {} walls {} frontiers {} loops, {pose}{exploring}",
        if sensor_ok {
            "streaming"
        } else {
            "SENSOR SILENT"
        },
        rate,
        s.scans,
        s.localized,
        s.walls,
        s.frontiers,
        s.loops
    )
}

fn tick_every(seconds: f64) -> tokio::time::Interval {
    let mut i = tokio::time::interval(Duration::from_secs_f64(seconds.max(1e-3)));
    i.set_missed_tick_behavior(MissedTickBehavior::Skip);
    i
}

/// Runs the daemon until the shutdown future completes, exploration ends
/// (with `exit_when_complete`) or the time limit passes; then stops the
/// base and the sensor and saves the map.
pub async fn run(config: DaemonConfig, mut hooks: Hooks<'_>) -> Result<RunSummary, DaemonError> {
    let mut config = config;
    let t0 = Instant::now();
    let clock = move || t0.elapsed().as_secs_f64();
    let out_dir = match &hooks.out_dir {
        Some(dir) => {
            std::fs::create_dir_all(dir).map_err(|source| DaemonError::OutputDir {
                path: dir.clone(),
                source,
            })?;
            dir.clone()
        }
        None => new_run_dir(&config.state_dir())?,
    };
    info!(dir = %out_dir.display(), "maps will be saved here");
    let rig = build_rig(&config, t0)?;
    let robot = rig.robot.clone();
    let link = config.link();
    let mode = link.measuring_mode;
    let (scan_tx, mut scan_rx) = watch::channel::<Option<ScanSlot>>(None);
    let (report_tx, mut report_rx) = mpsc::unbounded_channel();
    let sensor = SensorThread::spawn(
        SensorOptions {
            port: rig.sensor_port.clone(),
            link,
            retry_initial: Duration::from_secs_f64(config.sensor.retry_initial),
            retry_max: Duration::from_secs_f64(config.sensor.retry_max),
            record: config.sensor.record.clone(),
        },
        scan_tx,
        report_tx,
    )
    .map_err(DaemonError::Thread)?;
    info!(port = %rig.sensor_port.display(), "sensor thread started");

    let exploration = |c: &DaemonConfig| {
        c.exploration
            .enabled
            .then_some((c.exploration.planner, c.exploration.drive))
    };
    let mut live = LiveMapper::new(config.mapper, exploration(&config), clock());
    let mut base = BaseDriver::new(rig.base, config.base.limits(), config.base.stale_odometry);
    let mut notifier = Notifier::from_env();
    if let Some(w) = notifier.watchdog() {
        info!(interval_s = w.as_secs_f64(), "systemd watchdog enabled");
    }
    let mut base_tick = tick_every(1.0 / config.base.rate);
    let mut status_tick = tick_every(config.daemon.status_interval);
    let checkpoints = config.daemon.checkpoint_interval > 0.0;
    let mut checkpoint_tick = tick_every(if checkpoints {
        config.daemon.checkpoint_interval
    } else {
        3600.0
    });
    checkpoint_tick.reset();
    let mut last_seq = 0u64;
    let mut skipped = 0u64;
    let mut last_scan_at: Option<f64> = None;
    let mut first_scan_after = None;
    let mut sensor_silent_logged = false;
    let mut scans_at_last_status = 0u64;
    let mut last_status_t = 0.0;
    let mut reload = hooks.reload.take();
    let mut shutdown = hooks.shutdown;
    let reason = loop {
        tokio::select! {
            () = &mut shutdown => break StopReason::Shutdown,
            Some(()) = async {
                match reload.as_mut() {
                    Some(r) => r.recv().await,
                    None => std::future::pending().await,
                }
            } => {
                reload_config(&hooks.config_path, &mut config, &mut live, &mut base);
            }
            changed = scan_rx.changed() => {
                if changed.is_err() {
                    // The sensor thread ended; it only does on stop.
                    std::future::pending::<()>().await;
                }
                let Some(slot) = scan_rx.borrow_and_update().clone() else { continue };
                skipped += slot.seq.saturating_sub(last_seq + 1);
                last_seq = slot.seq;
                let now = clock();
                base.poll(now, &mut live);
                let t = slot.scan.timestamp.saturating_duration_since(t0).as_secs_f64();
                let Some(scan) = range_scan(&slot.scan.scan, t, mode) else { continue };
                let queued = slot.scan.received_at.elapsed();
                let outcome = live.on_scan(scan, Some(queued));
                if first_scan_after.is_none() {
                    first_scan_after = Some(now);
                    info!(after_s = now, "first scan mapped; ready");
                    notifier.ready();
                }
                if sensor_silent_logged {
                    info!("scans are back");
                    sensor_silent_logged = false;
                }
                last_scan_at = Some(now);
                if let Some(hook) = hooks.on_scan.as_mut() {
                    hook(&ScanProgress {
                        t: now,
                        pose: outcome.pose,
                        truth: robot.as_ref().map(|r| r.true_pose_at(t)),
                        localized: outcome.localized,
                        status: live.status(),
                    });
                }
            }
            Some(report) = report_rx.recv() => log_report(&report),
            _ = base_tick.tick() => {
                let _span = info_span!("control").entered();
                let now = clock();
                notifier.loop_alive(Instant::now());
                base.poll(now, &mut live);
                let sensor_ok = last_scan_at.is_some_and(|t| now - t <= config.sensor.silence_stop);
                if !sensor_ok && last_scan_at.is_some() && !sensor_silent_logged {
                    warn!(silent_s = config.sensor.silence_stop, "no scan: the base stops until scans return");
                    sensor_silent_logged = true;
                }
                if live.explorer().is_some() {
                    let (twist, _) = if sensor_ok { live.control(now) } else { (Twist::ZERO, None) };
                    base.command(twist, !sensor_ok, now, live.last_odometry_time());
                } else if !sensor_ok {
                    base.command(Twist::ZERO, true, now, live.last_odometry_time());
                }
                if config.exploration.exit_when_complete && live.exploration_complete() {
                    break StopReason::ExplorationComplete;
                }
                if config.daemon.max_run_time > 0.0 && now >= config.daemon.max_run_time {
                    break StopReason::TimeLimit;
                }
            }
            _ = status_tick.tick() => {
                let now = clock();
                let status = live.status();
                let rate = (status.scans - scans_at_last_status) as f64 / (now - last_status_t).max(1e-3);
                scans_at_last_status = status.scans;
                last_status_t = now;
                let sensor_ok = last_scan_at.is_some_and(|t| now - t <= config.sensor.silence_stop);
                let line = status_line(&status, rate, sensor_ok);
                info!(skipped, "{line}");
                info!("latency µs p50/p99/max: {}", live.latencies().line());
                notifier.status(&line);
            }
            _ = checkpoint_tick.tick(), if checkpoints => {
                if let Err(e) = live.checkpoint(&out_dir) {
                    error!(dir = %out_dir.display(), "checkpoint failed, the map stays in memory: {}", error_chain(&e));
                }
            }
        }
    };
    info!(?reason, "stopping");
    notifier.stopping();
    let now = clock();
    base.stop(now);
    // Closing the link (stop streaming, back to 9600 Bd) blocks briefly.
    let stopped = tokio::task::spawn_blocking(move || sensor.stop()).await;
    if stopped.is_err() {
        warn!("the sensor thread did not stop cleanly");
    }
    while let Ok(report) = report_rx.try_recv() {
        log_report(&report);
    }
    let saved_in = save(&mut live, &out_dir)?;
    let status = live.status();
    info!(dir = %saved_in.display(), "{}", status_line(&status, 0.0, true));
    Ok(RunSummary {
        reason,
        out_dir: saved_in,
        scans: status.scans,
        status,
        scans_skipped: skipped,
        odometry_refused: base.odometry_refused(),
        latencies: live.latencies().summaries(),
        first_scan_after,
        run_time: clock(),
    })
}

fn reload_config(
    path: &Option<PathBuf>,
    config: &mut DaemonConfig,
    live: &mut LiveMapper,
    base: &mut BaseDriver,
) {
    let Some(path) = path else {
        info!("reload asked for, but no configuration file to re-read");
        return;
    };
    match DaemonConfig::load(path) {
        Err(e) => error!(
            path = %path.display(),
            "reload refused, the running configuration stays: {}",
            error_chain(&e)
        ),
        Ok(new) => {
            let exploration = new
                .exploration
                .enabled
                .then_some((new.exploration.planner, new.exploration.drive));
            let kept = live.retune(new.mapper, exploration);
            base.retune(new.base.limits(), new.base.stale_odometry);
            let mut restart = kept
                .iter()
                .map(|k| format!("mapper.{k}"))
                .collect::<Vec<_>>();
            for (name, changed) in [
                ("sensor", new.sensor != config.sensor),
                ("base.adapter", new.base.adapter != config.base.adapter),
                ("sim", new.sim != config.sim),
                ("daemon", new.daemon != config.daemon),
                (
                    "exploration.enabled",
                    new.exploration.enabled != config.exploration.enabled,
                ),
            ] {
                if changed {
                    restart.push(name.to_string());
                }
            }
            // Tunables take effect; the rest stays as it runs.
            config.mapper = new.mapper;
            config.base.stale_odometry = new.base.stale_odometry;
            config.base.max_speed = new.base.max_speed;
            config.base.max_turn_rate = new.base.max_turn_rate;
            config.base.max_acceleration = new.base.max_acceleration;
            config.base.max_angular_acceleration = new.base.max_angular_acceleration;
            config.exploration.planner = new.exploration.planner;
            config.exploration.drive = new.exploration.drive;
            config.exploration.exit_when_complete = new.exploration.exit_when_complete;
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
    }
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
            Event::Reinitializing { reason } => warn!(?reason, "sensor link starting over"),
            Event::CommandRejected { command } => warn!(?command, "sensor rejected a command"),
            Event::Error(e) => warn!("sensor link: {e}"),
            Event::Closed => info!("sensor link closed"),
            Event::Scan(_) => {}
        },
    }
}

/// Link counters are per connection and live in the sensor thread; the
/// loop counts what reaches it. Kept for the status of a finished run.
#[allow(dead_code)]
fn link_stats_line(stats: &LinkStats) -> String {
    format!(
        "{} scans, {} frames dropped, {} telegrams lost",
        stats.scans, stats.dropped_frames, stats.lost_telegrams
    )
}
