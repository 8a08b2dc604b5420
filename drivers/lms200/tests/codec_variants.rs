//! Table-driven scan tests: five variants × two units × indices on/off ×
//! every measuring mode, encoded, decoded under the matching expectation and
//! read back; and refused under every mismatching expectation.

#![allow(clippy::unwrap_used)] // tests may unwrap: a panic is a failure

use lms200::{
    DecodeEvent, Decoder, DropReason, Implausibility, Measurement, MeasuringMode, RealTimeIndices,
    Reply, ReplyFrame, Scan, ScanShape, SpecialCode, Status, Units, Variant,
};

/// Frame sizes from TL Table 10-16 (without indices; +2 with them).
fn documented_frame_len(variant: Variant) -> usize {
    match variant {
        Variant::Fov100Res100 => 212,
        Variant::Fov100Res50 => 412,
        Variant::Fov100Res25 => 812,
        Variant::Fov180Res100 => 372,
        Variant::Fov180Res50 => 732,
    }
}

fn all_shapes() -> Vec<ScanShape> {
    let mut shapes = Vec::new();
    for variant in Variant::ALL {
        for units in Units::ALL {
            for real_time_indices in [false, true] {
                for mode in MeasuringMode::ALL {
                    shapes.push(ScanShape {
                        variant,
                        units,
                        real_time_indices,
                        mode,
                    });
                }
            }
        }
    }
    shapes
}

/// Value words for a scan under `mode` and what each must read back as:
/// distances with flag bits set in the upper bits, and every special code.
fn values_for(mode: MeasuringMode, count: u16) -> Vec<(u16, Measurement)> {
    let mut out = Vec::new();
    let specials: Vec<SpecialCode> = SpecialCode::ALL.to_vec();
    for i in 0..count {
        if !mode.is_distance() {
            let value = i.wrapping_mul(911);
            out.push((value, Measurement::Reflectivity(value)));
            continue;
        }
        let mask = mode.distance_mask();
        let flags = if mask == 0xFFFF { 0 } else { (i << 13) & !mask };
        let special = specials[usize::from(i) % specials.len()];
        let max = mode.max_distance().unwrap();
        if i % 5 == 0 {
            let raw = mode.special_value(special).unwrap();
            out.push((raw | flags, Measurement::Special(special)));
        } else {
            let distance = (i * 37) % (max + 1);
            out.push((distance | flags, Measurement::Distance(distance)));
        }
    }
    out
}

fn scan_frame(shape: &ScanShape, values: Vec<u16>) -> Vec<u8> {
    let indices = shape.real_time_indices.then_some(RealTimeIndices {
        scan: 17,
        telegram: 200,
    });
    ReplyFrame {
        address: 0x80,
        status: Status(0x11),
        reply: Reply::ScanData(Scan::complete(values, shape.units, indices)),
    }
    .encode()
    .unwrap()
}

fn decode(shape: Option<ScanShape>, bytes: &[u8]) -> Vec<DecodeEvent> {
    let mut decoder = Decoder::new();
    decoder.set_expectation(shape);
    let mut events = Vec::new();
    for chunk in bytes.chunks(64) {
        decoder.feed(chunk, |e| events.push(e));
    }
    events
}

#[test]
fn every_shape_encodes_to_its_documented_size_and_reads_back() {
    let shapes = all_shapes();
    assert_eq!(shapes.len(), 5 * 2 * 2 * MeasuringMode::ALL.len());
    for shape in shapes {
        let expected_len =
            documented_frame_len(shape.variant) + if shape.real_time_indices { 2 } else { 0 };
        assert_eq!(shape.frame_len(), expected_len, "{shape:?}");

        let table = values_for(shape.mode, shape.variant.value_count());
        let bytes = scan_frame(&shape, table.iter().map(|(v, _)| *v).collect());
        assert_eq!(bytes.len(), expected_len);
        assert_eq!(u16::from_le_bytes([bytes[2], bytes[3]]), shape.len_field());
        assert_eq!(
            u16::from_le_bytes([bytes[5], bytes[6]]),
            shape.count_word().0
        );

        let events = decode(Some(shape), &bytes);
        let [
            DecodeEvent::Reply(ReplyFrame {
                reply: Reply::ScanData(scan),
                status,
                ..
            }),
        ] = &events[..]
        else {
            panic!("{shape:?}: {events:?}");
        };
        assert_eq!(*status, Status(0x11));
        assert_eq!(scan.units(), Some(shape.units));
        assert_eq!(scan.indices.is_some(), shape.real_time_indices);
        for (i, (_, expected)) in table.iter().enumerate() {
            assert_eq!(
                scan.measurement(i, shape.mode),
                Some(*expected),
                "{shape:?} value {i}"
            );
            let range = scan.range_m(i, shape.mode);
            match expected {
                Measurement::Distance(raw) => {
                    assert_eq!(range, Some(f64::from(*raw) * shape.units.metres_per_unit()));
                }
                _ => assert_eq!(range, None, "{shape:?} value {i} is no range"),
            }
        }
    }
}

#[test]
fn every_shape_refuses_scans_of_every_other_shape() {
    for expected in all_shapes()
        .into_iter()
        .filter(|s| s.mode == MeasuringMode::Bits13FieldsAbDazzle)
    {
        for sent in all_shapes()
            .into_iter()
            .filter(|s| s.mode == MeasuringMode::Bits13FieldsAbDazzle)
        {
            if sent == expected {
                continue;
            }
            let values = vec![1000; usize::from(sent.variant.value_count())];
            let events = decode(Some(expected), &scan_frame(&sent, values));
            let reason = match &events[0] {
                DecodeEvent::Dropped { reason, bytes: 1 } => *reason,
                other => panic!("{sent:?} under {expected:?}: {other:?}"),
            };
            if sent.len_field() != expected.len_field() {
                assert_eq!(
                    reason,
                    DropReason::LengthMismatch {
                        expected: expected.len_field(),
                        actual: sent.len_field()
                    }
                );
            } else {
                assert_eq!(
                    reason,
                    DropReason::Implausible(Implausibility::CountWord {
                        expected: expected.count_word().0,
                        actual: sent.count_word().0
                    })
                );
            }
            assert!(!events.iter().any(|e| matches!(e, DecodeEvent::Reply(_))));
        }
    }
}

#[test]
fn without_expectation_every_shape_is_accepted() {
    for shape in all_shapes()
        .into_iter()
        .filter(|s| s.mode == MeasuringMode::Bits13FieldsAbDazzle)
    {
        let values = vec![1000; usize::from(shape.variant.value_count())];
        let events = decode(None, &scan_frame(&shape, values));
        assert!(matches!(&events[..], [DecodeEvent::Reply(_)]), "{shape:?}");
    }
}

#[test]
fn set_expectation_applies_from_the_next_telegram() {
    let first = ScanShape {
        variant: Variant::Fov180Res100,
        units: Units::Cm,
        real_time_indices: false,
        mode: MeasuringMode::Bits13FieldsAbDazzle,
    };
    let second = ScanShape {
        variant: Variant::Fov100Res25,
        ..first
    };
    let mut decoder = Decoder::with_expectation(first);
    let mut events = Vec::new();
    decoder.feed(&scan_frame(&first, vec![5; 181]), |e| events.push(e));
    decoder.set_expectation(Some(second));
    decoder.feed(&scan_frame(&second, vec![5; 401]), |e| events.push(e));
    decoder.feed(&scan_frame(&first, vec![5; 181]), |e| events.push(e));
    assert!(matches!(events[0], DecodeEvent::Reply(_)));
    assert!(matches!(events[1], DecodeEvent::Reply(_)));
    assert!(matches!(
        events[2],
        DecodeEvent::Dropped {
            reason: DropReason::LengthMismatch { .. },
            ..
        }
    ));
    assert_eq!(decoder.expectation(), Some(second));
}
