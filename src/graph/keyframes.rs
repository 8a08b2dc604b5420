//! The keyframes and their pose graph: the source of truth of a map. The
//! walls (segment map) and the CLS region are functions of them, rebuilt in
//! keyframe order whenever a loop closure moves the poses.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use serde::Serialize;
use tracing::{debug, trace_span};

use super::{
    EdgeKind, GraphError, LoopClosureConfig, LoopQuery, LoopRejection, OptimizeReport, PoseGraph,
    close_loop,
};
use crate::geometry::Pose2;
use crate::localize::LocalizerConfig;
use crate::localize::global::GlobalConfig;
use crate::map::cls::{ClsMap, ClsMapConfig};
use crate::map::{Keyframe, SegmentMap, SegmentMapConfig};

/// Loop-closure counters of a run.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct LoopStats {
    /// Keyframes that had at least one candidate in their search window.
    pub searched: usize,
    /// Verified loops (an agreeing one closer than
    /// `agreeing_loop_spacing` to the last loop edge is counted but not
    /// added as an edge).
    pub accepted: usize,
    /// Of those, found by the voting search (the others by local matching).
    pub by_voting: usize,
    /// Searches that found no verified loop, by reason.
    pub rejected: BTreeMap<String, usize>,
    /// Keyframes not kept because a loop tied them to a kept keyframe at
    /// nearly the same pose (a robot patrolling a mapped floor adds no
    /// keyframes, so memory follows the area, not the time).
    pub revisits_merged: usize,
    /// Optimisations run, and loop edges the optimiser's kernel
    /// down-weighted in the last one.
    pub optimisations: usize,
    pub down_weighted: usize,
    /// Time in loop search, optimisation and rebuilds (s).
    pub search_s: f64,
    pub optimise_s: f64,
    pub rebuild_s: f64,
}

/// What closing a loop did to the newest keyframe.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Correction {
    /// Map-frame correction of the newest keyframe: `new = correction ∘ old`.
    pub correction: Pose2,
    pub report: OptimizeReport,
}

/// Keyframes, the pose graph over them, and the counters.
#[derive(Debug, Clone, Default)]
pub struct KeyframeGraph {
    /// Shared, since a keyframe never changes once taken: a snapshot of
    /// the map for a checkpoint copies pointers, not scans.
    keyframes: Vec<Arc<Keyframe>>,
    graph: PoseGraph,
    stats: LoopStats,
    /// Loop edges added since the last optimisation (each agreed with the
    /// graph when it came, but together they may pull a little).
    unoptimised_loops: usize,
    /// Whether the newest keyframe found a loop that agrees with the graph.
    newest_agrees: bool,
    /// The newest keyframe that received a loop edge.
    last_loop_keyframe: Option<usize>,
    /// Path driven through every keyframe taken, kept or merged (m), and
    /// the pose of the last one taken (map frame).
    odometer: f64,
    last_taken: Option<Pose2>,
    /// Keyframes taken, kept or merged: the voting cadence counts these.
    taken: usize,
}

impl KeyframeGraph {
    pub fn new() -> Self {
        KeyframeGraph::default()
    }

    pub fn keyframes(&self) -> &[Arc<Keyframe>] {
        &self.keyframes
    }

    /// A graph of `keyframes` at `poses` tied by `edges`, as a map file
    /// stores them (see [`crate::map::file`]); the next keyframe taken
    /// continues the path from the last one. Refused when the counts
    /// disagree or an edge does not fit.
    pub fn from_parts(
        keyframes: Vec<Arc<Keyframe>>,
        poses: Vec<Pose2>,
        edges: Vec<super::Edge>,
    ) -> Result<Self, GraphError> {
        if keyframes.len() != poses.len() {
            return Err(GraphError::Inconsistent(format!(
                "{} keyframes but {} poses",
                keyframes.len(),
                poses.len()
            )));
        }
        let mut graph = PoseGraph::new();
        for pose in &poses {
            graph.add_pose(*pose);
        }
        let mut last_loop_keyframe = None;
        for edge in edges {
            if edge.kind == EdgeKind::Loop {
                last_loop_keyframe = Some(edge.to);
            }
            graph.add_edge(edge)?;
        }
        Ok(KeyframeGraph {
            odometer: keyframes.last().map_or(0.0, |k| k.travelled),
            last_taken: poses.last().copied(),
            taken: keyframes.len(),
            keyframes,
            graph,
            last_loop_keyframe,
            ..KeyframeGraph::default()
        })
    }

    pub fn graph(&self) -> &PoseGraph {
        &self.graph
    }

    pub fn poses(&self) -> &[Pose2] {
        self.graph.poses()
    }

    pub fn len(&self) -> usize {
        self.keyframes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.keyframes.is_empty()
    }

    pub fn stats(&self) -> &LoopStats {
        &self.stats
    }

    /// Adds `keyframe` at `pose` with a chain edge from the previous one
    /// (measured by the two poses; σ from `cfg`, tripled when the pose was
    /// not localized but predicted from odometry); its `travelled` is set
    /// here. Returns its index.
    pub fn add(
        &mut self,
        mut keyframe: Keyframe,
        pose: Pose2,
        localized: bool,
        cfg: &LoopClosureConfig,
    ) -> usize {
        let previous = self.graph.poses().last().copied();
        if let Some(p) = self.last_taken {
            self.odometer += (pose.x - p.x).hypot(pose.y - p.y);
        }
        self.last_taken = Some(pose);
        self.taken += 1;
        keyframe.travelled = self.odometer;
        let index = self.graph.add_pose(pose);
        self.newest_agrees = false;
        if let Some(p) = previous {
            let delta = p.between(&pose);
            let mut information = cfg.chain_information(&delta);
            if !localized {
                information /= 9.0;
            }
            let edge = super::Edge {
                from: index - 1,
                to: index,
                measurement: delta,
                information,
                kind: EdgeKind::Chain,
            };
            if let Err(e) = self.graph.add_edge(edge) {
                // Not finite: the keyframe stays, held by no edge but its
                // pose (the optimiser keeps it where it is).
                debug!("chain edge refused: {e}");
            }
        }
        self.keyframes.push(Arc::new(keyframe));
        index
    }

    /// Looks for a loop from the newest keyframe; adds a verified one to
    /// the graph and optimises when the graph disagrees with it. Returns
    /// the correction of the newest keyframe when the poses moved.
    pub fn close_loop(
        &mut self,
        fusion: &SegmentMapConfig,
        localizer: &LocalizerConfig,
        global: &GlobalConfig,
        cfg: &LoopClosureConfig,
    ) -> Result<Option<Correction>, GraphError> {
        let Some(current) = self.keyframes.len().checked_sub(1) else {
            return Ok(None);
        };
        if !cfg.enabled || current == 0 {
            return Ok(None);
        }
        let started = Instant::now();
        let query = LoopQuery {
            keyframes: &self.keyframes,
            poses: self.graph.poses(),
            current,
            allow_voting: self.taken % cfg.vote_every.max(1) == 0,
        };
        let found = trace_span!("loop_search")
            .in_scope(|| close_loop(&query, fusion, localizer, global, cfg));
        self.stats.search_s += started.elapsed().as_secs_f64();
        let m = match found {
            Ok(m) => m,
            Err(LoopRejection::NoCandidate) => return Ok(None),
            Err(why) => {
                debug!(keyframe = current, "no loop: {why:?}");
                self.stats.searched += 1;
                *self.stats.rejected.entry(format!("{why:?}")).or_default() += 1;
                return Ok(None);
            }
        };
        self.stats.searched += 1;
        self.stats.accepted += 1;
        self.stats.by_voting += usize::from(m.by_voting);
        let poses = self.graph.poses();
        let edge = m.edge(current, &poses[m.keyframe], cfg);
        let residual = super::edge_error(&edge, &poses[m.keyframe], &poses[current]);
        let chi2 = residual.dot(&(edge.information * residual));
        debug!(
            keyframe = current,
            with = m.keyframe,
            chi2,
            voting = m.by_voting,
            "loop closed"
        );
        if chi2 <= cfg.optimize_above_chi2 {
            self.newest_agrees = true;
            // Loops the graph already agrees with stiffen it only a little;
            // one every few keyframes keeps the graph sparse where a robot
            // patrols (a loop edge at every keyframe of a small floor makes
            // its factor dense).
            let recent = self
                .last_loop_keyframe
                .is_some_and(|k| current - k < cfg.agreeing_loop_spacing);
            if !recent {
                self.graph.add_edge(edge)?;
                self.unoptimised_loops += 1;
                self.last_loop_keyframe = Some(current);
            }
            return Ok(None);
        }
        self.graph.add_edge(edge)?;
        self.unoptimised_loops += 1;
        self.last_loop_keyframe = Some(current);
        match self.optimise(cfg) {
            Ok(c) => Ok(Some(c)),
            Err(e) => {
                // The poses are rolled back; the loop that could not be
                // optimised goes too, or every later optimisation would
                // fail on it.
                self.graph.pop_edge();
                self.unoptimised_loops -= 1;
                self.stats.accepted -= 1;
                Err(e)
            }
        }
    }

    /// Drops the newest keyframe when its loop search found a loop that
    /// agrees with the graph (added as an edge or not) and a kept keyframe
    /// at least `cfg.min_travel` of path back lies within
    /// `cfg.revisit_distance` and `cfg.revisit_angle`: that place is in the
    /// map already. Returns the kept keyframe it was merged into (the
    /// nearest such), if it was dropped.
    pub fn merge_revisit(&mut self, cfg: &LoopClosureConfig) -> Option<usize> {
        let newest = self.keyframes.len().checked_sub(1)?;
        if !self.newest_agrees {
            return None;
        }
        let poses = self.graph.poses();
        let b = poses[newest];
        let limit = self.keyframes[newest].travelled - cfg.min_travel;
        let near = self
            .keyframes
            .iter()
            .zip(poses)
            .enumerate()
            .take_while(|(_, (k, _))| k.travelled <= limit)
            .filter(|(_, (_, a))| {
                (a.x - b.x).hypot(a.y - b.y) <= cfg.revisit_distance
                    && crate::geometry::wrap_angle(a.theta - b.theta).abs() <= cfg.revisit_angle
            })
            .map(|(j, (_, a))| (j, (a.x - b.x).hypot(a.y - b.y)))
            .min_by(|x, y| x.1.total_cmp(&y.1))
            .map(|(j, _)| j)?;
        let had_loop = self
            .graph
            .edges()
            .last()
            .is_some_and(|e| e.kind == EdgeKind::Loop && e.to == newest);
        self.graph.pop_pose();
        self.keyframes.pop();
        self.newest_agrees = false;
        if had_loop {
            self.unoptimised_loops = self.unoptimised_loops.saturating_sub(1);
            self.last_loop_keyframe = None;
        }
        self.stats.revisits_merged += 1;
        Some(near)
    }

    /// Optimises once more if loop edges came in since the last
    /// optimisation (the end of a run); the correction of the newest
    /// keyframe when the poses moved.
    pub fn settle(&mut self, cfg: &LoopClosureConfig) -> Result<Option<Correction>, GraphError> {
        if self.unoptimised_loops == 0 {
            return Ok(None);
        }
        self.optimise(cfg).map(Some)
    }

    fn optimise(&mut self, cfg: &LoopClosureConfig) -> Result<Correction, GraphError> {
        let current = self.graph.poses().len().saturating_sub(1);
        let before = self.graph.poses()[current];
        let started = Instant::now();
        let saved = self.graph.poses().to_vec();
        let report = match trace_span!("optimise").in_scope(|| self.graph.optimize(&cfg.optimizer))
        {
            Ok(r) => r,
            Err(e) => {
                self.graph.set_poses(saved);
                return Err(e);
            }
        };
        self.stats.optimise_s += started.elapsed().as_secs_f64();
        self.stats.optimisations += 1;
        self.stats.down_weighted = report.loops_down_weighted;
        self.unoptimised_loops = 0;
        let after = self.graph.poses()[current];
        let correction = after.compose(&before.inverse());
        if let Some(p) = &mut self.last_taken {
            *p = correction.compose(p);
        }
        Ok(Correction { correction, report })
    }

    /// The walls of every kept keyframe fused in keyframe order at the
    /// current poses: what the incremental updates built for the same
    /// poses, less the scans of merged revisits.
    pub fn rebuild_walls(&mut self, config: SegmentMapConfig) -> SegmentMap {
        let started = Instant::now();
        let mut map = SegmentMap::new(config);
        for (kf, pose) in self.keyframes.iter().zip(self.graph.poses()) {
            map.update(&kf.lines, pose, &kf.covariance);
        }
        self.stats.rebuild_s += started.elapsed().as_secs_f64();
        map
    }

    /// The CLS map of every keyframe in keyframe order at the current
    /// poses, and how many keyframes it refused.
    pub fn rebuild_cls(&mut self, config: ClsMapConfig) -> (ClsMap, usize) {
        let started = Instant::now();
        let mut cls = ClsMap::new(config);
        let mut refused = 0;
        for (kf, pose) in self.keyframes.iter().zip(self.graph.poses()) {
            let grown = match &kf.region {
                Some(region) => cls
                    .add_keyframe(&kf.lines, region, *pose, kf.covariance)
                    .is_ok(),
                None => false,
            };
            refused += usize::from(!grown);
        }
        self.stats.rebuild_s += started.elapsed().as_secs_f64();
        (cls, refused)
    }
}
