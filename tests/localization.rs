//! Local localization on simulated scans: a map from the lines of a scan at
//! a reference pose, a second scan from a nearby pose, a perturbed
//! prediction; the true pose must come back within 10 mm and 0.5°.
//!
//! Run with `cargo test --test localization -- --nocapture` to see the
//! error statistics per world and noise level.

#![allow(clippy::unwrap_used)]

use clsmap::geometry::{
    CogLine, CorrespondenceConfig, ExtractionConfig, Pose2, RangeNoise, SegmentIndex,
    extract_lines, lines_correspond, point_segment_distance, wrap_angle,
};
use clsmap::localize::{
    LineConstraints, LocalizationResult, LocalizeError, LocalizerConfig, localize,
};
use clsmap::sim::{Rng, ScanSpec, World, cast_scan};
use proptest::prelude::*;
use std::f64::consts::PI;

/// The laser sits 0.1 m ahead of the robot centre (XR4000-like mount).
const MOUNT: Pose2 = Pose2 {
    x: 0.1,
    y: 0.0,
    theta: 0.0,
};
const POS_TOL: f64 = 0.010;
const ANGLE_TOL: f64 = 0.5 * PI / 180.0;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Place {
    Room,
    Loop,
    /// A plain 40 m corridor, 2 m wide: the along-corridor direction is
    /// unobservable.
    Corridor,
    /// The 30 m corridor with door recesses.
    DoorCorridor,
}

impl Place {
    fn world(self) -> World {
        match self {
            Place::Room => World::room_with_boxes(),
            Place::Loop => World::loop_around_block(),
            Place::Corridor => World::corridor(40.0, 2.0, None),
            Place::DoorCorridor => World::corridor_with_doors(),
        }
    }

    /// Whether the robot may stand at `p`: inside the free space, clear of
    /// every wall by 0.45 m.
    fn free(self, world: &World, p: [f64; 2]) -> bool {
        let inside = match self {
            Place::Room => (1.0..7.0).contains(&p[0]) && (1.0..5.0).contains(&p[1]),
            Place::Loop => {
                (0.0..12.0).contains(&p[0])
                    && (0.0..10.0).contains(&p[1])
                    && !((2.0..10.0).contains(&p[0]) && (2.0..8.0).contains(&p[1]))
            }
            Place::Corridor => (12.0..28.0).contains(&p[0]) && p[1].abs() < 0.4,
            Place::DoorCorridor => (8.0..22.0).contains(&p[0]) && p[1].abs() < 0.4,
        };
        inside
            && world
                .walls()
                .iter()
                .all(|&[a, b]| point_segment_distance(p, a, b) >= 0.45)
    }

    /// A random heading for this place: anything in open spaces; within
    /// 30° of the corridor axis in corridors, so both walls are in view.
    fn heading(self, rng: &mut Rng) -> f64 {
        match self {
            Place::Room | Place::Loop => rng.uniform_range(-3.2, 3.2),
            Place::Corridor | Place::DoorCorridor => {
                let base = if rng.uniform() < 0.5 { 0.0 } else { PI };
                base + rng.uniform_range(-0.5, 0.5)
            }
        }
    }
}

fn extraction_config(sigma: f64) -> ExtractionConfig {
    ExtractionConfig {
        split_threshold: (4.0 * sigma).max(0.04),
        merge_threshold: (4.0 * sigma).max(0.04),
        range_noise: RangeNoise { a: sigma, b: 0.0 },
        // An 8 m horizon, inside the simulated LMS200's mm-mode reach, so
        // the corridor cases see no door jamb or end wall 8.0–8.18 m away
        // (their premise: nothing constrains the along-corridor direction).
        max_range: 8.0,
        ..ExtractionConfig::default()
    }
}

fn prior() -> [[f64; 3]; 3] {
    [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]]
}

/// One simulated case: map from a scan at `reference`, local lines from a
/// scan at `truth`, prediction off by up to 20 cm and 10°.
struct Case {
    truth: Pose2,
    predicted: Pose2,
    map: SegmentIndex,
    local: Vec<CogLine>,
}

fn sample_pose(place: Place, world: &World, rng: &mut Rng, near: Option<Pose2>) -> Pose2 {
    loop {
        let p = match near {
            None => Pose2::new(
                rng.uniform_range(0.0, 40.0),
                rng.uniform_range(-1.0, 10.0),
                place.heading(rng),
            ),
            Some(r) => {
                let d = rng.uniform_range(0.0, 0.5);
                let a = rng.uniform_range(-3.2, 3.2);
                let turn = rng.uniform_range(-20.0, 20.0).to_radians();
                Pose2::new(r.x + d * a.cos(), r.y + d * a.sin(), r.theta + turn)
            }
        };
        if place.free(world, [p.x, p.y]) {
            return p;
        }
    }
}

/// A scan pair is a case when the second scan shows at least two walls of
/// the first at the true pose: with one, nothing can fix the pose, and
/// refusing is the right answer, not a failure.
fn make_case(place: Place, world: &World, sigma: f64, seed: u64) -> Case {
    let mut rng = Rng::new(seed);
    let cfg = extraction_config(sigma);
    let spec = ScanSpec::lms200_half_degree(sigma);
    let (truth, map, local) = loop {
        let reference = sample_pose(place, world, &mut rng, None);
        let truth = sample_pose(place, world, &mut rng, Some(reference));
        let scan_ref = cast_scan(world, &reference.compose(&MOUNT), &spec, 0.0, &mut rng);
        let scan_now = cast_scan(world, &truth.compose(&MOUNT), &spec, 0.1, &mut rng);
        let mut map = SegmentIndex::new();
        for l in extract_lines(&scan_ref, &MOUNT, &cfg) {
            map.insert(l.transformed(&reference));
        }
        let local = extract_lines(&scan_now, &MOUNT, &cfg);
        let shared = local
            .iter()
            .filter(|l| {
                let seen = l.transformed(&truth);
                map.iter()
                    .any(|(_, m)| lines_correspond(&seen, m, &CorrespondenceConfig::default()))
            })
            .count();
        if shared >= 2 {
            break (truth, map, local);
        }
    };
    let d = rng.uniform_range(0.0, 0.2);
    let a = rng.uniform_range(-3.2, 3.2);
    let turn = rng.uniform_range(-10.0, 10.0).to_radians();
    let predicted = Pose2::new(
        truth.x + d * a.cos(),
        truth.y + d * a.sin(),
        truth.theta + turn,
    );
    Case {
        truth,
        predicted,
        map,
        local,
    }
}

/// Position and heading error. When the result flags a direction as
/// unobservable, the position error is measured across it only, and the
/// pose must have kept the prediction along it (within 5 mm).
fn errors(r: &LocalizationResult, case: &Case) -> (f64, f64) {
    let (ex, ey) = (r.pose.x - case.truth.x, r.pose.y - case.truth.y);
    let ea = wrap_angle(r.pose.theta - case.truth.theta).abs();
    match r.degenerate {
        None => (ex.hypot(ey), ea),
        Some(v) => {
            let across = (-v[1] * ex + v[0] * ey).abs();
            let kept =
                (v[0] * (r.pose.x - case.predicted.x) + v[1] * (r.pose.y - case.predicted.y)).abs();
            (if kept < 0.005 { across } else { f64::INFINITY }, ea)
        }
    }
}

fn nees(r: &LocalizationResult, truth: &Pose2) -> f64 {
    let c = nalgebra::Matrix3::from_fn(|i, j| r.covariance[i][j]);
    let e = nalgebra::Vector3::new(
        r.pose.x - truth.x,
        r.pose.y - truth.y,
        wrap_angle(r.pose.theta - truth.theta),
    );
    c.try_inverse()
        .map_or(f64::INFINITY, |inv| (e.transpose() * inv * e)[0])
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return f64::NAN;
    }
    v[((v.len() - 1) as f64 * q).round() as usize]
}

struct Tally {
    ok: usize,
    total: usize,
    degenerate: usize,
    /// Normalised estimation error squared `eᵀ·C⁻¹·e` of the
    /// non-degenerate results: 3 on average if the covariance is honest.
    nees: Vec<f64>,
    pos: Vec<f64>,
    ang: Vec<f64>,
    failures: Vec<String>,
}

fn run_cases(place: Place, sigma: f64, n: usize, seed0: u64, cfg: &LocalizerConfig) -> Tally {
    let world = place.world();
    let mut t = Tally {
        ok: 0,
        total: 0,
        degenerate: 0,
        nees: Vec::new(),
        pos: Vec::new(),
        ang: Vec::new(),
        failures: Vec::new(),
    };
    for k in 0..n {
        let seed = seed0 + k as u64;
        let case = make_case(place, &world, sigma, seed);
        t.total += 1;
        match localize(&case.local, &case.map, case.predicted, &prior(), cfg) {
            Ok(r) => {
                let (ep, ea) = errors(&r, &case);
                t.degenerate += usize::from(r.degenerate.is_some());
                if r.degenerate.is_none() {
                    t.nees.push(nees(&r, &case.truth));
                }
                t.pos.push(ep);
                t.ang.push(ea);
                if ep <= POS_TOL && ea <= ANGLE_TOL {
                    t.ok += 1;
                } else {
                    t.failures
                        .push(format!("seed {seed}: {ep:.4} m, {:.3}°", ea.to_degrees()));
                }
            }
            Err(e) => t.failures.push(format!("seed {seed}: {e}")),
        }
    }
    let (mut p, mut a) = (t.pos.clone(), t.ang.clone());
    println!(
        "{place:?} σ={:.0} mm {:?}: {}/{} ok ({} degenerate); position median {:.2} mm p99 {:.2} mm; angle median {:.3}° p99 {:.3}°; mean NEES {:.2}",
        sigma * 1000.0,
        cfg.constraints,
        t.ok,
        t.total,
        t.degenerate,
        percentile(&mut p, 0.5) * 1000.0,
        percentile(&mut p, 0.99) * 1000.0,
        percentile(&mut a, 0.5).to_degrees(),
        percentile(&mut a, 0.99).to_degrees(),
        mean(&t.nees),
    );
    t
}

fn assert_rate(t: &Tally, min_rate: f64) {
    let rate = t.ok as f64 / t.total as f64;
    assert!(
        rate >= min_rate,
        "{}/{} within tolerance; failures: {:?}",
        t.ok,
        t.total,
        t.failures
    );
}

/// Within 10 mm and 0.5° in at least 99 % of cases at up to 1 cm range
/// noise (the LMS200's figure), every case when noise-free. At 3 cm the
/// error is bounded by the information two single scans carry (about 3.5 mm
/// per axis, so a 99th percentile near 11 mm even for an ideal estimator):
/// there the bound is scaled with the noise, 30 mm and 1.5°.
#[test]
fn recovers_pose_in_room_and_loop_at_all_noise_levels() {
    let cfg = LocalizerConfig::default();
    for (i, place) in [Place::Room, Place::Loop].into_iter().enumerate() {
        for (j, sigma) in [0.0, 0.01, 0.03].into_iter().enumerate() {
            let t = run_cases(place, sigma, 100, 1000 * (3 * i + j) as u64 + 1, &cfg);
            match j {
                0 => assert_rate(&t, 1.0),
                1 => assert_rate(&t, 0.99),
                _ => {
                    let within = t
                        .pos
                        .iter()
                        .zip(&t.ang)
                        .filter(|&(&p, &a)| p <= 3.0 * POS_TOL && a <= 3.0 * ANGLE_TOL)
                        .count();
                    assert!(
                        within >= 99,
                        "{place:?} σ=3 cm: {within}/100 within 30 mm / 1.5°"
                    );
                }
            }
            if sigma > 0.0 {
                // The covariance is honest: NEES near its expectation, 3.
                let m = mean(&t.nees);
                assert!(
                    (1.0..6.0).contains(&m),
                    "{place:?} σ={sigma}: mean NEES {m}"
                );
            }
        }
    }
}

/// In a plain corridor the along-corridor direction is flagged and the
/// prediction kept along it, at every noise level; y and θ are recovered.
#[test]
fn corridor_flags_the_along_axis_and_recovers_the_rest() {
    let cfg = LocalizerConfig::default();
    let place = Place::Corridor;
    let world = place.world();
    for (j, &sigma) in [0.0, 0.01, 0.03].iter().enumerate() {
        let mut good = 0;
        let n = 60;
        let tol = if sigma > 0.02 { 3.0 } else { 1.0 };
        for k in 0..n {
            let case = make_case(place, &world, sigma, 50_000 + 1000 * j as u64 + k);
            let r = localize(&case.local, &case.map, case.predicted, &prior(), &cfg)
                .unwrap_or_else(|e| panic!("{place:?} σ={sigma} case {k}: {e}"));
            let Some(v) = r.degenerate else {
                panic!("{place:?} σ={sigma} case {k}: not flagged degenerate");
            };
            assert!(v[0].abs() > 0.999, "unobservable direction {v:?}");
            // Across the corridor and the heading are recovered; along
            // it the prediction is kept.
            let across = (r.pose.y - case.truth.y).abs();
            let turn = wrap_angle(r.pose.theta - case.truth.theta).abs();
            let kept = (r.pose.x - case.predicted.x).abs();
            if across <= tol * POS_TOL && turn <= tol * ANGLE_TOL && kept < 0.005 {
                good += 1;
            }
            // The covariance says so: along the corridor it is the
            // prior's, across it millimetres.
            assert!(
                r.covariance[0][0] > 0.5 * prior()[0][0] && r.covariance[1][1] < 1e-4,
                "{place:?} σ={sigma} case {k}: {:?}",
                r.covariance
            );
        }
        assert!(
            good as f64 >= 0.99 * n as f64,
            "{place:?} σ={sigma}: {good}/{n}"
        );
    }
}

/// With door recesses in view, their jambs are true wall ends: the walls'
/// ends pin the along-corridor direction, which is then recovered, not
/// flagged (before wall ends it was flagged in every case). Measured:
/// σ = 0: 48/60 observable, 40 of them within 30 mm, median along-corridor
/// error 2.0 mm; σ = 1 cm: 49/60, 45, 7.9 mm (reading only the beam next
/// to each end, before the jambs' sides were read as faces: 36/60 and
/// 12/60).
#[test]
fn door_jambs_make_a_corridor_observable_along_its_length() {
    let cfg = LocalizerConfig::default();
    let place = Place::DoorCorridor;
    let world = place.world();
    for (j, &sigma) in [0.0, 0.01].iter().enumerate() {
        let n = 60;
        let (mut observable, mut good) = (0, 0);
        let mut along = Vec::new();
        for k in 0..n {
            let case = make_case(place, &world, sigma, 50_000 + 1000 * j as u64 + k);
            let r = localize(&case.local, &case.map, case.predicted, &prior(), &cfg)
                .unwrap_or_else(|e| panic!("{place:?} σ={sigma} case {k}: {e}"));
            if r.degenerate.is_some() {
                continue;
            }
            observable += 1;
            let err = (r.pose.x - case.truth.x).hypot(r.pose.y - case.truth.y);
            let turn = wrap_angle(r.pose.theta - case.truth.theta).abs();
            along.push((r.pose.x - case.truth.x).abs());
            if err <= 3.0 * POS_TOL && turn <= ANGLE_TOL {
                good += 1;
            }
        }
        along.sort_by(f64::total_cmp);
        let median = along.get(along.len() / 2).copied().unwrap_or(f64::NAN);
        eprintln!(
            "door corridor σ={sigma}: {observable}/{n} observable, {good} within {:.0} mm; median along error {:.1} mm",
            3.0 * POS_TOL * 1e3,
            median * 1e3
        );
        // Jambs count only where the beam meets the wall steeply enough
        // (within about 4 m along a 2 m corridor), and the predictions are
        // up to 20 cm off, so not every pair of scans shares a jamb.
        let least = n * 2 / 3;
        assert!(
            observable >= least,
            "{place:?} σ={sigma}: {observable}/{n} observable"
        );
        assert!(
            good * 4 >= observable * 3,
            "{place:?} σ={sigma}: {good}/{observable} good"
        );
        assert!(
            median < 0.02,
            "{place:?} σ={sigma}: median along error {median} m"
        );
    }
}

/// The paper's centre-and-direction residuals against start/centre/end
/// point residuals on the same cases. Both are as accurate (the end points
/// add no information beyond the line's two parameters), but the three
/// point rows count the local line's information up to three times, so
/// their covariance is too small: mean NEES above that of the default.
#[test]
fn constraint_sets_compared() {
    let mut medians = Vec::new();
    let mut nees = Vec::new();
    for constraints in [
        LineConstraints::CentreAndDirection,
        LineConstraints::EndPointsAndCentre,
    ] {
        let cfg = LocalizerConfig {
            constraints,
            ..LocalizerConfig::default()
        };
        let mut t = run_cases(Place::Room, 0.01, 100, 777_000, &cfg);
        assert_rate(&t, 0.99);
        medians.push(percentile(&mut t.pos, 0.5));
        nees.push(mean(&t.nees));
    }
    assert!((medians[0] / medians[1] - 1.0).abs() < 0.15, "{medians:?}");
    assert!(nees[1] > nees[0], "{nees:?}");
}

#[test]
fn rejects_implausible_jumps_and_too_few_matches() {
    let world = Place::Room.world();
    let case = make_case(Place::Room, &world, 0.01, 4242);
    let cfg = LocalizerConfig {
        max_translation_jump: 0.001,
        ..LocalizerConfig::default()
    };
    match localize(&case.local, &case.map, case.predicted, &prior(), &cfg) {
        Err(LocalizeError::ImplausibleJump { dx, .. }) => assert!(dx > 0.001),
        other => panic!("expected ImplausibleJump, got {other:?}"),
    }
    let empty = SegmentIndex::new();
    match localize(
        &case.local,
        &empty,
        case.predicted,
        &prior(),
        &LocalizerConfig::default(),
    ) {
        Err(LocalizeError::TooFewMatches {
            found: 0,
            needed: 2,
        }) => {}
        other => panic!("expected TooFewMatches, got {other:?}"),
    }
    let bad_prior = [[0.01, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 0.01]];
    assert_eq!(
        localize(
            &case.local,
            &case.map,
            case.predicted,
            &bad_prior,
            &LocalizerConfig::default()
        ),
        Err(LocalizeError::InvalidPrior)
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Localizing a scan's lines against the same lines moved by a random
    /// transform returns that transform.
    #[test]
    fn localizing_against_own_lines_returns_the_transform(
        seed in 0u64..10_000,
        tx in -20.0..20.0f64, ty in -20.0..20.0f64, tt in -PI..PI,
        ex in -0.15..0.15f64, ey in -0.15..0.15f64, et in -0.15..0.15f64,
    ) {
        let world = Place::Room.world();
        let mut rng = Rng::new(seed);
        let pose = sample_pose(Place::Room, &world, &mut rng, None);
        let scan = cast_scan(&world, &pose.compose(&MOUNT), &ScanSpec::lms200_half_degree(0.01), 0.0, &mut rng);
        let lines = extract_lines(&scan, &MOUNT, &extraction_config(0.01));
        let transform = Pose2::new(tx, ty, tt);
        let mut map = SegmentIndex::new();
        for l in &lines {
            map.insert(l.transformed(&transform));
        }
        let predicted = Pose2::new(tx + ex, ty + ey, tt + et);
        let r = localize(&lines, &map, predicted, &prior(), &LocalizerConfig::default()).unwrap();
        // Not exact: the prior pulls towards the prediction with a weight
        // about 10⁻⁵ of the lines'.
        prop_assert!((r.pose.x - tx).abs() < 1e-4 && (r.pose.y - ty).abs() < 1e-4,
            "{:?} vs {:?}", r.pose, transform);
        // (With few lines and a prediction 0.15 rad off, up to ~6e-5 rad.)
        prop_assert!(wrap_angle(r.pose.theta - tt).abs() < 1e-4);
        prop_assert_eq!(r.matches.len(), lines.len());
        prop_assert!(r.matches.iter().all(|&(i, id)| id.0 as usize == i));
    }
}
