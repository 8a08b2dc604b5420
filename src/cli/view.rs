//! `clsmap view MAP.json`: a saved map in the browser, through the same
//! live view the daemon serves (nothing changes it; Ctrl-C stops it).

use std::path::Path;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use anyhow::Context as _;
use clsmap::daemon::LiveStatus;
use clsmap::daemon::web::server::{WebOptions, serve};
use clsmap::daemon::web::{LiveView, MapView};
use clsmap::map::file::ChecksumCheck;

pub fn view(map: &Path, checksum: ChecksumCheck, bind: &str) -> anyhow::Result<ExitCode> {
    let address = bind.parse().with_context(|| {
        format!("--bind {bind:?}: not an address and port such as 127.0.0.1:8080")
    })?;
    let loaded = clsmap::map::file::load_with(map, checksum)
        .with_context(|| format!("cannot show the map {}", map.display()))?;
    let contents = Arc::new(loaded.contents);
    let cls = &contents.cls;
    let status = LiveStatus {
        keyframes: contents.keyframes.len(),
        graph_keyframes: contents.keyframes.len(),
        loops_closed: contents
            .edges
            .iter()
            .filter(|e| e.kind == clsmap::map::EdgeKind::Loop)
            .count(),
        walls: cls.actual_segments().count(),
        frontiers: cls.virtual_segments().count(),
        loops: cls.loops().count(),
        ..LiveStatus::default()
    };
    let live = LiveView {
        uptime: 0.0,
        sensor: format!("saved map (version {}), not live", loaded.version),
        scan_rate: 0.0,
        scans_skipped: 0,
        odometry_refused: 0,
        base_ok: false,
        command: [0.0; 3],
        status,
        covariance: [[0.0; 3]; 3],
        goal: None,
        plan: Vec::new(),
        paused: false,
        control: false,
        latencies: Vec::new(),
        map_version: 1,
    };
    // The keyframes' poses stand for the path driven.
    let path = contents.poses.clone();
    let map_view = MapView::from_contents(1, contents, path.into_iter());
    let (server, feed) = serve(WebOptions {
        address,
        token: None,
        max_clients: 8,
    })?;
    feed.map.send_replace(Some(Arc::new(map_view)));
    feed.view.send_replace(Some(Arc::new(live)));
    println!(
        "{}: http://{}/ (Ctrl-C stops)",
        map.display(),
        server.address()
    );
    let stop = super::stop_flag()?;
    while !stop.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_millis(100));
    }
    server.stop();
    Ok(ExitCode::SUCCESS)
}
