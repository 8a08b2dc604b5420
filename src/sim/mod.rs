//! Simulation: floor-plan worlds, a simulated LMS200 by ray casting, and a
//! small seeded random generator so simulated runs are reproducible.

pub mod cast;
pub mod laser;
pub mod rng;
pub mod robot;
pub mod tour;
pub mod world;
pub mod world_file;

pub use cast::{LMS200_MAX_RANGE_CM_MODE, LMS200_MAX_RANGE_MM_MODE, ScanSpec, cast_scan};
pub use laser::{Carrier, WorldRangeSource};
pub use rng::Rng;
pub use robot::{SimRobot, SimRobotBase};
pub use tour::Tour;
pub use world::{ROOM_WITH_BOXES_TOUR, World};
pub use world_file::{LineProblem, WorldFile, WorldFileError};
