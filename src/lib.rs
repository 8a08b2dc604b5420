//! clsmap: a SICK LMS200 driver and Closed Line Segment mapper
//! (after Zhang & Ghosh, ICRA 2000) for holonomic robots.

pub mod daemon;
#[cfg(feature = "sim")]
pub mod demo;
pub mod eval;
pub mod explore;
pub mod files;
pub mod geometry;
pub mod graph;
pub mod input;
pub mod localize;
pub mod map;
pub mod pipeline;
pub mod render;
#[cfg(feature = "sim")]
pub mod sim;

/// An error and its causes on one line, outermost first: what failed and
/// why, for a log line or a status report.
pub fn error_chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        text.push_str(": ");
        text.push_str(&s.to_string());
        source = s.source();
    }
    text
}
