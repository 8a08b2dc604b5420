//! Holonomic base kinematics in SI units.
//!
//! Frames: [`Twist`] is expressed in the robot frame (x forward, y left,
//! counter-clockwise positive); [`BasePose`] is in the odometry frame.

use std::f64::consts::{PI, TAU};

/// Body velocity in the robot frame: `vx`, `vy` in m/s, `omega` in rad/s (CCW+).
///
/// A holonomic base translates in x and y and turns independently.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Twist {
    /// Forward velocity, m/s.
    pub vx: f64,
    /// Leftward velocity, m/s.
    pub vy: f64,
    /// Yaw rate, rad/s, counter-clockwise positive.
    pub omega: f64,
}

impl Twist {
    /// The zero twist (stand still).
    pub const ZERO: Twist = Twist {
        vx: 0.0,
        vy: 0.0,
        omega: 0.0,
    };

    /// Creates a twist from m/s, m/s, rad/s.
    #[must_use]
    pub const fn new(vx: f64, vy: f64, omega: f64) -> Self {
        Self { vx, vy, omega }
    }

    /// True when all components are finite.
    #[must_use]
    pub fn is_finite(&self) -> bool {
        self.vx.is_finite() && self.vy.is_finite() && self.omega.is_finite()
    }

    /// Linear speed `hypot(vx, vy)`, m/s.
    #[must_use]
    pub fn linear_speed(&self) -> f64 {
        self.vx.hypot(self.vy)
    }
}

/// Pose in the odometry frame: `x`, `y` in metres, `theta` in radians in (-π, π].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BasePose {
    /// Position x, m.
    pub x: f64,
    /// Position y, m.
    pub y: f64,
    /// Heading, rad, CCW from the x axis.
    pub theta: f64,
}

impl BasePose {
    /// Creates a pose from m, m, rad (heading is wrapped).
    #[must_use]
    pub fn new(x: f64, y: f64, theta: f64) -> Self {
        Self {
            x,
            y,
            theta: wrap_angle(theta),
        }
    }
}

/// Wraps an angle in radians to (-π, π].
#[must_use]
pub fn wrap_angle(a: f64) -> f64 {
    // Within one turn either way the remainder is `a` itself, exactly:
    // the division's remainder is spared (the same bits as `rem_euclid`).
    let r = if a.abs() < TAU {
        if a < 0.0 { a + TAU } else { a }
    } else {
        a.rem_euclid(TAU)
    };
    if r > PI { r - TAU } else { r }
}

/// Integrates `pose` under a constant robot-frame `twist` for `dt` seconds.
///
/// Exact for constant twist (arc in the rotating frame); for `|omega·dt|`
/// near zero a Taylor series is used. Heading is wrapped to (-π, π].
#[must_use]
pub fn integrate(pose: BasePose, twist: Twist, dt: f64) -> BasePose {
    let phi = twist.omega * dt;
    // a = ∫ cos(ωs) ds = sin(φ)/ω, b = ∫ sin(ωs) ds = (1 - cos φ)/ω over [0, dt].
    let (a, b) = if phi.abs() < 1e-3 {
        let p2 = phi * phi;
        (
            dt * (1.0 - p2 / 6.0 + p2 * p2 / 120.0),
            dt * phi * (0.5 - p2 / 24.0 + p2 * p2 / 720.0),
        )
    } else {
        (phi.sin() / twist.omega, (1.0 - phi.cos()) / twist.omega)
    };
    let lx = a * twist.vx - b * twist.vy;
    let ly = b * twist.vx + a * twist.vy;
    let (s, c) = pose.theta.sin_cos();
    BasePose {
        x: pose.x + c * lx - s * ly,
        y: pose.y + s * lx + c * ly,
        theta: wrap_angle(pose.theta + phi),
    }
}

/// Velocity and acceleration limits of the base.
///
/// The [`Default`] values are conservative assumptions for a Nomadic XR4000,
/// not manufacturer figures: 1.0 m/s, 1.57 rad/s, 1.0 m/s², 3.0 rad/s².
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// Maximum linear speed (norm of vx, vy), m/s.
    pub max_linear: f64,
    /// Maximum yaw rate magnitude, rad/s.
    pub max_angular: f64,
    /// Maximum linear acceleration (norm), m/s².
    pub max_linear_accel: f64,
    /// Maximum yaw acceleration magnitude, rad/s².
    pub max_angular_accel: f64,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_linear: 1.0,
            max_angular: 1.57,
            max_linear_accel: 1.0,
            max_angular_accel: 3.0,
        }
    }
}

impl Limits {
    /// Scales the linear vector down to `max_linear` (keeping direction) and
    /// clamps `omega` to `±max_angular`.
    #[must_use]
    pub fn clamp_speed(&self, t: Twist) -> Twist {
        let max_lin = self.max_linear.max(0.0);
        let max_ang = self.max_angular.max(0.0);
        let speed = t.linear_speed();
        let k = if speed > max_lin {
            max_lin / speed
        } else {
            1.0
        };
        Twist {
            vx: t.vx * k,
            vy: t.vy * k,
            omega: t.omega.clamp(-max_ang, max_ang),
        }
    }

    /// See [`limit`].
    #[must_use]
    pub fn limit(&self, previous: Twist, wanted: Twist, dt: f64) -> Twist {
        limit(self, previous, wanted, dt)
    }
}

/// Limits `wanted` given the `previous` command sent `dt` seconds ago.
///
/// Clamps speed first (linear vector scaled, direction kept), then the change
/// from `previous` to `max_*_accel · dt`. Speed limits always hold; the
/// acceleration limit holds whenever `previous` is within the speed limits
/// (an out-of-limit `previous` is clamped first). Any non-finite input or
/// negative `dt` yields [`Twist::ZERO`].
#[must_use]
pub fn limit(limits: &Limits, previous: Twist, wanted: Twist, dt: f64) -> Twist {
    if !previous.is_finite() || !wanted.is_finite() || !dt.is_finite() || dt < 0.0 {
        return Twist::ZERO;
    }
    let prev = limits.clamp_speed(previous);
    let want = limits.clamp_speed(wanted);
    let (dvx, dvy) = (want.vx - prev.vx, want.vy - prev.vy);
    let dv = dvx.hypot(dvy);
    let max_dv = limits.max_linear_accel.max(0.0) * dt;
    let k = if dv > max_dv { max_dv / dv } else { 1.0 };
    let max_dw = limits.max_angular_accel.max(0.0) * dt;
    let dw = (want.omega - prev.omega).clamp(-max_dw, max_dw);
    let out = Twist {
        vx: prev.vx + dvx * k,
        vy: prev.vy + dvy * k,
        omega: prev.omega + dw,
    };
    if out.is_finite() {
        // Guard against rounding pushing the result a hair over the limit.
        limits.clamp_speed(out)
    } else {
        Twist::ZERO
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    fn pose_close(a: BasePose, b: BasePose, tol: f64) -> bool {
        close(a.x, b.x, tol) && close(a.y, b.y, tol) && wrap_angle(a.theta - b.theta).abs() <= tol
    }

    #[test]
    fn wrap_range() {
        assert!(close(wrap_angle(PI), PI, 1e-12));
        assert!(close(wrap_angle(-PI), PI, 1e-12));
        assert!(close(wrap_angle(3.0 * PI / 2.0), -PI / 2.0, 1e-12));
        assert!(close(wrap_angle(0.1 + 4.0 * TAU), 0.1, 1e-9));
    }

    #[test]
    fn pure_rotation() {
        let p = integrate(BasePose::new(1.0, 2.0, 0.0), Twist::new(0.0, 0.0, 0.5), 2.0);
        assert!(pose_close(p, BasePose::new(1.0, 2.0, 1.0), 1e-12));
    }

    #[test]
    fn straight_line_forward_and_sideways() {
        let p = integrate(
            BasePose::new(0.0, 0.0, PI / 2.0),
            Twist::new(1.0, 0.0, 0.0),
            2.0,
        );
        assert!(pose_close(p, BasePose::new(0.0, 2.0, PI / 2.0), 1e-12));
        // Holonomic: moving left (vy > 0) while facing +x goes to +y.
        let p = integrate(BasePose::default(), Twist::new(0.0, 0.5, 0.0), 2.0);
        assert!(pose_close(p, BasePose::new(0.0, 1.0, 0.0), 1e-12));
    }

    #[test]
    fn circle_returns_to_start() {
        let start = BasePose::new(0.3, -0.2, 0.7);
        let w = 0.5;
        let t = TAU / w;
        let twist = Twist::new(0.4, 0.1, w);
        assert!(pose_close(integrate(start, twist, t), start, 1e-9));
        // Half circle: forward motion with CCW turn, radius v/ω = 2 m, from
        // heading 0 ends 4 m to the left.
        let p = integrate(BasePose::default(), Twist::new(1.0, 0.0, 0.5), PI / 0.5);
        assert!(pose_close(p, BasePose::new(0.0, 4.0, PI), 1e-9));
        // Many small steps agree with one big step.
        let mut q = start;
        for _ in 0..1000 {
            q = integrate(q, twist, t / 1000.0);
        }
        assert!(pose_close(q, start, 1e-9));
    }

    #[test]
    fn series_branch_matches_closed_form() {
        let tw = Twist::new(0.7, -0.3, 1.5e-3);
        let a = integrate(BasePose::new(0.0, 0.0, 0.2), tw, 1.0); // closed form (φ = 1.5e-3)
        let b = integrate(BasePose::new(0.0, 0.0, 0.2), tw, 0.5); // series
        let b = integrate(b, tw, 0.5);
        assert!(pose_close(a, b, 1e-12));
    }

    #[test]
    fn limit_clamps_speed_keeping_direction() {
        let l = Limits::default();
        let out = l.clamp_speed(Twist::new(3.0, 4.0, -10.0));
        assert!(close(out.vx, 0.6, 1e-12) && close(out.vy, 0.8, 1e-12));
        assert!(close(out.omega, -1.57, 1e-12));
    }

    #[test]
    fn limit_clamps_acceleration() {
        let l = Limits::default();
        let out = limit(&l, Twist::ZERO, Twist::new(1.0, 0.0, 1.5), 0.1);
        assert!(close(out.vx, 0.1, 1e-12) && close(out.vy, 0.0, 1e-12));
        assert!(close(out.omega, 0.3, 1e-12));
        // Already reachable: passes through.
        let out = limit(
            &l,
            Twist::new(0.5, 0.0, 0.0),
            Twist::new(0.55, 0.0, 0.1),
            0.1,
        );
        assert_eq!(out, Twist::new(0.55, 0.0, 0.1));
    }

    #[test]
    fn non_finite_gives_zero() {
        let l = Limits::default();
        let good = Twist::new(0.2, 0.0, 0.0);
        assert_eq!(
            limit(&l, good, Twist::new(f64::NAN, 0.0, 0.0), 0.1),
            Twist::ZERO
        );
        assert_eq!(
            limit(&l, good, Twist::new(0.0, 0.0, f64::INFINITY), 0.1),
            Twist::ZERO
        );
        assert_eq!(
            limit(&l, Twist::new(0.0, f64::NAN, 0.0), good, 0.1),
            Twist::ZERO
        );
        assert_eq!(limit(&l, good, good, f64::NAN), Twist::ZERO);
        assert_eq!(limit(&l, good, good, -1.0), Twist::ZERO);
    }

    proptest! {
        #[test]
        fn wrap_angle_gives_the_bits_of_the_remainder(
            a in prop_oneof![-10.0..10.0f64, -1e6..1e6f64, Just(-0.0), Just(TAU), Just(-TAU)],
        ) {
            let r = a.rem_euclid(TAU);
            let reference = if r > PI { r - TAU } else { r };
            prop_assert_eq!(wrap_angle(a).to_bits(), reference.to_bits(), "{}", a);
        }

        #[test]
        fn integrate_composes(
            x in -10.0..10.0f64, y in -10.0..10.0f64, th in -PI..PI,
            vx in -2.0..2.0f64, vy in -2.0..2.0f64, w in -3.0..3.0f64,
            dt in 0.0..5.0f64,
        ) {
            let p = BasePose::new(x, y, th);
            let tw = Twist::new(vx, vy, w);
            let once = integrate(p, tw, dt);
            let twice = integrate(integrate(p, tw, dt / 2.0), tw, dt / 2.0);
            prop_assert!(pose_close(once, twice, 1e-9), "{once:?} vs {twice:?}");
            prop_assert!(once.theta > -PI && once.theta <= PI);
        }

        #[test]
        fn limit_respects_limits(
            pvx in -1.0..1.0f64, pvy in -1.0..1.0f64, pw in -1.57..1.57f64,
            wvx in -100.0..100.0f64, wvy in -100.0..100.0f64, ww in -100.0..100.0f64,
            dt in 0.0..2.0f64,
        ) {
            let l = Limits::default();
            let prev = l.clamp_speed(Twist::new(pvx, pvy, pw));
            let out = limit(&l, prev, Twist::new(wvx, wvy, ww), dt);
            let eps = 1e-9;
            prop_assert!(out.linear_speed() <= l.max_linear + eps);
            prop_assert!(out.omega.abs() <= l.max_angular + eps);
            let dv = (out.vx - prev.vx).hypot(out.vy - prev.vy);
            prop_assert!(dv <= l.max_linear_accel * dt + eps);
            prop_assert!((out.omega - prev.omega).abs() <= l.max_angular_accel * dt + eps);
        }

        #[test]
        fn limit_speed_holds_for_any_previous(
            pvx in -1e6..1e6f64, pvy in -1e6..1e6f64, pw in -1e6..1e6f64,
            wvx in -1e6..1e6f64, wvy in -1e6..1e6f64, ww in -1e6..1e6f64,
            dt in 0.0..10.0f64,
        ) {
            let l = Limits::default();
            let out = limit(&l, Twist::new(pvx, pvy, pw), Twist::new(wvx, wvy, ww), dt);
            prop_assert!(out.linear_speed() <= l.max_linear + 1e-9);
            prop_assert!(out.omega.abs() <= l.max_angular + 1e-9);
        }
    }
}
