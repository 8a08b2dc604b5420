//! Weighted least squares for the pose from matched lines: normal equations
//! of point-on-line and direction residuals, the paper's rotation (weighted
//! circular mean) and the observability analysis.
//!
//! Unknowns are the robot pose `(x, y, θ)` in the map frame. A point `q` of
//! a local line (robot frame) maps to `p = R(θ)·q + t`; its residual against
//! the matched map line `G` is the signed distance `n_G·p + c_G`, with
//! Jacobian `[n_x, n_y, n_G·(J·R(θ)·q)]`, `J` the 90° rotation. The
//! direction residual is `wrap(θ_L + θ − θ_G)` with Jacobian `[0, 0, 1]`.

use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};

use crate::geometry::{CogLine, Pose2, principal_axes, wrap_angle};

/// Farthest apart (m, beyond 3 σ) a local and a map wall end may be and
/// still be taken for the same end.
const WALL_END_GATE: f64 = 0.25;
/// In the final least squares a wall end agrees within this many σ plus
/// a slack (m) for the pose still settling.
const WALL_END_FINAL_SIGMAS: f64 = 4.0;
const WALL_END_FINAL_SLACK: f64 = 0.02;

/// Which residuals each matched pair contributes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LineConstraints {
    /// The paper's pair: the local centre lies on the map line, and the two
    /// directions agree. Independent to first order (centroid
    /// parametrisation), so their weights are exact.
    CentreAndDirection,
    /// The local start, centre and end on the map line, no direction row.
    /// The three rows share the local line's two degrees of freedom, so
    /// their weights over-count its information; kept for comparison.
    EndPointsAndCentre,
}

/// Lower bounds applied to the lines' standard deviations before weighting,
/// so a noise-free model or an over-confident fit cannot produce infinite
/// weights.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SigmaFloors {
    pub sigma_c: f64,
    pub sigma_theta: f64,
}

/// Accumulated normal equations `H·Δ = −g` and the weighted squared
/// residual `χ²`.
///
/// Line rows are weighted by a Cauchy kernel (iteratively reweighted least
/// squares): a row whose normalised residual is `z = r/σ` gets weight
/// `1/(1 + (z/k)²)` on top of `1/σ²`, so one wrong match (a door recess
/// taken for the wall 15 cm in front of it) cannot drag the pose, while
/// rows within a few σ keep almost their full weight. `k = 0` turns the
/// kernel off. The prior is never down-weighted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct NormalEquations {
    pub h: Matrix3<f64>,
    pub g: Vector3<f64>,
    /// Σ of robust-weighted squared normalised residuals of the line rows.
    pub chi2: f64,
    pub rows: usize,
    robust_scale: f64,
    /// Covariance (x, y, θ) of the predicted pose, when known; see
    /// [`NormalEquations::with_prediction`].
    prediction_cov: Option<Matrix3<f64>>,
}

impl Default for NormalEquations {
    fn default() -> Self {
        NormalEquations::new(0.0)
    }
}

impl NormalEquations {
    /// Empty equations with Cauchy kernel scale `robust_scale` (in σ).
    pub fn new(robust_scale: f64) -> Self {
        NormalEquations {
            h: Matrix3::zeros(),
            g: Vector3::zeros(),
            chi2: 0.0,
            rows: 0,
            robust_scale,
            prediction_cov: None,
        }
    }

    /// Equations for a pose predicted with covariance `cov`: a map wall end
    /// less certain along its wall than the prediction is then not used.
    /// Its error is the same in every scan that sees it, so scan after scan
    /// it would pull the pose all the way to that error (a wall end past a
    /// door recess, mapped from 4–5 m 4 cm off, took the simulated
    /// corridor's pose 6 cm off along it with exact odometry); left out, it learns from the
    /// scans instead (fusion at keyframes) and pins the pose once it knows
    /// more than the prediction does.
    pub fn with_prediction(mut self, cov: Matrix3<f64>) -> Self {
        self.prediction_cov = Some(cov);
        self
    }

    /// Whether a map wall end of along-wall σ `sigma` (m) on a wall of
    /// direction `d` may constrain the pose (see `with_prediction`).
    fn end_usable(&self, sigma: f64, d: [f64; 2]) -> bool {
        self.prediction_cov.is_none_or(|p| {
            let var =
                d[0] * d[0] * p[(0, 0)] + 2.0 * d[0] * d[1] * p[(0, 1)] + d[1] * d[1] * p[(1, 1)];
            sigma * sigma <= var
        })
    }

    fn add_row(&mut self, j: Vector3<f64>, r: f64, var: f64) {
        let z2 = r * r / var;
        let robust = if self.robust_scale > 0.0 {
            1.0 / (1.0 + z2 / (self.robust_scale * self.robust_scale))
        } else {
            1.0
        };
        let w = robust / var;
        self.h += j * j.transpose() * w;
        self.g += j * (w * r);
        self.chi2 += robust * z2;
        self.rows += 1;
    }

    /// Adds the prior `pose ~ N(predicted, Λ⁻¹)` evaluated at `pose`.
    pub fn add_prior(&mut self, info: &Matrix3<f64>, pose: &Pose2, predicted: &Pose2) {
        let e = Vector3::new(
            pose.x - predicted.x,
            pose.y - predicted.y,
            wrap_angle(pose.theta - predicted.theta),
        );
        self.h += info;
        self.g += info * e;
        self.chi2 += (e.transpose() * info * e)[0];
    }

    /// Adds the residuals of local line `local` (robot frame) against map
    /// line `map` at `pose`.
    pub fn add_match(
        &mut self,
        local: &CogLine,
        map: &CogLine,
        pose: &Pose2,
        mode: LineConstraints,
        floors: &SigmaFloors,
    ) {
        let local_sc = local.sigma_c.max(floors.sigma_c);
        let local_st = local.sigma_theta.max(floors.sigma_theta);
        let map_sc = map.sigma_c.max(floors.sigma_c);
        let map_st = map.sigma_theta.max(floors.sigma_theta);
        let (s, c) = pose.theta.sin_cos();
        let n = map.normal();
        let centre = local.centre();
        // True wall ends seen in both: the local end lies at the map end
        // along the wall (the one constraint a corridor's walls lack).
        let d = map.direction();
        let ends = [
            (
                local.wall_ends.start,
                map.wall_ends.start,
                local.start,
                map.start,
            ),
            (local.wall_ends.end, map.wall_ends.end, local.end, map.end),
        ];
        for (sl, sm, q, m) in ends {
            let (Some(sl), Some(sm)) = (sl, sm) else {
                continue;
            };
            if !self.end_usable(sm, d) {
                continue;
            }
            let rq = [c * q[0] - s * q[1], s * q[0] + c * q[1]];
            let p = [rq[0] + pose.x, rq[1] + pose.y];
            let r = d[0] * (p[0] - m[0]) + d[1] * (p[1] - m[1]);
            let var = sl.max(floors.sigma_c).powi(2) + sm.max(floors.sigma_c).powi(2);
            // Ends farther apart than this are not the same end (another
            // jamb of the same wall, a wall seen in part): while the robust
            // iterations still move the pose, ends within 25 cm are tried
            // and the kernel tames wrong ones; the final least squares
            // (no kernel, pose converged) keeps only ends that agree.
            let gate = if self.robust_scale > 0.0 {
                WALL_END_GATE + 3.0 * var.sqrt()
            } else {
                WALL_END_FINAL_SIGMAS * var.sqrt() + WALL_END_FINAL_SLACK
            };
            if r.abs() > gate {
                continue;
            }
            let j = Vector3::new(d[0], d[1], -d[0] * rq[1] + d[1] * rq[0]);
            self.add_row(j, r, var);
        }
        let mut point_row = |q: [f64; 2], local_var: f64| {
            let rq = [c * q[0] - s * q[1], s * q[0] + c * q[1]];
            let p = [rq[0] + pose.x, rq[1] + pose.y];
            let along_map = map.along(p);
            let var = local_var + map_sc * map_sc + (along_map * map_st).powi(2);
            let j = Vector3::new(n[0], n[1], -n[0] * rq[1] + n[1] * rq[0]);
            self.add_row(j, map.signed_distance(p), var);
        };
        match mode {
            LineConstraints::CentreAndDirection => {
                point_row(centre, local_sc * local_sc);
                let r = wrap_angle(local.theta + pose.theta - map.theta);
                let var = local_st * local_st + map_st * map_st;
                self.add_row(Vector3::new(0.0, 0.0, 1.0), r, var);
            }
            LineConstraints::EndPointsAndCentre => {
                for q in [local.start, centre, local.end] {
                    let s_local = local.along(q);
                    point_row(q, local_sc * local_sc + (s_local * local_st).powi(2));
                }
            }
        }
    }

    /// The Gauss–Newton step `Δ = −H⁻¹·g`, or `None` if `H` is not positive
    /// definite.
    pub fn step(&self) -> Option<Vector3<f64>> {
        let chol = self.h.cholesky()?;
        let d = chol.solve(&(-self.g));
        d.iter().all(|v| v.is_finite()).then_some(d)
    }

    /// The translation-only step with θ held fixed (the paper's translation
    /// solve): the 2×2 block of the normal equations.
    pub fn translation_step(&self) -> Option<Vector2<f64>> {
        let h: Matrix2<f64> = self.h.fixed_view::<2, 2>(0, 0).into_owned();
        let g = Vector2::new(self.g[0], self.g[1]);
        let chol = h.cholesky()?;
        let d = chol.solve(&(-g));
        d.iter().all(|v| v.is_finite()).then_some(d)
    }
}

/// Weighted circular mean of angles (rad): the direction of `Σ wᵢ·e^{iαᵢ}`.
/// Unlike a weighted arithmetic mean of wrapped differences it has no seam
/// at ±π. `None` if the weights cancel (no preferred direction).
pub(crate) fn weighted_circular_mean(items: impl Iterator<Item = (f64, f64)>) -> Option<f64> {
    let (mut sx, mut sy, mut sw) = (0.0, 0.0, 0.0);
    for (a, w) in items {
        sx += w * a.cos();
        sy += w * a.sin();
        sw += w;
    }
    // Normalised resultant length: near zero when the angles spread evenly.
    if sw <= 0.0 || sx.hypot(sy) <= 1e-9 * sw {
        return None;
    }
    Some(sy.atan2(sx))
}

/// The least observable translation direction of the line constraints and
/// its marginal standard deviation (m): the smallest eigenvalue of the
/// translation information with θ marginalised out (Schur complement).
/// An infinite deviation means that direction is not constrained at all.
pub(crate) fn weakest_translation(h_lines: &Matrix3<f64>) -> ([f64; 2], f64) {
    let htt = h_lines.fixed_view::<2, 2>(0, 0).into_owned();
    let htq = Vector2::new(h_lines[(0, 2)], h_lines[(1, 2)]);
    let hqq = h_lines[(2, 2)];
    let m = if hqq > 0.0 {
        htt - htq * htq.transpose() / hqq
    } else {
        htt
    };
    let (_, lambda_min, dir) = principal_axes(m[(0, 0)], 0.5 * (m[(0, 1)] + m[(1, 0)]), m[(1, 1)]);
    let sigma = if lambda_min > 0.0 {
        1.0 / lambda_min.sqrt()
    } else {
        f64::INFINITY
    };
    (dir, sigma)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    #[test]
    fn circular_mean_has_no_seam() {
        let m = weighted_circular_mean([(PI - 0.1, 1.0), (-PI + 0.1, 1.0)].into_iter()).unwrap();
        assert!(wrap_angle(m - PI).abs() < 1e-12);
        let w = weighted_circular_mean([(0.0, 3.0), (0.4, 1.0)].into_iter()).unwrap();
        assert!(w > 0.0 && w < 0.2);
        assert_eq!(
            weighted_circular_mean([(0.0, 1.0), (PI, 1.0)].into_iter()),
            None
        );
        assert_eq!(weighted_circular_mean(std::iter::empty()), None);
    }

    #[test]
    fn parallel_walls_leave_their_direction_unobservable() {
        let floors = SigmaFloors {
            sigma_c: 0.001,
            sigma_theta: 0.001,
        };
        let left = CogLine::from_centre(PI, [0.0, 1.0], -2.0, 2.0, 0.001, 0.001, 50);
        let right = CogLine::from_centre(0.0, [0.0, -1.0], -2.0, 2.0, 0.001, 0.001, 50);
        let mut ne = NormalEquations::default();
        for l in [&left, &right] {
            ne.add_match(
                l,
                l,
                &Pose2::IDENTITY,
                LineConstraints::CentreAndDirection,
                &floors,
            );
        }
        let (dir, sigma) = weakest_translation(&ne.h);
        assert!(dir[1].abs() < 1e-9 && (dir[0].abs() - 1.0).abs() < 1e-9);
        assert!(sigma.is_infinite() || sigma > 1e6);
        // A cross wall makes it observable.
        let cross = CogLine::from_centre(FRAC_PI_2, [3.0, 0.0], -1.0, 1.0, 0.001, 0.001, 50);
        ne.add_match(
            &cross,
            &cross,
            &Pose2::IDENTITY,
            LineConstraints::CentreAndDirection,
            &floors,
        );
        let (_, sigma) = weakest_translation(&ne.h);
        assert!(sigma < 0.01);
    }

    /// A corridor wall along x whose end is mapped 4 cm off with σ 3 cm:
    /// a prediction known to 1 cm along x leaves it out, one known to
    /// 5 cm takes it (and moves towards it); without a prediction it is
    /// always used.
    #[test]
    fn a_map_end_less_certain_than_the_prediction_is_not_used() {
        let floors = SigmaFloors {
            sigma_c: 0.001,
            sigma_theta: 0.001,
        };
        let mut local = CogLine::from_centre(0.0, [0.0, 1.0], -2.0, 2.0, 0.001, 0.001, 50);
        local.wall_ends.end = Some(0.01);
        let mut map = CogLine::from_centre(0.0, [0.0, 1.0], -2.0, 2.04, 0.001, 0.001, 50);
        map.wall_ends.end = Some(0.03);
        let along =
            |sigma: f64| Matrix3::from_diagonal(&Vector3::new(sigma * sigma, 0.01 * 0.01, 1e-4));
        let rows = |ne: NormalEquations| {
            let mut ne = ne;
            ne.add_match(
                &local,
                &map,
                &Pose2::IDENTITY,
                LineConstraints::CentreAndDirection,
                &floors,
            );
            (ne.rows, ne.g[0])
        };
        // Two rows for the line (offset, direction), one for the end.
        assert_eq!(
            rows(NormalEquations::new(0.0).with_prediction(along(0.01))).0,
            2
        );
        let (n, g) = rows(NormalEquations::new(0.0).with_prediction(along(0.05)));
        assert_eq!(n, 3);
        assert!(g < 0.0, "the end pulls the pose towards +x: {g}");
        assert_eq!(rows(NormalEquations::new(0.0)).0, 3);
    }

    #[test]
    fn residuals_vanish_at_the_true_pose() {
        let floors = SigmaFloors {
            sigma_c: 0.001,
            sigma_theta: 0.001,
        };
        let pose = Pose2::new(1.0, -0.5, 0.7);
        let local = CogLine::from_centre(0.3, [2.0, 1.0], -1.0, 1.0, 0.001, 0.001, 50);
        let map = local.transformed(&pose);
        for mode in [
            LineConstraints::CentreAndDirection,
            LineConstraints::EndPointsAndCentre,
        ] {
            let mut ne = NormalEquations::default();
            ne.add_match(&local, &map, &pose, mode, &floors);
            assert!(ne.chi2 < 1e-20, "{mode:?}");
        }
    }
}
