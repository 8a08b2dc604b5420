//! The robot daemon (`clsmap run`) and the loop the demo runs.
//!
//! - [`base_driver`]: [`BaseDriver`](base_driver::BaseDriver), commands with limits and safety stops.
//! - [`checkpoint`]: map snapshots written off the loop.
//! - [`config`]: [`DaemonConfig`], the TOML file, checked with key and line.
//! - [`live`]: [`LiveMapper`], the loop's work without the loop (sans-IO).
//! - [`latency`]: per-stage latency histograms.
//! - [`sensor`]: the serial driver's thread, latest scan wins.
//! - [`notify`]: systemd's READY/WATCHDOG/STATUS/STOPPING.
//! - [`runtime`]: the tokio loop wiring it all, [`run`].
//! - [`simulation`]: the simulated robot and [`VirtualRobot`](simulation::VirtualRobot): the same loop on a virtual clock, faster than real
//!   time, for tests and soak runs.

pub mod base_driver;
pub mod checkpoint;
pub mod config;
pub mod latency;
pub mod live;
pub mod notify;
pub mod runtime;
pub mod sensor;
pub mod simulation;

pub use config::{BaseKind, DaemonConfig, DaemonConfigError, SensorSource};
pub use latency::{Latencies, Stage, StageSummary};
pub use live::{LiveMapper, LiveStatus};
pub use runtime::{DaemonError, Hooks, RunSummary, ScanProgress, StopReason, run, run_blocking};
