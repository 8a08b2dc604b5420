//! Holonomic mobile base support for clsmap (XR4000-style robot).
//!
//! - [`kinematics`]: SI twist/pose types, exact constant-twist integration and
//!   velocity/acceleration limiting.
//! - [`adapter`]: the [`BaseAdapter`] trait the daemon drives, plus a
//!   stale-odometry guard.
//! - [`sim`]: a deterministic simulated base with odometry error.
//! - [`line_protocol`]: a sans-IO text protocol to bridge any real base over a
//!   serial port or TCP.
//! - [`line_base`]: [`LineBase`], the line protocol over TCP, a serial port or
//!   any [`LineStream`].
//! - [`replay`]: [`ReplayBase`], recorded odometry played back in real time.

pub mod adapter;
pub mod kinematics;
pub mod line_base;
pub mod line_protocol;
pub mod replay;
pub mod sim;

pub use adapter::{BaseAdapter, BaseError, Health, OdometrySample, StaleGuard};
pub use kinematics::{BasePose, Limits, Twist, integrate, limit, wrap_angle};
pub use line_base::{LineBase, LineBaseStats, LineStream};
pub use line_protocol::{BaseMessage, Command, LineDecoder, ProtocolError, encode_command};
pub use replay::{ReplayBase, ReplayError};
pub use sim::SimBase;
