//! [`Checkpoint`]: a snapshot of the map and the new poses, written off
//! the loop.
//!
//! Taking the snapshot is quick (a copy of the walls and the CLS map; the
//! keyframes are shared, not copied); writing it — JSON,
//! the picture, fsyncs on an SD card — can take long enough to starve the
//! loop, so the daemon writes it on a blocking thread while the loop goes
//! on. Poses of a checkpoint that could not be written come back in the
//! error and are written with the next one, so none is lost.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use crate::files::trajectory::{StampedPose, TUM_HEADER, write_tum_lines};
use crate::geometry::Pose2;
use crate::map::MapContents;
use crate::pipeline::{PipelineError, TRAJECTORY_FILE, create_output_dir, write_maps};

/// Everything one checkpoint writes.
#[derive(Debug, Clone)]
pub struct Checkpoint {
    pub dir: PathBuf,
    /// Poses since the last checkpoint written, appended to the trajectory.
    pub trajectory: Vec<StampedPose>,
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
    pub trajectory: Vec<StampedPose>,
}

impl Checkpoint {
    /// Appends the poses to [`TRAJECTORY_FILE`] (and syncs it), then
    /// rewrites the maps and the picture, each atomically, when the
    /// checkpoint holds them: a crash mid-write leaves the previous
    /// checkpoint whole.
    pub fn write(self) -> Result<(), CheckpointFailed> {
        let fail = |error: PipelineError, trajectory: Vec<StampedPose>| CheckpointFailed {
            error,
            trajectory,
        };
        if let Err(e) = create_output_dir(&self.dir) {
            return Err(fail(e, self.trajectory));
        }
        let file = self.dir.join(TRAJECTORY_FILE);
        if let Err(source) = append_tum(&file, &self.trajectory) {
            let error = PipelineError::Output { path: file, source };
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
}

/// Appends `poses` to the TUM file at `path` (created with its header if
/// new) and syncs it. On failure the file is cut back to its old length,
/// so the poses, handed back to the caller, are neither half written nor
/// written twice by the next checkpoint.
fn append_tum(path: &Path, poses: &[StampedPose]) -> std::io::Result<()> {
    let mut file = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(path)?;
    let old_len = file.metadata()?.len();
    let mut text = Vec::new();
    if old_len == 0 {
        text.extend_from_slice(TUM_HEADER.as_bytes());
        text.push(b'\n');
    }
    write_tum_lines(&mut text, poses).map_err(std::io::Error::other)?;
    let written = file.write_all(&text).and_then(|()| file.sync_data());
    if written.is_err() {
        let _ = file.set_len(old_len);
    }
    written
}
