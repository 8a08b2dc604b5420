//! [`DaemonConfig`]: the TOML file `clsmap run --config FILE` reads.
//!
//! Every key, its default and its unit is documented in
//! `config/clsmap.toml` (a test keeps that file equal to the defaults).
//! Unknown keys and wrong types are refused by serde with the line and
//! column; values out of range are refused by [`DaemonConfig::validate`]
//! with the key and, when the file names it, its line.

use std::path::{Path, PathBuf};

use clsmap_base::Limits;
use lms200::link::LinkConfig;
use lms200::{Baud, Units, Variant};
use serde::{Deserialize, Serialize};

use crate::explore::{DriveConfig, ExplorationConfig};
use crate::geometry::Pose2;
use crate::pipeline::config::{MapperConfig, Rule, line_of_key};

/// Everything the daemon needs.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DaemonConfig {
    pub sensor: SensorConfig,
    pub base: BaseConfig,
    pub sim: SimConfig,
    pub exploration: ExplorationSection,
    pub daemon: LoopConfig,
    pub map: MapSection,
    pub web: WebSection,
    pub ros2: Ros2Section,
    pub mapper: MapperConfig,
}

/// `[ros2]`: a ROS 2 node on DDS (pure Rust, no ROS installation) that
/// publishes what the daemon's bag holds: /scan, /pose, /odom, /tf,
/// /tf_static, /map, /cls_map and /diagnostics, and listens to /cmd_vel
/// and /initialpose (frames after REP 105, named here).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Ros2Section {
    /// Publish (default false on a robot: DDS discovery goes to every
    /// network the robot is on).
    pub enabled: bool,
    /// DDS domain, as `ROS_DOMAIN_ID` (0–232; default 0).
    pub domain_id: u16,
    /// DDS on this machine only (as `ROS_LOCALHOST_ONLY=1`): discovery
    /// and data go over the loopback interface (default false).
    pub localhost_only: bool,
    /// Namespace of the node and its topics (default "": `/scan`, …;
    /// "/robot1" gives `/robot1/scan`, …).
    pub namespace: String,
    /// The node's name (default "clsmap").
    pub node_name: String,
    /// The frames of REP 105: the map, the odometry, the robot and the
    /// laser (defaults "map", "odom", "base_link", "laser").
    pub map_frame: String,
    pub odom_frame: String,
    pub base_frame: String,
    pub laser_frame: String,
    /// `/map` is sent at most this often (s; default 5), when the map
    /// changed.
    pub map_interval: f64,
    /// Cell side of `/map` (m; default 0.05), coarsened (doubled) until
    /// the grid has at most 2 million cells.
    pub map_resolution: f64,
}

impl Default for Ros2Section {
    fn default() -> Self {
        Ros2Section {
            enabled: false,
            domain_id: 0,
            localhost_only: false,
            namespace: String::new(),
            node_name: "clsmap".into(),
            map_frame: "map".into(),
            odom_frame: "odom".into(),
            base_frame: "base_link".into(),
            laser_frame: "laser".into(),
            map_interval: 5.0,
            map_resolution: 0.05,
        }
    }
}

/// `[web]`: the live view in a browser, served by the daemon.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WebSection {
    /// Serve the live view (default false on a robot; `clsmap demo` turns
    /// it on).
    pub enabled: bool,
    /// Address and port to listen on. Default `"127.0.0.1:8080"`, this
    /// machine only; another address (`"0.0.0.0:8080"`: every network the
    /// robot is on) shows the robot's map and pose to whoever reaches it.
    pub bind: String,
    /// Pause, resume and stop the base from the page, only with this token
    /// (sent as `Authorization: Bearer …`; at least 16 characters).
    /// Default: none, and then nothing on the page changes anything.
    pub token: Option<String>,
    /// Requests served at once, live streams included (default 8); more
    /// are refused (503) rather than queued.
    pub max_clients: usize,
    /// Updates pushed to the page per second (default 2).
    pub rate: f64,
}

impl Default for WebSection {
    fn default() -> Self {
        WebSection {
            enabled: false,
            bind: "127.0.0.1:8080".into(),
            token: None,
            max_clients: 8,
            rate: 2.0,
        }
    }
}

impl WebSection {
    /// The bind address, once checked by [`DaemonConfig::validate`].
    pub fn address(&self) -> Option<std::net::SocketAddr> {
        self.bind.parse().ok()
    }
}

/// `[map]`: start from a saved map instead of a new one.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MapSection {
    /// A `map.json` to start from (default: none, a new map). It is never
    /// written: the run writes its own directory as always.
    pub load: Option<PathBuf>,
    /// `"localize"` (the map is not changed) or `"extend"` (new keyframes
    /// join it, loops close against it). Default `"localize"`.
    pub mode: String,
    /// When `load` cannot be read or is not a valid map: `"refuse"` (exit
    /// with the reason; a robot silently starting a fresh map in a mapped
    /// building is the worse failure) or `"new"` (warn, start a new map).
    /// Default `"refuse"`.
    pub on_bad_map: String,
    /// While the robot is looked for in the loaded map (at the start,
    /// after it was lost, after a pose hint), the base turns in place at
    /// this rate (rad/s), so the scans see more of the place and tell
    /// look-alike places apart; 0 = it stands still. Default 0.3.
    pub turn_rate: f64,
    /// Longest time (s) one search runs with scans coming in (not paused)
    /// while the base turns for it; then it drives (`drive_for`), stops
    /// and waits (status LOST) until a scan or a pose hint settles it. With `turn_rate = 0` the
    /// base stands still and the status turns LOST after this long; with 0
    /// here it never turns. Default 30 (a turn and a half at 0.3 rad/s).
    pub turn_for: f64,
    /// After `turn_for`, a search still unsettled (two stretches of a
    /// corridor that look the same within the sensor's reach) drives this
    /// far (m) at most, heading held, along the most open way its scan
    /// shows ahead (legs of at least 1 m, stopped 0.3 m short of what is
    /// in the way), so the scans reach what tells the places apart; then
    /// the base stops and the status says LOST. 0 = it never drives.
    /// Default 4.
    pub drive_for: f64,
    /// Speed (m/s) of that drive, at most `[base] max_speed`. Default 0.2.
    pub drive_speed: f64,
    /// Load `load` even when its checksum does not match (a map edited by
    /// hand), with a warning; every other check still applies. Default
    /// false: a damaged map is refused.
    pub ignore_checksum: bool,
}

impl Default for MapSection {
    fn default() -> Self {
        MapSection {
            load: None,
            mode: "localize".into(),
            on_bad_map: "refuse".into(),
            turn_rate: 0.3,
            turn_for: 30.0,
            drive_for: 4.0,
            drive_speed: 0.2,
            ignore_checksum: false,
        }
    }
}

impl MapSection {
    /// The mode, once checked by [`DaemonConfig::validate`].
    pub fn mode(&self) -> Option<crate::pipeline::MapMode> {
        self.mode.parse().ok()
    }

    /// How `load`'s checksum is checked.
    pub fn checksum_check(&self) -> crate::map::file::ChecksumCheck {
        crate::map::file::ChecksumCheck::ignoring(self.ignore_checksum)
    }

    /// Whether a bad map falls back to a new one.
    pub fn new_on_bad_map(&self) -> bool {
        self.on_bad_map == "new"
    }
}

/// Where the scans come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SensorSource {
    /// A real LMS200 on `port`.
    Serial,
    /// The built-in LMS200 emulator on a pseudo-terminal, measuring the
    /// `[sim]` world from the simulated robot (needs `base.adapter = "sim"`).
    Emulator,
}

/// `[sensor]`: the LMS200 and its serial line.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorConfig {
    pub source: SensorSource,
    /// Serial device (default /dev/lms200, the udev rule's name).
    pub port: PathBuf,
    /// Line speed while streaming (Bd): 9600, 19200, 38400 or 500000
    /// (default 500000: the only speed that carries every scan, 37.5 scans/s
    /// at 180°/0.5° and 75 at 180°/1°; RS-422 only).
    pub baud: u32,
    /// Field of view (deg): 100 or 180 (default 180).
    pub field_of_view: u16,
    /// Angular resolution (deg): 0.25 (100° only), 0.5 or 1 (default 0.5).
    pub resolution: f64,
    /// Range units: "mm" (8.183 m range, default) or "cm" (81.83 m).
    pub units: String,
    /// No scan for this long (s) stops the base until scans return
    /// (default 0.5 s: about 19 missed scans at 180°/0.5°).
    pub silence_stop: f64,
    /// First and longest wait (s) before opening the port again after it
    /// failed (unplugged, busy); the wait doubles in between (default 1 s
    /// and 30 s).
    pub retry_initial: f64,
    pub retry_max: f64,
    /// Record the raw telegram stream here, with the base's odometry
    /// samples, so `clsmap map` replays the run as it went (a new file per
    /// connection; an existing one is never overwritten). Default: no
    /// recording.
    pub record: Option<PathBuf>,
}

impl Default for SensorConfig {
    fn default() -> Self {
        SensorConfig {
            source: SensorSource::Serial,
            port: PathBuf::from("/dev/lms200"),
            baud: 500_000,
            field_of_view: 180,
            resolution: 0.5,
            units: "mm".into(),
            silence_stop: 0.5,
            retry_initial: 1.0,
            retry_max: 30.0,
            record: None,
        }
    }
}

/// Which base adapter drives the robot.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BaseKind {
    /// The simulated holonomic base of `[sim]`.
    Sim,
    /// A real base bridged by the line protocol over TCP (`address`).
    Tcp,
    /// A real base bridged by the line protocol over a serial port.
    Serial,
    /// A base driven by its own ROS 2 driver: odometry from its
    /// `odom_topic`, commands to its `cmd_vel_topic`.
    Ros2,
    /// Odometry replayed from a recording or CARMEN log (`replay`); the
    /// robot cannot be driven.
    Replay,
    /// No base: no odometry, no motion; mapping from scans alone.
    None,
}

/// `[base]`: the mobile base and its limits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BaseConfig {
    pub adapter: BaseKind,
    /// `tcp`: host:port of the bridge (default 127.0.0.1:7300).
    pub address: String,
    /// `serial`: device and line speed of the bridge (default
    /// /dev/xr4000, 115200 Bd).
    pub port: PathBuf,
    pub baud: u32,
    /// `ros2`: the base driver's odometry (nav_msgs/Odometry) and command
    /// (geometry_msgs/Twist) topics (defaults /odom, /cmd_vel).
    pub odom_topic: String,
    pub cmd_vel_topic: String,
    /// `ros2`: odometry from `/tf` instead (the transform `[ros2]
    /// odom_frame` → `base_frame`), for a driver that publishes only that
    /// (default false).
    pub odom_from_tf: bool,
    /// `replay`: the recording or CARMEN log whose odometry is played.
    pub replay: Option<PathBuf>,
    /// Odometry polls and velocity commands per second (default 50 Hz).
    pub rate: f64,
    /// Odometry older than this (s) stops the base (default 0.5 s).
    pub stale_odometry: f64,
    /// Speed and acceleration limits applied to every command (m/s, rad/s,
    /// m/s², rad/s²; defaults: conservative XR4000 assumptions).
    pub max_speed: f64,
    pub max_turn_rate: f64,
    pub max_acceleration: f64,
    pub max_angular_acceleration: f64,
}

impl Default for BaseConfig {
    fn default() -> Self {
        let limits = Limits::default();
        BaseConfig {
            adapter: BaseKind::None,
            address: "127.0.0.1:7300".into(),
            port: PathBuf::from("/dev/xr4000"),
            baud: 115_200,
            odom_topic: "/odom".into(),
            cmd_vel_topic: "/cmd_vel".into(),
            odom_from_tf: false,
            replay: None,
            rate: 50.0,
            stale_odometry: 0.5,
            max_speed: limits.max_linear,
            max_turn_rate: limits.max_angular,
            max_acceleration: limits.max_linear_accel,
            max_angular_acceleration: limits.max_angular_accel,
        }
    }
}

impl BaseConfig {
    pub fn limits(&self) -> Limits {
        Limits {
            max_linear: self.max_speed,
            max_angular: self.max_turn_rate,
            max_linear_accel: self.max_acceleration,
            max_angular_accel: self.max_angular_acceleration,
        }
    }
}

/// `[sim]`: the simulated world, robot and sensor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimConfig {
    /// A built-in world ("loop", "room", "corridor", "lab", "office") or
    /// the path of a world file (default "loop").
    pub world: String,
    /// Where the robot starts (world frame, m and rad); default: the
    /// world's own start.
    pub start: Option<Pose2>,
    /// Range noise of the emulated LMS200 (m; default 0.01, its σ).
    pub range_sigma: f64,
    /// Odometry scale error (fraction of distance; default 0.02).
    pub odometry_scale_error: f64,
    /// Odometry heading drift (rad per metre; default 0.01).
    pub odometry_heading_drift: f64,
    /// Seed of the range noise (default 7).
    pub seed: u64,
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            world: "loop".into(),
            start: None,
            range_sigma: 0.01,
            odometry_scale_error: 0.02,
            odometry_heading_drift: 0.01,
            seed: 7,
        }
    }
}

/// `[exploration]`: Virtual Line Segment Pursuit.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExplorationSection {
    /// Drive the base to frontiers (default false: map where the robot is
    /// driven by someone else).
    pub enabled: bool,
    /// Save the map and exit 0 once exploration is complete (default
    /// false: keep localizing and mapping).
    pub exit_when_complete: bool,
    /// `[exploration.planner]`: frontier choice and clearance.
    pub planner: ExplorationConfig,
    /// `[exploration.drive]`: path following.
    pub drive: DriveConfig,
}

/// `[daemon]`: state, checkpoints, reporting.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LoopConfig {
    /// Where maps go; each run writes into a new `run-<UTC time>`
    /// directory below it, so no earlier map is ever overwritten. Default:
    /// `$STATE_DIRECTORY` (set by systemd's `StateDirectory=`), else
    /// `./clsmap-state`.
    pub state_dir: Option<PathBuf>,
    /// Seconds between map checkpoints (default 30 s; 0 = only at exit).
    pub checkpoint_interval: f64,
    /// Seconds between status lines in the log (default 10 s).
    pub status_interval: f64,
    /// Stop after this many seconds, saving the map (default 0 = never).
    pub max_run_time: f64,
    /// systemd hears READY=1 at the first scan (in a loaded map, once the
    /// robot is found in it), or after this many seconds without (default
    /// 10 s). The start counts as complete only at
    /// READY, and boot waits for it (multi-user.target is ordered after
    /// the units it wants): a sensor switched off must not hold up the
    /// robot's boot. The daemon then goes on waiting for the sensor and
    /// says so in STATUS=.
    pub ready_after: f64,
    /// Write a rosbag2 MCAP bag of the run, `run.mcap` in the run's
    /// directory: /scan, /pose, /odom, /tf, /tf_static, /map and
    /// /diagnostics, as ROS 2 tools
    /// (Foxglove, `ros2 bag play`, RViz) read them (default false).
    pub bag: bool,
}

impl Default for LoopConfig {
    fn default() -> Self {
        LoopConfig {
            state_dir: None,
            checkpoint_interval: 30.0,
            status_interval: 10.0,
            max_run_time: 0.0,
            ready_after: 10.0,
            bag: false,
        }
    }
}

/// Why a configuration was refused.
#[derive(Debug, thiserror::Error)]
pub enum DaemonConfigError {
    #[error("cannot read {path}")]
    Read {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Not TOML, an unknown key, a wrong type: toml's message names the
    /// line and column.
    #[error("{0}")]
    Syntax(#[from] toml::de::Error),
    #[error("{key}{}: {value} is out of range (must be {rule})", line.map(|l| format!(" (line {l})")).unwrap_or_default())]
    Range {
        key: String,
        line: Option<usize>,
        value: String,
        rule: String,
    },
    #[error("{key}{}: {reason}", line.map(|l| format!(" (line {l})")).unwrap_or_default())]
    Invalid {
        key: String,
        line: Option<usize>,
        reason: String,
    },
}

impl DaemonConfig {
    /// Reads and checks a configuration file.
    pub fn load(path: &Path) -> Result<DaemonConfig, DaemonConfigError> {
        let text =
            crate::files::durable::read_bounded(path, crate::files::durable::MAX_CONFIG_BYTES)
                .map_err(|source| DaemonConfigError::Read {
                    path: path.to_owned(),
                    source,
                })?;
        DaemonConfig::from_toml(&text)
    }

    /// Parses and checks a TOML document.
    pub fn from_toml(text: &str) -> Result<DaemonConfig, DaemonConfigError> {
        let config: DaemonConfig = toml::from_str(text)?;
        config.validate(Some(text))?;
        Ok(config)
    }

    /// Checks every value; `source`, the TOML text, lets errors name lines.
    pub fn validate(&self, source: Option<&str>) -> Result<(), DaemonConfigError> {
        let locate = |key: &str| source.and_then(|text| line_of_key(text, key));
        let range = |key: &str, value: String, rule: &str| DaemonConfigError::Range {
            key: key.to_string(),
            line: locate(key),
            value,
            rule: rule.to_string(),
        };
        // The mapper's rules, so both files say the same of a number.
        let within = |key: &str, v: f64, lo: f64, hi: f64| {
            let rule = Rule::Within(lo, hi);
            if rule.holds(v) {
                Ok(())
            } else {
                Err(range(key, v.to_string(), &rule.text()))
            }
        };
        let s = &self.sensor;
        if Baud::from_bits_per_second(s.baud).is_none() {
            return Err(range(
                "sensor.baud",
                s.baud.to_string(),
                "9600, 19200, 38400 or 500000",
            ));
        }
        if self.variant().is_none() {
            return Err(DaemonConfigError::Invalid {
                key: "sensor.resolution".into(),
                line: locate("sensor.resolution").or_else(|| locate("sensor.field_of_view")),
                reason: format!(
                    "{}° at {}° is not an LMS200 variant (180° at 0.5° or 1°, 100° at 0.25°, 0.5° or 1°)",
                    s.field_of_view, s.resolution
                ),
            });
        }
        if self.units().is_none() {
            return Err(range(
                "sensor.units",
                format!("{:?}", s.units),
                "\"mm\" or \"cm\"",
            ));
        }
        // Ranges: beyond them a value is a typo, not a choice (and some
        // would overflow a timer).
        within("sensor.silence_stop", s.silence_stop, 0.05, 60.0)?;
        within("sensor.retry_initial", s.retry_initial, 0.01, 3600.0)?;
        within("sensor.retry_max", s.retry_max, s.retry_initial, 3600.0)?;
        let b = &self.base;
        within("base.rate", b.rate, 2.0, 1000.0)?;
        within("base.stale_odometry", b.stale_odometry, 0.01, 10.0)?;
        within("base.max_speed", b.max_speed, 1e-3, 5.0)?;
        within("base.max_turn_rate", b.max_turn_rate, 1e-3, 10.0)?;
        within("base.max_acceleration", b.max_acceleration, 1e-3, 20.0)?;
        within(
            "base.max_angular_acceleration",
            b.max_angular_acceleration,
            1e-3,
            50.0,
        )?;
        if self.map.mode().is_none() {
            return Err(range(
                "map.mode",
                format!("{:?}", self.map.mode),
                "\"localize\" or \"extend\"",
            ));
        }
        // Faster than the base allows is cut to its limit, like any command.
        within("map.turn_rate", self.map.turn_rate, 0.0, 10.0)?;
        within("map.turn_for", self.map.turn_for, 0.0, 3600.0)?;
        within("map.drive_for", self.map.drive_for, 0.0, 100.0)?;
        within("map.drive_speed", self.map.drive_speed, 0.0, 2.0)?;
        if !matches!(self.map.on_bad_map.as_str(), "refuse" | "new") {
            return Err(range(
                "map.on_bad_map",
                format!("{:?}", self.map.on_bad_map),
                "\"refuse\" or \"new\"",
            ));
        }
        if b.baud == 0 {
            return Err(range("base.baud", "0".into(), "> 0"));
        }
        let w = &self.web;
        if w.address().is_none() {
            return Err(DaemonConfigError::Invalid {
                key: "web.bind".into(),
                line: locate("web.bind"),
                reason: format!(
                    "{:?} is not an address and port such as \"127.0.0.1:8080\"",
                    w.bind
                ),
            });
        }
        if w.token.as_ref().is_some_and(|t| t.chars().count() < 16) {
            return Err(range(
                "web.token",
                "(hidden)".into(),
                "at least 16 characters",
            ));
        }
        if !(1..=256).contains(&w.max_clients) {
            return Err(range(
                "web.max_clients",
                w.max_clients.to_string(),
                "in [1, 256]",
            ));
        }
        within("web.rate", w.rate, 0.1, 10.0)?;
        let host_port = b.address.rsplit_once(':').is_some_and(|(host, port)| {
            !host.is_empty() && port.parse::<u16>().is_ok_and(|p| p > 0)
        });
        if b.adapter == BaseKind::Tcp && !host_port {
            return Err(DaemonConfigError::Invalid {
                key: "base.address".into(),
                line: locate("base.address"),
                reason: format!(
                    "{:?} is not a host and port such as \"192.168.1.20:7300\"",
                    b.address
                ),
            });
        }
        if b.adapter == BaseKind::Replay && b.replay.is_none() {
            return Err(DaemonConfigError::Invalid {
                key: "base.replay".into(),
                line: locate("base.adapter"),
                reason: "the replay adapter needs the log to replay".into(),
            });
        }
        if s.source == SensorSource::Emulator && b.adapter != BaseKind::Sim {
            return Err(DaemonConfigError::Invalid {
                key: "sensor.source".into(),
                line: locate("sensor.source"),
                reason:
                    "the emulated sensor rides on the simulated robot: set base.adapter = \"sim\""
                        .into(),
            });
        }
        let m = &self.sim;
        within("sim.range_sigma", m.range_sigma, 0.0, 1.0)?;
        if !m.odometry_scale_error.is_finite() || m.odometry_scale_error.abs() >= 0.5 {
            return Err(range(
                "sim.odometry_scale_error",
                m.odometry_scale_error.to_string(),
                "in (-0.5, 0.5)",
            ));
        }
        // rad per metre: a tenth of a turn per metre is no base.
        within(
            "sim.odometry_heading_drift",
            m.odometry_heading_drift,
            -0.6,
            0.6,
        )?;
        if let Some(p) = m.start
            && ![p.x, p.y, p.theta].iter().all(|v| v.is_finite())
        {
            return Err(range("sim.start", format!("{p:?}"), "finite"));
        }
        let e = &self.exploration;
        if !e.planner.is_valid() {
            return Err(DaemonConfigError::Invalid {
                key: "exploration.planner".into(),
                line: locate("exploration.planner"),
                reason: "every length must be finite and >= 0, robot_radius and goal_standoff > 0"
                    .into(),
            });
        }
        if !e.drive.is_valid() {
            return Err(DaemonConfigError::Invalid {
                key: "exploration.drive".into(),
                line: locate("exploration.drive"),
                reason: "speeds, gains and timeout_factor must be > 0, the rest finite and >= 0"
                    .into(),
            });
        }
        if e.enabled && matches!(b.adapter, BaseKind::Replay | BaseKind::None) {
            return Err(DaemonConfigError::Invalid {
                key: "exploration.enabled".into(),
                line: locate("exploration.enabled"),
                reason: format!(
                    "exploring needs a base that can be driven, not {:?}",
                    b.adapter
                ),
            });
        }
        let d = &self.daemon;
        if d.checkpoint_interval != 0.0 {
            within(
                "daemon.checkpoint_interval",
                d.checkpoint_interval,
                1.0,
                86_400.0,
            )?;
        }
        within("daemon.status_interval", d.status_interval, 0.1, 86_400.0)?;
        within("daemon.max_run_time", d.max_run_time, 0.0, 1e9)?;
        within("daemon.ready_after", d.ready_after, 0.0, 600.0)?;
        let r = &self.ros2;
        within("ros2.domain_id", f64::from(r.domain_id), 0.0, 232.0)?;
        if r.enabled && !cfg!(feature = "dds") {
            return Err(DaemonConfigError::Invalid {
                key: "ros2.enabled".into(),
                line: locate("ros2.enabled"),
                reason: "this build has no ROS 2 node (built without the `dds` feature)".into(),
            });
        }
        let name_ok = |s: &str, allow_slash: bool| {
            s.chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || (allow_slash && c == '/'))
        };
        let ns_ok = r.namespace.is_empty()
            || (r.namespace.starts_with('/')
                && name_ok(&r.namespace, true)
                && !r.namespace.ends_with('/'));
        if !ns_ok {
            return Err(DaemonConfigError::Invalid {
                key: "ros2.namespace".into(),
                line: locate("ros2.namespace"),
                reason: format!(
                    "{:?} is not a ROS 2 namespace (\"\" or /letters_digits/…)",
                    r.namespace
                ),
            });
        }
        within("ros2.map_interval", r.map_interval, 0.5, 3600.0)?;
        within("ros2.map_resolution", r.map_resolution, 0.01, 1.0)?;
        for (key, frame) in [
            ("ros2.map_frame", &r.map_frame),
            ("ros2.odom_frame", &r.odom_frame),
            ("ros2.base_frame", &r.base_frame),
            ("ros2.laser_frame", &r.laser_frame),
        ] {
            // tf2 frame ids: no leading slash, no spaces.
            if frame.is_empty() || frame.starts_with('/') || !name_ok(frame, true) {
                return Err(DaemonConfigError::Invalid {
                    key: key.into(),
                    line: locate(key),
                    reason: format!("{frame:?} is not a frame id (letters, digits, _ and /)"),
                });
            }
        }
        let frames = [&r.map_frame, &r.odom_frame, &r.base_frame, &r.laser_frame];
        if (1..frames.len()).any(|i| frames[..i].contains(&frames[i])) {
            return Err(DaemonConfigError::Invalid {
                key: "ros2.map_frame".into(),
                line: locate("ros2.map_frame"),
                reason: "the four frames need four names".into(),
            });
        }
        if r.node_name.is_empty()
            || !name_ok(&r.node_name, false)
            || r.node_name.starts_with(|c: char| c.is_ascii_digit())
        {
            return Err(DaemonConfigError::Invalid {
                key: "ros2.node_name".into(),
                line: locate("ros2.node_name"),
                reason: format!("{:?} is not a ROS 2 node name", r.node_name),
            });
        }
        if b.adapter == BaseKind::Ros2 {
            if !cfg!(feature = "dds") {
                return Err(DaemonConfigError::Invalid {
                    key: "base.adapter".into(),
                    line: locate("base.adapter"),
                    reason: "this build has no ROS 2 (built without the `dds` feature)".into(),
                });
            }
            for (key, topic) in [
                ("base.odom_topic", &b.odom_topic),
                ("base.cmd_vel_topic", &b.cmd_vel_topic),
            ] {
                // ROS 2 names: /token/token, each token letters, digits
                // and _, not starting with a digit, no "__".
                let tokens_ok = topic.strip_prefix('/').is_some_and(|rest| {
                    rest.split('/').all(|t| {
                        !t.is_empty()
                            && !t.starts_with(|c: char| c.is_ascii_digit())
                            && !t.contains("__")
                    })
                });
                if !tokens_ok || !name_ok(topic, true) {
                    return Err(DaemonConfigError::Invalid {
                        key: key.into(),
                        line: locate(key),
                        reason: format!("{topic:?} is not a ROS 2 topic (/letters_digits/…)"),
                    });
                }
            }
        }
        self.mapper.validate().map_err(|e| {
            let key = match &e {
                crate::pipeline::config::ConfigError::Range { key, .. } => mapper_key(key),
                _ => "mapper".to_string(),
            };
            DaemonConfigError::Invalid {
                line: locate(&key),
                key,
                reason: e.to_string(),
            }
        })
    }

    /// The LMS200 variant of `[sensor]`, if it is one.
    pub fn variant(&self) -> Option<Variant> {
        let centideg = (self.sensor.resolution * 100.0).round();
        if !(1.0..=100.0).contains(&centideg)
            || (self.sensor.resolution * 100.0 - centideg).abs() > 1e-6
        {
            return None;
        }
        Variant::from_wire(self.sensor.field_of_view, centideg as u16)
    }

    pub fn units(&self) -> Option<Units> {
        match self.sensor.units.as_str() {
            "mm" => Some(Units::Mm),
            "cm" => Some(Units::Cm),
            _ => None,
        }
    }

    /// The serial link's configuration for `[sensor]` (defaults elsewhere).
    pub fn link(&self) -> LinkConfig {
        let mut link = LinkConfig::default();
        if let Some(v) = self.variant() {
            link.variant = v;
        }
        if let Some(u) = self.units() {
            link.units = u;
        }
        if let Some(b) = Baud::from_bits_per_second(self.sensor.baud) {
            link.target_baud = b;
        }
        link
    }

    /// The state directory: `[daemon] state_dir`, else `$STATE_DIRECTORY`
    /// (its first entry), else `./clsmap-state`.
    pub fn state_dir(&self) -> PathBuf {
        if let Some(dir) = &self.daemon.state_dir {
            return dir.clone();
        }
        std::env::var_os("STATE_DIRECTORY")
            .and_then(|v| {
                v.to_str()
                    .and_then(|s| s.split(':').next())
                    .filter(|s| !s.is_empty())
                    .map(PathBuf::from)
            })
            .unwrap_or_else(|| PathBuf::from("clsmap-state"))
    }
}

/// `[section] key` or `key` of a mapper error as a dotted key under
/// `mapper`.
fn mapper_key(key: &str) -> String {
    match key.strip_prefix('[').and_then(|k| k.split_once("] ")) {
        Some((section, name)) => format!("mapper.{section}.{name}"),
        None => format!("mapper.{key}"),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn an_empty_file_is_the_defaults() {
        let c = DaemonConfig::from_toml("").unwrap();
        assert_eq!(c, DaemonConfig::default());
        assert_eq!(c.variant(), Some(Variant::Fov180Res50));
        assert_eq!(c.link().target_baud, Baud::B500000);
    }

    #[test]
    fn bad_values_name_key_and_line() {
        let text = "[sensor]\nport = \"/dev/ttyUSB0\"\nbaud = 57600\n";
        let e = DaemonConfig::from_toml(text).unwrap_err().to_string();
        assert!(
            e.contains("sensor.baud (line 3)") && e.contains("57600"),
            "{e}"
        );
        let text = "[base]\nadapter = \"sim\"\n\n[base.unknown]\n";
        let e = DaemonConfig::from_toml(text).unwrap_err().to_string();
        assert!(e.contains("line 4") || e.contains("unknown"), "{e}");
        let text = "[sensor]\nfield_of_view = 100\nresolution = 0.3\n";
        let e = DaemonConfig::from_toml(text).unwrap_err().to_string();
        assert!(
            e.contains("line 3") && e.contains("not an LMS200 variant"),
            "{e}"
        );
        let text = "[mapper.extraction]\nsplit_threshold = -1.0\n";
        let e = DaemonConfig::from_toml(text).unwrap_err().to_string();
        assert!(
            e.contains("mapper.extraction.split_threshold (line 2)"),
            "{e}"
        );
        let text = "[sensor]\nsource = \"emulator\"\n";
        let e = DaemonConfig::from_toml(text).unwrap_err().to_string();
        assert!(e.contains("sensor.source (line 2)"), "{e}");
        let text = "[exploration]\nenabled = true\n";
        let e = DaemonConfig::from_toml(text).unwrap_err().to_string();
        assert!(e.contains("exploration.enabled (line 2)"), "{e}");
        let e = DaemonConfig::from_toml("[sensor]\nbaud = \"fast\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2"), "{e}");
    }

    #[test]
    fn web_settings_are_checked_with_their_line() {
        let e = DaemonConfig::from_toml("[web]\nenabled = true\nbind = \"localhost\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("web.bind (line 3)"), "{e}");
        let e = DaemonConfig::from_toml("[web]\ntoken = \"short\"\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("web.token (line 2)") && !e.contains("short"),
            "{e}"
        );
        let e = DaemonConfig::from_toml("[web]\nmax_clients = 0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("web.max_clients (line 2)"), "{e}");
        let c = DaemonConfig::from_toml("[web]\nbind = \"0.0.0.0:9000\"\n").unwrap();
        assert_eq!(c.web.address().unwrap().port(), 9000);
    }

    /// A base link that cannot work is refused at load, with its line,
    /// not later in a retry loop.
    #[test]
    fn a_base_link_that_cannot_work_is_refused_with_its_line() {
        let e = DaemonConfig::from_toml("[base]\nadapter = \"tcp\"\naddress = \"robot\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("base.address (line 3)"), "{e}");
        let e = DaemonConfig::from_toml("[base]\nadapter = \"tcp\"\naddress = \"robot:99999\"\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("base.address"), "{e}");
        DaemonConfig::from_toml("[base]\nadapter = \"tcp\"\naddress = \"robot.local:7300\"\n")
            .unwrap();
        let e = DaemonConfig::from_toml("[base]\nbaud = 0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("base.baud (line 2)"), "{e}");
    }

    #[test]
    fn a_ros2_section_that_cannot_work_is_refused_with_its_line() {
        let c = DaemonConfig::from_toml(
            "[ros2]\nenabled = true\ndomain_id = 7\nnamespace = \"/robot_1\"\n",
        );
        assert_eq!(c.unwrap().ros2.namespace, "/robot_1");
        for (text, key) in [
            ("[ros2]\ndomain_id = 233\n", "ros2.domain_id (line 2)"),
            (
                "[ros2]\n\nnamespace = \"robot\"\n",
                "ros2.namespace (line 3)",
            ),
            ("[ros2]\nnamespace = \"/a b\"\n", "ros2.namespace (line 2)"),
            (
                "[ros2]\nnode_name = \"9lives\"\n",
                "ros2.node_name (line 2)",
            ),
            ("[ros2]\nmap_frame = \"/map\"\n", "ros2.map_frame (line 2)"),
            (
                "[ros2]\nlaser_frame = \"base_link\"\n",
                "the four frames need four names",
            ),
            ("[ros2]\nmap_interval = 0.0\n", "ros2.map_interval (line 2)"),
            (
                "[ros2]\n\nmap_resolution = 5.0\n",
                "ros2.map_resolution (line 3)",
            ),
            (
                "[base]\nadapter = \"ros2\"\nodom_topic = \"odom\"\n",
                "base.odom_topic (line 3)",
            ),
            (
                "[base]\nadapter = \"ros2\"\ncmd_vel_topic = \"/a b\"\n",
                "base.cmd_vel_topic (line 3)",
            ),
            (
                "[base]\nadapter = \"ros2\"\nodom_topic = \"/a//odom\"\n",
                "base.odom_topic (line 3)",
            ),
            (
                "[base]\nadapter = \"ros2\"\nodom_topic = \"/1odom\"\n",
                "base.odom_topic (line 3)",
            ),
        ] {
            let e = DaemonConfig::from_toml(text).unwrap_err().to_string();
            assert!(e.contains(key), "{text}: {e}");
        }
        assert!(DaemonConfig::from_toml("[ros2]\ndomain_id = 70000\n").is_err());
        let c = DaemonConfig::from_toml(
            "[ros2]\nbase_frame = \"robot1/base_link\"\n[base]\nadapter = \"ros2\"\n\
             odom_topic = \"/robot1/odom\"\n",
        )
        .unwrap();
        assert_eq!(c.ros2.base_frame, "robot1/base_link");
        assert_eq!(c.base.adapter, BaseKind::Ros2);
    }

    #[test]
    fn keys_are_found_on_their_lines() {
        let text = "# x\n[a]\nb = 1\n\n[a.c]\nd = 2\n";
        assert_eq!(line_of_key(text, "a.b"), Some(3));
        assert_eq!(line_of_key(text, "a.c.d"), Some(6));
        assert_eq!(line_of_key(text, "a.c"), Some(5));
        assert_eq!(line_of_key(text, "a.x"), None);
        assert_eq!(line_of_key("not toml [", "a"), None);
    }

    /// `config/clsmap.toml` lists every key with its default: it must parse
    /// to exactly the defaults and name every key; its `[mapper]` part is
    /// `config/mapper.toml`'s.
    #[test]
    fn the_documented_config_is_the_default() {
        let text = include_str!("../../config/clsmap.toml");
        let parsed = DaemonConfig::from_toml(text).unwrap();
        assert_eq!(parsed, DaemonConfig::default());
        let defaults = toml::to_string(&DaemonConfig::default()).unwrap();
        for line in defaults.lines() {
            if let Some((key, _)) = line.split_once(" = ") {
                assert!(
                    text.lines().any(|l| {
                        let l = l.trim_start().trim_start_matches("# ");
                        l.starts_with(&format!("{key} =")) || l.starts_with(&format!("{key}="))
                    }),
                    "config/clsmap.toml does not document `{key}`"
                );
            }
        }
        // Keys with no default value (optional paths, the sim start) are
        // documented as comments.
        for key in ["record", "replay", "start", "state_dir", "load"] {
            assert!(
                text.lines().any(|l| l.starts_with(&format!("# {key} ="))),
                "config/clsmap.toml does not show `{key}`"
            );
        }
        let mapper_toml: toml::Table =
            toml::from_str(include_str!("../../config/mapper.toml")).unwrap();
        let full: toml::Table = toml::from_str(text).unwrap();
        assert_eq!(full.get("mapper"), Some(&toml::Value::Table(mapper_toml)));
    }

    #[test]
    fn the_state_directory_prefers_the_config_then_systemd() {
        let mut c = DaemonConfig::default();
        c.daemon.state_dir = Some(PathBuf::from("/tmp/x"));
        assert_eq!(c.state_dir(), PathBuf::from("/tmp/x"));
    }
}
