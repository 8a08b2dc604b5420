//! Property: whatever the line does, the link never delivers a scan that
//! differs from one the emulator sent, and never reorders them; the one
//! exception is a damaged telegram whose 16-bit checksum matched by chance,
//! which must then be on the line as the link read it (see
//! `Harness::assert_scans_match_emulator`).

use std::time::Duration;

use lms200::Baud;
use lms200::emulator::{EmulatorConfig, FaultConfig};
use lms200::link::LinkConfig;
use proptest::prelude::*;

use super::harness::Harness;

proptest! {
    #![proptest_config(ProptestConfig { cases: 16, ..ProptestConfig::default() })]

    #[test]
    fn faults_never_produce_wrong_scans(
        seed in any::<u64>(),
        garbage in 0.0f64..0.0005,
        flips in 0.0f64..0.0005,
        drops in 0.0f64..0.0005,
        nak_every in prop::option::of(2u32..6),
        target in prop::sample::select(vec![Baud::B38400, Baud::B500000]),
        start in prop::sample::select(vec![Baud::B9600, Baud::B38400, Baud::B500000]),
    ) {
        let faults = FaultConfig {
            garbage_per_byte: garbage,
            bit_flip_per_byte: flips,
            drop_per_byte: drops,
            nak_every_nth_request: nak_every,
        };
        let emulator = EmulatorConfig { faults, seed, ..EmulatorConfig::left_running(start, false) };
        let link = LinkConfig { target_baud: target, ..LinkConfig::default() };
        let mut h = Harness::new(link, emulator);
        // At the highest rates about one 38400 Bd telegram in three is
        // intact, a couple a second: 60 s of virtual time leave 20 scans a
        // wide margin (30 s fell short about one run in 10,000).
        h.run_until(Duration::from_secs(60), |h| h.scans().count() >= 20);
        // The faults stay within what the link must ride out.
        prop_assert!(h.scans().count() >= 20, "{:?}", h.brief_log());
        h.assert_scans_match_emulator();
    }
}
