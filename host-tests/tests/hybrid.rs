//! Properties of the hybrid kinematic/dynamic switch (`catmodel::model::hybrid`), on arbitrary
//! input sequences (including NaN and infinities) and arbitrary well-formed thresholds:
//! it never chatters (a mode is held at least `min_dwell_ticks`), it only switches when the
//! thresholds say so, it ignores non-finite inputs, it counts every switch, and it does switch
//! when the conditions hold long enough (it cannot get stuck).
use catmodel::model::hybrid::{HybridConfig, HybridState, Mode};
use proptest::prelude::*;

/// Speeds and lateral accelerations around the thresholds, plus non-finite values.
fn input() -> impl Strategy<Value = (f32, f32)> {
    let value = prop_oneof![
        8 => -2.0f32..12.0,
        1 => Just(f32::NAN),
        1 => Just(f32::INFINITY),
        1 => Just(f32::NEG_INFINITY),
    ];
    let lat = prop_oneof![
        8 => -4.0f32..4.0,
        1 => Just(f32::NAN),
        1 => Just(f32::INFINITY),
    ];
    (value, lat)
}

/// Thresholds with enter > exit (the hysteresis band) and any dwell.
fn config() -> impl Strategy<Value = HybridConfig> {
    (1.0f32..8.0, 0.1f32..3.0, 0.5f32..3.0, 0.1f32..1.5, 1u16..60).prop_map(
        |(exit_v, band_v, enter_a, band_a, dwell)| HybridConfig {
            enter_dynamic_speed_mps: exit_v + band_v,
            enter_dynamic_lat_accel_mps2: enter_a,
            exit_dynamic_speed_mps: exit_v,
            exit_dynamic_lat_accel_mps2: (enter_a - band_a).max(0.05),
            min_dwell_ticks: dwell,
        },
    )
}

/// Runs the switch over `inputs`, returning the mode after each tick.
fn run(cfg: &HybridConfig, inputs: &[(f32, f32)]) -> (Vec<Mode>, HybridState) {
    let mut s = HybridState::default();
    let modes = inputs
        .iter()
        .map(|&(v, ay)| cfg.update(&mut s, v, ay))
        .collect();
    (modes, s)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn never_chatters_and_switches_only_on_its_thresholds(
        cfg in config(),
        inputs in prop::collection::vec(input(), 1..600),
    ) {
        let (modes, state) = run(&cfg, &inputs);
        let mut prev = Mode::Kinematic;
        // The initial mode counts as entered one tick before the first update.
        let mut last_switch: i64 = -1;
        let mut switches = 0u32;
        for (i, (&mode, &(v, ay))) in modes.iter().zip(&inputs).enumerate() {
            if mode != prev {
                let i = i as i64;
                prop_assert!(
                    i - last_switch >= i64::from(cfg.min_dwell_ticks),
                    "switch at tick {i} only {} ticks after the previous one (dwell {})",
                    i - last_switch, cfg.min_dwell_ticks
                );
                prop_assert!(v.is_finite() && ay.is_finite(), "switched on a non-finite input");
                match mode {
                    Mode::Dynamic => prop_assert!(
                        v > cfg.enter_dynamic_speed_mps
                            || ay.abs() >= cfg.enter_dynamic_lat_accel_mps2,
                        "entered dynamic at v={v} ay={ay}"
                    ),
                    Mode::Kinematic => prop_assert!(
                        v < cfg.exit_dynamic_speed_mps
                            && ay.abs() < cfg.exit_dynamic_lat_accel_mps2,
                        "left dynamic at v={v} ay={ay}"
                    ),
                }
                last_switch = i;
                switches += 1;
            }
            prev = mode;
        }
        prop_assert_eq!(state.switches, switches);
        prop_assert_eq!(state.mode, prev);
    }

    #[test]
    fn switches_once_the_conditions_hold_for_the_dwell(
        cfg in config(),
        prefix in prop::collection::vec(input(), 0..200),
    ) {
        // Whatever happened before, fast driving for one dwell (plus the tick that decides)
        // reaches dynamic, and slow straight driving then returns to kinematic.
        let (_, mut s) = run(&cfg, &prefix);
        let fast = cfg.enter_dynamic_speed_mps + 1.0;
        for _ in 0..=cfg.min_dwell_ticks {
            cfg.update(&mut s, fast, 0.0);
        }
        prop_assert_eq!(s.mode, Mode::Dynamic);
        let slow = cfg.exit_dynamic_speed_mps * 0.5;
        for _ in 0..=cfg.min_dwell_ticks {
            cfg.update(&mut s, slow, 0.0);
        }
        prop_assert_eq!(s.mode, Mode::Kinematic);
    }
}

#[test]
fn a_dwell_of_one_tick_still_cannot_switch_twice_in_a_tick() {
    // Alternating inputs across the whole band: with dwell 1 the mode may follow every tick,
    // but never more than one change per tick, and only on the side the input is on.
    let cfg = HybridConfig {
        min_dwell_ticks: 1,
        ..catmodel_model_file::paper().hybrid.config()
    };
    let inputs: Vec<(f32, f32)> = (0..50)
        .map(|i| if i % 2 == 0 { (7.0, 0.0) } else { (3.0, 0.0) })
        .collect();
    let (modes, s) = run(&cfg, &inputs);
    for (m, &(v, _)) in modes.iter().zip(&inputs) {
        assert_eq!(*m == Mode::Dynamic, v > 6.0);
    }
    assert_eq!(s.switches, 50);
}
