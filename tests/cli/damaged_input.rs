//! Damaged input mapped from what is intact, and logs localized in a saved map.

use super::*;

/// The number after `label` on a line of `clsmap map`'s report.
fn reported(stdout: &str, label: &str) -> usize {
    let line = stdout
        .lines()
        .find(|l| l.trim_start().starts_with(label))
        .unwrap_or_else(|| panic!("no {label:?} in:\n{stdout}"));
    let rest = &line.trim_start()[label.len()..];
    rest.split_whitespace().next().unwrap().parse().unwrap()
}

/// The fixture's records with `edit` applied, written as a new recording.
fn edited_fixture(path: &Path, edit: impl Fn(usize, &mut Record)) {
    let bytes = std::fs::read(fixture(CSAIL_FIXTURE)).unwrap();
    let (mut all, error) = records(&bytes);
    assert!(error.is_none());
    for (i, r) in all.iter_mut().enumerate() {
        edit(i, r);
    }
    let mut w = lms200::recording::RecordingWriter::new(Vec::new()).unwrap();
    for r in &all {
        w.write(r).unwrap();
    }
    std::fs::write(path, w.into_inner()).unwrap();
}

/// Hardening: one NaN odometry sample (valid record checksum) is skipped
/// and named; the scans around it keep interpolated odometry, the map is
/// as good as without it, and the exit status says input was skipped.
#[test]
fn a_nan_odometry_sample_is_skipped_not_spread() {
    let dir = TempDir::new("nan-odometry");
    let input = dir.join("nan.rec");
    let seen = std::cell::Cell::new(0);
    edited_fixture(&input, |_, r| {
        if let Record::Odometry { x, .. } = r {
            seen.set(seen.get() + 1);
            if seen.get() == 2 {
                *x = f64::NAN;
            }
        }
    });
    assert!(seen.get() > 10, "the fixture has odometry");
    let run = map(&input, &dir.join("out"), &[]);
    assert_eq!(run.status.code(), Some(4), "{run}");
    assert!(run.stdout.contains("non-finite pose"), "{run}");
    assert_eq!(reported(&run.stdout, "mapped"), CSAIL_SCANS);
    let rejected = reported(&run.stdout, "localizations rejected:");
    assert!(
        rejected < 10,
        "{rejected} of {CSAIL_SCANS} rejected:\n{run}"
    );
    let strict = map(&input, &dir.join("strict"), &["--strict"]);
    assert_eq!(strict.status.code(), Some(1), "{strict}");
    assert!(!dir.join("strict").exists());
}

/// Hardening: a flipped bit costs the damaged record (a chunk of serial
/// bytes: at most a scan or two), not the rest of the recording.
#[test]
fn a_flipped_bit_costs_one_record_not_the_rest() {
    let dir = TempDir::new("flipped");
    let mut bytes = std::fs::read(fixture(CSAIL_FIXTURE)).unwrap();
    let at = bytes.len() / 3;
    bytes[at] ^= 0x08;
    let input = dir.join("flipped.rec");
    std::fs::write(&input, &bytes).unwrap();
    let run = map(&input, &dir.join("out"), &[]);
    assert_eq!(run.status.code(), Some(4), "{run}");
    assert!(run.stdout.contains("damaged at byte"), "{run}");
    let mapped = reported(&run.stdout, "mapped");
    assert!((CSAIL_SCANS - 2..=CSAIL_SCANS).contains(&mapped), "{run}");
}

/// Hardening: a malformed CARMEN line is skipped and named with its line
/// number, the rest mapped; `--strict` keeps the old all-or-nothing run.
#[test]
fn a_malformed_carmen_line_is_skipped_and_named() {
    let Some(dir) = csail_dir() else { return };
    let tmp = TempDir::new("malformed");
    let mut lines: Vec<String> = clf_head(&dir.join("mit-csail.clf"), 40)
        .lines()
        .map(str::to_owned)
        .collect();
    let flaser_lines: Vec<usize> = (0..lines.len())
        .filter(|&i| lines[i].starts_with("FLASER"))
        .collect();
    let victim = flaser_lines[20];
    lines[victim] = lines[victim].replacen(' ', " x", 3);
    let input = tmp.join("bad.clf");
    std::fs::write(&input, lines.join("\n") + "\n").unwrap();
    let run = map(&input, &tmp.join("out"), &[]);
    assert_eq!(run.status.code(), Some(4), "{run}");
    assert!(
        run.stdout.contains(&format!("line {}", victim + 1)),
        "{run}"
    );
    assert_eq!(reported(&run.stdout, "mapped"), flaser_lines.len() - 1);
    let strict = map(&input, &tmp.join("strict"), &["--strict"]);
    assert_eq!(strict.status.code(), Some(1), "{strict}");
    assert!(!tmp.join("strict").exists());
}

/// `map --map M --mode localize`: a log replayed against a saved map is
/// found in it, its trajectory in the map's frame (here the first run's,
/// as the same log starts at the same place), the saved file untouched;
/// `--mode extend` on a version-1 map (no keyframes) is refused with the
/// reason.
#[test]
fn a_log_is_localized_against_a_saved_map() {
    let dir = TempDir::new("resume");
    let first = dir.join("first");
    map(&fixture(CSAIL_FIXTURE), &first, &[]).succeeded();
    let saved = std::fs::read(first.join("map.json")).unwrap();
    let again = dir.join("again");
    let run = map(
        &fixture(CSAIL_FIXTURE),
        &again,
        &["--map", arg(&first.join("map.json")), "--mode", "localize"],
    )
    .succeeded();
    assert_eq!(std::fs::read(first.join("map.json")).unwrap(), saved);
    let a = read_tum(&first.join("trajectory.tum"));
    let b = read_tum(&again.join("trajectory.tum"));
    assert!(b.len() + 5 >= a.len(), "{run}");
    let mut errors: Vec<f64> = b
        .iter()
        .filter_map(|p| {
            let q = a.iter().find(|q| (q[0] - p[0]).abs() < 1e-6)?;
            Some((p[1] - q[1]).hypot(p[2] - q[2]))
        })
        .collect();
    errors.sort_by(f64::total_cmp);
    assert!(errors[errors.len() / 2] < 0.05, "{errors:?}");

    let v1 = dir.join("v1.json");
    let map_v1 = clsmap::map::cls::ClsMap::load(
        &first.join("map.json"),
        clsmap::map::cls::ClsMapConfig::default(),
    )
    .unwrap();
    clsmap::map::cls::store::save_items(&v1, &map_v1.items()).unwrap();
    map(
        &fixture(CSAIL_FIXTURE),
        &dir.join("extend"),
        &["--map", arg(&v1), "--mode", "extend"],
    )
    .failed()
    .says("can be localized in, not extended");
    // Localized in, a version-1 map is written back whole, not emptied.
    let from_v1 = dir.join("from-v1");
    map(&fixture(CSAIL_FIXTURE), &from_v1, &["--map", arg(&v1)]).succeeded();
    let written = clsmap::map::cls::ClsMap::load(
        &from_v1.join("map.json"),
        clsmap::map::cls::ClsMapConfig::default(),
    )
    .unwrap();
    assert_eq!(written.items().len(), map_v1.items().len());
    // The run never writes over the map it starts from.
    map(
        &fixture(CSAIL_FIXTURE),
        &first,
        &["--map", arg(&first.join("map.json"))],
    )
    .failed()
    .says("would overwrite the map it starts from");
    assert_eq!(std::fs::read(first.join("map.json")).unwrap(), saved);
}

/// Hardening: a configuration or map path that is endless (`/dev/zero`)
/// fails at once with the reason instead of filling memory.
#[cfg(unix)]
#[test]
fn endless_files_are_refused_not_read() {
    let dir = TempDir::new("endless");
    map(
        &fixture(CSAIL_FIXTURE),
        &dir.join("out"),
        &["--config", "/dev/zero"],
    )
    .failed()
    .says("larger than");
    clsmap(&["render", "/dev/zero", "-o", arg(&dir.join("x.svg"))])
        .failed()
        .says("larger than");
    clsmap(&["run", "--config", "/dev/zero"])
        .failed()
        .says("larger than");
}
