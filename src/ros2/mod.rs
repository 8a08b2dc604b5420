//! ROS 2 on the wire: the messages clsmap exchanges with ROS 2 tools, in
//! their CDR form ([`cdr`], [`msg`]), and rosbag2 bags in MCAP ([`bag`]).

pub mod bag;
pub mod cdr;
pub mod msg;

pub use cdr::{CdrError, CdrReader, CdrWriter};
pub use msg::{
    ByteArray, ColorRgba, DiagnosticArray, DiagnosticStatus, Header, LaserScan, Marker,
    MarkerArray, OccupancyGrid, Odometry, PoseWithCovariance, PoseWithCovarianceStamped,
    Quaternion, RosMessage, TfMessage, Time, TransformStamped, Twist, Vector3,
};
