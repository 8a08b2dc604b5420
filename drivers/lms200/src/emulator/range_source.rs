//! Where the emulator's measured distances come from.
//!
//! The emulator asks a [`RangeSource`] for one range per beam whenever a scan
//! completes; the simulator plugs its ray caster in here. The default,
//! [`RoomRangeSource`], is a fixed rectangular room with one pillar, enough to
//! give plausible, structured scans without any world file.

/// A source of ranges in metres for the emulated sensor.
pub trait RangeSource: Send {
    /// Ranges in metres, one per beam angle (radians, sensor frame: x forward,
    /// y left, counter-clockwise; see DESIGN.md). `time_s` is the emulator time
    /// of the scan's mid-sweep in seconds since the emulator was created (or
    /// last powered up). Return `f64::INFINITY` or NaN for
    /// "no echo"; the emulator maps it to the sensor's special values.
    fn ranges_m(&mut self, time_s: f64, beam_angles_rad: &[f64]) -> Vec<f64>;
}

/// An axis-aligned rectangular room seen from a fixed pose, with a square pillar.
///
/// The sensor sits at `sensor_xy_m` facing +x. Walls are the rectangle
/// `[0, width] × [0, depth]`; the pillar is a square of side `pillar_side_m`
/// centred at `pillar_xy_m`. A slow sinusoidal "breathing" of the far wall
/// (amplitude `wobble_m`, 0.5 Hz) makes successive scans differ, so a link that
/// replays an old scan is caught by value comparisons.
#[derive(Debug, Clone)]
pub struct RoomRangeSource {
    /// Room extent along x, metres.
    pub width_m: f64,
    /// Room extent along y, metres.
    pub depth_m: f64,
    /// Sensor position inside the room, metres.
    pub sensor_xy_m: (f64, f64),
    /// Pillar centre, metres.
    pub pillar_xy_m: (f64, f64),
    /// Pillar side length, metres.
    pub pillar_side_m: f64,
    /// Amplitude of the far-wall motion, metres.
    pub wobble_m: f64,
}

impl Default for RoomRangeSource {
    /// A 6 m × 4 m room (fits the 8 m mm-mode range), sensor near the back wall.
    fn default() -> Self {
        Self {
            width_m: 6.0,
            depth_m: 4.0,
            sensor_xy_m: (0.5, 2.0),
            pillar_xy_m: (3.0, 1.2),
            pillar_side_m: 0.4,
            wobble_m: 0.05,
        }
    }
}

impl RoomRangeSource {
    /// Distance along the ray from `origin` in direction `dir` to the nearest
    /// hit with an axis-aligned box `[lo, hi]`, seen from inside or outside.
    fn ray_box(
        origin: (f64, f64),
        dir: (f64, f64),
        lo: (f64, f64),
        hi: (f64, f64),
        inside: bool,
    ) -> Option<f64> {
        let mut t_near = f64::NEG_INFINITY;
        let mut t_far = f64::INFINITY;
        for (o, d, l, h) in [(origin.0, dir.0, lo.0, hi.0), (origin.1, dir.1, lo.1, hi.1)] {
            if d.abs() < 1e-12 {
                if o < l || o > h {
                    return None;
                }
                continue;
            }
            let (t1, t2) = ((l - o) / d, (h - o) / d);
            let (a, b) = if t1 < t2 { (t1, t2) } else { (t2, t1) };
            t_near = t_near.max(a);
            t_far = t_far.min(b);
        }
        if t_near > t_far {
            return None;
        }
        let t = if inside { t_far } else { t_near };
        (t > 0.0).then_some(t)
    }
}

impl RangeSource for RoomRangeSource {
    fn ranges_m(&mut self, time_s: f64, beam_angles_rad: &[f64]) -> Vec<f64> {
        let width = self.width_m + self.wobble_m * (std::f64::consts::PI * time_s).sin();
        let half = self.pillar_side_m / 2.0;
        let pillar_lo = (self.pillar_xy_m.0 - half, self.pillar_xy_m.1 - half);
        let pillar_hi = (self.pillar_xy_m.0 + half, self.pillar_xy_m.1 + half);
        beam_angles_rad
            .iter()
            .map(|&a| {
                let dir = (a.cos(), a.sin());
                let wall = Self::ray_box(
                    self.sensor_xy_m,
                    dir,
                    (0.0, 0.0),
                    (width, self.depth_m),
                    true,
                );
                let pillar = Self::ray_box(self.sensor_xy_m, dir, pillar_lo, pillar_hi, false);
                match (wall, pillar) {
                    (Some(w), Some(p)) => w.min(p),
                    (Some(w), None) => w,
                    (None, Some(p)) => p,
                    (None, None) => f64::INFINITY,
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn straight_ahead_hits_far_wall() {
        let mut room = RoomRangeSource {
            wobble_m: 0.0,
            ..RoomRangeSource::default()
        };
        let r = room.ranges_m(0.0, &[0.0]);
        assert!((r[0] - 5.5).abs() < 1e-9, "{r:?}");
    }

    #[test]
    fn left_and_right_hit_side_walls() {
        let mut room = RoomRangeSource {
            wobble_m: 0.0,
            ..RoomRangeSource::default()
        };
        let r = room.ranges_m(
            0.0,
            &[std::f64::consts::FRAC_PI_2, -std::f64::consts::FRAC_PI_2],
        );
        assert!(
            (r[0] - 2.0).abs() < 1e-9 && (r[1] - 2.0).abs() < 1e-9,
            "{r:?}"
        );
    }

    #[test]
    fn pillar_shadows_the_wall() {
        let mut room = RoomRangeSource {
            wobble_m: 0.0,
            ..RoomRangeSource::default()
        };
        // Direction from the sensor (0.5, 2.0) to the pillar centre (3.0, 1.2).
        let a = (1.2f64 - 2.0).atan2(3.0 - 0.5);
        let r = room.ranges_m(0.0, &[a]);
        let centre_dist = ((2.5f64).powi(2) + 0.8f64.powi(2)).sqrt();
        assert!(r[0] < centre_dist && r[0] > centre_dist - 0.3, "{r:?}");
    }

    #[test]
    fn every_beam_of_a_half_circle_hits_something_within_8_m() {
        let mut room = RoomRangeSource::default();
        let angles: Vec<f64> = (0..=360)
            .map(|i| (-90.0 + 0.5 * i as f64).to_radians())
            .collect();
        let r = room.ranges_m(1.3, &angles);
        assert_eq!(r.len(), 361);
        assert!(r.iter().all(|x| x.is_finite() && *x > 0.0 && *x < 8.0));
    }
}
