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

fn csail_dir() -> Option<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/datasets/mit-csail");
    if dir.join("mit-csail.clf").is_file() && dir.join("mit-csail.relations").is_file() {
        Some(dir)
    } else {
        eprintln!(
            "SKIPPED (part): CSAIL dataset not found at {} (mit-csail.clf, mit-csail.relations)",
            dir.display()
        );
        None
    }
}

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

// ---------------------------------------------------------------------------
// decode
// ---------------------------------------------------------------------------

#[test]
fn decode_jsonl_gives_the_logged_scans_in_cm_at_the_logged_times() {
    let run = clsmap(&["decode", arg(&fixture(CSAIL_FIXTURE)), "--format", "jsonl"]).succeeded();
    let scans = parse_jsonl(&run.stdout);
    assert_eq!(scans.len(), CSAIL_SCANS, "{run}");
    for scan in &scans {
        assert_eq!(scan.units, "cm");
        assert_eq!(scan.ranges.len(), BEAMS);
        assert_eq!(scan.flags, vec![0; BEAMS]);
        assert_eq!(scan.status, 16);
    }
    assert_eq!(decode_summary(&run.stderr), (CSAIL_SCANS, 0), "{run}");

    let Some(dir) = csail_dir() else { return };
    let logged = logged_scans(&dir.join("mit-csail.clf"), CSAIL_SCANS);
    for (i, (scan, log)) in scans.iter().zip(&logged).enumerate() {
        assert_eq!(
            scan.ranges, log.ranges_cm,
            "scan {i}: ranges differ from the log"
        );
        assert!(
            (scan.t - log.t).abs() < 1e-5,
            "scan {i}: t {} but the log says {}",
            scan.t,
            log.t
        );
    }
}

#[test]
fn decode_csv_has_a_header_and_one_row_per_beam() {
    let run = clsmap(&["decode", arg(&fixture(CSAIL_FIXTURE)), "--format", "csv"]).succeeded();
    let lines = run.stdout_lines();
    assert_eq!(lines[0], "t,beam,units,range,flags,status");
    assert_eq!(lines.len(), 1 + CSAIL_SCANS * BEAMS);
    let first: Vec<&str> = lines[1].split(',').collect();
    assert_eq!(&first[1..], ["0", "cm", "140", "0", "16"], "{}", lines[1]);
    let last: Vec<&str> = lines[lines.len() - 1].split(',').collect();
    assert_eq!(last[1], (BEAMS - 1).to_string());
}

#[test]
fn decode_raw_reads_a_plain_serial_dump_of_the_same_bytes() {
    let dir = TempDir::new("raw");
    let (records, error) = records(&std::fs::read(fixture(CSAIL_FIXTURE)).unwrap());
    assert!(error.is_none());
    let dump = dir.join("csail.bin");
    std::fs::write(&dump, rx_bytes(&records)).unwrap();

    let raw = clsmap(&["decode", "--raw", arg(&dump)]).succeeded();
    let recorded = clsmap(&["decode", arg(&fixture(CSAIL_FIXTURE))]).succeeded();
    let (raw, recorded) = (parse_jsonl(&raw.stdout), parse_jsonl(&recorded.stdout));
    assert_eq!(raw.len(), CSAIL_SCANS);
    for (i, (a, b)) in raw.iter().zip(&recorded).enumerate() {
        assert_eq!(a.ranges, b.ranges, "scan {i}");
        assert_eq!(a.units, b.units);
        // A raw dump has no clock: scans are numbered.
        assert_eq!(a.t, i as f64);
    }
}

#[test]
fn a_truncated_recording_prints_the_whole_scans_and_names_the_byte_offset() {
    let dir = TempDir::new("truncated");
    let full = std::fs::read(fixture(CSAIL_FIXTURE)).unwrap();
    // Cut in the middle of a record, about half-way.
    let cut = full.len() / 2 + 7;
    let truncated = dir.join("truncated.rec");
    std::fs::write(&truncated, &full[..cut]).unwrap();

    let (whole_records, error) = records(&full[..cut]);
    let Some(RecordingError::Truncated { offset, .. }) = error else {
        panic!("the library does not see the cut as a truncation: {error:?}");
    };
    let whole_scans = count_scan_telegrams(&rx_bytes(&whole_records));
    assert!(whole_scans > 50 && whole_scans < CSAIL_SCANS);

    let run = clsmap(&["decode", arg(&truncated)])
        .failed()
        .says(&format!("byte {offset}"));
    let complete = clsmap(&["decode", arg(&fixture(CSAIL_FIXTURE))]).succeeded();
    assert_eq!(
        run.stdout_lines(),
        complete.stdout_lines()[..whole_scans].to_vec(),
        "the scans before the break must be printed as from the whole file"
    );
}

#[test]
fn a_noisy_line_recording_decodes_with_dropped_frames_counted() {
    let run = clsmap(&["decode", arg(&fixture(NOISY_FIXTURE))]).succeeded();
    let scans = parse_jsonl(&run.stdout);
    let (printed, dropped) = decode_summary(&run.stderr);
    assert_eq!(printed, scans.len());
    // The driver counted 60 scans while recording this line.
    assert!(scans.len() >= 60, "{run}");
    assert!(
        dropped > 0,
        "the line noise must show as dropped frames:\n{run}"
    );
    for (i, scan) in scans.iter().enumerate() {
        assert_eq!(scan.ranges.len(), BEAMS, "scan {i}");
        assert_eq!(scan.units, "mm", "scan {i}");
    }
    assert!(
        scans.windows(2).all(|w| w[0].t < w[1].t),
        "times must increase"
    );
}

// ---------------------------------------------------------------------------
// map, eval, render
// ---------------------------------------------------------------------------

/// `map INPUT --out DIR [EXTRA...]`.
fn map(input: &Path, out: &Path, extra: &[&str]) -> Run {
    let mut args = vec!["map", arg(input), "--out", arg(out)];
    args.extend_from_slice(extra);
    clsmap(&args)
}

#[test]
fn map_on_the_recording_writes_its_files_and_beats_the_odometry() {
    let dir = TempDir::new("map");
    let out = dir.join("out");
    let relations = csail_dir().map(|d| d.join("mit-csail.relations"));
    let extra: Vec<&str> = match &relations {
        Some(r) => vec!["--relations", arg(r)],
        None => vec![],
    };
    let run = map(&fixture(CSAIL_FIXTURE), &out, &extra).succeeded();

    let trajectory = read_tum(&out.join("trajectory.tum"));
    assert_eq!(trajectory.len(), CSAIL_SCANS);
    // The map frame is the first pose.
    assert_eq!(trajectory[0][1..], [0.0, 0.0, 0.0]);
    for name in ["trajectory.tum", "map.json", "map.svg"] {
        assert!(out.join(name).is_file(), "{name} missing:\n{run}");
    }
    for line in run.stdout.lines() {
        if let Some(path) = line.trim_start().strip_prefix("wrote ") {
            assert!(
                Path::new(path).exists(),
                "`{line}` but {path} does not exist"
            );
        }
    }

    let (Some(relations), Some(dir_csail)) = (relations, csail_dir()) else {
        return;
    };
    let mapped = parse_score(&run.stdout);
    // The logged odometry of the same scans, scored the same way.
    let odometry: Trajectory = logged_scans(&dir_csail.join("mit-csail.clf"), CSAIL_SCANS)
        .iter()
        .map(|s| [s.t, s.odometry[0], s.odometry[1], s.odometry[2]])
        .collect();
    let odometry_file = dir.join("odometry.tum");
    write_tum(&odometry_file, &odometry);
    let eval = clsmap(&["eval", arg(&odometry_file), "--relations", arg(&relations)]).succeeded();
    let logged = parse_score(&eval.stdout);
    assert!(mapped.used > 50, "{mapped:?}");
    assert_eq!(mapped.used, logged.used, "same relations for both");
    // These 42 s are mostly turns on the spot: the odometry's translation
    // is already within the map's noise (both 0.027 m to the printed
    // millimetre), its heading is not.
    assert!(
        mapped.translation_m <= logged.translation_m && mapped.rotation_deg < logged.rotation_deg,
        "the map must beat the odometry: map {mapped:?}, odometry {logged:?}"
    );
}

/// Largest difference between two trajectories: (time, position, heading).
fn trajectory_difference(a: &[[f64; 4]], b: &[[f64; 4]]) -> (f64, f64, f64) {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .fold((0.0, 0.0, 0.0), |(dt, dp, dh), (p, q)| {
            let heading = (p[3] - q[3] + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI;
            (
                f64::max(dt, (p[0] - q[0]).abs()),
                f64::max(dp, (p[1] - q[1]).hypot(p[2] - q[2])),
                f64::max(dh, heading.abs()),
            )
        })
}

/// Maps the CSAIL fixture and the same scans as CARMEN text; returns the
/// two trajectories (None without the dataset).
fn map_recording_and_clf() -> Option<(Trajectory, Trajectory)> {
    let csail = csail_dir()?;
    let dir = TempDir::new("same-data");
    let clf = dir.join("head.clf");
    std::fs::write(&clf, clf_head(&csail.join("mit-csail.clf"), CSAIL_SCANS)).unwrap();
    map(&clf, &dir.join("from-clf"), &[]).succeeded();
    map(&fixture(CSAIL_FIXTURE), &dir.join("from-rec"), &[]).succeeded();
    Some((
        read_tum(&dir.join("from-clf").join("trajectory.tum")),
        read_tum(&dir.join("from-rec").join("trajectory.tum")),
    ))
}

#[test]
/// The recording and the CARMEN text hold the same data: scan and
/// odometry times convert from integer microseconds exactly as the text's
/// decimals parse, so the two trajectories agree to the printed digit.
fn map_on_the_clf_and_on_its_recording_give_the_same_trajectory() {
    let Some((from_clf, from_rec)) = map_recording_and_clf() else {
        return;
    };
    let (dt, dp, dh) = trajectory_difference(&from_clf, &from_rec);
    // TUM files keep 6 decimals: allow the last digit of x and y to differ.
    let printed = 2e-6;
    assert!(
        dt <= 1e-6 && dp <= printed && dh <= printed,
        "differ by {dt} s, {dp} m, {dh} rad"
    );
}

#[test]
fn render_draws_the_map_as_svg_and_exports_an_occupancy_grid() {
    let dir = TempDir::new("render");
    let out = dir.join("out");
    map(&fixture(CSAIL_FIXTURE), &out, &[]).succeeded();
    let map_json = out.join("map.json");
    assert!(map_json.is_file(), "map wrote no map.json");

    let svg = dir.join("map.svg");
    clsmap(&["render", arg(&map_json), "-o", arg(&svg)]).succeeded();
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.contains("<svg") && text.trim_end().ends_with("</svg>"));
    assert!(text.contains("<line") || text.contains("<path") || text.contains("<polygon"));

    let pgm = dir.join("grid.pgm");
    clsmap(&["render", arg(&map_json), "-o", arg(&pgm)]).succeeded();
    let image = std::fs::read(&pgm).unwrap();
    let header: Vec<String> = String::from_utf8_lossy(&image[..image.len().min(64)])
        .split_ascii_whitespace()
        .take(4)
        .map(str::to_owned)
        .collect();
    assert_eq!(header[0], "P5", "binary PGM");
    let (width, height): (usize, usize) = (header[1].parse().unwrap(), header[2].parse().unwrap());
    assert!(width > 10 && height > 10);
    assert!(
        image.len() >= width * height,
        "{} bytes for {width}x{height}",
        image.len()
    );
    let yaml = std::fs::read_to_string(dir.join("grid.yaml")).unwrap();
    assert!(yaml.contains("image: grid.pgm"), "{yaml}");
    assert!(yaml.contains("resolution: 0.05"), "{yaml}");
}

// ---------------------------------------------------------------------------
// Bad input: a clear error naming what is wrong, never a panic.
// ---------------------------------------------------------------------------

#[test]
fn a_missing_input_file_is_named() {
    let dir = TempDir::new("missing");
    let missing = dir.join("no-such-recording.rec");
    let shown = missing.display().to_string();
    clsmap(&["decode", arg(&missing)]).failed().says(&shown);
    map(&missing, &dir.join("out"), &[]).failed().says(&shown);
}

#[test]
fn probe_refuses_what_is_not_a_serial_port() {
    clsmap(&["probe", "--port", "/dev/null"])
        .failed()
        .says("not a serial port");
    clsmap(&["probe", "--port", "/nonexistent"])
        .failed()
        .says("no such device");
}

#[test]
fn record_never_costs_an_existing_file() {
    let dir = TempDir::new("record-keep");
    let keep = dir.join("keep.rec");
    std::fs::write(&keep, b"the only copy").unwrap();
    // A wrong port fails before the output is touched.
    clsmap(&["record", "--port", "/nonexistent", "--out", arg(&keep)])
        .failed()
        .says("no such device");
    assert_eq!(std::fs::read(&keep).unwrap(), b"the only copy");
}

#[test]
fn render_refuses_to_draw_over_its_own_map() {
    let dir = TempDir::new("render-self");
    let out = dir.join("out");
    map(&fixture(CSAIL_FIXTURE), &out, &[]).succeeded();
    let map_json = out.join("map.json");
    let before = std::fs::read(&map_json).unwrap();
    clsmap(&["render", arg(&map_json), "-o", arg(&map_json)])
        .failed()
        .says("would overwrite the map");
    assert_eq!(std::fs::read(&map_json).unwrap(), before);
}

#[test]
fn a_recording_cut_short_is_mapped_up_to_the_break() {
    let dir = TempDir::new("map-truncated");
    let full = std::fs::read(fixture(CSAIL_FIXTURE)).unwrap();
    let half = dir.join("half.rec");
    std::fs::write(&half, &full[..full.len() / 2]).unwrap();
    let out = dir.join("out");
    // The map is written from what there is; the exit status says the
    // input was not whole.
    let run = map(&half, &out, &[]);
    assert_eq!(run.status.code(), Some(4), "{run}");
    assert!(run.stdout.contains("input broke off"), "{run}");
    let poses = read_tum(&out.join("trajectory.tum"));
    assert!(
        poses.len() > 50 && poses.len() < 200,
        "{} poses from half the fixture",
        poses.len()
    );
}

#[test]
fn an_out_of_range_configuration_value_is_named() {
    let dir = TempDir::new("config-range");
    let config = dir.join("bad.toml");
    std::fs::write(&config, "[extraction]\nmax_point_gap = 0.0\n").unwrap();
    map(
        &fixture(CSAIL_FIXTURE),
        &dir.join("out"),
        &["--config", arg(&config)],
    )
    .failed()
    .says("max_point_gap");
}

#[test]
fn an_unknown_configuration_key_is_named_with_its_line() {
    let dir = TempDir::new("config");
    let config = dir.join("bad.toml");
    std::fs::write(&config, "# mapper settings\n\n[odometry]\nbogus_key = 1\n").unwrap();
    map(
        &fixture(CSAIL_FIXTURE),
        &dir.join("out"),
        &["--config", arg(&config)],
    )
    .failed()
    .says("bogus_key")
    .says("line 4");
}

#[test]
fn a_malformed_carmen_line_is_named_by_number() {
    let dir = TempDir::new("carmen");
    let mut lines: Vec<String> = (0..7)
        .map(|i| {
            let mut fields = vec!["FLASER".to_owned(), "361".to_owned()];
            fields.extend((0..361).map(|_| "2.50".to_owned()));
            let t = 1000.0 + 0.2 * f64::from(i);
            fields.extend(
                ["0", "0", "0", "0", "0", "0"]
                    .iter()
                    .map(|s| (*s).to_owned()),
            );
            fields.extend([format!("{t:.6}"), "host".to_owned(), format!("{t:.6}")]);
            fields.join(" ")
        })
        .collect();
    lines.insert(0, "# a CARMEN log".to_owned());
    // Line 6 of the file: a range that is not a number.
    lines[5] = lines[5].replacen(" 2.50 ", " 2.5x ", 1);
    let clf = dir.join("bad.clf");
    std::fs::write(&clf, lines.join("\n") + "\n").unwrap();
    map(&clf, &dir.join("out"), &[])
        .failed()
        .says("line 6")
        .says("2.5x");
}

#[test]
fn decode_refuses_a_file_that_is_not_a_recording() {
    let dir = TempDir::new("random");
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let bytes: Vec<u8> = (0..4096)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 24) as u8
        })
        .collect();
    let file = dir.join("random.bin");
    std::fs::write(&file, bytes).unwrap();
    let run = clsmap(&["decode", arg(&file)])
        .failed()
        .says("not a clsmap recording");
    assert!(run.stdout.is_empty());
}

// ---------------------------------------------------------------------------
// The emulator over a pseudo-terminal, driven through the CLI.
// ---------------------------------------------------------------------------

/// A running `clsmap emulate`; killed if the test ends without stopping it.
struct EmulatorProcess {
    child: Child,
    stdout: PathBuf,
    stderr: PathBuf,
}

impl EmulatorProcess {
    fn start(dir: &TempDir, link: &Path) -> EmulatorProcess {
        let (stdout, stderr) = (dir.join("emulator.out"), dir.join("emulator.err"));
        let child = clsmap_command()
            .arg("emulate")
            .arg("--link")
            .arg(link)
            .stdin(Stdio::null())
            .stdout(File::create(&stdout).unwrap())
            .stderr(File::create(&stderr).unwrap())
            .spawn()
            .unwrap();
        let mut emulator = EmulatorProcess {
            child,
            stdout,
            stderr,
        };
        let deadline = Instant::now() + EMULATOR_START_LIMIT;
        while !link.exists() {
            if let Some(status) = emulator.child.try_wait().unwrap() {
                panic!("the emulator exited ({status}):\n{}", emulator.output());
            }
            assert!(
                Instant::now() < deadline,
                "no link {} after {EMULATOR_START_LIMIT:?}:\n{}",
                link.display(),
                emulator.output()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        emulator
    }

    fn output(&self) -> String {
        let read = |p: &Path| std::fs::read_to_string(p).unwrap_or_default();
        format!(
            "--- emulator stdout ---\n{}--- emulator stderr ---\n{}",
            read(&self.stdout),
            read(&self.stderr)
        )
    }

    /// Sends SIGINT (Ctrl-C) and waits for the exit.
    fn interrupt(&mut self) -> ExitStatus {
        let pid = self.child.id().to_string();
        let kill = Command::new("kill").args(["-INT", &pid]).status().unwrap();
        assert!(kill.success(), "kill -INT {pid} failed");
        wait_at_most(&mut self.child, EMULATOR_STOP_LIMIT).unwrap_or_else(|| {
            panic!(
                "the emulator ignored SIGINT for {EMULATOR_STOP_LIMIT:?}:\n{}",
                self.output()
            )
        })
    }
}

impl Drop for EmulatorProcess {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

#[test]
fn probe_record_and_decode_against_the_emulator_then_stop_it_with_ctrl_c() {
    let dir = TempDir::new("emulator");
    let link = dir.join("lms200");
    let mut emulator = EmulatorProcess::start(&dir, &link);

    let probe = clsmap(&["probe", "--port", arg(&link)]).succeeded();
    assert!(probe.stdout.contains("LMS200"), "{probe}");
    assert!(probe.stdout.contains("180/0.5"), "{probe}");

    let recording = dir.join("x.rec");
    let record = clsmap(&[
        "record",
        "--port",
        arg(&link),
        "--out",
        arg(&recording),
        "--scans",
        "10",
    ])
    .succeeded();
    assert!(record.stderr.contains("recorded 10 scans"), "{record}");

    let decode = clsmap(&["decode", arg(&recording)]).succeeded();
    let scans = parse_jsonl(&decode.stdout);
    assert!(scans.len() >= 10, "{decode}");
    assert!(
        scans
            .iter()
            .all(|s| s.ranges.len() == BEAMS && s.units == "mm")
    );

    let status = emulator.interrupt();
    assert!(
        status.success(),
        "emulator exit {status}:\n{}",
        emulator.output()
    );
    assert!(
        std::fs::symlink_metadata(&link).is_err(),
        "the emulator left its link {} behind",
        link.display()
    );
}

// ---------------------------------------------------------------------------
// clsmap run: the daemon as systemd runs it, driven by signals.
// ---------------------------------------------------------------------------

/// A running `clsmap run`, its stderr lines arriving on a channel.
struct Daemon {
    child: Child,
    lines: std::sync::mpsc::Receiver<String>,
    seen: Vec<String>,
}

impl Daemon {
    fn start(config: &Path) -> Daemon {
        let mut child = clsmap_command()
            .args(["run", "--config", arg(config)])
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let (tx, lines) = std::sync::mpsc::channel();
        let stderr = child.stderr.take().unwrap();
        std::thread::spawn(move || {
            for line in BufReader::new(stderr).lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Daemon {
            child,
            lines,
            seen: Vec::new(),
        }
    }

    /// Waits (at most `limit`) for a stderr line containing `text`.
    fn wait_for(&mut self, text: &str, limit: Duration) {
        let deadline = Instant::now() + limit;
        if self.seen.iter().any(|l| l.contains(text)) {
            return;
        }
        while let Some(left) = deadline.checked_duration_since(Instant::now()) {
            match self.lines.recv_timeout(left) {
                Ok(line) => {
                    let found = line.contains(text);
                    self.seen.push(line);
                    if found {
                        return;
                    }
                }
                Err(_) => break,
            }
        }
        let _ = self.child.kill();
        panic!(
            "no line with {text:?} within {limit:?}; stderr so far:\n{}",
            self.seen.join("\n")
        );
    }

    fn signal(&self, name: &str) {
        let status = Command::new("kill")
            .args([&format!("-{name}"), &self.child.id().to_string()])
            .status()
            .unwrap();
        assert!(status.success(), "kill -{name} failed");
    }

    /// Waits for the exit; returns the status, stdout and all of stderr.
    fn finish(mut self, limit: Duration) -> (ExitStatus, String, String) {
        let stdout = drain(self.child.stdout.take());
        let status = wait_at_most(&mut self.child, limit)
            .unwrap_or_else(|| panic!("clsmap run did not stop within {limit:?}"));
        self.seen.extend(self.lines.try_iter());
        // The reader thread ends with the pipe; collect what is left.
        std::thread::sleep(Duration::from_millis(50));
        self.seen.extend(self.lines.try_iter());
        (status, stdout.join().unwrap(), self.seen.join("\n"))
    }
}

fn demo_run_config(dir: &TempDir, extra: &str) -> PathBuf {
    let text =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("config/demo.toml"))
            .unwrap()
            .replace("exit_when_complete = true", "exit_when_complete = false")
            .replace("checkpoint_interval = 30.0", "checkpoint_interval = 1.0")
            .replace("status_interval = 5.0", "status_interval = 1.0")
            .replace(
                "[daemon]",
                &format!(
                    "[daemon]\nstate_dir = {:?}",
                    dir.join("state").display().to_string()
                ),
            );
    let path = dir.join("clsmap.toml");
    std::fs::write(&path, format!("{text}\n{extra}")).unwrap();
    path
}

/// The one run directory `clsmap run` made below `state`.
fn run_dir(state: &Path) -> PathBuf {
    let dirs: Vec<PathBuf> = std::fs::read_dir(state)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(dirs.len(), 1, "{dirs:?}");
    dirs[0].clone()
}

#[test]
fn run_reloads_on_sighup_and_stops_cleanly_on_sigterm_leaving_a_loadable_map() {
    let dir = TempDir::new("run-sigterm");
    let config = demo_run_config(&dir, "");
    let mut daemon = Daemon::start(&config);
    daemon.wait_for("first scan mapped", Duration::from_secs(60));
    daemon.wait_for("exploration: goal reached", Duration::from_secs(60));
    // A tunable change is applied; a change of the sensor needs a restart.
    let text = std::fs::read_to_string(&config).unwrap();
    std::fs::write(
        &config,
        text.replace("speed = 0.6", "speed = 0.4")
            .replace("[sensor]", "[sensor]\nsilence_stop = 0.8"),
    )
    .unwrap();
    daemon.signal("HUP");
    daemon.wait_for(
        "need a restart and are not applied: sensor",
        Duration::from_secs(20),
    );
    // A broken file is refused and the running configuration stays.
    std::fs::write(&config, "[sensor]\nbaud = 57600\n").unwrap();
    daemon.signal("HUP");
    daemon.wait_for("reload refused", Duration::from_secs(20));
    daemon.wait_for("sensor.baud (line 2)", Duration::from_secs(1));
    // Turning exploration off takes effect at once.
    std::fs::write(&config, text.replace("enabled = true", "enabled = false")).unwrap();
    daemon.signal("HUP");
    daemon.wait_for("exploration off", Duration::from_secs(20));
    daemon.signal("TERM");
    let (status, stdout, stderr) = daemon.finish(Duration::from_secs(30));
    assert!(status.success(), "{status}\n{stderr}");
    assert!(stdout.contains("stopped (Shutdown)"), "{stdout}");
    assert!(stderr.contains("SIGTERM: stopping"), "{stderr}");
    // The link was closed: the sensor stopped streaming before the exit.
    assert!(stderr.contains("sensor link closed"), "{stderr}");
    let run = run_dir(&dir.join("state"));
    let map = clsmap::map::cls::ClsMap::load(
        &run.join("map.json"),
        clsmap::map::cls::ClsMapConfig::default(),
    )
    .unwrap();
    map.check_invariants().unwrap();
    assert!(map.actual_segments().count() > 3, "{stderr}");
    assert!(run.join("map.svg").is_file() && run.join("trajectory.tum").is_file());
}

#[test]
fn run_without_its_sensor_keeps_retrying_and_still_stops_cleanly() {
    let dir = TempDir::new("run-nosensor");
    let config = dir.join("clsmap.toml");
    std::fs::write(
        &config,
        format!(
            "[sensor]\nport = \"/dev/clsmap-test-no-such-port\"\nretry_initial = 0.2\nretry_max = 0.4\n\
             [daemon]\nstate_dir = {:?}\nstatus_interval = 0.2\nready_after = 0.5\n",
            dir.join("state").display().to_string()
        ),
    )
    .unwrap();
    let mut daemon = Daemon::start(&config);
    daemon.wait_for("clsmap-test-no-such-port", Duration::from_secs(30));
    daemon.wait_for("trying again", Duration::from_secs(5));
    // Retried, not given up: more failures come after the back-off.
    std::thread::sleep(Duration::from_millis(800));
    daemon.signal("TERM");
    let (status, stdout, stderr) = daemon.finish(Duration::from_secs(30));
    assert!(status.success(), "{status}\n{stderr}");
    assert!(
        stderr.matches("trying again").count() >= 2,
        "expected retries:\n{stderr}"
    );
    assert!(
        stderr.contains("waiting for the sensor") || stderr.contains("SENSOR FAILING"),
        "{stderr}"
    );
    // Nothing was mapped: no empty run directory is left behind.
    assert!(stdout.contains("nothing mapped, nothing saved"), "{stdout}");
    let runs = std::fs::read_dir(dir.join("state")).unwrap().count();
    assert_eq!(runs, 0);
}

#[test]
fn run_refuses_a_bad_config_naming_the_key_and_line() {
    let dir = TempDir::new("run-badconfig");
    let config = dir.join("clsmap.toml");
    std::fs::write(&config, "# robot\n[base]\nmax_speed = -1.0\n").unwrap();
    let run = clsmap(&["run", "--config", arg(&config)]);
    assert!(!run.status.success(), "{run}");
    assert!(run.stderr.contains("base.max_speed (line 3)"), "{run}");
    std::fs::write(&config, "[sensor]\nprot = \"/dev/ttyUSB0\"\n").unwrap();
    let run = clsmap(&["run", "--config", arg(&config)]);
    assert!(!run.status.success(), "{run}");
    assert!(
        run.stderr.contains("prot") && run.stderr.contains("line 2"),
        "{run}"
    );
    let run = clsmap(&["run", "--config", arg(&dir.join("missing.toml"))]);
    assert!(
        !run.status.success() && run.stderr.contains("missing.toml"),
        "{run}"
    );
}

/// Hardening: links planted at the names a map write used to take (the
/// temporary file's `.map.json.tmp-<pid>`, with the pid known to a shell
/// that `exec`s the mapper) are never followed: the file they point at
/// keeps its contents and `map.json` is a regular file.
#[cfg(unix)]
#[test]
fn a_planted_link_never_redirects_a_map_write() {
    let dir = std::env::temp_dir().join(format!("clsmap-cli-link-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let out = dir.join("o");
    std::fs::create_dir_all(&out).unwrap();
    let victim = dir.join("victim");
    std::fs::write(&victim, "keep\n").unwrap();
    let script = format!(
        "for n in map.json.tmp-$$ map.svg.tmp-$$ trajectory.tum.tmp-$$; do ln -s '{}' '{}'/.$n; done; exec '{}' map '{}' --out '{}'",
        victim.display(),
        out.display(),
        env!("CARGO_BIN_EXE_clsmap"),
        fixture(CSAIL_FIXTURE).display(),
        out.display()
    );
    let status = Command::new("sh")
        .arg("-c")
        .arg(&script)
        .env("NO_COLOR", "1")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .unwrap();
    assert!(status.success());
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), "keep\n");
    let meta = std::fs::symlink_metadata(out.join("map.json")).unwrap();
    assert!(meta.file_type().is_file());
    clsmap::map::file::load(&out.join("map.json")).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The number after `label` on a line of `clsmap map`'s report.
fn reported(stdout: &str, label: &str) -> usize {
    let line = stdout
        .lines()
        .find(|l| l.trim_start().starts_with(label))
        .unwrap_or_else(|| panic!("no {label:?} in:\n{stdout}"));
    let rest = &line.trim_start()[label.len()..];
    rest.split_whitespace().next().unwrap().parse().unwrap()
}

/// The fixture's records with `edit` applied, written as a new recording.
fn edited_fixture(path: &Path, edit: impl Fn(usize, &mut Record)) {
    let bytes = std::fs::read(fixture(CSAIL_FIXTURE)).unwrap();
    let (mut all, error) = records(&bytes);
    assert!(error.is_none());
    for (i, r) in all.iter_mut().enumerate() {
        edit(i, r);
    }
    let mut w = lms200::recording::RecordingWriter::new(Vec::new()).unwrap();
    for r in &all {
        w.write(r).unwrap();
    }
    std::fs::write(path, w.into_inner()).unwrap();
}

/// Hardening: one NaN odometry sample (valid record checksum) is skipped
/// and named; the scans around it keep interpolated odometry, the map is
/// as good as without it, and the exit status says input was skipped.
#[test]
fn a_nan_odometry_sample_is_skipped_not_spread() {
    let dir = TempDir::new("nan-odometry");
    let input = dir.join("nan.rec");
    let seen = std::cell::Cell::new(0);
    edited_fixture(&input, |_, r| {
        if let Record::Odometry { x, .. } = r {
            seen.set(seen.get() + 1);
            if seen.get() == 2 {
                *x = f64::NAN;
            }
        }
    });
    assert!(seen.get() > 10, "the fixture has odometry");
    let run = map(&input, &dir.join("out"), &[]);
    assert_eq!(run.status.code(), Some(4), "{run}");
    assert!(run.stdout.contains("non-finite pose"), "{run}");
    assert_eq!(reported(&run.stdout, "mapped"), CSAIL_SCANS);
    let rejected = reported(&run.stdout, "localizations rejected:");
    assert!(
        rejected < 10,
        "{rejected} of {CSAIL_SCANS} rejected:\n{run}"
    );
    let strict = map(&input, &dir.join("strict"), &["--strict"]);
    assert_eq!(strict.status.code(), Some(1), "{strict}");
    assert!(!dir.join("strict").exists());
}

/// Hardening: a flipped bit costs the damaged record (a chunk of serial
/// bytes: at most a scan or two), not the rest of the recording.
#[test]
fn a_flipped_bit_costs_one_record_not_the_rest() {
    let dir = TempDir::new("flipped");
    let mut bytes = std::fs::read(fixture(CSAIL_FIXTURE)).unwrap();
    let at = bytes.len() / 3;
    bytes[at] ^= 0x08;
    let input = dir.join("flipped.rec");
    std::fs::write(&input, &bytes).unwrap();
    let run = map(&input, &dir.join("out"), &[]);
    assert_eq!(run.status.code(), Some(4), "{run}");
    assert!(run.stdout.contains("damaged at byte"), "{run}");
    let mapped = reported(&run.stdout, "mapped");
    assert!((CSAIL_SCANS - 2..=CSAIL_SCANS).contains(&mapped), "{run}");
}

/// Hardening: a malformed CARMEN line is skipped and named with its line
/// number, the rest mapped; `--strict` keeps the old all-or-nothing run.
#[test]
fn a_malformed_carmen_line_is_skipped_and_named() {
    let Some(dir) = csail_dir() else { return };
    let tmp = TempDir::new("malformed");
    let mut lines: Vec<String> = clf_head(&dir.join("mit-csail.clf"), 40)
        .lines()
        .map(str::to_owned)
        .collect();
    let flaser_lines: Vec<usize> = (0..lines.len())
        .filter(|&i| lines[i].starts_with("FLASER"))
        .collect();
    let victim = flaser_lines[20];
    lines[victim] = lines[victim].replacen(' ', " x", 3);
    let input = tmp.join("bad.clf");
    std::fs::write(&input, lines.join("\n") + "\n").unwrap();
    let run = map(&input, &tmp.join("out"), &[]);
    assert_eq!(run.status.code(), Some(4), "{run}");
    assert!(
        run.stdout.contains(&format!("line {}", victim + 1)),
        "{run}"
    );
    assert_eq!(reported(&run.stdout, "mapped"), flaser_lines.len() - 1);
    let strict = map(&input, &tmp.join("strict"), &["--strict"]);
    assert_eq!(strict.status.code(), Some(1), "{strict}");
    assert!(!tmp.join("strict").exists());
}

/// `map --map M --mode localize`: a log replayed against a saved map is
/// found in it, its trajectory in the map's frame (here the first run's,
/// as the same log starts at the same place), the saved file untouched;
/// `--mode extend` on a version-1 map (no keyframes) is refused with the
/// reason.
#[test]
fn a_log_is_localized_against_a_saved_map() {
    let dir = TempDir::new("resume");
    let first = dir.join("first");
    map(&fixture(CSAIL_FIXTURE), &first, &[]).succeeded();
    let saved = std::fs::read(first.join("map.json")).unwrap();
    let again = dir.join("again");
    let run = map(
        &fixture(CSAIL_FIXTURE),
        &again,
        &["--map", arg(&first.join("map.json")), "--mode", "localize"],
    )
    .succeeded();
    assert_eq!(std::fs::read(first.join("map.json")).unwrap(), saved);
    let a = read_tum(&first.join("trajectory.tum"));
    let b = read_tum(&again.join("trajectory.tum"));
    assert!(b.len() + 5 >= a.len(), "{run}");
    let mut errors: Vec<f64> = b
        .iter()
        .filter_map(|p| {
            let q = a.iter().find(|q| (q[0] - p[0]).abs() < 1e-6)?;
            Some((p[1] - q[1]).hypot(p[2] - q[2]))
        })
        .collect();
    errors.sort_by(f64::total_cmp);
    assert!(errors[errors.len() / 2] < 0.05, "{errors:?}");

    let v1 = dir.join("v1.json");
    let map_v1 = clsmap::map::cls::ClsMap::load(
        &first.join("map.json"),
        clsmap::map::cls::ClsMapConfig::default(),
    )
    .unwrap();
    clsmap::map::cls::store::save_items(&v1, &map_v1.items()).unwrap();
    map(
        &fixture(CSAIL_FIXTURE),
        &dir.join("extend"),
        &["--map", arg(&v1), "--mode", "extend"],
    )
    .failed()
    .says("can be localized in, not extended");
    // Localized in, a version-1 map is written back whole, not emptied.
    let from_v1 = dir.join("from-v1");
    map(&fixture(CSAIL_FIXTURE), &from_v1, &["--map", arg(&v1)]).succeeded();
    let written = clsmap::map::cls::ClsMap::load(
        &from_v1.join("map.json"),
        clsmap::map::cls::ClsMapConfig::default(),
    )
    .unwrap();
    assert_eq!(written.items().len(), map_v1.items().len());
    // The run never writes over the map it starts from.
    map(
        &fixture(CSAIL_FIXTURE),
        &first,
        &["--map", arg(&first.join("map.json"))],
    )
    .failed()
    .says("would overwrite the map it starts from");
    assert_eq!(std::fs::read(first.join("map.json")).unwrap(), saved);
}

/// Hardening: a configuration or map path that is endless (`/dev/zero`)
/// fails at once with the reason instead of filling memory.
#[cfg(unix)]
#[test]
fn endless_files_are_refused_not_read() {
    let dir = TempDir::new("endless");
    map(
        &fixture(CSAIL_FIXTURE),
        &dir.join("out"),
        &["--config", "/dev/zero"],
    )
    .failed()
    .says("larger than");
    clsmap(&["render", "/dev/zero", "-o", arg(&dir.join("x.svg"))])
        .failed()
        .says("larger than");
    clsmap(&["run", "--config", "/dev/zero"])
        .failed()
        .says("larger than");
}
