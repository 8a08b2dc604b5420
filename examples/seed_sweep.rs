//! The daemon's exploration of built-in worlds on the virtual clock over
//! many simulator seeds: the mean pose error of each run, and per world
//! the mean, median and range over the seeds. One seed says little in
//! these worlds (the explorer's path changes with the noise); the
//! README's daemon figures over seeds come from here.
//!
//!     cargo run --release --example seed_sweep -- [--seeds N] [--worlds corridor,office,loop]
//!         [--exact-odometry] [--range-sigma METRES] [--seconds S] [--turned]
//!
//! `--exact-odometry` takes out the simulated base's scale error and
//! heading drift; `--range-sigma` replaces the emulated sensor's range
//! noise (1 cm in the demo configuration). `--turned` also gives each
//! world's mean error with the map's turn about the start taken out: the
//! one rotation about the map's origin that brings a run's estimated
//! positions (each scan's, as mapped) nearest the true ones.

use clsmap::daemon::simulation::VirtualRobot;
use clsmap::demo::demo_config;

const USAGE: &str = "usage: seed_sweep [--seeds N] [--worlds a,b,...] [--exact-odometry] \
                     [--range-sigma METRES] [--seconds S] [--turned]";

struct Options {
    seeds: u64,
    worlds: Vec<String>,
    exact_odometry: bool,
    range_sigma: Option<f64>,
    seconds: f64,
    turned: bool,
}

fn options() -> Result<Options, Box<dyn std::error::Error>> {
    let mut o = Options {
        seeds: 40,
        worlds: ["corridor", "office", "loop"].map(String::from).to_vec(),
        exact_odometry: false,
        range_sigma: None,
        seconds: 240.0,
        turned: false,
    };
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        let mut value = || args.next().ok_or(format!("{arg} wants a value; {USAGE}"));
        match arg.as_str() {
            "--seeds" => o.seeds = value()?.parse()?,
            "--worlds" => o.worlds = value()?.split(',').map(String::from).collect(),
            "--exact-odometry" => o.exact_odometry = true,
            "--range-sigma" => o.range_sigma = Some(value()?.parse()?),
            "--seconds" => o.seconds = value()?.parse()?,
            "--turned" => o.turned = true,
            _ => return Err(format!("unknown argument {arg}; {USAGE}").into()),
        }
    }
    if o.seeds == 0 {
        return Err(format!("--seeds must be at least 1; {USAGE}").into());
    }
    Ok(o)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let o = options()?;
    for world in &o.worlds {
        let mut errors = Vec::with_capacity(o.seeds as usize);
        let mut turned_out = Vec::with_capacity(o.seeds as usize);
        for seed in 1..=o.seeds {
            let mut config = demo_config()?;
            config.sim.world.clone_from(world);
            config.sim.seed = seed;
            if o.exact_odometry {
                config.sim.odometry_scale_error = 0.0;
                config.sim.odometry_heading_drift = 0.0;
            }
            if let Some(sigma) = o.range_sigma {
                config.sim.range_sigma = sigma;
            }
            let mut robot = VirtualRobot::new(&config)?;
            // Each scan's estimate beside the truth (map frame), for --turned.
            let mut pairs: Vec<([f64; 2], [f64; 2])> = Vec::new();
            let mut last = f64::NEG_INFINITY;
            let done = robot.run_until(o.seconds, |r| {
                if let (true, Some(origin), Some((t, p))) = (
                    o.turned,
                    r.map_origin(),
                    r.live().mapper().trajectory().last(),
                ) && *t > last
                {
                    last = *t;
                    let truth = origin.between(&r.robot().true_pose_at(*t));
                    pairs.push(([truth.x, truth.y], [p.x, p.y]));
                }
                r.live().exploration_complete()
            });
            if !done {
                eprintln!(
                    "{world}, seed {seed}: exploration not complete in {} s",
                    o.seconds
                );
            }
            errors.push(1e3 * robot.stats().mean_error);
            turned_out.push(1e3 * error_turned_out(&pairs));
        }
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        let mut sorted = errors.clone();
        sorted.sort_by(f64::total_cmp);
        let per_seed: Vec<String> = errors.iter().map(|e| format!("{e:.1}")).collect();
        println!(
            "{world}: mean {mean:.1} mm, median {:.1} mm, {:.1}–{:.1} mm over seeds 1–{}: {}",
            sorted[sorted.len() / 2],
            sorted[0],
            sorted[sorted.len() - 1],
            o.seeds,
            per_seed.join(" ")
        );
        if o.turned {
            let mean = turned_out.iter().sum::<f64>() / turned_out.len() as f64;
            println!("{world}: with the map's turn about the start taken out, mean {mean:.1} mm");
        }
    }
    Ok(())
}

/// Mean distance (m) from true to estimated positions once the estimates
/// are turned by the rotation about the origin that fits them best (least
/// squares: the angle of Σ est × truth against Σ est · truth).
fn error_turned_out(pairs: &[([f64; 2], [f64; 2])]) -> f64 {
    if pairs.is_empty() {
        return 0.0;
    }
    let (dot, cross) = pairs.iter().fold((0.0, 0.0), |(d, c), (t, e)| {
        (d + t[0] * e[0] + t[1] * e[1], c + e[0] * t[1] - e[1] * t[0])
    });
    let (s, c) = cross.atan2(dot).sin_cos();
    let sum: f64 = pairs
        .iter()
        .map(|(t, e)| (c * e[0] - s * e[1] - t[0]).hypot(s * e[0] + c * e[1] - t[1]))
        .sum();
    sum / pairs.len() as f64
}
