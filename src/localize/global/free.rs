//! The map's explored free space as the start search asks it: does a wall
//! the scan shows stand where the map saw through?
//!
//! A scan line that no map wall explains at a place says little by itself
//! (the map may never have seen that wall: a corner it did not reach, a
//! cupboard moved in since), but one that stands deep inside the free space
//! the map explored there contradicts the place: from there the sensor saw
//! through that spot. That tells apart look-alike places one of which has
//! furniture the other lacks, where the explained length alone differs by
//! the same amount scan after scan and so never decides.
//!
//! The boundary edges of every CLS loop (walls and frontiers, holes
//! included) sit in a BVH: a point is inside by the even–odd rule over the
//! edges a ray to +x crosses, and away from the boundary when no edge lies
//! within the tolerance; both queries touch only the edges near the point
//! and along its row.

use parry2d_f64::bounding_volume::Aabb;
use parry2d_f64::math::Vector;
use parry2d_f64::partitioning::{Bvh, BvhNode};

use super::map::aabb_of;
use crate::geometry::{CogLine, SegmentIndex, point_segment_distance};
use crate::map::cls::ClsMap;

/// Spacing (m) of the points a line is judged at.
const SAMPLE_STEP: f64 = 0.05;

/// The explored free space of a map (map frame).
#[derive(Debug, Clone, Default)]
pub struct FreeSpace {
    /// Boundary edges, start and end.
    edges: Vec<([f64; 2], [f64; 2])>,
    /// Boxes of `edges`, keyed by position.
    bvh: Bvh,
    /// Largest x of any edge (m): where a ray to +x leaves the map.
    right: f64,
}

impl FreeSpace {
    /// The free space of `map`: every loop of every shape. Edges with a
    /// non-finite end are left out.
    pub fn new(map: &ClsMap) -> FreeSpace {
        let mut space = FreeSpace {
            right: f64::NEG_INFINITY,
            ..FreeSpace::default()
        };
        for segment in map
            .shapes()
            .iter()
            .flat_map(|s| s.loops())
            .flat_map(|l| l.segments())
        {
            let (a, b) = (segment.start(), segment.end());
            if !(a.iter().chain(&b).all(|v| v.is_finite())) {
                continue;
            }
            let Ok(key) = u32::try_from(space.edges.len()) else {
                break;
            };
            space.bvh.insert(aabb_of(&[a, b], 0.0), key);
            space.edges.push((a, b));
            space.right = space.right.max(a[0]).max(b[0]);
        }
        space
    }

    /// Whether the map explored nothing.
    pub fn is_empty(&self) -> bool {
        self.edges.is_empty()
    }

    fn edges_in(&self, query: Aabb) -> impl Iterator<Item = &([f64; 2], [f64; 2])> + '_ {
        let q = BvhNode::leaf(query, 0);
        self.bvh
            .leaves(move |node: &BvhNode| node.intersects(&q))
            .filter_map(|k| self.edges.get(k as usize))
    }

    /// Whether `p` lies in the explored free space farther than
    /// `tolerance` (m) from its boundary.
    pub fn strictly_contains(&self, p: [f64; 2], tolerance: f64) -> bool {
        if self.is_empty() || !(p[0].is_finite() && p[1].is_finite()) || p[0] > self.right {
            return false;
        }
        let near = self.edges_in(aabb_of(&[p], tolerance));
        if near
            .into_iter()
            .any(|(a, b)| point_segment_distance(p, *a, *b) <= tolerance)
        {
            return false;
        }
        let row = Aabb::new(
            Vector::new(p[0], p[1]),
            Vector::new(self.right.max(p[0]), p[1]),
        );
        let crossings = self
            .edges_in(row)
            .filter(|(a, b)| {
                (a[1] > p[1]) != (b[1] > p[1])
                    && a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]) > p[0]
            })
            .count();
        crossings % 2 == 1
    }

    /// Length (m) of `lines` (map frame) lying in the explored free space
    /// farther than `tolerance` from its boundary and from every one of
    /// `walls`, judged every 5 cm. A line on a map wall is explained, even
    /// where the free space reaches past the wall: on real floors it does
    /// (a door open at one time and shut at another, glass, a view from a
    /// pose a little off).
    pub fn length_inside(
        &self,
        lines: impl IntoIterator<Item = CogLine>,
        tolerance: f64,
        walls: &SegmentIndex,
    ) -> f64 {
        let on_a_wall = |p: [f64; 2]| {
            walls
                .near(p, tolerance)
                .any(|w| point_segment_distance(p, w.start, w.end) <= tolerance)
        };
        let mut inside = 0.0;
        for l in lines {
            let (piece, points) = l.samples(SAMPLE_STEP);
            for p in points {
                if self.strictly_contains(p, tolerance) && !on_a_wall(p) {
                    inside += piece;
                }
            }
        }
        inside
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
pub(super) mod tests {
    use super::*;
    use crate::map::cls::{ClsLoop, ClsSegment, ClsShape};

    /// The loop through `points`, in their order, of virtual segments.
    pub(in crate::localize::global) fn loop_through(points: &[[f64; 2]]) -> ClsLoop {
        ClsLoop::new(
            points
                .iter()
                .zip(points.iter().cycle().skip(1))
                .map(|(a, b)| ClsSegment::virtual_between(*a, *b))
                .collect(),
        )
    }

    /// A 4 m square room (counter-clockwise) with a 1 m pillar (a hole,
    /// clockwise) in its middle.
    fn room() -> FreeSpace {
        let outer = loop_through(&[[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]]);
        let pillar = loop_through(&[[1.5, 1.5], [1.5, 2.5], [2.5, 2.5], [2.5, 1.5]]);
        let map = ClsMap::from_shapes(
            Default::default(),
            vec![ClsShape {
                outer,
                holes: vec![pillar],
            }],
        )
        .unwrap();
        FreeSpace::new(&map)
    }

    #[test]
    fn inside_means_seen_through_and_away_from_every_edge() {
        let free = room();
        assert!(free.strictly_contains([0.5, 0.5], 0.15));
        assert!(free.strictly_contains([3.5, 2.0], 0.15));
        // The pillar is not free space, nor is what lies beyond the walls.
        assert!(!free.strictly_contains([2.0, 2.0], 0.15));
        assert!(!free.strictly_contains([5.0, 2.0], 0.15));
        assert!(!free.strictly_contains([-1.0, 2.0], 0.15));
        // Within the tolerance of a wall or of the pillar.
        assert!(!free.strictly_contains([0.1, 2.0], 0.15));
        assert!(!free.strictly_contains([1.4, 2.0], 0.15));
        assert!(free.strictly_contains([1.3, 2.0], 0.15));
        // A row through a vertex is counted once.
        assert!(free.strictly_contains([0.5, 1.5], 0.15));
        assert!(!free.strictly_contains([f64::NAN, 1.0], 0.15));
        assert!(!FreeSpace::default().strictly_contains([0.5, 0.5], 0.0));
    }

    #[test]
    fn a_line_across_the_room_is_inside_but_where_it_meets_the_pillar() {
        let free = room();
        let across = CogLine::from_centre(0.0, [2.0, 2.0], -1.8, 1.8, 0.001, 0.002, 100);
        // 3.6 m long, its ends 0.2 m from the walls; the pillar takes 1 m
        // and the tolerance 0.15 m on each side of it.
        let none = SegmentIndex::new();
        let inside = free.length_inside([across], 0.15, &none);
        assert!((inside - (3.6 - 1.3)).abs() < 0.06, "{inside}");
        let wall = CogLine::from_centre(0.0, [2.0, 0.0], -2.0, 2.0, 0.001, 0.002, 100);
        assert_eq!(free.length_inside([wall], 0.15, &none), 0.0);
        // A map wall across the room (the free space reaching past it)
        // explains the part of the line along it.
        let mut walls = SegmentIndex::new();
        walls.insert(CogLine::from_centre(
            0.0,
            [0.9, 2.0],
            -0.5,
            0.5,
            0.001,
            0.002,
            100,
        ));
        let inside = free.length_inside([across], 0.15, &walls);
        assert!((inside - (3.6 - 1.3 - 1.0 - 0.15)).abs() < 0.06, "{inside}");
    }
}
