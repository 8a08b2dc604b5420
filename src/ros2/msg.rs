//! The ROS 2 messages clsmap reads and writes, field for field as their
//! ROS 2 definitions (names, order, types), with their CDR form and the
//! `ros2msg` schema text that bags carry.

use serde::Deserialize;

use super::cdr::{CdrError, CdrReader, CdrWriter};

/// A ROS 2 message type.
pub trait RosMessage: Sized {
    /// Its full type name, e.g. `sensor_msgs/msg/LaserScan`.
    const TYPE: &'static str;
    /// Writes the fields (after the encapsulation header).
    fn write(&self, w: &mut CdrWriter);
    /// Reads the fields.
    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError>;
    /// Its definition and those of the types it uses, as a bag's schema.
    fn definition() -> String;

    fn to_cdr(&self) -> Vec<u8> {
        let mut w = CdrWriter::new();
        self.write(&mut w);
        w.finish()
    }

    fn from_cdr(bytes: &[u8]) -> Result<Self, CdrError> {
        let mut r = CdrReader::new(bytes)?;
        let m = Self::read(&mut r)?;
        r.finish()?;
        Ok(m)
    }
}

/// The field lists of every type used here, keyed by `pkg/Type`.
const FIELDS: &[(&str, &str)] = &[
    ("builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n"),
    (
        "std_msgs/Header",
        "builtin_interfaces/Time stamp\nstring frame_id\n",
    ),
    (
        "sensor_msgs/LaserScan",
        "std_msgs/Header header\nfloat32 angle_min\nfloat32 angle_max\nfloat32 angle_increment\n\
         float32 time_increment\nfloat32 scan_time\nfloat32 range_min\nfloat32 range_max\n\
         float32[] ranges\nfloat32[] intensities\n",
    ),
    ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n"),
    ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z\n"),
    (
        "geometry_msgs/Quaternion",
        "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    ),
    (
        "geometry_msgs/Pose",
        "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
    ),
    (
        "geometry_msgs/PoseWithCovariance",
        "geometry_msgs/Pose pose\nfloat64[36] covariance\n",
    ),
    (
        "geometry_msgs/Twist",
        "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n",
    ),
    (
        "geometry_msgs/TwistWithCovariance",
        "geometry_msgs/Twist twist\nfloat64[36] covariance\n",
    ),
    (
        "nav_msgs/Odometry",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n\
         geometry_msgs/TwistWithCovariance twist\n",
    ),
    (
        "geometry_msgs/Transform",
        "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation\n",
    ),
    (
        "geometry_msgs/TransformStamped",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform\n",
    ),
    (
        "geometry_msgs/PoseWithCovarianceStamped",
        "std_msgs/Header header\ngeometry_msgs/PoseWithCovariance pose\n",
    ),
    (
        "nav_msgs/MapMetaData",
        "builtin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\nuint32 height\n\
         geometry_msgs/Pose origin\n",
    ),
    (
        "nav_msgs/OccupancyGrid",
        "std_msgs/Header header\nnav_msgs/MapMetaData info\nint8[] data\n",
    ),
    ("diagnostic_msgs/KeyValue", "string key\nstring value\n"),
    (
        "diagnostic_msgs/DiagnosticStatus",
        "byte level\nstring name\nstring message\nstring hardware_id\n\
         diagnostic_msgs/KeyValue[] values\n",
    ),
    (
        "diagnostic_msgs/DiagnosticArray",
        "std_msgs/Header header\ndiagnostic_msgs/DiagnosticStatus[] status\n",
    ),
    (
        "tf2_msgs/TFMessage",
        "geometry_msgs/TransformStamped[] transforms\n",
    ),
    (
        "std_msgs/MultiArrayDimension",
        "string label\nuint32 size\nuint32 stride\n",
    ),
    (
        "std_msgs/MultiArrayLayout",
        "std_msgs/MultiArrayDimension[] dim\nuint32 data_offset\n",
    ),
    (
        "std_msgs/UInt8MultiArray",
        "std_msgs/MultiArrayLayout layout\nuint8[] data\n",
    ),
    ("builtin_interfaces/Duration", "int32 sec\nuint32 nanosec\n"),
    (
        "std_msgs/ColorRGBA",
        "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n",
    ),
    (
        "sensor_msgs/CompressedImage",
        "std_msgs/Header header\nstring format\nuint8[] data\n",
    ),
    ("visualization_msgs/UVCoordinate", "float32 u\nfloat32 v\n"),
    (
        "visualization_msgs/MeshFile",
        "string filename\nuint8[] data\n",
    ),
    (
        "visualization_msgs/Marker",
        "int32 ARROW=0\nint32 CUBE=1\nint32 SPHERE=2\nint32 CYLINDER=3\nint32 LINE_STRIP=4\n\
         int32 LINE_LIST=5\nint32 CUBE_LIST=6\nint32 SPHERE_LIST=7\nint32 POINTS=8\n\
         int32 TEXT_VIEW_FACING=9\nint32 MESH_RESOURCE=10\nint32 TRIANGLE_LIST=11\n\
         int32 ARROW_STRIP=12\nint32 ADD=0\nint32 MODIFY=0\nint32 DELETE=2\nint32 DELETEALL=3\n\
         std_msgs/Header header\nstring ns\nint32 id\nint32 type\nint32 action\n\
         geometry_msgs/Pose pose\ngeometry_msgs/Vector3 scale\nstd_msgs/ColorRGBA color\n\
         builtin_interfaces/Duration lifetime\nbool frame_locked\ngeometry_msgs/Point[] points\n\
         std_msgs/ColorRGBA[] colors\nstring texture_resource\n\
         sensor_msgs/CompressedImage texture\nvisualization_msgs/UVCoordinate[] uv_coordinates\n\
         string text\nstring mesh_resource\nvisualization_msgs/MeshFile mesh_file\n\
         bool mesh_use_embedded_materials\n",
    ),
    (
        "visualization_msgs/MarkerArray",
        "visualization_msgs/Marker[] markers\n",
    ),
];

fn fields_of(name: &str) -> &'static str {
    FIELDS
        .iter()
        .find(|(n, _)| *n == name)
        .map_or("", |(_, f)| f)
}

/// The `ros2msg` schema of `pkg/msg/Type`: its fields, then each type it
/// uses (depth first, once each) after a line of 80 `=` and `MSG: pkg/Type`,
/// as rosbag2 writes them.
fn schema(type_name: &str) -> String {
    let short = type_name.replace("/msg/", "/");
    let mut out = fields_of(&short).to_string();
    let mut seen = vec![short.clone()];
    let mut stack = vec![short];
    while let Some(t) = stack.pop() {
        for line in fields_of(&t).lines() {
            let ty = line.split_whitespace().next().unwrap_or("");
            let ty = ty.split('[').next().unwrap_or(ty);
            if ty.contains('/') && !seen.iter().any(|s| s == ty) {
                seen.push(ty.to_string());
                out.push_str(&"=".repeat(80));
                out.push_str(&format!("\nMSG: {ty}\n"));
                out.push_str(fields_of(ty));
                stack.push(ty.to_string());
            }
        }
    }
    out
}

/// `builtin_interfaces/Time`: seconds and nanoseconds since the epoch.
///
/// The types a subscriber receives also derive `Deserialize`, field for
/// field in the definition's order, for a DDS stack's serde-driven CDR
/// reader.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// The time `t` (s), rounded to the nanosecond; `None` if it does not
    /// fit (before 1970 minus 68 years or after 2038 plus 68).
    pub fn from_secs(t: f64) -> Option<Time> {
        if !t.is_finite() {
            return None;
        }
        let ns = (t * 1e9).round();
        let sec = (ns / 1e9).floor();
        let nanosec = ns - sec * 1e9;
        let sec = i32::try_from(sec as i64).ok()?;
        Some(Time {
            sec,
            nanosec: (nanosec as u32).min(999_999_999),
        })
    }

    pub fn as_secs(&self) -> f64 {
        f64::from(self.sec) + f64::from(self.nanosec) * 1e-9
    }

    /// Nanoseconds since the epoch (0 before it), as bags stamp messages.
    pub fn as_nanos(&self) -> u64 {
        u64::try_from(i64::from(self.sec) * 1_000_000_000 + i64::from(self.nanosec)).unwrap_or(0)
    }

    fn write(&self, w: &mut CdrWriter) {
        w.i32(self.sec);
        w.u32(self.nanosec);
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(Time {
            sec: r.i32()?,
            nanosec: r.u32()?,
        })
    }
}

/// `std_msgs/Header`.
#[derive(Debug, Clone, PartialEq, Eq, Default, Deserialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

impl Header {
    fn write(&self, w: &mut CdrWriter) {
        self.stamp.write(w);
        w.string(&self.frame_id);
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(Header {
            stamp: Time::read(r)?,
            frame_id: r.string()?,
        })
    }
}

/// `sensor_msgs/LaserScan` (REP 117: a range outside
/// `[range_min, range_max]` is invalid; `+inf` means no return, NaN an
/// erroneous reading). `header.stamp` is the time of the first beam.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LaserScan {
    pub header: Header,
    pub angle_min: f32,
    pub angle_max: f32,
    pub angle_increment: f32,
    pub time_increment: f32,
    pub scan_time: f32,
    pub range_min: f32,
    pub range_max: f32,
    pub ranges: Vec<f32>,
    pub intensities: Vec<f32>,
}

impl RosMessage for LaserScan {
    const TYPE: &'static str = "sensor_msgs/msg/LaserScan";

    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        for v in [
            self.angle_min,
            self.angle_max,
            self.angle_increment,
            self.time_increment,
            self.scan_time,
            self.range_min,
            self.range_max,
        ] {
            w.f32(v);
        }
        w.f32_seq(&self.ranges);
        w.f32_seq(&self.intensities);
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(LaserScan {
            header: Header::read(r)?,
            angle_min: r.f32()?,
            angle_max: r.f32()?,
            angle_increment: r.f32()?,
            time_increment: r.f32()?,
            scan_time: r.f32()?,
            range_min: r.f32()?,
            range_max: r.f32()?,
            ranges: r.f32_seq()?,
            intensities: r.f32_seq()?,
        })
    }

    fn definition() -> String {
        schema(Self::TYPE)
    }
}

/// `geometry_msgs/Vector3` and `geometry_msgs/Point` (same fields).
#[derive(Debug, Clone, Copy, PartialEq, Default, Deserialize)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

impl Vector3 {
    fn write(&self, w: &mut CdrWriter) {
        w.f64(self.x);
        w.f64(self.y);
        w.f64(self.z);
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(Vector3 {
            x: r.f64()?,
            y: r.f64()?,
            z: r.f64()?,
        })
    }
}

/// `geometry_msgs/Quaternion`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

impl Default for Quaternion {
    fn default() -> Self {
        Quaternion::from_yaw(0.0)
    }
}

impl Quaternion {
    /// A rotation by `yaw` (rad) about z.
    pub fn from_yaw(yaw: f64) -> Quaternion {
        let (s, c) = (0.5 * yaw).sin_cos();
        Quaternion {
            x: 0.0,
            y: 0.0,
            z: s,
            w: c,
        }
    }

    /// The rotation's heading about z (rad, −π..π); roll and pitch, which a
    /// planar robot does not have, are ignored.
    pub fn yaw(&self) -> f64 {
        let siny = 2.0 * (self.w * self.z + self.x * self.y);
        let cosy = 1.0 - 2.0 * (self.y * self.y + self.z * self.z);
        siny.atan2(cosy)
    }

    fn write(&self, w: &mut CdrWriter) {
        for v in [self.x, self.y, self.z, self.w] {
            w.f64(v);
        }
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(Quaternion {
            x: r.f64()?,
            y: r.f64()?,
            z: r.f64()?,
            w: r.f64()?,
        })
    }
}

fn write_covariance(w: &mut CdrWriter, c: &[f64; 36]) {
    for &v in c {
        w.f64(v);
    }
}

fn read_covariance(r: &mut CdrReader<'_>) -> Result<[f64; 36], CdrError> {
    let mut c = [0.0; 36];
    for v in &mut c {
        *v = r.f64()?;
    }
    Ok(c)
}

/// `geometry_msgs/PoseWithCovariance`: position, orientation and the 6×6
/// row-major covariance of (x, y, z, roll, pitch, yaw).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
pub struct PoseWithCovariance {
    pub position: Vector3,
    pub orientation: Quaternion,
    #[serde(deserialize_with = "covariance_36")]
    pub covariance: [f64; 36],
}

/// A `float64[36]` (a fixed array: 36 values, no count).
fn covariance_36<'de, D: serde::Deserializer<'de>>(d: D) -> Result<[f64; 36], D::Error> {
    struct Values;
    impl<'de> serde::de::Visitor<'de> for Values {
        type Value = [f64; 36];
        fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.write_str("36 float64 values")
        }
        fn visit_seq<A: serde::de::SeqAccess<'de>>(
            self,
            mut seq: A,
        ) -> Result<[f64; 36], A::Error> {
            let mut c = [0.0; 36];
            for (i, v) in c.iter_mut().enumerate() {
                *v = seq
                    .next_element()?
                    .ok_or_else(|| serde::de::Error::invalid_length(i, &self))?;
            }
            Ok(c)
        }
    }
    d.deserialize_tuple(36, Values)
}

impl Default for PoseWithCovariance {
    fn default() -> Self {
        PoseWithCovariance {
            position: Vector3::default(),
            orientation: Quaternion::default(),
            covariance: [0.0; 36],
        }
    }
}

/// `geometry_msgs/TwistWithCovariance`: linear and angular velocity and
/// their 6×6 covariance.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
pub struct TwistWithCovariance {
    pub linear: Vector3,
    pub angular: Vector3,
    #[serde(deserialize_with = "covariance_36")]
    pub covariance: [f64; 36],
}

impl Default for TwistWithCovariance {
    fn default() -> Self {
        TwistWithCovariance {
            linear: Vector3::default(),
            angular: Vector3::default(),
            covariance: [0.0; 36],
        }
    }
}

/// `nav_msgs/Odometry`: the pose of `child_frame_id` in `header.frame_id`
/// and its velocity in `child_frame_id`.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
pub struct Odometry {
    pub header: Header,
    pub child_frame_id: String,
    pub pose: PoseWithCovariance,
    pub twist: TwistWithCovariance,
}

impl RosMessage for Odometry {
    const TYPE: &'static str = "nav_msgs/msg/Odometry";

    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.string(&self.child_frame_id);
        self.pose.position.write(w);
        self.pose.orientation.write(w);
        write_covariance(w, &self.pose.covariance);
        self.twist.linear.write(w);
        self.twist.angular.write(w);
        write_covariance(w, &self.twist.covariance);
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(Odometry {
            header: Header::read(r)?,
            child_frame_id: r.string()?,
            pose: PoseWithCovariance {
                position: Vector3::read(r)?,
                orientation: Quaternion::read(r)?,
                covariance: read_covariance(r)?,
            },
            twist: TwistWithCovariance {
                linear: Vector3::read(r)?,
                angular: Vector3::read(r)?,
                covariance: read_covariance(r)?,
            },
        })
    }

    fn definition() -> String {
        schema(Self::TYPE)
    }
}

/// `geometry_msgs/PoseWithCovarianceStamped`: a pose estimate in
/// `header.frame_id` with its covariance.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
pub struct PoseWithCovarianceStamped {
    pub header: Header,
    pub pose: PoseWithCovariance,
}

impl RosMessage for PoseWithCovarianceStamped {
    const TYPE: &'static str = "geometry_msgs/msg/PoseWithCovarianceStamped";

    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        self.pose.position.write(w);
        self.pose.orientation.write(w);
        write_covariance(w, &self.pose.covariance);
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(PoseWithCovarianceStamped {
            header: Header::read(r)?,
            pose: PoseWithCovariance {
                position: Vector3::read(r)?,
                orientation: Quaternion::read(r)?,
                covariance: read_covariance(r)?,
            },
        })
    }

    fn definition() -> String {
        schema(Self::TYPE)
    }
}

/// `diagnostic_msgs/DiagnosticStatus`: one part's health (`level` 0 OK,
/// 1 WARN, 2 ERROR, 3 STALE) and its values.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct DiagnosticStatus {
    pub level: u8,
    pub name: String,
    pub message: String,
    pub hardware_id: String,
    pub values: Vec<(String, String)>,
}

/// `diagnostic_msgs/DiagnosticArray`.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct DiagnosticArray {
    pub header: Header,
    pub status: Vec<DiagnosticStatus>,
}

impl RosMessage for DiagnosticArray {
    const TYPE: &'static str = "diagnostic_msgs/msg/DiagnosticArray";

    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.count(self.status.len());
        for s in &self.status {
            w.u8(s.level);
            w.string(&s.name);
            w.string(&s.message);
            w.string(&s.hardware_id);
            w.count(s.values.len());
            for (k, v) in &s.values {
                w.string(k);
                w.string(v);
            }
        }
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        let header = Header::read(r)?;
        // A status is at least a level and three empty strings' lengths.
        let n = r.count(16)?;
        let status = (0..n)
            .map(|_| {
                let level = r.u8()?;
                let name = r.string()?;
                let message = r.string()?;
                let hardware_id = r.string()?;
                let k = r.count(8)?;
                let values = (0..k)
                    .map(|_| Ok((r.string()?, r.string()?)))
                    .collect::<Result<_, CdrError>>()?;
                Ok(DiagnosticStatus {
                    level,
                    name,
                    message,
                    hardware_id,
                    values,
                })
            })
            .collect::<Result<_, CdrError>>()?;
        Ok(DiagnosticArray { header, status })
    }

    fn definition() -> String {
        schema(Self::TYPE)
    }
}

/// `geometry_msgs/Twist`: a velocity command (m/s, rad/s), in the base's
/// frame for `/cmd_vel`.
#[derive(Debug, Clone, Copy, PartialEq, Default, Deserialize)]
pub struct Twist {
    pub linear: Vector3,
    pub angular: Vector3,
}

impl RosMessage for Twist {
    const TYPE: &'static str = "geometry_msgs/msg/Twist";

    fn write(&self, w: &mut CdrWriter) {
        self.linear.write(w);
        self.angular.write(w);
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(Twist {
            linear: Vector3::read(r)?,
            angular: Vector3::read(r)?,
        })
    }

    fn definition() -> String {
        schema(Self::TYPE)
    }
}

/// `nav_msgs/OccupancyGrid`: cells of `resolution` (m), `width` × `height`,
/// row-major from the cell at `origin` (its lower-left corner; rows go
/// along +y); 0 free, 100 occupied, −1 unknown.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct OccupancyGrid {
    pub header: Header,
    pub map_load_time: Time,
    pub resolution: f32,
    pub width: u32,
    pub height: u32,
    pub origin_position: Vector3,
    pub origin_orientation: Quaternion,
    pub data: Vec<i8>,
}

impl RosMessage for OccupancyGrid {
    const TYPE: &'static str = "nav_msgs/msg/OccupancyGrid";

    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        self.map_load_time.write(w);
        w.f32(self.resolution);
        w.u32(self.width);
        w.u32(self.height);
        self.origin_position.write(w);
        self.origin_orientation.write(w);
        w.i8_seq(&self.data);
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(OccupancyGrid {
            header: Header::read(r)?,
            map_load_time: Time::read(r)?,
            resolution: r.f32()?,
            width: r.u32()?,
            height: r.u32()?,
            origin_position: Vector3::read(r)?,
            origin_orientation: Quaternion::read(r)?,
            data: r.i8_seq()?,
        })
    }

    fn definition() -> String {
        schema(Self::TYPE)
    }
}

/// `geometry_msgs/TransformStamped`: the pose of `child_frame_id` in
/// `header.frame_id`.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
pub struct TransformStamped {
    pub header: Header,
    pub child_frame_id: String,
    pub translation: Vector3,
    pub rotation: Quaternion,
}

/// `tf2_msgs/TFMessage`.
#[derive(Debug, Clone, PartialEq, Default, Deserialize)]
pub struct TfMessage {
    pub transforms: Vec<TransformStamped>,
}

impl RosMessage for TfMessage {
    const TYPE: &'static str = "tf2_msgs/msg/TFMessage";

    fn write(&self, w: &mut CdrWriter) {
        w.count(self.transforms.len());
        for t in &self.transforms {
            t.header.write(w);
            w.string(&t.child_frame_id);
            t.translation.write(w);
            t.rotation.write(w);
        }
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        // A transform is at least 4 + 4 + 4 + 4 + 7 × 8 bytes.
        let n = r.count(72)?;
        let transforms = (0..n)
            .map(|_| {
                Ok(TransformStamped {
                    header: Header::read(r)?,
                    child_frame_id: r.string()?,
                    translation: Vector3::read(r)?,
                    rotation: Quaternion::read(r)?,
                })
            })
            .collect::<Result<_, CdrError>>()?;
        Ok(TfMessage { transforms })
    }

    fn definition() -> String {
        schema(Self::TYPE)
    }
}

/// `std_msgs/UInt8MultiArray` with an empty layout: a run of bytes, such
/// as the serial bytes of the LMS200 exactly as they came.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct ByteArray {
    pub data: Vec<u8>,
}

impl RosMessage for ByteArray {
    const TYPE: &'static str = "std_msgs/msg/UInt8MultiArray";

    fn write(&self, w: &mut CdrWriter) {
        w.count(0); // layout.dim
        w.u32(0); // layout.data_offset
        w.u8_seq(&self.data);
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        let dims = r.count(12)?;
        for _ in 0..dims {
            r.string()?;
            r.u32()?;
            r.u32()?;
        }
        r.u32()?;
        Ok(ByteArray { data: r.u8_seq()? })
    }

    fn definition() -> String {
        schema(Self::TYPE)
    }
}

/// `std_msgs/ColorRGBA`: red, green, blue and opacity, each 0–1.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ColorRgba {
    pub r: f32,
    pub g: f32,
    pub b: f32,
    pub a: f32,
}

impl ColorRgba {
    fn write(&self, w: &mut CdrWriter) {
        for v in [self.r, self.g, self.b, self.a] {
            w.f32(v);
        }
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        Ok(ColorRgba {
            r: r.f32()?,
            g: r.f32()?,
            b: r.f32()?,
            a: r.f32()?,
        })
    }
}

/// `visualization_msgs/Marker`, the fields a drawing of lines uses; the
/// texture, UV coordinates and mesh file (for meshes) are written empty
/// and skipped when read. Its layout is the one of Humble's later
/// releases and every distribution since.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Marker {
    pub header: Header,
    pub ns: String,
    pub id: i32,
    /// The definition's `type`: [`Marker::LINE_LIST`], ….
    pub kind: i32,
    /// [`Marker::ADD`] or [`Marker::DELETE`].
    pub action: i32,
    pub position: Vector3,
    pub orientation: Quaternion,
    /// For lines, `scale.x` is their width (m).
    pub scale: Vector3,
    pub color: ColorRgba,
    /// How long it stays (s, ns); zero: until replaced.
    pub lifetime: Time,
    pub frame_locked: bool,
    pub points: Vec<Vector3>,
    pub colors: Vec<ColorRgba>,
    pub text: String,
    pub mesh_resource: String,
    pub mesh_use_embedded_materials: bool,
}

impl Marker {
    pub const LINE_LIST: i32 = 5;
    pub const ADD: i32 = 0;
    pub const DELETE: i32 = 2;

    fn write(&self, w: &mut CdrWriter) {
        self.header.write(w);
        w.string(&self.ns);
        w.i32(self.id);
        w.i32(self.kind);
        w.i32(self.action);
        self.position.write(w);
        self.orientation.write(w);
        self.scale.write(w);
        self.color.write(w);
        self.lifetime.write(w);
        w.bool(self.frame_locked);
        w.count(self.points.len());
        for p in &self.points {
            p.write(w);
        }
        w.count(self.colors.len());
        for c in &self.colors {
            c.write(w);
        }
        w.string(""); // texture_resource
        Header::default().write(w); // texture: header, format, data
        w.string("");
        w.u8_seq(&[]);
        w.count(0); // uv_coordinates
        w.string(&self.text);
        w.string(&self.mesh_resource);
        w.string(""); // mesh_file: filename, data
        w.u8_seq(&[]);
        w.bool(self.mesh_use_embedded_materials);
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        let header = Header::read(r)?;
        let ns = r.string()?;
        let (id, kind, action) = (r.i32()?, r.i32()?, r.i32()?);
        let (position, orientation) = (Vector3::read(r)?, Quaternion::read(r)?);
        let (scale, color, lifetime) = (Vector3::read(r)?, ColorRgba::read(r)?, Time::read(r)?);
        let frame_locked = r.bool()?;
        let n = r.count(24)?;
        let points = (0..n).map(|_| Vector3::read(r)).collect::<Result<_, _>>()?;
        let n = r.count(16)?;
        let colors = (0..n)
            .map(|_| ColorRgba::read(r))
            .collect::<Result<_, _>>()?;
        r.string()?;
        Header::read(r)?;
        r.string()?;
        r.u8_seq()?;
        let n = r.count(8)?;
        for _ in 0..n {
            r.f32()?;
            r.f32()?;
        }
        let text = r.string()?;
        let mesh_resource = r.string()?;
        r.string()?;
        r.u8_seq()?;
        Ok(Marker {
            header,
            ns,
            id,
            kind,
            action,
            position,
            orientation,
            scale,
            color,
            lifetime,
            frame_locked,
            points,
            colors,
            text,
            mesh_resource,
            mesh_use_embedded_materials: r.bool()?,
        })
    }
}

/// `visualization_msgs/MarkerArray`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MarkerArray {
    pub markers: Vec<Marker>,
}

impl RosMessage for MarkerArray {
    const TYPE: &'static str = "visualization_msgs/msg/MarkerArray";

    fn write(&self, w: &mut CdrWriter) {
        w.count(self.markers.len());
        for m in &self.markers {
            m.write(w);
        }
    }

    fn read(r: &mut CdrReader<'_>) -> Result<Self, CdrError> {
        // A marker is at least 100 bytes (its fixed fields alone).
        let n = r.count(100)?;
        let markers = (0..n).map(|_| Marker::read(r)).collect::<Result<_, _>>()?;
        Ok(MarkerArray { markers })
    }

    fn definition() -> String {
        schema(Self::TYPE)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests;
