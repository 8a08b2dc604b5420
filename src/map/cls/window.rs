//! Keeping the union local: long loops of the map are clipped to a window
//! around the scan's region, only the clipped part goes through the
//! overlay, and the result is spliced back into the untouched rest.
//!
//! The window `W` is an axis-aligned rectangle on the snapping grid,
//! around the local region with a margin, its sides moved outwards until
//! no vertex of the clipped loops lies on one of them (so every crossing of
//! a loop with `∂W` is a proper crossing inside an edge). For each clipped
//! loop the parts inside `W` (chains, from an entry point on `∂W` to an exit
//! point) are kept, the parts outside (runs, from an exit to the next
//! entry) are set aside unchanged. Inside `W` the region is closed along
//! `∂W`: from each exit point counter-clockwise along `∂W` to the next
//! crossing, which for a boundary with free space on its left is always an
//! entry. These window edges carry [`EdgeOrigin::Window`].
//!
//! The local region lies strictly inside `W`, so the union cannot change
//! anything on `∂W`: each window edge of the result still runs between
//! crossing points, and the result's other edges form runs from entry to
//! exit points. The new loops are these runs joined to the set-aside
//! outside runs at the crossing points. Any inconsistency (an unmatched
//! crossing, a crossing on a corner, a long loop that does not cross `∂W`)
//! makes the caller fall back to the union of the whole loops.

use std::collections::BTreeMap;

use crate::geometry::CogLine;
use crate::geometry::{CorrespondenceConfig, lines_correspond};
use crate::map::SegmentMap;

use super::fusion::LineTable;
use super::loops::{ClsLoop, ClsSegment, SegmentMode};
use super::region::{EdgeOrigin, RegionEdge, RegionError, snap};

/// A window on the grid (grid units), with the set-aside outside runs.
#[derive(Debug)]
pub(crate) struct Window {
    x0: i64,
    y0: i64,
    x1: i64,
    y1: i64,
    grid: f64,
    /// Outside runs keyed by their first point (an exit point).
    outside: BTreeMap<[i64; 2], Vec<ClsSegment>>,
}

/// A point where a loop crosses `∂W`.
#[derive(Debug, Clone, Copy)]
struct Crossing {
    point: [i64; 2],
    entry: bool,
}

fn to_grid(p: [f64; 2], grid: f64) -> Result<[i64; 2], RegionError> {
    Ok([i64::from(snap(p[0], grid)?), i64::from(snap(p[1], grid)?)])
}

impl Window {
    /// A window around `lo..hi` (m) on the grid, its sides clear of every
    /// vertex of `loops`.
    pub fn around(
        lo: [f64; 2],
        hi: [f64; 2],
        loops: &[&ClsLoop],
        grid: f64,
    ) -> Result<Window, RegionError> {
        let lo = to_grid(lo, grid)?;
        let hi = to_grid(hi, grid)?;
        let mut w = Window {
            x0: lo[0] - 1,
            y0: lo[1] - 1,
            x1: hi[0] + 1,
            y1: hi[1] + 1,
            grid,
            outside: BTreeMap::new(),
        };
        // Rarely more than one pass: each moves a side by one grid unit.
        loop {
            let mut moved = false;
            for lp in loops {
                for seg in lp.segments() {
                    let p = to_grid(seg.start(), grid)?;
                    for (side, coord, step) in [
                        (&mut w.x0, p[0], -1),
                        (&mut w.x1, p[0], 1),
                        (&mut w.y0, p[1], -1),
                        (&mut w.y1, p[1], 1),
                    ] {
                        if *side == coord {
                            *side += step;
                            moved = true;
                        }
                    }
                }
            }
            if !moved {
                break;
            }
        }
        Ok(w)
    }

    fn inside(&self, p: [i64; 2]) -> bool {
        p[0] > self.x0 && p[0] < self.x1 && p[1] > self.y0 && p[1] < self.y1
    }

    fn to_m(&self, p: [i64; 2]) -> [f64; 2] {
        [p[0] as f64 * self.grid, p[1] as f64 * self.grid]
    }

    /// Position along `∂W` counter-clockwise from the lower-left corner.
    fn perimeter(&self, p: [i64; 2]) -> i64 {
        let (w, h) = (self.x1 - self.x0, self.y1 - self.y0);
        if p[1] == self.y0 {
            p[0] - self.x0
        } else if p[0] == self.x1 {
            w + p[1] - self.y0
        } else if p[1] == self.y1 {
            w + h + self.x1 - p[0]
        } else {
            2 * w + h + self.y1 - p[1]
        }
    }

    /// The crossings of the edge `p → q` with `∂W`, in order along it, or
    /// `None` if one falls on a corner.
    fn crossings(&self, p: [i64; 2], q: [i64; 2]) -> Option<Vec<Crossing>> {
        // Most edges of a long loop lie wholly beyond one side.
        let beyond = (p[0] < self.x0 && q[0] < self.x0)
            || (p[0] > self.x1 && q[0] > self.x1)
            || (p[1] < self.y0 && q[1] < self.y0)
            || (p[1] > self.y1 && q[1] > self.y1);
        if beyond || (self.inside(p) && self.inside(q)) {
            return Some(Vec::new());
        }
        let d = [(q[0] - p[0]) as f64, (q[1] - p[1]) as f64];
        let mut hits: Vec<(f64, [i64; 2])> = Vec::new();
        for (axis, side) in [(0, self.x0), (0, self.x1), (1, self.y0), (1, self.y1)] {
            let (a, b) = (p[axis], q[axis]);
            if (a < side) == (b < side) {
                continue;
            }
            let t = (side - a) as f64 / d[axis];
            let other = 1 - axis;
            let v = (p[other] as f64 + t * d[other]).round() as i64;
            let (lo, hi) = if other == 0 {
                (self.x0, self.x1)
            } else {
                (self.y0, self.y1)
            };
            if v < lo || v > hi {
                continue;
            }
            if v == lo || v == hi {
                return None;
            }
            let point = if axis == 0 { [side, v] } else { [v, side] };
            hits.push((t, point));
        }
        hits.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut inside = self.inside(p);
        Some(
            hits.into_iter()
                .map(|(_, point)| {
                    inside = !inside;
                    Crossing {
                        point,
                        entry: inside,
                    }
                })
                .collect(),
        )
    }

    /// Clips `loops` (each crossing `∂W`) to the window: returns the
    /// contours of region ∩ W for the overlay (walls registered in
    /// `table`) and keeps the outside runs for [`Window::splice`]. `None`
    /// if a loop does not cross `∂W` or a crossing is degenerate.
    pub fn clip(
        &mut self,
        loops: &[&ClsLoop],
        table: &mut LineTable,
        store: &SegmentMap,
    ) -> Option<Vec<Vec<RegionEdge>>> {
        // Chains keyed by their entry point; all crossings for the arcs.
        let mut chains: BTreeMap<[i64; 2], Vec<RegionEdge>> = BTreeMap::new();
        let mut crossings: Vec<Crossing> = Vec::new();
        for lp in loops {
            self.clip_loop(lp, table, store, &mut chains, &mut crossings)?;
        }
        // Arcs of ∂W from each exit counter-clockwise to the next crossing.
        let mut arcs: BTreeMap<[i64; 2], Vec<RegionEdge>> = BTreeMap::new();
        crossings.sort_by_key(|c| self.perimeter(c.point));
        let m = crossings.len();
        for (j, c) in crossings.iter().enumerate() {
            if c.entry {
                continue;
            }
            let next = crossings[(j + 1) % m];
            if !next.entry {
                return None;
            }
            arcs.insert(c.point, self.arc(c.point, next.point));
        }
        // Closed contours: chain, arc, chain, ...
        let mut contours = Vec::new();
        while let Some((start, chain)) = chains.pop_first() {
            let mut contour = chain;
            loop {
                let exit = to_grid(contour.last()?.end, self.grid).ok()?;
                let arc = arcs.remove(&exit)?;
                let entry = to_grid(arc.last()?.end, self.grid).ok()?;
                contour.extend(arc);
                if entry == start {
                    break;
                }
                contour.extend(chains.remove(&entry)?);
            }
            contours.push(contour);
        }
        arcs.is_empty().then_some(contours)
    }

    /// Splits one loop at its crossings into chains (inside, for the
    /// overlay) and runs (outside, kept in `self.outside`).
    fn clip_loop(
        &mut self,
        lp: &ClsLoop,
        table: &mut LineTable,
        store: &SegmentMap,
        chains: &mut BTreeMap<[i64; 2], Vec<RegionEdge>>,
        crossings: &mut Vec<Crossing>,
    ) -> Option<()> {
        let segs = lp.segments();
        let n = segs.len();
        let points: Vec<[i64; 2]> = segs
            .iter()
            .map(|s| to_grid(s.start(), self.grid).ok())
            .collect::<Option<_>>()?;
        // Events along the loop: each edge's crossings in order.
        let mut per_edge = Vec::with_capacity(n);
        for i in 0..n {
            per_edge.push(self.crossings(points[i], points[(i + 1) % n])?);
        }
        // Start on the last crossing of an edge that ends outside: an exit.
        let first = (0..n).find(|&i| per_edge[i].last().is_some_and(|c| !c.entry))?;
        let exit = *per_edge[first].last()?;
        let mut from = self.to_m(exit.point);
        let mut run_start = exit.point;
        let mut run: Vec<ClsSegment> = Vec::new();
        let mut chain: Option<([i64; 2], Vec<RegionEdge>)> = None;
        let mut wall: Option<(usize, EdgeOrigin)> = None;
        let mut origin_of = |i: usize, table: &mut LineTable| -> EdgeOrigin {
            let s = &segs[i];
            match s.mode {
                SegmentMode::Virtual => EdgeOrigin::Virtual,
                SegmentMode::Actual => match wall {
                    Some((k, o)) if k == i => o,
                    _ => {
                        let o = EdgeOrigin::Actual(table.add_segment(s, store));
                        wall = Some((i, o));
                        o
                    }
                },
            }
        };
        // Events after the starting exit: each vertex (ending the previous
        // edge's piece) followed by its edge's crossings, around to edge
        // `first`, whose last crossing is the starting exit again.
        let mut events: Vec<(usize, Option<Crossing>)> = Vec::with_capacity(2 * n + 2);
        for k in 1..=n {
            let i = (first + k) % n;
            events.push((i, None));
            events.extend(per_edge[i].iter().map(|c| (i, Some(*c))));
        }
        let mut current = first;
        for (i, event) in events {
            let (to, crossing) = match event {
                None => (self.to_m(points[i]), None),
                Some(c) => (self.to_m(c.point), Some(c)),
            };
            let edge = current;
            if from != to {
                match chain.as_mut() {
                    Some((_, ch)) => ch.push(RegionEdge {
                        start: from,
                        end: to,
                        origin: origin_of(edge, table),
                    }),
                    None => run.push(piece(&segs[edge], from, to)),
                }
            }
            match crossing {
                Some(c) if c.entry => {
                    self.outside.insert(run_start, std::mem::take(&mut run));
                    chain = Some((c.point, Vec::new()));
                    crossings.push(c);
                }
                Some(c) => {
                    let (start, ch) = chain.take()?;
                    chains.insert(start, ch);
                    run_start = c.point;
                    crossings.push(c);
                }
                None => current = i,
            }
            from = to;
        }
        // The walk ends on the starting exit with its chain closed.
        (chain.is_none() && run.is_empty()).then_some(())
    }

    /// Window edges from `from` counter-clockwise along `∂W` to `to`.
    fn arc(&self, from: [i64; 2], to: [i64; 2]) -> Vec<RegionEdge> {
        let (w, h) = (self.x1 - self.x0, self.y1 - self.y0);
        let total = 2 * (w + h);
        let corners = [
            (0, [self.x0, self.y0]),
            (w, [self.x1, self.y0]),
            (w + h, [self.x1, self.y1]),
            (2 * w + h, [self.x0, self.y1]),
        ];
        let s0 = self.perimeter(from);
        let mut s1 = self.perimeter(to);
        if s1 <= s0 {
            s1 += total;
        }
        let mut pts = vec![from];
        let mut between: Vec<(i64, [i64; 2])> = corners
            .iter()
            .flat_map(|&(s, p)| [(s, p), (s + total, p)])
            .filter(|&(s, _)| s > s0 && s < s1)
            .collect();
        between.sort_by_key(|&(s, _)| s);
        pts.extend(between.into_iter().map(|(_, p)| p));
        pts.push(to);
        pts.windows(2)
            .map(|w| RegionEdge {
                start: self.to_m(w[0]),
                end: self.to_m(w[1]),
                origin: EdgeOrigin::Window,
            })
            .collect()
    }

    /// Whether every vertex of `contours` lies in the closed window; the
    /// splice is only valid then (fusion may have moved a vertex out).
    pub fn holds(&self, contours: &[Vec<Vec<RegionEdge>>]) -> bool {
        let (lo, hi) = (self.to_m([self.x0, self.y0]), self.to_m([self.x1, self.y1]));
        contours.iter().flatten().flatten().all(|e| {
            e.start[0] >= lo[0] && e.start[0] <= hi[0] && e.start[1] >= lo[1] && e.start[1] <= hi[1]
        })
    }

    /// The new loops: the overlay's `result` (from the clipped contours,
    /// cleaned) joined to the outside runs at the crossing points, each
    /// junction merged where the two pieces are one segment again. `None`
    /// if the pieces do not match up.
    pub fn splice(
        mut self,
        result: &[Vec<Vec<RegionEdge>>],
        table: &LineTable,
        sliver_width: f64,
        gates: &CorrespondenceConfig,
    ) -> Option<Vec<ClsLoop>> {
        let mut loops = Vec::new();
        let mut inside: BTreeMap<[i64; 2], Vec<ClsSegment>> = BTreeMap::new();
        for contour in result.iter().flatten() {
            let is_window = |e: &RegionEdge| e.origin == EdgeOrigin::Window;
            let Some(k) = (0..contour.len())
                .find(|&k| is_window(&contour[k]) && !is_window(&contour[(k + 1) % contour.len()]))
            else {
                if contour.iter().any(is_window) {
                    return None;
                }
                loops.push(ClsLoop::new(
                    contour.iter().map(|e| table.segment(e)).collect(),
                ));
                continue;
            };
            let n = contour.len();
            let mut run: Vec<ClsSegment> = Vec::new();
            for j in 1..=n {
                let e = &contour[(k + j) % n];
                if is_window(e) {
                    if let (Some(first), false) = (run.first(), run.is_empty()) {
                        let key = to_grid(first.start(), self.grid).ok()?;
                        inside.insert(key, std::mem::take(&mut run));
                    }
                } else {
                    run.push(table.segment(e));
                }
            }
        }
        while let Some((start, run)) = inside.pop_first() {
            let mut segments = run;
            let mut junctions = Vec::new();
            loop {
                let exit = to_grid(segments.last()?.end(), self.grid).ok()?;
                let outside = self.outside.remove(&exit)?;
                let entry = to_grid(outside.last()?.end(), self.grid).ok()?;
                junctions.push(segments.len());
                segments.extend(outside);
                junctions.push(segments.len());
                if entry == start {
                    break;
                }
                segments.extend(inside.remove(&entry)?);
            }
            loops.push(ClsLoop::new(merge_junctions(
                segments,
                &junctions,
                self.grid,
                sliver_width,
                gates,
            )));
        }
        self.outside.is_empty().then_some(loops)
    }
}

/// `s` cut to run from `from` to `to` (both on it).
fn piece(s: &ClsSegment, from: [f64; 2], to: [f64; 2]) -> ClsSegment {
    ClsSegment {
        line: CogLine {
            start: from,
            end: to,
            wall_ends: crate::geometry::WallEnds::NONE,
            ..s.line
        },
        mode: s.mode,
        wall: s.wall,
    }
}

/// Joins the two segments meeting at each junction (an index into
/// `segments`, cyclic) when they are one straight segment cut at the
/// window: same mode and the junction within `tolerance` (m) of the chord
/// for virtual pieces; for wall pieces, corresponding lines and the
/// junction within `wall_tolerance`. The joined segment keeps the line
/// fitted to more points.
fn merge_junctions(
    mut segments: Vec<ClsSegment>,
    junctions: &[usize],
    tolerance: f64,
    wall_tolerance: f64,
    gates: &CorrespondenceConfig,
) -> Vec<ClsSegment> {
    let n = segments.len();
    // Indices already joined (as either side); a handful, so a short list.
    let mut used: Vec<usize> = Vec::with_capacity(2 * junctions.len());
    let mut gone: Vec<usize> = Vec::with_capacity(junctions.len());
    for &j in junctions {
        let (b_idx, a_idx) = (j % n, (j + n - 1) % n);
        if a_idx == b_idx || used.contains(&a_idx) || used.contains(&b_idx) {
            continue;
        }
        let (a, b) = (&segments[a_idx], &segments[b_idx]);
        if a.mode != b.mode {
            continue;
        }
        let (p, q) = (a.start(), b.end());
        let c = [q[0] - p[0], q[1] - p[1]];
        let len = c[0].hypot(c[1]);
        let v = a.end();
        let off = ((v[0] - p[0]) * c[1] - (v[1] - p[1]) * c[0]).abs() / len.max(f64::MIN_POSITIVE);
        let dot = (v[0] - p[0]) * c[0] + (v[1] - p[1]) * c[1];
        // Pieces of one wall: their lines correspond (the inside piece may
        // have been fused) and the junction is within the sliver width.
        let same = match a.mode {
            SegmentMode::Actual => {
                lines_correspond(&a.line, &b.line, gates) && off <= wall_tolerance
            }
            SegmentMode::Virtual => off <= tolerance,
        };
        if len == 0.0 || !same || dot <= 0.0 || dot >= len * len {
            continue;
        }
        let kept = if b.line.n_points > a.line.n_points {
            b
        } else {
            a
        };
        let (line, wall) = (kept.line, kept.wall);
        segments[a_idx] = match a.mode {
            SegmentMode::Actual => ClsSegment::actual_on(&line, wall, p, q),
            SegmentMode::Virtual => ClsSegment::virtual_between(p, q),
        };
        used.extend([a_idx, b_idx]);
        gone.push(b_idx);
    }
    if !gone.is_empty() {
        let mut k = 0;
        segments.retain(|_| {
            let keep = !gone.contains(&k);
            k += 1;
            keep
        });
    }
    segments
}
