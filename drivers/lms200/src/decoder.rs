//! Streaming, sans-IO telegram decoders for both directions.
//!
//! Bytes go in with `push` (any chunk size), events come out of `poll`.
//! The framing rules (TL §4.2, protocol notes §1 and §4):
//!
//! - between telegrams, `06` is ACK and `15` is NAK (LMS → host only);
//!   `02` starts a candidate; anything else is junk, reported in runs;
//! - a candidate is checked as soon as its bytes arrive: address bit 7,
//!   LEN bounds, LEN against the expected scan shape, CRC, then content;
//! - on any failure only the candidate's STX is dropped and scanning resumes
//!   at the next byte, so an intact telegram hidden inside a false candidate
//!   (a `02 80` inside scan data) is never lost;
//! - while a candidate is incomplete, or when it fails, the bytes inside it
//!   are searched for a complete valid telegram: if one starts there, the
//!   candidate was cut off (the host interrupted streaming, TL §4.3) and
//!   everything before the new telegram is dropped as
//!   [`DropReason::Truncated`], except an ACK/NAK right before it;
//! - after a candidate fails its CRC or content checks, `06`/`15` within the
//!   length it claimed are data, not handshakes (a corrupted scan would
//!   otherwise spray false ACKs), until a valid telegram is found.
//!
//! The CRC misses `e`/`e<<1` two-byte errors, hence the plausibility checks
//! on top of it (see [`ScanShape`]). The buffer has a fixed capacity larger
//! than the longest telegram; `push` takes what fits and says how much, so it
//! cannot overflow, and a pending candidate always fits.

use crate::command::Request;
pub use crate::error::{DropReason, Implausibility};
use crate::frame::{ACK, CRC_LEN, Direction, Framer, FramerEvent, HEADER_LEN};
pub use crate::frame::{BUFFER_CAPACITY, DecoderStats};
use crate::reply::{Reply, ReplyFrame};
pub use crate::scan::ScanShape;
use crate::variant::Status;

/// One result of [`Decoder::poll`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DecodeEvent {
    /// A single `06` between telegrams: the last request was accepted.
    Ack,
    /// A single `15` between telegrams: the last request had a bad CRC.
    Nak,
    /// A complete, checked reply telegram.
    Reply(ReplyFrame),
    /// `bytes` input bytes were discarded.
    Dropped {
        /// Why.
        reason: DropReason,
        /// How many bytes (1 for a rejected candidate: only its STX).
        bytes: usize,
    },
}

/// One result of [`RequestDecoder::poll`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RequestEvent {
    /// A complete request with a valid CRC.
    Request {
        /// Address byte (`00` broadcast, `01`..`7F` individual).
        address: u8,
        /// The request.
        request: Request,
    },
    /// `bytes` input bytes were discarded.
    Dropped {
        /// Why (a [`DropReason::BadCrc`] is what the LMS answers with NAK).
        reason: DropReason,
        /// How many bytes.
        bytes: usize,
    },
}

/// Checks and parses a reply frame that passed the CRC.
fn validate_reply(frame: &[u8], shape: Option<&ScanShape>) -> Result<ReplyFrame, DropReason> {
    let implausible = |what| Err(DropReason::Implausible(what));
    let body = &frame[HEADER_LEN..frame.len() - CRC_LEN - 1];
    let status = Status(frame[frame.len() - CRC_LEN - 1]);
    let reply = Reply::from_body(body)
        .map_err(|e| DropReason::Implausible(Implausibility::Malformed(e)))?;
    if let Reply::ScanData(scan) = &reply {
        if scan.count_word.units().is_none() {
            return implausible(Implausibility::ReservedUnits(scan.count_word.0));
        }
        if let Some(shape) = shape {
            shape.check(scan).map_err(DropReason::Implausible)?;
        }
    }
    Ok(ReplyFrame {
        address: frame[1],
        status,
        reply,
    })
}

/// Parses a request frame that passed the CRC.
fn validate_request(frame: &[u8], _shape: Option<&ScanShape>) -> Result<(u8, Request), DropReason> {
    let body = &frame[HEADER_LEN..frame.len() - CRC_LEN];
    let request = Request::from_body(body)
        .map_err(|e| DropReason::Implausible(Implausibility::Malformed(e)))?;
    Ok((frame[1], request))
}

/// The stream methods both decoders share around their `framer`; only the
/// event type and the reason to abandon a candidate differ. A macro rather
/// than a generic keeps both public types and their docs exactly as they are.
macro_rules! stream_methods {
    ($event:ty, $(#[$abandon_doc:meta])*) => {
        /// Pushes all of `bytes`, handing every event to `on_event`.
        pub fn feed(&mut self, mut bytes: &[u8], mut on_event: impl FnMut($event)) {
            loop {
                let taken = self.push(bytes);
                bytes = &bytes[taken..];
                while let Some(event) = self.poll() {
                    on_event(event);
                }
                if bytes.is_empty() {
                    return;
                }
            }
        }

        $(#[$abandon_doc])*
        pub fn abandon_incomplete(&mut self) {
            self.framer.abandon_before = self.framer.end;
        }

        /// Discards all buffered bytes (e.g. after a line speed change); they
        /// are counted as dropped.
        pub fn clear(&mut self) {
            self.framer.discard_buffered();
        }

        /// Bytes buffered and not yet turned into events.
        pub fn buffered(&self) -> usize {
            self.framer.buffered()
        }

        /// Counters since creation.
        pub fn stats(&self) -> &DecoderStats {
            &self.framer.stats
        }
    };
}

/// Decoder of the LMS → host byte stream.
#[derive(Debug, Clone)]
pub struct Decoder {
    framer: Framer,
}

impl Default for Decoder {
    fn default() -> Self {
        Decoder::new()
    }
}

impl Decoder {
    /// A decoder with no scan expectation (any plausible `B0` LEN accepted).
    pub fn new() -> Decoder {
        Decoder {
            framer: Framer::new(Direction::SensorToHost),
        }
    }

    /// A decoder that accepts only complete scans of `shape`.
    pub fn with_expectation(shape: ScanShape) -> Decoder {
        let mut decoder = Decoder::new();
        decoder.set_expectation(Some(shape));
        decoder
    }

    /// Sets (or clears) the scan shape `B0` telegrams must have. Clear it for
    /// interlaced streaming (`20 2A`, `30 08`), whose partial scans differ.
    pub fn set_expectation(&mut self, shape: Option<ScanShape>) {
        self.framer.shape = shape;
        self.framer.forget_judgements();
    }

    /// The scan shape currently expected.
    pub fn expectation(&self) -> Option<ScanShape> {
        self.framer.shape
    }

    /// Buffers as many of `bytes` as fit and returns how many; call
    /// [`Decoder::poll`] until `None`, then push the rest.
    #[must_use = "bytes beyond the returned count were not taken"]
    pub fn push(&mut self, bytes: &[u8]) -> usize {
        self.framer.push(bytes)
    }

    /// The next event, or `None` when more bytes are needed.
    pub fn poll(&mut self) -> Option<DecodeEvent> {
        Some(match self.framer.poll(validate_reply)? {
            FramerEvent::Control(ACK) => DecodeEvent::Ack,
            FramerEvent::Control(_) => DecodeEvent::Nak,
            FramerEvent::Frame(frame) => DecodeEvent::Reply(frame),
            FramerEvent::Dropped { reason, bytes } => DecodeEvent::Dropped { reason, bytes },
        })
    }

    stream_methods! {
        DecodeEvent,
        /// Gives up on every incomplete candidate buffered now: call it when the
        /// line has been silent longer than the LMS's 14 ms inter-byte gap. Each
        /// one's STX is dropped as [`DropReason::Truncated`] by the next polls.
    }
}

/// Decoder of the host → LMS byte stream (the emulator's side). Same resync
/// rules; no ACK/NAK bytes in this direction, so `06` and `15` are junk.
#[derive(Debug, Clone)]
pub struct RequestDecoder {
    framer: Framer,
}

impl Default for RequestDecoder {
    fn default() -> Self {
        RequestDecoder::new()
    }
}

impl RequestDecoder {
    /// A fresh decoder.
    pub fn new() -> RequestDecoder {
        RequestDecoder {
            framer: Framer::new(Direction::HostToSensor),
        }
    }

    /// Buffers as many of `bytes` as fit and returns how many.
    #[must_use = "bytes beyond the returned count were not taken"]
    pub fn push(&mut self, bytes: &[u8]) -> usize {
        self.framer.push(bytes)
    }

    /// The next event, or `None` when more bytes are needed.
    pub fn poll(&mut self) -> Option<RequestEvent> {
        Some(match self.framer.poll(validate_request)? {
            FramerEvent::Frame((address, request)) => RequestEvent::Request { address, request },
            FramerEvent::Dropped { reason, bytes } => RequestEvent::Dropped { reason, bytes },
            // The host direction has no control bytes; the framer never
            // reports one, but map it to junk rather than assume.
            FramerEvent::Control(_) => RequestEvent::Dropped {
                reason: DropReason::UnexpectedByte,
                bytes: 1,
            },
        })
    }

    stream_methods! {
        RequestEvent,
        /// Gives up on every incomplete request buffered now: the LMS ignores a
        /// request with more than 6 ms between its bytes.
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may unwrap: a panic is a failure
mod tests {
    use super::*;
    use crate::error::ParseError;
    use crate::frame::STX;
    use crate::reply::ModeChangeResult;

    /// Damaged bytes pushed one at a time: a request claiming more bytes
    /// than arrive, a second one inside it, then short requests whose CRCs
    /// fail. Each short one is checked once, not on every push (which costs
    /// 35,312 CRCs here, growing with the square of the bytes).
    #[test]
    fn a_damaged_candidate_is_checked_once_however_its_bytes_arrive() {
        let mut line = vec![STX, 0x00, 0x20, 0x03, 0x20, STX, 0x00, 0x10, 0x03, 0x20];
        for i in 0..100u8 {
            let body = [STX, 0x00, 0x01, 0x00, i];
            let crc = crate::crc::crc16(&body) ^ 1;
            line.extend(body);
            line.extend(crc.to_le_bytes());
        }
        let mut decoder = RequestDecoder::new();
        for byte in &line {
            assert_eq!(decoder.push(std::slice::from_ref(byte)), 1);
            while let Some(event) = decoder.poll() {
                assert!(!matches!(event, RequestEvent::Request { .. }));
            }
        }
        // At most once per STX (a CRC byte may be one too).
        let candidates = line.iter().filter(|&&b| b == STX).count() as u64;
        let checks = decoder.framer.crc_checks.get();
        assert!((100..=candidates).contains(&checks), "{checks} CRCs");
        assert_eq!(decoder.buffered(), line.len());
    }

    fn mode_ok() -> Vec<u8> {
        Reply::ModeChanged(ModeChangeResult::Success)
            .encode(0x80, Status::OK)
            .unwrap()
    }

    /// Fills the buffer close to capacity so the next push must compact
    /// while a candidate is half received.
    #[test]
    fn compaction_keeps_a_half_received_telegram() {
        let frame = mode_ok();
        let mut decoder = Decoder::new();
        let junk = vec![0xAA; BUFFER_CAPACITY - 4];
        assert_eq!(decoder.push(&junk), junk.len());
        assert_eq!(decoder.push(&frame[..4]), 4);
        let mut events = Vec::new();
        while let Some(e) = decoder.poll() {
            events.push(e);
        }
        assert_eq!(decoder.buffered(), 4);
        assert_eq!(decoder.push(&frame[4..]), frame.len() - 4);
        while let Some(e) = decoder.poll() {
            events.push(e);
        }
        assert_eq!(
            events.first(),
            Some(&DecodeEvent::Dropped {
                reason: DropReason::UnexpectedByte,
                bytes: junk.len()
            })
        );
        assert!(matches!(events.last(), Some(DecodeEvent::Reply(_))));
    }

    /// After a failed candidate the search state must survive a compaction
    /// and still find the telegram hidden in it.
    #[test]
    fn hidden_telegram_found_across_a_compaction() {
        let mut stream = vec![0x02, 0x80, 0x00, 0x01]; // false candidate, LEN 256
        stream.extend(vec![0x11; 20]);
        stream.extend(mode_ok());
        let mut decoder = Decoder::new();
        let filler = vec![0xAA; BUFFER_CAPACITY - 10];
        assert_eq!(decoder.push(&filler), filler.len());
        let mut replies = 0;
        decoder.feed(&stream, |e| {
            replies += usize::from(matches!(e, DecodeEvent::Reply(_)))
        });
        assert_eq!(replies, 1);
        let stats = decoder.stats();
        assert_eq!(
            stats.bytes_in,
            stats.bytes_accounted() + decoder.buffered() as u64
        );
    }

    #[test]
    fn control_bytes_inside_a_failed_telegram_are_data() {
        // A reply claiming LEN 6 whose CRC fails, carrying 06 and 15 bytes.
        let mut bad = vec![
            0x02, 0x80, 0x06, 0x00, 0xB1, 0x06, 0x15, 0x06, 0x15, 0x10, 0x00, 0x00,
        ];
        bad.push(0x06); // a real ACK after it
        let mut decoder = Decoder::new();
        let mut events = Vec::new();
        decoder.feed(&bad, |e| events.push(e));
        assert_eq!(
            events
                .iter()
                .filter(|e| matches!(e, DecodeEvent::Ack))
                .count(),
            1
        );
        assert!(!events.contains(&DecodeEvent::Nak));
        assert_eq!(events.last(), Some(&DecodeEvent::Ack));
    }

    #[test]
    fn malformed_body_with_valid_crc_is_implausible() {
        let frame = Reply::Other {
            code: 0xA0,
            data: vec![0x00, 0x00],
        }
        .encode(0x80, Status::OK)
        .unwrap();
        let mut decoder = Decoder::new();
        let mut events = Vec::new();
        decoder.feed(&frame, |e| events.push(e));
        assert!(matches!(
            events[0],
            DecodeEvent::Dropped {
                reason: DropReason::Implausible(Implausibility::Malformed(
                    ParseError::DataLength { code: 0xA0, .. }
                )),
                bytes: 1
            }
        ));
        assert_eq!(decoder.stats().implausible, 1);
    }
}
