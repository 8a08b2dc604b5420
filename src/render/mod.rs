//! Pictures of maps and trajectories.

pub mod svg;

pub use svg::{MapPicture, SegmentStyle};
