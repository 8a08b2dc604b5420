//! Disambiguation by further scans: every hypothesis is moved by the
//! odometry between the scans (for example a rotation in place) and
//! localized locally with the new scan (kept where the odometry puts it
//! when that fails); a hypothesis is dropped when the scan leaves most of
//! itself unexplained there, or when more of the scan's walls stand in the
//! map's explored free space there than at another place (see
//! [`super::FreeSpace`]). [`refute`] drops those at which map walls stand in
//! the scan's free space.
//!
//! A place is never dropped for explaining less of the scan than another:
//! a wall the map lacks (a corner it never reached, a piece seen from too
//! far to become a line) is no evidence against a place, and look-alike
//! places differ in such gaps by chance, so judging by explained length
//! decided between twins on the map's flaws (one restart in 50 in the
//! office world, on a map made with the odometry's scale learnt, chose the
//! wrong room so). A wall where the map saw through is evidence.

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
    check_config(cfg)?;
    let mut moved: Vec<(Hypothesis, f64)> = Vec::new();
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
                let seen = lines.iter().map(|l| l.transformed(&pose));
                map.free_space()
                    .length_inside(seen, cfg.free_space_tolerance, map.index())
            }),
        );
        moved.push((
            Hypothesis {
                pose,
                covariance,
                score: h.score + matched,
                votes: h.votes,
                refined,
                degenerate,
            },
            matched,
        ));
    }
    // The scan drops a place where it leaves most of itself unexplained
    // (when no place explains it, the search starts over from this scan),
    // and one where more of its walls stand in the map's explored free
    // space than at the place where the fewest do, by more than
    // `max_free_space_conflict`.
    let least_conflict = conflicts
        .iter()
        .flatten()
        .copied()
        .fold(f64::INFINITY, f64::min);
    let shown: f64 = lines.iter().map(CogLine::length).sum();
    let survivors: Vec<Hypothesis> = moved
        .into_iter()
        .zip(conflicts)
        .filter(|((_, m), conflict)| {
            *m > 0.0
                && *m >= cfg.min_explained * shown
                && conflict.is_none_or(|c| c - least_conflict <= cfg.max_free_space_conflict)
        })
        .map(|((h, _), _)| h)
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

    use super::super::free::tests::loop_through as polygon;

    /// Explored free space made of the rectangles `[x0, x1] × [-2, 2]`.
    fn corridors(spans: &[[f64; 2]]) -> crate::map::cls::ClsMap {
        use crate::map::cls::{ClsMap, ClsShape};
        let shapes = spans
            .iter()
            .map(|[x0, x1]| ClsShape {
                outer: polygon(&[[*x0, -2.0], [*x1, -2.0], [*x1, 2.0], [*x0, 2.0]]),
                holes: Vec::new(),
            })
            .collect();
        ClsMap::from_shapes(Default::default(), shapes).unwrap()
    }

    /// A 4 m wide corridor stretch and its twin 12 m on, each closed 3 m
    /// behind the robot; only the first has an end wall 3 m ahead. The robot at the first sees that wall more
    /// with each scan (it drives out of a door, the wall comes into view).
    /// Where the map explored the twin's corridor on past that wall's
    /// place, the wall stands where the map saw through, and the twin is
    /// dropped; where the map's twin ends short of it (a frontier), the
    /// twin only lacks a wall, which is no evidence, and both are kept.
    #[test]
    fn a_wall_coming_into_view_drops_the_twin_only_where_the_map_saw_through() {
        let half_pi = std::f64::consts::FRAC_PI_2;
        // Both stretches start at a wall behind the robot, so neither place
        // leaves the position along the corridor open.
        let walls = [
            wall(0.0, [0.0, 2.0], 3.0),
            wall(0.0, [0.0, -2.0], 3.0),
            wall(-half_pi, [-3.0, 0.0], 2.0),
            wall(half_pi, [3.0, 0.0], 2.0),
            wall(0.0, [12.0, 2.0], 3.0),
            wall(0.0, [12.0, -2.0], 3.0),
            wall(-half_pi, [9.0, 0.0], 2.0),
        ];
        let cfg = GlobalConfig::default();
        let place = |x: f64| Hypothesis {
            pose: Pose2::new(x, 0.0, 0.0),
            covariance: [[1e-4, 0.0, 0.0], [0.0, 1e-4, 0.0], [0.0, 0.0, 1e-5]],
            score: 12.0,
            votes: 12.0,
            refined: true,
            degenerate: None,
        };
        let track = |map: &GlobalMap| {
            let mut result = GlobalResult {
                hypotheses: vec![place(0.0), place(12.0)],
                ambiguous: true,
            };
            for i in 1..=15 {
                let seen = 0.05 * f64::from(i);
                let lines = [
                    wall(0.0, [0.0, 2.0], 3.0),
                    wall(0.0, [0.0, -2.0], 3.0),
                    wall(-half_pi, [-3.0, 0.0], 2.0),
                    wall(half_pi, [3.0, 0.0], seen),
                ];
                result = disambiguate(&result, &lines, Pose2::IDENTITY, map, &cfg).unwrap();
            }
            result
        };
        let explored_on =
            GlobalMap::new(walls).with_free_space(&corridors(&[[-3.0, 3.0], [9.0, 17.0]]));
        let result = track(&explored_on);
        let xs: Vec<f64> = result.hypotheses.iter().map(|h| h.pose.x).collect();
        assert_eq!(xs.len(), 1, "{result:#?}");
        assert!(xs[0].abs() < 0.05, "{xs:?}");
        assert!(!result.ambiguous);
        let explored_short =
            GlobalMap::new(walls).with_free_space(&corridors(&[[-3.0, 3.0], [9.0, 14.9]]));
        let result = track(&explored_short);
        assert_eq!(result.hypotheses.len(), 2, "{result:#?}");
        assert!(result.ambiguous);
    }

    /// Two congruent 4 m rooms 10 m apart; only the first has a cupboard
    /// (0.8 m by 0.4 m) by its south wall. The robot stands in the first
    /// and sees the cupboard's face: the twin explains 0.8 m less, scan
    /// after scan, which alone decides nothing (the map might lack the
    /// cupboard). The face stands where the map saw through at the twin,
    /// and that drops it.
    #[test]
    fn a_wall_where_the_map_saw_through_drops_the_look_alike_place() {
        use crate::map::cls::{ClsMap, ClsShape};
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
            votes: matched,
            refined: true,
            degenerate: None,
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
