//! `clsmap decode`: recordings to JSON lines, CSV and raw dumps.

use super::*;

#[test]
fn decode_jsonl_gives_the_logged_scans_in_cm_at_the_logged_times() {
    let run = clsmap(&["decode", arg(&fixture(CSAIL_FIXTURE)), "--format", "jsonl"]).succeeded();
    let scans = parse_jsonl(&run.stdout);
    assert_eq!(scans.len(), CSAIL_SCANS, "{run}");
    for scan in &scans {
        assert_eq!(scan.units, "cm");
        assert_eq!(scan.ranges.len(), BEAMS);
        assert_eq!(scan.flags, vec![0; BEAMS]);
        assert_eq!(scan.status, 16);
    }
    assert_eq!(decode_summary(&run.stderr), (CSAIL_SCANS, 0), "{run}");

    let Some(dir) = csail_dir() else { return };
    let logged = logged_scans(&dir.join("mit-csail.clf"), CSAIL_SCANS);
    for (i, (scan, log)) in scans.iter().zip(&logged).enumerate() {
        assert_eq!(
            scan.ranges, log.ranges_cm,
            "scan {i}: ranges differ from the log"
        );
        assert!(
            (scan.t - log.t).abs() < 1e-5,
            "scan {i}: t {} but the log says {}",
            scan.t,
            log.t
        );
    }
}

#[test]
fn decode_csv_has_a_header_and_one_row_per_beam() {
    let run = clsmap(&["decode", arg(&fixture(CSAIL_FIXTURE)), "--format", "csv"]).succeeded();
    let lines = run.stdout_lines();
    assert_eq!(lines[0], "t,beam,units,range,flags,status");
    assert_eq!(lines.len(), 1 + CSAIL_SCANS * BEAMS);
    let first: Vec<&str> = lines[1].split(',').collect();
    assert_eq!(&first[1..], ["0", "cm", "140", "0", "16"], "{}", lines[1]);
    let last: Vec<&str> = lines[lines.len() - 1].split(',').collect();
    assert_eq!(last[1], (BEAMS - 1).to_string());
}

#[test]
fn decode_raw_reads_a_plain_serial_dump_of_the_same_bytes() {
    let dir = TempDir::new("raw");
    let (records, error) = records(&std::fs::read(fixture(CSAIL_FIXTURE)).unwrap());
    assert!(error.is_none());
    let dump = dir.join("csail.bin");
    std::fs::write(&dump, rx_bytes(&records)).unwrap();

    let raw = clsmap(&["decode", "--raw", arg(&dump)]).succeeded();
    let recorded = clsmap(&["decode", arg(&fixture(CSAIL_FIXTURE))]).succeeded();
    let (raw, recorded) = (parse_jsonl(&raw.stdout), parse_jsonl(&recorded.stdout));
    assert_eq!(raw.len(), CSAIL_SCANS);
    for (i, (a, b)) in raw.iter().zip(&recorded).enumerate() {
        assert_eq!(a.ranges, b.ranges, "scan {i}");
        assert_eq!(a.units, b.units);
        // A raw dump has no clock: scans are numbered.
        assert_eq!(a.t, i as f64);
    }
}

#[test]
fn a_truncated_recording_prints_the_whole_scans_and_names_the_byte_offset() {
    let dir = TempDir::new("truncated");
    let full = std::fs::read(fixture(CSAIL_FIXTURE)).unwrap();
    // Cut in the middle of a record, about half-way.
    let cut = full.len() / 2 + 7;
    let truncated = dir.join("truncated.rec");
    std::fs::write(&truncated, &full[..cut]).unwrap();

    let (whole_records, error) = records(&full[..cut]);
    let Some(RecordingError::Truncated { offset, .. }) = error else {
        panic!("the library does not see the cut as a truncation: {error:?}");
    };
    let whole_scans = count_scan_telegrams(&rx_bytes(&whole_records));
    assert!(whole_scans > 50 && whole_scans < CSAIL_SCANS);

    let run = clsmap(&["decode", arg(&truncated)])
        .failed()
        .says(&format!("byte {offset}"));
    let complete = clsmap(&["decode", arg(&fixture(CSAIL_FIXTURE))]).succeeded();
    assert_eq!(
        run.stdout_lines(),
        complete.stdout_lines()[..whole_scans].to_vec(),
        "the scans before the break must be printed as from the whole file"
    );
}

#[test]
fn a_noisy_line_recording_decodes_with_dropped_frames_counted() {
    let run = clsmap(&["decode", arg(&fixture(NOISY_FIXTURE))]).succeeded();
    let scans = parse_jsonl(&run.stdout);
    let (printed, dropped) = decode_summary(&run.stderr);
    assert_eq!(printed, scans.len());
    // The driver counted 60 scans while recording this line.
    assert!(scans.len() >= 60, "{run}");
    assert!(
        dropped > 0,
        "the line noise must show as dropped frames:\n{run}"
    );
    for (i, scan) in scans.iter().enumerate() {
        assert_eq!(scan.ranges.len(), BEAMS, "scan {i}");
        assert_eq!(scan.units, "mm", "scan {i}");
    }
    assert!(
        scans.windows(2).all(|w| w[0].t < w[1].t),
        "times must increase"
    );
}
