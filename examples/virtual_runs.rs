//! Every built-in world explored by the daemon's loop on the virtual clock
//! (deterministic: same build, same bytes), each run's map, picture,
//! trajectory and figures written under one directory. A refactor that
//! must keep the behaviour byte for byte is checked by hashing this
//! directory before and after it (`scripts/fingerprint.sh` does, with the
//! CSAIL log and the fixture mapped offline as well).
//!
//!     cargo run --release --example virtual_runs -- OUT_DIR [SECONDS]

use clsmap::daemon::simulation::VirtualRobot;
use clsmap::demo::demo_config;
use clsmap::sim::world_file::WorldFile;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let out = std::path::PathBuf::from(args.next().ok_or("usage: virtual_runs OUT_DIR [SECONDS]")?);
    let limit: f64 = args.next().map_or(Ok(240.0), |s| s.parse())?;
    for world in WorldFile::BUILTIN_NAMES {
        let mut config = demo_config()?;
        config.sim.world = (*world).to_string();
        let mut robot = VirtualRobot::new(&config)?;
        robot.run_until(limit, |r| r.live().exploration_complete());
        let dir = out.join(world);
        std::fs::create_dir_all(&dir)?;
        robot.checkpoint(&dir)?;
        std::fs::write(
            dir.join("figures.txt"),
            format!("{:?}\n{:?}\n", robot.stats(), robot.live().status()),
        )?;
        println!(
            "{world}: {:.1} s, {} scans, mean error {:.1} mm",
            robot.now(),
            robot.stats().scans,
            robot.stats().mean_error * 1e3
        );
    }
    Ok(())
}
