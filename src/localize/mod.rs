//! Line correspondence and local localization against a line map.

pub mod correspond;
pub mod global;
pub mod heading;
pub mod local;
mod problem;
mod solve;

pub use correspond::{
    CorrespondenceConfig, SegmentId, SegmentIndex, lines_correspond, match_score,
};
pub use heading::localize_searching_heading;
pub use local::{LocalizationResult, LocalizeError, LocalizerConfig, localize};
pub use solve::LineConstraints;
