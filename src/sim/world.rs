//! Simulated worlds: wall segments in the map frame (m) with a parry BVH
//! for ray casting, and a few built-in floor plans.

use parry2d_f64::bounding_volume::Aabb;
use parry2d_f64::math::Vector;
use parry2d_f64::partitioning::Bvh;
use parry2d_f64::query::{Ray, RayCast};
use parry2d_f64::shape::Segment;

/// A set of wall segments a simulated laser can see.
#[derive(Debug, Clone, Default)]
pub struct World {
    walls: Vec<[[f64; 2]; 2]>,
    bvh: Bvh,
}

/// A closed tour round the furniture of [`World::room_with_boxes`], clear
/// of every obstacle (m): the run that maps the room in tests and benches.
pub const ROOM_WITH_BOXES_TOUR: [[f64; 2]; 7] = [
    [2.0, 2.0],
    [5.0, 2.5],
    [6.8, 3.0],
    [5.0, 4.4],
    [3.4, 3.2],
    [1.8, 2.6],
    [2.0, 2.0],
];

impl World {
    /// An empty world.
    pub fn new() -> Self {
        Self::default()
    }

    /// A world made of the given wall segments.
    pub fn from_segments(walls: impl IntoIterator<Item = [[f64; 2]; 2]>) -> Self {
        let mut w = World::new();
        for [a, b] in walls {
            w.add_wall(a, b);
        }
        w
    }

    /// Adds the wall from `a` to `b` (m). Non-finite walls are ignored.
    pub fn add_wall(&mut self, a: [f64; 2], b: [f64; 2]) {
        if ![a[0], a[1], b[0], b[1]].iter().all(|v| v.is_finite()) {
            return;
        }
        let Ok(key) = u32::try_from(self.walls.len()) else {
            return;
        };
        let aabb = Aabb::new(
            Vector::new(a[0].min(b[0]), a[1].min(b[1])),
            Vector::new(a[0].max(b[0]), a[1].max(b[1])),
        );
        self.walls.push([a, b]);
        self.bvh.insert(aabb, key);
    }

    /// Adds the walls of a polyline through `points`, closed back to the
    /// first point when `closed`.
    pub fn add_polyline(&mut self, points: &[[f64; 2]], closed: bool) {
        for w in points.windows(2) {
            self.add_wall(w[0], w[1]);
        }
        if closed && points.len() > 2 {
            self.add_wall(points[points.len() - 1], points[0]);
        }
    }

    /// Adds a rectangular box centred at `centre` with half sizes `half`
    /// (m), turned by `angle` (rad).
    pub fn add_box(&mut self, centre: [f64; 2], half: [f64; 2], angle: f64) {
        let (s, c) = angle.sin_cos();
        let corner = |u: f64, v: f64| {
            [
                centre[0] + c * u * half[0] - s * v * half[1],
                centre[1] + s * u * half[0] + c * v * half[1],
            ]
        };
        let pts = [
            corner(-1.0, -1.0),
            corner(1.0, -1.0),
            corner(1.0, 1.0),
            corner(-1.0, 1.0),
        ];
        self.add_polyline(&pts, true);
    }

    /// The walls, in insertion order.
    pub fn walls(&self) -> &[[[f64; 2]; 2]] {
        &self.walls
    }

    /// Distance (m) from `origin` along the unit vector `dir` to the first
    /// wall, if one is hit within `max_range`.
    pub fn cast_ray(&self, origin: [f64; 2], dir: [f64; 2], max_range: f64) -> Option<f64> {
        let ray = Ray::new(
            Vector::new(origin[0], origin[1]),
            Vector::new(dir[0], dir[1]),
        );
        self.bvh
            .cast_ray(&ray, max_range, |leaf, best| {
                let [a, b] = *self.walls.get(leaf as usize)?;
                Segment::new(Vector::new(a[0], a[1]), Vector::new(b[0], b[1]))
                    .cast_local_ray(&ray, best, true)
            })
            .map(|(_, toi)| toi)
    }

    /// An 8 m × 6 m room with a cut corner (a 45° wall), three boxes of
    /// furniture (one turned) and the four 4 cm legs of a chair. Free floor
    /// around (1.5..7, 1..5) except the furniture.
    pub fn room_with_boxes() -> World {
        let mut w = World::new();
        w.add_polyline(
            &[[0.0, 0.0], [8.0, 0.0], [8.0, 6.0], [1.0, 6.0], [0.0, 5.0]],
            true,
        );
        w.add_box([2.2, 4.3], [0.5, 0.3], 0.3);
        w.add_box([6.3, 1.2], [0.4, 0.4], 0.0);
        w.add_box([5.6, 5.65], [0.6, 0.35], 0.0);
        for (dx, dy) in [(-0.2, -0.2), (0.2, -0.2), (0.2, 0.2), (-0.2, 0.2)] {
            w.add_box([3.6 + dx, 1.6 + dy], [0.02, 0.02], 0.0);
        }
        w
    }

    /// A straight corridor along +x from x = 0 to `length`, `width` wide,
    /// centred on y = 0, closed at both ends. With `door_spacing`, door
    /// recesses 0.9 m wide and 0.15 m deep alternate between the two sides,
    /// the first at x = `door_spacing`.
    pub fn corridor(length: f64, width: f64, door_spacing: Option<f64>) -> World {
        const DOOR_WIDTH: f64 = 0.9;
        const DOOR_DEPTH: f64 = 0.15;
        let h = 0.5 * width;
        let mut doors = Vec::new();
        if let Some(spacing) = door_spacing.filter(|s| *s > DOOR_WIDTH) {
            let mut x = spacing;
            while x + DOOR_WIDTH < length {
                doors.push(x);
                x += spacing;
            }
        }
        let mut w = World::new();
        for (side, sign) in [(0usize, -1.0), (1usize, 1.0)] {
            let y = sign * h;
            let mut pts = vec![[0.0, y]];
            for &x in doors.iter().skip(side).step_by(2) {
                let back = y + sign * DOOR_DEPTH;
                pts.extend([
                    [x, y],
                    [x, back],
                    [x + DOOR_WIDTH, back],
                    [x + DOOR_WIDTH, y],
                ]);
            }
            pts.push([length, y]);
            w.add_polyline(&pts, false);
        }
        w.add_wall([0.0, -h], [0.0, h]);
        w.add_wall([length, -h], [length, h]);
        w
    }

    /// A 30 m corridor, 2 m wide, with a door every 5 m.
    pub fn corridor_with_doors() -> World {
        World::corridor(30.0, 2.0, Some(5.0))
    }

    /// A 2 m wide loop around a central 8 m × 6 m block: outer walls
    /// (0, 0)–(12, 10), block (2, 2)–(10, 8).
    pub fn loop_around_block() -> World {
        let mut w = World::new();
        w.add_polyline(&[[0.0, 0.0], [12.0, 0.0], [12.0, 10.0], [0.0, 10.0]], true);
        w.add_polyline(&[[2.0, 2.0], [2.0, 8.0], [10.0, 8.0], [10.0, 2.0]], true);
        w
    }

    /// A 2 m wide corridor round a 20 m × 14 m block (a 68 m loop along
    /// its centre line, corners at (1, 1) and (23, 17)), with boxes against
    /// the outer walls so that places along a side differ: the loop-closure
    /// world, long enough for odometry drift to exceed every local gate.
    pub fn long_loop() -> World {
        let mut w = World::new();
        w.add_polyline(&[[0.0, 0.0], [24.0, 0.0], [24.0, 18.0], [0.0, 18.0]], true);
        w.add_polyline(&[[2.0, 2.0], [2.0, 16.0], [22.0, 16.0], [22.0, 2.0]], true);
        for (c, h) in [
            ([6.0, 0.25], [0.4, 0.25]),
            ([15.0, 0.2], [0.8, 0.2]),
            ([23.75, 7.0], [0.25, 0.6]),
            ([23.8, 13.0], [0.2, 0.3]),
            ([18.0, 17.75], [0.5, 0.25]),
            ([9.0, 17.8], [1.0, 0.2]),
            ([0.25, 12.0], [0.25, 0.4]),
            ([0.2, 5.0], [0.2, 0.7]),
        ] {
            w.add_box(c, h, 0.0);
        }
        w
    }

    /// A laboratory like the one mapped by Zhang & Ghosh (ICRA 2000): a
    /// 10 m × 8 m room, (0, 0)–(10, 8), with
    /// - benches along the south wall, x 1.5–4.5 and 6.2–9.0 (0.8 m and
    ///   0.7 m deep), desks along the north wall, x 1–3 and 4.5–6.5
    ///   (0.8 m deep), a 3 m bench along the west wall (y 2.5–5.5, 0.8 m
    ///   deep) and a 2 m shelf on the east wall (y 1.5–3.5, 0.4 m deep);
    /// - a 0.5 m square pillar centred at (6, 4.2) and a 1.4 m × 0.8 m table
    ///   centred at (3.4, 4.0), turned by 20°;
    /// - a 1 m door (y 5.5–6.5) through the 0.3 m east wall into a corridor
    ///   stub 2 m wide, (10.3, 5)–(14, 7), closed at its far end.
    ///
    /// Every passage the robot needs is at least 1 m wide (a 0.64 m robot
    /// with its clearance needs 0.74 m); furniture stands against the walls,
    /// so no pocket behind it is reachable. The wall at the door has the
    /// thickness of a masonry wall, so its jambs are 0.3 m faces the line
    /// extractor keeps (its shortest line is 0.2 m), not knife edges: seen
    /// at a grazing angle, a knife edge leaves a thin sliver of unexplored
    /// floor at the jamb, and the planner's mitred offset of that sliver by
    /// the robot's clearance closes the doorway.
    pub fn paper_lab() -> World {
        let mut w = World::new();
        // The room, the door through the east wall and the corridor stub.
        w.add_polyline(
            &[
                [0.0, 0.0],
                [10.0, 0.0],
                [10.0, 5.5],
                [10.3, 5.5],
                [10.3, 5.0],
                [14.0, 5.0],
                [14.0, 7.0],
                [10.3, 7.0],
                [10.3, 6.5],
                [10.0, 6.5],
                [10.0, 8.0],
                [0.0, 8.0],
            ],
            true,
        );
        // Benches, desks and the shelf against the walls.
        w.add_box([3.0, 0.4], [1.5, 0.4], 0.0);
        w.add_box([7.6, 0.35], [1.4, 0.35], 0.0);
        w.add_box([2.0, 7.6], [1.0, 0.4], 0.0);
        w.add_box([5.5, 7.6], [1.0, 0.4], 0.0);
        w.add_box([0.4, 4.0], [0.4, 1.5], 0.0);
        w.add_box([9.8, 2.5], [0.2, 1.0], 0.0);
        // The pillar and the free-standing table.
        w.add_box([6.0, 4.2], [0.25, 0.25], 0.0);
        w.add_box([3.4, 4.0], [0.7, 0.4], 20f64.to_radians());
        w
    }

    /// A 20 m corridor, 2 m wide, (0, −1)–(20, 1), closed at both ends,
    /// with three 4 m × 4 m rooms behind 0.3 m walls, opening off it
    /// through 1 m doorways: north of it (y 1.3–5.3) at x 2–6 (door
    /// x 3.5–4.5) and x 14–18 (door x 15.5–16.5), south of it
    /// (y −5.3 to −1.3) at x 8–12 (door x 9.5–10.5). The south room holds a 1 m × 0.8 m box centred at
    /// (10, −3.6), turned by 0.3 rad, with at least 1.1 m of floor round
    /// it. The walls are as thick as masonry so the door jambs are faces
    /// the line extractor keeps (see [`World::paper_lab`]).
    pub fn corridor_with_rooms() -> World {
        let mut w = World::new();
        w.add_polyline(
            &[
                [0.0, -1.0],
                // South room.
                [9.5, -1.0],
                [9.5, -1.3],
                [8.0, -1.3],
                [8.0, -5.3],
                [12.0, -5.3],
                [12.0, -1.3],
                [10.5, -1.3],
                [10.5, -1.0],
                [20.0, -1.0],
                [20.0, 1.0],
                // East room.
                [16.5, 1.0],
                [16.5, 1.3],
                [18.0, 1.3],
                [18.0, 5.3],
                [14.0, 5.3],
                [14.0, 1.3],
                [15.5, 1.3],
                [15.5, 1.0],
                // West room.
                [4.5, 1.0],
                [4.5, 1.3],
                [6.0, 1.3],
                [6.0, 5.3],
                [2.0, 5.3],
                [2.0, 1.3],
                [3.5, 1.3],
                [3.5, 1.0],
                [0.0, 1.0],
            ],
            true,
        );
        w.add_box([10.0, -3.6], [0.5, 0.4], 0.3);
        w
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn ray_hits_nearest_wall() {
        let w = World::loop_around_block();
        let d = w.cast_ray([1.0, 5.0], [1.0, 0.0], 20.0).unwrap();
        assert!((d - 1.0).abs() < 1e-12);
        let d = w.cast_ray([1.0, 5.0], [-1.0, 0.0], 20.0).unwrap();
        assert!((d - 1.0).abs() < 1e-12);
        assert_eq!(w.cast_ray([1.0, 5.0], [-1.0, 0.0], 0.5), None);
    }

    #[test]
    fn ray_matches_brute_force_in_the_room() {
        let w = World::room_with_boxes();
        for k in 0..720 {
            let a = k as f64 * std::f64::consts::TAU / 720.0;
            let dir = [a.cos(), a.sin()];
            let origin = [4.0, 3.0];
            let got = w.cast_ray(origin, dir, 100.0);
            let brute = w
                .walls()
                .iter()
                .filter_map(|&[p, q]| {
                    // Solve origin + t·dir = p + u·(q − p).
                    let e = [q[0] - p[0], q[1] - p[1]];
                    let den = dir[0] * e[1] - dir[1] * e[0];
                    if den.abs() < 1e-15 {
                        return None;
                    }
                    let f = [p[0] - origin[0], p[1] - origin[1]];
                    let t = (f[0] * e[1] - f[1] * e[0]) / den;
                    let u = (f[0] * dir[1] - f[1] * dir[0]) / den;
                    (t >= 0.0 && (0.0..=1.0).contains(&u)).then_some(t)
                })
                .fold(f64::INFINITY, f64::min);
            let got = got.unwrap();
            assert!((got - brute).abs() < 1e-9, "beam {k}: {got} vs {brute}");
        }
    }

    #[test]
    fn corridor_doors_alternate_sides() {
        let w = World::corridor(12.0, 2.0, Some(5.0));
        // Door at x = 5 on the right (y < 0), at x = 10 on the left.
        let right = w.cast_ray([5.45, 0.0], [0.0, -1.0], 10.0).unwrap();
        let left = w.cast_ray([5.45, 0.0], [0.0, 1.0], 10.0).unwrap();
        assert!((right - 1.15).abs() < 1e-12 && (left - 1.0).abs() < 1e-12);
        let left = w.cast_ray([10.45, 0.0], [0.0, 1.0], 10.0).unwrap();
        assert!((left - 1.15).abs() < 1e-12);
    }

    /// Distance (m) from `p` to the nearest wall of `w`.
    fn clearance(w: &World, p: [f64; 2]) -> f64 {
        w.walls()
            .iter()
            .map(|&[a, b]| {
                let e = [b[0] - a[0], b[1] - a[1]];
                let len2 = e[0] * e[0] + e[1] * e[1];
                let t = (((p[0] - a[0]) * e[0] + (p[1] - a[1]) * e[1]) / len2).clamp(0.0, 1.0);
                (p[0] - a[0] - t * e[0]).hypot(p[1] - a[1] - t * e[1])
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// Smallest wall clearance (m) along the polyline `route`, sampled
    /// every centimetre.
    fn route_clearance(w: &World, route: &[[f64; 2]]) -> f64 {
        let mut least = f64::INFINITY;
        for leg in route.windows(2) {
            let (a, b) = (leg[0], leg[1]);
            let n = ((b[0] - a[0]).hypot(b[1] - a[1]) / 0.01).ceil() as usize;
            for k in 0..=n {
                let t = k as f64 / n as f64;
                let p = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
                least = least.min(clearance(w, p));
            }
        }
        least
    }

    /// Whether every one of 720 rays from `p` hits a wall within `range`.
    fn enclosed(w: &World, p: [f64; 2], range: f64) -> bool {
        (0..720).all(|k| {
            let a = k as f64 * std::f64::consts::TAU / 720.0;
            w.cast_ray(p, [a.cos(), a.sin()], range).is_some()
        })
    }

    /// Clearance (m) of the XR4000 (radius 0.32 m) plus the planner's 5 cm
    /// margin.
    const ROBOT_CLEARANCE: f64 = 0.37;

    #[test]
    fn paper_lab_is_closed_and_its_door_is_1_m() {
        let w = World::paper_lab();
        assert_eq!(w.walls().len(), 12 + 8 * 4);
        for p in [[2.0, 2.0], [8.0, 4.0], [12.0, 6.0]] {
            assert!(enclosed(&w, p, 20.0), "{p:?}");
        }
        // Across the doorway, inside the 0.3 m wall: 1 m between the jambs.
        let d = w.cast_ray([10.15, 5.6], [0.0, 1.0], 10.0).unwrap();
        assert!((d - 0.9).abs() < 1e-12, "{d}");
        // Straight through the door to the stub's far end.
        let d = w.cast_ray([9.0, 6.0], [1.0, 0.0], 10.0).unwrap();
        assert!((d - 5.0).abs() < 1e-12, "{d}");
    }

    #[test]
    fn paper_lab_has_room_for_the_robot_round_the_furniture_and_through_the_door() {
        let w = World::paper_lab();
        // Round the table and the pillar, past the benches and desks, then
        // through the door to the end of the stub.
        let route = [
            [2.0, 2.0],
            [1.6, 6.5],
            [4.0, 6.2],
            [7.5, 6.5],
            [7.5, 2.0],
            [5.0, 2.0],
            [5.0, 5.6],
            [9.0, 6.0],
            [13.4, 6.0],
        ];
        let least = route_clearance(&w, &route);
        assert!(least >= ROBOT_CLEARANCE, "{least}");
    }

    #[test]
    fn corridor_with_rooms_is_closed_and_every_room_is_reachable() {
        let w = World::corridor_with_rooms();
        assert_eq!(w.walls().len(), 28 + 4);
        for p in [[1.0, 0.0], [4.0, 3.3], [10.0, -2.0], [16.0, 3.3]] {
            assert!(enclosed(&w, p, 30.0), "{p:?}");
        }
        // The doorways are 1 m wide.
        for (x, y) in [(3.5, 1.15), (9.5, -1.15), (15.5, 1.15)] {
            let d = w.cast_ray([x + 0.05, y], [1.0, 0.0], 10.0).unwrap();
            assert!((d - 0.95).abs() < 1e-12, "door at x = {x}: {d}");
        }
        // Into each room, and round the box in the south one.
        let routes: [&[[f64; 2]]; 3] = [
            &[[1.0, 0.0], [4.0, 0.0], [4.0, 3.3], [2.6, 4.7], [5.4, 4.7]],
            &[
                [4.0, 0.0],
                [10.0, 0.0],
                [10.0, -2.0],
                [8.6, -2.5],
                [8.6, -4.7],
                [11.4, -4.7],
                [11.4, -2.5],
                [10.0, -2.0],
            ],
            &[
                [10.0, 0.0],
                [16.0, 0.0],
                [16.0, 3.3],
                [14.6, 4.7],
                [17.4, 4.7],
            ],
        ];
        for route in routes {
            let least = route_clearance(&w, route);
            assert!(least >= ROBOT_CLEARANCE, "{route:?}: {least}");
        }
    }
}
