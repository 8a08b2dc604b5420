//! Fusion of a scan's actual segments into the actual segments on the CLS
//! boundary, and the repair of the loops around the moved lines.
//!
//! The fusion itself is the segment map's ([`fuse`], after
//! [`blur_by_pose`] has moved the scan line into the map frame); this module
//! only decides which boundary line each scan line fuses with (the best
//! corresponding one, [`SegmentIndex::best_match`]) and moves the boundary
//! vertices onto the fused lines so every loop still closes: a vertex
//! between two actual segments goes to the intersection of their lines (if
//! that is near), otherwise it is projected onto the moved line, and both
//! neighbours share the new vertex.
//!
//! [`blur_by_pose`]: crate::map::blur_by_pose

use crate::geometry::CogLine;
use crate::geometry::{CorrespondenceConfig, SegmentId, SegmentIndex};
use crate::map::{SegmentMapConfig, fuse};

use super::loops::{ClsSegment, line_between};
use super::region::{EdgeOrigin, RegionEdge};

/// The wall lines taking part in one update: the actual segments of the
/// touched part of the map, then the scan's new lines. An
/// [`EdgeOrigin::Actual`] number indexes this table.
#[derive(Debug, Default)]
pub(crate) struct LineTable {
    lines: Vec<CogLine>,
    /// Whether the line was moved by a fusion (its segments' end points
    /// must follow).
    moved: Vec<bool>,
    index: SegmentIndex,
}

impl LineTable {
    /// Registers a line of the map; returns its number.
    pub fn add(&mut self, line: CogLine) -> u32 {
        let id = self.index.insert(line);
        self.lines.push(line);
        self.moved.push(false);
        debug_assert_eq!(id.0 as usize + 1, self.lines.len());
        id.0
    }

    pub fn line(&self, id: u32) -> Option<&CogLine> {
        self.lines.get(id as usize)
    }

    fn is_moved(&self, origin: EdgeOrigin) -> bool {
        match origin {
            EdgeOrigin::Actual(id) => self.moved.get(id as usize).copied().unwrap_or(false),
            EdgeOrigin::Virtual | EdgeOrigin::Window => false,
        }
    }

    fn actual_line(&self, origin: EdgeOrigin) -> Option<&CogLine> {
        match origin {
            EdgeOrigin::Actual(id) => self.line(id),
            EdgeOrigin::Virtual | EdgeOrigin::Window => None,
        }
    }

    /// The boundary segment for an edge of the union: a wall piece takes
    /// its line from the table, anything else is virtual.
    pub fn segment(&self, e: &RegionEdge) -> ClsSegment {
        match e.origin {
            EdgeOrigin::Actual(id) => self
                .line(id)
                .map_or(ClsSegment::virtual_between(e.start, e.end), |l| {
                    ClsSegment::actual_on(l, e.start, e.end)
                }),
            EdgeOrigin::Virtual | EdgeOrigin::Window => ClsSegment::virtual_between(e.start, e.end),
        }
    }

    /// Fuses each observed scan line (map frame, blurred) into its best
    /// corresponding map line, or adds it. Scan lines are matched only
    /// against the lines present before this call, so two pieces of one
    /// scan are never joined. Returns each scan line's number and how many
    /// were fused.
    pub fn observe(&mut self, observed: &[CogLine], cfg: &SegmentMapConfig) -> (Vec<u32>, usize) {
        let known = self.lines.len();
        let mut numbers = Vec::with_capacity(observed.len());
        let mut fresh = Vec::new();
        let mut fused_count = 0;
        for obs in observed {
            let target = self
                .index
                .best_match(obs, &cfg.fusion)
                .filter(|id| (id.0 as usize) < known);
            let fused =
                target.and_then(|id| Some((id, fuse(self.lines.get(id.0 as usize)?, obs)?)));
            match fused {
                Some((id, mut line)) => {
                    line.sigma_c = line.sigma_c.max(cfg.min_sigma_c);
                    line.sigma_theta = line.sigma_theta.max(cfg.min_sigma_theta);
                    self.set(id, line);
                    numbers.push(id.0);
                    fused_count += 1;
                }
                None => {
                    numbers.push(u32::MAX);
                    fresh.push((numbers.len() - 1, *obs));
                }
            }
        }
        for (k, line) in fresh {
            numbers[k] = self.add(line);
        }
        (numbers, fused_count)
    }

    fn set(&mut self, id: SegmentId, line: CogLine) {
        let i = id.0 as usize;
        if let (Some(slot), Some(moved)) = (self.lines.get_mut(i), self.moved.get_mut(i)) {
            *slot = line;
            *moved = true;
            self.index.update(id, line);
        }
    }

    /// Moves the vertices of a closed `contour` that touch a moved line onto
    /// it (see the module documentation). A vertex never moves farther than
    /// `max_shift` (m) through an intersection; beyond that it is projected.
    pub fn settle(&self, contour: &mut [RegionEdge], max_shift: f64) {
        let n = contour.len();
        for k in 0..n {
            let prev = (k + n - 1) % n;
            let (a, b) = (contour[prev], contour[k]);
            // Crossing points of the clipping window stay where they are.
            let pinned = a.origin == EdgeOrigin::Window || b.origin == EdgeOrigin::Window;
            if pinned || !(self.is_moved(a.origin) || self.is_moved(b.origin)) {
                continue;
            }
            let old = b.start;
            let la = self.actual_line(a.origin);
            let lb = self.actual_line(b.origin);
            let meet = match (la, lb) {
                (Some(la), Some(lb)) => {
                    intersection(la, lb).filter(|x| distance(*x, old) <= max_shift)
                }
                _ => None,
            };
            let moved = if self.is_moved(b.origin) { lb } else { la };
            let Some(new) = meet.or_else(|| moved.map(|l| l.project_point(old))) else {
                continue;
            };
            if new.iter().all(|v| v.is_finite()) {
                contour[prev].end = new;
                contour[k].start = new;
            }
        }
    }
}

impl LineTable {
    /// Gives a virtual edge of the union the origin of a wall it lies on:
    /// nearly parallel, same direction (free space on the same side), both
    /// ends within `tolerance` (m) of the wall's line, and its whole length
    /// within the extents (widened by `tolerance`) of such walls — one, or
    /// several pieces of one straight wall end to end; the edge takes the
    /// piece it overlaps most. Such an edge is a scan's frontier that noise
    /// put a few millimetres beyond the fitted wall, where the union keeps
    /// it instead of the wall; an actual segment must win over a virtual
    /// one lying on it. A gap between the pieces (a doorway on the wall's
    /// line) leaves the edge virtual. The walls are found through the
    /// spatial index, so this costs O(log n) per edge.
    pub fn recover_walls(&self, contour: &mut [RegionEdge], tolerance: f64) {
        let mut pieces: Vec<(f64, f64, u32)> = Vec::new();
        for e in contour
            .iter_mut()
            .filter(|e| e.origin == EdgeOrigin::Virtual)
        {
            let length = distance(e.start, e.end);
            if length == 0.0 {
                continue;
            }
            let u = [
                (e.end[0] - e.start[0]) / length,
                (e.end[1] - e.start[1]) / length,
            ];
            let along_edge = |p: [f64; 2]| (p[0] - e.start[0]) * u[0] + (p[1] - e.start[1]) * u[1];
            let probe = line_between(e.start, e.end);
            // Along the line the gate is as wide as the edge, so a piece
            // that covers only part of a long edge is still a candidate.
            let gates = CorrespondenceConfig {
                max_angle_diff: 0.087,
                max_centre_distance: tolerance,
                extent_tolerance: tolerance + length,
            };
            pieces.clear();
            pieces.extend(self.index.candidates(&probe, &gates).filter_map(|id| {
                let l = self.lines.get(id.0 as usize)?;
                let on_line = [e.start, e.end]
                    .iter()
                    .all(|&p| l.distance_to_point(p) <= tolerance);
                let (a, b) = (along_edge(l.start), along_edge(l.end));
                on_line.then_some((a.min(b) - tolerance, a.max(b) + tolerance, id.0))
            }));
            pieces.sort_by(|x, y| x.0.total_cmp(&y.0));
            // Swept from the edge's start: covered while the pieces overlap.
            let mut reach = 0.0;
            for &(lo, hi, _) in &pieces {
                if lo > reach {
                    break;
                }
                reach = f64::max(reach, hi);
            }
            if reach < length {
                continue;
            }
            let most = pieces
                .iter()
                .map(|&(lo, hi, id)| (hi.min(length) - lo.max(0.0), id))
                .max_by(|x, y| x.0.total_cmp(&y.0).then(y.1.cmp(&x.1)));
            if let Some((_, id)) = most {
                e.origin = EdgeOrigin::Actual(id);
            }
        }
    }
}

fn distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// Intersection of two infinite lines, `None` when they are within about
/// 10° of parallel (the point would be ill-conditioned).
fn intersection(a: &CogLine, b: &CogLine) -> Option<[f64; 2]> {
    let (da, db) = (a.direction(), b.direction());
    let den = da[0] * db[1] - da[1] * db[0];
    if den.abs() < 0.17 {
        return None;
    }
    let w = [b.xc - a.xc, b.yc - a.yc];
    let t = (w[0] * db[1] - w[1] * db[0]) / den;
    Some([a.xc + t * da[0], a.yc + t * da[1]])
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn wall(x0: f64, x1: f64, y: f64) -> CogLine {
        let c = 0.5 * (x0 + x1);
        CogLine::from_centre(0.0, [c, y], x0 - c, x1 - c, 0.003, 0.005, 30)
    }

    #[test]
    fn a_scan_line_fuses_with_its_wall_and_new_ones_are_added() {
        let cfg = SegmentMapConfig::default();
        let mut table = LineTable::default();
        let w = table.add(wall(0.0, 4.0, 0.0));
        let (numbers, fused) = table.observe(&[wall(1.0, 5.0, 0.02), wall(0.0, 2.0, 3.0)], &cfg);
        assert_eq!(fused, 1);
        assert_eq!(numbers[0], w);
        assert_eq!(numbers[1], 1);
        let l = table.line(w).unwrap();
        assert!(l.yc > 0.0 && l.yc < 0.02, "{}", l.yc);
        assert!(table.is_moved(EdgeOrigin::Actual(w)));
        assert!(!table.is_moved(EdgeOrigin::Actual(1)));
    }

    #[test]
    fn a_frontier_on_a_wall_in_pieces_is_the_wall_and_one_across_a_doorway_is_not() {
        // One straight wall held as two pieces end to end (0–4 m, 4–6 m),
        // then a doorway, then the wall again (7–9 m).
        let mut table = LineTable::default();
        let first = table.add(wall(0.0, 4.0, 0.0));
        let second = table.add(wall(4.0, 6.0, 0.0));
        table.add(wall(7.0, 9.0, 0.0));
        let virtual_edge = |x0: f64, x1: f64| RegionEdge {
            start: [x0, 0.001],
            end: [x1, 0.0015],
            origin: EdgeOrigin::Virtual,
        };
        let mut contour = [
            virtual_edge(1.0, 3.0),
            virtual_edge(2.5, 4.5),
            virtual_edge(3.5, 5.9),
            virtual_edge(5.0, 8.0),
            virtual_edge(6.2, 6.8),
        ];
        table.recover_walls(&mut contour, 0.02);
        let origins: Vec<EdgeOrigin> = contour.iter().map(|e| e.origin).collect();
        assert_eq!(
            origins,
            [
                EdgeOrigin::Actual(first),
                EdgeOrigin::Actual(first),
                EdgeOrigin::Actual(second),
                EdgeOrigin::Virtual,
                EdgeOrigin::Virtual,
            ]
        );
    }

    #[test]
    fn settling_keeps_the_loop_closed_at_the_corner() {
        let cfg = SegmentMapConfig::default();
        let mut table = LineTable::default();
        let bottom = table.add(wall(0.0, 4.0, 0.0));
        let right = table.add(CogLine::from_centre(
            std::f64::consts::FRAC_PI_2,
            [4.0, 1.5],
            -1.5,
            1.5,
            0.003,
            0.005,
            30,
        ));
        table.observe(&[wall(0.0, 4.0, 0.04)], &cfg);
        let p = [[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]];
        let origins = [
            EdgeOrigin::Actual(bottom),
            EdgeOrigin::Actual(right),
            EdgeOrigin::Virtual,
            EdgeOrigin::Virtual,
        ];
        let mut contour: Vec<RegionEdge> = (0..4)
            .map(|i| RegionEdge {
                start: p[i],
                end: p[(i + 1) % 4],
                origin: origins[i],
            })
            .collect();
        table.settle(&mut contour, 0.3);
        for i in 0..4 {
            assert_eq!(contour[i].end, contour[(i + 1) % 4].start);
        }
        let fused = table.line(bottom).unwrap();
        // The corner is where the fused bottom wall meets the right wall.
        assert!((contour[1].start[0] - 4.0).abs() < 1e-9);
        assert!(fused.distance_to_point(contour[1].start) < 1e-9);
        assert!(fused.distance_to_point(contour[0].start) < 1e-9);
    }
}
