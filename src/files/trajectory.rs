//! Trajectories as TUM text: one pose per line, `t x y z qx qy qz qw`
//! (s, m, unit quaternion), so standard tools (evo, the TUM scripts) read
//! them. Planar poses are written with z = 0 and a rotation about z.
//!
//! Beside it, the same poses anchored to keyframes ([`AnchoredPose`],
//! `t keyframe x y theta`): the record a long run's TUM file is rebuilt
//! from when a loop closure moves the keyframes.

use crate::geometry::Pose2;
use std::io::{BufRead, Write};
use thiserror::Error;

/// A timestamped planar pose (s; map frame, m and rad).
pub type StampedPose = (f64, Pose2);

#[derive(Debug, Error)]
pub enum TrajectoryError {
    #[error("trajectory I/O failed")]
    Io(#[from] std::io::Error),
    #[error("line {line}: expected 8 numbers `t x y z qx qy qz qw`, found {found:?}")]
    Malformed { line: usize, found: String },
    #[error("line {line}: quaternion has zero length")]
    ZeroQuaternion { line: usize },
}

/// Writes a trajectory. Times keep microseconds (the CARMEN resolution),
/// positions micrometres.
pub fn write_tum<W: Write>(out: &mut W, poses: &[StampedPose]) -> Result<(), TrajectoryError> {
    writeln!(out, "{TUM_HEADER}")?;
    write_tum_lines(out, poses)
}

/// The header line [`write_tum`] starts with.
pub const TUM_HEADER: &str = "# timestamp x y z qx qy qz qw";

/// The pose lines of [`write_tum`] without the header, for appending to a
/// trajectory file.
pub fn write_tum_lines<W: Write>(
    out: &mut W,
    poses: &[StampedPose],
) -> Result<(), TrajectoryError> {
    for (t, p) in poses {
        let (s, c) = (p.theta / 2.0).sin_cos();
        writeln!(out, "{t:.6} {:.6} {:.6} 0 0 0 {s:.9} {c:.9}", p.x, p.y)?;
    }
    Ok(())
}

/// A trajectory pose and what it hangs on: the keyframe (its index in the
/// pose graph) it was taken after, with the pose in that keyframe's frame,
/// so a loop closure that moves the keyframe moves it too; or no keyframe
/// (a resumed session's scans before its first keyframe), with the pose in
/// the map frame, where it stays.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnchoredPose {
    /// Scan time (s).
    pub t: f64,
    pub keyframe: Option<usize>,
    /// In the keyframe's frame, or the map frame without one (m, rad).
    pub pose: Pose2,
}

impl AnchoredPose {
    /// The pose in the map frame with the keyframes at `keyframe_poses`;
    /// none if its keyframe is not among them.
    pub fn in_map(&self, keyframe_poses: &[Pose2]) -> Option<Pose2> {
        match self.keyframe {
            Some(k) => keyframe_poses.get(k).map(|p| p.compose(&self.pose)),
            None => Some(self.pose),
        }
    }
}

/// The header line of an anchored trajectory.
pub const ANCHORED_HEADER: &str = "# timestamp keyframe x y theta \
     (keyframe -: the pose in the map frame; else in that keyframe's frame)";

/// Writes anchored poses, one per line, without a header. Numbers are
/// written in their shortest exact form, so reading them back gives the
/// same poses bit for bit.
pub fn write_anchored_lines<W: Write>(
    out: &mut W,
    poses: &[AnchoredPose],
) -> Result<(), TrajectoryError> {
    for a in poses {
        let p = a.pose;
        match a.keyframe {
            Some(k) => writeln!(out, "{} {k} {} {} {}", a.t, p.x, p.y, p.theta)?,
            None => writeln!(out, "{} - {} {} {}", a.t, p.x, p.y, p.theta)?,
        }
    }
    Ok(())
}

/// Reads an anchored trajectory line by line, handing each pose to `each`
/// (so a long run's is never held in memory whole); returns how many
/// there were. Comments and blank lines are skipped; the first malformed
/// line is an error naming it.
pub fn read_anchored<R: BufRead>(
    input: R,
    mut each: impl FnMut(AnchoredPose) -> Result<(), TrajectoryError>,
) -> Result<usize, TrajectoryError> {
    let mut count = 0;
    for (idx, line) in input.lines().enumerate() {
        let line = line?;
        let body = line.trim();
        if body.is_empty() || body.starts_with('#') {
            continue;
        }
        let malformed = || TrajectoryError::Malformed {
            line: idx + 1,
            found: body.to_owned(),
        };
        let (t, rest) = body.split_once(' ').ok_or_else(malformed)?;
        let (keyframe, pose) = rest.trim_start().split_once(' ').ok_or_else(malformed)?;
        let [t] = finite_numbers(t).ok_or_else(malformed)?;
        let [x, y, theta] = finite_numbers(pose).ok_or_else(malformed)?;
        let keyframe = match keyframe {
            "-" => None,
            k => Some(k.parse::<usize>().map_err(|_| malformed())?),
        };
        each(AnchoredPose {
            t,
            keyframe,
            pose: Pose2::new(x, y, theta),
        })?;
        count += 1;
    }
    Ok(count)
}

/// Exactly `N` whitespace-separated finite numbers, or `None`: the line
/// check shared by the TUM and relations readers, which both report any
/// failure as one malformed-line error.
pub(crate) fn finite_numbers<const N: usize>(text: &str) -> Option<[f64; N]> {
    let values: Vec<f64> = text
        .split_ascii_whitespace()
        .map(str::parse::<f64>)
        .collect::<Result<_, _>>()
        .ok()?;
    let values: [f64; N] = values.try_into().ok()?;
    values.iter().all(|v| v.is_finite()).then_some(values)
}

/// Reads a TUM trajectory, projecting each pose onto the plane (yaw of the
/// quaternion, z dropped). Comments (`#`) and blank lines are skipped.
pub fn read_tum<R: BufRead>(input: R) -> Result<Vec<StampedPose>, TrajectoryError> {
    let mut poses = Vec::new();
    for (idx, line) in input.lines().enumerate() {
        let line = line?;
        let number = idx + 1;
        let body = line.trim();
        if body.is_empty() || body.starts_with('#') {
            continue;
        }
        let malformed = || TrajectoryError::Malformed {
            line: number,
            found: body.to_owned(),
        };
        let [t, x, y, _z, qx, qy, qz, qw] = finite_numbers(body).ok_or_else(malformed)?;
        let norm2 = qx * qx + qy * qy + qz * qz + qw * qw;
        if norm2 <= f64::EPSILON {
            return Err(TrajectoryError::ZeroQuaternion { line: number });
        }
        // Yaw of a (possibly non-planar) rotation; scale-free, so an
        // unnormalised quaternion gives the same angle.
        let yaw = (2.0 * (qw * qz + qx * qy)).atan2(norm2 - 2.0 * (qy * qy + qz * qz));
        poses.push((t, Pose2::new(x, y, yaw)));
    }
    Ok(poses)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::geometry::wrap_angle;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn round_trip(
            raw in proptest::collection::vec(
                (0.0f64..2e9, -1e3f64..1e3, -1e3f64..1e3, -3.2f64..3.2), 0..20)
        ) {
            let poses: Vec<StampedPose> =
                raw.iter().map(|&(t, x, y, th)| (t, Pose2::new(x, y, th))).collect();
            let mut buf = Vec::new();
            write_tum(&mut buf, &poses).unwrap();
            let back = read_tum(&buf[..]).unwrap();
            prop_assert_eq!(back.len(), poses.len());
            for ((ta, a), (tb, b)) in poses.iter().zip(&back) {
                prop_assert!((ta - tb).abs() <= 1e-6);
                prop_assert!((a.x - b.x).abs() <= 1e-6 && (a.y - b.y).abs() <= 1e-6);
                prop_assert!(wrap_angle(a.theta - b.theta).abs() <= 1e-8);
            }
        }
    }

    proptest! {
        #[test]
        fn anchored_poses_read_back_bit_for_bit(
            raw in proptest::collection::vec(
                (0.0f64..2e9, proptest::option::of(0usize..100_000),
                 -1e3f64..1e3, -1e3f64..1e3, -3.2f64..3.2), 0..20)
        ) {
            let poses: Vec<AnchoredPose> = raw
                .iter()
                .map(|&(t, keyframe, x, y, th)| AnchoredPose { t, keyframe, pose: Pose2::new(x, y, th) })
                .collect();
            let mut buf = format!("{ANCHORED_HEADER}\n").into_bytes();
            write_anchored_lines(&mut buf, &poses).unwrap();
            let mut back = Vec::new();
            let n = read_anchored(&buf[..], |a| { back.push(a); Ok(()) }).unwrap();
            prop_assert_eq!(n, poses.len());
            prop_assert_eq!(back, poses);
        }
    }

    #[test]
    fn an_anchored_pose_moves_with_its_keyframe() {
        let relative = Pose2::new(1.0, 0.0, 0.0);
        let on_second = AnchoredPose {
            t: 1.0,
            keyframe: Some(1),
            pose: relative,
        };
        let loose = AnchoredPose {
            t: 2.0,
            keyframe: None,
            pose: relative,
        };
        let keyframes = [
            Pose2::IDENTITY,
            Pose2::new(2.0, 1.0, std::f64::consts::FRAC_PI_2),
        ];
        let moved = on_second.in_map(&keyframes).unwrap();
        assert!((moved.x - 2.0).abs() < 1e-12 && (moved.y - 2.0).abs() < 1e-12);
        assert_eq!(loose.in_map(&keyframes), Some(relative));
        assert_eq!(on_second.in_map(&keyframes[..1]), None);
        for bad in ["1 x 0 0 0", "1 2 0 0", "1 - 0 0 nan", "1"] {
            let text = format!("# c\n{bad}\n");
            assert!(
                matches!(
                    read_anchored(text.as_bytes(), |_| Ok(())),
                    Err(TrajectoryError::Malformed { line: 2, .. })
                ),
                "{bad}"
            );
        }
    }

    #[test]
    fn reads_yaw_from_a_general_quaternion() {
        // 90° about z, scaled by 2: yaw must still be π/2.
        let s = std::f64::consts::FRAC_1_SQRT_2 * 2.0;
        let text = format!("1.0 0 0 0 0 0 {s} {s}\n");
        let p = read_tum(text.as_bytes()).unwrap();
        assert!((p[0].1.theta - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
    }

    #[test]
    fn malformed_lines_are_reported_with_their_number() {
        let text = "# header\n1 0 0 0 0 0 0 1\n2 0 0 0 0 0 1\n";
        assert!(matches!(
            read_tum(text.as_bytes()),
            Err(TrajectoryError::Malformed { line: 3, .. })
        ));
        let zero = "1 0 0 0 0 0 0 0\n";
        assert!(matches!(
            read_tum(zero.as_bytes()),
            Err(TrajectoryError::ZeroQuaternion { line: 1 })
        ));
    }
}
