//! The incremental map of actual (observed) line segments, in the map
//! frame, with the paper's fusion of corresponding segments.
//!
//! # Fusion
//!
//! A scan's line, moved into the map frame with the corrected pose, is
//! "blurred" by the pose covariance: its σθ and σc grow by what the pose
//! uncertainty does to a line at that place. Two corresponding lines are
//! then fused as two independent measurements of the same infinite line:
//! the direction is the weighted circular mean (weights 1/σθ²), the offset
//! is the weighted mean of each line's offset at a common reference point
//! (weights 1/(σc² + s²σθ²), `s` the distance of the reference from that
//! line's centre), and the end points of both are projected onto the fused
//! line with the extremes kept, except where both saw a true end of the
//! wall that agrees: there the end is their σ-weighted mean. Map lines are floored at a minimum σ so
//! that many correlated observations (the same walls seen from poses that
//! were themselves derived from this map) do not make the map rigid beyond
//! what those observations justify.

use crate::geometry::{
    CogLine, CorrespondenceConfig, Pose2, SegmentId, SegmentIndex, WallEnds, match_score,
    wrap_angle,
};
use serde::{Deserialize, Serialize};

/// Tuning of the map update; SI units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SegmentMapConfig {
    /// When a scan's line (map frame) is the same wall as a map line.
    /// Defaults: 5°, 0.10 m across, 0.3 m beyond the ends — the paper's
    /// test with gates a little tighter across than localization's, since
    /// the pose is already corrected when the map is updated.
    pub fusion: CorrespondenceConfig,
    /// A fused line absorbs another corresponding map line only if their
    /// extents overlap or leave a gap no larger than this (m), so a scan
    /// line bridging two pieces of one wall joins them but a doorway is
    /// not closed over. Default 0.1.
    pub merge_gap: f64,
    /// Floor on a fused map line's σc (m). Default 0.005: a wall keeps
    /// learning from new views; measured on CSAIL, 2 mm (a rigid map) and
    /// 1–2 cm (a map that follows every view) both gave larger errors.
    pub min_sigma_c: f64,
    /// Floor on a fused map line's σθ (rad). Default 0.002 (see σc).
    pub min_sigma_theta: f64,
}

impl Default for SegmentMapConfig {
    fn default() -> Self {
        SegmentMapConfig {
            fusion: CorrespondenceConfig {
                max_angle_diff: 0.087,
                max_centre_distance: 0.10,
                extent_tolerance: 0.3,
            },
            merge_gap: 0.1,
            min_sigma_c: 0.005,
            min_sigma_theta: 0.002,
        }
    }
}

/// What one update did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct UpdateStats {
    /// Scan lines fused into an existing map line.
    pub fused: usize,
    /// Scan lines added as new map lines.
    pub added: usize,
    /// Map lines absorbed into another one (bridged by a scan line).
    pub merged: usize,
}

/// What one keyframe did to the walls: the counts, and the wall each of
/// its lines went into (fused, added, or the wall that absorbed that one
/// while bridging), in the order of the lines given.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct WallUpdate {
    pub stats: UpdateStats,
    pub walls: Vec<SegmentId>,
}

/// One wall of the map, as `map.json` stores it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MapSegment {
    pub id: SegmentId,
    /// Keyframe scans that contributed to this segment.
    pub observations: u32,
    pub line: CogLine,
}

/// The growing map of actual segments.
#[derive(Debug, Clone, Default)]
pub struct SegmentMap {
    config: SegmentMapConfig,
    index: SegmentIndex,
    /// Keyframes that contributed, per id (`SegmentId.0`); 0 once removed.
    observations: Vec<u32>,
    /// The wall that absorbed each wall bridged into another (by id;
    /// `u32::MAX` for none), so a reference to it still finds its wall.
    absorbed_into: Vec<u32>,
}

/// `(θ, offset)` variances a line gains from the pose covariance `cov`
/// (x, y, θ) when it is moved into the map frame by `pose`: first-order
/// propagation through the line's normal offset at its centre.
fn pose_blur(line_map: &CogLine, pose: &Pose2, cov: &[[f64; 3]; 3]) -> (f64, f64) {
    let n = line_map.normal();
    let arm = [line_map.xc - pose.x, line_map.yc - pose.y];
    // d(offset)/d(x, y, θ): the centre moves by δt + J·arm·δθ.
    let j = [n[0], n[1], -n[0] * arm[1] + n[1] * arm[0]];
    let mut var_c = 0.0;
    for (a, ja) in j.iter().enumerate() {
        for (b, jb) in j.iter().enumerate() {
            var_c += ja * cov[a][b] * jb;
        }
    }
    (cov[2][2].max(0.0), var_c.max(0.0))
}

/// A robot-frame line moved into the map frame by `pose`, its σθ and σc
/// grown by the pose covariance `cov` (x, y, θ; m², m·rad, rad²).
pub fn blur_by_pose(line_robot: &CogLine, pose: &Pose2, cov: &[[f64; 3]; 3]) -> CogLine {
    let mut line = line_robot.transformed(pose);
    let (var_t, var_c) = pose_blur(&line, pose, cov);
    line.sigma_theta = (line.sigma_theta.powi(2) + var_t).sqrt();
    line.sigma_c = (line.sigma_c.powi(2) + var_c).sqrt();
    // The ends move along the line with the pose's along-line spread.
    let d = line.direction();
    let var_along =
        d[0] * d[0] * cov[0][0] + 2.0 * d[0] * d[1] * cov[0][1] + d[1] * d[1] * cov[1][1];
    let grow = |s: Option<f64>| s.map(|s| (s * s + var_along.max(0.0)).sqrt());
    line.wall_ends = WallEnds {
        start: grow(line.wall_ends.start),
        end: grow(line.wall_ends.end),
    };
    line
}

/// Two positions of a wall end with combined σ `sigma` (m) are one end
/// if this close: 3 σ, plus a little for the ends' own pose noise.
fn same_end(sigma: f64) -> f64 {
    3.0 * sigma + 0.02
}
/// Floor on a wall end's σ (m), as on a line's offset: many views of one
/// end, from poses derived from this map, are not independent.
const MIN_END_SIGMA: f64 = 0.01;

/// Fuses two lines measured as the same wall (same direction sense) into
/// one; see the module documentation. `None` if the directions cancel or a
/// value is not finite.
pub fn fuse(a: &CogLine, b: &CogLine) -> Option<CogLine> {
    // Tiny floors keep the weights finite for noise-free (synthetic) lines.
    let var_t = |l: &CogLine| l.sigma_theta.powi(2).max(1e-18);
    let var_c = |l: &CogLine| l.sigma_c.powi(2).max(1e-18);
    let (wa, wb) = (1.0 / var_t(a), 1.0 / var_t(b));
    let sx = wa * a.theta.cos() + wb * b.theta.cos();
    let sy = wa * a.theta.sin() + wb * b.theta.sin();
    if sx.hypot(sy) <= 1e-9 * (wa + wb) {
        return None;
    }
    let theta = sy.atan2(sx);

    // Reference point: the centres weighted by their offset certainty.
    let (ca, cb) = (1.0 / var_c(a), 1.0 / var_c(b));
    let r = [
        (ca * a.xc + cb * b.xc) / (ca + cb),
        (ca * a.yc + cb * b.yc) / (ca + cb),
    ];
    // Each line's signed distance from r and its variance there.
    let offset = |l: &CogLine| {
        let s = l.along(r);
        (l.signed_distance(r), var_c(l) + s * s * var_t(l))
    };
    let (da, va) = offset(a);
    let (db, vb) = offset(b);
    let var_off = 1.0 / (1.0 / va + 1.0 / vb);
    let d = var_off * (da / va + db / vb);
    let (sn, cs) = theta.sin_cos();
    let normal = [-sn, cs];
    let centre = [r[0] - d * normal[0], r[1] - d * normal[1]];

    let along = |p: [f64; 2]| cs * (p[0] - centre[0]) + sn * (p[1] - centre[1]);
    // One side of the fused line (`outward` +1 at the end, −1 at the
    // start) from each line's extent there and whether it saw a true end.
    // Two true ends that agree within their σ are one end, placed at
    // their mean weighted by σ (each view put its end where it lies on
    // average); a view reaching beyond a true end by more than its σ
    // means the wall goes on (no end there); otherwise the true end holds.
    let side = |outward: f64, (sa, fa): (f64, Option<f64>), (sb, fb): (f64, Option<f64>)| {
        let farther = if outward * (sa - sb) >= 0.0 { sa } else { sb };
        let beyond = |s: f64, end: f64, sigma: f64| outward * (s - end) > same_end(sigma);
        match (fa, fb) {
            (Some(ea), Some(eb)) if (sa - sb).abs() <= same_end(ea.hypot(eb)) => {
                let (wa, wb) = (
                    ea.max(MIN_END_SIGMA).powi(-2),
                    eb.max(MIN_END_SIGMA).powi(-2),
                );
                let sigma = (wa + wb).recip().sqrt().max(MIN_END_SIGMA);
                ((wa * sa + wb * sb) / (wa + wb), Some(sigma))
            }
            // Disagreeing ends: the farther view holds (as with no ends).
            (Some(ea), Some(eb)) => {
                if farther == sa {
                    (sa, Some(ea))
                } else {
                    (sb, Some(eb))
                }
            }
            (Some(ea), None) if !beyond(sb, sa, ea) => (sa, Some(ea)),
            (None, Some(eb)) if !beyond(sa, sb, eb) => (sb, Some(eb)),
            _ => (farther, None),
        }
    };
    let (s_min, start_end) = side(
        -1.0,
        (along(a.start), a.wall_ends.start),
        (along(b.start), b.wall_ends.start),
    );
    let (s_max, end_end) = side(
        1.0,
        (along(a.end), a.wall_ends.end),
        (along(b.end), b.wall_ends.end),
    );
    let wall_ends = WallEnds {
        start: start_end,
        end: end_end,
    };
    let mut fused = CogLine::from_centre(
        theta,
        centre,
        s_min,
        s_max,
        (1.0 / (wa + wb)).sqrt(),
        var_off.sqrt(),
        a.n_points.saturating_add(b.n_points),
    );
    fused.wall_ends = wall_ends;
    let finite = [
        fused.theta,
        fused.xc,
        fused.yc,
        fused.sigma_c,
        fused.sigma_theta,
    ]
    .iter()
    .chain(fused.start.iter())
    .chain(fused.end.iter())
    .all(|v| v.is_finite());
    finite.then_some(fused)
}

/// Gap along `a` between `a`'s extent and `b`'s projected extent (m);
/// 0 when they overlap.
fn gap_along(a: &CogLine, b: &CogLine) -> f64 {
    let (a0, a1) = a.extent();
    let (b0, b1) = (a.along(b.start), a.along(b.end));
    let (alo, ahi) = (a0.min(a1), a0.max(a1));
    let (blo, bhi) = (b0.min(b1), b0.max(b1));
    (blo - ahi).max(alo - bhi).max(0.0)
}

/// Whether `a` and `b` lie on one line within the gates: directions close
/// and each centre close to the other's infinite line. Unlike the
/// correspondence test this ignores the extents, which [`gap_along`] checks.
fn collinear(a: &CogLine, b: &CogLine, gates: &CorrespondenceConfig) -> bool {
    wrap_angle(a.theta - b.theta).abs() <= gates.max_angle_diff
        && a.distance_to_point(b.centre()) <= gates.max_centre_distance
        && b.distance_to_point(a.centre()) <= gates.max_centre_distance
}

impl SegmentMap {
    pub fn new(config: SegmentMapConfig) -> Self {
        SegmentMap {
            config,
            index: SegmentIndex::new(),
            observations: Vec::new(),
            absorbed_into: Vec::new(),
        }
    }

    pub fn config(&self) -> &SegmentMapConfig {
        &self.config
    }

    /// The map lines, for localization.
    pub fn index(&self) -> &SegmentIndex {
        &self.index
    }

    pub fn len(&self) -> usize {
        self.index.len()
    }

    pub fn is_empty(&self) -> bool {
        self.index.is_empty()
    }

    /// Keyframes that contributed to segment `id` (0 if there is none).
    pub fn observations(&self, id: SegmentId) -> u32 {
        self.observations.get(id.0 as usize).copied().unwrap_or(0)
    }

    fn set_observations(&mut self, id: SegmentId, count: u32) {
        let i = id.0 as usize;
        if self.observations.len() <= i {
            self.observations.resize(i + 1, 0);
        }
        self.observations[i] = count;
    }

    /// The wall `id` is now: itself while it stands, else the wall that
    /// absorbed it (followed through later merges); `None` for an id this
    /// map never held.
    pub fn resolve(&self, id: SegmentId) -> Option<SegmentId> {
        let mut id = id;
        // Each merge absorbs a standing wall into another standing one, so
        // the chain is acyclic and shorter than the number of walls.
        for _ in 0..=self.absorbed_into.len() {
            if self.index.get(id).is_some() {
                return Some(id);
            }
            match self.absorbed_into.get(id.0 as usize) {
                Some(&next) if next != u32::MAX => id = SegmentId(next),
                _ => return None,
            }
        }
        None
    }

    /// The line of wall `id` (map frame), if it stands.
    pub fn wall(&self, id: SegmentId) -> Option<&CogLine> {
        self.index.get(id)
    }

    fn set_absorbed(&mut self, gone: SegmentId, into: SegmentId) {
        let i = gone.0 as usize;
        if self.absorbed_into.len() <= i {
            self.absorbed_into.resize(i + 1, u32::MAX);
        }
        self.absorbed_into[i] = into.0;
    }

    /// All segments in id order.
    pub fn segments(&self) -> impl Iterator<Item = MapSegment> + '_ {
        self.index.iter().map(|(id, line)| MapSegment {
            id,
            observations: self.observations(id),
            line: *line,
        })
    }

    /// Adds `walls` (map frame) as they are, each a wall of its own seen
    /// once: the walls of a map that kept only its CLS map.
    pub fn insert_walls(&mut self, walls: &[CogLine]) {
        for line in walls {
            let id = self.index.insert(self.floor_sigmas(*line));
            self.set_observations(id, 1);
        }
    }

    /// The map of `walls` (as [`segments`](Self::segments) gave them,
    /// from a map file), keeping their ids; `None` if two share an id.
    pub fn from_walls(config: SegmentMapConfig, walls: &[MapSegment]) -> Option<Self> {
        let index = SegmentIndex::from_ids(walls.iter().map(|w| (w.id, w.line)))?;
        let mut map = SegmentMap {
            config,
            index,
            observations: Vec::new(),
            absorbed_into: Vec::new(),
        };
        for w in walls {
            map.set_observations(w.id, w.observations);
        }
        Some(map)
    }

    fn floor_sigmas(&self, mut line: CogLine) -> CogLine {
        line.sigma_c = line.sigma_c.max(self.config.min_sigma_c);
        line.sigma_theta = line.sigma_theta.max(self.config.min_sigma_theta);
        line
    }

    /// Adds one keyframe: `local_lines` in the robot frame, `pose` the
    /// corrected robot pose (map frame) with covariance `pose_cov` (x, y,
    /// θ). Each scan line is fused into its best corresponding map line
    /// (several scan lines may fuse into one map line); a fused line then
    /// absorbs any other collinear map line it now overlaps (a scan line
    /// bridging two pieces of a wall); the rest are added. Scan lines are
    /// matched only against lines that existed before this scan, so two
    /// pieces of one scan are never joined across the gap the extractor
    /// saw between them. Returns the counts and the wall of each line.
    pub fn update(
        &mut self,
        local_lines: &[CogLine],
        pose: &Pose2,
        pose_cov: &[[f64; 3]; 3],
    ) -> WallUpdate {
        let mut stats = UpdateStats::default();
        let mut walls = Vec::with_capacity(local_lines.len());
        let mut new_lines = Vec::new();
        let gates = self.config.fusion;
        let mut candidates: Vec<(SegmentId, f64)> = Vec::new();
        for local in local_lines {
            let observed = blur_by_pose(local, pose, pose_cov);
            candidates.clear();
            candidates.extend(self.index.candidates(&observed, &gates).filter_map(|id| {
                let line = self.index.get(id)?;
                Some((id, match_score(&observed, line, &gates)))
            }));
            candidates.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
            let fused = candidates
                .first()
                .and_then(|&(target, _)| Some((target, fuse(self.index.get(target)?, &observed)?)));
            let Some((target, fused)) = fused else {
                // Numbered once the new walls are in.
                walls.push(SegmentId(u32::MAX));
                new_lines.push((walls.len() - 1, observed));
                continue;
            };
            walls.push(target);
            let mut fused = self.floor_sigmas(fused);
            let mut count = self.observations(target).saturating_add(1);
            // Bridging: the fused line may now reach other pieces of the
            // same wall; absorb them until none is left (each pass removes
            // a line, so this ends).
            loop {
                // The correspondence test looks for a centre within the
                // other's extent; widen it by the fused length so a long
                // line finds every piece it touches, then test the gap.
                let reach = CorrespondenceConfig {
                    extent_tolerance: fused.length() + self.config.merge_gap,
                    ..gates
                };
                let absorb = self.index.candidates(&fused, &reach).find(|&other| {
                    other != target
                        && self.index.get(other).is_some_and(|line| {
                            collinear(&fused, line, &gates)
                                && gap_along(&fused, line) <= self.config.merge_gap
                        })
                });
                let Some(other) = absorb else { break };
                let Some(line) = self.index.remove(other) else {
                    break;
                };
                if let Some(merged) = fuse(&fused, &line) {
                    fused = self.floor_sigmas(merged);
                }
                count = count.saturating_add(self.observations(other));
                self.set_observations(other, 0);
                self.set_absorbed(other, target);
                stats.merged += 1;
            }
            self.index.update(target, fused);
            self.set_observations(target, count);
            stats.fused += 1;
        }
        for (k, line) in new_lines {
            let id = self.index.insert(self.floor_sigmas(line));
            self.set_observations(id, 1);
            walls[k] = id;
            stats.added += 1;
        }
        // A line fused into a wall that a later line of this scan bridged
        // into another went there too.
        for id in &mut walls {
            *id = self.resolve(*id).unwrap_or(*id);
        }
        WallUpdate { stats, walls }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    const NO_COV: [[f64; 3]; 3] = [[0.0; 3]; 3];

    /// A wall along +x from `x0` to `x1` at height `y`, direction 0 (free
    /// space on its left, above it).
    fn wall(x0: f64, x1: f64, y: f64, sigma_c: f64, sigma_theta: f64) -> CogLine {
        let c = 0.5 * (x0 + x1);
        CogLine::from_centre(0.0, [c, y], x0 - c, x1 - c, sigma_theta, sigma_c, 50)
    }

    /// Invariants every map must keep: finite lines, extents ordered,
    /// centres on their lines, σ above the floors, counts for live ids.
    fn assert_well_formed(map: &SegmentMap) {
        for seg in map.segments() {
            let l = seg.line;
            assert!(l.length().is_finite() && l.xc.is_finite() && l.yc.is_finite());
            let (s0, s1) = l.extent();
            assert!(s0 <= s1 + 1e-9, "{l:?}");
            assert!(l.distance_to_point(l.start) < 1e-9 && l.distance_to_point(l.end) < 1e-9);
            assert!(l.sigma_c >= map.config().min_sigma_c - 1e-15);
            assert!(l.sigma_theta >= map.config().min_sigma_theta - 1e-15);
            assert!(seg.observations >= 1);
        }
    }

    #[test]
    fn two_noisy_views_of_a_wall_fuse_with_smaller_variance_and_union_extent() {
        let a = wall(0.0, 3.0, 2.0, 0.01, 0.01);
        let mut b = wall(1.0, 5.0, 2.02, 0.01, 0.01);
        b = CogLine::from_centre(0.01, b.centre(), -2.0, 2.0, 0.01, 0.01, 50);
        let f = fuse(&a, &b).unwrap();
        assert!(f.sigma_c < a.sigma_c && f.sigma_c < b.sigma_c);
        assert!(f.sigma_theta < a.sigma_theta);
        // Equal weights: the direction halves the difference.
        assert!((f.theta - 0.005).abs() < 1e-9, "{}", f.theta);
        // Offset between the two near the middle of the union.
        let y_mid = f.yc + (2.5 - f.xc) * f.theta.tan();
        assert!(y_mid > 2.0 && y_mid < 2.02, "{y_mid}");
        let (s0, s1) = f.extent();
        assert!((s1 - s0 - 5.0).abs() < 0.01, "union extent {s0}..{s1}");
        assert!(f.start[0] < 0.01 && f.end[0] > 4.99);

        let mut map = SegmentMap::new(SegmentMapConfig::default());
        let s = map.update(&[a], &Pose2::IDENTITY, &NO_COV).stats;
        assert_eq!((s.added, s.fused), (1, 0));
        let s = map.update(&[b], &Pose2::IDENTITY, &NO_COV).stats;
        assert_eq!((s.added, s.fused), (0, 1));
        assert_eq!(map.len(), 1);
        let seg = map.segments().next().unwrap();
        assert_eq!(seg.observations, 2);
        assert!(seg.line.sigma_c < 0.01);
        assert_well_formed(&map);
    }

    #[test]
    fn the_more_certain_line_dominates() {
        let sure = wall(0.0, 4.0, 1.0, 0.002, 0.001);
        let vague = wall(0.0, 4.0, 1.1, 0.05, 0.02);
        let f = fuse(&sure, &vague).unwrap();
        assert!((f.yc - 1.0).abs() < 0.001, "{}", f.yc);
    }

    #[test]
    fn a_bridging_segment_merges_two_pieces_of_a_wall() {
        let mut map = SegmentMap::new(SegmentMapConfig::default());
        // Two pieces seen in one scan (never joined within that scan).
        let left = wall(0.0, 2.0, 3.0, 0.005, 0.003);
        let right = wall(2.6, 5.0, 3.0, 0.005, 0.003);
        let s = map.update(&[left, right], &Pose2::IDENTITY, &NO_COV).stats;
        assert_eq!((s.added, s.merged), (2, 0));
        // A later scan sees the wall across the gap.
        let bridge = wall(1.5, 3.2, 3.01, 0.005, 0.003);
        let before: Vec<SegmentId> = map.segments().map(|w| w.id).collect();
        let update = map.update(&[bridge], &Pose2::IDENTITY, &NO_COV);
        let s = update.stats;
        assert_eq!((s.fused, s.merged, s.added), (1, 1, 0), "{s:?}");
        assert_eq!(map.len(), 1);
        // The absorbed piece's id leads to the wall that took it in.
        let standing = map.segments().next().unwrap().id;
        assert_eq!(update.walls, [standing]);
        for id in before {
            assert_eq!(map.resolve(id), Some(standing));
        }
        assert_eq!(map.resolve(SegmentId(99)), None);
        let seg = map.segments().next().unwrap();
        assert_eq!(seg.observations, 3);
        let (s0, s1) = seg.line.extent();
        assert!((s1 - s0 - 5.0).abs() < 0.01);
        assert_well_formed(&map);
    }

    #[test]
    fn doorway_is_not_bridged_by_a_line_that_does_not_reach_across() {
        let mut map = SegmentMap::new(SegmentMapConfig::default());
        let left = wall(0.0, 2.0, 3.0, 0.005, 0.003);
        let right = wall(2.9, 5.0, 3.0, 0.005, 0.003);
        map.update(&[left, right], &Pose2::IDENTITY, &NO_COV);
        // Extends the left piece but stops 0.6 m before the right one.
        let s = map
            .update(
                &[wall(1.0, 2.3, 3.0, 0.005, 0.003)],
                &Pose2::IDENTITY,
                &NO_COV,
            )
            .stats;
        assert_eq!((s.fused, s.merged), (1, 0));
        assert_eq!(map.len(), 2);
        assert_well_formed(&map);
    }

    #[test]
    fn several_scan_lines_fuse_into_one_map_line() {
        let mut map = SegmentMap::new(SegmentMapConfig::default());
        map.update(
            &[wall(0.0, 6.0, 2.0, 0.005, 0.003)],
            &Pose2::IDENTITY,
            &NO_COV,
        );
        let pieces = [
            wall(0.5, 2.0, 2.0, 0.005, 0.003),
            wall(3.0, 5.0, 2.0, 0.005, 0.003),
        ];
        let update = map.update(&pieces, &Pose2::IDENTITY, &NO_COV);
        assert_eq!((update.stats.fused, update.stats.added), (2, 0));
        assert_eq!(update.walls, [SegmentId(0), SegmentId(0)]);
        assert_eq!(map.len(), 1);
        assert_eq!(map.segments().next().unwrap().observations, 3);
    }

    #[test]
    fn opposite_faces_and_distant_walls_stay_separate() {
        let mut map = SegmentMap::new(SegmentMapConfig::default());
        let front = wall(0.0, 4.0, 2.0, 0.005, 0.003);
        let back = CogLine::from_centre(
            std::f64::consts::PI,
            [2.0, 2.05],
            -2.0,
            2.0,
            0.003,
            0.005,
            50,
        );
        let other = wall(0.0, 4.0, 2.5, 0.005, 0.003);
        map.update(&[front], &Pose2::IDENTITY, &NO_COV);
        let update = map.update(&[back, other], &Pose2::IDENTITY, &NO_COV);
        assert_eq!(update.stats.added, 2);
        assert_eq!(update.walls, [SegmentId(1), SegmentId(2)]);
        assert_eq!(map.len(), 3);
    }

    #[test]
    fn lines_are_placed_by_the_pose_and_blurred_by_its_covariance() {
        let pose = Pose2::new(1.0, 2.0, FRAC_PI_2);
        // A wall 2 m ahead of the robot, across its heading.
        let local = CogLine::from_centre(FRAC_PI_2, [2.0, 0.0], -1.0, 1.0, 0.002, 0.003, 40);
        let cov = [[0.01, 0.0, 0.0], [0.0, 0.04, 0.0], [0.0, 0.0, 1e-4]];
        let g = blur_by_pose(&local, &pose, &cov);
        assert!((g.xc - 1.0).abs() < 1e-12 && (g.yc - 4.0).abs() < 1e-12);
        assert!(wrap_angle(g.theta - std::f64::consts::PI).abs() < 1e-12);
        // Across this wall is map y (σ 0.2 m); the centre lies along the
        // heading so rotation does not move it across.
        assert!((g.sigma_c - (0.003f64.powi(2) + 0.04).sqrt()).abs() < 1e-12);
        assert!((g.sigma_theta - (0.002f64.powi(2) + 1e-4).sqrt()).abs() < 1e-12);
        let mut map = SegmentMap::new(SegmentMapConfig::default());
        map.update(&[local], &pose, &cov);
        assert_eq!(map.segments().next().unwrap().line.centre(), g.centre());
    }

    #[test]
    fn fuse_refuses_cancelling_directions() {
        let a = wall(0.0, 1.0, 0.0, 0.01, 0.01);
        let b = CogLine::from_centre(std::f64::consts::PI, [0.5, 0.0], -0.5, 0.5, 0.01, 0.01, 5);
        assert_eq!(fuse(&a, &b), None);
    }

    #[test]
    fn walls_round_trip_through_json_keeping_their_ids() {
        let mut map = SegmentMap::new(SegmentMapConfig::default());
        map.update(
            &[
                wall(0.0, 2.0, 1.0, 0.01, 0.01),
                wall(0.0, 2.0, -1.0, 0.01, 0.01),
            ],
            &Pose2::IDENTITY,
            &NO_COV,
        );
        map.update(
            &[wall(0.0, 2.0, 1.0, 0.01, 0.01)],
            &Pose2::IDENTITY,
            &NO_COV,
        );
        let mut walls: Vec<MapSegment> = map.segments().collect();
        // A gap in the ids, as a bridged wall leaves behind.
        walls[1].id = SegmentId(7);
        let json = serde_json::to_string(&walls).unwrap();
        let back: Vec<MapSegment> = serde_json::from_str(&json).unwrap();
        let rebuilt = SegmentMap::from_walls(SegmentMapConfig::default(), &back).unwrap();
        assert_eq!(rebuilt.segments().collect::<Vec<_>>(), walls);
        assert_eq!(rebuilt.observations(SegmentId(0)), 2);
        assert_eq!(rebuilt.index().get(SegmentId(7)), Some(&walls[1].line));
        assert!(rebuilt.index().get(SegmentId(1)).is_none());
        let twice = [walls[0], walls[0]];
        assert!(SegmentMap::from_walls(SegmentMapConfig::default(), &twice).is_none());
    }

    /// A wall along x at y = 0 from `x0` to `x1`, with true ends as given.
    fn ended(x0: f64, x1: f64, start: Option<f64>, end: Option<f64>) -> CogLine {
        let mut l = wall(x0, x1, 0.0, 0.01, 0.01);
        l.wall_ends = WallEnds { start, end };
        l
    }

    #[test]
    fn two_views_of_one_true_end_meet_at_their_weighted_mean() {
        // The jamb at x = 4, seen at 3.98 (σ 2 cm) and at 4.06 (σ 4 cm).
        let fused = fuse(
            &ended(0.0, 3.98, None, Some(0.02)),
            &ended(1.0, 4.06, None, Some(0.04)),
        )
        .unwrap();
        let expected = (3.98 / 0.02f64.powi(2) + 4.06 / 0.04f64.powi(2))
            / (1.0 / 0.02f64.powi(2) + 1.0 / 0.04f64.powi(2));
        assert!((fused.end[0] - expected).abs() < 1e-9, "{fused:?}");
        let sigma = fused.wall_ends.end.unwrap();
        assert!((MIN_END_SIGMA..0.02).contains(&sigma), "σ {sigma}");
        // No end seen at the start: the extent there is the union's.
        assert!(fused.wall_ends.start.is_none());
        assert!(fused.start[0].abs() < 1e-9);
    }

    #[test]
    fn a_view_reaching_past_a_true_end_means_the_wall_goes_on() {
        let fused = fuse(
            &ended(0.0, 4.0, None, Some(0.02)),
            &ended(1.0, 5.0, None, None),
        )
        .unwrap();
        assert!(fused.wall_ends.end.is_none(), "{fused:?}");
        assert!((fused.end[0] - 5.0).abs() < 1e-9);
        // A view stopping short of the end (without one) leaves it.
        let fused = fuse(
            &ended(0.0, 4.0, None, Some(0.02)),
            &ended(1.0, 3.5, None, None),
        )
        .unwrap();
        assert_eq!(fused.wall_ends.end, Some(0.02));
        assert!((fused.end[0] - 4.0).abs() < 1e-9);
    }

    #[test]
    fn true_ends_that_disagree_are_not_averaged() {
        // 30 cm apart with σ of 2 cm: not one end; the farther view holds.
        let fused = fuse(
            &ended(0.0, 4.0, None, Some(0.02)),
            &ended(1.0, 4.3, None, Some(0.02)),
        )
        .unwrap();
        assert!((fused.end[0] - 4.3).abs() < 1e-9, "{fused:?}");
        assert_eq!(fused.wall_ends.end, Some(0.02));
    }
}
