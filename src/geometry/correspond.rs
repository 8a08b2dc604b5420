//! Line correspondence (Zhang & Ghosh §4) over a spatial index of map lines.
//!
//! The index is a parry `Bvh` over the segments' bounding boxes, so a query
//! costs O(log n) in the map size: a map grows to thousands of segments
//! while a scan only sees a few dozen.

use parry2d_f64::bounding_volume::Aabb;
use parry2d_f64::math::Vector;
use parry2d_f64::partitioning::{Bvh, BvhNode};
use serde::{Deserialize, Serialize};

use crate::geometry::{CogLine, wrap_angle};

/// Stable identifier of a segment in a [`SegmentIndex`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct SegmentId(pub u32);

/// When two lines are taken to be the same wall (the paper's test).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CorrespondenceConfig {
    /// Largest direction difference (rad). Default 0.087 (5°): several σθ
    /// of a 1 m wall at 1 cm range noise plus a well-predicted pose.
    /// Must stay below π/2 so opposite faces of a wall never match.
    pub max_angle_diff: f64,
    /// Largest distance of one line's centre from the other line (m).
    /// Default 0.15: well above fit noise, below the depth of a door recess.
    pub max_centre_distance: f64,
    /// How far beyond the other segment's end points the centre may project
    /// along it (m). Default 0.3: walls seen partly occluded still match.
    pub extent_tolerance: f64,
}

impl Default for CorrespondenceConfig {
    fn default() -> Self {
        CorrespondenceConfig {
            max_angle_diff: 0.087,
            max_centre_distance: 0.15,
            extent_tolerance: 0.3,
        }
    }
}

/// Whether `c` lies close to `line`: within `max_centre_distance` across it
/// and within its extent widened by `extent_tolerance` along it.
fn centre_near(line: &CogLine, c: [f64; 2], cfg: &CorrespondenceConfig) -> bool {
    if line.distance_to_point(c) > cfg.max_centre_distance {
        return false;
    }
    let (s0, s1) = line.extent();
    let s = line.along(c);
    s >= s0.min(s1) - cfg.extent_tolerance && s <= s0.max(s1) + cfg.extent_tolerance
}

/// The paper's correspondence test: directions close (so opposite
/// directions never match) and the centre of either line close to the
/// other line.
pub fn lines_correspond(a: &CogLine, b: &CogLine, cfg: &CorrespondenceConfig) -> bool {
    wrap_angle(a.theta - b.theta).abs() <= cfg.max_angle_diff
        && (centre_near(b, a.centre(), cfg) || centre_near(a, b.centre(), cfg))
}

/// How well `b` matches `a` (smaller is better): squared direction and
/// centre-offset differences, each relative to its gate.
pub fn match_score(a: &CogLine, b: &CogLine, cfg: &CorrespondenceConfig) -> f64 {
    let da = wrap_angle(a.theta - b.theta) / cfg.max_angle_diff.max(f64::MIN_POSITIVE);
    let dc = b
        .distance_to_point(a.centre())
        .min(a.distance_to_point(b.centre()))
        / cfg.max_centre_distance.max(f64::MIN_POSITIVE);
    da * da + dc * dc
}

/// Bounding box of a line's end points and centre, or `None` if any
/// coordinate is not finite.
fn line_aabb(line: &CogLine, margin: f64) -> Option<Aabb> {
    let pts = [line.start, line.end, line.centre()];
    if pts.iter().flatten().any(|v| !v.is_finite()) || !margin.is_finite() {
        return None;
    }
    let mut lo = pts[0];
    let mut hi = pts[0];
    for p in &pts[1..] {
        lo = [lo[0].min(p[0]), lo[1].min(p[1])];
        hi = [hi[0].max(p[0]), hi[1].max(p[1])];
    }
    Some(Aabb::new(
        Vector::new(lo[0] - margin, lo[1] - margin),
        Vector::new(hi[0] + margin, hi[1] + margin),
    ))
}

/// A growing set of map lines with stable ids and a spatial index.
///
/// Lines with non-finite coordinates are stored (so ids stay consistent)
/// but never returned by spatial queries.
#[derive(Debug, Clone, Default)]
pub struct SegmentIndex {
    lines: Vec<Option<CogLine>>,
    bvh: Bvh,
    live: usize,
}

impl SegmentIndex {
    /// An empty index.
    pub fn new() -> Self {
        Self::default()
    }

    /// An index holding `lines` under the given ids (ids not given stay
    /// free and are never reused); `None` if an id repeats.
    pub fn from_ids(lines: impl IntoIterator<Item = (SegmentId, CogLine)>) -> Option<Self> {
        let mut index = SegmentIndex::new();
        for (id, line) in lines {
            let i = id.0 as usize;
            if index.lines.len() <= i {
                index.lines.resize(i + 1, None);
            }
            if index.lines[i].replace(line).is_some() {
                return None;
            }
            index.live += 1;
            if let Some(aabb) = line_aabb(&line, 0.0) {
                index.bvh.insert(aabb, id.0);
            }
        }
        Some(index)
    }

    /// Adds a line and returns its id.
    ///
    /// # Panics
    /// After `u32::MAX` insertions over the index's lifetime (ids are never
    /// reused and the BVH keys leaves by `u32`).
    pub fn insert(&mut self, line: CogLine) -> SegmentId {
        let id = u32::try_from(self.lines.len()).expect("SegmentIndex holds at most u32::MAX ids");
        self.lines.push(Some(line));
        self.live += 1;
        if let Some(aabb) = line_aabb(&line, 0.0) {
            self.bvh.insert(aabb, id);
        }
        SegmentId(id)
    }

    /// Replaces the line stored under `id`; `false` if there is none.
    pub fn update(&mut self, id: SegmentId, line: CogLine) -> bool {
        let Some(slot) = self.lines.get_mut(id.0 as usize) else {
            return false;
        };
        if slot.is_none() {
            return false;
        }
        *slot = Some(line);
        match line_aabb(&line, 0.0) {
            Some(aabb) => self.bvh.insert(aabb, id.0),
            None => self.bvh.remove(id.0),
        }
        true
    }

    /// Removes and returns the line stored under `id`.
    pub fn remove(&mut self, id: SegmentId) -> Option<CogLine> {
        let line = self.lines.get_mut(id.0 as usize)?.take()?;
        self.bvh.remove(id.0);
        self.live -= 1;
        Some(line)
    }

    /// The line stored under `id`.
    pub fn get(&self, id: SegmentId) -> Option<&CogLine> {
        self.lines.get(id.0 as usize)?.as_ref()
    }

    /// All stored lines in id order.
    pub fn iter(&self) -> impl Iterator<Item = (SegmentId, &CogLine)> + '_ {
        self.lines
            .iter()
            .enumerate()
            .filter_map(|(i, l)| Some((SegmentId(i as u32), l.as_ref()?)))
    }

    /// Number of stored lines.
    pub fn len(&self) -> usize {
        self.live
    }

    /// Whether no line is stored.
    pub fn is_empty(&self) -> bool {
        self.live == 0
    }

    /// The stored lines whose bounding boxes come within `radius` (m) of
    /// `centre`, in no particular order.
    pub fn near(&self, centre: [f64; 2], radius: f64) -> impl Iterator<Item = &CogLine> + '_ {
        let query = (centre.iter().all(|v| v.is_finite()) && radius.is_finite()).then(|| {
            BvhNode::leaf(
                Aabb::new(
                    Vector::new(centre[0] - radius, centre[1] - radius),
                    Vector::new(centre[0] + radius, centre[1] + radius),
                ),
                0,
            )
        });
        query
            .map(move |q| self.bvh.leaves(move |node: &BvhNode| node.intersects(&q)))
            .into_iter()
            .flatten()
            .filter_map(move |leaf| self.lines.get(leaf as usize)?.as_ref())
    }

    /// Ids of the map lines that correspond to `line` (same frame) under
    /// `cfg`, in no particular order.
    pub fn candidates<'a>(
        &'a self,
        line: &CogLine,
        cfg: &CorrespondenceConfig,
    ) -> impl Iterator<Item = SegmentId> + 'a {
        let line = *line;
        let cfg = *cfg;
        // Either centre lies within max_centre_distance across and
        // extent_tolerance along the other segment, so the two boxes are at
        // most their sum apart.
        let query = line_aabb(&line, cfg.max_centre_distance + cfg.extent_tolerance)
            .map(|aabb| BvhNode::leaf(aabb, 0));
        let hits = query
            .map(move |q| self.bvh.leaves(move |node: &BvhNode| node.intersects(&q)))
            .into_iter()
            .flatten();
        hits.filter_map(move |leaf| {
            let other = self.lines.get(leaf as usize)?.as_ref()?;
            lines_correspond(&line, other, &cfg).then_some(SegmentId(leaf))
        })
    }

    /// The corresponding map line with the best [`match_score`]; ties go to
    /// the lower id so results do not depend on the tree's layout.
    pub fn best_match(&self, line: &CogLine, cfg: &CorrespondenceConfig) -> Option<SegmentId> {
        self.best_match_scored(line, cfg).map(|(id, _)| id)
    }

    /// [`best_match`](Self::best_match) with its score.
    pub fn best_match_scored(
        &self,
        line: &CogLine,
        cfg: &CorrespondenceConfig,
    ) -> Option<(SegmentId, f64)> {
        let mut best: Option<(SegmentId, f64)> = None;
        for id in self.candidates(line, cfg) {
            let Some(other) = self.get(id) else { continue };
            let score = match_score(line, other, cfg);
            let better = match best {
                None => true,
                Some((bid, bs)) => score < bs || (score == bs && id < bid),
            };
            if better {
                best = Some((id, score));
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    fn seg(theta: f64, c: [f64; 2], half: f64) -> CogLine {
        CogLine::from_centre(theta, c, -half, half, 0.005, 0.002, 20)
    }

    #[test]
    fn matches_same_wall_but_never_its_opposite_face() {
        let cfg = CorrespondenceConfig::default();
        let wall = seg(FRAC_PI_2, [2.0, 0.0], 1.0);
        let shifted = seg(FRAC_PI_2 + 0.02, [2.05, 0.7], 0.5);
        let opposite = seg(FRAC_PI_2 + PI, [2.0, 0.0], 1.0);
        let far = seg(FRAC_PI_2, [2.5, 0.0], 1.0);
        assert!(lines_correspond(&wall, &shifted, &cfg));
        assert!(!lines_correspond(&wall, &opposite, &cfg));
        assert!(!lines_correspond(&wall, &far, &cfg));
        // Beyond the extent plus tolerance: a different wall on the same line.
        let beyond = seg(FRAC_PI_2, [2.0, 3.0], 0.5);
        assert!(!lines_correspond(&wall, &beyond, &cfg));
    }

    #[test]
    fn index_keeps_ids_stable_across_removal_and_update() {
        let mut idx = SegmentIndex::new();
        let a = idx.insert(seg(0.0, [0.0, 1.0], 1.0));
        let b = idx.insert(seg(FRAC_PI_2, [2.0, 0.0], 1.0));
        assert_eq!(idx.len(), 2);
        assert!(idx.remove(a).is_some());
        assert!(idx.remove(a).is_none());
        let c = idx.insert(seg(PI, [0.0, -1.0], 1.0));
        assert_ne!(a, c);
        assert_eq!(idx.len(), 2);
        assert!(!idx.update(a, seg(0.0, [0.0, 0.0], 1.0)));
        assert!(idx.update(b, seg(FRAC_PI_2, [5.0, 0.0], 1.0)));
        let probe = seg(FRAC_PI_2, [5.02, 0.1], 0.5);
        let cfg = CorrespondenceConfig::default();
        assert_eq!(idx.best_match(&probe, &cfg), Some(b));
        // The old position no longer matches.
        let old = seg(FRAC_PI_2, [2.0, 0.0], 0.5);
        assert_eq!(idx.best_match(&old, &cfg), None);
        let ids: Vec<SegmentId> = idx.iter().map(|(id, _)| id).collect();
        assert_eq!(ids, vec![b, c]);
    }

    #[test]
    fn non_finite_lines_are_stored_but_never_found() {
        let mut idx = SegmentIndex::new();
        let bad = idx.insert(seg(0.0, [f64::NAN, 0.0], 1.0));
        assert!(idx.get(bad).is_some());
        let cfg = CorrespondenceConfig::default();
        assert_eq!(idx.candidates(&seg(0.0, [0.0, 0.0], 1.0), &cfg).count(), 0);
        assert_eq!(
            idx.candidates(&seg(0.0, [f64::NAN, 0.0], 1.0), &cfg)
                .count(),
            0
        );
    }

    proptest! {
        /// The BVH query returns exactly what a brute-force scan returns.
        #[test]
        fn candidates_agree_with_brute_force(
            lines in prop::collection::vec(
                (0.0..std::f64::consts::TAU, -10.0..10.0f64, -10.0..10.0f64, 0.1..2.0f64), 1..60),
            probe in (0.0..std::f64::consts::TAU, -10.0..10.0f64, -10.0..10.0f64, 0.1..2.0f64),
            removed in prop::collection::vec(0usize..60, 0..10),
            moved in prop::collection::vec(
                (0usize..60, 0.0..std::f64::consts::TAU, -10.0..10.0f64, -10.0..10.0f64, 0.1..2.0f64), 0..10),
        ) {
            let cfg = CorrespondenceConfig { max_angle_diff: 0.5, max_centre_distance: 1.0, extent_tolerance: 0.5 };
            let mut idx = SegmentIndex::new();
            for &(t, x, y, h) in &lines {
                idx.insert(seg(t, [x, y], h));
            }
            for r in removed {
                idx.remove(SegmentId(r as u32));
            }
            // Updates move lines anywhere, larger or smaller.
            for (k, t, x, y, h) in moved {
                idx.update(SegmentId(k as u32), seg(t, [x, y], h));
            }
            let p = seg(probe.0, [probe.1, probe.2], probe.3);
            let mut got: Vec<SegmentId> = idx.candidates(&p, &cfg).collect();
            got.sort();
            let want: Vec<SegmentId> = idx.iter()
                .filter(|(_, l)| lines_correspond(&p, l, &cfg))
                .map(|(id, _)| id)
                .collect();
            prop_assert_eq!(got, want);
        }
    }
}
