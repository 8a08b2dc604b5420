//! The decoder checklist: empty input, byte by byte, all at once, every
//! split, two frames in one read, garbage before, bad CRC then good frames,
//! a false `02 80` candidate swallowing the next telegram, a truncated `B0`
//! followed by ACK + `A0`, `02 02 80 …`; plus the plausibility checks.
//! The host → LMS decoder is tested in `codec_request_decoder.rs`.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic is a failure

use lms200::{
    CountWord, DecodeEvent, Decoder, DropReason, Implausibility, MeasuringMode, ModeChangeResult,
    Reply, ReplyFrame, Scan, ScanShape, Status, Units, Variant, crc16,
};

const ACK: u8 = 0x06;
const NAK: u8 = 0x15;

fn hex(text: &str) -> Vec<u8> {
    text.split_whitespace()
        .map(|pair| u8::from_str_radix(pair, 16).unwrap())
        .collect()
}

fn frame(reply: Reply) -> ReplyFrame {
    ReplyFrame {
        address: 0x80,
        status: Status::OK,
        reply,
    }
}

fn mode_ok() -> ReplyFrame {
    frame(Reply::ModeChanged(ModeChangeResult::Success))
}

const SHAPE_180_050_MM: ScanShape = ScanShape {
    variant: Variant::Fov180Res50,
    units: Units::Mm,
    real_time_indices: false,
    mode: MeasuringMode::Bits13FieldsAbDazzle,
};

/// A complete scan of `shape` with distances that vary along the scan.
fn scan_of(shape: &ScanShape, seed: u16) -> ReplyFrame {
    let n = shape.variant.value_count();
    let values = (0..n).map(|i| 300 + (i * 7 + seed) % 4000).collect();
    let indices = shape.real_time_indices.then_some(lms200::RealTimeIndices {
        scan: seed as u8,
        telegram: seed as u8,
    });
    frame(Reply::ScanData(Scan::complete(
        values,
        shape.units,
        indices,
    )))
}

fn bytes(frame: &ReplyFrame) -> Vec<u8> {
    frame.encode().unwrap()
}

/// Feeds `chunks` one after the other, polling after each, and collects all events.
fn decode_chunks<'a>(
    decoder: &mut Decoder,
    chunks: impl IntoIterator<Item = &'a [u8]>,
) -> Vec<DecodeEvent> {
    let mut events = Vec::new();
    for chunk in chunks {
        decoder.feed(chunk, |e| events.push(e));
    }
    let stats = decoder.stats();
    assert_eq!(
        stats.bytes_in,
        stats.bytes_accounted() + decoder.buffered() as u64
    );
    events
}

fn decode_all(stream: &[u8]) -> Vec<DecodeEvent> {
    decode_chunks(&mut Decoder::new(), [stream])
}

fn replies(events: &[DecodeEvent]) -> Vec<ReplyFrame> {
    events
        .iter()
        .filter_map(|e| match e {
            DecodeEvent::Reply(r) => Some(r.clone()),
            _ => None,
        })
        .collect()
}

/// A stream of mixed traffic and the events it must give.
fn reference_stream() -> (Vec<u8>, Vec<DecodeEvent>) {
    let scan = scan_of(&SHAPE_180_050_MM, 1);
    let device = frame(Reply::DeviceType(b"LMS200;S18063;V02.19 ".to_vec()));
    let mut stream = vec![ACK];
    stream.extend(bytes(&mode_ok()));
    stream.extend(bytes(&scan));
    stream.push(NAK);
    stream.extend(bytes(&device));
    let events = vec![
        DecodeEvent::Ack,
        DecodeEvent::Reply(mode_ok()),
        DecodeEvent::Reply(scan),
        DecodeEvent::Nak,
        DecodeEvent::Reply(device),
    ];
    (stream, events)
}

#[test]
fn empty_input_gives_nothing() {
    let mut decoder = Decoder::new();
    assert_eq!(decoder.poll(), None);
    assert_eq!(decoder.push(&[]), 0);
    assert_eq!(decoder.poll(), None);
    assert_eq!(decoder.stats().bytes_in, 0);
}

#[test]
fn all_at_once() {
    let (stream, expected) = reference_stream();
    assert_eq!(decode_all(&stream), expected);
}

#[test]
fn byte_by_byte() {
    let (stream, expected) = reference_stream();
    let mut decoder = Decoder::new();
    assert_eq!(decode_chunks(&mut decoder, stream.chunks(1)), expected);
}

#[test]
fn split_across_every_boundary() {
    let (stream, expected) = reference_stream();
    for split in 0..=stream.len() {
        let mut decoder = Decoder::new();
        let events = decode_chunks(&mut decoder, [&stream[..split], &stream[split..]]);
        assert_eq!(events, expected, "split at {split}");
        assert_eq!(decoder.buffered(), 0);
    }
}

#[test]
fn two_frames_in_one_read() {
    let mut stream = bytes(&mode_ok());
    stream.extend(bytes(&frame(Reply::ResetAck)));
    assert_eq!(
        decode_all(&stream),
        vec![
            DecodeEvent::Reply(mode_ok()),
            DecodeEvent::Reply(frame(Reply::ResetAck))
        ]
    );
}

#[test]
fn garbage_before_is_reported_as_one_junk_run() {
    let mut stream = vec![0xFF, 0x00, 0x13, 0x80, 0x7E];
    stream.extend(bytes(&mode_ok()));
    assert_eq!(
        decode_all(&stream),
        vec![
            DecodeEvent::Dropped {
                reason: DropReason::UnexpectedByte,
                bytes: 5
            },
            DecodeEvent::Reply(mode_ok()),
        ]
    );
}

#[test]
fn bad_crc_followed_by_good_frames() {
    let mut bad = bytes(&mode_ok());
    let last = bad.len() - 1;
    bad[last] ^= 0x55;
    let mut stream = bad.clone();
    stream.extend(bytes(&mode_ok()));
    stream.extend(bytes(&frame(Reply::InvalidCommand)));
    let events = decode_all(&stream);
    assert_eq!(
        events[0],
        DecodeEvent::Dropped {
            reason: DropReason::BadCrc,
            bytes: 1
        }
    );
    assert_eq!(
        replies(&events),
        vec![mode_ok(), frame(Reply::InvalidCommand)]
    );
    let mut decoder = Decoder::new();
    decode_chunks(&mut decoder, [&stream[..]]);
    assert_eq!(decoder.stats().bad_crc, 1);
    assert_eq!(decoder.stats().frames_ok, 2);
    assert_eq!(decoder.stats().junk_bytes, bad.len() as u64 - 1);
}

/// A corrupted scan carries `02 80 00 01` near its end: a false candidate
/// of LEN 256 that covers the following real telegrams. They must still be
/// found, both when more traffic follows and when the stream stops there.
#[test]
fn false_candidate_inside_scan_data_does_not_swallow_the_next_telegram() {
    let scan = scan_of(&SHAPE_180_050_MM, 3);
    let mut corrupted = bytes(&scan);
    let at = corrupted.len() - 12;
    corrupted[at..at + 4].copy_from_slice(&[0x02, 0x80, 0x00, 0x01]);
    let following = [
        mode_ok(),
        frame(Reply::ResetAck),
        frame(Reply::InvalidCommand),
    ];
    let mut stream = corrupted;
    for f in &following {
        stream.extend(bytes(f));
    }
    // Stream stops right after: the lookahead inside the false candidate finds them.
    let events = decode_all(&stream);
    assert_eq!(replies(&events), following.to_vec());
    assert!(events.contains(&DecodeEvent::Dropped {
        reason: DropReason::BadCrc,
        bytes: 1
    }));

    // More traffic follows, so the false candidate completes and fails its CRC.
    let later = scan_of(&SHAPE_180_050_MM, 4);
    let mut longer = stream.clone();
    longer.extend(bytes(&later));
    let mut expected = following.to_vec();
    expected.push(later);
    for chunk in [1, 7, 64, 4096] {
        let mut decoder = Decoder::new();
        let events = decode_chunks(&mut decoder, longer.chunks(chunk));
        assert_eq!(replies(&events), expected, "chunk {chunk}");
    }
}

#[test]
fn truncated_scan_then_ack_and_mode_reply() {
    let scan = bytes(&scan_of(&SHAPE_180_050_MM, 5));
    for shape in [None, Some(SHAPE_180_050_MM)] {
        for cut in [5, 300, scan.len() - 3] {
            let mut stream = scan[..cut].to_vec();
            stream.push(ACK);
            stream.extend(bytes(&mode_ok()));
            let mut decoder = Decoder::new();
            decoder.set_expectation(shape);
            let events = decode_chunks(&mut decoder, stream.chunks(64));
            assert_eq!(
                events,
                vec![
                    DecodeEvent::Dropped {
                        reason: DropReason::Truncated,
                        bytes: cut
                    },
                    DecodeEvent::Ack,
                    DecodeEvent::Reply(mode_ok()),
                ],
                "cut {cut}, shape {shape:?}"
            );
        }
    }
}

#[test]
fn stx_stx_address_keeps_the_real_telegram() {
    let mut stream = vec![0x02];
    stream.extend(bytes(&mode_ok()));
    assert_eq!(
        decode_all(&stream),
        vec![
            DecodeEvent::Dropped {
                reason: DropReason::Implausible(Implausibility::Address(0x02)),
                bytes: 1
            },
            DecodeEvent::Reply(mode_ok()),
        ]
    );
}

#[test]
fn section_1_3_row_23_ack_then_mode_reply() {
    let events = decode_all(&hex("06 02 80 03 00 A0 00 10 16 0A"));
    assert_eq!(
        events,
        vec![DecodeEvent::Ack, DecodeEvent::Reply(mode_ok())]
    );
}

#[test]
fn reply_address_without_bit_7_is_implausible() {
    let request_like = hex("02 00 01 00 31 15 12");
    let events = decode_all(&request_like);
    assert_eq!(
        events[0],
        DecodeEvent::Dropped {
            reason: DropReason::Implausible(Implausibility::Address(0)),
            bytes: 1
        }
    );
    assert!(replies(&events).is_empty());
}

#[test]
fn impossible_lengths_are_dropped_at_once() {
    for len in [0u16, 1, 809, 0xFFFF] {
        let mut stream = vec![0x02, 0x80];
        stream.extend(len.to_le_bytes());
        let events = decode_all(&stream);
        assert_eq!(
            events[0],
            DecodeEvent::Dropped {
                reason: DropReason::ImpossibleLength { len },
                bytes: 1
            }
        );
    }
    // LEN 808 is the longest telegram (814 bytes): the decoder waits for it.
    let mut decoder = Decoder::new();
    assert_eq!(decoder.push(&[0x02, 0x80, 0x28, 0x03]), 4);
    assert_eq!(decoder.poll(), None);
}

#[test]
fn scan_of_another_variant_is_a_length_mismatch() {
    let other = ScanShape {
        variant: Variant::Fov180Res100,
        ..SHAPE_180_050_MM
    };
    let mut decoder = Decoder::with_expectation(SHAPE_180_050_MM);
    let events = decode_chunks(&mut decoder, [&bytes(&scan_of(&other, 0))[..]]);
    assert_eq!(
        events[0],
        DecodeEvent::Dropped {
            reason: DropReason::LengthMismatch {
                expected: 726,
                actual: 366
            },
            bytes: 1
        }
    );
    assert!(replies(&events).is_empty());
    assert_eq!(decoder.stats().length_mismatch, 1);
}

#[test]
fn scan_in_other_units_is_implausible_under_the_expectation() {
    let cm = ScanShape {
        units: Units::Cm,
        ..SHAPE_180_050_MM
    };
    let events = decode_chunks(
        &mut Decoder::with_expectation(SHAPE_180_050_MM),
        [&bytes(&scan_of(&cm, 0))[..]],
    );
    assert_eq!(
        events[0],
        DecodeEvent::Dropped {
            reason: DropReason::Implausible(Implausibility::CountWord {
                expected: 0x4169,
                actual: 0x0169
            }),
            bytes: 1
        }
    );
}

#[test]
fn reserved_unit_bits_are_implausible_even_without_expectation() {
    let mut scan = Scan::complete(vec![100, 200], Units::Mm, None);
    scan.count_word = CountWord(scan.count_word.0 | 0x8000);
    let events = decode_all(&bytes(&frame(Reply::ScanData(scan))));
    assert_eq!(
        events[0],
        DecodeEvent::Dropped {
            reason: DropReason::Implausible(Implausibility::ReservedUnits(0xC002)),
            bytes: 1
        }
    );
}

/// The CRC misses bit 0 of one byte plus bit 1 of the next; applied to the
/// count word it keeps the CRC valid but the plausibility checks catch it.
#[test]
fn crc_blind_error_in_count_word_is_caught_by_plausibility() {
    let good = bytes(&scan_of(&SHAPE_180_050_MM, 9));
    let mut bad = good.clone();
    bad[5] ^= 0x01; // count word low byte: 0x69 -> 0x68
    bad[6] ^= 0x02; // high byte: 0x41 -> 0x43 (count bit 9)
    let n = bad.len();
    assert_eq!(
        crc16(&bad[..n - 2]),
        crc16(&good[..n - 2]),
        "the CRC cannot see this error"
    );
    for shape in [None, Some(SHAPE_180_050_MM)] {
        let mut decoder = Decoder::new();
        decoder.set_expectation(shape);
        let events = decode_chunks(&mut decoder, [&bad[..]]);
        assert!(
            replies(&events).is_empty(),
            "shape {shape:?}: {:?}",
            events[0]
        );
        assert!(matches!(
            events[0],
            DecodeEvent::Dropped {
                reason: DropReason::Implausible(_),
                bytes: 1
            }
        ));
    }
}

/// The same blind pattern in a value word can push a distance into the gap
/// between the maximum and the special codes (8184 in mode 00).
#[test]
fn crc_blind_error_in_a_value_is_caught_when_it_leaves_the_value_range() {
    let mut scan = scan_of(&SHAPE_180_050_MM, 0);
    if let Reply::ScanData(s) = &mut scan.reply {
        s.values[10] = 0x1EF8; // 7928 mm
    }
    let good = bytes(&scan);
    let mut bad = good.clone();
    let high = 7 + 2 * 10 + 1; // high byte of value 10
    bad[high] ^= 0x01; // 0x1E -> 0x1F: value 0x1FF8 = 8184, in the gap
    bad[high + 1] ^= 0x02; // low byte of value 11: still a distance
    let n = bad.len();
    assert_eq!(
        crc16(&bad[..n - 2]),
        crc16(&good[..n - 2]),
        "the CRC cannot see this error"
    );
    let events = decode_chunks(&mut Decoder::with_expectation(SHAPE_180_050_MM), [&bad[..]]);
    assert!(matches!(
        events[0],
        DecodeEvent::Dropped {
            reason: DropReason::Implausible(Implausibility::Value {
                index: 10,
                value: 0x1FF8
            }),
            bytes: 1
        }
    ));
}

#[test]
fn error_and_fatal_status_are_delivered_not_dropped() {
    for status in [0x13, 0x14, 0x11, 0x93] {
        let reply = ReplyFrame {
            status: Status(status),
            ..mode_ok()
        };
        assert_eq!(decode_all(&bytes(&reply)), vec![DecodeEvent::Reply(reply)]);
    }
}

#[test]
fn reply_from_an_individual_address() {
    let events = decode_all(&hex("02 81 03 00 A0 00 10 36 1A"));
    assert_eq!(
        events,
        vec![DecodeEvent::Reply(ReplyFrame {
            address: 0x81,
            ..mode_ok()
        })]
    );
}

#[test]
fn abandon_incomplete_releases_what_follows() {
    let scan = bytes(&scan_of(&SHAPE_180_050_MM, 2));
    let mut decoder = Decoder::new();
    let mut events = Vec::new();
    // Half a scan, then an ACK whose reply has not arrived yet.
    decoder.feed(&scan[..200], |e| events.push(e));
    decoder.feed(&[ACK], |e| events.push(e));
    assert!(events.is_empty());
    decoder.abandon_incomplete();
    while let Some(e) = decoder.poll() {
        events.push(e);
    }
    assert_eq!(
        events[0],
        DecodeEvent::Dropped {
            reason: DropReason::Truncated,
            bytes: 1
        }
    );
    assert_eq!(events.last(), Some(&DecodeEvent::Ack));
    assert_eq!(decoder.buffered(), 0);
    // Decoding carries on normally afterwards.
    decoder.feed(&bytes(&mode_ok()), |e| events.push(e));
    assert_eq!(events.last(), Some(&DecodeEvent::Reply(mode_ok())));
}

#[test]
fn push_is_bounded_and_feed_takes_everything() {
    let scan = bytes(&scan_of(&SHAPE_180_050_MM, 0));
    let stream: Vec<u8> = scan.iter().copied().cycle().take(scan.len() * 40).collect();
    let mut decoder = Decoder::new();
    let taken = decoder.push(&stream);
    assert!(taken < stream.len());
    assert_eq!(decoder.push(&stream[taken..]), 0, "full until polled");
    let mut count = 0;
    while let Some(event) = decoder.poll() {
        assert!(matches!(event, DecodeEvent::Reply(_)));
        count += 1;
    }
    assert!(count > 0);
    let mut decoder = Decoder::new();
    let mut scans = 0;
    decoder.feed(&stream, |e| {
        scans += usize::from(matches!(e, DecodeEvent::Reply(_)))
    });
    assert_eq!(scans, 40);
    assert_eq!(decoder.stats().frames_ok, 40);
}

#[test]
fn clear_discards_and_counts() {
    let mut decoder = Decoder::new();
    assert_eq!(decoder.push(&[0x02, 0x80, 0x10]), 3);
    assert_eq!(decoder.poll(), None);
    decoder.clear();
    assert_eq!(decoder.buffered(), 0);
    assert_eq!(decoder.stats().bytes_accounted(), 3);
}

/// Section 5: a real 180°/0.5° mm scan is known only by its head
/// (`02 80 D6 02 B0 69 41 CB 08 CB 08 C2 08`) and tail
/// (`1B 23 B1 22 D7 22 18 05 10 64 47`). Rebuild a telegram with the same
/// head and tail values and check LEN, count word and value decoding.
#[test]
fn section_5_header_decodes() {
    let mut values = vec![0x08CB, 0x08CB, 0x08C2];
    values.extend((3..357).map(|i| 0x0800 + i));
    values.extend([0x231B, 0x22B1, 0x22D7, 0x0518]);
    let reply = ReplyFrame {
        status: Status(0x10),
        ..frame(Reply::ScanData(Scan::complete(values, Units::Mm, None)))
    };
    let telegram = bytes(&reply);
    assert_eq!(
        &telegram[..13],
        &hex("02 80 D6 02 B0 69 41 CB 08 CB 08 C2 08")[..]
    );
    let n = telegram.len();
    assert_eq!(
        &telegram[n - 11..n - 2],
        &hex("1B 23 B1 22 D7 22 18 05 10")[..]
    );
    assert_eq!(n, 732);

    let shape = ScanShape {
        mode: MeasuringMode::Bits14FieldsAb,
        ..SHAPE_180_050_MM
    };
    let events = decode_chunks(&mut Decoder::with_expectation(shape), [&telegram[..]]);
    let [
        DecodeEvent::Reply(ReplyFrame {
            reply: Reply::ScanData(scan),
            ..
        }),
    ] = &events[..]
    else {
        panic!("expected one scan, got {events:?}");
    };
    assert_eq!(scan.count_word.count(), 361);
    assert_eq!(scan.units(), Some(Units::Mm));
    assert_eq!(scan.range_m(0, shape.mode), Some(2.251));
    // 0x231B = 8987: 14-bit distance 8.987 m in mode 04 …
    assert_eq!(
        scan.range_m(357, MeasuringMode::Bits14FieldsAb),
        Some(8.987)
    );
    // … but 795 mm with field A set in mode 00.
    assert_eq!(
        scan.range_m(357, MeasuringMode::Bits13FieldsAbDazzle),
        Some(0.795)
    );
}
