//! Disambiguation by further scans: every hypothesis is moved by the
//! odometry between the scans (for example a rotation in place) and
//! localized locally with the new scan; only the hypotheses at which the new scan
//! leaves little more unexplained than at the best one survive.

use super::config::GlobalConfig;
use super::map::GlobalMap;
use super::search::{
    GlobalError, GlobalResult, Hypothesis, explained_length, global_localize, rank,
};
use crate::geometry::{CogLine, Pose2};
use crate::localize::localize;

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
    let mut moved: Vec<(Hypothesis, f64)> = Vec::new();
    for h in &previous.hypotheses {
        let predicted = h.pose.compose(&motion);
        let prior = predicted_covariance(h, &motion, cfg);
        let Ok(r) = localize(lines, map.index(), predicted, &prior, &cfg.localizer) else {
            continue;
        };
        let matched = explained_length(lines, map, &r.pose, cfg);
        moved.push((
            Hypothesis {
                pose: r.pose,
                covariance: r.covariance,
                score: h.score + matched,
                votes: h.votes,
                refined: true,
                degenerate: r.degenerate,
            },
            matched,
        ));
    }
    let best = moved.iter().map(|m| m.1).fold(0.0, f64::max);
    let survivors: Vec<Hypothesis> = moved
        .into_iter()
        .filter(|(_, m)| best > 0.0 && *m >= best - cfg.consistency_margin)
        .map(|(h, _)| h)
        .collect();
    if survivors.is_empty() {
        return global_localize(lines, map, cfg);
    }
    Ok(rank(survivors, cfg))
}
