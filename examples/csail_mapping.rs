//! Maps the MIT CSAIL CARMEN log and scores the result with the Kümmerle
//! et al. relations, beside the logged odometry's score.
//!
//! ```text
//! cargo run --release --example csail_mapping -- [CONFIG.toml] [--log LOG.clf] [--scans N] [--out DIR] [--trace]
//! cargo run --release --example csail_mapping -- config/csail.toml
//! ```
//! The log and relations are read from `../shared/datasets/mit-csail/`
//! relative to the crate (`--log` takes another recording of the same run,
//! such as a thinned copy from `scripts/sparse_carmen.py`). `--trace` prints one line per scan: whether it
//! was localized, degenerate, a keyframe, and its estimated step beside the
//! odometry step (the basis of the odometry latency estimate in
//! `config/csail.toml`).

use clsmap::eval::{RelationErrors, evaluate, read_relations};
use clsmap::input::{ScanRecord, open_log};
use clsmap::pipeline::Mapper;
use clsmap::pipeline::config::MapperConfig;
use std::error::Error;
use std::path::PathBuf;

fn row(name: &str, e: &RelationErrors) {
    println!(
        "{name:<22} {:>6} {:>4}  {:>7.3} ± {:<7.3} m  {:>6.2} ± {:<6.2} deg   max {:.2} m",
        e.used,
        e.missing,
        e.translation_m.mean,
        e.translation_m.std_dev,
        e.rotation_deg.mean,
        e.rotation_deg.std_dev,
        e.translation_m.max
    );
}

fn main() -> Result<(), Box<dyn Error>> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/datasets/mit-csail");
    let mut config = MapperConfig::default();
    let mut limit = usize::MAX;
    let mut out: Option<PathBuf> = None;
    let mut trace = false;
    let mut log = dir.join("mit-csail.clf");
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--scans" => limit = args.next().ok_or("--scans needs a number")?.parse()?,
            "--trace" => trace = true,
            "--log" => log = args.next().ok_or("--log needs a file")?.into(),
            "--out" => out = Some(args.next().ok_or("--out needs a directory")?.into()),
            path => config = MapperConfig::from_toml(&std::fs::read_to_string(path)?)?,
        }
    }
    let records: Vec<ScanRecord> = open_log(&log)?.take(limit).collect::<Result<_, _>>()?;
    let relations = read_relations(std::io::BufReader::new(std::fs::File::open(
        dir.join("mit-csail.relations"),
    )?))?;
    let t_last = records.last().map_or(f64::NEG_INFINITY, |r| r.scan.t);
    let relations: Vec<_> = relations
        .into_iter()
        .filter(|r| r.t1.max(r.t2) <= t_last + 1e-3)
        .collect();

    let odometry: Vec<_> = records
        .iter()
        .filter_map(|r| Some((r.scan.t, r.odometry?)))
        .collect();
    let mut mapper = Mapper::new(config);
    // As `clsmap map` runs it: the CLS map built once, at the end.
    mapper.defer_cls_rebuild();
    mapper.measure_scan_steps();
    let t0 = records.first().map_or(0.0, |r| r.scan.t);
    let mut prev: Option<(clsmap::geometry::Pose2, clsmap::geometry::Pose2)> = None;
    for r in &records {
        let o = mapper.process(r);
        if trace {
            // Per-scan step of the estimate against the odometry step.
            let (de, dodo) = match (prev, r.odometry) {
                (Some((pe, po)), Some(odo)) => (pe.between(&o.pose), po.between(&odo)),
                _ => Default::default(),
            };
            println!(
                "t {:7.2} loc {} deg {} kf {} lines {:2} match {:2} step ({:+.3} {:+.3} {:+.2}°) odo ({:+.3} {:+.3} {:+.2}°) {}",
                r.scan.t - t0,
                o.localized as u8,
                o.degenerate as u8,
                o.keyframe as u8,
                o.lines,
                o.matches,
                de.x,
                de.y,
                de.theta.to_degrees(),
                dodo.x,
                dodo.y,
                dodo.theta.to_degrees(),
                o.rejection.map_or("", |k| k.name())
            );
        }
        if let Some(odo) = r.odometry {
            prev = Some((o.pose, odo));
        }
    }
    mapper.settle();
    let summary = mapper.summary();
    println!(
        "{} scans, {} relations in span",
        records.len(),
        relations.len()
    );
    println!(
        "{:<22} {:>6} {:>4}  {:<21} {:<18}",
        "", "used", "miss", "translation", "rotation"
    );
    // As `clsmap map` writes it.
    let trajectory = mapper.smoothed_trajectory();
    row("odometry", &evaluate(&odometry, &relations));
    row("line map (this)", &evaluate(&trajectory, &relations));
    let short: Vec<_> = relations
        .iter()
        .copied()
        .filter(|r| (r.t2 - r.t1).abs() < 5.0)
        .collect();
    row("  relations < 5 s", &evaluate(&trajectory, &short));
    let long: Vec<_> = relations
        .iter()
        .copied()
        .filter(|r| (r.t2 - r.t1).abs() >= 5.0)
        .collect();
    row("  relations >= 5 s", &evaluate(&trajectory, &long));
    println!("{summary:#?}");
    if let Some(out) = out {
        clsmap::pipeline::write_outputs(&out, &mapper, false)?;
    }
    Ok(())
}
