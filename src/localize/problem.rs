//! One local-localization problem: the data, the association of local to
//! map lines, and the solver stages (paper initialisation, Gauss–Newton
//! refinement, validation of the matches).

use nalgebra::{Matrix3, Vector3};

use super::local::{LocalizeError, LocalizerConfig};
use super::solve::{LineConstraints, NormalEquations, SigmaFloors, weighted_circular_mean};
use crate::geometry::{CogLine, Pose2, wrap_angle};
use crate::geometry::{CorrespondenceConfig, SegmentId, SegmentIndex};

/// Robust Gauss–Newton iterations that re-associate before the matches are
/// validated and frozen.
const REASSOCIATE_ITERATIONS: usize = 5;

/// Matched pairs: index of the local line, id of the map line.
pub(crate) type Matches = Vec<(usize, SegmentId)>;

/// The inputs of one localization, borrowed.
#[derive(Debug)]
pub(crate) struct Problem<'a> {
    pub local: &'a [CogLine],
    pub map: &'a SegmentIndex,
    pub predicted: Pose2,
    pub prior_cov: Matrix3<f64>,
    pub prior_info: Matrix3<f64>,
    pub cfg: &'a LocalizerConfig,
    pub floors: SigmaFloors,
}

/// Outcome of the Gauss–Newton refinement.
#[derive(Debug)]
pub(crate) struct Refined {
    pub pose: Pose2,
    pub matches: Matches,
    pub iterations: usize,
}

/// Variance of the across-line position of `line`'s centre (map frame, at
/// `pose`) and of its direction caused by the pose uncertainty `cov`;
/// also the along-line part, for the extent gate.
fn pose_spread(line: &CogLine, pose: &Pose2, cov: &Matrix3<f64>) -> (f64, f64, f64) {
    let arm = [line.xc - pose.x, line.yc - pose.y];
    let n = line.normal();
    let d = line.direction();
    // Jacobians of the centre's across/along position w.r.t. (x, y, θ).
    let jn = Vector3::new(n[0], n[1], -n[0] * arm[1] + n[1] * arm[0]);
    let jd = Vector3::new(d[0], d[1], -d[0] * arm[1] + d[1] * arm[0]);
    (
        (jn.transpose() * cov * jn)[0].max(0.0),
        (jd.transpose() * cov * jd)[0].max(0.0),
        cov[(2, 2)].max(0.0),
    )
}

impl Problem<'_> {
    fn check_matches(&self, found: usize) -> Result<(), LocalizeError> {
        let needed = self.cfg.min_matches.max(1);
        if found < needed {
            return Err(LocalizeError::TooFewMatches { found, needed });
        }
        Ok(())
    }

    /// Gates for `moved` (a local line in the map frame at `pose`): the
    /// base gates widened by `gate_sigmas` standard deviations of where
    /// the pose uncertainty `cov` may put it.
    fn widened_gates(
        &self,
        moved: &CogLine,
        pose: &Pose2,
        cov: &Matrix3<f64>,
    ) -> CorrespondenceConfig {
        let (var_n, var_d, var_t) = pose_spread(moved, pose, cov);
        let k = self.cfg.gate_sigmas;
        let base = self.cfg.correspondence;
        CorrespondenceConfig {
            // Opposite faces must never match, whatever the uncertainty.
            max_angle_diff: (base.max_angle_diff + k * var_t.sqrt()).min(1.2),
            max_centre_distance: base.max_centre_distance + k * var_n.sqrt(),
            extent_tolerance: base.extent_tolerance + k * var_d.sqrt(),
        }
    }

    /// Matches every local line, moved by `pose`, to its best map line.
    pub fn associate(&self, pose: &Pose2, cov: &Matrix3<f64>, out: &mut Matches) {
        out.clear();
        for (i, line) in self.local.iter().enumerate() {
            let moved = line.transformed(pose);
            let gates = self.widened_gates(&moved, pose, cov);
            if let Some(id) = self.map.best_match(&moved, &gates) {
                out.push((i, id));
            }
        }
    }

    /// Normal equations of `matches` at `pose` (lines only, no prior).
    pub fn equations(
        &self,
        matches: &[(usize, SegmentId)],
        pose: &Pose2,
        mode: LineConstraints,
        robust_scale: f64,
    ) -> NormalEquations {
        let mut ne = NormalEquations::new(robust_scale).with_prediction(self.prior_cov);
        for &(i, id) in matches {
            if let (Some(l), Some(g)) = (self.local.get(i), self.map.get(id)) {
                ne.add_match(l, g, pose, mode, &self.floors);
            }
        }
        ne
    }

    /// The paper's solution from the prediction: rotation as the weighted
    /// circular mean of `θG − θL`, then translation by weighted least
    /// squares on "the local centre lies on the map line" with θ fixed.
    /// Returns the pose and the information matrix of the translation
    /// solve (lines and prior).
    pub fn paper_solution(
        &self,
        matches: &mut Matches,
    ) -> Result<(Pose2, Matrix3<f64>), LocalizeError> {
        let mut pose = self.predicted;
        self.associate(&pose, &self.prior_cov, matches);
        self.check_matches(matches.len())?;
        let floors = self.floors;
        let differences: Vec<(f64, f64)> = matches
            .iter()
            .filter_map(|&(i, id)| {
                let (l, g) = (self.local.get(i)?, self.map.get(id)?);
                let var = l.sigma_theta.max(floors.sigma_theta).powi(2)
                    + g.sigma_theta.max(floors.sigma_theta).powi(2);
                Some((wrap_angle(g.theta - l.theta - pose.theta), var))
            })
            .collect();
        let weighted = |keep: &dyn Fn(f64, f64) -> bool| {
            weighted_circular_mean(
                differences
                    .iter()
                    .filter(|(d, var)| keep(*d, *var))
                    .map(|&(d, var)| (d, 1.0 / var)),
            )
        };
        let first = weighted(&|_, _| true).ok_or(LocalizeError::Singular)?;
        // The wide first gates may admit a wrong pair at a different angle
        // (a turned box face near a wall); drop pairs that disagree with the
        // first mean by more than the base gate plus three of their σ.
        let base = self.cfg.correspondence.max_angle_diff;
        let turn = weighted(&|d, var| wrap_angle(d - first).abs() <= base + 3.0 * var.sqrt())
            .unwrap_or(first);
        pose = Pose2::new(pose.x, pose.y, pose.theta + turn);

        // The rotation is now known far better than the prior says: drop
        // its part of the gates so the translation gates stay tight.
        let mut gate_cov = self.prior_cov;
        for k in 0..3 {
            gate_cov[(k, 2)] = 0.0;
            gate_cov[(2, k)] = 0.0;
        }
        self.associate(&pose, &gate_cov, matches);
        self.check_matches(matches.len())?;
        let mut ne = self.equations(matches, &pose, LineConstraints::CentreAndDirection, 0.0);
        ne.add_prior(&self.prior_info, &pose, &self.predicted);
        let dt = ne.translation_step().ok_or(LocalizeError::Singular)?;
        Ok((Pose2::new(pose.x + dt[0], pose.y + dt[1], pose.theta), ne.h))
    }

    /// One Gauss–Newton step over `(x, y, θ)` on `matches` plus the prior,
    /// applied to `pose`; returns the step's size (m, rad) and the
    /// information matrix it used.
    fn step(
        &self,
        matches: &[(usize, SegmentId)],
        pose: &mut Pose2,
        robust_scale: f64,
    ) -> Result<((f64, f64), Matrix3<f64>), LocalizeError> {
        let mut ne = self.equations(matches, pose, self.cfg.constraints, robust_scale);
        ne.add_prior(&self.prior_info, pose, &self.predicted);
        let d = ne.step().ok_or(LocalizeError::Singular)?;
        *pose = Pose2::new(pose.x + d[0], pose.y + d[1], pose.theta + d[2]);
        Ok(((d[0].hypot(d[1]), d[2].abs()), ne.h))
    }

    fn converged(&self, step: (f64, f64)) -> bool {
        step.0 < self.cfg.converged_translation && step.1 < self.cfg.converged_rotation
    }

    /// Refines `pose` (with information `info`) in two phases:
    ///
    /// 1. up to [`REASSOCIATE_ITERATIONS`] robust Gauss–Newton iterations
    ///    (Cauchy kernel), re-associating each time with gates from the
    ///    current information, so wrong first matches get replaced;
    /// 2. the matches that fail validation at that robust pose are dropped,
    ///    the rest frozen, and plain weighted least squares iterated to
    ///    convergence. Freezing keeps two nearly equal match sets from
    ///    alternating; dropping the kernel gives full efficiency and the
    ///    quadratic convergence robust reweighting lacks.
    pub fn refine(
        &self,
        mut pose: Pose2,
        mut info: Matrix3<f64>,
    ) -> Result<Refined, LocalizeError> {
        let cfg = self.cfg;
        let mut matches = Vec::with_capacity(self.local.len());
        let mut iterations = 0;
        let robust_iterations = REASSOCIATE_ITERATIONS.min(cfg.max_iterations.saturating_sub(1));
        for _ in 0..robust_iterations {
            iterations += 1;
            let cov_now = info.try_inverse().unwrap_or(self.prior_cov);
            self.associate(&pose, &cov_now, &mut matches);
            self.check_matches(matches.len())?;
            let (step, h) = self.step(&matches, &mut pose, cfg.robust_kernel_scale)?;
            info = h;
            if self.converged(step) {
                break;
            }
        }
        let cov = info.try_inverse().ok_or(LocalizeError::Singular)?;
        let inconsistent = self.inconsistent(&matches, &pose, &cov);
        matches.retain(|(i, _)| !inconsistent.contains(i));
        self.check_matches(matches.len())?;

        let mut last_step = (f64::INFINITY, f64::INFINITY);
        while iterations < cfg.max_iterations {
            iterations += 1;
            let (step, _) = self.step(&matches, &mut pose, 0.0)?;
            last_step = step;
            if self.converged(step) {
                return Ok(Refined {
                    pose,
                    matches,
                    iterations,
                });
            }
        }
        Err(LocalizeError::NotConverged {
            iterations,
            step_m: last_step.0,
            step_rad: last_step.1,
        })
    }

    /// Local lines whose match is inconsistent at `pose` with covariance
    /// `cov`: direction or centre offset beyond `validation_gate_sigmas`
    /// standard deviations (line noise plus pose uncertainty). Such pairs
    /// are different walls that happen to lie close, e.g. pieces of a door
    /// recess segmented differently in the two scans; they carry false
    /// information along otherwise unobservable directions.
    pub fn inconsistent(
        &self,
        matches: &[(usize, SegmentId)],
        pose: &Pose2,
        cov: &Matrix3<f64>,
    ) -> Vec<usize> {
        let gate = self.cfg.validation_gate_sigmas;
        if gate <= 0.0 {
            return Vec::new();
        }
        let f = self.floors;
        matches
            .iter()
            .filter_map(|&(i, id)| {
                let (l, g) = (self.local.get(i)?, self.map.get(id)?);
                let moved = l.transformed(pose);
                let (var_n, _, var_t) = pose_spread(&moved, pose, cov);
                let st = |x: &CogLine| x.sigma_theta.max(f.sigma_theta);
                let sc = |x: &CogLine| x.sigma_c.max(f.sigma_c);
                let angle = wrap_angle(moved.theta - g.theta);
                let var_angle = st(l).powi(2) + st(g).powi(2) + var_t;
                let c = moved.centre();
                let offset = g.signed_distance(c);
                let s = g.along(c);
                let var_offset = sc(l).powi(2) + sc(g).powi(2) + (s * st(g)).powi(2) + var_n;
                let z = (angle * angle / var_angle)
                    .max(offset * offset / var_offset)
                    .sqrt();
                (z > gate).then_some(i)
            })
            .collect()
    }
}
