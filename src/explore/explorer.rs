//! [`Explorer`]: Virtual Line Segment Pursuit as a running behaviour —
//! choose a frontier ([`next_step`]), drive there ([`PathFollower`]), stand
//! still while the map takes in the view, choose again; until the map is
//! complete.
//!
//! It takes the map, the robot's pose and the time, and gives a velocity:
//! no clock, no I/O, so the daemon, the demo and the tests drive it alike.

use clsmap_base::Twist;
use serde::Serialize;

use super::config::ExplorationConfig;
use super::follow::{DriveConfig, FollowStep, PathFollower};
use super::goal::Frontier;
use super::memory::ExplorationMemory;
use super::planner::path_length;
use super::pursuit::{NextStep, next_step};
use crate::geometry::Pose2;
use crate::map::cls::ClsMap;

/// What the explorer is doing.
#[derive(Debug, Clone, PartialEq)]
enum State {
    /// Standing still until `until` (s), then choosing the next goal.
    Settling { until: f64 },
    /// Driving to a goal; abandoned at `deadline` (s).
    Driving {
        follower: PathFollower,
        deadline: f64,
    },
    /// No frontier worth pursuing is left.
    Complete { given_up: Vec<Frontier> },
}

/// Something worth telling the operator.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum ExplorerEvent {
    /// A new goal in front of `frontier`, `path_length` m away.
    Goal {
        goal: Pose2,
        frontier: Frontier,
        path_length: f64,
    },
    /// The goal was reached.
    Arrived { goal: Pose2 },
    /// The goal was not reached in time and is abandoned.
    TimedOut { goal: Pose2 },
    /// No step could be planned (the robot off the free region, an empty
    /// map); it waits and tries again.
    PlanFailed { reason: String },
    /// Exploration is complete; `given_up` frontiers could not be closed.
    Complete { given_up: usize },
}

/// Counters of a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct ExplorerStats {
    pub goals: usize,
    pub arrived: usize,
    pub timed_out: usize,
    pub plan_failures: usize,
    /// Long frontiers left open when exploration completed: no goal in
    /// front of them could be reached, or their visits ran out.
    pub given_up: usize,
}

/// Virtual Line Segment Pursuit, step by step.
#[derive(Debug, Clone)]
pub struct Explorer {
    planner: ExplorationConfig,
    drive: DriveConfig,
    memory: ExplorationMemory,
    state: State,
    stats: ExplorerStats,
    /// When `control` or `hold` was last called (s).
    last_control: Option<f64>,
}

impl Explorer {
    /// Starts by settling for `drive.settle_time` from `now` (s), so the
    /// first scans build a map to plan in.
    pub fn new(planner: ExplorationConfig, drive: DriveConfig, now: f64) -> Explorer {
        Explorer {
            planner,
            drive,
            memory: ExplorationMemory::default(),
            state: State::Settling {
                until: now + drive.settle_time,
            },
            stats: ExplorerStats::default(),
            last_control: None,
        }
    }

    /// Takes new tuning (SIGHUP); the memory of frontiers and the current
    /// goal are kept.
    pub fn retune(&mut self, planner: ExplorationConfig, drive: DriveConfig) {
        self.planner = planner;
        self.drive = drive;
    }

    pub fn is_complete(&self) -> bool {
        matches!(self.state, State::Complete { .. })
    }

    /// The map changed after exploration completed (the pose graph took
    /// in its last loops): settle from `now` (s) and plan again in it,
    /// with the memory of the frontiers visited so far.
    pub fn reconsider(&mut self, now: f64) {
        if self.is_complete() {
            self.stats.given_up = 0;
            self.settle(now);
        }
    }

    /// The map moved under the robot (a loop closure, `new = correction ∘
    /// old`): the goal and the path to it follow, so the robot does not
    /// drive to where the goal was in the old frame.
    pub fn reframe(&mut self, correction: &Pose2) {
        if let State::Driving { follower, .. } = &mut self.state {
            follower.reframe(correction);
        }
    }

    /// The goal driven to, if any.
    pub fn goal(&self) -> Option<Pose2> {
        match &self.state {
            State::Driving { follower, .. } => Some(follower.goal()),
            _ => None,
        }
    }

    /// The path planned to the current goal (map frame, m), if driving.
    pub fn planned_path(&self) -> &[[f64; 2]] {
        match &self.state {
            State::Driving { follower, .. } => follower.path(),
            _ => &[],
        }
    }

    /// Frontiers given up on when exploration completed.
    pub fn given_up(&self) -> &[Frontier] {
        match &self.state {
            State::Complete { given_up } => given_up,
            _ => &[],
        }
    }

    pub fn stats(&self) -> ExplorerStats {
        self.stats
    }

    /// The velocity (robot frame) for a robot at `pose` (map frame) at
    /// `now` (s) in `map`, and what happened, if anything.
    pub fn control(
        &mut self,
        map: &ClsMap,
        pose: Pose2,
        now: f64,
    ) -> (Twist, Option<ExplorerEvent>) {
        self.last_control = Some(now);
        match &mut self.state {
            State::Complete { .. } => (Twist::ZERO, None),
            State::Settling { until } => {
                if now < *until {
                    return (Twist::ZERO, None);
                }
                (Twist::ZERO, Some(self.plan(map, pose, now)))
            }
            State::Driving { follower, deadline } => {
                if now > *deadline {
                    let goal = follower.goal();
                    self.stats.timed_out += 1;
                    self.settle(now);
                    return (Twist::ZERO, Some(ExplorerEvent::TimedOut { goal }));
                }
                match follower.step(&pose, &self.drive) {
                    FollowStep::Drive(twist) => (twist, None),
                    FollowStep::Arrived => {
                        let goal = follower.goal();
                        self.stats.arrived += 1;
                        self.settle(now);
                        (Twist::ZERO, Some(ExplorerEvent::Arrived { goal }))
                    }
                }
            }
        }
    }

    /// The base is held at `now` (s) — a silent sensor, stale odometry, a
    /// fault — instead of driven: the goal's deadline moves on by the time
    /// held, so a pause does not count against the goal.
    pub fn hold(&mut self, now: f64) {
        let held = self.last_control.map_or(0.0, |t| (now - t).max(0.0));
        self.last_control = Some(now);
        if let State::Driving { deadline, .. } = &mut self.state {
            *deadline += held;
        }
    }

    fn settle(&mut self, now: f64) {
        self.state = State::Settling {
            until: now + self.drive.settle_time,
        };
    }

    fn plan(&mut self, map: &ClsMap, pose: Pose2, now: f64) -> ExplorerEvent {
        match next_step(map, pose, &self.planner, &mut self.memory) {
            Ok(NextStep::Goal {
                goal,
                frontier,
                path,
            }) => {
                let length = path_length(&path);
                self.stats.goals += 1;
                self.state = State::Driving {
                    follower: PathFollower::new(path, goal),
                    deadline: now + self.drive.timeout(length),
                };
                ExplorerEvent::Goal {
                    goal,
                    frontier,
                    path_length: length,
                }
            }
            Ok(NextStep::Complete { given_up }) => {
                let n = given_up.len();
                self.stats.given_up = n;
                self.state = State::Complete { given_up };
                ExplorerEvent::Complete { given_up: n }
            }
            Err(e) => {
                self.stats.plan_failures += 1;
                self.settle(now);
                ExplorerEvent::PlanFailed {
                    reason: crate::error_chain(&e),
                }
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn room(open: &[usize]) -> ClsMap {
        let pts = [[0.0, 0.0], [6.0, 0.0], [6.0, 3.0], [0.0, 3.0]];
        crate::explore::pursuit::tests::map_of(&pts, open)
    }

    #[test]
    fn settles_plans_drives_arrives_and_completes() {
        let drive = DriveConfig::default();
        let mut ex = Explorer::new(ExplorationConfig::default(), drive, 0.0);
        let open = room(&[1]);
        let mut pose = Pose2::new(3.0, 1.5, 0.0);
        // Settling first.
        assert_eq!(ex.control(&open, pose, 0.1), (Twist::ZERO, None));
        let (_, event) = ex.control(&open, pose, 0.6);
        assert!(
            matches!(event, Some(ExplorerEvent::Goal { .. })),
            "{event:?}"
        );
        let goal = ex.goal().unwrap();
        // Drive with perfect motion until arrival.
        let dt = 0.02;
        let mut t = 0.6;
        let arrived = loop {
            t += dt;
            let (tw, event) = ex.control(&open, pose, t);
            if let Some(e) = event {
                break e;
            }
            let (s, c) = pose.theta.sin_cos();
            pose = Pose2::new(
                pose.x + (c * tw.vx - s * tw.vy) * dt,
                pose.y + (s * tw.vx + c * tw.vy) * dt,
                pose.theta + tw.omega * dt,
            );
            assert!(t < 30.0);
        };
        assert_eq!(arrived, ExplorerEvent::Arrived { goal });
        // The frontier got "scanned": the map is now closed.
        let closed = room(&[]);
        let (_, event) = ex.control(&closed, pose, t + drive.settle_time + 0.01);
        assert_eq!(event, Some(ExplorerEvent::Complete { given_up: 0 }));
        assert!(ex.is_complete());
        assert_eq!(ex.control(&closed, pose, t + 5.0), (Twist::ZERO, None));
        assert_eq!(ex.stats().goals, 1);
        assert_eq!(ex.stats().arrived, 1);
        // The map changes after completion (its last loops optimised in)
        // and opens a frontier again: the explorer settles and pursues it.
        let t = t + 5.0;
        ex.reconsider(t);
        assert!(!ex.is_complete());
        assert_eq!(ex.control(&open, pose, t + 0.01), (Twist::ZERO, None));
        let (_, event) = ex.control(&open, pose, t + drive.settle_time + 0.01);
        assert!(
            matches!(event, Some(ExplorerEvent::Goal { .. })),
            "{event:?}"
        );
        assert_eq!(ex.stats().goals, 2);
    }

    #[test]
    fn a_goal_not_reached_in_time_is_abandoned_and_bad_poses_wait() {
        let mut ex = Explorer::new(ExplorationConfig::default(), DriveConfig::default(), 0.0);
        let open = room(&[1]);
        let pose = Pose2::new(3.0, 1.5, 0.0);
        ex.control(&open, pose, 1.0);
        assert!(ex.goal().is_some());
        // Held for 39 s: the deadline moves on.
        for k in 1..=390 {
            ex.hold(1.0 + 0.1 * k as f64);
        }
        let (_, event) = ex.control(&open, pose, 40.0);
        assert_eq!(event, None, "held for 39 s, not timed out");
        // The robot never moves.
        let (_, event) = ex.control(&open, pose, 40.3);
        assert_eq!(event, None);
        let mut t = 40.3;
        let event = loop {
            t += 0.1;
            if let (_, Some(e)) = ex.control(&open, pose, t) {
                break e;
            }
            assert!(t < 100.0);
        };
        assert!(matches!(event, ExplorerEvent::TimedOut { .. }), "{event:?}");
        let nan = Pose2::new(f64::NAN, 0.0, 0.0);
        let (tw, event) = ex.control(&open, nan, t + 0.6);
        assert_eq!(tw, Twist::ZERO);
        assert!(matches!(event, Some(ExplorerEvent::PlanFailed { .. })));
        assert_eq!(ex.stats().plan_failures, 1);
        assert!(!ex.is_complete());
    }
}
