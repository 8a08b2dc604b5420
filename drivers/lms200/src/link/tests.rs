//! The link against hand-fed sensor bytes: ordering of outputs, timers,
//! retries and error naming, without an emulator.

#![allow(clippy::unwrap_used)]

use std::time::{Duration, Instant};

use super::*;
use crate::{ModeChangeResult, Reply, Status};

fn outputs(link: &mut Link) -> Vec<Output> {
    std::iter::from_fn(|| link.poll_output()).collect()
}

fn transmits(outputs: &[Output]) -> Vec<Vec<u8>> {
    outputs
        .iter()
        .filter_map(|o| match o {
            Output::Transmit(bytes) => Some(bytes.clone()),
            _ => None,
        })
        .collect()
}

fn reply(reply: Reply) -> Vec<u8> {
    reply.encode(0x80, Status::OK).unwrap()
}

#[test]
fn starts_by_setting_the_first_probe_rate_then_stopping_output() {
    let t0 = Instant::now();
    let mut link = Link::new(LinkConfig::default(), t0);
    let out = outputs(&mut link);
    assert_eq!(
        out[0],
        Output::Event(Event::Reinitializing {
            reason: ReinitReason::Start
        })
    );
    assert_eq!(out[1], Output::SetBaud(Baud::B9600));
    assert_eq!(
        out[2],
        Output::Transmit(Request::ValuesOnRequest.encode().unwrap())
    );
    assert_eq!(out.len(), 3);
    // ACK wait = wire time of 8 bytes at 9600 (8.33 ms) + 100 ms.
    assert_eq!(
        link.poll_timeout(),
        Some(t0 + Duration::from_nanos(8_333_333) + Duration::from_millis(100))
    );
}

#[test]
fn a_nak_waits_30_ms_before_the_identical_resend() {
    let t0 = Instant::now();
    let mut link = Link::new(LinkConfig::default(), t0);
    let first = transmits(&outputs(&mut link));
    let t1 = t0 + Duration::from_millis(15);
    link.handle_input(&[0x15], t1);
    assert_eq!(link.poll_timeout(), Some(t1 + Duration::from_millis(30)));
    link.handle_timeout(t1 + Duration::from_millis(29));
    assert!(outputs(&mut link).is_empty());
    link.handle_timeout(t1 + Duration::from_millis(30));
    assert_eq!(transmits(&outputs(&mut link)), first);
    assert_eq!(link.stats().naks, 1);
    assert_eq!(link.stats().resends, 1);
}

#[test]
fn three_unanswered_tries_move_auto_baud_to_the_next_rate() {
    let t0 = Instant::now();
    let mut link = Link::new(LinkConfig::default(), t0);
    let mut sent = transmits(&outputs(&mut link)).len();
    let mut now = t0;
    let mut next_baud = None;
    while next_baud.is_none() {
        now = link.poll_timeout().unwrap();
        link.handle_timeout(now);
        for output in outputs(&mut link) {
            match output {
                Output::Transmit(_) => sent += 1,
                Output::SetBaud(baud) => next_baud = Some(baud),
                Output::Event(_) => {}
            }
        }
    }
    assert_eq!(next_baud, Some(Baud::B38400));
    assert_eq!(sent, 3 + 1, "three tries at 9600, then the first at 38400");
    assert!(now - t0 >= Duration::from_millis(3 * 100 + 2 * 30));
}

#[test]
fn an_invalid_command_reply_names_the_command() {
    let t0 = Instant::now();
    let mut link = Link::new(LinkConfig::default(), t0);
    outputs(&mut link);
    let mut bytes = vec![0x06];
    bytes.extend(reply(Reply::InvalidCommand));
    link.handle_input(&bytes, t0 + Duration::from_millis(20));
    let out = outputs(&mut link);
    assert!(out.contains(&Output::Event(Event::CommandRejected {
        command: Command::StopOutput
    })));
    assert_eq!(link.stats().rejected_commands, 1);
    // During auto-baud a rejection means "not the sensor we want here":
    // the link moves on to the next rate.
    assert!(out.contains(&Output::SetBaud(Baud::B38400)));
}

#[test]
fn a_stale_reply_does_not_complete_the_wrong_request() {
    let t0 = Instant::now();
    let mut link = Link::new(LinkConfig::default(), t0);
    outputs(&mut link);
    let t1 = t0 + Duration::from_millis(20);
    link.handle_input(&[0x06], t1);
    // A BA (type) reply while 20 25 is outstanding is ignored.
    link.handle_input(
        &reply(Reply::DeviceType(b"LMS200;30106;V02.10 ".to_vec())),
        t1,
    );
    assert!(transmits(&outputs(&mut link)).is_empty());
    link.handle_input(&reply(Reply::ModeChanged(ModeChangeResult::Success)), t1);
    assert_eq!(
        transmits(&outputs(&mut link)),
        vec![Request::Status.encode().unwrap()]
    );
}

#[test]
fn a_power_on_telegram_restarts_auto_baud_at_9600() {
    let t0 = Instant::now();
    let config = LinkConfig {
        baud_hint: Some(Baud::B500000),
        ..LinkConfig::default()
    };
    let mut link = Link::new(config, t0);
    assert!(outputs(&mut link).contains(&Output::SetBaud(Baud::B500000)));
    // 9600 garbage aside, suppose the 90 got through.
    link.handle_input(
        &reply(Reply::PowerOn(b"LMS200;30106;V02.10 ".to_vec())),
        t0 + Duration::from_millis(5),
    );
    let out = outputs(&mut link);
    assert!(out.contains(&Output::Event(Event::SensorRestarted)));
    assert!(out.contains(&Output::SetBaud(Baud::B9600)));
    assert_eq!(link.stats().sensor_restarts, 1);
}

#[test]
fn close_before_any_sensor_was_found_closes_at_once() {
    let t0 = Instant::now();
    let mut link = Link::new(LinkConfig::default(), t0);
    outputs(&mut link);
    link.close(t0 + Duration::from_millis(1));
    assert_eq!(outputs(&mut link), vec![Output::Event(Event::Closed)]);
    assert!(link.is_closed());
    assert_eq!(link.poll_timeout(), None);
    link.handle_input(&[0x06], t0 + Duration::from_millis(2));
    assert!(outputs(&mut link).is_empty());
}

mod properties {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Whatever arrives, the link never panics and always keeps a
        /// deadline armed: it can never wait forever (liveness).
        #[test]
        fn random_input_never_leaves_the_link_without_a_deadline(
            chunks in prop::collection::vec(
                (prop::collection::vec(any::<u8>(), 0..64), 0u64..400_000), 1..60),
            with_replies in any::<bool>(),
        ) {
            let t0 = Instant::now();
            let mut link = Link::new(LinkConfig::default(), t0);
            let mut now = t0;
            let canned = [
                reply(Reply::ModeChanged(ModeChangeResult::Success)),
                reply(Reply::Status(vec![0; 152])),
                reply(Reply::DeviceType(b"LMS200;30106;V02.10 ".to_vec())),
            ];
            for (i, (bytes, gap_us)) in chunks.iter().enumerate() {
                now += Duration::from_micros(*gap_us);
                link.handle_timeout(now);
                link.handle_input(bytes, now);
                if with_replies {
                    let mut acked = vec![0x06];
                    acked.extend(&canned[i % canned.len()]);
                    link.handle_input(&acked, now);
                }
                while link.poll_output().is_some() {}
                prop_assert!(link.poll_timeout().is_some());
                prop_assert!(!link.is_closed());
            }
        }
    }
}
