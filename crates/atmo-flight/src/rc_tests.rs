//! One test per mapping rule of [`super::RcPilot`] and per check of
//! [`super::RcConfig::validate`].

use super::*;

const MIN: u16 = 1094;
const CENTRE: u16 = 1514;
const MAX: u16 = 1934;

/// Sticks centred, switches low, 16 channels: offboard and MPC off.
fn frame() -> InputRc {
    let mut rc = InputRc {
        channel_count: 16,
        ..InputRc::default()
    };
    rc.values = [MIN; 18];
    for ch in [1, 2, 3, 4] {
        rc.values[ch - 1] = CENTRE;
    }
    rc
}

fn set(rc: &mut InputRc, channel: usize, pulse: u16) {
    rc.values[channel - 1] = pulse;
}

/// Offboard and MPC on (the authors' channels 9 and 8 at max).
fn flying_frame() -> InputRc {
    let mut rc = frame();
    set(&mut rc, 9, MAX);
    set(&mut rc, 8, MAX);
    rc
}

fn parse<T: serde::de::DeserializeOwned>(text: &str) -> atmo_core::Result<T> {
    atmo_core::config_file::parse_toml(text, Path::new("rc.toml"))
}

fn pilot() -> RcPilot {
    RcPilot::new(RcConfig::default())
}

#[test]
fn centred_sticks_command_nothing_within_the_dead_band() {
    let mut p = pilot();
    let mut rc = flying_frame();
    let r = p.map(&rc).unwrap();
    assert_eq!(r.pilot.velocity, [0.0; 3]);
    assert_eq!((r.pilot.yaw_rate, r.pilot.throttle), (0.0, 0.0));
    set(&mut rc, 2, CENTRE + 10);
    set(&mut rc, 1, CENTRE - 10);
    assert_eq!(
        p.map(&rc).unwrap().pilot.velocity,
        [0.0; 3],
        "edge of the band"
    );
    set(&mut rc, 2, CENTRE + 11);
    assert!(p.map(&rc).unwrap().pilot.velocity[0] < 0.0, "just past it");
}

#[test]
fn full_sticks_give_the_configured_rates_with_the_authors_signs() {
    let mut p = pilot();
    let mut rc = flying_frame();
    set(&mut rc, 2, MAX); // pitch: north negative (reversed)
    set(&mut rc, 1, MIN); // roll: east positive (reversed, low end)
    set(&mut rc, 3, MAX); // throttle up: NED z negative
    set(&mut rc, 4, MAX); // yaw: reversed
    let r = p.map(&rc).unwrap().pilot;
    assert!((r.velocity[0] + 0.75).abs() < 1e-12, "{:?}", r.velocity);
    assert!((r.velocity[1] - 0.75).abs() < 1e-12);
    assert!((r.velocity[2] + 0.75).abs() < 1e-12);
    assert!((r.yaw_rate + 45f64.to_radians()).abs() < 1e-12);
    assert!((r.throttle - 1.0).abs() < 1e-12);
}

#[test]
fn each_side_of_a_stick_scales_on_its_own_and_clamps() {
    let config = RcConfig {
        min_us: 1000,
        center_us: 1600,
        max_us: 1900,
        deadband_us: 0,
        ..RcConfig::default()
    };
    let mut p = RcPilot::new(config);
    let mut rc = flying_frame();
    set(&mut rc, 3, 1750); // half of 1600..1900
    assert!((p.map(&rc).unwrap().pilot.velocity[2] + 0.375).abs() < 1e-12);
    set(&mut rc, 3, 1300); // half of 1000..1600, down
    assert!((p.map(&rc).unwrap().pilot.velocity[2] - 0.375).abs() < 1e-12);
    set(&mut rc, 3, 2100); // past max: clamped
    assert!((p.map(&rc).unwrap().pilot.velocity[2] + 0.75).abs() < 1e-12);
}

#[test]
fn throttle_is_the_upper_half_of_the_vertical_stick_only() {
    let mut p = pilot();
    let mut rc = flying_frame();
    set(&mut rc, 3, MIN);
    let r = p.map(&rc).unwrap().pilot;
    assert_eq!(r.throttle, 0.0, "descending is no negative throttle");
    assert!(r.velocity[2] > 0.0, "but a descent");
    set(&mut rc, 3, u16::midpoint(CENTRE, MAX) + 5);
    let t = p.map(&rc).unwrap().pilot.throttle;
    assert!((0.5..0.52).contains(&t), "{t}");
}

#[test]
fn switches_read_high_and_low_positions_and_a_middle_is_off() {
    let mut config = RcConfig::default();
    config.switches.mpc.on = SwitchOn::Low;
    let mut p = RcPilot::new(config);
    let mut rc = frame();
    set(&mut rc, 9, MAX);
    set(&mut rc, 8, MIN);
    let r = p.map(&rc).unwrap().pilot;
    assert!(r.offboard && r.mpc_enabled && r.arm);
    set(&mut rc, 9, CENTRE);
    set(&mut rc, 8, CENTRE);
    let r = p.map(&rc).unwrap().pilot;
    assert!(!r.offboard && !r.mpc_enabled, "middle position");
}

#[test]
fn the_kill_switch_disarms_at_once_and_latches_until_offboard_goes_off() {
    let mut p = pilot();
    let mut rc = flying_frame();
    assert!(p.map(&rc).unwrap().pilot.arm);
    set(&mut rc, 5, MAX);
    let killed = p.map(&rc).unwrap().pilot;
    assert!(!killed.arm && p.kill_latched());
    set(&mut rc, 5, MIN);
    assert!(
        !p.map(&rc).unwrap().pilot.arm,
        "kill released: still latched"
    );
    set(&mut rc, 9, MIN);
    let off = p.map(&rc).unwrap().pilot;
    assert!(!off.offboard, "offboard off: disarmed");
    assert!(!p.kill_latched());
    set(&mut rc, 9, MAX);
    assert!(
        p.map(&rc).unwrap().pilot.arm,
        "offboard cycled: armed again"
    );
}

#[test]
fn px4_lost_and_failsafe_flags_mark_the_frame_lost_and_do_not_touch_the_latch() {
    let mut p = pilot();
    let mut rc = flying_frame();
    rc.rc_lost = true;
    set(&mut rc, 5, MAX); // a receiver's failsafe value on the kill channel
    let r = p.map(&rc).unwrap();
    assert!(r.lost && !p.kill_latched());
    rc.rc_lost = false;
    rc.rc_failsafe = true;
    assert!(p.map(&rc).unwrap().lost);
}

#[test]
fn frames_missing_a_mapped_channel_or_with_no_servo_pulse_are_rejected() {
    let mut p = pilot();
    let mut rc = flying_frame();
    rc.channel_count = 8; // offboard is channel 9
    assert_eq!(
        p.map(&rc),
        Err(RcReject::MissingChannel {
            channel: 9,
            channel_count: 8
        })
    );
    rc.channel_count = 16;
    set(&mut rc, 4, 0);
    let err = p.map(&rc).unwrap_err();
    assert_eq!(
        err,
        RcReject::ImplausiblePulse {
            channel: 4,
            pulse_us: 0
        }
    );
    assert!(err.to_string().contains("channel 4"), "{err}");
    // A rejected frame leaves the kill latch alone.
    set(&mut rc, 4, CENTRE);
    set(&mut rc, 5, MAX);
    set(&mut rc, 3, 2500);
    assert!(p.map(&rc).is_err() && !p.kill_latched());
}

#[test]
fn the_shipped_mapping_is_valid_and_bad_keys_are_named() {
    let file = Path::new("daemon.toml");
    RcConfig::default().validate(file).unwrap();
    let cases: [(&str, RcConfig); 6] = [
        (
            "rc.timeout_ms",
            RcConfig {
                timeout_ms: 0,
                ..RcConfig::default()
            },
        ),
        (
            "rc.center_us",
            RcConfig {
                center_us: 1000,
                ..RcConfig::default()
            },
        ),
        (
            "rc.max_us",
            RcConfig {
                max_us: 1400,
                ..RcConfig::default()
            },
        ),
        (
            "rc.deadband_us",
            RcConfig {
                deadband_us: 300,
                ..RcConfig::default()
            },
        ),
        (
            "rc.switch_threshold",
            RcConfig {
                switch_threshold: f64::NAN,
                ..RcConfig::default()
            },
        ),
        (
            "rc.max_yaw_rate_deg_s",
            RcConfig {
                max_yaw_rate_deg_s: -1.0,
                ..RcConfig::default()
            },
        ),
    ];
    for (key, config) in cases {
        let err = config.validate(file).unwrap_err().to_string();
        assert!(
            err.contains(key) && err.contains("daemon.toml"),
            "{key}: {err}"
        );
    }
    let mut config = RcConfig::default();
    config.switches.kill.channel = 19;
    let err = config.validate(file).unwrap_err().to_string();
    assert!(err.contains("rc.switches.kill.channel"), "{err}");
    config.switches.kill.channel = 2;
    let err = config.validate(file).unwrap_err().to_string();
    assert!(
        err.contains("rc.switches.kill.channel") && err.contains("rc.sticks.north.channel"),
        "{err}"
    );
}

#[test]
fn a_toml_table_overrides_only_what_it_names() {
    let text = "timeout_ms = 500\n[switches.kill]\nchannel = 6\non = \"low\"\n";
    let config: RcConfig = parse(text).unwrap();
    assert_eq!(config.timeout_ms, 500);
    assert_eq!(
        config.switches.kill,
        Switch {
            channel: 6,
            on: SwitchOn::Low
        }
    );
    assert_eq!(config.switches.offboard, Switches::default().offboard);
    assert!(
        parse::<RcConfig>("kill_channel = 5").is_err(),
        "unknown key"
    );
    assert!(parse::<RcConfig>("[switches.kill]\nchannel = 6\non = \"up\"").is_err());
}

#[test]
fn mapping_never_panics_on_any_pulse() {
    let mut p = pilot();
    let mut rc = flying_frame();
    for pulse in (0..=u16::MAX).step_by(7) {
        for ch in 1..=18 {
            set(&mut rc, ch, pulse);
        }
        rc.channel_count = (pulse % 40) as u8;
        if let Ok(r) = p.map(&rc) {
            assert!(r.pilot.velocity.iter().all(|v| v.abs() <= 0.75 + 1e-12));
            assert!((0.0..=1.0).contains(&r.pilot.throttle));
        }
    }
}

#[test]
fn the_tilt_lever_and_the_encoder_reset_read_the_authors_channels() {
    let mut p = pilot();
    let mut rc = frame();
    set(&mut rc, 10, CENTRE);
    let r = p.map(&rc).unwrap();
    assert_eq!((r.tilt_lever, r.rehome_tilt), (0.0, false), "lever centred");
    set(&mut rc, 10, MAX);
    set(&mut rc, 12, MAX);
    let r = p.map(&rc).unwrap();
    assert!((r.tilt_lever - 1.0).abs() < 1e-12, "towards drive");
    assert!(r.rehome_tilt);
    set(&mut rc, 10, MIN);
    assert!((p.map(&rc).unwrap().tilt_lever + 1.0).abs() < 1e-12);
}

#[test]
fn a_receiver_without_the_auxiliary_channels_leaves_them_at_rest() {
    let mut p = pilot();
    let mut rc = flying_frame();
    rc.channel_count = 9;
    set(&mut rc, 10, MAX);
    set(&mut rc, 12, MAX);
    let r = p.map(&rc).expect("the frame is used");
    assert_eq!((r.tilt_lever, r.rehome_tilt), (0.0, false));
    assert!(r.pilot.offboard);
    // A delivered auxiliary channel that is no servo pulse loses the frame,
    // as any mapped channel does.
    rc.channel_count = 16;
    set(&mut rc, 10, 3000);
    assert_eq!(
        p.map(&rc),
        Err(RcReject::ImplausiblePulse {
            channel: 10,
            pulse_us: 3000
        })
    );
}
