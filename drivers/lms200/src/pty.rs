//! The emulator on a pseudo-terminal: a thin shell that runs the sans-IO
//! [`Emulator`] in a thread behind a real tty path, so any LMS200 driver
//! (this one or another) can open it like a serial port.
//!
//! The shell reads the line speed the host set on its end of the pty (on
//! Linux the master sees the slave's termios) and tells the emulator, so a
//! driver that forgets to switch its own speed after a baud change hears
//! garbage, as it would on a real cable.

use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serialport::{SerialPort, TTYPort};

use crate::Baud;
use crate::emulator::{Emulator, EmulatorStats, FaultConfig};

/// Why the pty emulator could not start or stopped.
#[derive(Debug, thiserror::Error)]
pub enum PtyError {
    #[error("cannot create a pseudo-terminal: {0}")]
    Open(String),
    #[error("cannot create the link {link}: {source}")]
    Link {
        link: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error("pty I/O failed: {0}")]
    Io(#[from] io::Error),
    #[error("the emulator thread panicked")]
    Panicked,
}

/// Runtime controls shared with the emulator thread.
#[derive(Debug, Default)]
struct Controls {
    stop: AtomicBool,
    /// A fault configuration waiting to be applied.
    faults: std::sync::Mutex<Option<FaultConfig>>,
    /// Silence requested (duration), applied once.
    silence: std::sync::Mutex<Option<Duration>>,
    power_cycle: AtomicBool,
    stats: std::sync::Mutex<EmulatorStats>,
}

/// A running emulator behind a pty. Dropping it stops the thread.
#[derive(Debug)]
pub struct PtyEmulator {
    slave_path: PathBuf,
    link: Option<PathBuf>,
    controls: Arc<Controls>,
    thread: Option<JoinHandle<Result<(), PtyError>>>,
}

impl PtyEmulator {
    /// Starts `emulator` on a new pty. With `link`, a symlink to the tty
    /// path is created there (an existing symlink is replaced; any other
    /// file is an error).
    pub fn spawn(emulator: Emulator, link: Option<&Path>) -> Result<Self, PtyError> {
        let (master, slave) = TTYPort::pair().map_err(|e| PtyError::Open(e.to_string()))?;
        let slave_path = slave
            .name()
            .map(PathBuf::from)
            .ok_or_else(|| PtyError::Open("the pty has no name".into()))?;
        if let Some(link) = link {
            match std::fs::symlink_metadata(link) {
                Ok(meta) if meta.file_type().is_symlink() => {
                    std::fs::remove_file(link).map_err(|source| PtyError::Link {
                        link: link.to_path_buf(),
                        source,
                    })?
                }
                Ok(_) => {
                    return Err(PtyError::Link {
                        link: link.to_path_buf(),
                        source: io::Error::new(
                            io::ErrorKind::AlreadyExists,
                            "exists and is not a symlink; not replacing it",
                        ),
                    });
                }
                Err(_) => {}
            }
            make_symlink(&slave_path, link).map_err(|source| PtyError::Link {
                link: link.to_path_buf(),
                source,
            })?;
        }
        let controls = Arc::new(Controls::default());
        let thread_controls = Arc::clone(&controls);
        let thread = std::thread::Builder::new()
            .name("lms200-emulator".into())
            .spawn(move || run(emulator, master, slave, &thread_controls))?;
        Ok(PtyEmulator {
            slave_path,
            link: link.map(Path::to_path_buf),
            controls,
            thread: Some(thread),
        })
    }

    /// The tty path a driver opens (`/dev/pts/N`).
    pub fn tty_path(&self) -> &Path {
        &self.slave_path
    }

    /// Replaces the active line faults.
    pub fn set_faults(&self, faults: FaultConfig) {
        if let Ok(mut f) = self.controls.faults.lock() {
            *f = Some(faults);
        }
    }

    /// The sensor goes silent for `duration`.
    pub fn silence(&self, duration: Duration) {
        if let Ok(mut s) = self.controls.silence.lock() {
            *s = Some(duration);
        }
    }

    /// The sensor loses power and starts again at 9600 Bd.
    pub fn power_cycle(&self) {
        self.controls.power_cycle.store(true, Ordering::SeqCst);
    }

    /// The emulator's counters as of its last loop turn.
    pub fn stats(&self) -> EmulatorStats {
        self.controls.stats.lock().map(|s| *s).unwrap_or_default()
    }

    /// Stops the emulator and waits for its thread; reports how it ended.
    pub fn stop(mut self) -> Result<(), PtyError> {
        self.shutdown()
    }

    fn shutdown(&mut self) -> Result<(), PtyError> {
        self.controls.stop.store(true, Ordering::SeqCst);
        if let Some(link) = self.link.take() {
            let _ = std::fs::remove_file(link);
        }
        match self.thread.take() {
            Some(t) => t.join().map_err(|_| PtyError::Panicked)?,
            None => Ok(()),
        }
    }
}

impl Drop for PtyEmulator {
    fn drop(&mut self) {
        let _ = self.shutdown();
    }
}

#[cfg(unix)]
fn make_symlink(target: &Path, link: &Path) -> io::Result<()> {
    std::os::unix::fs::symlink(target, link)
}

#[cfg(not(unix))]
fn make_symlink(_target: &Path, _link: &Path) -> io::Result<()> {
    Err(io::Error::new(
        io::ErrorKind::Unsupported,
        "symlinks need a Unix system",
    ))
}

/// Longest the loop sleeps, so stop requests and termios changes are seen.
const POLL_CAP: Duration = Duration::from_millis(2);

fn run(
    mut emulator: Emulator,
    mut master: TTYPort,
    // Held open so the master never sees a hang-up while no driver has the
    // tty open (between `probe` and `record`, say).
    _slave: TTYPort,
    controls: &Controls,
) -> Result<(), PtyError> {
    let mut buf = [0u8; 4096];
    let mut host_bps = 0u32;
    while !controls.stop.load(Ordering::SeqCst) {
        let now = Instant::now();
        apply_controls(&mut emulator, controls, now);
        follow_host_speed(&mut emulator, &master, &mut host_bps);
        if let Some(bytes) = emulator.poll_transmit(now) {
            write_or_drop(&mut master, &bytes)?;
        }
        let wait = emulator
            .poll_timeout()
            .map(|t| t.saturating_duration_since(Instant::now()))
            .unwrap_or(POLL_CAP)
            .min(POLL_CAP);
        master
            .set_timeout(wait.max(Duration::from_micros(200)))
            .ok();
        match master.read(&mut buf) {
            Ok(0) => {}
            Ok(n) => {
                // The host may have switched its speed and written at once,
                // while this thread waited: its bytes went out at the speed
                // its termios says now, not at the one read before the wait.
                follow_host_speed(&mut emulator, &master, &mut host_bps);
                emulator.handle_input(&buf[..n], Instant::now());
            }
            Err(e) if is_transient(&e) => {}
            Err(e) => return Err(PtyError::Io(e)),
        }
        emulator.handle_timeout(Instant::now());
        if let Ok(mut s) = controls.stats.lock() {
            *s = emulator.stats();
        }
    }
    Ok(())
}

/// Tells the emulator the host's line speed, as the host's termios says,
/// when it changed since `host_bps`.
fn follow_host_speed(emulator: &mut Emulator, master: &TTYPort, host_bps: &mut u32) {
    if let Ok(bps) = master.baud_rate()
        && bps != *host_bps
    {
        *host_bps = bps;
        // A speed the LMS200 cannot run at never matches the sensor.
        let baud = Baud::from_bits_per_second(bps);
        emulator.set_host_baud(baud.unwrap_or_else(|| mismatched(emulator.baud())));
    }
}

fn apply_controls(emulator: &mut Emulator, controls: &Controls, now: Instant) {
    if let Ok(mut f) = controls.faults.lock()
        && let Some(faults) = f.take()
    {
        emulator.set_faults(faults);
    }
    if let Ok(mut s) = controls.silence.lock()
        && let Some(d) = s.take()
    {
        emulator.silence(now, d);
    }
    if controls.power_cycle.swap(false, Ordering::SeqCst) {
        emulator.power_cycle(now);
    }
}

/// Some LMS200 speed other than `sensor`, for a host speed the sensor
/// cannot run at: the line is garbled either way.
fn mismatched(sensor: Baud) -> Baud {
    if sensor == Baud::B9600 {
        Baud::B19200
    } else {
        Baud::B9600
    }
}

fn is_transient(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
    ) || e.raw_os_error() == Some(5) // EIO: no process has the tty open
}

/// Writes to the pty; bytes nobody reads (the tty's buffer is full) are
/// dropped, as on a real line with no listener.
fn write_or_drop(master: &mut TTYPort, bytes: &[u8]) -> Result<(), PtyError> {
    master.set_timeout(Duration::from_millis(1)).ok();
    let mut rest = bytes;
    while !rest.is_empty() {
        match master.write(rest) {
            Ok(0) => break,
            Ok(n) => rest = &rest[n..],
            Err(e) if is_transient(&e) => break,
            Err(e) => return Err(PtyError::Io(e)),
        }
    }
    Ok(())
}
