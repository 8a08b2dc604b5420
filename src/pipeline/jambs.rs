//! Jambs followed from scan to scan.
//!
//! One scan places a jamb only within the gap between the last beam on its
//! wall and the next beam, which passed the end: some 20 cm from 5 m along
//! a corridor. Scans a centimetre or two apart see nearly the same gap, so
//! one scan's error is shared by the dozen after it, and localization
//! counts it a dozen times (in the simulated corridor, a map end 27 mm off
//! took the pose 26 mm off within a second). But the end lies in every
//! scan's gap: carried from scan to scan by the odometry, the gaps'
//! intersection narrows to where the end is within a few scans, as the
//! beams sweep over it with the robot's motion.
//!
//! Followed so, a jamb is a wall end only once a second scan's gap agrees
//! with the first: at a grazing view consecutive beams on one wall differ
//! in range by nearly their spacing, and one range a few σ long there
//! reads as a jump. Unconfirmed, such a jamb entered the map with the σ of
//! one gap, and confirmed ones then pulled the pose 12 cm to it in one
//! scan (simulator seed 24). Scans too far apart to follow (thinned logs,
//! or none before) keep each jamb as one scan sees it.

use crate::geometry::{CogLine, Pose2, SeenJamb};

/// Largest step between scans (m) over which a gap is carried: beyond it
/// (scans kept far apart, as in thinned logs) each scan stands alone.
const MAX_STEP: f64 = 0.25;
/// Largest turn between scans (rad) over which a gap is carried.
const MAX_TURN: f64 = 0.2;
/// Share of a step's length, and of its turn times the range, by which a
/// carried gap widens on each side: odometry's error over the step.
const STEP_SHARE: f64 = 0.03;
/// A track and a jamb are one when their walls run within this angle
/// (rad) ...
const MAX_ANGLE: f64 = 0.1;
/// ... the track's gap lies within this distance (m) of the jamb's line ...
const MAX_OFFSET: f64 = 0.05;
/// ... and their gaps overlap, or miss by at most this many σ of the
/// crossings' noise.
const GAP_SIGMAS: f64 = 2.0;
/// Scans a track outlives its jamb's absence (hidden a moment, or its
/// end not read as a jamb in one scan).
const MAX_MISSED: u32 = 3;

/// One jamb's gap carried over the scans that saw it.
#[derive(Debug, Clone, Copy)]
struct Track {
    /// The gap's ends on the wall's line (robot frame of the last scan):
    /// `inner` the wall's side, `outer` the side past its end.
    inner: [f64; 2],
    outer: [f64; 2],
    /// The same intersection carried by the odometry's motion as it is,
    /// not widened: where the jamb is placed (see [`JambTracks::follow`]).
    exact: [[f64; 2]; 2],
    /// Unit vector along the wall, from `inner` to `outer`.
    outward: [f64; 2],
    /// Scans since the jamb was last seen.
    missed: u32,
}

/// The jambs in view, each with the intersection of the gaps the scans
/// that saw it placed it in.
#[derive(Debug, Default)]
pub(crate) struct JambTracks {
    tracks: Vec<Track>,
    next: Vec<Track>,
    /// The odometry pose of the last scan.
    odometry: Option<Pose2>,
}

impl JambTracks {
    /// Forgets every track: the next scan starts afresh.
    pub fn forget(&mut self) {
        self.tracks.clear();
        self.odometry = None;
    }

    /// Carries the tracks to this scan by the odometry's motion since the
    /// last one (`odometry`: this scan's odometry pose, `None` when it has
    /// none or none fresh), intersects each with the gap of the jamb it
    /// is, and places each such jamb's end in `lines` (robot frame, as
    /// extracted, `jambs` their jambs) at the middle of the intersection
    /// of the gaps as the odometry carried them, with the σ of a uniform
    /// spread over their intersection widened for the odometry's error. A
    /// jamb no track agrees with starts one, and is no wall end yet.
    pub fn follow(&mut self, odometry: Option<Pose2>, lines: &mut [CogLine], jambs: &[SeenJamb]) {
        let motion = match (self.odometry, odometry) {
            (Some(before), Some(now)) => Some(before.between(&now)),
            _ => None,
        }
        .filter(|m| m.x.hypot(m.y) <= MAX_STEP && m.theta.abs() <= MAX_TURN);
        self.odometry = odometry;
        let Some(motion) = motion else {
            self.tracks.clear();
            self.start_tracks(lines, jambs);
            return;
        };
        let back = motion.inverse();
        let turn = Pose2::new(0.0, 0.0, back.theta);
        let step = motion.x.hypot(motion.y);
        for t in &mut self.tracks {
            let (inner, outer) = (back.transform_point(t.inner), back.transform_point(t.outer));
            t.exact = t.exact.map(|p| back.transform_point(p));
            let outward = turn.transform_point(t.outward);
            let range = outer[0].hypot(outer[1]);
            let widen = STEP_SHARE * (step + motion.theta.abs() * range);
            t.inner = [inner[0] - widen * outward[0], inner[1] - widen * outward[1]];
            t.outer = [outer[0] + widen * outward[0], outer[1] + widen * outward[1]];
            t.outward = outward;
            t.missed += 1;
        }
        self.next.clear();
        let cos_max = MAX_ANGLE.cos();
        for jamb in jambs {
            let Some(line) = lines.get_mut(jamb.line) else {
                continue;
            };
            // Positions outward along the wall (m): the jamb's gap, and
            // the best overlapping track's.
            let (sign, lo, hi) = outward_gap(jamb);
            let d = line.direction();
            let outward = [sign * d[0], sign * d[1]];
            let slack = GAP_SIGMAS * jamb.gap.sigma;
            let best = self
                .tracks
                .iter()
                .enumerate()
                .filter(|(_, t)| {
                    t.missed > 0
                        && t.outward[0] * outward[0] + t.outward[1] * outward[1] >= cos_max
                        && line.distance_to_point(t.inner) <= MAX_OFFSET
                        && line.distance_to_point(t.outer) <= MAX_OFFSET
                })
                .map(|(i, t)| {
                    let (a, b) = (sign * line.along(t.inner), sign * line.along(t.outer));
                    (i, a, b, hi.min(b) - lo.max(a))
                })
                .filter(|&(.., overlap)| overlap >= -slack)
                .max_by(|x, y| x.3.total_cmp(&y.3));
            let (inner, outer, exact) = match best {
                Some((i, a, b, _)) => {
                    self.tracks[i].missed = 0;
                    let (inner, outer) = meet(lo.max(a), hi.min(b));
                    // Placed within the intersection carried unwidened
                    // when the gap meets it: the widening is a bound on
                    // the odometry's error, not its likely size, and
                    // where the beams stay put on one side of the end
                    // (a turn by a whole number of beam spacings a scan)
                    // the widened side alone moves, and its middle with
                    // it: 3 cm within 20 scans in the simulated corridor.
                    let [ea, eb] = self.tracks[i].exact.map(|p| sign * line.along(p));
                    let exact = if lo.max(ea) <= hi.min(eb) {
                        (lo.max(ea), hi.min(eb))
                    } else {
                        (inner, outer)
                    };
                    let sigma = ((outer - inner) / 12f64.sqrt()).hypot(jamb.gap.sigma);
                    set_end(
                        line,
                        jamb.at_start,
                        sign * 0.5 * (exact.0 + exact.1),
                        Some(sigma),
                    );
                    (inner, outer, exact)
                }
                None => {
                    // A first sighting: not a wall end until the next
                    // scan's gap agrees.
                    set_end(line, jamb.at_start, jamb.gap.last, None);
                    (lo, hi, (lo, hi))
                }
            };
            self.next.push(Track::on(line, sign, (inner, outer), exact));
        }
        // Tracks unseen this scan wait a few scans for their jamb.
        self.next.extend(
            self.tracks
                .iter()
                .filter(|t| t.missed > 0 && t.missed <= MAX_MISSED),
        );
        std::mem::swap(&mut self.tracks, &mut self.next);
    }

    fn start_tracks(&mut self, lines: &[CogLine], jambs: &[SeenJamb]) {
        for jamb in jambs {
            let Some(line) = lines.get(jamb.line) else {
                continue;
            };
            let (sign, lo, hi) = outward_gap(jamb);
            self.tracks.push(Track::on(line, sign, (lo, hi), (lo, hi)));
        }
    }
}

impl Track {
    /// A fresh track of the gap `(inner, outer)`, and `exact` its
    /// unwidened part (m outward along `line`; `sign` −1 for a jamb at its
    /// start, +1 at its end).
    fn on(line: &CogLine, sign: f64, (inner, outer): (f64, f64), exact: (f64, f64)) -> Track {
        let d = line.direction();
        Track {
            inner: line_point(line, sign * inner),
            outer: line_point(line, sign * outer),
            exact: [
                line_point(line, sign * exact.0),
                line_point(line, sign * exact.1),
            ],
            outward: [sign * d[0], sign * d[1]],
            missed: 0,
        }
    }
}

/// The intersection `(inner, outer)` of two gaps; gaps that miss by less
/// than their noise (see `GAP_SIGMAS`) meet at the middle of the miss.
fn meet(inner: f64, outer: f64) -> (f64, f64) {
    if inner <= outer {
        (inner, outer)
    } else {
        let mid = 0.5 * (inner + outer);
        (mid, mid)
    }
}

/// A jamb's gap outward along its line (m): the sign that turns positions
/// along the line outward (−1 at its start, +1 at its end), and the gap's
/// inner and outer ends.
fn outward_gap(jamb: &SeenJamb) -> (f64, f64, f64) {
    let sign = if jamb.at_start { -1.0 } else { 1.0 };
    (sign, sign * jamb.gap.last, sign * jamb.gap.past)
}

/// The point `along` m along `line` from its centre.
fn line_point(line: &CogLine, along: f64) -> [f64; 2] {
    let d = line.direction();
    [line.xc + along * d[0], line.yc + along * d[1]]
}

/// Puts the start (`at_start`) or end of `line` at `along` m along it: a
/// true end of its wall with σ `sigma` (m), or, with `None`, not one.
fn set_end(line: &mut CogLine, at_start: bool, along: f64, sigma: Option<f64>) {
    let p = line_point(line, along);
    if at_start {
        line.start = p;
        line.wall_ends.start = sigma;
    } else {
        line.end = p;
        line.wall_ends.end = sigma;
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::geometry::{ExtractionConfig, LineExtractor};
    use crate::sim::{Rng, ScanSpec, World, cast_scan};

    /// The end of the corridor wall that stops at x = 5 (the wall behind
    /// the doorway 0.5 m deeper), placed by each scan of a drive along
    /// the corridor from x = 1 to 2.5 m at 1.6 cm a scan with 1 cm of range
    /// noise: the rms error (m) and rms z of the ends placed, followed
    /// from scan to scan or (`follow` false) each scan on its own.
    fn jamb_errors(follow: bool, odometry_scale: f64) -> (f64, f64, usize) {
        let mut world = World::new();
        world.add_wall([-2.0, -1.0], [5.0, -1.0]);
        world.add_wall([5.0, -1.5], [9.0, -1.5]);
        world.add_wall([-2.0, 1.0], [12.0, 1.0]);
        let spec = ScanSpec::lms200_half_degree(0.01);
        let config = ExtractionConfig::default();
        let mut extractor = LineExtractor::new();
        let mut tracks = JambTracks::default();
        let mut rng = Rng::new(7);
        let (mut n, mut e2, mut z2) = (0, 0.0, 0.0);
        let mut lines = Vec::new();
        for k in 0..95 {
            let pose = Pose2::new(1.0 + 0.016 * k as f64, 0.0, 0.0);
            let scan = cast_scan(&world, &pose, &spec, 0.0, &mut rng);
            extractor.extract(&scan, &Pose2::IDENTITY, &config, &mut lines);
            if follow {
                let odometry = Pose2::new(odometry_scale * pose.x, 0.0, 0.0);
                tracks.follow(Some(odometry), &mut lines, extractor.jambs());
            }
            for l in &lines {
                let end = pose.transform_point(l.end);
                if let Some(sigma) = l.wall_ends.end
                    && (end[1] + 1.0).abs() < 0.05
                    && (end[0] - 5.0).abs() < 0.3
                    && k >= 20
                {
                    let e = end[0] - 5.0;
                    n += 1;
                    e2 += e * e;
                    z2 += (e / sigma).powi(2);
                }
            }
        }
        let n_f = n.max(1) as f64;
        ((e2 / n_f).sqrt(), (z2 / n_f).sqrt(), n)
    }

    /// A wall along x at y = -1 (robot frame) ending between x = `last`
    /// and `past`, as extracted: its end put at the middle of that gap.
    fn wall_ending(last: f64, past: f64) -> (Vec<CogLine>, Vec<SeenJamb>) {
        let mut line =
            CogLine::from_centre(0.0, [0.0, -1.0], -1.0, 0.5 * (last + past), 1e-3, 1e-3, 100);
        line.wall_ends.end = Some((past - last) / 12f64.sqrt());
        let jamb = SeenJamb {
            line: 0,
            at_start: false,
            gap: crate::geometry::JambGap {
                last,
                past,
                sigma: 0.002,
            },
        };
        (vec![line], vec![jamb])
    }

    #[test]
    fn a_jamb_is_a_wall_end_once_a_second_scan_agrees() {
        let mut tracks = JambTracks::default();
        // The first scan: nothing to follow, the jamb as seen.
        let (mut lines, jambs) = wall_ending(3.0, 3.1);
        tracks.follow(Some(Pose2::IDENTITY), &mut lines, &jambs);
        assert!((lines[0].end[0] - 3.05).abs() < 1e-9);
        assert!(lines[0].wall_ends.end.is_some());
        // 2 cm on, the first gap lies at 2.98–3.08 m; a gap at 3.02–3.12 m
        // narrows it to 3.02–3.08 m, where the jamb is placed, and to
        // 3.02–3.0806 m with the first widened by 3 % of the step on each
        // side, whose width gives its σ.
        let (mut lines, jambs) = wall_ending(3.02, 3.12);
        let moved = Pose2::new(0.02, 0.0, 0.0);
        tracks.follow(Some(moved), &mut lines, &jambs);
        let sigma = lines[0].wall_ends.end.unwrap();
        assert!((lines[0].end[0] - 3.05).abs() < 1e-6, "{:?}", lines[0]);
        let expected = (0.0606f64 / 12f64.sqrt()).hypot(0.002);
        assert!((sigma - expected).abs() < 1e-6, "σ {sigma}");
        // A jamb 30 cm off, one scan later: no wall end yet, the line ends
        // at its last beam.
        let (mut lines, jambs) = wall_ending(2.7, 2.8);
        tracks.follow(Some(Pose2::new(0.04, 0.0, 0.0)), &mut lines, &jambs);
        assert!(lines[0].wall_ends.end.is_none());
        assert!((lines[0].end[0] - 2.7).abs() < 1e-9);
        // Seen again where it was: a wall end.
        let (mut lines, jambs) = wall_ending(2.68, 2.78);
        tracks.follow(Some(Pose2::new(0.06, 0.0, 0.0)), &mut lines, &jambs);
        assert!(lines[0].wall_ends.end.is_some());
        // Odometry that jumped (a restart, or scans far apart): each jamb
        // as one scan sees it.
        let (mut lines, jambs) = wall_ending(1.0, 1.1);
        tracks.follow(Some(Pose2::new(5.0, 0.0, 0.0)), &mut lines, &jambs);
        assert!(lines[0].wall_ends.end.is_some());
        assert!((lines[0].end[0] - 1.05).abs() < 1e-9);
    }

    #[test]
    fn where_the_beams_stay_put_on_one_side_the_jamb_stays_put_too() {
        // A jamb 3 m ahead, approached 2 cm a scan. The second scan's gap
        // narrows the first's to 8 mm; every later scan's beams fall as the
        // first scan's did (the raster moving with the robot), so only the
        // far side of the gap (the beam past the end) is met again and
        // again, while the wall's side is carried from the second scan.
        // Widened by 3 % of each step, that side alone moved 17 mm in 28
        // scans and the middle with it; the
        // jamb is placed within the gaps carried as the odometry moved
        // them.
        let mut tracks = JambTracks::default();
        for k in 0..30 {
            let end = 3.0 - 0.02 * k as f64;
            let (last, past) = if k == 1 {
                (end - 0.003, end + 0.1)
            } else {
                (end - 0.1, end + 0.005)
            };
            let (mut lines, jambs) = wall_ending(last, past);
            tracks.follow(
                Some(Pose2::new(0.02 * k as f64, 0.0, 0.0)),
                &mut lines,
                &jambs,
            );
            if k >= 2 {
                let sigma = lines[0].wall_ends.end.unwrap();
                assert!(
                    (lines[0].end[0] - end).abs() < 0.002,
                    "scan {k}: {:?}",
                    lines[0]
                );
                // Its σ still owns the widening: the odometry may be off.
                assert!(sigma > 0.008 / 12f64.sqrt(), "scan {k}: σ {sigma}");
            }
        }
    }

    #[test]
    fn a_jamb_followed_over_scans_is_placed_closer_than_one_scan_places_it() {
        let (alone, z_alone, n_alone) = jamb_errors(false, 1.0);
        let (followed, z_followed, n) = jamb_errors(true, 1.0);
        // Odometry 3 % long carries the gaps a little wrong.
        let (scaled, z_scaled, _) = jamb_errors(true, 1.03);
        eprintln!(
            "alone {alone:.4} m (z {z_alone:.2}, {n_alone} scans), followed {followed:.4} m \
             (z {z_followed:.2}, {n}), odometry 3 % long {scaled:.4} m (z {z_scaled:.2})"
        );
        assert!(n_alone >= 60 && n >= 60, "{n_alone} and {n} scans");
        assert!(followed < 0.5 * alone, "{followed} against {alone}");
        assert!(scaled < 0.7 * alone, "{scaled} against {alone}");
        for z in [z_alone, z_followed, z_scaled] {
            assert!((0.3..2.5).contains(&z), "rms z {z}");
        }
    }
}
