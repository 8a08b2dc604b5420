//! The Closed Line Segment (CLS) map of Zhang & Ghosh (ICRA 2000, §3): a
//! closed, connected description of explored free space bounded only by
//! actual segments (walls seen by the laser) and virtual segments
//! (frontiers).
//!
//! - [`local`]: the local CLS map of one scan (actual segments, envelopes,
//!   closure through the sensor centre).
//! - [`region`]: region expansion by polygon union (i_overlay) with the
//!   origin of every boundary edge kept.
//! - `fusion`: fusion of corresponding actual segments on the boundary.
//! - `window`: clipping long loops to a window around the scan, so an
//!   update's union costs what the neighbourhood costs.
//! - [`loops`]: segments, loops, shapes, the CLSM_Item list, invariants.
//! - [`cls_map`]: [`ClsMap`] and its update.
//! - [`store`]: versioned, checksummed, atomically written `map.json`.
//! - [`grid`]: ROS map_server export (PGM + YAML).

pub mod cls_map;
mod fusion;
pub mod grid;
pub mod local;
pub mod loops;
pub mod region;
mod shapes;
pub mod store;
mod window;

pub use cls_map::{ClsError, ClsMap, ClsMapConfig, ClsUpdateStats};
pub use grid::{GridConfig, GridError, OccupancyGrid, occupancy_grid};
pub use local::{
    LocalEdge, LocalMapConfig, LocalMapError, LocalRegion, LocalSource, local_region, valid_points,
};
pub use loops::{
    ClsLoop, ClsSegment, ClsShape, ClsmItem, InvariantError, SegmentMode, check_loops,
};
pub use region::{EdgeOrigin, RegionConfig, RegionError};
pub use store::StoreError;
