//! Why a scan's localization was not used: the reason (`Rejection`,
//! with its numbers, for the log) and its kind ([`RejectionKind`], counted
//! in the summary).

use serde::Serialize;
use thiserror::Error;

use crate::localize::LocalizeError;

/// Why a scan's localization was not used.
#[derive(Debug, Clone, PartialEq, Error)]
pub(super) enum Rejection {
    #[error(transparent)]
    Localize(LocalizeError),
    #[error("correction of {sigmas:.1} σ from the odometry prediction")]
    Inconsistent { sigmas: f64 },
    #[error(
        "a fix from few lines turning the heading {turn:.3} rad ({sigmas:.1} σ) from the prediction"
    )]
    TurnOnFewLines { turn: f64, sigmas: f64 },
    #[error(
        "{length:.2} m of the scan's walls stand where the loaded map saw through and has no wall"
    )]
    AgainstTheLoadedMap { length: f64 },
}

impl Rejection {
    pub(super) fn kind(&self) -> RejectionKind {
        match self {
            Rejection::Localize(e) => match e {
                LocalizeError::TooFewMatches { .. } => RejectionKind::TooFewMatches,
                LocalizeError::ImplausibleJump { .. } => RejectionKind::ImplausibleJump,
                LocalizeError::InvalidPrior => RejectionKind::InvalidPrior,
                LocalizeError::NonFiniteInput { .. } => RejectionKind::NonFiniteInput,
                LocalizeError::Singular => RejectionKind::Singular,
                LocalizeError::NotConverged { .. } => RejectionKind::NotConverged,
            },
            Rejection::Inconsistent { .. } => RejectionKind::InconsistentWithOdometry,
            Rejection::TurnOnFewLines { .. } => RejectionKind::TurnOnFewLines,
            Rejection::AgainstTheLoadedMap { .. } => RejectionKind::AgainstTheLoadedMap,
        }
    }
}

/// The kind of a scan's rejection, as the summary counts it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
pub enum RejectionKind {
    /// Too few lines matched the map.
    TooFewMatches,
    /// The fix jumped further from the prediction than allowed.
    ImplausibleJump,
    /// The prediction's covariance was unusable.
    InvalidPrior,
    /// A line or the prediction was not finite.
    NonFiniteInput,
    /// The matched lines left the pose undetermined.
    Singular,
    /// The solver did not converge.
    NotConverged,
    /// The fix disagreed with the odometry beyond `max_correction_sigmas`.
    InconsistentWithOdometry,
    /// The fix rested on few lines and turned the heading beyond
    /// `few_lines_turn_sigmas`.
    TurnOnFewLines,
    /// Before the robot was found in a loaded map: no pose at all.
    NotFoundInTheMapYet,
    /// The fix put walls of the scan where the loaded map saw through and
    /// has no wall: the robot is not where it was thought (carried away,
    /// or matched to the wrong walls).
    AgainstTheLoadedMap,
}

impl RejectionKind {
    /// The kind's name, as the summary and the logs write it.
    pub fn name(self) -> &'static str {
        match self {
            RejectionKind::TooFewMatches => "TooFewMatches",
            RejectionKind::ImplausibleJump => "ImplausibleJump",
            RejectionKind::InvalidPrior => "InvalidPrior",
            RejectionKind::NonFiniteInput => "NonFiniteInput",
            RejectionKind::Singular => "Singular",
            RejectionKind::NotConverged => "NotConverged",
            RejectionKind::InconsistentWithOdometry => "InconsistentWithOdometry",
            RejectionKind::TurnOnFewLines => "TurnOnFewLines",
            RejectionKind::NotFoundInTheMapYet => "NotFoundInTheMapYet",
            RejectionKind::AgainstTheLoadedMap => "AgainstTheLoadedMap",
        }
    }
}

impl std::fmt::Display for RejectionKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}
