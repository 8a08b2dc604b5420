//! An SVG picture of a CLS map through [`MapPicture`]: actual segments
//! solid, virtual ones (the frontier) dashed, with the robot's path.

use super::{MapPicture, SegmentStyle};
use crate::geometry::Pose2;
use crate::map::cls::{ClsMap, SegmentMode};

/// The picture of `map`, with the `trajectory` (if any) and the robot's
/// final `pose` (if any).
pub fn picture(map: &ClsMap, trajectory: Option<&[Pose2]>, pose: Option<Pose2>) -> MapPicture {
    let mut pic = MapPicture::new().title(format!(
        "CLS map: {} actual, {} virtual segments, {:.1} m² explored",
        map.actual_segments().count(),
        map.virtual_segments().count(),
        map.area()
    ));
    for s in map.segments() {
        let style = match s.mode {
            SegmentMode::Actual => SegmentStyle::Actual,
            SegmentMode::Virtual => SegmentStyle::Virtual,
        };
        pic.segment(s.start(), s.end(), style);
    }
    if let Some(t) = trajectory {
        pic.trajectory(t.iter().copied());
    }
    if let Some(p) = pose {
        pic.pose(p);
    }
    pic
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::map::cls::cls_map::ClsMapConfig;
    use crate::map::cls::loops::{ClsLoop, ClsSegment, ClsShape};

    #[test]
    fn draws_walls_solid_and_frontiers_dashed() {
        let pts = [[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]];
        let segments = (0..4)
            .map(|i| {
                let mut s = ClsSegment::virtual_between(pts[i], pts[(i + 1) % 4]);
                if i == 0 {
                    s.mode = SegmentMode::Actual;
                }
                s
            })
            .collect();
        let shape = ClsShape {
            outer: ClsLoop::new(segments),
            holes: vec![],
        };
        let map = ClsMap::from_shapes(ClsMapConfig::default(), vec![shape]).unwrap();
        let path = [Pose2::new(0.5, 0.5, 0.0), Pose2::new(1.5, 0.5, 0.0)];
        let svg = picture(&map, Some(&path), path.last().copied()).to_svg();
        assert_eq!(svg.matches("stroke-dasharray").count(), 3);
        assert!(svg.contains("<path") && svg.contains("<polygon"));
        assert!(svg.contains("1 actual, 3 virtual"));
    }
}
