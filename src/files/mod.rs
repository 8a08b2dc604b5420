//! Files that are neither maps nor logs: durable writes and bounded reads
//! every output and input goes through, and trajectories as TUM text.

pub mod durable;
pub mod trajectory;
