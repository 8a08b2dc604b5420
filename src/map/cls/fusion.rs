//! The walls of one CLS update, and the repair of the loops around the
//! walls that moved.
//!
//! The CLS map does not fuse lines itself: its actual segments are pieces
//! of the walls of the wall store ([`SegmentMap`]), which fused the
//! keyframe's lines (with its bridging of pieces) before the CLS update.
//! This module gathers the walls an update touches into a [`LineTable`],
//! one entry per wall, each with the wall's current line, and moves the
//! boundary vertices onto the walls that moved so every loop still closes:
//! a vertex between two actual segments goes to the intersection of their
//! lines (if that is near), otherwise it is projected onto the moved line,
//! and both neighbours share the new vertex.

use std::collections::HashMap;

use crate::geometry::CogLine;
use crate::geometry::{CorrespondenceConfig, SegmentId};
use crate::map::SegmentMap;

use super::loops::{ClsSegment, line_between};
use super::region::{EdgeOrigin, RegionEdge};

/// The wall lines taking part in one update: the walls of the touched
/// part of the map, then the keyframe's walls. An [`EdgeOrigin::Actual`]
/// number indexes this table.
#[derive(Debug, Default)]
pub(crate) struct LineTable {
    lines: Vec<CogLine>,
    /// The wall store's id of each entry; `None` for a segment of a map
    /// saved without wall ids, which keeps its own line.
    walls: Vec<Option<SegmentId>>,
    /// Whether the line differs from where the boundary's vertices were
    /// put (they must follow).
    moved: Vec<bool>,
    /// Entry of each wall already in the table.
    entries: HashMap<SegmentId, u32>,
}

impl LineTable {
    /// Registers a line of the map; returns its number.
    fn push(&mut self, line: CogLine, wall: Option<SegmentId>, moved: bool) -> u32 {
        let k = u32::try_from(self.lines.len()).unwrap_or(u32::MAX);
        self.lines.push(line);
        self.walls.push(wall);
        self.moved.push(moved);
        if let Some(w) = wall {
            self.entries.insert(w, k);
        }
        k
    }

    /// The entry of wall `wall` of `store` (added if new), `None` if the
    /// store does not hold it (or the wall that absorbed it).
    fn wall_entry(&mut self, wall: SegmentId, store: &SegmentMap) -> Option<u32> {
        let wall = store.resolve(wall)?;
        let line = *store.wall(wall)?;
        match self.entries.get(&wall) {
            // The store's line is the truth, should it have changed since.
            Some(&k) => {
                let i = k as usize;
                if self.lines[i] != line {
                    self.lines[i] = line;
                    self.moved[i] = true;
                }
                Some(k)
            }
            None => Some(self.push(line, Some(wall), false)),
        }
    }

    /// Registers a boundary segment of the map: the entry of its wall in
    /// `store`, marked moved when the wall's line is not the one the
    /// segment was settled on. A segment naming no wall the store holds
    /// (a map saved before pieces named their walls) takes the wall its
    /// line corresponds to best, under the fusion gates; one with none
    /// keeps its own line. Returns its number.
    pub fn add_segment(&mut self, segment: &ClsSegment, store: &SegmentMap) -> u32 {
        let entry = segment
            .wall
            .and_then(|w| self.wall_entry(w, store))
            .or_else(|| {
                let w = store
                    .index()
                    .best_match(&segment.line, &store.config().fusion)?;
                self.wall_entry(w, store)
            });
        match entry {
            Some(k) => {
                let i = k as usize;
                let l = &self.lines[i];
                let s = &segment.line;
                if (l.theta, l.xc, l.yc) != (s.theta, s.xc, s.yc) {
                    self.moved[i] = true;
                }
                k
            }
            None => self.push(segment.line, None, false),
        }
    }

    /// Registers the walls `walls` (ids in `store`) the keyframe's lines
    /// went into, all marked moved; returns each one's number (`None`
    /// where the store does not hold it) and how many were in the table
    /// already (lines fused into a boundary wall).
    pub fn add_keyframe_walls(
        &mut self,
        walls: &[SegmentId],
        store: &SegmentMap,
    ) -> (Vec<Option<u32>>, usize) {
        let mut fused = 0;
        let numbers = walls
            .iter()
            .map(|&w| {
                let first_new = self.lines.len();
                let k = self.wall_entry(w, store)?;
                fused += usize::from((k as usize) < first_new);
                self.moved[k as usize] = true;
                Some(k)
            })
            .collect();
        (numbers, fused)
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
    /// its line and wall from the table, anything else is virtual.
    pub fn segment(&self, e: &RegionEdge) -> ClsSegment {
        match e.origin {
            EdgeOrigin::Actual(id) => {
                self.line(id)
                    .map_or(ClsSegment::virtual_between(e.start, e.end), |l| {
                        let wall = self.walls.get(id as usize).copied().flatten();
                        ClsSegment::actual_on(l, wall, e.start, e.end)
                    })
            }
            EdgeOrigin::Virtual | EdgeOrigin::Window => ClsSegment::virtual_between(e.start, e.end),
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
    /// line) leaves the edge virtual. The walls are those of `store`,
    /// found through its spatial index, so this costs O(log n) per edge.
    pub fn recover_walls(
        &mut self,
        contour: &mut [RegionEdge],
        tolerance: f64,
        store: &SegmentMap,
    ) {
        let mut pieces: Vec<(f64, f64, SegmentId)> = Vec::new();
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
            pieces.extend(store.index().candidates(&probe, &gates).filter_map(|id| {
                let l = store.wall(id)?;
                let on_line = [e.start, e.end]
                    .iter()
                    .all(|&p| l.distance_to_point(p) <= tolerance);
                let (a, b) = (along_edge(l.start), along_edge(l.end));
                on_line.then_some((a.min(b) - tolerance, a.max(b) + tolerance, id))
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
            if let Some(k) = most.and_then(|(_, id)| self.wall_entry(id, store)) {
                e.origin = EdgeOrigin::Actual(k);
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
    use crate::geometry::Pose2;

    const NO_COV: [[f64; 3]; 3] = [[0.0; 3]; 3];

    fn wall(x0: f64, x1: f64, y: f64) -> CogLine {
        let c = 0.5 * (x0 + x1);
        CogLine::from_centre(0.0, [c, y], x0 - c, x1 - c, 0.003, 0.005, 30)
    }

    /// The boundary piece of `line` from `x0` to `x1`, on wall `id`.
    fn piece(line: &CogLine, id: Option<SegmentId>, x0: f64, x1: f64) -> ClsSegment {
        let at = |x: f64| line.project_point([x, line.yc]);
        ClsSegment::actual_on(line, id, at(x0), at(x1))
    }

    #[test]
    fn a_wall_is_one_entry_and_the_keyframe_walls_take_the_store_lines() {
        let mut store = SegmentMap::default();
        let bottom = store.update(&[wall(0.0, 4.0, 0.0)], &Pose2::IDENTITY, &NO_COV);
        let b = bottom.walls[0];
        let line = *store.wall(b).unwrap();
        let mut table = LineTable::default();
        // Two pieces of one wall (a door between) share its entry.
        let first = table.add_segment(&piece(&line, Some(b), 0.0, 1.0), &store);
        let second = table.add_segment(&piece(&line, Some(b), 2.0, 4.0), &store);
        assert_eq!(first, second);
        assert!(!table.is_moved(EdgeOrigin::Actual(first)));
        // A piece without a wall takes the wall it lies on, or keeps its
        // own line where the store has none.
        let adopted = table.add_segment(&piece(&wall(0.5, 1.5, 0.01), None, 0.5, 1.5), &store);
        assert_eq!(adopted, first);
        let own = table.add_segment(&piece(&wall(0.0, 1.0, 3.0), None, 0.0, 1.0), &store);
        assert_ne!(own, first);

        let seen = store.update(
            &[wall(1.0, 5.0, 0.02), wall(0.0, 2.0, 5.0)],
            &Pose2::IDENTITY,
            &NO_COV,
        );
        let (numbers, fused) = table.add_keyframe_walls(&seen.walls, &store);
        assert_eq!(fused, 1);
        assert_eq!(numbers[0], Some(first));
        assert!(numbers[1].is_some_and(|n| n != first && n != own));
        // The entry is the store's fused wall, and it moved.
        assert_eq!(table.line(first), store.wall(b));
        assert!(table.line(first).unwrap().yc > 0.0);
        assert!(table.is_moved(EdgeOrigin::Actual(first)));
        let s = table.segment(&RegionEdge {
            start: [0.5, 0.01],
            end: [1.5, 0.01],
            origin: EdgeOrigin::Actual(first),
        });
        assert_eq!(s.wall, Some(b));
    }

    #[test]
    fn a_piece_of_a_wall_bridged_into_another_takes_that_wall() {
        let mut store = SegmentMap::default();
        let ids = store
            .update(
                &[wall(0.0, 2.0, 3.0), wall(2.05, 5.0, 3.0)],
                &Pose2::IDENTITY,
                &NO_COV,
            )
            .walls;
        let right = *store.wall(ids[1]).unwrap();
        // A later view across the seam joins the two pieces.
        let joined = store
            .update(&[wall(1.5, 3.2, 3.0)], &Pose2::IDENTITY, &NO_COV)
            .walls[0];
        assert_eq!(store.len(), 1);
        let mut table = LineTable::default();
        let k = table.add_segment(&piece(&right, Some(ids[1]), 3.0, 5.0), &store);
        assert_eq!(table.line(k), store.wall(joined));
        assert!(table.is_moved(EdgeOrigin::Actual(k)));
    }

    #[test]
    fn a_frontier_on_a_wall_in_pieces_is_the_wall_and_one_across_a_doorway_is_not() {
        // One straight wall held as two walls end to end (0–4 m, 4–6 m),
        // then a doorway, then the wall again (7–9 m).
        let mut store = SegmentMap::default();
        store.insert_walls(&[
            wall(0.0, 4.0, 0.0),
            wall(4.0, 6.0, 0.0),
            wall(7.0, 9.0, 0.0),
        ]);
        let mut table = LineTable::default();
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
        table.recover_walls(&mut contour, 0.02, &store);
        let walls: Vec<Option<SegmentId>> = contour
            .iter()
            .map(|e| match e.origin {
                EdgeOrigin::Actual(_) => table.segment(e).wall,
                _ => None,
            })
            .collect();
        let (first, second) = (Some(SegmentId(0)), Some(SegmentId(1)));
        assert_eq!(walls, [first, first, second, None, None]);
        // Both edges on the first wall share its entry.
        assert_eq!(contour[0].origin, contour[1].origin);
    }

    #[test]
    fn settling_keeps_the_loop_closed_at_the_corner() {
        let mut store = SegmentMap::default();
        let right_line = CogLine::from_centre(
            std::f64::consts::FRAC_PI_2,
            [4.0, 1.5],
            -1.5,
            1.5,
            0.003,
            0.005,
            30,
        );
        let ids = store
            .update(
                &[wall(0.0, 4.0, 0.0), right_line],
                &Pose2::IDENTITY,
                &NO_COV,
            )
            .walls;
        let mut table = LineTable::default();
        let p = [[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]];
        let bottom = table.add_segment(
            &ClsSegment::actual_on(store.wall(ids[0]).unwrap(), Some(ids[0]), p[0], p[1]),
            &store,
        );
        let right = table.add_segment(
            &ClsSegment::actual_on(store.wall(ids[1]).unwrap(), Some(ids[1]), p[1], p[2]),
            &store,
        );
        let seen = store.update(&[wall(0.0, 4.0, 0.04)], &Pose2::IDENTITY, &NO_COV);
        table.add_keyframe_walls(&seen.walls, &store);
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
        assert!(fused.yc > 0.0, "{fused:?}");
        // The corner is where the fused bottom wall meets the right wall.
        assert!((contour[1].start[0] - 4.0).abs() < 1e-9);
        assert!(fused.distance_to_point(contour[1].start) < 1e-9);
        assert!(fused.distance_to_point(contour[0].start) < 1e-9);
    }
}
