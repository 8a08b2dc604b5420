//! [`ExplorationMemory`]: what the pursuit remembers between steps — how
//! often each frontier was chased, and which ones could not be reached —
//! so that no frontier is chased forever.
//!
//! Frontiers change as the map grows (a union moves their ends), so they
//! are recognised by proximity: midpoints within
//! `ExplorationConfig::match_distance` and directions within
//! `ExplorationConfig::match_angle`.

use serde::Serialize;

use crate::geometry::wrap_angle;

use super::config::ExplorationConfig;
use super::free_space::distance;
use super::goal::Frontier;

/// One remembered frontier.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Remembered {
    pub frontier: Frontier,
    /// Goals issued for it.
    pub attempts: u32,
    /// Whether the last look found no goal or no path to it.
    pub unreachable: bool,
}

/// The pursuit's memory across calls of
/// [`next_step`](super::next_step). Start with `default()` and pass the
/// same memory to every call of one exploration.
#[derive(Debug, Clone, Default, Serialize)]
pub struct ExplorationMemory {
    frontiers: Vec<Remembered>,
    goals_issued: usize,
}

impl ExplorationMemory {
    /// Every remembered frontier.
    pub fn frontiers(&self) -> &[Remembered] {
        &self.frontiers
    }

    /// Goals issued so far.
    pub fn goals_issued(&self) -> usize {
        self.goals_issued
    }

    fn find(&self, f: &Frontier, cfg: &ExplorationConfig) -> Option<usize> {
        self.frontiers.iter().position(|r| {
            distance(r.frontier.midpoint(), f.midpoint()) <= cfg.match_distance
                && wrap_angle(r.frontier.direction() - f.direction()).abs() <= cfg.match_angle
        })
    }

    fn entry(&mut self, f: &Frontier, cfg: &ExplorationConfig) -> &mut Remembered {
        let i = match self.find(f, cfg) {
            Some(i) => i,
            None => {
                self.frontiers.push(Remembered {
                    frontier: *f,
                    attempts: 0,
                    unreachable: false,
                });
                self.frontiers.len() - 1
            }
        };
        let r = &mut self.frontiers[i];
        r.frontier = *f;
        r
    }

    /// Goals already issued for `f` (or a frontier like it).
    pub fn attempts(&self, f: &Frontier, cfg: &ExplorationConfig) -> u32 {
        self.find(f, cfg).map_or(0, |i| self.frontiers[i].attempts)
    }

    /// Whether `f` has been chased `max_attempts` times already.
    pub fn exhausted(&self, f: &Frontier, cfg: &ExplorationConfig) -> bool {
        self.attempts(f, cfg) >= cfg.max_attempts
    }

    /// Records that a goal was issued for `f`.
    pub fn record_goal(&mut self, f: &Frontier, cfg: &ExplorationConfig) {
        let r = self.entry(f, cfg);
        r.attempts += 1;
        r.unreachable = false;
        self.goals_issued += 1;
    }

    /// Marks `f` as unreachable: no goal in front of it fits the robot or
    /// no path leads there. It is looked at again on the next call (the
    /// map may have opened a way), but never chased while unreachable.
    pub fn mark_unreachable(&mut self, f: &Frontier, cfg: &ExplorationConfig) {
        self.entry(f, cfg).unreachable = true;
    }

    /// Whether `f` was unreachable when last looked at.
    pub fn is_unreachable(&self, f: &Frontier, cfg: &ExplorationConfig) -> bool {
        self.find(f, cfg)
            .is_some_and(|i| self.frontiers[i].unreachable)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frontiers_are_recognised_by_proximity_and_exhausted() {
        let cfg = ExplorationConfig::default();
        let mut m = ExplorationMemory::default();
        let f = Frontier {
            start: [0.0, 0.0],
            end: [0.0, 2.0],
        };
        let moved = Frontier {
            start: [0.1, 0.1],
            end: [0.1, 2.2],
        };
        let reversed = Frontier {
            start: f.end,
            end: f.start,
        };
        m.record_goal(&f, &cfg);
        assert_eq!(m.attempts(&moved, &cfg), 1);
        assert_eq!(m.attempts(&reversed, &cfg), 0);
        assert!(!m.exhausted(&moved, &cfg));
        m.record_goal(&moved, &cfg);
        assert!(m.exhausted(&f, &cfg));
        m.mark_unreachable(&reversed, &cfg);
        assert!(m.is_unreachable(&reversed, &cfg) && !m.is_unreachable(&f, &cfg));
        assert_eq!(m.goals_issued(), 2);
    }
}
