//! The emulator's paced transmitter: bytes leave at the line rate.
//!
//! Each telegram (or single control byte) is a [`Segment`]. A segment starts
//! when it is ready and the line is free; byte `k` of it has left the UART at
//! `start + (k + 1) · 10 / baud` seconds (start bit, 8 data bits, stop bit).
//! The emulator releases bytes only when their wire time has come, so a host
//! request arriving in the middle of a telegram can cut it, as on the real
//! sensor (protocol notes §2.5).

use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// What a queued segment carries: queued scans are dropped by a request,
/// queued replies are not.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum SegmentKind {
    /// A streamed `B0` scan telegram.
    Scan,
    /// ACK/NAK bytes and reply telegrams.
    Reply,
}

/// Something the sensor does once a segment's last byte has left the line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum AfterSent {
    /// Nothing.
    Nothing,
    /// Switch the sensor's UART to this many bits per second (the `A0` of a
    /// baud change is sent at the old rate).
    SwitchBaud(u32),
    /// Reboot (software reset): the `91` leaves first, then the sensor
    /// restarts and sends `90` when ready.
    Reboot,
}

/// One telegram or control byte waiting for the line.
#[derive(Debug)]
pub(crate) struct Segment {
    pub bytes: Vec<u8>,
    pub kind: SegmentKind,
    pub after: AfterSent,
    /// Earliest time the first byte may start (models processing delay).
    pub ready_at: Instant,
}

/// A segment the transmitter finished, for bookkeeping.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Finished {
    pub kind: SegmentKind,
    pub after: AfterSent,
}

/// Time for `bytes` bytes on the wire at `bits_per_s`, 10 bits per byte.
pub(crate) fn wire_time(bytes: usize, bits_per_s: u32) -> Duration {
    let bps = u128::from(bits_per_s.max(1));
    let nanos = (bytes as u128) * 10 * 1_000_000_000 / bps;
    Duration::from_nanos(u64::try_from(nanos).unwrap_or(u64::MAX))
}

/// The queue of segments and the state of the line.
#[derive(Debug)]
pub(crate) struct PacedTx {
    queue: VecDeque<Segment>,
    /// Bytes of the head segment already on the wire.
    head_sent: usize,
    /// When the head segment's first byte started, once known.
    head_start: Option<Instant>,
    /// When the last released byte finished.
    line_free_at: Option<Instant>,
}

impl PacedTx {
    pub fn new() -> Self {
        Self {
            queue: VecDeque::new(),
            head_sent: 0,
            head_start: None,
            line_free_at: None,
        }
    }

    pub fn push(&mut self, segment: Segment) {
        if !segment.bytes.is_empty() {
            self.queue.push_back(segment);
        }
    }

    /// Nothing queued and the last byte is off the line at `now`.
    pub fn is_idle(&self, now: Instant) -> bool {
        self.queue.is_empty() && self.line_free_at.is_none_or(|t| t <= now)
    }

    /// Drops everything queued (power loss, silence).
    pub fn clear(&mut self, now: Instant) {
        self.queue.clear();
        self.head_sent = 0;
        self.head_start = None;
        self.line_free_at = Some(self.line_free_at.map_or(now, |t| t.min(now)));
    }

    fn head_start(&mut self) -> Option<Instant> {
        let head = self.queue.front()?;
        let start = match (self.head_start, self.line_free_at) {
            (Some(s), _) => s,
            (None, Some(free)) => head.ready_at.max(free),
            (None, None) => head.ready_at,
        };
        self.head_start = Some(start);
        Some(start)
    }

    /// Releases the head segment's bytes whose wire time is ≤ `now` into `out`.
    /// Returns the segment's bookkeeping if it completed; the caller applies
    /// [`AfterSent`] (which may change the rate) before calling again.
    pub fn release_head(
        &mut self,
        now: Instant,
        bits_per_s: u32,
        out: &mut Vec<u8>,
    ) -> Option<Finished> {
        let start = self.head_start()?;
        let head = self.queue.front()?;
        let total = head.bytes.len();
        if now < start {
            return None;
        }
        let elapsed = now - start;
        let per_byte = wire_time(1, bits_per_s);
        let done =
            usize::try_from(elapsed.as_nanos() / per_byte.as_nanos().max(1)).unwrap_or(usize::MAX);
        let done = done.min(total);
        // Recompute exactly to avoid drift from the per-byte rounding.
        let mut done_exact = done;
        while done_exact < total && start + wire_time(done_exact + 1, bits_per_s) <= now {
            done_exact += 1;
        }
        while done_exact > 0 && start + wire_time(done_exact, bits_per_s) > now {
            done_exact -= 1;
        }
        if done_exact > self.head_sent {
            out.extend_from_slice(&head.bytes[self.head_sent..done_exact]);
            self.head_sent = done_exact;
            self.line_free_at = Some(start + wire_time(done_exact, bits_per_s));
        }
        if self.head_sent < total {
            return None;
        }
        let finished = Finished {
            kind: head.kind,
            after: head.after,
        };
        self.queue.pop_front();
        self.head_sent = 0;
        self.head_start = None;
        Some(finished)
    }

    /// A host request arrived: any telegram on the line is cut (protocol
    /// notes §2.5), queued scans are dropped; replies not yet started still
    /// go out, and so does a reply whose completion triggers an action (a
    /// baud switch or a reboot), which the sensor has already committed to.
    /// Call after releasing everything due. Returns the kind of the
    /// telegram cut after some of its bytes had left, if any.
    pub fn interrupt(&mut self) -> Option<SegmentKind> {
        let mut cut = None;
        if let Some(head) = self.queue.front() {
            let started = self.head_sent > 0;
            let droppable =
                head.kind == SegmentKind::Scan || (started && head.after == AfterSent::Nothing);
            if droppable {
                cut = started.then_some(head.kind);
                self.queue.pop_front();
                self.head_sent = 0;
                self.head_start = None;
            }
        }
        self.queue.retain(|s| s.kind != SegmentKind::Scan);
        cut
    }

    /// When the last released byte finished.
    pub fn line_free_at(&self) -> Option<Instant> {
        self.line_free_at
    }

    /// When the head segment will have fully left the line.
    pub fn next_completion(&mut self, bits_per_s: u32) -> Option<Instant> {
        let start = self.head_start()?;
        let len = self.queue.front()?.bytes.len();
        Some(start + wire_time(len, bits_per_s))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seg(bytes: &[u8], kind: SegmentKind, at: Instant) -> Segment {
        Segment {
            bytes: bytes.to_vec(),
            kind,
            after: AfterSent::Nothing,
            ready_at: at,
        }
    }

    #[test]
    fn wire_time_is_ten_bits_per_byte() {
        assert_eq!(wire_time(1, 500_000), Duration::from_micros(20));
        assert_eq!(wire_time(732, 500_000), Duration::from_micros(14_640));
        assert_eq!(wire_time(96, 9600), Duration::from_millis(100));
    }

    #[test]
    fn bytes_leave_only_when_due() {
        let t0 = Instant::now();
        let mut tx = PacedTx::new();
        tx.push(seg(&[1, 2, 3, 4], SegmentKind::Reply, t0));
        let mut out = Vec::new();
        assert_eq!(tx.release_head(t0, 9600, &mut out), None);
        assert!(out.is_empty());
        tx.release_head(t0 + wire_time(2, 9600), 9600, &mut out);
        assert_eq!(out, [1, 2]);
        let f = tx.release_head(t0 + Duration::from_secs(1), 9600, &mut out);
        assert_eq!(out, [1, 2, 3, 4]);
        assert_eq!(f.map(|f| f.kind), Some(SegmentKind::Reply));
        assert!(tx.is_idle(t0 + Duration::from_secs(1)));
    }

    #[test]
    fn second_segment_waits_for_the_line() {
        let t0 = Instant::now();
        let mut tx = PacedTx::new();
        tx.push(seg(&[1; 10], SegmentKind::Reply, t0));
        tx.push(seg(&[2; 10], SegmentKind::Reply, t0));
        let mut out = Vec::new();
        let end1 = tx.next_completion(9600);
        assert_eq!(end1, Some(t0 + wire_time(10, 9600)));
        tx.release_head(t0 + wire_time(10, 9600), 9600, &mut out);
        assert_eq!(
            tx.next_completion(9600),
            Some(t0 + wire_time(10, 9600) + wire_time(10, 9600))
        );
    }

    #[test]
    fn request_cuts_a_reply_in_flight_but_not_one_waiting() {
        let t0 = Instant::now();
        let mut tx = PacedTx::new();
        tx.push(seg(&[1; 20], SegmentKind::Reply, t0));
        tx.push(seg(&[2; 5], SegmentKind::Reply, t0));
        let mut out = Vec::new();
        tx.release_head(t0 + wire_time(10, 9600), 9600, &mut out);
        assert_eq!(tx.interrupt(), Some(SegmentKind::Reply));
        tx.release_head(t0 + Duration::from_secs(1), 9600, &mut out);
        assert_eq!(out, [[1; 10].as_slice(), &[2; 5]].concat());
        assert_eq!(tx.interrupt(), None);
    }

    #[test]
    fn request_cuts_a_scan_in_flight() {
        let t0 = Instant::now();
        let mut tx = PacedTx::new();
        tx.push(seg(&[7; 100], SegmentKind::Scan, t0));
        let mut out = Vec::new();
        tx.release_head(t0 + wire_time(30, 38_400), 38_400, &mut out);
        assert_eq!(out.len(), 30);
        assert_eq!(tx.interrupt(), Some(SegmentKind::Scan));
        tx.push(seg(&[6], SegmentKind::Reply, t0 + wire_time(30, 38_400)));
        let f = tx.release_head(t0 + Duration::from_secs(1), 38_400, &mut out);
        assert_eq!(out.len(), 31);
        assert_eq!(out[30], 6);
        assert!(f.is_some());
    }
}
