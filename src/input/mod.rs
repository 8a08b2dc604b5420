//! Offline inputs: logs turned into a stream of scans with the odometry
//! pose at each scan.
//!
//! Every reader yields [`ScanRecord`]s through the [`LogSource`] iterator
//! interface, so the mapping pipeline does not care whether scans come from
//! a CARMEN log or an LMS200 telegram recording.
//!
//! One policy for bad input in both: an item that cannot be used (a
//! malformed line, an odometry sample that is not finite or goes back in
//! time, a damaged recording record, a scan not after the previous one) is
//! yielded as an error for which [`InputError::is_skipped_item`] holds, and
//! the reader goes on with the next; the caller counts and reports them,
//! or stops at the first (`--strict`). Other errors end the input.

pub mod bag;
pub mod carmen;
pub mod lms200;
pub mod odometry;

pub use bag::{BagOdometry, BagScans, BagTopics};
pub use carmen::{CarmenEntry, CarmenScans, MalformedLine, NO_RETURN_RANGE};
pub use odometry::{OdometryError, OdometryTrack};

use crate::geometry::{Pose2, RangeScan};
use std::cell::Cell;
use std::fs::File;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::rc::Rc;
use thiserror::Error;

/// How a log says its laser sits on the robot.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DeclaredMount {
    /// It gives no laser pose apart from the robot's.
    None,
    /// One pose of the laser in the robot frame (m, rad).
    Fixed(Pose2),
    /// Poses that disagree, or a laser that does not scan the robot's
    /// plane (tilted, upside down): no planar mounting to read.
    Varying,
}

/// One scan and the odometry pose (odometry frame, m/rad) at the scan's
/// time, if the source has odometry.
#[derive(Debug, Clone, PartialEq)]
pub struct ScanRecord {
    pub scan: RangeScan,
    pub odometry: Option<Pose2>,
}

/// Why an input could not be read. Line numbers are 1-based.
#[derive(Debug, Error)]
pub enum InputError {
    #[error("cannot open {}", path.display())]
    Open {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("read failed at line {line}")]
    Read {
        line: usize,
        #[source]
        source: std::io::Error,
    },
    #[error("line {line}: {kind}")]
    Malformed { line: usize, kind: MalformedLine },
    #[error("line {line}: {error}")]
    Odometry { line: usize, error: OdometryError },
    #[error(transparent)]
    Recording(#[from] ::lms200::recording::RecordingError),
    #[error("recording byte {offset}: {error}")]
    RecordingOdometry { offset: u64, error: OdometryError },
    #[error("{at}: scan time {t} s is not after the previous scan's {previous} s")]
    ScanOutOfOrder { at: String, t: f64, previous: f64 },
    #[error(transparent)]
    Bag(#[from] crate::ros2::bag::BagError),
    #[error("the bag has no topic {topic} ({type_name}): {available}")]
    MissingTopic {
        topic: String,
        type_name: &'static str,
        available: String,
    },
    #[error("topic {topic} is {found}, not {expected}")]
    TopicType {
        topic: String,
        found: String,
        expected: &'static str,
    },
    #[error("{topic} message at {log_time} ns does not decode")]
    BagMessage {
        topic: String,
        log_time: u64,
        #[source]
        error: crate::ros2::CdrError,
    },
    #[error("{at}: {error}")]
    BagOdometry { at: String, error: OdometryError },
}

impl InputError {
    /// Whether the reader skipped just the item this error names and goes
    /// on (a malformed line, a bad odometry sample, a damaged recording
    /// record, a scan out of time order), as opposed to an error that ends
    /// the input.
    pub fn is_skipped_item(&self) -> bool {
        use ::lms200::recording::RecordingError;
        matches!(
            self,
            InputError::Malformed { .. }
                | InputError::Odometry { .. }
                | InputError::RecordingOdometry { .. }
                | InputError::ScanOutOfOrder { .. }
                | InputError::Recording(RecordingError::Damaged { .. })
                | InputError::BagMessage { .. }
                | InputError::BagOdometry { .. }
        )
    }

    /// Whether the input broke off here (a recording or a bag cut short
    /// or damaged), so that what came before it can still be used.
    pub fn is_break(&self) -> bool {
        use crate::ros2::bag::BagError;
        matches!(
            self,
            InputError::Recording(_)
                | InputError::Bag(BagError::EndsEarly { .. } | BagError::Damaged { .. })
        )
    }
}

/// A stream of scans with odometry; implemented by every reader.
pub trait LogSource: Iterator<Item = Result<ScanRecord, InputError>> {}

impl<T: Iterator<Item = Result<ScanRecord, InputError>>> LogSource for T {}

/// A log file being streamed, with how far the reading has got (for a
/// progress bar).
pub struct LogFile {
    scans: Box<dyn LogSource>,
    bytes_read: Rc<Cell<u64>>,
    size: u64,
}

impl std::fmt::Debug for LogFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LogFile")
            .field("bytes_read", &self.bytes_read.get())
            .field("size", &self.size)
            .finish_non_exhaustive()
    }
}

/// Counts the bytes that pass through a reader.
struct CountingReader<R> {
    inner: R,
    count: Rc<Cell<u64>>,
}

impl<R: Read> Read for CountingReader<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.count.set(self.count.get() + n as u64);
        Ok(n)
    }
}

/// How logs are read: for a bag, which of its topics.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct LogOptions {
    pub bag: BagTopics,
}

impl LogFile {
    /// Opens a log for streaming: an LMS200 recording (by its signature),
    /// a rosbag2 MCAP bag (by its signature, or a bag directory) or a
    /// CARMEN text log.
    pub fn open(path: &Path) -> Result<LogFile, InputError> {
        Self::open_with(path, &LogOptions::default())
    }

    /// [`open`](Self::open) with a bag's topics chosen.
    pub fn open_with(path: &Path, options: &LogOptions) -> Result<LogFile, InputError> {
        let open_error = |source| InputError::Open {
            path: path.to_owned(),
            source,
        };
        let Some((kind, file)) = log_kind(path)? else {
            return Self::open_bag(path, options);
        };
        let size = file.metadata().map_err(open_error)?.len();
        let is_recording = kind == LogKind::Recording;
        let bytes_read = Rc::new(Cell::new(0));
        let reader = BufReader::new(CountingReader {
            inner: file,
            count: Rc::clone(&bytes_read),
        });
        let scans: Box<dyn LogSource> = if is_recording {
            Box::new(lms200::RecordingScans::new(reader)?)
        } else {
            Box::new(CarmenScans::new(reader))
        };
        Ok(LogFile {
            scans,
            bytes_read,
            size,
        })
    }

    fn open_bag(path: &Path, options: &LogOptions) -> Result<LogFile, InputError> {
        let size = crate::ros2::bag::bag_files(path)?
            .iter()
            .filter_map(|p| std::fs::metadata(p).ok())
            .map(|m| m.len())
            .sum();
        let bytes_read = Rc::new(Cell::new(0));
        let scans =
            BagScans::open(path, options.bag.clone())?.with_progress(Rc::clone(&bytes_read));
        Ok(LogFile {
            scans: Box::new(scans),
            bytes_read,
            size,
        })
    }

    /// Bytes consumed from the file so far (read ahead by the buffer).
    pub fn bytes_read(&self) -> u64 {
        self.bytes_read.get()
    }

    /// Size of the file (bytes).
    pub fn size(&self) -> u64 {
        self.size
    }
}

impl Iterator for LogFile {
    type Item = Result<ScanRecord, InputError>;

    fn next(&mut self) -> Option<Self::Item> {
        self.scans.next()
    }
}

/// A log file that is not a bag.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum LogKind {
    Recording,
    Carmen,
}

/// What the log at `path` is, with its file opened at the start; `None`
/// for a bag (a directory, an SQLite `.db3`, or an MCAP file). A recording
/// and a bag start with their signatures; anything else is read as a
/// CARMEN text log, which names the first line it cannot parse.
fn log_kind(path: &Path) -> Result<Option<(LogKind, File)>, InputError> {
    let open_error = |source| InputError::Open {
        path: path.to_owned(),
        source,
    };
    if path.is_dir() || path.extension().is_some_and(|e| e == "db3") {
        return Ok(None);
    }
    let mut file = File::open(path).map_err(open_error)?;
    let mut head = [0u8; 8];
    let head_read = file.read_exact(&mut head).is_ok();
    if head_read && &head == b"\x89MCAP0\r\n" {
        return Ok(None);
    }
    let kind = if head_read && head[..7] == ::lms200::recording::MAGIC[..7] {
        LogKind::Recording
    } else {
        LogKind::Carmen
    };
    file.seek(SeekFrom::Start(0)).map_err(open_error)?;
    Ok(Some((kind, file)))
}

/// How the log at `path` says its laser sits on the robot: a CARMEN log
/// by its laser lines ([`carmen::declared_laser_mount`]), a bag by its
/// `/tf_static` ([`bag::declared_laser_mount`], with `options`' topics); a
/// recording declares none.
pub fn declared_laser_mount(
    path: &Path,
    options: &LogOptions,
) -> Result<DeclaredMount, InputError> {
    Ok(match log_kind(path)? {
        Some((LogKind::Carmen, file)) => carmen::declared_laser_mount(BufReader::new(file)),
        Some((LogKind::Recording, _)) => DeclaredMount::None,
        None => bag::declared_laser_mount(path, &options.bag)?,
    })
}

/// The range (m) the log at `path` writes for a beam without an echo, where
/// it writes one other than the SICK codes (see
/// [`carmen::repeated_no_return`]); recordings and bags mark those beams
/// themselves.
pub fn no_return_code(path: &Path) -> Result<Option<f64>, InputError> {
    Ok(match log_kind(path)? {
        Some((LogKind::Carmen, file)) => carmen::repeated_no_return(BufReader::new(file)),
        _ => None,
    })
}

/// Scans read for [`wall_scatter`]: a few minutes of a log.
const SCATTER_SCANS: usize = 2000;

/// The range noise the log at `path` shows over its first
/// `SCATTER_SCANS` scans ([`crate::geometry::wall_scatter`]); scans that
/// cannot be read are passed over here (the mapping names them).
pub fn wall_scatter(
    path: &Path,
    options: &LogOptions,
) -> Result<Option<crate::geometry::WallScatter>, InputError> {
    let scans = open_log_with(path, options)?
        .filter_map(Result::ok)
        .take(SCATTER_SCANS)
        .map(|record| record.scan);
    Ok(crate::geometry::wall_scatter(scans))
}

/// Opens a log file for streaming; see [`LogFile::open`].
pub fn open_log(path: &Path) -> Result<LogFile, InputError> {
    LogFile::open(path)
}

/// Opens a log file for streaming with `options`; see [`LogFile::open_with`].
pub fn open_log_with(path: &Path, options: &LogOptions) -> Result<LogFile, InputError> {
    LogFile::open_with(path, options)
}
