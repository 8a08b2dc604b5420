//! Which ends of an extracted line are true ends of its wall.
//!
//! The beam just past a line's end tells: a range that jumps away (the
//! wall stops and the laser sees past it: a jamb) or a point at about the
//! same range but off the line, with the beam after it not back on the
//! line (the next surface of a corner), make it a true end; a range that
//! jumps nearer (something in front hides the wall), no valid beam (the
//! field of view's edge, no return, the range limit) or a point on the
//! line's extension (the wall goes on) do not.
//! A short straight face across the wall right past its end (the side of
//! a door's jamb seen from in front of it, too short for a line of its
//! own) is a corner too, and then the end is put where the face's line
//! meets the wall's: known to about a centimetre however grazing the
//! view. Any other true end is known only to about the beam spacing where
//! the beam meets the wall, some 15 cm from 5 m along a corridor.

use super::cog_line::CogLine;
use super::extract::ExtractionConfig;
use super::points::{ScanPoint, usable_range};
use super::pose::Pose2;
use super::scan::RangeScan;

/// Smallest range step (m) read as a jump rather than the same surface.
const MIN_JUMP: f64 = 0.1;
/// Least |sin| of the angle between beam and wall: at more grazing angles
/// consecutive beams land far apart on the wall and its end is vague.
pub(crate) const MIN_SIN_INCIDENCE: f64 = 0.25;
/// A neighbour point farther than this from the line's extension (m, and
/// at least 3 σ of its range) belongs to another surface.
const MIN_OFF_LINE: f64 = 0.03;
/// Beams past a line's end read as a face of their own when the first
/// one is too close to tell: the side of a jamb seen from in front of the
/// door, too short for a line, whose first point lies a beam spacing
/// (a centimetre or two) off the wall's extension.
const FACE_BEAMS: usize = 6;
/// Least |sin| of the angle between the wall and such a face: a corner,
/// not the wall's own noise.
const MIN_FACE_SIN: f64 = 0.7;

/// A true end of a wall as one scan sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SeenEnd {
    /// σ (m) of the end's position along the wall.
    pub sigma: f64,
    /// How far (m) the wall's end lies beyond the last point on it, along
    /// the wall, on average: for a jamb, to the middle of its gap (about
    /// half a beam spacing), since the end is somewhere between that point
    /// and where the next beam would have met the wall; for a corner, as
    /// far as the next surface's
    /// first point (within that spacing). Left uncorrected, the last point
    /// falls short of the end by more the more grazing the view, and views
    /// from two places disagree about where one end is.
    pub beyond_last_point: f64,
    /// For a jamb: where the last beam on the wall and the next beam past
    /// its end cross the line (m along it, see [`CogLine::along`]), and
    /// the σ (m) along the line of both crossings from the line's offset
    /// error. The end lies between them.
    pub gap: Option<JambGap>,
}

/// The gap a jamb lies in, as one scan sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JambGap {
    /// Where the last beam on the wall crosses its line (m along it).
    pub last: f64,
    /// Where the next beam, past the end, crosses it (m along it).
    pub past: f64,
    /// σ (m) of both along the line, from the line's offset error.
    pub sigma: f64,
}

/// The end of `line` at its fitted point `end`, if that end is a true end
/// of the wall; `step` is −1 for the start (the beam before it in scan
/// order), +1 for the end (the beam after).
pub(crate) fn wall_end(
    scan: &RangeScan,
    mount: &Pose2,
    cfg: &ExtractionConfig,
    end: &ScanPoint,
    line: &CogLine,
    step: isize,
) -> Option<SeenEnd> {
    let next = end.beam_index.checked_add_signed(step)?;
    let Some(Ok(range_next)) = scan.ranges.get(next).copied() else {
        return None;
    };
    if !usable_range(range_next, cfg) {
        return None;
    }
    let range_end = range_of(mount, end.p);
    let jump = jump_for(end);
    // How far along the wall, past its last point, the next surface's
    // first point lies (m), when that surface is a corner's.
    let mut next_point_beyond = None;
    // The next beam's point, and how far it lies off the wall's line.
    let off_line = off_line_for(end);
    let q = beam_point(scan, mount, next, range_next);
    let first = line.signed_distance(q);
    // A jump away is a jamb unless the next beam's point lies on the
    // wall's line all the same: at a grazing view consecutive beams on one
    // wall differ in range by more than the jump (14 cm from 4 m at 15°),
    // and a last point trimmed off the line for its noise then read as a
    // jamb 11 cm short of the true end, which the next scan's gap
    // confirmed and the map kept (the simulated corridor's pose 10 cm off).
    let jamb = range_next > range_end + jump && first.abs() > off_line;
    let is_end = if jamb {
        true
    } else if range_next < range_end - jump {
        // Something nearer: an occlusion. (A concave corner whose next
        // wall comes this much nearer within one beam is read so too:
        // counting those as ends, on CSAIL thinned to sparse scans, made
        // the map metres worse, so the rule stays on the safe side.)
        false
    } else if let Some(corner) = face_corner(scan, mount, cfg, end, line, step) {
        // A short face turning away from the wall right there: the end is
        // where the two surfaces meet, not somewhere in a beam spacing.
        return incidence_ok(end, line).map(|_| corner);
    } else {
        // The very next beam off the wall, and the one after it not back
        // on it: one range a few σ out (one beam in a few hundred) would
        // otherwise read as a corner with the σ of a perpendicular view,
        // a millimetre, and pull the pose along the wall to the nearest
        // mapped end (a 19 cm jump in the loop world). At the field of
        // view's edge there is no beam after to tell. Looking past the
        // beams the end trimming left on the wall found more ends in the
        // simulated worlds but, in the clutter of a real building (CSAIL),
        // false ones that cost more than they gave (for a single point off
        // the wall, and for a face after up to three or eight such beams:
        // 0.107 and 0.085 m against 0.049 m on CSAIL thinned to scans
        // 0.7 m apart).
        let offset = |i: usize, r: f64| line.signed_distance(beam_point(scan, mount, i, r));
        next_point_beyond = Some(step as f64 * (line.along(q) - line.along(end.p)));
        let after = next
            .checked_add_signed(step)
            .and_then(|i| Some((i, scan.ranges.get(i)?)));
        first.abs() > off_line
            && after.is_some_and(|(i, reading)| match reading {
                Ok(r) if usable_range(*r, cfg) => {
                    let d = offset(i, *r);
                    d.abs() > off_line && d.signum() == first.signum()
                }
                _ => true,
            })
    };
    if !is_end {
        return None;
    }
    let sin_incidence = incidence_ok(end, line)?;
    if jamb {
        let origin = [mount.x, mount.y];
        let next_beam = beam_direction(scan, mount, next);
        return jamb_end(line, origin, end, next_beam, step, sin_incidence);
    }
    // Uniform over one beam spacing on the wall, plus the range noise
    // projected along it.
    let spacing = range_end * scan.angle_increment.abs() / sin_incidence;
    let cos_incidence = (1.0 - sin_incidence * sin_incidence).max(0.0).sqrt();
    let along_noise = end.sigma_range * cos_incidence / sin_incidence;
    // A jamb's end lies anywhere in the spacing past the last point: half
    // of it on average. A corner's next surface, seen at a grazing angle,
    // is met by the next beam well before that beam would meet the wall's
    // extension; where that surface runs square to the wall (a jamb's
    // side, a door recess's end) its first point lies right at the corner
    // along the wall. Half a spacing put such corners 3–4 cm beyond it
    // from 3–5 m (the simulated corridor's door recesses).
    let beyond = next_point_beyond.map_or(0.5 * spacing, |b| b.clamp(0.0, spacing));
    Some(SeenEnd {
        sigma: (spacing / 12f64.sqrt()).hypot(along_noise),
        beyond_last_point: beyond,
        gap: None,
    })
}

/// A jamb's end: somewhere between where the last beam on the wall and
/// the next beam, which passed its end, cross the fitted line (`origin`
/// the sensor, `next_beam` that beam's direction); uniform over that gap,
/// plus the line's own offset error there carried along it at the beams'
/// incidence. The beams' directions are exact, so the last point's range
/// noise does not enter.
fn jamb_end(
    line: &CogLine,
    origin: [f64; 2],
    end: &ScanPoint,
    next_beam: [f64; 2],
    step: isize,
    sin_incidence: f64,
) -> Option<SeenEnd> {
    let crossing = |u: [f64; 2]| {
        let t = ray_to_line(line, origin, u)?;
        Some(line.along([origin[0] + t * u[0], origin[1] + t * u[1]]))
    };
    let last = crossing(end.beam)?;
    let past = crossing(next_beam)?;
    let step = step as f64;
    let gap = step * (past - last);
    if gap.is_nan() || gap <= 0.0 {
        return None;
    }
    let from_centre = line.along(end.p);
    let offset_sigma = line.sigma_c.hypot(from_centre * line.sigma_theta);
    let cos_incidence = (1.0 - sin_incidence * sin_incidence).max(0.0).sqrt();
    let along_sigma = offset_sigma * cos_incidence / sin_incidence;
    Some(SeenEnd {
        sigma: (gap / 12f64.sqrt()).hypot(along_sigma),
        beyond_last_point: step * (0.5 * (last + past) - from_centre),
        gap: Some(JambGap {
            last,
            past,
            sigma: along_sigma,
        }),
    })
}

/// How far (m) the ray from `origin` along unit `u` runs to the infinite
/// `line`; `None` if it runs parallel to it or away from it.
fn ray_to_line(line: &CogLine, origin: [f64; 2], u: [f64; 2]) -> Option<f64> {
    let n = line.normal();
    let t = -line.signed_distance(origin) / (n[0] * u[0] + n[1] * u[1]);
    (t.is_finite() && t > 0.0).then_some(t)
}

/// |sin| of the angle between the beam to `end` and `line`, if not more
/// grazing than [`MIN_SIN_INCIDENCE`].
fn incidence_ok(end: &ScanPoint, line: &CogLine) -> Option<f64> {
    let d = line.direction();
    let sin_incidence = (end.beam[0] * d[1] - end.beam[1] * d[0]).abs();
    (sin_incidence >= MIN_SIN_INCIDENCE).then_some(sin_incidence)
}

/// Range (m) of robot-frame point `p` from the sensor at `mount`.
fn range_of(mount: &Pose2, p: [f64; 2]) -> f64 {
    (p[0] - mount.x).hypot(p[1] - mount.y)
}

/// Robot-frame unit direction of beam `i` of `scan`.
fn beam_direction(scan: &RangeScan, mount: &Pose2, i: usize) -> [f64; 2] {
    let (s, c) = (scan.angle(i) + mount.theta).sin_cos();
    [c, s]
}

/// Robot-frame point of beam `i` of `scan` at range `r` (m).
fn beam_point(scan: &RangeScan, mount: &Pose2, i: usize, r: f64) -> [f64; 2] {
    let u = beam_direction(scan, mount, i);
    [mount.x + r * u[0], mount.y + r * u[1]]
}

/// Range step (m) read as a jump next to `end`.
fn jump_for(end: &ScanPoint) -> f64 {
    MIN_JUMP.max(5.0 * end.sigma_range)
}

/// Distance (m) from a line beyond which a point next to `end` is off it.
fn off_line_for(end: &ScanPoint) -> f64 {
    MIN_OFF_LINE.max(3.0 * end.sigma_range)
}

/// The corner where a short face turns away from `line` at its end, if
/// the beams past `end` (in direction `step`) trace one: [`FACE_BEAMS`]
/// usable beams, each within a jump of the range before it (one surface),
/// on a straight chord within the off-line distance of every one of them,
/// at least [`MIN_FACE_SIN`] across the wall, and leaving the wall's
/// extension by more than 1.5 times that distance (a departure, not
/// noise). The corner is where the face's chord line meets the wall's
/// line, between the last point on the wall and the first on the face;
/// its σ along the wall comes from the range noise of the face's points
/// and the wall's offset.
fn face_corner(
    scan: &RangeScan,
    mount: &Pose2,
    cfg: &ExtractionConfig,
    end: &ScanPoint,
    line: &CogLine,
    step: isize,
) -> Option<SeenEnd> {
    let (jump, off_line) = (jump_for(end), off_line_for(end));
    let mut face = [[0.0; 2]; FACE_BEAMS];
    let mut previous = range_of(mount, end.p);
    for (k, slot) in face.iter_mut().enumerate() {
        let i = end.beam_index.checked_add_signed(step * (k as isize + 1))?;
        let Some(Ok(r)) = scan.ranges.get(i).copied() else {
            return None;
        };
        if !usable_range(r, cfg) || (r - previous).abs() > jump {
            return None;
        }
        previous = r;
        *slot = beam_point(scan, mount, i, r);
    }
    let (a, b) = (face[0], face[FACE_BEAMS - 1]);
    let chord = [b[0] - a[0], b[1] - a[1]];
    let length = chord[0].hypot(chord[1]);
    if length <= 1.5 * off_line {
        return None;
    }
    let u = [chord[0] / length, chord[1] / length];
    let straight = face
        .iter()
        .all(|q| ((q[0] - a[0]) * u[1] - (q[1] - a[1]) * u[0]).abs() <= off_line);
    let d = line.direction();
    let cross = d[0] * u[1] - d[1] * u[0];
    if !straight || cross.abs() < MIN_FACE_SIN || line.distance_to_point(b) <= 1.5 * off_line {
        return None;
    }
    // The face's line through its centroid, met with the wall's line.
    let n = FACE_BEAMS as f64;
    let centroid = face
        .iter()
        .fold([0.0, 0.0], |c, q| [c[0] + q[0] / n, c[1] + q[1] / n]);
    let w = [centroid[0] - line.xc, centroid[1] - line.yc];
    let s_corner = (w[0] * u[1] - w[1] * u[0]) / cross;
    let t_corner = (w[0] * d[1] - w[1] * d[0]) / cross;
    let beyond = step as f64 * (s_corner - line.along(end.p));
    let first = step as f64 * (line.along(a) - line.along(end.p));
    if !(-off_line..=first.max(0.0) + off_line).contains(&beyond) {
        return None;
    }
    // Offset of the face's line at the corner: the centroid's noise and
    // the chord's direction noise over the distance to the corner; the
    // wall's offset noise moves the corner along the face.
    let sigma_r = end.sigma_range;
    let sigma_dir = std::f64::consts::SQRT_2 * sigma_r / length;
    let across_face = (sigma_r * sigma_r / n + (t_corner * sigma_dir).powi(2)).sqrt();
    let cos = (d[0] * u[0] + d[1] * u[1]).abs();
    let sigma = across_face.hypot(line.sigma_c * cos) / cross.abs();
    sigma.is_finite().then_some(SeenEnd {
        sigma,
        beyond_last_point: beyond,
        gap: None,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::{SeenEnd, wall_end};
    use crate::geometry::points::ScanPoint;
    use crate::geometry::{CogLine, ExtractionConfig, Pose2, extract_lines};
    use crate::sim::{Rng, ScanSpec, World, cast_scan};

    fn lines_seen(world: &World, pose: Pose2) -> Vec<CogLine> {
        noisy_lines_seen(world, pose, 0.0, 1)
    }

    /// A corridor wall at y = -1 from x = 0 to 12 with a door recess 0.9 m
    /// wide and 0.15 m deep at x 5–5.9.
    fn wall_with_door_recess() -> World {
        let mut world = World::new();
        world.add_polyline(
            &[
                [0.0, -1.0],
                [5.0, -1.0],
                [5.0, -1.15],
                [5.9, -1.15],
                [5.9, -1.0],
                [12.0, -1.0],
            ],
            false,
        );
        world
    }

    /// The lines (robot frame) of a 0.5° scan from `pose` with range noise
    /// `sigma` (m), drawn from `seed`.
    fn noisy_lines_seen(world: &World, pose: Pose2, sigma: f64, seed: u64) -> Vec<CogLine> {
        let scan = cast_scan(
            world,
            &pose,
            &ScanSpec::lms200_half_degree(sigma),
            0.0,
            &mut Rng::new(seed),
        );
        extract_lines(&scan, &Pose2::IDENTITY, &ExtractionConfig::default())
    }

    /// The line (robot frame) whose centre is nearest `p`.
    fn nearest(lines: &[CogLine], p: [f64; 2]) -> CogLine {
        *lines
            .iter()
            .min_by(|a, b| {
                let da = (a.xc - p[0]).hypot(a.yc - p[1]);
                let db = (b.xc - p[0]).hypot(b.yc - p[1]);
                da.total_cmp(&db)
            })
            .unwrap()
    }

    #[test]
    fn corners_and_jambs_are_wall_ends_occlusions_and_the_view_edge_are_not() {
        // A wall ahead (x = 4) from y = -3 to y = 1, where a slanted wall
        // meets it (a corner, the next beam at about the same range); at
        // y = -3 it stops, and the next beam sees a wall 1.5 m behind (a
        // jamb).
        let mut world = World::new();
        world.add_polyline(&[[2.0, 2.0], [4.0, 1.0], [4.0, -3.0]], false);
        world.add_wall([5.5, -2.0], [5.5, -6.0]);
        let lines = lines_seen(&world, Pose2::IDENTITY);
        let front = nearest(&lines, [4.0, -1.0]);
        // Scan order runs right to left: the start is the jamb end (y = -3),
        // the end the corner (y = 1).
        assert!((front.start[1] + 3.0).abs() < 0.1, "{front:?}");
        assert!(front.wall_ends.start.is_some(), "jamb: {front:?}");
        assert!(front.wall_ends.end.is_some(), "corner: {front:?}");
        for s in [front.wall_ends.start, front.wall_ends.end]
            .into_iter()
            .flatten()
        {
            assert!(s > 0.0 && s < 0.05, "σ {s}");
        }

        // A box in front hides the middle of the wall: the two pieces end
        // at the occlusion, which is not an end of the wall.
        world.add_box([2.0, -1.0], [0.2, 0.2], 0.0);
        let lines = lines_seen(&world, Pose2::IDENTITY);
        let right = nearest(&lines, [4.0, -2.5]);
        let left = nearest(&lines, [4.0, 0.5]);
        assert!(
            right.wall_ends.start.is_some() && right.wall_ends.end.is_none(),
            "{right:?}"
        );
        assert!(
            left.wall_ends.start.is_none() && left.wall_ends.end.is_some(),
            "{left:?}"
        );

        // A wall running on past the field of view has no end there.
        let mut long = World::new();
        long.add_wall([-5.0, -2.0], [20.0, -2.0]);
        let lines = lines_seen(&long, Pose2::IDENTITY);
        let wall = nearest(&lines, [2.0, -2.0]);
        assert!(
            wall.wall_ends.start.is_none() && wall.wall_ends.end.is_none(),
            "{wall:?}"
        );
    }

    #[test]
    fn one_noisy_beam_past_a_line_is_no_corner() {
        // A wall 0.4 m to the right, seen across the whole field of view:
        // the first beam (−90°) meets it at (0, −0.4). Read 3.5 cm long
        // (3.5 σ of the LMS200's range noise), that beam is trimmed off the
        // line and lies off its extension like a corner's next surface;
        // with no beam after it to show the wall going on, it is no end.
        let mut world = World::new();
        world.add_wall([-5.0, -0.4], [12.0, -0.4]);
        world.add_wall([12.0, -3.0], [12.0, 3.0]);
        let spec = ScanSpec::lms200_half_degree(0.0);
        let mut scan = cast_scan(&world, &Pose2::IDENTITY, &spec, 0.0, &mut Rng::new(1));
        let config = ExtractionConfig::default();
        let wall_line = |scan: &crate::geometry::RangeScan| {
            let lines = extract_lines(scan, &Pose2::IDENTITY, &config);
            nearest(&lines, [1.0, -0.4])
        };
        assert!(wall_line(&scan).wall_ends.start.is_none());
        scan.ranges[0] = Ok(0.435);
        let wall = wall_line(&scan);
        assert!(wall.start[0] > 0.0, "the beam is trimmed: {wall:?}");
        assert!(wall.wall_ends.start.is_none(), "{wall:?}");
    }

    #[test]
    fn a_door_recess_s_corners_seen_from_afar_are_placed_at_them() {
        // A corridor wall at y = -1 with a door recess 0.15 m deep at
        // x 5-5.9, seen from 3-4.4 m before its far end. Past the end of
        // the recess's back wall, and before the start of the wall beyond,
        // the next beam meets the recess's end face (square to both) at
        // about the same range, well before it would meet the wall's
        // extension. Both corners at x = 5.9 are put where that beam's
        // point is along the wall; half a spacing past the last point put
        // them 3 and 4.5 cm beyond on average.
        let world = wall_with_door_recess();
        // Per corner: views that found it, and the sum of how far beyond
        // it (outward along its wall) they put it.
        let mut back = (0, 0.0);
        let mut beyond = (0, 0.0);
        for k in 0..30 {
            let pose = Pose2::new(1.5 + 0.05 * k as f64, 0.5, 0.0);
            for l in noisy_lines_seen(&world, pose, 0.01, k) {
                // Scan order runs along +x on this side: the back wall's
                // end is its corner, the wall beyond's start is.
                let (start, end) = (pose.transform_point(l.start), pose.transform_point(l.end));
                let near =
                    |p: [f64; 2], y: f64| (p[1] - y).abs() < 0.03 && (p[0] - 5.9).abs() < 0.3;
                if l.wall_ends.end.is_some() && near(end, -1.15) {
                    back = (back.0 + 1, back.1 + end[0] - 5.9);
                }
                if l.wall_ends.start.is_some() && near(start, -1.0) {
                    beyond = (beyond.0 + 1, beyond.1 + 5.9 - start[0]);
                }
            }
        }
        for (name, (n, sum)) in [("back wall's end", back), ("next wall's start", beyond)] {
            assert!(n >= 8, "the {name} found in {n} views");
            let mean = sum / n as f64;
            assert!(
                mean.abs() < 0.01,
                "the {name} {mean} m beyond the corner on average"
            );
        }
    }

    #[test]
    fn a_jamb_whose_side_is_in_view_is_a_wall_end_and_a_straight_wall_is_not() {
        // Standing in front of a door recess (a corridor wall at y = -1
        // with a 0.9 m recess 0.15 m deep, x 5–5.9), facing it: past each
        // wall's end the next beams run along the jamb's side, too short
        // for a line, the first of them only a beam spacing off the wall.
        let world = wall_with_door_recess();
        // Over views across the doorway, about half the jambs are found
        // (35 of 66; the next beam alone found 5: a beam spacing off the
        // wall is within its noise; the rest are lost where the split or
        // the end trimming leaves wall points before the face).
        let (mut views, mut found) = (0, 0);
        for k in 0..11 {
            for heading in [-100.0f64, -90.0, -80.0] {
                let x = 5.2 + 0.05 * k as f64;
                let pose = Pose2::new(x, -0.4, heading.to_radians());
                let lines = noisy_lines_seen(&world, pose, 0.01, k);
                let at = |p: [f64; 2], x: f64| {
                    let w = pose.transform_point(p);
                    (w[0] - x).abs() < 0.05 && (w[1] + 1.0).abs() < 0.05
                };
                // The wall before the door ends at x = 5, the one after it
                // starts at x = 5.9 (scan order runs along +x here).
                let before = lines
                    .iter()
                    .any(|l| at(l.end, 5.0) && l.wall_ends.end.is_some());
                let after = lines
                    .iter()
                    .any(|l| at(l.start, 5.9) && l.wall_ends.start.is_some());
                views += 2;
                found += usize::from(before) + usize::from(after);
            }
        }
        assert!(found * 10 >= views * 4, "{found} of {views} jambs found");

        // A long straight wall seen across the whole field of view, with
        // the same noise, ends only at the view's edges: no end anywhere.
        let mut long = World::new();
        long.add_wall([-20.0, -1.0], [20.0, -1.0]);
        for seed in 0..20 {
            let pose = Pose2::new(0.0, 0.0, -90f64.to_radians());
            for l in noisy_lines_seen(&long, pose, 0.01, seed) {
                assert!(
                    l.wall_ends.start.is_none() && l.wall_ends.end.is_none(),
                    "seed {seed}: {l:?}"
                );
            }
        }
    }

    /// The last beam of a noise-free 0.5° scan of `world` from (1.5, 0)
    /// that meets the line y = −1 before `x` (robot frame), as the end of
    /// a line along it, and what [`wall_end`] makes of that end.
    fn end_of_wall_at(world: &World, x: f64) -> (Option<SeenEnd>, CogLine) {
        let scan = cast_scan(
            world,
            &Pose2::new(1.5, 0.0, 0.0),
            &ScanSpec::lms200_half_degree(0.0),
            0.0,
            &mut Rng::new(1),
        );
        let point = |i: usize| {
            let r = *scan.ranges[i].as_ref().ok()?;
            let (s, c) = scan.angle(i).sin_cos();
            Some(([r * c, r * s], [c, s]))
        };
        let i = (0..scan.ranges.len())
            .filter(|&i| point(i).is_some_and(|(p, _)| (p[1] + 1.0).abs() < 1e-6 && p[0] <= x))
            .max_by(|&a, &b| point(a).unwrap().0[0].total_cmp(&point(b).unwrap().0[0]))
            .unwrap();
        let (p, beam) = point(i).unwrap();
        let end = ScanPoint {
            p,
            beam,
            sigma_range: 0.01,
            beam_index: i,
        };
        let line = CogLine::from_centre(
            0.0,
            [0.5 * p[0], -1.0],
            -0.5 * p[0],
            0.5 * p[0],
            0.002,
            0.001,
            100,
        );
        let end = wall_end(
            &scan,
            &Pose2::IDENTITY,
            &ExtractionConfig::default(),
            &end,
            &line,
            1,
        );
        (end, line)
    }

    #[test]
    fn a_line_trimmed_short_of_a_grazing_wall_s_end_is_no_jamb() {
        // 3.7 m down a corridor wall the beams meet it 12 cm apart, and
        // the next beam's range exceeds the last point's by more than a
        // jamb's jump. If that point is still on the wall (a last point
        // trimmed off the line for its noise), the line's end is none of
        // the wall's; where the wall does end (a door recess 3.5 m ahead),
        // the next beam passes its line and the end is a jamb.
        let mut long = World::new();
        long.add_wall([-5.0, -1.0], [40.0, -1.0]);
        assert!(end_of_wall_at(&long, 3.7).0.is_none());
        let (jamb, line) = end_of_wall_at(&wall_with_door_recess(), 3.5);
        let gap = jamb.expect("a jamb").gap.expect("its gap");
        let at = line.along([3.5, -1.0]);
        assert!(
            gap.last < at && at < gap.past,
            "the gap holds the end: {gap:?}"
        );
    }

    #[test]
    fn a_jamb_seen_from_far_and_near_is_placed_at_the_same_place() {
        // A corridor wall at y = -1 ending in a jamb at x = 5 (the wall
        // behind the doorway 0.5 m deeper). From far along the corridor
        // the beams meet the wall at a grazing angle, some 10 cm apart
        // near the jamb; from near, 2–3 cm apart. The last point on the
        // wall falls short of the jamb by up to one spacing; the end is
        // put half a spacing beyond it, so the views agree on average.
        let mut world = World::new();
        world.add_wall([-2.0, -1.0], [5.0, -1.0]);
        world.add_wall([5.0, -1.5], [9.0, -1.5]);
        let end_seen_from = |x: f64, jitter: f64| {
            let pose = Pose2::new(x + jitter, 0.0, 0.0);
            let lines = lines_seen(&world, pose);
            let wall = nearest(&lines, [3.0 - x - jitter, -1.0]);
            assert!(
                wall.wall_ends.end.is_some(),
                "a jamb from x = {x}: {wall:?}"
            );
            x + jitter + wall.end[0]
        };
        for x in [1.4, 3.5] {
            // The beam grid moves over the jamb with the robot: average
            // over positions a spacing apart.
            let n = 20;
            let mean: f64 = (0..n)
                .map(|k| end_seen_from(x, 0.005 * k as f64))
                .sum::<f64>()
                / n as f64;
            assert!(
                (mean - 5.0).abs() < 0.015,
                "from x = {x}: the jamb at {mean}"
            );
        }
    }

    #[test]
    fn a_corner_seen_from_afar_is_placed_where_its_faces_meet() {
        // A corridor wall at y = 1 with a 0.9 m doorway (x 14.6–15.5); the
        // wall beyond the door starts at x = 15.5, where the room's side
        // wall (x = 15.5, 0.6 m of it in view) faces down the corridor
        // through the door. Seen from 4.5–6 m away at a grazing angle,
        // consecutive beams meet the wall some 15 cm apart near the
        // corner: its last point tells where the wall starts only to
        // ±8 cm, the face seen through the door to about a centimetre.
        let mut world = World::new();
        world.add_wall([4.0, 1.0], [14.6, 1.0]);
        world.add_polyline(&[[15.5, 1.6], [15.5, 1.0], [22.0, 1.0]], false);
        let (mut n, mut sum, mut z2) = (0, 0.0, 0.0);
        for k in 0..40 {
            let pose = Pose2::new(9.5 + 0.04 * k as f64, -0.9, 30f64.to_radians());
            let lines = noisy_lines_seen(&world, pose, 0.01, k);
            let wall = nearest(&lines, pose.inverse().transform_point([18.0, 1.0]));
            // Scan order runs along −x on this wall: the corner is its end.
            let (Some(sigma), at) = (wall.wall_ends.end, pose.transform_point(wall.end)) else {
                continue;
            };
            let error = at[0] - 15.5;
            n += 1;
            sum += error.abs();
            z2 += (error / sigma).powi(2);
        }
        let mean = sum / n.max(1) as f64;
        let rms_z = (z2 / n.max(1) as f64).sqrt();
        eprintln!("corner found in {n} of 40 views, {mean} m off, rms z {rms_z}");
        assert!(n >= 30, "the corner found in {n} of 40 views");
        assert!(mean < 0.02, "{mean} m off on average");
        assert!((0.3..2.0).contains(&rms_z), "σ off by {rms_z}");
    }
}
