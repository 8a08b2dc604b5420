//! Telegram framing shared by both directions (TL §4.2).
//!
//! ```text
//! host -> LMS:  STX ADR LEN_lo LEN_hi CMD DATA[n]        CRC_lo CRC_hi   LEN = 1 + n
//! LMS -> host:  STX ADR LEN_lo LEN_hi CMD DATA[n] STATUS CRC_lo CRC_hi   LEN = 1 + n + 1
//! ```
//! The CRC covers STX through the byte before it. No ETX: `02`, `06`, `15`
//! may appear in DATA, only LEN delimits a telegram. ACK `06` and NAK `15`
//! are single bytes outside telegrams.
//!
//! Also home of `Framer`, the resynchronising frame finder both decoders
//! wrap; its rules are described in [`crate::decoder`].

use crate::crc::crc16;
use crate::error::{DropReason, EncodeError, Implausibility};
use crate::reply::SCAN_CODE;
use crate::scan::ScanShape;

/// Start of every telegram.
pub const STX: u8 = 0x02;
/// Single-byte acknowledge of a valid request.
pub const ACK: u8 = 0x06;
/// Single-byte refusal of a request with a bad CRC.
pub const NAK: u8 = 0x15;
/// Address the host sends to: `00` reaches any LMS (all drivers use it).
pub const BROADCAST_ADDRESS: u8 = 0x00;
/// Bit the LMS sets in the address of every reply (`00` → `80`).
pub const REPLY_ADDRESS_BIT: u8 = 0x80;
/// STX, ADR and the two LEN bytes.
pub const HEADER_LEN: usize = 4;
/// The two CRC bytes.
pub const CRC_LEN: usize = 2;
/// Longest telegram: 100°/0.25° scan with real-time indices (TL Table 10-16).
pub const MAX_FRAME_LEN: usize = 814;
/// Largest LEN field that fits in [`MAX_FRAME_LEN`].
pub const MAX_LEN_FIELD: u16 = (MAX_FRAME_LEN - HEADER_LEN - CRC_LEN) as u16;

/// Which way a telegram travels; decides the status byte and address rules.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Direction {
    /// Host to LMS: no status byte, address bit 7 clear.
    HostToSensor,
    /// LMS to host: status byte before the CRC, address bit 7 set.
    SensorToHost,
}

impl Direction {
    /// Smallest LEN field: the command byte, plus the status for replies.
    pub const fn min_len_field(self) -> u16 {
        match self {
            Direction::HostToSensor => 1,
            Direction::SensorToHost => 2,
        }
    }

    /// Whether `address` is one this direction can carry.
    pub const fn address_plausible(self, address: u8) -> bool {
        match self {
            Direction::HostToSensor => address & REPLY_ADDRESS_BIT == 0,
            Direction::SensorToHost => address & REPLY_ADDRESS_BIT != 0,
        }
    }
}

/// Frame length (STX through CRC) for a LEN field.
pub const fn frame_len(len_field: u16) -> usize {
    HEADER_LEN + len_field as usize + CRC_LEN
}

/// Appends a complete telegram to `out`: `parts` are concatenated into
/// CMD + DATA, `status` (replies only) goes before the CRC.
pub(crate) fn encode_frame(
    address: u8,
    parts: &[&[u8]],
    status: Option<u8>,
    out: &mut Vec<u8>,
) -> Result<(), EncodeError> {
    let body_len: usize =
        parts.iter().map(|p| p.len()).sum::<usize>() + usize::from(status.is_some());
    let total = HEADER_LEN + body_len + CRC_LEN;
    if total > MAX_FRAME_LEN {
        return Err(EncodeError::TooLong {
            len: total,
            max: MAX_FRAME_LEN,
        });
    }
    // Fits in u16: bounded by MAX_FRAME_LEN above.
    let len_field = body_len as u16;
    let start = out.len();
    out.reserve(total);
    out.push(STX);
    out.push(address);
    out.extend_from_slice(&len_field.to_le_bytes());
    for part in parts {
        out.extend_from_slice(part);
    }
    if let Some(status) = status {
        out.push(status);
    }
    let crc = crc16(&out[start..]);
    out.extend_from_slice(&crc.to_le_bytes());
    Ok(())
}

/// Bytes a decoder buffers at most: several telegrams, so 4 KiB reads go in
/// whole while a partial telegram waits.
pub const BUFFER_CAPACITY: usize = 8 * 1024;
const _: () = assert!(BUFFER_CAPACITY >= 2 * MAX_FRAME_LEN);

/// Counters of a decoder. Every pushed byte ends up in exactly one of
/// `frame_bytes`, `acks`, `naks`, `dropped_bytes`, `junk_bytes`, or is
/// still buffered.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DecoderStats {
    /// Bytes accepted by `push`.
    pub bytes_in: u64,
    /// Telegrams delivered.
    pub frames_ok: u64,
    /// Bytes of delivered telegrams.
    pub frame_bytes: u64,
    /// ACK bytes.
    pub acks: u64,
    /// NAK bytes.
    pub naks: u64,
    /// Candidates dropped for a bad CRC.
    pub bad_crc: u64,
    /// Candidates dropped for an impossible LEN.
    pub impossible_length: u64,
    /// Candidates dropped for a LEN that is not the expected scan's.
    pub length_mismatch: u64,
    /// Candidates dropped as implausible.
    pub implausible: u64,
    /// Truncated telegrams.
    pub truncated: u64,
    /// Bytes dropped with rejected or truncated candidates.
    pub dropped_bytes: u64,
    /// Bytes between telegrams that were neither STX, ACK nor NAK.
    pub junk_bytes: u64,
}

impl DecoderStats {
    pub(crate) fn record_drop(&mut self, reason: DropReason, bytes: usize) {
        let bytes = bytes as u64;
        match reason {
            DropReason::UnexpectedByte => {
                self.junk_bytes += bytes;
                return;
            }
            DropReason::BadCrc => self.bad_crc += 1,
            DropReason::ImpossibleLength { .. } => self.impossible_length += 1,
            DropReason::LengthMismatch { .. } => self.length_mismatch += 1,
            DropReason::Implausible(_) => self.implausible += 1,
            DropReason::Truncated => self.truncated += 1,
        }
        self.dropped_bytes += bytes;
    }

    /// Bytes accounted for by events so far (all but the buffered ones).
    pub const fn bytes_accounted(&self) -> u64 {
        self.frame_bytes + self.acks + self.naks + self.dropped_bytes + self.junk_bytes
    }
}

/// What the framing rules make of the bytes at one STX.
pub(crate) enum Verdict<T> {
    /// A telegram of this many bytes, checked and parsed.
    Frame(T, usize),
    /// Not enough bytes yet: judging it needs the buffer to reach this
    /// index.
    Incomplete(usize),
    /// The header alone rules it out: drop the STX.
    RejectHeader(DropReason),
    /// All its bytes arrived but it fails the CRC or content checks; the
    /// second field is the frame length its LEN claimed.
    RejectFrame(DropReason, usize),
}

/// Framer output before direction-specific wrapping.
pub(crate) enum FramerEvent<T> {
    Control(u8),
    Frame(T),
    Dropped { reason: DropReason, bytes: usize },
}

/// The direction-independent framing state: bounded buffer, resync, stats.
#[derive(Debug, Clone)]
pub(crate) struct Framer {
    pub(crate) direction: Direction,
    pub(crate) buffer: Box<[u8]>,
    /// First unconsumed byte.
    pub(crate) start: usize,
    /// One past the last buffered byte.
    pub(crate) end: usize,
    /// Every STX after `start` and before this index has been judged under
    /// the current shape. A verdict on a complete candidate depends only on
    /// its bytes and the shape, so only the ones still incomplete then
    /// (`pending`) are judged again: each candidate's CRC is computed once,
    /// however its bytes arrive.
    pub(crate) scanned_until: usize,
    /// Ascending positions of the STXs before `scanned_until` that were
    /// incomplete when judged, each with the buffer end it waits for.
    pub(crate) pending: Vec<(usize, usize)>,
    /// No `pending` candidate can be judged before the buffer reaches this
    /// index (a lower bound: stale entries may keep it low).
    pub(crate) pending_ready_at: usize,
    /// Incomplete candidates starting before this index are abandoned.
    pub(crate) abandon_before: usize,
    /// `06`/`15` before this index lie inside a failed telegram: data, not
    /// ACK/NAK.
    pub(crate) suppress_control_before: usize,
    pub(crate) shape: Option<ScanShape>,
    pub(crate) stats: DecoderStats,
    /// CRCs computed, so tests can show each candidate is checked once.
    #[cfg(test)]
    pub(crate) crc_checks: std::cell::Cell<u64>,
}

impl Framer {
    pub(crate) fn new(direction: Direction) -> Framer {
        Framer {
            direction,
            buffer: vec![0; BUFFER_CAPACITY].into_boxed_slice(),
            start: 0,
            end: 0,
            scanned_until: 0,
            pending: Vec::new(),
            pending_ready_at: usize::MAX,
            abandon_before: 0,
            suppress_control_before: 0,
            shape: None,
            stats: DecoderStats::default(),
            #[cfg(test)]
            crc_checks: std::cell::Cell::new(0),
        }
    }

    pub(crate) fn buffered(&self) -> usize {
        self.end - self.start
    }

    pub(crate) fn push(&mut self, bytes: &[u8]) -> usize {
        if self.start == self.end {
            self.start = 0;
            self.end = 0;
            self.forget_judgements();
            self.abandon_before = 0;
            self.suppress_control_before = 0;
        } else if bytes.len() > self.buffer.len() - self.end && self.start > 0 {
            self.compact();
        }
        let taken = bytes.len().min(self.buffer.len() - self.end);
        self.buffer[self.end..self.end + taken].copy_from_slice(&bytes[..taken]);
        self.end += taken;
        self.stats.bytes_in += taken as u64;
        taken
    }

    /// Moves the unconsumed bytes to the front of the buffer.
    fn compact(&mut self) {
        let shift = self.start;
        self.buffer.copy_within(self.start..self.end, 0);
        self.end -= shift;
        self.start = 0;
        self.abandon_before = self.abandon_before.saturating_sub(shift);
        self.suppress_control_before = self.suppress_control_before.saturating_sub(shift);
        self.scanned_until = self.scanned_until.saturating_sub(shift);
        self.pending.retain(|&(at, _)| at > shift);
        for (at, needed) in &mut self.pending {
            *at -= shift;
            *needed -= shift;
        }
        self.pending_ready_at = self.pending_ready_at.saturating_sub(shift);
    }

    /// Forgets every verdict: the bytes or the shape they were made on
    /// changed.
    pub(crate) fn forget_judgements(&mut self) {
        self.scanned_until = 0;
        self.pending.clear();
        self.pending_ready_at = usize::MAX;
    }

    /// Drops every buffered byte, counted as one truncated telegram.
    pub(crate) fn discard_buffered(&mut self) {
        let buffered = self.buffered();
        if buffered > 0 {
            self.stats.record_drop(DropReason::Truncated, buffered);
        }
        self.start = 0;
        self.end = 0;
        self.forget_judgements();
        self.abandon_before = 0;
        self.suppress_control_before = 0;
    }

    fn is_control(&self, byte: u8) -> bool {
        self.direction == Direction::SensorToHost && (byte == ACK || byte == NAK)
    }

    /// Applies the header, CRC and content checks to the candidate at `at`.
    fn judge<T>(
        &self,
        at: usize,
        validate: &impl Fn(&[u8], Option<&ScanShape>) -> Result<T, DropReason>,
    ) -> Verdict<T> {
        let candidate = &self.buffer[at..self.end];
        let Some(&address) = candidate.get(1) else {
            return Verdict::Incomplete(at + 2);
        };
        if !self.direction.address_plausible(address) {
            return Verdict::RejectHeader(DropReason::Implausible(Implausibility::Address(
                address,
            )));
        }
        let Some(&[len_lo, len_hi]) = candidate.get(2..HEADER_LEN) else {
            return Verdict::Incomplete(at + HEADER_LEN);
        };
        let len = u16::from_le_bytes([len_lo, len_hi]);
        if len < self.direction.min_len_field() || len > MAX_LEN_FIELD {
            return Verdict::RejectHeader(DropReason::ImpossibleLength { len });
        }
        if let Some(shape) = &self.shape {
            let Some(&code) = candidate.get(HEADER_LEN) else {
                return Verdict::Incomplete(at + HEADER_LEN + 1);
            };
            if code == SCAN_CODE && len != shape.len_field() {
                return Verdict::RejectHeader(DropReason::LengthMismatch {
                    expected: shape.len_field(),
                    actual: len,
                });
            }
        }
        let total = frame_len(len);
        let Some(frame) = candidate.get(..total) else {
            return Verdict::Incomplete(at + total);
        };
        let (covered, crc) = frame.split_at(total - CRC_LEN);
        #[cfg(test)]
        self.crc_checks.set(self.crc_checks.get() + 1);
        if crc16(covered) != u16::from_le_bytes([crc[0], crc[1]]) {
            return Verdict::RejectFrame(DropReason::BadCrc, total);
        }
        match validate(frame, self.shape.as_ref()) {
            Ok(item) => Verdict::Frame(item, total),
            Err(reason) => Verdict::RejectFrame(reason, total),
        }
    }

    /// Searches the failed or incomplete candidate at `start` for a complete
    /// valid telegram that begins before `limit`; returns its position.
    fn find_inner_telegram<T>(
        &mut self,
        limit: usize,
        validate: &impl Fn(&[u8], Option<&ScanShape>) -> Result<T, DropReason>,
    ) -> Option<usize> {
        let limit = limit.min(self.end);
        let first = self.start + 1;
        // Candidates once incomplete lie before the unscanned bytes: first.
        if self.end >= self.pending_ready_at
            && let Some(found) = self.judge_pending(first, limit, validate)
        {
            return Some(found);
        }
        let mut position = self.scanned_until.max(first);
        while position < limit {
            let Some(offset) = memchr::memchr(STX, &self.buffer[position..limit]) else {
                break;
            };
            let at = position + offset;
            match self.judge(at, validate) {
                Verdict::Frame(..) => {
                    self.scanned_until = at;
                    return Some(at);
                }
                Verdict::Incomplete(needed) => {
                    self.pending.push((at, needed));
                    self.pending_ready_at = self.pending_ready_at.min(needed);
                }
                Verdict::RejectHeader(_) | Verdict::RejectFrame(..) => {}
            }
            position = at + 1;
        }
        self.scanned_until = self.scanned_until.max(limit);
        None
    }

    /// Judges again the pending candidates from `first` up to `limit` whose
    /// bytes arrived; drops the ones now rejected and those before `first`;
    /// returns the first that is a valid telegram.
    fn judge_pending<T>(
        &mut self,
        first: usize,
        limit: usize,
        validate: &impl Fn(&[u8], Option<&ScanShape>) -> Result<T, DropReason>,
    ) -> Option<usize> {
        let mut kept = 0;
        let mut found = None;
        let mut ready_at = usize::MAX;
        for index in 0..self.pending.len() {
            let (at, needed) = self.pending[index];
            let keep = if at < first {
                false
            } else if found.is_some() || at >= limit || needed > self.end {
                true
            } else {
                match self.judge(at, validate) {
                    Verdict::Frame(..) => {
                        found = Some(at);
                        true
                    }
                    Verdict::Incomplete(needed) => {
                        self.pending[index].1 = needed;
                        true
                    }
                    Verdict::RejectHeader(_) | Verdict::RejectFrame(..) => false,
                }
            };
            if keep {
                self.pending[kept] = self.pending[index];
                ready_at = ready_at.min(self.pending[kept].1);
                kept += 1;
            }
        }
        self.pending.truncate(kept);
        self.pending_ready_at = ready_at;
        found
    }

    /// Drops the bytes from `start` up to the telegram found at `inner`,
    /// keeping an ACK/NAK right before it.
    fn cut_before<T>(&mut self, inner: usize) -> Option<FramerEvent<T>> {
        let before = inner - 1;
        let cut = if before > self.start && self.is_control(self.buffer[before]) {
            before
        } else {
            inner
        };
        // A valid telegram follows: the line is in step again.
        self.suppress_control_before = 0;
        self.drop_bytes(DropReason::Truncated, cut - self.start)
    }

    fn drop_bytes<T>(&mut self, reason: DropReason, bytes: usize) -> Option<FramerEvent<T>> {
        self.start += bytes;
        self.stats.record_drop(reason, bytes);
        Some(FramerEvent::Dropped { reason, bytes })
    }

    pub(crate) fn poll<T>(
        &mut self,
        validate: impl Fn(&[u8], Option<&ScanShape>) -> Result<T, DropReason>,
    ) -> Option<FramerEvent<T>> {
        let first = *self.buffer[self.start..self.end].first()?;
        if first == STX {
            return match self.judge(self.start, &validate) {
                Verdict::Frame(item, len) => {
                    self.start += len;
                    self.stats.frames_ok += 1;
                    self.stats.frame_bytes += len as u64;
                    self.suppress_control_before = 0;
                    Some(FramerEvent::Frame(item))
                }
                Verdict::RejectHeader(reason) => self.drop_bytes(reason, 1),
                Verdict::Incomplete(_) if self.start < self.abandon_before => {
                    self.drop_bytes(DropReason::Truncated, 1)
                }
                Verdict::Incomplete(_) => {
                    let inner = self.find_inner_telegram(self.end, &validate)?;
                    self.cut_before(inner)
                }
                Verdict::RejectFrame(reason, claimed) => {
                    let span_end = self.start + claimed;
                    if let Some(inner) = self.find_inner_telegram(span_end, &validate) {
                        return self.cut_before(inner);
                    }
                    // The bytes it claimed are rescanned for telegrams, but
                    // a 06/15 among them is data, not a handshake.
                    self.suppress_control_before = self.suppress_control_before.max(span_end);
                    self.drop_bytes(reason, 1)
                }
            };
        }
        if self.is_control(first) && self.start >= self.suppress_control_before {
            self.start += 1;
            if first == ACK {
                self.stats.acks += 1;
            } else {
                self.stats.naks += 1;
            }
            return Some(FramerEvent::Control(first));
        }
        let pending = &self.buffer[self.start..self.end];
        let junk = if self.direction == Direction::HostToSensor {
            memchr::memchr(STX, pending)
        } else if self.start >= self.suppress_control_before {
            memchr::memchr3(STX, ACK, NAK, pending)
        } else {
            // Inside a failed telegram 06/15 are data up to the suppression end.
            let suppressed = self.suppress_control_before.min(self.end) - self.start;
            memchr::memchr(STX, &pending[..suppressed]).or_else(|| {
                memchr::memchr3(STX, ACK, NAK, &pending[suppressed..]).map(|i| i + suppressed)
            })
        }
        .unwrap_or(pending.len());
        self.drop_bytes(DropReason::UnexpectedByte, junk)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // tests may unwrap: a panic is a failure
mod tests {
    use super::*;

    #[test]
    fn encodes_status_request_vector() {
        let mut out = Vec::new();
        encode_frame(BROADCAST_ADDRESS, &[&[0x31]], None, &mut out).unwrap();
        assert_eq!(out, [0x02, 0x00, 0x01, 0x00, 0x31, 0x15, 0x12]);
    }

    #[test]
    fn encodes_reply_with_status() {
        let mut out = Vec::new();
        encode_frame(0x80, &[&[0x92]], Some(0x10), &mut out).unwrap();
        assert_eq!(out, [0x02, 0x80, 0x02, 0x00, 0x92, 0x10, 0x7F, 0x33]);
    }

    #[test]
    fn refuses_frames_longer_than_the_maximum() {
        let mut out = Vec::new();
        let data = vec![0u8; MAX_FRAME_LEN];
        let err = encode_frame(0x80, &[&[0xB0], &data], Some(0x10), &mut out).unwrap_err();
        assert!(matches!(err, EncodeError::TooLong { .. }));
        assert!(out.is_empty());
        let fits = vec![0u8; usize::from(MAX_LEN_FIELD) - 2];
        encode_frame(0x80, &[&[0xB0], &fits], Some(0x10), &mut out).unwrap();
        assert_eq!(out.len(), MAX_FRAME_LEN);
    }

    #[test]
    fn address_rules_per_direction() {
        assert!(Direction::SensorToHost.address_plausible(0x80));
        assert!(Direction::SensorToHost.address_plausible(0x81));
        assert!(!Direction::SensorToHost.address_plausible(0x00));
        assert!(Direction::HostToSensor.address_plausible(0x00));
        assert!(!Direction::HostToSensor.address_plausible(0x80));
    }
}
