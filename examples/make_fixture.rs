//! Turns scans of a CARMEN log (FLASER lines) into an LMS200 recording: the
//! byte stream a SICK LMS200 would have sent for them, with the log's
//! odometry beside it. This is how `fixtures/csail-0000-0200.rec` is made.
//!
//! ```text
//! cargo run --example make_fixture -- INPUT.clf OUTPUT.rec [FIRST [COUNT]]
//! cargo run --example make_fixture -- ../shared/datasets/mit-csail/mit-csail.clf \
//!     fixtures/csail-0000-0200.rec 0 200
//! ```
//!
//! `FIRST` is the 0-based index of the first FLASER line to take (default
//! 0), `COUNT` how many (default 200).
//!
//! What is written, in time order:
//!
//! - a `Note` naming the sensor set-up (`variant=180/0.5 units=cm mode=00`)
//!   and the source, then a `Baud` record: 38400 Bd, the fastest speed of a
//!   plain RS-232 line, which the log's ~4.7 Hz scan rate fits (a 180°/0.5°
//!   telegram takes 190.6 ms on the wire at 38400 Bd);
//! - per scan, an `Odometry` record at the scan's `ipc_timestamp` with the
//!   log's `odom_x odom_y odom_theta`, then the `B0` telegram of the scan in
//!   cm (`81.91` m, the no-return code of SICK logs, is sent as `0x1FFF`,
//!   "not valid" in measuring mode 00), split into 256-byte `Rx` chunks the
//!   way serial reads return it. Each chunk's time is the arrival of its last
//!   byte, chosen so that the driver's timestamp model
//!   (`lms200::link::timing`: end of telegram − wire time − half the
//!   measurement window) gives back the log's `ipc_timestamp` exactly.
//!
//! The file is then read back with the same reader `clsmap map` uses and
//! compared with the log: ranges to the centimetre, times within 1 µs,
//! odometry within 1 µm / 1 µrad. Any mismatch is an error.

use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter};
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail, ensure};
use clsmap::geometry::{BeamFault, wrap_angle};
use clsmap::input::lms200::{RecordingScans, scan_time_us, seconds};
use lms200::link::timing::{mid_sweep_to_end, wire_time};
use lms200::recording::{Record, RecordingWriter};
use lms200::{Baud, MeasuringMode, Reply, ReplyFrame, Scan, SpecialCode, Status, Units, Variant};

/// The sensor set-up the log's scans are written as.
const VARIANT: Variant = Variant::Fov180Res50;
const UNITS: Units = Units::Cm;
const MODE: MeasuringMode = MeasuringMode::Bits13FieldsAbDazzle;
const BAUD: Baud = Baud::B38400;
/// Bytes per serial read: what a USB serial adapter typically hands over.
const CHUNK_LEN: usize = 256;
/// Status byte of a healthy sensor streaming scans (TL: 0x10, "ok").
const STATUS: Status = Status(0x10);
/// Address of the sensor's reply: host address 0x00 with the reply bit.
const REPLY_ADDRESS: u8 = 0x80;
/// Logged ranges at or above this (m) are the no-return code 8191 cm.
const NO_RETURN_M: f64 = 81.91;
const NOTE_SOURCE: &str = "source=MIT CSAIL 3rd floor (Kuemmerle et al. 2009)";

/// One FLASER line, as logged.
#[derive(Debug)]
struct LoggedScan {
    /// 1-based line number in the log, for messages.
    line: usize,
    /// Ranges in cm; the no-return code as 8191.
    ranges_cm: Vec<u16>,
    odom_x: f64,
    odom_y: f64,
    odom_theta: f64,
    /// `ipc_timestamp` in µs since the Unix epoch.
    t_us: i64,
}

fn main() -> anyhow::Result<()> {
    let usage = "usage: make_fixture INPUT.clf OUTPUT.rec [FIRST [COUNT]]";
    let mut args = std::env::args().skip(1);
    let input = PathBuf::from(args.next().context(usage)?);
    let output = PathBuf::from(args.next().context(usage)?);
    let first: usize = match args.next() {
        Some(a) => a.parse().with_context(|| format!("FIRST `{a}`: {usage}"))?,
        None => 0,
    };
    let count: usize = match args.next() {
        Some(a) => a.parse().with_context(|| format!("COUNT `{a}`: {usage}"))?,
        None => 200,
    };
    ensure!(count > 0, "COUNT must be at least 1");

    let scans = read_flaser(&input, first, count)?;
    ensure!(
        scans.len() == count,
        "{} has only {} FLASER lines from index {first}, {count} wanted",
        input.display(),
        scans.len()
    );
    write_recording(&output, &scans, first)?;
    verify(&output, &scans)?;
    let size = std::fs::metadata(&output)
        .with_context(|| format!("cannot stat {}", output.display()))?
        .len();
    println!(
        "wrote {} ({size} bytes): FLASER scans {first}..{} of {}, verified",
        output.display(),
        first + count,
        input.display()
    );
    Ok(())
}

/// Reads `count` FLASER lines starting with the `first` one (0-based).
fn read_flaser(path: &Path, first: usize, count: usize) -> anyhow::Result<Vec<LoggedScan>> {
    let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    let mut scans = Vec::with_capacity(count);
    let mut index = 0usize;
    for (i, line) in BufReader::new(file).lines().enumerate() {
        let number = i + 1;
        let line = line.with_context(|| format!("{}:{number}: cannot read", path.display()))?;
        if !line.starts_with("FLASER") {
            continue;
        }
        if index >= first {
            let scan = parse_flaser(&line, number)
                .with_context(|| format!("{}:{number}", path.display()))?;
            scans.push(scan);
            if scans.len() == count {
                break;
            }
        }
        index += 1;
    }
    Ok(scans)
}

/// `FLASER n r_1..r_n x y theta odom_x odom_y odom_theta ipc_t host logger_t`
fn parse_flaser(line: &str, number: usize) -> anyhow::Result<LoggedScan> {
    let fields: Vec<&str> = line.split_ascii_whitespace().collect();
    let n: usize = fields
        .get(1)
        .context("no beam count")?
        .parse()
        .context("beam count is not a number")?;
    let expected = usize::from(VARIANT.value_count());
    ensure!(
        n == expected,
        "{n} beams: only 180°/0.5° scans ({expected} beams) are converted"
    );
    ensure!(
        fields.len() == 2 + n + 9,
        "{} fields, a FLASER line of {n} beams has {}",
        fields.len(),
        2 + n + 9
    );
    let ranges_cm = fields[2..2 + n]
        .iter()
        .map(|text| range_cm(text))
        .collect::<anyhow::Result<Vec<u16>>>()?;
    let number_at = |k: usize, name: &str| -> anyhow::Result<f64> {
        let text = fields[2 + n + k];
        text.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .with_context(|| format!("{name} `{text}` is not a number"))
    };
    Ok(LoggedScan {
        line: number,
        ranges_cm,
        odom_x: number_at(3, "odom_x")?,
        odom_y: number_at(4, "odom_y")?,
        odom_theta: number_at(5, "odom_theta")?,
        t_us: micros(fields[2 + n + 6]).context("ipc_timestamp")?,
    })
}

/// A logged range (m, 2 decimals) as the sensor's cm value.
fn range_cm(text: &str) -> anyhow::Result<u16> {
    let metres: f64 = text
        .parse()
        .with_context(|| format!("range `{text}` is not a number"))?;
    let no_return = MODE
        .special_value(SpecialCode::NotValid)
        .context("mode 00 has a no-return code")?;
    if metres >= NO_RETURN_M - 0.005 {
        return Ok(no_return);
    }
    let max = MODE.max_distance().context("mode 00 has a maximum")?;
    let cm = (metres * 100.0).round();
    if !(0.0..=f64::from(max)).contains(&cm) {
        bail!("range `{text}` m does not fit the sensor's 0..={max} cm");
    }
    Ok(cm as u16)
}

/// A decimal timestamp in seconds (at most 6 decimals) as integer µs,
/// without going through floating point.
fn micros(text: &str) -> anyhow::Result<i64> {
    let (whole, fraction) = text.split_once('.').unwrap_or((text, ""));
    ensure!(
        fraction.len() <= 6 && fraction.bytes().all(|b| b.is_ascii_digit()),
        "`{text}` is not a time in seconds with at most 6 decimals"
    );
    let whole: i64 = whole
        .parse()
        .with_context(|| format!("`{text}` is not a time in seconds"))?;
    let fraction: i64 = format!("{fraction:0<6}")
        .parse()
        .with_context(|| format!("`{text}` is not a time in seconds"))?;
    whole
        .checked_mul(1_000_000)
        .and_then(|us| us.checked_add(fraction))
        .with_context(|| format!("`{text}` is out of range"))
}

/// The telegram a streaming LMS200 sends for one scan.
fn telegram(scan: &LoggedScan) -> anyhow::Result<Vec<u8>> {
    ReplyFrame {
        address: REPLY_ADDRESS,
        status: STATUS,
        reply: Reply::ScanData(Scan::complete(scan.ranges_cm.clone(), UNITS, None)),
    }
    .encode()
    .with_context(|| format!("line {}: cannot encode the telegram", scan.line))
}

/// Whole microseconds of a duration that the model keeps at µs resolution
/// (both terms are whole µs at 38400 Bd for 732 bytes; checked by `verify`).
fn duration_us(d: std::time::Duration) -> anyhow::Result<i64> {
    i64::try_from(d.as_micros()).context("duration out of range")
}

/// Writes the note, the line speed, then per scan its odometry and its
/// telegram in chunks, in time order.
fn write_recording(path: &Path, scans: &[LoggedScan], first: usize) -> anyhow::Result<()> {
    let file = File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut writer = RecordingWriter::new(BufWriter::new(file))?;
    let start_us = scans.first().map_or(0, |s| s.t_us);
    writer.write(&Record::Note {
        t_us: start_us,
        text: format!(
            "lms200 variant=180/0.5 units=cm mode={:02x} {NOTE_SOURCE} scans {first}..{}",
            MODE.code(),
            first + scans.len()
        ),
    })?;
    writer.write(&Record::Baud {
        t_us: start_us,
        baud: BAUD.bits_per_second(),
    })?;
    let mut previous_end_us: Option<i64> = None;
    for scan in scans {
        let bytes = telegram(scan)?;
        // The last byte arrives a wire time plus half the measurement
        // window after the mid-sweep time the log gives.
        let end_us =
            scan.t_us + duration_us(wire_time(bytes.len(), BAUD) + mid_sweep_to_end(VARIANT))?;
        if let Some(previous_end_us) = previous_end_us {
            ensure!(
                scan.t_us > previous_end_us,
                "line {}: scan at {} µs comes before the previous telegram ended ({} µs): \
                 scans closer than a telegram's wire time at {} Bd",
                scan.line,
                scan.t_us,
                previous_end_us,
                BAUD.bits_per_second()
            );
        }
        writer.write(&Record::Odometry {
            t_us: scan.t_us,
            x: scan.odom_x,
            y: scan.odom_y,
            theta: scan.odom_theta,
        })?;
        let mut sent = 0usize;
        for chunk in bytes.chunks(CHUNK_LEN) {
            sent += chunk.len();
            let still_to_come = duration_us(wire_time(bytes.len() - sent, BAUD))?;
            writer.write(&Record::Rx {
                t_us: end_us - still_to_come,
                bytes: chunk.to_vec(),
            })?;
        }
        previous_end_us = Some(end_us);
    }
    writer.flush()?;
    Ok(())
}

/// Reads the recording back as `clsmap map` does and compares it with the log.
fn verify(path: &Path, logged: &[LoggedScan]) -> anyhow::Result<()> {
    let file = File::open(path).with_context(|| format!("cannot reopen {}", path.display()))?;
    let records = RecordingScans::new(BufReader::new(file))?
        .collect::<Result<Vec<_>, _>>()
        .with_context(|| format!("reading back {}", path.display()))?;
    ensure!(
        records.len() == logged.len(),
        "read back {} scans, wrote {}",
        records.len(),
        logged.len()
    );
    for (record, want) in records.iter().zip(logged) {
        let line = want.line;
        let got_cm: Vec<u16> = record
            .scan
            .ranges
            .iter()
            .map(|r| match r {
                Ok(m) => Ok((m * 100.0).round() as u16),
                Err(BeamFault::NoReturn) => Ok(8191),
                Err(other) => Err(anyhow::anyhow!("line {line}: unexpected beam {other:?}")),
            })
            .collect::<anyhow::Result<_>>()?;
        ensure!(got_cm == want.ranges_cm, "line {line}: ranges differ");
        let t_error = (record.scan.t - seconds(want.t_us)).abs();
        ensure!(t_error < 1e-6, "line {line}: time off by {t_error} s");
        // The decoder's model and this file's timing agree by construction;
        // check the model the way `decode` applies it, too.
        let scan = Scan::complete(want.ranges_cm.clone(), UNITS, None);
        let end_us = want.t_us
            + duration_us(wire_time(telegram(want)?.len(), BAUD) + mid_sweep_to_end(VARIANT))?;
        let model_error = (seconds(scan_time_us(end_us, &scan, BAUD)) - record.scan.t).abs();
        ensure!(
            model_error < 1e-6,
            "line {line}: timestamp model off by {model_error} s"
        );
        let odometry = record
            .odometry
            .with_context(|| format!("line {line}: no odometry read back"))?;
        let pose_error = (odometry.x - want.odom_x)
            .abs()
            .max((odometry.y - want.odom_y).abs())
            .max(wrap_angle(odometry.theta - want.odom_theta).abs());
        ensure!(
            pose_error < 1e-6,
            "line {line}: odometry off by {pose_error}"
        );
    }
    Ok(())
}
