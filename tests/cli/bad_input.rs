//! Bad input: a clear error naming what is wrong, never a panic.

use super::*;

#[test]
fn a_missing_input_file_is_named() {
    let dir = TempDir::new("missing");
    let missing = dir.join("no-such-recording.rec");
    let shown = missing.display().to_string();
    clsmap(&["decode", arg(&missing)]).failed().says(&shown);
    map(&missing, &dir.join("out"), &[]).failed().says(&shown);
}

#[test]
fn probe_refuses_what_is_not_a_serial_port() {
    clsmap(&["probe", "--port", "/dev/null"])
        .failed()
        .says("not a serial port");
    clsmap(&["probe", "--port", "/nonexistent"])
        .failed()
        .says("no such device");
}

#[test]
fn record_never_costs_an_existing_file() {
    let dir = TempDir::new("record-keep");
    let keep = dir.join("keep.rec");
    std::fs::write(&keep, b"the only copy").unwrap();
    // A wrong port fails before the output is touched.
    clsmap(&["record", "--port", "/nonexistent", "--out", arg(&keep)])
        .failed()
        .says("no such device");
    assert_eq!(std::fs::read(&keep).unwrap(), b"the only copy");
}

#[test]
fn render_refuses_to_draw_over_its_own_map() {
    let dir = TempDir::new("render-self");
    let out = dir.join("out");
    map(&fixture(CSAIL_FIXTURE), &out, &[]).succeeded();
    let map_json = out.join("map.json");
    let before = std::fs::read(&map_json).unwrap();
    clsmap(&["render", arg(&map_json), "-o", arg(&map_json)])
        .failed()
        .says("would overwrite the map");
    assert_eq!(std::fs::read(&map_json).unwrap(), before);
}

#[test]
fn a_recording_cut_short_is_mapped_up_to_the_break() {
    let dir = TempDir::new("map-truncated");
    let full = std::fs::read(fixture(CSAIL_FIXTURE)).unwrap();
    let half = dir.join("half.rec");
    std::fs::write(&half, &full[..full.len() / 2]).unwrap();
    let out = dir.join("out");
    // The map is written from what there is; the exit status says the
    // input was not whole.
    let run = map(&half, &out, &[]);
    assert_eq!(run.status.code(), Some(4), "{run}");
    assert!(run.stdout.contains("input broke off"), "{run}");
    let poses = read_tum(&out.join("trajectory.tum"));
    assert!(
        poses.len() > 50 && poses.len() < 200,
        "{} poses from half the fixture",
        poses.len()
    );
}

#[test]
fn an_out_of_range_configuration_value_is_named() {
    let dir = TempDir::new("config-range");
    let config = dir.join("bad.toml");
    std::fs::write(&config, "[extraction]\nmax_point_gap = 0.0\n").unwrap();
    map(
        &fixture(CSAIL_FIXTURE),
        &dir.join("out"),
        &["--config", arg(&config)],
    )
    .failed()
    .says("max_point_gap");
}

#[test]
fn an_unknown_configuration_key_is_named_with_its_line() {
    let dir = TempDir::new("config");
    let config = dir.join("bad.toml");
    std::fs::write(&config, "# mapper settings\n\n[odometry]\nbogus_key = 1\n").unwrap();
    map(
        &fixture(CSAIL_FIXTURE),
        &dir.join("out"),
        &["--config", arg(&config)],
    )
    .failed()
    .says("bogus_key")
    .says("line 4");
}

#[test]
fn a_malformed_carmen_line_is_named_by_number() {
    let dir = TempDir::new("carmen");
    let mut lines: Vec<String> = (0..7)
        .map(|i| {
            let mut fields = vec!["FLASER".to_owned(), "361".to_owned()];
            fields.extend((0..361).map(|_| "2.50".to_owned()));
            let t = 1000.0 + 0.2 * f64::from(i);
            fields.extend(
                ["0", "0", "0", "0", "0", "0"]
                    .iter()
                    .map(|s| (*s).to_owned()),
            );
            fields.extend([format!("{t:.6}"), "host".to_owned(), format!("{t:.6}")]);
            fields.join(" ")
        })
        .collect();
    lines.insert(0, "# a CARMEN log".to_owned());
    // Line 6 of the file: a range that is not a number.
    lines[5] = lines[5].replacen(" 2.50 ", " 2.5x ", 1);
    let clf = dir.join("bad.clf");
    std::fs::write(&clf, lines.join("\n") + "\n").unwrap();
    map(&clf, &dir.join("out"), &[])
        .failed()
        .says("line 6")
        .says("2.5x");
}

#[test]
fn decode_refuses_a_file_that_is_not_a_recording() {
    let dir = TempDir::new("random");
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let bytes: Vec<u8> = (0..4096)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 24) as u8
        })
        .collect();
    let file = dir.join("random.bin");
    std::fs::write(&file, bytes).unwrap();
    let run = clsmap(&["decode", arg(&file)])
        .failed()
        .says("not a clsmap recording");
    assert!(run.stdout.is_empty());
}

#[test]
fn a_map_edited_by_hand_loads_only_with_ignore_checksum() {
    let dir = TempDir::new("edited-map");
    let out = dir.join("out");
    map(&fixture(CSAIL_FIXTURE), &out, &[]).succeeded();
    let text = std::fs::read_to_string(out.join("map.json")).unwrap();
    // The first wall seen once more than it was: a valid number, a
    // payload that no longer matches its checksum.
    let key = "\"observations\":";
    let at = text.find(key).unwrap() + key.len();
    let digits = text[at..].find(|c: char| !c.is_ascii_digit()).unwrap();
    let n: u64 = text[at..at + digits].parse().unwrap();
    let edited = format!("{}{}{}", &text[..at], n + 1, &text[at + digits..]);
    let edited_map = dir.join("edited.json");
    std::fs::write(&edited_map, &edited).unwrap();
    let svg = dir.join("edited.svg");

    clsmap(&["render", arg(&edited_map), "-o", arg(&svg)])
        .failed()
        .says("checksum mismatch");
    assert!(!svg.exists());
    let run = clsmap(&[
        "render",
        arg(&edited_map),
        "-o",
        arg(&svg),
        "--ignore-checksum",
    ])
    .succeeded();
    assert!(run.stderr.contains("checksum mismatch ignored"), "{run}");
    assert!(svg.is_file());

    // Going on from it offline: refused, then taken with the flag.
    let scans = fixture(CSAIL_FIXTURE);
    let again = dir.join("again");
    let from = ["--map", arg(&edited_map)];
    map(&scans, &again, &from)
        .failed()
        .says("checksum mismatch");
    let run = map(&scans, &again, &[from[0], from[1], "--ignore-checksum"]).succeeded();
    assert!(run.stderr.contains("checksum mismatch ignored"), "{run}");
    // The edited file itself is left as it was.
    assert_eq!(std::fs::read_to_string(&edited_map).unwrap(), edited);
}
