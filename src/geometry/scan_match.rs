//! Point-to-line ICP between two consecutive scans: how far the robot
//! moved between them, from the raw points.
//!
//! Localization places each scan against the map's lines, a couple of
//! centimetres from where it is; the raw points of two scans a fraction of
//! a second apart pin their relative pose to millimetres. Both together
//! (see [`crate::pipeline::smoothing`]) give a trajectory steady from scan
//! to scan and tied to the map.
//!
//! Points stay in the sensor frame, where a point's bearing names the beam
//! it fell near in the other scan (projective association: no search
//! structure, a handful of beams looked at per point).

use nalgebra::{Matrix3, Vector3};

use super::fit::principal_axes;
use super::pose::Pose2;
use super::scan::RangeScan;

/// Beams either side of a point's own that give its surface's normal.
const NORMAL_BEAMS: usize = 3;
/// Neighbours farther than this (m) belong to another surface: ±3 beams
/// of 1° at 5 m span 0.26 m.
const NORMAL_REACH: f64 = 0.3;
/// Least points (with the point itself) for a normal.
const NORMAL_POINTS: usize = 4;
/// Greatest ratio of the spread across the surface to the spread along
/// it: rounder patches (corners, clutter) have no normal.
const NORMAL_FLATNESS: f64 = 0.05;
/// Beams either side of the projected one searched for a partner, and
/// either side of the last partner once there is one.
const SEARCH_BEAMS: i64 = 4;
const NEAR_BEAMS: i64 = 1;
/// Iterations, and the partner distance (m) allowed in each stage: wide
/// first while the start may be centimetres off, then narrow.
const ITERATIONS: usize = 7;
fn gate(iteration: usize) -> f64 {
    if iteration < 3 { 0.15 } else { 0.08 }
}
/// Share of the pairs kept each iteration, the closest ones.
const KEPT: f64 = 0.85;
/// Least pairs for a result.
const MIN_PAIRS: usize = 15;
/// Least information across the weakest direction of translation (the
/// smallest eigenvalue of Σ n·nᵀ over the kept pairs, in pairs' worth of
/// normals): a corridor's two walls give none along it. Low enough for
/// 1° scans' 181 beams (at 30 pairs and 20, CSAIL decimated to 1° beams
/// gained nothing from the smoothing; at 15 and 10, 0.0337 → 0.0326 m).
const MIN_TRANSLATION_INFO: f64 = 10.0;
/// Least information (as above) along a direction for an iteration to
/// step along it at all: below it the step there is noise (a corridor's
/// length, two walls' points a few degrees from parallel).
const MIN_STEP_INFO: f64 = 1.0;
/// A result farther than this from the start (m, rad) is a different
/// alignment, not a refinement.
const MAX_CHANGE: f64 = 0.2;
const MAX_TURN: f64 = 0.1;

/// One scan's valid points (sensor frame) with their surface normals, by
/// beam.
#[derive(Debug, Clone, Default)]
pub struct ScanPoints {
    angle_increment: f64,
    /// Per beam, its point, if the beam returned within the range limits.
    points: Vec<Option<[f64; 2]>>,
    /// Per beam, its point if the surface there is flat, else NaN (never
    /// nearer than anything in the partner search).
    surface_points: Vec<[f64; 2]>,
    /// Per beam, the unit normal of the surface at its surface point
    /// (meaningless where that is NaN).
    normals: Vec<[f64; 2]>,
}

impl ScanPoints {
    /// The points of `scan` whose ranges lie within `[min_range,
    /// max_range]` (m).
    pub fn new(scan: &RangeScan, min_range: f64, max_range: f64) -> ScanPoints {
        // Beam directions by turning the first one beam by beam (one
        // sin_cos for the scan instead of one per beam).
        let (s0, c0) = scan.angle_min.sin_cos();
        let (si, ci) = scan.angle_increment.sin_cos();
        let mut direction = [c0, s0];
        let points: Vec<Option<[f64; 2]>> = scan
            .ranges
            .iter()
            .map(|r| {
                let [c, s] = direction;
                direction = [c * ci - s * si, s * ci + c * si];
                let r = *r.as_ref().ok()?;
                (r.is_finite() && r >= min_range && r <= max_range).then_some([r * c, r * s])
            })
            .collect();
        let (surface_points, normals) = (0..points.len())
            .map(|i| {
                points[i]
                    .zip(normal(&points, i))
                    .unwrap_or(([f64::NAN; 2], [f64::NAN; 2]))
            })
            .unzip();
        ScanPoints {
            angle_increment: scan.angle_increment,
            points,
            surface_points,
            normals,
        }
    }

    /// The beam of this scan nearest the bearing of `p`, the point `m` of
    /// beam `i` of a scan with the same beams, moved: beam `i` turned by
    /// the small angle between `m` and `p` (its tangent, to spare an
    /// arc tangent per point).
    fn beam_near(&self, i: usize, m: &[f64; 2], p: [f64; 2]) -> Option<i64> {
        let dot = m[0] * p[0] + m[1] * p[1];
        if dot <= 0.0 || self.angle_increment == 0.0 || !self.angle_increment.is_finite() {
            return None;
        }
        let tangent = (m[0] * p[1] - m[1] * p[0]) / dot;
        // The tangent is the angle within a twentieth of a 0.5° beam up
        // to 0.1 rad; a wider turn (a fast one between sparse scans) needs
        // the arc tangent.
        let turn = if tangent.abs() > 0.1 {
            tangent.atan()
        } else {
            tangent
        };
        let shift = (turn / self.angle_increment).round();
        (shift.abs() < 1e6).then(|| i as i64 + shift as i64)
    }

    /// The beam whose point (with a normal) lies nearest `p` within
    /// `reach` (m), among the `around` beams either side of `beam`.
    fn partner(&self, p: [f64; 2], beam: i64, around: i64, reach: f64) -> Option<usize> {
        let mut best = None;
        let mut best_d2 = reach * reach;
        // The beams that exist, in the same order as beam by beam.
        let lo = usize::try_from(beam.saturating_sub(around)).unwrap_or(0);
        let Ok(hi) = usize::try_from(beam.saturating_add(around)) else {
            return None;
        };
        let hi = hi.min(self.surface_points.len().checked_sub(1)?);
        for (j, q) in self.surface_points.get(lo..=hi)?.iter().enumerate() {
            let d2 = (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2);
            if d2 < best_d2 {
                best_d2 = d2;
                best = Some(lo + j);
            }
        }
        best
    }
}

/// The normal at beam `i`'s point from the points of the beams around it
/// on the same surface (principal axes of their scatter).
fn normal(points: &[Option<[f64; 2]>], i: usize) -> Option<[f64; 2]> {
    let p = points[i]?;
    let lo = i.saturating_sub(NORMAL_BEAMS);
    let hi = (i + NORMAL_BEAMS + 1).min(points.len());
    let mut near = [[0.0; 2]; 2 * NORMAL_BEAMS + 1];
    let mut n = 0;
    for q in points[lo..hi].iter().flatten() {
        // Relative to the point itself, which keeps the sums small.
        let d = [q[0] - p[0], q[1] - p[1]];
        if d[0] * d[0] + d[1] * d[1] < NORMAL_REACH * NORMAL_REACH {
            near[n] = d;
            n += 1;
        }
    }
    if n < NORMAL_POINTS {
        return None;
    }
    let near = &near[..n];
    let (sx, sy) = near
        .iter()
        .fold((0.0, 0.0), |(x, y), q| (x + q[0], y + q[1]));
    let (mx, my) = (sx / n as f64, sy / n as f64);
    let (xx, yy, xy) = near.iter().fold((0.0, 0.0, 0.0), |(a, b, c), q| {
        let (dx, dy) = (q[0] - mx, q[1] - my);
        (a + dx * dx, b + dy * dy, c + dx * dy)
    });
    let (along, across, normal) = principal_axes(xx, xy, yy);
    (along > 0.0 && across <= NORMAL_FLATNESS * along).then_some(normal)
}

/// Where [`align`] put the moving scan, and how much of it agreed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Alignment {
    /// The moving scan's sensor pose in the reference's sensor frame.
    pub pose: Pose2,
    /// Moving points that found a reference surface within the last gate
    /// (0.08 m) in the last iteration.
    pub pairs: usize,
    /// Moving points within the range limits.
    pub points: usize,
    /// The direction of translation (unit, in the reference scan's sensor
    /// frame) the points leave open, a corridor's length, if any: along it
    /// the pose is the start's.
    pub open: Option<[f64; 2]>,
}

/// The pose of `moving`'s sensor in `reference`'s sensor frame, refined
/// from `start` by point-to-line ICP; `None` when too few points pair up,
/// or when the result strays from `start` by more than a refinement
/// would. A direction of translation with less than
/// `MIN_TRANSLATION_INFO` at the end (a corridor's length) is named in
/// the result and held at the start's, the rest found again with it
/// held.
pub fn align(reference: &ScanPoints, moving: &ScanPoints, start: &Pose2) -> Option<Alignment> {
    let (mut pose, mut pairs, info) = refine(reference, moving, *start, None)?;
    let (weakest, v) = weakest_translation(&info);
    let open = (weakest < MIN_TRANSLATION_INFO).then_some(v);
    if let Some(v) = open {
        // Along the open direction the start stands: back there, and the
        // heading and the offset across found again with it held.
        let along = v[0] * (pose.x - start.x) + v[1] * (pose.y - start.y);
        let held = Pose2::new(pose.x - along * v[0], pose.y - along * v[1], pose.theta);
        (pose, pairs, _) = refine(reference, moving, held, Some(v))?;
    }
    let change = start.between(&pose);
    let fits = change.x.hypot(change.y) <= MAX_CHANGE && change.theta.abs() <= MAX_TURN;
    fits.then(|| Alignment {
        pose,
        pairs,
        points: moving.points.iter().flatten().count(),
        open,
    })
}

/// Point-to-line ICP iterations from `start`: the pose, the pairs of the
/// last iteration and their information matrix; `None` when too few pair
/// up. With `hold`, no step moves along that unit direction; without,
/// no step moves along a direction with less than [`MIN_STEP_INFO`].
fn refine(
    reference: &ScanPoints,
    moving: &ScanPoints,
    start: Pose2,
    hold: Option<[f64; 2]>,
) -> Option<(Pose2, usize, Matrix3<f64>)> {
    let mut pose = start;
    let mut rows: Vec<([f64; 3], f64)> = Vec::with_capacity(moving.points.len());
    // Per moving point, the reference beam it paired with last: later
    // iterations look only beside it (the pose moves by millimetres).
    let mut paired: Vec<Option<i64>> = vec![None; moving.points.len()];
    let mut info = Matrix3::zeros();
    let mut pairs = 0;
    for iteration in 0..ITERATIONS {
        let reach = gate(iteration);
        let (s, c) = pose.theta.sin_cos();
        rows.clear();
        for (i, (m, last)) in moving.points.iter().zip(paired.iter_mut()).enumerate() {
            let Some(m) = m else { continue };
            let p = [pose.x + c * m[0] - s * m[1], pose.y + s * m[0] + c * m[1]];
            let (beam, around) = match *last {
                Some(j) if iteration > 0 => (j, NEAR_BEAMS),
                _ => match reference.beam_near(i, m, p) {
                    Some(k) => (k, SEARCH_BEAMS),
                    None => continue,
                },
            };
            let found = reference.partner(p, beam, around, reach);
            *last = found.and_then(|j| i64::try_from(j).ok());
            let Some(j) = found else { continue };
            let (q, n) = (reference.surface_points[j], reference.normals[j]);
            let e = n[0] * (p[0] - q[0]) + n[1] * (p[1] - q[1]);
            let turn = n[0] * (-s * m[0] - c * m[1]) + n[1] * (c * m[0] - s * m[1]);
            rows.push(([n[0], n[1], turn], e));
        }
        if rows.len() < MIN_PAIRS {
            return None;
        }
        pairs = rows.len();
        let keep = ((KEPT * rows.len() as f64) as usize).max(MIN_PAIRS);
        if keep < rows.len() {
            rows.select_nth_unstable_by(keep, |a, b| a.1.abs().total_cmp(&b.1.abs()));
            rows.truncate(keep);
        }
        info = Matrix3::zeros();
        let mut g = Vector3::zeros();
        for (j, e) in &rows {
            let j = Vector3::from(*j);
            info += j * j.transpose();
            g += j * *e;
        }
        let step = match (hold, weakest_translation(&info)) {
            (Some(v), _) => solve_across(&info, &g, v)?,
            (None, (weakest, v)) if weakest < MIN_STEP_INFO => solve_across(&info, &g, v)?,
            (None, _) => info.cholesky()?.solve(&(-g)),
        };
        pose = Pose2::new(pose.x + step[0], pose.y + step[1], pose.theta + step[2]);
        if iteration >= 3 && step[0].hypot(step[1]) < 1e-4 && step[2].abs() < 1e-5 {
            break;
        }
    }
    Some((pose, pairs, info))
}

/// The smallest eigenvalue of the translation block of `info` and its
/// unit eigenvector.
fn weakest_translation(info: &Matrix3<f64>) -> (f64, [f64; 2]) {
    let (_, weakest, v) = principal_axes(info[(0, 0)], info[(0, 1)], info[(1, 1)]);
    (weakest, v)
}

/// The Gauss–Newton step for information `info` and gradient `g` with no
/// translation along the unit `v`: solved over the translation across it
/// and the turn.
fn solve_across(info: &Matrix3<f64>, g: &Vector3<f64>, v: [f64; 2]) -> Option<Vector3<f64>> {
    let basis = nalgebra::Matrix3x2::new(-v[1], 0.0, v[0], 0.0, 0.0, 1.0);
    let reduced = basis.transpose() * info * basis;
    let x = reduced.cholesky()?.solve(&(-(basis.transpose() * g)));
    Some(basis * x)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::sim::{Rng, ScanSpec, World, cast_scan};

    fn points(world: &World, pose: &Pose2, seed: u64) -> ScanPoints {
        let spec = ScanSpec::lms200_half_degree(0.005);
        let scan = cast_scan(world, pose, &spec, 0.0, &mut Rng::new(seed));
        ScanPoints::new(&scan, 0.05, 80.0)
    }

    /// The scans of the room with boxes from `a` and `b` aligned from the
    /// true motion put `off`: the alignment and its error.
    fn aligned_in_the_room(a: Pose2, b: Pose2, off: Pose2) -> (Alignment, Pose2) {
        let room = World::room_with_boxes();
        let truth = a.between(&b);
        let found = align(
            &points(&room, &a, 1),
            &points(&room, &b, 2),
            &truth.compose(&off),
        )
        .unwrap();
        (found, truth.between(&found.pose))
    }

    #[test]
    fn recovers_the_motion_between_two_scans_from_a_start_centimetres_off() {
        let (found, error) = aligned_in_the_room(
            Pose2::new(4.0, 3.0, 0.2),
            Pose2::new(4.3, 3.12, 0.27),
            Pose2::new(0.04, -0.03, 0.02),
        );
        assert!(found.pairs > 9 * found.points / 10, "{found:?}");
        assert_eq!(found.open, None);
        assert!(error.x.hypot(error.y) < 0.003, "{error:?}");
        assert!(error.theta.abs() < 0.002, "{error:?}");
    }

    #[test]
    fn pairs_beams_across_a_fast_turn() {
        // 1 rad between the scans (a fast turn between sparse scans): its
        // tangent would look 64 beams away from the partners.
        let (_, error) = aligned_in_the_room(
            Pose2::new(4.0, 3.0, 0.2),
            Pose2::new(4.2, 3.1, 1.2),
            Pose2::new(0.03, 0.02, -0.03),
        );
        assert!(error.x.hypot(error.y) < 0.005, "{error:?}");
        assert!(error.theta.abs() < 0.003, "{error:?}");
    }

    #[test]
    fn a_corridor_s_length_is_left_open() {
        // Two plain walls 2 m apart, the ends out of reach: the scans from
        // 0.3 m apart along it look the same.
        let corridor = World::corridor(40.0, 2.0, None);
        let a = points(&corridor, &Pose2::new(15.0, 0.0, 0.0), 1);
        let b = points(&corridor, &Pose2::new(15.3, 0.0, 0.0), 2);
        let start = Pose2::new(0.45, 0.04, 0.03);
        let found = align(&a, &b, &start).unwrap();
        let open = found.open.unwrap();
        assert!(open[0].abs() > 0.999, "{found:?}");
        // Across the corridor and in heading the points tell the step;
        // along it the start stands.
        assert!((found.pose.x - 0.45).abs() < 1e-3, "{found:?}");
        assert!(found.pose.y.abs() < 0.005, "{found:?}");
        assert!(found.pose.theta.abs() < 0.003, "{found:?}");
    }

    #[test]
    fn too_few_points_give_nothing() {
        let room = World::room_with_boxes();
        let b = points(&room, &Pose2::new(4.0, 3.0, 0.0), 1);
        assert!(align(&ScanPoints::default(), &b, &Pose2::IDENTITY).is_none());
    }
}
