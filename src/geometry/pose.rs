//! Planar rigid transforms (SE(2)) in metres and radians.

use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// Wraps an angle to (-π, π]: the base crate's, so odometry and the
/// mapper agree to the bit on every angle.
pub use clsmap_base::kinematics::wrap_angle;

/// Wraps an angle to [0, 2π), the range of a COG line direction.
pub fn wrap_angle_positive(a: f64) -> f64 {
    let r = a.rem_euclid(TAU);
    // rem_euclid can return TAU itself for tiny negative inputs.
    if r >= TAU { 0.0 } else { r }
}

/// A 2D pose: position (m) and heading (rad, counter-clockwise from +x).
///
/// Read as the transform from the pose's own frame into the parent frame:
/// `pose.transform_point(p_local)` gives the point in the parent frame.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Pose2 {
    pub x: f64,
    pub y: f64,
    pub theta: f64,
}

impl Pose2 {
    pub const IDENTITY: Pose2 = Pose2 {
        x: 0.0,
        y: 0.0,
        theta: 0.0,
    };

    /// Whether every component is finite (a log may carry NaN or ∞).
    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.theta.is_finite()
    }

    /// A pose with its heading wrapped to (-π, π].
    pub fn new(x: f64, y: f64, theta: f64) -> Self {
        Pose2 {
            x,
            y,
            theta: wrap_angle(theta),
        }
    }

    /// `self ∘ other`: first `other`, expressed in `self`'s frame.
    pub fn compose(&self, other: &Pose2) -> Pose2 {
        let (s, c) = self.theta.sin_cos();
        Pose2::new(
            self.x + c * other.x - s * other.y,
            self.y + s * other.x + c * other.y,
            self.theta + other.theta,
        )
    }

    /// The inverse transform.
    pub fn inverse(&self) -> Pose2 {
        let (s, c) = self.theta.sin_cos();
        Pose2::new(
            -(c * self.x + s * self.y),
            -(-s * self.x + c * self.y),
            -self.theta,
        )
    }

    /// `self⁻¹ ∘ other`: `other` expressed in the frame of `self`
    /// (the relative motion from `self` to `other`).
    pub fn between(&self, other: &Pose2) -> Pose2 {
        self.inverse().compose(other)
    }

    /// Maps a point from this pose's frame into the parent frame.
    pub fn transform_point(&self, p: [f64; 2]) -> [f64; 2] {
        let (s, c) = self.theta.sin_cos();
        [self.x + c * p[0] - s * p[1], self.y + s * p[0] + c * p[1]]
    }

    /// Linear interpolation between two poses (heading along the short arc);
    /// `f` = 0 gives `self`, 1 gives `other`.
    pub fn interpolate(&self, other: &Pose2, f: f64) -> Pose2 {
        Pose2::new(
            self.x + (other.x - self.x) * f,
            self.y + (other.y - self.y) * f,
            self.theta + wrap_angle(other.theta - self.theta) * f,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn close(a: &Pose2, b: &Pose2) -> bool {
        (a.x - b.x).abs() < 1e-12
            && (a.y - b.y).abs() < 1e-12
            && wrap_angle(a.theta - b.theta).abs() < 1e-12
    }

    #[test]
    fn compose_with_inverse_is_identity() {
        let p = Pose2::new(1.5, -2.0, 2.9);
        assert!(close(&p.compose(&p.inverse()), &Pose2::IDENTITY));
        assert!(close(&p.inverse().compose(&p), &Pose2::IDENTITY));
    }

    #[test]
    fn between_recovers_relative_motion() {
        let a = Pose2::new(3.0, 1.0, 3.0);
        let d = Pose2::new(0.3, -0.1, 0.4);
        let b = a.compose(&d);
        assert!(close(&a.between(&b), &d));
    }

    #[test]
    fn wrap_handles_edges() {
        assert!((wrap_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-PI) - PI).abs() < 1e-12);
        assert_eq!(wrap_angle_positive(-1e-300), 0.0);
        assert!((wrap_angle_positive(-0.5) - (TAU - 0.5)).abs() < 1e-12);
    }

    #[test]
    fn interpolate_takes_short_arc() {
        let a = Pose2::new(0.0, 0.0, 3.0);
        let b = Pose2::new(2.0, 0.0, -3.0);
        let m = a.interpolate(&b, 0.5);
        assert!((m.x - 1.0).abs() < 1e-12);
        assert!((wrap_angle(m.theta - PI)).abs() < 1e-9);
    }
}
