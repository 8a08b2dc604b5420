//! Starting from a saved map: where is the robot in it?
//!
//! The paper's global localization (translation-segment voting) on the
//! first scan, then, while its answer is ambiguous (a corridor, look-alike
//! rooms), each next scan narrows the hypotheses with the odometry between
//! them (`disambiguate`), until one place remains. Scans before that have
//! no pose in the map.
//!
//! A pose hint from outside (an operator's "2D pose estimate", a base's
//! `POSE` line) starts the search from that one hypothesis instead: the
//! next scan is localized locally from it, and only when that fails does
//! the search fall back to global localization.

use std::str::FromStr;

use crate::geometry::{CogLine, Pose2};
use crate::localize::global::{
    GlobalConfig, GlobalMap, GlobalResult, Hypothesis, disambiguate, global_localize, refute,
    same_place,
};
use crate::map::cls::{ClsMap, LocalRegion};

/// Uncertainty of a pose hint: σ 0.5 m in x and y and 15° in heading (an
/// operator's click on a map; RViz's "2D Pose Estimate" sends the same).
pub const HINT_COVARIANCE: [[f64; 3]; 3] = [[0.25, 0.0, 0.0], [0.0, 0.25, 0.0], [0.0, 0.0, 0.0685]];

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

/// Hypotheses a start search holds at most: a square room has four
/// alike headings, and a floor with two alike rooms eight; the default of
/// global localization (five) would cut the right one off among them.
const START_HYPOTHESES: usize = 12;

/// The search for the start pose.
#[derive(Debug)]
pub struct StartSearch {
    map: GlobalMap,
    config: GlobalConfig,
    /// The hypotheses so far and the odometry at their scan.
    last: Option<(GlobalResult, Option<Pose2>)>,
    /// Started from a pose hint, and whether the next scan is the first
    /// since it.
    hinted: bool,
    first_after_hint: bool,
}

impl StartSearch {
    pub fn new(walls: impl IntoIterator<Item = CogLine>, config: GlobalConfig) -> Self {
        StartSearch {
            map: GlobalMap::new(walls),
            config: GlobalConfig {
                max_hypotheses: config.max_hypotheses.max(START_HYPOTHESES),
                ..config
            },
            last: None,
            hinted: false,
            first_after_hint: false,
        }
    }

    /// The same search judging places also by the free space `cls`
    /// explored: a wall the scan shows where the map saw through tells
    /// look-alike places apart (see [`crate::localize::global::FreeSpace`]).
    pub fn with_free_space(mut self, cls: &ClsMap) -> Self {
        self.map = std::mem::take(&mut self.map).with_free_space(cls);
        self
    }

    /// A search that starts from `pose` (map frame) with `covariance`, told
    /// when the odometry read `odometry`.
    pub fn hinted(
        walls: impl IntoIterator<Item = CogLine>,
        config: GlobalConfig,
        pose: Pose2,
        covariance: [[f64; 3]; 3],
        odometry: Option<Pose2>,
    ) -> Self {
        let hint = Hypothesis {
            pose,
            covariance,
            score: 0.0,
            votes: 0.0,
            refined: false,
            degenerate: None,
        };
        let mut search = StartSearch::new(walls, config);
        search.last = Some((
            GlobalResult {
                hypotheses: vec![hint],
                ambiguous: true,
            },
            odometry,
        ));
        search.hinted = true;
        search.first_after_hint = true;
        search
    }

    /// One scan's lines (robot frame), its free space (the local region,
    /// robot frame, when the scan gave one) and its odometry: the start
    /// pose and its covariance once one place remains, else `None`
    /// (hypotheses kept for the next scan).
    pub fn step(
        &mut self,
        lines: &[CogLine],
        free: Option<&LocalRegion>,
        odometry: Option<Pose2>,
    ) -> Option<(Pose2, [[f64; 3]; 3])> {
        // The motion since the hypotheses' scan, from the odometry; a hint
        // given or followed without odometry takes the robot to stand still
        // (the hint's σ covers a slow drift meanwhile).
        let first_after_hint = std::mem::take(&mut self.first_after_hint);
        let motion = match (&self.last, odometry) {
            (Some((previous, Some(before))), Some(now)) => Some((previous, before.between(&now))),
            (Some((previous, _)), _) if first_after_hint => Some((previous, Pose2::IDENTITY)),
            _ => None,
        };
        let tracked = motion.is_some();
        // The places tracked so far, where the odometry puts them now.
        let tracked_places: Vec<Pose2> = motion
            .as_ref()
            .map(|(previous, motion)| {
                previous
                    .hypotheses
                    .iter()
                    .map(|h| h.pose.compose(motion))
                    .collect()
            })
            .unwrap_or_default();
        let result = match motion {
            Some((previous, motion)) => {
                disambiguate(previous, lines, motion, &self.map, &self.config)
            }
            None => {
                // Searching afresh: whatever the hint said is gone.
                self.hinted = false;
                global_localize(lines, &self.map, &self.config)
            }
        };
        match result.map(|r| self.screen(r, free)) {
            Ok(r) if !r.ambiguous && !r.hypotheses.is_empty() => {
                let best = r.best()?;
                // Narrowed down to one place: the scan that did it, searched
                // afresh, must find that place too. Otherwise the tracked
                // places never held the right one (it showed only now), and
                // the search goes on from this scan's. (A hint is trusted:
                // it may be where a fresh search of a look-alike floor does
                // not look.)
                if tracked
                    && !self.hinted
                    && let Some(fresh) = global_localize(lines, &self.map, &self.config)
                        .ok()
                        .map(|f| self.screen(f, free))
                {
                    // A fresh set too full of alike places to judge by
                    // says nothing against the tracked one, which was whole.
                    let inconclusive = fresh.hypotheses.is_empty() && fresh.ambiguous;
                    let chosen = fresh
                        .hypotheses
                        .iter()
                        .find(|h| same_place(&h.pose, &best.pose, &self.config));
                    // A place this scan cannot tell from the chosen one,
                    // where no tracked place stood (a corridor's guess along
                    // it went astray), was dropped on no evidence.
                    let unexamined_rival = chosen.is_some_and(|chosen| {
                        fresh.hypotheses.iter().any(|h| {
                            !same_place(&h.pose, &chosen.pose, &self.config)
                                && h.score >= self.config.ambiguity_ratio * chosen.score
                                && !tracked_places
                                    .iter()
                                    .any(|p| same_place(p, &h.pose, &self.config))
                        })
                    });
                    let agrees = inconclusive || (chosen.is_some() && !unexamined_rival);
                    if !agrees {
                        self.last = (!fresh.hypotheses.is_empty()).then_some((fresh, odometry));
                        return None;
                    }
                }
                Some((best.pose, best.covariance))
            }
            Ok(r) if !r.hypotheses.is_empty() => {
                self.last = Some((r, odometry));
                None
            }
            // Nothing to go on (too few lines, every place refuted or lost,
            // or a set too full to narrow down): start over with the next
            // scan.
            _ => {
                self.last = None;
                None
            }
        }
    }

    /// The places of `r` that the scan's free space `free` does not refute;
    /// none when the set is full and its last place scores like the best:
    /// more alike places may have been left out, the right one among them,
    /// so narrowing it down could end sure of a wrong one.
    fn screen(&self, r: GlobalResult, free: Option<&LocalRegion>) -> GlobalResult {
        let r = match free {
            Some(free) => refute(r, free, &self.map, &self.config),
            None => r,
        };
        let full = r.hypotheses.len() >= self.config.max_hypotheses;
        let alike = match (r.hypotheses.first(), r.hypotheses.last()) {
            (Some(best), Some(last)) => last.score >= self.config.ambiguity_ratio * best.score,
            _ => false,
        };
        if full && alike {
            GlobalResult {
                hypotheses: Vec::new(),
                ambiguous: true,
            }
        } else {
            r
        }
    }

    /// Hypotheses held now.
    pub fn hypotheses(&self) -> usize {
        self.last.as_ref().map_or(0, |(r, _)| r.hypotheses.len())
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::geometry::{ExtractionConfig, extract_lines};
    use crate::sim::{Rng, ScanSpec, World, cast_scan};

    #[test]
    fn a_narrowing_that_lost_the_true_place_along_a_corridor_decides_nothing() {
        // A closed corridor 20 m by 2 m is the same from either end. The
        // robot faces the west end from x = 5; the places tracked so far
        // are its twin, facing the east end from x = 15, and the true place
        // guessed 0.6 m along the corridor from where it is. This scan
        // drops the guess (the end wall is not where it puts it) and keeps
        // the twin alone, but searched afresh it fits the true place as
        // well as the twin: nothing tells them apart, so nothing is decided.
        let corners = [[0.0, -1.0], [20.0, -1.0], [20.0, 1.0], [0.0, 1.0]];
        let mut world = World::new();
        world.add_polyline(&corners, true);
        let walls: Vec<CogLine> = (0..4)
            .map(|i| {
                let (a, b): ([f64; 2], [f64; 2]) = (corners[i], corners[(i + 1) % 4]);
                let len = (b[0] - a[0]).hypot(b[1] - a[1]);
                let mid = [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])];
                let theta = (b[1] - a[1]).atan2(b[0] - a[0]);
                CogLine::from_centre(theta, mid, -0.5 * len, 0.5 * len, 0.001, 0.002, 50)
            })
            .collect();
        let truth = Pose2::new(5.0, 0.0, std::f64::consts::PI);
        let scan = cast_scan(
            &world,
            &truth,
            &ScanSpec::lms200_half_degree(0.0),
            0.0,
            &mut Rng::new(1),
        );
        let lines = extract_lines(&scan, &Pose2::IDENTITY, &ExtractionConfig::default());
        let tracked = |pose: Pose2| Hypothesis {
            pose,
            covariance: [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.003]],
            score: 9.0,
            votes: 9.0,
            refined: true,
            degenerate: None,
        };
        let mut search = StartSearch::new(walls, GlobalConfig::default());
        search.last = Some((
            GlobalResult {
                hypotheses: vec![
                    tracked(Pose2::new(15.0, 0.0, 0.0)),
                    tracked(Pose2::new(5.6, 0.0, std::f64::consts::PI)),
                ],
                ambiguous: true,
            },
            Some(Pose2::IDENTITY),
        ));
        let decided = search.step(&lines, None, Some(Pose2::IDENTITY));
        assert!(decided.is_none(), "decided {decided:?}");
        assert!(search.hypotheses() >= 2, "{:?}", search.last);
    }
}
