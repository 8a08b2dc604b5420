//! Total-least-squares line fit with first-order noise propagation.
//!
//! # Uncertainty of the fit
//!
//! The fitted line passes through the centroid `c̄` of the points with unit
//! direction `d` (major axis of the scatter) and left normal `n`. Perturb
//! each point by a small error; only its component `e_i` along `n` moves the
//! line to first order (a shift along the line leaves it in place). Writing
//! `s_i = d·(p_i − c̄)` for the position along the line:
//!
//! - the line's offset at the centroid moves by `mean(e_i)`, so
//!   `σc² = Σ σ_i² / n²`;
//! - its direction turns by the least-squares slope of `e` against `s`,
//!   `δθ = Σ s_i e_i / Σ s_i²`, so `σθ² = Σ s_i² σ_i² / (Σ s_i²)²`;
//! - the two are uncorrelated because `Σ s_i = 0` at the centroid.
//!
//! With equal `σ_i = σ` these reduce to `σc = σ/√n` and
//! `σθ = σ/√(Σ s_i²)`. The laser's noise acts along each beam `u_i`, so the
//! across-line part is `σ_i = σ_r(r_i)·|n·u_i|`: a wall seen head-on gets
//! the full range noise, one seen at grazing incidence much less of it.

use super::cog_line::CogLine;
use super::points::ScanPoint;

/// Running sums `[1, x, y, xx, xy, yy]` of a prefix of the points, so the
/// moments of any index range cost O(1).
#[derive(Debug, Default)]
pub(crate) struct PrefixMoments {
    sums: Vec<[f64; 6]>,
}

/// Centroid and major-axis direction of a point set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct LineFit {
    pub centroid: [f64; 2],
    /// Unit direction; its sign is arbitrary until oriented.
    pub direction: [f64; 2],
}

impl LineFit {
    /// Distance of `p` from the fitted line (m).
    pub fn distance(&self, p: [f64; 2]) -> f64 {
        let [dx, dy] = self.direction;
        (dx * (p[1] - self.centroid[1]) - dy * (p[0] - self.centroid[0])).abs()
    }
}

impl PrefixMoments {
    /// Rebuilds the sums for `points`, reusing the allocation.
    pub fn rebuild(&mut self, points: &[ScanPoint]) {
        self.sums.clear();
        self.sums.reserve(points.len() + 1);
        let mut acc = [0.0f64; 6];
        self.sums.push(acc);
        for sp in points {
            let [x, y] = sp.p;
            acc[0] += 1.0;
            acc[1] += x;
            acc[2] += y;
            acc[3] += x * x;
            acc[4] += x * y;
            acc[5] += y * y;
            self.sums.push(acc);
        }
    }

    /// Total-least-squares line through points `first..=last`, or `None` if
    /// the range is out of bounds or has fewer than two points.
    pub fn fit(&self, first: usize, last: usize) -> Option<LineFit> {
        if last <= first {
            return None;
        }
        let hi = self.sums.get(last + 1)?;
        let lo = self.sums.get(first)?;
        let n = hi[0] - lo[0];
        let mx = (hi[1] - lo[1]) / n;
        let my = (hi[2] - lo[2]) / n;
        // Centred second moments (divided by n; only the ratio matters).
        let sxx = (hi[3] - lo[3]) / n - mx * mx;
        let sxy = (hi[4] - lo[4]) / n - mx * my;
        let syy = (hi[5] - lo[5]) / n - my * my;
        let phi = 0.5 * (2.0 * sxy).atan2(sxx - syy);
        let (s, c) = phi.sin_cos();
        Some(LineFit {
            centroid: [mx, my],
            direction: [c, s],
        })
    }
}

/// How well a line fits a run of points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct FitResiduals {
    /// Largest distance of a point from the line (m).
    pub max_distance: f64,
    /// Index (into the slice) of the interior point farthest from the line;
    /// `None` for fewer than three points.
    pub farthest_interior: Option<usize>,
    /// Reduced χ²: `Σ (dᵢ/σᵢ)² / (n − 2)`, with `σᵢ` the across-line range
    /// noise of point i, floored at `sigma_floor`. About 1 for a straight
    /// wall under the noise model; much more for a bent or stepped one.
    pub chi2_per_dof: f64,
}

/// Residual statistics of `points` about `line`; `sigma_floor` (m) keeps
/// noise-free models from dividing by zero.
pub(crate) fn residuals(points: &[ScanPoint], line: &LineFit, sigma_floor: f64) -> FitResiduals {
    let n = [-line.direction[1], line.direction[0]];
    let mut max_distance = 0.0f64;
    let mut farthest = (None, -1.0f64);
    let mut chi2 = 0.0;
    let last = points.len().saturating_sub(1);
    for (i, sp) in points.iter().enumerate() {
        let d = line.distance(sp.p);
        max_distance = max_distance.max(d);
        if i > 0 && i < last && d > farthest.1 {
            farthest = (Some(i), d);
        }
        let across =
            (sp.sigma_range * (n[0] * sp.beam[0] + n[1] * sp.beam[1]).abs()).max(sigma_floor);
        chi2 += (d / across).powi(2);
    }
    let dof = points.len().saturating_sub(2).max(1) as f64;
    FitResiduals {
        max_distance,
        farthest_interior: farthest.0,
        chi2_per_dof: chi2 / dof,
    }
}

/// The COG line of `points` (in scan order) given their fit: oriented in
/// scan order, end points projected, uncertainties propagated as described
/// in the module documentation. `points` must hold at least two points.
pub(crate) fn cog_line(points: &[ScanPoint], fit: &LineFit) -> Option<CogLine> {
    let (first, last) = (points.first()?, points.last()?);
    let mut d = fit.direction;
    let chord = [last.p[0] - first.p[0], last.p[1] - first.p[1]];
    if d[0] * chord[0] + d[1] * chord[1] < 0.0 {
        d = [-d[0], -d[1]];
    }
    let n = [-d[1], d[0]];
    let c = fit.centroid;
    let mut sum_var = 0.0;
    let mut sum_s2 = 0.0;
    let mut sum_s2_var = 0.0;
    for sp in points {
        let s = d[0] * (sp.p[0] - c[0]) + d[1] * (sp.p[1] - c[1]);
        let across = sp.sigma_range * (n[0] * sp.beam[0] + n[1] * sp.beam[1]).abs();
        let var = across * across;
        sum_var += var;
        sum_s2 += s * s;
        sum_s2_var += s * s * var;
    }
    if sum_s2 <= 0.0 || !sum_s2.is_finite() {
        return None;
    }
    let count = points.len() as f64;
    let sigma_c = sum_var.sqrt() / count;
    let sigma_theta = sum_s2_var.sqrt() / sum_s2;
    let s_start = d[0] * (first.p[0] - c[0]) + d[1] * (first.p[1] - c[1]);
    let s_end = d[0] * (last.p[0] - c[0]) + d[1] * (last.p[1] - c[1]);
    Some(CogLine::from_centre(
        d[1].atan2(d[0]),
        c,
        s_start,
        s_end,
        sigma_theta,
        sigma_c,
        points.len(),
    ))
}

/// The eigenvalues of the symmetric 2×2 matrix `[[a, b], [b, d]]`,
/// largest then smallest, and the unit eigenvector of the smallest (its
/// sign arbitrary): a scatter's or an information matrix's principal
/// axes, in closed form.
pub(crate) fn principal_axes(a: f64, b: f64, d: f64) -> (f64, f64, [f64; 2]) {
    let mean = 0.5 * (a + d);
    let radius = (0.25 * (a - d) * (a - d) + b * b).sqrt();
    let smallest = mean - radius;
    // The better-conditioned of the two forms.
    let v = if (a - smallest).abs() >= (d - smallest).abs() {
        [-b, a - smallest]
    } else {
        [d - smallest, -b]
    };
    let norm = v[0].hypot(v[1]);
    let direction = if norm > 0.0 {
        [v[0] / norm, v[1] / norm]
    } else {
        [1.0, 0.0]
    };
    (mean + radius, smallest, direction)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn pts(xy: &[[f64; 2]], sigma: f64) -> Vec<ScanPoint> {
        xy.iter()
            .map(|&p| {
                let r = p[0].hypot(p[1]);
                ScanPoint {
                    p,
                    beam: [p[0] / r, p[1] / r],
                    sigma_range: sigma,
                    beam_index: 0,
                }
            })
            .collect()
    }

    #[test]
    fn fits_a_wall_and_orients_it_in_scan_order() {
        // Wall x = 2 scanned from y = -1 to y = 1: direction +y, free space
        // (the origin) on the left.
        let xy: Vec<[f64; 2]> = (0..21).map(|i| [2.0, -1.0 + 0.1 * i as f64]).collect();
        let p = pts(&xy, 0.01);
        let mut m = PrefixMoments::default();
        m.rebuild(&p);
        let fit = m.fit(0, 20).unwrap();
        let l = cog_line(&p, &fit).unwrap();
        assert!((l.theta - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!(l.signed_distance([0.0, 0.0]) > 0.0);
        assert!((l.xc - 2.0).abs() < 1e-12 && l.yc.abs() < 1e-12);
        assert!((l.start[1] + 1.0).abs() < 1e-12 && (l.end[1] - 1.0).abs() < 1e-12);
        assert_eq!(m.fit(3, 3), None);
        assert_eq!(m.fit(0, 21), None);
    }

    #[test]
    fn head_on_uncertainty_matches_closed_form() {
        // Beams along the normal everywhere: σ_i = σ, so σc = σ/√n and
        // σθ = σ/√Σs². Build it with beams set explicitly along x.
        let sigma = 0.02;
        let p: Vec<ScanPoint> = (0..11)
            .map(|i| ScanPoint {
                p: [3.0, -0.5 + 0.1 * i as f64],
                beam: [1.0, 0.0],
                sigma_range: sigma,
                beam_index: i,
            })
            .collect();
        let mut m = PrefixMoments::default();
        m.rebuild(&p);
        let l = cog_line(&p, &m.fit(0, 10).unwrap()).unwrap();
        let sum_s2: f64 = (0..11).map(|i| (-0.5 + 0.1 * i as f64).powi(2)).sum();
        assert!((l.sigma_c - sigma / 11f64.sqrt()).abs() < 1e-12);
        assert!((l.sigma_theta - sigma / sum_s2.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn degenerate_point_set_gives_no_line() {
        let p = pts(&[[1.0, 1.0], [1.0, 1.0], [1.0, 1.0]], 0.01);
        let mut m = PrefixMoments::default();
        m.rebuild(&p);
        let fit = m.fit(0, 2).unwrap();
        assert_eq!(cog_line(&p, &fit), None);
    }
}
