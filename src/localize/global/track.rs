//! Disambiguation by further scans: every hypothesis is moved by the
//! odometry between the scans (for example a rotation in place) and
//! localized locally with the new scan (kept where the odometry puts it
//! when that fails); a hypothesis is dropped when the new scan leaves more
//! unexplained there than at the best one, beyond what the scan it was
//! first tracked from did, or most of the scan unexplained, or when more
//! of the scan's walls stand in the map's explored free space there than
//! at another place (see [`super::FreeSpace`]). [`refute`] drops those at
//! which map walls stand in the scan's free space.

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
    // Length of the scan's walls standing where the map saw through, per
    // place (none where the place along a corridor is a guess).
    let mut conflicts: Vec<Option<f64>> = Vec::new();
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
        conflicts.push(
            (degenerate.is_none() && !map.free_space().is_empty()).then(|| {
                let seen: Vec<CogLine> = lines.iter().map(|l| l.transformed(&pose)).collect();
                map.free_space()
                    .length_inside(&seen, cfg.free_space_tolerance)
            }),
        );
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
    //
    // The scan also drops a place where more of its walls stand in the
    // map's explored free space than at the place where the fewest do,
    // by more than `max_free_space_conflict`: a wall where the map saw
    // through contradicts the place, scan after scan, where a wall the
    // map lacks says only that the map may be incomplete there.
    let best = moved.iter().map(|m| m.1).fold(0.0, f64::max);
    let least_conflict = conflicts
        .iter()
        .flatten()
        .copied()
        .fold(f64::INFINITY, f64::min);
    let shown: f64 = lines.iter().map(CogLine::length).sum();
    let survivors: Vec<Hypothesis> = moved
        .into_iter()
        .zip(conflicts)
        .filter(|((_, m, before), conflict)| {
            best > 0.0
                && *m >= cfg.min_explained * shown
                && best - m <= cfg.consistency_margin + before.max(0.0)
                && conflict.is_none_or(|c| c - least_conflict <= cfg.max_free_space_conflict)
        })
        .map(|((h, _, _), _)| h)
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

    /// Two congruent 4 m rooms 10 m apart; only the first has a cupboard
    /// (0.8 m by 0.4 m) by its south wall. The robot stands in the first
    /// and sees the cupboard's face: the twin explains 0.8 m less, scan
    /// after scan, which the shortfall it was first tracked with allows
    /// for, so the walls alone never decide. The face stands where the
    /// map saw through at the twin, and that drops it.
    #[test]
    fn a_wall_where_the_map_saw_through_drops_the_look_alike_place() {
        use crate::map::cls::{ClsLoop, ClsMap, ClsSegment, ClsShape};
        use std::f64::consts::{FRAC_PI_2, PI};
        let room = |x0: f64| {
            vec![
                wall(0.0, [x0 + 2.0, 0.0], 2.0),
                wall(FRAC_PI_2, [x0 + 4.0, 2.0], 2.0),
                wall(PI, [x0 + 2.0, 4.0], 2.0),
                wall(-FRAC_PI_2, [x0, 2.0], 2.0),
            ]
        };
        let face = wall(0.0, [2.0, 1.2], 0.4);
        let mut walls = room(0.0);
        walls.push(face);
        walls.extend(room(10.0));
        let polygon = |points: &[[f64; 2]]| {
            ClsLoop::new(
                points
                    .iter()
                    .zip(points.iter().cycle().skip(1))
                    .map(|(a, b)| ClsSegment::virtual_between(*a, *b))
                    .collect(),
            )
        };
        let square = |x0: f64| polygon(&[[x0, 0.0], [x0 + 4.0, 0.0], [x0 + 4.0, 4.0], [x0, 4.0]]);
        let cupboard = polygon(&[[1.6, 0.8], [1.6, 1.2], [2.4, 1.2], [2.4, 0.8]]);
        let explored = ClsMap::from_shapes(
            Default::default(),
            vec![
                ClsShape {
                    outer: square(0.0),
                    holes: vec![cupboard],
                },
                ClsShape {
                    outer: square(10.0),
                    holes: Vec::new(),
                },
            ],
        )
        .unwrap();
        let here = Pose2::new(2.0, 2.5, 0.3);
        let there = Pose2::new(12.0, 2.5, 0.3);
        let mut seen: Vec<CogLine> = room(0.0);
        seen.push(face);
        let lines: Vec<CogLine> = seen
            .iter()
            .map(|l| l.transformed(&here.inverse()))
            .collect();
        let shown: f64 = lines.iter().map(CogLine::length).sum();
        let place = |pose: Pose2, matched: f64| Hypothesis {
            pose,
            covariance: [[1e-4, 0.0, 0.0], [0.0, 1e-4, 0.0], [0.0, 0.0, 1e-5]],
            score: matched,
            last_matched: matched,
            votes: matched,
            refined: true,
            degenerate: None,
            allowance: f64::INFINITY,
        };
        let start = GlobalResult {
            hypotheses: vec![place(here, shown), place(there, shown - 0.8)],
            ambiguous: true,
        };
        let cfg = GlobalConfig::default();
        let track = |map: &GlobalMap| {
            let mut result = start.clone();
            for _ in 0..10 {
                result = disambiguate(&result, &lines, Pose2::IDENTITY, map, &cfg).unwrap();
            }
            result
        };
        let walls_only = GlobalMap::new(walls.clone());
        assert_eq!(track(&walls_only).hypotheses.len(), 2);
        let with_free = GlobalMap::new(walls).with_free_space(&explored);
        let result = track(&with_free);
        assert_eq!(result.hypotheses.len(), 1, "{result:#?}");
        assert!(result.hypotheses[0].pose.x < 5.0, "{result:#?}");
        assert!(!result.ambiguous);
    }
}
