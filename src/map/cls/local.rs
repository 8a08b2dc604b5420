//! The local CLS map of one scan (Zhang & Ghosh §3): a closed polygon of
//! the free space the beams crossed, made of the scan's actual segments and
//! virtual segments between them, closed through the sensor centre.
//!
//! # Construction
//!
//! Work in the sensor frame, where every valid range point has a beam
//! angle. The boundary visits, in increasing beam angle:
//! - the sensor centre, then a virtual segment out to the first boundary
//!   point;
//! - each accepted actual segment (start to end);
//! - between two consecutive boundary points `p1`, `p2` (an actual end and
//!   the next actual start, or the first/last valid point of the scan), an
//!   envelope: if every range point whose beam lies strictly between them
//!   is on or beyond the chord `p1–p2`, the chord itself (one virtual
//!   segment — an occlusion jump); otherwise three virtual segments: `l1`
//!   along the beam through `p1`, `l2` parallel to the chord through the
//!   range point nearest the sensor (measured across the chord), `l3` back
//!   out along the beam through `p2`;
//! - a virtual segment back to the sensor centre.
//!
//! Every vertex then has a beam angle no smaller than the one before it, so
//! the polygon is star-shaped about the sensor and simple. Wedges wider than
//! [`LocalMapConfig::max_wedge`] are first split at the range point nearest
//! their middle beam, so one close point does not flatten half the scan.
//!
//! An actual segment is accepted only if its direction runs counter-
//! clockwise about the sensor (free space on its left, as the extractor
//! promises), it does not overlap the previous one in angle, and no range
//! point in its wedge lies more than [`LocalMapConfig::point_tolerance`] on
//! the sensor side of it; otherwise its wedge is treated as a gap. Two
//! segments meeting at a corner may each have had their end put at the
//! corner (see [`crate::geometry::WallEnds`]), the two estimates a few
//! millimetres apart and crossing in angle: an overlap of less than one
//! beam step is no occlusion, and the later segment starts where the
//! earlier one's end beam meets it, joined to it along that beam.
//!
//! # Beams without a valid range
//!
//! Faulty, non-finite and out-of-limit beams are ignored: the region never
//! reaches past the chord between the valid points on either side of them,
//! so it claims no free space beyond what valid neighbours bound (the scan
//! may report no return from a black or distant surface; the chord is the
//! conservative reading). A wedge of at least π without any valid point in
//! it cannot be closed this way and makes the scan unusable.

use crate::geometry::{CogLine, Pose2, RangeScan, point_segment_distance, wrap_angle};
use std::f64::consts::PI;

/// Tuning of the local map; SI units.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LocalMapConfig {
    /// Laser pose in the robot frame. Default: identity.
    pub mount: Pose2,
    /// Shorter readings are ignored (m). Default 0.05, as the extractor.
    pub min_range: f64,
    /// Longer readings are ignored (m). Default 8.0, as the extractor.
    pub max_range: f64,
    /// How far a range point may lie on the sensor side of an actual
    /// segment in whose wedge it falls (m). Default 0.05: above the
    /// extractor's 4 cm split threshold, the largest residual it leaves.
    pub point_tolerance: f64,
    /// Widest wedge one envelope may span (rad). Default π/4.
    pub max_wedge: f64,
}

impl Default for LocalMapConfig {
    fn default() -> Self {
        LocalMapConfig {
            mount: Pose2::IDENTITY,
            min_range: 0.05,
            max_range: 8.0,
            point_tolerance: 0.05,
            max_wedge: PI / 4.0,
        }
    }
}

/// Where a local boundary edge comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LocalSource {
    /// Scan line `lines[i]`.
    Actual(usize),
    Virtual,
}

/// One edge of a local region.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalEdge {
    pub start: [f64; 2],
    pub end: [f64; 2],
    pub source: LocalSource,
}

/// A local CLS map: a closed counter-clockwise polygon in the robot frame.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LocalRegion {
    pub edges: Vec<LocalEdge>,
}

impl LocalRegion {
    /// Signed area (m²), positive for a counter-clockwise boundary.
    pub fn signed_area(&self) -> f64 {
        0.5 * self
            .edges
            .iter()
            .map(|e| e.start[0] * e.end[1] - e.end[0] * e.start[1])
            .sum::<f64>()
    }

    /// The same region in the parent frame of `pose`.
    pub fn transformed(&self, pose: &Pose2) -> LocalRegion {
        LocalRegion {
            edges: self
                .edges
                .iter()
                .map(|e| LocalEdge {
                    start: pose.transform_point(e.start),
                    end: pose.transform_point(e.end),
                    source: e.source,
                })
                .collect(),
        }
    }

    /// Length (m) of `lines` (this region's frame) lying inside it farther
    /// than `tolerance` (m) from the boundary, sampled every 5 cm: walls
    /// standing where the scan saw through.
    pub fn length_inside<'a>(
        &self,
        lines: impl IntoIterator<Item = &'a CogLine>,
        tolerance: f64,
    ) -> f64 {
        let mut inside = 0.0;
        for l in lines {
            let (piece, points) = l.samples(0.05);
            for p in points {
                if self.strictly_contains(p, tolerance) {
                    inside += piece;
                }
            }
        }
        inside
    }

    /// Centre and radius (m) of a circle that holds the region.
    pub fn bounding_circle(&self) -> ([f64; 2], f64) {
        let points = || self.edges.iter().flat_map(|e| [e.start, e.end]);
        let (lo, hi) = points().fold(
            ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
            |(lo, hi), p| {
                (
                    [lo[0].min(p[0]), lo[1].min(p[1])],
                    [hi[0].max(p[0]), hi[1].max(p[1])],
                )
            },
        );
        if !(lo[0] <= hi[0] && lo[1] <= hi[1]) {
            return ([0.0, 0.0], 0.0);
        }
        let centre = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
        (centre, 0.5 * (hi[0] - lo[0]).hypot(hi[1] - lo[1]))
    }

    /// Whether `p` lies strictly inside, farther than `tolerance` (m) from
    /// the boundary.
    pub fn strictly_contains(&self, p: [f64; 2], tolerance: f64) -> bool {
        let mut inside = false;
        let mut nearest = f64::INFINITY;
        for e in &self.edges {
            let (a, b) = (e.start, e.end);
            if (a[1] > p[1]) != (b[1] > p[1]) {
                let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
                if x > p[0] {
                    inside = !inside;
                }
            }
            nearest = nearest.min(point_segment_distance(p, a, b));
        }
        inside && nearest > tolerance
    }
}

/// Why a scan gives no local region.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LocalMapError {
    #[error("the scan's angle step {0} rad is not a positive finite number")]
    BadAngleStep(f64),
    #[error("the scan has {0} valid range points; at least 2 are needed")]
    TooFewPoints(usize),
    #[error("{0:.3} rad of the scan have no valid point; the region cannot be closed")]
    BlindWedge(f64),
}

/// A valid range point in the sensor frame with its angle from the first
/// beam direction (rad, increasing in scan order).
#[derive(Debug, Clone, Copy)]
struct Polar {
    angle: f64,
    p: [f64; 2],
}

/// The valid range points of `scan` in the robot frame, in scan order,
/// filtered by the limits of `cfg`.
pub fn valid_points(scan: &RangeScan, cfg: &LocalMapConfig) -> Vec<[f64; 2]> {
    sensor_points(scan, cfg)
        .into_iter()
        .map(|q| cfg.mount.transform_point(q.p))
        .collect()
}

fn sensor_points(scan: &RangeScan, cfg: &LocalMapConfig) -> Vec<Polar> {
    scan.ranges
        .iter()
        .enumerate()
        .filter_map(|(i, r)| {
            let r = *r.as_ref().ok()?;
            if !(r.is_finite() && r >= cfg.min_range && r <= cfg.max_range) {
                return None;
            }
            let a = scan.angle(i);
            Some(Polar {
                angle: i as f64 * scan.angle_increment,
                p: [r * a.cos(), r * a.sin()],
            })
        })
        .collect()
}

/// Builds the local CLS map of `scan` with its extracted `lines` (robot
/// frame, scan order). The result is in the robot frame.
pub fn local_region(
    lines: &[CogLine],
    scan: &RangeScan,
    cfg: &LocalMapConfig,
) -> Result<LocalRegion, LocalMapError> {
    let step = scan.angle_increment;
    if !(step.is_finite() && step > 0.0 && scan.angle_min.is_finite()) {
        return Err(LocalMapError::BadAngleStep(step));
    }
    let points = sensor_points(scan, cfg);
    let (Some(&first), Some(&last)) = (points.first(), points.last()) else {
        return Err(LocalMapError::TooFewPoints(points.len()));
    };
    if points.len() < 2 {
        return Err(LocalMapError::TooFewPoints(points.len()));
    }
    let to_sensor = cfg.mount.inverse();
    // Angles from the first beam, measured about the middle of the field
    // of view so that end points projected just outside it stay ordered.
    let half_fov = 0.5 * scan.fov();
    let angle_of =
        |p: [f64; 2]| wrap_angle(p[1].atan2(p[0]) - scan.angle_min - half_fov) + half_fov;
    let builder = Builder {
        points: &points,
        tolerance: cfg.point_tolerance,
        max_wedge: cfg.max_wedge.clamp(0.05, PI / 2.0),
    };

    // Accepted lines in the sensor frame with their end angles.
    let mut accepted: Vec<(usize, Polar, Polar)> = Vec::new();
    for (i, line) in lines.iter().enumerate() {
        let l = line.transformed(&to_sensor);
        let (mut s, e) = (
            Polar {
                angle: angle_of(l.start),
                p: l.start,
            },
            Polar {
                angle: angle_of(l.end),
                p: l.end,
            },
        );
        if let Some((_, _, prev_end)) = accepted.last()
            && s.angle <= prev_end.angle
            && prev_end.angle - s.angle < step
            && let Some(p) = beam_meets_line(prev_end.p, &l)
        {
            s = Polar {
                angle: prev_end.angle,
                p,
            };
        }
        let after_previous = accepted
            .last()
            .is_none_or(|(_, _, prev_end)| s.angle >= prev_end.angle && s.p != prev_end.p);
        let ok = [l.start, l.end, [l.xc, l.yc]]
            .iter()
            .flatten()
            .all(|v| v.is_finite())
            && e.angle > s.angle
            && e.angle - s.angle < PI
            && after_previous
            && builder.points_behind(&l, s.angle, e.angle);
        if ok {
            accepted.push((i, s, e));
        }
    }

    let mut chain = Chain::default();
    let centre = [0.0, 0.0];
    let mut cursor = match accepted.first() {
        Some((_, s, _)) if s.angle <= first.angle => *s,
        _ => first,
    };
    chain.push(centre, cursor.p, LocalSource::Virtual);
    for &(i, s, e) in &accepted {
        if s.angle > cursor.angle {
            builder.envelope(cursor, s, &mut chain)?;
        } else if s.p != cursor.p {
            // A corner's two estimates, joined along the beam.
            chain.push(cursor.p, s.p, LocalSource::Virtual);
        }
        chain.push(s.p, e.p, LocalSource::Actual(i));
        cursor = e;
    }
    if last.angle > cursor.angle {
        builder.envelope(cursor, last, &mut chain)?;
        cursor = last;
    }
    chain.push(cursor.p, centre, LocalSource::Virtual);
    chain.tidy();
    if chain.edges.len() < 3 {
        return Err(LocalMapError::TooFewPoints(points.len()));
    }
    Ok(LocalRegion { edges: chain.edges }.transformed(&cfg.mount))
}

/// Where the beam through `p` (sensor frame) meets `line`'s infinite
/// line, if it does ahead of the sensor.
fn beam_meets_line(p: [f64; 2], line: &CogLine) -> Option<[f64; 2]> {
    // The signed distance is affine along the beam t·p: f(t) = f0 + t·(f1 − f0).
    let (f0, f1) = (line.signed_distance([0.0, 0.0]), line.signed_distance(p));
    let t = f0 / (f0 - f1);
    (t.is_finite() && t > 0.0).then(|| [t * p[0], t * p[1]])
}

struct Builder<'a> {
    points: &'a [Polar],
    tolerance: f64,
    max_wedge: f64,
}

impl Builder<'_> {
    /// Points with angles strictly between `a0` and `a1`.
    fn between(&self, a0: f64, a1: f64) -> &[Polar] {
        let lo = self.points.partition_point(|q| q.angle <= a0);
        let hi = self.points.partition_point(|q| q.angle < a1);
        self.points.get(lo..hi.max(lo)).unwrap_or(&[])
    }

    /// Whether every point in the wedge `[a0, a1]` lies no more than the
    /// tolerance on the sensor side of `line`.
    fn points_behind(&self, line: &CogLine, a0: f64, a1: f64) -> bool {
        let lo = self.points.partition_point(|q| q.angle < a0);
        let hi = self.points.partition_point(|q| q.angle <= a1);
        self.points
            .get(lo..hi.max(lo))
            .unwrap_or(&[])
            .iter()
            .all(|q| line.signed_distance(q.p) <= self.tolerance)
    }

    /// Appends the virtual segments from `p1` to `p2` (see the module
    /// documentation).
    fn envelope(&self, p1: Polar, p2: Polar, chain: &mut Chain) -> Result<(), LocalMapError> {
        let gap = self.between(p1.angle, p2.angle);
        let width = p2.angle - p1.angle;
        if width > self.max_wedge {
            let mid = 0.5 * (p1.angle + p2.angle);
            let split = gap
                .iter()
                .min_by(|a, b| (a.angle - mid).abs().total_cmp(&(b.angle - mid).abs()));
            if let Some(&m) = split {
                self.envelope(p1, m, chain)?;
                return self.envelope(m, p2, chain);
            }
            if width >= PI - 1e-6 {
                return Err(LocalMapError::BlindWedge(width));
            }
        }
        let c = [p2.p[0] - p1.p[0], p2.p[1] - p1.p[1]];
        let len = c[0].hypot(c[1]);
        if len == 0.0 {
            return Ok(());
        }
        // Unit normal pointing to the sensor side of the chord.
        let n = [-c[1] / len, c[0] / len];
        let across = |p: [f64; 2]| n[0] * (p[0] - p1.p[0]) + n[1] * (p[1] - p1.p[1]);
        let d_max = gap.iter().map(|q| across(q.p)).fold(0.0, f64::max);
        // The sensor lies on the positive side at this distance.
        let d_sensor = across([0.0, 0.0]);
        if d_max <= 0.0 || d_sensor <= 0.0 {
            chain.push(p1.p, p2.p, LocalSource::Virtual);
            return Ok(());
        }
        // l2 cuts both bounding beams at the same fraction of their range.
        let t = (1.0 - d_max / d_sensor).max(0.0);
        let q1 = [t * p1.p[0], t * p1.p[1]];
        let q2 = [t * p2.p[0], t * p2.p[1]];
        chain.push(p1.p, q1, LocalSource::Virtual);
        chain.push(q1, q2, LocalSource::Virtual);
        chain.push(q2, p2.p, LocalSource::Virtual);
        Ok(())
    }
}

/// The boundary under construction.
#[derive(Default)]
struct Chain {
    edges: Vec<LocalEdge>,
}

impl Chain {
    fn push(&mut self, start: [f64; 2], end: [f64; 2], source: LocalSource) {
        self.edges.push(LocalEdge { start, end, source });
    }

    /// Removes edges shorter than a micrometre (two projections of one
    /// range point), joining their neighbours at the earlier vertex.
    fn drop_tiny_edges(&mut self) {
        const TINY: f64 = 1e-6;
        let mut i = 0;
        while i < self.edges.len() && self.edges.len() > 1 {
            let e = self.edges[i];
            if (e.end[0] - e.start[0]).hypot(e.end[1] - e.start[1]) < TINY {
                let j = (i + 1) % self.edges.len();
                self.edges[j].start = e.start;
                self.edges.remove(i);
            } else {
                i += 1;
            }
        }
    }

    /// Drops tiny edges, removes fold-backs (an edge retracing the
    /// one before it, as when an envelope's first beam is the closing
    /// segment's beam) and merges consecutive collinear virtual edges.
    fn tidy(&mut self) {
        self.drop_tiny_edges();
        let mut changed = true;
        while changed && self.edges.len() >= 3 {
            changed = false;
            let n = self.edges.len();
            for i in 0..n {
                let j = (i + 1) % n;
                let (a, b) = (self.edges[i], self.edges[j]);
                let u = [a.end[0] - a.start[0], a.end[1] - a.start[1]];
                let v = [b.end[0] - b.start[0], b.end[1] - b.start[1]];
                let cross = u[0] * v[1] - u[1] * v[0];
                let dot = u[0] * v[0] + u[1] * v[1];
                let scale = u[0].hypot(u[1]) * v[0].hypot(v[1]);
                let parallel = cross.abs() <= 1e-12 * scale;
                let fold = parallel && dot < 0.0;
                let same_virtual = parallel
                    && dot > 0.0
                    && a.source == LocalSource::Virtual
                    && b.source == LocalSource::Virtual;
                if !(fold || same_virtual) {
                    continue;
                }
                let source = if a.source == b.source {
                    a.source
                } else {
                    LocalSource::Virtual
                };
                self.edges[i] = LocalEdge {
                    start: a.start,
                    end: b.end,
                    source,
                };
                self.edges.remove(j);
                self.drop_tiny_edges();
                changed = true;
                break;
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::geometry::{BeamFault, ExtractionConfig, extract_lines};
    use crate::map::cls::loops::{ClsLoop, ClsSegment, ClsShape, check_loops};
    use crate::sim::{Rng, ScanSpec, World, cast_scan};
    use proptest::prelude::*;

    fn as_shape(r: &LocalRegion) -> ClsShape {
        ClsShape {
            outer: ClsLoop::new(
                r.edges
                    .iter()
                    .map(|e| ClsSegment::virtual_between(e.start, e.end))
                    .collect(),
            ),
            holes: vec![],
        }
    }

    fn scan_of(world: &World, pose: Pose2, sigma: f64, seed: u64) -> RangeScan {
        cast_scan(
            world,
            &pose,
            &ScanSpec::lms200_half_degree(sigma),
            0.0,
            &mut Rng::new(seed),
        )
    }

    fn assert_valid(region: &LocalRegion, scan: &RangeScan, cfg: &LocalMapConfig) {
        check_loops(&[as_shape(region)]).unwrap();
        for p in valid_points(scan, cfg) {
            assert!(
                !region.strictly_contains(p, cfg.point_tolerance),
                "{p:?} inside"
            );
        }
    }

    #[test]
    fn a_room_scan_gives_a_closed_region_with_its_walls() {
        let world = World::room_with_boxes();
        let scan = scan_of(&world, Pose2::new(4.0, 2.5, 0.3), 0.005, 1);
        let cfg = LocalMapConfig::default();
        let lines = extract_lines(&scan, &cfg.mount, &ExtractionConfig::default());
        let region = local_region(&lines, &scan, &cfg).unwrap();
        assert_valid(&region, &scan, &cfg);
        let actual = region
            .edges
            .iter()
            .filter(|e| matches!(e.source, LocalSource::Actual(_)))
            .count();
        assert!(
            actual >= lines.len() * 3 / 4,
            "{actual} of {} lines kept",
            lines.len()
        );
        assert!(region.signed_area() > 5.0);
    }

    #[test]
    fn occlusion_jump_is_one_virtual_segment() {
        // A near wall on the right half, a far wall on the left half.
        let world = World::from_segments([[[1.0, -3.0], [1.0, 0.0]], [[3.0, 0.0], [3.0, 4.0]]]);
        let scan = scan_of(&world, Pose2::IDENTITY, 0.0, 1);
        let cfg = LocalMapConfig::default();
        let lines = extract_lines(&scan, &cfg.mount, &ExtractionConfig::default());
        assert_eq!(lines.len(), 2);
        let region = local_region(&lines, &scan, &cfg).unwrap();
        assert_valid(&region, &scan, &cfg);
        let k = region
            .edges
            .iter()
            .position(|e| e.source == LocalSource::Actual(0))
            .unwrap();
        let next = region.edges[(k + 1) % region.edges.len()];
        assert_eq!(next.source, LocalSource::Virtual);
        assert_eq!(
            region.edges[(k + 2) % region.edges.len()].source,
            LocalSource::Actual(1)
        );
    }

    #[test]
    fn a_close_point_between_walls_gets_a_three_segment_envelope() {
        // Two walls with a chair leg closer to the sensor between them.
        let mut world =
            World::from_segments([[[2.0, -3.0], [2.0, -0.3]], [[2.0, 0.3], [2.0, 3.0]]]);
        world.add_wall([2.5, -0.3], [2.5, 0.3]);
        world.add_box([1.0, 0.0], [0.02, 0.02], 0.0);
        let scan = scan_of(&world, Pose2::IDENTITY, 0.0, 1);
        let cfg = LocalMapConfig::default();
        let lines = extract_lines(&scan, &cfg.mount, &ExtractionConfig::default());
        let region = local_region(&lines, &scan, &cfg).unwrap();
        assert_valid(&region, &scan, &cfg);
        // The leg at 1 m sets the envelope: nothing of the region is beyond it straight ahead.
        assert!(!region.strictly_contains([1.5, 0.0], 0.0));
        assert!(region.strictly_contains([0.5, 0.0], 0.0));
    }

    #[test]
    fn invalid_beams_are_closed_at_their_valid_neighbours() {
        let world = World::corridor(30.0, 2.0, None);
        let mut scan = scan_of(&world, Pose2::new(10.0, 0.0, 0.0), 0.0, 1);
        for r in &mut scan.ranges[100..140] {
            *r = Err(BeamFault::SensorCode);
        }
        let cfg = LocalMapConfig::default();
        let lines = extract_lines(&scan, &cfg.mount, &ExtractionConfig::default());
        let region = local_region(&lines, &scan, &cfg).unwrap();
        assert_valid(&region, &scan, &cfg);
        // Nothing beyond 8 m is claimed.
        for e in &region.edges {
            assert!(e.start[0].hypot(e.start[1]) <= 8.0 + 1e-9);
        }
    }

    #[test]
    fn no_points_is_an_error() {
        let scan = RangeScan {
            t: 0.0,
            angle_min: -PI / 2.0,
            angle_increment: PI / 360.0,
            ranges: vec![Err(BeamFault::NoReturn); 361],
        };
        let cfg = LocalMapConfig::default();
        assert_eq!(
            local_region(&[], &scan, &cfg),
            Err(LocalMapError::TooFewPoints(0))
        );
        let mut two = scan.clone();
        two.ranges[0] = Ok(1.0);
        two.ranges[360] = Ok(1.0);
        assert!(matches!(
            local_region(&[], &two, &cfg),
            Err(LocalMapError::BlindWedge(_))
        ));
        let bad = RangeScan {
            angle_increment: f64::NAN,
            ..scan
        };
        assert!(matches!(
            local_region(&[], &bad, &cfg),
            Err(LocalMapError::BadAngleStep(_))
        ));
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn no_range_point_is_strictly_inside(
            seed in 0u64..1000,
            boxes in prop::collection::vec((1.0..9.0f64, 1.0..7.0f64, 0.05..0.8f64, 0.05..0.8f64, 0.0..3.0f64), 0..8),
            pose in (2.0..8.0f64, 2.0..6.0f64, -PI..PI),
            mount in (-0.2..0.2f64, -0.1..0.1f64, -0.2..0.2f64),
        ) {
            let mut world = World::new();
            world.add_polyline(&[[0.0, 0.0], [10.0, 0.0], [10.0, 8.0], [0.0, 8.0]], true);
            for (x, y, hx, hy, a) in boxes {
                world.add_box([x, y], [hx, hy], a);
            }
            let robot = Pose2::new(pose.0, pose.1, pose.2);
            let cfg = LocalMapConfig { mount: Pose2::new(mount.0, mount.1, mount.2), ..LocalMapConfig::default() };
            let scan = scan_of(&world, robot.compose(&cfg.mount), 0.005, seed);
            let lines = extract_lines(&scan, &cfg.mount, &ExtractionConfig::default());
            if let Ok(region) = local_region(&lines, &scan, &cfg) {
                prop_assert!(check_loops(&[as_shape(&region)]).is_ok());
                for p in valid_points(&scan, &cfg) {
                    prop_assert!(!region.strictly_contains(p, cfg.point_tolerance), "{:?} inside", p);
                }
            }
        }
    }
}
