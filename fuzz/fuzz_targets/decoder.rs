//! Arbitrary bytes in arbitrary chunk splits through both decoders.
//!
//! Invariants: nothing panics; every delivered telegram re-encodes to
//! exactly the input bytes it was decoded from (the decoder consumes the
//! input in order, so those are the last bytes the counters account for);
//! a dropped run has at least one byte; the counters account for every
//! pushed byte.
//!
//! Input layout: byte 0 seeds the chunk sizes, byte 1 picks a scan
//! expectation (or none), the rest is the line.

#![no_main]

use libfuzzer_sys::fuzz_target;
use lms200::{
    DecodeEvent, Decoder, DecoderStats, MeasuringMode, RequestDecoder, RequestEvent, ScanShape,
    Units, Variant,
};

/// Chunk lengths from a seed: 1..=64 bytes, varying along the input.
fn chunks(data: &[u8], seed: u8) -> Vec<&[u8]> {
    let mut out = Vec::new();
    let mut rest = data;
    let mut state = u32::from(seed) | 1;
    while !rest.is_empty() {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        let len = (state % 64 + 1) as usize;
        let (head, tail) = rest.split_at(len.min(rest.len()));
        out.push(head);
        rest = tail;
    }
    out
}

fn shape(selector: u8) -> Option<ScanShape> {
    if selector & 0x80 == 0 {
        return None;
    }
    Some(ScanShape {
        variant: Variant::ALL[usize::from(selector) % Variant::ALL.len()],
        units: if selector & 1 == 0 {
            Units::Cm
        } else {
            Units::Mm
        },
        real_time_indices: selector & 2 != 0,
        mode: MeasuringMode::ALL[usize::from(selector >> 2) % MeasuringMode::ALL.len()],
    })
}

fn check_stats(stats: &DecoderStats, buffered: usize, pushed: usize) {
    assert_eq!(stats.bytes_in, pushed as u64);
    assert_eq!(stats.bytes_in, stats.bytes_accounted() + buffered as u64);
}

/// The input bytes the last event consumed, per the counters.
fn consumed<'a>(line: &'a [u8], stats: &DecoderStats, len: usize) -> &'a [u8] {
    let end = stats.bytes_accounted() as usize;
    &line[end - len..end]
}

fuzz_target!(|input: &[u8]| {
    let [seed, selector, line @ ..] = input else {
        return;
    };

    let mut decoder = Decoder::new();
    decoder.set_expectation(shape(*selector));
    for (i, mut chunk) in chunks(line, *seed).into_iter().enumerate() {
        while !chunk.is_empty() {
            let taken = decoder.push(chunk);
            chunk = &chunk[taken..];
            while let Some(event) = decoder.poll() {
                match event {
                    DecodeEvent::Reply(frame) => {
                        let bytes = frame.encode().expect("a decoded reply re-encodes");
                        assert_eq!(consumed(line, decoder.stats(), bytes.len()), &bytes[..]);
                    }
                    DecodeEvent::Dropped { bytes, .. } => assert!(bytes > 0),
                    DecodeEvent::Ack => assert_eq!(consumed(line, decoder.stats(), 1), [0x06]),
                    DecodeEvent::Nak => assert_eq!(consumed(line, decoder.stats(), 1), [0x15]),
                }
            }
        }
        if i % 7 == 6 {
            decoder.abandon_incomplete();
        }
    }
    check_stats(decoder.stats(), decoder.buffered(), line.len());

    let mut requests = RequestDecoder::new();
    for mut chunk in chunks(line, seed.wrapping_add(1)) {
        while !chunk.is_empty() {
            let taken = requests.push(chunk);
            chunk = &chunk[taken..];
            while let Some(event) = requests.poll() {
                match event {
                    RequestEvent::Request { address, request } => {
                        let mut bytes = Vec::new();
                        request
                            .encode_into(address, &mut bytes)
                            .expect("a decoded request re-encodes");
                        assert_eq!(consumed(line, requests.stats(), bytes.len()), &bytes[..]);
                    }
                    RequestEvent::Dropped { bytes, .. } => assert!(bytes > 0),
                }
            }
        }
    }
    check_stats(requests.stats(), requests.buffered(), line.len());
});
