//! The paper's COG ("centre of gravity") line: a fitted line segment with
//! its direction, centroid, uncertainties and extent.

use serde::{Deserialize, Serialize};

use super::pose::{Pose2, wrap_angle_positive};

/// A directed line segment in the form of Zhang & Ghosh's COG line.
///
/// The direction follows the scan order, so for a wall seen by the laser the
/// free space (the sensor side) lies on the LEFT of `start -> end`. The
/// centre is the centroid of the fitted points, which lies on the line and is
/// the point where offset and direction errors are uncorrelated; that is why
/// `sigma_c` and `sigma_theta` can be kept as two independent numbers.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CogLine {
    /// Direction of the segment (rad) in [0, 2π), scan order.
    pub theta: f64,
    /// Centroid of the fitted points, x (m).
    pub xc: f64,
    /// Centroid of the fitted points, y (m).
    pub yc: f64,
    /// Standard deviation of `theta` (rad).
    pub sigma_theta: f64,
    /// Standard deviation of the centre across the line (m).
    pub sigma_c: f64,
    /// First fitted point projected onto the line (m); at a true end of
    /// the wall, half a beam spacing beyond it (where the end lies on
    /// average, see `geometry::ends`).
    pub start: [f64; 2],
    /// Last fitted point projected onto the line (m); likewise.
    pub end: [f64; 2],
    /// Number of range points the line was fitted to.
    pub n_points: usize,
    /// Which ends are true ends of the wall, with their along-line σ.
    #[serde(default, skip_serializing_if = "WallEnds::is_none")]
    pub wall_ends: WallEnds,
}

/// The ends of a line that are true ends of its wall — a corner with the
/// next surface, or a jamb where the range jumps away behind it — each
/// with the standard deviation of its position along the line (m). `None`
/// where the view of the wall stops for another reason: a nearer object
/// in front, the edge of the field of view, the range limit, or a wall
/// that goes on. A true end pins the line along its own direction, which
/// a corridor otherwise leaves free.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct WallEnds {
    pub start: Option<f64>,
    pub end: Option<f64>,
}

impl WallEnds {
    pub const NONE: WallEnds = WallEnds {
        start: None,
        end: None,
    };

    pub fn is_none(&self) -> bool {
        self.start.is_none() && self.end.is_none()
    }
}

impl CogLine {
    /// Builds a line from its direction and centre and the signed positions
    /// of its end points along the direction, measured from the centre (m).
    pub fn from_centre(
        theta: f64,
        centre: [f64; 2],
        s_start: f64,
        s_end: f64,
        sigma_theta: f64,
        sigma_c: f64,
        n_points: usize,
    ) -> CogLine {
        let theta = wrap_angle_positive(theta);
        let (s, c) = theta.sin_cos();
        CogLine {
            theta,
            xc: centre[0],
            yc: centre[1],
            sigma_theta,
            sigma_c,
            start: [centre[0] + c * s_start, centre[1] + s * s_start],
            end: [centre[0] + c * s_end, centre[1] + s * s_end],
            n_points,
            wall_ends: WallEnds::NONE,
        }
    }

    /// Distance from start to end (m).
    pub fn length(&self) -> f64 {
        (self.end[0] - self.start[0]).hypot(self.end[1] - self.start[1])
    }

    /// The segment cut into equal pieces at most `step` long (m), at least
    /// one and at most 2²⁰: the pieces' length and their middle points.
    /// How much of a line lies in a region is judged at these points.
    pub fn samples(&self, step: f64) -> (f64, impl Iterator<Item = [f64; 2]> + '_) {
        let len = self.length();
        let n = ((len / step).ceil() as usize).clamp(1, 1 << 20);
        let piece = len / n as f64;
        let points = (0..n).map(move |k| {
            let f = (k as f64 + 0.5) / n as f64;
            [
                self.start[0] + f * (self.end[0] - self.start[0]),
                self.start[1] + f * (self.end[1] - self.start[1]),
            ]
        });
        (piece, points)
    }

    /// Unit vector along the segment, `[cos θ, sin θ]`.
    pub fn direction(&self) -> [f64; 2] {
        let (s, c) = self.theta.sin_cos();
        [c, s]
    }

    /// Unit left normal `[-sin θ, cos θ]`; it points into free space.
    pub fn normal(&self) -> [f64; 2] {
        let (s, c) = self.theta.sin_cos();
        [-s, c]
    }

    /// The centroid `[xc, yc]` (m).
    pub fn centre(&self) -> [f64; 2] {
        [self.xc, self.yc]
    }

    /// The same line seen from the parent frame of `pose`: if `self` is in
    /// the robot frame and `pose` is the robot in the map, the result is in
    /// the map frame. Variances are unchanged (the pose is taken as exact).
    pub fn transformed(&self, pose: &Pose2) -> CogLine {
        let c = pose.transform_point(self.centre());
        CogLine {
            theta: wrap_angle_positive(self.theta + pose.theta),
            xc: c[0],
            yc: c[1],
            sigma_theta: self.sigma_theta,
            sigma_c: self.sigma_c,
            start: pose.transform_point(self.start),
            end: pose.transform_point(self.end),
            n_points: self.n_points,
            wall_ends: self.wall_ends,
        }
    }

    /// Normalised coefficients `(a, b, c)` of `a·x + b·y + c = 0`, with
    /// `(a, b)` the left normal: `a·x + b·y + c` is the signed distance,
    /// positive on the free-space side.
    pub fn line_coefficients(&self) -> (f64, f64, f64) {
        let [a, b] = self.normal();
        (a, b, -(a * self.xc + b * self.yc))
    }

    /// Signed distance of `p` from the infinite line (m), positive on the
    /// left (free-space) side.
    pub fn signed_distance(&self, p: [f64; 2]) -> f64 {
        let [a, b] = self.normal();
        a * (p[0] - self.xc) + b * (p[1] - self.yc)
    }

    /// Unsigned distance of `p` from the infinite line (m).
    pub fn distance_to_point(&self, p: [f64; 2]) -> f64 {
        self.signed_distance(p).abs()
    }

    /// Position of `p` along the line, measured from the centre (m).
    pub fn along(&self, p: [f64; 2]) -> f64 {
        let [dx, dy] = self.direction();
        dx * (p[0] - self.xc) + dy * (p[1] - self.yc)
    }

    /// Foot of the perpendicular from `p` onto the infinite line.
    pub fn project_point(&self, p: [f64; 2]) -> [f64; 2] {
        let s = self.along(p);
        let [dx, dy] = self.direction();
        [self.xc + s * dx, self.yc + s * dy]
    }

    /// Positions of start and end along the line from the centre (m);
    /// `s_start <= s_end` for a well-formed line.
    pub fn extent(&self) -> (f64, f64) {
        (self.along(self.start), self.along(self.end))
    }

    /// Standard deviation (m) of the line's position across itself at
    /// distance `s` along it from the centre: `σc² + (s·σθ)²`, first order.
    pub fn sigma_offset_at(&self, s: f64) -> f64 {
        (self.sigma_c * self.sigma_c + (s * self.sigma_theta).powi(2)).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::{FRAC_PI_2, PI, TAU};

    fn wall() -> CogLine {
        // A wall at x = 2 seen from the origin: points run towards +y.
        CogLine::from_centre(FRAC_PI_2, [2.0, 0.5], -1.0, 1.5, 0.01, 0.002, 40)
    }

    #[test]
    fn free_space_is_on_the_left() {
        let l = wall();
        assert!(l.signed_distance([0.0, 0.0]) > 0.0);
        assert!((l.signed_distance([0.0, 0.0]) - 2.0).abs() < 1e-12);
        let (a, b, c) = l.line_coefficients();
        assert!((a * 0.0 + b * 0.0 + c - 2.0).abs() < 1e-12);
        assert!((a.hypot(b) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn extent_and_length_agree() {
        let l = wall();
        let (s0, s1) = l.extent();
        assert!((s0 + 1.0).abs() < 1e-12 && (s1 - 1.5).abs() < 1e-12);
        assert!((l.length() - 2.5).abs() < 1e-12);
        let f = l.project_point([5.0, 0.0]);
        assert!((f[0] - 2.0).abs() < 1e-12 && f[1].abs() < 1e-12);
    }

    #[test]
    fn uncertainty_grows_away_from_centre() {
        let l = wall();
        assert!((l.sigma_offset_at(0.0) - 0.002).abs() < 1e-15);
        assert!(l.sigma_offset_at(2.0) > l.sigma_offset_at(1.0));
    }

    proptest! {
        #[test]
        fn transformed_composes_with_pose(
            theta in 0.0..TAU, x in -5.0..5.0f64, y in -5.0..5.0f64,
            a in (-5.0..5.0f64, -5.0..5.0f64, -PI..PI),
            b in (-5.0..5.0f64, -5.0..5.0f64, -PI..PI),
        ) {
            let l = CogLine::from_centre(theta, [x, y], -0.7, 1.1, 0.01, 0.003, 9);
            let pa = Pose2::new(a.0, a.1, a.2);
            let pb = Pose2::new(b.0, b.1, b.2);
            let twice = l.transformed(&pb).transformed(&pa);
            let once = l.transformed(&pa.compose(&pb));
            prop_assert!((twice.xc - once.xc).abs() < 1e-9);
            prop_assert!((twice.yc - once.yc).abs() < 1e-9);
            prop_assert!(super::super::pose::wrap_angle(twice.theta - once.theta).abs() < 1e-9);
            prop_assert!((0.0..TAU).contains(&twice.theta));
            prop_assert!((twice.length() - l.length()).abs() < 1e-9);
            // The transform is rigid: signed distances are preserved.
            let p = [x + 0.3, y - 0.8];
            let d0 = l.signed_distance(p);
            let d1 = once.signed_distance(pa.compose(&pb).transform_point(p));
            prop_assert!((d0 - d1).abs() < 1e-9);
            prop_assert_eq!(once.sigma_c, l.sigma_c);
        }
    }
}
