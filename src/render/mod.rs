//! Pictures of maps and trajectories.

pub mod cls;
pub mod svg;

pub use cls::picture;
pub use svg::{MapPicture, SegmentStyle};
