//! Local localization (Zhang & Ghosh §5): the robot pose from the lines of
//! one scan matched against the map, starting from a predicted pose.
//!
//! # Method
//!
//! 1. Match each local line (moved by the prediction) against the map, with
//!    gates widened by the prediction's uncertainty at that line.
//! 2. Rotation as the paper does it: the weighted mean of `θG − θL`, taken
//!    on the circle (weights `1/(σθL² + σθG²)`), which matched parallel walls
//!    estimate correctly even when matched to the wrong one of two.
//! 3. Translation as the paper does it: weighted least squares on "the
//!    local centre lies on the map line", θ fixed.
//! 4. Refinement: Gauss–Newton on `(x, y, θ)` jointly over the
//!    point-on-line and direction residuals plus the prior. First a few
//!    robust iterations (Cauchy kernel) that re-match with gates from the
//!    current covariance; then the matches whose direction or offset is
//!    beyond `validation_gate_sigmas` are dropped, the rest frozen, and
//!    plain weighted least squares runs until the step is below the
//!    tolerances.
//!
//! The covariance is the inverse of the information (lines + prior),
//! inflated by `χ²/dof` when the residuals are larger than the noise model
//! explains (never shrunk). If the lines alone leave a translation
//! direction nearly unconstrained (a corridor), that direction is reported
//! in `degenerate` and the pose keeps the prediction's position along it.

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

use super::problem::{Problem, Refined};
use super::solve::{LineConstraints, SigmaFloors, weakest_translation};
use crate::geometry::{CogLine, Pose2, wrap_angle};
use crate::geometry::{CorrespondenceConfig, SegmentId, SegmentIndex};

/// Tuning of local localization; SI units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LocalizerConfig {
    /// Base correspondence gates, used as they are once the pose is known
    /// well and widened by `gate_sigmas` times the pose uncertainty before.
    pub correspondence: CorrespondenceConfig,
    /// Width of the uncertainty part of the gates, in standard deviations.
    /// Default 3.
    pub gate_sigmas: f64,
    /// Fewest matched lines accepted. Default 2: one line fixes only two of
    /// the three degrees of freedom.
    pub min_matches: usize,
    /// Residuals each match contributes. Default: the paper's centre and
    /// direction. Measured (tests/localization.rs, room, 1 cm noise): as
    /// accurate as start/centre/end points (median 1.3 mm both), but with an
    /// honest covariance (mean NEES 2.1 against 3.4 for the end points,
    /// which count each local line's information up to three times).
    pub constraints: LineConstraints,
    /// Gauss–Newton iteration cap. Default 20 (it usually converges in
    /// 3–6; the robust kernel makes convergence linear, not quadratic).
    pub max_iterations: usize,
    /// Stop when a step moves less than this (m). Default 1e-5, a
    /// hundredth of the LMS200's resolution.
    pub converged_translation: f64,
    /// Stop when a step turns less than this (rad). Default 1e-5.
    pub converged_rotation: f64,
    /// Reject a solution farther than this from the prediction (m), or
    /// than `gate_sigmas` of the prediction's largest position σ when that
    /// is wider (after scans localization could not place), up to twice
    /// this. Default 0.5: odometry between two scans drifts far less.
    pub max_translation_jump: f64,
    /// Reject a solution turned more than this from the prediction (rad),
    /// or than `gate_sigmas` of the prediction's own heading σ when that is
    /// wider (fast turns between sparse scans, where odometry headings lag
    /// by more), up to twice this. Default 0.35 (20°).
    pub max_rotation_jump: f64,
    /// Floor on a line's σc (m) before weighting. Default 0.001: the
    /// LMS200's 1 mm resolution.
    pub min_sigma_c: f64,
    /// Floor on a line's σθ (rad) before weighting. Default 0.0005.
    pub min_sigma_theta: f64,
    /// A translation direction whose marginal standard deviation from the
    /// lines alone exceeds this (m) is declared unobservable: the pose keeps
    /// the prediction along it and the lines' information there is dropped.
    /// Default 0.15: a corridor's door jambs seen at a grazing angle pin it
    /// to 5–15 cm per scan, which is worth fusing with the odometry; at
    /// 0.05 that was thrown away on 89 % of the corridor world's scans
    /// (mean pose error 235 → 129 mm with 0.15; CSAIL unchanged).
    pub max_observable_sigma: f64,
    /// Inflate the covariance by `χ²/dof` when that exceeds 1. Default true.
    pub scale_covariance_by_residual: bool,
    /// After the robust iterations, a match whose direction or centre
    /// offset is more than this many standard deviations off (line noise
    /// plus pose uncertainty) is dropped before the final least squares;
    /// 0 disables. Default 4.
    pub validation_gate_sigmas: f64,
    /// Scale `k` (in standard deviations) of the Cauchy kernel that
    /// down-weights wrong matches during the robust iterations; 0 disables
    /// it. Default 3: a row at 3σ
    /// keeps half its weight, one at 30σ a hundredth.
    pub robust_kernel_scale: f64,
    /// When nothing matches, this many headings are tried that would bring
    /// local lines onto map lines (see [`super::heading`]); 0 disables.
    /// Default 3: odometry headings lag in fast turns by more than any
    /// noise model admits without widening every gate.
    pub heading_search: usize,
}

impl Default for LocalizerConfig {
    fn default() -> Self {
        LocalizerConfig {
            correspondence: CorrespondenceConfig::default(),
            gate_sigmas: 3.0,
            min_matches: 2,
            constraints: LineConstraints::CentreAndDirection,
            max_iterations: 20,
            converged_translation: 1e-5,
            converged_rotation: 1e-5,
            max_translation_jump: 0.5,
            max_rotation_jump: 0.35,
            min_sigma_c: 0.001,
            min_sigma_theta: 0.0005,
            max_observable_sigma: 0.15,
            scale_covariance_by_residual: true,
            validation_gate_sigmas: 4.0,
            robust_kernel_scale: 3.0,
            heading_search: 3,
        }
    }
}

/// A localized pose.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalizationResult {
    /// Robot pose in the map frame.
    pub pose: Pose2,
    /// Covariance of `(x, y, θ)` (m², m·rad, rad²).
    pub covariance: [[f64; 3]; 3],
    /// Matched pairs: index into the local lines, id of the map line.
    pub matches: Vec<(usize, SegmentId)>,
    /// Unit vector (map frame) of a translation direction the lines do not
    /// constrain; the pose keeps the prediction along it.
    pub degenerate: Option<[f64; 2]>,
    /// Gauss–Newton iterations run (robust and final together).
    pub iterations: usize,
    /// Weighted squared residual of the line constraints at the solution.
    pub chi2: f64,
    /// Whether the solution started from a searched heading, not the
    /// prediction's (see [`super::heading`]).
    pub heading_searched: bool,
}

/// Why localization gave no pose.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LocalizeError {
    #[error("too few line matches: found {found}, need {needed}")]
    TooFewMatches { found: usize, needed: usize },
    #[error(
        "implausible jump from the prediction: {dx:.3} m and {dtheta:.3} rad, beyond the configured limits"
    )]
    ImplausibleJump { dx: f64, dtheta: f64 },
    #[error("prior covariance is not symmetric positive definite")]
    InvalidPrior,
    #[error("non-finite input: {what}")]
    NonFiniteInput { what: &'static str },
    #[error("normal equations are singular")]
    Singular,
    #[error(
        "no convergence after {iterations} iterations (last step {step_m:.2e} m, {step_rad:.2e} rad)"
    )]
    NotConverged {
        iterations: usize,
        step_m: f64,
        step_rad: f64,
    },
}

fn to_matrix(m: &[[f64; 3]; 3]) -> Matrix3<f64> {
    Matrix3::from_fn(|r, c| m[r][c])
}

fn to_array(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
}

/// `cov` with the translation's principal σ capped at `max_translation`
/// (m) and the heading's σ at `max_rotation` (rad). Each cap is a
/// congruence `A·cov·Aᵀ` that shrinks one direction only, so the result
/// stays symmetric positive definite and correlations keep their sign.
fn cap_covariance(cov: &Matrix3<f64>, max_translation: f64, max_rotation: f64) -> Matrix3<f64> {
    let mut out = *cov;
    let eig = cov.fixed_view::<2, 2>(0, 0).into_owned().symmetric_eigen();
    let cap = max_translation * max_translation;
    for k in 0..2 {
        let lambda = eig.eigenvalues[k];
        if lambda > cap {
            let u = Vector3::new(eig.eigenvectors[(0, k)], eig.eigenvectors[(1, k)], 0.0);
            let a = Matrix3::identity() - (1.0 - (cap / lambda).sqrt()) * u * u.transpose();
            out = a * out * a.transpose();
        }
    }
    let rot_cap = max_rotation * max_rotation;
    if out[(2, 2)] > rot_cap {
        let a = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, (rot_cap / out[(2, 2)]).sqrt()));
        out = a * out * a.transpose();
    }
    out
}

#[cfg(test)]
mod cap_tests {
    use super::*;

    #[test]
    fn wide_directions_are_capped_and_the_rest_kept() {
        // 100 m² along a corridor at 30°, 1 cm² across, some heading.
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        let r = nalgebra::Matrix2::new(c, -s, s, c);
        let t = r * nalgebra::Matrix2::new(100.0, 0.0, 0.0, 1e-4) * r.transpose();
        let mut cov = Matrix3::zeros();
        cov.fixed_view_mut::<2, 2>(0, 0).copy_from(&t);
        cov[(2, 2)] = 1e-4;
        cov[(0, 2)] = 5e-5;
        cov[(2, 0)] = 5e-5;
        assert!(cov.cholesky().is_some());
        let capped = cap_covariance(&cov, 0.5, 0.35);
        let eig = capped
            .fixed_view::<2, 2>(0, 0)
            .into_owned()
            .symmetric_eigen();
        let (hi, lo) = (eig.eigenvalues.max(), eig.eigenvalues.min());
        assert!(
            (hi - 0.25).abs() < 1e-9 && (lo - 1e-4).abs() < 1e-9,
            "{eig:?}"
        );
        assert!((capped[(2, 2)] - 1e-4).abs() < 1e-12);
        assert!(capped.cholesky().is_some(), "still positive definite");
        // A covariance within the caps is returned unchanged.
        let small = Matrix3::from_diagonal(&Vector3::new(0.01, 0.02, 0.001));
        assert_eq!(cap_covariance(&small, 0.5, 0.35), small);
        let spun = Matrix3::from_diagonal(&Vector3::new(0.01, 0.02, 4.0));
        assert!((cap_covariance(&spun, 0.5, 0.35)[(2, 2)] - 0.1225).abs() < 1e-12);
    }
}

/// Information matrix of the prior, checked.
fn prior_information(prior: &[[f64; 3]; 3]) -> Result<Matrix3<f64>, LocalizeError> {
    let p = to_matrix(prior);
    if p.iter().any(|v| !v.is_finite()) {
        return Err(LocalizeError::NonFiniteInput {
            what: "prior covariance",
        });
    }
    if (p - p.transpose()).abs().max() > 1e-9 * p.abs().max().max(1e-300) {
        return Err(LocalizeError::InvalidPrior);
    }
    let chol = p.cholesky().ok_or(LocalizeError::InvalidPrior)?;
    Ok(chol.inverse())
}

/// Largest heading correction (rad) accepted for a prediction with
/// covariance `prior`: `max_rotation_jump`, or as many of the prediction's
/// own σ as the gates let matches through when that is wider (a long, fast
/// turn between sparse scans), but at most twice `max_rotation_jump`.
///
/// The cap: the largest correction localization made on CSAIL and its
/// thinned versions was 28°, while a prediction after an odometry jump
/// (CSAIL driven backwards, thinned to 0.5 m / 0.5 rad: 101° in 0.4 s,
/// then 2 s without a fix) had σθ 28°, and three of its four lines then
/// matched walls 50° off, which broke the map (0.9 m mean relation error
/// against 0.07 m with the cap).
pub(crate) fn rotation_limit(prior: &[[f64; 3]; 3], cfg: &LocalizerConfig) -> f64 {
    (cfg.gate_sigmas * prior[2][2].max(0.0).sqrt())
        .min(2.0 * cfg.max_rotation_jump)
        .max(cfg.max_rotation_jump)
}

/// Largest translation correction (m) accepted for a prediction with
/// covariance `prior`: as [`rotation_limit`], `max_translation_jump` or
/// `gate_sigmas` of the prediction's largest position σ, at most twice
/// `max_translation_jump`.
pub(crate) fn translation_limit(prior: &[[f64; 3]; 3], cfg: &LocalizerConfig) -> f64 {
    let (a, b, c) = (prior[0][0], prior[0][1], prior[1][1]);
    let largest = 0.5 * (a + c) + (0.25 * (a - c) * (a - c) + b * b).sqrt();
    (cfg.gate_sigmas * largest.max(0.0).sqrt())
        .min(2.0 * cfg.max_translation_jump)
        .max(cfg.max_translation_jump)
}

/// Localizes the robot: `local_lines` in the robot frame, `map` in the map
/// frame, `predicted` the odometry prediction with covariance `prior`
/// (x, y, θ). See the module documentation for the method.
pub fn localize(
    local_lines: &[CogLine],
    map: &SegmentIndex,
    predicted: Pose2,
    prior: &[[f64; 3]; 3],
    cfg: &LocalizerConfig,
) -> Result<LocalizationResult, LocalizeError> {
    if ![predicted.x, predicted.y, predicted.theta]
        .iter()
        .all(|v| v.is_finite())
    {
        return Err(LocalizeError::NonFiniteInput {
            what: "predicted pose",
        });
    }
    let prior_info = prior_information(prior)?;
    let problem = Problem {
        local: local_lines,
        map,
        predicted,
        prior_cov: to_matrix(prior),
        prior_info,
        cfg,
        floors: SigmaFloors {
            sigma_c: cfg.min_sigma_c,
            sigma_theta: cfg.min_sigma_theta,
        },
    };
    let mut matches = Vec::with_capacity(local_lines.len());
    let (initial, initial_info) = problem.paper_solution(&mut matches)?;

    let Refined {
        mut pose,
        matches,
        iterations,
    } = problem.refine(initial, initial_info)?;

    // Final equations at the solution, lines only, for χ² and observability.
    let lines = problem.equations(&matches, &pose, cfg.constraints, 0.0);
    let (weak_dir, weak_sigma) = weakest_translation(&lines.h);
    let degenerate = (weak_sigma > cfg.max_observable_sigma).then_some(weak_dir);
    let mut line_info = lines.h;
    if let Some(v) = degenerate {
        // Keep the prediction along the unobservable direction, and drop
        // the lines' (weak) information along it so the covariance there
        // is the prior's, consistent with the pose.
        let along = v[0] * (predicted.x - pose.x) + v[1] * (predicted.y - pose.y);
        pose = Pose2::new(pose.x + along * v[0], pose.y + along * v[1], pose.theta);
        let project = Matrix3::identity() - {
            let u = Vector3::new(v[0], v[1], 0.0);
            u * u.transpose()
        };
        line_info = project * line_info * project;
    }
    let mut covariance = (line_info + prior_info)
        .try_inverse()
        .ok_or(LocalizeError::Singular)?;
    let dof = lines.rows.saturating_sub(3);
    if cfg.scale_covariance_by_residual && dof > 0 {
        covariance *= (lines.chi2 / dof as f64).max(1.0);
    }
    // No wider than the jumps the localizer accepts: along an unobservable
    // direction the covariance is the prior's, inflated on every scan, and
    // in a long corridor it grew to 100 m² within a minute; the next
    // prediction's correspondence gate then let walls 10 m away match.
    let covariance = cap_covariance(&covariance, cfg.max_translation_jump, cfg.max_rotation_jump);

    let dx = (pose.x - predicted.x).hypot(pose.y - predicted.y);
    let dtheta = wrap_angle(pose.theta - predicted.theta).abs();
    if dx > translation_limit(prior, cfg) || dtheta > rotation_limit(prior, cfg) {
        return Err(LocalizeError::ImplausibleJump { dx, dtheta });
    }
    Ok(LocalizationResult {
        pose,
        covariance: to_array(&covariance),
        matches,
        degenerate,
        iterations,
        chi2: lines.chi2,
        heading_searched: false,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    const PRIOR: [[f64; 3]; 3] = [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]];

    /// A line as certain as the weight floors allow, so the prior's pull
    /// (about 10⁻⁵ of the lines' information) stays below the tolerances.
    fn line(theta: f64, c: [f64; 2], half: f64) -> CogLine {
        CogLine::from_centre(theta, c, -half, half, 0.0005, 0.001, 100)
    }

    /// A box-shaped room seen from its centre (robot frame), and the map
    /// of the same room with the robot at `truth`.
    fn room(truth: &Pose2) -> (Vec<CogLine>, SegmentIndex) {
        let local = vec![
            line(FRAC_PI_2, [3.0, 0.0], 2.0),
            line(PI, [0.0, 2.0], 3.0),
            line(-FRAC_PI_2, [-3.0, 0.0], 2.0),
            line(0.0, [0.0, -2.0], 3.0),
        ];
        let mut map = SegmentIndex::new();
        for l in &local {
            map.insert(l.transformed(truth));
        }
        (local, map)
    }

    #[test]
    fn recovers_an_exact_pose_from_a_rough_prediction() {
        let truth = Pose2::new(1.0, -2.0, 0.4);
        let (local, map) = room(&truth);
        let predicted = Pose2::new(1.15, -2.1, 0.25);
        let r = localize(&local, &map, predicted, &PRIOR, &LocalizerConfig::default()).unwrap();
        let err = (r.pose.x - truth.x).hypot(r.pose.y - truth.y);
        assert!(err < 1e-4, "{:?}", r.pose);
        assert!(
            wrap_angle(r.pose.theta - truth.theta).abs() < 1e-5,
            "{:?}",
            r.pose
        );
        assert_eq!(r.matches.len(), 4);
        assert_eq!(r.degenerate, None);
        // The covariance is symmetric positive definite.
        let c = to_matrix(&r.covariance);
        assert!((c - c.transpose()).abs().max() < 1e-15);
        assert!(c.cholesky().is_some());
    }

    #[test]
    fn two_parallel_walls_are_flagged_and_keep_the_prediction_along_them() {
        let truth = Pose2::new(5.0, 1.0, 0.0);
        let (local, _) = room(&truth);
        let walls = [local[1], local[3]];
        let mut map = SegmentIndex::new();
        for l in &walls {
            map.insert(l.transformed(&truth));
        }
        let predicted = Pose2::new(5.12, 1.05, 0.03);
        let r = localize(&walls, &map, predicted, &PRIOR, &LocalizerConfig::default()).unwrap();
        let v = r.degenerate.unwrap();
        assert!(v[0].abs() > 0.9999, "{v:?}");
        assert!((r.pose.x - predicted.x).abs() < 1e-6);
        assert!((r.pose.y - truth.y).abs() < 1e-4, "{:?}", r.pose);
        assert!(
            wrap_angle(r.pose.theta - truth.theta).abs() < 1e-5,
            "{:?}",
            r.pose
        );
        assert!((r.covariance[0][0] - PRIOR[0][0]).abs() < 1e-9);
    }

    #[test]
    fn a_wide_position_prior_widens_the_translation_limit_only_up_to_twice_the_jump() {
        let cfg = LocalizerConfig::default();
        assert_eq!(cfg.max_translation_jump, 0.5);
        // σ 0.1 m: three σ is within the jump.
        assert!((translation_limit(&PRIOR, &cfg) - 0.5).abs() < 1e-12);
        // σ 0.3 m along y only (after scans localization could not place).
        let wide = [[0.01, 0.0, 0.0], [0.0, 0.09, 0.0], [0.0, 0.0, 0.01]];
        assert!((translation_limit(&wide, &cfg) - 0.9).abs() < 1e-12);
        // σ 1 m: capped at twice the jump.
        let lost = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.01]];
        assert!((translation_limit(&lost, &cfg) - 1.0).abs() < 1e-12);
        // 0.7 m off: beyond max_translation_jump, within the widened limit.
        let truth = Pose2::new(0.0, 0.0, 0.0);
        let (local, map) = room(&truth);
        let r = localize(&local, &map, Pose2::new(0.0, 0.7, 0.0), &wide, &cfg).unwrap();
        assert!(r.pose.x.hypot(r.pose.y) < 1e-4, "{:?}", r.pose);
        // σ 0.2 m: the gates still reach the walls, the limit (0.6 m)
        // refuses the fix.
        let middling = [[0.01, 0.0, 0.0], [0.0, 0.04, 0.0], [0.0, 0.0, 0.01]];
        match localize(&local, &map, Pose2::new(0.0, 0.7, 0.0), &middling, &cfg) {
            Err(LocalizeError::ImplausibleJump { dx, .. }) => assert!((dx - 0.7).abs() < 1e-3),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_wide_heading_prior_widens_the_rotation_limit_only_up_to_twice_the_jump() {
        let truth = Pose2::new(0.0, 0.0, 0.0);
        let (local, map) = room(&truth);
        let cfg = LocalizerConfig {
            max_rotation_jump: 0.2,
            ..LocalizerConfig::default()
        };
        // σθ 0.5 rad (29°): three σ would admit 86°.
        let wide = [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.25]];
        assert!((rotation_limit(&wide, &cfg) - 0.4).abs() < 1e-12);
        // σθ 0.1 rad: three σ, within the cap.
        assert!((rotation_limit(&PRIOR, &cfg) - 0.3).abs() < 1e-12);
        // 0.3 rad off: beyond max_rotation_jump, within the widened limit.
        let r = localize(&local, &map, Pose2::new(0.0, 0.0, 0.3), &wide, &cfg).unwrap();
        assert!(
            wrap_angle(r.pose.theta - truth.theta).abs() < 1e-5,
            "{:?}",
            r.pose
        );
        // 0.5 rad off: the room is found, and refused as too far a turn.
        match localize(&local, &map, Pose2::new(0.0, 0.0, 0.5), &wide, &cfg) {
            Err(LocalizeError::ImplausibleJump { dtheta, .. }) => {
                assert!((dtheta - 0.5).abs() < 1e-3, "{dtheta}");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn bad_inputs_get_typed_errors() {
        let truth = Pose2::new(0.0, 0.0, 0.0);
        let (local, map) = room(&truth);
        let cfg = LocalizerConfig::default();
        let nan = Pose2::new(f64::NAN, 0.0, 0.0);
        assert!(matches!(
            localize(&local, &map, nan, &PRIOR, &cfg),
            Err(LocalizeError::NonFiniteInput { .. })
        ));
        let asymmetric = [[0.01, 0.005, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]];
        assert_eq!(
            localize(&local, &map, truth, &asymmetric, &cfg),
            Err(LocalizeError::InvalidPrior)
        );
        let zero = [[0.0; 3]; 3];
        assert_eq!(
            localize(&local, &map, truth, &zero, &cfg),
            Err(LocalizeError::InvalidPrior)
        );
        // Lines seen from the wrong side never match: opposite directions.
        let flipped: Vec<CogLine> = local
            .iter()
            .map(|l| line(l.theta + PI, l.centre(), 1.0))
            .collect();
        assert_eq!(
            localize(&flipped, &map, truth, &PRIOR, &cfg),
            Err(LocalizeError::TooFewMatches {
                found: 0,
                needed: 2
            })
        );
    }
}
