//! The relation-based metric of Kümmerle et al., "On measuring the accuracy
//! of SLAM algorithms", Autonomous Robots 27(4), 2009.
//!
//! A relations file lists reference motions `δ*ᵢⱼ` between pairs of scan
//! times, `t1 t2 x y z roll pitch yaw` (s, m, rad; the motion from the pose
//! at t1 to the pose at t2, in the t1 frame). For each relation the
//! estimated motion is `δᵢⱼ = xᵢ⁻¹ ∘ xⱼ` and the error `δ*ᵢⱼ⁻¹ ∘ δᵢⱼ`
//! (`δᵢⱼ ⊖ δ*ᵢⱼ`); its translational part is the Euclidean norm of the
//! translation (m), its rotational part the absolute wrapped angle.
//! The paper tabulates the mean and standard deviation of these absolute
//! errors and, separately, of their squares; both are computed here.
//! Because only relative motions enter, the trajectory's frame is free.

use crate::files::trajectory::finite_numbers;
use crate::geometry::{Pose2, wrap_angle};
use serde::Serialize;
use std::io::BufRead;
use std::path::Path;
use thiserror::Error;

/// Largest difference (s) between a relation's timestamp and a trajectory
/// time for them to be the same scan. Relations files give 5 decimals
/// (10 µs); scans are ≥ 13 ms apart, so 0.1 ms is unambiguous.
pub const RELATION_TIME_TOLERANCE: f64 = 1e-4;

/// One reference relation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Relation {
    pub t1: f64,
    pub t2: f64,
    /// Motion from the pose at `t1` to the pose at `t2`, in the `t1` frame.
    pub delta: Pose2,
}

#[derive(Debug, Error)]
pub enum EvalError {
    #[error("cannot read relations file {path}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("relations file: read failed at line {line}")]
    Read {
        line: usize,
        #[source]
        source: std::io::Error,
    },
    #[error("relations line {line}: expected `t1 t2 x y z roll pitch yaw`, found {found:?}")]
    Malformed { line: usize, found: String },
    #[error("no relation could be matched to the trajectory ({missing} missing)")]
    NothingMatched { missing: usize },
}

/// Mean, standard deviation (n − 1 denominator) and maximum of a sample.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct ErrorStats {
    pub mean: f64,
    pub std_dev: f64,
    pub max: f64,
}

impl ErrorStats {
    fn of(values: &[f64]) -> ErrorStats {
        let n = values.len();
        if n == 0 {
            return ErrorStats::default();
        }
        let mean = values.iter().sum::<f64>() / n as f64;
        let var = if n > 1 {
            values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1) as f64
        } else {
            0.0
        };
        let max = values.iter().copied().fold(0.0, f64::max);
        ErrorStats {
            mean,
            std_dev: var.sqrt(),
            max,
        }
    }
}

/// The metric over one trajectory.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct RelationErrors {
    /// Relations whose two times were both found in the trajectory.
    pub used: usize,
    /// Relations with at least one time absent from the trajectory.
    pub missing: usize,
    /// Absolute translational error (m).
    pub translation_m: ErrorStats,
    /// Absolute rotational error (deg).
    pub rotation_deg: ErrorStats,
    /// Squared translational error (m²).
    pub translation_sq_m2: ErrorStats,
    /// Squared rotational error (deg²).
    pub rotation_sq_deg2: ErrorStats,
    /// Translational error (m) of the relations at most
    /// [`LOCAL_SPAN`] apart, and how many: the local accuracy.
    pub local_translation_m: ErrorStats,
    pub local_used: usize,
    /// Translational error (m) of the longer relations: the map's global
    /// consistency (loops closed or not).
    pub global_translation_m: ErrorStats,
}

/// Longest time (s) between a relation's two scans for it to count as
/// local: a few metres of path, where drift has not built up and no loop
/// is needed.
pub const LOCAL_SPAN: f64 = 3.0;

/// Reads a relations file.
pub fn read_relations<R: BufRead>(input: R) -> Result<Vec<Relation>, EvalError> {
    let mut out = Vec::new();
    for (idx, line) in input.lines().enumerate() {
        let number = idx + 1;
        let line = line.map_err(|source| EvalError::Read {
            line: number,
            source,
        })?;
        let body = line.trim();
        if body.is_empty() || body.starts_with('#') {
            continue;
        }
        let malformed = || EvalError::Malformed {
            line: number,
            found: body.to_owned(),
        };
        let [t1, t2, x, y, _z, _roll, _pitch, yaw] = finite_numbers(body).ok_or_else(malformed)?;
        out.push(Relation {
            t1,
            t2,
            delta: Pose2::new(x, y, yaw),
        });
    }
    Ok(out)
}

/// Index of the trajectory pose at time `t` (within the tolerance), given
/// indices sorted by time.
fn lookup(trajectory: &[(f64, Pose2)], by_time: &[usize], t: f64) -> Option<Pose2> {
    let after = by_time.partition_point(|&i| trajectory[i].0 < t);
    let nearest = [after.checked_sub(1), Some(after)]
        .into_iter()
        .flatten()
        .filter_map(|k| by_time.get(k))
        .map(|&i| trajectory[i])
        .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))?;
    ((nearest.0 - t).abs() <= RELATION_TIME_TOLERANCE).then_some(nearest.1)
}

/// The error of one relation: (translation m, rotation rad, absolute).
pub fn relation_error(estimated: &Pose2, reference: &Pose2) -> (f64, f64) {
    let e = reference.inverse().compose(estimated);
    (e.x.hypot(e.y), wrap_angle(e.theta).abs())
}

/// Evaluates a trajectory (times s, poses in any fixed frame) against
/// relations. Relations whose times are not in the trajectory are counted
/// as missing, not guessed by interpolation.
pub fn evaluate(trajectory: &[(f64, Pose2)], relations: &[Relation]) -> RelationErrors {
    let mut by_time: Vec<usize> = (0..trajectory.len()).collect();
    by_time.sort_by(|&a, &b| trajectory[a].0.total_cmp(&trajectory[b].0));
    let mut trans = Vec::with_capacity(relations.len());
    let mut rot = Vec::with_capacity(relations.len());
    let (mut local, mut global) = (Vec::new(), Vec::new());
    let mut missing = 0;
    for r in relations {
        match (
            lookup(trajectory, &by_time, r.t1),
            lookup(trajectory, &by_time, r.t2),
        ) {
            (Some(a), Some(b)) => {
                let (dt, dr) = relation_error(&a.between(&b), &r.delta);
                trans.push(dt);
                rot.push(dr.to_degrees());
                if (r.t2 - r.t1).abs() <= LOCAL_SPAN {
                    local.push(dt);
                } else {
                    global.push(dt);
                }
            }
            _ => missing += 1,
        }
    }
    let sq = |v: &[f64]| v.iter().map(|x| x * x).collect::<Vec<_>>();
    RelationErrors {
        used: trans.len(),
        missing,
        translation_m: ErrorStats::of(&trans),
        rotation_deg: ErrorStats::of(&rot),
        translation_sq_m2: ErrorStats::of(&sq(&trans)),
        rotation_sq_deg2: ErrorStats::of(&sq(&rot)),
        local_translation_m: ErrorStats::of(&local),
        local_used: local.len(),
        global_translation_m: ErrorStats::of(&global),
    }
}

/// Reads a relations file and evaluates the trajectory against it.
pub fn evaluate_relations(
    trajectory: &[(f64, Pose2)],
    relations_path: &Path,
) -> Result<RelationErrors, EvalError> {
    let file = std::fs::File::open(relations_path).map_err(|source| EvalError::Io {
        path: relations_path.display().to_string(),
        source,
    })?;
    let relations = read_relations(std::io::BufReader::new(file))?;
    let errors = evaluate(trajectory, &relations);
    if errors.used == 0 {
        return Err(EvalError::NothingMatched {
            missing: errors.missing,
        });
    }
    Ok(errors)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    /// A trajectory along a curve and its exact relations.
    fn ground_truth() -> Vec<(f64, Pose2)> {
        (0..50)
            .map(|k| {
                let t = 100.0 + 0.2 * k as f64;
                let th = 0.05 * k as f64;
                (t, Pose2::new(3.0 * th.sin(), 2.0 * (1.0 - th.cos()), th))
            })
            .collect()
    }

    fn relations_of(traj: &[(f64, Pose2)], pairs: &[(usize, usize)]) -> Vec<Relation> {
        pairs
            .iter()
            .map(|&(i, j)| Relation {
                t1: traj[i].0,
                t2: traj[j].0,
                delta: traj[i].1.between(&traj[j].1),
            })
            .collect()
    }

    #[test]
    fn exact_trajectory_in_another_frame_has_zero_error() {
        let gt = ground_truth();
        let rel = relations_of(&gt, &[(0, 1), (3, 7), (10, 40), (49, 2)]);
        let frame = Pose2::new(500.0, -20.0, 2.0);
        let moved: Vec<_> = gt.iter().map(|(t, p)| (*t, frame.compose(p))).collect();
        let e = evaluate(&moved, &rel);
        assert_eq!((e.used, e.missing), (4, 0));
        assert!(e.translation_m.max < 1e-9 && e.rotation_deg.max < 1e-9);
    }

    #[test]
    fn constant_offset_per_relation_is_measured() {
        // Each estimated step overshoots the reference by 0.1 m along the
        // t1 heading: every relation's translational error is 0.1 m.
        let gt = ground_truth();
        let pairs: Vec<(usize, usize)> = (0..49).map(|k| (k, k + 1)).collect();
        let rel = relations_of(&gt, &pairs);
        let mut est = vec![gt[0]];
        for r in &rel {
            let last = est.last().unwrap().1;
            let step = Pose2::new(r.delta.x + 0.1, r.delta.y, r.delta.theta);
            est.push((r.t2, last.compose(&step)));
        }
        let e = evaluate(&est, &rel);
        assert_eq!(e.used, 49);
        assert!((e.translation_m.mean - 0.1).abs() < 1e-9, "{e:?}");
        assert!(e.translation_m.std_dev < 1e-9);
        assert!((e.translation_sq_m2.mean - 0.01).abs() < 1e-9);
        // The steps are 0.2 s apart, all local; a relation over 8 s sums
        // forty of those errors and is global.
        assert_eq!(e.local_used, 49);
        assert!((e.local_translation_m.mean - 0.1).abs() < 1e-9);
        let mut with_long = rel.clone();
        with_long.extend(relations_of(&gt, &[(0, 40)]));
        let e = evaluate(&est, &with_long);
        assert_eq!((e.used, e.local_used), (50, 49));
        assert!(e.global_translation_m.mean > 1.0, "{e:?}");
        assert!((e.local_translation_m.mean - 0.1).abs() < 1e-9);
        assert!(e.rotation_deg.max < 1e-9);
    }

    #[test]
    fn rotation_error_is_wrapped_and_in_degrees() {
        let r = Relation {
            t1: 0.0,
            t2: 1.0,
            delta: Pose2::new(0.0, 0.0, 3.1),
        };
        let traj = [(0.0, Pose2::IDENTITY), (1.0, Pose2::new(0.0, 0.0, -3.1))];
        let e = evaluate(&traj, &[r]);
        let want = (2.0 * std::f64::consts::PI - 6.2).to_degrees();
        assert!((e.rotation_deg.mean - want).abs() < 1e-9, "{e:?}");
    }

    #[test]
    fn times_match_within_tolerance_only() {
        let traj = [
            (10.000_004, Pose2::IDENTITY),
            (10.5, Pose2::new(1.0, 0.0, 0.0)),
        ];
        let ok = Relation {
            t1: 10.0,
            t2: 10.50001,
            delta: Pose2::new(1.0, 0.0, 0.0),
        };
        let off = Relation { t2: 10.6, ..ok };
        let e = evaluate(&traj, &[ok, off]);
        assert_eq!((e.used, e.missing), (1, 1));
        assert!(e.translation_m.mean < 1e-12);
    }

    #[test]
    fn parses_relation_lines_and_reports_bad_ones() {
        let text =
            "1134864645.90321 1134864646.32420 0.31293 0.02935 0.00000  0.00000 0.00000 0.24198\n";
        let r = read_relations(text.as_bytes()).unwrap();
        assert_eq!(r.len(), 1);
        assert_eq!(r[0].delta, Pose2::new(0.31293, 0.02935, 0.24198));
        let bad = format!("{text}1 2 3\n");
        assert!(matches!(
            read_relations(bad.as_bytes()),
            Err(EvalError::Malformed { line: 2, .. })
        ));
    }

    #[test]
    fn stats_use_sample_standard_deviation() {
        let s = ErrorStats::of(&[1.0, 2.0, 3.0]);
        assert_eq!((s.mean, s.std_dev, s.max), (2.0, 1.0, 3.0));
        assert_eq!(ErrorStats::of(&[]), ErrorStats::default());
    }
}
