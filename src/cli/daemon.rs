//! `clsmap run`: the robot daemon, with SIGTERM/SIGINT (stop and save)
//! and SIGHUP (reload the tunables) wired to the loop.

use std::path::Path;
use std::process::ExitCode;

use anyhow::Context as _;
use clsmap::daemon::{DaemonConfig, Hooks, RunSummary, StopReason, run};
use tokio::signal::unix::{SignalKind, signal};
use tokio::sync::mpsc;
use tracing::info;

/// Exit status when the map had to be saved to a rescue directory.
pub const RESCUED: u8 = 3;

/// A current-thread tokio runtime for the daemon's loop.
pub fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("cannot start the async runtime")
}

/// Runs the daemon on `config` until SIGTERM or SIGINT.
pub fn run_daemon(
    config_path: &Path,
    map: Option<std::path::PathBuf>,
    mode: Option<String>,
    ignore_checksum: bool,
) -> anyhow::Result<ExitCode> {
    let mut config = DaemonConfig::load(config_path)
        .with_context(|| format!("invalid configuration {}", config_path.display()))?;
    if let Some(map) = map {
        config.map.load = Some(map);
    }
    config.map.ignore_checksum |= ignore_checksum;
    if let Some(mode) = mode {
        mode.parse::<clsmap::pipeline::MapMode>()
            .map_err(|e| anyhow::anyhow!("--mode: {e}"))?;
        config.map.mode = mode;
    }
    let summary = runtime()?.block_on(async {
        let hooks = signal_hooks(Some(config_path))?;
        run(config, hooks).await.context("the daemon failed")
    })?;
    report(&summary);
    if let Some(why) = &summary.rescued_because {
        eprintln!(
            "error: the map could not be saved where it belongs ({why}); it was rescued to {}",
            summary
                .out_dir
                .as_deref()
                .map_or_else(|| "?".into(), |d| d.display().to_string())
        );
        // Distinct, so systemd does not restart into the same broken place
        // (RestartPreventExitStatus=3 in systemd/clsmap.service).
        return Ok(ExitCode::from(RESCUED));
    }
    if summary.reason == StopReason::SensorThreadEnded {
        anyhow::bail!("the sensor thread ended unexpectedly (the map was saved)");
    }
    Ok(ExitCode::SUCCESS)
}

/// Hooks with SIGTERM/SIGINT as the shutdown and SIGHUP as reload; must be
/// called inside the runtime.
pub fn signal_hooks(config_path: Option<&Path>) -> anyhow::Result<Hooks<'static>> {
    let mut term = signal(SignalKind::terminate()).context("cannot handle SIGTERM")?;
    let mut int = signal(SignalKind::interrupt()).context("cannot handle SIGINT")?;
    let mut hup = signal(SignalKind::hangup()).context("cannot handle SIGHUP")?;
    let (reload_tx, reload_rx) = mpsc::unbounded_channel();
    tokio::spawn(async move {
        while hup.recv().await.is_some() {
            info!("SIGHUP: reloading the configuration");
            if reload_tx.send(()).is_err() {
                break;
            }
        }
    });
    let shutdown = async move {
        tokio::select! {
            _ = term.recv() => info!("SIGTERM: stopping"),
            _ = int.recv() => info!("SIGINT: stopping"),
        }
    };
    let mut hooks = Hooks::until(shutdown);
    hooks.reload = Some(reload_rx);
    hooks.config_path = config_path.map(Path::to_path_buf);
    Ok(hooks)
}

fn report(s: &RunSummary) {
    println!(
        "stopped ({:?}) after {:.1} s: {} scans mapped ({} skipped while busy), \
         map {} walls, {} frontiers, {} loops; {}",
        s.reason,
        s.run_time,
        s.scans,
        s.scans_skipped,
        s.status.walls,
        s.status.frontiers,
        s.status.loops,
        s.out_dir.as_deref().map_or_else(
            || "nothing mapped, nothing saved".to_string(),
            |d| format!("saved in {}", d.display())
        )
    );
    for l in &s.latencies {
        println!(
            "  {:<18} p50 {:>6} µs  p99 {:>6} µs  max {:>7} µs  ({} samples)",
            l.stage.name(),
            l.p50_us,
            l.p99_us,
            l.max_us,
            l.count
        );
    }
}
