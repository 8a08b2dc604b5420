//! ROS 2 on the wire: a 361-beam LaserScan to CDR and back, and a whole
//! rosbag2 MCAP bag (LaserScan + Odometry, the size of the CSAIL log:
//! 1,988 scans) read as scans with their odometry, as `clsmap map BAG`
//! reads it. Reading must stay far below mapping's cost per scan.
//!
//! `cargo bench --bench ros2 -- --warm-up-time 1 --measurement-time 3`

use std::hint::black_box;

use clsmap::input::{BagScans, BagTopics};
use clsmap::ros2::bag::{BagWriter, Durability};
use clsmap::ros2::{Header, LaserScan, Odometry, Quaternion, RosMessage, Time};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};

const SCANS: usize = 1988;

fn scan(t: f64) -> LaserScan {
    LaserScan {
        header: Header {
            stamp: Time::from_secs(t).unwrap_or_default(),
            frame_id: "laser".into(),
        },
        angle_min: (-std::f64::consts::FRAC_PI_2) as f32,
        angle_max: std::f64::consts::FRAC_PI_2 as f32,
        angle_increment: 0.5f64.to_radians() as f32,
        range_max: 81.9,
        ranges: (0..361).map(|i| 1.0 + (i % 97) as f32 * 0.031).collect(),
        ..LaserScan::default()
    }
}

fn bench_cdr(c: &mut Criterion) {
    let msg = scan(1_134_864_629.9);
    let bytes = msg.to_cdr();
    let mut g = c.benchmark_group("cdr");
    g.throughput(Throughput::Elements(1));
    g.bench_function("laser_scan_361_encode", |b| {
        b.iter(|| black_box(&msg).to_cdr())
    });
    g.bench_function("laser_scan_361_decode", |b| {
        b.iter(|| LaserScan::from_cdr(black_box(&bytes)))
    });
    g.finish();
}

fn bench_bag(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let path = dir.path().join("csail-size.mcap");
    let mut bag = BagWriter::create(&path).expect("bag");
    let mut s = bag
        .topic::<LaserScan>("/scan", Durability::Volatile)
        .expect("topic");
    let mut o = bag
        .topic::<Odometry>("/odom", Durability::Volatile)
        .expect("topic");
    for k in 0..SCANS {
        let t = 1_134_864_629.9 + 0.2 * k as f64;
        let ns = (t * 1e9) as u64;
        let mut odom = Odometry::default();
        odom.header.stamp = Time::from_secs(t).unwrap_or_default();
        odom.pose.position.x = 0.1 * k as f64;
        odom.pose.orientation = Quaternion::from_yaw(0.001 * k as f64);
        bag.write(&mut o, ns, &odom).expect("write");
        bag.write(&mut s, ns, &scan(t)).expect("write");
    }
    bag.finish().expect("finish");
    let mut g = c.benchmark_group("bag");
    g.throughput(Throughput::Elements(SCANS as u64));
    g.sample_size(20);
    g.bench_function("read_1988_scans_with_odometry", |b| {
        b.iter(|| {
            let n = BagScans::open(&path, BagTopics::default())
                .expect("open")
                .filter(Result::is_ok)
                .count();
            assert_eq!(n, SCANS);
        })
    });
    g.finish();
}

criterion_group!(benches, bench_cdr, bench_bag);
criterion_main!(benches);
