//! The keyframe pose graph: SE(2) poses joined by relative-pose
//! constraints (one between consecutive keyframes, one per verified loop),
//! optimised by Levenberg–Marquardt with a robust kernel on the loop edges.
//!
//! # Why a solver of its own
//!
//! The normal equations are 3×3 blocks over keyframes; `nalgebra-sparse`
//! (from the linear-algebra family the localizer already uses) factors
//! them, in a minimum-degree order computed here over the blocks (its own
//! Cholesky does no fill-reducing ordering, and a floor driven round many
//! times fills in badly in keyframe order). A 1,000-keyframe graph with
//! 331 loop edges optimises in about 17 ms (`benches/loop_closure.rs`);
//! the factor-graph crates (factrs, apex-solver) bring 100–230 crates for
//! the same Gauss–Newton step.
//!
//! # Robustness
//!
//! Loop edges carry dynamic covariance scaling (Agarwal et al., ICRA 2013):
//! an edge whose squared Mahalanobis error χ² exceeds the kernel's `Φ`
//! keeps the weight `s² = (2Φ/(Φ+χ²))²`, so one false loop that passed
//! verification bends the map a little instead of folding it. Chain edges
//! (scan matching or odometry between consecutive keyframes) are trusted.

mod closure;
mod keyframes;

pub use closure::{
    LoopCandidate, LoopClosureConfig, LoopMatch, LoopQuery, LoopRejection, close_loop, drift_paths,
    loop_candidates,
};
pub use keyframes::{
    AppliedOptimisation, Correction, KeyframeGraph, LoopSearchJob, LoopSearchResult, LoopStats,
    OptimisationJob, OptimisationResult,
};

use crate::geometry::{Pose2, wrap_angle};
use crate::map::{Edge, EdgeKind};
use nalgebra::{DMatrix, Matrix3, Vector3};
use nalgebra_sparse::factorization::CscCholesky;
use nalgebra_sparse::{CooMatrix, CscMatrix};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use thiserror::Error;

/// Lower-triangle 3×3 blocks of a symmetric matrix over poses, keyed
/// (row, column) with row ≥ column.
type Blocks = BTreeMap<(usize, usize), Matrix3<f64>>;

/// Optimiser settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OptimizerConfig {
    /// Levenberg–Marquardt iterations over all kernel stages (each stage
    /// still gets one once the cap is reached). Default 60; a stage
    /// converges in 2–8.
    pub max_iterations: usize,
    /// Stop once no pose moves more than this in one step (m, and rad for
    /// the heading). Default 1e-5.
    pub converged_step: f64,
    /// Dynamic covariance scaling `Φ` of loop edges (a χ² value); 0
    /// disables the kernel. Default 5: a loop consistent with the chain
    /// to about 2σ keeps its full weight, one at 7σ about 4 %, at 10σ 1 %.
    pub loop_kernel: f64,
}

impl Default for OptimizerConfig {
    fn default() -> Self {
        OptimizerConfig {
            max_iterations: 60,
            converged_step: 1e-5,
            loop_kernel: 5.0,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Error)]
pub enum GraphError {
    #[error("edge {from} -> {to} names a pose the graph does not have ({len} poses)")]
    NoSuchPose { from: usize, to: usize, len: usize },
    #[error("edge {from} -> {to} has a non-finite measurement or information")]
    NonFinite { from: usize, to: usize },
    #[error("the graph's normal equations are not positive definite (disconnected poses?)")]
    NotPositiveDefinite,
    #[error("the stored graph is inconsistent: {0}")]
    Inconsistent(String),
}

/// What one optimisation did.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct OptimizeReport {
    pub iterations: usize,
    /// Robust cost before and after (sum of weighted χ²).
    pub initial_cost: f64,
    pub final_cost: f64,
    /// Loop edges whose kernel weight ended below one half (in effect
    /// rejected by the optimiser).
    pub loops_down_weighted: usize,
}

/// Poses (the first one fixed: it defines the map frame) and edges.
#[derive(Debug, Clone, Default)]
pub struct PoseGraph {
    poses: Vec<Pose2>,
    edges: Vec<Edge>,
}

/// Error of an edge at the given poses, in the frame of the measurement:
/// `measurement⁻¹ ∘ (from⁻¹ ∘ to)` as `(x, y, θ)`.
fn edge_error(e: &Edge, a: &Pose2, b: &Pose2) -> Vector3<f64> {
    let d = e.measurement.between(&a.between(b));
    Vector3::new(d.x, d.y, wrap_angle(d.theta))
}

/// Jacobians of [`edge_error`] with respect to `a` and `b` (each `(x, y,
/// θ)` in the map frame, updated additively).
fn edge_jacobians(e: &Edge, a: &Pose2, b: &Pose2) -> (Matrix3<f64>, Matrix3<f64>) {
    let (sa, ca) = a.theta.sin_cos();
    let (sz, cz) = e.measurement.theta.sin_cos();
    // Rotations as matrices: Rzᵀ·Raᵀ and Rzᵀ·dRaᵀ/dθ.
    let rzt = nalgebra::Matrix2::new(cz, sz, -sz, cz);
    let rat = nalgebra::Matrix2::new(ca, sa, -sa, ca);
    let drat = nalgebra::Matrix2::new(-sa, ca, -ca, -sa);
    let dt = nalgebra::Vector2::new(b.x - a.x, b.y - a.y);
    let r = rzt * rat;
    let dtheta = rzt * drat * dt;
    let ja = Matrix3::new(
        -r[(0, 0)],
        -r[(0, 1)],
        dtheta[0],
        -r[(1, 0)],
        -r[(1, 1)],
        dtheta[1],
        0.0,
        0.0,
        -1.0,
    );
    let jb = Matrix3::new(
        r[(0, 0)],
        r[(0, 1)],
        0.0,
        r[(1, 0)],
        r[(1, 1)],
        0.0,
        0.0,
        0.0,
        1.0,
    );
    (ja, jb)
}

/// Dynamic covariance scaling: the weight (s²) of an edge with squared
/// error `chi2`, and its robust cost.
fn kernel(kind: EdgeKind, chi2: f64, phi: f64) -> (f64, f64) {
    if kind == EdgeKind::Chain || phi <= 0.0 || chi2 <= phi {
        return (1.0, chi2);
    }
    let s = 2.0 * phi / (phi + chi2);
    (s * s, s * s * chi2 + phi * (1.0 - s) * (1.0 - s))
}

/// The keyframes joined by each loop edge among `edges` that `poses`
/// agree with: kernel weight at least ½ (a loop the optimiser
/// down-weighted, or one not optimised in yet that disagrees, ties
/// nothing).
pub fn agreeing_loops<'a>(
    edges: &'a [Edge],
    poses: &'a [Pose2],
    cfg: &OptimizerConfig,
) -> impl Iterator<Item = (usize, usize)> + 'a {
    let phi = cfg.loop_kernel;
    edges
        .iter()
        .filter(move |e| {
            let (Some(a), Some(b)) = (poses.get(e.from), poses.get(e.to)) else {
                return false;
            };
            let r = edge_error(e, a, b);
            e.kind == EdgeKind::Loop && kernel(e.kind, r.dot(&(e.information * r)), phi).0 >= 0.5
        })
        .map(|e| (e.from, e.to))
}

impl PoseGraph {
    pub fn new() -> Self {
        PoseGraph::default()
    }

    /// Adds a pose (its initial estimate); returns its index.
    pub fn add_pose(&mut self, pose: Pose2) -> usize {
        self.poses.push(pose);
        self.poses.len() - 1
    }

    /// Adds a constraint; refused if it names a missing pose or is not
    /// finite.
    pub fn add_edge(&mut self, edge: Edge) -> Result<(), GraphError> {
        let len = self.poses.len();
        if edge.from >= len || edge.to >= len || edge.from == edge.to {
            return Err(GraphError::NoSuchPose {
                from: edge.from,
                to: edge.to,
                len,
            });
        }
        let m = &edge.measurement;
        if ![m.x, m.y, m.theta].iter().all(|v| v.is_finite())
            || !edge.information.iter().all(|v| v.is_finite())
        {
            return Err(GraphError::NonFinite {
                from: edge.from,
                to: edge.to,
            });
        }
        self.edges.push(edge);
        Ok(())
    }

    pub fn poses(&self) -> &[Pose2] {
        &self.poses
    }

    pub fn edges(&self) -> &[Edge] {
        &self.edges
    }

    /// Removes the newest edge.
    pub fn pop_edge(&mut self) -> Option<Edge> {
        self.edges.pop()
    }

    /// Removes the edges at `indices` (positions in [`Self::edges`]).
    pub fn remove_edges(&mut self, indices: &[usize]) {
        let mut k = 0;
        self.edges.retain(|_| {
            let keep = !indices.contains(&k);
            k += 1;
            keep
        });
    }

    /// Replaces every pose estimate (a rollback); ignored unless the count
    /// matches.
    pub fn set_poses(&mut self, poses: Vec<Pose2>) {
        if poses.len() == self.poses.len() {
            self.poses = poses;
        }
    }

    /// Removes the newest pose and the edges that reach it.
    pub fn pop_pose(&mut self) -> Option<Pose2> {
        let last = self.poses.len().checked_sub(1)?;
        self.edges.retain(|e| e.from != last && e.to != last);
        self.poses.pop()
    }

    /// Replaces the estimate of one pose (the daemon's latest keyframe,
    /// say); ignored for an index the graph does not have.
    pub fn set_pose(&mut self, index: usize, pose: Pose2) {
        if let Some(p) = self.poses.get_mut(index) {
            *p = pose;
        }
    }

    /// Loop edges in the graph.
    pub fn loop_edges(&self) -> impl Iterator<Item = &Edge> + '_ {
        self.edges.iter().filter(|e| e.kind == EdgeKind::Loop)
    }

    /// Kernel weight (s², 1 = fully trusted) of each edge at the current
    /// poses.
    pub fn edge_weights(&self, cfg: &OptimizerConfig) -> Vec<f64> {
        self.edges
            .iter()
            .map(|e| {
                let r = edge_error(e, &self.poses[e.from], &self.poses[e.to]);
                kernel(e.kind, r.dot(&(e.information * r)), cfg.loop_kernel).0
            })
            .collect()
    }

    /// The largest squared error of a loop edge at the current poses.
    fn largest_loop_chi2(&self) -> f64 {
        self.loop_edges()
            .map(|e| {
                let r = edge_error(e, &self.poses[e.from], &self.poses[e.to]);
                r.dot(&(e.information * r))
            })
            .fold(0.0, f64::max)
    }

    fn cost(&self, poses: &[Pose2], phi: f64) -> f64 {
        self.edges
            .iter()
            .map(|e| {
                let r = edge_error(e, &poses[e.from], &poses[e.to]);
                kernel(e.kind, r.dot(&(e.information * r)), phi).1
            })
            .sum()
    }

    /// Optimises every pose but the first (which stays where it is and so
    /// keeps the map frame).
    ///
    /// Graduated: first plain least squares (every loop trusted, so a true
    /// loop whose error is many of its own σ — the drift it corrects — is
    /// not thrown away at the start), then the loop kernel narrowed step by
    /// step to `loop_kernel`, so loops that disagree with the rest of the
    /// graph lose their weight as the estimate settles.
    pub fn optimize(&mut self, cfg: &OptimizerConfig) -> Result<OptimizeReport, GraphError> {
        let mut report = OptimizeReport {
            initial_cost: self.cost(&self.poses, cfg.loop_kernel),
            ..OptimizeReport::default()
        };
        report.final_cost = report.initial_cost;
        if self.poses.len() < 2 || self.edges.is_empty() {
            return Ok(report);
        }
        let mut stages = vec![0.0];
        if cfg.loop_kernel > 0.0 {
            let mut phi = 1e4;
            while phi > cfg.loop_kernel {
                stages.push(phi);
                phi /= 10.0;
            }
            stages.push(cfg.loop_kernel);
        }
        for phi in stages {
            // A stage whose kernel reaches no loop edge changes nothing.
            if phi > 0.0 {
                let largest = self.largest_loop_chi2();
                if largest <= cfg.loop_kernel {
                    break;
                }
                if largest <= phi {
                    continue;
                }
            }
            let budget = cfg.max_iterations.saturating_sub(report.iterations).max(1);
            report.iterations += self.levenberg_marquardt(phi, budget, cfg.converged_step)?;
        }
        report.final_cost = self.cost(&self.poses, cfg.loop_kernel);
        report.loops_down_weighted = self
            .edge_weights(cfg)
            .iter()
            .zip(&self.edges)
            .filter(|(w, e)| e.kind == EdgeKind::Loop && **w < 0.5)
            .count();
        Ok(report)
    }

    /// Levenberg–Marquardt at kernel width `phi` (0: none) until a step
    /// moves no pose more than `converged` or `max_iterations` ran;
    /// returns the iterations run.
    fn levenberg_marquardt(
        &mut self,
        phi: f64,
        max_iterations: usize,
        converged: f64,
    ) -> Result<usize, GraphError> {
        let n = self.poses.len();
        let mut lambda = 1e-6;
        let mut cost = self.cost(&self.poses, phi);
        let mut iterations = 0;
        let mut order = None;
        while iterations < max_iterations {
            iterations += 1;
            let (h, g) = self.normal_equations(phi);
            // The pattern stays while the edges do: one ordering per stage.
            let order: &[usize] = order.get_or_insert_with(|| elimination_order(&h, n - 1));
            // Retry with more damping until a step lowers the robust cost
            // (or the damping says there is none).
            let mut accepted = None;
            while lambda < 1e8 {
                // A system too ill-conditioned to factor gets more damping.
                let Ok(step) = solve_damped(&h, &g, order, lambda) else {
                    lambda *= 4.0;
                    continue;
                };
                let mut trial = self.poses.clone();
                for (i, p) in trial.iter_mut().enumerate().skip(1) {
                    let k = 3 * (i - 1);
                    *p = Pose2::new(p.x + step[k], p.y + step[k + 1], p.theta + step[k + 2]);
                }
                let trial_cost = self.cost(&trial, phi);
                if trial_cost <= cost {
                    let largest = step.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
                    accepted = Some((trial, trial_cost, largest));
                    lambda = (lambda / 3.0).max(1e-9);
                    break;
                }
                lambda *= 4.0;
            }
            let Some((trial, trial_cost, largest)) = accepted else {
                break;
            };
            self.poses = trial;
            let relative_gain = (cost - trial_cost) / cost.max(1e-300);
            cost = trial_cost;
            if largest < converged || relative_gain < 1e-10 {
                break;
            }
        }
        Ok(iterations)
    }

    /// Gauss–Newton normal equations over poses 1..n: the 3×3 blocks of
    /// `JᵀWJ` (lower triangle, keyed (row, column) pose index minus one)
    /// and `JᵀWr`.
    fn normal_equations(&self, phi: f64) -> (Blocks, Vec<f64>) {
        let n = self.poses.len();
        let mut h = Blocks::new();
        let mut g = vec![0.0; 3 * (n - 1)];
        for e in &self.edges {
            let (a, b) = (&self.poses[e.from], &self.poses[e.to]);
            let r = edge_error(e, a, b);
            let (w, _) = kernel(e.kind, r.dot(&(e.information * r)), phi);
            let info = e.information * w;
            let (ja, jb) = edge_jacobians(e, a, b);
            let blocks = [(e.from, ja), (e.to, jb)];
            for &(i, ji) in &blocks {
                if i == 0 {
                    continue;
                }
                let gi = ji.transpose() * info * r;
                for k in 0..3 {
                    g[3 * (i - 1) + k] += gi[k];
                }
                for &(j, jj) in &blocks {
                    if j == 0 || j > i {
                        continue;
                    }
                    *h.entry((i - 1, j - 1)).or_insert_with(Matrix3::zeros) +=
                        ji.transpose() * info * jj;
                }
            }
        }
        (h, g)
    }
}

/// Solves `(H + λ·diag(H) + λ·I) δ = −g` for the pose steps, `H` given by
/// its lower-triangle 3×3 blocks over `m` poses.
fn solve_damped(
    h: &Blocks,
    g: &[f64],
    order: &[usize],
    lambda: f64,
) -> Result<Vec<f64>, GraphError> {
    let m = order.len();
    let dim = 3 * m;
    let mut coo = CooMatrix::new(dim, dim);
    for (&(i, j), block) in h {
        for r in 0..3 {
            for c in 0..3 {
                let mut v = block[(r, c)];
                if i == j && r == c {
                    v += lambda * (v + 1.0);
                }
                if i == j && c > r {
                    continue;
                }
                let (pi, pj) = (order[i], order[j]);
                coo.push(3 * pi + r, 3 * pj + c, v);
                if i != j || r != c {
                    coo.push(3 * pj + c, 3 * pi + r, v);
                }
            }
        }
    }
    // A pose without any block (no edge reaches it) still gets the damping
    // so the system stays square and definite; its step is then zero.
    let mut present = vec![false; m];
    for &(i, j) in h.keys() {
        if i == j {
            present[i] = true;
        }
    }
    for (i, _) in present.iter().enumerate().filter(|(_, p)| !**p) {
        for r in 0..3 {
            coo.push(3 * order[i] + r, 3 * order[i] + r, 1.0);
        }
    }
    let csc = CscMatrix::from(&coo);
    let chol = CscCholesky::factor(&csc).map_err(|_| GraphError::NotPositiveDefinite)?;
    let mut rhs = DMatrix::zeros(dim, 1);
    for (i, &pi) in order.iter().enumerate() {
        for k in 0..3 {
            rhs[3 * pi + k] = -g[3 * i + k];
        }
    }
    let x = chol.solve(&rhs);
    if !x.iter().all(|v| v.is_finite()) {
        return Err(GraphError::NotPositiveDefinite);
    }
    let mut step = vec![0.0; dim];
    for (i, &pi) in order.iter().enumerate() {
        for k in 0..3 {
            step[3 * i + k] = x[3 * pi + k];
        }
    }
    Ok(step)
}

/// Position of each of the `m` poses in the elimination order: greedy
/// minimum degree over the graph of blocks (the fill each elimination
/// adds is kept, so degrees are those of the partly factored matrix).
/// Keyframe order suits one pass round a loop, but a floor patrolled for
/// an hour links every place to many visits, and in keyframe (or
/// breadth-first) order its factor turns nearly dense: 2,500 keyframes
/// then took seconds per factorisation. Minimum degree eliminates the
/// chain's pass-through keyframes first, at no fill, and the places where
/// visits meet last.
fn elimination_order(h: &Blocks, m: usize) -> Vec<usize> {
    use std::cmp::Reverse;
    use std::collections::{BTreeSet, BinaryHeap};
    let mut neighbours: Vec<BTreeSet<usize>> = vec![BTreeSet::new(); m];
    for &(i, j) in h.keys() {
        if i != j && i < m && j < m {
            neighbours[i].insert(j);
            neighbours[j].insert(i);
        }
    }
    let mut heap: BinaryHeap<Reverse<(usize, usize)>> =
        (0..m).map(|v| Reverse((neighbours[v].len(), v))).collect();
    let mut eliminated = vec![false; m];
    let mut position = vec![0; m];
    let mut next = 0;
    while let Some(Reverse((degree, v))) = heap.pop() {
        // Entries go stale as degrees change; only the current one counts.
        if eliminated[v] || degree != neighbours[v].len() {
            continue;
        }
        eliminated[v] = true;
        position[v] = next;
        next += 1;
        let around: Vec<usize> = std::mem::take(&mut neighbours[v]).into_iter().collect();
        for &u in &around {
            neighbours[u].remove(&v);
        }
        for (k, &a) in around.iter().enumerate() {
            for &b in &around[k + 1..] {
                neighbours[a].insert(b);
                neighbours[b].insert(a);
            }
        }
        for &u in &around {
            heap.push(Reverse((neighbours[u].len(), u)));
        }
    }
    position
}

/// Information matrix of a relative-pose measurement with isotropic
/// translation σ (m) and heading σ (rad).
pub fn diagonal_information(sigma_xy: f64, sigma_theta: f64) -> Matrix3<f64> {
    let t = 1.0 / (sigma_xy * sigma_xy).max(1e-12);
    let r = 1.0 / (sigma_theta * sigma_theta).max(1e-12);
    Matrix3::new(t, 0.0, 0.0, 0.0, t, 0.0, 0.0, 0.0, r)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests;
