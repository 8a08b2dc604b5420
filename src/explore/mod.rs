//! Exploration by Virtual Line Segment Pursuit (Zhang & Ghosh, ICRA 2000,
//! §3.1): the virtual segments of the CLS map are the frontier of explored
//! space; the robot pursues them one after another — drives to a pose in
//! front of one, facing through it, and scans — until none long enough is
//! left, and then the map is complete.
//!
//! - [`config`]: [`ExplorationConfig`] (robot radius, frontier length, …).
//! - [`free_space`]: the free region shrunk by the robot's clearance.
//! - [`planner`]: shortest paths in it ([`plan_path`]).
//! - [`goal`]: the goal pose in front of a frontier.
//! - [`memory`]: frontiers given up on, so none is chased forever.
//! - [`mod@open_way`]: the way to drive farthest in a scan, for a robot that
//!   does not know where it is.
//! - [`pursuit`]: [`next_step`], the choice of the next frontier.
//! - [`follow`]: [`PathFollower`], velocities along a path for a holonomic base.
//! - [`explorer`]: [`Explorer`], the pursuit as a running behaviour.

pub mod config;
pub mod explorer;
pub mod follow;
pub mod free_space;
pub mod goal;
pub mod memory;
pub mod open_way;
pub mod planner;
pub mod pursuit;

pub use config::{ExplorationConfig, XR4000_RADIUS};
pub use explorer::{Explorer, ExplorerEvent, ExplorerStats};
pub use follow::{DriveConfig, FollowStep, PathFollower};
pub use free_space::{Corner, FreeSpace, FreeSpaceError};
pub use goal::{Frontier, frontier_goal};
pub use memory::ExplorationMemory;
pub use open_way::{free_run, open_way};
pub use planner::{PlanError, Reach, Until, path_length, plan_path, shortest_paths};
pub use pursuit::{ExploreError, NextStep, next_step};
