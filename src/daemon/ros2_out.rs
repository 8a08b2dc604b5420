//! What the daemon tells ROS 2 about each scan, as messages: the scan, the
//! pose estimate with its covariance, the odometry, and the transforms of
//! REP 105 (`map` → `odom` from the localizer, `odom` → `base_link` from the
//! base's odometry, `base_link` → `laser` from the mounting, once, static).
//!
//! Sans-IO, like the core it belongs to: [`Ros2Outbox`] turns a scan and
//! its pose into stamped messages; a shell writes them into a bag (or, later,
//! onto DDS). Times are the daemon's clock (s since its start) plus the wall
//! clock at that start, so stamps are ROS times (ns since the epoch).

use std::collections::VecDeque;
use std::sync::Arc;

use crate::map::cls::{ClsMap, GridConfig, occupancy_grid};

use crate::geometry::{Pose2, RangeScan};
use crate::input::bag::laser_scan;
use crate::input::lms200::lms200_scan_timing;
use crate::ros2::msg::{PoseWithCovariance, TransformStamped, TwistWithCovariance};
use crate::ros2::{
    DiagnosticArray, DiagnosticStatus, Header, LaserScan, OccupancyGrid, Odometry,
    PoseWithCovarianceStamped, Quaternion, RosMessage, TfMessage, Time, Vector3,
};

/// REP 105 frame names.
pub const MAP_FRAME: &str = "map";
pub const ODOM_FRAME: &str = "odom";
pub const BASE_FRAME: &str = "base_link";
pub const LASER_FRAME: &str = "laser";

/// `/map` is sent at most this often (s), and only when the map changed.
pub const MAP_EVERY: f64 = 5.0;
/// Cell side of `/map` (m), coarsened (doubled) until the grid has at most
/// [`MAP_MAX_CELLS`] cells: DDS carries a megabyte or two well, not tens.
pub const MAP_RESOLUTION: f64 = 0.05;
pub const MAP_MAX_CELLS: usize = 2_000_000;

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
    Map(MapSnapshot),
}

/// The CLS map at one time, shared (cloning it is the loop's one cost).
#[derive(Debug, Clone)]
pub struct MapSnapshot {
    pub map: Arc<ClsMap>,
    pub stamp: Time,
}

impl PartialEq for MapSnapshot {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.map, &other.map) && self.stamp == other.stamp
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
pub const TOPICS: [Ros2Topic; 7] = [
    topic::<LaserScan>("scan", false, 10),
    topic::<PoseWithCovarianceStamped>("pose", false, 10),
    topic::<Odometry>("odom", false, 10),
    topic::<TfMessage>("tf", false, 100),
    topic::<TfMessage>("tf_static", true, 1),
    topic::<OccupancyGrid>("map", true, 1),
    topic::<DiagnosticArray>("diagnostics", false, 10),
];

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
    /// limit (m).
    pub fn new(epoch: f64, mount: Pose2, reach: f64) -> Self {
        Ros2Outbox {
            epoch,
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
    /// when the map does) is due at `t`: changed, and [`MAP_EVERY`] since
    /// the last.
    pub fn map_due(&self, version: u64, t: f64) -> bool {
        self.map_sent
            .is_none_or(|(v, at)| v != version && t - at >= MAP_EVERY)
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

    /// Queues `map` (at `version`) for `/map` at `t`.
    pub fn map(&mut self, version: u64, t: f64, map: Arc<ClsMap>) {
        self.map_sent = Some((version, t));
        let stamp = Time::from_secs(self.epoch + t).unwrap_or_default();
        self.push(t, Ros2Message::Map(MapSnapshot { map, stamp }));
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
        if !self.static_sent {
            self.static_sent = true;
            let tf = transform(stamp, BASE_FRAME, LASER_FRAME, &self.mount);
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
        let msg = laser_scan(&wall, LASER_FRAME, self.reach, time_increment, scan_time);
        self.push(t, Ros2Message::Scan(msg));
        let header = |frame: &str| Header {
            stamp,
            frame_id: frame.into(),
        };
        self.push(
            t,
            Ros2Message::Pose(Box::new(PoseWithCovarianceStamped {
                header: header(MAP_FRAME),
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
        if odometry.is_none() && self.had_odometry {
            return;
        }
        let odom = odometry.unwrap_or(Pose2::IDENTITY);
        let map_to_odom = pose.compose(&odom.inverse());
        let transforms = vec![
            transform(stamp, MAP_FRAME, ODOM_FRAME, &map_to_odom),
            transform(stamp, ODOM_FRAME, BASE_FRAME, &odom),
        ];
        self.push(t, Ros2Message::Tf(TfMessage { transforms }));
        if let Some(o) = odometry {
            self.push(
                t,
                Ros2Message::Odometry(Box::new(Odometry {
                    header: header(ODOM_FRAME),
                    child_frame_id: BASE_FRAME.into(),
                    pose: PoseWithCovariance {
                        position: Vector3 {
                            x: o.x,
                            y: o.y,
                            z: 0.0,
                        },
                        orientation: Quaternion::from_yaw(o.theta),
                        covariance: [0.0; 36],
                    },
                    twist: TwistWithCovariance::default(),
                })),
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

/// A map snapshot as an OccupancyGrid in `map` (0 free, 100 occupied,
/// −1 unknown), at [`MAP_RESOLUTION`] or coarser to stay within
/// [`MAP_MAX_CELLS`]; `None` for an empty map.
pub fn grid_message(snapshot: &MapSnapshot) -> Option<OccupancyGrid> {
    use crate::map::cls::grid::{FREE, OCCUPIED};
    if snapshot.map.is_empty() {
        return None;
    }
    let mut cfg = GridConfig {
        resolution: MAP_RESOLUTION,
        ..GridConfig::default()
    };
    let grid = loop {
        match occupancy_grid(&snapshot.map, &cfg) {
            Ok(g) if g.width * g.height <= MAP_MAX_CELLS => break g,
            Ok(_) | Err(crate::map::cls::GridError::TooLarge(_)) if cfg.resolution < 10.0 => {
                cfg.resolution *= 2.0;
            }
            _ => return None,
        }
    };
    Some(OccupancyGrid {
        header: Header {
            stamp: snapshot.stamp,
            frame_id: MAP_FRAME.into(),
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
        let mut out = Ros2Outbox::new(1_700_000_000.0, Pose2::new(0.2, 0.0, 0.0), 8.183);
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
    fn a_shell_that_does_not_take_its_messages_bounds_them() {
        let mut out = Ros2Outbox::new(0.0, Pose2::IDENTITY, 8.183);
        for k in 0..200 {
            out.scan(&scan(f64::from(k)), Pose2::IDENTITY, &[[0.0; 3]; 3], None);
        }
        assert_eq!(out.take().len(), MAX_QUEUED);
        assert!(out.dropped() > 0);
    }
}
