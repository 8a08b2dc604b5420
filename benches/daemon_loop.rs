//! The daemon's whole loop on a virtual clock: the emulated LMS200 (ray
//! casting 361 beams), the serial link state machine decoding every
//! telegram, the simulated base, localization of every scan, CLS map
//! updates on keyframes and Virtual Line Segment Pursuit, for the first
//! 20 s of exploring the demo's lab (750 scans at 37.5 scans/s).
//!
//! `cargo bench --bench daemon_loop -- --warm-up-time 1 --measurement-time 10`
//!
//! Divide by 750 for the cost per scan of everything a simulated robot
//! does; the daemon's own share on real hardware is the last-byte-to-pose
//! latency its histograms log.

use std::hint::black_box;

use clsmap::daemon::simulation::VirtualRobot;
use clsmap::demo::demo_config;
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

fn bench_daemon_loop(c: &mut Criterion) {
    let config = demo_config().expect("the built-in demo configuration is valid");
    let mut group = c.benchmark_group("daemon_loop");
    group.sample_size(10);
    group.throughput(Throughput::Elements(750));
    group.bench_function("lab_first_20_s_virtual", |b| {
        b.iter(|| {
            let mut robot = VirtualRobot::new(&config).expect("the demo world loads");
            robot.run_until(20.0, |_| false);
            black_box(robot.stats().scans)
        })
    });
    group.finish();
}

criterion_group!(benches, bench_daemon_loop);
criterion_main!(benches);
