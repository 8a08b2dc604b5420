//! Tuning of global localization and of the disambiguation by later scans.

use serde::{Deserialize, Serialize};

use crate::localize::LocalizerConfig;

/// Tuning of [`global_localize`](super::global_localize) and
/// [`disambiguate`](super::disambiguate); SI units (m, rad).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GlobalConfig {
    /// How many of the scan's longest lines are tried in turn as the anchor
    /// paired with map lines. Default 3: the longest alone fails when it is
    /// a wall the map lacks, and each anchor costs a full search.
    pub anchors: usize,
    /// Shortest anchor (m). Default 0.5: a shorter line pairs with almost
    /// every map line and its direction is too noisy to fix the rotation.
    pub min_anchor_length: f64,
    /// How much shorter than the anchor a map partner may be (m). Default
    /// 0.3: map walls end where they were last seen, a little short.
    pub length_tolerance: f64,
    /// A map partner may also be as short as this fraction of the anchor.
    /// Default 0.5. The paper pairs only with longer map lines, but a CLS
    /// map often holds a long wall in two or three pieces (seen partly
    /// occluded from different places), and the longest scan line is then
    /// longer than each of them.
    pub partner_min_fraction: f64,
    /// Largest disagreement (rad) between a voting pair's rotation and the
    /// anchor pair's. Default 0.05 (about 3°): several σθ of a 1 m line.
    pub angle_tolerance: f64,
    /// Blur of the translation segments (m): two pairs agree when their
    /// translation segments pass within this of each other. Default 0.15,
    /// the rotation error of a long anchor (≈0.5°) at 10 m plus fit noise.
    pub blur: f64,
    /// How far a voting local segment may extend beyond the ends of its map
    /// partner (m). Default 0.3, like the correspondence extent tolerance.
    pub extent_tolerance: f64,
    /// Most local lines that vote, longest first. Default 40.
    pub max_voters: usize,
    /// Best translation peaks kept per anchor pair. Default 2: a wall with
    /// repeated features (doors along a corridor) has several.
    pub peaks_per_pair: usize,
    /// Voted hypotheses refined by local localization. Default 24: places
    /// that look alike (the corners of a rectangular loop) tie in the vote,
    /// and the true one must not be cut off by the tie-break.
    pub refine_candidates: usize,
    /// Hypotheses reported. Default 5.
    pub max_hypotheses: usize,
    /// Two hypotheses closer than this (m) and [`cluster_angle`](Self::cluster_angle)
    /// are one. Default 0.3.
    pub cluster_distance: f64,
    /// Angular part of the clustering (rad). Default 0.1.
    pub cluster_angle: f64,
    /// The result is ambiguous when the runner-up scores at least this
    /// fraction of the best. Default 0.85: noise moves a wrong but
    /// symmetric place's score by a few percent, not fifteen.
    pub ambiguity_ratio: f64,
    /// Standard deviation of the voted position (m) given to the refinement
    /// as its prior. Default 0.1, about the blur.
    pub refine_sigma_xy: f64,
    /// Standard deviation of the voted heading (rad) for the refinement.
    /// Default 0.05.
    pub refine_sigma_theta: f64,
    /// Odometry noise for disambiguation: position σ per metre driven
    /// (fraction). Default 0.05.
    pub odometry_sigma_per_m: f64,
    /// Odometry noise for disambiguation: heading σ per radian turned.
    /// Default 0.05.
    pub odometry_sigma_per_rad: f64,
    /// Odometry noise floor for disambiguation (m and rad). Default 0.02.
    pub odometry_sigma_floor: f64,
    /// A hypothesis survives a later scan only when that scan's lines lie
    /// on map lines at its pose for at least this fraction of their length.
    /// Default 0.5: the map was built from such scans, so at the right
    /// place most of a scan is explained (clutter and people aside).
    pub min_explained: f64,
    /// A hypothesis is refuted when more than this length (m) of map walls
    /// stands inside the scan's free space at its pose (the beams went
    /// through where the map has a wall). Default 0.5 m, as for loop
    /// closures: a door left open or a moved chair, not a room's wall.
    /// The same length bounds the converse while places are tracked: how
    /// much more of the scan's walls may stand in the map's explored free
    /// space at a place than at the place where the least does.
    pub max_free_space_conflict: f64,
    /// A wall point counts as inside the free space when farther than this
    /// (m) from its boundary. Default 0.15: pose and fit noise.
    pub free_space_tolerance: f64,
    /// A local line at a hypothesis counts as lying on a map line, for the
    /// score, when their directions differ by at most this (rad). Default
    /// 0.05: the pose is refined, so only fit noise remains.
    pub score_angle: f64,
    /// ... and when the map line runs within this (m) of it where they
    /// overlap. Default 0.1.
    pub score_distance: f64,
    /// Local localization used for refinement and tracking. Its jump
    /// limits are widened by default (1 m, 0.3 rad) since voted poses are
    /// off by up to the blur.
    pub localizer: LocalizerConfig,
}

impl Default for GlobalConfig {
    fn default() -> Self {
        GlobalConfig {
            anchors: 3,
            min_anchor_length: 0.5,
            length_tolerance: 0.3,
            partner_min_fraction: 0.5,
            angle_tolerance: 0.05,
            blur: 0.15,
            extent_tolerance: 0.3,
            max_voters: 40,
            peaks_per_pair: 2,
            refine_candidates: 24,
            max_hypotheses: 5,
            cluster_distance: 0.3,
            cluster_angle: 0.1,
            ambiguity_ratio: 0.85,
            refine_sigma_xy: 0.1,
            refine_sigma_theta: 0.05,
            odometry_sigma_per_m: 0.05,
            odometry_sigma_per_rad: 0.05,
            odometry_sigma_floor: 0.02,
            min_explained: 0.5,
            max_free_space_conflict: 0.5,
            free_space_tolerance: 0.15,
            score_angle: 0.05,
            score_distance: 0.1,
            localizer: LocalizerConfig {
                max_translation_jump: 1.0,
                max_rotation_jump: 0.3,
                ..LocalizerConfig::default()
            },
        }
    }
}
