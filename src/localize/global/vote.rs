//! Voting for one anchor pair (the paper's translation line segments).
//!
//! Pairing the anchor `L` (robot frame) with a map line `G` fixes the
//! rotation `φ = θG − θL`. The translations that put the rotated anchor on
//! `G`'s line, the shorter of the two inside the other (the paper has `L`
//! inside `G`; maps hold long walls in pieces), form a segment parallel to
//! `G`:
//! `t(u) = centre(G) − R(φ)·mid(L) + u·dir(G)`, `u ∈ [a, b]`, of length
//! `|len(G) − len(L)|`. Every other local line `Lk` votes, with its
//! length, for the `u` at which it lies on some map line `Gk` of matching
//! direction: a point where `Gk` crosses the translation segment (the two
//! translation segments intersect), or an interval when `Gk` is parallel to
//! `G` (they overlap). The `u` covered by the most local length wins.

use super::config::GlobalConfig;
use super::map::{GlobalMap, aabb_of};
use crate::geometry::{CogLine, Pose2, wrap_angle};

/// Below this `|normal(Gk)·dir(G)|` (sine of about 11°) a voter's map line
/// is treated as parallel to the anchor's: its crossing would be too
/// sensitive to the blur to place.
const PARALLEL_SINE: f64 = 0.2;

/// A voted pose and the local length (m) that supports it, anchor included.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Vote {
    pub pose: Pose2,
    pub score: f64,
}

/// One voter's support: local line `voter` lies on a map line for
/// `u ∈ [lo, hi]`, with weight `weight` (m).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Support {
    lo: f64,
    hi: f64,
    weight: f64,
    voter: usize,
}

/// Where the centre of a segment of half length `half` may lie along
/// `line` (from its centre) for the two to overlap as much as their lengths
/// allow: the shorter inside the longer. Widened by `tol` (m) at both ends.
/// A segment longer than the map line covers it (the map holds the wall in
/// pieces), a shorter one lies within it.
fn centre_range(line: &CogLine, half: f64, tol: f64) -> (f64, f64) {
    let (s0, s1) = line.extent();
    let (s0, s1) = (s0.min(s1), s0.max(s1));
    let (p, q) = (s0 + half, s1 - half);
    (p.min(q) - tol, p.max(q) + tol)
}

/// Middle of a segment's end points. The overlap tests need it rather than
/// the centroid, which lies towards the end nearer the sensor (denser
/// points) and would shift a segment's extent by up to a third of its length.
fn midpoint(line: &CogLine) -> [f64; 2] {
    [
        0.5 * (line.start[0] + line.end[0]),
        0.5 * (line.start[1] + line.end[1]),
    ]
}

fn rotate(phi: f64, p: [f64; 2]) -> [f64; 2] {
    let (s, c) = phi.sin_cos();
    [c * p[0] - s * p[1], s * p[0] + c * p[1]]
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

/// The best translations for `anchor` (robot frame) paired with map line
/// `partner`, each with its score; at most `cfg.peaks_per_pair`, best first.
pub(crate) fn vote_pair(
    anchor: &CogLine,
    partner: &CogLine,
    voters: &[CogLine],
    map: &GlobalMap,
    cfg: &GlobalConfig,
    supports: &mut Vec<Support>,
) -> Vec<Vote> {
    let phi = wrap_angle(partner.theta - anchor.theta);
    let dir = partner.direction();
    let (a, b) = centre_range(partner, 0.5 * anchor.length(), cfg.extent_tolerance);
    let rc = rotate(phi, midpoint(anchor));
    // t(u) = t0 + u·dir
    let t0 = [partner.xc - rc[0], partner.yc - rc[1]];
    let at = |u: f64| [t0[0] + u * dir[0], t0[1] + u * dir[1]];

    supports.clear();
    for (k, voter) in voters.iter().enumerate() {
        let theta_k = voter.theta + phi;
        let ck = rotate(phi, midpoint(voter));
        let half = 0.5 * voter.length();
        // The voter swept along the translation segment.
        let (ta, tb) = (at(a), at(b));
        let ends = [rotate(phi, voter.start), rotate(phi, voter.end)];
        let swept = [
            [ends[0][0] + ta[0], ends[0][1] + ta[1]],
            [ends[1][0] + ta[0], ends[1][1] + ta[1]],
            [ends[0][0] + tb[0], ends[0][1] + tb[1]],
            [ends[1][0] + tb[0], ends[1][1] + tb[1]],
        ];
        let query = aabb_of(&swept, cfg.blur + cfg.extent_tolerance);
        for j in map.overlapping(query) {
            let Some(g) = map.lines().get(j) else {
                continue;
            };
            if wrap_angle(g.theta - theta_k).abs() > cfg.angle_tolerance {
                continue;
            }
            let n = g.normal();
            let d = g.direction();
            // Voter centre at u: ck + t0 + u·dir; offset from g's line and
            // position along it are linear in u.
            let p0 = [ck[0] + t0[0], ck[1] + t0[1]];
            let off0 = g.signed_distance(p0);
            let off_rate = dot(n, dir);
            let s0 = g.along(p0);
            let s_rate = dot(d, dir);
            let (slo, shi) = centre_range(g, half, cfg.extent_tolerance);
            let (lo, hi) = if off_rate.abs() >= PARALLEL_SINE {
                let u = -off0 / off_rate;
                let s = s0 + u * s_rate;
                if s < slo || s > shi {
                    continue;
                }
                let w = cfg.blur / off_rate.abs();
                (u - w, u + w)
            } else {
                // Parallel: the offset barely changes along the segment.
                let mid = 0.5 * (a + b);
                if (off0 + mid * off_rate).abs() > cfg.blur || s_rate.abs() < 1e-9 {
                    continue;
                }
                let (u1, u2) = ((slo - s0) / s_rate, (shi - s0) / s_rate);
                (u1.min(u2), u1.max(u2))
            };
            let (lo, hi) = (lo.max(a - cfg.blur), hi.min(b + cfg.blur));
            if lo <= hi {
                supports.push(Support {
                    lo,
                    hi,
                    weight: voter.length(),
                    voter: k,
                });
            }
        }
    }
    peaks(supports, a, b, cfg)
        .into_iter()
        .map(|(u, votes)| {
            let t = at(u);
            Vote {
                pose: Pose2::new(t[0], t[1], phi),
                score: anchor.length() + votes,
            }
        })
        .collect()
}

/// The `u` values covered by the most voter length (each voter counted
/// once), at most `cfg.peaks_per_pair` of them, farther than twice the blur
/// apart; with no support the middle of `[a, b]`.
fn peaks(supports: &[Support], a: f64, b: f64, cfg: &GlobalConfig) -> Vec<(f64, f64)> {
    // The maximum coverage is reached at some interval's left end; there,
    // the estimate is the middle of the contributing intervals' common part.
    let mut scored: Vec<(f64, f64)> = Vec::with_capacity(supports.len());
    let mut best_by_voter: Vec<(usize, f64, f64, f64)> = Vec::new();
    for probe in supports {
        let u = probe.lo;
        best_by_voter.clear();
        for s in supports.iter().filter(|s| s.lo <= u && u <= s.hi) {
            match best_by_voter.iter_mut().find(|e| e.0 == s.voter) {
                Some(e) if e.1 < s.weight => *e = (s.voter, s.weight, s.lo, s.hi),
                Some(_) => {}
                None => best_by_voter.push((s.voter, s.weight, s.lo, s.hi)),
            }
        }
        let total: f64 = best_by_voter.iter().map(|e| e.1).sum();
        let lo = best_by_voter.iter().map(|e| e.2).fold(a, f64::max);
        let hi = best_by_voter.iter().map(|e| e.3).fold(b, f64::min);
        let centre = if lo <= hi { 0.5 * (lo + hi) } else { u };
        scored.push((centre, total));
    }
    if scored.is_empty() {
        return vec![(0.5 * (a + b), 0.0)];
    }
    scored.sort_by(|x, y| y.1.total_cmp(&x.1).then(x.0.total_cmp(&y.0)));
    let mut out: Vec<(f64, f64)> = Vec::new();
    for (u, total) in scored {
        if out.len() >= cfg.peaks_per_pair.max(1) {
            break;
        }
        if out.iter().all(|(v, _)| (u - v).abs() > 2.0 * cfg.blur) {
            out.push((u, total));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shorter_segment_lies_inside_the_longer() {
        let wall = CogLine::from_centre(0.0, [0.0, 0.0], -2.0, 2.0, 0.001, 0.001, 50);
        // A 2 m local line on a 4 m wall: its centre within ±1 m (+ tol).
        let (lo, hi) = centre_range(&wall, 1.0, 0.1);
        assert!((lo + 1.1).abs() < 1e-12 && (hi - 1.1).abs() < 1e-12);
        // A 6 m local line covering the 4 m piece: also ±1 m (+ tol).
        let (lo, hi) = centre_range(&wall, 3.0, 0.1);
        assert!((lo + 1.1).abs() < 1e-12 && (hi - 1.1).abs() < 1e-12);
        // Equal lengths: only the middle (± tol).
        let (lo, hi) = centre_range(&wall, 2.0, 0.1);
        assert!((lo + 0.1).abs() < 1e-12 && (hi - 0.1).abs() < 1e-12);
    }
}
