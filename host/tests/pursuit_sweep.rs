//! The tuning sweep behind pure pursuit's `DEFAULT_TUNING` (docs/controller.md, "Pure pursuit
//! tuning"): the lookahead's two parameters (`lookahead_min_m`, `lookahead_time_s`) on a grid,
//! each scored by its highest clean speed through the double lane change on the closed-loop rig
//! (scan and bisection over three seeds, as `catmodel dlc-limits`), on the CAT Vehicle and on
//! the second car. Ignored (about 4 minutes in release); it prints a table per car:
//!
//! `cargo test --release -p catmodel-host --test pursuit_sweep -- --ignored --nocapture`
//!
//! `MINS` and `TIMES` (comma-separated) replace the grid; `VEHICLE=FILE` (and `MODEL=FILE`, its
//! model file; without it the rig describes the car to the node; paths from the workspace's root)
//! sweeps that car instead.
use catmodel::control::pure_pursuit::{PurePursuitTuning, DEFAULT_TUNING};
use catmodel_host::closed_loop::driver::Controller;
use catmodel_host::closed_loop::limits::{clean_at, highest_clean_speed, SCAN_FROM_MPS};
use catmodel_host::closed_loop::{load_setup, Receiver};

fn grid(var: &str, default: &str) -> Vec<f32> {
    std::env::var(var)
        .unwrap_or_else(|_| default.into())
        .split(',')
        .map(|s| s.parse().expect("a number"))
        .collect()
}

#[test]
#[ignore = "tuning sweep on the rig; prints"]
fn lookahead_sweep() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    // Paths in VEHICLE and MODEL are taken from the workspace's root (the test runs in host/).
    let at = |p: String| root.join("..").join(p);
    let cars = match std::env::var("VEHICLE") {
        Ok(v) => vec![(
            v.clone(),
            Some((at(v), std::env::var("MODEL").ok().map(at))),
        )],
        Err(_) => vec![
            ("CAT Vehicle".to_string(), None),
            (
                "hatchback".to_string(),
                Some((
                    root.join("vehicles/hatchback.toml"),
                    Some(root.join("../models/hatchback.toml")),
                )),
            ),
        ],
    };
    let mins = grid("MINS", "1,2,3,4,5");
    let times = grid("TIMES", "0.3,0.4,0.5,0.55,0.6,0.7,0.8");
    for (name, files) in cars {
        let (vehicle, node) = match &files {
            Some((v, m)) => load_setup(Some(v), m.as_deref()).unwrap(),
            None => load_setup(None, None).unwrap(),
        };
        println!(
            "{name}: highest clean speed, m/s (rows lookahead_min_m, columns lookahead_time_s)"
        );
        print!("{:>6}", "");
        for t in &times {
            print!("{t:>7}");
        }
        println!();
        for &min in &mins {
            print!("{min:>6}");
            for &time in &times {
                let tuning = PurePursuitTuning {
                    lookahead_min_m: min,
                    lookahead_time_s: time,
                    ..DEFAULT_TUNING
                };
                let limit = highest_clean_speed(
                    |v| {
                        clean_at(
                            &vehicle,
                            &node,
                            Controller::PurePursuit(tuning),
                            Receiver::Rtk,
                            v,
                        )
                        .0
                    },
                    SCAN_FROM_MPS,
                    20.0,
                );
                match limit {
                    Some(v) => print!("{v:>7.2}"),
                    None => print!("{:>7}", "-"),
                }
            }
            println!();
        }
    }
}
