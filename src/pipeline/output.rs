//! The files a run writes into its directory, each atomically: the
//! trajectory, the map and its picture, and a log's own odometry.

use std::path::Path;

use super::{Mapper, PipelineError};
use crate::files::trajectory::{StampedPose, write_tum};
use crate::geometry::Pose2;
use crate::map::MapContents;
use crate::render::{SegmentStyle, picture};

/// Name of the trajectory written by [`write_outputs`].
pub const TRAJECTORY_FILE: &str = "trajectory.tum";
/// Name of the map written by [`write_outputs`] (see
/// [`crate::map::file`]).
pub const MAP_FILE: &str = "map.json";
/// Name of the map's picture written by [`write_outputs`].
pub const PICTURE_FILE: &str = "map.svg";
/// Name of the log's own odometry at each mapped scan, written by
/// [`write_odometry`]: the baseline the mapped trajectory is judged
/// against.
pub const ODOMETRY_FILE: &str = "odometry.tum";

/// Writes `poses` to `path` in TUM format, atomically.
fn write_tum_file(path: &Path, poses: &[StampedPose]) -> Result<(), PipelineError> {
    let mut tum = Vec::new();
    write_tum(&mut tum, poses)?;
    write_file(path, &tum)
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<(), PipelineError> {
    crate::files::durable::write_atomically(path, bytes).map_err(|source| PipelineError::Output {
        path: path.to_owned(),
        source,
    })
}

/// Writes what a mapper built into `out_dir` (created if needed), each
/// file atomically: the trajectory ([`TRAJECTORY_FILE`]), the map
/// ([`MAP_FILE`]: CLS map, walls, keyframes, pose graph) and its picture
/// with the trajectory ([`PICTURE_FILE`]).
pub fn write_outputs(
    out_dir: &Path,
    mapper: &Mapper,
    draw_loops: bool,
) -> Result<(), PipelineError> {
    create_output_dir(out_dir)?;
    let trajectory = mapper.smoothed_trajectory();
    write_tum_file(&out_dir.join(TRAJECTORY_FILE), &trajectory)?;
    let poses: Vec<Pose2> = trajectory.iter().map(|(_, p)| *p).collect();
    let loops = if draw_loops {
        mapper.loop_edges()
    } else {
        Vec::new()
    };
    write_maps(out_dir, &mapper.contents(), &poses, &loops)
}

/// Writes `odometry` (the log's odometry at each mapped scan, TUM) into
/// `out_dir` as [`ODOMETRY_FILE`], atomically. Without odometry a file
/// left there by an earlier run is removed, so it is never taken for this
/// log's.
pub fn write_odometry(out_dir: &Path, odometry: &[StampedPose]) -> Result<(), PipelineError> {
    let path = out_dir.join(ODOMETRY_FILE);
    if odometry.is_empty() {
        return match std::fs::remove_file(&path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                Err(PipelineError::Output { path, source: e })
            }
            _ => Ok(()),
        };
    }
    write_tum_file(&path, odometry)
}

/// Creates `out_dir` and its parents if needed.
pub fn create_output_dir(out_dir: &Path) -> Result<(), PipelineError> {
    std::fs::create_dir_all(out_dir).map_err(|source| PipelineError::Output {
        path: out_dir.to_owned(),
        source,
    })
}

/// Writes the map into `out_dir`, each file atomically: [`MAP_FILE`]
/// (see [`crate::map::file`]) and its picture ([`PICTURE_FILE`]) with
/// `path` (and the loop closures `loops`, each from one keyframe position
/// to another) drawn on it.
pub fn write_maps(
    out_dir: &Path,
    contents: &MapContents,
    path: &[Pose2],
    loops: &[[[f64; 2]; 2]],
) -> Result<(), PipelineError> {
    crate::map::file::save(&out_dir.join(MAP_FILE), contents)?;
    let mut pic = picture(&contents.cls, Some(path), path.last().copied());
    for [a, b] in loops {
        pic.segment(*a, *b, SegmentStyle::LoopEdge);
    }
    write_file(&out_dir.join(PICTURE_FILE), pic.to_svg().as_bytes())
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn odometry_is_written_and_a_stale_file_removed_when_a_log_has_none() {
        let dir = std::env::temp_dir().join(format!("clsmap-odometry-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(ODOMETRY_FILE);
        let poses = [(1.0, Pose2::IDENTITY), (1.5, Pose2::new(0.2, 0.0, 0.1))];
        write_odometry(&dir, &poses).unwrap();
        let read = crate::files::trajectory::read_tum(std::io::BufReader::new(
            std::fs::File::open(&path).unwrap(),
        ))
        .unwrap();
        assert_eq!(read.len(), 2);
        assert!((read[1].1.theta - 0.1).abs() < 1e-9, "{read:?}");
        // The next run's log has no odometry: the old file must not stay
        // to be scored as this log's.
        write_odometry(&dir, &[]).unwrap();
        assert!(!path.exists());
        write_odometry(&dir, &[]).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
