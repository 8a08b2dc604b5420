//! Files that are neither maps nor logs: durable writes and bounded reads
//! every output and input goes through, a writer to several places, and
//! trajectories as TUM text.

pub mod durable;
pub mod tee;
pub mod trajectory;
