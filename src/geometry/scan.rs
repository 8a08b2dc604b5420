//! A range scan in SI units, the form every source (serial driver,
//! recording, CARMEN log, simulator) is converted into before mapping.

use serde::{Deserialize, Serialize};

/// Why a beam carries no usable distance.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum BeamFault {
    /// No echo (LMS "not valid", or a log's no-return value such as 81.91 m).
    NoReturn,
    /// Dazzled, overflow, low signal, channel error or any other sensor code.
    SensorCode,
    /// Beyond the configured maximum range.
    OutOfRange,
}

/// One scan: beams at `angle_min + i * angle_increment` in the sensor
/// frame (rad, counter-clockwise, the LMS200 sweeps right to left).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RangeScan {
    /// Time of the scan (s); for the LMS200 the mid-sweep time corrected
    /// for transmission, for logs their own timestamp.
    pub t: f64,
    /// Angle of beam 0 (rad), -π/2 for a 180° scan.
    pub angle_min: f64,
    /// Angular step between beams (rad).
    pub angle_increment: f64,
    /// One entry per beam: distance in metres, or why there is none.
    pub ranges: Vec<Result<f64, BeamFault>>,
}

impl RangeScan {
    /// Angle of beam `i` in the sensor frame (rad).
    pub fn angle(&self, i: usize) -> f64 {
        self.angle_min + i as f64 * self.angle_increment
    }

    /// Field of view covered by the beams (rad).
    pub fn fov(&self) -> f64 {
        self.angle_increment * (self.ranges.len().saturating_sub(1)) as f64
    }
}
