//! The driver's link state machine and the emulated LMS200 back to back, in
//! one thread on a virtual clock (no pty, no sleeping): a specification of
//! how the link brings a sensor from any state to streaming and recovers.

#![allow(clippy::unwrap_used)]

#[path = "link_emulator/harness.rs"]
mod harness;
#[path = "link_emulator/proptests.rs"]
mod proptests;

use std::time::Duration;

use harness::Harness;
use lms200::emulator::{EmulatorConfig, FaultConfig, OperatingMode};
use lms200::link::{Command, Event, LinkConfig, LinkError, ReinitReason};
use lms200::{Baud, ConfigBlock, MeasuringMode, Units, Variant};

fn fast_config(variant: Variant, units: Units, target: Baud) -> LinkConfig {
    LinkConfig {
        variant,
        units,
        target_baud: target,
        ..LinkConfig::default()
    }
}

#[test]
fn every_variant_and_unit_streams_scans_of_the_right_length() {
    for variant in Variant::ALL {
        for units in Units::ALL {
            let mut h = Harness::new(
                fast_config(variant, units, Baud::B500000),
                EmulatorConfig::default(),
            );
            h.run_until_scans(5, Duration::from_secs(30));
            let connected = h
                .connected()
                .unwrap_or_else(|| panic!("{variant:?} {units:?}: no Connected"));
            assert_eq!(
                connected,
                (Baud::B500000, variant, units),
                "{variant:?} {units:?}"
            );
            for scan in h.scans() {
                assert_eq!(
                    scan.scan.values.len(),
                    usize::from(variant.value_count()),
                    "{variant:?}"
                );
                assert_eq!(scan.scan.units(), Some(units));
                assert_eq!(scan.variant, variant);
            }
            assert_eq!(h.emulator.variant(), variant);
            assert_eq!(h.emulator.config_block().units(), Some(units));
            h.assert_scans_match_emulator();
        }
    }
}

#[test]
fn connected_reports_the_device_and_firmware() {
    let mut h = Harness::new(LinkConfig::default(), EmulatorConfig::default());
    h.run_until_scans(1, Duration::from_secs(30));
    let event = h
        .events()
        .find(|e| matches!(e, Event::Connected { .. }))
        .cloned()
        .unwrap();
    let Event::Connected {
        device_type,
        firmware,
        ..
    } = event
    else {
        unreachable!()
    };
    assert_eq!(device_type, "LMS200");
    assert_eq!(firmware, "V02.10");
}

#[test]
fn every_target_baud_is_reached_on_both_sides() {
    for target in Baud::ALL {
        let config = fast_config(Variant::Fov180Res100, Units::Mm, target);
        let mut h = Harness::new(config, EmulatorConfig::default());
        h.run_until_scans(3, Duration::from_secs(60));
        assert_eq!(h.emulator.baud(), target, "{target:?}");
        assert_eq!(h.host_baud, target, "{target:?}");
        assert_eq!(h.link.host_baud(), target);
        h.assert_scans_match_emulator();
    }
}

#[test]
fn a_sensor_left_at_another_speed_or_streaming_is_found() {
    let table = [
        (Baud::B38400, false),
        (Baud::B500000, false),
        (Baud::B19200, false),
        (Baud::B500000, true),
        (Baud::B9600, true),
        (Baud::B38400, true),
    ];
    for (baud, streaming) in table {
        let mut h = Harness::new(
            LinkConfig::default(),
            EmulatorConfig::left_running(baud, streaming),
        );
        h.run_until_scans(3, Duration::from_secs(60));
        assert!(h.link.is_streaming(), "{baud:?} streaming={streaming}");
        assert_eq!(h.emulator.baud(), Baud::B500000);
        h.assert_scans_match_emulator();
    }
}

#[test]
fn scan_timestamps_are_the_middle_of_the_sweep() {
    for (variant, baud) in [
        (Variant::Fov180Res50, Baud::B500000),
        (Variant::Fov100Res25, Baud::B500000),
        (Variant::Fov180Res100, Baud::B38400),
    ] {
        let mut h = Harness::new(
            fast_config(variant, Units::Mm, baud),
            EmulatorConfig::default(),
        );
        h.run_until_scans(4, Duration::from_secs(60));
        let sent: Vec<_> = h.emulator.sent_scans().cloned().collect();
        for scan in h.scans() {
            let original = sent
                .iter()
                .find(|s| s.values == scan.scan.values && s.indices == scan.scan.indices);
            let original = original.unwrap();
            let error = if scan.timestamp > original.mid_sweep {
                scan.timestamp - original.mid_sweep
            } else {
                original.mid_sweep - scan.timestamp
            };
            assert!(
                error < Duration::from_micros(5),
                "{variant:?} {baud:?}: off by {error:?}"
            );
        }
    }
}

#[test]
fn line_faults_cost_telegrams_but_never_deliver_wrong_scans() {
    let table = [
        (
            "garbage",
            FaultConfig {
                garbage_per_byte: 0.002,
                ..FaultConfig::default()
            },
        ),
        (
            "bit flips",
            FaultConfig {
                bit_flip_per_byte: 0.002,
                ..FaultConfig::default()
            },
        ),
        (
            "dropped bytes",
            FaultConfig {
                drop_per_byte: 0.002,
                ..FaultConfig::default()
            },
        ),
    ];
    for (name, faults) in table {
        let emulator = EmulatorConfig {
            faults,
            seed: 7,
            ..EmulatorConfig::default()
        };
        let mut h = Harness::new(LinkConfig::default(), emulator);
        h.run_until_scans(60, Duration::from_secs(120));
        assert!(h.link.is_streaming(), "{name}");
        let stats = h.link.stats();
        assert!(stats.lost_telegrams > 0, "{name}: {stats:?}");
        assert!(stats.dropped_frames > 0, "{name}: {stats:?}");
        h.assert_scans_match_emulator();
    }
}

#[test]
fn naks_are_answered_by_a_resend_after_30_ms() {
    let emulator = EmulatorConfig {
        faults: FaultConfig {
            nak_every_nth_request: Some(2),
            ..FaultConfig::default()
        },
        ..EmulatorConfig::default()
    };
    let mut h = Harness::new(LinkConfig::default(), emulator);
    h.run_until_scans(3, Duration::from_secs(60));
    assert!(h.link.is_streaming());
    let stats = h.link.stats();
    assert!(stats.naks >= 3 && stats.resends >= 3, "{stats:?}");
    let mut resends = 0;
    for pair in h.transmits.windows(2) {
        let ((t1, f1), (t2, f2)) = (&pair[0], &pair[1]);
        if f1 == f2 {
            resends += 1;
            assert!(
                *t2 - *t1 >= Duration::from_millis(30),
                "resent after {:?}",
                *t2 - *t1
            );
        }
    }
    assert!(resends >= 3);
}

#[test]
fn a_silent_sensor_is_reinitialised() {
    let mut h = Harness::new(LinkConfig::default(), EmulatorConfig::default());
    h.run_until_scans(3, Duration::from_secs(30));
    let now = h.now;
    h.emulator.silence(now, Duration::from_secs(2));
    let before = h.scans().count();
    h.run_until(Duration::from_secs(30), |h| h.scans().count() > before + 3);
    assert!(h.events().any(|e| *e == Event::SensorSilent));
    assert!(h.events().any(|e| *e
        == Event::Reinitializing {
            reason: ReinitReason::SensorSilent
        }));
    assert_eq!(h.link.stats().silences, 1);
    assert!(h.link.is_streaming());
}

#[test]
fn a_power_cycle_is_detected_and_streaming_resumes() {
    let mut h = Harness::new(LinkConfig::default(), EmulatorConfig::default());
    h.run_until_scans(3, Duration::from_secs(30));
    let now = h.now;
    h.emulator.power_cycle(now);
    let before = h.scans().count();
    h.run_until(Duration::from_secs(30), |h| h.scans().count() > before + 3);
    assert!(h.link.is_streaming());
    assert_eq!(h.emulator.baud(), Baud::B500000);
    // The 90 arrives at 9600 while the host listens at 500k: garbled, so
    // the watchdog finds the silence; either way the link starts over.
    let stats = h.link.stats();
    assert!(stats.silences + stats.sensor_restarts >= 1, "{stats:?}");
    h.assert_scans_match_emulator();
}

#[test]
fn a_power_on_telegram_while_streaming_at_9600_restarts_set_up() {
    let config = fast_config(Variant::Fov180Res100, Units::Mm, Baud::B9600);
    let mut h = Harness::new(config, EmulatorConfig::default());
    h.run_until_scans(2, Duration::from_secs(30));
    let now = h.now;
    h.emulator.power_cycle(now);
    let before = h.scans().count();
    h.run_until(Duration::from_secs(60), |h| h.scans().count() > before + 2);
    assert!(h.events().any(|e| *e == Event::SensorRestarted));
    assert!(h.events().any(|e| *e
        == Event::Reinitializing {
            reason: ReinitReason::SensorRestarted
        }));
    assert!(h.link.is_streaming());
}

#[test]
fn the_configuration_is_written_once_and_then_left_alone() {
    let mut h = Harness::new(LinkConfig::default(), EmulatorConfig::default());
    h.run_until_scans(2, Duration::from_secs(30));
    // TL defaults have the real-time indices off; the default link wants them.
    assert_eq!(h.emulator.eeprom_writes(), 1);
    assert!(h.emulator.config_block().real_time_indices());
    h.close_and_wait();
    let emulator = h.emulator;
    let mut second = Harness::with_emulator(LinkConfig::default(), emulator, h.now);
    second.run_until_scans(2, Duration::from_secs(30));
    assert_eq!(
        second.emulator.eeprom_writes(),
        1,
        "second run must not write the EEPROM"
    );
    assert_eq!(second.link.stats().config_writes, 0);
}

#[test]
fn a_matching_configuration_is_never_written() {
    let link = LinkConfig {
        real_time_indices: false,
        ..LinkConfig::default()
    };
    let mut h = Harness::new(link, EmulatorConfig::default());
    h.run_until_scans(2, Duration::from_secs(30));
    assert_eq!(h.emulator.eeprom_writes(), 0);
}

#[test]
fn old_firmware_gets_its_32_byte_block_back() {
    let link = fast_config(Variant::Fov180Res50, Units::Cm, Baud::B500000);
    let mut h = Harness::new(link, EmulatorConfig::old_firmware());
    h.run_until_scans(2, Duration::from_secs(30));
    assert_eq!(h.emulator.eeprom_writes(), 1);
    let block: ConfigBlock = h.emulator.config_block();
    assert_eq!(block.as_bytes().len(), 32);
    assert_eq!(block.units(), Some(Units::Cm));
    let write = h
        .transmits
        .iter()
        .find(|(_, f)| f.get(4) == Some(&0x77))
        .unwrap();
    assert_eq!(write.1.len(), 4 + 1 + 32 + 2);
}

#[test]
fn close_leaves_the_sensor_at_9600_in_request_mode() {
    for target in [Baud::B500000, Baud::B38400, Baud::B9600] {
        let mut h = Harness::new(
            fast_config(Variant::Fov180Res50, Units::Mm, target),
            EmulatorConfig::default(),
        );
        h.run_until_scans(2, Duration::from_secs(60));
        h.close_and_wait();
        assert!(h.events().any(|e| *e == Event::Closed), "{target:?}");
        assert!(h.link.is_closed());
        assert_eq!(h.emulator.baud(), Baud::B9600, "{target:?}");
        assert_eq!(h.emulator.operating_mode(), OperatingMode::OnRequest);
        assert_eq!(h.host_baud, Baud::B9600);
        // The permanent-baud command is never sent.
        assert!(!h.transmits.iter().any(|(_, f)| f.get(4) == Some(&0x66)));
    }
}

#[test]
fn a_sensor_that_never_answers_is_reported_with_the_bauds_tried() {
    let mut h = Harness::new(LinkConfig::default(), EmulatorConfig::default());
    let now = h.now;
    h.emulator.silence(now, Duration::from_secs(3600));
    h.run_until(Duration::from_secs(60), |_| false);
    let errors: Vec<&LinkError> = h
        .events()
        .filter_map(|e| match e {
            Event::Error(error) => Some(error),
            _ => None,
        })
        .collect();
    assert!(errors.len() >= 2, "{errors:?}");
    let expected = vec![Baud::B9600, Baud::B38400, Baud::B500000, Baud::B19200];
    assert_eq!(
        *errors[0],
        LinkError::NoAnswer {
            bauds_tried: expected
        }
    );
    assert!(
        errors[0]
            .to_string()
            .contains("9600, 38400, 500000, 19200 Bd")
    );
    // Capped doubling: the pauses between rounds never shrink.
    let gaps = h.backoff_pauses();
    assert!(gaps.len() >= 2, "{gaps:?}");
    assert!(gaps.windows(2).all(|w| w[1] >= w[0]), "{gaps:?}");
    assert!(
        gaps.iter()
            .all(|g| *g <= Duration::from_secs(5) + Duration::from_secs(2)),
        "{gaps:?}"
    );
}

#[test]
fn a_rejected_command_is_named() {
    let emulator = EmulatorConfig {
        unsupported_commands: vec![0x74],
        ..EmulatorConfig::default()
    };
    let mut h = Harness::new(LinkConfig::default(), emulator);
    h.run_until(Duration::from_secs(30), |h| {
        h.events().any(|e| {
            matches!(
                e,
                Event::Error(LinkError::Rejected { .. } | LinkError::VariantRefused(_))
            )
        })
    });
    assert!(h.events().any(|e| *e
        == Event::CommandRejected {
            command: Command::ReadConfig
        }));
    let error = LinkError::Rejected {
        command: Command::ReadConfig,
    };
    assert!(h.events().any(|e| *e == Event::Error(error.clone())));
    assert!(error.to_string().starts_with("74 (read configuration)"));
}

#[test]
fn a_refused_variant_is_a_typed_error() {
    let emulator = EmulatorConfig {
        variant_change_allowed: false,
        variant: Variant::Fov100Res100,
        ..EmulatorConfig::default()
    };
    let mut h = Harness::new(LinkConfig::default(), emulator);
    h.run_until(Duration::from_secs(30), |h| {
        h.events().any(|e| {
            matches!(
                e,
                Event::Error(LinkError::Rejected { .. } | LinkError::VariantRefused(_))
            )
        })
    });
    assert!(
        h.events()
            .any(|e| *e == Event::Error(LinkError::VariantRefused(Variant::Fov180Res50)))
    );
    assert!(!h.link.is_streaming());
}

#[test]
fn a_driver_that_ignores_set_baud_never_streams() {
    let mut h = Harness::new(LinkConfig::default(), EmulatorConfig::default());
    h.host_stuck_at_9600 = true;
    h.run_until(Duration::from_secs(10), |h| h.scans().count() > 0);
    assert_eq!(h.scans().count(), 0);
    assert!(h.emulator.stats().garbled_input_bytes > 0);
}

#[test]
fn the_info_status_of_real_units_is_normal() {
    let emulator = EmulatorConfig {
        status: lms200::Status(0x11),
        ..EmulatorConfig::left_running(Baud::B9600, false)
    };
    let mut h = Harness::new(LinkConfig::default(), emulator);
    h.run_until_scans(5, Duration::from_secs(30));
    assert!(!h.events().any(|e| matches!(
        e,
        Event::Error(_)
            | Event::Reinitializing {
                reason: ReinitReason::SensorSilent
            }
    )));
    assert_eq!(h.link.stats().reinits, 0);
    h.assert_scans_match_emulator();
}

#[test]
fn scan_index_gaps_count_the_scans_the_line_could_not_carry() {
    // At 38400 Bd a 732-byte telegram takes 191 ms: the sensor sends one
    // 180°/0.5° scan in 9 (TL Table 10-17) and the link sees the gaps in
    // the scan index.
    let config = fast_config(Variant::Fov180Res50, Units::Mm, Baud::B38400);
    let mut h = Harness::new(config, EmulatorConfig::default());
    h.run_until_scans(10, Duration::from_secs(30));
    let stats = h.link.stats();
    assert_eq!(stats.lost_telegrams, 0, "{stats:?}");
    assert_eq!(stats.skipped_scans, 8 * (stats.scans - 1), "{stats:?}");
}

#[test]
fn the_measuring_mode_is_configured_and_scans_follow_it() {
    for mode in [
        MeasuringMode::Bits14FieldsAb,
        MeasuringMode::Bits15FieldA,
        MeasuringMode::Bits16Immediate,
    ] {
        let link = LinkConfig {
            measuring_mode: mode,
            ..LinkConfig::default()
        };
        let mut h = Harness::new(link, EmulatorConfig::default());
        h.run_until_scans(3, Duration::from_secs(30));
        assert_eq!(h.emulator.config_block().measuring_mode(), Some(mode));
        for scan in h.scans() {
            let ranges: Vec<f64> = (0..scan.scan.values.len())
                .filter_map(|i| scan.scan.range_m(i, mode))
                .collect();
            assert_eq!(
                ranges.len(),
                scan.scan.values.len(),
                "{mode:?}: every beam of the room has an echo"
            );
            assert!(ranges.iter().all(|r| *r > 0.3 && *r < 8.0), "{mode:?}");
        }
        h.assert_scans_match_emulator();
    }
}

#[test]
fn a_command_that_is_always_nacked_is_named() {
    let emulator = EmulatorConfig {
        faults: FaultConfig {
            nak_every_nth_request: Some(1),
            ..FaultConfig::default()
        },
        ..EmulatorConfig::left_running(Baud::B9600, false)
    };
    let mut h = Harness::new(LinkConfig::default(), emulator);
    h.run_until(Duration::from_secs(10), |h| {
        h.events().any(|e| matches!(e, Event::Error(_)))
    });
    let error = LinkError::Nacked {
        command: Command::StopOutput,
        naks: 3,
    };
    assert!(
        h.events().any(|e| *e == Event::Error(error.clone())),
        "{:?}",
        h.brief_log()
    );
    assert_eq!(
        error.to_string(),
        "20 25 (stop output / request mode): refused with NAK 3 times"
    );
    assert!(!h.link.is_streaming());
}
