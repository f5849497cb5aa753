//! Properties of the controller on arbitrary inputs: whatever the reference, state, corridor
//! (feasible or not), obstacles and uncertainty, every output is finite and within its range,
//! the plan meets the steering range and rate limits exactly, the iteration and factorisation
//! counts stay within their caps, a non-finite input gives the fallback (status 3) without
//! a NaN anywhere, and a tick without a solve (`MpcConfig::coast`) moves the plan on by one tick.
use catmodel::control::mpc::longitudinal::SpeedTuning;
use catmodel::control::mpc::{
    CarState, ControlStatus, FallbackReason, MpcInput, MpcOutput, MpcState, MpcTuning, Obstacle,
    ObstacleSide, ObstacleVelocity, StageClock, DEFAULT_TUNING, MAX_OBSTACLES, PLAN_STEPS, STEPS,
    STEP_S, TICKS_PER_STEP,
};
use catmodel::model::dynamic::LateralState;
use catmodel::model::hybrid::Mode;
use catmodel::model::kinematic::Pose;
use catmodel::model::{paper, SsBlock};
use catmodel_host::sim::config::VehicleConfig;
use catmodel_host_tests::mpc_sim::{mpc_for, TestPath, ESCAPE_BODY};
use proptest::prelude::*;

/// Lateral offset, distance ahead, radius; velocity east and north (zero for most).
type CaseObstacle = ((f32, f32, f32), (f32, f32));

#[derive(Clone, Debug)]
struct Case {
    speed: f64,
    curvature: f64,
    left: f64,
    right: f64,
    offset: f32,
    heading_error: f32,
    steer: f32,
    lateral: (f32, f32),
    dynamic: bool,
    obstacles: Vec<CaseObstacle>,
    uncertainty: f32,
    /// Which input gets a NaN (0 = none).
    poison: u8,
}

fn case() -> impl Strategy<Value = Case> {
    (
        (0.0f64..28.0, -0.12f64..0.12, 0.3f64..6.0, 0.3f64..6.0),
        (-2.5f32..2.5, -0.6f32..0.6, -0.6f32..0.6),
        ((-1.0f32..1.0, -0.6f32..0.6), any::<bool>()),
        prop::collection::vec(
            (
                (-4.0f32..4.0, -5.0f32..45.0, 0.0f32..2.5),
                prop_oneof![2 => Just((0.0f32, 0.0f32)), 1 => (-3.0f32..3.0, -3.0f32..3.0)],
            ),
            0..=MAX_OBSTACLES,
        ),
        (0.0f32..1.2, prop_oneof![6 => Just(0u8), 1 => 1u8..7]),
    )
        .prop_map(
            |(
                (speed, curvature, left, right),
                (offset, heading_error, steer),
                (lateral, dynamic),
                obstacles,
                (uncertainty, poison),
            )| Case {
                speed,
                curvature,
                left,
                right,
                offset,
                heading_error,
                steer,
                lateral,
                dynamic,
                obstacles,
                uncertainty,
                poison,
            },
        )
}

/// An arc of curvature `k` from the origin heading north (right positive).
fn arc(k: f64, left: f64, right: f64, speed: f64) -> TestPath {
    TestPath::new(
        90.0,
        move |s| {
            if k.abs() < 1e-9 {
                (0.0, s)
            } else {
                ((1.0 - (k * s).cos()) / k, (k * s).sin() / k)
            }
        },
        move |_| (left, right),
        move |_| speed,
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(500))]

    #[test]
    fn outputs_are_finite_and_within_limits(c in case()) {
        let cfg = VehicleConfig::default();
        let mpc = mpc_for(&cfg, ESCAPE_BODY, DEFAULT_TUNING);
        let path = arc(c.curvature, c.left, c.right, c.speed);
        let speeds = [c.speed as f32; PLAN_STEPS + 1];
        let mut reference = path.reference(5.0, &speeds, &ESCAPE_BODY, &StageClock::UNIFORM);
        let (x, y, h) = path.pose(5.0);
        let mut pose = Pose::new(
            x as f32 + c.offset * (h as f32).cos(),
            y as f32 - c.offset * (h as f32).sin(),
            h as f32 + c.heading_error,
        );
        let eq5 = SsBlock::<2>::from_tf(&paper::EQ5_INTERNAL_CONTROLLER, paper::PAPER_TS_S).unwrap();
        let model_state = eq5.steady_state_for_output(c.speed as f32).unwrap();
        let mut obstacles = [None; MAX_OBSTACLES];
        for (slot, ((lat, along, r), (ve, vn))) in obstacles.iter_mut().zip(&c.obstacles) {
            let (ox, oy, oh) = path.pose(5.0 + *along as f64);
            let east = ox + *lat as f64 * oh.cos();
            let north = oy - *lat as f64 * oh.sin();
            let mut o = path.place(east, north, *r as f64, 5.0);
            let (sh, ch) = (oh.sin() as f32, oh.cos() as f32);
            o.velocity = ObstacleVelocity {
                east_mps: *ve,
                north_mps: *vn,
                along_mps: ve * sh + vn * ch,
                right_mps: ve * ch - vn * sh,
            };
            *slot = Some(o);
        }
        let mut steer = c.steer;
        let mut uncertainty = c.uncertainty;
        match c.poison {
            1 => pose.x_m = f32::NAN,
            2 => reference[7].curvature_per_m = f32::NAN,
            3 => steer = f32::INFINITY,
            4 => uncertainty = f32::NAN,
            5 => reference[3].front_left.sample.left_m = f32::NAN,
            // A velocity that is not a number, on an obstacle of its own if the case has none.
            6 => {
                let o = obstacles[0].get_or_insert_with(|| path.place(0.0, 30.0, 0.5, 5.0));
                o.velocity.right_mps = f32::NAN;
            }
            _ => {}
        }
        let mut state = MpcState::default();
        let max_steer = (cfg.chassis.max_steer_deg as f32).to_radians();
        let rate = (cfg.steering.rate_limit_pct_per_s as f32 / 100.0) * max_steer
            * DEFAULT_TUNING.steer_rate_share;
        // Three ticks, so that warm starts are exercised too (the second is followed by a tick
        // without a solve).
        for tick in 0..3 {
            let input = MpcInput {
                reference: &reference,
                obstacles: &obstacles,
                car: CarState {
                    pose,
                    speed_mps: c.speed as f32,
                    lateral: LateralState { vy_mps: c.lateral.0, yaw_rate_rps: c.lateral.1 },
                    steer_rad: steer,
                    mode: if c.dynamic { Mode::Dynamic } else { Mode::Kinematic },
                    speed_model: &model_state,
                    speed_bias_mps: 0.0,
                    last_speed_cmd_mps: c.speed as f32,
                },
                position_uncertainty_m: uncertainty,
                path_max_curvature_per_m: reference
                    .iter()
                    .map(|r| r.curvature_per_m.abs())
                    .fold(0.0, f32::max),
                to_end_m: f32::INFINITY,
                in_held_turn: false,
                slow_ahead: None,
            };
            let out = mpc.solve(&mut state, &input);
            prop_assert!(out.steer_cmd_pct.is_finite() && out.steer_cmd_pct.abs() <= 100.0);
            prop_assert!(out.speed_cmd_mps.is_finite());
            prop_assert!(out.speed_cmd_mps >= 0.0 && out.speed_cmd_mps <= DEFAULT_TUNING.speed.max_speed_mps);
            prop_assert!(out.primal_residual.is_finite() && out.dual_residual.is_finite());
            prop_assert!(out.iterations <= DEFAULT_TUNING.admm.max_iterations);
            let every = DEFAULT_TUNING.admm.rho_update_every;
            prop_assert!(out.factorisations <= 1 + (DEFAULT_TUNING.admm.max_iterations - 1) / every);
            if c.poison != 0 {
                prop_assert_eq!(out.status, ControlStatus::Fallback);
                prop_assert_eq!(out.fallback, Some(FallbackReason::BadInput));
                prop_assert_eq!(out.speed_cmd_mps, 0.0);
            }
            if out.status == ControlStatus::Fallback {
                prop_assert_eq!(out.speed_cmd_mps, 0.0);
                continue;
            }
            for p in &out.plan {
                prop_assert!(p.x_m.is_finite() && p.y_m.is_finite() && p.heading_rad.is_finite());
                prop_assert!(p.speed_mps.is_finite() && p.speed_mps >= 0.0);
                prop_assert!(p.steer_rad.abs() <= max_steer * (1.0 + 1e-5));
            }
            // The steering plan's rate limit holds exactly (to rounding).
            for k in 0..STEPS {
                let d = out.plan[k + 1].steer_rad - out.plan[k].steer_rad;
                prop_assert!(d.abs() <= rate * STEP_S * (1.0 + 1e-4) + 1e-6, "step {}: {}", k, d);
            }
            if tick == 1 {
                // A tick without a solve (the node's tick that loads a long path): the same
                // plan one tick (a fifth of a step) later, the same speed command, the steering
                // ramp one tick on; and the next solve starts from the warm start it aged.
                let mut coasted = out;
                mpc.coast(&mut state, &mut coasted);
                let f = 1.0 / TICKS_PER_STEP as f32;
                let near = |a: f32, b: f32| (a - b).abs() <= 1e-4 * (1.0 + a.abs().max(b.abs()));
                for k in 0..=PLAN_STEPS {
                    let (a, b, at) = if k < PLAN_STEPS {
                        (out.plan[k], out.plan[k + 1], f)
                    } else {
                        (out.plan[k - 1], out.plan[k], 1.0 + f)
                    };
                    let p = coasted.plan[k];
                    prop_assert!(near(p.t_s, k as f32 * STEP_S));
                    prop_assert!(near(p.x_m, a.x_m + (b.x_m - a.x_m) * at), "x at {}", k);
                    prop_assert!(near(p.y_m, a.y_m + (b.y_m - a.y_m) * at), "y at {}", k);
                    prop_assert!(near(p.steer_rad, a.steer_rad + (b.steer_rad - a.steer_rad) * at));
                }
                prop_assert_eq!(coasted.speed_cmd_mps, out.speed_cmd_mps);
                prop_assert_eq!(coasted.status, out.status);
                let ramp_pct = (out.plan[1].steer_rad - out.plan[0].steer_rad) * f / max_steer * 100.0;
                let steer = (out.steer_cmd_pct + ramp_pct).clamp(-100.0, 100.0);
                prop_assert!(near(coasted.steer_cmd_pct, steer));
                prop_assert_eq!(coasted.iterations, 0);
            }
        }
    }
}

/// One solve from a fresh state with `tuning` for a car at 10 m/s with straight wheels,
/// `offset_m` right of a straight path at its station 5 m, on the escape body; the path's
/// largest curvature as given.
fn solve_beside_a_straight(
    cfg: &VehicleConfig,
    tuning: MpcTuning,
    offset_m: f32,
    path_max_curvature_per_m: f32,
) -> MpcOutput {
    solve_on_a_straight(cfg, tuning, offset_m, path_max_curvature_per_m, |_| None)
}

/// As [`solve_beside_a_straight`], with the obstacles `place` puts on the path (3 m corridors
/// either side, north from the origin).
fn solve_on_a_straight(
    cfg: &VehicleConfig,
    tuning: MpcTuning,
    offset_m: f32,
    path_max_curvature_per_m: f32,
    place: impl Fn(&TestPath) -> Option<Obstacle>,
) -> MpcOutput {
    let path = arc(0.0, 3.0, 3.0, 10.0);
    solve_on(
        &path,
        cfg,
        tuning,
        offset_m,
        path_max_curvature_per_m,
        10.0,
        place,
    )
}

/// One solve from a fresh state with `tuning` for a car at `speed_mps` (its speed model steady
/// there) with straight wheels, `offset_m` right of `path` at its station 5 m, on the escape
/// body, with the obstacle `place` puts on the path; the path's largest curvature as given.
fn solve_on(
    path: &TestPath,
    cfg: &VehicleConfig,
    tuning: MpcTuning,
    offset_m: f32,
    path_max_curvature_per_m: f32,
    speed_mps: f32,
    place: impl Fn(&TestPath) -> Option<Obstacle>,
) -> MpcOutput {
    let speeds = [speed_mps; PLAN_STEPS + 1];
    let reference = path.reference(5.0, &speeds, &ESCAPE_BODY, &StageClock::UNIFORM);
    let (x, y, h) = path.pose(5.0);
    let pose = Pose::new(x as f32 + offset_m, y as f32, h as f32);
    let eq5 = SsBlock::<2>::from_tf(&paper::EQ5_INTERNAL_CONTROLLER, paper::PAPER_TS_S).unwrap();
    let model_state = eq5.steady_state_for_output(speed_mps).unwrap();
    let mut obstacles = [None; MAX_OBSTACLES];
    obstacles[0] = place(path);
    let mpc = mpc_for(cfg, ESCAPE_BODY, tuning);
    let mut state = MpcState::default();
    let input = MpcInput {
        reference: &reference,
        obstacles: &obstacles,
        car: CarState {
            pose,
            speed_mps,
            lateral: LateralState::default(),
            steer_rad: 0.0,
            mode: if speed_mps < 5.0 {
                Mode::Kinematic
            } else {
                Mode::Dynamic
            },
            speed_model: &model_state,
            speed_bias_mps: 0.0,
            last_speed_cmd_mps: speed_mps,
        },
        position_uncertainty_m: 0.1,
        path_max_curvature_per_m,
        to_end_m: f32::INFINITY,
        in_held_turn: false,
        slow_ahead: None,
    };
    mpc.solve(&mut state, &input)
}

/// An obstacle that crosses the path is passed behind: on the side it leaves, though the
/// other has more room where it is now (the side with room for one that stands, or one that
/// moves along the path). Here 1 m left of a straight path 30 m ahead, 4 m of corridor either
/// side. Behind it is where it is now (it may stop there, braking at 1 g: 0.11 m on from
/// 1.5 m/s), not where it will be: with 3 m of corridor on the left there is no room behind it
/// yet, and the car slows for it.
#[test]
fn a_crossing_obstacle_is_passed_behind() {
    let cfg = VehicleConfig::default();
    let solve = |corridor_m: f64, east_m: f64, east_mps: f32, north_mps: f32| {
        let path = arc(0.0, corridor_m, corridor_m, 10.0);
        solve_on(&path, &cfg, DEFAULT_TUNING, 0.0, 0.0, 10.0, |path| {
            let mut o = path.place(east_m, 35.0, 0.3, 5.0);
            // The path runs north: along is north, right is east.
            o.velocity = ObstacleVelocity {
                east_mps,
                north_mps,
                along_mps: north_mps,
                right_mps: east_mps,
            };
            Some(o)
        })
    };
    let side = |east_mps: f32, north_mps: f32| {
        let out = solve(4.0, -1.0, east_mps, north_mps);
        assert_ne!(out.status, ControlStatus::Fallback, "{out:?}");
        out.sides[0]
    };
    assert_eq!(side(0.0, 0.0), Some(ObstacleSide::Right));
    assert_eq!(side(0.0, 5.0), Some(ObstacleSide::Right));
    assert_eq!(side(1.5, 0.0), Some(ObstacleSide::Left));
    assert_eq!(side(-1.5, 0.0), Some(ObstacleSide::Right));
    // Below the crossing speed, as if it stood.
    assert_eq!(side(0.25, 0.0), Some(ObstacleSide::Right));
    // The inflated circle (1.0 m) 1.11 m left of the path at least leaves 1.89 m of a 3 m
    // corridor, less than the body's 1.81 m and the corner rows' 0.15 m.
    let no_room_yet = solve(3.0, -1.0, 1.5, 0.0);
    assert_eq!(no_room_yet.sides[0], None, "{no_room_yet:?}");
    assert!(no_room_yet.speed_cmd_mps < 9.0, "{no_room_yet:?}");
    // 2.5 m left and walking into the lane: the room is ahead of it, where it is going, and
    // none behind it yet: no side; the car stops short of it (a stand-still obstacle there is
    // passed on the right).
    assert_eq!(
        solve(4.0, -2.5, 0.0, 0.0).sides[0],
        Some(ObstacleSide::Right)
    );
    let walking_in = solve(4.0, -2.5, 0.5, 0.0);
    assert_eq!(walking_in.sides[0], None, "{walking_in:?}");
    assert!(walking_in.speed_cmd_mps < 9.0, "{walking_in:?}");
}

/// A car ahead is planned around wherever it can be: from where braking at 1 g from now would
/// stop it to where it goes on at its measured velocity. Here a car at 6 m/s, 14 m ahead in
/// the lane of a straight path (6 m of corridor on the left), overtaken at 10 m/s by a car
/// already 1 m left of the path. Going on, it is met after the 2 s horizon; braked, it stops
/// 1.8 m on and the body's front reaches it after about 1 s. Every plan step's body keeps the
/// inflated circle's margin (0.6 m and the position's 0.1 m, less the 0.25 m a plan's
/// obstacle rows are allowed) from where it would have stopped: 0.63 m at least. (Before,
/// the plan passed where it would have gone on: 0.23 m.)
#[test]
fn a_car_ahead_is_passed_clear_of_where_it_would_stop_braking() {
    let cfg = VehicleConfig::default();
    let path = arc(0.0, 6.0, 3.0, 10.0);
    let (station, ahead, speed, radius) = (5.0_f64, 14.0_f64, 6.0_f32, 1.0_f32);
    let out = solve_on(&path, &cfg, DEFAULT_TUNING, -1.0, 0.0, 10.0, |path| {
        let mut o = path.place(0.0, station + ahead, f64::from(radius), station);
        // The path runs north: along is north.
        o.velocity = ObstacleVelocity {
            east_mps: 0.0,
            north_mps: speed,
            along_mps: speed,
            right_mps: 0.0,
        };
        Some(o)
    });
    assert_ne!(out.status, ControlStatus::Fallback, "{out:?}");
    assert_eq!(out.sides[0], Some(ObstacleSide::Left), "{out:?}");
    // Its stop, by hand: v^2 / 2a = 16 / 20 m on.
    let stopped_north = (station + ahead) as f32 + 1.8;
    let front = ESCAPE_BODY.length_m - ESCAPE_BODY.rear_overhang_m;
    let rear = -ESCAPE_BODY.rear_overhang_m;
    let half = 0.5 * ESCAPE_BODY.width_m;
    let mut least = f32::INFINITY;
    for p in &out.plan {
        // Where it would be braked at 1 g from now (it stops at 0.4 s).
        let t = p.t_s.min(0.6);
        let north = (station + ahead) as f32 + speed * t - 5.0 * t * t;
        assert!(north <= stopped_north + 1e-4);
        let (dx, dy) = (0.0 - p.x_m, north - p.y_m);
        let (sh, ch) = p.heading_rad.sin_cos();
        let along = dx * sh + dy * ch;
        let lateral = dx * ch - dy * sh;
        let ox = along - along.clamp(rear, front);
        let oy = (lateral.abs() - half).max(0.0);
        least = least.min((ox * ox + oy * oy).sqrt() - radius);
    }
    assert!(least >= 0.6 + 0.1 - 0.25, "least clearance {least} m");
}

/// A slower car changing into the lane beside the car's front half is driven past, not braked
/// for: braking keeps the car beside it while it comes across (`MpcConfig::overtakes`). Here a
/// car (radius 1.5 m) 3 m left of a straight path (two lanes: 6 m of corridor on the left,
/// 1.75 m on the right) at 4 m/s, coming right at 1.2 m/s, its centre 1 m ahead of the rear
/// axle of a car at 8 m/s: its inflated circle (2.2 m) already reaches the body's left side.
/// By hand: past it at 4 m/s closing in (1 + 2.2 + 0.9) / 4 = 1.03 s; behind it braking at
/// 1 g after 0.8 s, 0.8 + (4 + sqrt(16 + 20 (3.2 + 4.74))) / 10 = 2.52 s. The car keeps to its
/// side (the obstacle's right), does not brake, and the plan moves it right first. (Before, the
/// crossing car left no room behind it, and the car braked at once: status 3, speed 0.)
/// The same car with its circle ahead of the body's front (6 m ahead), or faster than the car
/// (10 m/s), is braked for.
#[test]
fn a_slower_car_cutting_in_beside_the_front_is_driven_past() {
    let cfg = VehicleConfig::default();
    let solve = |ahead_m: f64, north_mps: f32| {
        let path = arc(0.0, 6.0, 1.75, 8.0);
        solve_on(&path, &cfg, DEFAULT_TUNING, 0.0, 0.0, 8.0, |path| {
            let mut o = path.place(-3.0, 5.0 + ahead_m, 1.5, 5.0);
            // The path runs north: along is north, right is east.
            o.velocity = ObstacleVelocity {
                east_mps: 1.2,
                north_mps,
                along_mps: north_mps,
                right_mps: 1.2,
            };
            Some(o)
        })
    };
    let beside = solve(1.0, 4.0);
    assert_ne!(beside.status, ControlStatus::Fallback, "{beside:?}");
    assert_eq!(beside.sides[0], Some(ObstacleSide::Right), "{beside:?}");
    assert!(beside.speed_cmd_mps >= 7.9, "{beside:?}");
    // Away from it first: right (east) over the plan's first second.
    assert!(beside.plan[2].steer_rad > 0.0, "{beside:?}");
    let away = beside.plan[..=10].iter().map(|p| p.x_m).fold(0.0, f32::max);
    assert!(away > 0.05, "{beside:?}");
    let ahead = solve(6.0, 4.0);
    assert!(ahead.speed_cmd_mps < 1.0, "{ahead:?}");
    let faster = solve(1.0, 10.0);
    assert!(faster.speed_cmd_mps < 1.0, "{faster:?}");
}

/// A car at rest sets off past an obstacle only if it can get beside it before its front
/// reaches it at full lock: here one 0.5 m right of a straight path, its inflated circle
/// 1.0 m, passed on the left, which takes a shift of 1.4 m (4.7 m forward at the lock's
/// radius, less the plan's tolerance). 2 m short of it the car stays (no passage, speed 0);
/// 8 m short it sets off on the left. (Before, it set off from 2 m as from 8.)
#[test]
fn a_car_at_rest_sets_off_only_past_an_obstacle_it_can_get_beside() {
    let cfg = VehicleConfig::default();
    let front = f64::from(ESCAPE_BODY.length_m - ESCAPE_BODY.rear_overhang_m);
    let solve = |gap_m: f64| {
        solve_on(
            &arc(0.0, 3.0, 3.0, 10.0),
            &cfg,
            DEFAULT_TUNING,
            0.0,
            0.0,
            0.0,
            |path| {
                // The rear axle at station 5; the inflated radius 0.3 + 0.1 + 0.6.
                Some(path.place(0.5, 5.0 + front + 1.0 + gap_m, 0.3, 5.0))
            },
        )
    };
    let near = solve(2.0);
    assert_eq!(near.status, ControlStatus::Fallback, "{near:?}");
    assert_eq!(near.speed_cmd_mps, 0.0, "{near:?}");
    assert_eq!(near.sides[0], None, "{near:?}");
    let far = solve(8.0);
    assert_ne!(far.status, ControlStatus::Fallback, "{far:?}");
    assert_eq!(far.sides[0], Some(ObstacleSide::Left), "{far:?}");
    assert!(far.speed_cmd_mps > 0.5, "{far:?}");
}

/// `MpcTuning::line_rule`: a path that asks for the lock (here its largest curvature is the
/// lock's) is weighed with the rule's lateral weight, a path that does not (or a non-finite
/// curvature) with the tuning's; without the rule the path's curvature changes nothing. Seen
/// in the command of a car 5 cm right of a straight path: the weight of 10 steers back
/// harder than the weight of 1.
#[test]
fn a_path_that_needs_the_lock_is_weighed_with_the_rules_weight() {
    let cfg = VehicleConfig::default();
    let lock_curvature =
        (cfg.chassis.max_steer_deg as f32).to_radians().tan() / cfg.chassis.wheelbase_m as f32;
    let command = |tuning, path_max_curvature_per_m: f32| {
        solve_beside_a_straight(&cfg, tuning, 0.05, path_max_curvature_per_m).steer_cmd_pct
    };
    let tracked = command(DEFAULT_TUNING, 0.0);
    let past_lock = command(DEFAULT_TUNING, lock_curvature);
    assert!(tracked < 0.0 && past_lock < 0.0, "{tracked} {past_lock}");
    assert!(
        past_lock.abs() < 0.8 * tracked.abs(),
        "{tracked} {past_lock}"
    );
    assert_eq!(command(DEFAULT_TUNING, -lock_curvature), past_lock);
    assert_eq!(command(DEFAULT_TUNING, f32::NAN), tracked);
    let mut weight_one = DEFAULT_TUNING;
    weight_one.weights.lateral_per_m2 = 1.0;
    weight_one.line_rule = None;
    assert_eq!(command(weight_one, 0.0), past_lock);
    let mut no_rule = DEFAULT_TUNING;
    no_rule.line_rule = None;
    assert_eq!(command(no_rule, lock_curvature), tracked);
}

/// `MpcTuning::steer_lead_s`: the steering command is the plan's steering the lead after the
/// commanded ramp's tick. Within the first stage (the built-in 0.07 s) that is the ramp plus
/// the first stage's rate; a lead that reaches past the stage (a slow actuator's, declared in
/// its model file) takes the plan's later stages, where a reversal of the rate shows.
#[test]
fn a_lead_past_the_first_stage_commands_the_plans_later_steering() {
    let cfg = VehicleConfig::default();
    let max_steer_rad = (cfg.chassis.max_steer_deg as f32).to_radians();
    // 0.3 m right of the path: the plan steers back left, then straightens.
    let solve = |lead_s: f32| {
        let mut tuning = DEFAULT_TUNING;
        tuning.steer_lead_s = lead_s;
        let out = solve_beside_a_straight(&cfg, tuning, 0.3, 0.0);
        let plan: Vec<f32> = out
            .plan
            .iter()
            .map(|p| p.steer_rad * 100.0 / max_steer_rad)
            .collect();
        (out.steer_cmd_pct, plan)
    };
    let (built_in, plan) = solve(DEFAULT_TUNING.steer_lead_s);
    // The lead does not change the plan, only where on it the command is taken.
    for lead in [0.0, 0.13, 0.18, 0.25] {
        assert_eq!(solve(lead).1, plan, "lead {lead}");
    }
    assert!(plan[1] < -1.0, "the plan steers back left: {plan:?}");
    let at = |t: f32| {
        let k = (t / 0.1) as usize;
        let f = t / 0.1 - k as f32;
        plan[k] + (plan[k + 1] - plan[k]) * f
    };
    let near = |a: f32, b: f32| (a - b).abs() < 1e-3 * (1.0 + b.abs());
    // The tick and the lead: 0.02 + 0.07 s; 0.02 s with none.
    assert!(near(built_in, at(0.09)), "{built_in} vs {}", at(0.09));
    assert!(
        near(solve(0.0).0, at(0.02)),
        "{} vs {}",
        solve(0.0).0,
        at(0.02)
    );
    // Past the first stage: the plan's own steering there, not the first rate extrapolated.
    assert!(
        near(solve(0.18).0, plan[2]),
        "{} vs {}",
        solve(0.18).0,
        plan[2]
    );
    assert!(
        near(solve(0.13).0, at(0.15)),
        "{} vs {}",
        solve(0.13).0,
        at(0.15)
    );
    let extrapolated = plan[0] + (plan[1] - plan[0]) * 2.0;
    assert!(
        (plan[2] - extrapolated).abs() > 0.5,
        "the plan's rate changes after its first stage: {plan:?}"
    );
}

/// The speed bias the plan works with (`SpeedState::filter_bias`), by hand: the first tick
/// takes the bias as measured; a step of the measured bias from 0 to 1 m/s is followed at
/// `1 - (1 - 0.02 / tau)^n` after `n` ticks (after `tau` = 1.5 s, 75 ticks: 0.6346, the
/// continuous lowpass's 1 - 1/e = 0.6321 to within the discretisation); a time constant of 0
/// (or below a tick) passes the bias through; a non-finite bias counts as 0 and never reaches
/// the filter's state.
#[test]
fn a_low_passed_speed_bias() {
    use catmodel::control::mpc::longitudinal::SpeedState;
    let tau = DEFAULT_TUNING.speed.bias_time_constant_s;
    assert_eq!(tau, 1.5);
    let mut s = SpeedState::new();
    assert_eq!(s.filter_bias(0.0, tau), 0.0);
    let mut b = 0.0;
    for _ in 0..75 {
        b = s.filter_bias(1.0, tau);
    }
    let want = 1.0 - (1.0 - 0.02f64 / 1.5).powi(75);
    assert!((f64::from(b) - want).abs() < 1e-5, "{b} vs {want}");
    assert!((b - 0.6321).abs() < 0.005);
    let before = b;
    assert!((s.filter_bias(f32::NAN, tau) - before * (1.0 - 0.02 / 1.5)).abs() < 1e-6);
    let mut raw = SpeedState::new();
    assert_eq!(raw.filter_bias(0.3, 0.0), 0.3);
    assert_eq!(raw.filter_bias(-2.0, 0.0), -2.0);
    assert_eq!(raw.filter_bias(f32::INFINITY, 0.01), 0.0);
}

/// A car that brakes harder than its speed model (eq 5 rolled on from 3 m/s with the command
/// at 0, the car measured at 0.5 m/s: a bias of about -2.5 m/s) asked to stop: the plan keeps
/// the command at 0 over the whole horizon and predicts no speed below 0. Before, model plus
/// bias went below zero after about a second and the plan commanded speed to bring the car
/// back to a stop.
#[test]
fn the_speed_plan_does_not_predict_a_car_reversing() {
    use catmodel::control::mpc::longitudinal::{SpeedPlanner, SpeedStart, SpeedState};
    let block = SsBlock::from_tf(&paper::EQ5_INTERNAL_CONTROLLER, paper::PAPER_TS_S).unwrap();
    let planner = SpeedPlanner::new(&block, DEFAULT_TUNING.speed).unwrap();
    let (model_state, modelled) = eq5_held_at(&block, 3.0, 0.0);
    let start = SpeedStart {
        model_state: &model_state,
        bias_mps: 0.5 - modelled,
        planning_bias_mps: 0.5 - modelled,
        speed_mps: 0.5,
        last_command_mps: 0.0,
        in_held_turn: false,
        slow_ahead: None,
    };
    assert!(start.bias_mps < -2.4);
    let free = planner.free_response(&start, 0.0);
    assert!(free.iter().all(|v| *v >= 0.0), "{free:?}");
    assert!(free.contains(&0.0), "the case no longer reaches below zero");
    let mut state = SpeedState::new();
    for _ in 0..50 {
        let plan = planner.plan(&mut state, &start, &[0.0; PLAN_STEPS + 1], f32::INFINITY);
        assert!(plan.commands_mps.iter().all(|c| *c < 0.01), "{plan:?}");
        assert!(plan.speeds_mps.iter().all(|v| *v >= 0.0));
    }
}

/// The stop at the path's end, by hand: it begins when the end is within the horizon's 2 s at
/// the car's speed or the path's (at least [`STOP_CREEP_MPS`]) and the last command is not
/// above the car's speed (cruising or braking, not launching), or within the creep's 2 m
/// whatever the command; it is held until the end moves more than [`STOP_END_MOVED_M`] away.
/// NaN is at the end, an infinite distance never stops.
#[test]
fn the_stop_at_the_path_end_is_held_until_the_end_moves_away() {
    use catmodel::control::mpc::longitudinal::{SpeedState, STOP_CREEP_MPS, STOP_END_MOVED_M};
    assert_eq!((STOP_CREEP_MPS, STOP_END_MOVED_M), (1.0, 1.0));
    // (speed, path's target here, last command, end ahead)
    let mut s = SpeedState::new();
    assert!(!s.in_stop(4.0, 4.0, 4.0, 8.1), "8.1 m ahead, 8 m reach");
    assert!(s.in_stop(4.0, 4.0, 4.0, 8.0));
    // Braking harder than the end comes nearer: 3 m of reach, 4 m to go, still in the stop.
    assert!(s.in_stop(1.5, 1.5, 1.5, 4.0));
    assert!(
        s.in_stop(1.5, 1.5, 1.5, 4.9),
        "0.9 m farther: noise, not a new end"
    );
    assert!(
        !s.in_stop(1.5, 1.5, 1.5, 6.0),
        "1.1 m farther: a longer path"
    );
    // The path's speed sets the reach too: a car below it, braking, 5 m before the end.
    let mut s = SpeedState::new();
    assert!(!s.in_stop(2.0, 3.0, 1.0, 6.1));
    assert!(s.in_stop(2.0, 3.0, 1.0, 6.0));
    // Launching (the command above the speed) on a path shorter than 2 s at its speed: not
    // until the creep's 2 m.
    let mut s = SpeedState::new();
    assert!(!s.in_stop(1.0, 5.0, 6.0, 9.0));
    assert!(!s.in_stop(3.0, 5.0, 6.0, 2.1));
    assert!(s.in_stop(3.0, 5.0, 6.0, 2.0));
    let mut s = SpeedState::new();
    assert!(!s.in_stop(30.0, 30.0, 30.0, f32::INFINITY));
    assert!(s.in_stop(f32::NAN, f32::NAN, f32::NAN, f32::NAN));
    let mut s = SpeedState::new();
    assert!(s.in_stop(0.5, 0.0, 1.0, -3.0), "past the end");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 500, ..ProptestConfig::default() })]

    /// The speed reference against the path's end, whatever the targets and the speed: no step
    /// above what stops it at the end at the tuning's deceleration unless that deceleration
    /// already binds (`r_k <= max(sqrt(2 decel d_k), r_{k-1} - decel dt)`, `d_k` the distance
    /// left after its own travel), never above the car's speed (or the creep's) in the stop,
    /// never outside `[0, max speed]`; with room to stop (`v0^2 / (2 decel)`), an end within
    /// 1 m is reached by the horizon's last step at 0, no more than 5 mm past it (the last
    /// step's partial deceleration: at most `decel dt^2 / 8`, 4 mm).
    #[test]
    fn the_speed_reference_stops_at_the_path_end(
        v0 in 0.0f32..20.0,
        targets in prop::collection::vec(0.0f32..25.0, PLAN_STEPS + 1),
        to_end in 0.0f32..80.0,
        stopping in any::<bool>(),
    ) {
        use catmodel::control::mpc::longitudinal::{SpeedPlanner, STOP_CREEP_MPS};
        let block = SsBlock::from_tf(&paper::EQ5_INTERNAL_CONTROLLER, paper::PAPER_TS_S).unwrap();
        let tuning = DEFAULT_TUNING.speed;
        let planner = SpeedPlanner::new(&block, tuning).unwrap();
        let targets: [f32; PLAN_STEPS + 1] = targets.try_into().unwrap();
        let r = planner.reference(v0, &targets, to_end, stopping);
        let (a, dt) = (tuning.decel_mps2, STEP_S);
        let (mut prev, mut travelled) = (v0, 0.0f32);
        for (k, &v) in r.iter().enumerate() {
            let bound = (2.0 * a * (to_end - travelled).max(0.0)).sqrt();
            prop_assert!(v >= 0.0 && v <= tuning.max_speed_mps, "step {k}: {v}");
            prop_assert!(v <= bound.max(prev - a * dt) + 1e-4, "step {k}: {v} over {bound}");
            if stopping {
                prop_assert!(v <= v0.max(STOP_CREEP_MPS) + 1e-6, "step {k}: {v} rises");
            }
            travelled += 0.5 * (prev + v) * dt;
            prev = v;
        }
        // Room to stop, an end near enough to be reached within the horizon's 2 s.
        if v0 * v0 / (2.0 * a) <= to_end && to_end <= 1.0 {
            prop_assert_eq!(r[PLAN_STEPS - 1], 0.0);
            prop_assert!(travelled <= to_end + 0.005, "{travelled} m for {to_end} m");
        }
    }
}

/// The speed plan in the stop at the path's end, against a car that brakes harder than its
/// model (eq 5 rolled on at 1.0 m/s, the car measured slower: a bias below zero): past the
/// end every command is 0 (before, the plan held 0.19 m/s: against the bias it saw no gain in
/// a lower command; a car of scripts/sil-sim.py rolled 2.3 m past the end); 3 m before it, no
/// command above the last one or the creep's 1 m/s, where without an end the same start is
/// commanded higher to hold a reference above the car.
#[test]
fn the_speed_plan_in_the_stop_does_not_rise() {
    use catmodel::control::mpc::longitudinal::{SpeedPlanner, SpeedStart, SpeedState};
    let block = SsBlock::from_tf(&paper::EQ5_INTERNAL_CONTROLLER, paper::PAPER_TS_S).unwrap();
    let planner = SpeedPlanner::new(&block, DEFAULT_TUNING.speed).unwrap();
    let (model_state, modelled) = eq5_held_at(&block, 1.0, 0.19);
    let past = SpeedStart {
        model_state: &model_state,
        bias_mps: 0.19 - modelled,
        planning_bias_mps: -0.8,
        speed_mps: 0.19,
        last_command_mps: 0.19,
        in_held_turn: false,
        slow_ahead: None,
    };
    let mut state = SpeedState::new();
    let plan = planner.plan(&mut state, &past, &[0.0; PLAN_STEPS + 1], -1.5);
    assert_eq!(plan.command_mps, 0.0, "{plan:?}");
    assert!(plan.commands_mps.iter().all(|c| *c == 0.0), "{plan:?}");

    let (model_state, modelled) = eq5_held_at(&block, 3.0, 0.5);
    let before = SpeedStart {
        model_state: &model_state,
        bias_mps: 1.4 - modelled,
        planning_bias_mps: -1.5,
        speed_mps: 1.4,
        last_command_mps: 0.5,
        in_held_turn: false,
        slow_ahead: None,
    };
    // The rig's taper (2 m/s^2) 3 m before the end, where the car is expected over the plan.
    let taper: [f32; PLAN_STEPS + 1] =
        std::array::from_fn(|k| (2.0 * 2.0 * (3.0 - 1.4 * STEP_S * k as f32).max(0.0)).sqrt());
    let mut state = SpeedState::new();
    let plan = planner.plan(&mut state, &before, &taper, 3.0);
    assert!(plan.commands_mps.iter().all(|c| *c <= 1.0), "{plan:?}");
    let mut state = SpeedState::new();
    let endless = planner.plan(&mut state, &before, &taper, f32::INFINITY);
    let highest = endless.commands_mps.iter().copied().fold(0.0, f32::max);
    assert!(highest > 1.5, "without the stop: {endless:?}");
}

/// The commands stay in a band about the steady-state commands that hold the plan's targets
/// (`(target - offset) / dc gain`). While the model predicts the car it is the tuning's 2 m/s
/// lead either side: a launch from 3 to 8 m/s on eq 5 with a reference rising at 6 m/s^2 (eq
/// 5's response is slow: the plan would lead the target by more) is commanded no more than
/// 8 / 1.01662 + 2 = 9.87 m/s; without the band and the lead (both infinite) the same plan
/// commands more. The centre moves with the offset the car shows while it holds a speed (a
/// bias of -1 m/s, steady for 30 s: 10.85 m/s), not with a bias on one tick. Once the model's
/// predictions miss by 1 m/s or more (the bias 1.5 m/s off its low-passed value) the band is
/// half the car's distance from the target, at least 0.5 m/s: at 7 m/s the commands stay
/// within 0.5 m/s of 7.87 m/s where without the band the plan leads by more, and a car at
/// 11 m/s is not commanded below 7.87 - 1.5 m/s, where without the band the plan goes lower.
#[test]
fn the_speed_commands_stay_in_a_band_about_the_steady_state() {
    use catmodel::control::mpc::longitudinal::{SpeedPlanner, SpeedStart, SpeedState};
    let block = SsBlock::from_tf(&paper::EQ5_INTERNAL_CONTROLLER, paper::PAPER_TS_S).unwrap();
    let g = 0.7647 / 0.7522;
    assert!((block.dc_gain().unwrap() - g).abs() < 1e-5);
    assert_eq!(DEFAULT_TUNING.speed.command_lead_mps, 2.0);
    assert_eq!(DEFAULT_TUNING.speed.command_band_mps, 0.5);
    assert_eq!(DEFAULT_TUNING.speed.command_band_per_mps, 0.5);
    // A reference that rises at 6 m/s^2: the plan leads it by far more than 2 m/s.
    let tuning = SpeedTuning {
        accel_mps2: 6.0,
        ..DEFAULT_TUNING.speed
    };
    let no_band = SpeedTuning {
        command_lead_mps: f32::INFINITY,
        command_band_mps: f32::INFINITY,
        ..tuning
    };
    let targets = [8.0f32; PLAN_STEPS + 1];
    // The commands of the plan on the `ticks`-th tick of a car at `speed` with the bias `bias`
    // (eq 5 settled at `speed - bias`) planned with `planning`, on every tick.
    let commands = |tuning, speed: f32, bias: f32, planning: f32, ticks: usize| {
        let planner = SpeedPlanner::new(&block, tuning).unwrap();
        let model_state = block.steady_state_for_output(speed - bias).unwrap();
        let start = SpeedStart {
            model_state: &model_state,
            bias_mps: bias,
            planning_bias_mps: planning,
            speed_mps: speed,
            last_command_mps: (speed - bias) / g,
            in_held_turn: false,
            slow_ahead: None,
        };
        let mut state = SpeedState::new();
        let mut plan = planner.plan(&mut state, &start, &targets, f32::INFINITY);
        for _ in 1..ticks {
            plan = planner.plan(&mut state, &start, &targets, f32::INFINITY);
        }
        plan.commands_mps
    };
    let highest = |c: [f32; 10]| c.iter().copied().fold(f32::MIN, f32::max);
    let lowest = |c: [f32; 10]| c.iter().copied().fold(f32::MAX, f32::min);
    let steady = 8.0 / g;
    let bounded = highest(commands(tuning, 3.0, 0.0, 0.0, 1));
    assert!((bounded - (steady + 2.0)).abs() < 1e-3, "{bounded}");
    let unbounded = highest(commands(no_band, 3.0, 0.0, 0.0, 1));
    assert!(unbounded > bounded + 1.0, "{unbounded} vs {bounded}");
    // A bias of -1 m/s on one tick does not move the band; held for 30 s it does.
    let once = highest(commands(tuning, 2.0, -1.0, -1.0, 1));
    assert!((once - (steady + 2.0)).abs() < 1e-3, "{once}");
    let held = highest(commands(tuning, 2.0, -1.0, -1.0, 1500));
    assert!((held - (9.0 / g + 2.0)).abs() < 0.01, "{held}");
    // A model that misses: the bias 1.5 m/s, its low-passed value 0.
    let near = commands(tuning, 7.0, 1.5, 0.0, 1);
    assert!(highest(near) <= steady + 0.5 + 1e-4, "{near:?}");
    assert!(lowest(near) >= steady - 0.5 - 1e-4, "{near:?}");
    let near_free = commands(no_band, 7.0, 1.5, 0.0, 1);
    assert!(highest(near_free) > steady + 1.0, "{near_free:?}");
    let over = commands(tuning, 11.0, -1.5, 0.0, 1);
    assert!(lowest(over) >= steady - 1.5 - 1e-4, "{over:?}");
    let over_free = commands(no_band, 11.0, -1.5, 0.0, 1);
    assert!(lowest(over_free) < steady - 2.0, "{over_free:?}");
}

/// In a turn the path's lateral limit holds (`SpeedStart::in_held_turn`) the commands do not
/// lead: a car at 7 m/s held to 7 m/s where it is, 15 m/s ahead (the turn's exit within the
/// plan), is commanded at most the steady state of 7 m/s plus the 0.5 m/s band, where out of
/// the turn the plan leads towards 15 (up to its steady state plus the 2 m/s lead); a car below
/// the held speed is still led up to it within the band.
#[test]
fn the_speed_commands_do_not_lead_in_a_held_turn() {
    use catmodel::control::mpc::longitudinal::{SpeedPlanner, SpeedStart, SpeedState};
    let block = SsBlock::from_tf(&paper::EQ5_INTERNAL_CONTROLLER, paper::PAPER_TS_S).unwrap();
    let g = block.dc_gain().unwrap();
    let planner = SpeedPlanner::new(&block, DEFAULT_TUNING.speed).unwrap();
    let mut targets = [15.0f32; PLAN_STEPS + 1];
    for t in targets.iter_mut().take(8) {
        *t = 7.0;
    }
    let highest = |speed: f32, held: bool| {
        let model_state = block.steady_state_for_output(speed).unwrap();
        let start = SpeedStart {
            model_state: &model_state,
            bias_mps: 0.0,
            planning_bias_mps: 0.0,
            speed_mps: speed,
            last_command_mps: speed / g,
            in_held_turn: held,
            slow_ahead: None,
        };
        let plan = planner.plan(&mut SpeedState::new(), &start, &targets, f32::INFINITY);
        plan.commands_mps.iter().copied().fold(f32::MIN, f32::max)
    };
    let held = highest(7.0, true);
    assert!(held <= 7.0 / g + 0.5 + 1e-4, "{held}");
    let free = highest(7.0, false);
    assert!(free > 7.0 / g + 2.0, "{free}");
    assert!(free <= 15.0 / g + 2.0 + 1e-4, "{free}");
    let below = highest(5.0, true);
    assert!(below > 5.0 / g && below <= 7.0 / g + 0.5 + 1e-4, "{below}");
}

/// How well the speed model describes the car (`SpeedState::track_fit`), by hand: the gap
/// between the bias and its low-passed value is the mismatch, held at its largest and
/// forgotten by 0.02 / 3 per tick; the offset starts at 0 and follows the bias by 0.02 / 3 per
/// tick only while the gap is under 0.25 m/s.
#[test]
fn the_speed_models_fit_by_hand() {
    use catmodel::control::mpc::longitudinal::{
        SpeedState, MISMATCH_TIME_CONSTANT_S, OFFSET_STEADY_MPS, OFFSET_TIME_CONSTANT_S,
    };
    assert_eq!(
        (
            MISMATCH_TIME_CONSTANT_S,
            OFFSET_TIME_CONSTANT_S,
            OFFSET_STEADY_MPS
        ),
        (3.0, 3.0, 0.25)
    );
    let k = 0.02f32 / 3.0;
    let mut s = SpeedState::new();
    let fit = s.track_fit(1.0, 1.0);
    assert_eq!((fit.offset_mps, fit.mismatch_mps), (0.0, 0.0));
    let fit = s.track_fit(1.0, 1.0);
    assert!((fit.offset_mps - k).abs() < 1e-7, "{fit:?}");
    // A miss of 1.5 m/s: the mismatch jumps, the offset holds.
    let before = fit.offset_mps;
    let fit = s.track_fit(2.0, 0.5);
    assert_eq!((fit.offset_mps, fit.mismatch_mps), (before, 1.5));
    let fit = s.track_fit(1.0, 1.0);
    assert!((fit.mismatch_mps - 1.5 * (1.0 - k)).abs() < 1e-6, "{fit:?}");
    assert!((fit.offset_mps - (before + (1.0 - before) * k)).abs() < 1e-7);
    // Just under the gate the offset moves; at it, not.
    let prev = fit.offset_mps;
    let fit = s.track_fit(0.3, 0.3 - 0.249);
    assert!(
        (fit.offset_mps - (prev + (0.3 - prev) * k)).abs() < 1e-7,
        "{fit:?}"
    );
    let held = fit.offset_mps;
    assert_eq!(s.track_fit(5.0, 4.75).offset_mps, held);
    // Non-finite inputs count as 0.
    let fit = s.track_fit(f32::NAN, f32::INFINITY);
    assert!(fit.offset_mps.is_finite() && fit.mismatch_mps.is_finite());
}

/// Eq 5 settled at `speed_mps` and what it outputs on its next step with the command at
/// `command_mps`: the model's state and its speed there (the bias a start is given against).
fn eq5_held_at(
    block: &SsBlock<2>,
    speed_mps: f32,
    command_mps: f32,
) -> (catmodel::model::SsBlockState<2>, f32) {
    let model_state = block.steady_state_for_output(speed_mps).unwrap();
    let mut peek = model_state;
    let modelled = block.step(&mut peek, command_mps);
    (model_state, modelled)
}

/// The model's coast-out (`SpeedPlanner::coast_m`), by hand: eq 5 settled at 5 m/s, every
/// later command 0, rolls `v T` to a standstill, `T` its mean response time: the delay plus
/// `den1 / den0 - num1 / num0` of `(0.03679 s^2 - 0.1981 s + 0.7647) / (s^2 + 1.629 s +
/// 0.7522)`, 0.42 + 2.16565 + 0.25906 = 2.84471 s (the first moment of its impulse response
/// over its DC gain), 14.224 m, within half a 20 ms step of speed (the sum of the outputs
/// counts the step it starts on). Stepping the model to rest says the same.
#[test]
fn the_coast_out_is_the_speed_times_the_models_mean_response() {
    use catmodel::control::mpc::longitudinal::SpeedPlanner;
    let block = SsBlock::from_tf(&paper::EQ5_INTERNAL_CONTROLLER, paper::PAPER_TS_S).unwrap();
    let planner = SpeedPlanner::new(&block, DEFAULT_TUNING.speed).unwrap();
    let settled = block.steady_state_for_output(5.0).unwrap();
    let coast = planner.coast_m(&settled).unwrap();
    let by_hand = 5.0 * (0.42 + 1.629 / 0.7522 + 0.1981 / 0.7647);
    assert!(
        (coast - by_hand).abs() < 0.5 * 5.0 * 0.02 + 0.01,
        "{coast} vs {by_hand}"
    );
    let mut rolled = settled;
    let mut distance = 0.0f64;
    for _ in 0..5000 {
        distance += f64::from(block.step(&mut rolled, 0.0)) * 0.02;
    }
    assert!(
        (f64::from(coast) - distance).abs() < 1e-3,
        "{coast} vs {distance}"
    );
    // At rest with nothing in flight, nothing.
    assert_eq!(planner.coast_m(&block.zero_state()), Some(0.0));
}

/// A car whose speed loop is eq 5 exactly stops at the path's end, not past it: the speed
/// plan alone, with eq 5 as the car (no bias), from 6 m/s, 40 m before the end of a path whose
/// targets taper to the end at 1 m/s^2 as `scripts/sil-sim.py`'s do, each tick's targets where
/// the last plan's speeds take the car. Without the cap from the model's coast-out the car
/// rolled 0.83 m past the end (the reference's taper asks for a deceleration eq 5 cannot give
/// with commands of 0 or more, and the 2 s plan saw it too late); with it, 3 mm short.
#[test]
fn a_car_that_is_its_speed_model_stops_at_the_path_end() {
    use catmodel::control::mpc::longitudinal::{SpeedPlanner, SpeedStart, SpeedState};
    let block = SsBlock::from_tf(&paper::EQ5_INTERNAL_CONTROLLER, paper::PAPER_TS_S).unwrap();
    let planner = SpeedPlanner::new(&block, DEFAULT_TUNING.speed).unwrap();
    let (cruise, length) = (6.0f32, 40.0f32);
    let target = |s: f32| cruise.min((2.0 * 1.0 * (length - s).max(0.0)).sqrt());
    let mut car = block.steady_state_for_output(cruise).unwrap();
    let mut state = SpeedState::new();
    let (mut s, mut v, mut last) = (0.0f32, cruise, cruise / block.dc_gain().unwrap());
    let mut speeds = [cruise; PLAN_STEPS + 1];
    for tick in 0..3000 {
        let mut station = s;
        let targets: [f32; PLAN_STEPS + 1] = std::array::from_fn(|k| {
            if k > 0 {
                station += 0.5 * (speeds[k - 1] + speeds[k]) * STEP_S;
            }
            target(station)
        });
        let mut peek = car;
        let modelled = block.step(&mut peek, 0.0);
        let start = SpeedStart {
            model_state: &car,
            bias_mps: v - modelled,
            planning_bias_mps: v - modelled,
            speed_mps: v,
            last_command_mps: last,
            in_held_turn: false,
            slow_ahead: None,
        };
        let plan = planner.plan(&mut state, &start, &targets, length - s);
        speeds = plan.speeds_mps;
        last = plan.command_mps;
        v = block.step(&mut car, last);
        s += v * 0.02;
        if tick > 100 && v < 0.01 {
            break;
        }
    }
    assert!(v < 0.01, "still moving at {v} m/s");
    assert!(
        s <= length && s > length - 0.05,
        "stopped {} m from the end (+ past it)",
        s - length
    );
}

/// The steering plan's clock by hand (`mpc::StageClock`): the horizon is 2 s for a car whose
/// steering changes its curvature at least at 0.14 1/m per s, 2 s times 0.14 over the car's
/// rate for a slower one (the first second in 0.1 s stages, the rest in stages of whole ticks,
/// rounded up), at most 4 s; and its times, indices and speeds agree with one another.
#[test]
fn the_stage_clock_by_hand() {
    let rate = |pct: f32, lock_deg: f32| pct / 100.0 * lock_deg.to_radians();
    // The CAT Vehicle: 60 % of 35.5 deg a second on 2.62 m is 0.142 1/m per s.
    assert_eq!(
        StageClock::for_steering(2.62, rate(60.0, 35.5)),
        StageClock::UNIFORM
    );
    // A van, 55 % of 36 deg on 3.665 m: 0.0943 1/m per s asks for 2.97 s; 1 s + 10 x 0.2 s.
    let van = StageClock::for_steering(3.665, rate(55.0, 36.0));
    assert_eq!(van, StageClock::with_late_ticks(10));
    assert!((van.horizon_s() - 3.0).abs() < 1e-5, "{}", van.horizon_s());
    // 0.1 s short of what the van asks for: 9 ticks are not enough (1 + 10 x 0.18 = 2.8 s).
    assert!(1.0 + 10.0 * 0.18 < 2.0 * 0.14 / (rate(55.0, 36.0) / 3.665));
    // A truck, 40 % of 32 deg on 4.8 m: 0.0465 asks for 6.0 s; capped at 1 s + 10 x 0.3 s.
    let truck = StageClock::for_steering(4.8, rate(40.0, 32.0));
    assert_eq!(truck, StageClock::with_late_ticks(15));
    assert!((truck.horizon_s() - 4.0).abs() < 1e-5);
    // Nothing usable: the tuning's clock; a rate of 0: the longest.
    assert_eq!(StageClock::for_steering(f32::NAN, 0.3), StageClock::UNIFORM);
    assert_eq!(StageClock::for_steering(2.6, 0.0), truck);
    for clock in [StageClock::UNIFORM, van, truck] {
        let mut t = 0.0f32;
        for k in 0..STEPS {
            assert!((clock.time_s(k) - t).abs() < 1e-5, "stage {k}");
            assert!((clock.index_at_s(t) - k as f32).abs() < 1e-4, "stage {k}");
            let ticks = clock.stage_ticks(k);
            assert!((clock.stage_s(k) - ticks as f32 * 0.02).abs() < 1e-6);
            // A tick after stage k is its share of the stage; a stage's ticks reach the next.
            assert!((clock.index_after(k, 1) - (k as f32 + 1.0 / ticks as f32)).abs() < 1e-6);
            assert!((clock.index_after(k, ticks) - (k + 1) as f32).abs() < 1e-5);
            t += clock.stage_s(k);
        }
        assert!((clock.horizon_s() - t).abs() < 1e-5);
        // The speed plan's speeds at the stages: a ramp of 1 m/s per 0.1 s step, held past 2 s.
        let plan: [f32; PLAN_STEPS + 1] = std::array::from_fn(|k| k as f32);
        for (k, v) in clock.stage_speeds(&plan).iter().enumerate() {
            let want = (clock.time_s(k) / STEP_S).min(PLAN_STEPS as f32);
            assert!((v - want).abs() < 1e-4, "stage {k}: {v} against {want}");
        }
    }
}

/// `MpcConfig::blind_steer_pct`, by hand: a plan at 10 m/s for its first second and 5 m/s for
/// its second (0.1 s steps, so 1 m and 0.5 m a step; the step across the change 0.75 m), its
/// steering 0.01 rad per step. The steering is the plan's where it had covered the distance
/// travelled plus the lead's (0.07 s at the car's speed), linear between points, the last
/// point's past the end, and in percent of the lock.
#[test]
fn a_car_driven_blind_steers_along_its_plan_by_distance() {
    use catmodel::control::mpc::PlanPoint;
    let cfg = VehicleConfig::default();
    let lock = (cfg.chassis.max_steer_deg as f32).to_radians();
    let mpc = mpc_for(&cfg, ESCAPE_BODY, DEFAULT_TUNING);
    let mut plan = [PlanPoint::default(); PLAN_STEPS + 1];
    for (k, p) in plan.iter_mut().enumerate() {
        p.t_s = k as f32 * 0.1;
        p.speed_mps = if k <= 10 { 10.0 } else { 5.0 };
        p.steer_rad = 0.01 * k as f32;
    }
    let pct = |rad: f32| rad / lock * 100.0;
    let near = |a: f32, b: f32| (a - b).abs() < 1e-4;
    // Standing at the start: the first point.
    assert!(near(mpc.blind_steer_pct(&plan, 0.0, 0.0), 0.0));
    // 2.5 m covered, standing: halfway between points 2 and 3.
    assert!(near(mpc.blind_steer_pct(&plan, 2.5, 0.0), pct(0.025)));
    // 2.5 m and 10 m/s: 0.7 m more, 3.2 m: 0.2 of the way from point 3 to 4.
    assert!(near(mpc.blind_steer_pct(&plan, 2.5, 10.0), pct(0.032)));
    // 10.375 m: halfway across the 0.75 m step from point 10 to 11.
    assert!(near(mpc.blind_steer_pct(&plan, 10.375, 0.0), pct(0.105)));
    // 11.75 m: point 13 (10.75 m to point 11, 0.5 m a step after it).
    assert!(near(mpc.blind_steer_pct(&plan, 11.75, 0.0), pct(0.13)));
    // Past the plan's 15.25 m: its last steering.
    assert!(near(mpc.blind_steer_pct(&plan, 40.0, 8.0), pct(0.2)));
    // Not finite: from the start.
    assert!(near(mpc.blind_steer_pct(&plan, f32::NAN, f32::NAN), 0.0));
}

/// A car that is eq 5 a few ticks late (the published speed model, its commands taking effect
/// `lag_ticks` of 20 ms after the model's delay: a car a little slower than its model), on a
/// straight whose target steps down from 12 m/s to `low` 80 m ahead, the plan's targets the
/// path's envelope at the tuning's deceleration, the node's bias (measured minus modelled
/// speed) fed back: with the lower target ahead (`SpeedStart::slow_ahead`, as
/// `Path::slow_ahead` picks it) the car is at the step within the target's slack and excess;
/// without it (the horizon and the envelope alone) it is over by more (a black-box probe's car
/// over `sil --stdio`: 2.94 m/s at a step to 1 m/s). After the step the speed does not fall far
/// below the target (it is not a stop).
#[test]
fn the_speed_plan_slows_for_a_lower_target_beyond_its_horizon() {
    use catmodel::control::mpc::longitudinal::{
        SpeedPlanner, SpeedStart, SpeedState, SLOW_AHEAD_EXCESS_MPS, SLOW_AHEAD_SHARE,
        SPEED_LIMIT_SLACK_MPS,
    };
    use catmodel::control::mpc::{SlowAhead, STEP_S};
    let block = SsBlock::from_tf(&paper::EQ5_INTERNAL_CONTROLLER, paper::PAPER_TS_S).unwrap();
    let tuning = DEFAULT_TUNING.speed;
    let planner = SpeedPlanner::new(&block, tuning).unwrap();
    let run = |low: f32, lag_ticks: usize, slow: bool| -> (f32, f32) {
        let (high, step_m) = (12.0f32, 80.0f32);
        let target = |s: f32| {
            if s >= step_m {
                low
            } else {
                high.min((low * low + 2.0 * tuning.decel_mps2 * (step_m - s)).sqrt())
            }
        };
        let hold = high / block.dc_gain().unwrap();
        let mut model = block.steady_state_for_output(high).unwrap();
        let mut car = model;
        let mut late = std::collections::VecDeque::from(vec![hold; lag_ticks]);
        let mut state = SpeedState::new();
        let (mut s, mut v, mut last, mut bias) = (0.0f32, high, hold, 0.0f32);
        let (mut at, mut least_after) = (f32::NAN, f32::INFINITY);
        for _ in 0..4000 {
            let targets: [f32; PLAN_STEPS + 1] =
                core::array::from_fn(|k| target(s + v * STEP_S * k as f32));
            let below = v - SPEED_LIMIT_SLACK_MPS - SLOW_AHEAD_EXCESS_MPS;
            let slow_ahead = (slow && s < step_m && low < below && low < SLOW_AHEAD_SHARE * high)
                .then_some(SlowAhead {
                    ahead_m: step_m - s,
                    target_mps: low,
                });
            let start = SpeedStart {
                model_state: &model,
                bias_mps: bias,
                planning_bias_mps: state.filter_bias(bias, tuning.bias_time_constant_s),
                speed_mps: v,
                last_command_mps: last,
                in_held_turn: false,
                slow_ahead,
            };
            last = planner
                .plan(&mut state, &start, &targets, f32::INFINITY)
                .command_mps;
            let modelled = block.step(&mut model, last);
            late.push_back(last);
            v = block
                .step(&mut car, late.pop_front().unwrap_or(last))
                .max(0.0);
            bias = v - modelled;
            let before = s;
            s += v * catmodel::SAMPLE_PERIOD_S;
            if before < step_m && s >= step_m {
                at = v;
            }
            if s >= step_m + 10.0 {
                least_after = least_after.min(v);
            }
            if s > step_m + 40.0 {
                break;
            }
        }
        (at, least_after)
    };
    let slack = SPEED_LIMIT_SLACK_MPS + SLOW_AHEAD_EXCESS_MPS;
    // Steps to less than half the speed: the bound brakes earlier, and the car is at the step
    // within the slack and the excess (and 0.15 m/s), where without it it was over (to 5 m/s:
    // 5.33 / 5.65 / 5.99 m/s without, 5.07 / 5.29 / 5.58 with, 0 / 5 / 10 ticks late).
    for (low, lag_ticks) in [(5.0f32, 0), (5.0, 5), (5.0, 10), (3.0, 10)] {
        let (with, after) = run(low, lag_ticks, true);
        let (without, _) = run(low, lag_ticks, false);
        assert!(
            with < without - 0.05 && with <= low + slack + 0.15,
            "to {low}, {lag_ticks} ticks late: {with} m/s at the step ({without} without)"
        );
        assert!(
            after > 0.75 * low,
            "to {low}: down to {after} m/s after the step"
        );
    }
    for lag_ticks in [0, 5, 10] {
        // A step to more than half the speed is left to the horizon: the bound slowed eq 5's
        // car well below it (down to 5.0-6.1 m/s after a step from 12 to 8 m/s).
        assert_eq!(run(8.0, lag_ticks, true), run(8.0, lag_ticks, false));
    }
}

/// `MpcConfig::shift_speed_mps` against the manoeuvre it stands for, flown step by step: at the
/// speed it gives, the car's curvature ramped at the plan's steering rate (the actuator's rate
/// limit times `steer_rate_share`, over the wheelbase), held at the lock when the ramp would
/// pass it, in the jerk's bang-bang pattern (up, down twice as long, up, with holds at the lock
/// between), shifts the car sideways by the shift over the run and leaves it straight, to first
/// order in the heading (`y'' = v^2 k`); the pattern is the fastest there is for a limited
/// jerk and acceleration (the time-optimal rest-to-rest triple integrator), so no faster speed
/// makes the shift. A run shorter than the lock's `2 sqrt(shift R)` has no speed.
#[test]
fn the_speed_of_a_shift_is_the_one_at_which_the_fastest_manoeuvre_makes_it() {
    let cfg = VehicleConfig::default();
    let mpc = mpc_for(&cfg, ESCAPE_BODY, DEFAULT_TUNING);
    let c = &cfg.chassis;
    let lock = c.max_steer_deg.to_radians().tan() / c.wheelbase_m;
    let rate = cfg.steering.rate_limit_pct_per_s / 100.0
        * c.max_steer_deg.to_radians()
        * f64::from(DEFAULT_TUNING.steer_rate_share)
        / c.wheelbase_m;
    let mut lock_limited = 0;
    for (shift, run) in [
        (4.756, 15.56),
        (4.756, 20.56),
        (1.0, 7.56),
        (4.756, 10.56),
        (2.76, 10.56),
        (2.0, 6.0),
        (0.5, 30.0),
    ] {
        let v = f64::from(mpc.shift_speed_mps(shift as f32, run as f32));
        assert!(v > 0.0, "{shift} m over {run} m");
        let t_total = run / v;
        // Time to ramp from straight to the lock; the bang-bang's quarter when it stays below.
        let ramp = (lock / rate).min(t_total / 4.0);
        let hold = 0.5 * (t_total - 4.0 * ramp);
        if hold > 1e-9 {
            lock_limited += 1;
        }
        let phases = [
            (ramp, rate),
            (hold, 0.0),
            (2.0 * ramp, -rate),
            (hold, 0.0),
            (ramp, rate),
        ];
        let (mut k, mut heading, mut y, mut peak) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        let steps = 20_000;
        for (duration, dk) in phases {
            let h = duration / f64::from(steps);
            for _ in 0..steps {
                // Exact over a step for a linear ramp of the curvature.
                y += v * heading * h + 0.5 * v * v * k * h * h + v * v * dk * h * h * h / 6.0;
                heading += v * k * h + 0.5 * v * dk * h * h;
                k += dk * h;
                peak = peak.max(k.abs());
            }
        }
        println!(
            "{shift} m over {run} m: {v:.3} m/s, {t_total:.2} s, shifted {y:.4} m, heading \
             {heading:.2e} rad, curvature {k:.2e} 1/m, peak {peak:.4} of the lock's {lock:.4}"
        );
        assert!((y - shift).abs() < 1e-3 * shift, "shifted {y}");
        assert!(heading.abs() < 1e-6 && k.abs() < 1e-9, "{heading} {k}");
        assert!(peak <= lock * (1.0 + 1e-6), "{peak}");
    }
    assert!(
        lock_limited >= 2,
        "both regimes: {lock_limited} at the lock"
    );
    // The lock's 2 sqrt(shift R) for 4.756 m is 8.37 m on the CAT Vehicle: no speed below it.
    let radius = 1.0 / lock;
    let least = 2.0 * (4.756 * radius).sqrt();
    assert!(mpc.shift_speed_mps(4.756, (least - 0.05) as f32) <= 0.0);
    assert!(mpc.shift_speed_mps(4.756, (least + 0.05) as f32) > 0.0);
    assert!(mpc.shift_speed_mps(4.756, -1.0) <= 0.0);
}

/// The fallback's braking plan (`SpeedPlanner::stop`: the model rolled under command 0) is the
/// plan's own prediction of zero commands (`SpeedPlanner::predict` over the free response with
/// the last command held, the pulse matrix's product), to f32 rounding: for eq 5 and a slower
/// loop with a longer delay, at speeds from a crawl to 30 m/s, with last commands above, at and
/// below the steady state and speed biases either way. A roll-out under another command, or a
/// product that dropped a knot, is metres per second off.
#[test]
fn the_fallbacks_stop_is_the_plans_prediction_of_zero_commands() {
    use catmodel::control::mpc::longitudinal::{SpeedPlanner, SpeedStart, KNOTS};
    let eq5 = SsBlock::from_tf(&paper::EQ5_INTERNAL_CONTROLLER, paper::PAPER_TS_S).unwrap();
    // A slower loop (poles at -0.7 and -2 1/s, gain 0.9) with a 0.6 s delay.
    let slow = catmodel::model::tf::TransferFunction::new(&[0.0, 0.0, 1.26], &[1.0, 2.7, 1.4], 0.6)
        .and_then(|tf| SsBlock::from_tf(&tf, paper::PAPER_TS_S));
    let mut checked = 0;
    for block in [Some(eq5), slow.ok()].into_iter().flatten() {
        let planner = SpeedPlanner::new(&block, DEFAULT_TUNING.speed).unwrap();
        let g = block.dc_gain().unwrap();
        for speed in [0.5f32, 4.0, 12.0, 30.0] {
            for last_factor in [0.0f32, 0.6, 1.0, 1.3] {
                for bias in [-0.8f32, 0.0, 0.8] {
                    let state = block.steady_state_for_output(speed).unwrap();
                    let last = speed / g * last_factor;
                    let start = SpeedStart {
                        model_state: &state,
                        bias_mps: bias,
                        planning_bias_mps: bias,
                        speed_mps: speed + bias,
                        last_command_mps: last,
                        in_held_turn: false,
                        slow_ahead: None,
                    };
                    let stop = planner.stop(&start);
                    let free = nalgebra::SVector::<f32, PLAN_STEPS>::from(
                        planner.free_response(&start, last),
                    );
                    let predicted = planner.predict(&free, last, &[0.0; KNOTS], speed + bias);
                    assert_eq!(stop.command_mps, 0.0);
                    assert!(stop.commands_mps.iter().all(|c| *c == 0.0));
                    for (k, (s, p)) in stop.speeds_mps.iter().zip(&predicted).enumerate() {
                        // The prediction clamps the free response at 0 before the product;
                        // where the held command's response stays above 0 the two agree.
                        if free.iter().all(|f| *f > 0.0) {
                            assert!(
                                (s - p).abs() < 2e-3,
                                "speed {speed}, last {last}, bias {bias}: step {k} {s} vs {p}"
                            );
                            checked += 1;
                        }
                        assert!(s.is_finite() && *s >= 0.0);
                    }
                    // Braking from a speed: the plan's last speed is below its first.
                    if speed + bias > 1.0 {
                        let end = stop.speeds_mps[PLAN_STEPS];
                        assert!(end < speed + bias, "{end} vs {}", speed + bias);
                    }
                }
            }
        }
    }
    assert!(checked > 500, "{checked} steps compared");
}
