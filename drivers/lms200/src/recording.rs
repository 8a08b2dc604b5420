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
//! time of the chunk's last byte. A record whose length runs past the end of
//! the file, or whose CRC does not match, ends the readable part: the reader
//! reports the byte offset where the file broke and keeps everything before.
//! Unknown kinds with a good CRC are skipped, so later versions can add kinds
//! without breaking older readers.

use std::io::{self, Read, Write};

use crc::{CRC_32_ISO_HDLC, Crc};

/// File signature: "CLSMREC" followed by the format version.
pub const MAGIC: [u8; 8] = *b"CLSMREC\x01";
/// Largest payload a record may carry; bounds memory on a corrupt length.
pub const MAX_PAYLOAD: u32 = 1 << 20;

const RECORD_CRC: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);
const HEADER_LEN: usize = 1 + 8 + 4;

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
        self.out.write_all(&head)?;
        self.out.write_all(&payload)?;
        self.out.write_all(&digest.finalize().to_le_bytes())?;
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

/// Reads records one by one; after the first error it yields nothing more.
#[derive(Debug)]
pub struct RecordingReader<R: Read> {
    input: R,
    offset: u64,
    failed: bool,
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
            offset: MAGIC.len() as u64,
            failed: false,
        })
    }

    /// Byte offset of the next record in the file.
    pub fn offset(&self) -> u64 {
        self.offset
    }

    /// The next record, `None` at a clean end of file.
    pub fn next_record(&mut self) -> Option<Result<Record, RecordingError>> {
        if self.failed {
            return None;
        }
        let result = self.read_one().transpose();
        if matches!(result, Some(Err(_))) {
            self.failed = true;
        }
        result
    }

    fn read_one(&mut self) -> Result<Option<Record>, RecordingError> {
        loop {
            let start = self.offset;
            let mut head = [0u8; HEADER_LEN];
            let n = read_full(&mut self.input, &mut head)?;
            if n == 0 {
                return Ok(None);
            }
            if n < HEADER_LEN {
                return Err(RecordingError::Truncated {
                    offset: start,
                    what: "record header cut short",
                });
            }
            let kind = head[0];
            let t_us = i64::from_le_bytes(copy_array(&head[1..9]));
            let len = u32::from_le_bytes(copy_array(&head[9..13]));
            if len > MAX_PAYLOAD {
                return Err(RecordingError::Corrupt {
                    offset: start,
                    what: format!("record length {len} exceeds {MAX_PAYLOAD}"),
                });
            }
            let mut payload = vec![0u8; len as usize];
            if read_full(&mut self.input, &mut payload)? < payload.len() {
                return Err(RecordingError::Truncated {
                    offset: start,
                    what: "record payload cut short",
                });
            }
            let mut crc = [0u8; 4];
            if read_full(&mut self.input, &mut crc)? < crc.len() {
                return Err(RecordingError::Truncated {
                    offset: start,
                    what: "record checksum cut short",
                });
            }
            let mut digest = RECORD_CRC.digest();
            digest.update(&head);
            digest.update(&payload);
            if digest.finalize() != u32::from_le_bytes(crc) {
                return Err(RecordingError::Corrupt {
                    offset: start,
                    what: "record checksum mismatch".into(),
                });
            }
            self.offset = start + (HEADER_LEN + payload.len() + crc.len()) as u64;
            let corrupt = |what: &str| RecordingError::Corrupt {
                offset: start,
                what: what.to_string(),
            };
            let record = match kind {
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
                        .map_err(|_| corrupt("baud record is not 4 bytes"))?;
                    Record::Baud {
                        t_us,
                        baud: u32::from_le_bytes(bytes),
                    }
                }
                4 => {
                    if payload.len() != 24 {
                        return Err(corrupt("odometry record is not 24 bytes"));
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
                    text: String::from_utf8(payload).map_err(|_| corrupt("note is not UTF-8"))?,
                },
                // A later version's record kind: skip it, its CRC was good.
                _ => continue,
            };
            return Ok(Some(record));
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
    fn bit_flip_is_reported_as_corruption() {
        let mut bytes = encode(&sample());
        bytes[8 + 13 + 3] ^= 0x01; // inside the first note's text
        let mut reader = RecordingReader::new(bytes.as_slice()).unwrap();
        assert!(matches!(
            reader.next_record(),
            Some(Err(RecordingError::Corrupt { offset: 8, .. }))
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
}
