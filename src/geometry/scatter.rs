//! How far a sensor's points scatter about the straight walls they lie
//! on: the range noise a log shows, which need not be the LMS200's.
//!
//! Runs of consecutive beams on smooth surfaces are fitted with a straight
//! line each, and the quartile of their residuals gives the noise: the
//! cleanest quarter of the runs lie on flat walls, while the rest take in
//! corners, clutter and rough surfaces. The public benchmark logs fall in
//! two groups: 4–7 mm (CSAIL 5.8 mm, Intel 5.0 mm, Freiburg 079 6.1 mm)
//! and 2–3 cm (ACES 2.1 cm, its ranges on a 5 cm grid; MIT's Killian
//! Court 2.1 cm).

use super::fit::principal_axes;
use super::scan::RangeScan;
use std::borrow::Borrow;

/// Beams fitted with one line.
const RUN: usize = 9;
/// Runs start this many beams apart.
const RUN_STEP: usize = 5;
/// Ranges (m) used: nearer readings are the sensor's faults, and farther
/// ones scatter more (CSAIL's runs: 5 mm under 4 m, 13 mm beyond 8 m)
/// while a run of them spans metres of wall.
const MIN_RANGE: f64 = 0.1;
const MAX_RANGE: f64 = 8.0;
/// Largest range step (m) between neighbours within a run: a larger one
/// is an edge, not one surface.
const MAX_STEP: f64 = 0.2;
/// Fewest runs for an estimate.
const MIN_RUNS: usize = 200;
/// The quartile of the runs' residual RMS per unit of range noise σ:
/// 0.61–0.65 in simulated rectangular rooms with Gaussian range noise of
/// 5 mm to 2 cm, at 1° and at 0.5° (the test below).
const QUARTILE_PER_SIGMA: f64 = 0.64;

/// The range noise a sequence of scans shows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WallScatter {
    /// Estimated range noise σ (m).
    pub sigma: f64,
    /// Runs of beams it was estimated from.
    pub runs: usize,
}

/// The range noise `scans` show, if they hold enough runs of beams on
/// smooth surfaces (`MIN_RUNS`).
pub fn wall_scatter<S: Borrow<RangeScan>>(
    scans: impl IntoIterator<Item = S>,
) -> Option<WallScatter> {
    let mut residuals: Vec<f64> = Vec::new();
    // The beams' directions, kept while the scans' geometry stays.
    let mut directions: Vec<(f64, f64)> = Vec::new();
    let mut geometry = None;
    for scan in scans {
        let scan = scan.borrow();
        let this = (
            scan.angle_min.to_bits(),
            scan.angle_increment.to_bits(),
            scan.ranges.len(),
        );
        if geometry != Some(this) {
            directions = (0..scan.ranges.len())
                .map(|i| scan.angle(i).sin_cos())
                .collect();
            geometry = Some(this);
        }
        let points: Vec<Option<(f64, [f64; 2])>> = scan
            .ranges
            .iter()
            .zip(&directions)
            .map(|(r, &(s, c))| {
                let r = *r.as_ref().ok()?;
                ((MIN_RANGE..=MAX_RANGE).contains(&r) && r.is_finite())
                    .then_some((r, [r * c, r * s]))
            })
            .collect();
        for start in (0..points.len().saturating_sub(RUN - 1)).step_by(RUN_STEP) {
            if let Some(rms) = run_residual(&points[start..start + RUN]) {
                residuals.push(rms);
            }
        }
    }
    if residuals.len() < MIN_RUNS {
        return None;
    }
    let quarter = residuals.len() / 4;
    let (_, quartile, _) = residuals.select_nth_unstable_by(quarter, f64::total_cmp);
    Some(WallScatter {
        sigma: *quartile / QUARTILE_PER_SIGMA,
        runs: residuals.len(),
    })
}

/// RMS distance (m) of a run's points from their total-least-squares line
/// (over the degrees of freedom left), if every beam has a point and no
/// step between neighbours is an edge.
fn run_residual(run: &[Option<(f64, [f64; 2])>]) -> Option<f64> {
    let points: Vec<(f64, [f64; 2])> = run.iter().copied().collect::<Option<_>>()?;
    if points
        .windows(2)
        .any(|w| (w[1].0 - w[0].0).abs() > MAX_STEP)
    {
        return None;
    }
    let n = points.len() as f64;
    let mean = points
        .iter()
        .fold([0.0, 0.0], |m, (_, p)| [m[0] + p[0] / n, m[1] + p[1] / n]);
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for (_, p) in &points {
        let (dx, dy) = (p[0] - mean[0], p[1] - mean[1]);
        sxx += dx * dx;
        sxy += dx * dy;
        syy += dy * dy;
    }
    let (_, smallest, _) = principal_axes(sxx, sxy, syy);
    Some((smallest.max(0.0) / (n - 2.0)).sqrt())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::sim::rng::Rng;

    /// Scans from random poses inside random rectangular rooms, ranges
    /// with Gaussian noise `sigma`.
    fn room_scans(sigma: f64, beams: usize, seed: u64) -> Vec<RangeScan> {
        let mut rng = Rng::new(seed);
        (0..100)
            .map(|_| {
                let (w, h) = (rng.uniform_range(4.0, 10.0), rng.uniform_range(3.0, 8.0));
                let (x, y) = (
                    rng.uniform_range(0.5, w - 0.5),
                    rng.uniform_range(0.5, h - 0.5),
                );
                let heading = rng.uniform_range(0.0, std::f64::consts::TAU);
                let increment = std::f64::consts::PI / (beams - 1) as f64;
                let ranges = (0..beams)
                    .map(|i| {
                        let a = heading - std::f64::consts::FRAC_PI_2 + i as f64 * increment;
                        let (s, c) = a.sin_cos();
                        let to_x = if c > 0.0 { (w - x) / c } else { -x / c };
                        let to_y = if s > 0.0 { (h - y) / s } else { -y / s };
                        Ok(to_x.min(to_y) + rng.normal(sigma))
                    })
                    .collect();
                RangeScan {
                    t: 0.0,
                    angle_min: -std::f64::consts::FRAC_PI_2,
                    angle_increment: increment,
                    ranges,
                }
            })
            .collect()
    }

    #[test]
    fn the_noise_of_simulated_rooms_is_found() {
        for (beams, sigma) in [(181, 0.005), (181, 0.02), (361, 0.01), (361, 0.03)] {
            let found = wall_scatter(room_scans(sigma, beams, 7)).unwrap();
            assert!(found.runs > 1000, "{found:?}");
            let ratio = found.sigma / sigma;
            assert!(
                (0.9..1.1).contains(&ratio),
                "{beams} beams, σ {sigma}: {found:?}"
            );
        }
    }

    #[test]
    fn too_few_runs_give_no_estimate() {
        let scans = room_scans(0.01, 181, 1);
        assert!(wall_scatter(&scans[..1]).is_none());
        // Beams without a range give no runs.
        let mut blind = scans[0].clone();
        for r in &mut blind.ranges {
            *r = Err(crate::geometry::BeamFault::NoReturn);
        }
        assert!(wall_scatter(std::iter::repeat_n(&blind, 100)).is_none());
    }
}
