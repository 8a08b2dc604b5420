//! What the daemon tells ROS 2 about each scan, as messages: the scan, the
//! pose estimate with its covariance, the odometry, and the transforms of
//! REP 105 (`map` → `odom` from the localizer, `odom` → `base_link` from the
//! base's odometry, `base_link` → `laser` from the mounting, once, static);
//! and, at a bounded rate, the map as an occupancy grid (`/map`) and as
//! lines (`/cls_map`). The frames are named by `[ros2]`. When the base is
//! a ROS 2 node itself, its driver publishes `/odom` and `odom` →
//! `base_link` on DDS, so [`for_dds`] leaves them out there (the bag keeps
//! them).
//!
//! Sans-IO, like the core it belongs to: [`Ros2Outbox`] turns a scan and
//! its pose into stamped messages; a shell writes them into a bag (or, later,
//! onto DDS). Times are the daemon's clock (s since its start) plus the wall
//! clock at that start, so stamps are ROS times (ns since the epoch).

use std::borrow::Cow;
use std::collections::VecDeque;
use std::sync::Arc;

use super::config::Ros2Section;
use crate::map::cls::grid::grid_extent;
use crate::map::cls::{ClsMap, GridConfig, occupancy_grid};

use crate::geometry::{Pose2, RangeScan};
use crate::input::bag::laser_scan;
use crate::input::lms200::lms200_scan_timing;
use crate::ros2::msg::{PoseWithCovariance, TransformStamped, TwistWithCovariance};
use crate::ros2::{
    ColorRgba, DiagnosticArray, DiagnosticStatus, Header, LaserScan, Marker, MarkerArray,
    OccupancyGrid, Odometry, PoseWithCovarianceStamped, Quaternion, RosMessage, TfMessage, Time,
    Vector3,
};

/// The laser's frame when no `[ros2]` names one (`clsmap record --bag`).
pub const LASER_FRAME: &str = "laser";

/// The bag topic whose messages, put end to end, are the recording (the
/// `.rec` format) of the serial stream byte for byte.
pub const RECORDING_TOPIC: &str = "/lms200/recording";

/// `/map` has at most this many cells (its resolution is doubled until
/// it fits): DDS carries a megabyte or two well, not tens.
pub const MAP_MAX_CELLS: usize = 2_000_000;

/// Frontiers on `/cls_map` are drawn dashed: this much line (m), …
const DASH: f64 = 0.2;
/// … then this much gap.
const DASH_GAP: f64 = 0.1;

/// Messages held for the shell at most; older ones are dropped (and
/// counted) if it does not take them, so the loop's memory stays bounded.
const MAX_QUEUED: usize = 256;

/// One message for a topic.
#[derive(Debug, Clone, PartialEq)]
pub enum Ros2Message {
    /// `/scan`.
    Scan(LaserScan),
    /// `/pose`: the localizer's estimate in `map` (boxed, as the
    /// odometry: its covariance makes it large).
    Pose(Box<PoseWithCovarianceStamped>),
    /// `/odom`: the base's odometry (boxed: its two covariances make it
    /// the largest by far).
    Odometry(Box<Odometry>),
    /// `/tf`.
    Tf(TfMessage),
    /// `/tf_static` (transient-local: a late subscriber still gets it).
    TfStatic(TfMessage),
    /// `/diagnostics`: the status line's facts, per part.
    Diagnostics(DiagnosticArray),
    /// `/map` (transient-local): the CLS map as it was, to be rendered as
    /// an occupancy grid by the shell ([`grid_message`]), off the loop.
    Map(Arc<MapSnapshot>),
    /// `/cls_map` (transient-local): the same map as lines
    /// ([`marker_message`]), rendered by the shell.
    ClsMap(Arc<MapSnapshot>),
}

/// The CLS map at one time and the pose graph's loop edges then, shared
/// by `/map` and `/cls_map` (copying the map is the loop's one cost).
#[derive(Debug)]
pub struct MapSnapshot {
    pub map: Arc<ClsMap>,
    /// Lines between the keyframes each loop closure joins (map frame, m).
    pub loop_edges: Vec<[[f64; 2]; 2]>,
    pub stamp: Time,
    pub frame: String,
    /// `/map`'s finest cell side (m).
    pub resolution: f64,
}

impl PartialEq for MapSnapshot {
    fn eq(&self, other: &Self) -> bool {
        std::ptr::eq(self, other)
    }
}

/// A topic the daemon publishes: its name (below the namespace), ROS
/// type and schema, whether it is latched (transient-local: a late
/// subscriber gets the last message) and how many messages a writer keeps.
#[derive(Debug, Clone, Copy)]
pub struct Ros2Topic {
    pub name: &'static str,
    pub type_name: &'static str,
    pub definition: fn() -> String,
    pub latched: bool,
    pub depth: usize,
}

/// Every topic, in [`Ros2Message::topic_index`] order: the one table the
/// bag and the DDS node are built from.
pub const TOPICS: [Ros2Topic; 8] = [
    topic::<LaserScan>("scan", false, 10),
    topic::<PoseWithCovarianceStamped>("pose", false, 10),
    topic::<Odometry>("odom", false, 10),
    topic::<TfMessage>("tf", false, 100),
    topic::<TfMessage>("tf_static", true, 1),
    topic::<OccupancyGrid>("map", true, 1),
    topic::<DiagnosticArray>("diagnostics", false, 10),
    topic::<MarkerArray>("cls_map", true, 1),
];

/// The place in [`TOPICS`] of `/odom`, which a ROS 2 base's own driver
/// publishes instead.
pub const ODOM_TOPIC: usize = 2;

const fn topic<M: RosMessage>(name: &'static str, latched: bool, depth: usize) -> Ros2Topic {
    Ros2Topic {
        name,
        type_name: M::TYPE,
        definition: M::definition,
        latched,
        depth,
    }
}

impl Ros2Message {
    /// Its topic's place in [`TOPICS`].
    pub fn topic_index(&self) -> usize {
        match self {
            Ros2Message::Scan(_) => 0,
            Ros2Message::Pose(_) => 1,
            Ros2Message::Odometry(_) => 2,
            Ros2Message::Tf(_) => 3,
            Ros2Message::TfStatic(_) => 4,
            Ros2Message::Map(_) => 5,
            Ros2Message::Diagnostics(_) => 6,
            Ros2Message::ClsMap(_) => 7,
        }
    }

    /// The topic it goes on (`/scan`, …).
    pub fn topic(&self) -> String {
        format!("/{}", TOPICS[self.topic_index()].name)
    }

    /// Its CDR bytes (header included); a map is rendered as its grid here,
    /// so a shell calls this off the loop. `None` for an empty map.
    pub fn encode(&self) -> Option<Vec<u8>> {
        Some(match self {
            Ros2Message::Scan(m) => m.to_cdr(),
            Ros2Message::Pose(m) => m.to_cdr(),
            Ros2Message::Odometry(m) => m.to_cdr(),
            Ros2Message::Tf(m) | Ros2Message::TfStatic(m) => m.to_cdr(),
            Ros2Message::Diagnostics(m) => m.to_cdr(),
            Ros2Message::Map(m) => grid_message(m)?.to_cdr(),
            Ros2Message::ClsMap(m) => marker_message(m)?.to_cdr(),
        })
    }
}

/// A message and when it was produced (ns since the epoch).
#[derive(Debug, Clone, PartialEq)]
pub struct Stamped {
    pub stamp_ns: u64,
    pub message: Ros2Message,
}

/// Builds the messages of each scan; see the module documentation.
#[derive(Debug)]
pub struct Ros2Outbox {
    /// Wall-clock time (s since the epoch) at the daemon's clock's zero.
    epoch: f64,
    /// Frame names and the map's rate and resolution.
    settings: Ros2Section,
    /// Whether a base is configured (its odometry is then awaited before
    /// any transform goes out).
    has_base: bool,
    mount: Pose2,
    /// The sensor's reach (m), the scans' `range_max`.
    reach: f64,
    queue: VecDeque<Stamped>,
    static_sent: bool,
    dropped: u64,
    /// What the last `/map` was taken of, and when (daemon clock, s).
    map_sent: Option<(u64, f64)>,
    /// Whether any scan came with odometry (a base is there).
    had_odometry: bool,
}

/// `nav_msgs/Odometry` of `child` at the planar pose `p` in the header's
/// frame, with no covariance or twist given.
pub fn planar_odometry(header: Header, child: &str, p: &Pose2) -> Odometry {
    Odometry {
        header,
        child_frame_id: child.into(),
        pose: PoseWithCovariance {
            position: Vector3 {
                x: p.x,
                y: p.y,
                z: 0.0,
            },
            orientation: Quaternion::from_yaw(p.theta),
            covariance: [0.0; 36],
        },
        twist: TwistWithCovariance::default(),
    }
}

/// A pose as a ROS transform of `child` in `parent` at `stamp`.
fn transform(stamp: Time, parent: &str, child: &str, p: &Pose2) -> TransformStamped {
    TransformStamped {
        header: Header {
            stamp,
            frame_id: parent.into(),
        },
        child_frame_id: child.into(),
        translation: Vector3 {
            x: p.x,
            y: p.y,
            z: 0.0,
        },
        rotation: Quaternion::from_yaw(p.theta),
    }
}

/// The 6×6 covariance (x, y, z, roll, pitch, yaw) of a planar one (x, y,
/// θ); z, roll and pitch are not estimated and carry a large variance, as
/// ROS tools expect of a 2D estimate.
fn covariance_6(cov: &[[f64; 3]; 3]) -> [f64; 36] {
    let mut c = [0.0; 36];
    let index = [0usize, 1, 5];
    for (i, &a) in index.iter().enumerate() {
        for (j, &b) in index.iter().enumerate() {
            c[a * 6 + b] = cov[i][j];
        }
    }
    for k in [2usize, 3, 4] {
        c[k * 6 + k] = 1e6;
    }
    c
}

impl Ros2Outbox {
    /// `epoch`: the wall clock (s since the epoch) at the daemon's zero;
    /// `mount`: the laser in the base frame; `reach`: the sensor's range
    /// limit (m); `settings`: the frames and the map's rate; `has_base`:
    /// a base gives odometry (no base: `odom` is `base_link`).
    pub fn new(
        epoch: f64,
        mount: Pose2,
        reach: f64,
        settings: &Ros2Section,
        has_base: bool,
    ) -> Self {
        Ros2Outbox {
            epoch,
            settings: settings.clone(),
            has_base,
            mount,
            reach,
            queue: VecDeque::new(),
            static_sent: false,
            dropped: 0,
            map_sent: None,
            had_odometry: false,
        }
    }

    /// Whether a map that is now at `version` (any number that changes
    /// when the map does) is due at `t`: changed, and `map_interval` since
    /// the last.
    pub fn map_due(&self, version: u64, t: f64) -> bool {
        self.map_sent
            .is_none_or(|(v, at)| v != version && t - at >= self.settings.map_interval)
    }

    /// Queues the health of the parts for `/diagnostics` at `t`.
    pub fn diagnostics(&mut self, t: f64, status: Vec<DiagnosticStatus>) {
        let stamp = Time::from_secs(self.epoch + t).unwrap_or_default();
        self.push(
            t,
            Ros2Message::Diagnostics(DiagnosticArray {
                header: Header {
                    stamp,
                    frame_id: String::new(),
                },
                status,
            }),
        );
    }

    /// Queues `map` (at `version`) with the pose graph's `loop_edges`
    /// for `/map` and `/cls_map` at `t`.
    pub fn map(&mut self, version: u64, t: f64, map: Arc<ClsMap>, loop_edges: Vec<[[f64; 2]; 2]>) {
        self.map_sent = Some((version, t));
        let snapshot = Arc::new(MapSnapshot {
            map,
            loop_edges,
            stamp: Time::from_secs(self.epoch + t).unwrap_or_default(),
            frame: self.settings.map_frame.clone(),
            resolution: self.settings.map_resolution,
        });
        self.push(t, Ros2Message::Map(Arc::clone(&snapshot)));
        self.push(t, Ros2Message::ClsMap(snapshot));
    }

    fn push(&mut self, t: f64, message: Ros2Message) {
        if self.queue.len() >= MAX_QUEUED {
            self.queue.pop_front();
            self.dropped += 1;
        }
        let stamp_ns = ((self.epoch + t) * 1e9).max(0.0) as u64;
        self.queue.push_back(Stamped { stamp_ns, message });
    }

    /// The messages of one scan (`scan.t` on the daemon's clock), located
    /// at `pose` (map frame) with covariance `cov` (x, y, θ), with the
    /// odometry pose then (`None` without a base).
    pub fn scan(
        &mut self,
        scan: &RangeScan,
        pose: Pose2,
        cov: &[[f64; 3]; 3],
        odometry: Option<Pose2>,
    ) {
        let t = scan.t;
        let stamp = Time::from_secs(self.epoch + t).unwrap_or_default();
        let f = &self.settings;
        let (map_frame, odom_frame) = (f.map_frame.clone(), f.odom_frame.clone());
        let (base_frame, laser_frame) = (f.base_frame.clone(), f.laser_frame.clone());
        if !self.static_sent {
            self.static_sent = true;
            let tf = transform(stamp, &base_frame, &laser_frame, &self.mount);
            self.push(
                t,
                Ros2Message::TfStatic(TfMessage {
                    transforms: vec![tf],
                }),
            );
        }
        let (time_increment, scan_time) = lms200_scan_timing(scan.angle_increment);
        // Stamped on the wall clock: the scan's time moved by the epoch.
        let wall = RangeScan {
            t: self.epoch + t,
            ..scan.clone()
        };
        let msg = laser_scan(&wall, &laser_frame, self.reach, time_increment, scan_time);
        self.push(t, Ros2Message::Scan(msg));
        let header = |frame: &str| Header {
            stamp,
            frame_id: frame.into(),
        };
        self.push(
            t,
            Ros2Message::Pose(Box::new(PoseWithCovarianceStamped {
                header: header(&map_frame),
                pose: PoseWithCovariance {
                    position: Vector3 {
                        x: pose.x,
                        y: pose.y,
                        z: 0.0,
                    },
                    orientation: Quaternion::from_yaw(pose.theta),
                    covariance: covariance_6(cov),
                },
            })),
        );
        // map → odom so that map → odom → base_link is the pose; without a
        // base, odom is base_link. A scan whose odometry is missing while
        // a base is there gets no transforms: odom must not jump (REP 105).
        self.had_odometry |= odometry.is_some();
        if odometry.is_none() && (self.had_odometry || self.has_base) {
            return;
        }
        let odom = odometry.unwrap_or(Pose2::IDENTITY);
        let map_to_odom = pose.compose(&odom.inverse());
        let transforms = vec![
            transform(stamp, &map_frame, &odom_frame, &map_to_odom),
            transform(stamp, &odom_frame, &base_frame, &odom),
        ];
        self.push(t, Ros2Message::Tf(TfMessage { transforms }));
        if let Some(o) = odometry {
            self.push(
                t,
                Ros2Message::Odometry(Box::new(planar_odometry(
                    header(&odom_frame),
                    &base_frame,
                    &o,
                ))),
            );
        }
    }

    /// The messages built since the last call, oldest first.
    pub fn take(&mut self) -> Vec<Stamped> {
        self.queue.drain(..).collect()
    }

    /// Messages dropped because the shell did not take them in time.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }
}

/// A map snapshot as an OccupancyGrid in the map frame (0 free, 100
/// occupied, −1 unknown), at its resolution or coarser to stay within
/// [`MAP_MAX_CELLS`]; `None` for an empty map.
pub fn grid_message(snapshot: &MapSnapshot) -> Option<OccupancyGrid> {
    use crate::map::cls::grid::{FREE, OCCUPIED};
    if snapshot.map.is_empty() {
        return None;
    }
    let mut cfg = GridConfig {
        resolution: snapshot.resolution,
        ..GridConfig::default()
    };
    // Coarsened before rendering: a grid is drawn once.
    while cfg.resolution < 10.0 && {
        let (_, cols, rows) = grid_extent(&snapshot.map, &cfg);
        cols * rows > MAP_MAX_CELLS as f64
    } {
        cfg.resolution *= 2.0;
    }
    let grid = occupancy_grid(&snapshot.map, &cfg).ok()?;
    Some(OccupancyGrid {
        header: Header {
            stamp: snapshot.stamp,
            frame_id: snapshot.frame.clone(),
        },
        map_load_time: snapshot.stamp,
        resolution: grid.resolution as f32,
        width: u32::try_from(grid.width).ok()?,
        height: u32::try_from(grid.height).ok()?,
        origin_position: Vector3 {
            x: grid.origin[0],
            y: grid.origin[1],
            z: 0.0,
        },
        origin_orientation: Quaternion::from_yaw(0.0),
        data: grid
            .cells
            .iter()
            .map(|&v| match v {
                FREE => 0,
                OCCUPIED => 100,
                _ => -1,
            })
            .collect(),
    })
}

/// `message` as it goes out on DDS beside a base's own ROS 2 driver
/// (`base_is_ros2`), which publishes `/odom` and `odom` → `base_frame`
/// itself: those are left out (`None`, or the other transforms only).
/// Anything else is passed through as it is, uncopied.
pub fn for_dds<'a>(
    message: &'a Ros2Message,
    base_is_ros2: bool,
    base_frame: &str,
) -> Option<Cow<'a, Ros2Message>> {
    match message {
        Ros2Message::Odometry(_) if base_is_ros2 => None,
        Ros2Message::Tf(tf) if base_is_ros2 => {
            let transforms: Vec<TransformStamped> = tf
                .transforms
                .iter()
                .filter(|t| t.child_frame_id != base_frame)
                .cloned()
                .collect();
            (!transforms.is_empty())
                .then_some(Cow::Owned(Ros2Message::Tf(TfMessage { transforms })))
        }
        other => Some(Cow::Borrowed(other)),
    }
}

/// A map snapshot as lines for RViz and Foxglove: the walls (the CLS map's
/// actual segments) solid, its frontiers (virtual segments) dashed, and the
/// pose graph's loop edges; one marker each, replaced by the next message
/// (an empty one is deleted). `None` for an empty map, as the grid.
pub fn marker_message(snapshot: &MapSnapshot) -> Option<MarkerArray> {
    if snapshot.map.is_empty() {
        return None;
    }
    let point = |p: [f64; 2]| Vector3 {
        x: p[0],
        y: p[1],
        z: 0.0,
    };
    let walls: Vec<Vector3> = snapshot
        .map
        .actual_segments()
        .flat_map(|s| [point(s.start()), point(s.end())])
        .collect();
    let mut frontiers = Vec::new();
    for s in snapshot.map.virtual_segments() {
        let (a, b) = (s.start(), s.end());
        let length = s.length();
        let mut from = 0.0;
        while from < length {
            let to = (from + DASH).min(length);
            let at = |d: f64| {
                [
                    a[0] + (b[0] - a[0]) * d / length,
                    a[1] + (b[1] - a[1]) * d / length,
                ]
            };
            frontiers.extend([point(at(from)), point(at(to))]);
            from = to + DASH_GAP;
        }
    }
    let loops: Vec<Vector3> = snapshot
        .loop_edges
        .iter()
        .flat_map(|&[a, b]| [point(a), point(b)])
        .collect();
    let rgba = |r, g, b| ColorRgba { r, g, b, a: 1.0 };
    // Stamped zero ("the latest transform"): a viewer joining late, with
    // another fixed frame, still places the latched markers.
    let marker = |id: i32, ns: &str, points: Vec<Vector3>, width: f64, color| Marker {
        header: Header {
            stamp: Time::default(),
            frame_id: snapshot.frame.clone(),
        },
        ns: ns.into(),
        id,
        kind: Marker::LINE_LIST,
        action: if points.is_empty() {
            Marker::DELETE
        } else {
            Marker::ADD
        },
        orientation: Quaternion::from_yaw(0.0),
        scale: Vector3 {
            x: width,
            y: 0.0,
            z: 0.0,
        },
        color,
        points,
        ..Marker::default()
    };
    Some(MarkerArray {
        markers: vec![
            marker(0, "walls", walls, 0.05, rgba(0.1, 0.1, 0.1)),
            marker(1, "frontiers", frontiers, 0.03, rgba(1.0, 0.55, 0.0)),
            marker(2, "loop_edges", loops, 0.02, rgba(0.1, 0.7, 0.2)),
        ],
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::geometry::BeamFault;

    fn scan(t: f64) -> RangeScan {
        RangeScan {
            t,
            angle_min: -std::f64::consts::FRAC_PI_2,
            angle_increment: 0.5f64.to_radians(),
            ranges: (0..361)
                .map(|i| {
                    if i == 7 {
                        Err(BeamFault::NoReturn)
                    } else {
                        Ok(2.0)
                    }
                })
                .collect(),
        }
    }

    #[test]
    fn the_transforms_chain_to_the_pose() {
        let mut out = Ros2Outbox::new(
            1_700_000_000.0,
            Pose2::new(0.2, 0.0, 0.0),
            8.183,
            &Ros2Section::default(),
            false,
        );
        let pose = Pose2::new(3.0, -1.0, 0.7);
        let odom = Pose2::new(10.0, 4.0, -2.0);
        let cov = [[0.01, 0.0, 0.0], [0.0, 0.02, 0.0], [0.0, 0.0, 0.003]];
        out.scan(&scan(5.0), pose, &cov, Some(odom));
        out.scan(&scan(5.1), pose, &cov, None);
        let all = out.take();
        let topics: Vec<String> = all.iter().map(|m| m.message.topic()).collect();
        assert_eq!(
            topics,
            [
                "/tf_static",
                "/scan",
                "/pose",
                "/tf",
                "/odom",
                "/scan",
                "/pose"
            ],
            "the second scan has no odometry while a base is there: no transforms, \
             so odom does not jump"
        );
        let Ros2Message::Tf(tf) = &all[3].message else {
            panic!()
        };
        let as_pose =
            |t: &TransformStamped| Pose2::new(t.translation.x, t.translation.y, t.rotation.yaw());
        assert_eq!(tf.transforms[0].header.frame_id, "map");
        assert_eq!(tf.transforms[0].child_frame_id, "odom");
        assert_eq!(tf.transforms[1].child_frame_id, "base_link");
        let chained = as_pose(&tf.transforms[0]).compose(&as_pose(&tf.transforms[1]));
        assert!((chained.x - pose.x).abs() < 1e-9 && (chained.y - pose.y).abs() < 1e-9);
        assert!((chained.theta - pose.theta).abs() < 1e-9);
        let Ros2Message::Pose(p) = &all[2].message else {
            panic!()
        };
        assert_eq!(p.pose.covariance[0], 0.01);
        assert_eq!(p.pose.covariance[35], 0.003);
        let Ros2Message::Scan(s) = &all[1].message else {
            panic!()
        };
        assert!(s.ranges[7].is_infinite() && s.ranges[0] == 2.0);
        assert_eq!(s.header.frame_id, "laser");
        // The scan's stamp is its first beam's: before the pose's.
        assert!(s.header.stamp.as_nanos() < p.header.stamp.as_nanos());
        assert!(all[1].stamp_ns.abs_diff(1_700_000_005_000_000_000) < 1000);
        assert!(out.take().is_empty());
    }

    #[test]
    fn frames_are_named_by_the_config_and_a_ros2_base_keeps_its_own_odometry() {
        let settings = Ros2Section {
            map_frame: "world".into(),
            odom_frame: "r1/odom".into(),
            base_frame: "r1/base".into(),
            laser_frame: "r1/lms".into(),
            ..Ros2Section::default()
        };
        let mut out = Ros2Outbox::new(0.0, Pose2::IDENTITY, 8.183, &settings, true);
        let cov = [[0.0; 3]; 3];
        out.scan(&scan(1.0), Pose2::new(1.0, 2.0, 0.3), &cov, None);
        out.scan(
            &scan(1.1),
            Pose2::new(1.0, 2.0, 0.3),
            &cov,
            Some(Pose2::IDENTITY),
        );
        let all = out.take();
        let topics: Vec<String> = all.iter().map(|m| m.message.topic()).collect();
        // No /tf before the base's first odometry (map → odom would be a
        // guess that jumps when it comes).
        assert_eq!(
            topics,
            [
                "/tf_static",
                "/scan",
                "/pose",
                "/scan",
                "/pose",
                "/tf",
                "/odom"
            ]
        );
        let frames = |m: &Ros2Message| match m {
            Ros2Message::Tf(tf) | Ros2Message::TfStatic(tf) => tf
                .transforms
                .iter()
                .map(|t| (t.header.frame_id.clone(), t.child_frame_id.clone()))
                .collect::<Vec<_>>(),
            _ => panic!("{m:?}"),
        };
        let pair = |a: &str, b: &str| (a.to_string(), b.to_string());
        assert_eq!(frames(&all[0].message), [pair("r1/base", "r1/lms")]);
        assert_eq!(
            frames(&all[5].message),
            [pair("world", "r1/odom"), pair("r1/odom", "r1/base")]
        );
        let Ros2Message::Pose(p) = &all[2].message else {
            panic!()
        };
        assert_eq!(p.header.frame_id, "world");
        let Ros2Message::Scan(s) = &all[1].message else {
            panic!()
        };
        assert_eq!(s.header.frame_id, "r1/lms");
        // On DDS beside a ROS 2 base's driver, /odom and odom → base are
        // the driver's; the bag keeps them.
        let dds: Vec<Ros2Message> = all
            .iter()
            .filter_map(|m| for_dds(&m.message, true, "r1/base").map(Cow::into_owned))
            .collect();
        assert_eq!(dds.len(), 6);
        assert_eq!(frames(&dds[5]), [pair("world", "r1/odom")]);
        assert!(
            all.iter()
                .all(|m| for_dds(&m.message, false, "r1/base").as_deref() == Some(&m.message))
        );
        assert_eq!(TOPICS[ODOM_TOPIC].name, "odom");
    }

    #[test]
    fn the_map_goes_out_as_a_grid_and_as_lines_at_the_configured_rate() {
        use crate::map::cls::{ClsLoop, ClsMapConfig, ClsSegment, ClsShape, SegmentMode};
        let pts = [[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]];
        let segments = (0..4)
            .map(|i| {
                let mut s = ClsSegment::virtual_between(pts[i], pts[(i + 1) % 4]);
                if i != 1 {
                    s.mode = SegmentMode::Actual;
                }
                s
            })
            .collect();
        let shape = ClsShape {
            outer: ClsLoop::new(segments),
            holes: vec![],
        };
        let map = ClsMap::from_shapes(ClsMapConfig::default(), vec![shape]).unwrap();
        let settings = Ros2Section {
            map_interval: 2.0,
            map_resolution: 0.1,
            ..Ros2Section::default()
        };
        let mut out = Ros2Outbox::new(0.0, Pose2::IDENTITY, 8.183, &settings, false);
        assert!(out.map_due(1, 0.0));
        out.map(1, 0.0, Arc::new(map), vec![]);
        assert!(!out.map_due(2, 1.9) && !out.map_due(1, 5.0) && out.map_due(2, 2.0));
        let all = out.take();
        let Ros2Message::Map(grid) = &all[0].message else {
            panic!()
        };
        let grid = grid_message(grid).unwrap();
        assert!((grid.resolution - 0.1).abs() < 1e-6);
        let Ros2Message::ClsMap(lines) = &all[1].message else {
            panic!()
        };
        let markers = marker_message(lines).unwrap().markers;
        assert_eq!(all[1].message.topic(), "/cls_map");
        // Three walls solid (one line each); the 1 m frontier in dashes of
        // 0.2 m every 0.3 m: 4 dashes; no loop edges: deleted.
        assert_eq!(markers[0].points.len(), 3 * 2);
        assert_eq!(markers[1].points.len(), 4 * 2);
        let dash = &markers[1].points;
        assert!(((dash[1].y - dash[0].y).abs() - DASH).abs() < 1e-9);
        assert!(markers[..2].iter().all(|m| m.action == Marker::ADD));
        assert_eq!(markers[2].action, Marker::DELETE);
        assert!(markers.iter().all(|m| m.header.frame_id == "map"));
        // It survives its own codec.
        let cdr = all[1].message.encode().unwrap();
        assert_eq!(MarkerArray::from_cdr(&cdr).unwrap().markers, markers);
    }

    #[test]
    fn a_shell_that_does_not_take_its_messages_bounds_them() {
        let mut out = Ros2Outbox::new(0.0, Pose2::IDENTITY, 8.183, &Ros2Section::default(), false);
        for k in 0..200 {
            out.scan(&scan(f64::from(k)), Pose2::IDENTITY, &[[0.0; 3]; 3], None);
        }
        assert_eq!(out.take().len(), MAX_QUEUED);
        assert!(out.dropped() > 0);
    }
}
