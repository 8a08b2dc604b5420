//! Polar range scan to Cartesian points in the robot frame.

use super::extract::ExtractionConfig;
use super::pose::Pose2;
use super::scan::RangeScan;

/// One valid range reading in the robot frame, with what the fit needs to
/// propagate its noise: the beam direction and the range standard deviation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct ScanPoint {
    /// Position in the robot frame (m).
    pub p: [f64; 2],
    /// Unit beam direction in the robot frame; range noise acts along it.
    pub beam: [f64; 2],
    /// Standard deviation of the range reading (m).
    pub sigma_range: f64,
    /// Index of the beam in the scan.
    pub beam_index: usize,
}

/// Whether a beam carries a range the extractor may use: error codes are
/// already `Err`, and non-finite, too-short or too-long readings are dropped
/// here so they never reach the fit.
pub(crate) fn usable_range(r: f64, cfg: &ExtractionConfig) -> bool {
    r.is_finite() && r >= cfg.min_range && r <= cfg.max_range
}

/// Appends the valid beams of `scan` to `out` as robot-frame points, in
/// scan order. `mount` is the laser's pose in the robot frame.
pub(crate) fn collect_points(
    scan: &RangeScan,
    mount: &Pose2,
    cfg: &ExtractionConfig,
    out: &mut Vec<ScanPoint>,
) {
    out.reserve(scan.ranges.len());
    // Beam angles advance by a constant step: rotate the unit vector
    // incrementally instead of calling sin/cos per beam, re-anchoring every
    // few beams so rounding cannot accumulate.
    let (ds, dc) = scan.angle_increment.sin_cos();
    let mut dir = [0.0, 0.0];
    for (i, reading) in scan.ranges.iter().enumerate() {
        if i % 32 == 0 {
            let (s, c) = (scan.angle(i) + mount.theta).sin_cos();
            dir = [c, s];
        } else {
            dir = [dir[0] * dc - dir[1] * ds, dir[0] * ds + dir[1] * dc];
        }
        let Ok(r) = *reading else { continue };
        if !usable_range(r, cfg) {
            continue;
        }
        out.push(ScanPoint {
            p: [mount.x + r * dir[0], mount.y + r * dir[1]],
            beam: dir,
            sigma_range: cfg.range_noise.sigma(r),
            beam_index: i,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::scan::BeamFault;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn drops_faults_and_out_of_limit_ranges() {
        let cfg = ExtractionConfig {
            max_range: 8.0,
            ..ExtractionConfig::default()
        };
        let scan = RangeScan {
            t: 0.0,
            angle_min: -FRAC_PI_2,
            angle_increment: FRAC_PI_2,
            ranges: vec![
                Ok(1.0),
                Err(BeamFault::NoReturn),
                Ok(9.0),
                Ok(f64::NAN),
                Ok(0.0),
            ],
        };
        let mut pts = Vec::new();
        collect_points(&scan, &Pose2::IDENTITY, &cfg, &mut pts);
        assert_eq!(pts.len(), 1);
        assert!((pts[0].p[0]).abs() < 1e-12 && (pts[0].p[1] + 1.0).abs() < 1e-12);
    }

    #[test]
    fn applies_the_mounting_pose_and_matches_direct_trigonometry() {
        let mount = Pose2::new(0.2, -0.1, 0.3);
        let n = 361;
        let scan = RangeScan {
            t: 0.0,
            angle_min: -FRAC_PI_2,
            angle_increment: std::f64::consts::PI / 360.0,
            ranges: (0..n).map(|i| Ok(1.0 + 0.01 * i as f64)).collect(),
        };
        let mut pts = Vec::new();
        collect_points(&scan, &mount, &ExtractionConfig::default(), &mut pts);
        assert_eq!(pts.len(), n);
        for (i, sp) in pts.iter().enumerate() {
            let r = 1.0 + 0.01 * i as f64;
            let a = scan.angle(i);
            let expect = mount.transform_point([r * a.cos(), r * a.sin()]);
            assert!((sp.p[0] - expect[0]).abs() < 1e-12, "beam {i}");
            assert!((sp.p[1] - expect[1]).abs() < 1e-12, "beam {i}");
        }
    }
}
