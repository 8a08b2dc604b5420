//! The robot daemon (`clsmap run`) and the loop the demo runs.
//!
//! - [`base_driver`]: [`BaseDriver`](base_driver::BaseDriver), commands with limits and safety stops.
//! - [`checkpoint`]: map snapshots written off the loop.
//! - [`core`]: [`Core`](core::Core), the loop without the loop (sans-IO): scans,
//!   odometry and the clock in; commands, checkpoints, optimisations and status out.
//! - [`config`]: [`DaemonConfig`], the TOML file, checked with key and line.
//! - [`live`]: [`LiveMapper`], the loop's work without the loop (sans-IO).
//! - [`latency`]: per-stage latency histograms.
//! - [`sensor`]: the serial driver's thread, latest scan wins.
//! - [`notify`]: systemd's READY/WATCHDOG/STATUS/STOPPING.
//! - [`ros2_out`]: the ROS 2 messages of each scan and of the map (sans-IO);
//!   `bag_sink` writes them into a bag, `dds_sink` onto DDS.
//! - `ros2_base`: a base behind its own ROS 2 driver (feature `dds`).
//! - [`run_dir`]: the run's directory and the rescue of a map that cannot go there.
//! - [`runtime`]: the tokio shell around the core, [`run`].
//! - [`simulation`]: the simulated robot and [`VirtualRobot`](simulation::VirtualRobot): the same core on a virtual clock, faster than real
//!   time, for tests and soak runs.

pub mod bag_sink;
pub mod base_driver;
pub mod checkpoint;
pub mod config;
pub mod core;
#[cfg(feature = "dds")]
pub mod dds_sink;
pub mod handoff;
pub mod latency;
pub mod live;
pub mod notify;
#[cfg(feature = "dds")]
pub mod ros2_base;
pub mod ros2_out;
pub mod run_dir;
pub mod runtime;
pub mod sensor;
#[cfg(feature = "sim")]
pub mod simulation;
pub mod web;

pub use config::{BaseKind, DaemonConfig, DaemonConfigError, SensorSource};
pub use latency::{Latencies, Stage, StageSummary};
pub use live::{LiveMapper, LiveStatus};
pub use runtime::{DaemonError, Hooks, RunSummary, ScanProgress, StopReason, run, run_blocking};
