//! Points, poses, COG lines, line extraction, and the paper's test of
//! when two lines are one wall, over a spatial index of lines.

pub mod cog_line;
pub mod correspond;
mod ends;
pub mod extract;
mod fit;
mod points;
pub mod pose;
pub mod scan;
pub mod scan_match;
mod scatter;
mod split;

pub use cog_line::{CogLine, WallEnds};
pub use correspond::{
    CorrespondenceConfig, SegmentId, SegmentIndex, lines_correspond, match_score,
};
pub use ends::JambGap;
pub use extract::{
    ExtractionConfig, LineExtractor, RangeNoise, SeenJamb, extract_lines, scan_points,
};
pub(crate) use fit::principal_axes;
pub use pose::{Pose2, wrap_angle, wrap_angle_positive};
pub use scan::{BeamFault, RangeScan};
pub use scatter::{WallScatter, wall_scatter};

/// Distance (m) from `p` to the closed segment `ab` (to `a` when the
/// segment has no length).
pub fn point_segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let e = [b[0] - a[0], b[1] - a[1]];
    let len2 = e[0] * e[0] + e[1] * e[1];
    let t = if len2 > 0.0 {
        (((p[0] - a[0]) * e[0] + (p[1] - a[1]) * e[1]) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p[0] - a[0] - t * e[0]).hypot(p[1] - a[1] - t * e[1])
}
