//! [`Core`]: the daemon's loop without the loop.
//!
//! Scans, odometry, sensor failures, reloads and the clock go in
//! (`handle_*`); what the shell must do comes out (`poll_*`): tell systemd
//! it is ready, publish a status line, write a checkpoint, run a
//! loop-closure optimisation, stop. The core keeps the loop's timers (base
//! control, status, checkpoints) and says when it next needs the clock
//! ([`Core::poll_timeout`]); it never sleeps, spawns or opens a file. Its
//! one port is the base adapter the shell hands it (a trait object: the
//! simulated base, a replay, a line-protocol bridge), driven through
//! [`BaseDriver`] with its limits and safety stops.
//!
//! Two shells drive the same core: the tokio loop of `clsmap run` and
//! `clsmap demo` ([`super::runtime`]), at the sensor's real pace, and
//! [`VirtualRobot`](super::simulation::VirtualRobot), on a virtual clock
//! as fast as the CPU allows. Times are seconds since the run started.

use std::time::Duration;

use clsmap_base::Twist;
use tracing::{debug, info, info_span, warn};

use super::base_driver::BaseDriver;
use super::checkpoint::{Checkpoint, CheckpointFailed};
use super::config::DaemonConfig;
use super::live::{LiveMapper, LiveStatus};
use super::web::{ControlCommand, LiveView, MapView};
use crate::explore::{free_run, open_way};
use crate::geometry::{BeamFault, ExtractionConfig, Pose2, RangeScan};
use crate::graph::{LoopSearchJob, LoopSearchResult, OptimisationJob, OptimisationResult};
use crate::input::lms200::range_scan;
use crate::pipeline::{MapSearch, PipelineError, ScanOutcome};

/// Why the loop ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
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

/// A periodic timer: due at `next`, then every `period` seconds; ticks
/// missed while the loop was busy are skipped, not caught up.
#[derive(Debug, Clone, Copy)]
struct Timer {
    next: f64,
    period: f64,
}

impl Timer {
    /// First due at `first` (s).
    fn new(first: f64, period: f64) -> Timer {
        Timer {
            next: first,
            period: period.max(1e-3),
        }
    }

    /// Whether it is due at `now`; if so, moves on past `now`.
    fn fire(&mut self, now: f64) -> bool {
        if now < self.next {
            return false;
        }
        while self.next <= now {
            self.next += self.period;
        }
        true
    }
}

/// The loop's timers, by what they start.
#[derive(Debug, Clone, Copy)]
struct Timers {
    /// Poll the base, command it, check the stop conditions.
    control: Timer,
    /// The status line and `STATUS=`.
    status: Timer,
    /// A map checkpoint; `None` when `checkpoint_interval` is 0.
    checkpoint: Option<Timer>,
    /// A snapshot for the live view; `None` when `[web]` is off.
    view: Option<Timer>,
}

/// Seconds between map snapshots for the live view at most: a snapshot
/// copies the map, which grows with the building.
const MAP_VIEW_EVERY: f64 = 1.0;
/// A velocity command drives the base this long (s) and no longer: a
/// teleop that stops sending (a dropped link, a closed window) stops the
/// robot. Half a second, as ROS base drivers' command timeouts.
pub const TELEOP_TIMEOUT: f64 = 0.5;

/// Seconds within which the same pose hint again is a repeat of it (a
/// bridge resending its line), not a new hint.
const REPEATED_HINT: f64 = 5.0;

/// The drive of a search for the robot (see `Core::search_drive`): ways
/// within this angle (rad) of the sensor's forward, which it sees ahead of
/// it; looked along this far (m, the LMS200's reach in mm mode); a leg
/// starts only where this much (m) is open and ends where the way ahead
/// closes to this (m).
const SEARCH_HALF_ANGLE: f64 = 60.0 * std::f64::consts::PI / 180.0;
const SEARCH_REACH: f64 = 8.0;
const SEARCH_MIN_LEG: f64 = 1.0;
const SEARCH_STOP: f64 = 0.3;

/// The points of `scan` in the robot frame (m) that the line extractor
/// uses (`cfg`), the sensor mounted at `mount`; a beam the sensor flagged
/// (dazzled, low signal) is added as a point a metre out, so the robot
/// does not drive where it cannot see. A beam with no echo leaves its way
/// open.
fn scan_points(scan: &RangeScan, mount: &Pose2, cfg: &ExtractionConfig) -> Vec<[f64; 2]> {
    let mut points = crate::geometry::scan_points(scan, mount, cfg);
    points.extend(
        (0..scan.ranges.len())
            .filter(|&i| scan.ranges[i] == Err(BeamFault::SensorCode))
            .map(|i| {
                let (s, c) = scan.angle(i).sin_cos();
                mount.transform_point([c, s])
            }),
    );
    points
}

/// The daemon's loop, sans-IO; see the module doc.
#[derive(Debug)]
pub struct Core {
    config: DaemonConfig,
    live: LiveMapper,
    base: BaseDriver,
    mode: lms200::MeasuringMode,
    timers: Timers,
    skipped: u64,
    last_scan_at: Option<f64>,
    first_scan_after: Option<f64>,
    silence_logged: bool,
    /// The sensor's last failure, for the status line.
    sensor_trouble: Option<String>,
    scans_at_last_status: u64,
    last_status_t: f64,
    ready_sent: bool,
    ready_due: bool,
    status_due: Option<String>,
    checkpoint_due: bool,
    checkpoint_in_flight: bool,
    optimisation_in_flight: bool,
    stop: Option<StopReason>,
    /// Exploration held from the live view.
    paused: bool,
    view_due: Option<LiveView>,
    map_view_due: Option<MapView>,
    /// The scans, poses and transforms for ROS 2 (a bag), when asked for.
    ros2: Option<super::ros2_out::Ros2Outbox>,
    /// What the last map snapshot was taken of, its version, and when.
    map_key: Option<MapKey>,
    map_version: u64,
    last_map_view: f64,
    scans_at_last_view: u64,
    last_view_t: f64,
    /// Optimisations taken in so far (each moves the whole map).
    optimisations: u64,
    /// Seconds the current search for the robot in a loaded map has run
    /// with scans coming in, and whether that is past `turn_for` and the
    /// drive after it is done (the robot then waits, stopped); whether the
    /// base turned or drove for it at the last control step, and when that
    /// step was.
    search_time: f64,
    search_waiting: bool,
    was_turning: bool,
    /// The drive of a search that turning did not settle: the latest
    /// scan's points (robot frame, m) while a search is on, the metres
    /// driven for it, and the direction (rad, robot frame) of the leg
    /// under way.
    search_view: Vec<[f64; 2]>,
    search_driven: f64,
    search_leg: Option<f64>,
    /// Seconds the drive turned in place for want of an open way.
    search_seek: f64,
    /// The last velocity command from ROS 2 (`/cmd_vel`) and when it came.
    teleop: Option<(f64, Twist)>,
    /// Whether the last control step was driven by it.
    teleop_driving: bool,
    last_control_at: Option<f64>,
    /// The last pose hint and when it came (s): the same hint again within
    /// [`REPEATED_HINT`] is a bridge repeating itself, not a new one.
    last_hint: Option<(Pose2, f64)>,
}

/// What makes the map look different: counts that change with it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct MapKey {
    keyframes: usize,
    walls: usize,
    frontiers: usize,
    loops: usize,
    optimisations: u64,
    /// Poses on the path drawn (it grows in localize mode too, where the
    /// map does not).
    path: usize,
}

impl Core {
    /// The loop of `config` around `live` (a new or loaded map) and `base`.
    pub fn new(config: DaemonConfig, live: LiveMapper, base: BaseDriver) -> Core {
        let daemon = &config.daemon;
        let timers = Timers {
            control: Timer::new(0.0, 1.0 / config.base.rate),
            status: Timer::new(0.0, daemon.status_interval),
            checkpoint: (daemon.checkpoint_interval > 0.0).then(|| {
                let every = daemon.checkpoint_interval.max(1.0);
                Timer::new(every, every)
            }),
            view: config
                .web
                .enabled
                .then(|| Timer::new(0.0, 1.0 / config.web.rate)),
        };
        Core {
            mode: config.link().measuring_mode,
            config,
            live,
            base,
            timers,
            skipped: 0,
            last_scan_at: None,
            first_scan_after: None,
            silence_logged: false,
            sensor_trouble: None,
            scans_at_last_status: 0,
            last_status_t: 0.0,
            ready_sent: false,
            ready_due: false,
            status_due: None,
            checkpoint_due: false,
            checkpoint_in_flight: false,
            optimisation_in_flight: false,
            stop: None,
            paused: false,
            view_due: None,
            map_view_due: None,
            ros2: None,
            map_key: None,
            map_version: 0,
            last_map_view: f64::NEG_INFINITY,
            scans_at_last_view: 0,
            last_view_t: 0.0,
            optimisations: 0,
            search_time: 0.0,
            search_waiting: false,
            was_turning: false,
            search_view: Vec::new(),
            search_driven: 0.0,
            search_leg: None,
            search_seek: 0.0,
            teleop: None,
            teleop_driving: false,
            last_control_at: None,
            last_hint: None,
        }
    }

    pub fn config(&self) -> &DaemonConfig {
        &self.config
    }

    pub fn live(&self) -> &LiveMapper {
        &self.live
    }

    pub fn base(&self) -> &BaseDriver {
        &self.base
    }

    /// Scans replaced in the sensor's mailbox before the loop took them.
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    /// Seconds from the start to the first mapped scan.
    pub fn first_scan_after(&self) -> Option<f64> {
        self.first_scan_after
    }

    fn sensor_ok(&self, now: f64) -> bool {
        self.last_scan_at
            .is_some_and(|t| now - t <= self.config.sensor.silence_stop)
    }

    /// One scan taken from the sensor at `now`; `t` is the middle of its
    /// sweep and `queued` the time since its last byte, when known. `None`
    /// when the telegram holds no usable scan.
    pub fn handle_scan(
        &mut self,
        now: f64,
        t: f64,
        scan: &lms200::Scan,
        queued: Option<Duration>,
    ) -> Option<ScanOutcome> {
        self.poll_base(now);
        let scan = range_scan(scan, t, self.mode)?;
        let for_ros2 = self.ros2.is_some().then(|| scan.clone());
        let view = self.live.mapper().map_search().is_some().then(|| {
            scan_points(
                &scan,
                &self.config.mapper.laser_mount,
                &self.config.mapper.extraction,
            )
        });
        let outcome = self.live.on_scan(scan, queued);
        match view {
            Some(points) if self.live.mapper().map_search().is_some() => self.search_view = points,
            _ => self.search_view.clear(),
        }
        if let (Some(out), Some(scan)) = (self.ros2.as_mut(), for_ros2) {
            let odometry = self.live.odometry_at(t);
            let cov = self.live.mapper().last_covariance();
            out.scan(&scan, outcome.pose, &cov, odometry);
            // The map changes with every keyframe and every optimisation.
            let mapper = self.live.mapper();
            let version = (mapper.keyframe_graph().keyframes().len() as u64) << 32
                | (self.optimisations & 0xffff_ffff);
            if out.map_due(version, t) {
                // The map copied here (at most every map_interval), rendered by the
                // shells off the loop.
                let map = std::sync::Arc::new(mapper.cls_map().clone());
                out.map(version, t, map, mapper.loop_edges());
            }
        }
        if self.first_scan_after.is_none() {
            self.first_scan_after = Some(now);
        }
        // Ready once the robot has a pose: at the first scan in a new map,
        // once found in a loaded one (or at `ready_after`, see `control`).
        if !self.ready_sent && self.live.mapper().map_search().is_none() {
            info!(after_s = now, "first scan localized; ready");
            self.ready();
        }
        if self.silence_logged {
            info!("scans are back");
            self.silence_logged = false;
        }
        self.sensor_trouble = None;
        self.last_scan_at = Some(now);
        Some(outcome)
    }

    /// `n` scans the sensor produced that the loop never saw.
    pub fn handle_skipped(&mut self, n: u64) {
        self.skipped += n;
    }

    /// The sensor could not be opened or its driver failed (it is tried
    /// again); the status line says so until scans return.
    pub fn handle_sensor_failure(&mut self, error: &str) {
        self.sensor_trouble = Some(error.to_owned());
    }

    /// The clock at `now`: runs the timers that are due. `manual`, when
    /// given, replaces the explorer's command for this control step (the
    /// safety stops still apply).
    pub fn handle_tick(&mut self, now: f64, manual: Option<Twist>) {
        if self.timers.control.fire(now) {
            self.control(now, manual);
        }
        if self.timers.status.fire(now) {
            self.status_tick(now);
        }
        if let Some(timer) = self.timers.checkpoint.as_mut()
            && timer.fire(now)
            && !self.checkpoint_in_flight
        {
            self.checkpoint_due = true;
        }
        if let Some(timer) = self.timers.view.as_mut()
            && timer.fire(now)
        {
            self.take_views(now);
        }
    }

    /// The page asked for something (with the token).
    pub fn handle_control(&mut self, command: ControlCommand, now: f64) {
        match command {
            ControlCommand::Pause => {
                warn!("exploration paused from the live view; the base stops");
                self.paused = true;
                self.base.halt(now);
            }
            ControlCommand::Resume => {
                info!("exploration resumed from the live view");
                self.paused = false;
            }
            ControlCommand::Stop => {
                warn!("STOP from the live view: the base stops, exploration is held");
                self.paused = true;
                self.base.stop(now);
            }
            ControlCommand::Pose(pose) => self.handle_pose_hint(now, pose, "the live view"),
        }
    }

    /// A velocity command from outside (ROS 2 `/cmd_vel`, base frame: m/s
    /// forward and left, rad/s) at `now`. It drives the base through the
    /// same limits and stops when exploration is off, for
    /// [`TELEOP_TIMEOUT`] s; after that the base is halted until the next
    /// (and a search for the robot may turn it again).
    /// With exploration on, the explorer drives and commands are ignored.
    pub fn handle_velocity_command(&mut self, now: f64, twist: Twist) {
        if self.live.explorer().is_some() {
            if self.teleop.is_none() {
                warn!("velocity commands are ignored while exploring");
                self.teleop = Some((f64::NEG_INFINITY, Twist::ZERO));
            }
            return;
        }
        if !(twist.vx.is_finite() && twist.vy.is_finite() && twist.omega.is_finite()) {
            warn!("a velocity command that is not finite is ignored");
            return;
        }
        if self.teleop.is_none() {
            info!("driven by velocity commands (/cmd_vel)");
        }
        self.teleop = Some((now, twist));
    }

    /// The command teleoperation gives now, if a fresh one drives; once
    /// it is older than [`TELEOP_TIMEOUT`] the base is halted (by
    /// `control`) and left to whatever else drives it.
    fn teleop_command(&self, now: f64) -> Option<Twist> {
        if self.live.explorer().is_some() {
            return None;
        }
        let (at, twist) = self.teleop?;
        (now - at <= TELEOP_TIMEOUT).then_some(twist)
    }

    /// Odometry and health from the base, and its pose hint if it sent one.
    fn poll_base(&mut self, now: f64) {
        self.base.poll(now, &mut self.live);
        if let Some(pose) = self.base.take_pose_hint() {
            self.handle_pose_hint(now, pose, "the base link");
        }
    }

    /// A pose hint (map frame) from `from` at `now`: the search for the
    /// robot in the loaded map starts again from it.
    pub fn handle_pose_hint(&mut self, now: f64, pose: Pose2, from: &str) {
        // A bridge that repeats its hint must not restart the search on
        // every line: the same pose again, soon after, is the same hint.
        if let Some((last, at)) = self.last_hint.as_mut()
            && *last == pose
            && now - *at <= REPEATED_HINT
        {
            *at = now;
            debug!("pose hint from {from} repeated; already taken");
            return;
        }
        self.last_hint = Some((pose, now));
        match self.live.hint_pose(now, pose) {
            Ok(()) => {
                info!(
                    x = pose.x,
                    y = pose.y,
                    theta = pose.theta,
                    "pose hint from {from}: looking for the robot there"
                );
                // A new search: the base may turn and drive for it again.
                self.reset_search();
            }
            Err(e) => warn!("pose hint from {from} refused: {e}"),
        }
    }

    fn sensor_state(&self, now: f64) -> String {
        match (&self.sensor_trouble, self.sensor_ok(now)) {
            (_, true) => "streaming".to_string(),
            (Some(why), false) => format!("SENSOR FAILING ({why})"),
            (None, false) if self.last_scan_at.is_none() => "waiting for the sensor".to_string(),
            (None, false) => "SENSOR SILENT".to_string(),
        }
    }

    /// Snapshots for the live view: the panel's every time, the map's when
    /// it changed (at most every [`MAP_VIEW_EVERY`]).
    fn take_views(&mut self, now: f64) {
        let status = self.live_status();
        let key = MapKey {
            keyframes: status.keyframes,
            walls: status.walls,
            frontiers: status.frontiers,
            loops: status.loops_closed,
            optimisations: self.optimisations,
            path: self.live.picture_path().len(),
        };
        if self.map_key != Some(key) && now - self.last_map_view >= MAP_VIEW_EVERY {
            self.map_key = Some(key);
            self.map_version += 1;
            self.last_map_view = now;
            let contents = std::sync::Arc::new(self.live.mapper().contents());
            let path = self.live.picture_path().copied();
            self.map_view_due = Some(MapView::from_contents(self.map_version, contents, path));
        }
        let rate =
            (status.scans - self.scans_at_last_view) as f64 / (now - self.last_view_t).max(1e-3);
        self.scans_at_last_view = status.scans;
        self.last_view_t = now;
        let explorer = self.live.explorer();
        let command = self.base.last_command();
        self.view_due = Some(LiveView {
            uptime: now,
            sensor: self.sensor_state(now),
            scan_rate: rate,
            scans_skipped: self.skipped,
            odometry_refused: self.base.odometry_refused(),
            base_ok: self.base.can_drive(now, self.live.last_odometry_time()),
            command: [command.vx, command.vy, command.omega],
            covariance: self.live.mapper().last_covariance(),
            goal: explorer.and_then(|e| e.goal()),
            plan: explorer
                .map(|e| e.planned_path().to_vec())
                .unwrap_or_default(),
            paused: self.paused,
            control: self.config.web.token.is_some(),
            latencies: self.live.latencies().summaries(),
            map_version: self.map_version,
            status,
        });
    }

    /// From now on, every scan gives the messages ROS 2 tools expect of
    /// it (the scan, the pose, the odometry, the transforms), for a shell
    /// to take with [`poll_ros2`](Self::poll_ros2). `epoch`: the wall
    /// clock (s since the Unix epoch) at this core's clock's zero.
    pub fn enable_ros2(&mut self, epoch: f64) {
        let units = match self.config.sensor.units.as_str() {
            "cm" => lms200::Units::Cm,
            _ => lms200::Units::Mm,
        };
        self.ros2 = Some(super::ros2_out::Ros2Outbox::new(
            epoch,
            self.config.mapper.laser_mount,
            crate::input::lms200::lms200_reach(units),
            &self.config.ros2,
            self.config.base.adapter != super::config::BaseKind::None,
        ));
    }

    /// The ROS 2 messages of the scans since the last call (none unless
    /// [`enable_ros2`](Self::enable_ros2) was called).
    pub fn poll_ros2(&mut self) -> Vec<super::ros2_out::Stamped> {
        self.ros2.as_mut().map(|o| o.take()).unwrap_or_default()
    }

    /// A snapshot of the loop for the live view's panel.
    pub fn poll_view(&mut self) -> Option<LiveView> {
        self.view_due.take()
    }

    /// A snapshot of the map for the live view, when it changed.
    pub fn poll_map_view(&mut self) -> Option<MapView> {
        self.map_view_due.take()
    }

    fn ready(&mut self) {
        if !self.ready_sent {
            self.ready_sent = true;
            self.ready_due = true;
        }
    }

    /// Polls and commands the base; notes why to stop, if it is time.
    fn control(&mut self, now: f64, manual: Option<Twist>) {
        let _span = info_span!("control").entered();
        if now >= self.config.daemon.ready_after && !self.ready_sent {
            self.ready();
            if self.first_scan_after.is_none() {
                warn!(
                    after_s = now,
                    "no scan yet: ready anyway, still waiting for the sensor"
                );
            } else {
                warn!(
                    after_s = now,
                    "not found in the loaded map yet: ready anyway, still looking"
                );
            }
        }
        self.poll_base(now);
        let sensor_ok = self.sensor_ok(now);
        if !sensor_ok && self.last_scan_at.is_some() && !self.silence_logged {
            warn!(
                silent_s = self.config.sensor.silence_stop,
                "no scan: the base stops until scans return"
            );
            self.silence_logged = true;
        }
        // A robot not (or no longer) found in a loaded map does not
        // explore but turns in place for a while, so its scans see more of
        // the place, then drives a few metres the open way; one paused
        // from the live view is held.
        let last_control = self.last_control_at;
        let searching = self.follow_search(now, sensor_ok);
        let turned = self.search_waiting;
        // Turned for the search without settling it: drive the open way
        // (waiting, LOST, once that is done too).
        let search_drive = if searching && turned && sensor_ok && !self.paused {
            let dt = last_control.map_or(0.0, |t| (now - t).max(0.0));
            let drive = self.search_drive(dt);
            self.search_waiting = drive.is_none();
            drive
        } else {
            None
        };
        let turning =
            searching && !turned && self.config.map.turn_rate > 0.0 || search_drive.is_some();
        let teleop = self.teleop_command(now);
        if teleop.is_none() && self.teleop_driving {
            // A teleop that stopped sending stops the robot.
            self.base.halt(now);
        }
        self.teleop_driving = teleop.is_some();
        let manual = manual.or(teleop);
        let manual = if self.paused {
            self.live.hold_exploration(now);
            Some(Twist::ZERO)
        } else if manual.is_none() && turning {
            self.live.hold_exploration(now);
            Some(search_drive.unwrap_or(Twist {
                vx: 0.0,
                vy: 0.0,
                omega: self.config.map.turn_rate,
            }))
        } else {
            manual
        };
        // The turn ends (found, or out of time): stopped, not left turning
        // when no explorer takes over.
        if self.was_turning && !turning {
            self.base.halt(now);
        }
        self.was_turning = turning;
        self.base.control(
            &mut self.live,
            sensor_ok && (!searching || turning),
            now,
            manual,
        );
        if self.stop.is_none() {
            let limit = self.config.daemon.max_run_time;
            self.stop =
                if self.config.exploration.exit_when_complete && self.live.exploration_complete() {
                    Some(StopReason::ExplorationComplete)
                } else {
                    (limit > 0.0 && now >= limit).then_some(StopReason::TimeLimit)
                };
        }
    }

    /// Follows the search for the robot in a loaded map at `now` (s):
    /// whether one is on. Its time counts while scans come in and the robot
    /// is not paused; after `turn_for` of it the robot waits, stopped.
    fn follow_search(&mut self, now: f64, sensor_ok: bool) -> bool {
        let last = self.last_control_at.replace(now);
        if self.live.mapper().map_search().is_none() {
            self.reset_search();
            return false;
        }
        if sensor_ok && !self.paused {
            self.search_time += last.map_or(0.0, |t| (now - t).max(0.0));
        }
        self.search_waiting = self.search_time >= self.config.map.turn_for;
        true
    }

    /// A new search (or none): the base may turn and drive for it again.
    fn reset_search(&mut self) {
        self.search_time = 0.0;
        self.search_waiting = false;
        self.search_driven = 0.0;
        self.search_leg = None;
        self.search_seek = 0.0;
    }

    /// The velocity (robot frame, heading held) along the open way of the
    /// latest scan (see [`open_way`]), `dt` (s) after the last step; none
    /// once `drive_for` is driven. A leg goes on until the way ahead
    /// closes to [`SEARCH_STOP`]; where no way of at least
    /// [`SEARCH_MIN_LEG`] is open ahead (facing a wall), the base turns
    /// in place until one is, for half a turn in all, then the drive is
    /// over.
    fn search_drive(&mut self, dt: f64) -> Option<Twist> {
        let map = &self.config.map;
        let speed = map.drive_speed.min(self.config.base.max_speed);
        if self.search_driven >= map.drive_for || speed <= 0.0 || self.search_view.is_empty() {
            self.search_leg = None;
            // Done for this search: no later step starts it again.
            self.search_driven = f64::INFINITY;
            return None;
        }
        let radius = self.config.exploration.planner.clearance();
        let ahead = |d: f64| free_run(&self.search_view, radius, d, SEARCH_REACH);
        let leg = match self.search_leg {
            Some(d) if ahead(d) > SEARCH_STOP => d,
            _ => match open_way(&self.search_view, radius, SEARCH_HALF_ANGLE, SEARCH_REACH) {
                Some((d, run)) if run >= SEARCH_MIN_LEG => {
                    info!(
                        direction_deg = d.to_degrees(),
                        open_m = run,
                        "not found by turning: driving the open way"
                    );
                    d
                }
                _ => {
                    self.search_leg = None;
                    let turn = map.turn_rate;
                    if turn > 0.0 && self.search_seek < std::f64::consts::PI / turn {
                        self.search_seek += dt;
                        return Some(Twist {
                            vx: 0.0,
                            vy: 0.0,
                            omega: turn,
                        });
                    }
                    self.search_driven = f64::INFINITY;
                    return None;
                }
            },
        };
        if self.search_leg.is_some() {
            self.search_driven += speed * dt;
        }
        self.search_leg = Some(leg);
        let (s, c) = leg.sin_cos();
        Some(Twist {
            vx: speed * c,
            vy: speed * s,
            omega: 0.0,
        })
    }

    /// The status line's facts per part, for `/diagnostics`: the sensor,
    /// the localization and map, and the base (level 0 OK, 1 WARN, 2
    /// ERROR).
    fn diagnostics(
        &self,
        now: f64,
        status: &LiveStatus,
        rate: f64,
        sensor: &str,
        latency: &str,
    ) -> Vec<crate::ros2::DiagnosticStatus> {
        let kv = |k: &str, v: String| (k.to_string(), v);
        let part = |name: &str, level: u8, message: String, values| crate::ros2::DiagnosticStatus {
            level,
            name: name.into(),
            message,
            hardware_id: String::new(),
            values,
        };
        let sensor_level = if self.sensor_ok(now) {
            0
        } else if self.last_scan_at.is_none() {
            1
        } else {
            2
        };
        let (map_level, map_message) = match status.map_search {
            None => (0, "localized".to_string()),
            Some(crate::pipeline::MapSearch::Finding(n)) => {
                (1, format!("localizing ({n} hypotheses)"))
            }
            Some(crate::pipeline::MapSearch::Lost(n)) => (2, format!("lost ({n} hypotheses)")),
        };
        let base_ok = self.base.can_drive(now, self.live.last_odometry_time());
        let command = self.base.last_command();
        vec![
            part(
                "clsmap: sensor",
                sensor_level,
                sensor.to_string(),
                vec![
                    kv("scan rate (Hz)", format!("{rate:.1}")),
                    kv("scans skipped", self.skipped.to_string()),
                    kv("port", self.config.sensor.port.display().to_string()),
                ],
            ),
            part(
                "clsmap: localization and map",
                map_level,
                map_message,
                vec![
                    kv("scans", status.scans.to_string()),
                    kv("localized", status.localized.to_string()),
                    kv("keyframes", status.keyframes.to_string()),
                    kv("walls", status.walls.to_string()),
                    kv("frontiers", status.frontiers.to_string()),
                    kv("loops closed", status.loops_closed.to_string()),
                    kv("latency µs p50/p99/max", latency.to_string()),
                ],
            ),
            part(
                "clsmap: base",
                if base_ok { 0 } else { 1 },
                if base_ok { "ok" } else { "cannot drive" }.to_string(),
                vec![
                    kv("odometry refused", self.base.odometry_refused().to_string()),
                    kv(
                        "command (vx, vy, ω)",
                        format!("{:.2} {:.2} {:.2}", command.vx, command.vy, command.omega),
                    ),
                ],
            ),
        ]
    }

    /// The mapper's status; a search for the robot that has run longer
    /// than the base may turn for it counts as lost (the robot waits,
    /// stopped, until a scan or a pose hint settles it).
    fn live_status(&self) -> LiveStatus {
        let mut status = self.live.status();
        if self.search_waiting
            && let Some(MapSearch::Finding(n)) = status.map_search
        {
            status.map_search = Some(MapSearch::Lost(n));
        }
        status
    }

    fn status_tick(&mut self, now: f64) {
        let status = self.live_status();
        let rate = (status.scans - self.scans_at_last_status) as f64
            / (now - self.last_status_t).max(1e-3);
        self.scans_at_last_status = status.scans;
        self.last_status_t = now;
        let sensor = self.sensor_state(now);
        let line = status_line(&status, rate, &sensor);
        info!(skipped = self.skipped, "{line}");
        let latency = self.live.latencies().line();
        if !latency.is_empty() {
            info!("latency µs p50/p99/max: {latency}");
        }
        if self.ros2.is_some() {
            let parts = self.diagnostics(now, &status, rate, &sensor, &latency);
            if let Some(out) = self.ros2.as_mut() {
                out.diagnostics(now, parts);
            }
        }
        self.status_due = Some(line);
    }

    /// When (s) the core next needs [`handle_tick`](Self::handle_tick).
    pub fn poll_timeout(&self) -> f64 {
        let t = &self.timers;
        let checkpoint = t.checkpoint.map_or(f64::INFINITY, |c| c.next);
        let view = t.view.map_or(f64::INFINITY, |v| v.next);
        t.control.next.min(t.status.next).min(checkpoint).min(view)
    }

    /// True once: time to tell systemd the daemon is ready (the first
    /// scan, or `ready_after` without one).
    pub fn poll_ready(&mut self) -> bool {
        std::mem::take(&mut self.ready_due)
    }

    /// A status line to publish (`STATUS=`), every `status_interval`.
    pub fn poll_status(&mut self) -> Option<String> {
        self.status_due.take()
    }

    /// Why the loop should end, once it should.
    pub fn poll_stop(&self) -> Option<StopReason> {
        self.stop
    }

    /// Whether a checkpoint is due; the shell then picks the directory and
    /// calls [`begin_checkpoint`](Self::begin_checkpoint). Nothing is due
    /// before the first scan.
    pub fn poll_checkpoint(&mut self) -> bool {
        std::mem::take(&mut self.checkpoint_due) && self.live.scans() > 0
    }

    /// A snapshot to write into `dir`; its result goes to
    /// [`handle_checkpoint_done`](Self::handle_checkpoint_done).
    pub fn begin_checkpoint(&mut self, dir: &std::path::Path) -> Checkpoint {
        self.checkpoint_in_flight = true;
        self.live.begin_checkpoint(dir)
    }

    /// A checkpoint was written, or not (its poses are taken back and go
    /// with the next one; the error is returned for the log).
    pub fn handle_checkpoint_done(
        &mut self,
        result: Result<(), CheckpointFailed>,
    ) -> Result<(), PipelineError> {
        self.checkpoint_in_flight = false;
        result.map_err(|failed| self.live.checkpoint_failed(failed))
    }

    /// A checkpoint's writer died (a panic): its poses are gone, the next
    /// checkpoint goes ahead.
    pub fn handle_checkpoint_lost(&mut self) {
        self.checkpoint_in_flight = false;
    }

    /// A loop-closure optimisation to run off the loop, when one is ready
    /// and none is running; its result goes to
    /// [`handle_optimisation_done`](Self::handle_optimisation_done).
    pub fn poll_optimisation(&mut self) -> Option<OptimisationJob> {
        if self.optimisation_in_flight {
            return None;
        }
        let job = self.live.take_optimisation()?;
        self.optimisation_in_flight = true;
        Some(job)
    }

    /// The newest keyframe's loop search, to run off the loop, when one is
    /// wanted and none is running; its result goes to
    /// [`handle_loop_search_done`](Self::handle_loop_search_done).
    pub fn poll_loop_search(&mut self) -> Option<LoopSearchJob> {
        self.live.take_loop_search()
    }

    /// A loop search's result, or `None` when its thread failed.
    pub fn handle_loop_search_done(&mut self, result: Option<LoopSearchResult>) {
        match result {
            Some(result) => self.live.apply_loop_search(result),
            None => self.live.abandon_loop_search(),
        }
    }

    /// An optimisation's result, or `None` when its thread failed (the job
    /// is abandoned, so the next one takes its loops in).
    pub fn handle_optimisation_done(&mut self, result: Option<OptimisationResult>) {
        self.optimisation_in_flight = false;
        match result {
            Some(result) => {
                self.optimisations += 1;
                self.live.apply_optimisation(result);
            }
            None => self.live.abandon_optimisation(),
        }
    }

    /// A reloaded configuration (SIGHUP): the tunables take effect, the
    /// rest is named in a warning as needing a restart.
    pub fn handle_reload(&mut self, new: DaemonConfig, now: f64, from: &std::path::Path) {
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
            ("web", new.web != old.web),
            ("map", new.map != old.map),
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
            info!(path = %from.display(), "configuration reloaded");
        } else {
            warn!(
                path = %from.display(),
                "configuration reloaded; these changes need a restart and are not applied: {}",
                restart.join(", ")
            );
        }
    }

    /// Stops the base for good at `now` (shutdown, or a test's stop).
    pub fn stop_base(&mut self, now: f64) {
        self.base.stop(now);
    }

    /// The end of a run: the last optimisation and rebuild, before the
    /// last save.
    pub fn finish(&mut self) {
        self.live.settle();
    }

    /// Writes a checkpoint into `dir` now, on this thread (the last save,
    /// a rescue, a test).
    pub fn checkpoint(&mut self, dir: &std::path::Path) -> Result<(), PipelineError> {
        self.live.checkpoint(dir)
    }

    pub fn status(&self) -> LiveStatus {
        self.live_status()
    }
}

/// The status line of the log and `STATUS=`.
pub fn status_line(s: &LiveStatus, rate: f64, sensor: &str) -> String {
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
        Some(MapSearch::Finding(n)) => {
            format!("localizing in the loaded map ({n} hypotheses)")
        }
        Some(MapSearch::Lost(n)) => {
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

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::geometry::Pose2;

    /// A core with no base and no sensor, from the daemon's TOML.
    fn core(toml: &str) -> Core {
        let config = DaemonConfig::from_toml(toml).unwrap();
        let live = LiveMapper::new(config.mapper, None, 0.0);
        let base = BaseDriver::new(None, config.base.limits(), 0.5, 1.0, 8.0);
        Core::new(config, live, base)
    }

    #[test]
    fn a_velocity_command_drives_for_half_a_second_then_the_base_stops() {
        let mut c = core("");
        assert_eq!(c.teleop_command(0.0), None, "no teleop: nothing changes");
        let t = Twist {
            vx: 0.3,
            vy: -0.1,
            omega: 0.2,
        };
        c.handle_velocity_command(1.0, t);
        assert_eq!(c.teleop_command(1.0 + TELEOP_TIMEOUT), Some(t));
        assert_eq!(
            c.teleop_command(1.01 + TELEOP_TIMEOUT),
            None,
            "stale: no longer drives"
        );
        c.handle_velocity_command(3.0, Twist { vx: f64::NAN, ..t });
        assert_eq!(c.teleop_command(3.0), None, "not finite: ignored");
    }

    #[test]
    fn without_scans_ready_comes_once_after_ready_after() {
        let mut c = core("[daemon]\nready_after = 2.0\n");
        c.handle_tick(0.0, None);
        assert!(!c.poll_ready());
        c.handle_tick(1.9, None);
        assert!(!c.poll_ready());
        c.handle_tick(2.05, None);
        assert!(c.poll_ready(), "READY once ready_after has passed");
        c.handle_tick(2.5, None);
        assert!(!c.poll_ready(), "READY is sent once");
    }

    #[test]
    fn the_status_line_comes_every_status_interval_and_names_a_silent_sensor() {
        let mut c = core("[daemon]\nstatus_interval = 1.0\n");
        c.handle_tick(0.0, None);
        let first = c.poll_status().unwrap();
        assert!(first.starts_with("waiting for the sensor"), "{first}");
        c.handle_tick(0.5, None);
        assert!(c.poll_status().is_none());
        c.handle_sensor_failure("cannot open /dev/lms200");
        c.handle_tick(1.0, None);
        let line = c.poll_status().unwrap();
        assert!(
            line.contains("SENSOR FAILING (cannot open /dev/lms200)"),
            "{line}"
        );
    }

    #[test]
    fn the_time_limit_stops_the_loop_and_no_checkpoint_comes_before_a_scan() {
        let mut c = core("[daemon]\nmax_run_time = 3.0\ncheckpoint_interval = 1.0\n");
        let mut t = 0.0;
        while c.poll_stop().is_none() && t < 10.0 {
            c.handle_tick(t, None);
            assert!(
                !c.poll_checkpoint(),
                "nothing to save before the first scan"
            );
            t = c.poll_timeout();
        }
        assert_eq!(c.poll_stop(), Some(StopReason::TimeLimit));
        assert!((3.0..3.2).contains(&t), "stopped at {t} s");
    }

    #[test]
    fn the_next_timeout_is_the_earliest_timer() {
        let mut c = core("[base]\nrate = 20.0\n[daemon]\nstatus_interval = 5.0\n");
        assert_eq!(c.poll_timeout(), 0.0);
        c.handle_tick(0.0, None);
        assert!((c.poll_timeout() - 0.05).abs() < 1e-12);
    }

    #[test]
    fn a_timer_skips_the_ticks_a_busy_loop_missed() {
        let mut t = Timer::new(0.0, 0.1);
        assert!(t.fire(0.0));
        assert!(!t.fire(0.05));
        assert!(t.fire(0.35));
        // Due next at 0.4, not at 0.2 and 0.3 as well.
        assert!(!t.fire(0.39));
        assert!(t.fire(0.4));
    }

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
