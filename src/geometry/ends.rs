//! Which ends of an extracted line are true ends of its wall.
//!
//! The beam just past a line's end tells: a range that jumps away (the
//! wall stops and the laser sees past it: a jamb) or a point at about the
//! same range but off the line (the next surface of a corner) make it a
//! true end; a range that jumps nearer (something in front hides the
//! wall), no valid beam (the field of view's edge, no return, the range
//! limit) or a point on the line's extension (the wall goes on) do not. A true end is known to about the beam spacing where
//! the beam meets the wall.

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

/// A true end of a wall as one scan sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SeenEnd {
    /// σ (m) of the end's position along the wall.
    pub sigma: f64,
    /// How far (m) the wall's end lies beyond the last point on it, along
    /// the wall, on average: half a beam spacing there, since the end is
    /// somewhere between that point and where the next beam would have
    /// met the wall. Left uncorrected, the last point falls short of the
    /// end by more the more grazing the view, and views from two places
    /// disagree about where one end is.
    pub beyond_last_point: f64,
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
    let sensor = [mount.x, mount.y];
    let range_end = (end.p[0] - sensor[0]).hypot(end.p[1] - sensor[1]);
    let jump = MIN_JUMP.max(5.0 * end.sigma_range);
    let is_end = if range_next > range_end + jump {
        true
    } else if range_next < range_end - jump {
        // Something nearer: an occlusion. (A concave corner whose next
        // wall comes this much nearer within one beam is read so too:
        // counting those as ends, on CSAIL thinned to sparse scans, made
        // the map metres worse, so the rule stays on the safe side.)
        false
    } else {
        // Only the very next beam decides: looking past beams the end
        // trimming left on the wall found more ends in a simulated
        // corridor but, in the clutter of a real building (CSAIL), false
        // ones that cost more than they gave.
        let (s, c) = (scan.angle(next) + mount.theta).sin_cos();
        let q = [sensor[0] + range_next * c, sensor[1] + range_next * s];
        line.distance_to_point(q) > MIN_OFF_LINE.max(3.0 * end.sigma_range)
    };
    if !is_end {
        return None;
    }
    let d = line.direction();
    let sin_incidence = (end.beam[0] * d[1] - end.beam[1] * d[0]).abs();
    if sin_incidence < MIN_SIN_INCIDENCE {
        return None;
    }
    // Uniform over one beam spacing on the wall, plus the range noise
    // projected along it.
    let spacing = range_end * scan.angle_increment.abs() / sin_incidence;
    let cos_incidence = (1.0 - sin_incidence * sin_incidence).max(0.0).sqrt();
    let along_noise = end.sigma_range * cos_incidence / sin_incidence;
    Some(SeenEnd {
        sigma: (spacing / 12f64.sqrt()).hypot(along_noise),
        beyond_last_point: 0.5 * spacing,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use crate::geometry::{CogLine, ExtractionConfig, Pose2, extract_lines};
    use crate::sim::{Rng, ScanSpec, World, cast_scan};

    fn lines_seen(world: &World, pose: Pose2) -> Vec<CogLine> {
        let scan = cast_scan(
            world,
            &pose,
            &ScanSpec::lms200_half_degree(0.0),
            0.0,
            &mut Rng::new(1),
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
}
