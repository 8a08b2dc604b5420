//! Disambiguation by further scans: every hypothesis is moved by the
//! odometry between the scans (for example a rotation in place) and
//! localized locally with the new scan (kept where the odometry puts it
//! when that fails); a hypothesis is dropped when the new scan leaves more
//! unexplained there than at the best one, beyond what the scan it was
//! first tracked from did, or most of the scan unexplained. [`refute`] drops those at which
//! map walls stand in the scan's free space.

use super::config::GlobalConfig;
use super::map::GlobalMap;
use super::search::{
    GlobalError, GlobalResult, Hypothesis, check_config, explained_length, global_localize, rank,
};
use crate::geometry::{CogLine, Pose2};
use crate::localize::localize;
use crate::map::cls::LocalRegion;

/// Covariance of a hypothesis moved by `motion` (robot frame): its own plus
/// odometry noise growing with the distance and the turn.
fn predicted_covariance(h: &Hypothesis, motion: &Pose2, cfg: &GlobalConfig) -> [[f64; 3]; 3] {
    let sxy = cfg.odometry_sigma_floor + cfg.odometry_sigma_per_m * motion.x.hypot(motion.y);
    let sth = cfg.odometry_sigma_floor + cfg.odometry_sigma_per_rad * motion.theta.abs();
    let mut cov = h.covariance;
    // The hypothesis' own heading uncertainty also swings the position;
    // the diagonal odometry term below is larger than that for short moves.
    cov[0][0] += sxy * sxy;
    cov[1][1] += sxy * sxy;
    cov[2][2] += sth * sth;
    cov
}

/// Keeps the hypotheses of `previous` that are consistent with a further
/// scan: `lines` (robot frame) taken after the robot moved by `motion`
/// (odometry, in the frame of the previous scan's pose). Survivors carry
/// their new pose and their score plus the new scan's matched length; the
/// ambiguity is judged again on the accumulated scores. When no hypothesis
/// survives (the odometry or the earlier scans were wrong), the scan is
/// localized globally afresh.
pub fn disambiguate(
    previous: &GlobalResult,
    lines: &[CogLine],
    motion: Pose2,
    map: &GlobalMap,
    cfg: &GlobalConfig,
) -> Result<GlobalResult, GlobalError> {
    // The best place's explained length on the previous scan, against
    // which each place's shortfall then is measured (the allowance of a
    // place tracked for the first time).
    let best_before = previous
        .hypotheses
        .iter()
        .map(|h| h.last_matched)
        .fold(0.0, f64::max);
    check_config(cfg)?;
    let mut moved: Vec<(Hypothesis, f64, f64)> = Vec::new();
    for h in &previous.hypotheses {
        let predicted = h.pose.compose(&motion);
        let mut prior = predicted_covariance(h, &motion, cfg);
        let mut localizer = cfg.localizer;
        if let Some(v) = h.degenerate {
            // Where along a corridor the robot is was a guess: the scan
            // that first shows a cross wall may move it far along it.
            let along = cfg.localizer.max_translation_jump;
            for (r, vr) in v.iter().enumerate() {
                for (c, vc) in v.iter().enumerate() {
                    prior[r][c] += along * along * vr * vc;
                }
            }
            localizer.max_translation_jump = 3.0 * along;
        }
        // A local localization that fails (a wall up close, too few lines)
        // is no evidence against the place: the hypothesis stays where the
        // odometry puts it and is judged by what the scan shows there.
        let (pose, covariance, refined, degenerate) =
            match localize(lines, map.index(), predicted, &prior, &localizer) {
                Ok(r) => (r.pose, r.covariance, true, r.degenerate),
                Err(_) => (predicted, prior, false, None),
            };
        let matched = explained_length(lines, map, &pose, cfg);
        // The shortfall the place had when first tracked (a view it
        // explained less from the start says nothing new against it),
        // kept while it is tracked: a shortfall that grows a little with
        // each scan (a wall coming into view as the robot drives that
        // only the true place has) is judged in all, not scan by scan.
        let allowance = if h.allowance.is_finite() {
            h.allowance
        } else {
            (best_before - h.last_matched).max(0.0)
        };
        moved.push((
            Hypothesis {
                pose,
                covariance,
                score: h.score + matched,
                last_matched: matched,
                votes: h.votes,
                refined,
                degenerate,
                allowance,
            },
            matched,
            allowance,
        ));
    }
    // The new scan drops a place when it explains more than the margin
    // less there than at the best place, beyond the shortfall the place
    // had when first tracked (the same view again drops nothing), or when
    // it leaves most of the scan unexplained there: when no place explains
    // the scan, the search starts over from this scan.
    let best = moved.iter().map(|m| m.1).fold(0.0, f64::max);
    let shown: f64 = lines.iter().map(CogLine::length).sum();
    let survivors: Vec<Hypothesis> = moved
        .into_iter()
        .filter(|(_, m, before)| {
            best > 0.0
                && *m >= cfg.min_explained * shown
                && best - m <= cfg.consistency_margin + before.max(0.0)
        })
        .map(|(h, _, _)| h)
        .collect();
    if survivors.is_empty() {
        return global_localize(lines, map, cfg);
    }
    Ok(rank(survivors, cfg))
}

/// Drops the hypotheses at whose pose more than
/// [`GlobalConfig::max_free_space_conflict`] of the map's walls stands
/// inside `free`, the scan's free space (robot frame): the beams went
/// through where the map has a wall, so the robot is not there. Matched
/// line length only counts what agrees; this counts what contradicts,
/// which tells apart places that agree on every wall one of them shows.
pub fn refute(
    result: GlobalResult,
    free: &LocalRegion,
    map: &GlobalMap,
    cfg: &GlobalConfig,
) -> GlobalResult {
    let (centre, radius) = free.bounding_circle();
    let kept: Vec<Hypothesis> = result
        .hypotheses
        .into_iter()
        .filter(|h| {
            // Along a corridor the pose is a guess: its jambs and cross
            // walls may stand in the free space of the true place a metre
            // on, so a degenerate hypothesis is not judged by them.
            if h.degenerate.is_some() {
                return true;
            }
            let region = free.transformed(&h.pose);
            let walls = map.index().near(h.pose.transform_point(centre), radius);
            region.length_inside(walls, cfg.free_space_tolerance) <= cfg.max_free_space_conflict
        })
        .collect();
    rank(kept, cfg)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn wall(theta: f64, centre: [f64; 2], half: f64) -> CogLine {
        CogLine::from_centre(theta, centre, -half, half, 0.001, 0.002, 100)
    }

    /// A 4 m wide corridor stretch and its twin 12 m on; only the first has
    /// an end wall 3 m ahead. The robot at the first sees that wall more
    /// with each scan (it drives out of a door, the wall comes into view):
    /// the twin, which explains the rest as well, falls short by 0.1 m
    /// more each scan, never by the margin in one, and is dropped once the
    /// shortfall it had when first tracked is exceeded by the margin.
    #[test]
    fn a_shortfall_growing_scan_by_scan_drops_the_twin() {
        let half_pi = std::f64::consts::FRAC_PI_2;
        let map = GlobalMap::new([
            wall(0.0, [0.0, 2.0], 3.0),
            wall(0.0, [0.0, -2.0], 3.0),
            wall(half_pi, [3.0, 0.0], 2.0),
            wall(0.0, [12.0, 2.0], 3.0),
            wall(0.0, [12.0, -2.0], 3.0),
        ]);
        let cfg = GlobalConfig::default();
        let place = |x: f64| Hypothesis {
            pose: Pose2::new(x, 0.0, 0.0),
            covariance: [[1e-4, 0.0, 0.0], [0.0, 1e-4, 0.0], [0.0, 0.0, 1e-5]],
            score: 12.0,
            last_matched: 12.0,
            votes: 12.0,
            refined: true,
            degenerate: None,
            allowance: f64::INFINITY,
        };
        let mut result = GlobalResult {
            hypotheses: vec![place(0.0), place(12.0)],
            ambiguous: true,
        };
        for i in 1..=15 {
            let seen = 0.05 * f64::from(i);
            let lines = [
                wall(0.0, [0.0, 2.0], 3.0),
                wall(0.0, [0.0, -2.0], 3.0),
                wall(half_pi, [3.0, 0.0], seen),
            ];
            result = disambiguate(&result, &lines, Pose2::IDENTITY, &map, &cfg).unwrap();
        }
        let xs: Vec<f64> = result.hypotheses.iter().map(|h| h.pose.x).collect();
        assert_eq!(xs.len(), 1, "{result:#?}");
        assert!(xs[0].abs() < 0.05, "{xs:?}");
        assert!(!result.ambiguous);
    }
}
