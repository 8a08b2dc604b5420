//! Points, poses, COG lines and line extraction.

pub mod cog_line;
pub mod extract;
mod fit;
mod points;
pub mod pose;
pub mod scan;
mod split;

pub use cog_line::CogLine;
pub use extract::{ExtractionConfig, LineExtractor, RangeNoise, extract_lines, scan_points};
pub use pose::{Pose2, wrap_angle, wrap_angle_positive};
pub use scan::{BeamFault, RangeScan};
