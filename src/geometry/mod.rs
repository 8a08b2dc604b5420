//! Points, poses, COG lines and line extraction.

pub mod pose;
pub mod scan;

pub use pose::{Pose2, wrap_angle, wrap_angle_positive};
pub use scan::{BeamFault, RangeScan};
