//! `clsmap map`, `eval` and `render` on the fixtures and the CSAIL log.

use super::*;

#[test]
fn map_on_the_recording_writes_its_files_and_beats_the_odometry() {
    let dir = TempDir::new("map");
    let out = dir.join("out");
    let relations = csail_dir().map(|d| d.join("mit-csail.relations"));
    let extra: Vec<&str> = match &relations {
        Some(r) => vec!["--relations", arg(r)],
        None => vec![],
    };
    let run = map(&fixture(CSAIL_FIXTURE), &out, &extra).succeeded();

    let trajectory = read_tum(&out.join("trajectory.tum"));
    assert_eq!(trajectory.len(), CSAIL_SCANS);
    // The map frame is the first pose.
    assert_eq!(trajectory[0][1..], [0.0, 0.0, 0.0]);
    for name in ["trajectory.tum", "odometry.tum", "map.json", "map.svg"] {
        assert!(out.join(name).is_file(), "{name} missing:\n{run}");
    }
    for line in run.stdout.lines() {
        if let Some(path) = line.trim_start().strip_prefix("wrote ") {
            assert!(
                Path::new(path).exists(),
                "`{line}` but {path} does not exist"
            );
        }
    }

    let (Some(relations), Some(dir_csail)) = (relations, csail_dir()) else {
        return;
    };
    let mapped = parse_score(&run.stdout);
    // The logged odometry of the same scans, scored the same way.
    let odometry: Trajectory = logged_scans(&dir_csail.join("mit-csail.clf"), CSAIL_SCANS)
        .iter()
        .map(|s| [s.t, s.odometry[0], s.odometry[1], s.odometry[2]])
        .collect();
    let odometry_file = dir.join("odometry.tum");
    write_tum(&odometry_file, &odometry);
    let eval = clsmap(&["eval", arg(&odometry_file), "--relations", arg(&relations)]).succeeded();
    let logged = parse_score(&eval.stdout);
    assert!(mapped.used > 50, "{mapped:?}");
    assert_eq!(mapped.used, logged.used, "same relations for both");
    // `map` scored the odometry it wrote beside the trajectory the same
    // way: the odometry read here from the log, independently.
    let baseline = run
        .stdout
        .lines()
        .find_map(|l| l.trim_start().strip_prefix("the log's odometry alone:"))
        .unwrap_or_else(|| panic!("no odometry baseline in:\n{run}"));
    let words: Vec<&str> = baseline.split_ascii_whitespace().collect();
    assert_eq!(
        words[0],
        format!("{:.3}", logged.translation_m),
        "{baseline}"
    );
    assert_eq!(
        words[4],
        format!("{:.3}", logged.rotation_deg),
        "{baseline}"
    );
    assert_eq!(words[8], format!("({}", logged.used), "{baseline}");
    // The score split by span: every relation used is counted once.
    let by_span: Vec<usize> = run
        .stdout
        .lines()
        .find_map(|l| l.trim_start().strip_prefix("by span:"))
        .unwrap_or_else(|| panic!("no split by span in:\n{run}"))
        .split_ascii_whitespace()
        .filter_map(|w| w.parse().ok())
        .collect();
    assert_eq!(
        by_span.len(),
        3,
        "{by_span:?}: local count, span, longer count"
    );
    assert_eq!(by_span[0] + by_span[2], mapped.used, "{by_span:?}");
    // These 42 s are mostly turns on the spot: the odometry's translation
    // is already within the map's noise (both 0.027 m to the printed
    // millimetre), its heading is not.
    assert!(
        mapped.translation_m <= logged.translation_m && mapped.rotation_deg < logged.rotation_deg,
        "the map must beat the odometry: map {mapped:?}, odometry {logged:?}"
    );
}

/// Largest difference between two trajectories: (time, position, heading).
fn trajectory_difference(a: &[[f64; 4]], b: &[[f64; 4]]) -> (f64, f64, f64) {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .fold((0.0, 0.0, 0.0), |(dt, dp, dh), (p, q)| {
            let heading = (p[3] - q[3] + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
                - std::f64::consts::PI;
            (
                f64::max(dt, (p[0] - q[0]).abs()),
                f64::max(dp, (p[1] - q[1]).hypot(p[2] - q[2])),
                f64::max(dh, heading.abs()),
            )
        })
}

/// Maps the CSAIL fixture and the same scans as CARMEN text; returns the
/// two trajectories (None without the dataset).
fn map_recording_and_clf() -> Option<(Trajectory, Trajectory)> {
    let csail = csail_dir()?;
    let dir = TempDir::new("same-data");
    let clf = dir.join("head.clf");
    std::fs::write(&clf, clf_head(&csail.join("mit-csail.clf"), CSAIL_SCANS)).unwrap();
    map(&clf, &dir.join("from-clf"), &[]).succeeded();
    map(&fixture(CSAIL_FIXTURE), &dir.join("from-rec"), &[]).succeeded();
    Some((
        read_tum(&dir.join("from-clf").join("trajectory.tum")),
        read_tum(&dir.join("from-rec").join("trajectory.tum")),
    ))
}

#[test]
/// The recording and the CARMEN text hold the same data: scan and
/// odometry times convert from integer microseconds exactly as the text's
/// decimals parse, so the two trajectories agree to the printed digit.
fn map_on_the_clf_and_on_its_recording_give_the_same_trajectory() {
    let Some((from_clf, from_rec)) = map_recording_and_clf() else {
        return;
    };
    let (dt, dp, dh) = trajectory_difference(&from_clf, &from_rec);
    // TUM files keep 6 decimals: allow the last digit of x and y to differ.
    let printed = 2e-6;
    assert!(
        dt <= 1e-6 && dp <= printed && dh <= printed,
        "differ by {dt} s, {dp} m, {dh} rad"
    );
}

#[test]
fn render_draws_the_map_as_svg_and_exports_an_occupancy_grid() {
    let dir = TempDir::new("render");
    let out = dir.join("out");
    map(&fixture(CSAIL_FIXTURE), &out, &[]).succeeded();
    let map_json = out.join("map.json");
    assert!(map_json.is_file(), "map wrote no map.json");

    let svg = dir.join("map.svg");
    clsmap(&["render", arg(&map_json), "-o", arg(&svg)]).succeeded();
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.contains("<svg") && text.trim_end().ends_with("</svg>"));
    assert!(text.contains("<line") || text.contains("<path") || text.contains("<polygon"));

    let pgm = dir.join("grid.pgm");
    clsmap(&["render", arg(&map_json), "-o", arg(&pgm)]).succeeded();
    let image = std::fs::read(&pgm).unwrap();
    let header: Vec<String> = String::from_utf8_lossy(&image[..image.len().min(64)])
        .split_ascii_whitespace()
        .take(4)
        .map(str::to_owned)
        .collect();
    assert_eq!(header[0], "P5", "binary PGM");
    let (width, height): (usize, usize) = (header[1].parse().unwrap(), header[2].parse().unwrap());
    assert!(width > 10 && height > 10);
    assert!(
        image.len() >= width * height,
        "{} bytes for {width}x{height}",
        image.len()
    );
    let yaml = std::fs::read_to_string(dir.join("grid.yaml")).unwrap();
    assert!(yaml.contains("image: grid.pgm"), "{yaml}");
    assert!(yaml.contains("resolution: 0.05"), "{yaml}");
}

#[test]
fn view_serves_a_saved_map_over_http_until_ctrl_c() {
    use std::io::{Read, Write};
    let dir = TempDir::new("view");
    let out = dir.join("out");
    map(&fixture(CSAIL_FIXTURE), &out, &[]).succeeded();
    let map_json = out.join("map.json");
    let mut child = clsmap_command()
        .args(["view", arg(&map_json), "--bind", "127.0.0.1:0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    let mut line = String::new();
    stdout.read_line(&mut line).unwrap();
    // "…/map.json: http://127.0.0.1:PORT/ (Ctrl-C stops)"
    let address = line
        .split("http://")
        .nth(1)
        .and_then(|rest| rest.split('/').next())
        .unwrap_or_else(|| panic!("no address in {line:?}"))
        .to_string();
    let mut stream = std::net::TcpStream::connect(&address).unwrap();
    stream
        .write_all(b"GET /api/geometry HTTP/1.1\r\nHost: clsmap\r\nConnection: close\r\n\r\n")
        .unwrap();
    let mut reply = String::new();
    stream.read_to_string(&mut reply).unwrap();
    assert!(reply.starts_with("HTTP/1.1 200"), "{reply}");
    let body = reply.split_once("\r\n\r\n").unwrap().1;
    let geometry: serde_json::Value = serde_json::from_str(body).unwrap();
    let loaded = clsmap::map::file::load(&map_json).unwrap();
    assert_eq!(
        geometry["walls"].as_array().unwrap().len(),
        loaded.contents.cls.actual_segments().count()
    );
    // Nothing changes a saved map from the page.
    let mut stream = std::net::TcpStream::connect(&address).unwrap();
    stream
        .write_all(b"POST /api/control/stop HTTP/1.1\r\nHost: clsmap\r\nContent-Length: 0\r\nConnection: close\r\n\r\n")
        .unwrap();
    let mut reply = String::new();
    stream.read_to_string(&mut reply).unwrap();
    assert!(reply.starts_with("HTTP/1.1 403"), "{reply}");
    let pid = child.id().to_string();
    Command::new("kill").args(["-INT", &pid]).status().unwrap();
    let status = wait_at_most(&mut child, Duration::from_secs(10)).expect("view stops on Ctrl-C");
    assert!(status.success(), "{status:?}");
}
