//! The CLS map's boundary: segments (actual or virtual), closed loops,
//! shapes (an outer loop and the holes inside it), the paper's CLSM_Item
//! list, and the invariant checker.
//!
//! Invariants (checked by [`check_loops`]):
//! - every loop has at least three segments and closes: each segment's end
//!   is exactly (bit for bit) the next one's start;
//! - all coordinates are finite and no segment has zero length;
//! - an outer loop is counter-clockwise (positive area), a hole clockwise,
//!   so free space lies on the left of every segment;
//! - no two segments of the map cross or overlap, except consecutive ones
//!   meeting at their shared vertex (so no loop self-intersects and loops do
//!   not cross each other).

use serde::{Deserialize, Serialize};

use crate::geometry::{CogLine, SegmentId, wrap_angle_positive};

/// Whether a boundary segment is a wall or a frontier.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SegmentMode {
    /// A wall seen by the laser (a fitted COG line).
    Actual,
    /// A frontier of the explored region: free space was not seen beyond
    /// it, so exploration continues there.
    Virtual,
}

/// One boundary segment: its COG line (start and end are the boundary
/// vertices), its mode, and for a piece of a wall the wall of the wall
/// store ([`crate::map::SegmentMap`]) it lies on, whose line it carries.
/// Virtual segments carry a line with zero variances and `n_points == 0`
/// and no wall.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClsSegment {
    pub line: CogLine,
    pub mode: SegmentMode,
    /// The wall this piece belongs to; `None` for virtual segments and for
    /// walls of a map saved before walls had ids in the CLS map.
    pub wall: Option<SegmentId>,
}

impl ClsSegment {
    /// A virtual segment from `start` to `end` (m, map frame).
    pub fn virtual_between(start: [f64; 2], end: [f64; 2]) -> ClsSegment {
        ClsSegment {
            line: line_between(start, end),
            mode: SegmentMode::Virtual,
            wall: None,
        }
    }

    /// An actual segment on `line` with its end points replaced by the
    /// boundary vertices `start` and `end`. These lie on the line within
    /// the union's tolerances (the 1 mm grid; after fusion and sliver
    /// cleaning, within `RegionConfig::sliver_width`): the loop must close
    /// exactly, the line carries the wall's best estimate.
    pub fn actual_on(
        line: &CogLine,
        wall: Option<SegmentId>,
        start: [f64; 2],
        end: [f64; 2],
    ) -> ClsSegment {
        ClsSegment {
            // A piece of a wall has no wall ends of its own.
            line: CogLine {
                start,
                end,
                wall_ends: crate::geometry::WallEnds::NONE,
                ..*line
            },
            mode: SegmentMode::Actual,
            wall,
        }
    }

    pub fn start(&self) -> [f64; 2] {
        self.line.start
    }

    pub fn end(&self) -> [f64; 2] {
        self.line.end
    }

    pub fn length(&self) -> f64 {
        self.line.length()
    }

    pub fn is_actual(&self) -> bool {
        self.mode == SegmentMode::Actual
    }

    /// The point `offset` (m) to the left of the segment's middle: in the
    /// free space it bounds, for a small enough offset.
    pub fn point_on_left(&self, offset: f64) -> [f64; 2] {
        let (a, b) = (self.start(), self.end());
        let len = self.length().max(f64::MIN_POSITIVE);
        [
            0.5 * (a[0] + b[0]) - (b[1] - a[1]) / len * offset,
            0.5 * (a[1] + b[1]) + (b[0] - a[0]) / len * offset,
        ]
    }
}

/// An exact COG line through two points: direction from `start` to `end`,
/// centre at the midpoint, zero variances (used for virtual segments).
pub fn line_between(start: [f64; 2], end: [f64; 2]) -> CogLine {
    let theta = wrap_angle_positive((end[1] - start[1]).atan2(end[0] - start[0]));
    CogLine {
        theta,
        xc: 0.5 * (start[0] + end[0]),
        yc: 0.5 * (start[1] + end[1]),
        sigma_theta: 0.0,
        sigma_c: 0.0,
        start,
        end,
        n_points: 0,
        wall_ends: crate::geometry::WallEnds::NONE,
    }
}

/// A closed chain of segments.
#[derive(Debug, Clone, PartialEq)]
pub struct ClsLoop {
    segments: Vec<ClsSegment>,
}

impl ClsLoop {
    /// A loop from segments in boundary order. The chain is not checked
    /// here; [`check_loops`] does.
    pub fn new(segments: Vec<ClsSegment>) -> ClsLoop {
        ClsLoop { segments }
    }

    pub fn segments(&self) -> &[ClsSegment] {
        &self.segments
    }

    /// Re-points each wall piece at the wall `f` gives for its wall
    /// (none where `f` gives none); the geometry stays as it is.
    pub(crate) fn map_walls(&mut self, f: impl Fn(SegmentId) -> Option<SegmentId>) {
        for s in &mut self.segments {
            s.wall = s.wall.and_then(&f);
        }
    }

    #[cfg(test)]
    pub(crate) fn segments_mut(&mut self) -> &mut [ClsSegment] {
        &mut self.segments
    }

    pub fn len(&self) -> usize {
        self.segments.len()
    }

    pub fn is_empty(&self) -> bool {
        self.segments.is_empty()
    }

    /// Signed area (m²) by the shoelace formula: positive when
    /// counter-clockwise.
    pub fn signed_area(&self) -> f64 {
        0.5 * self
            .segments
            .iter()
            .map(|s| {
                let (a, b) = (s.start(), s.end());
                a[0] * b[1] - b[0] * a[1]
            })
            .sum::<f64>()
    }

    /// Axis-aligned bounding box `(min, max)` of the vertices.
    pub fn bounds(&self) -> ([f64; 2], [f64; 2]) {
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for s in &self.segments {
            let p = s.start();
            lo = [lo[0].min(p[0]), lo[1].min(p[1])];
            hi = [hi[0].max(p[0]), hi[1].max(p[1])];
        }
        (lo, hi)
    }

    /// Whether `p` lies inside the loop's polygon (crossing number; points
    /// on the boundary may go either way).
    pub fn encloses(&self, p: [f64; 2]) -> bool {
        let mut inside = false;
        for s in &self.segments {
            let (a, b) = (s.start(), s.end());
            if (a[1] > p[1]) != (b[1] > p[1]) {
                let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
                if x > p[0] {
                    inside = !inside;
                }
            }
        }
        inside
    }
}

/// A connected piece of explored free space: an outer loop
/// (counter-clockwise) and the loops of obstacles inside it (clockwise).
#[derive(Debug, Clone, PartialEq)]
pub struct ClsShape {
    pub outer: ClsLoop,
    pub holes: Vec<ClsLoop>,
}

impl ClsShape {
    /// Area of free space (m²): the outer area less the holes'.
    pub fn area(&self) -> f64 {
        self.outer.signed_area() + self.holes.iter().map(ClsLoop::signed_area).sum::<f64>()
    }

    /// Whether `p` lies in this piece of free space.
    pub fn contains(&self, p: [f64; 2]) -> bool {
        self.outer.encloses(p) && !self.holes.iter().any(|h| h.encloses(p))
    }

    /// All loops, outer first.
    pub fn loops(&self) -> impl Iterator<Item = &ClsLoop> + '_ {
        std::iter::once(&self.outer).chain(self.holes.iter())
    }
}

/// One entry of the paper's CLSM_Item list: the segment at `index`, the
/// index of the next segment along its loop, its line and its mode.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClsmItem {
    pub index: usize,
    pub next: usize,
    pub line: CogLine,
    pub mode: SegmentMode,
    /// The wall an actual segment lies on (see [`ClsSegment::wall`]).
    pub wall: Option<SegmentId>,
}

/// The CLSM_Item list of `shapes`: loops in order (each outer loop before
/// its holes), segments numbered consecutively, `next` closing each loop.
pub fn items(shapes: &[ClsShape]) -> Vec<ClsmItem> {
    let mut out = Vec::new();
    for lp in shapes.iter().flat_map(ClsShape::loops) {
        let first = out.len();
        let n = lp.len();
        for (k, s) in lp.segments().iter().enumerate() {
            out.push(ClsmItem {
                index: first + k,
                next: first + (k + 1) % n,
                line: s.line,
                mode: s.mode,
                wall: s.wall,
            });
        }
    }
    out
}

/// Why a map is not a valid CLS map. Loops are numbered as
/// [`ClsShape::loops`] visits them, shape after shape.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InvariantError {
    #[error("loop {loop_index} has {len} segments; a closed loop needs at least 3")]
    TooShort { loop_index: usize, len: usize },
    #[error("loop {loop_index}: segment {segment} has a non-finite coordinate")]
    NotFinite { loop_index: usize, segment: usize },
    #[error("loop {loop_index}: segment {segment} has zero length")]
    ZeroLength { loop_index: usize, segment: usize },
    #[error("loop {loop_index}: segment {segment} does not end where the next one starts")]
    Open { loop_index: usize, segment: usize },
    #[error(
        "loop {loop_index} has the wrong orientation (signed area {signed_area} m²; {expected})"
    )]
    Orientation {
        loop_index: usize,
        signed_area: f64,
        expected: &'static str,
    },
    #[error("segments {first:?} and {second:?} (loop, segment) intersect")]
    Intersection {
        first: (usize, usize),
        second: (usize, usize),
    },
}

/// A segment as the crossing test sees it: `(loop, segment)`, its ends,
/// and the length of its loop (to recognise neighbours).
/// Loop index, segment index, start, end, loop length, and whether the
/// segment is known to be unchanged from a valid map.
type SweepEntry = (usize, usize, [f64; 2], [f64; 2], usize, bool);

/// Checks every invariant of the module documentation.
pub fn check_loops<'a>(
    shapes: impl IntoIterator<Item = &'a ClsShape>,
) -> Result<(), InvariantError> {
    check_loops_changed(shapes, |_, _| false)
}

/// [`check_loops`] for a map made by changing a valid one: `unchanged`
/// tells the segments (start, end) taken over as they were (asked once
/// per segment, in loop order). Closure and
/// orientation are checked everywhere (linear time); crossings only where
/// a changed segment takes part, since two unchanged ones did not cross
/// before and still do not.
pub fn check_loops_changed<'a>(
    shapes: impl IntoIterator<Item = &'a ClsShape>,
    mut unchanged: impl FnMut([f64; 2], [f64; 2]) -> bool,
) -> Result<(), InvariantError> {
    // Sized up front: grown push by push, a map of thousands of segments
    // was copied over and over on every update.
    let shapes: Vec<&ClsShape> = shapes.into_iter().collect();
    let segments = shapes
        .iter()
        .flat_map(|shape| shape.loops())
        .map(|lp| lp.len())
        .sum();
    let mut all: Vec<SweepEntry> = Vec::with_capacity(segments);
    let mut loop_index = 0;
    for shape in shapes {
        for (k, lp) in shape.loops().enumerate() {
            check_chain(lp, loop_index)?;
            let area = lp.signed_area();
            let (ok, expected) = if k == 0 {
                (area > 0.0, "an outer loop must be counter-clockwise")
            } else {
                (area < 0.0, "a hole must be clockwise")
            };
            if !ok {
                return Err(InvariantError::Orientation {
                    loop_index,
                    signed_area: area,
                    expected,
                });
            }
            for (i, s) in lp.segments().iter().enumerate() {
                let old = unchanged(s.start(), s.end());
                all.push((loop_index, i, s.start(), s.end(), lp.len(), old));
            }
            loop_index += 1;
        }
    }
    // Only segments that meet the box of the changed ones can cross them.
    let mut changed = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for &(_, _, a, b, _, old) in &all {
        if !old {
            for p in [a, b] {
                changed.0 = [changed.0[0].min(p[0]), changed.0[1].min(p[1])];
                changed.1 = [changed.1[0].max(p[0]), changed.1[1].max(p[1])];
            }
        }
    }
    all.retain(|&(_, _, a, b, _, old)| {
        !old || (a[0].min(b[0]) <= changed.1[0]
            && a[0].max(b[0]) >= changed.0[0]
            && a[1].min(b[1]) <= changed.1[1]
            && a[1].max(b[1]) >= changed.0[1])
    });
    check_no_crossings(&mut all)
}

fn check_chain(lp: &ClsLoop, loop_index: usize) -> Result<(), InvariantError> {
    let segs = lp.segments();
    if segs.len() < 3 {
        return Err(InvariantError::TooShort {
            loop_index,
            len: segs.len(),
        });
    }
    for (i, s) in segs.iter().enumerate() {
        let (a, b) = (s.start(), s.end());
        if ![a[0], a[1], b[0], b[1]].iter().all(|v| v.is_finite()) {
            return Err(InvariantError::NotFinite {
                loop_index,
                segment: i,
            });
        }
        if a == b {
            return Err(InvariantError::ZeroLength {
                loop_index,
                segment: i,
            });
        }
        if segs[(i + 1) % segs.len()].start() != b {
            return Err(InvariantError::Open {
                loop_index,
                segment: i,
            });
        }
    }
    Ok(())
}

/// Sweep over x: each segment is tested only against segments whose
/// x-intervals overlap it, so typical maps cost O(n log n).
fn check_no_crossings(all: &mut [SweepEntry]) -> Result<(), InvariantError> {
    all.sort_by(|p, q| p.2[0].min(p.3[0]).total_cmp(&q.2[0].min(q.3[0])));
    for i in 0..all.len() {
        let (li, si, a, b, ni, old_i) = all[i];
        let max_x = a[0].max(b[0]);
        for &(lj, sj, c, d, _, old_j) in &all[i + 1..] {
            if c[0].min(d[0]) > max_x {
                break;
            }
            if old_i && old_j {
                continue;
            }
            let adjacent = li == lj && ((si + 1) % ni == sj || (sj + 1) % ni == si);
            let shared = [a, b].into_iter().find(|p| *p == c || *p == d);
            let hit = match shared {
                // Segments meeting at a common vertex (consecutive ones, or a
                // loop pinched at one point) may not fold over each other.
                Some(v) => overlap_beyond(v, a, b, c, d),
                None if adjacent => true,
                None => segments_touch(a, b, c, d),
            };
            if hit {
                return Err(InvariantError::Intersection {
                    first: (li, si),
                    second: (lj, sj),
                });
            }
        }
    }
    Ok(())
}

fn cross(o: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

fn on_segment(a: [f64; 2], b: [f64; 2], p: [f64; 2]) -> bool {
    p[0] >= a[0].min(b[0])
        && p[0] <= a[0].max(b[0])
        && p[1] >= a[1].min(b[1])
        && p[1] <= a[1].max(b[1])
}

/// Whether closed segments `ab` and `cd` share any point (exact predicates
/// on the stored coordinates).
pub(crate) fn segments_touch(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let d1 = cross(c, d, a);
    let d2 = cross(c, d, b);
    let d3 = cross(a, b, c);
    let d4 = cross(a, b, d);
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    (d1 == 0.0 && on_segment(c, d, a))
        || (d2 == 0.0 && on_segment(c, d, b))
        || (d3 == 0.0 && on_segment(a, b, c))
        || (d4 == 0.0 && on_segment(a, b, d))
}

/// Whether segments `ab` and `cd`, which share the vertex `v`, have more
/// than `v` in common: collinear, and leaving `v` in the same direction.
fn overlap_beyond(v: [f64; 2], a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    if cross(a, b, c) != 0.0 || cross(a, b, d) != 0.0 {
        return false;
    }
    let far_ab = if a == v { b } else { a };
    let far_cd = if c == v { d } else { c };
    (far_ab[0] - v[0]) * (far_cd[0] - v[0]) + (far_ab[1] - v[1]) * (far_cd[1] - v[1]) > 0.0
}

/// A closed loop of virtual segments through `pts`: the test fixture of
/// this module and of `cls_map`.
#[cfg(test)]
pub(crate) fn polygon(pts: &[[f64; 2]]) -> ClsLoop {
    let n = pts.len();
    ClsLoop::new(
        (0..n)
            .map(|i| ClsSegment::virtual_between(pts[i], pts[(i + 1) % n]))
            .collect(),
    )
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn square(x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<[f64; 2]> {
        vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
    }

    #[test]
    fn a_room_with_a_pillar_is_valid() {
        let mut hole = square(2.0, 2.0, 3.0, 3.0);
        hole.reverse();
        let shape = ClsShape {
            outer: polygon(&square(0.0, 0.0, 5.0, 4.0)),
            holes: vec![polygon(&hole)],
        };
        check_loops(std::slice::from_ref(&shape)).unwrap();
        assert!((shape.area() - 19.0).abs() < 1e-12);
        assert!(shape.contains([1.0, 1.0]));
        assert!(!shape.contains([2.5, 2.5]));
        assert!(!shape.contains([6.0, 1.0]));
        let list = items(std::slice::from_ref(&shape));
        assert_eq!(list.len(), 8);
        assert_eq!(list[3].next, 0);
        assert_eq!(list[7].next, 4);
        assert_eq!(list[5].index, 5);
    }

    #[test]
    fn each_violation_is_named() {
        let cw = {
            let mut p = square(0.0, 0.0, 1.0, 1.0);
            p.reverse();
            p
        };
        let shape = |outer: ClsLoop| {
            vec![ClsShape {
                outer,
                holes: vec![],
            }]
        };
        assert!(matches!(
            check_loops(&shape(polygon(&cw))),
            Err(InvariantError::Orientation { .. })
        ));
        let bow_tie = polygon(&[[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.5]]);
        assert!(matches!(
            check_loops(&shape(bow_tie)),
            Err(InvariantError::Intersection { .. })
        ));
        let mut open = polygon(&square(0.0, 0.0, 1.0, 1.0));
        open.segments_mut()[1].line.end = [1.0, 0.9];
        assert!(matches!(
            check_loops(&shape(open)),
            Err(InvariantError::Open { .. })
        ));
        let two = polygon(&[[0.0, 0.0], [1.0, 0.0]]);
        assert!(matches!(
            check_loops(&shape(two)),
            Err(InvariantError::TooShort { .. })
        ));
        let mut nan = polygon(&square(0.0, 0.0, 1.0, 1.0));
        nan.segments_mut()[0].line.start = [f64::NAN, 0.0];
        assert!(matches!(
            check_loops(&shape(nan)),
            Err(InvariantError::NotFinite { .. })
        ));
        // A spike: out along an edge and straight back.
        let spike = polygon(&[[0.0, 0.0], [2.0, 0.0], [1.0, 0.0], [1.0, 1.0]]);
        assert!(check_loops(&shape(spike)).is_err());
    }

    #[test]
    fn touching_loops_are_rejected() {
        let a = ClsShape {
            outer: polygon(&square(0.0, 0.0, 1.0, 1.0)),
            holes: vec![],
        };
        let b = ClsShape {
            outer: polygon(&square(1.0, 0.5, 2.0, 1.5)),
            holes: vec![],
        };
        assert!(check_loops(std::slice::from_ref(&a)).is_ok());
        assert!(matches!(
            check_loops(&[a, b]),
            Err(InvariantError::Intersection { .. })
        ));
    }
}
