//! The keyframes and their pose graph: the source of truth of a map. The
//! walls (segment map) and the CLS region are functions of them, rebuilt in
//! keyframe order whenever a loop closure moves the poses.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use serde::Serialize;
use tracing::{debug, trace_span};

use super::{
    GraphError, LoopClosureConfig, LoopMatch, LoopQuery, LoopRejection, OptimizeReport, PoseGraph,
    agreeing_loops, close_loop, drift_paths,
};
use crate::geometry::Pose2;
use crate::localize::LocalizerConfig;
use crate::localize::global::GlobalConfig;
use crate::map::cls::{ClsMap, ClsMapConfig};
use crate::map::{Edge, EdgeKind, Keyframe, SegmentMap, SegmentMapConfig};

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
    /// Loop searches and optimisations are handed out as
    /// [`LoopSearchJob`]s and [`OptimisationJob`]s to run off the caller's
    /// thread instead of running where keyframes are added.
    background: bool,
    /// A loop moved the map and no job has taken it in yet.
    wants_optimisation: bool,
    /// The job in flight: its id, how many keyframes it covers, and how
    /// many of the newest loop edges it is to optimise in.
    in_flight: Option<(u64, usize, usize)>,
    jobs: u64,
    /// The next keyframe gets no chain edge (see [`Self::add_relocalized`]).
    unchained_next: bool,
    /// In background mode: the newest keyframe waits for its loop search.
    search_wanted: bool,
    /// The keyframe whose loop search is in flight.
    search_in_flight: Option<Arc<Keyframe>>,
}

/// A loop search for one keyframe over a snapshot of the keyframes and
/// their poses: about 0.2 ms a keyframe on a large map (more when the
/// voting search runs), to run off the real-time loop.
#[derive(Debug, Clone)]
pub struct LoopSearchJob {
    keyframes: Vec<Arc<Keyframe>>,
    poses: Vec<Pose2>,
    current: usize,
    /// The graph's loop edges, for the paths through it (worked out in
    /// the job, off the real-time loop).
    loops: Vec<Edge>,
    allow_voting: bool,
    fusion: SegmentMapConfig,
    localizer: LocalizerConfig,
    global: GlobalConfig,
    cfg: LoopClosureConfig,
    /// The keyframe searched for, to tell its result from a stale one.
    keyframe: Arc<Keyframe>,
}

/// What a search found: a verified loop with its edge (measured at the
/// searched poses), or why there was none; and how long it took.
#[derive(Debug, Clone)]
struct SearchOutcome {
    found: Result<(LoopMatch, super::Edge), LoopRejection>,
    elapsed_s: f64,
}

/// What a [`LoopSearchJob`] gives back.
#[derive(Debug, Clone)]
pub struct LoopSearchResult {
    current: usize,
    keyframe: Arc<Keyframe>,
    searched: SearchOutcome,
}

impl LoopSearchJob {
    /// Searches; runs anywhere, touches nothing but itself.
    pub fn run(self) -> LoopSearchResult {
        let ties: Vec<(usize, usize)> =
            agreeing_loops(&self.loops, &self.poses, &self.cfg.optimizer).collect();
        let paths = drift_paths(&self.keyframes, &ties, self.current);
        let query = LoopQuery {
            keyframes: &self.keyframes,
            poses: &self.poses,
            current: self.current,
            paths: &paths,
            allow_voting: self.allow_voting,
        };
        let searched = Self::search(
            &query,
            &self.fusion,
            &self.localizer,
            &self.global,
            &self.cfg,
        );
        LoopSearchResult {
            current: self.current,
            keyframe: self.keyframe,
            searched,
        }
    }

    fn search(
        query: &LoopQuery<'_>,
        fusion: &SegmentMapConfig,
        localizer: &LocalizerConfig,
        global: &GlobalConfig,
        cfg: &LoopClosureConfig,
    ) -> SearchOutcome {
        let started = Instant::now();
        let found = trace_span!("loop_search")
            .in_scope(|| close_loop(query, fusion, localizer, global, cfg))
            .map(|m| {
                let edge = m.edge(query.current, &query.poses[m.keyframe], cfg);
                (m, edge)
            });
        SearchOutcome {
            found,
            elapsed_s: started.elapsed().as_secs_f64(),
        }
    }
}

/// An optimisation of a snapshot of the graph, with the rebuild of the
/// walls and the CLS map at the optimised poses: the long part of a loop
/// closure (seconds on a large map), to run off the real-time loop while
/// the mapper goes on localizing against the old map.
#[derive(Debug, Clone)]
pub struct OptimisationJob {
    id: u64,
    graph: PoseGraph,
    keyframes: Vec<Arc<Keyframe>>,
    optimizer: super::OptimizerConfig,
    fusion: SegmentMapConfig,
    cls: ClsMapConfig,
    /// Indices of the loop edges no optimisation has taken in yet.
    new_loops: Vec<usize>,
}

/// What a job gives back.
#[derive(Debug)]
pub struct OptimisationResult {
    id: u64,
    outcome: Result<(Vec<Pose2>, OptimizeReport, SegmentMap, ClsMap), GraphError>,
    new_loops: Vec<usize>,
    optimise_s: f64,
    rebuild_s: f64,
}

impl OptimisationJob {
    /// Optimises and rebuilds; runs anywhere, touches nothing but itself.
    pub fn run(mut self) -> OptimisationResult {
        let started = Instant::now();
        let report = trace_span!("optimise").in_scope(|| self.graph.optimize(&self.optimizer));
        let optimise_s = started.elapsed().as_secs_f64();
        let started = Instant::now();
        let outcome = report.map(|report| {
            let poses = self.graph.poses().to_vec();
            let (walls, cls, _) = build_maps(&self.keyframes, &poses, self.fusion, self.cls);
            (poses, report, walls, cls)
        });
        OptimisationResult {
            id: self.id,
            outcome,
            new_loops: self.new_loops,
            optimise_s,
            rebuild_s: started.elapsed().as_secs_f64(),
        }
    }
}

/// A job's result taken in: the correction of the newest keyframe, the
/// maps rebuilt for the keyframes the job covered, and from which
/// keyframe on the caller must add the rest itself.
#[derive(Debug)]
pub struct AppliedOptimisation {
    pub correction: Correction,
    pub walls: SegmentMap,
    pub cls: ClsMap,
    pub covered: usize,
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

    /// Hands loop searches and optimisations out as jobs
    /// ([`Self::take_loop_search`], [`Self::take_job`]) instead of running
    /// them where keyframes are added.
    pub fn set_background_loop_closure(&mut self, on: bool) {
        self.background = on;
    }

    /// The optimisation a loop asked for, as a job covering the keyframes
    /// so far, unless one is in flight; `fusion` and `cls` configure the
    /// rebuild.
    pub fn take_job(
        &mut self,
        fusion: SegmentMapConfig,
        cls: ClsMapConfig,
        cfg: &LoopClosureConfig,
    ) -> Option<OptimisationJob> {
        if !self.wants_optimisation || self.in_flight.is_some() {
            return None;
        }
        self.jobs += 1;
        let id = self.jobs;
        let new_loops = self.unoptimised_loop_edges();
        let job_loops = self.unoptimised_loops;
        self.wants_optimisation = false;
        self.unoptimised_loops = 0;
        self.in_flight = Some((id, self.keyframes.len(), job_loops));
        Some(OptimisationJob {
            id,
            graph: self.graph.clone(),
            keyframes: self.keyframes.clone(),
            optimizer: cfg.optimizer,
            fusion,
            cls,
            new_loops,
        })
    }

    /// The job in flight was lost (its thread failed): the next
    /// [`take_job`](Self::take_job) covers its loops again.
    pub fn abandon_job(&mut self) {
        if let Some((_, _, loops)) = self.in_flight.take() {
            self.unoptimised_loops += loops;
            self.wants_optimisation = true;
        }
    }

    /// Takes in a job's result: the keyframes it covered get their
    /// optimised poses, later ones follow the last of them rigidly. A
    /// result of a job no longer in flight (superseded by [`Self::settle`])
    /// is ignored (`Ok(None)`). A failed optimisation drops the loops it
    /// was for, so later ones do not fail on them too.
    pub fn apply_job(
        &mut self,
        result: OptimisationResult,
    ) -> Result<Option<AppliedOptimisation>, GraphError> {
        let Some((id, covered, _)) = self.in_flight else {
            return Ok(None);
        };
        if id != result.id {
            return Ok(None);
        }
        self.in_flight = None;
        self.stats.optimise_s += result.optimise_s;
        self.stats.rebuild_s += result.rebuild_s;
        let (optimised, report, walls, cls) = match result.outcome {
            Ok(parts) => parts,
            Err(e) => {
                self.graph.remove_edges(&result.new_loops);
                self.stats.accepted = self.stats.accepted.saturating_sub(result.new_loops.len());
                return Err(e);
            }
        };
        let old = self.graph.poses().to_vec();
        let Some(last) = covered.checked_sub(1) else {
            return Ok(None);
        };
        if optimised.len() != covered || old.len() < covered {
            return Err(GraphError::Inconsistent(format!(
                "a job over {covered} keyframes gave {} poses for a graph of {}",
                optimised.len(),
                old.len()
            )));
        }
        let mut poses = optimised.clone();
        for pose in &old[covered..] {
            poses.push(optimised[last].compose(&old[last].between(pose)));
        }
        let newest = old.len() - 1;
        let correction = poses[newest].compose(&old[newest].inverse());
        self.graph.set_poses(poses);
        if let Some(p) = &mut self.last_taken {
            *p = correction.compose(p);
        }
        self.stats.optimisations += 1;
        self.stats.down_weighted = report.loops_down_weighted;
        Ok(Some(AppliedOptimisation {
            correction: Correction { correction, report },
            walls,
            cls,
            covered,
        }))
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
        if let Some(p) = previous.filter(|_| !std::mem::take(&mut self.unchained_next)) {
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
        self.search_wanted = self.background;
        index
    }

    /// Adds `keyframe` at `pose` (covariance `covariance`), the first of a
    /// new session on a loaded map: no measurement joins it to the last
    /// keyframe of the old session, so it is tied instead by a loop edge
    /// to the nearest old keyframe, as a relocalization against the old
    /// map is a loop closure. Returns its index.
    pub fn add_relocalized(
        &mut self,
        keyframe: Keyframe,
        pose: Pose2,
        covariance: [[f64; 3]; 3],
        cfg: &LoopClosureConfig,
    ) -> usize {
        let nearest = self
            .graph
            .poses()
            .iter()
            .enumerate()
            .map(|(j, p)| (j, (p.x - pose.x).hypot(p.y - pose.y)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(j, _)| j);
        self.unchained_next = true;
        let index = self.add(keyframe, pose, true, cfg);
        if let Some(j) = nearest {
            let seen = super::LoopMatch {
                keyframe: j,
                pose,
                covariance,
                matches: 0,
                matched_length: 0.0,
                by_voting: false,
            };
            let edge = seen.edge(index, &self.graph.poses()[j], cfg);
            match self.graph.add_edge(edge) {
                // A loop edge like any other: counted until optimised (and
                // uncounted if its keyframe is merged as a revisit).
                Ok(()) => self.unoptimised_loops += 1,
                Err(e) => debug!("relocalization edge refused: {e}"),
            }
        }
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
        // Searched here, not as a job.
        self.search_wanted = false;
        let Some(current) = self.searchable_newest(cfg) else {
            return Ok(None);
        };
        let paths = self.drift_paths(current, cfg);
        let query = LoopQuery {
            keyframes: &self.keyframes,
            poses: self.graph.poses(),
            current,
            paths: &paths,
            allow_voting: self.voting_now(cfg),
        };
        let searched = LoopSearchJob::search(&query, fusion, localizer, global, cfg);
        self.take_found(current, searched, cfg)
    }

    /// The newest keyframe's index when a loop search may run for it.
    fn searchable_newest(&self, cfg: &LoopClosureConfig) -> Option<usize> {
        let current = self.keyframes.len().checked_sub(1)?;
        (cfg.enabled && current > 0).then_some(current)
    }

    /// Path from each keyframe to `current` through the graph, with the
    /// loops the poses agree with now (see [`drift_paths`]).
    pub fn drift_paths(&self, current: usize, cfg: &LoopClosureConfig) -> Vec<f64> {
        let ties: Vec<(usize, usize)> =
            agreeing_loops(self.graph.edges(), self.graph.poses(), &cfg.optimizer).collect();
        drift_paths(&self.keyframes, &ties, current)
    }

    /// Whether the voting search may run for the newest keyframe.
    fn voting_now(&self, cfg: &LoopClosureConfig) -> bool {
        self.taken.is_multiple_of(cfg.vote_every.max(1))
    }

    /// Whether the newest keyframe waits for its loop search (handed out
    /// as a job in background mode, see [`Self::take_loop_search`]).
    pub fn wants_loop_search(&self) -> bool {
        self.search_wanted
    }

    /// Whether a loop search waits or is in flight: its result may still
    /// close a loop.
    pub fn loop_search_pending(&self) -> bool {
        self.search_wanted || self.search_in_flight.is_some()
    }

    /// The loop search of the newest keyframe as a job over a snapshot of
    /// the keyframes and poses, when it wants one and none is in flight;
    /// its result goes to [`Self::apply_loop_search`]. Keyframes taken
    /// while a search runs wait as one: only the newest of them is searched
    /// next (a search takes about 0.2 ms, keyframes come tenths of a
    /// second apart, so this is rare).
    pub fn take_loop_search(
        &mut self,
        fusion: &SegmentMapConfig,
        localizer: &LocalizerConfig,
        global: &GlobalConfig,
        cfg: &LoopClosureConfig,
    ) -> Option<LoopSearchJob> {
        if !self.search_wanted || self.search_in_flight.is_some() {
            return None;
        }
        self.search_wanted = false;
        let current = self.searchable_newest(cfg)?;
        let keyframe = Arc::clone(&self.keyframes[current]);
        self.search_in_flight = Some(Arc::clone(&keyframe));
        Some(LoopSearchJob {
            keyframes: self.keyframes.clone(),
            poses: self.graph.poses().to_vec(),
            current,
            loops: self.graph.loop_edges().cloned().collect(),
            allow_voting: self.voting_now(cfg),
            fusion: *fusion,
            localizer: *localizer,
            global: *global,
            cfg: *cfg,
            keyframe,
        })
    }

    /// The loop search in flight was lost (its thread failed); the next
    /// keyframe's search goes ahead.
    pub fn abandon_loop_search(&mut self) {
        self.search_in_flight = None;
    }

    /// Takes in a loop search's result as [`Self::close_loop`] would have:
    /// a verified loop becomes an edge (measured against the snapshot's
    /// poses, so the optimisations since do not skew it). The result of a
    /// keyframe no longer in the graph (or of another search than the
    /// one in flight) is dropped.
    pub fn apply_loop_search(
        &mut self,
        result: LoopSearchResult,
        cfg: &LoopClosureConfig,
    ) -> Result<Option<Correction>, GraphError> {
        let in_flight = self.search_in_flight.take();
        let ours = in_flight.is_some_and(|k| Arc::ptr_eq(&k, &result.keyframe));
        let here = self
            .keyframes
            .get(result.current)
            .is_some_and(|k| Arc::ptr_eq(k, &result.keyframe));
        if !ours || !here {
            self.stats.search_s += result.searched.elapsed_s;
            return Ok(None);
        }
        self.take_found(result.current, result.searched, cfg)
    }

    /// What a search for keyframe `current` found, taken into the graph:
    /// counted, and a verified loop added as an edge; optimised at once
    /// when the graph disagrees with it (in the foreground).
    fn take_found(
        &mut self,
        current: usize,
        searched: SearchOutcome,
        cfg: &LoopClosureConfig,
    ) -> Result<Option<Correction>, GraphError> {
        self.stats.search_s += searched.elapsed_s;
        let (m, edge) = match searched.found {
            Ok(found) => found,
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
            // Only the newest keyframe may be merged as a revisit.
            self.newest_agrees = current + 1 == self.keyframes.len();
            // Loops the graph already agrees with stiffen it only a little;
            // one every few keyframes keeps the graph sparse where a robot
            // patrols (a loop edge at every keyframe of a small floor makes
            // its factor dense).
            let recent = self
                .last_loop_keyframe
                .is_some_and(|k| current.saturating_sub(k) < cfg.agreeing_loop_spacing);
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
        if self.background {
            self.wants_optimisation = true;
            return Ok(None);
        }
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
        // A keyframe a job in flight covers stays: its result is indexed
        // by keyframe.
        if !self.newest_agrees || self.in_flight.is_some_and(|(_, n, _)| newest < n) {
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

    /// Indices of the loop edges not optimised in yet (the newest ones).
    fn unoptimised_loop_edges(&self) -> Vec<usize> {
        let loops = self.graph.loop_edges().count();
        self.graph
            .edges()
            .iter()
            .enumerate()
            .filter(|(_, e)| e.kind == EdgeKind::Loop)
            .map(|(i, _)| i)
            .skip(loops.saturating_sub(self.unoptimised_loops))
            .collect()
    }

    /// Whether every loop edge is optimised in and no optimisation job is
    /// in flight: [`settle`](Self::settle) would change nothing. (A loop
    /// search waiting or in flight is [`Self::loop_search_pending`].)
    pub fn is_settled(&self) -> bool {
        self.unoptimised_loops == 0 && !self.wants_optimisation && self.in_flight.is_none()
    }

    /// Optimises now if loop edges came in since the last optimisation (the
    /// end of a run, or exploration judged complete); the correction of the
    /// newest keyframe when the poses moved. A job in flight is superseded:
    /// its result will be ignored. A failed optimisation drops the loops it
    /// was for.
    pub fn settle(&mut self, cfg: &LoopClosureConfig) -> Result<Option<Correction>, GraphError> {
        if self.is_settled() {
            return Ok(None);
        }
        // A superseded job's loops are optimised in here.
        if let Some((_, _, loops)) = self.in_flight.take() {
            self.unoptimised_loops += loops;
        }
        self.wants_optimisation = false;
        let result = self.optimise(cfg).map(Some);
        if result.is_err() {
            // As for a failed job: the loops it was for are dropped, so the
            // graph is settled and later optimisations do not fail on them.
            let new_loops = self.unoptimised_loop_edges();
            self.graph.remove_edges(&new_loops);
            self.stats.accepted = self.stats.accepted.saturating_sub(new_loops.len());
            self.unoptimised_loops = 0;
        }
        result
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
            kf.add_to(pose, &mut map, None);
        }
        self.stats.rebuild_s += started.elapsed().as_secs_f64();
        map
    }

    /// The walls and the CLS map of every keyframe in keyframe order at
    /// the current poses (the CLS map's wall pieces on those walls), and
    /// how many keyframes the CLS map refused.
    pub fn rebuild_maps(
        &mut self,
        fusion: SegmentMapConfig,
        cls: ClsMapConfig,
    ) -> (SegmentMap, ClsMap, usize) {
        let started = Instant::now();
        let built = build_maps(&self.keyframes, self.graph.poses(), fusion, cls);
        self.stats.rebuild_s += started.elapsed().as_secs_f64();
        built
    }
}

/// The walls and the CLS map of `keyframes` at `poses`, in keyframe
/// order, and how many keyframes the CLS map refused.
fn build_maps(
    keyframes: &[Arc<Keyframe>],
    poses: &[Pose2],
    fusion: SegmentMapConfig,
    cls: ClsMapConfig,
) -> (SegmentMap, ClsMap, usize) {
    let mut walls = SegmentMap::new(fusion);
    let mut map = ClsMap::new(cls);
    let mut refused = 0;
    for (kf, pose) in keyframes.iter().zip(poses) {
        refused += usize::from(!kf.add_to(pose, &mut walls, Some(&mut map)));
    }
    (walls, map, refused)
}
