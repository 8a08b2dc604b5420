//! [`next_step`]: Virtual Line Segment Pursuit's choice of the next goal.
//!
//! Order. The paper (Zhang & Ghosh 2000, §3.1) has the robot pursue the
//! map's virtual segments one after another but leaves the order open. We
//! take the frontier whose goal is nearest by *path length* inside the
//! shrunk free region (greedy nearest frontier, as in Yamauchi's
//! frontier-based exploration): straight-line distance would send the robot
//! to a frontier just behind a wall, and path length is what driving costs.
//! Each scan at a goal removes or moves the frontiers around it, so greedy
//! nearest keeps the robot sweeping its neighbourhood before it leaves it.
//! Ties (within [`TIE_TOLERANCE`]) go to the frontier met first along the
//! map's loop order (shapes, then outer loop before holes, then segment
//! order), which makes the choice deterministic.

use serde::Serialize;

use crate::geometry::Pose2;
use crate::map::cls::ClsMap;

use super::config::ExplorationConfig;
use super::free_space::{FreeSpace, FreeSpaceError};
use super::goal::{Frontier, frontier_goal};
use super::memory::ExplorationMemory;
use super::planner::{PlanError, Reach, Start, Until, shortest_paths};

/// Path lengths (m) closer than this count as a tie.
pub const TIE_TOLERANCE: f64 = 0.01;

/// What the robot should do next.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum NextStep {
    /// Drive along `path` (m, map frame; from the robot's position to the
    /// goal's) and turn to `goal`'s heading, which faces through
    /// `frontier`; then scan.
    Goal {
        goal: Pose2,
        frontier: Frontier,
        path: Vec<[f64; 2]>,
    },
    /// No frontier long enough is left that can still be pursued: the map
    /// is complete. `given_up` lists long frontiers left behind because no
    /// goal in front of them is reachable or because they survived
    /// `max_attempts` visits (empty when the map is closed everywhere).
    Complete { given_up: Vec<Frontier> },
}

/// Why no step could be chosen.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ExploreError {
    #[error("the exploration configuration has a non-finite or out-of-range value")]
    BadConfig,
    #[error("the robot's pose is not finite")]
    BadPose,
    #[error("the map is empty: scan before exploring")]
    EmptyMap,
    #[error(transparent)]
    FreeSpace(#[from] FreeSpaceError),
    #[error("the robot cannot start a path: {0}")]
    Start(#[from] PlanError),
}

/// The frontiers worth pursuing: virtual segments at least
/// `min_frontier_length` long, in loop order.
pub fn long_frontiers(map: &ClsMap, min_length: f64) -> Vec<Frontier> {
    map.loops()
        .flat_map(|l| l.segments().iter())
        .filter(|s| !s.is_actual() && s.length() >= min_length)
        .map(|s| Frontier {
            start: s.start(),
            end: s.end(),
        })
        .collect()
}

/// The next step of Virtual Line Segment Pursuit for a robot at `robot`
/// (map frame) in `map`: the nearest pursuable frontier's goal and the
/// path there, or `Complete`. Frontiers with no reachable goal are marked
/// in `memory`; the chosen one's attempt is counted there.
pub fn next_step(
    map: &ClsMap,
    robot: Pose2,
    cfg: &ExplorationConfig,
    memory: &mut ExplorationMemory,
) -> Result<NextStep, ExploreError> {
    if !cfg.is_valid() {
        return Err(ExploreError::BadConfig);
    }
    if ![robot.x, robot.y, robot.theta]
        .iter()
        .all(|v| v.is_finite())
    {
        return Err(ExploreError::BadPose);
    }
    if map.is_empty() {
        return Err(ExploreError::EmptyMap);
    }
    let free = FreeSpace::from_map(map, cfg.clearance())?;
    let (candidates, mut given_up): (Vec<Frontier>, Vec<Frontier>) =
        long_frontiers(map, cfg.min_frontier_length)
            .into_iter()
            .partition(|f| !memory.exhausted(f, cfg));
    if candidates.is_empty() {
        return Ok(NextStep::Complete { given_up });
    }
    let start = Start::new(&free, [robot.x, robot.y], cfg.start_snap)?;
    let mut placed: Vec<(Frontier, Pose2)> = Vec::new();
    for f in candidates {
        match frontier_goal(&f, &free, cfg.goal_standoff, |p| map.contains(p)) {
            Some(g) => placed.push((f, g)),
            None => {
                memory.mark_unreachable(&f, cfg);
                given_up.push(f);
            }
        }
    }
    let goals: Vec<[f64; 2]> = placed.iter().map(|(_, g)| [g.x, g.y]).collect();
    let reach = shortest_paths(&free, &start, &goals, Until::Nearest { tie: TIE_TOLERANCE });
    // Nearest by path length; among ties the first in loop order.
    let mut best: Option<(f64, usize)> = None;
    for (i, r) in reach.iter().enumerate() {
        match r {
            Reach::Path { length, .. } => {
                if best.is_none_or(|(b, _)| *length < b - TIE_TOLERANCE) {
                    best = Some((*length, i));
                }
            }
            Reach::Unreachable => {
                memory.mark_unreachable(&placed[i].0, cfg);
                given_up.push(placed[i].0);
            }
            Reach::NotSearched => {}
        }
    }
    let Some((_, i)) = best else {
        return Ok(NextStep::Complete { given_up });
    };
    let (frontier, goal) = placed[i];
    let Some(Reach::Path { path, .. }) = reach.into_iter().nth(i) else {
        // `best` indexes a `Reach::Path`, so this is not reached.
        return Ok(NextStep::Complete { given_up });
    };
    memory.record_goal(&frontier, cfg);
    Ok(NextStep::Goal {
        goal,
        frontier,
        path,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
pub(crate) mod tests {
    use super::*;
    use crate::map::cls::{ClsLoop, ClsMapConfig, ClsSegment, ClsShape, SegmentMode};

    /// A map of one CCW polygon; edges listed in `open` are virtual.
    pub(crate) fn map_of(points: &[[f64; 2]], open: &[usize]) -> ClsMap {
        let n = points.len();
        let segments = (0..n)
            .map(|i| {
                let mut s = ClsSegment::virtual_between(points[i], points[(i + 1) % n]);
                if !open.contains(&i) {
                    s.mode = SegmentMode::Actual;
                }
                s
            })
            .collect();
        let shape = ClsShape {
            outer: ClsLoop::new(segments),
            holes: vec![],
        };
        ClsMap::from_shapes(ClsMapConfig::default(), vec![shape]).unwrap()
    }

    const ROOM: [[f64; 2]; 4] = [[0.0, 0.0], [6.0, 0.0], [6.0, 3.0], [0.0, 3.0]];

    #[test]
    fn picks_the_nearest_frontier_and_faces_through_it() {
        // Frontiers: the right wall (edge 1) and the left wall (edge 3).
        let map = map_of(&ROOM, &[1, 3]);
        let cfg = ExplorationConfig::default();
        let mut mem = ExplorationMemory::default();
        let step = next_step(&map, Pose2::new(4.5, 1.5, 0.0), &cfg, &mut mem).unwrap();
        let NextStep::Goal {
            goal,
            frontier,
            path,
        } = step
        else {
            panic!("expected a goal");
        };
        assert_eq!(frontier.start, [6.0, 0.0]);
        assert!((goal.x - 5.4).abs() < 1e-9 && (goal.y - 1.5).abs() < 1e-9);
        assert!(goal.theta.abs() < 1e-12);
        assert_eq!(path.first(), Some(&[4.5, 1.5]));
        assert_eq!(path.last(), Some(&[goal.x, goal.y]));
        // Chased max_attempts times, then the other one, then complete.
        let robot = Pose2::new(5.4, 1.5, 0.0);
        next_step(&map, robot, &cfg, &mut mem).unwrap();
        let NextStep::Goal { frontier, .. } = next_step(&map, robot, &cfg, &mut mem).unwrap()
        else {
            panic!("expected the second frontier");
        };
        assert_eq!(frontier.start, [0.0, 3.0]);
        next_step(&map, robot, &cfg, &mut mem).unwrap();
        let last = next_step(&map, robot, &cfg, &mut mem).unwrap();
        assert!(matches!(last, NextStep::Complete { ref given_up } if given_up.len() == 2));
    }

    #[test]
    fn short_frontiers_do_not_count_and_a_closed_map_is_complete() {
        let map = map_of(&ROOM, &[]);
        let cfg = ExplorationConfig::default();
        let mut mem = ExplorationMemory::default();
        let step = next_step(&map, Pose2::new(3.0, 1.5, 0.0), &cfg, &mut mem).unwrap();
        assert_eq!(step, NextStep::Complete { given_up: vec![] });
        let notch = [
            [0.0, 0.0],
            [3.0, 0.0],
            [3.5, 0.0],
            [6.0, 0.0],
            [6.0, 3.0],
            [0.0, 3.0],
        ];
        let map = map_of(&notch, &[1]);
        let step = next_step(&map, Pose2::new(3.0, 1.5, 0.0), &cfg, &mut mem).unwrap();
        assert_eq!(step, NextStep::Complete { given_up: vec![] });
    }

    #[test]
    fn unreachable_frontier_is_marked_and_bad_input_refused() {
        // A frontier at the end of a 0.5 m wide dead end: no goal fits.
        let pts = [
            [0.0, 0.0],
            [3.0, 0.0],
            [3.0, 1.25],
            [6.0, 1.25],
            [6.0, 1.75],
            [3.0, 1.75],
            [3.0, 3.0],
            [0.0, 3.0],
        ];
        let map = map_of(&pts, &[3]);
        let cfg = ExplorationConfig {
            min_frontier_length: 0.4,
            ..ExplorationConfig::default()
        };
        let mut mem = ExplorationMemory::default();
        let step = next_step(&map, Pose2::new(1.5, 1.5, 0.0), &cfg, &mut mem).unwrap();
        assert!(matches!(step, NextStep::Complete { ref given_up } if given_up.len() == 1));
        assert!(mem.frontiers()[0].unreachable);
        assert_eq!(
            next_step(&map, Pose2::new(f64::NAN, 0.0, 0.0), &cfg, &mut mem),
            Err(ExploreError::BadPose)
        );
        let empty = ClsMap::new(ClsMapConfig::default());
        assert_eq!(
            next_step(&empty, Pose2::IDENTITY, &cfg, &mut mem),
            Err(ExploreError::EmptyMap)
        );
        let bad = ExplorationConfig {
            robot_radius: -1.0,
            ..cfg
        };
        assert_eq!(
            next_step(&map, Pose2::IDENTITY, &bad, &mut mem),
            Err(ExploreError::BadConfig)
        );
    }
}
