//! `clsmap demo`: the embedded default, with live progress.

use std::path::Path;
use std::process::ExitCode;

use anyhow::{Context as _, bail};
use clsmap::demo::{DemoOptions, DemoProgress, Scenario, run_demo};
use indicatif::{ProgressBar, ProgressStyle};

pub fn demo(out: &Path, seed: u64, speed: f64) -> anyhow::Result<ExitCode> {
    if !(speed.is_finite() && speed > 0.0 && speed <= 3.0) {
        bail!("--speed {speed}: the simulated base drives at more than 0 and at most 3 m/s");
    }
    let scenario = Scenario::loop_around_block(speed);
    let options = DemoOptions {
        seed,
        ..DemoOptions::new(out)
    };
    println!(
        "clsmap demo: an emulated LMS200 on a pseudo-terminal, streaming 180°/0.5° at 500 kBd,\n\
         on a holonomic base driving {:.0} s through \"{}\"; mapping live.",
        scenario.tour.duration(),
        scenario.name
    );
    let bar = ProgressBar::new(1000).with_style(
        ProgressStyle::with_template("{spinner} [{bar:30}] {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let on_progress = |p: &DemoProgress| {
        if p.tour_duration > 0.0 {
            bar.set_position((1000.0 * (p.t / p.tour_duration).clamp(0.0, 1.0)) as u64);
        }
        bar.set_message(format!(
            "{:5.1} s  {:4} scans  {:3} segments  pose error {:.3} m (odometry alone {:.3} m)",
            p.t, p.scans, p.segments, p.error, p.odometry_error
        ));
    };
    let result = run_demo(&scenario, &options, on_progress);
    bar.finish_and_clear();
    let s = result.context("the demo failed")?;
    println!(
        "mapped {} scans at {} Bd ({} telegrams dropped on the line)",
        s.scans,
        s.connected_baud
            .map_or_else(|| "?".into(), |b| b.to_string()),
        s.dropped_frames
    );
    println!(
        "CLS map: {} actual + {} virtual segments in {} loops",
        s.cls_actual, s.cls_virtual, s.cls_loops
    );
    println!(
        "pose error against the simulator's truth: mean {:.3} m, max {:.3} m, max heading {:.2}°; \
         final {:.3} m (odometry alone: {:.3} m)",
        s.mean_error_m,
        s.max_error_m,
        s.max_heading_error_deg,
        s.final_error_m,
        s.odometry_final_error_m
    );
    println!(
        "wrote {}/{{map.json, map.svg, segments.json, trajectory.tum, demo.json}}",
        s.out_dir.display()
    );
    Ok(ExitCode::SUCCESS)
}
