//! The `clsmap` command line, as a user meets it: the built binary run on
//! the recorded fixtures, on the real MIT CSAIL log, on bad input, and
//! against the LMS200 emulator over a pseudo-terminal.
//!
//! Fixtures (`fixtures/README.md` says how they were made):
//! - `csail-0000-0200.rec`: the first 200 scans of the CSAIL log as the
//!   telegrams an LMS200 sends at 38400 Bd, with the log's odometry;
//! - `emulator-noisy-500k.rec`: the driver talking to the emulator over a
//!   noisy line (handshake, baud switch, corrupted telegrams).
//!
//! Parts that compare with the CSAIL log read `../shared/datasets/mit-csail/`
//! relative to the crate root and are skipped, with a message, when it is
//! absent.

#![allow(clippy::unwrap_used)]

use std::fmt;
use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use lms200::recording::{Record, RecordingError, RecordingReader};
use lms200::{DecodeEvent, Decoder, Reply};

// ---------------------------------------------------------------------------
// Harness: run the binary, capture what it says, clean up after it.
// ---------------------------------------------------------------------------

/// Longest any single command may run before the test fails (generous:
/// debug build on a loaded 2-core machine; commands take well under 5 s).
const RUN_LIMIT: Duration = Duration::from_secs(120);
/// Longest the emulator may take to create its link.
const EMULATOR_START_LIMIT: Duration = Duration::from_secs(30);
/// Longest the emulator may take to stop after SIGINT.
const EMULATOR_STOP_LIMIT: Duration = Duration::from_secs(30);

/// What one run of `clsmap` did.
struct Run {
    command: String,
    status: ExitStatus,
    stdout: String,
    stderr: String,
}

impl fmt::Display for Run {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        const SHOWN: usize = 3000;
        let cut = |s: &str| -> String {
            if s.len() <= SHOWN {
                s.to_owned()
            } else {
                let mut end = SHOWN;
                while !s.is_char_boundary(end) {
                    end -= 1;
                }
                format!("{}… ({} bytes in all)", &s[..end], s.len())
            }
        };
        write!(
            f,
            "$ {}\nexit: {}\n--- stdout ---\n{}\n--- stderr ---\n{}",
            self.command,
            self.status,
            cut(&self.stdout),
            cut(&self.stderr)
        )
    }
}

impl Run {
    /// Asserts exit code 0.
    fn succeeded(self) -> Run {
        assert!(self.status.success(), "expected success:\n{self}");
        self
    }

    /// Asserts a non-zero exit code (not a crash by signal).
    fn failed(self) -> Run {
        assert!(
            matches!(self.status.code(), Some(c) if c != 0),
            "expected a non-zero exit code:\n{self}"
        );
        self
    }

    /// Asserts that stderr contains `text`.
    fn says(self, text: &str) -> Run {
        assert!(
            self.stderr.contains(text),
            "expected stderr to contain {text:?}:\n{self}"
        );
        self
    }

    fn stdout_lines(&self) -> Vec<&str> {
        self.stdout.lines().collect()
    }
}

/// The `clsmap` binary under test, with a quiet, colourless environment.
fn clsmap_command() -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_clsmap"));
    command
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .env("NO_COLOR", "1")
        .env_remove("RUST_LOG");
    command
}

/// Runs `clsmap ARGS` to completion (at most [`RUN_LIMIT`]).
fn clsmap(args: &[&str]) -> Run {
    let command = format!("clsmap {}", args.join(" "));
    let mut child = clsmap_command()
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot start {command}: {e}"));
    // Drain both pipes while waiting, so a chatty command never blocks.
    let stdout = drain(child.stdout.take());
    let stderr = drain(child.stderr.take());
    let status = wait_at_most(&mut child, RUN_LIMIT)
        .unwrap_or_else(|| panic!("{command} still running after {RUN_LIMIT:?}: killed"));
    Run {
        command,
        status,
        stdout: stdout.join().unwrap(),
        stderr: stderr.join().unwrap(),
    }
}

/// Reads a child's pipe to the end on a thread of its own.
fn drain<R: Read + Send + 'static>(pipe: Option<R>) -> std::thread::JoinHandle<String> {
    std::thread::spawn(move || {
        let mut text = Vec::new();
        if let Some(mut pipe) = pipe {
            let _ = pipe.read_to_end(&mut text);
        }
        String::from_utf8_lossy(&text).into_owned()
    })
}

/// Waits for `child` to exit; kills it and returns `None` after `limit`.
fn wait_at_most(child: &mut Child, limit: Duration) -> Option<ExitStatus> {
    let deadline = Instant::now() + limit;
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return Some(status);
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            return None;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A directory under the system's temp dir, removed when dropped.
struct TempDir(PathBuf);

impl TempDir {
    fn new(name: &str) -> TempDir {
        static COUNT: AtomicUsize = AtomicUsize::new(0);
        let n = COUNT.fetch_add(1, Ordering::SeqCst);
        let path =
            std::env::temp_dir().join(format!("clsmap-cli-{}-{n}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&path);
        std::fs::create_dir_all(&path).unwrap();
        TempDir(path)
    }

    fn join(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A path as a command-line argument (the test paths are UTF-8).
fn arg(path: &Path) -> &str {
    path.to_str()
        .unwrap_or_else(|| panic!("{} is not UTF-8", path.display()))
}

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures")
        .join(name)
}

const CSAIL_FIXTURE: &str = "csail-0000-0200.rec";
const NOISY_FIXTURE: &str = "emulator-noisy-500k.rec";
/// Scans in the CSAIL fixture.
const CSAIL_SCANS: usize = 200;
/// Values in a 180°/0.5° scan.
const BEAMS: usize = 361;

// ---------------------------------------------------------------------------
// The CSAIL log, read independently of the library.
// ---------------------------------------------------------------------------

/// One FLASER line: ranges in cm (81.91 m → 8191), odometry, ipc time.
struct LoggedScan {
    t: f64,
    ranges_cm: Vec<u64>,
    odometry: [f64; 3],
}

/// The first `n` FLASER lines of a CARMEN log.
fn logged_scans(clf: &Path, n: usize) -> Vec<LoggedScan> {
    let file = BufReader::new(File::open(clf).unwrap());
    let mut scans = Vec::new();
    for line in file.lines() {
        let line = line.unwrap();
        let fields: Vec<&str> = line.split_ascii_whitespace().collect();
        if fields.first() != Some(&"FLASER") {
            continue;
        }
        let count: usize = fields[1].parse().unwrap();
        let number = |i: usize| -> f64 { fields[i].parse().unwrap() };
        let tail = 2 + count;
        scans.push(LoggedScan {
            t: number(tail + 6),
            ranges_cm: (2..tail)
                .map(|i| (number(i) * 100.0).round() as u64)
                .collect(),
            odometry: [number(tail + 3), number(tail + 4), number(tail + 5)],
        });
        if scans.len() == n {
            break;
        }
    }
    scans
}

/// The lines of a CARMEN log up to and including its `n`-th FLASER line.
fn clf_head(clf: &Path, n: usize) -> String {
    let mut text = String::new();
    let mut scans = 0;
    for line in BufReader::new(File::open(clf).unwrap()).lines() {
        let line = line.unwrap();
        text.push_str(&line);
        text.push('\n');
        if line.starts_with("FLASER") {
            scans += 1;
            if scans == n {
                break;
            }
        }
    }
    text
}

// ---------------------------------------------------------------------------
// Output parsers.
// ---------------------------------------------------------------------------

/// One line of `decode --format jsonl`.
struct DecodedScan {
    t: f64,
    units: String,
    ranges: Vec<u64>,
    flags: Vec<u64>,
    status: u64,
}

fn parse_jsonl(stdout: &str) -> Vec<DecodedScan> {
    stdout
        .lines()
        .map(|line| {
            let v: serde_json::Value =
                serde_json::from_str(line).unwrap_or_else(|e| panic!("not JSON ({e}): {line}"));
            let ints = |key: &str| -> Vec<u64> {
                v[key]
                    .as_array()
                    .unwrap_or_else(|| panic!("no array `{key}` in {line}"))
                    .iter()
                    .map(|x| x.as_u64().unwrap())
                    .collect()
            };
            DecodedScan {
                t: v["t"].as_f64().unwrap(),
                units: v["units"].as_str().unwrap().to_owned(),
                ranges: ints("ranges"),
                flags: ints("flags"),
                status: v["status"].as_u64().unwrap(),
            }
        })
        .collect()
}

/// `t x y θ` per pose (s, m, m, rad).
type Trajectory = Vec<[f64; 4]>;

/// A TUM trajectory file (θ from the z-axis quaternion).
fn read_tum(path: &Path) -> Trajectory {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()))
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.starts_with('#'))
        .map(|l| {
            let v: Vec<f64> = l
                .split_ascii_whitespace()
                .map(|f| f.parse().unwrap())
                .collect();
            assert_eq!(v.len(), 8, "TUM line: {l}");
            [v[0], v[1], v[2], 2.0 * v[6].atan2(v[7])]
        })
        .collect()
}

fn write_tum(path: &Path, poses: &[[f64; 4]]) {
    let mut text = String::from("# timestamp x y z qx qy qz qw\n");
    for [t, x, y, theta] in poses {
        text.push_str(&format!(
            "{t:.6} {x:.9} {y:.9} 0 0 0 {:.12} {:.12}\n",
            (theta / 2.0).sin(),
            (theta / 2.0).cos()
        ));
    }
    std::fs::write(path, text).unwrap();
}

/// Mean relation errors as printed by `map --relations` and `eval`.
#[derive(Debug)]
struct RelationScore {
    used: usize,
    translation_m: f64,
    rotation_deg: f64,
}

fn parse_score(stdout: &str) -> RelationScore {
    let after = |key: &str| -> &str {
        let line = stdout
            .lines()
            .find(|l| l.trim_start().starts_with(key))
            .unwrap_or_else(|| panic!("no `{key}` line in:\n{stdout}"));
        line.trim_start()[key.len()..].trim_start()
    };
    let first_number = |s: &str| -> f64 {
        s.split_ascii_whitespace()
            .next()
            .and_then(|w| w.parse().ok())
            .unwrap_or_else(|| panic!("no number in {s:?}"))
    };
    RelationScore {
        used: first_number(after("relations used:")) as usize,
        translation_m: first_number(after("translation:")),
        rotation_deg: first_number(after("rotation:")),
    }
}

/// `N` and `M` of decode's summary "N scans; M frames dropped (...)".
fn decode_summary(stderr: &str) -> (usize, usize) {
    let line = stderr
        .lines()
        .find(|l| l.contains("frames dropped"))
        .unwrap_or_else(|| panic!("no summary in stderr:\n{stderr}"));
    let words: Vec<&str> = line.split_ascii_whitespace().collect();
    (words[0].parse().unwrap(), words[2].parse().unwrap())
}

// ---------------------------------------------------------------------------
// Recordings, read with the library's reader.
// ---------------------------------------------------------------------------

/// The records of a recording up to its end or its first error.
fn records(bytes: &[u8]) -> (Vec<Record>, Option<RecordingError>) {
    let mut reader = RecordingReader::new(bytes).unwrap();
    let mut whole = Vec::new();
    while let Some(item) = reader.next_record() {
        match item {
            Ok(r) => whole.push(r),
            Err(e) => return (whole, Some(e)),
        }
    }
    (whole, None)
}

/// Every byte the sensor sent, in order: what a plain serial dump holds.
fn rx_bytes(records: &[Record]) -> Vec<u8> {
    records
        .iter()
        .filter_map(|r| match r {
            Record::Rx { bytes, .. } => Some(bytes.as_slice()),
            _ => None,
        })
        .flatten()
        .copied()
        .collect()
}

fn count_scan_telegrams(bytes: &[u8]) -> usize {
    let mut decoder = Decoder::new();
    let mut scans = 0;
    decoder.feed(bytes, |event| {
        if let DecodeEvent::Reply(frame) = event
            && matches!(frame.reply, Reply::ScanData(_))
        {
            scans += 1;
        }
    });
    scans
}

/// `map INPUT --out DIR [EXTRA...]`.
fn map(input: &Path, out: &Path, extra: &[&str]) -> Run {
    let mut args = vec!["map", arg(input), "--out", arg(out)];
    args.extend_from_slice(extra);
    clsmap(&args)
}

mod bad_input;
#[path = "../common/mod.rs"]
mod common;
use common::csail_dir;
mod daemon;
mod damaged_input;
mod decode;
mod emulator;
mod mapping;
mod web;
