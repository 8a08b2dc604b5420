//! Global localization (Zhang & Ghosh §6): where in a known map is the
//! robot, with no prediction at all?
//!
//! API:
//! - `GlobalMap::new(lines)` — the map's actual segments (map frame);
//!   `.with_free_space(&ClsMap)` adds the free space it explored.
//! - `global_localize(&[CogLine] /* robot frame */, &GlobalMap, &GlobalConfig)
//!    -> Result<GlobalResult { hypotheses, ambiguous }, GlobalError>`.
//! - `disambiguate(&GlobalResult, lines, odometry motion, &GlobalMap, &GlobalConfig)`
//!   keeps the hypotheses a further scan agrees with.
//! - `refute(GlobalResult, &LocalRegion /* the scan's free space */, &GlobalMap, &GlobalConfig)`
//!   drops the hypotheses at which map walls stand where the scan saw through.
//!
//! # Method
//!
//! The scan's longest lines are anchors. Each anchor is paired with every
//! map line at least about as long (a prefix of the map sorted by length);
//! the pair fixes the rotation and leaves a segment of translations (see
//! `vote.rs`). The other local lines vote for points or stretches of that
//! segment where they lie on a map line of matching direction; the map's
//! BVH returns only the map lines near each voter's swept box, so a pair
//! costs O(voters · log n), not O(voters · n). The best-voted poses are
//! refined by local localization and re-scored by the local length they
//! match; near-identical poses are merged, and a result whose runner-up
//! scores nearly as well as the best (a symmetric place), whose best leaves
//! a direction unconstrained, or whose best local localization did not
//! confirm, is flagged as ambiguous instead of being collapsed.

mod config;
mod free;
mod map;
mod search;
mod track;
mod vote;

pub use config::GlobalConfig;
pub use free::FreeSpace;
pub use map::GlobalMap;
pub(crate) use search::same_place;
pub use search::{GlobalError, GlobalResult, Hypothesis, global_localize};
pub use track::{disambiguate, refute};
