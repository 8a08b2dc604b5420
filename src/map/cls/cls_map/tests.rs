use super::*;
use crate::geometry::point_segment_distance;
use crate::map::cls::local::LocalEdge;
use crate::map::cls::loops::polygon;

fn square(x0: f64, y0: f64, x1: f64, y1: f64, clockwise: bool) -> ClsLoop {
    let mut p = vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]];
    if clockwise {
        p.reverse();
    }
    polygon(&p)
}

fn local_square(x0: f64, y0: f64, x1: f64, y1: f64) -> LocalRegion {
    let p = [[x0, y0], [x1, y0], [x1, y1], [x0, y1]];
    LocalRegion {
        edges: (0..4)
            .map(|i| LocalEdge {
                start: p[i],
                end: p[(i + 1) % 4],
                source: LocalSource::Virtual,
            })
            .collect(),
    }
}

/// A 40 m hall with ten pillars along it.
fn hall() -> ClsMap {
    let holes = (0..10)
        .map(|k| {
            let x = 2.0 + 4.0 * k as f64;
            square(x, 2.0, x + 0.5, 2.5, true)
        })
        .collect();
    let shape = ClsShape {
        outer: square(0.0, 0.0, 42.0, 5.0, false),
        holes,
    };
    ClsMap::from_shapes(ClsMapConfig::default(), vec![shape]).unwrap()
}

#[test]
fn far_obstacle_loops_stay_out_of_the_union_and_in_the_map() {
    let mut map = hall();
    let area = map.area();
    // Grow the hall's end; only the last pillar is near.
    let stats = map
        .add_region(
            &SegmentMap::default(),
            &local_square(38.8, 1.0, 44.0, 4.0),
            &[],
        )
        .unwrap();
    assert_eq!(stats.touched_shapes, 1);
    assert_eq!(
        stats.touched_segments,
        4 + 4,
        "the outer loop and the nearest pillar"
    );
    map.check_invariants().unwrap();
    assert_eq!(map.shapes()[0].holes.len(), 10);
    assert!(
        (map.area() - (area + 2.0 * 3.0)).abs() < 1e-6,
        "{}",
        map.area()
    );
    assert!(!map.contains([2.25, 2.25]) && map.contains([43.0, 2.0]));
}

#[test]
fn a_bulge_through_a_long_wall_is_clipped_and_spliced() {
    let mut map = hall();
    let before = map.area();
    let stats = map
        .add_region(
            &SegmentMap::default(),
            &local_square(10.0, -1.0, 12.0, 1.0),
            &[],
        )
        .unwrap();
    assert!(stats.clipped);
    // Only the pieces near the window went through the union.
    assert!(stats.touched_segments < 12, "{stats:?}");
    map.check_invariants().unwrap();
    assert!((map.area() - before - 2.0).abs() < 1e-9, "{}", map.area());
    assert!(map.contains([11.0, -0.5]));
    // The hall's far walls are untouched: still one segment each.
    let outer = map.shapes()[0].outer.segments();
    assert!(
        outer
            .iter()
            .any(|s| s.start() == [42.0, 0.0] && s.end() == [42.0, 5.0])
    );
    assert!(
        outer
            .iter()
            .any(|s| s.start() == [42.0, 5.0] && s.end() == [0.0, 5.0])
    );
    // The bottom wall is cut only where the bulge meets it.
    assert_eq!(outer.len(), 4 + 4, "{outer:?}");
}

#[test]
fn separate_regions_are_not_touched() {
    let mut map = hall();
    let stats = map
        .add_region(
            &SegmentMap::default(),
            &local_square(100.0, 0.0, 102.0, 2.0),
            &[],
        )
        .unwrap();
    assert_eq!((stats.touched_shapes, stats.touched_segments), (0, 0));
    assert_eq!(map.shapes().len(), 2);
    // Bridging the two merges them into one shape.
    map.add_region(
        &SegmentMap::default(),
        &local_square(41.0, 0.5, 101.0, 1.5),
        &[],
    )
    .unwrap();
    assert_eq!(map.shapes().len(), 1);
    assert_eq!(map.shapes()[0].holes.len(), 10);
    map.check_invariants().unwrap();
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(48))]
    /// The clipped union gives the same region as the whole one.
    #[test]
    fn clipping_to_the_window_changes_nothing(
        regions in proptest::collection::vec((-2.0..44.0f64, -1.0..6.0f64, 0.2..4.0f64, 0.2..3.0f64), 1..6),
    ) {
        let mut clipped = hall();
        let mut whole = hall();
        whole.config.clip_to_window = false;
        for (x, y, w, h) in regions {
            let local = local_square(x, y, x + w, y + h);
            let a = clipped.add_region(&SegmentMap::default(), &local, &[]);
            let b = whole.add_region(&SegmentMap::default(), &local, &[]);
            proptest::prop_assert_eq!(a.is_ok(), b.is_ok());
            proptest::prop_assert_eq!(clipped.check_invariants(), Ok(()));
            // Same region, up to the cleaning's vertex moves (a few mm):
            // membership agrees away from both boundaries.
            for i in 0..120 {
                for j in 0..24 {
                    let p = [-2.5 + 0.4 * f64::from(i) + 0.013, -1.5 + 0.4 * f64::from(j) + 0.007];
                    let clear = |m: &ClsMap| {
                        m.segments().all(|s| point_segment_distance(p, s.start(), s.end()) > 0.01)
                    };
                    if clear(&clipped) && clear(&whole) {
                        proptest::prop_assert_eq!(clipped.contains(p), whole.contains(p), "at {:?}", p);
                    }
                }
            }
            // Collapsing an edge shorter than `min_edge` moves a vertex by
            // up to that much, which tilts a whole wall of the unclipped
            // map: a 5 mm step at the end of the hall's 42 m wall is
            // 0.1 m². The two may differ by that along their boundary.
            let perimeter: f64 = whole.segments().map(|s| s.length()).sum();
            let tolerance = 0.05 + 0.5 * whole.config.region.min_edge * perimeter;
            proptest::prop_assert!((clipped.area() - whole.area()).abs() < tolerance, "{} vs {}", clipped.area(), whole.area());
            proptest::prop_assert_eq!(clipped.shapes().len(), whole.shapes().len());
            let holes = |m: &ClsMap| m.shapes().iter().map(|s| s.holes.len()).sum::<usize>();
            proptest::prop_assert_eq!(holes(&clipped), holes(&whole));
        }
    }
}

#[test]
fn a_bad_update_leaves_the_map_as_it_was() {
    let mut map = hall();
    let before = map.items();
    let scan = RangeScan {
        t: 0.0,
        angle_min: -1.0,
        angle_increment: 0.01,
        ranges: vec![Ok(1.0); 100],
    };
    let nan_pose = Pose2 {
        x: f64::NAN,
        y: 0.0,
        theta: 0.0,
    };
    assert_eq!(
        map.update(
            &mut SegmentMap::default(),
            &[],
            &scan,
            nan_pose,
            [[0.0; 3]; 3]
        ),
        Err(ClsError::BadPose)
    );
    let far = local_square(0.0, 0.0, 2e5, 1.0);
    assert!(matches!(
        map.add_region(&SegmentMap::default(), &far, &[]),
        Err(ClsError::Region(RegionError::Coordinate(_)))
    ));
    assert_eq!(map.items(), before);
}
