//! clsmap: a SICK LMS200 driver and Closed Line Segment mapper
//! (after Zhang & Ghosh, ICRA 2000) for holonomic robots.

pub mod daemon;
pub mod demo;
pub mod durable;
pub mod eval;
pub mod explore;
pub mod geometry;
pub mod input;
pub mod localize;
pub mod map;
pub mod mapping_config;
pub mod pipeline;
pub mod render;
pub mod sim;
pub mod trajectory;
