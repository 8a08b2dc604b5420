//! Simulation: floor-plan worlds, a simulated LMS200 by ray casting, and a
//! small seeded random generator so simulated runs are reproducible.

pub mod cast;
pub mod laser;
pub mod rng;
pub mod tour;
pub mod world;

pub use cast::{LMS200_MAX_RANGE_CM_MODE, LMS200_MAX_RANGE_MM_MODE, ScanSpec, cast_scan};
pub use laser::WorldRangeSource;
pub use rng::Rng;
pub use tour::Tour;
pub use world::World;
