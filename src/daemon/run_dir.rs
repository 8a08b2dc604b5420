//! Where a run's maps go: its own directory under the state directory
//! (made at the first checkpoint), and rescue directories when that one
//! cannot be written at the end.

use std::path::{Path, PathBuf};

use tracing::{error, info};

use super::checkpoint::ANCHORED_TRAJECTORY_FILE;
use super::core::Core;
use super::runtime::DaemonError;
use crate::error_chain;
use crate::pipeline::TRAJECTORY_FILE;

/// A name for a run's directory: `run-YYYYmmddTHHMMSSZ-<pid>` (UTC; the
/// process id keeps names apart on a robot whose clock restarts at the
/// same time after every boot).
fn dir_name(prefix: &str) -> String {
    let stamp = humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string();
    let compact: String = stamp.chars().filter(|c| !matches!(c, '-' | ':')).collect();
    format!("{prefix}-{compact}-{}", std::process::id())
}

/// A new directory below `parent`, never an existing one.
fn new_dir(parent: &Path, prefix: &str) -> std::io::Result<PathBuf> {
    std::fs::create_dir_all(parent)?;
    let base = dir_name(prefix);
    for k in 0..10_000 {
        let dir = parent.join(if k == 0 {
            base.clone()
        } else {
            format!("{base}-{k}")
        });
        match std::fs::create_dir(&dir) {
            Ok(()) => return Ok(dir),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
            Err(e) => return Err(e),
        }
    }
    Err(std::io::Error::new(
        std::io::ErrorKind::AlreadyExists,
        "every run directory name is taken",
    ))
}

/// Fails early, before the sensor is touched, when `dir` cannot be
/// written: a map that cannot be saved is worse than no start.
fn check_writable(dir: &Path) -> Result<(), DaemonError> {
    let fail = |source| DaemonError::OutputDir {
        path: dir.to_owned(),
        source,
    };
    std::fs::create_dir_all(dir).map_err(fail)?;
    crate::files::durable::check_writable(dir).map_err(fail)
}

/// The run's directory (given, or made on first use under the state
/// directory) and where to rescue a map that cannot go there.
#[derive(Debug)]
pub struct RunDirs {
    state_dir: PathBuf,
    out_dir: Option<PathBuf>,
}

impl RunDirs {
    /// Checks that the maps can be written: into `out_dir` when given,
    /// else into a new directory under `state_dir`.
    pub fn new(state_dir: PathBuf, out_dir: Option<PathBuf>) -> Result<RunDirs, DaemonError> {
        check_writable(out_dir.as_deref().unwrap_or(&state_dir))?;
        Ok(RunDirs { state_dir, out_dir })
    }

    /// The run's directory, made on first use (a run that never saw a scan
    /// leaves no empty directory behind).
    pub fn out_dir(&mut self) -> std::io::Result<PathBuf> {
        if let Some(dir) = &self.out_dir {
            return Ok(dir.clone());
        }
        let dir = new_dir(&self.state_dir, "run")?;
        info!(dir = %dir.display(), "maps of this run are saved here");
        self.out_dir = Some(dir.clone());
        Ok(dir)
    }

    /// Saves `core`'s map into the run's directory; if that fails, into a
    /// rescue directory in the state directory, then in its parent. Returns where it went and, if rescued, why.
    pub fn save(
        &mut self,
        core: &mut Core,
    ) -> Result<(Option<PathBuf>, Option<String>), DaemonError> {
        if core.live().scans() == 0 {
            info!("no scan was mapped: nothing to save");
            return Ok((None, None));
        }
        let first = match self.out_dir() {
            Ok(dir) => match core.checkpoint(&dir) {
                Ok(()) => return Ok((Some(dir), None)),
                Err(e) => format!("{}: {}", dir.display(), error_chain(&e)),
            },
            Err(e) => format!("{}: {e}", self.state_dir.display()),
        };
        error!("cannot save the map in {first}");
        let mut tried = vec![first.clone()];
        // Beside the run's directory, then beside the state directory: not
        // under $TMPDIR, which the unit's PrivateTmp= empties at stop.
        let mut parents = vec![self.state_dir.clone()];
        if let Some(up) = self
            .state_dir
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
        {
            parents.push(up.to_path_buf());
        }
        let earlier = self.out_dir.clone();
        for parent in parents {
            let rescue = match new_dir(&parent, "rescue") {
                Ok(dir) => dir,
                Err(e) => {
                    tried.push(format!("{}: {e}", parent.display()));
                    continue;
                }
            };
            // The rescue is whole: the poses the run's directory holds
            // already come first, then the ones not written yet.
            let copied = [TRAJECTORY_FILE, ANCHORED_TRAJECTORY_FILE]
                .iter()
                .filter_map(|name| Some((earlier.as_ref()?.join(name), rescue.join(name))))
                .filter(|(from, _)| from.is_file())
                .try_for_each(|(from, to)| std::fs::copy(from, to).map(|_| ()));
            match copied
                .map_err(|e| e.to_string())
                .and_then(|()| core.checkpoint(&rescue).map_err(|e| error_chain(&e)))
            {
                Ok(()) => {
                    error!(dir = %rescue.display(), "map saved to a rescue directory instead");
                    return Ok((Some(rescue), Some(first)));
                }
                Err(e) => {
                    tried.push(format!("{}: {e}", rescue.display()));
                    // Nothing half-written is left behind.
                    let _ = std::fs::remove_dir_all(&rescue);
                }
            }
        }
        Err(DaemonError::Save {
            tried: tried.join("; "),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_directory_is_named_by_its_utc_start_and_process() {
        let name = dir_name("run");
        let rest = name.strip_prefix("run-").expect("prefix");
        let (stamp, pid) = rest.split_once("Z-").expect("stamp and pid");
        // YYYYmmddTHHMMSS
        assert_eq!(stamp.len(), 15, "{name}");
        assert_eq!(&stamp[8..9], "T", "{name}");
        assert!(stamp[..8].chars().all(|c| c.is_ascii_digit()), "{name}");
        assert_eq!(pid, std::process::id().to_string());
    }

    #[test]
    fn new_directories_never_reuse_a_name() {
        let parent = tempfile::tempdir().expect("tempdir");
        let a = new_dir(parent.path(), "run").expect("first");
        let b = new_dir(parent.path(), "run").expect("second");
        assert_ne!(a, b);
        assert!(a.is_dir() && b.is_dir());
    }
}
