//! Maps built from scans: the incremental map of actual segments, the
//! keyframe policy that decides when a scan updates it, and the map file.

pub mod cls;
pub mod file;
pub mod keyframe;
pub mod segment_map;

pub use file::{LoadedMap, MapContents};
pub use keyframe::{Edge, EdgeKind, Keyframe, KeyframeConfig, KeyframePolicy};
pub use segment_map::{
    MapSegment, SegmentMap, SegmentMapConfig, UpdateStats, WallUpdate, blur_by_pose, fuse,
};
