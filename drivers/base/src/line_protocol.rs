//! Sans-IO text protocol for bridging a real base over a serial port or TCP.
//!
//! ASCII lines terminated by `\n` (an optional `\r` before it is ignored);
//! fields separated by spaces or tabs; numbers are decimal floats (Rust/C
//! syntax, e.g. `0.25`, `-1e-3`); blank lines are ignored. Lines longer than
//! [`DEFAULT_MAX_LINE`] bytes (configurable) are reported as an error and
//! skipped. Units are SI; frames as in [`crate::kinematics`] (robot frame:
//! x forward, y left, angles counter-clockwise positive).
//!
//! Base → host:
//! - `ODOM <t> <x> <y> <theta>`: odometry sample; `t` in s (base clock),
//!   `x`, `y` in m and `theta` in rad in the odometry frame. All finite.
//! - `HEALTH OK [<text>]` or `HEALTH FAULT <text>`: health report; `text` is
//!   free-form up to the end of the line.
//! - `POSE <x> <y> <theta>`: a pose hint — the robot is here now, in the
//!   *map* frame (m, m, rad), as an operator or a docking station knows
//!   it; the host looks for the robot in its map from there. All finite.
//!
//! Host → base ([`encode_command`]):
//! - `VEL <vx> <vy> <omega>`: robot-frame velocity, m/s, m/s, rad/s, to hold
//!   until the next command. The bridge should stop the base if no command
//!   arrives for a few hundred milliseconds.
//! - `STOP`: stop now.
//!
//! Example exchange:
//! ```text
//! > VEL 0.3 0 0.1
//! < ODOM 12.5 1.02 -0.4 0.785
//! < HEALTH OK
//! > STOP
//! < HEALTH FAULT bumper pressed
//! ```

use crate::kinematics::Twist;

/// Default maximum line length in bytes, excluding the terminator.
pub const DEFAULT_MAX_LINE: usize = 256;

/// A decoded base → host message.
#[derive(Debug, Clone, PartialEq)]
pub enum BaseMessage {
    /// Odometry: `t` s, `x`, `y` m, `theta` rad.
    Odometry {
        /// Sample time, s.
        t: f64,
        /// Position x, m.
        x: f64,
        /// Position y, m.
        y: f64,
        /// Heading, rad.
        theta: f64,
    },
    /// A pose hint in the map frame: `x`, `y` m, `theta` rad.
    PoseHint {
        /// Position x, m.
        x: f64,
        /// Position y, m.
        y: f64,
        /// Heading, rad.
        theta: f64,
    },
    /// Health report.
    Health {
        /// `true` for `OK`, `false` for `FAULT`.
        ok: bool,
        /// Free-form text (may be empty).
        text: String,
    },
}

/// A host → base command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Command {
    /// Robot-frame velocity (m/s, m/s, rad/s).
    Velocity(Twist),
    /// Stop.
    Stop,
}

/// Why a line could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ProtocolError {
    /// The line exceeded the maximum length and was skipped.
    #[error("line longer than {max} bytes, skipped")]
    LineTooLong {
        /// Maximum allowed length, bytes.
        max: usize,
    },
    /// The line was not valid UTF-8.
    #[error("line is not valid UTF-8")]
    NotUtf8,
    /// The first word is not a known keyword.
    #[error("unknown keyword {0:?}")]
    UnknownKeyword(String),
    /// Wrong number of fields after the keyword.
    #[error("{keyword}: expected {expected} fields, found {found}")]
    FieldCount {
        /// The keyword.
        keyword: &'static str,
        /// Expected field count.
        expected: usize,
        /// Found field count.
        found: usize,
    },
    /// A field is not a finite number.
    #[error("{keyword}: field {field} is not a finite number: {text:?}")]
    BadNumber {
        /// The keyword.
        keyword: &'static str,
        /// The field name.
        field: &'static str,
        /// The offending text.
        text: String,
    },
    /// `HEALTH` status other than `OK` or `FAULT`.
    #[error("HEALTH: status must be OK or FAULT, found {0:?}")]
    BadHealthStatus(String),
}

/// Incremental line decoder: [`push`](Self::push) bytes, then call
/// [`poll`](Self::poll) until it returns `None`.
#[derive(Debug, Clone)]
pub struct LineDecoder {
    buf: Vec<u8>,
    max_line: usize,
    discarding: bool,
}

impl Default for LineDecoder {
    fn default() -> Self {
        Self::new(DEFAULT_MAX_LINE)
    }
}

impl LineDecoder {
    /// A decoder accepting lines of at most `max_line` bytes (terminator excluded).
    #[must_use]
    pub fn new(max_line: usize) -> Self {
        Self {
            buf: Vec::new(),
            max_line,
            discarding: false,
        }
    }

    /// Appends received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
    }

    /// Next message or error, or `None` when more bytes are needed.
    pub fn poll(&mut self) -> Option<Result<BaseMessage, ProtocolError>> {
        loop {
            let Some(pos) = self.buf.iter().position(|&b| b == b'\n') else {
                // `+ 1` leaves room for a `\r` still waiting for its `\n`.
                if self.discarding {
                    self.buf.clear();
                } else if self.buf.len() > self.max_line + 1 {
                    self.buf.clear();
                    self.discarding = true;
                    return Some(Err(ProtocolError::LineTooLong { max: self.max_line }));
                }
                return None;
            };
            let mut line: Vec<u8> = self.buf.drain(..=pos).collect();
            line.pop(); // '\n'
            if line.last() == Some(&b'\r') {
                line.pop();
            }
            if std::mem::take(&mut self.discarding) {
                continue; // tail of a line already reported as too long
            }
            if line.len() > self.max_line {
                return Some(Err(ProtocolError::LineTooLong { max: self.max_line }));
            }
            match parse_line(&line) {
                Ok(None) => continue,
                Ok(Some(msg)) => return Some(Ok(msg)),
                Err(e) => return Some(Err(e)),
            }
        }
    }
}

/// Splits off the first whitespace-delimited word: `(word, rest)`.
fn split_word(s: &str) -> (&str, &str) {
    let s = s.trim_start_matches([' ', '\t']);
    match s.find([' ', '\t']) {
        Some(i) => (&s[..i], &s[i..]),
        None => (s, ""),
    }
}

fn parse_line(line: &[u8]) -> Result<Option<BaseMessage>, ProtocolError> {
    let s = std::str::from_utf8(line).map_err(|_| ProtocolError::NotUtf8)?;
    let (keyword, rest) = split_word(s);
    match keyword {
        "" => Ok(None),
        "ODOM" => {
            let [t, x, y, theta] = numbers("ODOM", ["t", "x", "y", "theta"], rest)?;
            Ok(Some(BaseMessage::Odometry { t, x, y, theta }))
        }
        "POSE" => {
            let [x, y, theta] = numbers("POSE", ["x", "y", "theta"], rest)?;
            Ok(Some(BaseMessage::PoseHint { x, y, theta }))
        }
        "HEALTH" => {
            let (status, text) = split_word(rest);
            let ok = match status {
                "OK" => true,
                "FAULT" => false,
                other => return Err(ProtocolError::BadHealthStatus(truncate(other))),
            };
            Ok(Some(BaseMessage::Health {
                ok,
                text: text.trim_matches([' ', '\t']).to_owned(),
            }))
        }
        other => Err(ProtocolError::UnknownKeyword(truncate(other))),
    }
}

/// The `N` finite numbers named `names` that follow `keyword`.
fn numbers<const N: usize>(
    keyword: &'static str,
    names: [&'static str; N],
    rest: &str,
) -> Result<[f64; N], ProtocolError> {
    let fields: Vec<&str> = rest.split([' ', '\t']).filter(|f| !f.is_empty()).collect();
    if fields.len() != N {
        return Err(ProtocolError::FieldCount {
            keyword,
            expected: N,
            found: fields.len(),
        });
    }
    let mut v = [0.0; N];
    for ((slot, text), field) in v.iter_mut().zip(&fields).zip(names) {
        *slot = text
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| ProtocolError::BadNumber {
                keyword,
                field,
                text: truncate(text),
            })?;
    }
    Ok(v)
}

/// Limits echoed text in errors to 32 characters.
fn truncate(s: &str) -> String {
    s.chars().take(32).collect()
}

/// Encodes a command line (with trailing `\n`). A velocity with any
/// non-finite component is encoded as `STOP` so NaN never reaches motors.
/// Components below 1e-9 in magnitude are sent as `0` to keep lines short.
#[must_use]
pub fn encode_command(cmd: Command) -> String {
    let f = |v: f64| if v.abs() < 1e-9 { 0.0 } else { v };
    match cmd {
        Command::Velocity(t) if t.is_finite() => {
            format!("VEL {} {} {}\n", f(t.vx), f(t.vy), f(t.omega))
        }
        Command::Velocity(_) | Command::Stop => "STOP\n".to_owned(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn odom(t: f64, x: f64, y: f64, theta: f64) -> BaseMessage {
        BaseMessage::Odometry { t, x, y, theta }
    }

    #[test]
    fn split_across_pushes() {
        let mut d = LineDecoder::default();
        d.push(b"ODOM 1.5 0.");
        assert_eq!(d.poll(), None);
        d.push(b"25 -1 3.1");
        assert_eq!(d.poll(), None);
        d.push(b"\nHEALTH OK\n");
        assert_eq!(d.poll(), Some(Ok(odom(1.5, 0.25, -1.0, 3.1))));
        assert_eq!(
            d.poll(),
            Some(Ok(BaseMessage::Health {
                ok: true,
                text: String::new()
            }))
        );
        assert_eq!(d.poll(), None);
    }

    #[test]
    fn a_pose_hint_is_three_finite_numbers() {
        let mut d = LineDecoder::default();
        d.push(b"POSE 1.5 -2 0.25\nPOSE 1 2\nPOSE 1 2 inf\n");
        assert_eq!(
            d.poll(),
            Some(Ok(BaseMessage::PoseHint {
                x: 1.5,
                y: -2.0,
                theta: 0.25
            }))
        );
        assert_eq!(
            d.poll(),
            Some(Err(ProtocolError::FieldCount {
                keyword: "POSE",
                expected: 3,
                found: 2
            }))
        );
        assert!(matches!(
            d.poll(),
            Some(Err(ProtocolError::BadNumber {
                keyword: "POSE",
                field: "theta",
                ..
            }))
        ));
        assert_eq!(d.poll(), None);
    }

    #[test]
    fn crlf_and_blank_lines() {
        let mut d = LineDecoder::default();
        d.push(b"\r\n\nHEALTH FAULT  bumper pressed \r\nODOM 0 0 0 0\r\n");
        assert_eq!(
            d.poll(),
            Some(Ok(BaseMessage::Health {
                ok: false,
                text: "bumper pressed".to_owned()
            }))
        );
        assert_eq!(d.poll(), Some(Ok(odom(0.0, 0.0, 0.0, 0.0))));
        assert_eq!(d.poll(), None);
    }

    #[test]
    fn garbage_then_good() {
        let mut d = LineDecoder::default();
        d.push(b"hello world\nODOM 1 2 3\nODOM 1 2 x 4\nODOM 1 2 NaN 4\nHEALTH MAYBE\n\xff\xfe\nODOM 2 1 0 -0.5\n");
        assert_eq!(
            d.poll(),
            Some(Err(ProtocolError::UnknownKeyword("hello".to_owned())))
        );
        assert_eq!(
            d.poll(),
            Some(Err(ProtocolError::FieldCount {
                keyword: "ODOM",
                expected: 4,
                found: 3
            }))
        );
        let e = d.poll().expect("item").expect_err("bad number");
        assert!(e.to_string().contains("field y"), "{e}");
        assert!(matches!(
            d.poll(),
            Some(Err(ProtocolError::BadNumber { field: "y", .. }))
        ));
        assert!(matches!(
            d.poll(),
            Some(Err(ProtocolError::BadHealthStatus(_)))
        ));
        assert_eq!(d.poll(), Some(Err(ProtocolError::NotUtf8)));
        assert_eq!(d.poll(), Some(Ok(odom(2.0, 1.0, 0.0, -0.5))));
        assert_eq!(d.poll(), None);
    }

    #[test]
    fn over_long_line() {
        let mut d = LineDecoder::new(16);
        d.push(&[b'A'; 40]);
        assert_eq!(d.poll(), Some(Err(ProtocolError::LineTooLong { max: 16 })));
        assert_eq!(d.poll(), None);
        d.push(&[b'B'; 40]);
        assert_eq!(d.poll(), None, "rest of the long line is dropped silently");
        d.push(b"CC\nODOM 1 1 1 1\n");
        assert_eq!(d.poll(), Some(Ok(odom(1.0, 1.0, 1.0, 1.0))));
        // Over-long line arriving complete in one push.
        d.push(b"ODOM 1.000000000000 2 3 4\nHEALTH OK\n");
        assert_eq!(d.poll(), Some(Err(ProtocolError::LineTooLong { max: 16 })));
        assert!(matches!(
            d.poll(),
            Some(Ok(BaseMessage::Health { ok: true, .. }))
        ));
        assert_eq!(d.poll(), None);
    }

    #[test]
    fn encode() {
        assert_eq!(
            encode_command(Command::Velocity(Twist::new(0.3, -0.1, 0.0))),
            "VEL 0.3 -0.1 0\n"
        );
        assert_eq!(encode_command(Command::Stop), "STOP\n");
        assert_eq!(
            encode_command(Command::Velocity(Twist::new(5e-324, -1e-300, 1e300))).len(),
            "VEL 0 0 \n".len() + 301
        );
        assert_eq!(
            encode_command(Command::Velocity(Twist::new(f64::NAN, 0.0, 0.0))),
            "STOP\n"
        );
    }

    proptest! {
        #[test]
        fn decoder_never_panics(chunks in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..64), 0..16)) {
            let mut d = LineDecoder::new(32);
            for c in &chunks {
                d.push(c);
                while d.poll().is_some() {}
            }
        }

        #[test]
        fn odometry_round_trip(
            t in -1e9..1e9f64, x in -1e6..1e6f64, y in -1e6..1e6f64, theta in -4.0..4.0f64,
            split in 0usize..200,
        ) {
            let line = format!("ODOM {t} {x} {y} {theta}\n");
            let bytes = line.as_bytes();
            let split = split.min(bytes.len());
            let mut d = LineDecoder::default();
            d.push(&bytes[..split]);
            let first = d.poll();
            d.push(&bytes[split..]);
            let msg = first.or_else(|| d.poll());
            prop_assert_eq!(msg, Some(Ok(odom(t, x, y, theta))));
            prop_assert_eq!(d.poll(), None);
        }

        #[test]
        fn velocity_encoding_is_parseable(vx in -10.0..10.0f64, vy in -10.0..10.0f64, w in -10.0..10.0f64) {
            let s = encode_command(Command::Velocity(Twist::new(vx, vy, w)));
            let fields: Vec<&str> = s.trim_end().split(' ').collect();
            prop_assert_eq!(fields.len(), 4);
            prop_assert_eq!(fields[0], "VEL");
            prop_assert_eq!(fields[1].parse::<f64>().ok(), Some(vx));
            prop_assert_eq!(fields[2].parse::<f64>().ok(), Some(vy));
            prop_assert_eq!(fields[3].parse::<f64>().ok(), Some(w));
        }
    }
}
