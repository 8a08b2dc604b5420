//! `clsmap demo`: the embedded default, with live progress.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context as _, bail};
use clsmap::demo::{DemoProgress, DemoStop, demo_config, run_demo};
use indicatif::{ProgressBar, ProgressStyle};

/// `out/demo`, or the first of `out/demo-2`, `out/demo-3` … without a map.
fn default_out() -> PathBuf {
    let holds_map = |p: &Path| p.join(clsmap::pipeline::MAP_FILE).exists();
    let first = PathBuf::from("out/demo");
    if !holds_map(&first) {
        return first;
    }
    (2..)
        .map(|k| PathBuf::from(format!("out/demo-{k}")))
        .find(|p| !holds_map(p))
        .unwrap_or(first)
}

pub fn demo(
    out: Option<&Path>,
    world: Option<&str>,
    seed: Option<u64>,
    web: bool,
    ros2: bool,
) -> anyhow::Result<ExitCode> {
    let out = out.map_or_else(default_out, Path::to_path_buf);
    let out = out.as_path();
    let mut config = demo_config().context("the built-in demo configuration is invalid")?;
    if let Some(w) = world {
        config.sim.world = w.to_string();
    }
    if let Some(s) = seed {
        config.sim.seed = s;
    }
    config.web.enabled = web;
    if ros2 {
        if !cfg!(feature = "dds") {
            bail!("--ros2: this clsmap was built without its ROS 2 node (cargo feature `dds`)");
        }
        config.ros2.enabled = true;
        if let Some(id) = std::env::var("ROS_DOMAIN_ID")
            .ok()
            .filter(|v| !v.is_empty())
        {
            config.ros2.domain_id = id
                .parse()
                .ok()
                .filter(|d| *d <= 232)
                .with_context(|| format!("ROS_DOMAIN_ID={id} is not a domain (0-232)"))?;
        }
    }
    if out.join(clsmap::pipeline::MAP_FILE).exists() {
        bail!(
            "{} already holds a map; choose another --out (the demo never overwrites a map)",
            out.display()
        );
    }
    println!(
        "clsmap demo: an emulated LMS200 on a pseudo-terminal (180°/0.5°, 500 kBd) on a simulated\n\
         holonomic base in the \"{}\" world; the daemon's loop localizes every scan, grows the\n\
         CLS map and explores by Virtual Line Segment Pursuit until no frontier is left.",
        config.sim.world
    );
    let bar = ProgressBar::new_spinner().with_style(
        ProgressStyle::with_template("{spinner} {elapsed_precise} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    let on_progress = |p: &DemoProgress| {
        bar.set_message(format!(
            "{:5} scans  {:3} walls  {:3} frontiers  goal {:2}  pose error {:.3} m",
            p.scans, p.walls, p.frontiers, p.goals, p.error
        ));
    };
    let on_web = |address: std::net::SocketAddr| {
        bar.suspend(|| {
            println!("live view: http://{address}/ (served until the exploration ends)");
        });
    };
    let result = run_demo(config, out, DemoStop::CtrlC, on_progress, on_web);
    bar.finish_and_clear();
    let s = result.context("the demo failed")?;
    println!(
        "{} after {:.0} s: {} goals, {:.1} m driven, {} scans mapped ({} skipped while busy)",
        if s.exploration_complete {
            "exploration complete"
        } else {
            "stopped before exploration completed (the map so far is saved)"
        },
        s.run_time_s,
        s.goals,
        s.driven_m,
        s.scans,
        s.scans_skipped
    );
    println!(
        "CLS map: {} walls + {} frontiers in {} loops; {:.1} % of the wall length within 5 cm of the world's walls",
        s.walls,
        s.frontiers,
        s.loops,
        100.0 * s.walls_on_world
    );
    println!(
        "pose error against the simulator's truth: mean {:.3} m, max {:.3} m, max heading {:.2}°",
        s.mean_error_m, s.max_error_m, s.max_heading_error_deg
    );
    if let Some(l) = s
        .latencies
        .iter()
        .find(|l| l.stage == clsmap::daemon::Stage::Pose)
    {
        println!(
            "last telegram byte to corrected pose: p50 {} µs, p99 {} µs, max {} µs",
            l.p50_us, l.p99_us, l.max_us
        );
    }
    println!(
        "wrote {}/{{map.json, map.svg, trajectory.tum, trajectory.anchors, demo.json}}",
        s.out_dir.display()
    );
    // Stopped by Ctrl-C is what the user asked for; stopped by the time
    // limit with frontiers left is a failure of the demo.
    Ok(
        if s.exploration_complete || s.reason == clsmap::daemon::StopReason::Shutdown {
            ExitCode::SUCCESS
        } else {
            ExitCode::FAILURE
        },
    )
}
