//! [`Mapper`]: one scan at a time — predict, extract, localize, and on
//! keyframes grow the maps and the keyframe graph. The offline run and
//! the live daemon both feed it.

use std::cell::OnceCell;
use std::f64::consts::PI;
use std::time::Instant;

use nalgebra::{Matrix3, Vector3};
use tracing::{debug, trace_span, warn};

use super::jambs::JambTracks;
use super::offline::SKIPPED_EXAMPLES;
use super::prediction::{Estimate, MotionPredictor, OdometryFeed, OdometryReading, compose};
use super::rejection::{Rejection, RejectionKind};
use super::smoothing;
use super::start::{HINT_COVARIANCE, MapMode, StartSearch};
use super::summary::{LastScanTimes, MappingSummary, StageClocks};
use super::{MapSearch, PipelineError, ScanOutcome};
use crate::files::trajectory::{AnchoredPose, StampedPose};
use crate::geometry::scan_match::{self, ScanPoints};
use crate::geometry::{
    CogLine, ExtractionConfig, LineExtractor, Pose2, RangeScan, SegmentIndex, wrap_angle,
};
use crate::graph::{
    AppliedOptimisation, Correction, KeyframeGraph, LoopSearchJob, LoopSearchResult,
    OptimisationJob, OptimisationResult,
};
use crate::input::ScanRecord;
use crate::localize::global::{FreeSpace, GlobalConfig};
use crate::localize::local::{rotation_limit, translation_limit};
use crate::localize::{LocalizationResult, LocalizeError, localize, localize_searching_heading};
use crate::map::cls::{ClsError, ClsMap, local_region};
use crate::map::{Keyframe, KeyframePolicy, MapContents, SegmentMap};
use crate::pipeline::config::MapperConfig;

/// Mahalanobis distance (in σ) of `pose` from `predicted` under the
/// prediction covariance `cov` (x, y, θ); infinite if `cov` is singular.
fn mahalanobis(pose: &Pose2, predicted: &Pose2, cov: &[[f64; 3]; 3]) -> f64 {
    let e = Vector3::new(
        pose.x - predicted.x,
        pose.y - predicted.y,
        wrap_angle(pose.theta - predicted.theta),
    );
    let m = Matrix3::from_fn(|i, j| cov[i][j]);
    match m.cholesky() {
        Some(chol) => e.dot(&chol.solve(&e)).max(0.0).sqrt(),
        None => f64::INFINITY,
    }
}

/// Most lines a fix may rest on and still count as resting on few
/// (see [`turn_on_few_lines`]): two or three lines are matched wrongly,
/// or to walls mapped at a wrong heading, far oftener than four.
const FEW_LINES: usize = 3;
/// A fix whose heading σ is below this share of the prediction's rests
/// on lines that fix the heading themselves, and stands: CSAIL's odometry
/// lags in turns, and such fixes turned its thinned log, driven backwards,
/// 11–14° (3–4 σ) where the robot did turn (refused, 0.09 → 4.2 m).
const LINES_FIX_THE_HEADING: f64 = 0.5;
/// A refused turn asked for again within this much (rad) is the
/// odometry's error, not the lines': the scan after a refusal predicts
/// from the same odometry and, if the odometry is what is wrong, asks for
/// about the same correction (Killian Court: 4.4–4.9° five scans running).
const SAME_TURN: f64 = 2.0 * PI / 180.0;

/// Refuses a fix from at most [`FEW_LINES`] matched lines that turns the
/// heading by more than `gate` σ of the prediction's heading, while the
/// lines leave its heading about as uncertain as the prediction's (see
/// [`LINES_FIX_THE_HEADING`]); `None` when it stands. Unless
/// `asked_before`, the turn (rad) refused on the last fix, was about the
/// same. Between sparse scans with good odometry (the Infinite
/// Corridor's with its corrected steps as odometry, 1 m apart) two lines
/// along a corridor turned single scans 6–7° (4–5 σ) while hardly
/// narrowing the heading's σ, and the walls mapped from them carried the
/// error on: 0.37 m of relation error where 0.05 m is the log's floor.
fn turn_on_few_lines(
    fix: &LocalizationResult,
    predicted: &Pose2,
    cov: &[[f64; 3]; 3],
    gate: f64,
    asked_before: Option<f64>,
) -> Option<Rejection> {
    let turn = wrap_angle(fix.pose.theta - predicted.theta);
    let sigmas = turn.abs() / cov[2][2].sqrt();
    let again = asked_before.is_some_and(|before| (turn - before).abs() <= SAME_TURN);
    let lines_fix_it =
        fix.covariance[2][2] < (LINES_FIX_THE_HEADING * LINES_FIX_THE_HEADING) * cov[2][2];
    (gate > 0.0 && fix.matches.len() <= FEW_LINES && sigmas > gate && !again && !lines_fix_it)
        .then_some(Rejection::TurnOnFewLines { turn, sigmas })
}

/// The mapper's state between scans.
#[derive(Debug)]
pub struct Mapper {
    config: MapperConfig,
    extractor: LineExtractor,
    /// The jambs in view, followed from scan to scan.
    jamb_tracks: JambTracks,
    lines: Vec<CogLine>,
    map: SegmentMap,
    cls: ClsMap,
    keyframes: KeyframePolicy,
    odometry: OdometryFeed,
    predictor: MotionPredictor,
    /// The previous scan's lines in the map frame, the fallback reference
    /// when the map offers too little to localize against.
    previous_scan: SegmentIndex,
    /// The last scan's points and where it was taken, for the step to the
    /// next and for localizing the next against it.
    last_scan: Option<LastScan>,
    trajectory: Vec<StampedPose>,
    /// Per trajectory entry, the motion from the entry before, measured by
    /// matching the two scans' points (`None` where they were not).
    steps: Vec<Option<Pose2>>,
    /// Per trajectory entry: the keyframe it was taken after and its pose
    /// in that keyframe's frame, so loop closures can move it with them.
    anchors: Vec<Option<(usize, Pose2)>>,
    /// The keyframes and their pose graph, from which the maps are rebuilt
    /// after a loop closure.
    graph: KeyframeGraph,
    /// Whether a rebuild of the CLS map after a loop closure waits for
    /// [`Mapper::refresh_cls_map`] (offline runs, which need it
    /// only at the end), and whether one is waiting.
    defer_cls_rebuild: bool,
    /// Whether each scan's points are matched against the last scan's
    /// (see [`measure_scan_steps`](Self::measure_scan_steps)).
    measure_steps: bool,
    cls_stale: bool,
    /// The kept keyframe the latest keyframe was merged into, if it was:
    /// the anchor of the scans after it until a keyframe is kept.
    anchor_keyframe: Option<usize>,
    /// Whether the previous scan's fix was refused as an implausible jump.
    previous_refused_jump: bool,
    /// The heading turn (rad) the last fix asked for, if it was refused
    /// as a turn on few lines ([`turn_on_few_lines`]).
    refused_turn: Option<f64>,
    /// Scans in a row local localization failed on.
    unlocalized_run: usize,
    /// A loaded map's mode, the search for the start pose in it, the pose
    /// found (for the next scan's prediction), and whether the session's
    /// first keyframe is still to come.
    mode: Option<MapMode>,
    start: Option<StartSearch>,
    seed: Option<(Pose2, [[f64; 3]; 3])>,
    first_session_keyframe: bool,
    /// Whether the newest keyframe is the session's first (merged as a
    /// revisit after its background loop search, the next kept one is).
    newest_is_session_start: bool,
    /// Scans in a row not localized against the loaded map, and the search
    /// that runs once there are [`LOST_AFTER_SCANS`].
    lost_scans: usize,
    relocalizer: Option<StartSearch>,
    /// The free space of the loaded map, against which each fix is checked
    /// (see [`MAX_AGAINST_LOADED_MAP`]); empty without a loaded map.
    loaded_free: FreeSpace,
    /// A pose hint restarted the search (see [`Self::hint_pose`]).
    hinted: bool,
    /// The last scan's pose covariance (x, y, θ; m², m·rad, rad²).
    last_covariance: [[f64; 3]; 3],
    /// Loop closures that moved the keyframes so far.
    reframes: u64,
    pub(super) summary: MappingSummary,
    clocks: StageClocks,
}

/// Scans in a row without a fix against a loaded map after which the
/// robot is taken as lost and looked for again (about a second of scans at
/// a walking pace's keyframe spacing; a few scans of a featureless stretch
/// are normal).
const LOST_AFTER_SCANS: usize = 5;
/// While lost, global localization runs on every this many scans.
const RELOCALIZE_EVERY_SCANS: usize = 5;
/// A fix that puts more than this length (m) of the scan's walls in the
/// loaded map's explored free space, away from its boundary and from
/// every map wall, is not taken: the robot is not where it is thought.
const MAX_AGAINST_LOADED_MAP: f64 = 1.0;
/// Consecutive scans farther apart than this in time (s), distance (m) or
/// turn (rad) are not matched point to point: too little of one falls
/// near the other's points.
const MAX_MATCH_GAP: f64 = 1.0;
const MAX_MATCH_STEP: f64 = 0.5;
const MAX_MATCH_TURN: f64 = 0.35;
/// Whether a robot step is short enough for two scans' points to pair up.
fn within_match_reach(step: &Pose2) -> bool {
    step.x.hypot(step.y) <= MAX_MATCH_STEP && step.theta.abs() <= MAX_MATCH_TURN
}
/// The scans' step overrules the odometry's only when at least this share
/// of the scan's points pairs with the last scan's surfaces: scans of
/// CSAIL thinned to 0.3 m or 0.3 rad apart that paired fewer were matched
/// up to 20° and 0.3 m off.
const CHECK_MIN_SHARE: f64 = 0.5;
/// Nor does it overrule a step that differs from the odometry's by less
/// than this share of the localizer's correspondence gates (0.075 m and
/// 2.5° by default), which the lines' matches reach and correct: the
/// Intel lab's odometry, a few degrees behind in its turns, was overruled
/// 275 times at no gain, ACES's jittered stamps 54 times (one start of
/// six then lost a loop), while Freiburg 079's backward steps are off by
/// 0.1–0.2 m (half of those it overruled at 5 σ).
const CHECK_LINE_REACH: f64 = 0.5;
/// A step measured before localization stands for the step to the
/// localized pose when the two differ by no more than this (m, rad): well
/// inside the point match's reach, it would find the same step again.
const SAME_STEP: (f64, f64) = (0.05, 0.02);
/// A scan whose lines found too little to localize is matched point to
/// point against the last scan when that one was localized at most this
/// long before (s): sparse logs keep a scan per second or so.
const MAX_FALLBACK_GAP: f64 = 2.0;
/// The headings the point match starts from around the prediction's are
/// this far apart (rad), within the localizer's rotation limit: each start
/// brings in headings within about half of it (the match refines by at
/// most 0.1 rad).
const FALLBACK_HEADING_STEP: f64 = 0.1;
/// A point match sets the heading when at least this share of the scan's
/// points pairs with the last scan's surfaces (scans 0.8 m and 12° apart
/// shared 42 %), and no match from a start elsewhere pairs nearly as many
/// (this share of the best's).
const FALLBACK_MIN_SHARE: f64 = 0.3;
const FALLBACK_RIVAL_SHARE: f64 = 0.8;
/// σ of a point-matched step (m, rad) where the scans are a fast turn
/// apart: a centimetre and 0.6°, looser than between consecutive dense
/// scans (see [`smoothing`]).
const FALLBACK_STEP_SIGMA: (f64, f64) = (0.01, 0.01);
/// The lines' fix from the point-matched pose is taken only when it stays
/// this close to it (m, rad): two witnesses, each of which alone was seen
/// to mislead (points matched 25° off in a thinned log, two lines 16° off
/// in another).
const FALLBACK_AGREEMENT: (f64, f64) = (0.1, 0.035);

/// A scan and its points, worked out when first asked for: the daemon,
/// which matches no steps, needs them only for a scan its lines failed on
/// and the one before it.
#[derive(Debug)]
struct ScanWithPoints {
    scan: RangeScan,
    points: OnceCell<ScanPoints>,
}

impl ScanWithPoints {
    fn new(scan: RangeScan) -> Self {
        ScanWithPoints {
            scan,
            points: OnceCell::new(),
        }
    }

    /// The points within `range`'s limits.
    fn points(&self, range: &ExtractionConfig) -> &ScanPoints {
        self.points
            .get_or_init(|| ScanPoints::new(&self.scan, range.min_range, range.max_range))
    }
}

/// The last scan's points and where it was taken.
#[derive(Debug)]
struct LastScan {
    points: ScanWithPoints,
    pose: Pose2,
    t: f64,
    /// Whether the pose was localized (a reference for the next scan).
    localized: bool,
}

impl Mapper {
    pub fn new(config: MapperConfig) -> Self {
        Mapper {
            config,
            extractor: LineExtractor::new(),
            jamb_tracks: JambTracks::default(),
            lines: Vec::new(),
            map: SegmentMap::new(config.map),
            cls: ClsMap::new(config.cls_map()),
            keyframes: KeyframePolicy::new(config.keyframes),
            odometry: OdometryFeed::new(config.odometry_time_offset).learning(config.max_scan_lag),
            predictor: MotionPredictor::default(),
            previous_scan: SegmentIndex::new(),
            last_scan: None,
            trajectory: Vec::new(),
            steps: Vec::new(),
            anchors: Vec::new(),
            graph: KeyframeGraph::new(),
            defer_cls_rebuild: false,
            measure_steps: false,
            cls_stale: false,
            anchor_keyframe: None,
            previous_refused_jump: false,
            refused_turn: None,
            unlocalized_run: 0,
            mode: None,
            start: None,
            seed: None,
            first_session_keyframe: false,
            newest_is_session_start: false,
            lost_scans: 0,
            relocalizer: None,
            loaded_free: FreeSpace::default(),
            hinted: false,
            last_covariance: [[0.0; 3]; 3],
            reframes: 0,
            summary: MappingSummary::default(),
            clocks: StageClocks::default(),
        }
    }

    /// A mapper that goes on from a saved map (see [`crate::map::file`]):
    /// the first scans find the robot in it ([`StartSearch`]); then it
    /// localizes against the map's walls, and in [`MapMode::Extend`] adds
    /// keyframes to the map's graph and closes loops against it. A map
    /// without keyframes (version 1) can be localized in, not extended.
    pub fn from_map(
        config: MapperConfig,
        contents: MapContents,
        mode: MapMode,
    ) -> Result<Self, PipelineError> {
        let mut mapper = Mapper::new(config);
        let walls: Vec<CogLine> = if contents.walls.is_empty() {
            contents.cls.actual_segments().map(|s| s.line).collect()
        } else {
            contents.walls.iter().map(|w| w.line).collect()
        };
        if walls.is_empty() {
            return Err(PipelineError::StartMap("the map has no walls".into()));
        }
        mapper.map = if contents.walls.is_empty() {
            let mut map = SegmentMap::new(config.map);
            map.insert_walls(&walls);
            map
        } else {
            SegmentMap::from_walls(config.map, &contents.walls)
                .ok_or_else(|| PipelineError::StartMap("the map repeats a wall id".into()))?
        };
        if mode == MapMode::Extend && contents.keyframes.is_empty() {
            return Err(PipelineError::StartMap(
                "the map holds no keyframes (a version 1 file): it can be localized in, not extended".into(),
            ));
        }
        // Loaded in either mode, so the map written at the end is the map
        // loaded (and, extended, more).
        mapper.graph =
            KeyframeGraph::from_parts(contents.keyframes, contents.poses, contents.edges)
                .map_err(|e| PipelineError::StartMap(e.to_string()))?;
        mapper.first_session_keyframe = mode == MapMode::Extend;
        mapper.cls = contents.cls.with_config(config.cls_map());
        mapper.loaded_free = FreeSpace::new(&mapper.cls);
        mapper.start =
            Some(StartSearch::new(walls, GlobalConfig::default()).with_free_space(&mapper.cls));
        mapper.mode = Some(mode);
        Ok(mapper)
    }

    pub fn config(&self) -> &MapperConfig {
        &self.config
    }

    /// Length (m) of this scan's lines that `pose` puts in the loaded map's
    /// explored free space, away from its walls (0 without a loaded map).
    fn against_loaded_map(&self, pose: &Pose2) -> f64 {
        if self.loaded_free.is_empty() {
            return 0.0;
        }
        let seen = self.lines.iter().map(|l| l.transformed(pose));
        self.loaded_free.length_inside(
            seen,
            GlobalConfig::default().free_space_tolerance,
            self.map.index(),
        )
    }

    pub fn map(&self) -> &SegmentMap {
        &self.map
    }

    /// The last scan's pose covariance (x, y, θ; m², m·rad, rad²).
    pub fn last_covariance(&self) -> [[f64; 3]; 3] {
        self.last_covariance
    }

    /// The Closed Line Segment map grown so far (with its rebuild deferred,
    /// see [`defer_cls_rebuild`](Self::defer_cls_rebuild), empty or out of
    /// date until [`settle`](Self::settle)).
    pub fn cls_map(&self) -> &ClsMap {
        &self.cls
    }

    /// The keyframes and their pose graph.
    pub fn keyframe_graph(&self) -> &KeyframeGraph {
        &self.graph
    }

    /// The loop edges of the pose graph as lines between their keyframes'
    /// positions (map frame), for a picture.
    pub fn loop_edges(&self) -> Vec<[[f64; 2]; 2]> {
        let poses = self.graph.poses();
        self.graph
            .graph()
            .loop_edges()
            .map(|e| {
                let (a, b) = (poses[e.from], poses[e.to]);
                [[a.x, a.y], [b.x, b.y]]
            })
            .collect()
    }

    /// Match each scan's points against the last scan's, for
    /// [`smoothed_trajectory`](Self::smoothed_trajectory): for a run that
    /// keeps its whole trajectory (an offline one), some 70 µs per scan.
    pub fn measure_scan_steps(&mut self) {
        self.measure_steps = true;
    }

    /// Grow the CLS map only when [`refresh_cls_map`](Self::refresh_cls_map)
    /// asks (an offline run needs it once, at the end), from the keyframes
    /// at their final poses; meanwhile keyframes do not grow it.
    pub fn defer_cls_rebuild(&mut self) {
        self.defer_cls_rebuild = true;
        // Built once from the keyframes at the end, since it is the same
        // map the incremental updates would give for the same poses; a CLS
        // map loaded without keyframes (version 1) is kept as it is.
        self.cls_stale = !self.graph.is_empty() || self.cls.is_empty();
    }

    /// Optimises the pose graph now if loops came in since its last
    /// optimisation (superseding a background job in flight) and brings
    /// the trajectory and both maps up to date; the newest keyframe's
    /// correction when the poses moved. The end of a run calls it last.
    pub fn settle(&mut self) -> Option<Pose2> {
        self.search_now();
        let moved = match self.graph.settle(&self.config.loop_closure) {
            Ok(Some(c)) => {
                self.apply_correction(&c);
                Some(c.correction)
            }
            Ok(None) => None,
            Err(e) => {
                warn!("pose graph not optimised: {e}");
                None
            }
        };
        self.refresh_cls_map();
        moved
    }

    /// Whether the map is up to date with every loop closed so far
    /// ([`settle`](Self::settle) would change nothing).
    pub fn is_settled(&self) -> bool {
        self.graph.is_settled() && !self.graph.loop_search_pending() && !self.cls_stale
    }

    /// Rebuilds the walls and the CLS map from the keyframes if a loop
    /// closure moved them since the CLS map was grown (or it waits for its
    /// one build at the end of a run): the CLS map's wall pieces name the
    /// walls they lie on, so both come from one pass.
    pub fn refresh_cls_map(&mut self) {
        if self.cls_stale {
            let (walls, cls, refused) = self
                .graph
                .rebuild_maps(self.config.map, self.config.cls_map());
            // No keyframes, no walls from them: keep what was loaded.
            if !self.graph.is_empty() {
                self.map = walls;
            }
            self.cls = cls;
            self.summary.cls_rejected = refused;
            self.cls_stale = false;
        }
    }

    /// What the map is made of, as [`super::MAP_FILE`] stores it: the CLS map,
    /// the walls, and the keyframes (shared, not copied) with their poses
    /// and the pose graph's edges.
    pub fn contents(&self) -> MapContents {
        let mut cls = self.cls.clone();
        cls.resolve_walls(&self.map);
        MapContents {
            cls,
            walls: self.map.segments().collect(),
            keyframes: self.graph.keyframes().to_vec(),
            poses: self.graph.poses().to_vec(),
            edges: self.graph.graph().edges().to_vec(),
        }
    }

    /// How many times loop closures moved the keyframes (and the poses
    /// anchored to them) so far.
    pub fn reframes(&self) -> u64 {
        self.reframes
    }

    /// One pose per scan processed so far (s, map frame).
    pub fn trajectory(&self) -> &[StampedPose] {
        &self.trajectory
    }

    /// Counters and mean stage times so far.
    pub fn summary(&self) -> MappingSummary {
        let mut s = self.summary.clone();
        s.segments = self.map.len();
        s.cls_actual = self.cls.actual_segments().count();
        s.cls_virtual = self.cls.virtual_segments().count();
        s.cls_loops = self.cls.loops().count();
        s.loops = self.graph.stats().clone();
        s.odometry_heading_scale = self.predictor.heading_scale(&self.config.odometry);
        s.odometry_scale = self.predictor.odometry_scale(&self.config.odometry);
        s.odometry_heading_drift = self.predictor.odometry_heading_drift(&self.config.odometry);
        s.odometry_time_offset = self.odometry.offset();
        s.mean_time = self.clocks.means();
        s
    }

    /// Takes the parts of `config` that can change while mapping: line
    /// extraction, localization, keyframes, odometry noise and the
    /// correction gates. The laser mounting, the fusion gates, the CLS map
    /// and the odometry time offset (and its learning) shape what is
    /// already in the map or in flight; they are kept, and their names
    /// returned when `config` would change them (they need a restart).
    pub fn retune(&mut self, config: MapperConfig) -> Vec<&'static str> {
        let mut kept = Vec::new();
        let old = self.config;
        if config.laser_mount != old.laser_mount {
            kept.push("laser_mount");
        }
        if config.map != old.map {
            kept.push("map");
        }
        if config.cls != old.cls {
            kept.push("cls");
        }
        if config.odometry_time_offset != old.odometry_time_offset {
            kept.push("odometry_time_offset");
        }
        if config.max_scan_lag != old.max_scan_lag {
            kept.push("max_scan_lag");
        }
        self.config = MapperConfig {
            laser_mount: old.laser_mount,
            map: old.map,
            cls: old.cls,
            odometry_time_offset: old.odometry_time_offset,
            max_scan_lag: old.max_scan_lag,
            ..config
        };
        self.keyframes.retune(config.keyframes);
        // Its points were taken within the old range limits.
        if config.extraction != old.extraction {
            self.last_scan = None;
        }
        kept
    }

    /// Odometry from a live base: a sample equal to the previous one is the
    /// robot standing still, not frozen odometry as in logs (see
    /// [`OdometryFeed`]). Without this a robot resting for a few seconds
    /// gets a prediction as uncertain as if it had no odometry at all.
    pub fn trust_unchanged_odometry(&mut self) {
        self.odometry.trust_unchanged(true);
    }

    /// The odometry starts over in a new frame (a base reconnected after a
    /// restart): samples from before are not compared with those after.
    pub fn odometry_restarted(&mut self) {
        self.odometry.restart();
        self.predictor.forget_odometry();
        self.jamb_tracks.forget();
    }

    /// Hands over the poses recorded so far, anchored to their keyframes,
    /// and forgets them, so a mapper that runs for days keeps its memory
    /// bounded (the daemon appends them to its trajectory files at each
    /// checkpoint, and rebuilds the TUM file from the anchors when a loop
    /// closure moves the keyframes). The end of a run takes them all.
    pub fn take_trajectory(&mut self) -> Vec<AnchoredPose> {
        self.take_trajectory_before(self.trajectory.len())
    }

    /// [`take_trajectory`](Self::take_trajectory) while mapping goes on:
    /// the poses anchored to the newest keyframe stay (with those after
    /// them) while its loop search may still merge it into an older one,
    /// since its index then goes to the next keyframe kept.
    pub fn take_settled_trajectory(&mut self) -> Vec<AnchoredPose> {
        let newest = self.graph.len().checked_sub(1);
        let settled = match newest {
            Some(newest) if self.graph.loop_search_pending() => self
                .anchors
                .iter()
                .position(|a| a.is_some_and(|(k, _)| k == newest))
                .unwrap_or(self.anchors.len()),
            _ => self.trajectory.len(),
        };
        self.take_trajectory_before(settled)
    }

    /// The trajectory smoothed by the steps measured between consecutive
    /// scans (see [`crate::pipeline::smoothing`]); the trajectory as
    /// localized unless [`measure_scan_steps`](Self::measure_scan_steps)
    /// was asked for.
    pub fn smoothed_trajectory(&self) -> Vec<StampedPose> {
        smoothing::smooth(&self.trajectory, &self.steps)
    }

    /// The motion from the last scan to this one (the robot's step, in
    /// the last scan's robot frame) from their points, matched from each
    /// step in `starts`: of the alignments that constrain every direction,
    /// the one that pairs the most points. `None` when the scans lie too
    /// far apart in time, or every start too far in place, for their
    /// points to pair up.
    fn measure_step(
        &self,
        current: &ScanWithPoints,
        t: f64,
        starts: &[Pose2],
    ) -> Option<scan_match::Alignment> {
        let last = self
            .last_scan
            .as_ref()
            .filter(|last| t - last.t <= MAX_MATCH_GAP)?;
        let range = &self.config.extraction;
        let (reference, points) = (last.points.points(range), current.points(range));
        starts
            .iter()
            .filter(|m| within_match_reach(m))
            .filter_map(|m| self.align_with_last(reference, points, m))
            .filter(|a| a.open.is_none())
            .max_by_key(|a| a.pairs)
    }

    /// The motion from the last scan to this one at `pose`, from their
    /// points: the step measured before localization when `pose` lies
    /// well inside its reach, else measured afresh from `pose`.
    fn match_last_scan(
        &self,
        current: &ScanWithPoints,
        t: f64,
        pose: &Pose2,
        measured: Option<Pose2>,
    ) -> Option<Pose2> {
        let moved = self.last_scan.as_ref()?.pose.between(pose);
        if let Some(step) = measured {
            let (offset, turn) = SAME_STEP;
            let d = step.between(&moved);
            if d.x.hypot(d.y) <= offset && d.theta.abs() <= turn {
                return Some(step);
            }
        }
        self.measure_step(current, t, &[moved]).map(|a| a.pose)
    }

    /// The predicted pose `predicted`, or where the scans' own step from
    /// the last scan puts the robot when that step lies more than
    /// `odometry_check_sigmas` of the prediction's uncertainty from it,
    /// beyond what the lines correct themselves ([`CHECK_LINE_REACH`]),
    /// with enough points paired ([`CHECK_MIN_SHARE`]); and the step
    /// measured, if any. The points are matched
    /// from the odometry's step and, when that finds no agreeing step,
    /// from the last scan's (constant velocity): a faulty odometry step
    /// may start the match beyond its reach.
    fn check_odometry(
        &mut self,
        current: &ScanWithPoints,
        t: f64,
        predicted: Pose2,
        predicted_cov: &[[f64; 3]; 3],
    ) -> (Pose2, Option<Pose2>) {
        let Some(last) = &self.last_scan else {
            return (predicted, None);
        };
        let from_last = last.pose;
        let odometry_step = from_last.between(&predicted);
        if !within_match_reach(&odometry_step) {
            return (predicted, None);
        }
        let gate = self.config.odometry_check_sigmas;
        let agrees = |a: &scan_match::Alignment| {
            mahalanobis(&from_last.compose(&a.pose), &predicted, predicted_cov) <= gate
        };
        let mut measured = self.measure_step(current, t, &[odometry_step]);
        if !measured.as_ref().is_some_and(agrees) {
            let previous = match self.trajectory.as_slice() {
                [.., (_, before), (_, last)] => Some(before.between(last)),
                _ => None,
            };
            let again = previous.and_then(|p| self.measure_step(current, t, &[p]));
            measured = [measured, again]
                .into_iter()
                .flatten()
                .max_by_key(|a| a.pairs);
        }
        // What the lines' own gates comfortably reach they correct
        // themselves; only a step off by more is overruled.
        let gates = &self.config.localizer.correspondence;
        let beyond_lines = |a: &scan_match::Alignment| {
            let d = odometry_step.between(&a.pose);
            d.x.hypot(d.y) > CHECK_LINE_REACH * gates.max_centre_distance
                || d.theta.abs() > CHECK_LINE_REACH * gates.max_angle_diff
        };
        let paired =
            |a: &scan_match::Alignment| a.pairs as f64 >= CHECK_MIN_SHARE * a.points as f64;
        match measured {
            Some(a) if !agrees(&a) && beyond_lines(&a) && paired(&a) => {
                self.summary.odometry_steps_overruled += 1;
                (from_last.compose(&a.pose), Some(a.pose))
            }
            other => (predicted, other.map(|a| a.pose)),
        }
    }

    /// [`scan_match::align`] of `current` against the last scan's
    /// `reference` from the robot's step `moved`; the alignment's pose is
    /// the robot's step, its open direction (if any) still in the last
    /// scan's sensor frame.
    fn align_with_last(
        &self,
        reference: &ScanPoints,
        current: &ScanPoints,
        moved: &Pose2,
    ) -> Option<scan_match::Alignment> {
        let mount = self.config.laser_mount;
        let start = mount.inverse().compose(moved).compose(&mount);
        let found = scan_match::align(reference, current, &start)?;
        Some(scan_match::Alignment {
            pose: mount.compose(&found.pose).compose(&mount.inverse()),
            ..found
        })
    }

    /// Localizes a scan whose lines found too little to match, neither
    /// the map's nor the last scan's: its `points` are matched against the
    /// last scan's (when that one was localized just before), from the
    /// predicted heading and from headings around it as far as the
    /// localizer's rotation limit, and the map's lines are then matched
    /// from the pose found. The point match must pair
    /// [`FALLBACK_MIN_SHARE`] of the points with no rival elsewhere, and
    /// the lines' fix must agree with it ([`FALLBACK_AGREEMENT`]). Where
    /// the points leave a direction open (a corridor's length), the pose
    /// along it is about the prediction's, and at least as uncertain.
    /// Odometry headings in a fast turn between sparse scans were seen 16°
    /// off, where only two lines matched at the right heading.
    fn localize_by_last_scan(
        &self,
        current: &ScanWithPoints,
        t: f64,
        predicted: Pose2,
        predicted_cov: &[[f64; 3]; 3],
    ) -> Option<LocalizationResult> {
        let last = self
            .last_scan
            .as_ref()
            .filter(|l| l.localized && (0.0..=MAX_FALLBACK_GAP).contains(&(t - l.t)))?;
        let cfg = &self.config.localizer;
        let limit = rotation_limit(predicted_cov, cfg);
        let range = &self.config.extraction;
        let (reference, points) = (last.points.points(range), current.points(range));
        let starts = (limit.min(PI) / FALLBACK_HEADING_STEP).floor() as i32;
        let mut found: Vec<scan_match::Alignment> = (-starts..=starts)
            .filter_map(|k| {
                let turned = Pose2::new(
                    predicted.x,
                    predicted.y,
                    predicted.theta + f64::from(k) * FALLBACK_HEADING_STEP,
                );
                self.align_with_last(reference, points, &last.pose.between(&turned))
            })
            .collect();
        found.sort_by_key(|a| std::cmp::Reverse(a.pairs));
        let best = *found.first()?;
        if (best.pairs as f64) < FALLBACK_MIN_SHARE * best.points as f64 {
            return None;
        }
        let rival = found.iter().skip(1).find(|a| {
            let d = best.pose.between(&a.pose);
            d.x.hypot(d.y) > 0.1 || d.theta.abs() > FALLBACK_HEADING_STEP
        });
        if rival.is_some_and(|r| r.pairs as f64 >= FALLBACK_RIVAL_SHARE * best.pairs as f64) {
            return None;
        }
        let (sx, st) = FALLBACK_STEP_SIGMA;
        let q = [
            [sx * sx, 0.0, 0.0],
            [0.0, sx * sx, 0.0],
            [0.0, 0.0, st * st],
        ];
        let (pose, mut covariance) = compose(&last.pose, &self.last_covariance, &best.pose, &q);
        if let Some(v) = best.open {
            // Along the direction the points leave open (a corridor's
            // length) the pose is about the prediction's, and at least as
            // uncertain.
            let (s, c) = (last.pose.theta + self.config.laser_mount.theta).sin_cos();
            let v = [c * v[0] - s * v[1], s * v[0] + c * v[1]];
            let variance_along = |m: &[[f64; 3]; 3]| {
                v[0] * (m[0][0] * v[0] + m[0][1] * v[1]) + v[1] * (m[1][0] * v[0] + m[1][1] * v[1])
            };
            let wider = (variance_along(predicted_cov) - variance_along(&covariance)).max(0.0);
            for (i, row) in covariance.iter_mut().take(2).enumerate() {
                for (j, value) in row.iter_mut().take(2).enumerate() {
                    *value += wider * v[i] * v[j];
                }
            }
        }
        let moved = (pose.x - predicted.x).hypot(pose.y - predicted.y);
        if moved > translation_limit(predicted_cov, cfg)
            || wrap_angle(pose.theta - predicted.theta).abs() > limit
        {
            return None;
        }
        let fix = localize(&self.lines, self.map.index(), pose, &covariance, cfg).ok()?;
        let agree = pose.between(&fix.pose);
        let (max_offset, max_turn) = FALLBACK_AGREEMENT;
        (agree.x.hypot(agree.y) <= max_offset && agree.theta.abs() <= max_turn).then_some(
            LocalizationResult {
                heading_searched: true,
                ..fix
            },
        )
    }

    /// The first `end` poses (the lists grow together, one entry per
    /// scan).
    fn take_trajectory_before(&mut self, end: usize) -> Vec<AnchoredPose> {
        let end = end.min(self.trajectory.len()).min(self.anchors.len());
        self.steps.drain(..end.min(self.steps.len()));
        self.trajectory
            .drain(..end)
            .zip(self.anchors.drain(..end))
            .map(|((t, pose), anchor)| match anchor {
                Some((k, relative)) => AnchoredPose {
                    t,
                    keyframe: Some(k),
                    pose: relative,
                },
                None => AnchoredPose {
                    t,
                    keyframe: None,
                    pose,
                },
            })
            .collect()
    }

    /// How long each stage took in the last scan processed.
    pub fn last_scan_times(&self) -> LastScanTimes {
        self.clocks.last()
    }

    /// Localizes the current lines against the map; when the map offers
    /// too few matches (curved walls cut into different chords by each
    /// scan, freshly entered space), against the previous scan's lines,
    /// which consecutive scans share far more reliably; when those are too
    /// few as well, from the heading the last scan's points give
    /// ([`Self::localize_by_last_scan`]).
    fn localize_with_fallback(
        &self,
        current: &ScanWithPoints,
        t: f64,
        predicted: Pose2,
        predicted_cov: &[[f64; 3]; 3],
        outcome: &mut ScanOutcome,
    ) -> Result<LocalizationResult, Rejection> {
        let cfg = &self.config.localizer;
        // Only a scan far from the last one (in time or motion) may take a
        // heading from the wide search: between scans close enough to
        // pair their points the odometry's heading cannot be 20° off, and
        // in a standstill of ACES (odometry unchanged, its prior widened)
        // the wide search turned a scan 30° off.
        let wide = self.last_scan.as_ref().is_none_or(|l| {
            t - l.t > MAX_MATCH_GAP || !within_match_reach(&l.pose.between(&predicted))
        });
        match localize_searching_heading(
            &self.lines,
            self.map.index(),
            predicted,
            predicted_cov,
            cfg,
            wide,
        ) {
            Err(LocalizeError::TooFewMatches { .. })
                if self.config.previous_scan_fallback && !self.previous_scan.is_empty() =>
            {
                match localize_searching_heading(
                    &self.lines,
                    &self.previous_scan,
                    predicted,
                    predicted_cov,
                    cfg,
                    wide,
                ) {
                    Ok(fix) => {
                        outcome.by_previous_scan = true;
                        Ok(fix)
                    }
                    // The last scan's points then set the heading the
                    // map's lines are matched from.
                    Err(e @ LocalizeError::TooFewMatches { .. }) => {
                        let fix = self
                            .localize_by_last_scan(current, t, predicted, predicted_cov)
                            .ok_or(Rejection::Localize(e));
                        outcome.by_last_scan_points = fix.is_ok();
                        fix
                    }
                    Err(e) => Err(Rejection::Localize(e)),
                }
            }
            // The previous scan's fix was refused as too large a jump too:
            // the lines keep asking for the same big correction, so the
            // odometry is what is wrong (a lagging heading in a fast turn
            // between sparse scans). Accepted at twice the limits, so one
            // odd scan still cannot move the pose that far.
            Err(LocalizeError::ImplausibleJump { .. }) if self.previous_refused_jump => {
                let wide = crate::localize::LocalizerConfig {
                    max_translation_jump: 2.0 * cfg.max_translation_jump,
                    max_rotation_jump: 2.0 * cfg.max_rotation_jump,
                    ..*cfg
                };
                localize(
                    &self.lines,
                    self.map.index(),
                    predicted,
                    predicted_cov,
                    &wide,
                )
                .map_err(Rejection::Localize)
            }
            other => other.map_err(Rejection::Localize),
        }
    }

    /// A loop closure moved the keyframes: the predictor, the keyframe
    /// policy and the trajectory follow them, and
    /// the maps are rebuilt from the keyframes at their new poses.
    fn apply_correction(&mut self, c: &Correction) {
        self.follow_correction(c);
        self.cls_stale = true;
        if self.defer_cls_rebuild {
            self.map = self.graph.rebuild_walls(self.config.map);
        } else {
            self.refresh_cls_map();
        }
    }

    /// The predictor, the keyframe policy and the trajectory follow the
    /// keyframes to their corrected poses.
    fn follow_correction(&mut self, c: &Correction) {
        self.reframes += 1;
        let poses = self.graph.poses();
        self.predictor.reframe(&c.correction);
        self.keyframes.reframe(&c.correction);
        if let Some(last) = &mut self.last_scan {
            last.pose = c.correction.compose(&last.pose);
        }
        for ((_, pose), anchor) in self.trajectory.iter_mut().zip(&self.anchors) {
            if let Some((k, relative)) = anchor {
                *pose = poses[*k].compose(relative);
            }
        }
    }

    /// Runs loop searches and pose-graph optimisations as jobs taken with
    /// [`take_loop_search`](Self::take_loop_search) and
    /// [`take_optimisation`](Self::take_optimisation) (to run off the
    /// real-time loop) instead of inside [`process`](Self::process).
    pub fn set_background_loop_closure(&mut self, on: bool) {
        self.graph.set_background_loop_closure(on);
    }

    /// The optimisation a closed loop asks for, if any and none is in
    /// flight; run it anywhere ([`OptimisationJob::run`]) and hand the
    /// result to [`apply_optimisation`](Self::apply_optimisation).
    pub fn take_optimisation(&mut self) -> Option<OptimisationJob> {
        self.graph.take_job(
            self.config.map,
            self.config.cls_map(),
            &self.config.loop_closure,
        )
    }

    /// The loop search the newest keyframe waits for (background mode),
    /// if none is in flight; run it anywhere ([`LoopSearchJob::run`]) and
    /// hand the result to [`apply_loop_search`](Self::apply_loop_search).
    pub fn take_loop_search(&mut self) -> Option<LoopSearchJob> {
        self.graph.take_loop_search(
            &self.config.map,
            &self.config.localizer,
            &GlobalConfig::default(),
            &self.config.loop_closure,
        )
    }

    /// A job taken with [`take_loop_search`](Self::take_loop_search) was
    /// lost (its thread failed).
    pub fn abandon_loop_search(&mut self) {
        self.graph.abandon_loop_search();
    }

    /// Takes in a loop search's result as a search inside
    /// [`process`](Self::process) would have been: a loop that moves the
    /// map asks for an optimisation (a job: searches are jobs only in
    /// background mode, where optimisations are too), and a loop at a place
    /// already kept merges the newest keyframe into it, re-anchoring the
    /// scans taken since on the kept one. Returns the map-frame correction
    /// of the newest keyframe if the poses moved (never in background
    /// mode, where the optimisation is a job of its own).
    pub fn apply_loop_search(&mut self, result: LoopSearchResult) -> Option<Pose2> {
        match self
            .graph
            .apply_loop_search(result, &self.config.loop_closure)
        {
            Ok(Some(c)) => {
                self.apply_correction(&c);
                return Some(c.correction);
            }
            Ok(None) => {}
            Err(e) => {
                warn!("pose graph not optimised: {e}");
                return None;
            }
        }
        let newest = self.graph.len().checked_sub(1)?;
        let newest_pose = self.graph.poses()[newest];
        let near = self.graph.merge_revisit(&self.config.loop_closure)?;
        let kept = self.graph.poses()[near];
        // Scans since the merged keyframe hang on it, or on nothing (a
        // resumed session's scans before its first keyframe); earlier ones
        // on earlier keyframes.
        for anchor in self.anchors.iter_mut().rev() {
            match anchor {
                Some((k, relative)) if *k == newest => {
                    *anchor = Some((near, kept.between(&newest_pose.compose(relative))));
                }
                None => {}
                Some(_) => break,
            }
        }
        self.anchor_keyframe = Some(near);
        self.first_session_keyframe |= self.newest_is_session_start;
        None
    }

    /// Runs the loop search the newest keyframe waits for, here and now
    /// (before the last optimisation of a run).
    fn search_now(&mut self) {
        if let Some(job) = self.take_loop_search() {
            self.apply_loop_search(job.run());
        }
    }

    /// A pose hint from outside: the robot is at `pose` (map frame) now,
    /// when the odometry reads `odometry`. In a loaded map the search for
    /// the robot starts again from it (scans have no pose until the hint is
    /// confirmed by local localization, or, failing that, by global
    /// localization); a new map refuses it, since its frame is where the
    /// robot started.
    pub fn hint_pose(&mut self, pose: Pose2, odometry: Option<Pose2>) -> Result<(), PipelineError> {
        if ![pose.x, pose.y, pose.theta].iter().all(|v| v.is_finite()) {
            return Err(PipelineError::BadHint(pose));
        }
        if self.mode.is_none() {
            return Err(PipelineError::HintWithoutMap);
        }
        let walls = self.map.index().iter().map(|(_, l)| *l);
        let odometry =
            odometry.filter(|p| p.x.is_finite() && p.y.is_finite() && p.theta.is_finite());
        self.start = Some(
            StartSearch::hinted(
                walls,
                GlobalConfig::default(),
                pose,
                HINT_COVARIANCE,
                odometry,
            )
            .with_free_space(&self.cls),
        );
        self.relocalizer = None;
        self.lost_scans = 0;
        // The last scan's pose is the one the hint doubts.
        self.last_scan = None;
        self.summary.pose_hints += 1;
        self.hinted = true;
        // Wherever it is found, the next keyframe is tied to the old map by
        // a loop edge, not chained to the last one across the jump.
        self.first_session_keyframe |= self.mode == Some(MapMode::Extend);
        Ok(())
    }

    /// The mode of a loaded map; `None` for a new map.
    pub fn map_mode(&self) -> Option<MapMode> {
        self.mode
    }

    /// Where the robot stands in a loaded map: `None` for a new map or
    /// once found (and not lost); else the search's hypotheses so far.
    pub fn map_search(&self) -> Option<MapSearch> {
        match (&self.start, &self.relocalizer) {
            (Some(s), _) => Some(MapSearch::Finding(s.hypotheses())),
            (None, Some(s)) => Some(MapSearch::Lost(s.hypotheses())),
            (None, None) => None,
        }
    }

    /// A job taken with [`take_optimisation`](Self::take_optimisation) was
    /// lost (its thread failed): the next one takes its loops in.
    pub fn abandon_optimisation(&mut self) {
        self.graph.abandon_job();
    }

    /// Takes in an optimisation's result: keyframes, trajectory and
    /// predictor move to the corrected poses, the walls and the CLS map
    /// become the job's rebuild plus the keyframes taken since it started.
    /// Returns the map-frame correction of the newest keyframe
    /// (`new = correction ∘ old`), for poses held outside the mapper.
    pub fn apply_optimisation(&mut self, result: OptimisationResult) -> Option<Pose2> {
        let applied = match self.graph.apply_job(result) {
            Ok(Some(applied)) => applied,
            Ok(None) => return None,
            Err(e) => {
                warn!("pose graph not optimised: {e}");
                return None;
            }
        };
        self.follow_correction(&applied.correction);
        let correction = applied.correction.correction;
        let AppliedOptimisation {
            mut walls,
            mut cls,
            covered,
            ..
        } = applied;
        let poses = self.graph.poses();
        for (kf, pose) in self.graph.keyframes().iter().zip(poses).skip(covered) {
            kf.add_to(pose, &mut walls, Some(&mut cls));
        }
        self.map = walls;
        if self.defer_cls_rebuild {
            self.cls_stale = true;
        } else {
            self.cls = cls;
            self.cls_stale = false;
        }
        Some(correction)
    }

    /// Processes one scan; returns what became of it.
    pub fn process(&mut self, record: &ScanRecord) -> ScanOutcome {
        let started = Instant::now();
        self.clocks.start_scan();
        let _scan_span = trace_span!("scan", t = record.scan.t).entered();
        // A non-finite odometry pose would poison every prediction after
        // it: the scan is mapped as one without odometry.
        let odometry = record.odometry.filter(Pose2::is_finite);
        if odometry.is_none() && record.odometry.is_some() {
            self.summary.scans_with_bad_odometry += 1;
            if self.summary.scans_with_bad_odometry <= SKIPPED_EXAMPLES {
                warn!(
                    t = record.scan.t,
                    "the scan's odometry is not finite; mapped without it"
                );
            }
        }
        if odometry.is_none() {
            self.summary.scans_without_odometry += 1;
        }
        if let Some(search) = &mut self.start {
            self.extractor.extract(
                &record.scan,
                &self.config.laser_mount,
                &self.config.extraction,
                &mut self.lines,
            );
            let free = local_region(&self.lines, &record.scan, &self.cls.config().local).ok();
            match search.step(&self.lines, free.as_ref(), odometry) {
                Some(found) => {
                    debug!(t = record.scan.t, pose = ?found.0, "found in the map");
                    self.start = None;
                    self.seed = Some(found);
                }
                None => {
                    self.summary.scans_before_start += 1;
                    return ScanOutcome {
                        pose: Pose2::IDENTITY,
                        localized: false,
                        degenerate: false,
                        keyframe: false,
                        lines: self.lines.len(),
                        matches: 0,
                        rejection: Some(RejectionKind::NotFoundInTheMapYet),
                        by_previous_scan: false,
                        by_last_scan_points: false,
                    };
                }
            }
        }

        let t = Instant::now();
        let (prediction, reading) = trace_span!("predict").in_scope(|| {
            let reading = self.odometry.reading(record.scan.t, odometry);
            if reading == OdometryReading::Stale && odometry.is_some() {
                self.summary.scans_with_unchanged_odometry += 1;
            }
            let prediction = self
                .predictor
                .predict(record.scan.t, reading, &self.config.odometry);
            (prediction, reading)
        });
        // The first scan after the robot was found in a loaded map starts
        // from where it was found.
        // Found after a hint mid-run: the step to here is a jump.
        let from_seed = self.seed.is_some();
        let seeded = from_seed && std::mem::take(&mut self.hinted);
        let (predicted, predicted_cov) = match self.seed.take() {
            Some(found) => found,
            None => (prediction.pose, prediction.cov),
        };
        self.clocks.predict.add(t.elapsed());

        let t = Instant::now();
        trace_span!("extract").in_scope(|| {
            self.extractor.extract(
                &record.scan,
                &self.config.laser_mount,
                &self.config.extraction,
                &mut self.lines,
            );
            // Only regularly moving odometry carries the jambs' gaps.
            let moved = match reading {
                OdometryReading::Fresh(o) if prediction.from_odometry => Some(o),
                _ => None,
            };
            self.jamb_tracks
                .follow(moved, &mut self.lines, self.extractor.jambs());
        });
        self.clocks.extract.add(t.elapsed());

        let mut outcome = ScanOutcome {
            pose: predicted,
            localized: false,
            degenerate: false,
            keyframe: false,
            lines: self.lines.len(),
            matches: 0,
            rejection: None,
            by_previous_scan: false,
            by_last_scan_points: false,
        };
        let mut cov = predicted_cov;
        let current = ScanWithPoints::new(record.scan.clone());
        // Point matching, before localization and after: timed as one
        // run of the stage, when either ran.
        let t = Instant::now();
        let checking =
            self.config.odometry_check_sigmas > 0.0 && prediction.from_odometry && !from_seed;
        let (predicted, measured_step) = if checking {
            trace_span!("check_odometry").in_scope(|| {
                self.check_odometry(&current, record.scan.t, predicted, &predicted_cov)
            })
        } else {
            (predicted, None)
        };
        let mut matching_time = t.elapsed();
        outcome.pose = predicted;
        // Whether the map may learn from this scan: always when localized
        // (or on the first scan), and after a failure only when the scan
        // shows too little known structure to localize (new territory);
        // other failures mean the pose is doubtful.
        let mut may_update_map = true;
        if !self.map.is_empty() {
            let t = Instant::now();
            let result = trace_span!("localize").in_scope(|| {
                self.localize_with_fallback(
                    &current,
                    record.scan.t,
                    predicted,
                    &predicted_cov,
                    &mut outcome,
                )
            });
            self.clocks.localize.add(t.elapsed());
            self.previous_refused_jump = matches!(
                result,
                Err(Rejection::Localize(LocalizeError::ImplausibleJump { .. }))
            );
            let result = result.and_then(|fix| {
                let sigmas = mahalanobis(&fix.pose, &predicted, &predicted_cov);
                if sigmas > self.config.max_correction_sigmas {
                    Err(Rejection::Inconsistent { sigmas })
                } else {
                    Ok(fix)
                }
            });
            let result = result.and_then(|fix| {
                let asked_before = self.refused_turn.take();
                // The last scan's points, not the lines, chose the heading
                // of a fix matched from them.
                if outcome.by_last_scan_points {
                    return Ok(fix);
                }
                let gate = self.config.few_lines_turn_sigmas;
                match turn_on_few_lines(&fix, &predicted, &predicted_cov, gate, asked_before) {
                    Some(refused) => {
                        if let Rejection::TurnOnFewLines { turn, .. } = refused {
                            self.refused_turn = Some(turn);
                        }
                        Err(refused)
                    }
                    None => Ok(fix),
                }
            });
            let result = result.and_then(|fix| {
                let length = self.against_loaded_map(&fix.pose);
                if length > MAX_AGAINST_LOADED_MAP {
                    Err(Rejection::AgainstTheLoadedMap { length })
                } else {
                    Ok(fix)
                }
            });
            match result {
                Ok(fix) => {
                    if matches!(reading, OdometryReading::Fresh(_)) {
                        self.odometry.localized(record.scan.t, fix.pose.theta);
                    } else {
                        self.odometry.unlocalized();
                    }
                    self.unlocalized_run = 0;
                    self.predictor.observe_heading(fix.pose.theta);
                    self.summary.heading_searches += usize::from(fix.heading_searched);
                    outcome.pose = fix.pose;
                    outcome.localized = true;
                    outcome.degenerate = fix.degenerate.is_some();
                    outcome.matches = fix.matches.len();
                    cov = fix.covariance;
                    if outcome.degenerate {
                        self.summary.degenerate_scans += 1;
                    }
                }
                Err(e) => {
                    self.odometry.unlocalized();
                    let kind = e.kind();
                    // Too few matches is new territory, or a view of
                    // too little to match (a bare wall up close), when it
                    // lasts or the scan has hardly any lines. The first
                    // scan after a localized one whose lines were enough
                    // to match but did not is more likely odometry gone
                    // wrong in a fast turn: CSAIL thinned to scans 0.6 m
                    // or 0.3 rad apart had two 18–22° off, beyond every
                    // gate, and learnt from, the first put its walls into
                    // the map at that heading for every later scan to
                    // match (5 m of relation error).
                    self.unlocalized_run += 1;
                    let too_few =
                        matches!(e, Rejection::Localize(LocalizeError::TooFewMatches { .. }));
                    let unmapped = too_few
                        && (self.unlocalized_run > 1
                            || self.lines.len() <= self.config.localizer.min_matches);
                    may_update_map = self.config.update_map_when_unlocalized || unmapped;
                    self.summary.held_back += usize::from(too_few && !may_update_map);
                    self.summary.rejected_localizations += 1;
                    *self
                        .summary
                        .rejections_by_kind
                        .entry(kind.name().to_owned())
                        .or_default() += 1;
                    // Per scan at debug level (hundreds per long log);
                    // the totals are warned about once at the end.
                    debug!(
                        t = record.scan.t,
                        rejected = self.summary.rejected_localizations,
                        "localization failed, keeping the odometry prediction: {e}"
                    );
                    outcome.rejection = Some(kind);
                }
            }
        }

        // In a loaded map, a robot that has not been localized against the
        // map for a while (pushed aside, or drifted through a stretch the
        // map shows little of) is looked for again by global localization
        // while it goes on; once one place remains, that is its pose.
        let mut relocated = seeded;
        if self.mode.is_some() {
            if outcome.localized && !outcome.by_previous_scan {
                self.lost_scans = 0;
                self.relocalizer = None;
            } else {
                self.lost_scans += 1;
            }
            if self.lost_scans >= LOST_AFTER_SCANS && self.relocalizer.is_none() {
                debug!(
                    t = record.scan.t,
                    "lost in the map: global localization again"
                );
                let walls = self.map.index().iter().map(|(_, l)| *l);
                self.relocalizer = Some(
                    StartSearch::new(walls, GlobalConfig::default()).with_free_space(&self.cls),
                );
            }
            // A search costs milliseconds on a large map: every few scans.
            let due = self.lost_scans.is_multiple_of(RELOCALIZE_EVERY_SCANS);
            let free = due
                .then(|| local_region(&self.lines, &record.scan, &self.cls.config().local).ok())
                .flatten();
            if let Some(search) = self.relocalizer.as_mut().filter(|_| due)
                && let Some((pose, found_cov)) = search.step(&self.lines, free.as_ref(), odometry)
            {
                debug!(t = record.scan.t, ?pose, "found in the map again");
                self.relocalizer = None;
                self.lost_scans = 0;
                self.summary.relocalizations += 1;
                outcome.pose = pose;
                outcome.localized = true;
                cov = found_cov;
                relocated = true;
                // The next keyframe is tied to the old map by a loop edge,
                // not chained to the last one across the jump.
                self.first_session_keyframe |= self.mode == Some(MapMode::Extend);
            }
        }

        // In a loaded map, a scan not localized against it, or taken while
        // the robot is lost, teaches the map nothing: its pose may be
        // anywhere.
        if self.mode.is_some() {
            may_update_map &= outcome.localized && self.relocalizer.is_none();
        }
        // Nor does an unlocalized pose predicted without fresh odometry:
        // constant velocity is a guess, and frozen odometry happens in
        // fast turns, where a wrong heading misplaces walls the most.
        may_update_map &= outcome.localized || prediction.from_odometry || self.map.is_empty();
        let learns = self.mode != Some(MapMode::Localize);
        if may_update_map && learns && self.keyframes.is_keyframe(&outcome.pose) {
            let t = Instant::now();
            let line_walls = trace_span!("map_update")
                .in_scope(|| self.map.update(&self.lines, &outcome.pose, &cov))
                .walls;
            self.clocks.map_update.add(t.elapsed());
            let t = Instant::now();
            let region = local_region(&self.lines, &record.scan, &self.cls.config().local);
            // A map waiting for its rebuild is not grown: the rebuild
            // takes this keyframe too.
            if !self.cls_stale {
                let grown = trace_span!("cls_update").in_scope(|| match &region {
                    Ok(local) => {
                        self.cls
                            .add_keyframe(&self.map, &line_walls, local, outcome.pose, cov)
                    }
                    Err(e) => Err(ClsError::Local(e.clone())),
                });
                if let Err(e) = grown {
                    // The CLS map refuses an update whole and stays valid.
                    self.summary.cls_rejected += 1;
                    debug!(t = record.scan.t, "CLS map update refused: {e}");
                }
            }
            self.clocks.cls_update.add(t.elapsed());
            // Keyframes are kept for loop closure and for a deferred CLS
            // map; a live mapper without loop closure needs neither, and
            // would only grow.
            if self.config.loop_closure.enabled || self.defer_cls_rebuild {
                let first = self.graph.is_empty();
                let keyframe = Keyframe {
                    t: record.scan.t,
                    lines: self.lines.clone(),
                    region: region.ok(),
                    covariance: cov,
                    travelled: 0.0,
                };
                let session_start = std::mem::take(&mut self.first_session_keyframe);
                if session_start {
                    self.graph.add_relocalized(
                        keyframe,
                        outcome.pose,
                        cov,
                        &self.config.loop_closure,
                    );
                } else {
                    self.graph.add(
                        keyframe,
                        outcome.pose,
                        outcome.localized || first,
                        &self.config.loop_closure,
                    );
                }
                self.anchor_keyframe = None;
                // In the background the search is a job (`take_loop_search`).
                self.newest_is_session_start = session_start;
                let closed = if self.graph.wants_loop_search() {
                    Ok(None)
                } else {
                    self.graph.close_loop(
                        &self.config.map,
                        &self.config.localizer,
                        &GlobalConfig::default(),
                        &self.config.loop_closure,
                    )
                };
                match closed {
                    Ok(Some(correction)) => {
                        self.apply_correction(&correction);
                        // This scan is the newest keyframe.
                        outcome.pose = correction.correction.compose(&outcome.pose);
                    }
                    Ok(None) => {
                        // Scans until the next kept keyframe hang on the
                        // one this revisit was merged into, not on the last
                        // kept one, which may be far back along the path.
                        self.anchor_keyframe = self.graph.merge_revisit(&self.config.loop_closure);
                        // The session's first keyframe merged into an old
                        // one: the next kept keyframe starts the session.
                        self.first_session_keyframe |=
                            session_start && self.anchor_keyframe.is_some();
                    }
                    Err(e) => warn!(t = record.scan.t, "pose graph not optimised: {e}"),
                }
            }
            outcome.keyframe = true;
            self.summary.keyframes += 1;
        }

        // After a relocalization the step to here is the jump, not motion.
        let estimate = match (relocated, outcome.localized) {
            (true, _) => Estimate::Jumped,
            (false, true) => Estimate::Localized,
            (false, false) => Estimate::Predicted,
        };
        self.predictor.record(outcome.pose, cov, estimate);
        self.last_covariance = cov;
        // The fallback reference follows the map's rule: a scan at a
        // doubtful pose (a refused fix) does not become the reference the
        // next scan is matched against, or the next scan would agree with
        // the doubt; the last trusted scan stays the reference.
        if self.config.previous_scan_fallback && may_update_map {
            self.previous_scan = SegmentIndex::new();
            for line in &self.lines {
                self.previous_scan.insert(line.transformed(&outcome.pose));
            }
        }
        self.trajectory.push((record.scan.t, outcome.pose));
        let step = if self.measure_steps {
            let t = Instant::now();
            let step = trace_span!("scan_match").in_scope(|| {
                self.match_last_scan(&current, record.scan.t, &outcome.pose, measured_step)
            });
            matching_time += t.elapsed();
            step
        } else {
            None
        };
        if checking || self.measure_steps {
            self.clocks.scan_match.add(matching_time);
        }
        self.steps.push(step);
        self.last_scan = Some(LastScan {
            points: current,
            pose: outcome.pose,
            t: record.scan.t,
            localized: outcome.localized,
        });
        // Before a resumed session's first keyframe, the last keyframe is
        // the old session's, anywhere in the map: no anchor.
        let anchor = if self.first_session_keyframe {
            None
        } else {
            self.anchor_keyframe.or(self.graph.len().checked_sub(1))
        };
        self.anchors
            .push(anchor.map(|k| (k, self.graph.poses()[k].between(&outcome.pose))));
        self.summary.scans += 1;
        self.clocks.whole.add(started.elapsed());
        outcome
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::geometry::{RangeScan, SegmentId};
    use crate::sim::{Rng, ScanSpec, World, cast_scan};

    #[test]
    fn first_scan_defines_the_map_frame_and_is_a_keyframe() {
        let world = World::room_with_boxes();
        let spec = ScanSpec::lms200_half_degree(0.0);
        let mut rng = Rng::new(1);
        let odo = Pose2::new(1.0, 1.0, 0.3);
        let scan: RangeScan = cast_scan(&world, &odo, &spec, 0.0, &mut rng);
        let mut mapper = Mapper::new(MapperConfig::default());
        let out = mapper.process(&ScanRecord {
            scan,
            odometry: Some(odo),
        });
        assert_eq!(out.pose, Pose2::IDENTITY);
        assert!(out.keyframe && !out.localized);
        assert!(mapper.map().len() >= 3, "{} segments", mapper.map().len());
    }

    #[test]
    fn a_turn_on_few_lines_beyond_the_gate_is_refused_unless_asked_for_again() {
        // Prediction heading σ 1.5°; a fix 7° off it (4.7 σ), its lines
        // leaving the heading as uncertain.
        let sd = 1.5f64.to_radians();
        let cov = [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, sd * sd]];
        let predicted = Pose2::new(2.0, 1.0, 0.3);
        let fix = |lines: usize, turn_deg: f64| LocalizationResult {
            pose: Pose2::new(2.0, 1.0, 0.3 + turn_deg.to_radians()),
            covariance: cov,
            matches: (0..lines).map(|i| (i, SegmentId(i as u32))).collect(),
            degenerate: None,
            iterations: 3,
            chi2: 0.0,
            heading_searched: false,
        };
        let seven = 7f64.to_radians();
        match turn_on_few_lines(&fix(2, -7.0), &predicted, &cov, 3.0, None) {
            Some(Rejection::TurnOnFewLines { turn, sigmas }) => {
                assert!((turn + seven).abs() < 1e-12, "{turn}");
                assert!((sigmas - 7.0 / 1.5).abs() < 1e-9, "{sigmas}");
            }
            other => panic!("refused as a turn on few lines: {other:?}"),
        }
        assert!(turn_on_few_lines(&fix(3, 7.0), &predicted, &cov, 3.0, None).is_some());
        // Four lines, a turn within the gate, the gate off: it stands.
        assert!(turn_on_few_lines(&fix(4, 7.0), &predicted, &cov, 3.0, None).is_none());
        assert!(turn_on_few_lines(&fix(2, 4.4), &predicted, &cov, 3.0, None).is_none());
        assert!(turn_on_few_lines(&fix(2, 7.0), &predicted, &cov, 0.0, None).is_none());
        // Lines that fix the heading to 0.5° themselves: it stands.
        let narrow = [
            [0.01, 0.0, 0.0],
            [0.0, 0.01, 0.0],
            [0.0, 0.0, (sd / 3.0).powi(2)],
        ];
        let sure = LocalizationResult {
            covariance: narrow,
            ..fix(2, 7.0)
        };
        assert!(turn_on_few_lines(&sure, &predicted, &cov, 3.0, None).is_none());
        // Asked for again (within 2°): the odometry is what is wrong.
        let before = Some(6.0f64.to_radians());
        assert!(turn_on_few_lines(&fix(2, 7.0), &predicted, &cov, 3.0, before).is_none());
        // Another turn, or the other way, is refused again.
        assert!(turn_on_few_lines(&fix(2, 9.5), &predicted, &cov, 3.0, before).is_some());
        assert!(turn_on_few_lines(&fix(2, -7.0), &predicted, &cov, 3.0, before).is_some());
    }

    /// The odometry reports a 23° turn the robot did not make (a heading
    /// that lags in a fast turn, then catches up): the 22° correction is
    /// more than the localizer takes from one scan, so it is refused; the
    /// next scan asks for the same correction and it is taken.
    #[test]
    fn a_correction_asked_for_twice_in_a_row_is_taken() {
        let world = World::room_with_boxes();
        let spec = ScanSpec::lms200_half_degree(0.0);
        let mut rng = Rng::new(4);
        let mut mapper = Mapper::new(MapperConfig::default());
        let mut feed = |k: usize, truth: Pose2, odometry: Pose2| {
            let scan = cast_scan(&world, &truth, &spec, 0.2 * k as f64, &mut rng);
            mapper.process(&ScanRecord {
                scan,
                odometry: Some(odometry),
            })
        };
        let start = Pose2::new(3.0, 3.0, 0.2);
        feed(0, start, Pose2::IDENTITY);
        feed(
            1,
            start.compose(&Pose2::new(0.01, 0.0, 0.0)),
            Pose2::new(0.01, 0.0, 0.0),
        );
        let moved = Pose2::new(0.02, 0.0, 0.02);
        let truth = start.compose(&moved);
        let first = feed(2, truth, Pose2::new(0.02, 0.0, 0.4));
        assert_eq!(
            first.rejection.map(|k| k.name()),
            Some("ImplausibleJump"),
            "{first:?}"
        );
        let moved = Pose2::new(0.03, 0.0, 0.02);
        let truth = start.compose(&moved);
        let second = feed(3, truth, Pose2::new(0.03, 0.0, 0.4));
        assert!(second.localized, "{second:?}");
        assert!(
            wrap_angle(second.pose.theta - moved.theta).abs() < 0.01
                && (second.pose.x - moved.x).hypot(second.pose.y - moved.y) < 0.02,
            "{second:?} vs {moved:?}"
        );
    }

    /// The odometry counts the robot's backward steps forwards, as
    /// Freiburg 079's does: the robot drives 1.2 m, stops, and backs up
    /// 1.08 m while the odometry reports it going on, each prediction
    /// landing up to 0.24 m from the truth. The scans' own step overrules
    /// the odometry on the backward steps and on no other, and the pose
    /// stays within 2 cm of the truth; with the check off it ends over a
    /// metre off.
    #[test]
    fn odometry_that_counts_backward_steps_forward_is_overruled_by_the_scans() {
        // (true step, reported step) along the robot's heading, m.
        let steps: Vec<(f64, f64)> = std::iter::repeat_n((0.12, 0.12), 10)
            .chain(std::iter::repeat_n((0.0, 0.0), 2))
            .chain([(-0.06, 0.06)])
            .chain(std::iter::repeat_n((-0.12, 0.12), 8))
            .collect();
        let drive = |config: MapperConfig| {
            let world = World::room_with_boxes();
            let spec = ScanSpec::lms200_half_degree(0.005);
            let mut rng = Rng::new(5);
            let mut mapper = Mapper::new(config);
            let start = Pose2::new(3.0, 3.0, 0.3);
            let (mut along, mut reported, mut faulty) = (0.0, 0.0, 0);
            let mut worst: f64 = 0.0;
            let mut overruled_good = 0;
            for (k, &(step, claimed)) in std::iter::once(&(0.0, 0.0)).chain(&steps).enumerate() {
                along += step;
                reported += claimed;
                faulty += usize::from(step != claimed);
                let truth = start.compose(&Pose2::new(along, 0.0, 0.0));
                let scan = cast_scan(&world, &truth, &spec, 0.2 * k as f64, &mut rng);
                let before = mapper.summary().odometry_steps_overruled;
                let out = mapper.process(&ScanRecord {
                    scan,
                    odometry: Some(Pose2::new(reported, 0.0, 0.0)),
                });
                worst = worst.max((out.pose.x - along).hypot(out.pose.y));
                let overruled = mapper.summary().odometry_steps_overruled > before;
                overruled_good += usize::from(overruled && step == claimed);
            }
            (
                worst,
                mapper.summary().odometry_steps_overruled,
                faulty,
                overruled_good,
            )
        };
        let (checked, overruled, faulty, overruled_good) = drive(MapperConfig::default());
        assert!(checked < 0.02, "{checked} m off with the check");
        assert_eq!(overruled_good, 0);
        // The first backward step, from standstill, the lines correct.
        assert!(
            overruled + 1 >= faulty,
            "{overruled} of {faulty} faulty steps overruled"
        );
        let (unchecked, ..) = drive(MapperConfig {
            odometry_check_sigmas: 0.0,
            ..MapperConfig::default()
        });
        assert!(
            unchecked > 1.0,
            "{unchecked} m off without the check, {checked} m with"
        );
    }

    /// Down a plain corridor (no end in reach) the robot turns 17° the
    /// odometry does not report: the two walls' lines match at the right
    /// heading only as a pair that leaves the corridor's length open, too
    /// little to take from a heading search. The scan's points, matched
    /// against the last scan's, give the heading; the length stays the
    /// prediction's, and as uncertain. The base drives along the corridor
    /// turned 0.5 rad from it, the laser mounted off its centre and turned.
    #[test]
    fn a_heading_lost_in_a_corridor_is_found_by_the_last_scan_s_points() {
        let world = World::corridor(40.0, 2.0, None);
        let spec = ScanSpec::lms200_half_degree(0.005);
        let mut rng = Rng::new(3);
        let mount = Pose2::new(0.4, 0.1, 0.1);
        let mut mapper = Mapper::new(MapperConfig {
            laser_mount: mount,
            ..MapperConfig::default()
        });
        let start = Pose2::new(10.0, 0.3, 0.5);
        for k in 0..12 {
            let turned = if k >= 8 { 0.3 } else { 0.0 };
            let truth = Pose2::new(10.0 + 0.4 * k as f64, 0.3, 0.5 + turned);
            let moved = start.between(&truth);
            let laser = truth.compose(&mount);
            let scan = cast_scan(&world, &laser, &spec, 0.5 * k as f64, &mut rng);
            let out = mapper.process(&ScanRecord {
                scan,
                odometry: Some(Pose2::new(moved.x, moved.y, moved.theta - turned)),
            });
            if k >= 8 {
                let off = moved.between(&out.pose);
                assert!(out.localized, "scan {k}: {out:?}");
                assert!(off.theta.abs() < 0.01, "scan {k}: {off:?}");
                // Along the corridor the odometry's steps, turned by the
                // heading it missed, fall 2 cm short each.
                let bound = 0.03 + 0.025 * (k - 8) as f64;
                assert!(off.x.hypot(off.y) < bound, "scan {k}: {off:?}");
            }
            if k == 8 {
                // The corridor runs at −0.5 rad in the map frame.
                let cov = mapper.last_covariance();
                let (s, c) = (-0.5f64).sin_cos();
                let variance = |v: [f64; 2]| {
                    v[0] * (cov[0][0] * v[0] + cov[0][1] * v[1])
                        + v[1] * (cov[1][0] * v[0] + cov[1][1] * v[1])
                };
                let (along, across) = (variance([c, s]), variance([-s, c]));
                assert!(along > 10.0 * across, "{along} vs {across}: {cov:?}");
            }
        }
    }

    #[test]
    fn only_trusted_poses_update_the_map() {
        let world = World::room_with_boxes();
        let spec = ScanSpec::lms200_half_degree(0.0);
        let mut rng = Rng::new(2);
        let start = Pose2::new(3.0, 3.0, 0.0);
        let blind = |t: f64| RangeScan {
            t,
            angle_min: -std::f64::consts::FRAC_PI_2,
            angle_increment: std::f64::consts::PI / 360.0,
            ranges: vec![Err(crate::geometry::BeamFault::NoReturn); 361],
        };
        let mut mapper = Mapper::new(MapperConfig::default());
        let first = mapper.process(&ScanRecord {
            scan: cast_scan(&world, &start, &spec, 0.0, &mut rng),
            odometry: Some(start),
        });
        assert!(first.keyframe);
        // No lines: too few matches, but real odometry moved 0.5 m, so the
        // scan counts as new territory and may update the map.
        let moved = Pose2::new(3.5, 3.0, 0.0);
        let second = mapper.process(&ScanRecord {
            scan: blind(0.2),
            odometry: Some(moved),
        });
        assert_eq!(second.rejection, Some(RejectionKind::TooFewMatches));
        assert!(second.keyframe);
        assert!((second.pose.x - 0.5).abs() < 1e-9);
        // Frozen odometry: predicted at constant velocity (another 0.5 m),
        // which is a guess, so the map is left alone.
        let third = mapper.process(&ScanRecord {
            scan: blind(0.4),
            odometry: Some(moved),
        });
        assert!((third.pose.x - 1.0).abs() < 1e-9, "{:?}", third.pose);
        assert!(!third.keyframe);
        let summary = mapper.summary();
        assert_eq!(summary.rejected_localizations, 2);
        assert_eq!(summary.scans_with_unchanged_odometry, 1);
        assert_eq!(summary.keyframes, 2);
    }

    #[test]
    fn lines_that_fit_nowhere_right_after_a_fix_teach_the_map_nothing() {
        let world = World::room_with_boxes();
        let spec = ScanSpec::lms200_half_degree(0.0);
        let mut rng = Rng::new(3);
        let start = Pose2::new(3.0, 3.0, 0.0);
        let mut mapper = Mapper::new(MapperConfig::default());
        let scan_at =
            |truth: &Pose2, t: f64, rng: &mut Rng| cast_scan(&world, truth, &spec, t, rng);
        let first = mapper.process(&ScanRecord {
            scan: scan_at(&start, 0.0, &mut rng),
            odometry: Some(start),
        });
        assert!(first.keyframe);
        let walls = mapper.map().len();
        // The robot drove 0.6 m and turned 0.5 rad; odometry says it
        // turned the other way (1 rad off, beyond any search): the lines
        // are there but fit nowhere.
        let truth = start.compose(&Pose2::new(0.6, 0.0, 0.5));
        let glitch = start.compose(&Pose2::new(0.6, 0.0, -0.5));
        let second = mapper.process(&ScanRecord {
            scan: scan_at(&truth, 0.2, &mut rng),
            odometry: Some(glitch),
        });
        assert!(second.lines > 2, "{second:?}");
        assert_eq!(second.rejection, Some(RejectionKind::TooFewMatches));
        assert!(!second.keyframe, "{second:?}");
        assert_eq!(mapper.map().len(), walls);
        assert_eq!(mapper.summary().held_back, 1);
        // Odometry catches up: the next scan localizes against the walls
        // the first one saw, none of them placed at the wrong heading.
        let truth = truth.compose(&Pose2::new(0.6, 0.0, 0.0));
        let third = mapper.process(&ScanRecord {
            scan: scan_at(&truth, 0.4, &mut rng),
            odometry: Some(truth),
        });
        assert!(third.localized, "{third:?}");
        let moved = start.between(&truth);
        assert!(
            (third.pose.x - moved.x).hypot(third.pose.y - moved.y) < 0.05
                && wrap_angle(third.pose.theta - moved.theta).abs() < 0.02,
            "{third:?} vs {moved:?}"
        );
    }
}
