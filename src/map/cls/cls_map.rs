//! [`ClsMap`]: the global CLS map and its update (local CLS map → map
//! frame → fusion of actual segments → region union).

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::geometry::{CogLine, Pose2, RangeScan, SegmentId};
use crate::map::{SegmentMap, SegmentMapConfig};

use super::fusion::LineTable;
use super::local::{LocalMapConfig, LocalMapError, LocalRegion, LocalSource, local_region};
use super::loops::{
    ClsLoop, ClsSegment, ClsShape, ClsmItem, InvariantError, SegmentMode, check_loops,
    check_loops_changed, items,
};
use super::region::{
    EdgeOrigin, RegionConfig, RegionEdge, RegionError, RegionShape, clean_checked, union,
};
use super::shapes::{group_loops, to_shapes, whole_contours};
use super::store::StoreError;
use super::window::Window;

/// A multiply–rotate hasher for the exact bit patterns of segment end
/// points: the candidate check hashes every segment near each update, and
/// SipHash's defence against chosen keys (which map data are not) cost a
/// tenth of a whole CSAIL run.
#[derive(Debug, Default)]
struct BitsHasher(u64);

impl Hasher for BitsHasher {
    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(8) {
            let mut word = [0u8; 8];
            word[..chunk.len()].copy_from_slice(chunk);
            self.write_u64(u64::from_le_bytes(word));
        }
    }

    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(5) ^ v).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

/// Refuses a pose or covariance that is not finite.
fn check_pose(pose: &Pose2, pose_cov: &[[f64; 3]; 3]) -> Result<(), ClsError> {
    let finite = [pose.x, pose.y, pose.theta]
        .iter()
        .chain(pose_cov.iter().flatten())
        .all(|v| v.is_finite());
    if finite {
        Ok(())
    } else {
        Err(ClsError::BadPose)
    }
}

/// Tuning of the CLS map.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ClsMapConfig {
    /// The local map of one scan (laser mounting, range limits).
    pub local: LocalMapConfig,
    /// Snapping and sliver limits of the union.
    pub region: RegionConfig,
    /// Fusion gates and σ floors, shared with the segment map.
    pub fusion: SegmentMapConfig,
    /// Clip long loops to a window around the scan so the union's cost
    /// follows the neighbourhood, not the map. Default true; false unions
    /// whole loops (the same region within the cleaning tolerances, for
    /// comparison and as a reference in tests).
    pub clip_to_window: bool,
}

impl Default for ClsMapConfig {
    fn default() -> Self {
        ClsMapConfig {
            local: LocalMapConfig::default(),
            region: RegionConfig::default(),
            fusion: SegmentMapConfig::default(),
            clip_to_window: true,
        }
    }
}

/// Why an update was refused; the map is left as it was.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ClsError {
    #[error("the pose or its covariance is not finite")]
    BadPose,
    #[error("no local map from this scan: {0}")]
    Local(#[from] LocalMapError),
    #[error("region union failed: {0}")]
    Region(#[from] RegionError),
    #[error("an obstacle loop of the map lies in no shape after the union")]
    LostHole,
    #[error("the updated map would break an invariant: {0}")]
    Invariant(#[from] InvariantError),
}

/// What one update did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct ClsUpdateStats {
    /// Scan lines fused into a boundary line.
    pub fused: usize,
    /// Scan lines that became new boundary lines.
    pub added: usize,
    /// Shapes of the map the local region touched (the union's input).
    pub touched_shapes: usize,
    /// Segments (or pieces of segments clipped to the window around the
    /// scan) of the map that went through the union.
    pub touched_segments: usize,
    /// Whether long loops were clipped to the window (the local path);
    /// false when the whole touched loops were unioned.
    pub clipped: bool,
}

/// The global Closed Line Segment map: pieces of explored free space, each
/// an outer loop with obstacle loops inside, bounded by actual and virtual
/// segments.
#[derive(Debug, Clone, Default)]
pub struct ClsMap {
    config: ClsMapConfig,
    shapes: Vec<ClsShape>,
    /// Bounding box of each shape's outer loop, to find the touched ones.
    bounds: Vec<([f64; 2], [f64; 2])>,
}

fn boxes_overlap(a: &([f64; 2], [f64; 2]), b: &([f64; 2], [f64; 2]), margin: f64) -> bool {
    a.0[0] <= b.1[0] + margin
        && b.0[0] <= a.1[0] + margin
        && a.0[1] <= b.1[1] + margin
        && b.0[1] <= a.1[1] + margin
}

impl ClsMap {
    /// An empty map.
    pub fn new(config: ClsMapConfig) -> Self {
        ClsMap {
            config,
            shapes: Vec::new(),
            bounds: Vec::new(),
        }
    }

    /// A map made of `shapes`, refused unless it is a valid CLS map.
    pub fn from_shapes(
        config: ClsMapConfig,
        shapes: Vec<ClsShape>,
    ) -> Result<Self, InvariantError> {
        check_loops(&shapes)?;
        let bounds = shapes.iter().map(|s| s.outer.bounds()).collect();
        Ok(ClsMap {
            config,
            shapes,
            bounds,
        })
    }

    pub fn config(&self) -> &ClsMapConfig {
        &self.config
    }

    /// The pieces of explored free space.
    pub fn shapes(&self) -> &[ClsShape] {
        &self.shapes
    }

    /// All loops: each shape's outer loop followed by its holes.
    pub fn loops(&self) -> impl Iterator<Item = &ClsLoop> + '_ {
        self.shapes.iter().flat_map(ClsShape::loops)
    }

    /// Every boundary segment.
    pub fn segments(&self) -> impl Iterator<Item = &ClsSegment> + '_ {
        self.loops().flat_map(|l| l.segments().iter())
    }

    /// The walls seen so far.
    pub fn actual_segments(&self) -> impl Iterator<Item = &ClsSegment> + '_ {
        self.segments().filter(|s| s.mode == SegmentMode::Actual)
    }

    /// The exploration frontier: exactly the virtual segments.
    pub fn virtual_segments(&self) -> impl Iterator<Item = &ClsSegment> + '_ {
        self.segments().filter(|s| s.mode == SegmentMode::Virtual)
    }

    /// Number of boundary segments.
    pub fn len(&self) -> usize {
        self.loops().map(ClsLoop::len).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.shapes.is_empty()
    }

    /// Area of explored free space (m²).
    pub fn area(&self) -> f64 {
        self.shapes.iter().map(ClsShape::area).sum()
    }

    /// Whether `p` (map frame) lies in explored free space.
    pub fn contains(&self, p: [f64; 2]) -> bool {
        self.shapes
            .iter()
            .zip(&self.bounds)
            .any(|(s, b)| boxes_overlap(b, &(p, p), 0.0) && s.contains(p))
    }

    /// The paper's CLSM_Item list.
    pub fn items(&self) -> Vec<ClsmItem> {
        items(&self.shapes)
    }

    /// Checks the map's invariants (see [`super::loops`]).
    pub fn check_invariants(&self) -> Result<(), InvariantError> {
        check_loops(&self.shapes)
    }

    /// Writes the map alone (no walls or keyframes, so its pieces name no
    /// wall) to `path` as `map.json` (see [`crate::map::file`]),
    /// atomically.
    pub fn save(&self, path: &Path) -> Result<(), StoreError> {
        // Without the walls beside it, a piece names no wall.
        let mut cls = self.clone();
        cls.resolve_walls(&SegmentMap::default());
        let contents = crate::map::MapContents {
            cls,
            ..Default::default()
        };
        crate::map::file::save(path, &contents)
    }

    /// Points every wall piece at the wall that now stands for its wall in
    /// `walls` (a wall bridged into another leaves its id behind), or at
    /// none if `walls` lost it; for a map about to be stored beside those
    /// walls.
    pub fn resolve_walls(&mut self, walls: &SegmentMap) {
        for shape in &mut self.shapes {
            for lp in std::iter::once(&mut shape.outer).chain(shape.holes.iter_mut()) {
                lp.map_walls(|w| walls.resolve(w));
            }
        }
    }

    /// The same map under another configuration (for what it grows next).
    pub fn with_config(mut self, config: ClsMapConfig) -> Self {
        self.config = config;
        self
    }

    /// Reads the CLS map of a `map.json` of either version; a corrupt,
    /// truncated or invalid file is refused with the reason.
    pub fn load(path: &Path, config: ClsMapConfig) -> Result<Self, StoreError> {
        Ok(crate::map::file::load(path)?
            .contents
            .cls
            .with_config(config))
    }

    /// Adds one scan: `lines` extracted from `scan` (robot frame, scan
    /// order), taken at `pose` (robot in the map frame) with covariance
    /// `pose_cov` (x, y, θ; m², m·rad, rad²). The lines go into the wall
    /// store `walls` first, then the scan's region into this map, its wall
    /// pieces on those walls. Only the shapes whose bounding boxes touch
    /// the scan's region take part; the rest stay untouched.
    pub fn update(
        &mut self,
        walls: &mut SegmentMap,
        lines: &[CogLine],
        scan: &RangeScan,
        pose: Pose2,
        pose_cov: [[f64; 3]; 3],
    ) -> Result<ClsUpdateStats, ClsError> {
        check_pose(&pose, &pose_cov)?;
        let ids = walls.update(lines, &pose, &pose_cov).walls;
        let local = local_region(lines, scan, &self.config.local)?;
        self.add_keyframe(walls, &ids, &local, pose, pose_cov)
    }

    /// The update after the walls: `walls` already holds the keyframe's
    /// lines, `line_walls` the wall each went into (as
    /// [`SegmentMap::update`] gave them), `local` the scan's local region
    /// (robot frame). What the mapper and a rebuild from stored keyframes
    /// call.
    pub fn add_keyframe(
        &mut self,
        walls: &SegmentMap,
        line_walls: &[SegmentId],
        local: &LocalRegion,
        pose: Pose2,
        pose_cov: [[f64; 3]; 3],
    ) -> Result<ClsUpdateStats, ClsError> {
        check_pose(&pose, &pose_cov)?;
        self.add_region(walls, &local.transformed(&pose), line_walls)
    }

    /// The update after the local map is built: `local` is in the map
    /// frame, its actual edges numbering `line_walls` (the walls of the
    /// keyframe's lines in `walls`).
    ///
    /// Shapes whose bounding boxes miss a window around `local` are not
    /// touched, nor are the holes of touched shapes that miss it. Loops
    /// that cross the window are clipped to it and only the clipped part
    /// goes through the union (module `window`), so the cost follows the
    /// size of the neighbourhood, not of the map; if the clipping meets a
    /// degenerate case the whole loops are unioned instead.
    pub fn add_region(
        &mut self,
        walls: &SegmentMap,
        local: &LocalRegion,
        line_walls: &[SegmentId],
    ) -> Result<ClsUpdateStats, ClsError> {
        let mut lb = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for e in &local.edges {
            for p in [e.start, e.end] {
                lb = (
                    [lb.0[0].min(p[0]), lb.0[1].min(p[1])],
                    [lb.1[0].max(p[0]), lb.1[1].max(p[1])],
                );
            }
        }
        let gates = self.config.fusion.fusion;
        let margin = gates.max_centre_distance + gates.extent_tolerance + self.config.region.grid;
        let window_box = (
            [lb.0[0] - margin, lb.0[1] - margin],
            [lb.1[0] + margin, lb.1[1] + margin],
        );
        let touched: Vec<usize> = (0..self.shapes.len())
            .filter(|&i| boxes_overlap(&self.bounds[i], &window_box, 0.0))
            .collect();
        // Holes far from the scan cannot change: they stay out of the union
        // and are handed back to whichever new shape encloses them.
        let mut far_holes: Vec<ClsLoop> = Vec::new();
        let mut near: Vec<&ClsLoop> = Vec::new();
        for &i in &touched {
            let shape = &self.shapes[i];
            near.push(&shape.outer);
            for h in &shape.holes {
                if boxes_overlap(&h.bounds(), &window_box, 0.0) {
                    near.push(h);
                } else {
                    far_holes.push(h.clone());
                }
            }
        }
        let inside = |l: &ClsLoop| {
            let (lo, hi) = l.bounds();
            lo[0] > window_box.0[0]
                && lo[1] > window_box.0[1]
                && hi[0] < window_box.1[0]
                && hi[1] < window_box.1[1]
        };
        let (whole, crossing): (Vec<&ClsLoop>, Vec<&ClsLoop>) =
            near.iter().partition(|l| inside(l));
        // The windowed union first when long loops cross the window; if it
        // meets a degenerate case or its result would break an invariant
        // of the map, the union of the whole touched loops.
        let try_window = !crossing.is_empty() && self.config.clip_to_window;
        let mut result = None;
        if try_window
            && let Some((shapes, stats)) =
                self.windowed_union(walls, local, line_walls, &whole, &crossing, window_box)?
        {
            let committed = self.with_far_holes(shapes, &far_holes)?;
            // Checked whole: the splice can disturb a loop away from the
            // window too (seen in the daemon's simulated runs).
            if self.check_candidate(&touched, &committed).is_ok() {
                result = Some((committed, stats));
            }
        }
        let (new_shapes, mut stats) = match result {
            Some(done) => done,
            None => {
                let mut table = LineTable::default();
                let subject = whole_contours(&near, &mut table, walls);
                let mut stats = ClsUpdateStats::default();
                let merged =
                    self.merge_local(subject, &mut table, walls, local, line_walls, &mut stats)?;
                let committed = self.with_far_holes(to_shapes(&merged, &table), &far_holes)?;
                // Refuse the update whole rather than keep an invalid map.
                self.check_candidate(&touched, &committed)?;
                (committed, stats)
            }
        };
        stats.touched_shapes = touched.len();
        for &i in touched.iter().rev() {
            self.shapes.swap_remove(i);
            self.bounds.swap_remove(i);
        }
        for s in new_shapes {
            self.bounds.push(s.outer.bounds());
            self.shapes.push(s);
        }
        debug_assert_eq!(self.check_invariants(), Ok(()));
        Ok(stats)
    }

    /// Hands each far hole back to the new shape that encloses it.
    fn with_far_holes(
        &self,
        mut new_shapes: Vec<ClsShape>,
        far_holes: &[ClsLoop],
    ) -> Result<Vec<ClsShape>, ClsError> {
        for hole in far_holes {
            let probe = hole.segments().first().map(|s| s.point_on_left(1e-6));
            let owner = match new_shapes.len() {
                1 => Some(0),
                _ => probe.and_then(|p| new_shapes.iter().position(|s| s.outer.encloses(p))),
            };
            match owner.and_then(|k| new_shapes.get_mut(k)) {
                Some(shape) => shape.holes.push(hole.clone()),
                // Cannot happen for a valid map (the union only grows the
                // free space around the hole); refuse rather than lose it.
                None => return Err(ClsError::LostHole),
            }
        }
        Ok(new_shapes)
    }

    /// Checks the map the update would leave: `new_shapes` and the
    /// untouched shapes next to them (O(n log n) in their segments; once
    /// per keyframe).
    fn check_candidate(
        &self,
        touched: &[usize],
        new_shapes: &[ClsShape],
    ) -> Result<(), InvariantError> {
        // Untouched shapes apart from the new ones cannot cross them, and
        // they were valid before: only those whose boxes meet take part.
        // (Every loop's box, holes included: nothing here assumes a hole
        // lies inside its outer loop; the check is what finds out.)
        let boxes: Vec<_> = new_shapes
            .iter()
            .flat_map(|s| s.loops())
            .map(|l| l.bounds())
            .collect();
        let untouched: Vec<usize> = (0..self.shapes.len())
            .filter(|i| {
                !touched.contains(i)
                    && boxes
                        .iter()
                        .any(|b| boxes_overlap(&self.bounds[*i], b, 0.0))
            })
            .collect();
        // Segments of the map as it was (touched shapes included) are
        // unchanged wherever the update took them over bit for bit.
        let key = |a: [f64; 2], b: [f64; 2]| {
            [
                a[0].to_bits(),
                a[1].to_bits(),
                b[0].to_bits(),
                b[1].to_bits(),
            ]
        };
        // Counted, so a segment the update duplicated is not taken for old.
        let segments = touched
            .iter()
            .chain(&untouched)
            .flat_map(|&i| self.shapes[i].loops())
            .map(|l| l.len())
            .sum();
        let mut before: HashMap<[u64; 4], usize, BuildHasherDefault<BitsHasher>> =
            HashMap::with_capacity_and_hasher(segments, BuildHasherDefault::default());
        for &i in touched.iter().chain(&untouched) {
            for l in self.shapes[i].loops() {
                for seg in l.segments() {
                    *before.entry(key(seg.start(), seg.end())).or_default() += 1;
                }
            }
        }
        let shapes = untouched.iter().map(|&i| &self.shapes[i]).chain(new_shapes);
        check_loops_changed(shapes, |a, b| match before.get_mut(&key(a, b)) {
            Some(n) if *n > 0 => {
                *n -= 1;
                true
            }
            _ => false,
        })
    }

    /// The union with the crossing loops clipped to the window; `None` if
    /// the clipping or the splice meets a degenerate case.
    fn windowed_union(
        &self,
        walls: &SegmentMap,
        local: &LocalRegion,
        line_walls: &[SegmentId],
        whole: &[&ClsLoop],
        crossing: &[&ClsLoop],
        window_box: ([f64; 2], [f64; 2]),
    ) -> Result<Option<(Vec<ClsShape>, ClsUpdateStats)>, ClsError> {
        let mut table = LineTable::default();
        let mut window = Window::around(
            window_box.0,
            window_box.1,
            crossing,
            self.config.region.grid,
        )?;
        let Some(clipped) = window.clip(crossing, &mut table, walls) else {
            return Ok(None);
        };
        let mut subject = whole_contours(whole, &mut table, walls);
        subject.extend(clipped);
        let mut stats = ClsUpdateStats::default();
        let result = self.merge_local(subject, &mut table, walls, local, line_walls, &mut stats)?;
        if !window.holds(&result) {
            return Ok(None);
        }
        let Some(loops) = window.splice(
            &result,
            &table,
            self.config.region.sliver_width,
            &self.config.fusion.fusion,
        ) else {
            return Ok(None);
        };
        stats.clipped = true;
        Ok(group_loops(loops).map(|shapes| (shapes, stats)))
    }

    /// The union: the keyframe's walls taken into the table, the
    /// boundaries settled onto the walls that moved, the local region
    /// unioned with `subject`, walls recovered and slivers cleaned.
    fn merge_local(
        &self,
        mut subject: Vec<Vec<RegionEdge>>,
        table: &mut LineTable,
        walls: &SegmentMap,
        local: &LocalRegion,
        line_walls: &[SegmentId],
        stats: &mut ClsUpdateStats,
    ) -> Result<Vec<RegionShape>, ClsError> {
        stats.touched_segments = subject.iter().map(Vec::len).sum();
        let mut used: Vec<usize> = local
            .edges
            .iter()
            .filter_map(|e| match e.source {
                LocalSource::Actual(i) => Some(i),
                LocalSource::Virtual => None,
            })
            .filter(|&i| i < line_walls.len())
            .collect();
        used.sort_unstable();
        used.dedup();
        let seen: Vec<SegmentId> = used.iter().map(|&i| line_walls[i]).collect();
        let (numbers, fused) = table.add_keyframe_walls(&seen, walls);
        stats.fused = fused;
        stats.added = seen.len() - fused;
        let mut clip: Vec<RegionEdge> = local
            .edges
            .iter()
            .map(|e| RegionEdge {
                start: e.start,
                end: e.end,
                origin: match e.source {
                    LocalSource::Actual(i) => used
                        .binary_search(&i)
                        .ok()
                        .and_then(|k| numbers.get(k).copied().flatten())
                        .map_or(EdgeOrigin::Virtual, EdgeOrigin::Actual),
                    LocalSource::Virtual => EdgeOrigin::Virtual,
                },
            })
            .collect();
        let max_shift = 2.0 * self.config.fusion.fusion.max_centre_distance;
        table.settle(&mut clip, max_shift);
        for contour in &mut subject {
            table.settle(contour, max_shift);
        }
        let mut raw = union(
            subject.iter().map(Vec::as_slice),
            [clip.as_slice()],
            &self.config.region,
        )?;
        for contour in raw.iter_mut().flatten() {
            table.recover_walls(contour, self.config.region.sliver_width, walls);
        }
        Ok(clean_checked(&raw, &self.config.region)?)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests;
