//! [`BaseAdapter`] speaking the [line protocol](crate::line_protocol) over a
//! byte stream: TCP, a serial port, or anything implementing [`LineStream`].
//!
//! Framing: `\n`-terminated ASCII lines in both directions (see
//! [`crate::line_protocol`] for the messages). The base sends `ODOM` and
//! `HEALTH` lines whenever it likes; the adapter writes one `VEL` or `STOP`
//! line per [`command`](BaseAdapter::command)/[`stop`](BaseAdapter::stop)
//! call. There is no handshake, acknowledgement or checksum; a line that does
//! not parse is counted, reported through [`BaseAdapter::health`] and skipped,
//! never dropping the link.
//!
//! The adapter is a thin shell: [`BaseAdapter::odometry`] drains whatever
//! bytes are waiting (never blocking) into a [`LineDecoder`]; all protocol
//! logic is in the decoder and in [`LineBase`]'s handling of decoded messages.
//!
//! Clocks: the `t` of an `ODOM` line is the base's own clock and is used only
//! to order samples and drop repeats (a sample whose base time is not after
//! the previous one is discarded and counted). Returned samples are stamped
//! with the daemon's clock at receipt, i.e. the last time passed to
//! [`BaseAdapter::advance`], `command` or `stop`, so they lag the base by the
//! transport delay plus at most one daemon cycle. Call `advance(now)` before
//! `odometry()` each cycle; before the first time is known nothing is read.
//!
//! A read or write error, or the peer closing a TCP connection, latches the
//! link as failed: health becomes [`Health::Failed`] with the error and
//! commands return [`BaseError::Link`]. Reconnecting means building a new
//! adapter. Dropping the adapter sends a best-effort `STOP`.

use std::fmt;
use std::io::{self, Read, Write};
use std::net::{SocketAddr, TcpStream, ToSocketAddrs};
use std::path::Path;
use std::time::{Duration, Instant};

use crate::adapter::{BaseAdapter, BaseError, Health, OdometrySample};
use crate::kinematics::{BasePose, Twist};
use crate::line_protocol::{BaseMessage, Command, LineDecoder, ProtocolError, encode_command};

/// A byte stream the adapter can poll without blocking.
pub trait LineStream: Send {
    /// Reads the bytes already received into `buf`; `Ok(0)` when none are
    /// waiting. Must not block. An end of stream is an error.
    ///
    /// # Errors
    /// The link is broken.
    fn read_available(&mut self, buf: &mut [u8]) -> io::Result<usize>;

    /// Writes all of `bytes`, waiting at most a short bounded time
    /// ([`WRITE_TIMEOUT`]) for room in the transmit buffer.
    ///
    /// # Errors
    /// The link is broken or did not accept the bytes in time.
    fn write_all_now(&mut self, bytes: &[u8]) -> io::Result<()>;
}

/// Longest a command write may wait for room on the link: 50 ms, well below
/// the few hundred milliseconds after which a bridge stops an unattended base.
pub const WRITE_TIMEOUT: Duration = Duration::from_millis(50);

/// How long a malformed or out-of-order line keeps health degraded, s.
pub const PROBLEM_HOLD: f64 = 5.0;

/// Bytes read per call of [`LineStream::read_available`].
const READ_CHUNK: usize = 4096;
/// Upper bound on bytes drained per `odometry()` call so a flooding peer
/// cannot stall the daemon loop.
const MAX_READ_PER_POLL: usize = 64 * 1024;
/// Bytes of an offending line echoed in health messages.
const ECHO_MAX: usize = 80;

impl LineStream for TcpStream {
    /// Expects the stream to be non-blocking ([`LineBase::connect_tcp`] sets it).
    fn read_available(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        loop {
            return match self.read(buf) {
                Ok(0) if !buf.is_empty() => Err(io::Error::new(
                    io::ErrorKind::UnexpectedEof,
                    "peer closed the connection",
                )),
                Ok(n) => Ok(n),
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => Ok(0),
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => Err(e),
            };
        }
    }

    fn write_all_now(&mut self, mut bytes: &[u8]) -> io::Result<()> {
        let deadline = Instant::now() + WRITE_TIMEOUT;
        while !bytes.is_empty() {
            match self.write(bytes) {
                Ok(0) => {
                    return Err(io::Error::new(
                        io::ErrorKind::WriteZero,
                        "connection accepted no bytes",
                    ));
                }
                Ok(n) => bytes = &bytes[n..],
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                    if Instant::now() >= deadline {
                        return Err(io::Error::new(
                            io::ErrorKind::TimedOut,
                            format!("peer did not accept a command within {WRITE_TIMEOUT:?}"),
                        ));
                    }
                    std::thread::sleep(Duration::from_millis(1));
                }
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }
}

impl LineStream for Box<dyn serialport::SerialPort> {
    /// Reads with a zero timeout: "timed out" means nothing is waiting, a
    /// hang-up (e.g. the other end of a pty closing) is an error.
    fn read_available(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if self.timeout() != Duration::ZERO {
            self.set_timeout(Duration::ZERO).map_err(io::Error::from)?;
        }
        loop {
            return match self.read(buf) {
                Ok(0) if !buf.is_empty() => Err(io::Error::new(
                    io::ErrorKind::UnexpectedEof,
                    "serial port hung up",
                )),
                Ok(n) => Ok(n),
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock
                    ) =>
                {
                    Ok(0)
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => Err(e),
            };
        }
    }

    /// Writes with [`WRITE_TIMEOUT`], then restores the zero read timeout.
    fn write_all_now(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.set_timeout(WRITE_TIMEOUT).map_err(io::Error::from)?;
        let written = self.write_all(bytes);
        let restored = self.set_timeout(Duration::ZERO).map_err(io::Error::from);
        written.and(restored)
    }
}

/// Counters of what the adapter received, for diagnostics.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LineBaseStats {
    /// Well-formed `ODOM` lines received.
    pub odometry_received: u64,
    /// Samples superseded by a newer one before `odometry()` returned them.
    pub odometry_skipped: u64,
    /// Samples dropped because their base time was not after the previous one.
    pub odometry_out_of_order: u64,
    /// Lines that did not parse (including over-long ones).
    pub malformed_lines: u64,
    /// Well-formed `POSE` lines received.
    pub pose_hints: u64,
}

/// A base bridged by the line protocol over the stream `S`.
pub struct LineBase<S: LineStream> {
    stream: S,
    /// Human-readable link name for messages, e.g. `tcp 10.0.0.5:5600`.
    link: String,
    decoder: LineDecoder,
    /// Start of the line being received, for echoing in error reports.
    echo: Vec<u8>,
    /// Latest daemon time, s.
    now: Option<f64>,
    /// Newest sample not yet returned (stamped with the daemon clock).
    pending: Option<OdometrySample>,
    /// Newest `POSE` hint not yet returned (map frame).
    pose_hint: Option<BasePose>,
    /// Base-clock time of the newest accepted sample, s.
    last_base_t: Option<f64>,
    /// Text of the last `HEALTH FAULT`, until a `HEALTH OK`.
    base_fault: Option<String>,
    /// Last protocol problem and the daemon time it was seen, s.
    problem: Option<(String, f64)>,
    /// Latched link failure.
    failure: Option<String>,
    stats: LineBaseStats,
}

impl<S: LineStream> fmt::Debug for LineBase<S> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("LineBase")
            .field("link", &self.link)
            .field("now", &self.now)
            .field("pending", &self.pending)
            .field("pose_hint", &self.pose_hint)
            .field("last_base_t", &self.last_base_t)
            .field("base_fault", &self.base_fault)
            .field("problem", &self.problem)
            .field("failure", &self.failure)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl LineBase<TcpStream> {
    /// Connects to a base bridge at `addr` (`host:port`), trying each
    /// resolved address for at most `timeout` (must be non-zero).
    ///
    /// # Errors
    /// [`BaseError::Link`] naming `addr` if it does not resolve, no address
    /// accepts the connection, or the socket cannot be configured.
    pub fn connect_tcp(addr: &str, timeout: Duration) -> Result<Self, BaseError> {
        let addrs: Vec<SocketAddr> = addr
            .to_socket_addrs()
            .map_err(|e| BaseError::Link(format!("cannot resolve base address {addr:?}: {e}")))?
            .collect();
        let mut last_error = None;
        for a in &addrs {
            match TcpStream::connect_timeout(a, timeout) {
                Ok(stream) => {
                    let configure = |s: &TcpStream| {
                        s.set_nodelay(true)?;
                        s.set_nonblocking(true)
                    };
                    configure(&stream).map_err(|e| {
                        BaseError::Link(format!("cannot configure TCP link to base at {addr}: {e}"))
                    })?;
                    return Ok(Self::new(stream, format!("tcp {addr}")));
                }
                Err(e) => last_error = Some(e),
            }
        }
        Err(BaseError::Link(match last_error {
            Some(e) => format!("cannot connect to base at {addr}: {e}"),
            None => format!("base address {addr:?} resolves to no socket address"),
        }))
    }
}

impl LineBase<Box<dyn serialport::SerialPort>> {
    /// Opens the serial port at `path` with `baud` Bd, 8N1, no flow control.
    ///
    /// Keep the link fast enough for the command rate: at 50 Hz a `VEL` line
    /// of ~30 bytes needs ~15 kBd, so use 38400 Bd or more.
    ///
    /// # Errors
    /// [`BaseError::Link`] naming `path` if the baud rate is zero, the path is
    /// not UTF-8, or the port cannot be opened.
    pub fn open_serial(path: &Path, baud: u32) -> Result<Self, BaseError> {
        let name = path.to_str().ok_or_else(|| {
            BaseError::Link(format!(
                "serial port path {} is not valid UTF-8",
                path.display()
            ))
        })?;
        if baud == 0 {
            return Err(BaseError::Link(format!(
                "serial port {name}: baud rate must be positive"
            )));
        }
        let port = serialport::new(name, baud)
            .timeout(Duration::ZERO)
            .open()
            .map_err(|e| {
                BaseError::Link(format!("cannot open serial port {name} at {baud} Bd: {e}"))
            })?;
        Ok(Self::new(port, format!("serial {name}")))
    }
}

impl<S: LineStream> LineBase<S> {
    /// Wraps an open `stream`; `link` names it in messages (e.g. `tcp host:port`).
    pub fn new(stream: S, link: impl Into<String>) -> Self {
        Self {
            stream,
            link: link.into(),
            decoder: LineDecoder::default(),
            echo: Vec::new(),
            now: None,
            pending: None,
            pose_hint: None,
            last_base_t: None,
            base_fault: None,
            problem: None,
            failure: None,
            stats: LineBaseStats::default(),
        }
    }

    /// Sets the daemon time `now` (s) used to stamp received samples.
    /// Non-finite times and times that do not move forward are ignored.
    pub fn advance(&mut self, now: f64) {
        if now.is_finite() && self.now.is_none_or(|t| now > t) {
            self.now = Some(now);
        }
    }

    /// The link name given at construction.
    #[must_use]
    pub fn link_name(&self) -> &str {
        &self.link
    }

    /// Receive counters.
    #[must_use]
    pub fn stats(&self) -> LineBaseStats {
        self.stats
    }

    /// Base-clock time of the newest accepted `ODOM` line, s.
    #[must_use]
    pub fn last_base_time(&self) -> Option<f64> {
        self.last_base_t
    }

    /// Drains the stream (bounded), feeding the decoder; latches failures.
    fn pump(&mut self, now: f64) {
        let mut buf = [0u8; READ_CHUNK];
        let mut total = 0;
        while self.failure.is_none() && total < MAX_READ_PER_POLL {
            match self.stream.read_available(&mut buf) {
                Ok(0) => break,
                Ok(n) => {
                    total += n;
                    self.receive(&buf[..n], now);
                }
                Err(e) => self.fail("read", &e),
            }
        }
    }

    /// Feeds received bytes to the decoder one line piece at a time, so each
    /// decoder result belongs to the line in [`Self::echo`].
    fn receive(&mut self, bytes: &[u8], now: f64) {
        for piece in bytes.split_inclusive(|&b| b == b'\n') {
            self.decoder.push(piece);
            let room = ECHO_MAX.saturating_sub(self.echo.len());
            self.echo.extend_from_slice(&piece[..piece.len().min(room)]);
            while let Some(item) = self.decoder.poll() {
                self.handle(item, now);
            }
            if piece.ends_with(b"\n") {
                self.echo.clear();
            }
        }
    }

    fn handle(&mut self, item: Result<BaseMessage, ProtocolError>, now: f64) {
        match item {
            Ok(BaseMessage::Odometry { t, x, y, theta }) => {
                self.stats.odometry_received += 1;
                if let Some(last) = self.last_base_t.filter(|&last| t <= last) {
                    self.stats.odometry_out_of_order += 1;
                    self.problem = Some((
                        format!(
                            "{}: ODOM time {t} s is not after the previous {last} s \
                             (repeated, reordered or base clock reset); dropped {} so far",
                            self.link, self.stats.odometry_out_of_order
                        ),
                        now,
                    ));
                    return;
                }
                self.last_base_t = Some(t);
                if self.pending.is_some() {
                    self.stats.odometry_skipped += 1;
                }
                self.pending = Some(OdometrySample {
                    t: now,
                    pose: BasePose::new(x, y, theta),
                });
            }
            Ok(BaseMessage::PoseHint { x, y, theta }) => {
                self.stats.pose_hints += 1;
                self.pose_hint = Some(BasePose::new(x, y, theta));
            }
            Ok(BaseMessage::Health { ok: true, .. }) => self.base_fault = None,
            Ok(BaseMessage::Health { ok: false, text }) => self.base_fault = Some(text),
            Err(e) => {
                self.stats.malformed_lines += 1;
                let text = String::from_utf8_lossy(&self.echo);
                self.problem = Some((
                    format!(
                        "{}: malformed line ({e}): {:?}; {} so far",
                        self.link,
                        text.trim_end_matches(['\r', '\n']),
                        self.stats.malformed_lines
                    ),
                    now,
                ));
            }
        }
    }

    fn fail(&mut self, what: &str, e: &io::Error) {
        if self.failure.is_none() {
            self.failure = Some(format!("{}: {what} failed: {e}", self.link));
        }
    }

    fn send(&mut self, cmd: Command) -> Result<(), BaseError> {
        if let Some(f) = &self.failure {
            return Err(BaseError::Link(f.clone()));
        }
        if let Err(e) = self.stream.write_all_now(encode_command(cmd).as_bytes()) {
            self.fail("write", &e);
        }
        match &self.failure {
            Some(f) => Err(BaseError::Link(f.clone())),
            None => Ok(()),
        }
    }
}

impl<S: LineStream> BaseAdapter for LineBase<S> {
    fn advance(&mut self, now: f64) {
        LineBase::advance(self, now);
    }

    fn odometry(&mut self) -> Option<OdometrySample> {
        let now = self.now?;
        self.pump(now);
        self.pending.take()
    }

    fn pose_hint(&mut self) -> Option<BasePose> {
        self.pose_hint.take()
    }

    /// Sends `VEL`; a non-finite twist sends `STOP` and returns
    /// [`BaseError::InvalidCommand`].
    fn command(&mut self, twist: Twist, now: f64) -> Result<(), BaseError> {
        self.advance(now);
        if twist.is_finite() {
            self.send(Command::Velocity(twist))
        } else {
            self.send(Command::Stop)?;
            Err(BaseError::InvalidCommand(format!(
                "non-finite twist {twist:?}; sent STOP"
            )))
        }
    }

    fn stop(&mut self, now: f64) -> Result<(), BaseError> {
        self.advance(now);
        self.send(Command::Stop)
    }

    fn link_lost(&self) -> bool {
        self.failure.is_some()
    }

    /// Link failure, then a base `FAULT` (both [`Health::Failed`]), then a
    /// protocol problem seen in the last [`PROBLEM_HOLD`] s (degraded).
    fn health(&self) -> Health {
        if let Some(f) = &self.failure {
            return Health::Failed(f.clone());
        }
        if let Some(text) = &self.base_fault {
            return Health::Failed(if text.is_empty() {
                format!("{}: base reports FAULT", self.link)
            } else {
                format!("{}: base reports FAULT: {text}", self.link)
            });
        }
        match (&self.problem, self.now) {
            (Some((msg, seen)), Some(now)) if now - seen < PROBLEM_HOLD => {
                Health::Degraded(msg.clone())
            }
            _ => Health::Ok,
        }
    }
}

impl<S: LineStream> Drop for LineBase<S> {
    /// Best-effort `STOP` so a dropped adapter does not leave the base moving.
    fn drop(&mut self) {
        if self.failure.is_none() {
            // Nothing to report to from a destructor; the bridge's own command
            // timeout is the backstop.
            let _ = self
                .stream
                .write_all_now(encode_command(Command::Stop).as_bytes());
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests;
