//! The live view under load: the daemon on the demo's simulated robot at
//! 75 scans/s (180°/1°) for a while without clients, then again with 50
//! clients streaming `/api/events` and one that connects and never reads.
//! Prints the scan-to-pose latency of both runs, the process's memory,
//! what the clients received, and whether the stalled one was dropped.
//!
//!     cargo run --release --example web_load -- [SECONDS]

use std::io::{Read, Write};
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use clsmap::daemon::{Hooks, RunSummary, Stage, run_blocking};
use clsmap::demo::demo_config;

fn rss_kib() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .unwrap_or_default()
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .unwrap_or(0)
}

/// Runs the daemon for `seconds`; `during(address)` runs beside it.
fn run(
    seconds: f64,
    clients: usize,
    during: impl FnOnce(SocketAddr) + Send + 'static,
) -> Result<RunSummary, Box<dyn std::error::Error>> {
    let mut config = demo_config()?;
    config.sensor.resolution = 1.0;
    config.web.bind = "127.0.0.1:0".into();
    config.web.max_clients = clients.max(1) + 8;
    config.daemon.max_run_time = seconds;
    config.exploration.exit_when_complete = false;
    let dir =
        std::env::temp_dir().join(format!("clsmap-web-load-{}-{clients}", std::process::id()));
    let mut hooks = Hooks::until(std::future::pending());
    hooks.out_dir = Some(dir.clone());
    let mut during = Some(during);
    hooks.on_web = Some(Box::new(move |address| {
        if let Some(f) = during.take() {
            std::thread::spawn(move || f(address));
        }
    }));
    let summary = run_blocking(config, hooks)?;
    let _ = std::fs::remove_dir_all(&dir);
    Ok(summary)
}

fn pose_latency(s: &RunSummary) -> String {
    s.latencies
        .iter()
        .find(|l| l.stage == Stage::Pose)
        .map_or("–".into(), |l| {
            format!(
                "p50 {} µs, p99 {} µs, max {} µs",
                l.p50_us, l.p99_us, l.max_us
            )
        })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let seconds: f64 = std::env::args().nth(1).map_or(Ok(30.0), |s| s.parse())?;
    let quiet = run(seconds, 0, |_| {})?;
    println!(
        "without clients: {} scans ({:.1}/s), scan to pose {}",
        quiet.scans,
        quiet.scans as f64 / quiet.run_time,
        pose_latency(&quiet)
    );
    let rss_before = rss_kib();
    let received = Arc::new(AtomicU64::new(0));
    let stalled_dropped = Arc::new(AtomicBool::new(false));
    let (rx_count, dropped) = (received.clone(), stalled_dropped.clone());
    let peak = Arc::new(AtomicU64::new(0));
    let peak_in = peak.clone();
    let loaded = run(seconds, 50, move |address| {
        let mut readers = Vec::new();
        for _ in 0..50 {
            let count = rx_count.clone();
            readers.push(std::thread::spawn(move || {
                let Ok(mut s) = std::net::TcpStream::connect(address) else {
                    return;
                };
                let _ = s.write_all(b"GET /api/events HTTP/1.1\r\nHost: clsmap\r\n\r\n");
                let mut buf = [0u8; 16 * 1024];
                while let Ok(n) = s.read(&mut buf) {
                    if n == 0 {
                        break;
                    }
                    count.fetch_add(n as u64, Ordering::Relaxed);
                }
            }));
        }
        // One client that asks for the stream and never reads it.
        if let Ok(mut stalled) = std::net::TcpStream::connect(address) {
            let _ = stalled.write_all(b"GET /api/events HTTP/1.1\r\nHost: clsmap\r\n\r\n");
            let until = std::time::Instant::now() + Duration::from_secs_f64(seconds - 2.0);
            while std::time::Instant::now() < until {
                peak_in.fetch_max(rss_kib(), Ordering::Relaxed);
                std::thread::sleep(Duration::from_millis(500));
            }
            // Drain what the kernel buffered: the end of the stream shows
            // the server let it go.
            let _ = stalled.set_read_timeout(Some(Duration::from_millis(500)));
            let mut buf = [0u8; 64 * 1024];
            loop {
                match stalled.read(&mut buf) {
                    Ok(0) | Err(_) => break,
                    Ok(_) => {}
                }
            }
            let ended = matches!(stalled.read(&mut buf), Ok(0))
                || matches!(stalled.read(&mut buf), Err(e) if e.kind() != std::io::ErrorKind::WouldBlock && e.kind() != std::io::ErrorKind::TimedOut);
            dropped.store(ended, Ordering::Relaxed);
        }
    })?;
    println!(
        "with 50 streaming clients: {} scans ({:.1}/s), scan to pose {}",
        loaded.scans,
        loaded.scans as f64 / loaded.run_time,
        pose_latency(&loaded)
    );
    println!(
        "clients received {:.1} MB in all; resident memory {:.1} MiB before, peak {:.1} MiB during",
        received.load(Ordering::Relaxed) as f64 / 1e6,
        rss_before as f64 / 1024.0,
        peak.load(Ordering::Relaxed) as f64 / 1024.0
    );
    println!(
        "the client that never read: {}",
        if stalled_dropped.load(Ordering::Relaxed) {
            "dropped by the server"
        } else {
            "still connected at the end (its buffers never filled)"
        }
    );
    Ok(())
}
