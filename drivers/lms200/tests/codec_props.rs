//! Property tests of the codec.
//!
//! (a) every `Request` and `Reply` survives encode → decode unchanged;
//! (b) a stream of valid telegrams mixed with garbage and single-bit
//!     corruptions loses no telegram that arrived intact, and never yields
//!     one that overlaps an intact telegram without being it. Frames in (b)
//!     are built here with a reference CRC written straight from the TL
//!     pseudo-code, not the library's.
//!
//! A frame-shaped run inside damaged bytes whose 16-bit CRC happens to
//! match is a valid telegram to any decoder (about one candidate in 65,536
//! passes); (b) therefore locates every delivered telegram in the stream
//! and allows such a one only where it touches no intact telegram.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic is a failure

use lms200::{
    Baud, ConfigBlock, CountWord, DecodeEvent, Decoder, ErrorEntry, ModeChangeResult,
    PermanentBaud, RealTimeIndices, Reply, ReplyFrame, Request, RequestDecoder, RequestEvent, Scan,
    Status,
};
use proptest::prelude::*;

/// Request codes with a typed variant; `Request::Other` avoids them.
const KNOWN_REQUEST_CODES: [u8; 10] = [0x10, 0x20, 0x30, 0x31, 0x32, 0x3A, 0x3B, 0x66, 0x74, 0x77];
/// Reply codes with a typed variant; `Reply::Other` avoids them.
const KNOWN_REPLY_CODES: [u8; 13] = [
    0x90, 0x91, 0x92, 0xA0, 0xB0, 0xB1, 0xB2, 0xBA, 0xBB, 0xE6, 0xF4, 0xF7, 0xB0,
];

/// TL §9 checksum, literally: 16-bit register shifted once per byte, XORed
/// with (previous byte, current byte).
fn reference_crc(bytes: &[u8]) -> u16 {
    let mut crc: u32 = 0;
    let mut previous: u32 = 0;
    for &byte in bytes {
        if crc & 0x8000 != 0 {
            crc = ((crc << 1) & 0xFFFF) ^ 0x8005;
        } else {
            crc = (crc << 1) & 0xFFFF;
        }
        crc ^= (previous << 8) | u32::from(byte);
        previous = u32::from(byte);
    }
    crc as u16
}

/// A reply frame assembled by hand: STX ADR LEN CODE DATA STATUS CRC.
fn reference_reply_bytes(frame: &ReplyFrame) -> Vec<u8> {
    let data = frame.reply.data().unwrap();
    let len = (1 + data.len() + 1) as u16;
    let mut out = vec![
        0x02,
        frame.address,
        len as u8,
        (len >> 8) as u8,
        frame.reply.code(),
    ];
    out.extend(&data);
    out.push(frame.status.0);
    let crc = reference_crc(&out);
    out.push(crc as u8);
    out.push((crc >> 8) as u8);
    out
}

fn password() -> impl Strategy<Value = [u8; 8]> {
    any::<[u8; 8]>()
}

fn config_block() -> impl Strategy<Value = ConfigBlock> {
    prop_oneof![
        proptest::collection::vec(any::<u8>(), 32),
        proptest::collection::vec(any::<u8>(), 34)
    ]
    .prop_map(|bytes| ConfigBlock::from_bytes(&bytes).unwrap())
}

fn request() -> impl Strategy<Value = Request> {
    prop_oneof![
        Just(Request::Reset),
        password().prop_map(|password| Request::InstallationMode { password }),
        Just(Request::DiagnosticMode),
        Just(Request::ContinuousAllValues),
        Just(Request::ValuesOnRequest),
        Just(Request::ContinuousInterlaced),
        password().prop_map(|password| Request::TestPassword { password }),
        proptest::sample::select(Baud::ALL.to_vec()).prop_map(Request::SetBaud),
        Just(Request::OneScan),
        Just(Request::PartialScan),
        Just(Request::Status),
        Just(Request::ErrorList),
        Just(Request::DeviceType),
        (any::<u16>(), any::<u16>()).prop_map(|(fov_deg, resolution_centideg)| {
            Request::SetVariant {
                fov_deg,
                resolution_centideg,
            }
        }),
        proptest::sample::select(vec![
            PermanentBaud::PowerOn9600,
            PermanentBaud::KeepCurrent,
            PermanentBaud::KeepLmsType
        ])
        .prop_map(Request::PermanentBaud),
        Just(Request::ReadConfig),
        config_block().prop_map(Request::WriteConfig),
        (
            any::<u8>().prop_filter("typed code", |c| !KNOWN_REQUEST_CODES.contains(c)),
            proptest::collection::vec(any::<u8>(), 0..40)
        )
            .prop_map(|(code, data)| Request::Other { code, data }),
    ]
}

fn scan() -> impl Strategy<Value = Scan> {
    (
        proptest::collection::vec(any::<u16>(), 0..=401),
        0u16..2,
        any::<bool>(),
        0u16..4,
        proptest::option::of(any::<(u8, u8)>()),
    )
        .prop_map(|(values, units, partial, raster, indices)| {
            let mut word = values.len() as u16 | (units << 14);
            if partial {
                word |= (1 << 13) | (raster << 11);
            }
            Scan {
                count_word: CountWord(word),
                values,
                indices: indices.map(|(scan, telegram)| RealTimeIndices { scan, telegram }),
            }
        })
}

fn bytes(max: usize) -> impl Strategy<Value = Vec<u8>> {
    proptest::collection::vec(any::<u8>(), 0..max)
}

fn reply() -> impl Strategy<Value = Reply> {
    prop_oneof![
        bytes(60).prop_map(Reply::PowerOn),
        Just(Reply::ResetAck),
        Just(Reply::InvalidCommand),
        any::<u8>().prop_map(|b| Reply::ModeChanged(ModeChangeResult::from_code(b))),
        scan().prop_map(Reply::ScanData),
        bytes(160).prop_map(Reply::Status),
        proptest::collection::vec(any::<(u8, u8)>(), 0..10).prop_map(|pairs| Reply::ErrorList(
            pairs
                .into_iter()
                .map(|(kind, number)| ErrorEntry { kind, number })
                .collect()
        )),
        bytes(30).prop_map(Reply::DeviceType),
        (any::<bool>(), any::<u16>(), any::<u16>()).prop_map(
            |(accepted, fov_deg, resolution_centideg)| {
                Reply::VariantChanged {
                    accepted,
                    fov_deg,
                    resolution_centideg,
                }
            }
        ),
        (any::<bool>(), any::<u8>())
            .prop_map(|(accepted, setting)| Reply::PermanentBaud { accepted, setting }),
        config_block().prop_map(Reply::Config),
        (any::<bool>(), config_block())
            .prop_map(|(accepted, config)| Reply::ConfigWritten { accepted, config }),
        (
            any::<u8>().prop_filter("typed code", |c| !KNOWN_REPLY_CODES.contains(c)),
            bytes(60)
        )
            .prop_map(|(code, data)| Reply::Other { code, data }),
    ]
}

fn reply_frame() -> impl Strategy<Value = ReplyFrame> {
    (0x80u8..=0xFF, any::<u8>(), reply()).prop_map(|(address, status, reply)| ReplyFrame {
        address,
        status: Status(status),
        reply,
    })
}

/// A generated (position, bit) flip mapped into a frame of `len` bytes;
/// `None` when there is no flip or it would hit a LEN byte (offsets 2–3).
fn flip_outside_len(flip: Option<(usize, u8)>, len: usize) -> Option<(usize, u8)> {
    flip.map(|(at, bit)| (at % len, bit))
        .filter(|(at, _)| *at != 2 && *at != 3)
}

/// One piece of a test stream.
#[derive(Debug, Clone)]
enum Piece {
    /// A telegram, optionally with one bit flipped at (byte, bit).
    Telegram(ReplyFrame, Option<(usize, u8)>),
    /// Random bytes between telegrams.
    Garbage(Vec<u8>),
    /// An ACK or NAK byte.
    Handshake(bool),
}

/// A request telegram built with the reference CRC.
fn reference_request_bytes(address: u8, request: &Request) -> Vec<u8> {
    let data = request.data();
    let len = (1 + data.len()) as u16;
    let mut bytes = vec![0x02, address, len as u8, (len >> 8) as u8, request.code()];
    bytes.extend(&data);
    let crc = reference_crc(&bytes);
    bytes.extend([crc as u8, (crc >> 8) as u8]);
    bytes
}

/// What one decoder event consumed of the stream, in stream order.
#[derive(Debug, Clone)]
enum Consumed {
    /// A delivered telegram, encoded again; its length on the wire is
    /// read from the LEN bytes there.
    Telegram(Vec<u8>),
    /// Bytes dropped, or a handshake byte.
    Skipped(usize),
}

/// Walks the events along `stream` and checks that every intact telegram
/// (its byte range) was delivered whole, that any other delivered telegram
/// touches no intact one, and that the events and the still buffered bytes
/// account for every byte.
fn check_delivery(
    stream: &[u8],
    intact: &[std::ops::Range<usize>],
    events: &[Consumed],
    buffered: usize,
) -> Result<(), TestCaseError> {
    let mut at = 0;
    let mut delivered = Vec::new();
    for event in events {
        match event {
            Consumed::Skipped(bytes) => at += *bytes,
            Consumed::Telegram(bytes) => {
                prop_assert!(at + 4 <= stream.len(), "telegram past the end at {}", at);
                prop_assert_eq!(stream[at], 0x02, "telegram not at an STX: {}", at);
                let len = usize::from(u16::from_le_bytes([stream[at + 2], stream[at + 3]]));
                let range = at..at + 4 + len + 2;
                prop_assert!(range.end <= stream.len(), "telegram past the end at {}", at);
                let overlapping = intact
                    .iter()
                    .find(|r| r.start < range.end && range.start < r.end);
                if let Some(r) = overlapping {
                    prop_assert_eq!(r, &range, "a false telegram overlaps an intact one");
                    prop_assert_eq!(bytes, &stream[range.clone()], "an intact telegram changed");
                }
                at = range.end;
                delivered.push(range);
            }
        }
    }
    prop_assert_eq!(at + buffered, stream.len(), "bytes unaccounted for");
    for r in intact {
        prop_assert!(delivered.contains(r), "intact telegram at {:?} lost", r);
    }
    Ok(())
}

fn piece() -> impl Strategy<Value = Piece> {
    prop_oneof![
        6 => (reply_frame(), proptest::option::weighted(0.3, (any::<usize>(), 0u8..8)))
            .prop_map(|(frame, flip)| Piece::Telegram(frame, flip)),
        2 => bytes(40).prop_map(Piece::Garbage),
        1 => any::<bool>().prop_map(Piece::Handshake),
    ]
}

proptest! {
    #[test]
    fn every_request_round_trips(request in request(), address in 0u8..0x80) {
        let mut frame = Vec::new();
        request.encode_into(address, &mut frame).unwrap();
        let mut decoder = RequestDecoder::new();
        let mut events = Vec::new();
        decoder.feed(&frame, |e| events.push(e));
        prop_assert_eq!(events, vec![RequestEvent::Request { address, request }]);
    }

    #[test]
    fn every_reply_round_trips(frame in reply_frame()) {
        let bytes = frame.encode().unwrap();
        prop_assert_eq!(&bytes, &reference_reply_bytes(&frame));
        let mut decoder = Decoder::new();
        let mut events = Vec::new();
        decoder.feed(&bytes, |e| events.push(e));
        prop_assert_eq!(events, vec![DecodeEvent::Reply(frame)]);
    }

    /// Single-bit flips go anywhere but the two LEN bytes: a changed LEN
    /// moves the CRC to other bytes, which no 16-bit check can catch with
    /// certainty (and the scan-shape check covers in practice). Every other
    /// single-bit error is caught by this CRC, so the decoder must deliver
    /// exactly the untouched telegrams.
    #[test]
    fn stream_yields_exactly_the_intact_telegrams(
        pieces in proptest::collection::vec(piece(), 0..24),
        chunk in 1usize..300,
    ) {
        let mut stream = Vec::new();
        let mut intact = Vec::new();
        for piece in &pieces {
            match piece {
                Piece::Telegram(frame, flip) => {
                    let mut bytes = reference_reply_bytes(frame);
                    match flip_outside_len(*flip, bytes.len()) {
                        Some((at, bit)) => bytes[at] ^= 1 << bit,
                        None => intact.push(stream.len()..stream.len() + bytes.len()),
                    }
                    stream.extend(bytes);
                }
                Piece::Garbage(bytes) => stream.extend(bytes),
                Piece::Handshake(ack) => stream.push(if *ack { 0x06 } else { 0x15 }),
            }
        }
        let mut decoder = Decoder::new();
        let mut events = Vec::new();
        for piece in stream.chunks(chunk) {
            decoder.feed(piece, |e| {
                events.push(match e {
                    DecodeEvent::Reply(frame) => Consumed::Telegram(reference_reply_bytes(&frame)),
                    DecodeEvent::Dropped { bytes, .. } => Consumed::Skipped(bytes),
                    DecodeEvent::Ack | DecodeEvent::Nak => Consumed::Skipped(1),
                })
            });
        }
        check_delivery(&stream, &intact, &events, decoder.buffered())?;
        let stats = decoder.stats();
        prop_assert_eq!(stats.bytes_in, stream.len() as u64);
        prop_assert_eq!(stats.bytes_in, stats.bytes_accounted() + decoder.buffered() as u64);
    }

    #[test]
    fn request_stream_yields_exactly_the_intact_requests(
        pieces in proptest::collection::vec(
            (request(), proptest::option::weighted(0.3, (any::<usize>(), 0u8..8)), bytes(20)),
            0..16,
        ),
        chunk in 1usize..100,
    ) {
        let mut stream = Vec::new();
        let mut intact = Vec::new();
        for (request, flip, garbage) in &pieces {
            let mut bytes = reference_request_bytes(0x00, request);
            match flip_outside_len(*flip, bytes.len()) {
                Some((at, bit)) => bytes[at] ^= 1 << bit,
                None => intact.push(stream.len()..stream.len() + bytes.len()),
            }
            stream.extend(bytes);
            stream.extend(garbage);
        }
        let mut decoder = RequestDecoder::new();
        let mut events = Vec::new();
        for piece in stream.chunks(chunk) {
            decoder.feed(piece, |e| {
                events.push(match e {
                    RequestEvent::Request { address, request } => {
                        Consumed::Telegram(reference_request_bytes(address, &request))
                    }
                    RequestEvent::Dropped { bytes, .. } => Consumed::Skipped(bytes),
                })
            });
        }
        check_delivery(&stream, &intact, &events, decoder.buffered())?;
    }

    #[test]
    fn library_crc_matches_the_reference(
        data in proptest::collection::vec(any::<u8>(), 0..2000),
        split in any::<usize>(),
    ) {
        prop_assert_eq!(lms200::crc16(&data), reference_crc(&data));
        let split = split % (data.len() + 1);
        let mut streaming = lms200::Crc16::new();
        streaming.update(&data[..split]);
        streaming.update(&data[split..]);
        prop_assert_eq!(streaming.value(), reference_crc(&data));
    }
}
