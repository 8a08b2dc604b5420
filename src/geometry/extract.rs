//! Line extraction from one range scan (Zhang & Ghosh §2): valid points,
//! runs split at range discontinuities, recursive split, merge of collinear
//! neighbours, total-least-squares fit, COG lines with propagated variances.

use serde::{Deserialize, Serialize};

use super::cog_line::{CogLine, WallEnds};
use super::ends::{JambGap, wall_end};
use super::fit::{PrefixMoments, cog_line};
use super::points::{ScanPoint, collect_points};
use super::pose::Pose2;
use super::scan::RangeScan;
use super::split::{
    LineTest, Span, assign_break_points, merge_collinear, split_by_fit, split_recursive,
    split_runs, trim_ends,
};

/// Range noise model `σ_r = a + b·r` (standard deviation, m).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RangeNoise {
    /// Constant part (m). Default 0.01: the LMS200 data sheet gives a 1σ
    /// statistical error of 5 mm in mm mode and ±15 mm systematic; 1 cm is
    /// the usual working figure for real scans.
    pub a: f64,
    /// Part proportional to range (m per m). Default 0: the LMS200's error
    /// is specified as constant up to 8 m.
    pub b: f64,
}

impl Default for RangeNoise {
    fn default() -> Self {
        RangeNoise { a: 0.01, b: 0.0 }
    }
}

impl RangeNoise {
    /// Standard deviation of a reading at range `r` (m).
    pub fn sigma(&self, r: f64) -> f64 {
        self.a + self.b * r
    }
}

/// Tuning of the line extractor; all lengths in metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExtractionConfig {
    /// A span is split while its farthest point is more than this far from
    /// the chord. Default 0.04: about four times the range noise, so noise
    /// alone rarely splits a wall, yet a 5 cm step or a door frame does.
    pub split_threshold: f64,
    /// Two touching spans merge when every point of the union lies within
    /// this distance of the union's fitted line (and the fit passes
    /// `max_fit_chi2`). Default 0.04, as the split.
    pub merge_threshold: f64,
    /// Largest reduced χ² of a segment's fit, `Σ(dᵢ/σᵢ)²/(n−2)` with `σᵢ`
    /// the point's across-line range noise; a segment above it is split
    /// again at its worst point. Default 4: a straight wall under the noise
    /// model scores about 1, and a 15 cm door recess merged into a wall by
    /// a coarse split threshold scores well above 4.
    pub max_fit_chi2: f64,
    /// Fewer points than this and a segment is dropped. Default 4: enough
    /// for a variance estimate; `min_span` asks for more at fine beam
    /// spacings.
    pub min_points: usize,
    /// A segment's points must span at least this angle of the sweep (rad);
    /// with `min_points`, the larger count applies. Default 2.5° (0.0436):
    /// 6 points at 0.5°, 4 at 1° — one count for every spacing dropped
    /// most walls of 1° scans (CSAIL decimated to 1° and thinned to 0.5 m
    /// steps: 0.60 m mean relation error with 6 points, 0.057 m with 4),
    /// while 4 points at 0.5° admit chair legs and clutter.
    pub min_span: f64,
    /// Shorter segments are dropped. Default 0.2: shorter ones have poorly
    /// known direction and do not help localization.
    pub min_length: f64,
    /// Consecutive points farther apart than this start a new segment
    /// (occlusion boundary or missing wall). Default 0.3: the spacing of
    /// 0.5° beams on a wall 8 m away seen at 70° incidence is about 0.2 m.
    pub max_point_gap: f64,
    /// Readings shorter than this are dropped (m). Default 0.05: the LMS200
    /// reports dazzle and near-field faults as tiny ranges.
    pub min_range: f64,
    /// Readings longer than this are dropped (m), on top of what the input
    /// already reports as no return: the sensor's reach in its unit mode
    /// (8.183 m in mm mode, 81.83 m in cm mode; the special codes above
    /// them), a log's declared maximum, CARMEN's 81.9 m code. Default
    /// 81.83, the LMS200's largest range, so the data sets the reach: long
    /// beams carry the geometry of halls and long corridors (on CSAIL thinned
    /// to scans 0.5 m apart, 8 m here gave 0.33 m of relation error where
    /// the log's own reach gives 0.09 m).
    pub max_range: f64,
    /// Range noise model used to propagate σθ and σc.
    pub range_noise: RangeNoise,
    /// An end point farther than this many σ (its across-line range noise)
    /// from the line through the rest of its segment is dropped, up to
    /// three per end. Default 3. This catches the first point of the next
    /// surface after a corner, which the split threshold lets through.
    pub end_trim_sigmas: f64,
    /// Distance (m) below which an end point is never trimmed, so noise-free
    /// data does not lose points to rounding; also the floor on a point's
    /// σ in the fit's χ². Default 0.001, the LMS200's resolution in mm mode.
    pub end_trim_floor: f64,
}

impl Default for ExtractionConfig {
    fn default() -> Self {
        ExtractionConfig {
            split_threshold: 0.04,
            merge_threshold: 0.04,
            max_fit_chi2: 4.0,
            min_points: 4,
            min_span: 2.5f64.to_radians(),
            min_length: 0.2,
            max_point_gap: 0.3,
            min_range: 0.05,
            max_range: 81.83,
            range_noise: RangeNoise::default(),
            end_trim_sigmas: 3.0,
            end_trim_floor: 0.001,
        }
    }
}

/// Fewest beams whose sweep spans `span` (rad) at `increment` (rad per
/// beam): one more than the steps needed, so 2.5° at 0.5° is 6 beams.
fn points_for_span(span: f64, increment: f64) -> usize {
    let inc = increment.abs();
    if !(span > 0.0 && inc > 0.0 && span.is_finite() && inc.is_finite()) {
        return 0;
    }
    // Beam angles are not exact multiples; a part in a million is rounding.
    ((span / inc - 1e-6).ceil().min(1e6) as usize) + 1
}

/// A line extractor that keeps its buffers between scans, so extracting in
/// a loop does not allocate once the buffers have grown.
#[derive(Debug, Default)]
pub struct LineExtractor {
    points: Vec<ScanPoint>,
    moments: PrefixMoments,
    runs: Vec<Span>,
    chord_spans: Vec<Span>,
    spans: Vec<Span>,
    stack: Vec<Span>,
    jambs: Vec<SeenJamb>,
}

/// A jamb the last extraction found: at which end of which line, and the
/// gap it lies in.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SeenJamb {
    /// Index of the line in the extraction's output.
    pub line: usize,
    /// Whether the jamb is the line's start (else its end).
    pub at_start: bool,
    /// Where along the line the scan places it.
    pub gap: JambGap,
}

impl LineExtractor {
    /// A new extractor with empty buffers.
    pub fn new() -> Self {
        Self::default()
    }

    /// The jambs found by the last [`extract`](Self::extract), in the
    /// order of their lines.
    pub fn jambs(&self) -> &[SeenJamb] {
        &self.jambs
    }

    /// Extracts the lines of `scan` into `out` (cleared first), robot frame,
    /// scan order. See [`extract_lines`].
    pub fn extract(
        &mut self,
        scan: &RangeScan,
        mount: &Pose2,
        cfg: &ExtractionConfig,
        out: &mut Vec<CogLine>,
    ) {
        out.clear();
        self.jambs.clear();
        self.points.clear();
        self.runs.clear();
        self.chord_spans.clear();
        self.spans.clear();
        collect_points(scan, mount, cfg, &mut self.points);
        let points = &self.points;
        self.moments.rebuild(points);
        split_runs(points, cfg.max_point_gap, &mut self.runs);
        for &run in &self.runs {
            split_recursive(
                points,
                run,
                cfg.split_threshold,
                &mut self.stack,
                &mut self.chord_spans,
            );
        }
        let min_points = cfg
            .min_points
            .max(2)
            .max(points_for_span(cfg.min_span, scan.angle_increment));
        let merge_test = LineTest {
            max_distance: cfg.merge_threshold,
            max_chi2: cfg.max_fit_chi2,
            sigma_floor: cfg.end_trim_floor,
        };
        split_by_fit(
            points,
            &self.moments,
            &merge_test,
            min_points,
            &self.chord_spans,
            &mut self.stack,
            &mut self.spans,
        );
        merge_collinear(points, &self.moments, &merge_test, &mut self.spans);
        assign_break_points(points, &self.moments, &mut self.spans);
        trim_ends(
            points,
            &self.moments,
            cfg.end_trim_sigmas,
            cfg.end_trim_floor,
            &mut self.spans,
        );
        for span in &self.spans {
            if span.len() < min_points {
                continue;
            }
            let Some(fit) = self.moments.fit(span.first, span.last) else {
                continue;
            };
            let Some(mut line) = cog_line(&points[span.first..=span.last], &fit) else {
                continue;
            };
            if line.length() >= cfg.min_length {
                let start = wall_end(scan, mount, cfg, &points[span.first], &line, -1);
                let end = wall_end(scan, mount, cfg, &points[span.last], &line, 1);
                // A true end is placed where it lies on average, not at
                // the last point on the wall (see `SeenEnd`).
                let d = line.direction();
                if let Some(e) = start {
                    line.start = [
                        line.start[0] - d[0] * e.beyond_last_point,
                        line.start[1] - d[1] * e.beyond_last_point,
                    ];
                }
                if let Some(e) = end {
                    line.end = [
                        line.end[0] + d[0] * e.beyond_last_point,
                        line.end[1] + d[1] * e.beyond_last_point,
                    ];
                }
                line.wall_ends = WallEnds {
                    start: start.map(|e| e.sigma),
                    end: end.map(|e| e.sigma),
                };
                // A corner placed where a face meets the wall may lie a
                // little before the last point on it.
                if line.length() >= cfg.min_length {
                    for (at_start, seen) in [(true, start), (false, end)] {
                        if let Some(gap) = seen.and_then(|e| e.gap) {
                            self.jambs.push(SeenJamb {
                                line: out.len(),
                                at_start,
                                gap,
                            });
                        }
                    }
                    out.push(line);
                }
            }
        }
    }
}

/// Extracts the COG lines of `scan` in the robot frame (`mount` is the
/// laser's pose in the robot frame), in scan order, free space on the left
/// of each line. Faulty, non-finite and out-of-limit beams are dropped
/// before fitting; segments shorter or with fewer points than the limits
/// are dropped after.
pub fn extract_lines(scan: &RangeScan, mount: &Pose2, cfg: &ExtractionConfig) -> Vec<CogLine> {
    let mut out = Vec::new();
    LineExtractor::new().extract(scan, mount, cfg, &mut out);
    out
}

/// The valid points of `scan` in the robot frame, in scan order, filtered
/// exactly as [`extract_lines`] filters them.
pub fn scan_points(scan: &RangeScan, mount: &Pose2, cfg: &ExtractionConfig) -> Vec<[f64; 2]> {
    let mut pts = Vec::new();
    collect_points(scan, mount, cfg, &mut pts);
    pts.into_iter().map(|sp| sp.p).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::BeamFault;
    use crate::geometry::point_segment_distance;
    use crate::sim::{Rng, ScanSpec, World, cast_scan};
    use proptest::prelude::*;
    use std::f64::consts::TAU;

    const MOUNT: Pose2 = Pose2 {
        x: 0.1,
        y: 0.05,
        theta: 0.02,
    };

    fn room_scan(robot: Pose2, sigma: f64, seed: u64) -> RangeScan {
        cast_scan(
            &World::room_with_boxes(),
            &robot.compose(&MOUNT),
            &ScanSpec::lms200_half_degree(sigma),
            0.0,
            &mut Rng::new(seed),
        )
    }

    #[test]
    fn the_fewest_points_follow_the_beam_spacing() {
        let span = 2.5f64.to_radians();
        let deg = |d: f64| d.to_radians();
        assert_eq!(points_for_span(span, deg(0.5)), 6);
        assert_eq!(points_for_span(span, deg(1.0)), 4);
        assert_eq!(points_for_span(span, deg(0.25)), 11);
        assert_eq!(
            points_for_span(span, -deg(0.5)),
            6,
            "either sweep direction"
        );
        assert_eq!(points_for_span(0.0, deg(0.5)), 0);
        assert_eq!(points_for_span(span, 0.0), 0);
        assert_eq!(points_for_span(f64::NAN, deg(0.5)), 0);
        // A wall 5 m away spanning 5° (45 cm, 5 beams at 1°): kept, where
        // 6 points would have dropped it.
        let world = World::from_segments([[[5.0, -0.225], [5.0, 0.225]]]);
        let scan = cast_scan(
            &world,
            &Pose2::IDENTITY,
            &ScanSpec::lms200_one_degree(0.0),
            0.0,
            &mut Rng::new(1),
        );
        let lines = extract_lines(&scan, &Pose2::IDENTITY, &Default::default());
        assert_eq!(lines.len(), 1, "{lines:?}");
        let fixed = ExtractionConfig {
            min_points: 6,
            min_span: 0.0,
            ..Default::default()
        };
        assert!(extract_lines(&scan, &Pose2::IDENTITY, &fixed).is_empty());
    }

    #[test]
    fn noise_free_lines_lie_on_walls_with_free_space_left() {
        let world = World::room_with_boxes();
        for (k, robot) in [
            Pose2::new(4.0, 3.0, 0.3),
            Pose2::new(2.0, 2.0, 1.9),
            Pose2::new(6.5, 3.5, -2.8),
        ]
        .into_iter()
        .enumerate()
        {
            let lines = extract_lines(
                &room_scan(robot, 0.0, k as u64),
                &MOUNT,
                &Default::default(),
            );
            assert!(lines.len() >= 4, "pose {k}: {} lines", lines.len());
            for l in &lines {
                let m = l.transformed(&robot);
                // On a wall; a true end up to half a beam spacing past
                // the last point, so possibly past the wall's corner.
                let slack = |e: Option<f64>| if e.is_some() { 0.1 } else { 1e-3 };
                let on_wall = world.walls().iter().any(|&w| {
                    point_segment_distance(m.start, w[0], w[1]) < slack(m.wall_ends.start)
                        && point_segment_distance(m.end, w[0], w[1]) < slack(m.wall_ends.end)
                        && point_segment_distance(m.centre(), w[0], w[1]) < 1e-3
                });
                assert!(on_wall, "pose {k}: {m:?} is on no wall");
                let sensor = MOUNT.transform_point([0.0, 0.0]);
                assert!(l.signed_distance(sensor) > 0.0, "pose {k}: {l:?}");
            }
        }
    }

    #[test]
    fn dropouts_inside_a_wall_do_not_split_it() {
        let world = World::from_segments([[[3.0, -2.0], [3.0, 2.0]]]);
        let mut scan = cast_scan(
            &world,
            &Pose2::IDENTITY,
            &ScanSpec::lms200_half_degree(0.0),
            0.0,
            &mut Rng::new(1),
        );
        for i in [170, 171, 185, 200] {
            scan.ranges[i] = Err(BeamFault::SensorCode);
        }
        scan.ranges[190] = Ok(0.01);
        let lines = extract_lines(&scan, &Pose2::IDENTITY, &Default::default());
        assert_eq!(lines.len(), 1, "{lines:?}");
        assert!((lines[0].xc - 3.0).abs() < 1e-9);
    }

    /// The propagated σθ and σc match the scatter of repeated noisy fits.
    #[test]
    fn propagated_sigmas_match_monte_carlo() {
        let world = World::from_segments([[[3.0, -2.0], [3.5, 2.5]]]);
        let sigma = 0.02;
        let cfg = ExtractionConfig {
            split_threshold: 0.2,
            merge_threshold: 0.2,
            range_noise: RangeNoise { a: sigma, b: 0.0 },
            ..ExtractionConfig::default()
        };
        let spec = ScanSpec::lms200_half_degree(sigma);
        let mut rng = Rng::new(2024);
        let truth_theta = (4.5f64).atan2(0.5);
        let truth =
            crate::geometry::CogLine::from_centre(truth_theta, [3.0, -2.0], 0.0, 1.0, 0.0, 0.0, 2);
        let trials = 1500;
        let (mut dth, mut dc, mut pred_th, mut pred_c) = (Vec::new(), Vec::new(), 0.0, 0.0);
        for _ in 0..trials {
            let scan = cast_scan(&world, &Pose2::IDENTITY, &spec, 0.0, &mut rng);
            let lines = extract_lines(&scan, &Pose2::IDENTITY, &cfg);
            assert_eq!(lines.len(), 1);
            let l = lines[0];
            dth.push(crate::geometry::wrap_angle(l.theta - truth_theta));
            dc.push(-truth.signed_distance(l.centre()));
            pred_th += l.sigma_theta / trials as f64;
            pred_c += l.sigma_c / trials as f64;
        }
        let std = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
        };
        let (s_th, s_c) = (std(&dth), std(&dc));
        assert!((s_th / pred_th - 1.0).abs() < 0.1, "σθ {s_th} vs {pred_th}");
        assert!((s_c / pred_c - 1.0).abs() < 0.1, "σc {s_c} vs {pred_c}");
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

        #[test]
        fn extraction_invariants(
            x in 1.5..6.5f64, y in 1.2..4.8f64, heading in 0.0..TAU,
            sigma in 0.0..0.03f64, seed in 0u64..1000,
        ) {
            let robot = Pose2::new(x, y, heading);
            let scan = room_scan(robot, sigma, seed);
            let cfg = ExtractionConfig {
                split_threshold: (4.0 * sigma).max(0.04),
                merge_threshold: (4.0 * sigma).max(0.04),
                ..ExtractionConfig::default()
            };
            let lines = extract_lines(&scan, &MOUNT, &cfg);
            let pts = scan_points(&scan, &MOUNT, &cfg);
            let tol = cfg.split_threshold.max(cfg.merge_threshold);
            // A true end lies up to half a beam spacing beyond the last
            // point, the spacing at most this far from the sensor.
            let sensor = MOUNT.transform_point([0.0, 0.0]);
            let reach = pts.iter().map(|p| (p[0] - sensor[0]).hypot(p[1] - sensor[1])).fold(0.0, f64::max);
            let beyond = 0.5 * reach * scan.angle_increment.abs() / super::super::ends::MIN_SIN_INCIDENCE;
            for l in &lines {
                prop_assert!((0.0..TAU).contains(&l.theta));
                prop_assert!(l.n_points >= cfg.min_points);
                prop_assert!(l.length() >= cfg.min_length);
                prop_assert!(l.sigma_c >= 0.0 && l.sigma_theta >= 0.0);
                // End points are projections of input points (true ends:
                // moved on along the line by up to half a spacing).
                for (e, true_end) in [(l.start, l.wall_ends.start), (l.end, l.wall_ends.end)] {
                    let slack = tol + if true_end.is_some() { beyond } else { 0.0 };
                    let near = pts.iter().any(|p| (p[0] - e[0]).hypot(p[1] - e[1]) <= slack);
                    prop_assert!(near, "{e:?} is far from every point");
                }
            }
            // Lines do not depend on where the laser is mounted beyond a
            // rigid transform.
            let bare = extract_lines(&scan, &Pose2::IDENTITY, &cfg);
            prop_assert_eq!(bare.len(), lines.len());
            for (b, l) in bare.iter().zip(&lines) {
                let moved = b.transformed(&MOUNT);
                prop_assert!((moved.xc - l.xc).abs() < 1e-9 && (moved.yc - l.yc).abs() < 1e-9);
                prop_assert!(crate::geometry::wrap_angle(moved.theta - l.theta).abs() < 1e-9);
            }
        }
    }
}
