//! [`Checkpoint`]: a snapshot of the map and the new poses, written off
//! the loop.
//!
//! Taking the snapshot is quick (a copy of the walls and the CLS map; the
//! keyframes are shared, not copied); writing it — JSON,
//! the picture, fsyncs on an SD card — can take long enough to starve the
//! loop, so the daemon writes it on a blocking thread while the loop goes
//! on. Poses of a checkpoint that could not be written come back in the
//! error and are written with the next one, so none is lost.
//!
//! The poses go to two files: [`ANCHORED_TRAJECTORY_FILE`], each pose in
//! its keyframe's frame, the record; and [`TRAJECTORY_FILE`], the same
//! poses in the map frame for other tools, derived from it. New poses are
//! appended to both; when loop closures moved the keyframes since the last
//! checkpoint, the TUM file is rebuilt from the record whole, so every
//! pose in it is in the corrected frame, not only the ones still held.

use std::fs::File;
use std::io::{BufRead as _, BufReader, BufWriter, Write as _};
use std::path::{Path, PathBuf};

use tracing::{info, warn};

use crate::files::trajectory::{
    ANCHORED_HEADER, AnchoredPose, StampedPose, TUM_HEADER, TrajectoryError, read_anchored,
    write_anchored_lines, write_tum_lines,
};
use crate::geometry::Pose2;
use crate::map::MapContents;
use crate::pipeline::{PipelineError, TRAJECTORY_FILE, create_output_dir, write_maps};

/// The trajectory's record, each pose anchored to its keyframe (see
/// [`AnchoredPose`]), beside [`TRAJECTORY_FILE`].
pub const ANCHORED_TRAJECTORY_FILE: &str = "trajectory.anchors";

/// Everything one checkpoint writes.
#[derive(Debug, Clone)]
pub struct Checkpoint {
    pub dir: PathBuf,
    /// Poses since the last checkpoint written, appended to the trajectory.
    pub trajectory: Vec<AnchoredPose>,
    /// The keyframes' poses now (map frame), which put the anchored poses
    /// in the map frame.
    pub keyframe_poses: Vec<Pose2>,
    /// Whether loop closures moved the keyframes since the trajectory
    /// files were last written: the TUM file is then rebuilt whole.
    pub reframed: bool,
    /// The map as [`crate::map::file`] stores it; none when it did not
    /// change (localizing in a loaded map): the poses only.
    pub map: Option<MapContents>,
    /// The path drawn on the picture.
    pub path: Vec<Pose2>,
}

/// A checkpoint that could not be written, with its poses to keep.
#[derive(Debug)]
pub struct CheckpointFailed {
    pub error: PipelineError,
    pub trajectory: Vec<AnchoredPose>,
}

impl Checkpoint {
    /// Appends the poses to the trajectory files (and syncs them), or
    /// rebuilds the TUM file when the keyframes moved, then rewrites the
    /// maps and the picture, each atomically, when the checkpoint holds
    /// them: a crash mid-write leaves the previous checkpoint whole.
    pub fn write(self) -> Result<(), CheckpointFailed> {
        let fail = |error: PipelineError, trajectory: Vec<AnchoredPose>| CheckpointFailed {
            error,
            trajectory,
        };
        if let Err(e) = create_output_dir(&self.dir) {
            return Err(fail(e, self.trajectory));
        }
        if let Err(error) = self.write_trajectory() {
            return Err(fail(error, self.trajectory));
        }
        // The poses are on disk now; a failure below keeps none back.
        match &self.map {
            Some(map) => {
                write_maps(&self.dir, map, &self.path, &[]).map_err(|e| fail(e, Vec::new()))
            }
            None => Ok(()),
        }
    }

    fn write_trajectory(&self) -> Result<(), PipelineError> {
        let record = self.dir.join(ANCHORED_TRAJECTORY_FILE);
        let tum = self.dir.join(TRAJECTORY_FILE);
        let output = |path: &Path| {
            let path = path.to_owned();
            move |source| PipelineError::Output { path, source }
        };
        let in_map: Vec<StampedPose> = self
            .trajectory
            .iter()
            .map(|a| {
                a.in_map(&self.keyframe_poses)
                    .map(|p| (a.t, p))
                    .ok_or_else(|| unknown_keyframe(a, self.keyframe_poses.len()))
            })
            .collect::<std::io::Result<_>>()
            .map_err(output(&tum))?;
        let tum_lines = if self.reframed {
            pose_lines(&tum).map_err(output(&tum))?
        } else {
            0
        };
        let record_len = append(&record, ANCHORED_HEADER, |out| {
            write_anchored_lines(out, &self.trajectory)
        })
        .map_err(output(&record))?;
        let tum_written = if self.reframed {
            rebuild_tum(
                &tum,
                &record,
                &self.keyframe_poses,
                tum_lines + in_map.len(),
            )
        } else {
            Ok(false)
        }
        .and_then(|rebuilt| {
            if rebuilt {
                Ok(0)
            } else {
                append(&tum, TUM_HEADER, |out| write_tum_lines(out, &in_map))
            }
        });
        if let Err(source) = tum_written {
            // Neither file keeps the poses, which go back to the caller.
            let _ = cut_back(&record, record_len);
            return Err(PipelineError::Output { path: tum, source });
        }
        Ok(())
    }
}

fn unknown_keyframe(a: &AnchoredPose, keyframes: usize) -> std::io::Error {
    std::io::Error::other(format!(
        "the pose at {:.6} s hangs on keyframe {:?} of {keyframes}",
        a.t, a.keyframe
    ))
}

/// Appends what `write` writes to the file at `path` (created with
/// `header` if new) and syncs it; returns the file's old length. On
/// failure the file is cut back to it, so the poses, handed back to the
/// caller, are neither half written nor written twice by the next
/// checkpoint.
fn append(
    path: &Path,
    header: &str,
    write: impl FnOnce(&mut Vec<u8>) -> Result<(), TrajectoryError>,
) -> std::io::Result<u64> {
    let mut file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)?;
    let old_len = file.metadata()?.len();
    let mut text = Vec::new();
    if old_len == 0 {
        text.extend_from_slice(header.as_bytes());
        text.push(b'\n');
    }
    write(&mut text).map_err(std::io::Error::other)?;
    let written = file.write_all(&text).and_then(|()| file.sync_data());
    if written.is_err() {
        let _ = file.set_len(old_len);
    }
    written.map(|()| old_len)
}

fn cut_back(path: &Path, len: u64) -> std::io::Result<()> {
    let file = std::fs::OpenOptions::new().write(true).open(path)?;
    file.set_len(len)?;
    file.sync_data()
}

/// Pose lines (not comments, not blank) of the text file at `path`; none
/// if there is no file.
fn pose_lines(path: &Path) -> std::io::Result<usize> {
    let file = match File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(0),
        Err(e) => return Err(e),
    };
    let mut count = 0;
    for line in BufReader::new(file).lines() {
        let line = line?;
        let body = line.trim();
        count += usize::from(!body.is_empty() && !body.starts_with('#'));
    }
    Ok(count)
}

/// Rewrites the TUM file at `tum` atomically from the anchored record at
/// `record`, with the keyframes at `keyframe_poses`, streaming (an hour's
/// record is tens of megabytes). Returns false, leaving the TUM file as it
/// is, when the record does not hold the `expected` poses the TUM file
/// would (a record cut short or removed by hand): its poses would be lost.
fn rebuild_tum(
    tum: &Path,
    record: &Path,
    keyframe_poses: &[Pose2],
    expected: usize,
) -> std::io::Result<bool> {
    let started = std::time::Instant::now();
    // Counted while streaming; a count that does not match fails the write,
    // so the temporary file is dropped and the TUM file kept.
    let mut anchored = None;
    let written = crate::files::durable::write_atomically_with(tum, |out| {
        let mut out = BufWriter::new(out);
        writeln!(out, "{TUM_HEADER}")?;
        let input = BufReader::new(File::open(record)?);
        let count = read_anchored(input, |a| {
            let pose = a
                .in_map(keyframe_poses)
                .ok_or_else(|| unknown_keyframe(&a, keyframe_poses.len()))?;
            write_tum_lines(&mut out, &[(a.t, pose)])
        })
        .map_err(std::io::Error::other)?;
        anchored = Some(count);
        if count != expected {
            return Err(std::io::Error::other("the record does not match"));
        }
        out.flush()
    });
    match (written, anchored) {
        (Ok(()), _) => {
            info!(
                poses = expected,
                ms = started.elapsed().as_secs_f64() * 1e3,
                "trajectory rewritten in the corrected frame"
            );
            Ok(true)
        }
        (Err(_), Some(anchored)) if anchored != expected => {
            warn!(
                record = %record.display(),
                anchored,
                expected,
                "the trajectory's record does not match {}: its poses stay in the frame they were written in",
                tum.display()
            );
            Ok(false)
        }
        (Err(e), _) => Err(e),
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::files::trajectory::read_tum;

    fn checkpoint(dir: &Path, poses: &[(f64, usize)], keyframes: &[Pose2], reframed: bool) {
        Checkpoint {
            dir: dir.to_owned(),
            trajectory: poses
                .iter()
                .map(|&(t, k)| AnchoredPose {
                    t,
                    keyframe: Some(k),
                    pose: Pose2::new(0.5, 0.0, 0.0),
                })
                .collect(),
            keyframe_poses: keyframes.to_vec(),
            reframed,
            map: None,
            path: Vec::new(),
        }
        .write()
        .unwrap();
    }

    fn xs(dir: &Path) -> Vec<f64> {
        let text = std::fs::read_to_string(dir.join(TRAJECTORY_FILE)).unwrap();
        read_tum(text.as_bytes())
            .unwrap()
            .iter()
            .map(|(_, p)| p.x)
            .collect()
    }

    #[test]
    fn moved_keyframes_move_every_pose_written_and_later_ones_are_appended() {
        let dir = tempfile::tempdir().unwrap();
        let at = |x0: f64, x1: f64| [Pose2::new(x0, 0.0, 0.0), Pose2::new(x1, 0.0, 0.0)];
        checkpoint(dir.path(), &[(1.0, 0), (2.0, 1)], &at(0.0, 1.0), false);
        assert_eq!(xs(dir.path()), [0.5, 1.5]);
        // A loop closure moved keyframe 1 by 0.25 m.
        checkpoint(dir.path(), &[(3.0, 1)], &at(0.0, 1.25), true);
        assert_eq!(xs(dir.path()), [0.5, 1.75, 1.75]);
        checkpoint(dir.path(), &[(4.0, 1)], &at(0.0, 1.25), false);
        assert_eq!(xs(dir.path()), [0.5, 1.75, 1.75, 1.75]);
        let record = std::fs::read_to_string(dir.path().join(ANCHORED_TRAJECTORY_FILE)).unwrap();
        assert_eq!(record.lines().count(), 5, "{record}");
    }

    #[test]
    fn a_record_that_lost_poses_never_costs_the_trajectory_any() {
        let dir = tempfile::tempdir().unwrap();
        let keyframes = [Pose2::IDENTITY];
        checkpoint(dir.path(), &[(1.0, 0), (2.0, 0)], &keyframes, false);
        std::fs::remove_file(dir.path().join(ANCHORED_TRAJECTORY_FILE)).unwrap();
        checkpoint(dir.path(), &[(3.0, 0)], &[Pose2::new(1.0, 0.0, 0.0)], true);
        // Left in the frame they were written in, the new one appended.
        assert_eq!(xs(dir.path()), [0.5, 0.5, 1.5]);
    }

    #[test]
    fn a_pose_on_an_unknown_keyframe_is_refused_and_handed_back() {
        let dir = tempfile::tempdir().unwrap();
        let failed = Checkpoint {
            dir: dir.path().to_owned(),
            trajectory: vec![AnchoredPose {
                t: 1.0,
                keyframe: Some(3),
                pose: Pose2::IDENTITY,
            }],
            keyframe_poses: vec![Pose2::IDENTITY],
            reframed: false,
            map: None,
            path: Vec::new(),
        }
        .write()
        .unwrap_err();
        assert_eq!(failed.trajectory.len(), 1);
        assert!(!dir.path().join(ANCHORED_TRAJECTORY_FILE).exists());
    }
}
