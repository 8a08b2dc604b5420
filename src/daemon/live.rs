//! [`LiveMapper`]: the real-time loop's work, without the loop.
//!
//! Odometry samples and scans go in with their times (seconds on the
//! daemon's monotonic clock); poses, map updates, velocity commands and
//! latencies come out. No thread, no port, no clock of its own (it reads
//! `Instant` only to time its stages), so the tokio daemon, the demo and a
//! faster-than-real-time simulation all run the same code.

use std::collections::VecDeque;
use std::path::Path;
use std::time::Duration;

use clsmap_base::Twist;
use serde::Serialize;
use tracing::{info, info_span, warn};

use super::checkpoint::{Checkpoint, CheckpointFailed};
use super::latency::{Latencies, Stage};
use crate::explore::{DriveConfig, ExplorationConfig, Explorer, ExplorerEvent, ExplorerStats};
use crate::files::trajectory::AnchoredPose;
use crate::geometry::{Pose2, RangeScan};
use crate::input::ScanRecord;
use crate::input::odometry::OdometryTrack;
use crate::pipeline::config::MapperConfig;
use crate::pipeline::{MapMode, Mapper, PipelineError, ScanOutcome};

/// How far (s) odometry is extrapolated past its newest sample to a scan's
/// time: bases report at 10–50 Hz, so a scan often lies up to one period
/// beyond the newest sample; further than this the odometry counts as
/// missing.
const MAX_EXTRAPOLATION: f64 = 0.1;

/// How much odometry history is kept (s): scans arrive a few tens of
/// milliseconds after their mid-sweep time.
const ODOMETRY_HISTORY: f64 = 2.0;

/// A snapshot for the status line and `STATUS=`.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct LiveStatus {
    pub scans: u64,
    pub localized: u64,
    pub keyframes: usize,
    /// Keyframes kept in the pose graph (revisits of mapped places are
    /// not kept) and loop closures accepted.
    pub graph_keyframes: usize,
    pub loops_closed: usize,
    /// Actual and virtual segments and loops of the CLS map.
    pub walls: usize,
    pub frontiers: usize,
    pub loops: usize,
    pub pose: Option<Pose2>,
    pub exploring: bool,
    pub exploration_complete: bool,
    pub explorer: Option<ExplorerStats>,
    /// In a loaded map: still being found, or lost (with the hypotheses).
    pub map_search: Option<crate::pipeline::MapSearch>,
}

/// The mapper, the odometry buffer and the explorer of a running robot.
#[derive(Debug)]
pub struct LiveMapper {
    mapper: Mapper,
    odometry: OdometryTrack,
    explorer: Option<Explorer>,
    latencies: Latencies,
    scans: u64,
    localized: u64,
    /// The last scan's time, its pose (map frame) and the odometry then.
    last_fix: Option<(f64, Pose2, Option<Pose2>)>,
    /// Poses taken from the mapper and not yet appended to a trajectory
    /// file (kept when an append fails, so none is lost).
    unwritten: Vec<AnchoredPose>,
    /// The mapper's [`reframes`](Mapper::reframes) when the trajectory
    /// files were last snapshotted; none after a failed write, so the next
    /// one rebuilds the TUM file whatever happened.
    reframes_written: Option<u64>,
    /// The path drawn on the map's picture: poses at least
    /// [`PICTURE_STEP`] apart, the newest [`PICTURE_POSES`] of them.
    picture_path: VecDeque<Pose2>,
}

/// Spacing (m) of the poses drawn on the map's picture.
const PICTURE_STEP: f64 = 0.1;
/// Poses drawn on the map's picture at most (a few hours of driving).
const PICTURE_POSES: usize = 50_000;

impl LiveMapper {
    /// A new map; with `exploration`, the robot explores from `now` (s).
    pub fn new(
        mapper: MapperConfig,
        exploration: Option<(ExplorationConfig, DriveConfig)>,
        now: f64,
    ) -> LiveMapper {
        Self::with_mapper(Mapper::new(mapper), exploration, now)
    }

    /// A live mapper that goes on from a saved map (see
    /// [`Mapper::from_map`]).
    pub fn from_map(
        mapper: MapperConfig,
        contents: crate::map::MapContents,
        mode: crate::pipeline::MapMode,
        exploration: Option<(ExplorationConfig, DriveConfig)>,
        now: f64,
    ) -> Result<LiveMapper, crate::pipeline::PipelineError> {
        let inner = Mapper::from_map(mapper, contents, mode)?;
        Ok(Self::with_mapper(inner, exploration, now))
    }

    fn with_mapper(
        mut inner: Mapper,
        exploration: Option<(ExplorationConfig, DriveConfig)>,
        now: f64,
    ) -> LiveMapper {
        // Samples come from a base polled live, each with its own time: an
        // unchanged pose is the robot standing still.
        inner.trust_unchanged_odometry();
        LiveMapper {
            mapper: inner,
            odometry: OdometryTrack::new(),
            explorer: exploration.map(|(planner, drive)| Explorer::new(planner, drive, now)),
            latencies: Latencies::new(),
            scans: 0,
            localized: 0,
            last_fix: None,
            unwritten: Vec::new(),
            reframes_written: Some(0),
            picture_path: VecDeque::new(),
        }
    }

    /// Scans taken up so far.
    pub fn scans(&self) -> u64 {
        self.scans
    }

    pub fn mapper(&self) -> &Mapper {
        &self.mapper
    }

    /// See [`Mapper::set_background_loop_closure`].
    pub fn set_background_loop_closure(&mut self, on: bool) {
        self.mapper.set_background_loop_closure(on);
    }

    /// See [`Mapper::take_optimisation`].
    pub fn take_optimisation(&mut self) -> Option<crate::graph::OptimisationJob> {
        self.mapper.take_optimisation()
    }

    /// See [`Mapper::abandon_optimisation`].
    pub fn abandon_optimisation(&mut self) {
        self.mapper.abandon_optimisation();
    }

    /// See [`Mapper::apply_optimisation`].
    /// The live pose, the picture's path and the explorer's goal move with
    /// the map (by the newest keyframe's correction).
    pub fn apply_optimisation(&mut self, result: crate::graph::OptimisationResult) {
        let _span = info_span!("apply_optimisation").entered();
        if let Some(c) = self.mapper.apply_optimisation(result) {
            self.follow(&c);
        }
    }

    /// See [`Mapper::take_loop_search`].
    pub fn take_loop_search(&mut self) -> Option<crate::graph::LoopSearchJob> {
        self.mapper.take_loop_search()
    }

    /// See [`Mapper::abandon_loop_search`].
    pub fn abandon_loop_search(&mut self) {
        self.mapper.abandon_loop_search();
    }

    /// See [`Mapper::apply_loop_search`]; a correction moves the live pose,
    /// the picture's path and the explorer's goal as an optimisation does.
    pub fn apply_loop_search(&mut self, result: crate::graph::LoopSearchResult) {
        let _span = info_span!("apply_loop_search").entered();
        if let Some(c) = self.mapper.apply_loop_search(result) {
            self.follow(&c);
        }
    }

    /// See [`Mapper::settle`]; the live pose, the picture's path and the
    /// explorer's goal move with the map as after an optimisation.
    pub fn settle(&mut self) {
        let _span = info_span!("settle").entered();
        if let Some(c) = self.mapper.settle() {
            self.follow(&c);
        }
    }

    /// Everything kept in the map frame follows the map's `correction`.
    fn follow(&mut self, c: &Pose2) {
        if let Some((_, pose, _)) = self.last_fix.as_mut() {
            *pose = c.compose(pose);
        }
        for p in &mut self.picture_path {
            *p = c.compose(p);
        }
        if let Some(explorer) = &mut self.explorer {
            explorer.reframe(c);
        }
    }

    pub fn latencies(&self) -> &Latencies {
        &self.latencies
    }

    pub fn explorer(&self) -> Option<&Explorer> {
        self.explorer.as_ref()
    }

    /// Takes the tunable parts of a new mapper configuration (SIGHUP);
    /// returns the keys that need a restart to change.
    pub fn retune(&mut self, mapper: MapperConfig) -> Vec<&'static str> {
        self.mapper.retune(mapper)
    }

    /// One odometry sample (t in s, pose in the odometry frame). Samples
    /// older than the newest are refused (and counted by the caller).
    pub fn on_odometry(&mut self, t: f64, pose: Pose2) -> bool {
        if self.odometry.push(t, pose).is_err() {
            return false;
        }
        self.odometry.discard_before(t - ODOMETRY_HISTORY);
        true
    }

    /// The base's odometry starts over in a new frame (the base was
    /// connected anew): old samples are dropped so none is blended with
    /// the new ones, and the mapper re-anchors.
    pub fn odometry_restarted(&mut self) {
        self.odometry = OdometryTrack::new();
        if let Some((_, _, odo)) = self.last_fix.as_mut() {
            *odo = None;
        }
        self.mapper.odometry_restarted();
    }

    /// Time of the newest odometry sample (s).
    pub fn last_odometry_time(&self) -> Option<f64> {
        self.odometry.last_time()
    }

    /// The odometry pose at `t`: interpolated, or extrapolated up to
    /// `MAX_EXTRAPOLATION` past the newest sample.
    pub fn odometry_at(&self, t: f64) -> Option<Pose2> {
        let last = self.odometry.last_time()?;
        if t <= last {
            return self.odometry.at(t);
        }
        if t - last > MAX_EXTRAPOLATION {
            return None;
        }
        let newest = self.odometry.at(last)?;
        let step = 0.02_f64.min(t - last).max(1e-3);
        match self.odometry.at(last - step) {
            Some(before) if self.odometry.covers(last - step) => {
                Some(before.interpolate(&newest, (t - (last - step)) / step))
            }
            _ => Some(newest),
        }
    }

    /// Localizes one scan (its `t` on the daemon's clock) and, on
    /// keyframes, grows the map. `queued` is the time from the telegram's
    /// last byte to now, when known; the last-byte-to-pose latency is
    /// `queued` plus the processing.
    pub fn on_scan(&mut self, scan: RangeScan, queued: Option<Duration>) -> ScanOutcome {
        let _span = info_span!("scan", t = scan.t).entered();
        let started = std::time::Instant::now();
        let t = scan.t;
        let odometry = self.odometry_at(t);
        let outcome = self.mapper.process(&ScanRecord { scan, odometry });
        let times = self.mapper.last_scan_times();
        let l = &mut self.latencies;
        for (stage, d) in [
            (Stage::Predict, times.predict),
            (Stage::Extract, times.extract),
            (Stage::Localize, times.localize),
            (Stage::MapUpdate, times.map_update),
            (Stage::ClsUpdate, times.cls_update),
        ] {
            if let Some(d) = d {
                l.record(stage, d);
            }
        }
        if let Some(q) = queued {
            l.record(Stage::Queue, q);
            l.record(Stage::Pose, q + started.elapsed());
        }
        self.scans += 1;
        self.localized += u64::from(outcome.localized);
        self.last_fix = Some((t, outcome.pose, odometry));
        let far = self
            .picture_path
            .back()
            .is_none_or(|p| (p.x - outcome.pose.x).hypot(p.y - outcome.pose.y) >= PICTURE_STEP);
        if far {
            if self.picture_path.len() >= PICTURE_POSES {
                self.picture_path.pop_front();
            }
            self.picture_path.push_back(outcome.pose);
        }
        outcome
    }

    /// A pose hint (map frame) for the robot now (`now`, s on the daemon's
    /// clock): see [`Mapper::hint_pose`].
    pub fn hint_pose(&mut self, now: f64, pose: Pose2) -> Result<(), PipelineError> {
        let odometry = self.odometry_at(now);
        self.mapper.hint_pose(pose, odometry)
    }

    /// The path drawn on the map's picture (map frame), oldest first.
    pub fn picture_path(&self) -> impl ExactSizeIterator<Item = &Pose2> + '_ {
        self.picture_path.iter()
    }

    /// The robot's pose (map frame) now: the last scan's pose moved on by
    /// the odometry since it, when there is odometry for both times.
    pub fn pose_now(&self) -> Option<Pose2> {
        let (_, pose, odo_then) = self.last_fix?;
        let newest = self.odometry.last_time().and_then(|t| self.odometry.at(t));
        match (odo_then, newest) {
            (Some(a), Some(b)) => Some(pose.compose(&a.between(&b))),
            _ => Some(pose),
        }
    }

    /// The exploration command at `now` (s): zero without an explorer or a
    /// pose, and what the explorer reported, if anything.
    pub fn control(&mut self, now: f64) -> (Twist, Option<ExplorerEvent>) {
        let started = std::time::Instant::now();
        let Some(pose) = self.pose_now() else {
            return (Twist::ZERO, None);
        };
        let Some(explorer) = self.explorer.as_mut() else {
            return (Twist::ZERO, None);
        };
        let mut result = explorer.control(self.mapper.cls_map(), pose, now);
        if matches!(result.1, Some(ExplorerEvent::Complete { .. })) && !self.mapper.is_settled() {
            // Completion is judged on the map as it will be saved: the
            // loops not optimised in yet may open a frontier. (A job in
            // flight is done again here, on the loop: the robot stands.)
            info!("exploration: frontiers closed; the map takes in its last loops first");
            self.settle();
            if let Some(explorer) = self.explorer.as_mut() {
                explorer.reconsider(now);
            }
            result = (Twist::ZERO, None);
        }
        self.latencies.record(Stage::Control, started.elapsed());
        if let Some(event) = &result.1 {
            log_event(event);
        }
        result
    }

    /// The base is held at `now` (s) instead of driven; exploration's
    /// clock for the current goal stops meanwhile.
    pub fn hold_exploration(&mut self, now: f64) {
        if let Some(ex) = self.explorer.as_mut() {
            ex.hold(now);
        }
    }

    pub fn exploration_complete(&self) -> bool {
        self.explorer.as_ref().is_some_and(|e| e.is_complete())
    }

    pub fn status(&self) -> LiveStatus {
        let cls = self.mapper.cls_map();
        LiveStatus {
            scans: self.scans,
            localized: self.localized,
            keyframes: self.mapper.summary().keyframes,
            graph_keyframes: self.mapper.keyframe_graph().len(),
            loops_closed: self.mapper.keyframe_graph().stats().accepted,
            walls: cls.actual_segments().count(),
            frontiers: cls.virtual_segments().count(),
            loops: cls.loops().count(),
            pose: self.pose_now(),
            exploring: self.explorer.as_ref().is_some_and(|e| !e.is_complete()),
            exploration_complete: self.exploration_complete(),
            explorer: self.explorer.as_ref().map(|e| e.stats()),
            map_search: self.mapper.map_search(),
        }
    }

    /// A snapshot for a checkpoint into `dir`: the poses since the last
    /// one (the mapper forgets them, so memory stays bounded however long
    /// the daemon runs; the newest few wait while their keyframe may still
    /// be merged away), the maps and the picture's path. Localizing in a
    /// loaded map, which does not change, it holds the poses only.
    pub fn begin_checkpoint(&mut self, dir: &Path) -> Checkpoint {
        let with_map = self.mapper.map_mode() != Some(MapMode::Localize);
        let poses = self.mapper.take_settled_trajectory();
        self.snapshot(dir, poses, with_map)
    }

    fn snapshot(&mut self, dir: &Path, poses: Vec<AnchoredPose>, with_map: bool) -> Checkpoint {
        let mut trajectory = std::mem::take(&mut self.unwritten);
        trajectory.extend(poses);
        let reframes = self.mapper.reframes();
        let reframed = self.reframes_written != Some(reframes);
        self.reframes_written = Some(reframes);
        Checkpoint {
            dir: dir.to_owned(),
            trajectory,
            keyframe_poses: self.mapper.keyframe_graph().poses().to_vec(),
            reframed,
            map: with_map.then(|| self.mapper.contents()),
            path: self.picture_path.iter().copied().collect(),
        }
    }

    /// Takes back the poses of a checkpoint that failed, to be written
    /// with the next one.
    pub fn checkpoint_failed(&mut self, failed: CheckpointFailed) -> PipelineError {
        let mut poses = failed.trajectory;
        poses.append(&mut self.unwritten);
        self.unwritten = poses;
        self.reframes_written = None;
        failed.error
    }

    /// Writes a checkpoint into `dir` now, the map included whatever the
    /// mode (the last save, so a run's directory holds the map it ended
    /// with; see [`Checkpoint::write`]).
    pub fn checkpoint(&mut self, dir: &Path) -> Result<(), PipelineError> {
        let _span = info_span!("checkpoint").entered();
        let poses = self.mapper.take_trajectory();
        self.snapshot(dir, poses, true)
            .write()
            .map_err(|failed| self.checkpoint_failed(failed))
    }

    /// Starts exploring (from `now`, s) or stops; a running explorer is
    /// retuned, keeping its memory of frontiers and its goal.
    pub fn set_exploration(
        &mut self,
        exploration: Option<(ExplorationConfig, DriveConfig)>,
        now: f64,
    ) {
        match (self.explorer.as_mut(), exploration) {
            (Some(ex), Some((planner, drive))) => ex.retune(planner, drive),
            (None, Some((planner, drive))) => {
                info!("exploration on");
                self.explorer = Some(Explorer::new(planner, drive, now));
            }
            (Some(_), None) => {
                info!("exploration off");
                self.explorer = None;
            }
            (None, None) => {}
        }
    }
}

fn log_event(event: &ExplorerEvent) {
    match event {
        ExplorerEvent::Goal {
            goal, path_length, ..
        } => info!(
            x = goal.x,
            y = goal.y,
            path_m = path_length,
            "exploration: new goal in front of a frontier"
        ),
        ExplorerEvent::Arrived { .. } => info!("exploration: goal reached"),
        ExplorerEvent::TimedOut { .. } => warn!("exploration: goal not reached in time, abandoned"),
        ExplorerEvent::PlanFailed { reason } => warn!("exploration: no step planned: {reason}"),
        ExplorerEvent::Complete { given_up } => info!(
            given_up,
            "exploration complete: no frontier worth pursuing is left"
        ),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn odometry_is_interpolated_and_briefly_extrapolated() {
        let mut live = LiveMapper::new(MapperConfig::default(), None, 0.0);
        assert!(live.odometry_at(0.0).is_none());
        for k in 0..=10 {
            let t = k as f64 * 0.02;
            assert!(live.on_odometry(t, Pose2::new(t * 0.5, 0.0, 0.0)));
        }
        assert!(!live.on_odometry(0.1, Pose2::IDENTITY), "out of order");
        let mid = live.odometry_at(0.11).unwrap();
        assert!((mid.x - 0.055).abs() < 1e-12);
        let ahead = live.odometry_at(0.25).unwrap();
        assert!((ahead.x - 0.125).abs() < 1e-9, "{ahead:?}");
        assert!(live.odometry_at(0.35).is_none(), "too far ahead");
        // A restarted base: nothing from before is blended with what comes.
        live.odometry_restarted();
        assert!(live.odometry_at(0.2).is_none());
        assert!(
            live.on_odometry(0.1, Pose2::IDENTITY),
            "a new frame, a new clock start"
        );
    }

    #[test]
    fn checkpoints_append_the_trajectory_and_keep_memory_bounded() {
        use crate::sim::{Rng, ScanSpec, World, cast_scan};
        let world = World::loop_around_block();
        let mut rng = Rng::new(3);
        let mut live = LiveMapper::new(MapperConfig::default(), None, 0.0);
        let dir = std::env::temp_dir().join(format!("clsmap-live-ckpt-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let mut k = 0;
        for round in 0..2 {
            for _ in 0..10 {
                let t = k as f64 * 0.1;
                let pose = Pose2::new(1.0 + 0.05 * k as f64, 1.0, 0.0);
                live.on_odometry(t, pose);
                let scan = cast_scan(
                    &world,
                    &pose,
                    &ScanSpec::lms200_half_degree(0.01),
                    t,
                    &mut rng,
                );
                live.on_scan(scan, Some(Duration::from_micros(300)));
                k += 1;
            }
            live.checkpoint(&dir).unwrap();
            assert!(live.mapper().trajectory().is_empty(), "round {round}");
        }
        let text = std::fs::read_to_string(dir.join(crate::pipeline::TRAJECTORY_FILE)).unwrap();
        assert_eq!(text.lines().filter(|l| l.starts_with('#')).count(), 1);
        assert_eq!(text.lines().filter(|l| !l.starts_with('#')).count(), 20);
        let map = crate::map::cls::ClsMap::load(
            &dir.join(crate::pipeline::MAP_FILE),
            crate::map::cls::ClsMapConfig::default(),
        )
        .unwrap();
        assert!(map.actual_segments().count() > 2);
        assert!(live.latencies().summary(Stage::Pose).is_some());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn without_a_scan_there_is_no_pose_and_no_motion() {
        let mut live = LiveMapper::new(
            MapperConfig::default(),
            Some((ExplorationConfig::default(), DriveConfig::default())),
            0.0,
        );
        assert_eq!(live.pose_now(), None);
        assert_eq!(live.control(1.0), (Twist::ZERO, None));
        let s = live.status();
        assert_eq!((s.scans, s.walls), (0, 0));
        assert!(s.exploring && !s.exploration_complete);
    }
}
