//! Conversions between the map's loops and the overlay's contours: whole
//! loops into contours (walls registered in the line table), the union's
//! contours back into shapes, and loose loops grouped into shapes.

use super::fusion::LineTable;
use super::loops::{ClsLoop, ClsShape, SegmentMode};
use super::region::{EdgeOrigin, RegionEdge, RegionShape};
use crate::map::SegmentMap;

/// Whole loops as overlay contours, walls (of `store`) registered in
/// `table`.
pub(crate) fn whole_contours(
    loops: &[&ClsLoop],
    table: &mut LineTable,
    store: &SegmentMap,
) -> Vec<Vec<RegionEdge>> {
    loops
        .iter()
        .map(|lp| {
            lp.segments()
                .iter()
                .map(|s| RegionEdge {
                    start: s.start(),
                    end: s.end(),
                    origin: match s.mode {
                        SegmentMode::Actual => EdgeOrigin::Actual(table.add_segment(s, store)),
                        SegmentMode::Virtual => EdgeOrigin::Virtual,
                    },
                })
                .collect()
        })
        .collect()
}

/// Loops grouped into shapes: counter-clockwise ones are outer loops, each
/// clockwise one goes to the smallest outer loop around it. `None` if a
/// hole has no outer loop.
pub(crate) fn group_loops(loops: Vec<ClsLoop>) -> Option<Vec<ClsShape>> {
    let (outers, holes): (Vec<ClsLoop>, Vec<ClsLoop>) =
        loops.into_iter().partition(|l| l.signed_area() > 0.0);
    let mut shapes: Vec<ClsShape> = outers
        .into_iter()
        .map(|outer| ClsShape {
            outer,
            holes: vec![],
        })
        .collect();
    for hole in holes {
        let k = if shapes.len() == 1 {
            0
        } else {
            let p = hole.segments().first()?.point_on_left(1e-6);
            (0..shapes.len())
                .filter(|&k| shapes[k].outer.encloses(p))
                .min_by(|&a, &b| {
                    shapes[a]
                        .outer
                        .signed_area()
                        .total_cmp(&shapes[b].outer.signed_area())
                })?
        };
        shapes.get_mut(k)?.holes.push(hole);
    }
    Some(shapes)
}

/// The union's contours as CLS shapes, wall pieces taking their line from
/// the table.
pub(crate) fn to_shapes(shapes: &[RegionShape], table: &LineTable) -> Vec<ClsShape> {
    shapes
        .iter()
        .filter_map(|shape| {
            let mut loops = shape
                .iter()
                .map(|contour| ClsLoop::new(contour.iter().map(|e| table.segment(e)).collect()));
            let outer = loops.next()?;
            Some(ClsShape {
                outer,
                holes: loops.collect(),
            })
        })
        .collect()
}
