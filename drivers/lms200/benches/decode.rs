//! Decode throughput on a long stream of 180°/0.5° mm `B0` telegrams
//! (732 bytes each), fed in 64-byte and 4 KiB reads. Target: ≥ 500 MB/s.

use std::hint::black_box;

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use lms200::{
    DecodeEvent, Decoder, MeasuringMode, Reply, ReplyFrame, Scan, ScanShape, Status, Units, Variant,
};

const SCANS: u16 = 1000;

const SHAPE: ScanShape = ScanShape {
    variant: Variant::Fov180Res50,
    units: Units::Mm,
    real_time_indices: false,
    mode: MeasuringMode::Bits13FieldsAbDazzle,
};

/// Scans with ranges that change from scan to scan, like a moving robot's.
fn stream() -> Vec<u8> {
    let mut out = Vec::new();
    for s in 0..SCANS {
        let values = (0..SHAPE.variant.value_count())
            .map(|i| 200 + (i * 13 + s * 7) % 7900)
            .collect();
        let frame = ReplyFrame {
            address: 0x80,
            status: Status::OK,
            reply: Reply::ScanData(Scan::complete(values, Units::Mm, None)),
        };
        out.extend(frame.encode().expect("a 361-value scan fits in a telegram"));
    }
    out
}

fn decode(c: &mut Criterion) {
    let stream = stream();
    let mut group = c.benchmark_group("decode_b0_180_050");
    group.throughput(Throughput::Bytes(stream.len() as u64));
    for chunk in [64usize, 4096] {
        group.bench_with_input(BenchmarkId::from_parameter(chunk), &chunk, |b, &chunk| {
            b.iter(|| {
                let mut decoder = Decoder::with_expectation(SHAPE);
                let mut scans = 0u32;
                for piece in stream.chunks(chunk) {
                    decoder.feed(piece, |event| {
                        if let DecodeEvent::Reply(frame) = event {
                            scans += 1;
                            black_box(frame);
                        }
                    });
                }
                assert_eq!(scans, u32::from(SCANS));
                scans
            });
        });
    }
    group.finish();
}

criterion_group!(benches, decode);
criterion_main!(benches);
