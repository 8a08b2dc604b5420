//! `LineBase` against `scripts/fake_base.py`. Needs `python3` and real-time
//! scheduling to within ~0.1 s, so it is opt-in:
//! `cargo test -p clsmap-base --test fake_base_script -- --ignored`.
#![allow(clippy::unwrap_used)]

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::thread;
use std::time::{Duration, Instant};

use clsmap_base::{BaseAdapter, Health, LineBase, Twist};

/// Kills the script however the test ends.
struct Script(Child);

impl Drop for Script {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
#[ignore = "spawns python3 scripts/fake_base.py and runs 1.5 s in real time"]
fn drives_the_python_fake_base() {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/fake_base.py");
    let mut child = Script(
        Command::new("python3")
            .arg(&script)
            .args(["--port", "0", "--once"])
            .stdout(Stdio::piped())
            .spawn()
            .unwrap(),
    );
    let mut first = String::new();
    BufReader::new(child.0.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    let addr = first
        .trim()
        .strip_prefix("listening on ")
        .unwrap()
        .to_owned();
    let mut b = LineBase::connect_tcp(&addr, Duration::from_secs(2)).unwrap();

    // 1 s at 0.5 m/s forward, commanded at 50 Hz like the daemon.
    let start = Instant::now();
    let mut samples = 0;
    let mut last = None;
    let drive = 1.0;
    while start.elapsed().as_secs_f64() < drive + 0.5 {
        let now = start.elapsed().as_secs_f64();
        b.advance(now);
        if let Some(o) = b.odometry() {
            samples += 1;
            last = Some(o);
        }
        if now < drive {
            b.command(Twist::new(0.5, 0.0, 0.0), now).unwrap();
        } else {
            b.stop(now).unwrap();
        }
        thread::sleep(Duration::from_millis(20));
    }
    let pose = last.unwrap().pose;
    assert!((pose.x - 0.5).abs() < 0.1, "{pose:?}");
    assert!(pose.y.abs() < 1e-6 && pose.theta.abs() < 1e-6, "{pose:?}");
    // ~50 Hz ODOM polled at ≤ 50 Hz: most polls see a new sample.
    assert!(samples > 40, "{samples} samples in 1.5 s");
    assert_eq!(b.health(), Health::Ok);
    assert_eq!(b.stats().malformed_lines, 0);
    assert_eq!(b.stats().odometry_out_of_order, 0);
    eprintln!(
        "fake_base.py: {samples} samples in 1.5 s, final pose {pose:?}, {:?}",
        b.stats()
    );
}
