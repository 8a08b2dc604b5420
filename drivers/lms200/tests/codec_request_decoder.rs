//! The host → LMS decoder (the emulator's side): every host vector of the
//! protocol notes, bad CRC (what the LMS answers with NAK), ACK/NAK bytes as
//! junk in this direction, reply addresses refused.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic is a failure

use lms200::{DropReason, Implausibility, Request, RequestDecoder, RequestEvent, Variant};

fn hex(text: &str) -> Vec<u8> {
    text.split_whitespace()
        .map(|pair| u8::from_str_radix(pair, 16).unwrap())
        .collect()
}

#[test]
fn request_decoder_reads_every_host_vector() {
    let vectors = [
        "02 00 01 00 31 15 12",
        "02 00 02 00 20 24 34 08",
        "02 00 0A 00 20 00 53 49 43 4B 5F 4C 4D 53 BE C5",
        "02 00 05 00 3B B4 00 32 00 3B 1F",
        "02 00 01 00 10 34 12",
        "02 00 02 00 41 00 D2 69",
    ];
    let stream: Vec<u8> = vectors.iter().flat_map(|v| hex(v)).collect();
    let expected = [
        Request::Status,
        Request::ContinuousAllValues,
        Request::installation_mode(),
        Request::set_variant(Variant::Fov180Res50),
        Request::Reset,
        Request::Other {
            code: 0x41,
            data: vec![0x00],
        },
    ];
    for chunk in [1, 3, 100] {
        let mut decoder = RequestDecoder::new();
        let mut got = Vec::new();
        for piece in stream.chunks(chunk) {
            decoder.feed(piece, |e| got.push(e));
        }
        let requests: Vec<Request> = got
            .into_iter()
            .map(|e| match e {
                RequestEvent::Request {
                    address: 0,
                    request,
                } => request,
                other => panic!("unexpected {other:?}"),
            })
            .collect();
        assert_eq!(requests, expected);
    }
}

#[test]
fn request_decoder_reports_bad_crc_and_treats_ack_as_junk() {
    let mut stream = vec![0x06, 0x15];
    let mut bad = hex("02 00 01 00 31 15 12");
    bad[5] ^= 1;
    stream.extend(&bad);
    stream.extend(hex("02 00 01 00 74 50 12"));
    let mut decoder = RequestDecoder::new();
    let mut events = Vec::new();
    decoder.feed(&stream, |e| events.push(e));
    assert_eq!(
        events[0],
        RequestEvent::Dropped {
            reason: DropReason::UnexpectedByte,
            bytes: 2
        }
    );
    assert_eq!(
        events[1],
        RequestEvent::Dropped {
            reason: DropReason::BadCrc,
            bytes: 1
        }
    );
    assert_eq!(
        events.last(),
        Some(&RequestEvent::Request {
            address: 0,
            request: Request::ReadConfig
        })
    );
    let stats = decoder.stats();
    assert_eq!(stats.bytes_in, stats.bytes_accounted());
}

#[test]
fn request_decoder_refuses_reply_addresses() {
    let reply = hex("02 80 02 00 91 10 79 30");
    let mut decoder = RequestDecoder::new();
    let mut events = Vec::new();
    decoder.feed(&reply, |e| events.push(e));
    assert_eq!(
        events[0],
        RequestEvent::Dropped {
            reason: DropReason::Implausible(Implausibility::Address(0x80)),
            bytes: 1
        }
    );
}
