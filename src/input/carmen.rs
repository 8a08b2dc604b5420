//! CARMEN log files (`.clf`): laser scans and odometry, streamed line by line.
//!
//! Record layouts read here (whitespace separated; angles rad, lengths m,
//! times s; `ipc_timestamp` is the scan time used everywhere):
//!
//! ```text
//! ODOM        x y theta tv rv accel                        ipc_t host logger_t
//! FLASER      n r_1..r_n  x y theta  odom_x odom_y odom_theta  ipc_t host logger_t
//! RAWLASERk   type start_angle fov resolution max_range accuracy remission_mode
//!             n r_1..r_n  m rem_1..rem_m                   ipc_t host logger_t
//! ROBOTLASER1 type start_angle fov resolution max_range accuracy remission_mode
//!             n r_1..r_n  m rem_1..rem_m
//!             laser_x laser_y laser_theta  robot_x robot_y robot_theta
//!             tv rv forward_safety side_safety turn_axis   ipc_t host logger_t
//! ```
//!
//! FLASER beams start at −90° (the old front-laser message carries no
//! geometry), 1° apart for 180 or 181 of them, 0.5° for 360 or 361, as
//! CARMEN reads them, else spread over 180°. FLASER's odometry is the `odom_*` triple (`x y theta` may be a
//! corrected pose), ROBOTLASER1's is the robot pose. RAWLASER lines carry no
//! pose: their odometry is interpolated from the ODOM lines around them.
//! Comments (`#`), blank lines and other record types are skipped.

use super::odometry::ScansAwaitingOdometry;
use super::{DeclaredMount, InputError, ScanRecord};
use crate::geometry::{BeamFault, Pose2, RangeScan};
use std::f64::consts::PI;
use std::io::BufRead;
use thiserror::Error;

/// Ranges at or above this (m) are the "no return" code of SICK logs
/// (8191 cm written as 81.91 m), never a real echo.
pub const NO_RETURN_RANGE: f64 = 81.9;

/// Beam counts above this are refused: no planar scanner of the field gives
/// more, and a corrupt count must not drive a huge allocation.
const MAX_BEAMS: usize = 100_000;

/// What is wrong with one line of a CARMEN log.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum MalformedLine {
    #[error("line is not valid UTF-8")]
    NotUtf8,
    #[error("{record}: missing field `{field}`")]
    MissingField {
        record: &'static str,
        field: &'static str,
    },
    #[error("{record}: field `{field}` is not a finite number: {text:?}")]
    BadNumber {
        record: &'static str,
        field: &'static str,
        text: String,
    },
    #[error("{record}: field `{field}` is not a count: {text:?}")]
    BadCount {
        record: &'static str,
        field: &'static str,
        text: String,
    },
    #[error("{record}: angular resolution {resolution} rad is not positive")]
    BadResolution {
        record: &'static str,
        resolution: f64,
    },
    #[error("{record}: {extra} unexpected field(s) after the logger timestamp")]
    TrailingFields { record: &'static str, extra: usize },
}

/// One useful line of a CARMEN log.
#[derive(Debug, Clone, PartialEq)]
pub enum CarmenEntry {
    /// A laser scan, with the odometry pose the line itself carries (if
    /// any) and the laser's pose on the robot where the line declares it.
    Laser {
        scan: RangeScan,
        odometry: Option<Pose2>,
        mount: Option<Pose2>,
    },
    /// A standalone odometry sample.
    Odometry { t: f64, pose: Pose2 },
}

/// Beam spacing (rad) of a FLASER line of `n` beams, which carries no
/// geometry; the beams start at −90°. As CARMEN reads them: 1° for 181
/// beams and for 180 (an LMS200's 181 less its last, as in the Intel lab's
/// log), 0.5° for 361 and 360; otherwise 180° spread over the beams.
fn flaser_increment(n: usize) -> f64 {
    match n {
        180 | 181 => PI / 180.0,
        360 | 361 => PI / 360.0,
        n if n > 1 => PI / (n - 1) as f64,
        _ => PI,
    }
}

/// Converts one logged range (m) into a beam: the no-return code, zero,
/// negative or non-finite values and readings at the sensor's declared
/// maximum range carry no echo.
fn beam(range: f64, max_range: Option<f64>) -> Result<f64, BeamFault> {
    let at_max = max_range.is_some_and(|m| m > 0.0 && range >= m);
    if !range.is_finite() || range <= 0.0 || range >= NO_RETURN_RANGE || at_max {
        Err(BeamFault::NoReturn)
    } else {
        Ok(range)
    }
}

/// Powers of ten a double holds exactly.
const EXACT_POWERS_OF_TEN: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// A plain decimal such as `12.345` or `-0.5`, with at most 15 digits:
/// its digits and its power of ten are exact doubles, so their quotient
/// is the correctly rounded value, the same bits as `str::parse` gives.
/// `None` for anything else (exponents, `inf`, longer numbers), which the
/// full parser reads. A log holds hundreds of ranges per line: with this,
/// reading CSAIL's lines took 29 % fewer instructions.
fn plain_decimal(text: &str) -> Option<f64> {
    let (negative, digits) = match text.as_bytes() {
        [b'-', rest @ ..] => (true, rest),
        rest => (false, rest),
    };
    let mut mantissa: u64 = 0;
    let mut count = 0;
    let mut decimals = None;
    for (i, &b) in digits.iter().enumerate() {
        match b {
            b'0'..=b'9' => {
                mantissa = mantissa * 10 + u64::from(b - b'0');
                count += 1;
            }
            b'.' if decimals.is_none() && i > 0 => decimals = Some(digits.len() - i - 1),
            _ => return None,
        }
    }
    if count == 0 || count > 15 {
        return None;
    }
    let value = mantissa as f64 / EXACT_POWERS_OF_TEN.get(decimals.unwrap_or(0))?;
    Some(if negative { -value } else { value })
}

/// A cursor over a line's fields that names what it expected when it fails.
struct Fields<'a> {
    record: &'static str,
    it: std::str::SplitAsciiWhitespace<'a>,
}

impl<'a> Fields<'a> {
    fn text(&mut self, field: &'static str) -> Result<&'a str, MalformedLine> {
        self.it.next().ok_or(MalformedLine::MissingField {
            record: self.record,
            field,
        })
    }

    fn number(&mut self, field: &'static str) -> Result<f64, MalformedLine> {
        let text = self.text(field)?;
        match text.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => Err(MalformedLine::BadNumber {
                record: self.record,
                field,
                text: text.to_owned(),
            }),
        }
    }

    /// A range: parsed like a number, but "inf"/"nan" are kept (as
    /// no-return beams) rather than refused.
    fn range(&mut self) -> Result<f64, MalformedLine> {
        let text = self.text("range")?;
        if let Some(v) = plain_decimal(text) {
            return Ok(v);
        }
        text.parse::<f64>().map_err(|_| MalformedLine::BadNumber {
            record: self.record,
            field: "range",
            text: text.to_owned(),
        })
    }

    fn count(&mut self, field: &'static str) -> Result<usize, MalformedLine> {
        let text = self.text(field)?;
        match text.parse::<usize>() {
            Ok(n) if n <= MAX_BEAMS => Ok(n),
            _ => Err(MalformedLine::BadCount {
                record: self.record,
                field,
                text: text.to_owned(),
            }),
        }
    }

    fn pose(
        &mut self,
        x: &'static str,
        y: &'static str,
        theta: &'static str,
    ) -> Result<Pose2, MalformedLine> {
        Ok(Pose2::new(
            self.number(x)?,
            self.number(y)?,
            self.number(theta)?,
        ))
    }

    fn ranges(
        &mut self,
        n: usize,
        max_range: Option<f64>,
    ) -> Result<Vec<Result<f64, BeamFault>>, MalformedLine> {
        // Sized up front (`n` is at most `MAX_BEAMS`): grown push by push,
        // the reallocations cost as much as reading the numbers.
        let mut ranges = Vec::with_capacity(n);
        for _ in 0..n {
            ranges.push(beam(self.range()?, max_range));
        }
        Ok(ranges)
    }

    /// `ipc_timestamp ipc_hostname logger_timestamp`, then end of line;
    /// returns the ipc timestamp (s).
    fn tail(&mut self) -> Result<f64, MalformedLine> {
        let t = self.number("ipc_timestamp")?;
        self.text("ipc_hostname")?;
        self.number("logger_timestamp")?;
        let extra = self.it.by_ref().count();
        if extra > 0 {
            return Err(MalformedLine::TrailingFields {
                record: self.record,
                extra,
            });
        }
        Ok(t)
    }
}

/// Parses one line. `Ok(None)` for comments, blank lines and record types
/// the mapper does not use.
pub fn parse_line(line: &str) -> Result<Option<CarmenEntry>, MalformedLine> {
    let mut words = line.split_ascii_whitespace();
    let Some(tag) = words.next() else {
        return Ok(None);
    };
    if tag.starts_with('#') {
        return Ok(None);
    }
    let record: &'static str = match tag {
        "ODOM" => "ODOM",
        "FLASER" => "FLASER",
        "RAWLASER1" => "RAWLASER1",
        "RAWLASER2" => "RAWLASER2",
        "RAWLASER3" => "RAWLASER3",
        "RAWLASER4" => "RAWLASER4",
        "ROBOTLASER1" => "ROBOTLASER1",
        _ => return Ok(None),
    };
    let mut f = Fields { record, it: words };
    let entry = match record {
        "ODOM" => {
            let pose = f.pose("x", "y", "theta")?;
            f.number("tv")?;
            f.number("rv")?;
            f.number("accel")?;
            let t = f.tail()?;
            CarmenEntry::Odometry { t, pose }
        }
        "FLASER" => {
            let n = f.count("num_readings")?;
            let ranges = f.ranges(n, None)?;
            f.pose("x", "y", "theta")?;
            let odom = f.pose("odom_x", "odom_y", "odom_theta")?;
            let t = f.tail()?;
            let angle_increment = flaser_increment(n);
            CarmenEntry::Laser {
                scan: RangeScan {
                    t,
                    angle_min: -PI / 2.0,
                    angle_increment,
                    ranges,
                },
                odometry: Some(odom),
                mount: None,
            }
        }
        _ => {
            // RAWLASERk and ROBOTLASER1 share the laser header.
            f.number("laser_type")?;
            let angle_min = f.number("start_angle")?;
            f.number("field_of_view")?;
            let resolution = f.number("angular_resolution")?;
            if resolution <= 0.0 {
                return Err(MalformedLine::BadResolution { record, resolution });
            }
            let max_range = f.number("maximum_range")?;
            f.number("accuracy")?;
            f.number("remission_mode")?;
            let n = f.count("num_readings")?;
            let ranges = f.ranges(n, Some(max_range))?;
            let n_remissions = f.count("num_remissions")?;
            for _ in 0..n_remissions {
                f.number("remission")?;
            }
            let (odometry, mount) = if record == "ROBOTLASER1" {
                let laser = f.pose("laser_pose_x", "laser_pose_y", "laser_pose_theta")?;
                let robot = f.pose("robot_pose_x", "robot_pose_y", "robot_pose_theta")?;
                for field in [
                    "laser_tv",
                    "laser_rv",
                    "forward_safety_dist",
                    "side_safety_dist",
                    "turn_axis",
                ] {
                    f.number(field)?;
                }
                (Some(robot), Some(robot.between(&laser)))
            } else {
                (None, None)
            };
            let t = f.tail()?;
            CarmenEntry::Laser {
                scan: RangeScan {
                    t,
                    angle_min,
                    angle_increment: resolution,
                    ranges,
                },
                odometry,
                mount,
            }
        }
    };
    Ok(Some(entry))
}

/// The laser lines of a CARMEN log that parse: each scan, with the laser's
/// pose on the robot where the line declares it. Lines that cannot be
/// parsed are passed over (the mapping names them); reading stops at the
/// end or at a read error.
fn laser_lines<R: BufRead>(mut reader: R) -> impl Iterator<Item = (RangeScan, Option<Pose2>)> {
    let mut buf = Vec::new();
    std::iter::from_fn(move || {
        loop {
            buf.clear();
            if !matches!(reader.read_until(b'\n', &mut buf), Ok(n) if n > 0) {
                return None;
            }
            if let Ok(Ok(Some(CarmenEntry::Laser { scan, mount, .. }))) =
                std::str::from_utf8(&buf).map(parse_line)
            {
                return Some((scan, mount));
            }
        }
    })
}

/// Laser lines read for [`declared_laser_mount`].
const MOUNT_LINES: usize = 100;
/// How far (m, rad) the mounts those lines declare may differ and still be
/// one mounting: a log writes its poses to 6 decimals.
const MOUNT_TOLERANCE: f64 = 1e-3;
/// Farthest a laser sits from its robot's centre (m): a "mounting" farther
/// off is the offset between two frames (a corrected laser pose beside raw
/// odometry, both still while the log begins).
const MAX_MOUNT_OFFSET: f64 = 2.0;

/// The laser's pose on the robot as the first `MOUNT_LINES` laser lines
/// of a CARMEN log declare it (ROBOTLASER1 carries the laser's pose beside
/// the robot's; FLASER and RAWLASER lines declare none). Mounts that
/// disagree, or one farther than `MAX_MOUNT_OFFSET` from the robot's
/// centre (a corrected laser pose beside raw odometry), are
/// [`DeclaredMount::Varying`]. Lines that cannot be parsed are passed over
/// here; the mapping names them.
pub fn declared_laser_mount<R: BufRead>(reader: R) -> DeclaredMount {
    let mut first: Option<Pose2> = None;
    for (_, mount) in laser_lines(reader).take(MOUNT_LINES) {
        match (mount, first) {
            (Some(m), None) => first = Some(m),
            (Some(m), Some(f)) => {
                let far = (m.x - f.x).abs().max((m.y - f.y).abs());
                if far > MOUNT_TOLERANCE
                    || crate::geometry::wrap_angle(m.theta - f.theta).abs() > MOUNT_TOLERANCE
                {
                    return DeclaredMount::Varying;
                }
            }
            (None, _) => {}
        }
    }
    match first {
        None => DeclaredMount::None,
        Some(m) if m.x.hypot(m.y) > MAX_MOUNT_OFFSET => DeclaredMount::Varying,
        Some(m) => DeclaredMount::Fixed(m),
    }
}

/// Laser lines read for [`repeated_no_return`].
const NO_RETURN_LINES: usize = 2000;
/// Beams of one scan that read a candidate exactly, in runs whose
/// neighbours read none or read far nearer ...
const NO_RETURN_BEAMS: usize = 5;
/// ... in this many scans make it the log's code for no return.
const NO_RETURN_SCANS: usize = 5;
/// How far nearer (m) a beam beside a candidate must read: a wall beyond
/// the others, seen square on, gives neighbours within centimetres of one
/// another (at a centimetre's resolution several may read one value).
const NO_RETURN_STEP: f64 = 1.0;
/// The LMS200's 8 m (mm) mode writes its special values (no echo,
/// dazzled, out of range) as 8183–8191 mm.
const MM_MODE_CODES: [f64; 2] = [8.183, 8.191];

/// The shortest range (m) a CARMEN log writes for a beam without an echo,
/// where it writes one below the SICK cm-mode codes (81.9 m and up, always
/// read as none), from its first `NO_RETURN_LINES` laser lines:
/// their longest reading, when `NO_RETURN_BEAMS` beams of each of
/// `NO_RETURN_SCANS` scans read exactly it, in runs whose neighbours read
/// none or read more than `NO_RETURN_STEP` nearer. A code is read by
/// every beam that meets nothing; a real surface that far by beams beside
/// others that read it within its noise. Where that longest reading is one
/// of the 8 m mode's special values, any of them counts, and all of them
/// are codes: 8.183 m is returned.
///
/// Lines that cannot be parsed are passed over.
pub fn repeated_no_return<R: BufRead>(reader: R) -> Option<f64> {
    // Each scan's longest reading and how many beams read it as a code.
    let mut longest: Vec<(f64, usize)> = Vec::new();
    for (scan, _) in laser_lines(reader).take(NO_RETURN_LINES) {
        let range = |i: usize| scan.ranges.get(i).and_then(|r| r.as_ref().ok().copied());
        let Some(max) = (0..scan.ranges.len()).filter_map(range).reduce(f64::max) else {
            continue;
        };
        // Runs of beams that read it, counted where the beams on either
        // side read none or read far nearer.
        let apart = |j: Option<usize>| j.and_then(range).is_none_or(|r| r < max - NO_RETURN_STEP);
        let mut codes = 0;
        let mut i = 0;
        while i < scan.ranges.len() {
            if range(i) != Some(max) {
                i += 1;
                continue;
            }
            let first = i;
            while range(i) == Some(max) {
                i += 1;
            }
            if apart(first.checked_sub(1)) && apart(Some(i)) {
                codes += i - first;
            }
        }
        longest.push((max, codes));
    }
    let max = longest.iter().map(|&(m, _)| m).reduce(f64::max)?;
    let mm_mode = MM_MODE_CODES[0]..=MM_MODE_CODES[1];
    // Scans whose longest reading, read as a code, is the log's longest
    // (or, in the 8 m mode, any of its special values).
    let repeated = longest
        .iter()
        .filter(|&&(m, n)| {
            n >= NO_RETURN_BEAMS && (m == max || (mm_mode.contains(&max) && mm_mode.contains(&m)))
        })
        .count();
    (repeated >= NO_RETURN_SCANS).then(|| {
        if mm_mode.contains(&max) {
            MM_MODE_CODES[0]
        } else {
            max
        }
    })
}

/// Streams the scans of a CARMEN log with the odometry pose at each scan.
///
/// Scans are yielded in file order. A scan whose line carries no pose
/// (RAWLASER) waits until an ODOM sample at or after its time has been read
/// (or the file ends), so its odometry is interpolated, not guessed; memory
/// stays bounded by the scans between two odometry samples.
#[derive(Debug)]
pub struct CarmenScans<R> {
    reader: R,
    line_no: usize,
    buf: Vec<u8>,
    /// Scans read but not yet yielded, and the odometry they wait for.
    pending: ScansAwaitingOdometry,
    finished: bool,
    /// Time of the last scan queued, to skip scans out of time order.
    last_scan_t: Option<f64>,
}

impl<R: BufRead> CarmenScans<R> {
    pub fn new(reader: R) -> Self {
        CarmenScans {
            reader,
            line_no: 0,
            buf: Vec::new(),
            pending: ScansAwaitingOdometry::default(),
            finished: false,
            last_scan_t: None,
        }
    }

    /// Reads one line into the pending queue or the odometry track.
    fn read_one(&mut self) -> Result<(), InputError> {
        self.buf.clear();
        let n = self
            .reader
            .read_until(b'\n', &mut self.buf)
            .map_err(|source| InputError::Read {
                line: self.line_no + 1,
                source,
            })?;
        if n == 0 {
            self.finished = true;
            return Ok(());
        }
        self.line_no += 1;
        let line = self.line_no;
        let text = std::str::from_utf8(&self.buf).map_err(|_| InputError::Malformed {
            line,
            kind: MalformedLine::NotUtf8,
        })?;
        match parse_line(text).map_err(|kind| InputError::Malformed { line, kind })? {
            Some(CarmenEntry::Laser { scan, odometry, .. }) => {
                if let Some(previous) = self.last_scan_t.filter(|&p| scan.t <= p) {
                    return Err(InputError::ScanOutOfOrder {
                        at: format!("line {line}"),
                        t: scan.t,
                        previous,
                    });
                }
                self.last_scan_t = Some(scan.t);
                self.pending.push_scan(scan, odometry);
            }
            Some(CarmenEntry::Odometry { t, pose }) => self
                .pending
                .push_odometry(t, pose)
                .map_err(|error| InputError::Odometry { line, error })?,
            None => {}
        }
        Ok(())
    }
}

impl<R: BufRead> Iterator for CarmenScans<R> {
    type Item = Result<ScanRecord, InputError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(record) = self.pending.pop(self.finished) {
                return Some(Ok(record));
            }
            if self.finished {
                return None;
            }
            if let Err(e) = self.read_one() {
                // A bad line is skipped (the caller counts it); a failed
                // read ends the log.
                if !e.is_skipped_item() {
                    self.finished = true;
                    self.pending.clear();
                }
                return Some(Err(e));
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn plain_decimals_read_as_the_full_parser_reads_them() {
        for text in [
            "0",
            "0.0",
            "-0.0",
            "5.",
            "12.345",
            "81.91",
            "0.001",
            "-3.14159",
            "999999999999999",
            "0.00000000000001",
            "1.000000000000",
        ] {
            let expected = text.parse::<f64>().unwrap();
            assert_eq!(
                plain_decimal(text).map(f64::to_bits),
                Some(expected.to_bits()),
                "{text}"
            );
        }
        for text in [
            "",
            "-",
            ".5",
            "1e3",
            "inf",
            "nan",
            "+1",
            "1.2.3",
            "1,5",
            "1000000000000000",
            "0.000000000000000000001",
        ] {
            assert_eq!(plain_decimal(text), None, "{text}");
        }
    }

    proptest::proptest! {
        #[test]
        fn any_plain_decimal_reads_to_the_same_bits(
            negative: bool,
            whole in 0u64..10_000_000,
            fraction in 0u64..100_000_000,
            decimals in 0usize..9,
        ) {
            let fraction = fraction % 10u64.pow(decimals as u32);
            let sign = if negative { "-" } else { "" };
            let text = if decimals == 0 {
                format!("{sign}{whole}")
            } else {
                format!("{sign}{whole}.{fraction:0decimals$}")
            };
            let expected = text.parse::<f64>().unwrap();
            proptest::prop_assert_eq!(
                plain_decimal(&text).map(f64::to_bits),
                Some(expected.to_bits()),
                "{}", text
            );
        }
    }

    fn flaser(ranges: &[&str], odom: (f64, f64, f64), t: f64) -> String {
        format!(
            "FLASER {} {} 9.0 9.0 0.0 {} {} {} {t} b21 0.5\n",
            ranges.len(),
            ranges.join(" "),
            odom.0,
            odom.1,
            odom.2
        )
    }

    fn scans(text: &str) -> Vec<Result<ScanRecord, InputError>> {
        CarmenScans::new(text.as_bytes()).collect()
    }

    /// The scan, odometry and mounting of a laser line.
    fn laser(line: &str) -> (RangeScan, Option<Pose2>, Option<Pose2>) {
        match parse_line(line).unwrap() {
            Some(CarmenEntry::Laser {
                scan,
                odometry,
                mount,
            }) => (scan, odometry, mount),
            other => panic!("not a laser entry: {other:?}"),
        }
    }

    #[test]
    fn flaser_spans_180_degrees_and_marks_no_return() {
        let line = flaser(
            &["1.00", "81.91", "2.50"],
            (576.5, 0.1, -2.2),
            1134864629.895182,
        );
        let (scan, odometry, _) = laser(&line);
        assert_eq!(scan.t, 1134864629.895182);
        assert_eq!(scan.angle_min, -PI / 2.0);
        assert!((scan.fov() - PI).abs() < 1e-12);
        assert_eq!(
            scan.ranges,
            vec![Ok(1.0), Err(BeamFault::NoReturn), Ok(2.5)]
        );
        assert_eq!(odometry, Some(Pose2::new(576.5, 0.1, -2.2)));
    }

    #[test]
    fn flaser_of_180_beams_is_read_one_degree_apart() {
        let ranges = vec!["2.0"; 180];
        let line = flaser(&ranges, (0.0, 0.0, 0.0), 1.0);
        let (scan, ..) = laser(&line);
        assert_eq!(scan.angle_min, -PI / 2.0);
        assert!((scan.angle(179) - 89f64.to_radians()).abs() < 1e-12);
        for (n, degrees) in [(181, 1.0), (360, 0.5), (361, 0.5), (91, 2.0)] {
            let ranges = vec!["2.0"; n];
            let line = flaser(&ranges, (0.0, 0.0, 0.0), 1.0);
            let (scan, ..) = laser(&line);
            assert!(
                (scan.angle_increment - f64::to_radians(degrees)).abs() < 1e-12,
                "{n}"
            );
        }
    }

    #[test]
    fn no_return_threshold_and_invalid_values() {
        assert_eq!(beam(81.91, None), Err(BeamFault::NoReturn));
        assert_eq!(beam(81.9, None), Err(BeamFault::NoReturn));
        assert_eq!(beam(81.89, None), Ok(81.89));
        assert_eq!(beam(0.0, None), Err(BeamFault::NoReturn));
        assert_eq!(beam(f64::INFINITY, None), Err(BeamFault::NoReturn));
        assert_eq!(beam(8.0, Some(8.0)), Err(BeamFault::NoReturn));
        assert_eq!(beam(7.99, Some(8.0)), Ok(7.99));
    }

    #[test]
    fn rawlaser_carries_its_own_geometry() {
        let line = "RAWLASER1 0 -1.5 3.0 0.0175 8.0 0.01 0 3 1.0 8.0 2.0 \
                    2 100 200 12.5 host 12.6";
        let (scan, odometry, mount) = laser(line);
        assert_eq!(scan.angle_min, -1.5);
        assert_eq!(scan.angle_increment, 0.0175);
        assert_eq!(
            scan.ranges,
            vec![Ok(1.0), Err(BeamFault::NoReturn), Ok(2.0)]
        );
        assert_eq!(scan.t, 12.5);
        assert_eq!(odometry, None);
        assert_eq!(mount, None);
    }

    #[test]
    fn robotlaser_uses_the_robot_pose_as_odometry() {
        let line = "ROBOTLASER1 0 -1.5708 3.1416 0.5 81.9 0.01 0 2 1.5 2.5 0 \
                    1.1 2.1 0.3 1.0 2.0 0.3 0.2 0.0 0.5 0.2 0.0 7.25 host 7.3";
        let (scan, odometry, mount) = laser(line);
        assert_eq!(scan.ranges, vec![Ok(1.5), Ok(2.5)]);
        assert_eq!(odometry, Some(Pose2::new(1.0, 2.0, 0.3)));
        assert_eq!(scan.t, 7.25);
        // The laser 0.1 m on in x and y of the map, the robot turned 0.3
        // rad: on the robot it sits (0.1 cos 0.3 + 0.1 sin 0.3, ...).
        let mount = mount.unwrap();
        let (c, s) = (0.3f64.cos(), 0.3f64.sin());
        assert!((mount.x - 0.1 * (c + s)).abs() < 1e-12, "{mount:?}");
        assert!((mount.y - 0.1 * (c - s)).abs() < 1e-12, "{mount:?}");
        assert!(mount.theta.abs() < 1e-12);
    }

    /// A ROBOTLASER1 line with the robot at `robot` and the laser at
    /// `laser` (x, y, θ), two beams.
    fn robotlaser(robot: (f64, f64, f64), laser: (f64, f64, f64), t: f64) -> String {
        format!(
            "ROBOTLASER1 0 -1.5708 3.1416 0.5 81.9 0.01 0 2 1.5 2.5 0 \
             {} {} {} {} {} {} 0.2 0.0 0.5 0.2 0.0 {t} host {t}\n",
            laser.0, laser.1, laser.2, robot.0, robot.1, robot.2
        )
    }

    #[test]
    fn the_laser_mount_is_read_where_the_lines_agree_on_it() {
        // The laser 0.2 m ahead of the robot, which turns and drives.
        let mut text = String::from("# a comment\nROBOTLASER1 broken\n");
        for k in 0..5 {
            let (x, y, th) = (0.3 * k as f64, 0.1, 0.4 * k as f64);
            let laser = (x + 0.2 * th.cos(), y + 0.2 * th.sin(), th);
            text += &robotlaser((x, y, th), laser, k as f64);
        }
        let DeclaredMount::Fixed(m) = declared_laser_mount(text.as_bytes()) else {
            panic!("no mount read");
        };
        assert!((m.x - 0.2).abs() < 1e-9 && m.y.abs() < 1e-9 && m.theta.abs() < 1e-9);
        // A laser pose that wanders on the robot (a corrected pose beside
        // raw odometry) is no mounting.
        text += &robotlaser((2.0, 0.1, 0.0), (2.3, 0.1, 0.0), 9.0);
        assert_eq!(
            declared_laser_mount(text.as_bytes()),
            DeclaredMount::Varying
        );
        // Laser poses 5 m from the robot's: two frames, not a mounting.
        let far: String = (0..3)
            .map(|k| robotlaser((0.0, 0.0, 0.0), (5.0, 0.0, 0.0), k as f64))
            .collect();
        assert_eq!(declared_laser_mount(far.as_bytes()), DeclaredMount::Varying);
        // FLASER declares none.
        let flaser = flaser(&["1.0", "2.0"], (1.0, 2.0, 0.3), 5.0);
        assert_eq!(declared_laser_mount(flaser.as_bytes()), DeclaredMount::None);
    }

    #[test]
    fn a_repeated_longest_reading_is_the_logs_code_for_no_return() {
        // Scans of a room whose open side reads `code`, the log's code.
        let scan = |code: &str, t: f64| {
            let mut ranges: Vec<String> = (0..20)
                .map(|i| format!("{:.2}", 3.0 + 0.01 * i as f64))
                .collect();
            ranges.extend(std::iter::repeat_n(code.to_string(), 6));
            let ranges: Vec<&str> = ranges.iter().map(String::as_str).collect();
            flaser(&ranges, (0.0, 0.0, 0.0), t)
        };
        let log = |code: &str, scans: usize| -> String {
            (0..scans).map(|k| scan(code, k as f64)).collect()
        };
        assert_eq!(repeated_no_return(log("50.0", 6).as_bytes()), Some(50.0));
        // The SICK code is read as no return anyway: nothing to find.
        assert_eq!(repeated_no_return(log("81.91", 6).as_bytes()), None);
        // Too few scans repeat it: a far wall, not a code.
        assert_eq!(repeated_no_return(log("50.0", 4).as_bytes()), None);
        // A log of the 8 m mode: all its special values are codes.
        assert_eq!(repeated_no_return(log("8.191", 6).as_bytes()), Some(8.183));
        // A wall square on, the farthest thing in view, read as one value
        // by eight beams whose neighbours read it a centimetre nearer: no
        // code.
        let wall = |t: f64| {
            let mut ranges: Vec<&str> = vec!["3.0"; 20];
            ranges.extend(["11.99"]);
            ranges.extend(["12.0"; 8]);
            ranges.extend(["11.99", "3.0"]);
            flaser(&ranges, (0.0, 0.0, 0.0), t)
        };
        let walls: String = (0..6).map(|k| wall(k as f64)).collect();
        assert_eq!(repeated_no_return(walls.as_bytes()), None);
        // Nor is such a wall at 8.185 m, within the 8 m mode's band: a
        // room's far wall must not cut the whole log's ranges there.
        let near_band: String = (0..6)
            .map(|k| {
                wall(k as f64)
                    .replace("12.0 ", "8.185 ")
                    .replace("11.99", "8.18")
            })
            .collect();
        assert_eq!(repeated_no_return(near_band.as_bytes()), None);
    }

    #[test]
    fn odom_line_parses() {
        let e = parse_line("ODOM 1.0 2.0 0.5 0.3 0.0 0.0 100.25 host 100.3").unwrap();
        assert_eq!(
            e,
            Some(CarmenEntry::Odometry {
                t: 100.25,
                pose: Pose2::new(1.0, 2.0, 0.5)
            })
        );
    }

    #[test]
    fn comments_blank_and_unknown_lines_are_skipped() {
        for line in [
            "# FLASER 3 1 2",
            "",
            "   \t",
            "PARAM robot_width 0.5 1.0 host 1.0",
            "RLASER 1 2",
        ] {
            assert_eq!(parse_line(line), Ok(None), "{line:?}");
        }
    }

    #[test]
    fn malformed_lines_name_the_problem() {
        let cases: &[(&str, MalformedLine)] = &[
            (
                "FLASER 3 1.0 2.0",
                MalformedLine::MissingField {
                    record: "FLASER",
                    field: "range",
                },
            ),
            (
                "FLASER 1 1.0 0 0 0 0 0 0 abc host 1.0",
                MalformedLine::BadNumber {
                    record: "FLASER",
                    field: "ipc_timestamp",
                    text: "abc".into(),
                },
            ),
            (
                "FLASER -2 1.0",
                MalformedLine::BadCount {
                    record: "FLASER",
                    field: "num_readings",
                    text: "-2".into(),
                },
            ),
            (
                "ODOM 1 2 3 0 0 0 5.0 host 5.0 extra",
                MalformedLine::TrailingFields {
                    record: "ODOM",
                    extra: 1,
                },
            ),
            (
                "RAWLASER2 0 -1.57 3.14 0 8 0.01 0 0 0 1.0 h 1.0",
                MalformedLine::BadResolution {
                    record: "RAWLASER2",
                    resolution: 0.0,
                },
            ),
        ];
        for (line, want) in cases {
            assert_eq!(parse_line(line).as_ref(), Err(want), "{line:?}");
        }
    }

    #[test]
    fn stream_reports_the_line_number_of_a_malformed_line() {
        let text = format!(
            "# comment\n{}FLASER 2 1.0 nope 0 0 0 0 0 0 2.0 h 2.0\n{}",
            flaser(&["1.0"], (0.0, 0.0, 0.0), 1.0),
            flaser(&["1.0"], (0.0, 0.0, 0.0), 3.0)
        );
        let out = scans(&text);
        assert_eq!(
            out.len(),
            3,
            "one scan, the skipped line's error, the next scan"
        );
        assert!(out[0].is_ok() && out[2].is_ok());
        let err = out[1].as_ref().unwrap_err();
        assert!(
            matches!(err, InputError::Malformed { line: 3, .. }),
            "{err}"
        );
        assert!(err.to_string().starts_with("line 3: FLASER"), "{err}");
    }

    #[test]
    fn non_utf8_line_is_an_error_with_its_number() {
        let mut bytes = flaser(&["1.0"], (0.0, 0.0, 0.0), 1.0).into_bytes();
        bytes.extend_from_slice(b"FLASER \xff\n");
        let out: Vec<_> = CarmenScans::new(&bytes[..]).collect();
        assert!(matches!(
            out[1],
            Err(InputError::Malformed {
                line: 2,
                kind: MalformedLine::NotUtf8
            })
        ));
    }

    #[test]
    fn rawlaser_odometry_is_interpolated_from_odom_lines() {
        let text = "ODOM 0.0 0.0 0.0 0 0 0 10.0 h 10.0\n\
                    RAWLASER1 0 -1.57 3.14 0.5 80 0.01 0 1 1.0 0 10.5 h 10.5\n\
                    RAWLASER1 0 -1.57 3.14 0.5 80 0.01 0 1 1.0 0 10.75 h 10.75\n\
                    ODOM 1.0 0.0 0.2 0 0 0 11.0 h 11.0\n\
                    RAWLASER1 0 -1.57 3.14 0.5 80 0.01 0 1 1.0 0 12.0 h 12.0\n";
        let out: Vec<ScanRecord> = scans(text).into_iter().map(Result::unwrap).collect();
        let times: Vec<f64> = out.iter().map(|r| r.scan.t).collect();
        assert_eq!(times, vec![10.5, 10.75, 12.0]);
        let p = out[0].odometry.unwrap();
        assert!((p.x - 0.5).abs() < 1e-12 && (p.theta - 0.1).abs() < 1e-12);
        assert!((out[1].odometry.unwrap().x - 0.75).abs() < 1e-12);
        // After the last ODOM the newest sample is held.
        assert_eq!(out[2].odometry, Some(Pose2::new(1.0, 0.0, 0.2)));
    }

    #[test]
    fn log_without_odometry_yields_scans_without_odometry() {
        let text = "RAWLASER1 0 -1.57 3.14 0.5 80 0.01 0 1 1.0 0 1.0 h 1.0\n";
        let out: Vec<ScanRecord> = scans(text).into_iter().map(Result::unwrap).collect();
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].odometry, None);
    }

    #[test]
    fn out_of_order_odometry_is_an_error_with_its_line() {
        let text = "ODOM 0 0 0 0 0 0 10.0 h 10.0\nODOM 0 0 0 0 0 0 9.0 h 9.0\n";
        let out = scans(text);
        assert!(matches!(out[0], Err(InputError::Odometry { line: 2, .. })));
    }

    #[test]
    fn bad_lines_are_skipped_named_and_the_rest_read() {
        let r = ["1.0", "2.0", "3.0"];
        let text = [
            flaser(&r, (0.0, 0.0, 0.0), 10.0),
            "FLASER 3 1.0 nope\n".to_owned(),
            flaser(&r, (0.1, 0.0, 0.0), 10.2),
            // Back in time, then a duplicate time: both skipped.
            flaser(&r, (0.2, 0.0, 0.0), 10.1),
            flaser(&r, (0.2, 0.0, 0.0), 10.2),
            "ODOM 1 0 0 0 0 0 10.3 host 10.3\n".to_owned(),
            "ODOM 1 0 0 0 0 0 10.25 host 10.25\n".to_owned(),
            "ODOM nan 0 0 0 0 0 10.35 host 10.35\n".to_owned(),
            flaser(&r, (0.3, 0.0, 0.0), 10.4),
        ]
        .concat();
        let items = scans(&text);
        let good: Vec<f64> = items
            .iter()
            .filter_map(|i| Some(i.as_ref().ok()?.scan.t))
            .collect();
        assert_eq!(good, vec![10.0, 10.2, 10.4]);
        let lines: Vec<String> = items
            .iter()
            .filter_map(|i| i.as_ref().err())
            .inspect(|e| assert!(e.is_skipped_item(), "{e}"))
            .map(|e| e.to_string())
            .collect();
        assert_eq!(lines.len(), 5, "{lines:?}");
        for (e, line) in lines
            .iter()
            .zip(["line 2", "line 4", "line 5", "line 7", "line 8"])
        {
            assert!(e.contains(line), "{e} should name {line}");
        }
    }
}
