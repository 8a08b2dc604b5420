//! The blocking serial driver: a thin shell that runs the sans-IO [`Link`]
//! on a [`SerialTransport`], optionally writing everything that crosses the
//! line to a recording. Used by `clsmap probe` and `clsmap record`; the
//! same link runs on any other shell (an async port, say) unchanged.

use std::io::Write;
use std::ops::ControlFlow;
use std::path::Path;
use std::sync::Mutex;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use crate::link::{Event, Link, LinkConfig, LinkStats, Output};
use crate::recording::{Record, RecordQueue, RecordingError, RecordingWriter};
use crate::serial::{SerialError, SerialTransport};

/// Why the driver stopped before it was asked to.
#[derive(Debug, thiserror::Error)]
pub enum DriverError {
    #[error(transparent)]
    Serial(#[from] SerialError),
    #[error("cannot write the recording: {0}")]
    Recording(#[from] RecordingError),
}

/// Longest single wait on the port, so a stop request is seen promptly (s).
const MAX_WAIT: Duration = Duration::from_millis(20);

/// A link on a serial port.
pub struct SerialDriver {
    transport: SerialTransport,
    link: Link,
    recording: Option<RecordingWriter<Box<dyn Write + Send>>>,
    /// Records made elsewhere, written into the recording as they come.
    queued: Option<RecordQueue>,
}

impl std::fmt::Debug for SerialDriver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SerialDriver")
            .field("transport", &self.transport)
            .field("link", &self.link)
            .field("recording", &self.recording.is_some())
            .finish()
    }
}

impl SerialDriver {
    /// Opens `port` at the first line speed the link will probe.
    pub fn open(port: &Path, config: LinkConfig) -> Result<Self, DriverError> {
        let first = config
            .probe_order()
            .first()
            .map(|b| b.bits_per_second())
            .unwrap_or(9600);
        let transport = SerialTransport::open(port, first)?;
        Ok(SerialDriver {
            transport,
            link: Link::new(config, Instant::now()),
            recording: None,
            queued: None,
        })
    }

    /// Records every chunk in both directions, every speed change and
    /// `note` (describe the set-up there) into `out`.
    pub fn with_recording(
        self,
        out: Box<dyn Write + Send>,
        note: &str,
    ) -> Result<SerialDriver, DriverError> {
        let mut writer = RecordingWriter::new(out)?;
        writer.write(&Record::Note {
            t_us: recording_micros(),
            text: note.to_string(),
        })?;
        writer.write(&Record::Baud {
            t_us: recording_micros(),
            baud: self.transport.baud(),
        })?;
        Ok(SerialDriver {
            recording: Some(writer),
            ..self
        })
    }

    /// Writes the records pushed into `queue` (odometry samples of the
    /// base, say) into the recording too, when there is one.
    pub fn with_queued_records(self, queue: RecordQueue) -> SerialDriver {
        SerialDriver {
            queued: Some(queue),
            ..self
        }
    }

    /// Link counters.
    pub fn stats(&self) -> LinkStats {
        self.link.stats()
    }

    /// The current host line speed (baud).
    pub fn baud(&self) -> u32 {
        self.transport.baud()
    }

    /// Runs the link, handing every event to `on_event`, until `on_event`
    /// breaks or `stop` returns true; then closes the link cleanly (stops
    /// the output, returns the sensor to 9600 Bd) before returning.
    pub fn run(
        &mut self,
        mut stop: impl FnMut() -> bool,
        mut on_event: impl FnMut(&Event) -> ControlFlow<()>,
    ) -> Result<(), DriverError> {
        let mut buf = [0u8; 4096];
        let mut closing = false;
        loop {
            while let Some(output) = self.link.poll_output() {
                match output {
                    Output::Transmit(bytes) => {
                        self.record(|t_us| Record::Tx {
                            t_us,
                            bytes: bytes.clone(),
                        })?;
                        self.transport.write_telegram(&bytes)?;
                    }
                    Output::SetBaud(baud) => {
                        let bps = baud.bits_per_second();
                        self.transport.set_baud(bps)?;
                        self.record(|t_us| Record::Baud { t_us, baud: bps })?;
                    }
                    Output::Event(Event::Closed) => {
                        // The link is closed; there is nothing left to stop.
                        let _ = on_event(&Event::Closed);
                        self.write_queued()?;
                        if let Some(r) = self.recording.as_mut() {
                            r.flush()?;
                        }
                        return Ok(());
                    }
                    Output::Event(event) => {
                        if on_event(&event).is_break() && !closing {
                            closing = true;
                            self.link.close(Instant::now());
                        }
                    }
                }
            }
            if !closing && stop() {
                closing = true;
                self.link.close(Instant::now());
                continue;
            }
            let wait = self
                .link
                .poll_timeout()
                .map(|t| t.saturating_duration_since(Instant::now()))
                .unwrap_or(MAX_WAIT)
                .min(MAX_WAIT);
            let n = self.transport.read(&mut buf, wait)?;
            let now = Instant::now();
            self.write_queued()?;
            if n > 0 {
                self.record(|t_us| Record::Rx {
                    t_us,
                    bytes: buf[..n].to_vec(),
                })?;
                self.link.handle_input(&buf[..n], now);
            }
            if self.link.poll_timeout().is_some_and(|t| t <= now) {
                self.link.handle_timeout(now);
            }
        }
    }

    /// Writes the records waiting in the queue, if there is a recording.
    fn write_queued(&mut self) -> Result<(), DriverError> {
        if let (Some(r), Some(q)) = (self.recording.as_mut(), self.queued.as_ref()) {
            for record in q.take() {
                r.write(&record)?;
            }
        }
        Ok(())
    }

    fn record(&mut self, make: impl FnOnce(i64) -> Record) -> Result<(), DriverError> {
        if let Some(r) = self.recording.as_mut() {
            r.write(&make(recording_micros()))?;
        }
        Ok(())
    }
}

/// Host wall-clock time in µs since the Unix epoch.
pub fn unix_micros() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| i64::try_from(d.as_micros()).unwrap_or(i64::MAX))
        .unwrap_or(0)
}

/// The recordings' clock (µs since the Unix epoch): the wall clock, but
/// never backwards. When the wall clock steps back (NTP correcting a
/// clock that ran ahead) the recordings' clock goes on at the monotonic
/// clock's pace until the wall clock catches up; a step forward (a robot
/// without a battery clock setting its time) is followed. A recording
/// whose times went back would lose every scan until they caught up.
pub fn recording_micros() -> i64 {
    static LAST: Mutex<Option<(i64, Instant)>> = Mutex::new(None);
    let mut last = LAST
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let now = Instant::now();
    let t = never_backwards(*last, unix_micros(), now);
    *last = Some((t, now));
    t
}

/// The wall time `wall_us`, or, when it is behind the `last` reading
/// (its value, taken at an instant) plus the monotonic time since, that.
fn never_backwards(last: Option<(i64, Instant)>, wall_us: i64, now: Instant) -> i64 {
    match last {
        Some((t, at)) => {
            let since = i64::try_from(now.saturating_duration_since(at).as_micros()).unwrap_or(0);
            wall_us.max(t.saturating_add(since))
        }
        None => wall_us,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_recording_clock_never_steps_back_and_follows_steps_forward() {
        let start = Instant::now();
        let at = |ms: u64| start + Duration::from_millis(ms);
        let t0 = never_backwards(None, 1_000_000_000, at(0));
        assert_eq!(t0, 1_000_000_000);
        // 100 ms later the wall clock is stepped back an hour: the clock
        // goes on 100 ms later instead.
        let t1 = never_backwards(Some((t0, at(0))), 1_000_100_000 - 3_600_000_000, at(100));
        assert_eq!(t1, 1_000_100_000);
        let t2 = never_backwards(Some((t1, at(100))), 1_000_200_000 - 3_600_000_000, at(200));
        assert_eq!(t2, 1_000_200_000);
        // A step forward (a day) is taken.
        let t3 = never_backwards(Some((t2, at(200))), 1_086_400_000_000, at(300));
        assert_eq!(t3, 1_086_400_000_000);
        assert!(recording_micros() <= recording_micros());
    }
}
