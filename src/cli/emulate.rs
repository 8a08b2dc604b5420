//! `clsmap emulate`: an emulated LMS200 on a pseudo-terminal, for any
//! host's serial code (this one's, another driver's) to talk to.

use std::io::Write;
use std::path::Path;
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail};
use lms200::Baud;
use lms200::emulator::{Emulator, EmulatorConfig, FaultConfig};
use lms200::pty::PtyEmulator;

/// Byte-level faults for `emulate`.
#[derive(Debug, Clone, Copy)]
pub struct LineFaults {
    pub bit_flips: f64,
    pub garbage: f64,
    pub drops: f64,
    pub seed: u64,
}

pub fn emulate(
    link: Option<&Path>,
    start_baud: Option<u32>,
    power_on: Option<f64>,
    faults: LineFaults,
) -> anyhow::Result<ExitCode> {
    for (name, p) in [
        ("--bit-flips", faults.bit_flips),
        ("--garbage", faults.garbage),
        ("--drops", faults.drops),
    ] {
        if !(0.0..=1.0).contains(&p) {
            bail!("{name} {p}: a probability per byte lies in [0, 1]");
        }
    }
    let mut config = EmulatorConfig {
        seed: faults.seed,
        faults: FaultConfig {
            bit_flip_per_byte: faults.bit_flips,
            garbage_per_byte: faults.garbage,
            drop_per_byte: faults.drops,
            nak_every_nth_request: None,
        },
        // A sensor that has been on for a while, unless a power-up is
        // asked for: a host that opens the port long after the emulator
        // started must not find it deaf.
        power_on_delay: power_on_delay(power_on)?,
        ..EmulatorConfig::default()
    };
    if let Some(bps) = start_baud {
        config.start_baud = Baud::from_bits_per_second(bps).with_context(|| {
            format!("{bps} Bd: the LMS200 runs at 9600, 19200, 38400 or 500000")
        })?;
    }
    let stop = super::stop_flag()?;
    if let Some(delay) = config.power_on_delay {
        println!(
            "powering up: deaf for {:.1} s, then the 90 power-on telegram",
            delay.as_secs_f64()
        );
    }
    let pty = PtyEmulator::spawn(Emulator::new(config, Instant::now()), link)
        .context("cannot start the emulator")?;
    match link {
        Some(l) => println!(
            "LMS200 emulator on {} (link {})",
            pty.tty_path().display(),
            l.display()
        ),
        None => println!("LMS200 emulator on {}", pty.tty_path().display()),
    }
    println!(
        "try: clsmap probe --port {}",
        link.unwrap_or(pty.tty_path()).display()
    );
    std::io::stdout().flush()?;
    while !stop.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_millis(50));
    }
    let stats = pty.stats();
    pty.stop().context("emulator failed")?;
    eprintln!("emulator stopped: {stats:?}");
    Ok(ExitCode::SUCCESS)
}

/// The boot time `--power-on` asks for (real units take up to 60 s).
fn power_on_delay(seconds: Option<f64>) -> anyhow::Result<Option<Duration>> {
    match seconds {
        None => Ok(None),
        Some(s) if s.is_finite() && (0.0..=120.0).contains(&s) => {
            Ok(Some(Duration::from_secs_f64(s)))
        }
        Some(s) => bail!("--power-on {s}: seconds of boot time lie in [0, 120]"),
    }
}
