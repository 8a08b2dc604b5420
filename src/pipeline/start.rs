//! Starting from a saved map: where is the robot in it?
//!
//! The paper's global localization (translation-segment voting) on the
//! first scan, then, while its answer is ambiguous (a corridor, look-alike
//! rooms), each next scan narrows the hypotheses with the odometry between
//! them (`disambiguate`), until one place remains. Scans before that have
//! no pose in the map.

use std::str::FromStr;

use crate::geometry::{CogLine, Pose2};
use crate::localize::global::{
    GlobalConfig, GlobalMap, GlobalResult, disambiguate, global_localize,
};

/// What a mapper started from a saved map does with it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MapMode {
    /// Localize only: the map is never changed.
    Localize,
    /// New keyframes join the loaded graph; loops close against the old map.
    Extend,
}

impl FromStr for MapMode {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "localize" => Ok(MapMode::Localize),
            "extend" => Ok(MapMode::Extend),
            other => Err(format!(
                "unknown map mode {other:?}: expected \"localize\" or \"extend\""
            )),
        }
    }
}

/// The search for the start pose.
#[derive(Debug)]
pub struct StartSearch {
    map: GlobalMap,
    config: GlobalConfig,
    /// The hypotheses so far and the odometry at their scan.
    last: Option<(GlobalResult, Option<Pose2>)>,
}

impl StartSearch {
    pub fn new(walls: impl IntoIterator<Item = CogLine>, config: GlobalConfig) -> Self {
        StartSearch {
            map: GlobalMap::new(walls),
            config,
            last: None,
        }
    }

    /// One scan's lines (robot frame) and its odometry: the start pose and
    /// its covariance once one place remains, else `None` (hypotheses kept
    /// for the next scan).
    pub fn step(
        &mut self,
        lines: &[CogLine],
        odometry: Option<Pose2>,
    ) -> Option<(Pose2, [[f64; 3]; 3])> {
        let result = match (&self.last, odometry) {
            (Some((previous, Some(before))), Some(now)) => disambiguate(
                previous,
                lines,
                before.between(&now),
                &self.map,
                &self.config,
            ),
            _ => global_localize(lines, &self.map, &self.config),
        };
        match result {
            Ok(r) if !r.ambiguous => {
                let best = r.best()?;
                Some((best.pose, best.covariance))
            }
            Ok(r) if !r.hypotheses.is_empty() => {
                self.last = Some((r, odometry));
                None
            }
            // Nothing to go on (too few lines, or every hypothesis lost):
            // start over with the next scan.
            _ => {
                self.last = None;
                None
            }
        }
    }

    /// Hypotheses held now.
    pub fn hypotheses(&self) -> usize {
        self.last.as_ref().map_or(0, |(r, _)| r.hypotheses.len())
    }
}
