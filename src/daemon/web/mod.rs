//! The live view: what a person watching the robot sees in a browser —
//! the CLS map growing (walls solid, frontiers dashed, loop closures), the
//! robot with its uncertainty, its path, the exploration goal and the path
//! planned to it, and a panel of health and latencies.
//!
//! The loop publishes snapshots ([`LiveView`] a few times a second,
//! [`MapView`] when the map changed) into watch channels; the server
//! ([`server`]) runs on a thread of its own and only ever reads the newest
//! one, so no client, however slow or many, can hold up the loop or make
//! anything queue.

pub mod server;

use std::sync::Arc;

use serde::Serialize;

use super::latency::StageSummary;
use super::live::LiveStatus;
use crate::geometry::Pose2;
use crate::map::cls::SegmentMode;
use crate::map::{EdgeKind, MapContents};

/// The loop's state for the page's panel, a few times a second.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LiveView {
    /// Seconds since the daemon started.
    pub uptime: f64,
    /// "streaming", "waiting for the sensor", "SENSOR SILENT", …
    pub sensor: String,
    /// Scans taken up per second since the last view.
    pub scan_rate: f64,
    /// Scans replaced in the sensor's mailbox before the loop took them.
    pub scans_skipped: u64,
    /// Odometry samples refused as out of order.
    pub odometry_refused: u64,
    /// Whether a base is connected and healthy enough to drive.
    pub base_ok: bool,
    /// The last velocity sent to the base (robot frame; m/s, rad/s).
    pub command: [f64; 3],
    pub status: LiveStatus,
    /// Covariance of the pose (x, y, θ; m², m·rad, rad²).
    pub covariance: [[f64; 3]; 3],
    /// The exploration goal and the path planned to it (map frame).
    pub goal: Option<Pose2>,
    pub plan: Vec<[f64; 2]>,
    /// Exploration paused from the page.
    pub paused: bool,
    /// Whether the page may pause, resume and stop (a token is set).
    pub control: bool,
    pub latencies: Vec<StageSummary>,
    /// The [`MapView::version`] this view goes with.
    pub map_version: u64,
}

/// One segment of the CLS map: `[x1, y1, x2, y2]` (m, map frame).
pub type SegmentView = [f64; 4];

/// The map for the page, and the map file for `/api/map`.
#[derive(Debug, Clone, Serialize)]
pub struct MapView {
    /// Counts up with every change.
    pub version: u64,
    /// Actual segments (walls).
    pub walls: Vec<SegmentView>,
    /// Virtual segments (frontiers).
    pub frontiers: Vec<SegmentView>,
    /// Accepted loop closures, keyframe to keyframe.
    pub loops: Vec<SegmentView>,
    /// The path driven (map frame), poses some 10 cm apart.
    pub path: Vec<[f64; 3]>,
    /// The whole map, for `/api/map` (encoded there, off the loop).
    #[serde(skip)]
    pub contents: Option<Arc<MapContents>>,
}

impl MapView {
    /// The view of `contents` with the driven `path`.
    pub fn from_contents(
        version: u64,
        contents: Arc<MapContents>,
        path: impl Iterator<Item = Pose2>,
    ) -> MapView {
        let seg = |l: &crate::geometry::CogLine| [l.start[0], l.start[1], l.end[0], l.end[1]];
        let (mut walls, mut frontiers) = (Vec::new(), Vec::new());
        for s in contents.cls.segments() {
            match s.mode {
                SegmentMode::Actual => walls.push(seg(&s.line)),
                SegmentMode::Virtual => frontiers.push(seg(&s.line)),
            }
        }
        let loops = contents
            .edges
            .iter()
            .filter(|e| e.kind == EdgeKind::Loop)
            .filter_map(|e| {
                let (a, b) = (contents.poses.get(e.from)?, contents.poses.get(e.to)?);
                Some([a.x, a.y, b.x, b.y])
            })
            .collect();
        MapView {
            version,
            walls,
            frontiers,
            loops,
            path: path.map(|p| [p.x, p.y, p.theta]).collect(),
            contents: Some(contents),
        }
    }
}

/// What the page may ask the loop to do (with the token).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ControlCommand {
    /// Hold exploration; the base stops until resumed.
    Pause,
    Resume,
    /// Stop the base now (an emergency stop), and hold exploration.
    Stop,
    /// The robot is here (map frame): look for it in the loaded map from
    /// this pose (an operator's "2D pose estimate").
    Pose(Pose2),
}
