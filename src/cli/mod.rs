//! Command-line interface: argument parsing and dispatch to subcommands.
//! Errors here are `anyhow` with context; the libraries below use typed errors.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

use anyhow::Context as _;
use clap::{Parser, Subcommand, ValueEnum};

mod daemon;
#[cfg(feature = "sim")]
mod demo;
#[cfg(feature = "sim")]
mod emulate;
mod localize;
mod mapping;
mod sensor;
mod view;

/// SICK LMS200 driver and Closed Line Segment mapper.
#[derive(Debug, Parser)]
#[command(name = "clsmap", version, about, long_about = None)]
pub struct Cli {
    /// More log output (-v debug, -vv trace). RUST_LOG overrides.
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub verbose: u8,
    /// Only warnings and errors.
    #[arg(short, long, global = true)]
    pub quiet: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    #[cfg(feature = "sim")]
    /// The embedded default: the daemon on a simulated robot. An emulated
    /// LMS200 on a pseudo-terminal and a simulated holonomic base in a
    /// built-in floor plan; the loop localizes, maps and explores by
    /// Virtual Line Segment Pursuit until no frontier is left, then writes
    /// the map, its picture and the trajectory.
    Demo {
        /// Where to write map.json, map.svg, trajectory.tum (and its
        /// trajectory.anchors), demo.json; it
        /// must not hold a map already. Default: out/demo, or out/demo-2,
        /// out/demo-3 … when earlier runs are there (none is overwritten).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Built-in world (loop, room, corridor, lab, office) or a world
        /// file; default: config/demo.toml's.
        #[arg(long)]
        world: Option<String>,
        /// Seed of the simulated range noise.
        #[arg(long)]
        seed: Option<u64>,
        /// Do not serve the live view (served by default on
        /// 127.0.0.1:8080, or a free port when that one is taken).
        #[arg(long)]
        no_web: bool,
        /// Publish the demo as a ROS 2 node on DDS (domain 0, or
        /// ROS_DOMAIN_ID): /scan, /pose, /odom, /tf and /tf_static, for
        /// RViz or Foxglove on this machine or the network.
        #[arg(long)]
        ros2: bool,
    },
    /// The robot daemon: the LMS200, the base, localization, the CLS map
    /// and exploration in one real-time loop (systemd `Type=notify`).
    /// SIGTERM/SIGINT stop the base and the sensor and save the map;
    /// SIGHUP reloads the tunable parts of the configuration.
    Run {
        /// Daemon configuration (TOML); every key and default is in config/clsmap.toml.
        #[arg(long)]
        config: PathBuf,
        /// Start from this saved map (map.json), as `[map] load`.
        #[arg(long)]
        map: Option<PathBuf>,
        /// With --map: `localize` or `extend`, as `[map] mode`.
        #[arg(long, requires = "map")]
        mode: Option<String>,
        /// As `[map] ignore_checksum = true`: load the map even if its
        /// checksum does not match (edited by hand), with a warning.
        #[arg(long)]
        ignore_checksum: bool,
    },
    /// Find an LMS200 on a serial port: line speed, type, firmware, variant, units.
    Probe {
        /// Serial device, e.g. /dev/ttyUSB0.
        #[arg(long)]
        port: PathBuf,
    },
    /// Capture the raw telegram stream of an LMS200 into a recording, a
    /// rosbag2 MCAP bag, or both.
    #[command(group(clap::ArgGroup::new("output").required(true).multiple(true).args(["out", "bag"])))]
    Record {
        /// Serial device.
        #[arg(long)]
        port: PathBuf,
        /// Recording to write (clsmap's own format).
        #[arg(long)]
        out: Option<PathBuf>,
        /// rosbag2 MCAP bag to write: sensor_msgs/LaserScan on /scan and
        /// the recording's bytes on /lms200/recording (nothing is lost).
        #[arg(long)]
        bag: Option<PathBuf>,
        /// Stop after this many scans (default: until Ctrl-C).
        #[arg(long)]
        scans: Option<u64>,
        /// Line speed while streaming.
        #[arg(long, default_value_t = 500_000)]
        baud: u32,
        /// Field of view / resolution in degrees: 180/0.5, 180/1, 100/1, 100/0.5, 100/0.25.
        #[arg(long, default_value = "180/0.5")]
        variant: String,
        /// Range units.
        #[arg(long, value_enum, default_value_t = UnitsArg::Mm)]
        units: UnitsArg,
    },
    /// Decode a recording (or a raw serial dump) to one line per scan.
    Decode {
        /// Recording (`clsmap record`) or, with --raw, a plain byte dump.
        file: PathBuf,
        /// The file is a plain serial byte dump, not a recording.
        #[arg(long)]
        raw: bool,
        /// Output format.
        #[arg(long, value_enum, default_value_t = DecodeFormat::Jsonl)]
        format: DecodeFormat,
        /// Measuring mode of the sensor (configuration block D, hex), when
        /// the recording does not say; it decides which bits are distance.
        #[arg(long, value_parser = parse_hex_u8)]
        mode: Option<u8>,
    },
    #[cfg(feature = "sim")]
    /// Run an emulated LMS200 on a pseudo-terminal until Ctrl-C.
    Emulate {
        /// Create a symlink to the emulator's tty here (e.g. /tmp/lms200).
        #[arg(long)]
        link: Option<PathBuf>,
        /// Line speed the emulated sensor was left at (it powers up at 9600).
        #[arg(long)]
        start_baud: Option<u32>,
        /// Model a power-up: the sensor is deaf for this many seconds after
        /// the start, then sends its `90` power-on telegram. Without it the
        /// sensor has been on for a while and answers at once.
        #[arg(long, value_name = "SECONDS")]
        power_on: Option<f64>,
        /// Probability per byte of a flipped bit on the line.
        #[arg(long, default_value_t = 0.0)]
        bit_flips: f64,
        /// Probability per byte of an inserted garbage byte.
        #[arg(long, default_value_t = 0.0)]
        garbage: f64,
        /// Probability per byte of a lost byte.
        #[arg(long, default_value_t = 0.0)]
        drops: f64,
        /// Seed of the fault generator.
        #[arg(long, default_value_t = 1)]
        seed: u64,
    },
    /// Build a map offline from a CARMEN log or a recording. Input that
    /// cannot be used (malformed lines, bad odometry, damaged records,
    /// scans out of time order) is skipped and named; the exit status is
    /// then 4 (the map was written from the rest), 0 when all input was
    /// used.
    Map {
        /// CARMEN log (.clf/.log), clsmap recording, or rosbag2 MCAP bag
        /// (a .mcap file or a bag directory).
        input: PathBuf,
        /// Directory for trajectory.tum, map.json and map.svg.
        #[arg(long)]
        out: PathBuf,
        /// Mapper configuration (TOML); every key and default is in config/mapper.toml.
        #[arg(long)]
        config: Option<PathBuf>,
        /// Score the trajectory against a relations file (Kümmerle et al. 2009).
        #[arg(long)]
        relations: Option<PathBuf>,
        /// Draw the accepted loop closures on map.svg (keyframe to keyframe).
        #[arg(long)]
        draw_loops: bool,
        /// Stop at the first input item that cannot be used, writing
        /// nothing, instead of skipping it.
        #[arg(long)]
        strict: bool,
        /// Go on from this saved map (map.json) instead of a new one: the
        /// robot is found in it by global localization, and the trajectory
        /// is in its frame. The file itself is never written.
        #[arg(long)]
        map: Option<PathBuf>,
        /// With --map: `localize` (the map stays as it is) or `extend`
        /// (new keyframes join it, loops close against it).
        #[arg(long, default_value = "localize", requires = "map")]
        mode: String,
        /// Read --map even if its checksum does not match (a map edited by
        /// hand), with a warning; every other check still applies.
        #[arg(long, requires = "map")]
        ignore_checksum: bool,
        #[command(flatten)]
        bag: BagArgs,
    },
    /// Draw a CLS map (map.json) as SVG, or export it as a ROS map_server
    /// occupancy grid (PGM + YAML) when the output ends in `.pgm`.
    Render {
        /// Map written by `clsmap map` or `clsmap demo` (map.json).
        map: PathBuf,
        /// Output: FILE.svg, or FILE.pgm (FILE.yaml is written beside it).
        #[arg(short, long)]
        output: PathBuf,
        /// Cell size of the occupancy grid (m).
        #[arg(long, default_value_t = 0.05)]
        resolution: f64,
        /// Read the map even if its checksum does not match (a map edited
        /// by hand), with a warning; every other check still applies.
        #[arg(long)]
        ignore_checksum: bool,
    },
    /// Show a saved map (map.json) in the browser, through the live view
    /// the daemon serves, until Ctrl-C.
    View {
        /// Map written by `clsmap map`, `clsmap run` or `clsmap demo`.
        map: PathBuf,
        /// Address and port to listen on (another address than 127.0.0.1
        /// shows the map to whoever reaches it).
        #[arg(long, default_value = "127.0.0.1:8080")]
        bind: String,
        /// Read the map even if its checksum does not match (a map edited
        /// by hand), with a warning; every other check still applies.
        #[arg(long)]
        ignore_checksum: bool,
    },
    /// Global localization: for each scan of a log, where in the map the
    /// robot may be, as one JSON line of ranked hypotheses (map frame).
    Localize {
        /// CLS map written by `clsmap map` (map.json); its walls are used.
        #[arg(long)]
        map: PathBuf,
        /// CARMEN log or clsmap recording with the scans.
        #[arg(long)]
        scan: PathBuf,
        /// Carry the hypotheses from scan to scan with the log's odometry
        /// and keep only those every scan agrees with (disambiguation);
        /// scores are then summed over the scans tracked.
        #[arg(long)]
        track: bool,
        /// Most hypotheses printed per scan.
        #[arg(long, default_value_t = 5)]
        max_hypotheses: usize,
        /// Read the map even if its checksum does not match (a map edited
        /// by hand), with a warning; every other check still applies.
        #[arg(long)]
        ignore_checksum: bool,
        /// Mapper configuration (TOML) for the laser mounting and line
        /// extraction; see config/mapper.toml.
        #[arg(long)]
        config: Option<PathBuf>,
    },
    /// Score a TUM trajectory against a relations file (Kümmerle et al. 2009).
    Eval {
        /// Trajectory in TUM format (t x y z qx qy qz qw).
        trajectory: PathBuf,
        /// Relations file (t1 t2 x y z roll pitch yaw).
        #[arg(long)]
        relations: PathBuf,
    },
}

/// Which topics of a rosbag2 bag are mapped.
#[derive(Debug, Clone, clap::Args)]
struct BagArgs {
    /// Bag input: the sensor_msgs/LaserScan topic.
    #[arg(long, default_value = "/scan")]
    scan_topic: String,
    /// Bag input: the nav_msgs/Odometry topic.
    #[arg(long, default_value = "/odom", conflicts_with = "tf")]
    odom_topic: String,
    /// Bag input: take odometry from /tf (the base frame in the odometry
    /// frame) instead of an Odometry topic.
    #[arg(long)]
    tf: bool,
    /// Bag input: map the scans without odometry (a sensor-only bag).
    #[arg(long, conflicts_with_all = ["tf", "odom_topic"])]
    no_odometry: bool,
    /// With --tf: the odometry frame.
    #[arg(long, default_value = "odom", requires = "tf")]
    odom_frame: String,
    /// With --tf: the robot's base frame.
    #[arg(long, default_value = "base_link", requires = "tf")]
    base_frame: String,
}

impl BagArgs {
    fn log_options(self) -> clsmap::input::LogOptions {
        use clsmap::input::{BagOdometry, BagTopics};
        let odometry = if self.no_odometry {
            BagOdometry::None
        } else if self.tf {
            BagOdometry::Tf {
                parent: self.odom_frame,
                child: self.base_frame,
            }
        } else {
            BagOdometry::Topic(self.odom_topic)
        };
        clsmap::input::LogOptions {
            bag: BagTopics {
                scan: self.scan_topic,
                odometry,
            },
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum UnitsArg {
    Mm,
    Cm,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum DecodeFormat {
    Jsonl,
    Csv,
}

fn parse_hex_u8(s: &str) -> Result<u8, String> {
    let digits = s.trim_start_matches("0x").trim_start_matches("0X");
    u8::from_str_radix(digits, 16).map_err(|e| format!("`{s}` is not a hex byte: {e}"))
}

impl Cli {
    pub fn parse_args() -> Self {
        Cli::parse()
    }

    /// Whether the command draws live progress of its own (the demo): its
    /// log then shows warnings only, unless -v asks for more.
    pub fn shows_progress(&self) -> bool {
        #[cfg(feature = "sim")]
        return matches!(self.command, Command::Demo { .. });
        #[cfg(not(feature = "sim"))]
        return false;
    }
}

/// Logs to stderr; RUST_LOG or else CLSMAP_LOG (the systemd unit's), if
/// set, wins over -v/-q. A command with live progress of its own starts a
/// level lower (warnings), so the log does not drown the progress line.
/// The DDS stack's own discovery chatter (a hundred lines at a node's
/// start) shows from -v on; below that only its errors.
pub fn init_logging(verbose: u8, quiet: bool, shows_progress: bool) {
    const LEVELS: [&str; 4] = [
        "warn,rustdds=error,ros2_client=error",
        "info,rustdds=error,ros2_client=error",
        "debug",
        "trace",
    ];
    let level = if quiet {
        0
    } else {
        (1 + usize::from(verbose)).saturating_sub(usize::from(shows_progress))
    };
    let default = LEVELS[level.min(LEVELS.len() - 1)];
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .or_else(|_| tracing_subscriber::EnvFilter::try_from_env("CLSMAP_LOG"))
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .try_init();
}

/// A flag raised by SIGINT or SIGTERM, for commands that run until stopped.
fn stop_flag() -> anyhow::Result<Arc<AtomicBool>> {
    let flag = Arc::new(AtomicBool::new(false));
    for sig in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(sig, Arc::clone(&flag))
            .context("cannot install the signal handler")?;
    }
    Ok(flag)
}

pub fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        #[cfg(feature = "sim")]
        Command::Demo {
            out,
            world,
            seed,
            no_web,
            ros2,
        } => demo::demo(out.as_deref(), world.as_deref(), seed, !no_web, ros2),
        Command::Run {
            config,
            map,
            mode,
            ignore_checksum,
        } => daemon::run_daemon(&config, map, mode, ignore_checksum),
        Command::Probe { port } => sensor::probe(&port),
        Command::Record {
            port,
            out,
            bag,
            scans,
            baud,
            variant,
            units,
        } => sensor::record(
            &port,
            &sensor::RecordOutputs {
                recording: out.as_deref(),
                bag: bag.as_deref(),
            },
            scans,
            baud,
            &variant,
            units,
        ),
        Command::Decode {
            file,
            raw,
            format,
            mode,
        } => sensor::decode(&file, raw, format, mode),
        #[cfg(feature = "sim")]
        Command::Emulate {
            link,
            start_baud,
            power_on,
            bit_flips,
            garbage,
            drops,
            seed,
        } => emulate::emulate(
            link.as_deref(),
            start_baud,
            power_on,
            emulate::LineFaults {
                bit_flips,
                garbage,
                drops,
                seed,
            },
        ),
        Command::Map {
            input,
            out,
            config,
            relations,
            draw_loops,
            strict,
            map,
            mode,
            ignore_checksum,
            bag,
        } => {
            let mode: clsmap::pipeline::MapMode = mode
                .parse()
                .map_err(|e: String| anyhow::anyhow!("--mode: {e}"))?;
            let log = bag.log_options();
            mapping::map(
                &input,
                &out,
                config.as_deref(),
                relations.as_deref(),
                &clsmap::pipeline::MapRunOptions {
                    draw_loops,
                    strict,
                    start_from: map.as_deref().map(|m| (m, mode)),
                    checksum: clsmap::map::file::ChecksumCheck::ignoring(ignore_checksum),
                    log: Some(&log),
                },
            )
        }
        Command::Eval {
            trajectory,
            relations,
        } => mapping::eval(&trajectory, &relations),
        Command::Localize {
            map,
            scan,
            track,
            max_hypotheses,
            config,
            ignore_checksum,
        } => localize::localize(
            &map,
            clsmap::map::file::ChecksumCheck::ignoring(ignore_checksum),
            &scan,
            config.as_deref(),
            track,
            max_hypotheses,
        ),
        Command::Render {
            map,
            output,
            resolution,
            ignore_checksum,
        } => mapping::render(
            &map,
            clsmap::map::file::ChecksumCheck::ignoring(ignore_checksum),
            &output,
            resolution,
        ),
        Command::View {
            map,
            bind,
            ignore_checksum,
        } => view::view(
            &map,
            clsmap::map::file::ChecksumCheck::ignoring(ignore_checksum),
            &bind,
        ),
    }
}
