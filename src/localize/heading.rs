//! Heading search: local localization for a prediction whose heading is
//! off by more than its covariance admits.
//!
//! Odometry headings lag in fast turns: between scans 0.7 m apart, logged
//! odometry was seen 10–20° off in a 10° turn, while its noise model
//! allowed 3°. No line then falls inside the correspondence gates, and
//! local localization finds nothing to match, scan after scan, while the
//! heading error goes into the map.
//!
//! A rotation about the robot keeps each line's distance from the robot
//! and its placement along itself, and turns only its direction. So every
//! pair of a local line and a map line with about the same distance and an
//! overlapping placement votes for the rotation that aligns them, weighted
//! by the length they share; the best-supported rotations (apart from the
//! prediction's own, which failed) are tried as new predictions, and the
//! fix with the most matches wins. The result must still lie within the
//! localizer's jump limits of the original prediction.

use super::local::{LocalizationResult, LocalizeError, LocalizerConfig, localize, rotation_limit};
use crate::geometry::SegmentIndex;
use crate::geometry::{CogLine, Pose2, wrap_angle};

/// Rotations (rad) about `predicted`'s position that would bring
/// `local` lines (robot frame) onto `map` lines, best supported first: at
/// most `tries`, each at least `separation` from the others and from 0,
/// none beyond `limit`. A pair votes when the lines' distances from the
/// robot differ by at most `tolerance` (m) and their placements along
/// themselves overlap with that much slack.
pub fn heading_candidates(
    local: &[CogLine],
    map: &SegmentIndex,
    predicted: &Pose2,
    limit: f64,
    tolerance: f64,
    separation: f64,
    tries: usize,
) -> Vec<f64> {
    let robot = [predicted.x, predicted.y];
    let reach = local
        .iter()
        .flat_map(|l| [l.start, l.end])
        .map(|p| p[0].hypot(p[1]))
        .fold(0.0, f64::max)
        + tolerance;
    let nearby: Vec<&CogLine> = map.near(robot, reach).collect();
    let mut votes: Vec<(f64, f64)> = Vec::new();
    for l in local {
        let d_local = l.signed_distance([0.0, 0.0]);
        let a = l.along([0.0, 0.0]);
        let (lo, hi) = l.extent();
        let (l_lo, l_hi) = (lo - a, hi - a);
        for m in &nearby {
            let rotation = wrap_angle(m.theta - l.theta - predicted.theta);
            if rotation.abs() > limit || (m.signed_distance(robot) - d_local).abs() > tolerance {
                continue;
            }
            let b = m.along(robot);
            let (lo, hi) = m.extent();
            let shared = l_hi.min(hi - b) - l_lo.max(lo - b) + tolerance;
            if shared > 0.0 {
                votes.push((rotation, shared.min(l.length()).min(m.length())));
            }
        }
    }
    // Support of each vote's rotation: the weight within half a
    // separation of it, and their weighted mean.
    let half = 0.5 * separation;
    let mut supported: Vec<(f64, f64)> = votes
        .iter()
        .map(|&(r, _)| {
            let (w, wr) = votes
                .iter()
                .filter(|(q, _)| (q - r).abs() <= half)
                .fold((0.0, 0.0), |(w, wr), &(q, v)| (w + v, wr + v * q));
            (w, wr / w)
        })
        .collect();
    supported.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.total_cmp(&b.1)));
    let mut chosen: Vec<f64> = Vec::new();
    for (_, r) in supported {
        if chosen.len() >= tries {
            break;
        }
        if r.abs() >= half && chosen.iter().all(|c| (c - r).abs() >= separation) {
            chosen.push(r);
        }
    }
    chosen
}

/// [`localize`], and when it finds too few matches, again from the
/// prediction turned by each of [`heading_candidates`]
/// (`cfg.heading_search` of them): the fix with the most matches (then
/// the lowest χ²) whose jump from `predicted` is within the limits, or the
/// first error. A searched heading needs one match more than
/// `cfg.min_matches`, since it was chosen to make lines match, and must
/// leave no direction unconstrained. When nothing within the rotation
/// limit fits, headings up to `WIDE_SEARCH` times as far are tried, a
/// fix there needing more than `WIDE_SEARCH_MATCHES` times the matches;
/// only when `wide` (the scan far from the last one, see `WIDE_SEARCH`).
pub fn localize_searching_heading(
    local: &[CogLine],
    map: &SegmentIndex,
    predicted: Pose2,
    prior: &[[f64; 3]; 3],
    cfg: &LocalizerConfig,
    wide: bool,
) -> Result<LocalizationResult, LocalizeError> {
    let first = localize(local, map, predicted, prior, cfg);
    if cfg.heading_search == 0 || !matches!(first, Err(LocalizeError::TooFewMatches { .. })) {
        return first;
    }
    let limit = rotation_limit(prior, cfg);
    search_pass(local, map, predicted, prior, cfg, limit, cfg.min_matches)
        .or_else(|| {
            wide.then(|| {
                search_pass(
                    local,
                    map,
                    predicted,
                    prior,
                    cfg,
                    WIDE_SEARCH * limit,
                    WIDE_SEARCH_MATCHES * cfg.min_matches,
                )
            })
            .flatten()
        })
        .ok_or_else(|| first.err().unwrap_or(LocalizeError::Singular))
}

/// How much farther than the rotation limit a second search looks when
/// nothing within it fits. Logged odometry in a fast turn between sparse
/// scans was seen 18–22° off (CSAIL thinned to scans 0.6 m or 0.3 rad
/// apart) where the limit is 20°: the scan then found nothing, went into
/// the map at the wrong heading, and every later scan localized against
/// it, 5 m of relation error in all. Between scans close in time and
/// motion the odometry cannot lag that far, and there the wider search
/// only finds look-alike headings (one standing still in ACES, 30° off).
const WIDE_SEARCH: f64 = 2.0;
/// A heading from the wider search must match more than this many times
/// the lines a fix needs: far from the prediction, a few chance matches in
/// a rectilinear building are no evidence.
const WIDE_SEARCH_MATCHES: usize = 2;

/// One search for a heading at most `limit` (rad) from `predicted`'s,
/// accepting a fix with more than `min_matches` matches.
fn search_pass(
    local: &[CogLine],
    map: &SegmentIndex,
    predicted: Pose2,
    prior: &[[f64; 3]; 3],
    cfg: &LocalizerConfig,
    limit: f64,
    min_matches: usize,
) -> Option<LocalizationResult> {
    let tolerance = cfg.correspondence.max_centre_distance
        + cfg.gate_sigmas * prior[0][0].max(prior[1][1]).max(0.0).sqrt();
    let candidates = heading_candidates(
        local,
        map,
        &predicted,
        limit,
        tolerance.min(cfg.max_translation_jump),
        cfg.correspondence.max_angle_diff,
        cfg.heading_search,
    );
    // The searched heading is known only to about the vote's width, not
    // to the prediction's σ: the prior's heading is widened to that.
    let separation = cfg.correspondence.max_angle_diff;
    let mut searched_prior = *prior;
    searched_prior[2][2] = prior[2][2].max(separation * separation);
    let mut best: Option<LocalizationResult> = None;
    for rotation in candidates {
        let start = Pose2::new(predicted.x, predicted.y, predicted.theta + rotation);
        let Ok(fix) = localize(local, map, start, &searched_prior, cfg) else {
            continue;
        };
        let dx = (fix.pose.x - predicted.x).hypot(fix.pose.y - predicted.y);
        let dtheta = wrap_angle(fix.pose.theta - predicted.theta).abs();
        if fix.matches.len() <= min_matches
            || fix.degenerate.is_some()
            || dx > cfg.max_translation_jump
            || dtheta > limit
        {
            continue;
        }
        let better = best.as_ref().is_none_or(|b| {
            fix.matches.len() > b.matches.len()
                || (fix.matches.len() == b.matches.len() && fix.chi2 < b.chi2)
        });
        if better {
            best = Some(LocalizationResult {
                heading_searched: true,
                ..fix
            });
        }
    }
    best
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    fn line(theta: f64, c: [f64; 2], half: f64) -> CogLine {
        CogLine::from_centre(theta, c, -half, half, 0.003, 0.002, 60)
    }

    /// An L-shaped corner and a far wall (robot frame), and the map of them
    /// with the robot at `truth`.
    fn corner(truth: &Pose2) -> (Vec<CogLine>, SegmentIndex) {
        seen_from(
            truth,
            vec![
                line(FRAC_PI_2, [4.0, 0.5], 2.0),
                line(std::f64::consts::PI, [1.5, 2.5], 2.5),
                line(0.0, [2.0, -1.8], 2.0),
            ],
        )
    }

    /// `local` (robot frame) and the map of it with the robot at `truth`.
    fn seen_from(truth: &Pose2, local: Vec<CogLine>) -> (Vec<CogLine>, SegmentIndex) {
        let mut map = SegmentIndex::new();
        for l in &local {
            map.insert(l.transformed(truth));
        }
        (local, map)
    }

    const PRIOR: [[f64; 3]; 3] = [[0.0004, 0.0, 0.0], [0.0, 0.0004, 0.0], [0.0, 0.0, 0.0009]];

    #[test]
    fn a_heading_far_outside_the_prior_is_found_and_fixed() {
        let truth = Pose2::new(3.0, 1.0, 0.5);
        let (local, map) = corner(&truth);
        // 17° off, where the prior's σ is 1.7°: the gates let nothing in.
        let predicted = Pose2::new(3.02, 0.99, 0.5 - 0.3);
        let cfg = LocalizerConfig {
            max_rotation_jump: 0.35,
            ..LocalizerConfig::default()
        };
        assert!(matches!(
            localize(&local, &map, predicted, &PRIOR, &cfg),
            Err(LocalizeError::TooFewMatches { .. })
        ));
        let candidates = heading_candidates(&local, &map, &predicted, 0.35, 0.3, 0.087, 3);
        assert!((candidates[0] - 0.3).abs() < 0.01, "{candidates:?}");
        let fix = localize_searching_heading(&local, &map, predicted, &PRIOR, &cfg, true).unwrap();
        assert_eq!(fix.matches.len(), 3);
        assert!(fix.heading_searched);
        assert!(
            wrap_angle(fix.pose.theta - truth.theta).abs() < 1e-3,
            "{:?}",
            fix.pose
        );
        assert!(
            (fix.pose.x - truth.x).hypot(fix.pose.y - truth.y) < 0.01,
            "{:?}",
            fix.pose
        );
    }

    /// The corner's walls and three more round the robot, and their map.
    fn room(truth: &Pose2) -> (Vec<CogLine>, SegmentIndex) {
        let (mut local, _) = corner(truth);
        local.extend([
            line(FRAC_PI_2, [6.0, -3.0], 1.0),
            line(0.0, [5.0, -4.0], 1.0),
            line(std::f64::consts::PI, [3.0, 4.5], 1.0),
        ]);
        seen_from(truth, local)
    }

    #[test]
    fn beyond_the_rotation_limit_only_a_heading_many_lines_agree_on() {
        let truth = Pose2::new(3.0, 1.0, 0.5);
        let cfg = LocalizerConfig::default();
        // 29° off, beyond the 20° limit: three matching lines are too few
        // there, six are enough.
        let predicted = Pose2::new(3.0, 1.0, 0.5 - 0.5);
        let (local, map) = corner(&truth);
        assert!(matches!(
            localize_searching_heading(&local, &map, predicted, &PRIOR, &cfg, true),
            Err(LocalizeError::TooFewMatches { .. })
        ));
        let (local, map) = room(&truth);
        let fix = localize_searching_heading(&local, &map, predicted, &PRIOR, &cfg, true).unwrap();
        assert_eq!(fix.matches.len(), 6);
        assert!(
            wrap_angle(fix.pose.theta - truth.theta).abs() < 1e-3,
            "{:?}",
            fix.pose
        );
        // Nor beyond the limit at all when the scan is near the last one.
        assert!(matches!(
            localize_searching_heading(&local, &map, predicted, &PRIOR, &cfg, false),
            Err(LocalizeError::TooFewMatches { .. })
        ));
        // Beyond twice the limit nothing is tried.
        let predicted = Pose2::new(3.0, 1.0, 0.5 - 0.75);
        assert!(matches!(
            localize_searching_heading(&local, &map, predicted, &PRIOR, &cfg, true),
            Err(LocalizeError::TooFewMatches { .. })
        ));
    }

    #[test]
    fn few_lines_far_off_or_a_disabled_search_find_nothing() {
        let truth = Pose2::new(3.0, 1.0, 0.5);
        let (local, map) = corner(&truth);
        let predicted = Pose2::new(3.0, 1.0, 0.5 - 0.6);
        let cfg = LocalizerConfig::default();
        assert!(matches!(
            localize_searching_heading(&local, &map, predicted, &PRIOR, &cfg, true),
            Err(LocalizeError::TooFewMatches { .. })
        ));
        let predicted = Pose2::new(3.0, 1.0, 0.5 - 0.3);
        let off = LocalizerConfig {
            heading_search: 0,
            ..cfg
        };
        assert!(localize_searching_heading(&local, &map, predicted, &PRIOR, &off, true).is_err());
    }

    #[test]
    fn lines_at_other_distances_do_not_vote() {
        let truth = Pose2::new(0.0, 0.0, 0.0);
        let (local, _) = corner(&truth);
        // The same directions, every wall a metre farther away.
        let mut map = SegmentIndex::new();
        for l in &local {
            let n = l.normal();
            let mut moved = *l;
            moved.xc -= n[0];
            moved.yc -= n[1];
            moved.start = [l.start[0] - n[0], l.start[1] - n[1]];
            moved.end = [l.end[0] - n[0], l.end[1] - n[1]];
            map.insert(moved.transformed(&Pose2::new(0.0, 0.0, 0.2)));
        }
        let candidates = heading_candidates(
            &local,
            &map,
            &Pose2::new(0.0, 0.0, 0.0),
            0.35,
            0.3,
            0.087,
            3,
        );
        assert!(candidates.is_empty(), "{candidates:?}");
    }
}
