//! The emulator against hand-built request frames and the golden reply
//! vectors of the protocol notes §1.3.

#![allow(clippy::unwrap_used)]

use std::time::{Duration, Instant};

use super::*;
use crate::test_util::hex;
use crate::{DecodeEvent, Decoder, ModeChangeResult, PermanentBaud, Request, Status};

/// A sensor that has been on for a while, at `baud`, idle.
fn running(baud: Baud) -> (Emulator, Instant) {
    let t0 = Instant::now();
    let mut emulator = Emulator::new(EmulatorConfig::left_running(baud, false), t0);
    emulator.set_host_baud(baud);
    (emulator, t0)
}

/// Everything the emulator sends from `from` to `from + span`.
fn collect(emulator: &mut Emulator, from: Instant, span: Duration) -> Vec<u8> {
    let end = from + span;
    let mut now = from;
    let mut out = Vec::new();
    loop {
        if let Some(bytes) = emulator.poll_transmit(now) {
            out.extend(bytes);
        }
        match emulator.poll_timeout() {
            Some(next) if next <= end => now = next.max(now),
            _ => break,
        }
        emulator.handle_timeout(now);
    }
    if let Some(bytes) = emulator.poll_transmit(end) {
        out.extend(bytes);
    }
    out
}

fn send(emulator: &mut Emulator, request: &Request, at: Instant) {
    emulator.handle_input(&request.encode().unwrap(), at);
}

fn decode(bytes: &[u8]) -> Vec<DecodeEvent> {
    let mut events = Vec::new();
    Decoder::new().feed(bytes, |e| events.push(e));
    events
}

#[test]
fn power_up_sends_90_at_9600_after_the_delay_and_ignores_requests_before() {
    let t0 = Instant::now();
    let mut emulator = Emulator::new(EmulatorConfig::default(), t0);
    send(
        &mut emulator,
        &Request::Status,
        t0 + Duration::from_millis(500),
    );
    assert!(collect(&mut emulator, t0, Duration::from_millis(999)).is_empty());
    let bytes = collect(
        &mut emulator,
        t0 + Duration::from_millis(999),
        Duration::from_secs(1),
    );
    let events = decode(&bytes);
    assert_eq!(events.len(), 1, "{events:?}");
    let DecodeEvent::Reply(frame) = &events[0] else {
        panic!("{events:?}")
    };
    assert_eq!(frame.reply.text().as_deref(), Some("LMS200;30106;V02.10"));
    assert_eq!(emulator.baud(), Baud::B9600);
    assert_eq!(emulator.operating_mode(), OperatingMode::OnRequest);
}

#[test]
fn a_mode_change_is_acked_and_answered_with_the_golden_a0() {
    let (mut emulator, t0) = running(Baud::B9600);
    send(&mut emulator, &Request::ValuesOnRequest, t0);
    let bytes = collect(&mut emulator, t0, Duration::from_secs(1));
    assert_eq!(bytes, hex("06 02 80 03 00 A0 00 10 16 0A"));
}

#[test]
fn the_own_address_is_answered_with_bit_7_set_and_others_are_ignored() {
    let (mut emulator, t0) = running(Baud::B9600);
    let mut frame = Vec::new();
    Request::ValuesOnRequest
        .encode_into(0x01, &mut frame)
        .unwrap();
    emulator.handle_input(&frame, t0);
    assert_eq!(
        collect(&mut emulator, t0, Duration::from_secs(1)),
        hex("06 02 81 03 00 A0 00 10 36 1A")
    );
    let t1 = t0 + Duration::from_secs(1);
    let mut other = Vec::new();
    Request::ValuesOnRequest
        .encode_into(0x05, &mut other)
        .unwrap();
    emulator.handle_input(&other, t1);
    assert!(collect(&mut emulator, t1, Duration::from_secs(1)).is_empty());
}

#[test]
fn a_bad_checksum_gets_a_single_nak() {
    let (mut emulator, t0) = running(Baud::B9600);
    let mut frame = Request::Status.encode().unwrap();
    let last = frame.len() - 1;
    frame[last] ^= 0x01;
    emulator.handle_input(&frame, t0);
    assert_eq!(collect(&mut emulator, t0, Duration::from_secs(1)), [0x15]);
    assert_eq!(emulator.stats().naks, 1);
}

#[test]
fn an_unknown_command_gets_the_golden_92() {
    let (mut emulator, t0) = running(Baud::B9600);
    send(
        &mut emulator,
        &Request::Other {
            code: 0x45,
            data: vec![0x01, 0x00],
        },
        t0,
    );
    assert_eq!(
        collect(&mut emulator, t0, Duration::from_secs(1)),
        hex("06 02 80 02 00 92 10 7F 33")
    );
}

#[test]
fn status_is_a_160_byte_frame_with_version_and_mode() {
    let (mut emulator, t0) = running(Baud::B38400);
    send(&mut emulator, &Request::Status, t0);
    let bytes = collect(&mut emulator, t0, Duration::from_secs(1));
    assert_eq!(bytes[0], 0x06);
    assert_eq!(bytes.len(), 1 + 160);
    let events = decode(&bytes[1..]);
    let DecodeEvent::Reply(frame) = &events[0] else {
        panic!("{events:?}")
    };
    assert_eq!(frame.reply.firmware_version(), Some("V02.10"));
    let Reply::Status(data) = &frame.reply else {
        panic!()
    };
    assert_eq!(data[7], 0x25);
}

#[test]
fn the_baud_switch_is_answered_at_the_old_rate() {
    let (mut emulator, t0) = running(Baud::B9600);
    send(&mut emulator, &Request::SetBaud(Baud::B500000), t0);
    let reply = hex("06 02 80 03 00 A0 00 10 16 0A");
    // Still at 9600 until the A0's last byte has left: 10 bytes = 10.4 ms.
    let early = collect(&mut emulator, t0, Duration::from_millis(5));
    assert_eq!(emulator.baud(), Baud::B9600);
    let rest = collect(
        &mut emulator,
        t0 + Duration::from_millis(5),
        Duration::from_millis(100),
    );
    assert_eq!([early, rest].concat(), reply);
    assert_eq!(emulator.baud(), Baud::B500000);
}

#[test]
fn configuration_writes_need_installation_mode_and_are_counted() {
    let (mut emulator, t0) = running(Baud::B9600);
    let mut block = ConfigBlock::tl_default();
    block.set_units(crate::Units::Cm);
    send(&mut emulator, &Request::WriteConfig(block), t0);
    let t1 = t0 + Duration::from_secs(1);
    let refused = decode(&collect(&mut emulator, t0, Duration::from_secs(1)));
    assert!(
        matches!(&refused[1], DecodeEvent::Reply(f) if f.reply == Reply::ConfigWritten { accepted: false, config: ConfigBlock::tl_default() })
    );
    assert_eq!(emulator.eeprom_writes(), 0);

    send(
        &mut emulator,
        &Request::InstallationMode {
            password: *b"SICK_PLS",
        },
        t1,
    );
    let wrong = decode(&collect(&mut emulator, t1, Duration::from_secs(1)));
    assert!(
        matches!(&wrong[1], DecodeEvent::Reply(f) if f.reply == Reply::ModeChanged(ModeChangeResult::WrongPassword))
    );

    let t2 = t1 + Duration::from_secs(1);
    send(&mut emulator, &Request::installation_mode(), t2);
    send(
        &mut emulator,
        &Request::WriteConfig(block),
        t2 + Duration::from_millis(100),
    );
    let events = decode(&collect(&mut emulator, t2, Duration::from_secs(2)));
    assert!(events.iter().any(|e| matches!(e, DecodeEvent::Reply(f) if f.reply == Reply::ConfigWritten { accepted: true, config: block })));
    assert_eq!(emulator.eeprom_writes(), 1);
    assert_eq!(emulator.config_block().units(), Some(crate::Units::Cm));
}

#[test]
fn variants_follow_the_golden_bb_and_illegal_ones_keep_the_old() {
    let (mut emulator, t0) = running(Baud::B9600);
    send(
        &mut emulator,
        &Request::SetVariant {
            fov_deg: 180,
            resolution_centideg: 25,
        },
        t0,
    );
    let bytes = collect(&mut emulator, t0, Duration::from_secs(1));
    let events = decode(&bytes);
    assert!(
        matches!(&events[1], DecodeEvent::Reply(f) if f.reply == Reply::VariantChanged { accepted: false, fov_deg: 180, resolution_centideg: 50 })
    );
    let t1 = t0 + Duration::from_secs(1);
    send(
        &mut emulator,
        &Request::set_variant(Variant::Fov100Res25),
        t1,
    );
    let events = decode(&collect(&mut emulator, t1, Duration::from_secs(1)));
    assert!(
        matches!(&events[1], DecodeEvent::Reply(f) if f.reply.variant() == Some(Variant::Fov100Res25))
    );
    assert_eq!(emulator.variant(), Variant::Fov100Res25);
    let t2 = t1 + Duration::from_secs(1);
    send(
        &mut emulator,
        &Request::set_variant(Variant::Fov180Res50),
        t2,
    );
    assert_eq!(
        collect(&mut emulator, t2, Duration::from_secs(1)),
        hex("06 02 80 07 00 BB 01 B4 00 32 00 10 03 9D")
    );
}

#[test]
fn streaming_at_500k_sends_every_scan() {
    let (mut emulator, t0) = running(Baud::B500000);
    send(&mut emulator, &Request::ContinuousAllValues, t0);
    let bytes = collect(&mut emulator, t0, Duration::from_secs(1));
    let scans = decode(&bytes)
        .iter()
        .filter(|e| matches!(e, DecodeEvent::Reply(f) if f.reply.code() == 0xB0))
        .count();
    // 1 s / 26.64 ms = 37.5 scans; the last may still be on the line.
    assert!((36..=37).contains(&scans), "{scans}");
    assert_eq!(emulator.stats().scans_skipped, 0);
}

#[test]
fn streaming_at_38400_skips_the_scans_that_do_not_fit() {
    let (mut emulator, t0) = running(Baud::B38400);
    send(&mut emulator, &Request::ContinuousAllValues, t0);
    collect(&mut emulator, t0, Duration::from_secs(2));
    let stats = emulator.stats();
    // A 732-byte telegram takes 190.6 ms: one scan in 8 goes out (TL: 4.2 Hz).
    assert!((9..=11).contains(&stats.scans_sent), "{stats:?}");
    // Every one of the 75 scans completed in 2 s is either sent or skipped.
    assert_eq!(stats.scans_skipped + stats.scans_sent, 75, "{stats:?}");
}

#[test]
fn a_request_cuts_the_scan_on_the_line() {
    let (mut emulator, t0) = running(Baud::B9600);
    send(&mut emulator, &Request::ContinuousAllValues, t0);
    // The first scan completes at 26.64 ms and takes 762.5 ms at 9600.
    let part = collect(&mut emulator, t0, Duration::from_millis(300));
    let t1 = t0 + Duration::from_millis(300);
    send(&mut emulator, &Request::ValuesOnRequest, t1);
    let rest = collect(&mut emulator, t1, Duration::from_secs(2));
    assert_eq!(emulator.stats().scans_cut, 1);
    assert!(
        rest.ends_with(&hex("06 02 80 03 00 A0 00 10 16 0A")),
        "{rest:02X?}"
    );
    let events = decode(&[part, rest].concat());
    assert!(
        events
            .iter()
            .any(|e| matches!(e, DecodeEvent::Dropped { .. }))
    );
    assert_eq!(emulator.operating_mode(), OperatingMode::OnRequest);
}

#[test]
fn a_host_at_the_wrong_speed_gets_no_answer() {
    let (mut emulator, t0) = running(Baud::B9600);
    emulator.set_host_baud(Baud::B38400);
    send(&mut emulator, &Request::Status, t0);
    let bytes = collect(&mut emulator, t0, Duration::from_secs(1));
    assert!(
        !decode(&bytes)
            .iter()
            .any(|e| matches!(e, DecodeEvent::Ack | DecodeEvent::Reply(_)))
    );
    assert!(emulator.stats().garbled_input_bytes > 0);
}

#[test]
fn reset_answers_91_then_boots_to_9600_and_sends_90() {
    let (mut emulator, t0) = running(Baud::B38400);
    send(&mut emulator, &Request::Reset, t0);
    let first = collect(&mut emulator, t0, Duration::from_millis(500));
    assert_eq!(first, hex("06 02 80 02 00 91 10 79 30"));
    assert!(emulator.is_booting());
    emulator.set_host_baud(Baud::B9600);
    let t1 = t0 + Duration::from_millis(500);
    let events = decode(&collect(&mut emulator, t1, Duration::from_secs(2)));
    assert!(
        matches!(&events[0], DecodeEvent::Reply(f) if f.reply.code() == 0x90),
        "{events:?}"
    );
    assert_eq!(emulator.baud(), Baud::B9600);
}

#[test]
fn permanent_baud_needs_installation_mode_and_survives_a_power_cycle() {
    let (mut emulator, t0) = running(Baud::B38400);
    send(
        &mut emulator,
        &Request::PermanentBaud(PermanentBaud::KeepCurrent),
        t0,
    );
    let refused = decode(&collect(&mut emulator, t0, Duration::from_secs(1)));
    assert!(
        matches!(&refused[1], DecodeEvent::Reply(f) if f.reply == Reply::PermanentBaud { accepted: false, setting: 1 })
    );
    let t1 = t0 + Duration::from_secs(1);
    send(&mut emulator, &Request::installation_mode(), t1);
    send(
        &mut emulator,
        &Request::PermanentBaud(PermanentBaud::KeepCurrent),
        t1 + Duration::from_millis(50),
    );
    collect(&mut emulator, t1, Duration::from_secs(1));
    let t2 = t1 + Duration::from_secs(1);
    emulator.power_cycle(t2);
    collect(&mut emulator, t2, Duration::from_secs(2));
    assert_eq!(emulator.baud(), Baud::B38400, "66 01 stored the speed");
    assert_eq!(emulator.operating_mode(), OperatingMode::OnRequest);
}

#[test]
fn every_nth_request_is_nacked_on_purpose() {
    let t0 = Instant::now();
    let faults = FaultConfig {
        nak_every_nth_request: Some(2),
        ..FaultConfig::default()
    };
    let config = EmulatorConfig {
        faults,
        ..EmulatorConfig::left_running(Baud::B9600, false)
    };
    let mut emulator = Emulator::new(config, t0);
    let mut answers = Vec::new();
    for i in 0..4u32 {
        let t = t0 + Duration::from_secs(u64::from(i));
        send(&mut emulator, &Request::ValuesOnRequest, t);
        answers.push(collect(&mut emulator, t, Duration::from_secs(1))[0]);
    }
    assert_eq!(answers, [0x06, 0x15, 0x06, 0x15]);
    assert_eq!(emulator.fault_counts().forced_naks, 2);
}

#[test]
fn one_scan_on_request_and_interlaced_partial_scans() {
    let (mut emulator, t0) = running(Baud::B500000);
    send(&mut emulator, &Request::OneScan, t0);
    let events = decode(&collect(&mut emulator, t0, Duration::from_millis(100)));
    let DecodeEvent::Reply(frame) = &events[1] else {
        panic!("{events:?}")
    };
    let Reply::ScanData(scan) = &frame.reply else {
        panic!()
    };
    assert_eq!(scan.values.len(), 361);
    assert_eq!(frame.status, Status::OK);

    let t1 = t0 + Duration::from_millis(100);
    send(&mut emulator, &Request::ContinuousInterlaced, t1);
    let events = decode(&collect(&mut emulator, t1, Duration::from_millis(100)));
    let partials: Vec<_> = events
        .iter()
        .filter_map(|e| match e {
            DecodeEvent::Reply(f) => match &f.reply {
                Reply::ScanData(s) => Some(s.count_word),
                _ => None,
            },
            _ => None,
        })
        .collect();
    assert!(partials.len() >= 6, "{partials:?}");
    assert!(partials.iter().all(|c| c.is_partial()));
    assert!(partials.iter().any(|c| c.raster() == 0 && c.count() == 181));
    assert!(partials.iter().any(|c| c.raster() == 2 && c.count() == 180));
}

#[test]
fn silence_drops_everything_until_it_ends() {
    let (mut emulator, t0) = running(Baud::B9600);
    emulator.silence(t0, Duration::from_secs(1));
    send(
        &mut emulator,
        &Request::Status,
        t0 + Duration::from_millis(10),
    );
    assert!(collect(&mut emulator, t0, Duration::from_secs(1)).is_empty());
    let t1 = t0 + Duration::from_secs(1);
    send(&mut emulator, &Request::ValuesOnRequest, t1);
    assert_eq!(collect(&mut emulator, t1, Duration::from_secs(1))[0], 0x06);
}

mod properties {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

        /// On a clean line, in request mode, the emulator's output is always
        /// well framed whatever the host sends: only ACK, NAK and valid
        /// replies, one ACK per valid request and one NAK per bad checksum.
        #[test]
        fn output_is_always_well_framed(
            chunks in prop::collection::vec(
                (prop::collection::vec(any::<u8>(), 0..48), 0u64..50_000), 1..40),
            valid in prop::collection::vec(0usize..5, 1..40),
        ) {
            let requests = [
                Request::Status,
                Request::ValuesOnRequest,
                Request::DeviceType,
                Request::ReadConfig,
                Request::OneScan,
            ];
            let (mut emulator, t0) = running(Baud::B500000);
            let mut now = t0;
            let mut out = Vec::new();
            for ((bytes, gap_us), pick) in chunks.iter().zip(valid.iter().cycle()) {
                now += Duration::from_micros(*gap_us);
                emulator.handle_input(bytes, now);
                // Past the 6 ms gap: a partial random frame is abandoned.
                now += Duration::from_millis(100);
                out.extend(emulator.poll_transmit(now).unwrap_or_default());
                send(&mut emulator, &requests[*pick], now);
                now += Duration::from_millis(100);
                out.extend(emulator.poll_transmit(now).unwrap_or_default());
            }
            out.extend(collect(&mut emulator, now, Duration::from_secs(1)));
            let events = decode(&out);
            let acks = events.iter().filter(|e| matches!(e, DecodeEvent::Ack)).count() as u64;
            let naks = events.iter().filter(|e| matches!(e, DecodeEvent::Nak)).count() as u64;
            let replies = events.iter().filter(|e| matches!(e, DecodeEvent::Reply(_))).count() as u64;
            prop_assert!(!events.iter().any(|e| matches!(e, DecodeEvent::Dropped { .. })), "{events:?}");
            prop_assert_eq!(acks, emulator.stats().requests);
            prop_assert_eq!(naks, emulator.stats().naks);
            prop_assert_eq!(replies, acks);
        }
    }
}
