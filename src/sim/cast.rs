//! Simulated LMS200 scans by ray casting against a [`World`].

use super::rng::Rng;
use super::world::World;
use crate::geometry::{BeamFault, Pose2, RangeScan};

/// Largest range of the LMS200 in mm mode (m): 8183 mm.
pub const LMS200_MAX_RANGE_MM_MODE: f64 = 8.183;
/// Largest range of the LMS200 in cm mode (m): 8183 cm.
pub const LMS200_MAX_RANGE_CM_MODE: f64 = 81.83;

/// Beam layout and noise of a simulated laser.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanSpec {
    /// Number of beams.
    pub beams: usize,
    /// Angle of beam 0 in the sensor frame (rad).
    pub angle_min: f64,
    /// Angular step between beams (rad).
    pub angle_increment: f64,
    /// Beams whose true range exceeds this report `BeamFault::NoReturn` (m).
    pub max_range: f64,
    /// Standard deviation of the Gaussian range noise (m).
    pub range_sigma: f64,
    /// Ranges are rounded to multiples of this (m); 0 disables rounding
    /// (the LMS200 reports whole mm in mm mode, whole cm in cm mode).
    pub range_resolution: f64,
}

impl ScanSpec {
    /// The LMS200 at 180° / 0.5° (361 beams) in mm mode, no rounding.
    pub fn lms200_half_degree(range_sigma: f64) -> Self {
        ScanSpec {
            beams: 361,
            angle_min: -std::f64::consts::FRAC_PI_2,
            angle_increment: std::f64::consts::PI / 360.0,
            max_range: LMS200_MAX_RANGE_MM_MODE,
            range_sigma,
            range_resolution: 0.0,
        }
    }

    /// The LMS200 at 180° / 1° (181 beams) in mm mode, no rounding.
    pub fn lms200_one_degree(range_sigma: f64) -> Self {
        ScanSpec {
            beams: 181,
            angle_increment: std::f64::consts::PI / 180.0,
            ..ScanSpec::lms200_half_degree(range_sigma)
        }
    }
}

/// A scan of `world` from `sensor_pose` (the laser's pose in the map
/// frame), stamped `t` (s). Each beam returns the first wall along it plus
/// Gaussian noise; no wall within `max_range` (or a noisy reading beyond
/// it) gives `BeamFault::NoReturn`.
pub fn cast_scan(
    world: &World,
    sensor_pose: &Pose2,
    spec: &ScanSpec,
    t: f64,
    rng: &mut Rng,
) -> RangeScan {
    let origin = [sensor_pose.x, sensor_pose.y];
    let ranges = (0..spec.beams)
        .map(|i| {
            let a = sensor_pose.theta + spec.angle_min + i as f64 * spec.angle_increment;
            let (s, c) = a.sin_cos();
            let truth = world
                .cast_ray(origin, [c, s], spec.max_range)
                .ok_or(BeamFault::NoReturn)?;
            let mut r = (truth + rng.normal(spec.range_sigma)).max(0.0);
            if spec.range_resolution > 0.0 {
                r = (r / spec.range_resolution).round() * spec.range_resolution;
            }
            if r > spec.max_range {
                return Err(BeamFault::NoReturn);
            }
            Ok(r)
        })
        .collect();
    RangeScan {
        t,
        angle_min: spec.angle_min,
        angle_increment: spec.angle_increment,
        ranges,
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn noise_free_scan_sees_the_walls() {
        let w = World::loop_around_block();
        let scan = cast_scan(
            &w,
            &Pose2::new(1.0, 5.0, 0.0),
            &ScanSpec::lms200_half_degree(0.0),
            2.5,
            &mut Rng::new(1),
        );
        assert_eq!(scan.ranges.len(), 361);
        assert_eq!(scan.t, 2.5);
        // Straight ahead hits the block 1 m away; beam 0 (straight right)
        // hits the outer wall y = 0, 5 m away.
        assert!((scan.ranges[180].unwrap() - 1.0).abs() < 1e-12);
        assert!((scan.ranges[0].unwrap() - 5.0).abs() < 1e-12);
    }

    #[test]
    fn beyond_max_range_is_no_return() {
        let w = World::corridor(30.0, 2.0, None);
        let scan = cast_scan(
            &w,
            &Pose2::new(10.0, 0.0, 0.0),
            &ScanSpec::lms200_one_degree(0.01),
            0.0,
            &mut Rng::new(3),
        );
        assert_eq!(scan.ranges[90], Err(BeamFault::NoReturn));
        assert!(scan.ranges[0].is_ok());
    }

    #[test]
    fn rounding_gives_whole_millimetres() {
        let w = World::room_with_boxes();
        let spec = ScanSpec {
            range_resolution: 0.001,
            ..ScanSpec::lms200_half_degree(0.01)
        };
        let scan = cast_scan(&w, &Pose2::new(4.0, 3.0, 0.2), &spec, 0.0, &mut Rng::new(9));
        for r in scan.ranges.iter().flatten() {
            assert!((r * 1000.0 - (r * 1000.0).round()).abs() < 1e-6);
        }
    }
}
