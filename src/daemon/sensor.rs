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
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use lms200::driver::SerialDriver;
use lms200::link::{Event, LinkConfig, TimedScan};
use tokio::sync::{mpsc, watch};
use tracing::{error, info, warn};

use crate::error_chain;

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
            .and_then(|driver| match record.as_deref() {
                Some(path) => attach_recording(driver, path, &options),
                None => Ok(driver),
            })
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

/// Adds a recording in a new file next to `path` (`-1`, `-2` … appended
/// when the name exists); the port is opened again if the recording cannot
/// be started.
fn attach_recording(
    driver: SerialDriver,
    path: &std::path::Path,
    options: &SensorOptions,
) -> Result<SerialDriver, DriverError> {
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
    driver
        .with_recording(
            Box::new(std::io::BufWriter::new(file)),
            &format!(
                "clsmap run; mode={:02x}",
                options.link.measuring_mode.code()
            ),
        )
        .map_err(DriverError::from_run)
}
