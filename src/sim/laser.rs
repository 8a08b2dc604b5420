//! The simulated world as the LMS200 emulator's range source: the emulated
//! sensor rides on whatever carries it (a scripted [`Tour`] or a simulated
//! robot driven by the daemon, see [`Carrier`]) and measures by ray casting.

use lms200::emulator::RangeSource;

use super::rng::Rng;
use super::tour::Tour;
use super::world::World;
use crate::geometry::Pose2;

/// Where the robot carrying the sensor truly is at a time.
pub trait Carrier: Send {
    /// The robot's true pose (world frame, m and rad) at `t` seconds on the
    /// emulator's clock.
    fn pose_at(&mut self, t: f64) -> Pose2;
}

impl Carrier for Tour {
    fn pose_at(&mut self, t: f64) -> Pose2 {
        Tour::pose_at(self, t)
    }
}

/// Ranges for the emulator from a world, the robot carrying the sensor and
/// the laser's mounting pose on it.
#[derive(Debug)]
pub struct WorldRangeSource<C = Tour> {
    world: World,
    carrier: C,
    /// Laser pose in the robot frame.
    mount: Pose2,
    /// Largest range the sensor reports (m); beyond it, no echo.
    max_range: f64,
    /// Standard deviation of the range noise (m); the LMS200's is ~1 cm.
    range_sigma: f64,
    rng: Rng,
}

impl<C: Carrier> WorldRangeSource<C> {
    pub fn new(
        world: World,
        carrier: C,
        mount: Pose2,
        max_range: f64,
        range_sigma: f64,
        seed: u64,
    ) -> Self {
        WorldRangeSource {
            world,
            carrier,
            mount,
            max_range,
            range_sigma,
            rng: Rng::new(seed),
        }
    }
}

impl<C: Carrier> RangeSource for WorldRangeSource<C> {
    fn ranges_m(&mut self, time_s: f64, beam_angles_rad: &[f64]) -> Vec<f64> {
        let sensor = self.carrier.pose_at(time_s).compose(&self.mount);
        beam_angles_rad
            .iter()
            .map(|a| {
                let (s, c) = (sensor.theta + a).sin_cos();
                match self
                    .world
                    .cast_ray([sensor.x, sensor.y], [c, s], self.max_range)
                {
                    Some(r) => (r + self.rng.normal(self.range_sigma)).max(0.0),
                    None => f64::INFINITY,
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_follow_the_tour() {
        let world = World::loop_around_block();
        let tour = Tour::new(
            vec![Pose2::new(1.0, 1.0, 0.0), Pose2::new(5.0, 1.0, 0.0)],
            1.0,
            1.0,
        );
        let mut src = WorldRangeSource::new(world, tour, Pose2::IDENTITY, 8.183, 0.0, 1);
        // Straight right (-90°) sees the outer wall y = 0 at 1 m; straight
        // ahead the far wall x = 12.
        let at0 = src.ranges_m(0.0, &[-std::f64::consts::FRAC_PI_2, 0.0]);
        assert!((at0[0] - 1.0).abs() < 1e-9);
        assert!(at0[1].is_infinite(), "11 m is beyond 8.183 m");
        let at4 = src.ranges_m(4.0, &[0.0]);
        assert!((at4[0] - 7.0).abs() < 1e-9);
    }
}
