//! Region expansion: the union of the local region with the touched part of
//! the global region, by i_overlay, keeping each boundary edge's origin.
//!
//! Coordinates are snapped to a fixed grid (default 1 mm) and handed to
//! i_overlay's integer engine, which is exact on that grid: touching,
//! collinear and almost-parallel edges are resolved without panics or
//! hairline gaps. Each input edge carries its origin ([`EdgeOrigin`]) as
//! i_overlay edge data; where the engine splits an edge the pieces keep it,
//! and where two coincident edges merge [`EdgeOrigin::merge`] decides: an
//! actual piece always wins over a virtual one lying on it. This tracks
//! origins exactly through the overlay, which is sturdier than matching the
//! result's edges back to the inputs within a tolerance afterwards.
//!
//! After the union, edges shorter than [`RegionConfig::min_edge`] are
//! collapsed, spikes narrower than [`RegionConfig::sliver_width`] are cut,
//! nearly collinear runs of one origin are merged and contours smaller
//! than [`RegionConfig::min_loop_area`] are dropped; if that cleaning would
//! break an invariant the raw (valid) overlay output is kept instead.

use i_overlay::core::edge_data::{EdgeDataMerge, OverlayEdgeData};
use i_overlay::core::edge_overlay::{EdgeOverlay, InputEdge};
use i_overlay::core::fill_rule::FillRule;
use i_overlay::core::overlay::ShapeType;
use i_overlay::core::overlay_rule::OverlayRule;
use i_overlay::i_float::int::point::IntPoint;
use i_overlay::segm::boolean::ShapeCountBoolean;

use super::loops::{ClsLoop, ClsSegment, ClsShape, InvariantError, check_loops};

/// Tolerances of the union; metres.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RegionConfig {
    /// Snapping grid (m). Default 0.001: far below the laser's noise, and
    /// with i32 coordinates it leaves ±1000 km of map.
    pub grid: f64,
    /// Edges shorter than this are collapsed into their neighbours (m).
    /// Default 0.005.
    pub min_edge: f64,
    /// Loops enclosing less than this are dropped as slivers (m²).
    /// Default 1e-4 (1 cm²): a 4 cm chair leg (16 cm²) stays.
    pub min_loop_area: f64,
    /// Spikes narrower than this are cut off (m): where scans overlap, the
    /// union zigzags between their nearly coincident boundaries. Default
    /// 0.02, a few times the range noise. A vertex between edges of one
    /// origin within a tenth of this of their chord is dropped too.
    pub sliver_width: f64,
}

impl Default for RegionConfig {
    fn default() -> Self {
        RegionConfig {
            grid: 0.001,
            min_edge: 0.005,
            min_loop_area: 1e-4,
            sliver_width: 0.02,
        }
    }
}

/// Largest map coordinate accepted (m); keeps snapped values well inside
/// i_overlay's i32 range (±2^30 grid units).
pub const MAX_COORDINATE: f64 = 1.0e5;

/// Where a boundary edge comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EdgeOrigin {
    /// A frontier.
    Virtual,
    /// A piece of wall line number `.0` in the caller's line table.
    Actual(u32),
    /// A side of the clipping window around the scan (see
    /// module `window`); never part of the map's boundary.
    Window,
}

impl EdgeOrigin {
    /// The origin of two coincident edges merged into one: actual beats
    /// virtual; of two walls the lower (older) line number is kept.
    /// A window side never coincides with a map edge (the window is
    /// placed so); if it did, the map edge wins.
    pub fn merge(a: EdgeOrigin, b: EdgeOrigin) -> EdgeOrigin {
        match (a, b) {
            (EdgeOrigin::Actual(x), EdgeOrigin::Actual(y)) => EdgeOrigin::Actual(x.min(y)),
            (EdgeOrigin::Actual(x), _) | (_, EdgeOrigin::Actual(x)) => EdgeOrigin::Actual(x),
            (EdgeOrigin::Window, EdgeOrigin::Window) => EdgeOrigin::Window,
            _ => EdgeOrigin::Virtual,
        }
    }
}

impl OverlayEdgeData for EdgeOrigin {
    type Store = ();

    fn merge(ctx: EdgeDataMerge<ShapeCountBoolean, Self>, _store: &mut ()) -> Self {
        EdgeOrigin::merge(ctx.lhs_data, ctx.rhs_data)
    }
}

/// A boundary edge in the map frame (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegionEdge {
    pub start: [f64; 2],
    pub end: [f64; 2],
    pub origin: EdgeOrigin,
}

/// A shape of the union: its outer contour (counter-clockwise) first, then
/// its holes (clockwise); each contour a closed chain of edges.
pub type RegionShape = Vec<Vec<RegionEdge>>;

/// Why a union could not be formed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RegionError {
    #[error("coordinate {0} m is not finite or beyond ±{MAX_COORDINATE} m")]
    Coordinate(f64),
    #[error("the snapping grid {0} m is not a positive finite number")]
    Grid(f64),
}

/// `v` (m) in grid units, checked against the coordinate limits.
pub(crate) fn snap(v: f64, grid: f64) -> Result<i32, RegionError> {
    if !(v.is_finite() && v.abs() <= MAX_COORDINATE) {
        return Err(RegionError::Coordinate(v));
    }
    let q = (v / grid).round();
    // |q| ≤ 1e5 / grid; with grid ≥ 1e-4 m this is within ±2^30.
    if q.abs() > f64::from(1i32 << 30) {
        return Err(RegionError::Coordinate(v));
    }
    Ok(q as i32)
}

/// The union (non-zero fill) of all `subject` contours and the `clip`
/// contours, with origins kept and slivers removed. Contours must be
/// closed; outer contours counter-clockwise and holes clockwise.
pub fn union<'a>(
    subject: impl IntoIterator<Item = &'a [RegionEdge]>,
    clip: impl IntoIterator<Item = &'a [RegionEdge]>,
    cfg: &RegionConfig,
) -> Result<Vec<RegionShape>, RegionError> {
    let grid = cfg.grid;
    if !(grid.is_finite() && grid >= 1e-4) {
        return Err(RegionError::Grid(grid));
    }
    let mut overlay = EdgeOverlay::<i32, EdgeOrigin>::new(64);
    overlay.options.preserve_output_collinear = false;
    // The engine measures area in grid units (doubled); a little under the
    // sliver limit, the cleaning below applies the exact one.
    overlay.options.min_output_area = (cfg.min_loop_area.max(0.0) / (grid * grid)) as u64;
    for (contours, kind) in [
        (subject.into_iter().collect::<Vec<_>>(), ShapeType::Subject),
        (clip.into_iter().collect::<Vec<_>>(), ShapeType::Clip),
    ] {
        for contour in contours {
            for e in contour {
                let a = IntPoint::new(snap(e.start[0], grid)?, snap(e.start[1], grid)?);
                let b = IntPoint::new(snap(e.end[0], grid)?, snap(e.end[1], grid)?);
                overlay.add_edge(
                    InputEdge {
                        a,
                        b,
                        data: e.origin,
                    },
                    kind,
                );
            }
        }
    }
    let shapes = overlay.build_vector_shapes(OverlayRule::Union, FillRule::NonZero);
    let to_m = |p: IntPoint<i32>| [f64::from(p.x) * grid, f64::from(p.y) * grid];
    let raw: Vec<RegionShape> = shapes
        .into_iter()
        .map(|shape| {
            shape
                .into_iter()
                .map(|contour| {
                    contour
                        .into_iter()
                        .map(|e| RegionEdge {
                            start: to_m(e.a),
                            end: to_m(e.b),
                            origin: e.data,
                        })
                        .collect()
                })
                .collect()
        })
        .collect();
    Ok(raw)
}

/// The loop invariants ([`check_loops`]) of the union's shapes, on their
/// geometry alone.
pub fn check_shapes(shapes: &[RegionShape]) -> Result<(), InvariantError> {
    let cls: Vec<ClsShape> = shapes
        .iter()
        .filter_map(|shape| {
            let mut loops = shape.iter().map(|c| {
                ClsLoop::new(
                    c.iter()
                        .map(|e| ClsSegment::virtual_between(e.start, e.end))
                        .collect(),
                )
            });
            Some(ClsShape {
                outer: loops.next()?,
                holes: loops.collect(),
            })
        })
        .collect();
    check_loops(&cls)
}

/// The union's `raw` shapes cleaned ([`clean`]) where that keeps them
/// valid: all at once if possible, else shape by shape, keeping the raw
/// form of any shape whose cleaning would break an invariant (moving a
/// vertex can make a pinched loop cross itself). Fails only if the raw
/// shapes are invalid themselves.
pub fn clean_checked(
    raw: &[RegionShape],
    cfg: &RegionConfig,
) -> Result<Vec<RegionShape>, InvariantError> {
    let cleaned = clean(raw, cfg);
    if check_shapes(&cleaned).is_ok() {
        return Ok(cleaned);
    }
    let mut mixed = Vec::with_capacity(raw.len());
    for shape in raw {
        let one = clean(std::slice::from_ref(shape), cfg);
        if check_shapes(&one).is_ok() {
            mixed.extend(one);
        } else {
            mixed.push(shape.clone());
        }
    }
    if check_shapes(&mixed).is_ok() {
        return Ok(mixed);
    }
    check_shapes(raw)?;
    Ok(raw.to_vec())
}

/// Signed area (m²) of a closed contour.
pub fn contour_area(contour: &[RegionEdge]) -> f64 {
    0.5 * contour
        .iter()
        .map(|e| e.start[0] * e.end[1] - e.end[0] * e.start[1])
        .sum::<f64>()
}

/// `shapes` with short edges collapsed, collinear runs of one origin
/// merged and sliver contours (or shapes whose outer contour is one)
/// dropped. The result may need checking: collapsing moves vertices.
pub fn clean(shapes: &[RegionShape], cfg: &RegionConfig) -> Vec<RegionShape> {
    shapes
        .iter()
        .filter_map(|shape| {
            let mut contours = shape.iter().map(|c| clean_contour(c, cfg));
            let outer = contours.next()??;
            if contour_area(&outer) < cfg.min_loop_area {
                return None;
            }
            let mut out = vec![outer];
            out.extend(
                contours
                    .flatten()
                    .filter(|c| contour_area(c) <= -cfg.min_loop_area),
            );
            Some(out)
        })
        .collect()
}

fn clean_contour(contour: &[RegionEdge], cfg: &RegionConfig) -> Option<Vec<RegionEdge>> {
    let mut c: Vec<RegionEdge> = contour
        .iter()
        .copied()
        .filter(|e| e.start != e.end)
        .collect();
    let length = |e: &RegionEdge| (e.end[0] - e.start[0]).hypot(e.end[1] - e.start[1]);
    loop {
        if c.len() < 3 {
            return None;
        }
        let n = c.len();
        let Some(i) = (0..n)
            .find(|&i| length(&c[i]) < cfg.min_edge && !frozen(&c, i) && !frozen(&c, (i + 1) % n))
        else {
            break;
        };
        // Collapse edge i: the next edge now starts where i started.
        let j = (i + 1) % n;
        c[j].start = c[i].start;
        c.remove(i);
        c.retain(|e| e.start != e.end);
    }
    // Remove spikes and merge nearly collinear runs of one origin, until
    // nothing changes (each removal drops a vertex, so this ends).
    let mut changed = true;
    while changed && c.len() >= 3 {
        changed = false;
        let mut k = 0;
        while c.len() >= 3 && k < c.len() {
            let j = (k + 1) % c.len();
            let (a, b) = (c[k], c[j]);
            // Pieces cut at the window are never taken for spikes; their
            // collinear continuations still merge.
            let cut = frozen(&c, k) || frozen(&c, j);
            match joint(&a, &b, cfg, !cut) {
                Some(origin) => {
                    c[k] = RegionEdge {
                        start: a.start,
                        end: b.end,
                        origin,
                    };
                    c.remove(j);
                    c.retain(|e| e.start != e.end);
                    changed = true;
                    if j < k {
                        k = k.saturating_sub(1);
                    }
                }
                None => k += 1,
            }
        }
    }
    (c.len() >= 3).then_some(c)
}

/// Whether edge `i` of the closed contour `c` must stay as it is: a side
/// of the clipping window or a piece cut at one (its length is an artefact
/// of where the window lies, and its end on the window must not move).
fn frozen(c: &[RegionEdge], i: usize) -> bool {
    let n = c.len();
    let window = |k: usize| c[k % n].origin == EdgeOrigin::Window;
    window(i) || window(i + 1) || window(i + n - 1)
}

/// Whether the vertex between `a` and `b` should go, and the origin of the
/// edge that replaces them: a spike (the boundary turns back and the two
/// edges stay within [`RegionConfig::sliver_width`] of each other), or a
/// vertex within a tenth of that of the straight line from `a`'s start to
/// `b`'s end between edges of one origin. Spikes only when `spikes`.
fn joint(a: &RegionEdge, b: &RegionEdge, cfg: &RegionConfig, spikes: bool) -> Option<EdgeOrigin> {
    if a.origin == EdgeOrigin::Window || b.origin == EdgeOrigin::Window {
        return None;
    }
    let u = [a.end[0] - a.start[0], a.end[1] - a.start[1]];
    let v = [b.end[0] - b.start[0], b.end[1] - b.start[1]];
    let (lu, lv) = (u[0].hypot(u[1]), v[0].hypot(v[1]));
    if lu == 0.0 || lv == 0.0 {
        return Some(EdgeOrigin::merge(a.origin, b.origin));
    }
    let cross = u[0] * v[1] - u[1] * v[0];
    let dot = u[0] * v[0] + u[1] * v[1];
    if dot < 0.0 && !spikes {
        return None;
    }
    if dot < 0.0 {
        // Distance of each far end from the other edge's line.
        let width = (cross / lu).abs().min((cross / lv).abs());
        if width < cfg.sliver_width {
            // The new edge runs along the longer of the two.
            return Some(if lu >= lv { a.origin } else { b.origin });
        }
        return None;
    }
    let w = [b.end[0] - a.start[0], b.end[1] - a.start[1]];
    let lw = w[0].hypot(w[1]);
    // Distance of the shared vertex from the chord a.start → b.end.
    let offset = if lw > 0.0 {
        (u[0] * w[1] - u[1] * w[0]).abs() / lw
    } else {
        lu
    };
    (a.origin == b.origin && offset <= 0.1 * cfg.sliver_width).then_some(a.origin)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn polygon(pts: &[[f64; 2]], origin: EdgeOrigin) -> Vec<RegionEdge> {
        let n = pts.len();
        (0..n)
            .map(|i| RegionEdge {
                start: pts[i],
                end: pts[(i + 1) % n],
                origin,
            })
            .collect()
    }

    fn rect(x0: f64, y0: f64, x1: f64, y1: f64, origin: EdgeOrigin) -> Vec<RegionEdge> {
        polygon(&[[x0, y0], [x1, y0], [x1, y1], [x0, y1]], origin)
    }

    fn assert_chains(shapes: &[RegionShape]) {
        for shape in shapes {
            for (k, c) in shape.iter().enumerate() {
                assert!(c.len() >= 3);
                for i in 0..c.len() {
                    assert_eq!(c[i].end, c[(i + 1) % c.len()].start, "contour closes");
                }
                let area = contour_area(c);
                assert!(
                    if k == 0 { area > 0.0 } else { area < 0.0 },
                    "orientation {area}"
                );
            }
        }
    }

    #[test]
    fn overlapping_squares_merge_and_keep_origins() {
        let a = rect(0.0, 0.0, 4.0, 4.0, EdgeOrigin::Actual(0));
        let b = rect(2.0, 1.0, 6.0, 3.0, EdgeOrigin::Virtual);
        let shapes = union([a.as_slice()], [b.as_slice()], &RegionConfig::default()).unwrap();
        assert_chains(&shapes);
        assert_eq!(shapes.len(), 1);
        assert_eq!(shapes[0].len(), 1);
        let area = contour_area(&shapes[0][0]);
        assert!((area - 20.0).abs() < 1e-9, "{area}");
        for e in &shapes[0][0] {
            let right = e.start[0] > 4.0 + 1e-9 || e.end[0] > 4.0 + 1e-9;
            assert_eq!(e.origin == EdgeOrigin::Virtual, right, "{e:?}");
        }
    }

    #[test]
    fn actual_wins_over_a_virtual_edge_lying_on_it() {
        // The same square twice, walls in one and frontier in the other,
        // plus a shifted copy sharing the bottom edge.
        let walls = rect(0.0, 0.0, 2.0, 2.0, EdgeOrigin::Actual(3));
        let frontier = rect(0.0, 0.0, 2.0, 2.0, EdgeOrigin::Virtual);
        let shapes = union(
            [frontier.as_slice()],
            [walls.as_slice()],
            &RegionConfig::default(),
        )
        .unwrap();
        assert_chains(&shapes);
        assert!(
            shapes[0][0]
                .iter()
                .all(|e| e.origin == EdgeOrigin::Actual(3))
        );
    }

    #[test]
    fn a_ring_keeps_its_hole() {
        let outer = rect(0.0, 0.0, 10.0, 10.0, EdgeOrigin::Virtual);
        let mut hole = rect(4.0, 4.0, 6.0, 6.0, EdgeOrigin::Actual(1));
        hole.reverse();
        for e in &mut hole {
            std::mem::swap(&mut e.start, &mut e.end);
        }
        let small = rect(1.0, 1.0, 2.0, 2.0, EdgeOrigin::Virtual);
        let shapes = union(
            [outer.as_slice(), hole.as_slice()],
            [small.as_slice()],
            &RegionConfig::default(),
        )
        .unwrap();
        assert_chains(&shapes);
        assert_eq!(shapes[0].len(), 2);
        assert!(
            shapes[0][1]
                .iter()
                .all(|e| e.origin == EdgeOrigin::Actual(1))
        );
    }

    #[test]
    fn non_finite_input_is_an_error() {
        let bad = rect(0.0, 0.0, f64::NAN, 1.0, EdgeOrigin::Virtual);
        assert!(matches!(
            union([bad.as_slice()], [], &RegionConfig::default()),
            Err(RegionError::Coordinate(_))
        ));
        let far = rect(0.0, 0.0, 2e5, 1.0, EdgeOrigin::Virtual);
        assert!(union([far.as_slice()], [], &RegionConfig::default()).is_err());
    }

    #[test]
    fn tiny_edges_and_slivers_are_cleaned() {
        let cfg = RegionConfig::default();
        let with_notch = polygon(
            &[
                [0.0, 0.0],
                [1.0, 0.0],
                [1.0, 0.002],
                [1.001, 0.003],
                [1.0, 1.0],
                [0.0, 1.0],
            ],
            EdgeOrigin::Virtual,
        );
        let sliver = rect(3.0, 0.0, 4.0, 0.00005, EdgeOrigin::Virtual);
        let shapes = union([with_notch.as_slice(), sliver.as_slice()], [], &cfg).unwrap();
        let cleaned = clean(&shapes, &cfg);
        assert_chains(&cleaned);
        assert_eq!(cleaned.len(), 1);
        let c = &cleaned[0][0];
        assert!(
            c.iter()
                .all(|e| (e.end[0] - e.start[0]).hypot(e.end[1] - e.start[1]) >= cfg.min_edge)
        );
    }

    fn star(centre: [f64; 2], radii: &[f64], phase: f64) -> Vec<[f64; 2]> {
        let n = radii.len();
        (0..n)
            .map(|i| {
                let a = phase + std::f64::consts::TAU * i as f64 / n as f64;
                [
                    centre[0] + radii[i] * a.cos(),
                    centre[1] + radii[i] * a.sin(),
                ]
            })
            .collect()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]
        #[test]
        fn random_star_polygons_union_into_valid_loops(
            c1 in (-2.0..2.0f64, -2.0..2.0f64), r1 in prop::collection::vec(0.3..3.0f64, 3..12), p1 in 0.0..6.3f64,
            c2 in (-2.0..2.0f64, -2.0..2.0f64), r2 in prop::collection::vec(0.3..3.0f64, 3..12), p2 in 0.0..6.3f64,
        ) {
            let cfg = RegionConfig::default();
            let a = polygon(&star([c1.0, c1.1], &r1, p1), EdgeOrigin::Actual(0));
            let b = polygon(&star([c2.0, c2.1], &r2, p2), EdgeOrigin::Virtual);
            let shapes = union([a.as_slice()], [b.as_slice()], &cfg).unwrap();
            prop_assert_eq!(check_shapes(&shapes), Ok(()));
            let cleaned = clean_checked(&shapes, &cfg).unwrap();
            // The union covers both inputs: its area is at least each one's,
            // up to snapping (half a grid step along the boundary) and, once
            // cleaned, the slivers cut off (narrower than sliver_width).
            let perimeter: f64 = a.iter().chain(&b).map(|e| (e.end[0] - e.start[0]).hypot(e.end[1] - e.start[1])).sum();
            let largest = contour_area(&a).max(contour_area(&b));
            let raw_total: f64 = shapes.iter().flatten().map(|c| contour_area(c)).sum();
            prop_assert!(raw_total >= largest - perimeter * cfg.grid);
            let total: f64 = cleaned.iter().flatten().map(|c| contour_area(c)).sum();
            prop_assert!(total >= largest - perimeter * (cfg.grid + 0.5 * cfg.sliver_width));
        }

        #[test]
        fn near_degenerate_pairs_never_panic(
            w in 0.5..3.0f64, h in 0.5..3.0f64,
            dx in prop_oneof![Just(0.0), -1e-4..1e-4f64, -3.0..3.0f64],
            dy in prop_oneof![Just(0.0), -1e-4..1e-4f64, Just(1.0), -3.0..3.0f64],
            tilt in prop_oneof![Just(0.0), -1e-5..1e-5f64],
        ) {
            let cfg = RegionConfig::default();
            let a = rect(0.0, 0.0, w, h, EdgeOrigin::Actual(1));
            // A rectangle sharing an edge, overlapping collinearly or
            // offset by a hair, possibly tilted by a hair.
            let pts = [[w + dx, dy], [2.0 * w + dx, dy + tilt], [2.0 * w + dx, h + dy], [w + dx, h + dy + tilt]];
            let b = polygon(&pts, EdgeOrigin::Virtual);
            let shapes = union([a.as_slice()], [b.as_slice()], &cfg).unwrap();
            let cleaned = clean_checked(&shapes, &cfg).unwrap();
            for c in cleaned.iter().flatten() {
                for e in c {
                    let len = (e.end[0] - e.start[0]).hypot(e.end[1] - e.start[1]);
                    prop_assert!(len >= cfg.min_edge * 0.999, "short edge {:?}", e);
                }
            }
        }
    }
}
