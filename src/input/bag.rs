//! Scans and odometry from a rosbag2 MCAP bag: `sensor_msgs/LaserScan` on
//! one topic, odometry from `nav_msgs/Odometry` on another or from the
//! `/tf` transforms between two frames, whatever laser recorded it.
//!
//! A scan's time is the middle of its sweep (its `header.stamp` is the
//! first beam's, plus half the sweep from `time_increment`), as for the
//! LMS200's own scans, and its odometry is interpolated there from the
//! samples around it, so scans wait (in a queue bounded by the odometry
//! rate) until a sample at or after their time has been read.
//!
//! Beams follow REP 117: a finite range within `[range_min, range_max]` is
//! an echo, `+inf` or beyond `range_max` no return, NaN, `-inf` or below
//! `range_min` a reading the sensor flagged.

use std::cell::Cell;
use std::path::Path;
use std::rc::Rc;

use crate::geometry::{BeamFault, Pose2, RangeScan};
use crate::ros2::bag::{BagMessage, BagReader, TopicInfo};
use crate::ros2::{LaserScan, Odometry, Quaternion, RosMessage, TfMessage};

use super::odometry::ScansAwaitingOdometry;
use super::{DeclaredMount, InputError, ScanRecord};

/// Where the odometry of a bag comes from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum BagOdometry {
    /// `nav_msgs/Odometry` messages on this topic.
    Topic(String),
    /// The transform of `child` (the base) in `parent` (the odometry
    /// frame), from `tf2_msgs/TFMessage` on `/tf`.
    Tf { parent: String, child: String },
    /// None: scans are mapped without odometry (a sensor-only bag).
    None,
}

/// Which topics of a bag to map.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BagTopics {
    /// `sensor_msgs/LaserScan` topic. Default `/scan`.
    pub scan: String,
    /// Default: `nav_msgs/Odometry` on `/odom`.
    pub odometry: BagOdometry,
}

impl Default for BagTopics {
    fn default() -> Self {
        BagTopics {
            scan: "/scan".into(),
            odometry: BagOdometry::Topic("/odom".into()),
        }
    }
}

/// What a missing topic's error suggests.
const HINT: &str = " (choose with --scan-topic, and --odom-topic, --tf or --no-odometry)";

/// The topic on which `/tf` transforms come.
pub const TF_TOPIC: &str = "/tf";
/// Scans held for odometry at most while a bag without a summary has
/// shown no odometry at all: then it has none on the topic asked for.
const MAX_SCANS_WITHOUT_ODOMETRY: usize = 2000;

impl BagTopics {
    fn odometry_topic(&self) -> Option<(&str, &'static str)> {
        match &self.odometry {
            BagOdometry::Topic(t) => Some((t, Odometry::TYPE)),
            BagOdometry::Tf { .. } => Some((TF_TOPIC, TfMessage::TYPE)),
            BagOdometry::None => None,
        }
    }

    /// The scan and odometry topics, with the type each must have.
    fn wanted(&self) -> Vec<(&str, &'static str)> {
        std::iter::once((self.scan.as_str(), LaserScan::TYPE))
            .chain(self.odometry_topic())
            .collect()
    }
}

/// A frame name without the leading `/` of ROS 1 habits.
fn frame(name: &str) -> &str {
    name.strip_prefix('/').unwrap_or(name)
}

/// The topic of the transforms that do not change.
pub const TF_STATIC_TOPIC: &str = "/tf_static";
/// Messages read at most for [`declared_laser_mount`]: a recorder writes
/// `/tf_static` once, at the start.
const MOUNT_MESSAGES: usize = 10_000;
/// Largest roll or pitch (rad) of a mounting read as level: a scanner
/// tilted more, or upside down, does not scan the plane its 2-D pose
/// says.
const MAX_TILT: f64 = 0.05;
/// The robot's frame when the odometry does not name it.
const BASE_FRAME: &str = "base_link";

/// A static transform's 2-D pose and whether it is level.
fn planar(translation: &crate::ros2::Vector3, rotation: &Quaternion) -> (Pose2, bool) {
    let q = rotation;
    let roll = (2.0 * (q.w * q.x + q.y * q.z)).atan2(1.0 - 2.0 * (q.x * q.x + q.y * q.y));
    let pitch = (2.0 * (q.w * q.y - q.z * q.x)).clamp(-1.0, 1.0).asin();
    let level = roll.abs() <= MAX_TILT && pitch.abs() <= MAX_TILT;
    (Pose2::new(translation.x, translation.y, q.yaw()), level)
}

/// The laser's pose on the robot as a bag's `/tf_static` gives it: the
/// frame of the first scan on `topics.scan` in the robot's frame (the
/// `--tf` child, else the odometry's `child_frame_id`, else `base_link`),
/// chained through the static transforms between them. A chain that is not
/// level (a scanner mounted upside down) is [`DeclaredMount::Varying`]: no
/// planar mounting to read. Messages that do not decode are passed over
/// here; the mapping names them.
pub fn declared_laser_mount(path: &Path, topics: &BagTopics) -> Result<DeclaredMount, InputError> {
    let reader = BagReader::open(path)?;
    let mut base = match &topics.odometry {
        BagOdometry::Tf { child, .. } => Some(frame(child).to_string()),
        _ => None,
    };
    let mut laser: Option<String> = None;
    // Child frame → (parent frame, pose in it, level).
    let mut statics: std::collections::HashMap<String, (String, Pose2, bool)> =
        std::collections::HashMap::new();
    for m in reader.take(MOUNT_MESSAGES) {
        let Ok(m) = m else { break };
        if m.topic.topic == topics.scan && laser.is_none() {
            if let Ok(scan) = LaserScan::from_cdr(&m.data) {
                laser = Some(frame(&scan.header.frame_id).to_string());
            }
        } else if m.topic.topic == TF_STATIC_TOPIC {
            if let Ok(tf) = TfMessage::from_cdr(&m.data) {
                for t in tf.transforms {
                    let (pose, level) = planar(&t.translation, &t.rotation);
                    statics.insert(
                        frame(&t.child_frame_id).to_string(),
                        (frame(&t.header.frame_id).to_string(), pose, level),
                    );
                }
            }
        } else if let BagOdometry::Topic(odom) = &topics.odometry
            && m.topic.topic == *odom
            && base.is_none()
            && let Ok(o) = Odometry::from_cdr(&m.data)
        {
            base = Some(frame(&o.child_frame_id).to_string());
        }
        if let Some(laser) = &laser
            && let Some(found) = mount_in(&statics, laser, base.as_deref().unwrap_or(BASE_FRAME))
        {
            return Ok(found);
        }
    }
    Ok(DeclaredMount::None)
}

/// The pose of frame `laser` in frame `base` through the static transforms
/// `statics` (child → parent, pose, level), if they link the two.
fn mount_in(
    statics: &std::collections::HashMap<String, (String, Pose2, bool)>,
    laser: &str,
    base: &str,
) -> Option<DeclaredMount> {
    let mut pose = Pose2::IDENTITY;
    let mut level = true;
    let mut at = laser;
    // A tree of frames has fewer links than frames; more is a cycle.
    for _ in 0..=statics.len() {
        if at == base {
            return Some(if level {
                DeclaredMount::Fixed(pose)
            } else {
                DeclaredMount::Varying
            });
        }
        let (parent, link, link_level) = statics.get(at)?;
        pose = link.compose(&pose);
        level &= link_level;
        at = parent;
    }
    None
}

/// Streams the scans of a bag with the odometry at each.
#[derive(Debug)]
pub struct BagScans {
    reader: BagReader,
    topics: BagTopics,
    pending: ScansAwaitingOdometry,
    /// Messages of the two topics seen (without a summary, how a missing
    /// topic is found).
    seen: [bool; 2],
    finished: bool,
    last_scan_t: Option<f64>,
    /// The break of a damaged bag, given once the scans before it are out.
    refused: Option<InputError>,
    /// Where the bytes read so far are reported (for a progress bar).
    progress: Option<Rc<Cell<u64>>>,
}

impl BagScans {
    /// Opens `path` (a `.mcap` file or a rosbag2 directory). When the bag
    /// has a summary, a missing topic or one of another type is refused
    /// here, before any scan is read.
    pub fn open(path: &Path, topics: BagTopics) -> Result<BagScans, InputError> {
        let reader = BagReader::open(path)?;
        if let Some(listed) = reader.summary_topics() {
            for (topic, type_name) in topics.wanted() {
                match listed.iter().find(|t| t.topic == topic) {
                    None => {
                        return Err(InputError::MissingTopic {
                            topic: topic.into(),
                            type_name,
                            available: format!("{}{}", describe(listed), HINT),
                        });
                    }
                    Some(t) => check_type(t, type_name)?,
                }
            }
        }
        let no_odometry = topics.odometry == BagOdometry::None;
        Ok(BagScans {
            reader,
            topics,
            pending: ScansAwaitingOdometry::default(),
            seen: [false, no_odometry],
            finished: false,
            last_scan_t: None,
            refused: None,
            progress: None,
        })
    }

    /// Reports the bytes of the bag read so far into `cell` as it goes.
    pub fn with_progress(mut self, cell: Rc<Cell<u64>>) -> Self {
        self.progress = Some(cell);
        self
    }

    /// Takes one message into the queue or the odometry track.
    fn take(&mut self, m: BagMessage) -> Result<(), InputError> {
        let (odom_topic, odom_type) = self.topics.odometry_topic().unwrap_or(("", ""));
        let skipped = |error| InputError::BagMessage {
            topic: m.topic.topic.clone(),
            log_time: m.log_time,
            error,
        };
        if m.topic.topic == self.topics.scan {
            check_type(&m.topic, LaserScan::TYPE)?;
            self.seen[0] = true;
            let msg = LaserScan::from_cdr(&m.data).map_err(skipped)?;
            let scan = range_scan(&msg);
            if let Some(previous) = self.last_scan_t.filter(|&p| scan.t <= p) {
                return Err(InputError::ScanOutOfOrder {
                    at: format!("{} message at {} ns", m.topic.topic, m.log_time),
                    t: scan.t,
                    previous,
                });
            }
            self.last_scan_t = Some(scan.t);
            self.pending.push_scan(scan, None);
            if !self.seen[1] && self.pending.waiting() > MAX_SCANS_WITHOUT_ODOMETRY {
                return Err(InputError::MissingTopic {
                    topic: odom_topic.into(),
                    type_name: odom_type,
                    available: format!(
                        "no odometry from it in the first {MAX_SCANS_WITHOUT_ODOMETRY} scans{HINT}"
                    ),
                });
            }
        } else if !odom_topic.is_empty() && m.topic.topic == odom_topic {
            check_type(&m.topic, odom_type)?;
            let at = format!("{} message at {} ns", m.topic.topic, m.log_time);
            let odometry = |error| InputError::BagOdometry {
                at: at.clone(),
                error,
            };
            match &self.topics.odometry {
                BagOdometry::Topic(_) => {
                    let o = Odometry::from_cdr(&m.data).map_err(skipped)?;
                    let p = &o.pose;
                    let pose = Pose2::new(p.position.x, p.position.y, p.orientation.yaw());
                    self.pending
                        .push_odometry(seconds(&o.header.stamp), pose)
                        .map_err(odometry)?;
                    self.seen[1] = true;
                }
                BagOdometry::None => {}
                BagOdometry::Tf { parent, child } => {
                    let tf = TfMessage::from_cdr(&m.data).map_err(skipped)?;
                    for t in tf.transforms.iter().filter(|t| {
                        frame(&t.header.frame_id) == frame(parent)
                            && frame(&t.child_frame_id) == frame(child)
                    }) {
                        let pose = Pose2::new(t.translation.x, t.translation.y, t.rotation.yaw());
                        self.pending
                            .push_odometry(seconds(&t.header.stamp), pose)
                            .map_err(odometry)?;
                        // Seen only when a transform of the frames asked
                        // for came: other /tf traffic is no odometry.
                        self.seen[1] = true;
                    }
                }
            }
        }
        Ok(())
    }

    /// At the end of the bag: a topic never seen is an error.
    fn missing_at_end(&self) -> Option<InputError> {
        let wanted = self.topics.wanted();
        let k = self.seen.iter().position(|s| !s)?;
        let (topic, type_name) = wanted[k];
        let available = match &self.topics.odometry {
            BagOdometry::Tf { parent, child } if k == 1 => {
                format!("no transform of {child} in {parent} in the whole bag{HINT}")
            }
            _ => format!("no message of it in the whole bag{HINT}"),
        };
        Some(InputError::MissingTopic {
            topic: topic.into(),
            type_name,
            available,
        })
    }
}

impl Iterator for BagScans {
    type Item = Result<ScanRecord, InputError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            // Without odometry to wait for, every scan is ready.
            let complete = self.finished || self.topics.odometry == BagOdometry::None;
            if let Some(record) = self.pending.pop(complete) {
                return Some(Ok(record));
            }
            if self.finished {
                // A break, once the scans before it are out.
                return self.refused.take().map(Err);
            }
            match self.reader.next() {
                None => {
                    self.finished = true;
                    if let Some(e) = self.missing_at_end() {
                        self.pending.clear();
                        return Some(Err(e));
                    }
                }
                Some(Err(e)) => {
                    // The scans before the break are still mapped.
                    self.refused = Some(e.into());
                    self.finished = true;
                }
                Some(Ok(m)) => {
                    if let Some(cell) = &self.progress {
                        cell.set(self.reader.bytes_read());
                    }
                    match self.take(m) {
                        Ok(()) => {}
                        Err(e) if e.is_skipped_item() => return Some(Err(e)),
                        Err(e) => {
                            self.finished = true;
                            self.pending.clear();
                            return Some(Err(e));
                        }
                    }
                }
            }
        }
    }
}

/// Refuses a topic whose type is not the one asked for.
fn check_type(t: &TopicInfo, type_name: &'static str) -> Result<(), InputError> {
    if t.type_name == type_name && t.encoding == "cdr" {
        Ok(())
    } else {
        Err(InputError::TopicType {
            topic: t.topic.clone(),
            found: format!("{} ({})", t.type_name, t.encoding),
            expected: type_name,
        })
    }
}

fn describe(topics: &[TopicInfo]) -> String {
    if topics.is_empty() {
        return "the bag has no topics".into();
    }
    let list: Vec<String> = topics
        .iter()
        .map(|t| format!("{} ({})", t.topic, t.type_name))
        .collect();
    format!("the bag has {}", list.join(", "))
}

/// A LaserScan as a [`RangeScan`] (see the module documentation).
///
/// LaserScan's angles and ranges are `f32`. Where a value is the `f32` of
/// a whole quarter degree (angles) or a whole millimetre (ranges), the
/// `f64` of that value is taken, as a text log's decimals or the LMS200's
/// integer millimetres give it; otherwise the `f32` as it is. Both lose
/// nothing the `f32` holds, and the same scan reads the same whatever it
/// came in.
pub fn range_scan(msg: &LaserScan) -> RangeScan {
    let n = msg.ranges.len();
    let sweep = f64::from(msg.time_increment) * n.saturating_sub(1) as f64;
    let sweep = if sweep.is_finite() { sweep } else { 0.0 };
    let (lo, hi) = (f64::from(msg.range_min), f64::from(msg.range_max));
    let ranges = msg
        .ranges
        .iter()
        .map(|&r| {
            let r = whole_millimetres(r);
            if r.is_nan() || r == f64::NEG_INFINITY {
                Err(BeamFault::SensorCode)
            } else if r == f64::INFINITY || (hi > 0.0 && r > hi) {
                Err(BeamFault::NoReturn)
            } else if r < lo || r <= 0.0 {
                Err(BeamFault::SensorCode)
            } else {
                Ok(r)
            }
        })
        .collect();
    RangeScan {
        t: seconds(&msg.header.stamp) + 0.5 * sweep,
        angle_min: quarter_degrees(msg.angle_min),
        angle_increment: quarter_degrees(msg.angle_increment),
        ranges,
    }
}

/// `v` (m) as the `f64` of a whole number of millimetres if it is one in
/// `f32`.
fn whole_millimetres(v: f32) -> f64 {
    let x = f64::from(v);
    let k = (x * 1000.0).round();
    let snapped = k / 1000.0;
    if x.is_finite() && k.abs() < 1e9 && snapped as f32 == v {
        snapped
    } else {
        x
    }
}

/// `a` (rad) as the `f64` of a whole number of quarter degrees if it is
/// one in `f32`: π / (720 / k), the form `π / 360` of a 0.5° log takes.
fn quarter_degrees(a: f32) -> f64 {
    use std::f64::consts::PI;
    let x = f64::from(a);
    let k = (x / PI * 720.0).round();
    if !x.is_finite() || k == 0.0 || k.abs() > 1e6 {
        return x;
    }
    let snapped = if 720.0 % k == 0.0 {
        PI / (720.0 / k)
    } else {
        PI * k / 720.0
    };
    if snapped as f32 == a { snapped } else { x }
}

/// A stamp as seconds: for a whole microsecond the `f64` nearest to it (as
/// a text log's six decimals parse, and the recordings' µs clock gives).
fn seconds(t: &crate::ros2::Time) -> f64 {
    if t.nanosec.is_multiple_of(1000) {
        (i64::from(t.sec) * 1_000_000 + i64::from(t.nanosec / 1000)) as f64 / 1e6
    } else {
        t.as_secs()
    }
}

/// A [`RangeScan`] as a LaserScan (the inverse of [`range_scan`]): the
/// stamp is the first beam's, `time_increment` (s) apart; no return and
/// beyond range are `+inf`, a flagged reading NaN (REP 117). `frame` is the
/// laser's frame id; `range_max` (m) the sensor's reach; `scan_time` (s)
/// the time from one scan to the next.
pub fn laser_scan(
    scan: &RangeScan,
    frame: &str,
    range_max: f64,
    time_increment: f64,
    scan_time: f64,
) -> LaserScan {
    let n = scan.ranges.len();
    let first_beam = scan.t - 0.5 * time_increment * n.saturating_sub(1) as f64;
    LaserScan {
        header: crate::ros2::Header {
            stamp: crate::ros2::Time::from_secs(first_beam).unwrap_or_default(),
            frame_id: frame.into(),
        },
        angle_min: scan.angle_min as f32,
        angle_max: scan.angle(n.saturating_sub(1)) as f32,
        angle_increment: scan.angle_increment as f32,
        time_increment: time_increment as f32,
        scan_time: scan_time as f32,
        range_min: 0.0,
        range_max: range_max as f32,
        ranges: scan
            .ranges
            .iter()
            .map(|r| match r {
                Ok(r) => *r as f32,
                Err(BeamFault::NoReturn | BeamFault::OutOfRange) => f32::INFINITY,
                Err(BeamFault::SensorCode) => f32::NAN,
            })
            .collect(),
        intensities: Vec::new(),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn a_mounting_is_chained_through_level_static_transforms() {
        let level = |x: f64, theta: f64| {
            let q = Quaternion::from_yaw(theta);
            planar(&crate::ros2::Vector3 { x, y: 0.0, z: 0.2 }, &q)
        };
        let mut statics = std::collections::HashMap::new();
        for (child, parent, (pose, is_level)) in [
            ("plate", "base_link", level(0.2, 0.0)),
            ("laser", "plate", level(0.1, 0.5)),
        ] {
            statics.insert(child.to_string(), (parent.to_string(), pose, is_level));
        }
        let Some(DeclaredMount::Fixed(m)) = mount_in(&statics, "laser", "base_link") else {
            panic!("no mounting");
        };
        assert!((m.x - 0.3).abs() < 1e-12 && m.y.abs() < 1e-12 && (m.theta - 0.5).abs() < 1e-12);
        // No link to the robot's frame: nothing declared.
        assert_eq!(mount_in(&statics, "laser", "base_footprint"), None);
        // Upside down (rolled half a turn): no planar mounting.
        let flipped = Quaternion {
            x: 1.0,
            y: 0.0,
            z: 0.0,
            w: 0.0,
        };
        let (pose, is_level) = planar(
            &crate::ros2::Vector3 {
                x: 0.1,
                y: 0.0,
                z: 0.0,
            },
            &flipped,
        );
        assert!(!is_level);
        statics.insert("laser".into(), ("plate".into(), pose, is_level));
        assert_eq!(
            mount_in(&statics, "laser", "base_link"),
            Some(DeclaredMount::Varying)
        );
        // A cycle ends.
        statics.insert("base_link".into(), ("laser".into(), Pose2::IDENTITY, true));
        assert_eq!(mount_in(&statics, "laser", "odom"), None);
    }
    use crate::ros2::bag::{BagWriter, Durability};
    use crate::ros2::msg::{Header, Quaternion, Time, TransformStamped, Vector3};

    fn scan_at(t: f64) -> LaserScan {
        LaserScan {
            header: Header {
                stamp: Time::from_secs(t).unwrap(),
                frame_id: "laser".into(),
            },
            angle_min: -1.0,
            angle_max: 1.0,
            angle_increment: 0.5,
            time_increment: 0.001,
            scan_time: 0.1,
            range_min: 0.1,
            range_max: 8.0,
            ranges: vec![1.0, f32::INFINITY, f32::NAN, 0.05, 9.0],
            intensities: vec![],
        }
    }

    fn odom_at(t: f64, x: f64) -> Odometry {
        let mut o = Odometry::default();
        o.header.stamp = Time::from_secs(t).unwrap();
        o.pose.position.x = x;
        o.pose.orientation = Quaternion::from_yaw(0.5);
        o
    }

    /// A bag with scans at 10.0, 10.1, … and odometry at 10.0, 10.05, …
    /// moving 1 m/s along x, on `/odom` and as `/tf` odom → base_link.
    fn bag(path: &Path, scans: usize) {
        let mut bag = BagWriter::create(path).unwrap();
        let mut s = bag
            .topic::<LaserScan>("/scan", Durability::Volatile)
            .unwrap();
        let mut o = bag
            .topic::<Odometry>("/odom", Durability::Volatile)
            .unwrap();
        let mut tf = bag.topic::<TfMessage>("/tf", Durability::Volatile).unwrap();
        for k in 0..2 * scans + 2 {
            let t = 10.0 + 0.05 * k as f64;
            let ns = (t * 1e9) as u64;
            if k % 2 == 0 && k / 2 < scans {
                bag.write(&mut s, ns, &scan_at(t)).unwrap();
            }
            bag.write(&mut o, ns, &odom_at(t, t - 10.0)).unwrap();
            let transform = TransformStamped {
                header: Header {
                    stamp: Time::from_secs(t).unwrap(),
                    frame_id: "odom".into(),
                },
                child_frame_id: "base_link".into(),
                translation: Vector3 {
                    x: 2.0 * (t - 10.0),
                    y: 0.0,
                    z: 0.0,
                },
                rotation: Quaternion::from_yaw(0.0),
            };
            bag.write(
                &mut tf,
                ns,
                &TfMessage {
                    transforms: vec![transform],
                },
            )
            .unwrap();
        }
        bag.finish().unwrap();
    }

    #[test]
    fn scans_get_the_odometry_at_their_mid_sweep() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("b.mcap");
        bag(&path, 20);
        let records: Vec<ScanRecord> = BagScans::open(&path, BagTopics::default())
            .unwrap()
            .map(Result::unwrap)
            .collect();
        assert_eq!(records.len(), 20);
        let r = &records[3];
        // Stamp 10.3 s, plus half of 4 × 1 ms.
        assert!((r.scan.t - 10.302).abs() < 1e-6, "{}", r.scan.t);
        let odom = r.odometry.unwrap();
        assert!((odom.x - 0.302).abs() < 1e-6 && (odom.theta - 0.5).abs() < 1e-9);
        assert_eq!(r.scan.ranges[0], Ok(1.0));
        assert_eq!(
            r.scan.ranges[1..],
            [
                Err(BeamFault::NoReturn),
                Err(BeamFault::SensorCode),
                Err(BeamFault::SensorCode),
                Err(BeamFault::NoReturn)
            ]
        );
        let tf = BagScans::open(
            &path,
            BagTopics {
                odometry: BagOdometry::Tf {
                    parent: "odom".into(),
                    child: "/base_link".into(),
                },
                ..BagTopics::default()
            },
        )
        .unwrap()
        .map(Result::unwrap)
        .nth(3)
        .unwrap();
        assert!((tf.odometry.unwrap().x - 0.604).abs() < 1e-6);
    }

    #[test]
    fn a_range_scan_survives_the_laser_scan() {
        let scan = RangeScan {
            t: 1_700_000_000.25,
            angle_min: -std::f64::consts::FRAC_PI_2,
            angle_increment: std::f64::consts::PI / 360.0,
            ranges: vec![
                Ok(1.5),
                Err(BeamFault::NoReturn),
                Err(BeamFault::SensorCode),
                Ok(8.0),
            ],
        };
        let msg = laser_scan(&scan, "laser", 8.183, 1e-4, 0.0267);
        assert_eq!(msg.header.frame_id, "laser");
        let back = range_scan(&LaserScan::from_cdr(&msg.to_cdr()).unwrap());
        assert!((back.t - scan.t).abs() < 1e-6, "{} {}", back.t, scan.t);
        assert_eq!(back.ranges, scan.ranges);
        assert!((back.angle_increment - scan.angle_increment).abs() < 1e-7);
    }

    #[test]
    fn f32_values_read_as_the_decimals_they_were() {
        assert_eq!(whole_millimetres(2.35), 2.35);
        assert_eq!(whole_millimetres(8.183), 8.183);
        let odd = 2.345_678_9_f32;
        assert_eq!(whole_millimetres(odd), f64::from(odd));
        use std::f64::consts::PI;
        assert_eq!(quarter_degrees((PI / 360.0) as f32), PI / 360.0);
        assert_eq!(quarter_degrees((-PI / 2.0) as f32), -PI / 2.0);
        assert_eq!(quarter_degrees((PI / 180.0) as f32), PI / 180.0);
        let hokuyo = (2.0 * PI / 1024.0) as f32;
        assert_eq!(quarter_degrees(hokuyo), f64::from(hokuyo));
        let t = crate::ros2::Time {
            sec: 1_100_000_000,
            nanosec: 123_456_000,
        };
        assert_eq!(seconds(&t), 1_100_000_000.123_456);
    }

    #[test]
    fn tf_between_frames_the_bag_lacks_is_named_not_mapped_without_odometry() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("b.mcap");
        bag(&path, 5);
        let topics = BagTopics {
            odometry: BagOdometry::Tf {
                parent: "odom".into(),
                child: "base_footprint".into(),
            },
            ..BagTopics::default()
        };
        let items: Vec<_> = BagScans::open(&path, topics).unwrap().collect();
        assert_eq!(items.len(), 1, "{items:?}");
        let e = items[0].as_ref().unwrap_err().to_string();
        assert!(e.contains("no transform of base_footprint in odom"), "{e}");
    }

    #[test]
    fn a_missing_topic_or_a_wrong_type_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("b.mcap");
        bag(&path, 3);
        let topics = |scan: &str, odom: &str| BagTopics {
            scan: scan.into(),
            odometry: BagOdometry::Topic(odom.into()),
        };
        let e = BagScans::open(&path, topics("/laser", "/odom")).unwrap_err();
        let text = e.to_string();
        assert!(matches!(e, InputError::MissingTopic { .. }));
        assert!(
            text.contains("/laser") && text.contains("/scan (sensor_msgs/msg/LaserScan)"),
            "{text}"
        );
        let e = BagScans::open(&path, topics("/odom", "/odom")).unwrap_err();
        assert!(matches!(e, InputError::TopicType { .. }), "{e}");
        assert!(e.to_string().contains("nav_msgs/msg/Odometry"), "{e}");
    }

    #[test]
    fn a_bag_cut_short_maps_up_to_the_cut_without_its_summary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("b.mcap");
        bag(&path, 4000);
        let bytes = std::fs::read(&path).unwrap();
        let cut = dir.path().join("cut.mcap");
        std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
        let items: Vec<_> = BagScans::open(&cut, BagTopics::default())
            .unwrap()
            .collect();
        let last = items.last().unwrap();
        assert!(
            matches!(
                last,
                Err(InputError::Bag(
                    crate::ros2::bag::BagError::EndsEarly { .. }
                ))
            ),
            "{last:?}"
        );
        let ok = items.iter().filter(|r| r.is_ok()).count();
        assert!(ok > 1000 && ok < 4000, "{ok}");
        // Without a summary a wrong topic is found as the bag is read.
        let e = BagScans::open(
            &cut,
            BagTopics {
                scan: "/odom".into(),
                ..BagTopics::default()
            },
        )
        .unwrap()
        .find_map(Result::err)
        .unwrap();
        assert!(matches!(e, InputError::TopicType { .. }), "{e}");
    }
}
