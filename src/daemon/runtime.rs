//! The real-time loop on tokio: the sensor thread, the base, the mapper,
//! the explorer, checkpoints, status and systemd, wired together.
//!
//! One current-thread runtime runs the loop around [`Core`]; the serial
//! driver runs on its own thread (it blocks on the port) and hands over
//! only the newest scan; checkpoints and loop-closure optimisations run on
//! blocking threads; the live view serves from a thread of its own. The
//! loop turns into `Core` calls: a new scan, the core's next timeout, a
//! checkpoint's or an optimisation's completion, sensor reports, the live
//! view's commands, a reload request and the shutdown future; what the
//! core polls out becomes systemd notifications, snapshots for the live
//! view, checkpoints and optimisations. On shutdown it stops the base,
//! stops the sensor, saves the map.

use std::future::Future;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use clsmap_base::{BaseAdapter, LineBase, ReplayBase};
use lms200::link::Event;
use serde::Serialize;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;
use tracing::{error, info, warn};

use super::bag_sink::{BAG_FILE, BagSink};
use super::base_driver::{BaseConnector, BaseDriver};
use super::checkpoint::CheckpointFailed;
use super::config::{BaseKind, DaemonConfig};
pub use super::core::StopReason;
use super::core::{Core, status_line};
use super::latency::StageSummary;
use super::live::{LiveMapper, LiveStatus};
use super::notify::Notifier;
use super::run_dir::RunDirs;
use super::sensor::{RawTelegrams, ScanSlot, SensorOptions, SensorReport, SensorThread};
use crate::error_chain;
use crate::geometry::Pose2;
use crate::graph::{LoopSearchResult, OptimisationResult};

/// Why the daemon could not start or finish.
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    #[error("cannot write to {path}")]
    OutputDir {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[cfg(feature = "sim")]
    #[error("cannot load the simulated world {0:?}")]
    World(String, #[source] crate::sim::world_file::WorldFileError),
    #[cfg(feature = "sim")]
    #[error("no built-in world is called {0:?} (built in: {1})")]
    UnknownWorld(String, String),
    #[cfg(feature = "sim")]
    #[error("cannot start the emulated LMS200")]
    Emulator(#[from] lms200::pty::PtyError),
    #[error("{0}; this clsmap was built without it (cargo feature `sim`)")]
    NoSimulator(&'static str),
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
    #[cfg(feature = "dds")]
    #[error(transparent)]
    Ros2(#[from] super::dds_sink::DdsError),
    #[error("cannot start the async runtime")]
    Runtime(#[source] std::io::Error),
    #[error("the map could not be saved anywhere; tried {tried}")]
    Save { tried: String },
    #[error(transparent)]
    Web(#[from] super::web::server::WebError),
    #[error("cannot start from the map {path} (on_bad_map = \"refuse\")")]
    Map {
        path: PathBuf,
        #[source]
        source: crate::pipeline::PipelineError,
    },
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
    /// Called with the live view's address once it listens.
    pub on_web: Option<Box<dyn FnMut(std::net::SocketAddr) + 'a>>,
    /// When `[web] bind`'s port is taken, listen on a free port of the
    /// same address instead of refusing to start (the demo).
    pub web_any_port: bool,
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
            on_web: None,
            web_any_port: false,
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
    let loaded = crate::map::file::load_with(path, config.map.checksum_check())
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
    /// The simulated robot, to report where it truly was.
    #[cfg(feature = "sim")]
    robot: Option<crate::sim::SimRobot>,
    /// Keeps the emulator's pty open while the daemon runs.
    #[cfg(feature = "sim")]
    _pty: Option<lms200::pty::PtyEmulator>,
    sensor_port: PathBuf,
}

impl Rig {
    /// Where the simulated robot truly was at `t` (s), on a simulated rig.
    fn truth(&self, t: f64) -> Option<Pose2> {
        #[cfg(feature = "sim")]
        return self.robot.as_ref().map(|r| r.true_pose_at(t));
        #[cfg(not(feature = "sim"))]
        return {
            let _ = t;
            None
        };
    }
}

/// The rig of `config`; `t0` is the daemon clock's zero and `epoch` the
/// wall clock then (s since the Unix epoch).
fn build_rig(config: &DaemonConfig, t0: Instant, epoch: f64) -> Result<Rig, DaemonError> {
    #[cfg(feature = "sim")]
    let (mut robot, mut pty) = (None, None);
    #[cfg(not(feature = "sim"))]
    let _ = t0;
    #[cfg(not(feature = "dds"))]
    let _ = epoch;
    #[allow(unused_mut)]
    let mut sensor_port = config.sensor.port.clone();
    let base: Option<BaseConnector> = match config.base.adapter {
        #[cfg(feature = "sim")]
        BaseKind::Sim => {
            let (sim, world) = super::simulation::simulated_robot(config)?;
            if config.sensor.source == super::config::SensorSource::Emulator {
                let emulator = super::simulation::emulated_sensor(config, &world, &sim, t0);
                let p = lms200::pty::PtyEmulator::spawn(emulator, None)?;
                sensor_port = p.tty_path().to_owned();
                pty = Some(p);
            }
            let base = sim.base();
            robot = Some(sim);
            Some(BaseDriver::once(Box::new(base)))
        }
        #[cfg(not(feature = "sim"))]
        BaseKind::Sim => {
            return Err(DaemonError::NoSimulator(
                "[base] adapter = \"sim\" needs the simulator",
            ));
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
        #[cfg(feature = "dds")]
        BaseKind::Ros2 => {
            let (ros2, base) = (config.ros2.clone(), config.base.clone());
            Some(Box::new(move || {
                super::ros2_base::Ros2Base::start(&ros2, &base, t0, epoch)
                    .map(|b| Box::new(b) as Box<dyn BaseAdapter + Send>)
            }))
        }
        #[cfg(not(feature = "dds"))]
        BaseKind::Ros2 => {
            return Err(DaemonError::NoSimulator(
                "[base] adapter = \"ros2\" needs the `dds` feature",
            ));
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
        #[cfg(feature = "sim")]
        robot,
        #[cfg(feature = "sim")]
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

/// What the ROS 2 node heard, given to the core.
#[cfg(feature = "dds")]
use super::dds_sink::Ros2Command;

/// Without the node nothing is heard.
#[cfg(not(feature = "dds"))]
#[derive(Debug)]
enum Ros2Command {}

fn on_ros2(core: &mut Core, command: Ros2Command, now: f64) {
    #[cfg(feature = "dds")]
    match command {
        Ros2Command::Velocity(twist) => core.handle_velocity_command(now, twist),
        Ros2Command::PoseHint(pose) => core.handle_pose_hint(now, pose, "/initialpose"),
    }
    #[cfg(not(feature = "dds"))]
    {
        let _ = (core, now);
        match command {}
    }
}

/// Runs the daemon until the shutdown future completes, exploration ends
/// (with `exit_when_complete`) or the time limit passes; then stops the
/// base and the sensor and saves the map.
///
/// This is the tokio shell around [`Core`]: it turns the sensor thread's
/// mailbox, its reports, SIGHUP and the clock into `handle_*` calls, and
/// what the core polls out into systemd notifications, checkpoints and
/// optimisations on blocking threads.
pub async fn run(config: DaemonConfig, hooks: Hooks<'_>) -> Result<RunSummary, DaemonError> {
    let t0 = Instant::now();
    // The wall clock at the daemon clock's zero: ROS 2 stamps are wall times.
    let epoch = lms200::driver::unix_micros() as f64 / 1e6;
    let clock = move || t0.elapsed().as_secs_f64();
    let mut dirs = RunDirs::new(config.state_dir(), hooks.out_dir.clone())?;
    // The map first: a saved map that cannot be used stops the start
    // before the sensor and the base are touched.
    let exploration = config
        .exploration
        .enabled
        .then_some((config.exploration.planner, config.exploration.drive));
    // Loop-closure optimisations and rebuilds run on a blocking thread; the
    // loop goes on localizing against the old map meanwhile.
    let mut live = start_map(&config, exploration)?;
    live.set_background_loop_closure(true);
    let Hooks {
        shutdown: mut shutdown_signal,
        mut reload,
        config_path,
        mut on_scan,
        mut on_web,
        web_any_port,
        ..
    } = hooks;
    // The live view's port next: a taken one stops the start before the
    // sensor and the base are touched.
    let web = start_web(&config, web_any_port)?;
    let (_web_server, mut web_feed) = match web {
        Some((server, feed)) => {
            if let Some(hook) = on_web.as_mut() {
                hook(server.address());
            }
            (Some(server), Some(feed))
        }
        None => (None, None),
    };
    let mut rig = build_rig(&config, t0, epoch)?;
    let (scan_tx, mut scan_rx) = watch::channel::<Option<ScanSlot>>(None);
    let (report_tx, mut report_rx) = mpsc::unbounded_channel();
    // The run's bag holds the serial stream too; a recording of it, the
    // base's odometry as well.
    let raw_telegrams = config.daemon.bag.then(RawTelegrams::default);
    let recorded_odometry = (raw_telegrams.is_some() || config.sensor.record.is_some())
        .then(lms200::recording::RecordQueue::default);
    let sensor = SensorThread::spawn(
        SensorOptions {
            port: rig.sensor_port.clone(),
            link: config.link(),
            retry_initial: Duration::from_secs_f64(config.sensor.retry_initial),
            retry_max: Duration::from_secs_f64(config.sensor.retry_max),
            record: config.sensor.record.clone(),
            raw: raw_telegrams.clone(),
            queued: recorded_odometry.clone(),
        },
        scan_tx,
        report_tx,
    )
    .map_err(DaemonError::Thread)?;
    info!(port = %rig.sensor_port.display(), "sensor thread started");
    let mut notifier = Notifier::from_env();
    if let Some(w) = notifier.watchdog() {
        info!(interval_s = w.as_secs_f64(), "systemd watchdog enabled");
    }
    let mut base = BaseDriver::new(
        rig.base.take(),
        config.base.limits(),
        config.base.stale_odometry,
        config.sensor.retry_initial,
        config.sensor.retry_max,
    );
    if let Some(queue) = recorded_odometry {
        base.record_odometry_into(queue);
    }
    let write_bag = config.daemon.bag;
    // The ROS 2 node before the loop starts: asked for, it must be there.
    #[cfg(feature = "dds")]
    let (mut dds, mut ros2_inbox) = match config.ros2.enabled {
        true => {
            let (tx, rx) = mpsc::unbounded_channel();
            (
                Some(super::dds_sink::DdsSink::start(
                    &config.ros2,
                    config.base.adapter == BaseKind::Ros2,
                    tx,
                )?),
                Some(rx),
            )
        }
        false => (None, None),
    };
    let publish = write_bag || config.ros2.enabled;
    let mut core = Core::new(config, live, base);
    if publish {
        core.enable_ros2(epoch);
    }
    // Started at the first scan, in the run's directory (a run that never
    // saw a scan leaves none behind); a bag that cannot be written is given
    // up with an error, the run goes on.
    let mut bag: Option<BagSink> = None;
    let mut bag_failed = false;
    let mut last_seq = 0;
    let mut writing: Option<JoinHandle<Result<(), CheckpointFailed>>> = None;
    let mut optimising: Option<JoinHandle<OptimisationResult>> = None;
    // The newest keyframe's loop search runs beside the loop too.
    let mut searching: Option<JoinHandle<LoopSearchResult>> = None;
    let reason = loop {
        let wake = Duration::try_from_secs_f64(core.poll_timeout())
            .ok()
            .and_then(|d| t0.checked_add(d))
            .unwrap_or_else(|| Instant::now() + Duration::from_secs(3600));
        tokio::select! {
            () = &mut shutdown_signal => break StopReason::Shutdown,
            Some(()) = async {
                match reload.as_mut() {
                    Some(r) => r.recv().await,
                    None => std::future::pending().await,
                }
            } => reload_config(&mut core, &config_path, clock()),
            changed = scan_rx.changed() => {
                if changed.is_err() {
                    error!("the sensor thread ended; saving the map and stopping");
                    break StopReason::SensorThreadEnded;
                }
                let slot = scan_rx.borrow_and_update().clone();
                if let Some(slot) = slot {
                    core.handle_skipped(slot.seq.saturating_sub(last_seq + 1));
                    last_seq = slot.seq;
                    let now = clock();
                    let t = slot.scan.timestamp.saturating_duration_since(t0).as_secs_f64();
                    let queued = slot.scan.received_at.elapsed();
                    let outcome = core.handle_scan(now, t, &slot.scan.scan, Some(queued));
                    if let (Some(outcome), Some(hook)) = (outcome, on_scan.as_mut()) {
                        hook(&ScanProgress {
                            t: now,
                            pose: outcome.pose,
                            truth: rig.truth(t),
                            localized: outcome.localized,
                            status: core.status(),
                        });
                    }
                }
            }
            result = finished(&mut optimising) => {
                optimising = None;
                optimisation_done(&mut core, result);
            }
            result = finished(&mut searching) => {
                searching = None;
                loop_search_done(&mut core, result);
            }
            Some(report) = report_rx.recv() => on_report(&mut core, &report),
            Some(command) = async {
                #[cfg(feature = "dds")]
                if let Some(inbox) = ros2_inbox.as_mut() {
                    return inbox.recv().await;
                }
                std::future::pending::<Option<Ros2Command>>().await
            } => on_ros2(&mut core, command, clock()),
            Some(command) = async {
                match web_feed.as_mut() {
                    Some(feed) => feed.control.recv().await,
                    None => std::future::pending().await,
                }
            } => core.handle_control(command, clock()),
            () = tokio::time::sleep_until(wake.into()) => {
                core.handle_tick(clock(), None);
                notifier.loop_alive(Instant::now());
            }
            result = finished(&mut writing) => {
                writing = None;
                checkpoint_done(&mut core, result);
            }
        }
        // What the core built for ROS 2 (scans, and at each status tick
        // the diagnostics, also while the sensor is silent).
        let messages = core.poll_ros2();
        #[cfg(feature = "dds")]
        if let Some(node) = dds.as_mut() {
            node.send(&messages);
        }
        // The bag (and with it the run's directory) starts with a scan.
        let has_scan = messages
            .iter()
            .any(|m| matches!(m.message, super::ros2_out::Ros2Message::Scan(_)));
        if write_bag && bag.is_none() && has_scan && !bag_failed {
            let started = dirs.out_dir().map_err(|e| e.to_string()).and_then(|d| {
                BagSink::start(&d.join(BAG_FILE), raw_telegrams.clone())
                    .map_err(|e| crate::error_chain(&e))
            });
            match started {
                Ok(sink) => bag = Some(sink),
                Err(e) => {
                    error!("no bag of this run: {e}");
                    bag_failed = true;
                }
            }
        }
        if let Some(sink) = bag.as_mut() {
            sink.send(messages);
        }
        if core.poll_ready() {
            notifier.ready();
        }
        if let Some(line) = core.poll_status() {
            notifier.status(&line);
        }
        if let Some(feed) = &web_feed {
            if let Some(map) = core.poll_map_view() {
                feed.map.send_replace(Some(std::sync::Arc::new(map)));
            }
            if let Some(view) = core.poll_view() {
                feed.view.send_replace(Some(std::sync::Arc::new(view)));
            }
        }
        if core.poll_checkpoint() {
            writing = start_checkpoint(&mut core, &mut dirs);
        }
        if searching.is_none()
            && let Some(job) = core.poll_loop_search()
        {
            searching = Some(tokio::task::spawn_blocking(move || job.run()));
        }
        if optimising.is_none()
            && let Some(job) = core.poll_optimisation()
        {
            optimising = Some(tokio::task::spawn_blocking(move || job.run()));
        }
        if let Some(reason) = core.poll_stop() {
            break reason;
        }
    };
    info!(?reason, "stopping");
    notifier.stopping();
    core.stop_base(clock());
    // Stop streaming while the map is saved; closing the link (stop the
    // output, back to 9600 Bd) takes a moment and the save does not wait.
    sensor.request_stop();
    if let Some(task) = writing.take() {
        let result = task.await;
        checkpoint_done(&mut core, result);
    }
    if let Some(task) = searching.take() {
        loop_search_done(&mut core, task.await);
    }
    if let Some(task) = optimising.take() {
        optimisation_done(&mut core, task.await);
    }
    // Loops that agreed with the graph but were not optimised yet are
    // taken in before the last save.
    core.finish();
    let saved = dirs.save(&mut core);
    #[cfg(feature = "dds")]
    if let Some(node) = dds.take() {
        let _ = tokio::task::spawn_blocking(move || node.finish()).await;
    }
    // The sensor first: the bag then holds the serial stream to its end.
    let joined = tokio::task::spawn_blocking(move || sensor.stop()).await;
    if joined.is_err() {
        warn!("the sensor thread did not stop cleanly");
    }
    if let Some(sink) = bag.take() {
        match tokio::task::spawn_blocking(move || sink.finish()).await {
            Ok(Ok((path, n))) => info!(path = %path.display(), messages = n, "bag written"),
            Ok(Err(e)) => error!("the bag is incomplete: {}", crate::error_chain(&e)),
            Err(_) => error!("the bag writer did not finish"),
        }
    }
    while let Ok(report) = report_rx.try_recv() {
        on_report(&mut core, &report);
    }
    let (out_dir, rescued_because) = saved?;
    let status = core.status();
    info!("{}", status_line(&status, 0.0, "stopped:"));
    Ok(RunSummary {
        reason,
        out_dir,
        rescued_because,
        scans: status.scans,
        status,
        scans_skipped: core.skipped(),
        odometry_refused: core.base().odometry_refused(),
        latencies: core.live().latencies().summaries(),
        first_scan_after: core.first_scan_after(),
        run_time: clock(),
    })
}

/// The live view's server, when `[web]` asks for it; with `any_port` a
/// taken port gives way to a free one on the same address.
fn start_web(
    config: &DaemonConfig,
    any_port: bool,
) -> Result<Option<(super::web::server::WebServer, super::web::server::WebFeed)>, DaemonError> {
    use super::web::server::{WebError, WebOptions, serve};
    if !config.web.enabled {
        return Ok(None);
    }
    let Some(address) = config.web.address() else {
        return Ok(None);
    };
    let options = WebOptions {
        address,
        token: config.web.token.clone(),
        max_clients: config.web.max_clients,
    };
    match serve(options.clone()) {
        Ok(served) => Ok(Some(served)),
        Err(WebError::Bind { source, .. })
            if any_port && source.kind() == std::io::ErrorKind::AddrInUse =>
        {
            warn!(%address, "the live view's port is taken; using a free one");
            let mut elsewhere = options;
            elsewhere.address.set_port(0);
            Ok(Some(serve(elsewhere)?))
        }
        Err(e) => Err(e.into()),
    }
}

/// Starts writing a checkpoint on a blocking thread.
fn start_checkpoint(
    core: &mut Core,
    dirs: &mut RunDirs,
) -> Option<JoinHandle<Result<(), CheckpointFailed>>> {
    let dir = match dirs.out_dir() {
        Ok(dir) => dir,
        Err(e) => {
            error!("cannot make the run directory, the map stays in memory: {e}");
            return None;
        }
    };
    let checkpoint = core.begin_checkpoint(&dir);
    Some(tokio::task::spawn_blocking(move || checkpoint.write()))
}

fn checkpoint_done(
    core: &mut Core,
    result: Result<Result<(), CheckpointFailed>, tokio::task::JoinError>,
) {
    match result {
        Ok(written) => {
            if let Err(e) = core.handle_checkpoint_done(written) {
                error!(
                    "checkpoint failed, the map stays in memory: {}",
                    error_chain(&e)
                );
            }
        }
        Err(e) => {
            error!("the checkpoint writer failed, its poses are lost: {e}");
            core.handle_checkpoint_lost();
        }
    }
}

/// The result of `task` once it has finished; never, while there is none
/// (a `select!` branch that waits for a blocking job if one runs).
async fn finished<T>(task: &mut Option<JoinHandle<T>>) -> Result<T, tokio::task::JoinError> {
    match task {
        Some(task) => task.await,
        None => std::future::pending().await,
    }
}

/// Takes in a background optimisation's result; a job whose thread
/// failed is abandoned, so the next one takes its loops in.
fn optimisation_done(core: &mut Core, result: Result<OptimisationResult, tokio::task::JoinError>) {
    if let Err(e) = &result {
        error!("the loop-closure optimiser failed: {e}");
    }
    core.handle_optimisation_done(result.ok());
}

/// Takes in a background loop search's result; a search whose thread
/// failed is dropped (the next keyframe's goes ahead).
fn loop_search_done(core: &mut Core, result: Result<LoopSearchResult, tokio::task::JoinError>) {
    if let Err(e) = &result {
        error!("the loop search failed: {e}");
    }
    core.handle_loop_search_done(result.ok());
}

/// Re-reads the configuration (SIGHUP); a file that does not load is
/// refused with the reason and the running configuration stays.
fn reload_config(core: &mut Core, path: &Option<PathBuf>, now: f64) {
    let Some(path) = path else {
        info!("reload asked for, but no configuration file to re-read");
        return;
    };
    match DaemonConfig::load(path) {
        Ok(new) => core.handle_reload(new, now, path),
        Err(e) => error!(
            path = %path.display(),
            "reload refused, the running configuration stays: {}",
            error_chain(&e)
        ),
    }
}

fn on_report(core: &mut Core, report: &SensorReport) {
    if let SensorReport::Failed { error, .. } = report {
        core.handle_sensor_failure(error);
    }
    log_report(report);
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
