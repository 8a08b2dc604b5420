//! Line correspondence and local localization against a line map.

pub mod global;
pub mod heading;
pub mod local;
mod problem;
mod solve;

pub use heading::localize_searching_heading;
pub use local::{LocalizationResult, LocalizeError, LocalizerConfig, localize};
pub use solve::LineConstraints;
