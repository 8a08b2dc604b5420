//! [`open_way`]: the way a robot can drive farthest in what its scan
//! shows. A robot that does not know where it is in its map, and has
//! turned in place without telling look-alike places apart (two stretches
//! of a corridor that look the same within the sensor's reach), drives
//! that way so its scans reach what tells them apart. Everything is in the
//! robot frame, from the scan alone: no map pose is trusted.

/// How far (m) a disc of `radius` (m) at the origin travels in
/// `direction` (rad) before it touches one of `points` (robot frame, m),
/// at most `reach` (m). Points behind it or beside the band it sweeps do
/// not stop it; one it touches already gives 0.
pub fn free_run(points: &[[f64; 2]], radius: f64, direction: f64, reach: f64) -> f64 {
    let (s, c) = direction.sin_cos();
    points.iter().fold(reach.max(0.0), |run, p| {
        let along = p[0] * c + p[1] * s;
        let across = (p[1] * c - p[0] * s).abs();
        if across >= radius || along <= 0.0 {
            return run;
        }
        let touch = along - (radius * radius - across * across).sqrt();
        run.min(touch.max(0.0))
    })
}

/// The direction (rad, robot frame) within `half_angle` (rad) of forward,
/// in steps of about half a degree, along which a disc of `radius` runs
/// farthest (see [`free_run`]), and that run (m). Where a sector of
/// directions runs as far (within a centimetre), its middle: the way
/// through a doorway or down a corridor keeps off both sides. The widest
/// such sector wins, then the one nearest forward. None for a half angle
/// that is not a finite number ≥ 0.
pub fn open_way(
    points: &[[f64; 2]],
    radius: f64,
    half_angle: f64,
    reach: f64,
) -> Option<(f64, f64)> {
    if !(half_angle.is_finite() && half_angle >= 0.0) {
        return None;
    }
    let steps = (4.0 * half_angle.to_degrees()).ceil().clamp(1.0, 720.0) as usize;
    let directions: Vec<f64> = (0..=steps)
        .map(|i| -half_angle + 2.0 * half_angle * i as f64 / steps as f64)
        .collect();
    let runs: Vec<f64> = directions
        .iter()
        .map(|&d| free_run(points, radius, d, reach))
        .collect();
    let longest = runs.iter().copied().fold(0.0, f64::max);
    // Sectors of directions as open as the most open: (first, last).
    let mut sectors: Vec<(usize, usize)> = Vec::new();
    for (i, &run) in runs.iter().enumerate() {
        if run < longest - 0.01 {
            continue;
        }
        match sectors.last_mut() {
            Some((_, last)) if *last + 1 == i => *last = i,
            _ => sectors.push((i, i)),
        }
    }
    let middle = |&(first, last): &(usize, usize)| 0.5 * (directions[first] + directions[last]);
    let best = sectors.iter().min_by(|a, b| {
        (b.1 - b.0)
            .cmp(&(a.1 - a.0))
            .then(middle(a).abs().total_cmp(&middle(b).abs()))
    })?;
    let direction = middle(best);
    Some((direction, free_run(points, radius, direction, reach)))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A 2 m wide corridor along x, the robot on its centre line, walls
    /// sampled every 5 cm from 0.5 m behind to 8 m ahead.
    fn corridor() -> Vec<[f64; 2]> {
        (0..170)
            .flat_map(|i| {
                let x = -0.5 + 0.05 * f64::from(i);
                [[x, 1.0], [x, -1.0]]
            })
            .collect()
    }

    #[test]
    fn in_a_corridor_the_open_way_is_along_it() {
        let (direction, run) = open_way(&corridor(), 0.37, 60f64.to_radians(), 20.0).unwrap();
        assert!(direction.abs() < 1e-9, "{direction}");
        assert!((run - 20.0).abs() < 1e-9, "{run}");
        // Nothing in view: straight ahead.
        assert_eq!(open_way(&[], 0.37, 1.0, 5.0), Some((0.0, 5.0)));
        assert_eq!(open_way(&corridor(), 0.37, f64::NAN, 5.0), None);
        // Across it, the disc touches the wall 1 m away after 0.63 m.
        let across = free_run(&corridor(), 0.37, std::f64::consts::FRAC_PI_2, 20.0);
        assert!((across - 0.63).abs() < 0.01, "{across}");
    }

    #[test]
    fn a_wall_ahead_with_a_gap_is_left_through_the_gap() {
        // A wall 3 m ahead, open between y 0.5 and 1.5.
        let wall: Vec<[f64; 2]> = (0..81)
            .map(|i| [3.0, -4.0 + 0.1 * f64::from(i)])
            .filter(|p| !(0.5..=1.5).contains(&p[1]))
            .collect();
        let (direction, run) = open_way(&wall, 0.37, 60f64.to_radians(), 8.0).unwrap();
        // Through the middle of the gap between the points either side
        // (y 0.4 and 1.6), not grazing one jamb.
        let aim = 1.0f64.atan2(3.0);
        assert!(
            (direction - aim).abs() < 1.0f64.to_radians(),
            "{direction} vs {aim}"
        );
        assert!(run > 6.0, "{run}");
    }

    proptest! {
        /// The run never passes a point the disc would overlap, and where
        /// it stops short of the reach the disc touches one.
        #[test]
        fn the_run_stops_at_the_first_touch(
            points in proptest::collection::vec((-5.0f64..5.0, -5.0f64..5.0), 1..40),
            direction in -3.2f64..3.2,
            radius in 0.05f64..0.6,
        ) {
            let points: Vec<[f64; 2]> = points.iter().map(|&(x, y)| [x, y]).collect();
            let reach = 10.0;
            let run = free_run(&points, radius, direction, reach);
            prop_assert!((0.0..=reach).contains(&run));
            let (s, c) = direction.sin_cos();
            let overlaps = |d: f64| {
                points.iter().any(|p| (p[0] - d * c).hypot(p[1] - d * s) < radius - 1e-9)
            };
            // Nothing touched on the way (sampled every centimetre), unless
            // the disc started on a point.
            if !overlaps(0.0) {
                let mut d = 0.0;
                while d < run - 1e-6 {
                    prop_assert!(!overlaps(d), "overlap at {d} before {run}");
                    d += 0.01;
                }
            }
            // Stopped short of the reach, it touches a point.
            if run < reach && run > 0.0 {
                let touches = points
                    .iter()
                    .any(|p| (p[0] - run * c).hypot(p[1] - run * s) <= radius + 1e-6);
                prop_assert!(touches, "nothing at {run}");
            }
        }
    }
}
