//! LMS200 telegrams as range scans: the conversion from raw `B0` values to
//! SI, and recordings (`clsmap record`, the daemon's fixtures) read as a
//! stream of scans with the odometry interpolated at each scan's time.

use std::collections::VecDeque;
use std::io::Read;

use lms200::link::{scan_frame_len, timing};
use lms200::recording::{ODOMETRY_RESTARTED_NOTE, Record, RecordingError, RecordingReader};
use lms200::{
    Baud, DecodeEvent, Decoder, Measurement, MeasuringMode, Reply, Scan, SpecialCode, Units,
    Variant,
};

use super::{InputError, ScanRecord};
use crate::geometry::{BeamFault, Pose2, RangeScan};
use crate::input::odometry::ScansAwaitingOdometry;

/// The variant a complete scan was taken with, from its number of values.
/// Partial (interlaced) scans have none.
pub fn scan_variant(scan: &Scan) -> Option<Variant> {
    if scan.count_word.is_partial() {
        return None;
    }
    Variant::ALL
        .into_iter()
        .find(|v| usize::from(v.value_count()) == scan.values.len())
}

/// Converts a complete scan taken at `t` (s) under measuring `mode` into
/// SI units. `None` for partial scans, reserved units or reflectivity mode.
pub fn range_scan(scan: &Scan, t: f64, mode: MeasuringMode) -> Option<RangeScan> {
    let variant = scan_variant(scan)?;
    // Divide by the units per metre (exact) rather than multiply by the
    // metres per unit (inexact), so 140 cm is 1.4 m to the last bit, as a
    // text log's "1.40" reads.
    let per_metre = match scan.units()? {
        Units::Mm => 1000.0,
        Units::Cm => 100.0,
    };
    if !mode.is_distance() {
        return None;
    }
    let ranges = scan
        .values
        .iter()
        .map(|&v| match Measurement::from_value(v, mode) {
            Measurement::Distance(d) => Ok(f64::from(d) / per_metre),
            Measurement::Special(SpecialCode::NotValid) => Err(BeamFault::NoReturn),
            Measurement::Special(SpecialCode::AboveMaximum) => Err(BeamFault::OutOfRange),
            Measurement::Special(_) | Measurement::Undefined(_) | Measurement::Reflectivity(_) => {
                Err(BeamFault::SensorCode)
            }
        })
        .collect();
    Some(RangeScan {
        t,
        angle_min: variant.beam_angle_rad(0),
        angle_increment: f64::from(variant.resolution_centideg()).to_radians() / 100.0,
        ranges,
    })
}

/// The LMS200's reach (m) in `units`: the largest distance its 13-bit
/// values carry.
pub fn lms200_reach(units: Units) -> f64 {
    match units {
        Units::Mm => 8.183,
        Units::Cm => 81.83,
    }
}

/// A scan's `time_increment` and `scan_time` (s) as a LaserScan gives them,
/// for beams `angle_increment` (rad) apart: the mirror turns at 75 Hz, and
/// a 0.5° or 0.25° scan interlaces 2 or 4 turns (the beams' order in time
/// is then not their order in angle; the increment is that of one turn).
pub fn lms200_scan_timing(angle_increment: f64) -> (f64, f64) {
    let turn = 1.0 / 75.0;
    let turns = (1f64.to_radians() / angle_increment)
        .round()
        .clamp(1.0, 4.0);
    (turn * angle_increment / std::f64::consts::TAU, turn * turns)
}

/// Mid-sweep time (µs) of a complete scan whose telegram ended at `t_end_us`
/// (µs) on a line at `baud`: the model of [`lms200::link::timing`]. A
/// partial scan keeps `t_end_us`. Integer microseconds, like the
/// recording's clock, so scan and odometry times convert to seconds the
/// same way ([`seconds`]) and compare exactly.
pub fn scan_time_us(t_end_us: i64, scan: &Scan, baud: Baud) -> i64 {
    let Some(variant) = scan_variant(scan) else {
        return t_end_us;
    };
    let frame_len = scan_frame_len(variant, scan.indices.is_some());
    let back = timing::wire_time(frame_len, baud) + timing::mid_sweep_to_end(variant);
    t_end_us.saturating_sub(i64::try_from(back.as_micros()).unwrap_or(i64::MAX))
}

/// Microseconds (the recording's clock) as seconds: the f64 nearest to the
/// exact value, as parsing the decimal number from a text log gives.
pub fn seconds(t_us: i64) -> f64 {
    t_us as f64 / 1e6
}

/// The measuring mode named in a recording's note (`mode=04`), which
/// decides which bits of a value are distance.
pub fn note_mode(text: &str) -> Option<MeasuringMode> {
    text.split_whitespace()
        .find_map(|w| w.strip_prefix("mode="))
        .and_then(|m| u8::from_str_radix(m, 16).ok())
        .and_then(MeasuringMode::from_code)
}

/// Scans held back waiting for a first odometry sample before they are
/// given out without one: 10 s at the LMS200's fastest 75 scans/s.
const MAX_SCANS_WITHOUT_ODOMETRY: usize = 750;

/// A recording read as scans with odometry.
///
/// A scan is held back until an odometry sample at or after its time has
/// been read, so that its odometry is interpolated, not extrapolated; at
/// the end of the file the last sample is used. A recording without any
/// odometry yields scans with `odometry: None` (after a bounded wait for a
/// first sample). A broken recording yields
/// every whole scan before the break, then the error.
#[derive(Debug)]
pub struct RecordingScans<R: Read> {
    records: RecordingReader<R>,
    decoder: Decoder,
    mode: MeasuringMode,
    baud: Baud,
    /// Scans decoded, waiting for the odometry at their time.
    waiting: ScansAwaitingOdometry,
    /// Skipped items to report before the next scan.
    skipped: VecDeque<InputError>,
    /// What ended the recording, yielded after its last scan.
    error: Option<InputError>,
    /// Time of the last scan queued, to skip scans out of time order.
    last_scan_t: Option<f64>,
    /// The newest odometry pose handed on, and the frame the samples are
    /// put into: after a restart of the base's odometry
    /// ([`ODOMETRY_RESTARTED_NOTE`]) its new samples continue from the last
    /// pose before it, so the step across reads as no motion, not as a
    /// jump back to the origin.
    last_odometry: Option<Pose2>,
    odometry_frame: Option<Pose2>,
    odometry_restarted: bool,
    ended: bool,
}

impl<R: Read> RecordingScans<R> {
    /// Reads the recording's signature; fails for a file that is not one.
    pub fn new(input: R) -> Result<Self, RecordingError> {
        Ok(RecordingScans {
            records: RecordingReader::new(input)?,
            decoder: Decoder::new(),
            mode: MeasuringMode::Bits13FieldsAbDazzle,
            baud: Baud::B9600,
            waiting: ScansAwaitingOdometry::default(),
            skipped: VecDeque::new(),
            error: None,
            last_scan_t: None,
            last_odometry: None,
            odometry_frame: None,
            odometry_restarted: false,
            ended: false,
        })
    }

    /// Frames the decoder dropped so far (corrupt or cut short on the line).
    pub fn dropped_frames(&self) -> u64 {
        let s = self.decoder.stats();
        s.bad_crc + s.impossible_length + s.length_mismatch + s.implausible + s.truncated
    }

    /// Whether no more odometry will come for the scans waiting: the
    /// file ended, or none came after this many scans (the recording has
    /// none, as `clsmap record` makes them; the file is not held in
    /// memory waiting for it).
    fn odometry_complete(&self) -> bool {
        self.ended
            || (!self.waiting.has_odometry() && self.waiting.waiting() > MAX_SCANS_WITHOUT_ODOMETRY)
    }

    fn read_record(&mut self) {
        match self.records.next_record() {
            None => self.ended = true,
            // Damage is skipped by the reader and reported; anything else
            // ends the recording.
            Some(Err(e)) => {
                let e = InputError::Recording(e);
                if e.is_skipped_item() {
                    self.skipped.push_back(e);
                } else {
                    self.ended = true;
                    self.error = Some(e);
                }
            }
            Some(Ok(record)) => match record {
                Record::Rx { t_us, bytes } => {
                    let (mode, baud) = (self.mode, self.baud);
                    let waiting = &mut self.waiting;
                    let skipped = &mut self.skipped;
                    let last_scan_t = &mut self.last_scan_t;
                    let offset = self.records.offset();
                    self.decoder.feed(&bytes, |event| {
                        if let DecodeEvent::Reply(frame) = event
                            && let Reply::ScanData(scan) = frame.reply
                        {
                            let t = seconds(scan_time_us(t_us, &scan, baud));
                            if let Some(rs) = range_scan(&scan, t, mode) {
                                match last_scan_t.filter(|&p| rs.t <= p) {
                                    Some(previous) => {
                                        skipped.push_back(InputError::ScanOutOfOrder {
                                            at: format!("recording byte {offset}"),
                                            t: rs.t,
                                            previous,
                                        })
                                    }
                                    None => {
                                        *last_scan_t = Some(rs.t);
                                        waiting.push_scan(rs, None);
                                    }
                                }
                            }
                        }
                    });
                }
                Record::Baud { baud, .. } => {
                    if let Some(b) = Baud::from_bits_per_second(baud) {
                        self.baud = b;
                    }
                }
                Record::Note { text, .. } => {
                    if let Some(m) = note_mode(&text) {
                        self.mode = m;
                    }
                    self.odometry_restarted |= text == ODOMETRY_RESTARTED_NOTE;
                }
                Record::Odometry { t_us, x, y, theta } => {
                    let t = seconds(t_us);
                    let sample = Pose2::new(x, y, theta);
                    let frame = match self.last_odometry {
                        Some(last)
                            if self.odometry_restarted
                                && [x, y, theta].iter().all(|v| v.is_finite()) =>
                        {
                            Some(last.compose(&sample.inverse()))
                        }
                        _ => self.odometry_frame,
                    };
                    // Until a restart the samples are taken as they are.
                    let pose = frame.map_or(sample, |f| f.compose(&sample));
                    // A bad sample is skipped and reported; the track goes on.
                    match self.waiting.push_odometry(t, pose) {
                        Ok(()) => {
                            self.odometry_frame = frame;
                            self.odometry_restarted = false;
                            self.last_odometry = Some(pose);
                        }
                        Err(error) => self.skipped.push_back(InputError::RecordingOdometry {
                            offset: self.records.offset(),
                            error,
                        }),
                    }
                }
                Record::Tx { .. } => {}
            },
        }
    }
}

impl<R: Read> Iterator for RecordingScans<R> {
    type Item = Result<ScanRecord, InputError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(e) = self.skipped.pop_front() {
                return Some(Err(e));
            }
            if self.waiting.waiting() > 0 {
                if let Some(record) = self.waiting.pop(self.odometry_complete()) {
                    return Some(Ok(record));
                }
            } else if self.ended {
                return self.error.take().map(Err);
            }
            self.read_record();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use lms200::recording::RecordingWriter;

    fn telegram(values: Vec<u16>, units: Units) -> Vec<u8> {
        lms200::ReplyFrame {
            address: 0x80,
            status: lms200::Status(0x10),
            reply: Reply::ScanData(Scan::complete(values, units, None)),
        }
        .encode()
        .unwrap()
    }

    #[test]
    fn odometry_restarted_by_a_reconnected_base_goes_on_from_where_it_was() {
        let mut w = RecordingWriter::new(Vec::new()).unwrap();
        w.write(&Record::Baud {
            t_us: 0,
            baud: 500_000,
        })
        .unwrap();
        let odometry = |w: &mut RecordingWriter<Vec<u8>>, t_us: i64, x: f64| {
            w.write(&Record::Odometry {
                t_us,
                x,
                y: 0.0,
                theta: 0.5,
            })
            .unwrap();
        };
        let scan = |w: &mut RecordingWriter<Vec<u8>>, t_us: i64| {
            w.write(&Record::Rx {
                t_us,
                bytes: telegram(vec![2000; 361], Units::Mm),
            })
            .unwrap();
        };
        odometry(&mut w, 1_000_000, 3.0);
        scan(&mut w, 1_100_000);
        odometry(&mut w, 1_200_000, 4.0);
        w.write(&Record::Note {
            t_us: 1_300_000,
            text: ODOMETRY_RESTARTED_NOTE.into(),
        })
        .unwrap();
        // The base counts from zero again, and moves 1 m (x) in 0.2 s.
        odometry(&mut w, 1_400_000, 0.0);
        scan(&mut w, 1_500_000);
        odometry(&mut w, 1_600_000, 1.0);
        scan(&mut w, 1_700_000);
        odometry(&mut w, 1_800_000, 2.0);
        let records: Vec<ScanRecord> = RecordingScans::new(w.into_inner().as_slice())
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(records.len(), 3);
        let odo: Vec<Pose2> = records.iter().map(|r| r.odometry.unwrap()).collect();
        // Each sample is (x, 0, 0.5) in its frame: after the restart the
        // track goes on from (4, 0, 0.5), not from the origin.
        let last = Pose2::new(4.0, 0.0, 0.5);
        for pair in odo.windows(2) {
            let step = pair[0].between(&pair[1]);
            assert!(step.x.hypot(step.y) < 1.0 + 1e-6, "{odo:?}");
            assert!(step.theta.abs() < 1e-9, "{odo:?}");
        }
        // The base moved along its (new) frame's x, which its heading
        // turns 0.5 rad from: so it does from the pose before the restart.
        for r in &odo[1..] {
            let moved = last.between(r);
            let along = moved.x.hypot(moved.y);
            assert!(along < 1.5, "{odo:?}");
            assert!((moved.y + along * 0.5f64.sin()).abs() < 1e-9, "{moved:?}");
            assert!(moved.theta.abs() < 1e-9, "{moved:?}");
        }
    }

    #[test]
    fn special_codes_become_faults_and_units_become_metres() {
        let mut values = vec![1234u16; 361];
        values[0] = 0x1FFF; // no return
        values[1] = 0x1FF7; // above maximum
        values[2] = 0x1FFE; // dazzled
        values[3] = 0x2000 | 500; // 500 with the field-A flag
        let scan = Scan::complete(values, Units::Cm, None);
        let rs = range_scan(&scan, 1.0, MeasuringMode::Bits13FieldsAbDazzle).unwrap();
        assert_eq!(rs.ranges.len(), 361);
        assert_eq!(rs.ranges[0], Err(BeamFault::NoReturn));
        assert_eq!(rs.ranges[1], Err(BeamFault::OutOfRange));
        assert_eq!(rs.ranges[2], Err(BeamFault::SensorCode));
        assert_eq!(rs.ranges[3], Ok(5.0));
        assert_eq!(rs.ranges[4], Ok(12.34));
        assert!((rs.angle_min + std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert!((rs.angle_increment - 0.5f64.to_radians()).abs() < 1e-12);
    }

    #[test]
    fn hundred_degree_scans_are_centred() {
        let scan = Scan::complete(vec![1000; 201], Units::Mm, None);
        let rs = range_scan(&scan, 0.0, MeasuringMode::Bits13FieldsAbDazzle).unwrap();
        assert!((rs.angle_min + 50f64.to_radians()).abs() < 1e-12);
        assert!((rs.angle(200) - 50f64.to_radians()).abs() < 1e-12);
    }

    #[test]
    fn recording_yields_scans_with_interpolated_odometry() {
        let mut w = RecordingWriter::new(Vec::new()).unwrap();
        w.write(&Record::Note {
            t_us: 0,
            text: "lms200 variant=180/0.5 units=mm mode=00".into(),
        })
        .unwrap();
        w.write(&Record::Baud {
            t_us: 0,
            baud: 500_000,
        })
        .unwrap();
        w.write(&Record::Odometry {
            t_us: 1_000_000,
            x: 0.0,
            y: 0.0,
            theta: 0.0,
        })
        .unwrap();
        let bytes = telegram(vec![2000; 361], Units::Mm);
        // Split a telegram across two chunks, as a serial read does.
        w.write(&Record::Rx {
            t_us: 1_040_000,
            bytes: bytes[..100].to_vec(),
        })
        .unwrap();
        w.write(&Record::Rx {
            t_us: 1_050_000,
            bytes: bytes[100..].to_vec(),
        })
        .unwrap();
        w.write(&Record::Odometry {
            t_us: 1_100_000,
            x: 1.0,
            y: 0.0,
            theta: 0.0,
        })
        .unwrap();
        let file = w.into_inner();
        let records: Vec<ScanRecord> = RecordingScans::new(file.as_slice())
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(records.len(), 1);
        let expected_t = 1.05 - (732.0 * 10.0 / 500_000.0) - 0.00999;
        assert!(
            (records[0].scan.t - expected_t).abs() < 1e-5,
            "{}",
            records[0].scan.t
        );
        let odo = records[0].odometry.unwrap();
        assert!((odo.x - (expected_t - 1.0) / 0.1).abs() < 1e-3, "{odo:?}");
        assert_eq!(records[0].scan.ranges[0], Ok(2.0));
    }

    #[test]
    fn a_truncated_recording_yields_whole_scans_then_the_error() {
        let mut w = RecordingWriter::new(Vec::new()).unwrap();
        let bytes = telegram(vec![1500; 181], Units::Cm);
        for i in 0..3 {
            w.write(&Record::Rx {
                t_us: 1_000_000 * (i + 1),
                bytes: bytes.clone(),
            })
            .unwrap();
        }
        let mut file = w.into_inner();
        file.truncate(file.len() - 20);
        let items: Vec<_> = RecordingScans::new(file.as_slice()).unwrap().collect();
        assert_eq!(items.len(), 3);
        assert!(items[0].is_ok() && items[1].is_ok());
        assert!(items[0].as_ref().unwrap().odometry.is_none());
        let err = items[2].as_ref().unwrap_err().to_string();
        assert!(err.contains("truncated"), "{err}");
    }

    /// A recording of five scans a second apart with odometry around each;
    /// the odometry at `bad_odometry` is NaN, and the scan record at
    /// `flipped_scan` has a bit flipped.
    fn damaged_recording(bad_odometry: Option<usize>, flipped_scan: Option<usize>) -> Vec<u8> {
        let mut w = RecordingWriter::new(Vec::new()).unwrap();
        let bytes = telegram(vec![1500; 181], Units::Cm);
        let mut scan_records = Vec::new();
        let mut len = lms200::recording::MAGIC.len();
        let mut put = |w: &mut RecordingWriter<Vec<u8>>, r: Record| {
            let before = len;
            let mut one = RecordingWriter::new(Vec::new()).unwrap();
            one.write(&r).unwrap();
            len += one.into_inner().len() - lms200::recording::MAGIC.len();
            w.write(&r).unwrap();
            before..len
        };
        for i in 0..6i64 {
            let x = if bad_odometry == Some(i as usize) {
                f64::NAN
            } else {
                i as f64
            };
            put(
                &mut w,
                Record::Odometry {
                    t_us: 1_000_000 * i + 500_000,
                    x,
                    y: 0.0,
                    theta: 0.0,
                },
            );
            if i < 5 {
                scan_records.push(put(
                    &mut w,
                    Record::Rx {
                        t_us: 1_000_000 * (i + 1),
                        bytes: bytes.clone(),
                    },
                ));
            }
        }
        let mut file = w.into_inner();
        if let Some(k) = flipped_scan {
            file[scan_records[k].start + 40] ^= 0x10;
        }
        file
    }

    #[test]
    fn bad_odometry_and_damaged_records_are_skipped_and_reported() {
        let items: Vec<_> = RecordingScans::new(damaged_recording(Some(2), Some(3)).as_slice())
            .unwrap()
            .collect();
        let scans: Vec<&ScanRecord> = items.iter().filter_map(|i| i.as_ref().ok()).collect();
        let errors: Vec<&InputError> = items.iter().filter_map(|i| i.as_ref().err()).collect();
        assert_eq!(scans.len(), 4, "{items:?}");
        assert_eq!(errors.len(), 2, "{errors:?}");
        assert!(errors.iter().all(|e| e.is_skipped_item()), "{errors:?}");
        assert!(matches!(
            errors[0],
            InputError::RecordingOdometry {
                error: crate::input::OdometryError::NonFinitePose { .. },
                ..
            }
        ));
        assert!(matches!(
            errors[1],
            InputError::Recording(lms200::recording::RecordingError::Damaged { .. })
        ));
        // Every scan has finite odometry, interpolated across the bad sample.
        for s in &scans {
            let o = s.odometry.unwrap();
            assert!(o.x.is_finite(), "{s:?}");
        }
    }
}
