//! `clsmap demo`: the daemon on a simulated robot, start to finish.
//!
//! The configuration is `config/demo.toml`, built in: an emulated LMS200 on
//! a pseudo-terminal measures a built-in floor plan from a simulated
//! holonomic base; the real serial driver opens the pty, auto-bauds,
//! configures the sensor and streams at 500 kBd; the daemon's loop
//! localizes every scan against the map, grows the CLS map on keyframes
//! and explores by Virtual Line Segment Pursuit until no frontier is left.
//! The map, its picture and the trajectory are written, and the run is
//! scored against the simulator's truth: pose error, and how much of the
//! map's wall length lies on the world's walls.

use std::io;
use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::daemon::runtime::{DaemonError, Hooks, RunSummary, ScanProgress, StopReason, run};
use crate::daemon::simulation::load_world;
use crate::daemon::{DaemonConfig, DaemonConfigError, StageSummary};
use crate::geometry::{Pose2, point_segment_distance, wrap_angle};
use crate::map::cls::{ClsMap, ClsMapConfig, StoreError};
use crate::pipeline::MAP_FILE;
use crate::sim::World;

/// The demo's configuration, as shipped in `config/demo.toml`.
pub const DEMO_CONFIG: &str = include_str!("../config/demo.toml");

/// Why the demo failed.
#[derive(Debug, thiserror::Error)]
pub enum DemoError {
    #[error("the demo configuration is invalid")]
    Config(#[from] DaemonConfigError),
    #[error("the daemon failed")]
    Daemon(#[from] DaemonError),
    #[error("the sensor delivered no scan")]
    NoScans,
    #[error("cannot read back the saved map")]
    Map(#[from] StoreError),
    #[error("cannot write {path}")]
    Io {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
}

/// The built-in demo configuration (a test keeps it valid).
pub fn demo_config() -> Result<DaemonConfig, DaemonConfigError> {
    DaemonConfig::from_toml(DEMO_CONFIG)
}

/// Live progress, after every scan.
#[derive(Debug, Clone, PartialEq)]
pub struct DemoProgress {
    /// Seconds since the start.
    pub t: f64,
    pub scans: u64,
    pub walls: usize,
    pub frontiers: usize,
    /// Exploration goals chosen so far.
    pub goals: usize,
    /// Distance of the estimate from the truth (m).
    pub error: f64,
}

/// What the demo did and how well.
#[derive(Debug, Clone, Serialize)]
pub struct DemoSummary {
    pub world: String,
    pub reason: StopReason,
    pub exploration_complete: bool,
    pub run_time_s: f64,
    pub scans: u64,
    pub scans_skipped: u64,
    /// Actual and virtual segments and loops of the saved CLS map.
    pub walls: usize,
    pub frontiers: usize,
    pub loops: usize,
    pub goals: usize,
    /// Long frontiers the explorer left open (no reachable goal in front
    /// of them, or their visits ran out).
    pub frontiers_given_up: usize,
    /// Metres driven (truth).
    pub driven_m: f64,
    /// Mean and largest position error of the estimate (m) and largest
    /// heading error (deg), against the simulator's truth.
    pub mean_error_m: f64,
    pub max_error_m: f64,
    pub max_heading_error_deg: f64,
    /// Share of the map's wall length within 5 cm of a real wall.
    pub walls_on_world: f64,
    pub latencies: Vec<StageSummary>,
    pub out_dir: PathBuf,
}

/// Accumulates the error of the estimate against the truth.
#[derive(Debug, Default)]
struct Score {
    origin: Option<Pose2>,
    last_truth: Option<Pose2>,
    driven: f64,
    sum: f64,
    n: u64,
    max: f64,
    max_heading: f64,
    last: f64,
}

impl Score {
    fn add(&mut self, estimate: Pose2, truth: Pose2) {
        let origin = *self.origin.get_or_insert(truth);
        if let Some(last) = self.last_truth {
            self.driven += (truth.x - last.x).hypot(truth.y - last.y);
        }
        self.last_truth = Some(truth);
        let t = origin.between(&truth);
        let e = (estimate.x - t.x).hypot(estimate.y - t.y);
        self.sum += e;
        self.n += 1;
        self.max = self.max.max(e);
        self.max_heading = self
            .max_heading
            .max(wrap_angle(estimate.theta - t.theta).abs());
        self.last = e;
    }
}

/// Share of `map`'s wall length (map frame, whose origin is `origin` in
/// the world) lying within `tolerance` metres of one of `world`'s walls,
/// sampled every centimetre.
pub fn walls_on_world(map: &ClsMap, world: &World, origin: Pose2, tolerance: f64) -> f64 {
    let (mut good, mut total) = (0usize, 0usize);
    for s in map.actual_segments() {
        let (a, b) = (
            origin.transform_point(s.start()),
            origin.transform_point(s.end()),
        );
        let n = ((b[0] - a[0]).hypot(b[1] - a[1]) / 0.01).ceil().max(1.0) as usize;
        for k in 0..n {
            let f = (k as f64 + 0.5) / n as f64;
            let p = [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1])];
            total += 1;
            good += usize::from(
                world
                    .walls()
                    .iter()
                    .any(|w| point_segment_distance(p, w[0], w[1]) <= tolerance),
            );
        }
    }
    good as f64 / total.max(1) as f64
}

/// When the demo stops before exploration completes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DemoStop {
    /// Only at its time limit.
    TimeLimit,
    /// Also on Ctrl-C (SIGINT), saving the map as the daemon does.
    CtrlC,
}

/// Runs `config` (the demo's, or a variation of it) with its maps written
/// to `out_dir`, until exploration completes, its time limit passes or, as
/// `stop` says, Ctrl-C is pressed. With `[web]` on, `on_web` hears the
/// live view's address (a free port when the configured one is taken).
pub fn run_demo(
    config: DaemonConfig,
    out_dir: &Path,
    stop: DemoStop,
    mut on_progress: impl FnMut(&DemoProgress),
    on_web: impl FnMut(std::net::SocketAddr),
) -> Result<DemoSummary, DemoError> {
    let world = load_world(&config.sim.world)?;
    let score = std::rc::Rc::new(std::cell::RefCell::new(Score::default()));
    let hook_score = score.clone();
    let mut hooks = Hooks::until(async move {
        match stop {
            DemoStop::CtrlC => {
                if tokio::signal::ctrl_c().await.is_err() {
                    std::future::pending::<()>().await;
                }
            }
            DemoStop::TimeLimit => std::future::pending::<()>().await,
        }
    });
    hooks.out_dir = Some(out_dir.to_owned());
    hooks.web_any_port = true;
    hooks.on_web = Some(Box::new(on_web));
    hooks.on_scan = Some(Box::new(move |p: &ScanProgress| {
        let mut s = hook_score.borrow_mut();
        if let Some(truth) = p.truth {
            s.add(p.pose, truth);
        }
        on_progress(&DemoProgress {
            t: p.t,
            scans: p.status.scans,
            walls: p.status.walls,
            frontiers: p.status.frontiers,
            goals: p.status.explorer.map_or(0, |e| e.goals),
            error: s.last,
        });
    }));
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(DaemonError::Runtime)?;
    let summary: RunSummary = runtime.block_on(run(config.clone(), hooks))?;
    let score = score.borrow();
    let (Some(out_dir), true) = (summary.out_dir.clone(), score.n > 0) else {
        return Err(DemoError::NoScans);
    };
    let map = ClsMap::load(&out_dir.join(MAP_FILE), ClsMapConfig::default())?;
    let origin = score.origin.unwrap_or(world.start);
    let result = DemoSummary {
        world: world.name.clone(),
        reason: summary.reason,
        exploration_complete: summary.status.exploration_complete,
        run_time_s: summary.run_time,
        scans: summary.scans,
        scans_skipped: summary.scans_skipped,
        walls: map.actual_segments().count(),
        frontiers: map.virtual_segments().count(),
        loops: map.loops().count(),
        goals: summary.status.explorer.map_or(0, |e| e.goals),
        frontiers_given_up: summary.status.explorer.map_or(0, |e| e.given_up),
        driven_m: score.driven,
        mean_error_m: score.sum / score.n as f64,
        max_error_m: score.max,
        max_heading_error_deg: score.max_heading.to_degrees(),
        walls_on_world: walls_on_world(&map, &world.world, origin, 0.05),
        latencies: summary.latencies,
        out_dir: out_dir.clone(),
    };
    let path = out_dir.join("demo.json");
    let text = serde_json::to_string_pretty(&result).map_err(io::Error::from);
    text.and_then(|t| crate::files::durable::write_atomically(&path, (t + "\n").as_bytes()))
        .map_err(|source| DemoError::Io { path, source })?;
    Ok(result)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn the_built_in_configuration_is_valid() {
        let c = demo_config().unwrap();
        assert!(c.exploration.enabled && c.exploration.exit_when_complete);
        assert!(load_world(&c.sim.world).is_ok());
    }
}
