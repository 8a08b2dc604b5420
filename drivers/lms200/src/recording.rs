//! Recordings: a versioned file of timestamped raw byte chunks in both
//! directions, baud changes, odometry samples and free-form notes.
//!
//! Replay feeds the `rx` chunks to the same [`crate::decoder::Decoder`] the
//! live driver uses, resynchronising the same way. (The live link also
//! narrows the decoder to the configured scan shape; a replay that knows
//! only the note's description decodes with the general checks.)
//!
//! # Format, version 1
//!
//! All integers little-endian.
//!
//! ```text
//! file    = magic record*
//! magic   = "CLSMREC" 0x01                        8 bytes; the last byte is the version
//! record  = kind:u8 t_us:i64 len:u32 payload[len] crc:u32
//!           crc = CRC-32/ISO-HDLC over kind..payload (the zip/PNG CRC)
//! kind 1  = bytes received from the sensor        payload: raw bytes
//! kind 2  = bytes sent to the sensor              payload: raw bytes
//! kind 3  = host line speed changed               payload: baud:u32
//! kind 4  = odometry sample of the base           payload: x:f64 y:f64 theta:f64 (m, m, rad, odometry frame)
//! kind 5  = note                                  payload: UTF-8 text (e.g. "variant=180/0.5 units=mm mode=0")
//! ```
//!
//! `t_us` is microseconds since the Unix epoch, the host's receive (or send)
//! time of the chunk's last byte. A damaged record (its CRC does not match,
//! its length is impossible, its payload does not fit its kind) is reported
//! with its byte offset and skipped: the reader resynchronises on the next
//! intact record (a known kind, a length within bounds, a matching CRC) and
//! goes on, so a flipped bit costs one record, not the
//! rest of the file. A record cut short by the end of the file (a killed
//! recorder) ends it, reported as a truncation. Unknown kinds with a good
//! CRC are skipped, so later versions can add kinds without breaking older
//! readers.

use std::io::{self, Read, Write};

use crc::{CRC_32_ISO_HDLC, Crc};

/// File signature: "CLSMREC" followed by the format version.
pub const MAGIC: [u8; 8] = *b"CLSMREC\x01";
/// Largest payload a record may carry; bounds memory on a corrupt length.
pub const MAX_PAYLOAD: u32 = 1 << 20;

const RECORD_CRC: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);
const HEADER_LEN: usize = 1 + 8 + 4;

/// The [`Record::Note`] text that says the base's odometry counts from
/// zero again from the next [`Record::Odometry`] on (the base was
/// connected anew): a replay must not read the step across it as motion.
pub const ODOMETRY_RESTARTED_NOTE: &str = "odometry restarted";

/// One entry of a recording.
#[derive(Debug, Clone, PartialEq)]
pub enum Record {
    /// Bytes read from the sensor.
    Rx { t_us: i64, bytes: Vec<u8> },
    /// Bytes written to the sensor.
    Tx { t_us: i64, bytes: Vec<u8> },
    /// The host switched its line speed.
    Baud { t_us: i64, baud: u32 },
    /// An odometry sample of the base (m, m, rad).
    Odometry {
        t_us: i64,
        x: f64,
        y: f64,
        theta: f64,
    },
    /// Free-form text: sensor configuration, operator remarks.
    Note { t_us: i64, text: String },
}

impl Record {
    /// Host time of the record (µs since the Unix epoch).
    pub fn t_us(&self) -> i64 {
        match self {
            Record::Rx { t_us, .. }
            | Record::Tx { t_us, .. }
            | Record::Baud { t_us, .. }
            | Record::Odometry { t_us, .. }
            | Record::Note { t_us, .. } => *t_us,
        }
    }

    fn kind(&self) -> u8 {
        match self {
            Record::Rx { .. } => 1,
            Record::Tx { .. } => 2,
            Record::Baud { .. } => 3,
            Record::Odometry { .. } => 4,
            Record::Note { .. } => 5,
        }
    }

    fn payload(&self) -> Vec<u8> {
        match self {
            Record::Rx { bytes, .. } | Record::Tx { bytes, .. } => bytes.clone(),
            Record::Baud { baud, .. } => baud.to_le_bytes().to_vec(),
            Record::Odometry { x, y, theta, .. } => {
                let mut p = Vec::with_capacity(24);
                for v in [x, y, theta] {
                    p.extend_from_slice(&v.to_le_bytes());
                }
                p
            }
            Record::Note { text, .. } => text.as_bytes().to_vec(),
        }
    }
}

/// Why a recording could not be read (further).
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    #[error("not a clsmap recording (bad signature)")]
    BadMagic,
    #[error("recording format version {0} is not supported (this build reads version 1)")]
    UnsupportedVersion(u8),
    #[error("recording truncated at byte {offset}: {what}")]
    Truncated { offset: u64, what: &'static str },
    #[error("recording corrupt at byte {offset}: {what}")]
    Corrupt { offset: u64, what: String },
    #[error(
        "recording damaged at byte {offset}: {what}; {skipped} bytes skipped to the next intact record"
    )]
    Damaged {
        offset: u64,
        skipped: u64,
        what: String,
    },
    #[error("payload of {len} bytes exceeds a recording write limit of {MAX_PAYLOAD} bytes")]
    PayloadTooLarge { len: usize },
    #[error(transparent)]
    Io(#[from] io::Error),
}

/// Appends records to a recording.
pub struct RecordingWriter<W: Write> {
    out: W,
}

impl<W: Write> std::fmt::Debug for RecordingWriter<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("RecordingWriter")
    }
}

impl<W: Write> RecordingWriter<W> {
    /// Writes the signature and returns a writer for the records.
    pub fn new(mut out: W) -> Result<Self, RecordingError> {
        out.write_all(&MAGIC)?;
        Ok(RecordingWriter { out })
    }

    /// Appends one record.
    pub fn write(&mut self, record: &Record) -> Result<(), RecordingError> {
        let payload = record.payload();
        let len = u32::try_from(payload.len())
            .ok()
            .filter(|&l| l <= MAX_PAYLOAD)
            .ok_or(RecordingError::PayloadTooLarge { len: payload.len() })?;
        let mut head = [0u8; HEADER_LEN];
        head[0] = record.kind();
        head[1..9].copy_from_slice(&record.t_us().to_le_bytes());
        head[9..13].copy_from_slice(&len.to_le_bytes());
        let mut digest = RECORD_CRC.digest();
        digest.update(&head);
        digest.update(&payload);
        // One write per record: a writer that keeps or drops whole writes
        // (a bounded buffer) then keeps or drops whole records.
        let mut bytes = Vec::with_capacity(HEADER_LEN + payload.len() + 4);
        bytes.extend_from_slice(&head);
        bytes.extend_from_slice(&payload);
        bytes.extend_from_slice(&digest.finalize().to_le_bytes());
        self.out.write_all(&bytes)?;
        Ok(())
    }

    /// Flushes buffered records to the underlying writer.
    pub fn flush(&mut self) -> Result<(), RecordingError> {
        self.out.flush()?;
        Ok(())
    }

    /// Returns the underlying writer.
    pub fn into_inner(self) -> W {
        self.out
    }
}

/// Records made on another thread (a robot's odometry, on its control
/// loop) for the recording a [`crate::driver::SerialDriver`] writes: the
/// driver writes them, in the order pushed, before the next chunk it
/// records and at least every few tens of milliseconds. Bounded: beyond
/// [`RecordQueue::CAPACITY`] records waiting (no recording is being
/// written, the port is down) new ones are dropped and counted.
#[derive(Debug, Clone, Default)]
pub struct RecordQueue(std::sync::Arc<std::sync::Mutex<QueuedRecords>>);

#[derive(Debug, Default)]
struct QueuedRecords {
    records: Vec<Record>,
    dropped: u64,
}

impl RecordQueue {
    /// Records waiting at most (a minute of 50 Hz odometry).
    pub const CAPACITY: usize = 3000;

    /// Queues `record` for the recording.
    pub fn push(&self, record: Record) {
        if let Ok(mut q) = self.0.lock() {
            if q.records.len() < Self::CAPACITY {
                q.records.push(record);
            } else {
                q.dropped += 1;
            }
        }
    }

    /// The records pushed since the last call, oldest first.
    pub fn take(&self) -> Vec<Record> {
        self.0
            .lock()
            .map(|mut q| std::mem::take(&mut q.records))
            .unwrap_or_default()
    }

    /// Records dropped so far because the queue was full.
    pub fn dropped(&self) -> u64 {
        self.0.lock().map(|q| q.dropped).unwrap_or(0)
    }
}

/// Reads records one by one. A damaged stretch comes as one
/// [`RecordingError::Damaged`] (or, when nothing intact follows it,
/// [`RecordingError::Corrupt`] or [`RecordingError::Truncated`], after
/// which nothing more comes); the records after it come as usual.
#[derive(Debug)]
pub struct RecordingReader<R: Read> {
    input: R,
    /// Bytes read and not yet consumed; `buf[0]` is at file offset `offset`.
    buf: Vec<u8>,
    offset: u64,
    eof: bool,
    ended: bool,
}

/// What the bytes at one position are.
enum Parse {
    /// A record and the bytes it takes.
    Record(Record, usize),
    /// An intact record of a kind this version does not know.
    Unknown(usize),
    /// Not a record: why.
    Bad(String),
    /// This many bytes are needed to tell.
    NeedMore(usize),
}

/// Known record kinds.
const KINDS: std::ops::RangeInclusive<u8> = 1..=5;
/// Skipped bytes are dropped from the buffer in chunks of this size while
/// resynchronising, so a long damaged stretch is not held in memory.
const RESYNC_CHUNK: usize = 1 << 16;

fn decode_record(kind: u8, t_us: i64, payload: Vec<u8>) -> Result<Option<Record>, String> {
    Ok(Some(match kind {
        1 => Record::Rx {
            t_us,
            bytes: payload,
        },
        2 => Record::Tx {
            t_us,
            bytes: payload,
        },
        3 => {
            let bytes: [u8; 4] = payload
                .as_slice()
                .try_into()
                .map_err(|_| "baud record is not 4 bytes".to_string())?;
            Record::Baud {
                t_us,
                baud: u32::from_le_bytes(bytes),
            }
        }
        4 => {
            if payload.len() != 24 {
                return Err("odometry record is not 24 bytes".into());
            }
            let f = |i: usize| f64::from_le_bytes(copy_array(&payload[i * 8..i * 8 + 8]));
            Record::Odometry {
                t_us,
                x: f(0),
                y: f(1),
                theta: f(2),
            }
        }
        5 => Record::Note {
            t_us,
            text: String::from_utf8(payload).map_err(|_| "note is not UTF-8".to_string())?,
        },
        // A later version's record kind.
        _ => return Ok(None),
    }))
}

impl<R: Read> RecordingReader<R> {
    /// Checks the signature and returns a reader positioned at the first record.
    pub fn new(mut input: R) -> Result<Self, RecordingError> {
        let mut magic = [0u8; 8];
        let n = read_full(&mut input, &mut magic)?;
        if n < magic.len() || magic[..7] != MAGIC[..7] {
            return Err(RecordingError::BadMagic);
        }
        if magic[7] != MAGIC[7] {
            return Err(RecordingError::UnsupportedVersion(magic[7]));
        }
        Ok(RecordingReader {
            input,
            buf: Vec::new(),
            offset: MAGIC.len() as u64,
            eof: false,
            ended: false,
        })
    }

    /// Byte offset of the next record in the file.
    pub fn offset(&self) -> u64 {
        self.offset
    }

    /// The next record, `None` at the end of the file (or after damage
    /// that reached it).
    pub fn next_record(&mut self) -> Option<Result<Record, RecordingError>> {
        if self.ended {
            return None;
        }
        let result = self.read_one().transpose();
        if matches!(
            result,
            None | Some(Err(RecordingError::Truncated { .. }
                | RecordingError::Corrupt { .. }
                | RecordingError::Io(_)))
        ) {
            self.ended = true;
        }
        result
    }

    /// Reads until `buf` holds `n` bytes or the input ends; whether it does.
    fn fill(&mut self, n: usize) -> io::Result<bool> {
        let mut chunk = [0u8; 8192];
        while self.buf.len() < n && !self.eof {
            match self.input.read(&mut chunk) {
                Ok(0) => self.eof = true,
                Ok(k) => self.buf.extend_from_slice(&chunk[..k]),
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        Ok(self.buf.len() >= n)
    }

    fn consume(&mut self, n: usize) {
        self.buf.drain(..n);
        self.offset += n as u64;
    }

    /// What the bytes at `at` in the buffer are (reading more as needed).
    fn parse_at(&mut self, at: usize) -> io::Result<Parse> {
        if !self.fill(at + HEADER_LEN)? {
            return Ok(Parse::NeedMore(at + HEADER_LEN));
        }
        let head: [u8; HEADER_LEN] = copy_array(&self.buf[at..at + HEADER_LEN]);
        let kind = head[0];
        let t_us = i64::from_le_bytes(copy_array(&head[1..9]));
        let len = u32::from_le_bytes(copy_array(&head[9..13]));
        if len > MAX_PAYLOAD {
            return Ok(Parse::Bad(format!(
                "record length {len} exceeds {MAX_PAYLOAD}"
            )));
        }
        let total = HEADER_LEN + len as usize + 4;
        if !self.fill(at + total)? {
            return Ok(Parse::NeedMore(at + total));
        }
        let body = &self.buf[at..at + total - 4];
        let crc = u32::from_le_bytes(copy_array(&self.buf[at + total - 4..at + total]));
        if RECORD_CRC.checksum(body) != crc {
            return Ok(Parse::Bad("record checksum mismatch".into()));
        }
        let payload = self.buf[at + HEADER_LEN..at + total - 4].to_vec();
        Ok(match decode_record(kind, t_us, payload) {
            Ok(Some(record)) => Parse::Record(record, total),
            Ok(None) => Parse::Unknown(total),
            Err(what) => Parse::Bad(what),
        })
    }

    fn read_one(&mut self) -> Result<Option<Record>, RecordingError> {
        loop {
            let start = self.offset;
            match self.parse_at(0)? {
                Parse::Record(record, total) => {
                    self.consume(total);
                    return Ok(Some(record));
                }
                Parse::Unknown(total) => self.consume(total),
                Parse::NeedMore(_) if self.buf.is_empty() => return Ok(None),
                Parse::NeedMore(n) => {
                    let what = if n == HEADER_LEN {
                        "record header cut short"
                    } else {
                        "record cut short"
                    };
                    // A length flipped to run past the end, or a real cut:
                    // an intact record further on tells them apart.
                    return match self.resync()? {
                        Some(skipped) => Err(RecordingError::Damaged {
                            offset: start,
                            skipped,
                            what: what.into(),
                        }),
                        None => Err(RecordingError::Truncated {
                            offset: start,
                            what,
                        }),
                    };
                }
                Parse::Bad(what) => {
                    return match self.resync()? {
                        Some(skipped) => Err(RecordingError::Damaged {
                            offset: start,
                            skipped,
                            what,
                        }),
                        None => Err(RecordingError::Corrupt {
                            offset: start,
                            what,
                        }),
                    };
                }
            }
        }
    }

    /// Skips to the next intact record after the damaged one at the front
    /// of the buffer; the bytes skipped, or `None` (everything consumed)
    /// when none follows.
    fn resync(&mut self) -> io::Result<Option<u64>> {
        let mut skipped = 0u64;
        let mut at = 1;
        loop {
            if at >= RESYNC_CHUNK {
                self.consume(at);
                skipped += at as u64;
                at = 0;
            }
            if !self.fill(at + HEADER_LEN)? {
                let rest = self.buf.len();
                self.consume(rest);
                return Ok(None);
            }
            // A known kind and a length within bounds make a candidate
            // (about one position in 50,000 of random bytes); its CRC
            // decides. The time is not asked: a recorder's clock may jump
            // (an RTC-less computer syncing NTP) right where the damage is.
            let kind = self.buf[at];
            let len = u32::from_le_bytes(copy_array(&self.buf[at + 9..at + 13]));
            let candidate = KINDS.contains(&kind) && len <= MAX_PAYLOAD;
            if candidate && matches!(self.parse_at(at)?, Parse::Record(..)) {
                self.consume(at);
                return Ok(Some(skipped + at as u64));
            }
            at += 1;
        }
    }
}

impl<R: Read> Iterator for RecordingReader<R> {
    type Item = Result<Record, RecordingError>;

    fn next(&mut self) -> Option<Self::Item> {
        self.next_record()
    }
}

/// Copies a slice whose length the caller has already checked.
fn copy_array<const N: usize>(s: &[u8]) -> [u8; N] {
    let mut a = [0u8; N];
    a.copy_from_slice(&s[..N]);
    a
}

/// Reads until `buf` is full or the input ends; returns the bytes read.
fn read_full(input: &mut impl Read, buf: &mut [u8]) -> io::Result<usize> {
    let mut filled = 0;
    while filled < buf.len() {
        match input.read(&mut buf[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(filled)
}

#[cfg(test)]
mod tests {

    #[test]
    fn a_record_queue_hands_over_in_order_and_drops_beyond_its_bound() {
        let queue = RecordQueue::default();
        let odometry = |t_us| Record::Odometry {
            t_us,
            x: 0.0,
            y: 0.0,
            theta: 0.0,
        };
        for t in 0..(RecordQueue::CAPACITY as i64 + 5) {
            queue.clone().push(odometry(t));
        }
        let taken = queue.take();
        assert_eq!(taken.len(), RecordQueue::CAPACITY);
        assert!(taken.iter().enumerate().all(|(i, r)| r.t_us() == i as i64));
        assert_eq!(queue.dropped(), 5);
        assert!(queue.take().is_empty());
        queue.push(odometry(7));
        assert_eq!(queue.take(), vec![odometry(7)]);
    }
    use super::*;

    fn sample() -> Vec<Record> {
        vec![
            Record::Note {
                t_us: 1,
                text: "variant=180/0.5 units=mm".into(),
            },
            Record::Tx {
                t_us: 2,
                bytes: vec![0x02, 0x00, 0x01, 0x00, 0x31, 0x15, 0x12],
            },
            Record::Rx {
                t_us: 3,
                bytes: vec![0x06, 0x02, 0x80],
            },
            Record::Baud {
                t_us: 4,
                baud: 500_000,
            },
            Record::Odometry {
                t_us: 5,
                x: 1.25,
                y: -0.5,
                theta: 3.0,
            },
        ]
    }

    fn encode(records: &[Record]) -> Vec<u8> {
        let mut w = RecordingWriter::new(Vec::new()).unwrap();
        for r in records {
            w.write(r).unwrap();
        }
        w.into_inner()
    }

    #[test]
    fn round_trip() {
        let bytes = encode(&sample());
        let back: Vec<Record> = RecordingReader::new(bytes.as_slice())
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(back, sample());
    }

    #[test]
    fn truncation_keeps_whole_records_and_names_the_offset() {
        let bytes = encode(&sample());
        // Cut inside the last record (the odometry sample: 13 + 24 + 4 bytes).
        let cut = bytes.len() - 10;
        let mut reader = RecordingReader::new(&bytes[..cut]).unwrap();
        let mut whole = Vec::new();
        let err = loop {
            match reader.next_record() {
                Some(Ok(r)) => whole.push(r),
                Some(Err(e)) => break e,
                None => panic!("truncation not reported"),
            }
        };
        assert_eq!(whole, sample()[..4].to_vec());
        match err {
            RecordingError::Truncated { offset, .. } => {
                assert_eq!(offset as usize, bytes.len() - (13 + 24 + 4))
            }
            other => panic!("unexpected error {other}"),
        }
        assert!(reader.next_record().is_none());
    }

    #[test]
    fn a_bit_flip_costs_one_record_and_is_reported() {
        let mut bytes = encode(&sample());
        bytes[8 + 13 + 3] ^= 0x01; // inside the first note's text
        let mut reader = RecordingReader::new(bytes.as_slice()).unwrap();
        let first_len = encode(&sample()[..1]).len() - 8;
        match reader.next_record() {
            Some(Err(RecordingError::Damaged {
                offset: 8, skipped, ..
            })) => assert_eq!(skipped as usize, first_len),
            other => panic!("{other:?}"),
        }
        let rest: Vec<Record> = reader.collect::<Result<_, _>>().unwrap();
        assert_eq!(rest, sample()[1..].to_vec());
    }

    #[test]
    fn damage_that_reaches_the_end_ends_the_file() {
        let mut bytes = encode(&sample());
        let last = bytes.len() - 5;
        bytes[last] ^= 0x40;
        let mut reader = RecordingReader::new(bytes.as_slice()).unwrap();
        let items: Vec<_> = std::iter::from_fn(|| reader.next_record()).collect();
        assert_eq!(items.len(), sample().len());
        assert!(matches!(
            items.last(),
            Some(Err(RecordingError::Corrupt { .. }))
        ));
    }

    #[test]
    fn unknown_kind_is_skipped() {
        let mut bytes = encode(&sample()[..1]);
        // Hand-build a record of kind 200 with a good CRC.
        let mut rec = vec![200u8];
        rec.extend_from_slice(&7i64.to_le_bytes());
        rec.extend_from_slice(&2u32.to_le_bytes());
        rec.extend_from_slice(&[9, 9]);
        let crc = RECORD_CRC.checksum(&rec);
        rec.extend_from_slice(&crc.to_le_bytes());
        bytes.extend_from_slice(&rec);
        bytes.extend_from_slice(&encode(&sample()[1..2])[8..]);
        let back: Vec<Record> = RecordingReader::new(bytes.as_slice())
            .unwrap()
            .collect::<Result<_, _>>()
            .unwrap();
        assert_eq!(back, sample()[..2].to_vec());
    }

    #[test]
    fn rejects_other_files() {
        assert!(matches!(
            RecordingReader::new(&b"FLASER 361"[..]),
            Err(RecordingError::BadMagic)
        ));
        assert!(matches!(
            RecordingReader::new(&b"CLSMREC\x07"[..]),
            Err(RecordingError::UnsupportedVersion(7))
        ));
        assert!(matches!(
            RecordingReader::new(&b""[..]),
            Err(RecordingError::BadMagic)
        ));
    }

    #[test]
    fn huge_length_is_corruption_not_allocation() {
        let mut bytes = MAGIC.to_vec();
        bytes.push(1);
        bytes.extend_from_slice(&0i64.to_le_bytes());
        bytes.extend_from_slice(&u32::MAX.to_le_bytes());
        let mut reader = RecordingReader::new(bytes.as_slice()).unwrap();
        assert!(matches!(
            reader.next_record(),
            Some(Err(RecordingError::Corrupt { .. }))
        ));
    }

    fn arbitrary_record() -> impl proptest::strategy::Strategy<Value = Record> {
        use proptest::prelude::*;
        let t = 1_700_000_000_000_000i64..1_700_000_100_000_000;
        prop_oneof![
            (t.clone(), proptest::collection::vec(any::<u8>(), 0..300))
                .prop_map(|(t_us, bytes)| Record::Rx { t_us, bytes }),
            (t.clone(), proptest::collection::vec(any::<u8>(), 0..40))
                .prop_map(|(t_us, bytes)| Record::Tx { t_us, bytes }),
            (t.clone(), any::<u32>()).prop_map(|(t_us, baud)| Record::Baud { t_us, baud }),
            (t.clone(), -1e3..1e3f64, -1e3..1e3f64, -4.0..4.0f64)
                .prop_map(|(t_us, x, y, theta)| Record::Odometry { t_us, x, y, theta }),
            (t, "[a-z =/0-9.]{0,40}").prop_map(|(t_us, text)| Record::Note { t_us, text }),
        ]
    }

    proptest::proptest! {
        /// Random bit flips in some records and a cut anywhere: every
        /// record untouched by either comes back, in order, and nothing
        /// else does.
        #[test]
        fn flips_and_cuts_never_lose_an_intact_record(
            records in proptest::collection::vec(arbitrary_record(), 1..25),
            flips in proptest::collection::vec((0usize..25, 0usize..10_000, 0u8..8), 0..4),
            cut in proptest::option::of(0usize..100_000),
        ) {
            let mut bytes = MAGIC.to_vec();
            let mut spans = Vec::new();
            for r in &records {
                let start = bytes.len();
                bytes.extend_from_slice(&encode(std::slice::from_ref(r))[8..]);
                spans.push(start..bytes.len());
            }
            let original = bytes.clone();
            for (k, at, bit) in flips {
                let span = spans[k % records.len()].clone();
                let i = span.start + at % span.len();
                bytes[i] ^= 1 << bit;
            }
            // Two flips of the same bit cancel: damaged is what differs.
            let damaged: Vec<bool> = spans
                .iter()
                .map(|span| bytes[span.clone()] != original[span.clone()])
                .collect();
            let end = cut.map_or(bytes.len(), |c| MAGIC.len() + c % (bytes.len() - MAGIC.len() + 1));
            let expected: Vec<Record> = records
                .iter()
                .zip(&spans)
                .zip(&damaged)
                .filter(|((_, span), d)| !**d && span.end <= end)
                .map(|((r, _), _)| r.clone())
                .collect();
            let mut reader = RecordingReader::new(&bytes[..end]).unwrap();
            let mut got = Vec::new();
            let mut guard = 0;
            while let Some(item) = reader.next_record() {
                if let Ok(r) = item {
                    got.push(r);
                }
                guard += 1;
                proptest::prop_assert!(guard < 1000, "the reader does not end");
            }
            proptest::prop_assert_eq!(got, expected);
        }
    }
}
