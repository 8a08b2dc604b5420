//! The sensor reader: the blocking serial driver on its own thread.
//!
//! It never waits for the mapper: each scan replaces the one before it in a
//! one-slot mailbox (a `watch` channel), so a slow map update costs the
//! scans it overlapped — counted — and never a growing backlog of old ones.
//! Everything else the link reports goes through an unbounded channel (a
//! few events a minute). When the port cannot be opened or the driver
//! fails (unplugged, permission, I/O), the thread waits and tries again,
//! the wait doubling up to a limit; a silent sensor is re-initialised by
//! the link itself. On stop the driver closes the link: the sensor stops
//! streaming and returns to 9600 Bd.

use std::fs::OpenOptions;
use std::io::Write;
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use lms200::driver::SerialDriver;
use lms200::link::{Event, LinkConfig, TimedScan};
use tokio::sync::{mpsc, watch};
use tracing::{error, info, warn};

use crate::error_chain;
use crate::files::tee::Tee;

/// A scan in the mailbox, numbered so the reader of the mailbox can count
/// the scans it never saw.
#[derive(Debug, Clone)]
pub struct ScanSlot {
    pub seq: u64,
    pub scan: Arc<TimedScan>,
}

/// What the sensor thread reports besides scans.
#[derive(Debug, Clone)]
pub enum SensorReport {
    /// A link event other than a scan (connected, silent, restarted, …).
    Link(Event),
    /// The port could not be opened or the driver failed; the next try
    /// comes after `retry_in`.
    Failed { error: String, retry_in: Duration },
}

/// How the sensor thread runs.
#[derive(Debug, Clone)]
pub struct SensorOptions {
    pub port: PathBuf,
    pub link: LinkConfig,
    pub retry_initial: Duration,
    pub retry_max: Duration,
    /// Record the raw stream here (a new file per connection: `-1`, `-2`
    /// … are appended when the name exists).
    pub record: Option<PathBuf>,
    /// Record the raw stream into this buffer too (for the run's bag).
    pub raw: Option<RawTelegrams>,
    /// Records made on the loop (the base's odometry) for the recording.
    pub queued: Option<lms200::recording::RecordQueue>,
}

/// The recording of the serial stream (the `.rec` format) as it grows,
/// for a reader on another thread (the bag's `/lms200/recording`): all
/// connections in one stream, so the bytes taken, put end to end, are one
/// recording. Bounded: bytes no reader took are dropped and counted
/// beyond [`RawTelegrams::CAPACITY`].
#[derive(Debug, Clone, Default)]
pub struct RawTelegrams(Arc<Mutex<RawBuffer>>);

#[derive(Debug, Default)]
struct RawBuffer {
    bytes: Vec<u8>,
    connections: u64,
    dropped: u64,
}

impl RawTelegrams {
    /// Bytes held for the reader at most (about a minute of 500 kBd).
    pub const CAPACITY: usize = 4 << 20;

    /// The bytes written since the last call, and how many were dropped
    /// meanwhile (the reader fell behind).
    pub fn take(&self) -> (Vec<u8>, u64) {
        self.0
            .lock()
            .map(|mut b| (std::mem::take(&mut b.bytes), std::mem::take(&mut b.dropped)))
            .unwrap_or_default()
    }

    /// A writer for one connection's recording. A recording starts with
    /// its 8-byte magic; every connection after the first leaves it out,
    /// so the records continue the first connection's stream.
    fn connection(&self) -> RawConnection {
        let skip = self
            .0
            .lock()
            .map(|mut b| {
                b.connections += 1;
                if b.connections > 1 {
                    lms200::recording::MAGIC.len()
                } else {
                    0
                }
            })
            .unwrap_or(0);
        RawConnection {
            buffer: self.clone(),
            skip,
        }
    }
}

/// One connection's writer into [`RawTelegrams`].
struct RawConnection {
    buffer: RawTelegrams,
    /// Bytes still to leave out (the magic).
    skip: usize,
}

impl Write for RawConnection {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let skipped = self.skip.min(buf.len());
        self.skip -= skipped;
        let rest = &buf[skipped..];
        let mut b = self
            .buffer
            .0
            .lock()
            .map_err(|_| std::io::Error::other("raw telegram buffer poisoned"))?;
        if b.bytes.len() + rest.len() > RawTelegrams::CAPACITY {
            b.dropped += rest.len() as u64;
        } else {
            b.bytes.extend_from_slice(rest);
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// The running sensor thread.
#[derive(Debug)]
pub struct SensorThread {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl SensorThread {
    /// Starts the thread; scans go to `scans`, other reports to `reports`.
    pub fn spawn(
        options: SensorOptions,
        scans: watch::Sender<Option<ScanSlot>>,
        reports: mpsc::UnboundedSender<SensorReport>,
    ) -> std::io::Result<SensorThread> {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let thread = std::thread::Builder::new()
            .name("lms200".into())
            .spawn(move || run(options, &flag, &scans, &reports))?;
        Ok(SensorThread {
            stop,
            thread: Some(thread),
        })
    }

    /// Asks the thread to stop streaming and close the link, without
    /// waiting for it.
    pub fn request_stop(&self) {
        self.stop.store(true, Ordering::SeqCst);
    }

    /// Stops streaming, closes the link and waits for the thread.
    pub fn stop(mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(t) = self.thread.take()
            && t.join().is_err()
        {
            warn!("the sensor thread panicked");
        }
    }
}

impl Drop for SensorThread {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
    }
}

fn run(
    options: SensorOptions,
    stop: &AtomicBool,
    scans: &watch::Sender<Option<ScanSlot>>,
    reports: &mpsc::UnboundedSender<SensorReport>,
) {
    let mut wait = options.retry_initial;
    let mut seq = 0u64;
    // A recording is a convenience: when it cannot be written (disk full,
    // a read-only path) it is given up, never the scans.
    let mut record = options.record.clone();
    while !stop.load(Ordering::SeqCst) {
        let mut streamed = false;
        let result = SerialDriver::open(&options.port, options.link.clone())
            .map_err(DriverError::from_open)
            .and_then(|driver| attach_recording(driver, record.as_deref(), &options))
            .and_then(|mut driver| {
                info!(port = %options.port.display(), "serial port open");
                driver
                    .run(
                        || stop.load(Ordering::SeqCst),
                        |event| {
                            match event {
                                Event::Scan(scan) => {
                                    streamed = true;
                                    seq += 1;
                                    scans.send_replace(Some(ScanSlot {
                                        seq,
                                        scan: Arc::new(scan.clone()),
                                    }));
                                }
                                other => {
                                    let _ = reports.send(SensorReport::Link(other.clone()));
                                }
                            }
                            ControlFlow::Continue(())
                        },
                    )
                    .map_err(DriverError::from_run)
            });
        if streamed {
            wait = options.retry_initial;
        }
        match result {
            Ok(()) => {
                if stop.load(Ordering::SeqCst) {
                    break;
                }
            }
            Err(DriverError::Recording(error)) => {
                error!("recording stopped, streaming goes on without it: {error}");
                record = None;
            }
            Err(DriverError::Port(error)) => {
                let _ = reports.send(SensorReport::Failed {
                    error,
                    retry_in: wait,
                });
                let until = Instant::now() + wait;
                while Instant::now() < until && !stop.load(Ordering::SeqCst) {
                    std::thread::sleep(Duration::from_millis(20));
                }
                wait = (wait * 2).min(options.retry_max);
            }
        }
    }
}

/// A failure of the sensor thread's driver, sorted by what to do next.
enum DriverError {
    /// The port or the sensor: wait and try again.
    Port(String),
    /// The recording: drop it and stream on.
    Recording(String),
}

impl DriverError {
    fn from_open(e: lms200::driver::DriverError) -> DriverError {
        DriverError::Port(error_chain(&e))
    }

    fn from_run(e: lms200::driver::DriverError) -> DriverError {
        match e {
            lms200::driver::DriverError::Recording(_) => DriverError::Recording(error_chain(&e)),
            other => DriverError::Port(error_chain(&other)),
        }
    }
}

/// Adds the recording: into a new file next to `path` (`-1`, `-2` …
/// appended when the name exists) and into the options' buffer, either or
/// both; the port is opened again if the recording cannot be started.
fn attach_recording(
    driver: SerialDriver,
    path: Option<&std::path::Path>,
    options: &SensorOptions,
) -> Result<SerialDriver, DriverError> {
    let mut sinks: Vec<Box<dyn Write + Send>> = Vec::new();
    if let Some(path) = path {
        sinks.push(Box::new(std::io::BufWriter::new(new_recording_file(path)?)));
    }
    if let Some(raw) = &options.raw {
        sinks.push(Box::new(raw.connection()));
    }
    if sinks.is_empty() {
        return Ok(driver);
    }
    let driver = match &options.queued {
        Some(queue) => driver.with_queued_records(queue.clone()),
        None => driver,
    };
    driver
        .with_recording(
            Box::new(Tee(sinks)),
            &format!(
                "clsmap run; mode={:02x}",
                options.link.measuring_mode.code()
            ),
        )
        .map_err(DriverError::from_run)
}

/// A new file at `path`, or next to it.
fn new_recording_file(path: &std::path::Path) -> Result<std::fs::File, DriverError> {
    let file = (0..1000)
        .map(|k| {
            if k == 0 {
                path.to_owned()
            } else {
                let mut name = path.as_os_str().to_owned();
                name.push(format!("-{k}"));
                PathBuf::from(name)
            }
        })
        .find_map(|p| {
            OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(&p)
                .ok()
                .map(|f| (p, f))
        });
    let Some((p, file)) = file else {
        return Err(DriverError::Recording(format!(
            "cannot create a new recording next to {}",
            path.display()
        )));
    };
    info!(path = %p.display(), "recording the telegram stream");
    Ok(file)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use lms200::recording::{Record, RecordingReader, RecordingWriter};

    fn connection_bytes(raw: &RawTelegrams, note: &str) {
        let mut w = RecordingWriter::new(raw.connection()).unwrap();
        w.write(&Record::Note {
            t_us: 1,
            text: note.into(),
        })
        .unwrap();
    }

    #[test]
    fn every_connection_continues_one_recording() {
        let raw = RawTelegrams::default();
        connection_bytes(&raw, "first");
        let (mut bytes, dropped) = raw.take();
        connection_bytes(&raw, "second");
        bytes.extend(raw.take().0);
        assert_eq!(dropped, 0);
        let notes: Vec<String> = RecordingReader::new(&bytes[..])
            .unwrap()
            .map(|r| match r.unwrap() {
                Record::Note { text, .. } => text,
                other => panic!("{other:?}"),
            })
            .collect();
        assert_eq!(notes, ["first", "second"]);
    }

    #[test]
    fn bytes_no_one_takes_are_dropped_and_counted() {
        let raw = RawTelegrams::default();
        let mut w = raw.connection();
        let block = vec![0u8; 1 << 20];
        for _ in 0..6 {
            w.write_all(&block).unwrap();
        }
        let (bytes, dropped) = raw.take();
        assert_eq!(bytes.len(), RawTelegrams::CAPACITY);
        assert_eq!(dropped, 2 << 20);
        assert_eq!(raw.take(), (vec![], 0));
    }
}
