//! The free region shrunk by the robot's clearance (configuration space of
//! a round robot): where the robot's centre may go without its footprint
//! touching a map boundary.
//!
//! The CLS map is a polygon with holes (free space on the left of every
//! segment). i_overlay offsets it inwards by the clearance (`outline` with
//! a negative offset and round joins, the arc drawn as chords with the
//! offset widened so every chord keeps the clearance; see
//! [`FreeSpace::from_shapes`]). A frontier is treated like a wall here:
//! what lies beyond it is unknown.
//!
//! The edges sit in a parry BVH, so inside tests cost what the edges near
//! the query cost, not what the whole map costs.

use i_overlay::mesh::float::outline::offset::OutlineOffset;
use i_overlay::mesh::float::style::{LineJoin, OutlineStyle};
use parry2d_f64::bounding_volume::Aabb;
use parry2d_f64::math::Vector;
use parry2d_f64::partitioning::{Bvh, BvhBuildStrategy};
use parry2d_f64::query::Ray;

use crate::map::cls::{ClsMap, ClsShape};

/// Grid of the offset engine (points per metre): 0.1 mm, far below the
/// map's own 1 mm grid.
const OFFSET_SCALE: f64 = 1e4;
/// Geometric tolerance (m) of the inside tests: points within it of the
/// boundary count as inside, so paths may run along the boundary.
pub const BOUNDARY_TOLERANCE: f64 = 1e-6;

/// Why the free region could not be shrunk.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FreeSpaceError {
    #[error("the clearance {0} m is not a finite positive length")]
    BadClearance(f64),
    #[error("the polygon cannot be offset: {0}")]
    Offset(String),
}

/// One boundary edge of the shrunk region.
#[derive(Debug, Clone, Copy)]
struct Edge {
    a: [f64; 2],
    b: [f64; 2],
}

/// A reflex corner of the region's boundary: `vertex` between `prev` and
/// `next` (boundary order).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Corner {
    pub prev: [f64; 2],
    pub vertex: [f64; 2],
    pub next: [f64; 2],
}

impl Corner {
    /// Whether the line from the vertex towards `w` is tangent to the
    /// boundary here: both neighbours lie on one side of it (or on it). A
    /// shortest path only ever bends at a corner along such lines, so the
    /// other visibility edges can be skipped (the reduced visibility graph).
    pub fn tangent_towards(&self, w: [f64; 2]) -> bool {
        let d = sub(w, self.vertex);
        let len = dot(d, d).sqrt();
        if len <= BOUNDARY_TOLERANCE {
            return true;
        }
        let s1 = cross(d, sub(self.prev, self.vertex)) / len;
        let s2 = cross(d, sub(self.next, self.vertex)) / len;
        let tol = BOUNDARY_TOLERANCE;
        !((s1 > tol && s2 < -tol) || (s1 < -tol && s2 > tol))
    }
}

/// The shrunk free region: closed contours, outer ones counter-clockwise,
/// holes clockwise, so the region lies on the left of every edge.
#[derive(Debug, Clone, Default)]
pub struct FreeSpace {
    contours: Vec<Vec<[f64; 2]>>,
    edges: Vec<Edge>,
    /// The edges' boxes, grown by the tolerance, keyed by edge index.
    bvh: Bvh,
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn cross(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

/// Euclidean distance (m).
pub fn distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// The point of segment `a`–`b` nearest `p`, and its parameter in [0, 1].
pub fn project_on_segment(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> ([f64; 2], f64) {
    let e = sub(b, a);
    let len2 = dot(e, e);
    let t = if len2 > 0.0 {
        (dot(sub(p, a), e) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    ([a[0] + t * e[0], a[1] + t * e[1]], t)
}

/// The loops of one CLS shape as plain contours (outer first).
fn shape_contours(shape: &ClsShape) -> Vec<Vec<[f64; 2]>> {
    shape
        .loops()
        .map(|l| l.segments().iter().map(|s| s.start()).collect())
        .collect()
}

/// Angle (rad) between the chords that approximate the offset's arcs.
const ROUND_STEP: f64 = 0.3;

impl FreeSpace {
    /// The free space of `map` shrunk by `clearance` (m).
    pub fn from_map(map: &ClsMap, clearance: f64) -> Result<Self, FreeSpaceError> {
        let shapes: Vec<Vec<Vec<[f64; 2]>>> = map.shapes().iter().map(shape_contours).collect();
        FreeSpace::from_shapes(&shapes, clearance)
    }

    /// `shapes` (each an outer contour, counter-clockwise, followed by its
    /// holes, clockwise; m) shrunk by `clearance` (m).
    pub fn from_shapes(
        shapes: &[Vec<Vec<[f64; 2]>>],
        clearance: f64,
    ) -> Result<Self, FreeSpaceError> {
        if !(clearance.is_finite() && clearance > 0.0) {
            return Err(FreeSpaceError::BadClearance(clearance));
        }
        // Round joins are the exact offset around a wall's end or an
        // obstacle's corner; mitred ones reach far out at sharp corners
        // (0.37 m / sin(θ/2): 3.4 m for a 12.6° sliver of unexplored space)
        // and close doorways that are wide open. The arc is drawn with
        // chords ROUND_STEP radians apart; offsetting by r / cos(step/2)
        // keeps every chord at least r from the corner.
        let offset = clearance / (0.5 * ROUND_STEP).cos();
        let style = OutlineStyle::new(-offset).line_join(LineJoin::Round(ROUND_STEP));
        let mut contours = Vec::new();
        for shape in shapes {
            let finite = shape
                .iter()
                .flatten()
                .all(|p| p[0].is_finite() && p[1].is_finite());
            if !finite {
                return Err(FreeSpaceError::Offset("a vertex is not finite".into()));
            }
            if shape.first().is_none_or(|c| c.len() < 3) {
                continue;
            }
            let out = shape
                .outline_fixed_scale(&style, OFFSET_SCALE)
                .map_err(|e| FreeSpaceError::Offset(format!("{e:?}")))?;
            contours.extend(out.into_iter().flatten().filter(|c| c.len() >= 3));
        }
        Ok(FreeSpace::from_contours(contours))
    }

    /// A region given directly by its contours (region on the left of
    /// every edge).
    /// Contours with a non-finite vertex or fewer than three vertices are
    /// left out.
    pub fn from_contours(contours: Vec<Vec<[f64; 2]>>) -> Self {
        let contours: Vec<Vec<[f64; 2]>> = contours
            .into_iter()
            .filter(|c| c.len() >= 3 && c.iter().all(|p| p[0].is_finite() && p[1].is_finite()))
            .collect();
        let mut edges = Vec::new();
        for c in &contours {
            for (i, &a) in c.iter().enumerate() {
                edges.push(Edge {
                    a,
                    b: c[(i + 1) % c.len()],
                });
            }
        }
        let t = 2.0 * BOUNDARY_TOLERANCE;
        let boxes: Vec<Aabb> = edges
            .iter()
            .map(|e| {
                Aabb::new(
                    Vector::new(e.a[0].min(e.b[0]) - t, e.a[1].min(e.b[1]) - t),
                    Vector::new(e.a[0].max(e.b[0]) + t, e.a[1].max(e.b[1]) + t),
                )
            })
            .collect();
        let bvh = Bvh::from_leaves(BvhBuildStrategy::Binned, &boxes);
        FreeSpace {
            contours,
            edges,
            bvh,
        }
    }

    /// The edges whose boxes the segment `p`–`q` meets.
    fn edges_along(&self, p: [f64; 2], q: [f64; 2]) -> impl Iterator<Item = &Edge> + '_ {
        let ray = Ray::new(
            Vector::new(p[0], p[1]),
            Vector::new(q[0] - p[0], q[1] - p[1]),
        );
        self.bvh
            .leaves(move |node| node.cast_ray(&ray, 1.0) <= 1.0)
            .filter_map(|i| self.edges.get(i as usize))
    }

    /// The edges whose boxes lie within `r` (m) of `p` (box distance).
    fn edges_near(&self, p: [f64; 2], r: f64) -> impl Iterator<Item = &Edge> + '_ {
        let query = Aabb::new(
            Vector::new(p[0] - r, p[1] - r),
            Vector::new(p[0] + r, p[1] + r),
        );
        let hits: Vec<u32> = self.bvh.intersect_aabb(&query).collect();
        hits.into_iter().filter_map(|i| self.edges.get(i as usize))
    }

    /// The contours (outer counter-clockwise, holes clockwise).
    pub fn contours(&self) -> &[Vec<[f64; 2]>] {
        &self.contours
    }

    pub fn is_empty(&self) -> bool {
        self.contours.is_empty()
    }

    /// Area (m²) of the region.
    pub fn area(&self) -> f64 {
        self.contours
            .iter()
            .map(|c| {
                0.5 * (0..c.len())
                    .map(|i| cross(c[i], c[(i + 1) % c.len()]))
                    .sum::<f64>()
            })
            .sum()
    }

    /// Distance (m) from `p` to the nearest boundary edge.
    pub fn boundary_distance(&self, p: [f64; 2]) -> f64 {
        self.edges
            .iter()
            .map(|e| distance(p, project_on_segment(p, e.a, e.b).0))
            .fold(f64::INFINITY, f64::min)
    }

    /// Whether `p` lies strictly inside by the crossing number.
    fn encloses(&self, p: [f64; 2]) -> bool {
        let mut inside = false;
        let ray = Ray::new(Vector::new(p[0], p[1]), Vector::new(1.0, 0.0));
        let crossing = self
            .bvh
            .leaves(move |node| node.cast_ray(&ray, f64::MAX) < f64::MAX)
            .filter_map(|i| self.edges.get(i as usize));
        for e in crossing {
            let (a, b) = (e.a, e.b);
            if (a[1] > p[1]) != (b[1] > p[1]) {
                let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
                if x > p[0] {
                    inside = !inside;
                }
            }
        }
        inside
    }

    /// Whether `p` lies in the region or within [`BOUNDARY_TOLERANCE`] of
    /// its boundary.
    pub fn contains(&self, p: [f64; 2]) -> bool {
        self.encloses(p)
            || self
                .edges_near(p, BOUNDARY_TOLERANCE)
                .any(|e| distance(p, project_on_segment(p, e.a, e.b).0) <= BOUNDARY_TOLERANCE)
    }

    /// The point of the region's boundary nearest `p`.
    pub fn nearest_boundary_point(&self, p: [f64; 2]) -> Option<[f64; 2]> {
        self.edges
            .iter()
            .map(|e| project_on_segment(p, e.a, e.b).0)
            .min_by(|x, y| distance(p, *x).total_cmp(&distance(p, *y)))
    }

    /// The vertices where the boundary turns away from the region
    /// (reflex corners of the free space): the only vertices a shortest
    /// path can bend at.
    pub fn reflex_vertices(&self) -> Vec<[f64; 2]> {
        self.reflex_corners()
            .into_iter()
            .map(|c| c.vertex)
            .collect()
    }

    /// The reflex corners with their neighbouring vertices.
    pub fn reflex_corners(&self) -> Vec<Corner> {
        let mut out = Vec::new();
        for c in &self.contours {
            let n = c.len();
            for i in 0..n {
                let prev = c[(i + n - 1) % n];
                let vertex = c[i];
                let next = c[(i + 1) % n];
                if cross(sub(vertex, prev), sub(next, vertex)) < 0.0 {
                    out.push(Corner { prev, vertex, next });
                }
            }
        }
        out
    }

    /// Whether the straight segment `p`–`q` lies in the region (boundary
    /// included): it crosses no edge, and every piece between the places
    /// where it touches the boundary has its middle inside.
    pub fn segment_inside(&self, p: [f64; 2], q: [f64; 2]) -> bool {
        let tol = BOUNDARY_TOLERANCE;
        let d = sub(q, p);
        let len = dot(d, d).sqrt();
        if len <= tol {
            return self.contains(p);
        }
        let mut cuts = vec![0.0, 1.0];
        for e in self.edges_along(p, q) {
            // Signed distances of the edge's ends from the line p–q and of
            // p, q from the edge's line.
            let da = cross(d, sub(e.a, p)) / len;
            let db = cross(d, sub(e.b, p)) / len;
            let ed = sub(e.b, e.a);
            let elen = dot(ed, ed).sqrt();
            if elen > tol {
                let dp = cross(ed, sub(p, e.a)) / elen;
                let dq = cross(ed, sub(q, e.a)) / elen;
                let proper = da.abs() > tol
                    && db.abs() > tol
                    && dp.abs() > tol
                    && dq.abs() > tol
                    && (da > 0.0) != (db > 0.0)
                    && (dp > 0.0) != (dq > 0.0);
                if proper {
                    return false;
                }
            }
            for v in [e.a, e.b] {
                let (x, t) = project_on_segment(v, p, q);
                if distance(x, v) <= tol {
                    cuts.push(t);
                }
            }
        }
        cuts.sort_by(f64::total_cmp);
        cuts.windows(2).all(|w| {
            if (w[1] - w[0]) * len <= tol {
                return true;
            }
            let t = 0.5 * (w[0] + w[1]);
            self.contains([p[0] + t * d[0], p[1] + t * d[1]])
        })
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn square(x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<[f64; 2]> {
        vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
    }

    #[test]
    fn square_shrinks_by_the_clearance() {
        let f = FreeSpace::from_shapes(&[vec![square(0.0, 0.0, 4.0, 2.0)]], 0.5).unwrap();
        // Straight walls move in by r / cos(ROUND_STEP / 2): 1.1 % more
        // than the clearance, the price of arcs drawn outside the circle.
        let r = 0.5 / (0.5 * ROUND_STEP).cos();
        let area = (4.0 - 2.0 * r) * (2.0 - 2.0 * r);
        assert!(
            (f.area() - area).abs() < 1e-3,
            "area {} vs {area}",
            f.area()
        );
        assert!(f.contains([0.51, 0.51]) && f.contains([2.0, 1.0]));
        assert!(!f.contains([0.5, 1.0]));
    }

    #[test]
    fn hole_grows_and_blocks_segments() {
        let mut hole = square(1.5, 0.8, 2.5, 1.2);
        hole.reverse();
        let f = FreeSpace::from_shapes(&[vec![square(0.0, 0.0, 4.0, 2.0), hole]], 0.3).unwrap();
        assert!(!f.contains([2.0, 1.0]));
        assert!(!f.segment_inside([0.5, 1.0], [3.5, 1.0]));
        assert!(f.segment_inside([0.5, 0.31], [3.5, 0.31]));
        assert!(!f.reflex_vertices().is_empty());
    }

    #[test]
    fn segment_through_a_concave_corner_is_refused() {
        // An L: the chord between the two arms leaves the region.
        let l = vec![
            [0.0, 0.0],
            [4.0, 0.0],
            [4.0, 1.0],
            [1.0, 1.0],
            [1.0, 4.0],
            [0.0, 4.0],
        ];
        let f = FreeSpace::from_contours(vec![l]);
        assert!(!f.segment_inside([3.5, 0.5], [0.5, 3.5]));
        assert!(f.segment_inside([3.5, 0.5], [1.0, 1.0]));
        assert!(f.segment_inside([1.0, 1.0], [0.5, 3.5]));
        // Along the boundary counts as inside.
        assert!(f.segment_inside([0.0, 0.0], [4.0, 0.0]));
        assert_eq!(f.reflex_vertices(), vec![[1.0, 1.0]]);
    }

    #[test]
    fn tangent_lines_keep_both_neighbours_on_one_side() {
        // The L's reflex corner (1, 1) between (4, 1) and (1, 4).
        let c = Corner {
            prev: [4.0, 1.0],
            vertex: [1.0, 1.0],
            next: [1.0, 4.0],
        };
        assert!(c.tangent_towards([3.5, 0.5]));
        assert!(c.tangent_towards([0.5, 3.5]));
        assert!(c.tangent_towards([4.0, 1.0]), "along an edge");
        // Into the corner's wedge, or out of it the other way: not tangent.
        assert!(!c.tangent_towards([2.0, 2.0]));
        assert!(!c.tangent_towards([0.0, 0.0]));
    }

    #[test]
    fn bad_clearance_is_refused() {
        let s = [vec![square(0.0, 0.0, 1.0, 1.0)]];
        assert!(matches!(
            FreeSpace::from_shapes(&s, f64::NAN),
            Err(FreeSpaceError::BadClearance(_))
        ));
        assert!(FreeSpace::from_shapes(&s, 0.6).unwrap().is_empty());
    }
}
