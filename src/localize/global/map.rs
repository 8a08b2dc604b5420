//! The map as global localization needs it: the actual segments sorted by
//! length (the anchor's partners are a prefix), a BVH over their bounding
//! boxes for the voters' swept-box queries, and a [`SegmentIndex`] for the
//! refinement by local localization.

use parry2d_f64::bounding_volume::Aabb;
use parry2d_f64::math::Vector;
use parry2d_f64::partitioning::{Bvh, BvhNode};

use super::free::FreeSpace;
use crate::geometry::CogLine;
use crate::geometry::SegmentIndex;
use crate::map::cls::ClsMap;

/// Map lines prepared for global localization (map frame).
#[derive(Debug, Clone, Default)]
pub struct GlobalMap {
    /// Finite lines, longest first.
    lines: Vec<CogLine>,
    /// Boxes of `lines`, keyed by position in `lines`.
    bvh: Bvh,
    /// The same lines for [`localize`](crate::localize::localize).
    index: SegmentIndex,
    /// The free space the map explored (empty unless given).
    free: FreeSpace,
}

/// Bounding box of the points, grown by `margin` (m).
pub(crate) fn aabb_of(points: &[[f64; 2]], margin: f64) -> Aabb {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for p in points {
        lo = [lo[0].min(p[0]), lo[1].min(p[1])];
        hi = [hi[0].max(p[0]), hi[1].max(p[1])];
    }
    Aabb::new(
        Vector::new(lo[0] - margin, lo[1] - margin),
        Vector::new(hi[0] + margin, hi[1] + margin),
    )
}

fn is_finite(line: &CogLine) -> bool {
    [
        line.theta,
        line.xc,
        line.yc,
        line.start[0],
        line.start[1],
        line.end[0],
        line.end[1],
    ]
    .iter()
    .all(|v| v.is_finite())
}

impl GlobalMap {
    /// Prepares `lines` (map frame, free space on their left). Lines with
    /// non-finite numbers are left out.
    pub fn new(lines: impl IntoIterator<Item = CogLine>) -> GlobalMap {
        let mut lines: Vec<CogLine> = lines.into_iter().filter(is_finite).collect();
        // Longest first; ties by position so the order never depends on
        // the input's.
        lines.sort_by(|a, b| {
            b.length()
                .total_cmp(&a.length())
                .then(a.xc.total_cmp(&b.xc))
                .then(a.yc.total_cmp(&b.yc))
                .then(a.theta.total_cmp(&b.theta))
        });
        let mut bvh = Bvh::new();
        let mut index = SegmentIndex::new();
        for (i, line) in lines.iter().enumerate() {
            // Fewer than u32::MAX lines fit in memory as CogLines anyway;
            // the ones beyond are simply not indexed.
            let Ok(key) = u32::try_from(i) else { break };
            bvh.insert(aabb_of(&[line.start, line.end], 0.0), key);
            index.insert(*line);
        }
        GlobalMap {
            lines,
            bvh,
            index,
            free: FreeSpace::default(),
        }
    }

    /// The same map with the free space `cls` explored, against which
    /// [`disambiguate`](super::disambiguate) also judges the places.
    pub fn with_free_space(mut self, cls: &ClsMap) -> GlobalMap {
        self.free = FreeSpace::new(cls);
        self
    }

    /// The explored free space (empty unless given).
    pub fn free_space(&self) -> &FreeSpace {
        &self.free
    }

    /// The lines, longest first.
    pub fn lines(&self) -> &[CogLine] {
        &self.lines
    }

    /// Number of lines.
    pub fn len(&self) -> usize {
        self.lines.len()
    }

    /// Whether the map has no line.
    pub fn is_empty(&self) -> bool {
        self.lines.is_empty()
    }

    /// The index local localization runs against.
    pub fn index(&self) -> &SegmentIndex {
        &self.index
    }

    /// The lines at least `min_length` long (m): a prefix of [`lines`](Self::lines).
    pub(crate) fn at_least(&self, min_length: f64) -> &[CogLine] {
        let n = self.lines.partition_point(|l| l.length() >= min_length);
        &self.lines[..n]
    }

    /// Positions in [`lines`](Self::lines) of the lines whose boxes meet `query`.
    pub(crate) fn overlapping(&self, query: Aabb) -> impl Iterator<Item = usize> + '_ {
        let q = BvhNode::leaf(query, 0);
        self.bvh
            .leaves(move |node: &BvhNode| node.intersects(&q))
            .map(|k| k as usize)
    }
}
