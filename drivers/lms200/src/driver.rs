//! The blocking serial driver: a thin shell that runs the sans-IO [`Link`]
//! on a [`SerialTransport`], optionally writing everything that crosses the
//! line to a recording. Used by `clsmap probe` and `clsmap record`; the
//! same link runs on any other shell (an async port, say) unchanged.

use std::io::Write;
use std::ops::ControlFlow;
use std::path::Path;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use crate::link::{Event, Link, LinkConfig, LinkStats, Output};
use crate::recording::{Record, RecordingError, RecordingWriter};
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
            t_us: unix_micros(),
            text: note.to_string(),
        })?;
        writer.write(&Record::Baud {
            t_us: unix_micros(),
            baud: self.transport.baud(),
        })?;
        Ok(SerialDriver {
            transport: self.transport,
            link: self.link,
            recording: Some(writer),
        })
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

    fn record(&mut self, make: impl FnOnce(i64) -> Record) -> Result<(), DriverError> {
        if let Some(r) = self.recording.as_mut() {
            r.write(&make(unix_micros()))?;
        }
        Ok(())
    }
}

/// Host wall-clock time in µs since the Unix epoch, the recording's clock.
pub fn unix_micros() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| i64::try_from(d.as_micros()).unwrap_or(i64::MAX))
        .unwrap_or(0)
}
