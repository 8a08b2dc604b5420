//! The emulator over a pseudo-terminal, driven through the CLI.

use super::*;

/// A running `clsmap emulate`; killed if the test ends without stopping it.
pub(super) struct EmulatorProcess {
    child: Child,
    stdout: PathBuf,
    stderr: PathBuf,
}

impl EmulatorProcess {
    pub(super) fn start(dir: &TempDir, link: &Path) -> EmulatorProcess {
        Self::start_with(dir, link, &[])
    }

    /// `clsmap emulate --link LINK` with `args` after it.
    fn start_with(dir: &TempDir, link: &Path, args: &[&str]) -> EmulatorProcess {
        let (stdout, stderr) = (dir.join("emulator.out"), dir.join("emulator.err"));
        let child = clsmap_command()
            .arg("emulate")
            .arg("--link")
            .arg(link)
            .args(args)
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

/// Runs the independent host (`scripts/lms200_host.py`, Python's standard
/// library only) against `link`; its JSON report and whether it succeeded.
fn python_host(link: &Path, args: &[&str]) -> (serde_json::Value, bool) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/lms200_host.py");
    let out = Command::new("python3")
        .arg(&script)
        .arg("--port")
        .arg(link)
        .args(args)
        .output()
        .expect("python3 runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let report = serde_json::from_str(stdout.trim()).unwrap_or_else(|e| {
        panic!(
            "the host printed no report ({e}):\n{stdout}\n{}",
            String::from_utf8_lossy(&out.stderr)
        )
    });
    (report, out.status.success())
}

/// An independent host, written from the telegram listing, finds the
/// emulator a sensor: its status reply says the variant and units in
/// force, the first request after each baud change is understood at once,
/// and streaming runs at the listing's rate (TL Table 10-17: one
/// 180°/0.5° scan in 9 at 38400 Bd, 4.2 Hz; one in 16 at 19200, 2.3 Hz).
#[test]
fn an_independent_host_finds_the_emulator_a_sensor() {
    let dir = TempDir::new("emulator-host");
    let link = dir.join("lms200");
    let mut emulator = EmulatorProcess::start(&dir, &link);
    for (baud, rate) in [("38400", 37.5 / 9.0), ("19200", 37.5 / 16.0)] {
        // No pause between switching the host's speed and the request.
        let (report, ok) = python_host(
            &link,
            &["--baud", baud, "--pause", "0", "--stream-seconds", "3"],
        );
        assert!(ok, "{baud} Bd: {report}\n{}", emulator.output());
        let status = &report["status_9600"];
        assert_eq!(status["scan_angle_deg"], 180, "{report}");
        assert_eq!(status["resolution_centideg"], 50, "{report}");
        assert_eq!(status["units_code"], 1, "mm: {report}");
        assert_eq!(status["operating_mode"], 0x25, "{report}");
        assert_eq!(status["address"], 1, "{report}");
        assert_eq!(status["device_status"], 0, "{report}");
        assert!(
            status["software"].as_str().unwrap().starts_with("V02.10"),
            "{report}"
        );
        assert_eq!(
            report["variants_in_status"],
            serde_json::json!([[100, 25], [180, 50]]),
            "{report}"
        );
        assert_eq!(report["first_request_after_change_answered"], true);
        assert_eq!(report["first_request_back_at_9600_answered"], true);
        let measured = report["scan_rate_hz"].as_f64().unwrap();
        assert!(
            (measured / rate - 1.0).abs() < 0.05,
            "{baud} Bd: {measured:.2} Hz streamed, the listing's rate is {rate:.2} Hz"
        );
    }
    let status = emulator.interrupt();
    assert!(status.success(), "{}", emulator.output());
    let output = emulator.output();
    assert!(
        output.contains("garbled_input_bytes: 0,"),
        "a request was heard at the wrong speed:\n{output}"
    );
}

/// Asked to model a power-up, the emulator is deaf while it boots; by
/// default it has been on a while and answers the first request at once
/// (the test above starts its host as soon as the link appears).
#[test]
fn the_emulator_boots_only_when_asked_to() {
    let dir = TempDir::new("emulator-boot");
    let link = dir.join("lms200");
    let _emulator = EmulatorProcess::start_with(&dir, &link, &["--power-on", "3"]);
    let (report, ok) = python_host(&link, &["--baud", "9600", "--stream-seconds", "0.2"]);
    assert!(!ok, "answered while booting: {report}");
    assert_eq!(report["failed"], "status request at 9600 Bd", "{report}");
}

/// `clsmap record --bag` against the emulator: a bag of `scans` scans.
fn record_bag(dir: &TempDir, scans: &str) -> PathBuf {
    let link = dir.join("lms200");
    let mut emulator = EmulatorProcess::start(dir, &link);
    let bag = dir.join("run.mcap");
    let recording = dir.join("run.rec");
    let record = clsmap(&[
        "record",
        "--port",
        arg(&link),
        "--bag",
        arg(&bag),
        "--out",
        arg(&recording),
        "--scans",
        scans,
    ])
    .succeeded();
    assert!(
        record.stderr.contains(&format!("recorded {scans} scans")),
        "{record}"
    );
    assert!(emulator.interrupt().success(), "{}", emulator.output());
    bag
}

/// The bag `record --bag` writes holds the scans as LaserScan and, on
/// `/lms200/recording`, the recording written beside it byte for byte;
/// `clsmap map` maps the bag, and refuses a topic the bag lacks by name.
#[test]
fn record_writes_a_rosbag2_bag_that_holds_the_whole_recording_and_maps() {
    use clsmap::ros2::bag::BagReader;
    use clsmap::ros2::{ByteArray, LaserScan, RosMessage};
    let dir = TempDir::new("record-bag");
    let bag = record_bag(&dir, "40");
    let (mut scans, mut bytes) = (Vec::new(), Vec::new());
    for m in BagReader::open(&bag).unwrap() {
        let m = m.unwrap();
        match m.topic.topic.as_str() {
            "/scan" => scans.push(LaserScan::from_cdr(&m.data).unwrap()),
            "/lms200/recording" => bytes.extend(ByteArray::from_cdr(&m.data).unwrap().data),
            other => panic!("unexpected topic {other}"),
        }
    }
    assert!(scans.len() >= 40, "{} scans", scans.len());
    let s = &scans[0];
    assert_eq!(
        (s.ranges.len(), s.header.frame_id.as_str()),
        (BEAMS, "laser")
    );
    assert!((s.angle_min + std::f32::consts::FRAC_PI_2).abs() < 1e-6);
    assert!((s.range_max - 8.183).abs() < 1e-6);
    assert!(
        scans
            .windows(2)
            .all(|w| w[0].header.stamp.as_nanos() < w[1].header.stamp.as_nanos())
    );
    assert_eq!(bytes, std::fs::read(dir.join("run.rec")).unwrap());

    let out = dir.join("map");
    // The emulated sensor has no base: without odometry, and saying so.
    let no_odometry = clsmap(&["map", arg(&bag), "--out", arg(&out)]).failed();
    assert!(
        no_odometry
            .stderr
            .contains("no topic /odom (nav_msgs/msg/Odometry)")
            && no_odometry.stderr.contains("--no-odometry"),
        "{no_odometry}"
    );
    let map = clsmap(&["map", arg(&bag), "--out", arg(&out), "--no-odometry"]).succeeded();
    assert!(
        map.stdout
            .contains(&format!("mapped {} scans", scans.len())),
        "{map}"
    );
    assert!(out.join("map.json").is_file());
    let wrong = clsmap(&[
        "map",
        arg(&bag),
        "--out",
        arg(&out),
        "--scan-topic",
        "/laser",
    ])
    .failed();
    assert!(
        wrong
            .stderr
            .contains("no topic /laser (sensor_msgs/msg/LaserScan)")
            && wrong.stderr.contains("/scan (sensor_msgs/msg/LaserScan)"),
        "{wrong}"
    );
}

/// An independent reader (PyPI `rosbags`, its ROS 2 Humble types) opens
/// the bag `record --bag` writes and decodes every message.
#[test]
#[ignore = "needs PyPI rosbags; CI runs it: cargo test --test cli -- --ignored"]
fn an_independent_reader_decodes_every_message_of_a_recorded_bag() {
    let dir = TempDir::new("record-bag-rosbags");
    let bag = record_bag(&dir, "20");
    let python = std::env::var("CLSMAP_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/ros2_bag_check.py");
    let out = Command::new(&python)
        .arg(&script)
        .arg(&bag)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{python} {}: {}\n(needs PyPI rosbags: set CLSMAP_PYTHON to a Python that has it)",
        script.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        report["topics"]["/scan"]["type"], "sensor_msgs/msg/LaserScan",
        "{report}"
    );
    assert!(
        report["topics"]["/scan"]["count"].as_u64().unwrap() >= 20,
        "{report}"
    );
    assert_eq!(
        report["topics"]["/lms200/recording"]["type"], "std_msgs/msg/UInt8MultiArray",
        "{report}"
    );
    let scan = &report["first_scan"];
    assert_eq!(scan["frame_id"], "laser");
    assert_eq!(scan["beams"], BEAMS);
    assert!((scan["angle_increment"].as_f64().unwrap() - 0.5f64.to_radians()).abs() < 1e-6);
    assert_eq!(report["scan_stamps_increase"], true);
    let recording = std::fs::read(dir.join("run.rec")).unwrap();
    assert_eq!(report["recording_bytes"], recording.len());
}
