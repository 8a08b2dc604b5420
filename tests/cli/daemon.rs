//! `clsmap run`: the daemon as systemd runs it, driven by signals.

use super::*;
use clsmap::daemon::simulation::VirtualRobot;

/// A running `clsmap run`, its stderr lines arriving on a channel.
pub(super) struct Daemon {
    child: Child,
    lines: std::sync::mpsc::Receiver<String>,
    seen: Vec<String>,
}

impl Daemon {
    pub(super) fn start(config: &Path) -> Daemon {
        Daemon::start_with(config, &[])
    }

    /// `clsmap run --config CONFIG` with more arguments.
    pub(super) fn start_with(config: &Path, more: &[&str]) -> Daemon {
        let mut child = clsmap_command()
            .args(["run", "--config", arg(config)])
            .args(more)
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
    pub(super) fn wait_for(&mut self, text: &str, limit: Duration) {
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

    /// The first stderr line seen so far containing `text`.
    pub(super) fn line_with(&self, text: &str) -> Option<&str> {
        self.seen
            .iter()
            .find(|l| l.contains(text))
            .map(String::as_str)
    }

    pub(super) fn signal(&self, name: &str) {
        let status = Command::new("kill")
            .args([&format!("-{name}"), &self.child.id().to_string()])
            .status()
            .unwrap();
        assert!(status.success(), "kill -{name} failed");
    }

    /// Waits for the exit; returns the status, stdout and all of stderr.
    pub(super) fn finish(mut self, limit: Duration) -> (ExitStatus, String, String) {
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

pub(super) fn demo_run_config(dir: &TempDir, extra: &str) -> PathBuf {
    let text =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("config/demo.toml"))
            .unwrap()
            .replace("exit_when_complete = true", "exit_when_complete = false")
            .replace("checkpoint_interval = 30.0", "checkpoint_interval = 1.0")
            .replace("status_interval = 5.0", "status_interval = 1.0")
            // Tests run side by side: the live view on a free port.
            .replace(
                "[web]\nenabled = true",
                "[web]\nenabled = true\nbind = \"127.0.0.1:0\"",
            )
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
    daemon.wait_for("first scan localized", Duration::from_secs(60));
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

/// The morning after, as a process: `clsmap run --map saved --mode
/// localize` finds the robot in the saved map, checkpoints only its path
/// while it runs, and leaves the saved map byte for byte as it was after
/// SIGTERM; the run's directory ends with the map and the path.
#[test]
fn run_with_a_saved_map_localizes_and_leaves_the_map_untouched_on_sigterm() {
    let dir = TempDir::new("run-localize");
    // A map of the lab's start area, made on the virtual clock.
    let mut robot = VirtualRobot::new(&clsmap::demo::demo_config().unwrap()).unwrap();
    robot.run_until(15.0, |_| false);
    let saved = dir.join("saved");
    robot.checkpoint(&saved).unwrap();
    let saved = saved.join("map.json");
    let bytes = std::fs::read(&saved).unwrap();
    let config = demo_run_config(&dir, "");
    let mut daemon = Daemon::start_with(&config, &["--map", arg(&saved), "--mode", "localize"]);
    daemon.wait_for("first scan localized", Duration::from_secs(60));
    // Checkpoints (every second here) write the path, not the map: two of
    // them done (the path grew after the first) and still no map.
    let deadline = Instant::now() + Duration::from_secs(30);
    let mut first: Option<u64> = None;
    let run = loop {
        let written = std::fs::read_dir(dir.join("state"))
            .ok()
            .and_then(|mut d| d.next())
            .and_then(Result::ok)
            .map(|e| e.path())
            .and_then(|run| {
                let len = std::fs::metadata(run.join("trajectory.tum")).ok()?.len();
                Some((run, len))
            });
        match (first, written) {
            (Some(before), Some((run, len))) if len > before => break run,
            (None, Some((_, len))) if len > 0 => first = Some(len),
            _ => {}
        }
        assert!(Instant::now() < deadline, "no two checkpoints within 30 s");
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(
        !run.join("map.json").exists(),
        "a localize run checkpointed the map"
    );
    daemon.signal("TERM");
    let (status, _, stderr) = daemon.finish(Duration::from_secs(30));
    assert!(status.success(), "{status}\n{stderr}");
    assert_eq!(
        std::fs::read(&saved).unwrap(),
        bytes,
        "the saved map changed"
    );
    let ended = clsmap::map::file::load(&run.join("map.json")).unwrap();
    assert_eq!(
        ended.contents.keyframes.len(),
        clsmap::map::file::load(&saved)
            .unwrap()
            .contents
            .keyframes
            .len()
    );
    let poses = std::fs::read_to_string(run.join("trajectory.tum")).unwrap();
    assert!(
        poses.lines().filter(|l| !l.starts_with('#')).count() > 10,
        "{poses}"
    );
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

/// `clsmap run` with `[daemon] bag = true` on the demo, stopped by
/// SIGTERM; returns the run's directory.
fn run_with_a_bag(dir: &TempDir) -> PathBuf {
    let config = demo_run_config(dir, "");
    let text = std::fs::read_to_string(&config).unwrap();
    std::fs::write(
        &config,
        text.replacen("[daemon]", "[daemon]\nbag = true", 1),
    )
    .unwrap();
    let mut daemon = Daemon::start(&config);
    daemon.wait_for("writing a rosbag2 bag", Duration::from_secs(60));
    daemon.wait_for("exploration: goal reached", Duration::from_secs(60));
    daemon.signal("TERM");
    let (status, _, stderr) = daemon.finish(Duration::from_secs(30));
    assert!(status.success(), "{status}\n{stderr}");
    assert!(stderr.contains("bag written"), "{stderr}");
    run_dir(&dir.join("state"))
}

/// The daemon's bag holds, for every scan, the scan, the pose estimate,
/// the odometry and the transforms map → odom → base_link that chain to
/// the pose, and base_link → laser once; the poses are those of
/// trajectory.tum; the map as a grid and as lines; and the serial stream,
/// whose bytes put end to end are a recording holding every scan, with
/// the base's odometry.
#[test]
fn run_writes_a_rosbag2_bag_whose_transforms_chain_to_its_poses() {
    use clsmap::ros2::bag::BagReader;
    use clsmap::ros2::{PoseWithCovarianceStamped, RosMessage, TfMessage};
    let dir = TempDir::new("run-bag");
    let run = run_with_a_bag(&dir);
    let (mut poses, mut tfs, mut counts) =
        (Vec::new(), Vec::new(), std::collections::BTreeMap::new());
    let mut recording = Vec::new();
    for m in BagReader::open(&run.join("run.mcap")).unwrap() {
        let m = m.unwrap();
        *counts.entry(m.topic.topic.clone()).or_insert(0usize) += 1;
        match m.topic.topic.as_str() {
            "/pose" => poses.push(PoseWithCovarianceStamped::from_cdr(&m.data).unwrap()),
            "/tf" => tfs.push(TfMessage::from_cdr(&m.data).unwrap()),
            "/lms200/recording" => {
                recording.extend(clsmap::ros2::ByteArray::from_cdr(&m.data).unwrap().data);
            }
            _ => {}
        }
    }
    let scans = counts["/scan"];
    assert!(scans > 20, "{counts:?}");
    assert_eq!(counts["/tf_static"], 1, "{counts:?}");
    assert!(counts.get("/map").is_some_and(|&n| n >= 1), "{counts:?}");
    assert_eq!(counts.get("/map"), counts.get("/cls_map"), "{counts:?}");
    // The raw stream carries every scan the loop saw, and those it
    // skipped (the sensor streams faster than a debug build maps).
    let raw: Vec<_> = clsmap::input::lms200::RecordingScans::new(&recording[..])
        .unwrap()
        .filter_map(Result::ok)
        .collect();
    let raw_scans = raw.len();
    assert!(
        raw_scans >= scans,
        "{raw_scans} scans in the raw stream, {scans} on /scan"
    );
    // With the base's odometry in it, so a replay maps as the run did:
    // every scan but those before the first sample and after the last.
    let with_odometry = raw.iter().filter(|s| s.odometry.is_some()).count();
    assert!(
        with_odometry + 10 >= raw_scans,
        "{with_odometry} of {raw_scans} recorded scans with odometry"
    );
    // The demo's status line comes every second.
    assert!(
        counts.get("/diagnostics").is_some_and(|&n| n >= 1),
        "{counts:?}"
    );
    for topic in ["/pose", "/tf", "/odom"] {
        assert_eq!(counts[topic], scans, "{topic}: {counts:?}");
    }
    let as_xy = |t: &clsmap::ros2::TransformStamped| {
        clsmap::geometry::Pose2::new(t.translation.x, t.translation.y, t.rotation.yaw())
    };
    for (p, tf) in poses.iter().zip(&tfs) {
        assert_eq!(
            (
                tf.transforms[0].header.frame_id.as_str(),
                tf.transforms[1].child_frame_id.as_str()
            ),
            ("map", "base_link")
        );
        let chained = as_xy(&tf.transforms[0]).compose(&as_xy(&tf.transforms[1]));
        let pose = &p.pose.position;
        assert!(
            (chained.x - pose.x).hypot(chained.y - pose.y) < 1e-6,
            "{chained:?} {p:?}"
        );
    }
    // The trajectory file holds the same poses (the last ones it wrote).
    let tum = std::fs::read_to_string(run.join("trajectory.tum")).unwrap();
    let written = tum.lines().filter(|l| !l.starts_with('#')).count();
    assert!(
        written + 5 >= scans && written <= scans + 5,
        "{written} poses, {scans} scans"
    );
}

/// An independent reader (PyPI `rosbags`) decodes every message of the
/// daemon's bag.
#[test]
#[ignore = "needs PyPI rosbags; CI runs it: cargo test --test cli -- --ignored"]
fn an_independent_reader_decodes_every_message_of_the_daemon_s_bag() {
    let dir = TempDir::new("run-bag-rosbags");
    let run = run_with_a_bag(&dir);
    let python = std::env::var("CLSMAP_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/ros2_bag_check.py");
    let out = Command::new(&python)
        .arg(&script)
        .arg(run.join("run.mcap"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{python}: {}\n(needs PyPI rosbags: set CLSMAP_PYTHON to a Python that has it)",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for (topic, ty) in [
        ("/scan", "sensor_msgs/msg/LaserScan"),
        ("/pose", "geometry_msgs/msg/PoseWithCovarianceStamped"),
        ("/odom", "nav_msgs/msg/Odometry"),
        ("/tf", "tf2_msgs/msg/TFMessage"),
        ("/tf_static", "tf2_msgs/msg/TFMessage"),
        ("/map", "nav_msgs/msg/OccupancyGrid"),
        ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"),
        ("/cls_map", "visualization_msgs/msg/MarkerArray"),
        ("/lms200/recording", "std_msgs/msg/UInt8MultiArray"),
    ] {
        assert_eq!(report["topics"][topic]["type"], ty, "{report}");
        assert!(
            report["topics"][topic]["count"].as_u64().unwrap() >= 1,
            "{report}"
        );
    }
    assert_eq!(report["scan_stamps_increase"], true, "{report}");
    // The raw stream starts as a recording does ("CLSMREC", version 1).
    assert_eq!(report["recording_head"], "434c534d52454301", "{report}");
}

/// The daemon as a ROS 2 node, seen from an independent DDS stack (PyPI
/// `cyclonedds`, `scripts/ros2_subscriber.py`, with the message layouts
/// written there from the ROS 2 definitions): a subscriber that joins
/// after the start gets /scan, /pose, /tf and, transient-local, the
/// /tf_static sent at the first scan and the latest /map and /cls_map;
/// frames as REP 105, stamps on the wall clock. Both sides keep DDS on the
/// loopback interface.
#[test]
#[ignore = "needs PyPI cyclonedds; CI runs it: cargo test --test cli -- --ignored"]
fn an_independent_dds_subscriber_sees_the_daemon_s_topics() {
    let dir = TempDir::new("run-ros2");
    // A domain of its own, so tests side by side do not hear each other.
    let domain = 100 + std::process::id() % 100;
    let config = demo_run_config(
        &dir,
        &format!("[ros2]\nenabled = true\nlocalhost_only = true\ndomain_id = {domain}\n"),
    );
    let mut daemon = Daemon::start(&config);
    daemon.wait_for("ROS 2 node up", Duration::from_secs(60));
    daemon.wait_for("first scan localized", Duration::from_secs(60));
    let python = std::env::var("CLSMAP_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/ros2_subscriber.py");
    let out = Command::new(&python)
        .arg(&script)
        .args([
            "--domain",
            &domain.to_string(),
            "--late",
            "1",
            "--timeout",
            "60",
            "--localhost",
        ])
        .output()
        .unwrap();
    daemon.signal("TERM");
    let (status, _, stderr) = daemon.finish(Duration::from_secs(30));
    assert!(status.success(), "{status}\n{stderr}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{python} {}: {stdout}\n{}\n(needs PyPI cyclonedds: set CLSMAP_PYTHON to a Python that has it)",
        script.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    let scan = &report["scan"];
    assert_eq!(scan["frame_id"], "laser", "{report}");
    assert_eq!(scan["beams"], BEAMS, "{report}");
    assert!((scan["angle_increment"].as_f64().unwrap() - 0.5f64.to_radians()).abs() < 1e-6);
    assert!(
        (scan["range_max"].as_f64().unwrap() - 8.183).abs() < 1e-5,
        "{report}"
    );
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs_f64();
    assert!(
        (now - scan["stamp"].as_f64().unwrap()).abs() < 120.0,
        "{report}"
    );
    assert_eq!(report["pose"]["frame_id"], "map", "{report}");
    assert!(report["pose"]["var_x"].as_f64().unwrap() > 0.0, "{report}");
    assert_eq!(
        report["tf"],
        serde_json::json!([["map", "odom"], ["odom", "base_link"]])
    );
    assert_eq!(
        report["tf_static"],
        serde_json::json!([["base_link", "laser"]])
    );
    // Walls and frontiers as line lists in the map frame.
    let lines = &report["cls_map"];
    for ns in ["walls", "frontiers"] {
        assert_eq!(lines[ns]["frame_id"], "map", "{report}");
        assert_eq!(lines[ns]["type"], 5, "{report}");
        assert!(lines[ns]["points"].as_u64().unwrap() >= 2, "{report}");
    }
    assert!(lines["loop_edges"].is_object(), "{report}");
}

/// A ROS 2 teleop on the independent DDS stack drives the robot: with
/// exploration off, Twist messages on /cmd_vel move the simulated base
/// through the daemon's limits, and the daemon's /pose follows.
#[test]
#[ignore = "needs PyPI cyclonedds; CI runs it: cargo test --test cli -- --ignored"]
fn cmd_vel_from_an_independent_dds_publisher_drives_the_base() {
    let dir = TempDir::new("run-ros2-teleop");
    let domain = 100 + (std::process::id() + 50) % 100;
    let config = demo_run_config(
        &dir,
        &format!("[ros2]\nenabled = true\ndomain_id = {domain}\n"),
    );
    let text = std::fs::read_to_string(&config).unwrap();
    std::fs::write(
        &config,
        text.replacen(
            "[exploration]\nenabled = true",
            "[exploration]\nenabled = false",
            1,
        ),
    )
    .unwrap();
    let mut daemon = Daemon::start(&config);
    daemon.wait_for("ROS 2 node up", Duration::from_secs(60));
    daemon.wait_for("first scan localized", Duration::from_secs(60));
    let python = std::env::var("CLSMAP_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/ros2_subscriber.py");
    let out = Command::new(&python)
        .arg(&script)
        .args(["--domain", &domain.to_string(), "--timeout", "60"])
        .args(["--cmd-vel", "0.2", "--drive", "3"])
        .output()
        .unwrap();
    daemon.wait_for("driven by velocity commands", Duration::from_secs(5));
    daemon.signal("TERM");
    let (status, _, stderr) = daemon.finish(Duration::from_secs(30));
    assert!(status.success(), "{status}\n{stderr}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap();
    let d = &report["driven"];
    let moved = d["dx"].as_f64().unwrap().hypot(d["dy"].as_f64().unwrap());
    // 0.2 m/s for 3 s, less the start and the stop.
    assert!((0.3..0.8).contains(&moved), "moved {moved:.3} m: {report}");
}

/// `clsmap run` with `[base] adapter = "ros2"` (and `base` added to
/// `[base]`) beside `scripts/ros2_base.py` run with `args`, on the scans of
/// `clsmap emulate`, DDS on the loopback interface; returns the script's
/// report and the daemon's log.
fn run_with_a_ros2_base(name: &str, base: &str, args: &[&str]) -> (serde_json::Value, String) {
    let dir = TempDir::new(name);
    let link = dir.join("lms200");
    let emulator = super::emulator::EmulatorProcess::start(&dir, &link);
    let domain = 100 + (std::process::id() + 25 + args.len() as u32) % 100;
    let config = dir.join("clsmap.toml");
    std::fs::write(
        &config,
        format!(
            "[sensor]\nsource = \"serial\"\nport = {:?}\n\n[base]\nadapter = \"ros2\"\n{base}\n\
             [exploration]\nenabled = true\n\n[daemon]\nstate_dir = {:?}\n\n\
             [ros2]\nlocalhost_only = true\ndomain_id = {domain}\n",
            link.display().to_string(),
            dir.join("state").display().to_string()
        ),
    )
    .unwrap();
    let mut daemon = Daemon::start(&config);
    daemon.wait_for("base connected", Duration::from_secs(60));
    let python = std::env::var("CLSMAP_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/ros2_base.py");
    let out = Command::new(&python)
        .arg(&script)
        .args(["--domain", &domain.to_string(), "--localhost"])
        .args(args)
        .output()
        .unwrap();
    daemon.signal("TERM");
    let (status, _, stderr) = daemon.finish(Duration::from_secs(30));
    assert!(status.success(), "{status}\n{stderr}");
    drop(emulator);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{python} {}: {stdout}\n{}\n(needs PyPI cyclonedds: set CLSMAP_PYTHON to a Python that has it)",
        script.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    (serde_json::from_str(stdout.trim()).unwrap(), stderr)
}

/// A base behind its own ROS 2 driver (`[base] adapter = "ros2"`), the
/// driver on an independent DDS stack (`scripts/ros2_base.py`: PyPI
/// `cyclonedds`, integrating /cmd_vel into /odom at 50 Hz like a holonomic
/// base's driver node): exploration drives it through /cmd_vel within the
/// speed limit; when the driver's odometry stops, the base gets a stop
/// within the stale-odometry guard (0.5 s) and nothing moving until the
/// odometry is back; then it drives again.
#[test]
#[ignore = "needs PyPI cyclonedds; CI runs it: cargo test --test cli -- --ignored"]
fn a_ros2_base_driver_is_driven_and_stopped_when_its_odometry_stops() {
    let (report, stderr) = run_with_a_ros2_base(
        "run-ros2-base",
        "",
        &["--seconds", "14", "--silent-at", "5", "--silent-for", "3"],
    );
    let moving = report["moving"].as_u64().unwrap();
    let fastest = report["fastest"].as_f64().unwrap();
    assert!(moving > 50, "{report}\n{stderr}");
    // Within [base] max_speed (1 m/s) and the drive's cruise (0.5 m/s).
    assert!(fastest > 0.05 && fastest <= 0.5 + 1e-6, "{report}");
    assert!(report["driven"].as_f64().unwrap() > 0.3, "{report}");
    let silence = &report["silence"];
    let stop = silence["first_stop_after"].as_f64();
    assert!(stop.is_some_and(|t| t < 0.5 + 0.3), "{report}\n{stderr}");
    let last_moving = silence["last_moving_after"].as_f64().unwrap_or(0.0);
    assert!(last_moving < 0.5 + 0.1, "{report}");
    assert!(
        report["moving_after_silence"].as_u64().unwrap() > 10,
        "{report}"
    );
    assert!(
        stderr.contains("no odometry on /odom for more than"),
        "{stderr}"
    );
}

/// The same driver publishing its odometry only as `odom` → `base_link`
/// on /tf (`odom_from_tf`): the base is driven on it.
#[test]
#[ignore = "needs PyPI cyclonedds; CI runs it: cargo test --test cli -- --ignored"]
fn a_ros2_base_driver_that_publishes_only_tf_is_driven() {
    let (report, stderr) = run_with_a_ros2_base(
        "run-ros2-base-tf",
        "odom_from_tf = true\n",
        &["--seconds", "6", "--tf"],
    );
    // Motion is commanded only on fresh odometry.
    assert!(
        report["moving"].as_u64().unwrap() > 20,
        "{report}\n{stderr}"
    );
    assert!(report["driven"].as_f64().unwrap() > 0.1, "{report}");
}
