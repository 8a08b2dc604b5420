//! Shortest paths for a round robot inside the CLS map: a visibility graph
//! over the shrunk free region ([`FreeSpace`]) — start, goals and the
//! region's reflex vertices, joined where the straight step stays inside —
//! searched by Dijkstra. In a polygon with holes the Euclidean shortest
//! path bends only at reflex vertices, so this graph holds it exactly.
//!
//! Edges are tested lazily, when a node is settled, so a search that ends
//! early never pays for the rest of the graph; an edge that is not tangent
//! to the boundary at a corner it ends in is skipped before the (costlier)
//! inside test, since no shortest path bends along it (the reduced
//! visibility graph).

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use crate::map::cls::ClsMap;

use super::free_space::{FreeSpace, FreeSpaceError, distance};

/// Why no path was planned.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    #[error("a point is not finite")]
    NotFinite,
    #[error(transparent)]
    FreeSpace(#[from] FreeSpaceError),
    #[error("the start ({0:?}) is {1:.3} m outside the region the robot fits in")]
    StartOutside([f64; 2], f64),
    #[error("the goal ({0:?}) is not in the region the robot fits in")]
    GoalOutside([f64; 2]),
    #[error("no path with the robot's clearance joins the start and the goal")]
    Unreachable,
}

/// Where a search starts: the robot's position, joined to the shrunk region
/// by a straight step when it lies just outside (see
/// [`ExplorationConfig::start_snap`](super::ExplorationConfig)).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Start {
    /// The robot's position (m).
    pub position: [f64; 2],
    /// The first point inside the region: `position` itself, or the
    /// nearest boundary point of the region.
    pub entry: [f64; 2],
}

impl Start {
    /// The start at `position`, snapped into `free` if it lies no more than
    /// `snap` (m) outside.
    pub fn new(free: &FreeSpace, position: [f64; 2], snap: f64) -> Result<Start, PlanError> {
        if !(position[0].is_finite() && position[1].is_finite()) {
            return Err(PlanError::NotFinite);
        }
        if free.contains(position) {
            return Ok(Start {
                position,
                entry: position,
            });
        }
        let entry = free
            .nearest_boundary_point(position)
            .ok_or(PlanError::StartOutside(position, f64::INFINITY))?;
        let gap = distance(entry, position);
        if gap > snap {
            return Err(PlanError::StartOutside(position, gap));
        }
        Ok(Start { position, entry })
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Queued {
    cost: f64,
    node: usize,
}

impl Eq for Queued {}

impl Ord for Queued {
    fn cmp(&self, other: &Self) -> Ordering {
        // Min-heap on cost; ties by node index for determinism.
        other
            .cost
            .total_cmp(&self.cost)
            .then_with(|| other.node.cmp(&self.node))
    }
}

impl PartialOrd for Queued {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// How far a search for several goals goes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Until {
    /// Until every goal is settled or known to be unreachable (Dijkstra).
    AllGoals,
    /// Until the nearest goal (by path length) is settled, and every other
    /// goal within `tie` (m) of it. The search is an A* with the distance
    /// to the nearest goal as heuristic (consistent, so goals are settled
    /// in order of path length); goals it did not reach are
    /// [`Reach::NotSearched`] unless the whole region was searched.
    Nearest { tie: f64 },
}

/// What a search found for one goal.
#[derive(Debug, Clone, PartialEq)]
pub enum Reach {
    /// The shortest path (m, from the robot's position to the goal) and its
    /// length inside the region (m, without the step that snaps the start
    /// into the region).
    Path { length: f64, path: Vec<[f64; 2]> },
    /// The goal is outside the region or not connected to the start.
    Unreachable,
    /// The search stopped before it reached this goal (see
    /// [`Until::Nearest`]).
    NotSearched,
}

/// Shortest paths from `start` to `goals` inside `free`, one [`Reach`] per
/// goal, searched as far as `until` says.
pub fn shortest_paths(
    free: &FreeSpace,
    start: &Start,
    goals: &[[f64; 2]],
    until: Until,
) -> Vec<Reach> {
    // Nodes: 0 = entry, 1..=goals, then the reflex corners.
    let mut nodes = vec![start.entry];
    nodes.extend_from_slice(goals);
    let first_vertex = nodes.len();
    let corners = free.reflex_corners();
    nodes.extend(corners.iter().map(|c| c.vertex));
    // The corner at node `i`, if it is one.
    let corner = |i: usize| i.checked_sub(first_vertex).and_then(|k| corners.get(k));
    let is_goal = |i: usize| (1..first_vertex).contains(&i);
    let usable: Vec<bool> = nodes
        .iter()
        .enumerate()
        .map(|(i, p)| i >= first_vertex || free.contains(*p))
        .collect();
    let open: Vec<[f64; 2]> = (1..first_vertex)
        .filter(|&g| usable[g])
        .map(|g| nodes[g])
        .collect();
    let heuristic = |p: [f64; 2]| match until {
        Until::AllGoals => 0.0,
        Until::Nearest { .. } => open
            .iter()
            .map(|g| distance(p, *g))
            .fold(f64::INFINITY, f64::min),
    };
    let mut cost = vec![f64::INFINITY; nodes.len()];
    let mut prev = vec![usize::MAX; nodes.len()];
    let mut done = vec![false; nodes.len()];
    let mut open_goals = open.len();
    let mut exhausted = true;
    let mut stop_at = f64::INFINITY;
    let mut heap = BinaryHeap::new();
    cost[0] = 0.0;
    heap.push(Queued {
        cost: heuristic(nodes[0]),
        node: 0,
    });
    while let Some(Queued { cost: f, node: u }) = heap.pop() {
        if done[u] {
            continue;
        }
        if f > stop_at || open_goals == 0 {
            exhausted = false;
            break;
        }
        done[u] = true;
        if is_goal(u) {
            open_goals -= 1;
            if let Until::Nearest { tie } = until {
                stop_at = stop_at.min(cost[u] + tie.max(0.0));
            }
            // A goal is an end, not a corner: paths never bend there.
            continue;
        }
        for v in 0..nodes.len() {
            if done[v] || !usable[v] {
                continue;
            }
            let candidate = cost[u] + distance(nodes[u], nodes[v]);
            let tangent = corner(u).is_none_or(|k| k.tangent_towards(nodes[v]))
                && corner(v).is_none_or(|k| k.tangent_towards(nodes[u]));
            if candidate < cost[v] && tangent && free.segment_inside(nodes[u], nodes[v]) {
                cost[v] = candidate;
                prev[v] = u;
                heap.push(Queued {
                    cost: candidate + heuristic(nodes[v]),
                    node: v,
                });
            }
        }
    }
    (1..first_vertex)
        .map(|g| {
            if !done[g] {
                return if usable[g] && !exhausted {
                    Reach::NotSearched
                } else {
                    Reach::Unreachable
                };
            }
            let mut path = vec![nodes[g]];
            let mut at = g;
            while prev[at] != usize::MAX {
                at = prev[at];
                path.push(nodes[at]);
            }
            if start.entry != start.position {
                path.push(start.position);
            }
            path.reverse();
            path.dedup();
            Reach::Path {
                length: cost[g],
                path,
            }
        })
        .collect()
}

/// Length (m) of a polyline.
pub fn path_length(path: &[[f64; 2]]) -> f64 {
    path.windows(2).map(|w| distance(w[0], w[1])).sum()
}

/// The shortest path (m, map frame) from `from` to `to` for a round robot
/// of radius `radius` (m) inside the free space of `map`: every point of
/// it keeps at least `radius` from every map boundary (walls and frontiers
/// alike), except that `from` may lie up to `radius` outside that region
/// (a robot that just scanned sits on the map's boundary) and is joined to
/// it by a straight step.
pub fn plan_path(
    map: &ClsMap,
    from: [f64; 2],
    to: [f64; 2],
    radius: f64,
) -> Result<Vec<[f64; 2]>, PlanError> {
    let free = FreeSpace::from_map(map, radius)?;
    plan_in(&free, from, to, radius)
}

/// [`plan_path`] in an already shrunk region, with start snapping up to
/// `snap` (m).
pub fn plan_in(
    free: &FreeSpace,
    from: [f64; 2],
    to: [f64; 2],
    snap: f64,
) -> Result<Vec<[f64; 2]>, PlanError> {
    if !(to[0].is_finite() && to[1].is_finite()) {
        return Err(PlanError::NotFinite);
    }
    let start = Start::new(free, from, snap)?;
    if !free.contains(to) {
        return Err(PlanError::GoalOutside(to));
    }
    match shortest_paths(free, &start, &[to], Until::Nearest { tie: 0.0 }).pop() {
        Some(Reach::Path { path, .. }) => Ok(path),
        _ => Err(PlanError::Unreachable),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn straight_when_visible_and_around_a_corner_otherwise() {
        let l = vec![
            [0.0, 0.0],
            [4.0, 0.0],
            [4.0, 1.0],
            [1.0, 1.0],
            [1.0, 4.0],
            [0.0, 4.0],
        ];
        let free = FreeSpace::from_contours(vec![l]);
        let p = plan_in(&free, [3.5, 0.5], [3.0, 0.2], 0.0).unwrap();
        assert_eq!(p, vec![[3.5, 0.5], [3.0, 0.2]]);
        let p = plan_in(&free, [3.5, 0.5], [0.5, 3.5], 0.0).unwrap();
        assert_eq!(p, vec![[3.5, 0.5], [1.0, 1.0], [0.5, 3.5]]);
        let expected = distance([3.5, 0.5], [1.0, 1.0]) + distance([1.0, 1.0], [0.5, 3.5]);
        assert!((path_length(&p) - expected).abs() < 1e-12);
    }

    #[test]
    fn typed_errors_for_bad_ends() {
        let sq = vec![[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]];
        let free = FreeSpace::from_contours(vec![sq]);
        assert_eq!(
            plan_in(&free, [1.0, 1.0], [3.0, 1.0], 0.0),
            Err(PlanError::GoalOutside([3.0, 1.0]))
        );
        assert!(matches!(
            plan_in(&free, [5.0, 1.0], [1.0, 1.0], 0.5),
            Err(PlanError::StartOutside(_, _))
        ));
        assert_eq!(
            plan_in(&free, [f64::NAN, 1.0], [1.0, 1.0], 0.5),
            Err(PlanError::NotFinite)
        );
        // Just outside: snapped in by a straight step.
        let p = plan_in(&free, [2.2, 1.0], [1.0, 1.0], 0.5).unwrap();
        assert_eq!(p.first(), Some(&[2.2, 1.0]));
        assert_eq!(p.get(1), Some(&[2.0, 1.0]));
    }
}
