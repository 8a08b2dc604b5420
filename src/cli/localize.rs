//! `clsmap localize`: global localization of every scan of a log against a
//! CLS map, one JSON line per scan.

use std::io::Write as _;
use std::path::Path;
use std::process::ExitCode;

use anyhow::Context as _;
use clsmap::geometry::{Pose2, extract_lines};
use clsmap::input::{LogOptions, open_log};
use clsmap::localize::global::{
    GlobalConfig, GlobalError, GlobalMap, GlobalResult, disambiguate, global_localize,
};

/// One output line: `{"t", "hypotheses": [{x, y, theta, score}], "ambiguous"}`,
/// or `"error"` when the scan could not be localized.
fn json_line(t: f64, result: &Result<GlobalResult, GlobalError>) -> serde_json::Value {
    match result {
        Ok(r) => serde_json::json!({
            "t": t,
            "hypotheses": r.hypotheses.iter().map(|h| serde_json::json!({
                "x": h.pose.x,
                "y": h.pose.y,
                "theta": h.pose.theta,
                "score": h.score,
            })).collect::<Vec<_>>(),
            "ambiguous": r.ambiguous,
        }),
        Err(e) => serde_json::json!({
            "t": t,
            "hypotheses": [],
            "ambiguous": false,
            "error": e.to_string(),
        }),
    }
}

/// Localizes each scan of `input` against the actual segments of `map`.
/// With `track`, the hypotheses of one scan are carried to the next by the
/// log's odometry and kept only where the next scan agrees
/// (disambiguation); without it, every scan is localized on its own and
/// odometry is ignored.
pub fn localize(
    map: &Path,
    checksum: clsmap::map::file::ChecksumCheck,
    input: &Path,
    config: Option<&Path>,
    track: bool,
    max_hypotheses: usize,
) -> anyhow::Result<ExitCode> {
    let mapper = super::mapping::mapper_config(config, input, &LogOptions::default())?;
    let loaded = clsmap::map::file::load_with(map, checksum)
        .with_context(|| format!("cannot load the map {}", map.display()))?;
    // The walls local localization matched against when the map was made
    // (version 2); a version-1 file has only the CLS map's actual segments.
    let contents = loaded.contents;
    // With the free space the map explored, which `--track` judges places by.
    let global_map = if contents.walls.is_empty() {
        GlobalMap::new(contents.cls.actual_segments().map(|s| s.line))
    } else {
        GlobalMap::new(contents.walls.iter().map(|w| w.line))
    }
    .with_free_space(&contents.cls);
    anyhow::ensure!(
        !global_map.is_empty(),
        "the map {} has no walls (actual segments) to localize against",
        map.display()
    );
    let cfg = GlobalConfig {
        max_hypotheses: max_hypotheses.max(1),
        ..GlobalConfig::default()
    };
    let log = open_log(input).with_context(|| format!("cannot open {}", input.display()))?;

    let stdout = std::io::stdout();
    let mut out = std::io::BufWriter::new(stdout.lock());
    // The last result and the odometry at its scan, for tracking.
    let mut last: Option<(GlobalResult, Option<Pose2>)> = None;
    let mut warned_no_odometry = false;
    for record in log {
        let record = record.with_context(|| format!("cannot read {}", input.display()))?;
        if track && record.odometry.is_none() && !warned_no_odometry {
            warned_no_odometry = true;
            tracing::warn!(
                "--track: {} has scans without odometry; those are localized on their own",
                input.display()
            );
        }
        let lines = extract_lines(&record.scan, &mapper.laser_mount, &mapper.extraction);
        let result = match (&last, record.odometry) {
            (Some((previous, Some(before))), Some(now)) if track => {
                disambiguate(previous, &lines, before.between(&now), &global_map, &cfg)
            }
            _ => global_localize(&lines, &global_map, &cfg),
        };
        writeln!(out, "{}", json_line(record.scan.t, &result))
            .context("cannot write the output")?;
        last = match result {
            Ok(r) if track && !r.hypotheses.is_empty() => Some((r, record.odometry)),
            _ => None,
        };
    }
    out.flush().context("cannot write the output")?;
    Ok(ExitCode::SUCCESS)
}
