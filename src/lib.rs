//! clsmap: a SICK LMS200 driver daemon and Closed Line Segment mapper
//! (after Zhang & Ghosh, ICRA 2000) for holonomic robots.

pub mod geometry;
