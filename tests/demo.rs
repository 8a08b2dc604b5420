//! `clsmap demo` end to end through a real pseudo-terminal, at the
//! sensor's real pace: the emulated LMS200 measures the simulated world
//! from the simulated base, the serial driver streams at 500 kBd, and the
//! daemon's loop localizes, maps and explores until no frontier is left.

#![allow(clippy::unwrap_used)]

use clsmap::daemon::StopReason;
use clsmap::demo::{DemoStop, demo_config, run_demo};
use clsmap::map::cls::{ClsMap, ClsMapConfig};

#[test]
#[ignore = "a minute of real time; CI runs it: cargo test --test demo -- --ignored"]
fn the_demo_world_is_explored_to_completion_through_the_pty() {
    // Exactly what `clsmap demo` runs (about a minute of real time).
    let config = demo_config().unwrap();
    let out = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("demo-{}", std::process::id()));
    let mut reports = 0u64;
    let summary = run_demo(config, &out, DemoStop::TimeLimit, |_| reports += 1, |_| {}).unwrap();
    println!("{}", serde_json::to_string_pretty(&summary).unwrap());
    assert_eq!(
        summary.reason,
        StopReason::ExplorationComplete,
        "{summary:?}"
    );
    assert!(summary.exploration_complete);
    assert_eq!(reports, summary.scans);
    assert!(summary.scans > 100, "{summary:?}");
    assert!(summary.walls_on_world > 0.9, "{summary:?}");
    assert!(summary.mean_error_m < 0.05, "{summary:?}");
    let latency = summary
        .latencies
        .iter()
        .find(|l| l.stage == clsmap::daemon::Stage::Pose)
        .unwrap();
    assert_eq!(latency.count, summary.scans);
    assert!(summary.max_heading_error_deg < 1.0, "{summary:?}");
    // The saved map loads, is valid and closed: no frontier worth a goal
    // but those the explorer visited and gave up on (as on the virtual
    // clock, a wall piece left virtual a few cm off the wall can be one).
    let map = ClsMap::load(&out.join("map.json"), ClsMapConfig::default()).unwrap();
    map.check_invariants().unwrap();
    let left = clsmap::explore::pursuit::long_frontiers(&map, 0.74);
    assert!(
        left.len() <= summary.frontiers_given_up && summary.frontiers_given_up <= 2,
        "long frontiers left: {left:?}, {summary:?}"
    );
    for file in ["map.svg", "trajectory.tum", "demo.json"] {
        assert!(out.join(file).is_file(), "{file} missing");
    }
}

/// Hardening: when the run's directory stops taking the map (here
/// `map.json` replaced by a directory mid-run), the last save goes to a
/// rescue directory beside the run's, inside the state directory — not
/// under `$TMPDIR`, which the unit's `PrivateTmp=` empties at stop — and
/// the rescue is whole: every pose of the run, including those written to
/// the run's directory before it failed.
#[test]
fn a_rescued_map_is_whole_and_kept_in_the_state_directory() {
    let dir = std::env::temp_dir().join(format!("clsmap-rescue-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let mut config = clsmap::demo::demo_config().unwrap();
    config.daemon.max_run_time = 6.0;
    config.daemon.checkpoint_interval = 1.0;
    config.daemon.state_dir = Some(dir.join("state"));
    config.exploration.exit_when_complete = false;
    config.web.bind = "127.0.0.1:0".into();
    let run_dir = dir.join("state").join("run");
    let blocked = run_dir.join("map.json");
    let mut hooks = clsmap::daemon::Hooks::until(std::future::pending());
    hooks.out_dir = Some(run_dir.clone());
    let mut broke = false;
    hooks.on_scan = Some(Box::new(move |_| {
        // Once a checkpoint has written the map there (scans before it
        // are in the run's trajectory), the directory stops taking it.
        if !broke && blocked.is_file() {
            std::fs::remove_file(&blocked).unwrap();
            std::fs::create_dir_all(blocked.join("in-the-way")).unwrap();
            broke = true;
        }
    }));
    let summary = clsmap::daemon::run_blocking(config, hooks).unwrap();
    let why = summary
        .rescued_because
        .clone()
        .expect("the map was rescued");
    let rescue = summary.out_dir.clone().unwrap();
    assert!(why.contains("map.json") || why.contains("run"), "{why}");
    assert_eq!(
        rescue.parent(),
        Some(dir.join("state").as_path()),
        "{rescue:?}"
    );
    let poses = std::fs::read_to_string(rescue.join("trajectory.tum"))
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .count() as u64;
    assert_eq!(poses, summary.scans, "every pose of the run in the rescue");
    clsmap::map::file::load(&rescue.join("map.json")).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
}

/// One HTTP/1.1 request on a new connection; the status and the body.
fn http(address: std::net::SocketAddr, request: &str) -> (u16, String) {
    use std::io::{Read, Write};
    let mut stream = std::net::TcpStream::connect(address).unwrap();
    stream
        .set_read_timeout(Some(std::time::Duration::from_secs(10)))
        .unwrap();
    stream.write_all(request.as_bytes()).unwrap();
    let mut reply = Vec::new();
    stream.read_to_end(&mut reply).unwrap();
    let reply = String::from_utf8_lossy(&reply).into_owned();
    let status = reply
        .split_whitespace()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let body = reply
        .split_once("\r\n\r\n")
        .map(|(_, b)| b.to_string())
        .unwrap_or_default();
    (status, body)
}

fn get(address: std::net::SocketAddr, path: &str) -> (u16, String) {
    http(
        address,
        &format!("GET {path} HTTP/1.1\r\nHost: clsmap\r\nConnection: close\r\n\r\n"),
    )
}

fn post(address: std::net::SocketAddr, path: &str, token: Option<&str>) -> u16 {
    let auth = token.map_or(String::new(), |t| format!("Authorization: Bearer {t}\r\n"));
    http(
        address,
        &format!(
            "POST {path} HTTP/1.1\r\nHost: clsmap\r\n{auth}Content-Length: 0\r\nConnection: close\r\n\r\n"
        ),
    )
    .0
}

/// The live view of a running daemon: JSON endpoints for scripts, the
/// client limit, control only with the token. (The page in a browser:
/// `tests/cli/web.rs`.)
#[test]
#[ignore = "real time; CI runs it: cargo test --test demo -- --ignored"]
fn the_live_view_serves_the_running_daemon_to_scripts() {
    use std::io::{Read, Write};
    const TOKEN: &str = "a-test-token-of-some-length";
    let mut config = demo_config().unwrap();
    config.web.bind = "127.0.0.1:0".into();
    config.web.token = Some(TOKEN.into());
    config.web.max_clients = 3;
    config.daemon.max_run_time = 60.0;
    let dir = std::env::temp_dir().join(format!("clsmap-web-{}", std::process::id()));
    let (address_tx, address_rx) = std::sync::mpsc::channel();
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let out = dir.clone();
    let daemon = std::thread::spawn(move || {
        let mut hooks = clsmap::daemon::Hooks::until(async move {
            let _ = stop_rx.await;
        });
        hooks.out_dir = Some(out);
        hooks.on_web = Some(Box::new(move |a| {
            let _ = address_tx.send(a);
        }));
        clsmap::daemon::run_blocking(config, hooks).unwrap()
    });
    let address = address_rx
        .recv_timeout(std::time::Duration::from_secs(30))
        .unwrap();

    // Scripts: the status once the loop is mapping.
    let started = std::time::Instant::now();
    let status = loop {
        let (code, body) = get(address, "/api/status");
        if code == 200 {
            let v: serde_json::Value = serde_json::from_str(&body).unwrap();
            if v["status"]["scans"].as_u64().unwrap_or(0) > 100 {
                break v;
            }
        }
        assert!(started.elapsed().as_secs() < 30, "no status: {code} {body}");
        std::thread::sleep(std::time::Duration::from_millis(200));
    };
    assert_eq!(status["sensor"], "streaming", "{status}");
    assert_eq!(status["control"], true);
    let (code, geometry) = get(address, "/api/geometry");
    assert_eq!(code, 200);
    let geometry: serde_json::Value = serde_json::from_str(&geometry).unwrap();
    assert!(
        geometry["walls"].as_array().unwrap().len() > 5,
        "{geometry}"
    );
    let (code, trajectory) = get(address, "/api/trajectory");
    assert_eq!(code, 200);
    let trajectory: serde_json::Value = serde_json::from_str(&trajectory).unwrap();
    assert!(!trajectory.as_array().unwrap().is_empty());
    // /api/map is the map file itself.
    let (code, map) = get(address, "/api/map");
    assert_eq!(code, 200);
    let loaded = clsmap::map::file::decode(&map).unwrap();
    assert_eq!(loaded.version, 3);
    assert!(loaded.contents.cls.actual_segments().count() > 5);

    // Control only with the token.
    assert_eq!(post(address, "/api/control/pause", None), 401);
    assert_eq!(
        post(
            address,
            "/api/control/pause",
            Some("wrong-token-wrong-token")
        ),
        401
    );
    assert_eq!(post(address, "/api/control/pause", Some(TOKEN)), 202);
    let started = std::time::Instant::now();
    loop {
        let (_, body) = get(address, "/api/status");
        let v: serde_json::Value = serde_json::from_str(&body).unwrap_or_default();
        if v["paused"] == true && v["command"] == serde_json::json!([0.0, 0.0, 0.0]) {
            break;
        }
        assert!(started.elapsed().as_secs() < 10, "not paused: {body}");
        std::thread::sleep(std::time::Duration::from_millis(200));
    }
    assert_eq!(post(address, "/api/control/resume", Some(TOKEN)), 202);
    // A pose hint needs its three numbers (a new map then refuses it in
    // the loop, with a warning: its frame is where the robot started).
    assert_eq!(post(address, "/api/control/pose?x=1&y=2", Some(TOKEN)), 400);
    assert_eq!(
        post(address, "/api/control/pose?x=1&y=2&theta=0", None),
        401
    );
    assert_eq!(
        post(address, "/api/control/pose?x=1&y=2&theta=0", Some(TOKEN)),
        202
    );

    // Three streams that never read take every client slot: the next
    // request is refused, not queued, and the loop goes on meanwhile.
    let streams: Vec<_> = (0..3)
        .map(|_| {
            let mut s = std::net::TcpStream::connect(address).unwrap();
            s.write_all(b"GET /api/events HTTP/1.1\r\nHost: clsmap\r\n\r\n")
                .unwrap();
            let mut head = [0u8; 12];
            s.read_exact(&mut head).unwrap();
            assert_eq!(&head, b"HTTP/1.1 200");
            s
        })
        .collect();
    let scans_before = status["status"]["scans"].as_u64().unwrap();
    std::thread::sleep(std::time::Duration::from_secs(2));
    assert_eq!(get(address, "/api/status").0, 503);
    drop(streams);
    std::thread::sleep(std::time::Duration::from_millis(500));
    let (code, body) = get(address, "/api/status");
    assert_eq!(code, 200);
    let v: serde_json::Value = serde_json::from_str(&body).unwrap();
    assert!(
        v["status"]["scans"].as_u64().unwrap() > scans_before + 30,
        "{v}"
    );

    let _ = stop_tx.send(());
    let summary = daemon.join().unwrap();
    assert_eq!(summary.reason, StopReason::Shutdown);
    let _ = std::fs::remove_dir_all(&dir);
}
