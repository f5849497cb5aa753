//! The controller in closed loop with the host simulator's plant (host-tests/src/mpc_sim.rs):
//! it converges onto a straight path from an offset, holds a curve, passes an obstacle on the
//! side with room, stops short of one that leaves no room (status 3 once stopped) and follows
//! one that moves on.
use catmodel::control::mpc::{
    ControlStatus, FallbackReason, MpcConfig, MpcTuning, Obstacle, ObstacleSide, StageClock,
    DEFAULT_TUNING,
};
use catmodel::vehicle::Body;
use catmodel_host::sim::config::VehicleConfig;
use catmodel_host_tests::mpc_sim::{
    circle, hatchback, mpc_for, truck, van, Delays, Loop, PositionError, TestPath, TickLog,
    ESCAPE_BODY,
};

fn straight(length: f64, lane: f64, speed: f64) -> TestPath {
    TestPath::new(length, |s| (0.0, s), |_| (lane, lane), |_| speed)
}

/// A car with the default controller on `path`, at `speed` and `offset` m right of it.
fn car_loop(cfg: &VehicleConfig, body: Body, path: &TestPath, speed: f64, offset: f64) -> Loop {
    let mpc = mpc_for(cfg, body, DEFAULT_TUNING);
    Loop::new(cfg.clone(), mpc, path, speed, offset, 0.0)
}

/// The CAT Vehicle with the default controller on `path`.
fn cat_loop(path: &TestPath, speed: f64, offset: f64) -> Loop {
    car_loop(&VehicleConfig::default(), ESCAPE_BODY, path, speed, offset)
}

fn summary(l: &Loop, from_s: f64) -> (f64, f64) {
    let tail: Vec<f64> = l
        .log
        .iter()
        .filter(|t| t.t_s >= from_s)
        .map(|t| t.e_y_m)
        .collect();
    let rms = (tail.iter().map(|e| e * e).sum::<f64>() / tail.len().max(1) as f64).sqrt();
    let max = tail.iter().fold(0.0f64, |m, e| m.max(e.abs()));
    (rms, max)
}

#[test]
fn converges_onto_a_straight_path_from_an_offset() {
    let path = straight(400.0, 3.0, 10.0);
    let mut l = cat_loop(&path, 10.0, 1.0);
    l.run(&path, 350.0, 30.0);
    let (rms, max) = summary(&l, 5.0);
    let iters: Vec<u16> = l.log.iter().map(|t| t.out.iterations).collect();
    println!(
        "rms {rms:.3} max {max:.3} iterations max {:?}",
        iters.iter().max()
    );
    for t in l.log.iter().step_by(25).take(20) {
        println!(
            "t {:.2} e_y {:+.3} v {:.2} steer {:+.1} status {:?} it {} res {:.1e}",
            t.t_s,
            t.e_y_m,
            t.speed_mps,
            t.out.steer_cmd_pct,
            t.out.status,
            t.out.iterations,
            t.out.primal_residual
        );
    }
    assert!(max < 0.05, "after 5 s: max |e_y| {max}");
    assert!(l
        .log
        .iter()
        .all(|t| t.out.status == ControlStatus::Tracking));
}

/// ISO 3888-2 double lane change for a car of width `b` (facts: section lengths 12, 13.5, 11,
/// 12.5, 12 m; widths 1.1 b + 0.25, b + 1, 1.3 b + 0.25; section 3's near edge 1 m beside
/// section 1's far edge), after `lead` m of straight approach, to the left. Returns the path
/// (lane centres joined by cosine transitions) and the stations where sections 1, 3 and 5 begin.
fn double_lane_change(b: f64, lead: f64, speed: f64) -> (TestPath, [(f64, f64); 3]) {
    let w1 = 1.1 * b + 0.25;
    let w3 = b + 1.0;
    let w5 = 1.3 * b + 0.25;
    let s1 = lead;
    let s2 = s1 + 12.0;
    let s3 = s2 + 13.5;
    let s4 = s3 + 11.0;
    let s5 = s4 + 12.5;
    let s6 = s5 + 12.0;
    let lane3_right = w1 / 2.0 + 1.0;
    let lane3_left = lane3_right + w3;
    let c3 = 0.5 * (lane3_right + lane3_left);
    // Lateral position, left positive.
    let p = move |s: f64| {
        let blend = |a: f64, b: f64, s: f64| {
            let t = ((s - a) / (b - a)).clamp(0.0, 1.0);
            0.5 - 0.5 * (std::f64::consts::PI * t).cos()
        };
        if s < s3 {
            c3 * blend(s2, s3, s)
        } else {
            c3 * (1.0 - blend(s4, s5, s))
        }
    };
    let corridor = move |s: f64| {
        let ps = p(s);
        if s < s2 {
            (w1 / 2.0, w1 / 2.0)
        } else if s < s3 {
            (lane3_left - ps, ps + w1 / 2.0)
        } else if s < s4 {
            (lane3_left - ps, ps - lane3_right)
        } else if s < s5 {
            (lane3_left - ps, ps + w5 / 2.0)
        } else {
            (w5 / 2.0, w5 / 2.0)
        }
    };
    let path = TestPath::new(s6 + 60.0, move |s| (-p(s), s), corridor, move |_| speed);
    (path, [(s1, s2), (s3, s4), (s5, s6)])
}

/// Runs the double lane change at `speed`; returns the largest corridor violation of the body
/// and the largest iteration count.
fn dlc_run(cfg: &VehicleConfig, speed: f64) -> (f64, u16, Loop) {
    dlc_run_with(cfg, speed, DEFAULT_TUNING)
}

fn dlc_run_with(cfg: &VehicleConfig, speed: f64, tuning: MpcTuning) -> (f64, u16, Loop) {
    dlc_run_body(cfg, ESCAPE_BODY, speed, tuning)
}

fn dlc_run_body(
    cfg: &VehicleConfig,
    body: Body,
    speed: f64,
    tuning: MpcTuning,
) -> (f64, u16, Loop) {
    let (path, _) = double_lane_change(body.width_m as f64, 40.0, speed);
    let mut l = Loop::new(
        cfg.clone(),
        mpc_for(cfg, body, tuning),
        &path,
        speed,
        0.0,
        0.0,
    );
    l.run(&path, path.length_m() - 20.0, 30.0);
    let worst = l.worst_corridor_violation_m();
    let iters = l.log.iter().map(|t| t.out.iterations).max().unwrap_or(0);
    (worst, iters, l)
}

/// Highest speed (0.5 m/s steps from 8 m/s) at which the double lane change is clean.
fn highest_clean_speed(cfg: &VehicleConfig, body: Body) -> f64 {
    let mut best = 0.0;
    for v10 in (80..=200).step_by(5) {
        let v = v10 as f64 / 10.0;
        let (worst, _, _) = dlc_run_body(cfg, body, v, DEFAULT_TUNING);
        if worst > 0.0 {
            break;
        }
        best = v;
    }
    best
}

#[test]
#[ignore = "tuning sweep; prints the highest clean double-lane-change speed"]
fn dlc_speed_sweep() {
    let cfg = VehicleConfig::default();
    let (hatch_cfg, hatch_body) = hatchback();
    let (van_cfg, van_body) = van();
    println!(
        "highest clean speed: CAT Vehicle {} m/s, hatchback {} m/s, van {} m/s",
        highest_clean_speed(&cfg, ESCAPE_BODY),
        highest_clean_speed(&hatch_cfg, hatch_body),
        highest_clean_speed(&van_cfg, van_body)
    );
    for v10 in (80..=200).step_by(5) {
        let v = v10 as f64 / 10.0;
        let (worst, iters, l) = dlc_run(&cfg, v);
        let fallback = l
            .log
            .iter()
            .filter(|t| t.out.status == ControlStatus::Fallback)
            .count();
        println!("{v:5.1} m/s: worst corridor violation {worst:+.3} m, max iterations {iters}, fallback ticks {fallback}");
    }
}

#[test]
#[ignore = "tuning sweep over the iteration cap"]
fn dlc_iteration_cap_sweep() {
    let cfg = VehicleConfig::default();
    for cap in [5u16, 10, 15, 20, 30, 60] {
        let mut best = 0.0;
        for v10 in (100..=160).step_by(5) {
            let v = v10 as f64 / 10.0;
            let mut t = DEFAULT_TUNING;
            t.admm.max_iterations = cap;
            t.admm.rho_update_every = if cap >= 10 { 10 } else { 0 };
            let (worst, _, _) = dlc_run_with(&cfg, v, t);
            if worst <= 0.0 {
                best = v;
            } else {
                break;
            }
        }
        println!("cap {cap}: clean up to {best} m/s");
    }
}

/// A left curve of radius `radius` after a straight lead-in, at constant speed.
fn curve(radius: f64, lead: f64, speed: f64) -> TestPath {
    TestPath::new(
        lead + 1.5 * std::f64::consts::PI * radius,
        move |s| {
            if s <= lead {
                (0.0, s)
            } else {
                // Left turn from heading north: centre at (-radius, lead).
                let a = (s - lead) / radius;
                (-radius + radius * a.cos(), lead + radius * a.sin())
            }
        },
        |_| (2.0, 2.0),
        move |_| speed,
    )
}

#[test]
fn holds_a_curve() {
    let path = curve(40.0, 30.0, 8.0);
    let mut l = cat_loop(&path, 8.0, 0.0);
    l.run(&path, path.length_m() - 10.0, 60.0);
    // On the arc (after the entry transient), the rear axle stays on the path.
    let on_arc: Vec<f64> = l
        .log
        .iter()
        .filter(|t| t.station_m > 50.0)
        .map(|t| t.e_y_m)
        .collect();
    let max = on_arc.iter().fold(0.0f64, |m, e| m.max(e.abs()));
    println!(
        "curve r 40 m at 8 m/s: max |e_y| on the arc {max:.3} m over {} ticks",
        on_arc.len()
    );
    assert!(on_arc.len() > 300, "reached the arc");
    assert!(max < 0.10, "max |e_y| {max}");
    assert!(l.log.iter().all(|t| t.corridor_violation_m <= 0.0));
}

/// Runs the loop until the rear axle passes `station_m` (or `max_s` seconds), with `obstacle`
/// in slot `slot`; returns the smallest body clearance to it.
fn drive_past(
    l: &mut Loop,
    path: &TestPath,
    obstacle: Obstacle,
    slot: usize,
    station_m: f64,
    max_s: f64,
) -> f64 {
    l.obstacles[slot] = Some(obstacle);
    let mut clearance = f64::INFINITY;
    let mut t = 0.0;
    while l.log.last().is_none_or(|x| x.station_m < station_m) && t < max_s {
        let out = l.tick(path, t);
        assert!(out.steer_cmd_pct.is_finite() && out.speed_cmd_mps.is_finite());
        assert!(out
            .plan
            .iter()
            .all(|p| p.x_m.is_finite() && p.y_m.is_finite()));
        t += 0.02;
        clearance = clearance.min(l.clearance(&obstacle));
    }
    clearance
}

#[test]
fn passes_an_obstacle_on_the_side_with_room() {
    let path = straight(200.0, 3.5, 10.0);
    let mut l = cat_loop(&path, 10.0, 0.0);
    // Slightly right of the centre line: the room is on the left.
    let clearance = drive_past(&mut l, &path, circle(0.4, 60.0, 0.5), 0, 120.0, 20.0);
    let avoiding = l
        .log
        .iter()
        .filter(|t| t.out.status == ControlStatus::Avoiding)
        .count();
    let sides: Vec<_> = l.log.iter().filter_map(|t| t.out.sides[0]).collect();
    println!("obstacle: min body clearance {clearance:.3} m, {avoiding} ticks avoiding");
    assert!(clearance >= 0.5, "clearance {clearance}");
    assert!(avoiding > 50);
    assert!(
        sides.iter().all(|s| *s == ObstacleSide::Left),
        "never changes its mind"
    );
    assert!(l.log.iter().all(|t| t.corridor_violation_m <= 0.0));
    // Back on the path and tracking afterwards.
    let last = l.log.last().unwrap();
    assert_eq!(last.out.status, ControlStatus::Tracking);
    assert!(last.e_y_m.abs() < 0.1, "{}", last.e_y_m);
}

/// An obstacle across a narrow corridor: the speed plan stops the car short of it (status 2,
/// the speed commands falling, never the fallback's 0 while the car can stop by plan), and
/// once it is stopped, status 3 `NoPassage` with speed 0, for as long as the obstacle stays.
/// The planner takes it away: the car drives on.
#[test]
fn brakes_when_no_side_fits() {
    let path = straight(200.0, 1.5, 5.0);
    let mut l = cat_loop(&path, 5.0, 0.0);
    let clearance = drive_past(
        &mut l,
        &path,
        circle(0.0, 40.0, 1.0),
        2,
        f64::INFINITY,
        15.0,
    );
    let first = l
        .log
        .iter()
        .position(|t| t.out.status == ControlStatus::Fallback)
        .expect("no passage");
    let approach = &l.log[..first];
    let fallback = &l.log[first..];
    let last = l.log.last().unwrap();
    println!(
        "blocked: {} ticks avoiding before, then {} no passage, stopped at {:.2} m/s, clearance \
         {clearance:.2} m",
        approach
            .iter()
            .filter(|t| t.out.status == ControlStatus::Avoiding)
            .count(),
        fallback.len(),
        last.speed_mps
    );
    // Stopped by plan: avoiding while it stops, commands that fall without a step to 0.
    assert!(approach
        .iter()
        .all(|t| t.out.status != ControlStatus::Fallback));
    assert!(approach
        .iter()
        .rev()
        .take(50)
        .all(|t| t.out.status == ControlStatus::Avoiding));
    assert!(approach
        .windows(2)
        .all(|w| w[1].out.speed_cmd_mps >= w[0].out.speed_cmd_mps - 0.2));
    // Stopped, it says so, and it stays stopped: no tick drives off again.
    assert!(fallback
        .iter()
        .all(|t| t.out.fallback == Some(FallbackReason::NoPassage) && t.out.speed_cmd_mps == 0.0));
    assert!(fallback.len() > 100);
    assert!(last.speed_mps < 0.05, "stopped");
    assert!(
        clearance > 1.0,
        "stopped short of the obstacle: {clearance}"
    );
    // The planner takes the obstacle away: the car drives on.
    l.obstacles[2] = None;
    let n = l.log.len();
    let mut t = 15.0;
    while t < 20.0 {
        l.tick(&path, t);
        t += 0.02;
    }
    assert!(
        l.log[n..]
            .iter()
            .all(|t| t.out.status == ControlStatus::Tracking),
        "did not drive on without the obstacle"
    );
    assert!(l.log.last().unwrap().speed_mps > 1.0);
}

/// A slower car ahead in a lane with no room to pass (the obstacle moved on by the planner
/// every tick, as a tracker reports it): the car slows to its speed and follows it, neither
/// stopping for good nor stopping and going (docs/findings.md: it stopped and stayed stopped
/// while the obstacle drove 100 m away). Ahead at 3 m/s, the path's target 6 m/s.
#[test]
fn follows_a_slower_car_it_cannot_pass() {
    let path = straight(300.0, 1.5, 6.0);
    let mut l = cat_loop(&path, 6.0, 0.0);
    let lead = |t: f64| circle(0.0, (40.0 + 3.0 * t) as f32, 1.0);
    let mut clearance = f64::INFINITY;
    let mut t = 0.0;
    while t < 40.0 {
        l.obstacles[2] = Some(lead(t));
        let out = l.tick(&path, t);
        assert!(out.steer_cmd_pct.is_finite() && out.speed_cmd_mps.is_finite());
        clearance = clearance.min(l.clearance(&lead(t)));
        t += 0.02;
    }
    let late: Vec<_> = l.log.iter().filter(|x| x.t_s >= 25.0).collect();
    let (lo, hi) = late.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), x| {
        (lo.min(x.speed_mps), hi.max(x.speed_mps))
    });
    let gap = |x: &&TickLog| 40.0 + 3.0 * x.t_s - x.station_m;
    let gaps: Vec<f64> = late.iter().map(gap).collect();
    println!(
        "following: speed {lo:.2}..{hi:.2} m/s after 25 s, gap {:.1}..{:.1} m, clearance \
         {clearance:.2} m",
        gaps.iter().cloned().fold(f64::INFINITY, f64::min),
        gaps.iter().cloned().fold(0.0, f64::max)
    );
    assert!(l
        .log
        .iter()
        .all(|x| x.out.status != ControlStatus::Fallback));
    assert!(lo > 2.7 && hi < 3.3, "{lo}..{hi}");
    assert!(clearance > 1.0, "{clearance}");
}

/// An obstacle whose side leaves the body its width but not the corner rows' margin from the
/// corridor's edge is no passage: a plan through it cannot keep its own rows (the pickup of
/// docs/findings.md fought the corridor beside the obstacle, fell back and passed it by 0.29 m
/// where 0.6 m was planned). With the margin's room and 0.05 m more the car passes, keeping the
/// obstacle's inflation and the corridor.
#[test]
fn an_obstacle_that_leaves_the_body_less_than_its_margin_is_no_passage() {
    let t = DEFAULT_TUNING;
    // The obstacle on the path; its inflated circle (no position uncertainty in this loop).
    let (radius, speed) = (0.5, 5.0);
    let inflated = radius + t.obstacle_margin_m;
    let width = ESCAPE_BODY.width_m;
    let margin = t.weights.corridor_margin_m;
    let run = |spare: f32| {
        let lane = f64::from(inflated + width + spare);
        let path = straight(200.0, lane, speed);
        let mut l = cat_loop(&path, speed, 0.0);
        let clearance = drive_past(&mut l, &path, circle(0.0, 40.0, radius), 0, 70.0, 20.0);
        (l, clearance)
    };
    let (short, _) = run(margin - 0.05);
    let stops: Vec<_> = short
        .log
        .iter()
        .filter(|t| t.out.fallback == Some(FallbackReason::NoPassage))
        .collect();
    let last = short.log.last().unwrap();
    println!(
        "{:.2} m spare: {} ticks no passage, stopped at {:.2} m/s, station {:.1} m",
        margin - 0.05,
        stops.len(),
        last.speed_mps,
        last.station_m
    );
    assert!(!stops.is_empty(), "tried to pass");
    assert!(last.speed_mps < 0.05 && last.station_m < 40.0);
    let (wide, clearance) = run(margin + 0.05);
    println!(
        "{:.2} m spare: body clearance {clearance:.3} m",
        margin + 0.05
    );
    assert!(wide.log.iter().all(|t| t.out.fallback.is_none()));
    assert!(wide.log.last().unwrap().station_m >= 70.0, "passed");
    assert!(
        clearance >= f64::from(t.obstacle_margin_m) - 0.05,
        "{clearance}"
    );
    assert!(wide.log.iter().all(|t| t.corridor_violation_m <= 0.0));
}

/// A winding road: the centre line swings 3 m either side with a 60 m period (radius down to
/// 30 m), corridor 2 m either side.
fn s_curves(length: f64, speed: f64) -> TestPath {
    let k = 2.0 * std::f64::consts::PI / 60.0;
    TestPath::new(
        length,
        move |s| (3.0 * (k * s).sin(), s),
        |_| (2.0, 2.0),
        move |_| speed,
    )
}

/// Lateral RMS and max (after 3 s) on the winding road at 10 m/s with the RTK receiver.
fn rtk_winding_road(cfg: &VehicleConfig, body: Body) -> (f64, f64) {
    let path = s_curves(400.0, 10.0);
    let mut l = car_loop(cfg, body, &path, 10.0, 0.0);
    l.position_error = PositionError::RTK;
    l.run(&path, 350.0, 60.0);
    summary(&l, 3.0)
}

/// Goal: lateral RMS at most 0.10 m at 10 m/s with a survey-grade receiver.
#[test]
fn rtk_lateral_rms_at_10_mps() {
    let (rms, max) = rtk_winding_road(&VehicleConfig::default(), ESCAPE_BODY);
    println!("RTK, winding road, 10 m/s: lateral RMS {rms:.3} m, max {max:.3} m");
    assert!(rms <= 0.10, "RMS {rms}");
}

/// Drives past an obstacle 0.3 m right of the centre of a straight road (corridor 5 m each
/// side) at 10 m/s with the standard receiver's error (`bias_east` m east, 0.5 m north); returns
/// the smallest body clearance and the ticks in status 3.
fn pass_obstacle_standard_receiver(
    cfg: &VehicleConfig,
    body: Body,
    bias_east: f64,
) -> (f64, usize) {
    let path = straight(200.0, 5.0, 10.0);
    let mut l = car_loop(cfg, body, &path, 10.0, 0.0);
    l.position_error = PositionError::standard((bias_east, 0.5));
    let clearance = drive_past(&mut l, &path, circle(0.3, 60.0, 0.5), 0, 120.0, 20.0);
    let fallback = l
        .log
        .iter()
        .filter(|t| t.out.status == ControlStatus::Fallback)
        .count();
    (clearance, fallback)
}

/// Goal: the obstacle passed with at least 0.5 m body clearance with the standard receiver,
/// whichever way its bias points (here 1.2 m, 1.5 sigma, towards and away from the obstacle).
#[test]
fn standard_receiver_obstacle_clearance() {
    let cfg = VehicleConfig::default();
    for bias_east in [-1.2, 1.2, 0.0] {
        let (clearance, fallback) = pass_obstacle_standard_receiver(&cfg, ESCAPE_BODY, bias_east);
        println!("standard receiver, bias {bias_east:+.1} m east: min body clearance {clearance:.3} m, fallback ticks {fallback}");
        assert!(clearance >= 0.5, "bias {bias_east}: clearance {clearance}");
        assert_eq!(fallback, 0);
    }
}

/// The controller built from the published model file (body, steering rate limit, `[dynamics]`
/// and eq 5 from `models/paper.toml`, as the node has them) drives the winding road too.
#[test]
fn controller_from_the_model_file() {
    let node = catmodel_model_file::paper().node_config();
    let mpc = MpcConfig::for_node(&node, DEFAULT_TUNING).expect("the published car is valid");
    assert_eq!(mpc.body(), &node.body);
    let cfg = VehicleConfig::default();
    let path = s_curves(300.0, 10.0);
    let mut l = Loop::new(cfg, mpc, &path, 10.0, 0.0, 0.0);
    l.position_error = PositionError::RTK;
    l.run(&path, 250.0, 60.0);
    let (rms, _) = summary(&l, 3.0);
    println!("model-file controller, RTK, winding road: lateral RMS {rms:.3} m");
    assert!(rms <= 0.10, "RMS {rms}");
}

/// The double lane change clean at 13 m/s on the CAT Vehicle (the defaults' car) and on the
/// hatchback (its lanes sized for its 1.75 m width). (13.5 m/s on the CAT Vehicle before the
/// corners kept `corridor_margin_m` inside: the margin costs the truth-fed bench 0.5 m/s and
/// buys the node on the rig clean runs at 5-10.5 m/s.)
#[test]
fn double_lane_change_is_clean() {
    let cfg = VehicleConfig::default();
    let (worst, _, l) = dlc_run(&cfg, 13.0);
    assert!(
        worst <= 0.0,
        "CAT Vehicle at 13 m/s: body {worst} m outside"
    );
    assert!(l
        .log
        .iter()
        .all(|t| t.out.status == ControlStatus::Tracking));
    let (hatch_cfg, hatch_body) = hatchback();
    let (worst, _, _) = dlc_run_body(&hatch_cfg, hatch_body, 13.0, DEFAULT_TUNING);
    assert!(worst <= 0.0, "hatchback at 13 m/s: body {worst} m outside");
}

/// The tracking and obstacle goals on the hatchback, with the defaults.
#[test]
fn second_vehicle_goals() {
    let (cfg, body) = hatchback();
    let (rms, _) = rtk_winding_road(&cfg, body);
    println!("hatchback, RTK, winding road, 10 m/s: lateral RMS {rms:.3} m");
    assert!(rms <= 0.10, "RMS {rms}");
    for bias_east in [-1.2, 1.2] {
        let (clearance, fallback) = pass_obstacle_standard_receiver(&cfg, body, bias_east);
        println!("hatchback, standard receiver, bias {bias_east:+.1} m: clearance {clearance:.3} m, fallback ticks {fallback}");
        assert!(clearance >= 0.5, "bias {bias_east}: clearance {clearance}");
    }
}

/// The state a real node has, not the truth: the steering report a tick old, the command acting
/// a tick late, the heading a tick late, with RTK-grade noise. Planning from the steering
/// report made this oscillate out of the lanes even at 5 m/s; from the commanded steering ramp
/// it is clean at 5 and 8 m/s. Not at 10 m/s (0.12 m outside), nor with two ticks of heading
/// delay at 8 m/s (0.045 m): the MPC's sensitivity to heading errors is what remains
/// (docs/controller.md).
#[test]
fn double_lane_change_is_clean_with_a_real_nodes_delays() {
    let cfg = VehicleConfig::default();
    for speed in [5.0, 8.0] {
        let (path, _) = double_lane_change(ESCAPE_BODY.width_m as f64, 40.0, speed);
        let mut l = Loop::new(
            cfg.clone(),
            mpc_for(&cfg, ESCAPE_BODY, DEFAULT_TUNING),
            &path,
            speed,
            0.0,
            0.0,
        );
        l.position_error = PositionError::RTK;
        l.delays = Delays {
            heading_ticks: 1,
            steer_ticks: 1,
            command_ticks: 1,
        };
        l.run(&path, path.length_m() - 20.0, 30.0);
        let worst = l.worst_corridor_violation_m();
        assert!(worst <= 0.0, "{speed} m/s: body {worst} m outside");
    }
}

/// The rig's planner's lane-change path (least-curvature transitions 0.15 m from the cones,
/// host/src/closed_loop/scenario.rs) for the CAT Vehicle's body at `speed`, with the lanes'
/// edges as its corridor.
fn rigs_lane_change(speed: f64) -> TestPath {
    use catmodel_host::closed_loop::scenario::{design_lane_change, dlc_edges, dlc_lanes};
    let body = catmodel_host::sim::config::Body {
        width_m: ESCAPE_BODY.width_m as f64,
        length_m: ESCAPE_BODY.length_m as f64,
        rear_overhang_m: ESCAPE_BODY.rear_overhang_m as f64,
    };
    let lanes = dlc_lanes(body.width_m);
    let end = lanes[2].x_end_m;
    let design = design_lane_change(&body, &lanes);
    let lead = 40.0;
    // Lateral (left) offset of the path at `s`, and the lane edges beside it.
    let y = move |s: f64| design.y_at((s - lead).clamp(0.0, end));
    let edges = move |s: f64| {
        let x = s - lead;
        if !(0.0..=end).contains(&x) {
            (y(s) + 1.5, y(s) - 1.5)
        } else {
            dlc_edges(&lanes, x)
        }
    };
    TestPath::new(
        lead + end + 60.0,
        move |s| (-y(s), s),
        move |s| {
            let (l, r) = edges(s);
            (l - y(s), y(s) - r)
        },
        move |_| speed,
    )
}

/// The CAT Vehicle through the rig's lane-change path at `speed` on the bench, with `delays`
/// and `position_error` between the plant and the controller.
fn rigs_lane_change_run(speed: f64, delays: Delays, position_error: PositionError) -> Loop {
    let cfg = VehicleConfig::default();
    let path = rigs_lane_change(speed);
    let mut l = Loop::new(
        cfg.clone(),
        mpc_for(&cfg, ESCAPE_BODY, DEFAULT_TUNING),
        &path,
        speed,
        0.0,
        0.0,
    );
    l.delays = delays;
    l.position_error = position_error;
    l.run(&path, path.length_m() - 20.0, 30.0);
    l
}

/// The largest corridor violation of the CAT Vehicle's body on the rig's lane-change path at
/// `speed`, with `delays` and `position_error` between the plant and the controller, m.
fn rigs_lane_change_violation(speed: f64, delays: Delays, position_error: PositionError) -> f64 {
    rigs_lane_change_run(speed, delays, position_error).worst_corridor_violation_m()
}

/// The rig's lane-change path on the bench, as a check that the gap between the bench and the
/// rig is not the path: clean at 12 m/s.
#[test]
fn the_rigs_lane_change_path_is_clean_on_the_bench() {
    let worst = rigs_lane_change_violation(12.0, Delays::default(), PositionError::NONE);
    assert!(worst <= 0.0, "body {worst} m outside");
}

/// Where the lane change's limit goes between the bench and the rig: the rig's path at 13 to
/// 17 m/s, fed the truth at once, then with each of the node's one-tick delays and the RTK
/// receiver's error alone, then all of them (docs/controller.md, "What is left"). Prints each
/// speed's largest corridor violation (m) and the highest speed with every speed below it
/// clean.
#[test]
#[ignore = "measurement; prints the lane change's limit per delay"]
fn rigs_lane_change_limit_per_delay() {
    let one = |heading_ticks, steer_ticks, command_ticks| Delays {
        heading_ticks,
        steer_ticks,
        command_ticks,
    };
    let cases = [
        ("truth", one(0, 0, 0), PositionError::NONE),
        ("heading a tick old", one(1, 0, 0), PositionError::NONE),
        (
            "steering report a tick old",
            one(0, 1, 0),
            PositionError::NONE,
        ),
        ("command a tick late", one(0, 0, 1), PositionError::NONE),
        ("RTK position error", one(0, 0, 0), PositionError::RTK),
        ("all of them", one(1, 1, 1), PositionError::RTK),
    ];
    for (name, delays, error) in cases {
        let mut limit = None;
        let mut line = String::new();
        for v4 in 52..=68 {
            let speed = v4 as f64 / 4.0;
            let worst = rigs_lane_change_violation(speed, delays, error);
            line += &format!(" {speed}:{worst:.2}");
            if worst > 0.0 && limit.is_none() {
                limit = Some(speed - 0.25);
            }
        }
        println!("{name}: limit {limit:?} m/s;{line}");
    }
}

/// The smallest clearance between the body and the cones of the rig's lane change on the
/// bench, fed the truth, at `speed`, m (the cones as the rig places them: their edges on the
/// lanes' edges).
fn rigs_lane_change_cone_clearance(speed: f64) -> f64 {
    use catmodel_host::closed_loop::metrics::distance_to_body;
    use catmodel_host::closed_loop::scenario::{cone_stations, dlc_lanes, CONE_RADIUS_M};
    let l = rigs_lane_change_run(speed, Delays::default(), PositionError::NONE);
    let body = catmodel_host::sim::config::Body {
        width_m: f64::from(ESCAPE_BODY.width_m),
        length_m: f64::from(ESCAPE_BODY.length_m),
        rear_overhang_m: f64::from(ESCAPE_BODY.rear_overhang_m),
    };
    // The bench's path runs north from the lane change's course x = -40 m; course y (left) is
    // west.
    let cones: Vec<(f64, f64)> = dlc_lanes(body.width_m)
        .iter()
        .flat_map(|lane| {
            cone_stations(lane).flat_map(move |x| {
                [
                    lane.y_left_m + CONE_RADIUS_M,
                    lane.y_right_m - CONE_RADIUS_M,
                ]
                .map(|y| (-y, x + 40.0))
            })
        })
        .collect();
    let body = &body;
    l.log
        .iter()
        .flat_map(|t| {
            cones.iter().map(move |&(e, n)| {
                distance_to_body(body, t.x_m, t.y_m, t.heading_rad, e, n) - CONE_RADIUS_M
            })
        })
        .fold(f64::INFINITY, f64::min)
}

/// The smallest cone clearance of the rig's lane change on the truth-fed bench, per speed
/// (docs/controller.md, "Where the corridor binds the body").
#[test]
#[ignore = "measurement; prints the cone clearance per speed"]
fn rigs_lane_change_cone_clearance_per_speed() {
    for v4 in 48..=62 {
        let speed = f64::from(v4) / 4.0;
        println!(
            "{speed} m/s: {:+.3} m",
            rigs_lane_change_cone_clearance(speed)
        );
    }
}

/// An obstacle that appears beside the car, its inflated circle already over the body, at
/// `speed` m/s: the closed loop from then on, with what the test asserts on. Straight road,
/// 5 m a side, the CAT Vehicle; the obstacle 0.1 m beyond the body's left side, 2 m ahead of
/// the rear axle, from t = 2 s.
struct Beside {
    /// The ticks in the fallback.
    fallback: Vec<TickLog>,
    /// The largest steering command in the fallback, %.
    steer_pct: f64,
    /// How far the rear axle moved from its offset at the obstacle's appearance, m.
    swing_m: f64,
    /// The body's least clearance from the obstacle, m.
    clearance_m: f64,
    /// The least speed command after the obstacle appeared, m/s.
    least_speed_cmd_mps: f32,
    /// The last tick.
    last: TickLog,
}

fn appears_beside(speed: f64) -> Beside {
    let path = straight(200.0, 5.0, speed);
    let mut l = cat_loop(&path, speed, 0.0);
    let mut t = 0.0;
    while t < 2.0 {
        l.tick(&path, t);
        t += 0.02;
    }
    let now = *l.log.last().unwrap();
    let north = now.station_m + 2.0;
    let west = -(f64::from(ESCAPE_BODY.width_m) / 2.0 + 0.1 + 0.5) + now.e_y_m;
    let obstacle = circle(west as f32, north as f32, 0.5);
    let start = l.log.len();
    let clearance_m = drive_past(&mut l, &path, obstacle, 0, north + 20.0, 10.0);
    let after = &l.log[start..];
    let fallback: Vec<TickLog> = after
        .iter()
        .filter(|t| t.out.status == ControlStatus::Fallback)
        .copied()
        .collect();
    let swing_m = after
        .iter()
        .map(|t| (t.e_y_m - now.e_y_m).abs())
        .fold(0.0f64, f64::max);
    let steer_pct = fallback
        .iter()
        .map(|t| f64::from(t.out.steer_cmd_pct.abs()))
        .fold(0.0f64, f64::max);
    let least_speed_cmd_mps = after
        .iter()
        .map(|t| t.out.speed_cmd_mps)
        .fold(f32::INFINITY, f32::min);
    let beside = Beside {
        fallback,
        steer_pct,
        swing_m,
        clearance_m,
        least_speed_cmd_mps,
        last: *l.log.last().unwrap(),
    };
    println!(
        "beside at {speed} m/s: {} ticks not cleared, steering within {:.2} %, the rear axle \
         within {:.3} m of its offset; body clearance {:.2} m; speed commands down to {:.2} \
         m/s; then {:?}",
        beside.fallback.len(),
        beside.steer_pct,
        beside.swing_m,
        beside.clearance_m,
        beside.least_speed_cmd_mps,
        beside.last.out.status
    );
    beside
}

/// At 6 m/s the car is past such an obstacle sooner than braking would drop it behind it
/// (`MpcConfig::overtakes`): it drives on in its lane, its plans keeping to their side of the
/// obstacle, never braking for it, and tracks again once past. (Before, no plan cleared it and
/// the car braked past it along the lane, the test below; braking keeps a car beside an object,
/// which for one that comes across, a car cutting in, was the collision: docs/bus.md, "A car
/// that cuts in".)
#[test]
fn an_obstacle_beside_the_car_is_driven_past_in_its_lane() {
    let b = appears_beside(6.0);
    assert!(b.fallback.is_empty(), "the fallback was taken");
    assert!(
        b.least_speed_cmd_mps > 5.0,
        "braked to {:.2} m/s",
        b.least_speed_cmd_mps
    );
    assert!(b.swing_m < 0.1, "the rear axle moved {:.3} m", b.swing_m);
    assert!(b.clearance_m > 0.0, "body {:.2} m from it", b.clearance_m);
    assert_eq!(b.last.out.status, ControlStatus::Tracking, "tracks again");
}

/// At 1.5 m/s braking drops the car behind it sooner: no plan clears it, and the fallback
/// (status 3, the obstacle not cleared) brakes along the lane at the offset the car has, its
/// heading held to the path's, instead of following the plans that entered the circle and then
/// holding their last steering (which, beside an obstacle passed on one side and returned from
/// on the other, turned a braking car back into it; docs/mpc.md, "Fallback"). By hand: past it
/// (2 + 1.2 + 0.9) / 1.5 = 2.7 s; behind it 0.8 + (1.5 + sqrt(2.25 + 20 (1.2 + 2.74))) / 10
/// = 1.85 s.
#[test]
fn an_obstacle_beside_a_slow_car_is_braked_for_along_the_lane() {
    let b = appears_beside(1.5);
    assert!(!b.fallback.is_empty(), "the fallback was not taken");
    assert!(b.fallback.iter().all(|t| {
        t.out.fallback == Some(FallbackReason::ObstacleNotCleared) && t.out.speed_cmd_mps == 0.0
    }));
    assert!(
        b.steer_pct < 1.0,
        "steered {:.2} % in the fallback",
        b.steer_pct
    );
    assert!(b.swing_m < 0.05, "the rear axle moved {:.3} m", b.swing_m);
    assert!(b.clearance_m > 0.0, "body {:.2} m from it", b.clearance_m);
}

/// An obstacle that appears on the path late, on a road wide enough to pass it, where no plan
/// clears it in time: the car brakes for it (status 3) and must not take back a plan that
/// ends short of it, not aside. Such plans, accepted while they entered the obstacle by no more
/// than the tolerance and dropped again ticks later, asked for the path's speed: a black-box
/// probe's car, braked to 2.5 m/s 3.5 m short of the obstacle, was commanded up to 9.5 m/s,
/// sped up and hit it (docs/findings.md). Here: the CAT Vehicle, the van and the truck at 4,
/// 6 and 8 m/s, a 1 m obstacle on the path of a 10 m road appearing with its surface 4 to 16
/// m ahead of the front. After the first fallback for it no command is above the car's speed
/// while the obstacle is ahead (the truck at 4 m/s with 8 m: 3.1 m/s above it before); that
/// truck stops short of it. (Where braking cannot stop the car in time the bench's car drives
/// through the obstacle: it models no collision.)
#[test]
fn a_car_braking_for_an_obstacle_does_not_speed_up_towards_it() {
    let radius = 1.0;
    let mut fallbacks = 0;
    for (name, cfg, body) in three_cars() {
        let front_m = f64::from(body.length_m - body.rear_overhang_m);
        for speed in [4.0, 6.0, 8.0] {
            for gap in [4.0, 6.0, 8.0, 10.0, 12.0, 14.0, 16.0] {
                let (l, start, centre_north, clearance) =
                    obstacle_appears(&cfg, body, speed, gap, radius);
                let after = &l.log[start..];
                let Some(first) = after
                    .iter()
                    .position(|t| t.out.fallback == Some(FallbackReason::ObstacleNotCleared))
                else {
                    continue;
                };
                fallbacks += 1;
                let surge = after[first..]
                    .iter()
                    .filter(|t| t.station_m + front_m < centre_north - radius)
                    .map(|t| f64::from(t.out.speed_cmd_mps) - t.speed_mps)
                    .fold(f64::NEG_INFINITY, f64::max);
                println!(
                    "{name} at {speed} m/s, the surface {gap} m ahead: braking {first} ticks after \
                     it appeared, commands at most {surge:+.2} m/s over the car's speed while it \
                     is ahead, body clearance {clearance:.2} m"
                );
                assert!(
                    surge <= 0.0,
                    "{name} at {speed} m/s, {gap} m: a command {surge:.2} m/s over the car's speed"
                );
                if name == "truck" && speed == 4.0 && gap == 8.0 {
                    let last = after.last().unwrap();
                    assert!(clearance > 0.5, "body {clearance:.2} m from it");
                    assert_eq!(
                        (last.speed_mps, last.out.status),
                        (0.0, ControlStatus::Fallback)
                    );
                }
            }
        }
    }
    assert!(fallbacks >= 20, "{fallbacks} runs braked for the obstacle");
}

/// The CAT Vehicle, the van and the truck: cars of three lengths.
fn three_cars() -> [(&'static str, VehicleConfig, Body); 3] {
    [
        ("CAT Vehicle", VehicleConfig::default(), ESCAPE_BODY),
        ("van", van().0, van().1),
        ("truck", truck().0, truck().1),
    ]
}

/// A car driven 2 s along a straight 10 m road at `speed`, then an obstacle of `radius` on
/// the path with its surface `gap` m ahead of the front, driven past (20 m beyond it, 20 s at
/// most): the loop, the log's index when the obstacle appeared, the obstacle's station and
/// the least body clearance.
fn obstacle_appears(
    cfg: &VehicleConfig,
    body: Body,
    speed: f64,
    gap: f64,
    radius: f64,
) -> (Loop, usize, f64, f64) {
    let front_m = f64::from(body.length_m - body.rear_overhang_m);
    let path = straight(200.0, 5.0, speed);
    let mut l = car_loop(cfg, body, &path, speed, 0.0);
    let mut t = 0.0;
    while t < 2.0 {
        l.tick(&path, t);
        t += 0.02;
    }
    let now = *l.log.last().unwrap();
    let centre_north = now.station_m + front_m + gap + radius;
    let obstacle = circle(0.0, centre_north as f32, radius as f32);
    let start = l.log.len();
    let clearance = drive_past(&mut l, &path, obstacle, 0, centre_north + 20.0, 20.0);
    (l, start, centre_north, clearance)
}

/// An obstacle on the path nearer than the car can stop: the car brakes (status 3, no
/// passage) until it stands, and goes on braking once its front has reached the circle. A
/// black-box probe's car at 8 m/s, an obstacle 8 m ahead of its rear axle: once the front
/// reached the circle the node took it for one it was overtaking alongside
/// (`MpcConfig::overtakes`), said "avoiding" and commanded 9.4 m/s through it
/// (docs/findings.md). Here the three cars at 6 and 8 m/s, 0.5 m obstacles whose surface
/// appears 1, 2 and 3 m ahead of the front: from the first tick it is braked for to the stop,
/// every command is a fallback's, at 0 m/s. (The bench models no collision: the car rolls
/// into the circle, and through it; judged until the circle is behind the body.)
#[test]
fn a_car_that_cannot_stop_for_an_obstacle_goes_on_braking_into_it() {
    let radius = 0.5;
    for (name, cfg, body) in three_cars() {
        for speed in [6.0, 8.0] {
            for gap in [1.0, 2.0, 3.0] {
                let (l, start, centre, clearance) =
                    obstacle_appears(&cfg, body, speed, gap, radius);
                let after = &l.log[start..];
                let first = after
                    .iter()
                    .position(|t| t.out.status == ControlStatus::Fallback)
                    .unwrap_or_else(|| panic!("{name} at {speed} m/s, {gap} m: not braked for"));
                // To the stop, or until the bench's car has rolled through the circle.
                let rear = f64::from(body.rear_overhang_m);
                let end = after[first..]
                    .iter()
                    .position(|t| t.speed_mps == 0.0 || centre + radius < t.station_m - rear)
                    .map_or(after.len(), |k| first + k);
                let driven = after[first..end]
                    .iter()
                    .find(|t| t.out.status != ControlStatus::Fallback || t.out.speed_cmd_mps > 0.0);
                println!(
                    "{name} at {speed} m/s, the surface {gap} m ahead: braked {first} ticks \
                     after it appeared, {} ticks braking, body clearance {clearance:.2} m",
                    end - first
                );
                assert!(
                    clearance < 0.0,
                    "{name} at {speed} m/s, {gap} m: stopped short ({clearance:.2} m), not the \
                     case this test is for"
                );
                assert!(
                    driven.is_none(),
                    "{name} at {speed} m/s, {gap} m: {:?} while it braked into the obstacle",
                    driven.map(|t| (t.out.status, t.out.speed_cmd_mps, t.speed_mps))
                );
            }
        }
    }
}

/// An S-curve without transitions (`scripts/sil-drive.py scurve`): 40 m straight, 25 m arcs
/// turning left by 60 deg, right by 120 deg and left by 60 deg, 40 m straight; corridor 2.5 m a
/// side. The curvature steps by 0.08 1/m at each reversal.
fn s_curve_of_arcs(speed: f64) -> TestPath {
    use std::f64::consts::FRAC_PI_3;
    let r = 25.0;
    let arcs = [(1.0, FRAC_PI_3), (-1.0, 2.0 * FRAC_PI_3), (1.0, FRAC_PI_3)];
    let arc_len = |a: f64| r * a;
    let total = 80.0 + arcs.iter().map(|(_, a)| arc_len(*a)).sum::<f64>();
    TestPath::new(
        total,
        move |s| {
            // Heading from north, clockwise; a left turn lowers it.
            let (mut x, mut y, mut h) = (0.0f64, 0.0f64, 0.0f64);
            let step = |x: &mut f64, y: &mut f64, h: f64, d: f64| {
                *x += d * h.sin();
                *y += d * h.cos();
            };
            let d = s.min(40.0);
            step(&mut x, &mut y, h, d);
            let mut left = s - d;
            for (turn, a) in arcs {
                let d = left.clamp(0.0, arc_len(a));
                // The chord of an arc of `d`: half the turn, then the chord's length.
                let dh = -turn * d / r;
                let chord = 2.0 * r * (0.5 * d / r).sin();
                step(&mut x, &mut y, h + 0.5 * dh, chord);
                h += dh;
                left -= d;
            }
            step(&mut x, &mut y, h, left.max(0.0));
            (x, y)
        },
        |_| (2.5, 2.5),
        move |_| speed,
    )
}

/// A truck whose steering is slow for its wheelbase (`mpc_sim::truck`: 40 %/s of 32 deg on
/// 4.8 m) through the S-curve at 10 m/s: reversing the steering that a 25 m arc asks for takes
/// it about 2 s, as long as the tuning's horizon, and with 2 s the plan began each reversal too
/// late to share the error between the arcs. Its horizon of 4 s (`StageClock::for_steering`:
/// 0.1 s stages for the first second, 0.3 s after) starts the reversals earlier: the rear axle
/// stays closer to the path (the largest offset at most two thirds of the 2 s horizon's).
#[test]
fn a_truck_with_slow_steering_anticipates_the_reversals() {
    let (cfg, body) = truck();
    let path = s_curve_of_arcs(10.0);
    let run = |clock: Option<StageClock>| {
        let mut mpc = mpc_for(&cfg, body, DEFAULT_TUNING);
        if let Some(c) = clock {
            mpc.set_stage(c);
        }
        let mut l = Loop::new(cfg.clone(), mpc, &path, 10.0, 0.0, 0.0);
        l.run(&path, path.length_m() - 10.0, 40.0);
        let (rms, max) = summary(&l, 1.0);
        let horizon = l.mpc.stage().horizon_s();
        (rms, max, horizon)
    };
    let (rms, max, horizon) = run(None);
    let (rms2, max2, horizon2) = run(Some(StageClock::UNIFORM));
    println!(
        "truck, S-curve at 10 m/s: horizon {horizon:.1} s: lateral RMS {rms:.3} m, max {max:.3} m; \
         {horizon2:.1} s: {rms2:.3} m, {max2:.3} m"
    );
    assert!((horizon - 4.0).abs() < 1e-4, "{horizon}");
    assert!((horizon2 - 2.0).abs() < 1e-4, "{horizon2}");
    assert!(max <= 2.0 / 3.0 * max2, "{max:.3} against {max2:.3} m");
    assert!(rms < rms2, "{rms:.3} against {rms2:.3} m");
}

/// A motorway path at 38 m/s (137 km/h; PATH_POINT's speed reaches 40.94 m/s): the plan's
/// speed is the model file's limit (60 m/s for the CAT Vehicle), not a tuning's, and the
/// lateral loop holds the lane at that speed. The built-in tuning capped every command at
/// 30 m/s while reporting "tracking" (docs/findings.md).
#[test]
fn follows_a_motorway_path_at_its_speed() {
    let path = straight(2000.0, 1.8, 38.0);
    let mut l = cat_loop(&path, 30.0, 0.3);
    l.run(&path, 1900.0, 40.0);
    let last = l.log.last().expect("ran");
    let (rms, max) = summary(&l, 10.0);
    println!(
        "{} ticks to {:.0} m: speed {:.2} m/s, command {:.2}; after 10 s rms {rms:.4} max {max:.4}; \
         first e_y {:.3}",
        l.log.len(),
        last.station_m,
        last.speed_mps,
        last.out.speed_cmd_mps,
        l.log[0].e_y_m
    );
    assert!(
        (last.speed_mps - 38.0).abs() < 0.5,
        "speed {} m/s for a 38 m/s path",
        last.speed_mps
    );
    assert!(max < 0.05, "after 10 s: max |e_y| {max}");
    assert!(l
        .log
        .iter()
        .all(|t| t.out.status == ControlStatus::Tracking));
}

/// A slalom of four standing circles of 0.5 m, 1.5 m right and left of a straight road's centre
/// line in turn, `gap` m apart from 60 m on, corridor 5 m each side, at 8 m/s, the controller
/// told a 2 m position uncertainty (the published model file's receiver); the car's position
/// exact. Returns the loop and the least body clearance of any circle.
fn slalom(gap: f64) -> (Loop, f64) {
    let path = straight(260.0, 5.0, 8.0);
    let mut l = cat_loop(&path, 8.0, 0.0);
    l.position_error = PositionError {
        uncertainty_m: 2.0,
        ..PositionError::NONE
    };
    let circles: Vec<_> = (0..4)
        .map(|i| {
            let side = if i % 2 == 0 { 1.5 } else { -1.5 };
            circle(side, (60.0 + gap * f64::from(i)) as f32, 0.5)
        })
        .collect();
    for (slot, c) in l.obstacles.iter_mut().zip(&circles) {
        *slot = Some(*c);
    }
    let mut clearance = f64::INFINITY;
    let mut t = 0.0;
    while l.log.last().is_none_or(|x| x.station_m < 250.0) && t < 80.0 {
        let out = l.tick(&path, t);
        assert!(out.steer_cmd_pct.is_finite() && out.speed_cmd_mps.is_finite());
        t += 0.02;
        for c in &circles {
            clearance = clearance.min(l.clearance(c));
        }
    }
    (l, clearance)
}

/// The fastest the car went while its body was beside circles 2 to 4 of [`slalom`]'s.
fn speed_beside_later_circles(l: &Loop, gap: f64) -> f64 {
    let front = f64::from(ESCAPE_BODY.length_m - ESCAPE_BODY.rear_overhang_m);
    let rear = f64::from(ESCAPE_BODY.rear_overhang_m);
    l.log
        .iter()
        .filter(|x| {
            (1..4).any(|i| {
                let c = 60.0 + gap * f64::from(i);
                (c - front..=c + rear).contains(&x.station_m)
            })
        })
        .fold(0.0f64, |m, x| m.max(x.speed_mps))
}

/// Circles in a row passed on opposite sides leave the car the run between them to shift
/// across by what both ask (5 m here: the inflated circles' 3.1 m, the body's width, less the
/// plan's tolerance). 15 m apart no speed makes it by the check's measure (the run past the
/// body, 10.6 m, is within the lock's small-angle 2 sqrt(shift R), 8.4 m, only at a crawl, and
/// from where the first leaves it the car cannot get beside the second): the car stops short
/// of the second, at rest with no passage. A black-box probe's car, its speed loop the model
/// file's, was told of the four circles 12 s ahead, found the pair only when the second came
/// within the 2 s horizon, and hit it at 3.6-4.2 m/s on 4 seeds of 6 (docs/findings.md); this
/// loop's car, whose steering answers at once, had passed it at 8 m/s. 20 m apart the
/// steering's rate makes the shift at 3.2 m/s at most (`MpcConfig::shift_speed_mps`): the car
/// slows for each pair and keeps clear of every circle (this loop's car passes all four; that
/// is not asserted: at that speed a plan may still fall back beside a circle, which leaves the
/// car at rest there). 40 m apart it is not slowed and passes all four.
#[test]
fn a_slalom_the_car_cannot_shift_through_stops_it_short_and_one_it_can_slows_it() {
    let (tight, clearance) = slalom(15.0);
    let last = tight.log.last().unwrap();
    println!(
        "15 m apart: least body clearance {clearance:.2} m, at rest at station {:.1} m, {:?}",
        last.station_m, last.out.fallback
    );
    assert!(clearance > 1.5, "{clearance}");
    assert!(last.speed_mps < 0.05, "{}", last.speed_mps);
    assert!(last.station_m < 75.0, "{}", last.station_m);
    assert_eq!(last.out.fallback, Some(FallbackReason::NoPassage));
    for (gap, slowest, fastest) in [(20.0, 2.5, 4.0), (40.0, 7.0, 8.5)] {
        let (l, clearance) = slalom(gap);
        let beside = speed_beside_later_circles(&l, gap);
        println!(
            "{gap} m apart: least body clearance {clearance:.2} m, fastest beside circles 2-4 \
             {beside:.2} m/s, reached station {:.1} m",
            l.log.last().unwrap().station_m
        );
        assert!(clearance > 1.5, "{clearance}");
        assert!((slowest..fastest).contains(&beside), "{beside}");
        if gap >= 40.0 {
            assert!(l.log.last().unwrap().station_m >= 250.0, "passed");
        }
    }
}
