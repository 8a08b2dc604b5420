//! Mapping subcommands: `map` (offline mapping of a log) and `eval`.

use std::path::Path;
use std::process::ExitCode;

use anyhow::Context as _;
use clsmap::eval::{LOCAL_SPAN, RelationErrors};
use clsmap::files::trajectory::read_tum;
use clsmap::input::{DeclaredMount, LogOptions};
use clsmap::map::cls::{self, GridConfig};
use clsmap::pipeline::config::MapperConfig;
use clsmap::pipeline::{self, Progress};
use indicatif::{ProgressBar, ProgressStyle};
use tracing::warn;

/// Exit status of `map` when some input was skipped or the input broke
/// off: the map was written, from less than was asked for.
pub const PARTIAL_INPUT: u8 = 4;

pub fn map(
    input: &Path,
    out: &Path,
    config: Option<&Path>,
    relations: Option<&Path>,
    run: &pipeline::MapRunOptions<'_>,
) -> anyhow::Result<ExitCode> {
    let config = mapper_config(config, input, run.log.unwrap_or(&LogOptions::default()))?;
    if let Some((map, _)) = run.start_from {
        let written = out.join(pipeline::MAP_FILE);
        if let (Ok(a), Ok(b)) = (map.canonicalize(), written.canonicalize())
            && a == b
        {
            anyhow::bail!(
                "--out {} would overwrite the map it starts from ({}); choose another directory",
                out.display(),
                map.display()
            );
        }
    }
    let bar = ProgressBar::new(0).with_style(
        ProgressStyle::with_template(
            "{spinner} mapping [{bar:40}] {percent:>3}% {msg} ({elapsed} elapsed, {eta} left)",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    let mut on_progress = |p: Progress| {
        if bar.length() != Some(p.bytes_total) {
            bar.set_length(p.bytes_total);
        }
        bar.set_position(p.bytes_read);
        if p.scans.is_multiple_of(64) {
            bar.set_message(format!("{} scans", p.scans));
        }
    };
    let result = pipeline::run_offline_mapping(input, out, &config, run, &mut on_progress);
    bar.finish_and_clear();
    let summary = result.with_context(|| format!("cannot map {}", input.display()))?;
    let t = &summary.mean_time;
    println!(
        "mapped {} scans ({} keyframes) from {}",
        summary.scans,
        summary.keyframes,
        input.display()
    );
    println!("  segments in the map:        {}", summary.segments);
    println!(
        "  CLS map:                    {} actual + {} virtual segments in {} loops ({} updates refused)",
        summary.cls_actual, summary.cls_virtual, summary.cls_loops, summary.cls_rejected
    );
    println!(
        "  degenerate scans:           {} (a direction left to odometry)",
        summary.degenerate_scans
    );
    println!(
        "  localizations rejected:     {} {:?}; {} kept out of the map (lines that fit nowhere right after a fix)",
        summary.rejected_localizations, summary.rejections_by_kind, summary.held_back
    );
    println!(
        "  odometry heading:           σ ×{:.2} of the model (learnt); {} scans localized from a searched heading",
        summary.odometry_heading_scale, summary.heading_searches
    );
    if config.odometry_check_sigmas > 0.0 {
        println!(
            "  odometry steps overruled:   {} (the scans' own step contradicted them)",
            summary.odometry_steps_overruled
        );
    }
    if config.odometry.max_scale_correction > 0.0 {
        println!(
            "  odometry distances:         ×{:.4} (learnt from the localized scans)",
            summary.odometry_scale
        );
    }
    if config.odometry.max_heading_drift > 0.0 {
        println!(
            "  odometry heading drift:     {:+.4} rad/m added (learnt from the localized scans)",
            summary.odometry_heading_drift
        );
    }
    let learnt = if config.max_scan_lag > 0.0 {
        "learnt from the localized scans"
    } else {
        "as configured"
    };
    println!(
        "  odometry time offset:       {:+.2} s ({learnt})",
        summary.odometry_time_offset
    );
    println!(
        "  mean time per scan:         {:.1} µs (extraction {:.1}, localization {:.1}, scan matching {:.1}; per keyframe: segment map {:.1}, CLS map {:.1})",
        t.per_scan_us,
        t.extract_us,
        t.localize_us,
        t.scan_match_us,
        t.map_update_us,
        t.cls_update_us
    );
    let l = &summary.loops;
    println!(
        "  loop closure:               {} loops closed ({} by voting) in {} searches, rejected {:?}; {} revisits merged; {} optimisations ({} loops down-weighted); search {:.0} ms, optimisation {:.0} ms, rebuilds {:.0} ms",
        l.accepted,
        l.by_voting,
        l.searched,
        l.rejected,
        l.revisits_merged,
        l.optimisations,
        l.down_weighted,
        l.search_s * 1e3,
        l.optimise_s * 1e3,
        l.rebuild_s * 1e3
    );
    if let Some(broken) = &summary.input_broken {
        println!("  input broke off:            {broken} (the scans before it were mapped)");
    }
    if summary.skipped_input > 0 {
        println!(
            "  input skipped:              {} items (first: {})",
            summary.skipped_input,
            summary.skipped_examples.join("; ")
        );
    }
    if summary.scans_before_start > 0 {
        println!(
            "  before found in the map:    {} scans (no pose)",
            summary.scans_before_start
        );
    }
    if summary.scans_with_bad_odometry > 0 {
        println!(
            "  odometry not finite:        {} scans (mapped without it)",
            summary.scans_with_bad_odometry
        );
    }
    println!("  wrote {}", out.display());
    if let Some(relations) = relations {
        let trajectory_file = out.join(pipeline::TRAJECTORY_FILE);
        print_errors(&score(&trajectory_file, relations)?);
        if summary.logged_odometry > 0 {
            // The same relations scored on the log's own odometry: what
            // the map is worth over dead reckoning.
            let odometry = score(&out.join(pipeline::ODOMETRY_FILE), relations)?;
            println!(
                "  the log's odometry alone: {:.3} ± {:.3} m, {:.3} ± {:.3} deg ({} relations)",
                odometry.translation_m.mean,
                odometry.translation_m.std_dev,
                odometry.rotation_deg.mean,
                odometry.rotation_deg.std_dev,
                odometry.used
            );
        }
    }
    let partial = summary.input_broken.is_some()
        || summary.skipped_input > 0
        || summary.scans_with_bad_odometry > 0;
    if partial {
        eprintln!(
            "clsmap: {} was not used whole (see above); the map was written from the rest (exit status {PARTIAL_INPUT})",
            input.display()
        );
        return Ok(ExitCode::from(PARTIAL_INPUT));
    }
    Ok(ExitCode::SUCCESS)
}

pub fn eval(trajectory: &Path, relations: &Path) -> anyhow::Result<ExitCode> {
    print_errors(&score(trajectory, relations)?);
    Ok(ExitCode::SUCCESS)
}

fn score(trajectory: &Path, relations: &Path) -> anyhow::Result<RelationErrors> {
    let file = std::fs::File::open(trajectory)
        .with_context(|| format!("cannot open the trajectory {}", trajectory.display()))?;
    let poses = read_tum(std::io::BufReader::new(file))
        .with_context(|| format!("cannot read the trajectory {}", trajectory.display()))?;
    pipeline::evaluate_relations(&poses, relations)
        .with_context(|| format!("cannot score against {}", relations.display()))
}

fn print_errors(e: &RelationErrors) {
    println!(
        "relations used: {} (missing {})\n  translation: {:.3} ± {:.3} m (max {:.3})\n  rotation:    {:.3} ± {:.3} deg (max {:.3})",
        e.used,
        e.missing,
        e.translation_m.mean,
        e.translation_m.std_dev,
        e.translation_m.max,
        e.rotation_deg.mean,
        e.rotation_deg.std_dev,
        e.rotation_deg.max
    );
    // Local accuracy and global consistency fail differently: the split
    // says which one a score is made of.
    println!(
        "  by span:     {:.3} m over the {} relations up to {} s apart, {:.3} m over the {} longer",
        e.local_translation_m.mean,
        e.local_used,
        LOCAL_SPAN,
        e.global_translation_m.mean,
        e.used - e.local_used
    );
}

pub fn render(
    map: &Path,
    checksum: clsmap::map::file::ChecksumCheck,
    output: &Path,
    resolution: f64,
) -> anyhow::Result<ExitCode> {
    let same_file = |a: &Path, b: &Path| match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    let yaml = output.with_extension("yaml");
    if same_file(map, output) || same_file(map, &yaml) {
        anyhow::bail!(
            "{} would overwrite the map it is drawn from; choose another output",
            output.display()
        );
    }
    let loaded = clsmap::map::file::load_with(map, checksum)
        .map(|m| m.contents.cls)
        .with_context(|| format!("cannot load the map {}", map.display()))?;
    let is_pgm = output
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("pgm"));
    if is_pgm {
        let grid = cls::occupancy_grid(
            &loaded,
            &GridConfig {
                resolution,
                ..GridConfig::default()
            },
        )
        .context("cannot rasterise the map")?;
        let dir = match output.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        let stem = output
            .file_stem()
            .and_then(|s| s.to_str())
            .context("the output needs a UTF-8 file name")?;
        grid.write(dir, stem)
            .with_context(|| format!("cannot write {}", output.display()))?;
        println!(
            "wrote {} and {}.yaml ({} x {} cells of {resolution} m)",
            output.display(),
            dir.join(stem).display(),
            grid.width,
            grid.height
        );
    } else {
        let svg = clsmap::render::picture(&loaded, None, None).to_svg();
        clsmap::files::durable::write_atomically(output, svg.as_bytes())
            .with_context(|| format!("cannot write {}", output.display()))?;
        println!("wrote {}", output.display());
    }
    Ok(ExitCode::SUCCESS)
}

/// The mapper configuration from `path` (TOML), or the defaults; where it
/// leaves `laser_mount` out, the laser's mounting as the log `input`
/// (read with `log`) declares it (see [`pipeline::take_declared_mount`]),
/// where it leaves `extraction.max_range` out, the ranges end under
/// the log's own code for no return ([`pipeline::take_no_return_code`]),
/// and where it leaves the range noise and the line split and merge
/// thresholds out, they widen to the noise the log shows
/// ([`pipeline::take_wall_scatter`]).
pub fn mapper_config(
    path: Option<&Path>,
    input: &Path,
    log: &LogOptions,
) -> anyhow::Result<MapperConfig> {
    let (mut config, sets_mount, sets_max_range, sets_noise) = match path {
        None => (MapperConfig::default(), false, false, false),
        Some(path) => {
            let text = clsmap::files::durable::read_bounded(
                path,
                clsmap::files::durable::MAX_CONFIG_BYTES,
            )
            .with_context(|| format!("cannot read the configuration {}", path.display()))?;
            let config = MapperConfig::from_toml(&text)
                .with_context(|| format!("invalid configuration {}", path.display()))?;
            let table = text.parse::<toml::Table>().unwrap_or_default();
            let sets_mount = table.contains_key("laser_mount");
            let extraction = table.get("extraction").and_then(toml::Value::as_table);
            let sets = |key: &str| extraction.is_some_and(|e| e.contains_key(key));
            let sets_max_range = sets("max_range");
            let sets_noise =
                sets("range_noise") || sets("split_threshold") || sets("merge_threshold");
            (config, sets_mount, sets_max_range, sets_noise)
        }
    };
    if !sets_noise
        && let Some(scaled) = pipeline::take_wall_scatter(&mut config, input, log)
            .with_context(|| format!("cannot read {}", input.display()))?
    {
        println!(
            "{}'s ranges scatter {:.1} mm about its walls (σ, from {} runs of beams), more \
             than the range noise model allows: the model and the line split and merge \
             thresholds are taken {:.2} times as wide",
            input.display(),
            1e3 * scaled.scatter.sigma,
            scaled.scatter.runs,
            scaled.factor
        );
    }
    if !sets_max_range
        && let Some(code) = pipeline::take_no_return_code(&mut config, input)
            .with_context(|| format!("cannot read {}", input.display()))?
    {
        println!(
            "{} writes {code} m for a beam without an echo: such readings are no echo",
            input.display()
        );
    }
    if !sets_mount {
        let declared = pipeline::take_declared_mount(&mut config, input, log)
            .with_context(|| format!("cannot read {}", input.display()))?;
        match declared {
            DeclaredMount::Fixed(m) => println!(
                "laser mounted at x {:.3} m, y {:.3} m, θ {:.4} rad on the robot, as {} declares",
                m.x,
                m.y,
                m.theta,
                input.display()
            ),
            DeclaredMount::Varying => warn!(
                "{} gives no one planar pose of the laser on the robot (laser poses that \
                 move on it, or a tilted laser); mapping with the laser at the robot's centre \
                 (set laser_mount to say where it is)",
                input.display()
            ),
            DeclaredMount::None => {}
        }
    }
    Ok(config)
}
