//! Global localization of one scan: anchor pairs, voting, refinement by
//! local localization, re-scoring, clustering and the ambiguity verdict.

use super::config::GlobalConfig;
use super::map::{GlobalMap, aabb_of};
use super::vote::{Vote, vote_pair};
use crate::geometry::{CogLine, Pose2, wrap_angle};
use crate::localize::localize;

/// One place the robot may be.
#[derive(Debug, Clone, PartialEq)]
pub struct Hypothesis {
    /// Robot pose in the map frame.
    pub pose: Pose2,
    /// Covariance of `(x, y, θ)` (m², m·rad, rad²): local localization's
    /// when the refinement succeeded (with the voting blur,
    /// `refine_sigma_*`, as its prior), else that prior.
    pub covariance: [[f64; 3]; 3],
    /// Local line length (m) lying on map lines at `pose`, overlaps only
    /// (after [`disambiguate`](super::disambiguate): summed over the scans
    /// used).
    pub score: f64,
    /// Local line length (m) that voted for the unrefined pose.
    pub votes: f64,
    /// Whether local localization refined the voted pose.
    pub refined: bool,
    /// A translation direction (map frame, unit) the matched lines leave
    /// unconstrained, as in a plain corridor; the position along it is a guess.
    pub degenerate: Option<[f64; 2]>,
}

/// Ranked hypotheses for one scan.
#[derive(Debug, Clone, PartialEq)]
pub struct GlobalResult {
    /// Distinct poses, best score first.
    pub hypotheses: Vec<Hypothesis>,
    /// Whether the best is not clearly the place: a distinct runner-up
    /// scores within [`GlobalConfig::ambiguity_ratio`] of it, the best
    /// leaves a direction unconstrained, or local localization did not
    /// confirm it.
    pub ambiguous: bool,
}

impl GlobalResult {
    /// The best hypothesis, if any.
    pub fn best(&self) -> Option<&Hypothesis> {
        self.hypotheses.first()
    }
}

/// Why a scan could not be localized globally.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GlobalError {
    #[error("the map has no lines")]
    EmptyMap,
    #[error("no scan line is at least {min_length} m long to anchor the search")]
    NoAnchor { min_length: f64 },
    #[error("invalid configuration: {what}")]
    InvalidConfig { what: &'static str },
}

/// Diagonal covariance with standard deviations `sxy` (m) and `sth` (rad).
pub(crate) fn diagonal(sxy: f64, sth: f64) -> [[f64; 3]; 3] {
    [
        [sxy * sxy, 0.0, 0.0],
        [0.0, sxy * sxy, 0.0],
        [0.0, 0.0, sth * sth],
    ]
}

/// Local line length (m) explained by the map at `pose`: for each local
/// line, the summed length of its overlaps with the map lines of nearly the
/// same direction that run within `score_distance` of it there, at most its
/// own length. Counting overlaps rather than whole matched lines keeps a
/// wall seen whole from scoring fully against a shorter wall at a wrong
/// place, and summing over map lines credits a wall the map holds in
/// pieces (which the centre-based correspondence test may miss when the
/// scan's centroid lies off every piece).
pub(crate) fn explained_length(
    lines: &[CogLine],
    map: &GlobalMap,
    pose: &Pose2,
    cfg: &GlobalConfig,
) -> f64 {
    let mut total = 0.0;
    for line in lines {
        let seen = line.transformed(pose);
        let query = aabb_of(&[seen.start, seen.end], cfg.score_distance);
        let mut covered = 0.0;
        for j in map.overlapping(query) {
            let Some(g) = map.lines().get(j) else {
                continue;
            };
            if wrap_angle(g.theta - seen.theta).abs() > cfg.score_angle {
                continue;
            }
            let (a, b) = (g.along(seen.start), g.along(seen.end));
            let (g0, g1) = g.extent();
            let lo = a.min(b).max(g0.min(g1));
            let hi = a.max(b).min(g0.max(g1));
            if hi <= lo {
                continue;
            }
            let d = g.direction();
            let s = 0.5 * (lo + hi);
            let mid = [g.xc + s * d[0], g.yc + s * d[1]];
            if seen.distance_to_point(mid) <= cfg.score_distance {
                covered += hi - lo;
            }
        }
        total += covered.min(line.length());
    }
    total
}

pub(crate) fn check_config(cfg: &GlobalConfig) -> Result<(), GlobalError> {
    let positive = [
        (cfg.blur, "blur"),
        (cfg.score_angle, "score_angle"),
        (cfg.score_distance, "score_distance"),
        (cfg.angle_tolerance, "angle_tolerance"),
        (cfg.refine_sigma_xy, "refine_sigma_xy"),
        (cfg.refine_sigma_theta, "refine_sigma_theta"),
        (cfg.odometry_sigma_floor, "odometry_sigma_floor"),
    ];
    for (v, what) in positive {
        if !(v.is_finite() && v > 0.0) {
            return Err(GlobalError::InvalidConfig { what });
        }
    }
    let non_negative = [
        (cfg.length_tolerance, "length_tolerance"),
        (cfg.partner_min_fraction, "partner_min_fraction"),
        (cfg.extent_tolerance, "extent_tolerance"),
        (cfg.min_anchor_length, "min_anchor_length"),
        (cfg.cluster_distance, "cluster_distance"),
        (cfg.cluster_angle, "cluster_angle"),
        (cfg.ambiguity_ratio, "ambiguity_ratio"),
        (cfg.odometry_sigma_per_m, "odometry_sigma_per_m"),
        (cfg.odometry_sigma_per_rad, "odometry_sigma_per_rad"),
        (cfg.min_explained, "min_explained"),
        (cfg.max_free_space_conflict, "max_free_space_conflict"),
        (cfg.free_space_tolerance, "free_space_tolerance"),
    ];
    for (v, what) in non_negative {
        if !(v.is_finite() && v >= 0.0) {
            return Err(GlobalError::InvalidConfig { what });
        }
    }
    Ok(())
}

/// Whether two poses are the same place under the clustering tolerances.
pub(crate) fn same_place(a: &Pose2, b: &Pose2, cfg: &GlobalConfig) -> bool {
    (a.x - b.x).hypot(a.y - b.y) <= cfg.cluster_distance
        && wrap_angle(a.theta - b.theta).abs() <= cfg.cluster_angle
}

/// Orders by score (best first), ties by position, so results do not depend
/// on iteration order.
fn by_score(a: &Hypothesis, b: &Hypothesis) -> std::cmp::Ordering {
    b.score
        .total_cmp(&a.score)
        .then(b.votes.total_cmp(&a.votes))
        .then(a.pose.x.total_cmp(&b.pose.x))
        .then(a.pose.y.total_cmp(&b.pose.y))
        .then(a.pose.theta.total_cmp(&b.pose.theta))
}

/// Sorts, merges same places (keeping the best of each) and truncates.
pub(crate) fn rank(mut hyps: Vec<Hypothesis>, cfg: &GlobalConfig) -> GlobalResult {
    hyps.sort_by(by_score);
    let mut kept: Vec<Hypothesis> = Vec::new();
    for h in hyps {
        if kept.len() >= cfg.max_hypotheses.max(1) {
            break;
        }
        if kept.iter().all(|k| !same_place(&k.pose, &h.pose, cfg)) {
            kept.push(h);
        }
    }
    let ambiguous = match kept.as_slice() {
        [] => false,
        [best, rest @ ..] => {
            // Only a pose that local localization confirmed is the place.
            !best.refined
                || best.degenerate.is_some()
                || rest
                    .first()
                    .is_some_and(|r| r.score >= cfg.ambiguity_ratio * best.score)
        }
    };
    GlobalResult {
        hypotheses: kept,
        ambiguous,
    }
}

/// Refines a voted pose by local localization and re-scores it by the
/// matched local length; an unrefinable pose keeps its vote.
pub(crate) fn refine(
    lines: &[CogLine],
    map: &GlobalMap,
    pose: Pose2,
    prior: &[[f64; 3]; 3],
    votes: f64,
    cfg: &GlobalConfig,
) -> Hypothesis {
    match localize(lines, map.index(), pose, prior, &cfg.localizer) {
        Ok(r) => {
            let score = explained_length(lines, map, &r.pose, cfg);
            Hypothesis {
                pose: r.pose,
                covariance: r.covariance,
                score,
                votes,
                refined: true,
                degenerate: r.degenerate,
            }
        }
        Err(_) => {
            let score = explained_length(lines, map, &pose, cfg);
            Hypothesis {
                pose,
                covariance: *prior,
                score,
                votes,
                refined: false,
                degenerate: None,
            }
        }
    }
}

/// Votes (m of local line) this close count as tied.
const TIED_VOTES: f64 = 1e-6;
/// At most this many times [`GlobalConfig::refine_candidates`] are refined
/// when votes tie at the cut.
const TIED_CANDIDATES_FACTOR: usize = 4;

/// Global localization of one scan: `lines` in the robot frame (from
/// [`extract_lines`](crate::geometry::extract_lines)), `map` in the map
/// frame. Returns the distinct candidate poses, best first.
pub fn global_localize(
    lines: &[CogLine],
    map: &GlobalMap,
    cfg: &GlobalConfig,
) -> Result<GlobalResult, GlobalError> {
    check_config(cfg)?;
    if map.is_empty() {
        return Err(GlobalError::EmptyMap);
    }
    let mut local: Vec<CogLine> = lines
        .iter()
        .filter(|l| {
            [
                l.theta, l.xc, l.yc, l.start[0], l.start[1], l.end[0], l.end[1],
            ]
            .iter()
            .all(|v| v.is_finite())
        })
        .copied()
        .collect();
    local.sort_by(|a, b| b.length().total_cmp(&a.length()));
    let anchors: Vec<usize> = (0..local.len().min(cfg.anchors.max(1)))
        .filter(|&i| local[i].length() >= cfg.min_anchor_length)
        .collect();
    if anchors.is_empty() {
        return Err(GlobalError::NoAnchor {
            min_length: cfg.min_anchor_length,
        });
    }

    let mut votes: Vec<Vote> = Vec::new();
    let mut supports = Vec::new();
    let mut voters: Vec<CogLine> = Vec::with_capacity(cfg.max_voters);
    for &ai in &anchors {
        let anchor = local[ai];
        voters.clear();
        voters.extend(
            local
                .iter()
                .enumerate()
                .filter(|&(i, _)| i != ai)
                .map(|(_, l)| *l)
                .take(cfg.max_voters),
        );
        let shortest = (anchor.length() - cfg.length_tolerance)
            .min(cfg.partner_min_fraction * anchor.length());
        for partner in map.at_least(shortest) {
            votes.extend(vote_pair(
                &anchor,
                partner,
                &voters,
                map,
                cfg,
                &mut supports,
            ));
        }
    }

    // Best votes first; near-identical ones are one candidate.
    votes.sort_by(|a, b| {
        b.score
            .total_cmp(&a.score)
            .then(a.pose.x.total_cmp(&b.pose.x))
            .then(a.pose.y.total_cmp(&b.pose.y))
            .then(a.pose.theta.total_cmp(&b.pose.theta))
    });
    // Votes tied with the last candidate taken are taken too: a scan of
    // few lines (a corridor's end: one wall and the end wall) gives dozens
    // of places the same vote, and whichever the sort put last would never
    // be refined, however well it explains the scan. Past the cap, the
    // places left out could hold the best, so the answer is not clear.
    let wanted = cfg.refine_candidates.max(1);
    let mut candidates: Vec<Vote> = Vec::new();
    let mut tied_left_out = false;
    for v in votes {
        if candidates.len() >= wanted {
            let tied = candidates
                .last()
                .is_some_and(|c| v.score >= c.score - TIED_VOTES);
            if !tied {
                break;
            }
            if candidates.len() >= TIED_CANDIDATES_FACTOR * wanted {
                tied_left_out = true;
                break;
            }
        }
        if candidates
            .iter()
            .all(|c| !same_place(&c.pose, &v.pose, cfg))
        {
            candidates.push(v);
        }
    }

    let prior = diagonal(cfg.refine_sigma_xy, cfg.refine_sigma_theta);
    let hyps = candidates
        .iter()
        .map(|v| refine(&local, map, v.pose, &prior, v.score, cfg))
        .collect();
    let mut result = rank(hyps, cfg);
    result.ambiguous |= tied_left_out;
    Ok(result)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// The walls of a room given as a counter-clockwise polygon (free
    /// space on the left of each edge).
    fn room(corners: &[[f64; 2]]) -> Vec<CogLine> {
        (0..corners.len())
            .map(|i| {
                let (a, b) = (corners[i], corners[(i + 1) % corners.len()]);
                let len = (b[0] - a[0]).hypot(b[1] - a[1]);
                let theta = (b[1] - a[1]).atan2(b[0] - a[0]);
                let mid = [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])];
                CogLine::from_centre(theta, mid, -0.5 * len, 0.5 * len, 0.001, 0.002, 50)
            })
            .collect()
    }

    /// The map lines as seen from `pose` (robot frame), whole.
    fn seen_from(map: &[CogLine], pose: &Pose2) -> Vec<CogLine> {
        map.iter().map(|l| l.transformed(&pose.inverse())).collect()
    }

    #[test]
    fn an_asymmetric_room_gives_one_clear_answer() {
        // An L-shaped room.
        let walls = room(&[
            [0.0, 0.0],
            [8.0, 0.0],
            [8.0, 3.0],
            [4.0, 3.0],
            [4.0, 6.0],
            [0.0, 6.0],
        ]);
        let map = GlobalMap::new(walls.clone());
        let truth = Pose2::new(3.0, 2.0, 0.7);
        let r =
            global_localize(&seen_from(&walls, &truth), &map, &GlobalConfig::default()).unwrap();
        let best = r.best().unwrap();
        assert!(
            (best.pose.x - truth.x).hypot(best.pose.y - truth.y) < 1e-3,
            "{r:?}"
        );
        assert!(
            wrap_angle(best.pose.theta - truth.theta).abs() < 1e-3,
            "{r:?}"
        );
        assert!(best.refined);
        assert!(!r.ambiguous, "{r:?}");
        let total: f64 = walls.iter().map(CogLine::length).sum();
        assert!(
            (best.score - total).abs() < 1e-6,
            "{} of {total}",
            best.score
        );
    }

    #[test]
    fn a_rectangle_has_two_equal_answers_and_says_so() {
        let walls = room(&[[0.0, 0.0], [8.0, 0.0], [8.0, 6.0], [0.0, 6.0]]);
        let map = GlobalMap::new(walls.clone());
        let truth = Pose2::new(3.0, 2.0, 0.7);
        let twin = Pose2::new(5.0, 4.0, 0.7 + std::f64::consts::PI);
        let r =
            global_localize(&seen_from(&walls, &truth), &map, &GlobalConfig::default()).unwrap();
        assert!(r.ambiguous, "{r:?}");
        for p in [truth, twin] {
            assert!(
                r.hypotheses[..2].iter().any(|h| {
                    (h.pose.x - p.x).hypot(h.pose.y - p.y) < 1e-3
                        && wrap_angle(h.pose.theta - p.theta).abs() < 1e-3
                }),
                "{p:?} missing from {r:?}"
            );
        }
    }

    #[test]
    fn a_place_whose_vote_ties_with_many_is_still_refined() {
        // The end of a corridor seen from in front of it: one long wall
        // and the end wall, 2 lines. Forty shorter walls ending in the
        // same corner, each a place the two lines vote for as much as for
        // the true one, come before it in the vote order; only the true
        // one explains the whole scan once refined.
        let corner = |x: f64, length: f64| {
            vec![
                CogLine::from_centre(
                    0.0,
                    [x - 0.5 * length, 0.0],
                    -0.5 * length,
                    0.5 * length,
                    0.001,
                    0.002,
                    50,
                ),
                CogLine::from_centre(
                    std::f64::consts::FRAC_PI_2,
                    [x, 1.0],
                    -1.0,
                    1.0,
                    0.001,
                    0.002,
                    50,
                ),
            ]
        };
        let mut walls: Vec<CogLine> = (0..40).flat_map(|k| corner(20.0 * k as f64, 6.0)).collect();
        let truth_corner = corner(2000.0, 9.5);
        walls.extend(truth_corner.iter().copied());
        let map = GlobalMap::new(walls);
        let truth = Pose2::new(1998.5, 1.5, -1.36);
        let r = global_localize(
            &seen_from(&truth_corner, &truth),
            &map,
            &GlobalConfig::default(),
        )
        .unwrap();
        let best = r.best().unwrap();
        assert!(
            (best.pose.x - truth.x).hypot(best.pose.y - truth.y) < 1e-3,
            "{r:?}"
        );
        assert!(!r.ambiguous, "{r:?}");
    }

    #[test]
    fn ranking_merges_only_the_same_place() {
        let cfg = GlobalConfig::default();
        let h = |x: f64, score: f64| Hypothesis {
            pose: Pose2::new(x, 0.0, 0.0),
            covariance: diagonal(0.1, 0.05),
            score,
            votes: score,
            refined: true,
            degenerate: None,
        };
        let r = rank(vec![h(0.0, 5.0), h(0.1, 4.0), h(3.0, 4.5)], &cfg);
        assert_eq!(r.hypotheses.len(), 2);
        assert_eq!(r.hypotheses[0].score, 5.0);
        assert!(r.ambiguous, "4.5 is within 15 % of 5");
        let r = rank(vec![h(0.0, 5.0), h(3.0, 2.0)], &cfg);
        assert!(!r.ambiguous);
    }
}
