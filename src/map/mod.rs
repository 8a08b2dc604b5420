//! Maps built from scans: the incremental map of actual segments and the
//! keyframe policy that decides when a scan updates it.

pub mod cls;
pub mod keyframe;
pub mod segment_map;

pub use keyframe::{Keyframe, KeyframeConfig, KeyframePolicy};
pub use segment_map::{
    MapSegment, SegmentMap, SegmentMapConfig, SegmentMapFile, UpdateStats, blur_by_pose, fuse,
};
