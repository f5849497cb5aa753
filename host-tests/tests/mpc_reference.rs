//! The controller's numerics against independent references (`host-tests/reference/mpc.json`,
//! made by `host-tests/reference/gen_mpc.py`):
//! - the trapezoidal discretisation of the lateral error model against
//!   `scipy.signal.cont2discrete(method='bilinear')`;
//! - the Riccati-ADMM solver against an interior-point solution (cvxpy + Clarabel) of random
//!   time-varying problems of the controller's shape, with hard and exact-penalty rows;
//! - the speed plan: eq 5's pulse response at 0.1 s against scipy's simulation of the ZOH
//!   model with its delay, and the condensed QP against Clarabel.
use catmodel::control::mpc::admm::{AdmmSettings, Problem, Row, Workspace};
use catmodel::control::mpc::lateral::tustin;
use catmodel::control::mpc::longitudinal::{SpeedPlanner, SpeedStart, SpeedState, SpeedTuning};
use catmodel::control::mpc::{StageClock, NX, PLAN_STEPS, ROWS};

/// Stages of the reference problems (the solver is generic in the horizon).
const STEPS: usize = 20;
use catmodel::model::{paper, SsBlock};
use catmodel_host_tests::load_reference;
use nalgebra::{SMatrix, SVector};
use serde_json::Value;

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

fn vec_f32(v: &Value) -> Vec<f32> {
    v.as_array().unwrap().iter().map(|x| f(x) as f32).collect()
}

fn mat5(v: &Value) -> SMatrix<f32, NX, NX> {
    let rows: Vec<Vec<f32>> = v.as_array().unwrap().iter().map(vec_f32).collect();
    SMatrix::from_fn(|i, j| rows[i][j])
}

fn vec5(v: &Value) -> SVector<f32, NX> {
    SVector::from_column_slice(&vec_f32(v))
}

#[test]
fn trapezoidal_discretisation_matches_scipy_bilinear() {
    let r = load_reference("mpc.json");
    let h = f(&r["h"]) as f32;
    for case in r["tustin"].as_array().unwrap() {
        let (a, b, c) = tustin(&mat5(&case["f"]), &vec5(&case["e"]), h).expect("discretises");
        let what = format!("{} at {} m/s", case["mode"], case["v"]);
        for (got, want) in [(a.as_slice(), mat5(&case["a"]))] {
            for (g, w) in got.iter().zip(want.as_slice()) {
                assert!(
                    (g - w).abs() <= 2e-6 + 1e-5 * w.abs(),
                    "{what}: A {g} vs {w}"
                );
            }
        }
        for (got, want) in [(b, vec5(&case["b"])), (c, vec5(&case["c"]))] {
            for (g, w) in got.iter().zip(want.iter()) {
                assert!(
                    (g - w).abs() <= 2e-6 + 1e-5 * w.abs(),
                    "{what}: B/c {g} vs {w}"
                );
            }
        }
    }
}

/// The reference problem as the solver's data; rows beyond the file's are inactive.
fn problem(p: &Value) -> (Problem<NX, STEPS, ROWS>, SVector<f32, NX>) {
    let mut q = Problem::<NX, STEPS, ROWS>::zeroed();
    let (mut box_state, mut box_rho) = (0, 1.0);
    for k in 0..STEPS {
        let st = &mut q.stages[k];
        st.a = mat5(&p["a"][k]);
        st.b = vec5(&p["b"][k]);
        st.c = vec5(&p["c"][k]);
        st.q_diag = vec5(&p["q_diag"][k]);
        st.q_lin = vec5(&p["q_lin"][k]);
        st.r_lin = f(&p["r_lin"][k]) as f32;
        st.u_lower = f(&p["u_lower"][k]) as f32;
        st.u_upper = f(&p["u_upper"][k]) as f32;
        let mut slot = 0;
        for row in p["rows"][k].as_array().unwrap() {
            let bound = |v: &Value, inf: f32| v.as_f64().map_or(inf, |x| x as f32);
            let idx = [
                row["idx"][0].as_u64().unwrap(),
                row["idx"][1].as_u64().unwrap(),
            ];
            if idx == [4, 4] {
                // The steering range: the solver's state box.
                box_state = 4;
                st.box_lower = bound(&row["lower"], f32::NEG_INFINITY);
                st.box_upper = bound(&row["upper"], f32::INFINITY);
                box_rho = f(&row["rho"]) as f32;
                continue;
            }
            assert_eq!(idx, [0, 1], "rows read e_y and e_psi");
            st.rows[slot] = Row {
                a: f(&row["coef"][0]) as f32,
                b: f(&row["coef"][1]) as f32,
                lower: bound(&row["lower"], f32::NEG_INFINITY),
                upper: bound(&row["upper"], f32::INFINITY),
                rho: f(&row["rho"]) as f32,
                soft_weight: row["soft"].as_f64().map_or(f32::INFINITY, |x| x as f32),
                active: true,
            };
            slot += 1;
        }
    }
    q.box_state = box_state;
    q.box_rho = box_rho;
    q.r = f(&p["r"]) as f32;
    q.u_rho = 10.0;
    (q, vec5(&p["x0"]))
}

/// The problem's objective (f64) at the solver's plan, soft penalties included.
fn objective(p: &Problem<NX, STEPS, ROWS>, ws: &Workspace<NX, STEPS, ROWS>) -> f64 {
    let mut j = 0.0f64;
    for k in 0..STEPS {
        let (st, it) = (&p.stages[k], &ws.stages[k]);
        let x = &it.x;
        for i in 0..NX {
            let xi = x[i] as f64;
            j += 0.5 * st.q_diag[i] as f64 * xi * xi + st.q_lin[i] as f64 * xi;
        }
        let u = it.u as f64;
        j += 0.5 * p.r as f64 * u * u + st.r_lin as f64 * u;
        for row in st
            .rows
            .iter()
            .filter(|r| r.active && r.soft_weight.is_finite())
        {
            j += row.soft_weight as f64 * row.violation(row.eval(x)) as f64;
        }
    }
    j
}

fn settings(iterations: u16) -> AdmmSettings {
    AdmmSettings {
        max_iterations: iterations,
        primal_tolerance: 0.0,
        dual_tolerance: 0.0,
        relaxation: 1.6,
        check_every: 1,
        rho_update_every: 0,
    }
}

#[test]
fn admm_reaches_the_interior_point_solution() {
    let r = load_reference("mpc.json");
    for (n, case) in r["ltv_qp"].as_array().unwrap().iter().enumerate() {
        let (p, x0) = problem(&case["problem"]);
        let mut ws = Workspace::default();
        ws.cold_start(&p);
        ws.factor(&p).unwrap();
        let report = ws.iterate(&p, &x0, &settings(20_000)).unwrap();
        let sol = &case["solution"];
        let u_ref = vec_f32(&sol["u"]);
        let worst_u = ws
            .stages
            .iter()
            .map(|it| it.u)
            .zip(&u_ref)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        let worst_x = (0..STEPS)
            .flat_map(|k| {
                let xr = vec_f32(&sol["x"][k]);
                (0..NX).map(move |i| (k, i, xr[i]))
            })
            .map(|(k, i, xr)| (ws.stages[k].x[i] - xr).abs())
            .fold(0.0f32, f32::max);
        let j = objective(&p, &ws);
        let j_ref = f(&sol["objective"]);
        let mode = &case["problem"]["mode"];
        println!(
            "case {n} ({mode}): |u - u*| {worst_u:.2e} rad/s, |x - x*| {worst_x:.2e}, J {j:.6} vs {j_ref:.6}, residuals {:.1e} / {:.1e}",
            report.primal_residual, report.dual_residual
        );
        assert!(worst_u < 1e-3, "case {n}: inputs off by {worst_u}");
        assert!(worst_x < 1e-3, "case {n}: states off by {worst_x}");
        assert!(
            (j - j_ref).abs() <= 1e-4 * j_ref.abs().max(1.0),
            "case {n}: objective {j} vs {j_ref}"
        );
        // Hard rows and the box hold to the primal residual.
        for k in 0..STEPS {
            for row in p.stages[k]
                .rows
                .iter()
                .filter(|r| r.active && !r.soft_weight.is_finite())
            {
                assert!(
                    row.violation(row.eval(&ws.stages[k].x)) < 1e-3,
                    "case {n}: hard row violated"
                );
            }
            let d = ws.stages[k].x[p.box_state];
            assert!(
                d >= p.stages[k].box_lower - 1e-3 && d <= p.stages[k].box_upper + 1e-3,
                "case {n}: steering box"
            );
        }
    }
}

/// Warm start: after the state moves a little (the next tick), 30 iterations from the previous
/// solution's copies and duals land closer to the new optimum than 30 from a cold start.
#[test]
fn warm_start_beats_cold_start_at_the_iteration_cap() {
    let r = load_reference("mpc.json");
    for (n, case) in r["ltv_qp"].as_array().unwrap().iter().enumerate() {
        let (p, x0) = problem(&case["problem"]);
        let mut solved = Workspace::default();
        solved.cold_start(&p);
        solved.factor(&p).unwrap();
        solved.iterate(&p, &x0, &settings(20_000)).unwrap();
        // The next tick: the car a little further off the path.
        let mut x1 = x0;
        x1[0] += 0.05;
        x1[1] -= 0.01;
        let mut exact = solved.clone();
        exact.iterate(&p, &x1, &settings(20_000)).unwrap();
        let error = |ws: &Workspace<NX, STEPS, ROWS>| {
            ws.stages
                .iter()
                .map(|it| it.u)
                .zip(exact.stages.iter().map(|it| it.u))
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max)
        };
        let mut warm = solved.clone();
        warm.iterate(&p, &x1, &settings(30)).unwrap();
        let mut cold = Workspace::default();
        cold.cold_start(&p);
        cold.factor(&p).unwrap();
        cold.iterate(&p, &x1, &settings(30)).unwrap();
        println!(
            "case {n}: input error after 30 iterations: warm {:.2e}, cold {:.2e}",
            error(&warm),
            error(&cold)
        );
        assert!(
            error(&warm) < 0.5 * error(&cold) || error(&warm) < 1e-4,
            "case {n}"
        );
    }
}

/// A workspace that forgot a solve (`Workspace::forget`, a new path) solves the next problem
/// exactly as one reset to nothing does, bit for bit, whatever the solve before left in it:
/// after a solve of another problem from another state, and of the same problem.
#[test]
fn a_forgotten_solve_is_a_reset_one() {
    let r = load_reference("mpc.json");
    let cases = r["ltv_qp"].as_array().unwrap();
    for (n, case) in cases.iter().enumerate() {
        let (p, x0) = problem(&case["problem"]);
        for (m, before) in cases.iter().enumerate() {
            let (q, y0) = problem(&before["problem"]);
            let mut used = Workspace::default();
            used.cold_start(&q);
            used.factor(&q).unwrap();
            used.iterate(&q, &y0, &settings(50)).unwrap();
            // A solve that failed (the controller's `Solver` fallback forgets the workspace
            // too): the non-finite copies, duals and iterates it left reach nothing of the
            // next solve (what the cold start and the factorisation overwrite before reading).
            let mut failed = used.clone();
            for it in failed.stages.iter_mut() {
                it.u = f32::NAN;
                it.x = SVector::repeat(f32::NAN);
                it.z = [f32::NAN; ROWS];
                it.w = [f32::INFINITY; ROWS];
                (it.zb, it.wb, it.zu, it.wu) = (f32::NAN, f32::NAN, f32::NAN, f32::NAN);
            }
            let (mut forgot, mut reset) = (used.clone(), used);
            forgot.forget();
            reset.reset();
            failed.forget();
            for ws in [&mut forgot, &mut reset, &mut failed] {
                ws.cold_start(&p);
                ws.factor(&p).unwrap();
                ws.iterate(&p, &x0, &settings(12)).unwrap();
            }
            for (a, b) in failed.stages.iter().zip(&reset.stages) {
                assert_eq!(a.u.to_bits(), b.u.to_bits(), "case {n} after {m}, failed");
            }
            for (k, (a, b)) in forgot.stages.iter().zip(&reset.stages).enumerate() {
                assert_eq!(
                    a.u.to_bits(),
                    b.u.to_bits(),
                    "case {n} after {m}, stage {k}"
                );
                for i in 0..NX {
                    assert_eq!(a.x[i].to_bits(), b.x[i].to_bits(), "case {n} after {m}");
                }
            }
            // The solve before did move the workspace: a warm start would not be the same.
            let mut warm = forgot.clone();
            warm.shift(0.2);
            warm.factor(&p).unwrap();
            warm.iterate(&p, &x0, &settings(1)).unwrap();
            let mut cold = reset.clone();
            cold.reset();
            cold.cold_start(&p);
            cold.factor(&p).unwrap();
            cold.iterate(&p, &x0, &settings(1)).unwrap();
            assert!(
                warm.stages
                    .iter()
                    .zip(&cold.stages)
                    .any(|(a, b)| a.u != b.u),
                "case {n} after {m}: the test cannot tell a warm start from a cold one"
            );
        }
    }
}

fn eq5_block() -> SsBlock<2> {
    SsBlock::from_tf(&paper::EQ5_INTERNAL_CONTROLLER, paper::PAPER_TS_S).unwrap()
}

fn speed_tuning(r: &Value, iterations: u16) -> SpeedTuning {
    let t = &r["speed_qp"]["tuning"];
    SpeedTuning {
        speed_weight: f(&t["speed_weight"]) as f32,
        command_change_weight: f(&t["command_change_weight"]) as f32,
        max_speed_mps: f(&t["max_speed_mps"]) as f32,
        accel_mps2: f(&t["accel_mps2"]) as f32,
        decel_mps2: f(&t["decel_mps2"]) as f32,
        iterations,
        // The plan itself takes the bias it is given (the controller filters it).
        bias_time_constant_s: 0.0,
        // Nor does it bound the commands: scipy's QP has no such bound.
        command_lead_mps: f32::INFINITY,
        command_band_mps: f32::INFINITY,
        command_band_per_mps: 0.0,
    }
}

#[test]
fn speed_pulse_response_matches_scipy() {
    let r = load_reference("mpc.json");
    let planner = SpeedPlanner::new(&eq5_block(), speed_tuning(&r, 10)).unwrap();
    let want = vec_f32(&r["speed_qp"]["pulse"]);
    assert_eq!(want.len(), PLAN_STEPS + 1);
    for (m, (g, w)) in planner.pulse().iter().zip(&want).enumerate() {
        assert!((g - w).abs() < 2e-6, "pulse[{m}]: {g} vs {w}");
    }
    // The delay: 21 samples = 4.2 steps, so the first response is at step 5.
    assert!(planner.pulse()[..5].iter().all(|p| *p == 0.0));
    assert!(planner.pulse()[5] > 0.0);
}

#[test]
fn speed_plan_matches_the_qp_solution() {
    let r = load_reference("mpc.json");
    let block = eq5_block();
    let planner = SpeedPlanner::new(&block, speed_tuning(&r, 2000)).unwrap();
    for case in r["speed_qp"]["cases"].as_array().unwrap() {
        let v0 = f(&case["v0"]) as f32;
        let model_state = block.steady_state_for_output(v0).unwrap();
        let start = SpeedStart {
            model_state: &model_state,
            bias_mps: 0.0,
            planning_bias_mps: 0.0,
            speed_mps: v0,
            last_command_mps: f(&case["last_command"]) as f32,
            in_held_turn: false,
            slow_ahead: None,
        };
        let targets: [f32; PLAN_STEPS + 1] = vec_f32(&case["targets"]).try_into().unwrap();
        let plan = planner.plan(&mut SpeedState::default(), &start, &targets, f32::INFINITY);
        let want = vec_f32(&case["commands"]);
        for (j, (g, w)) in plan.commands_mps.iter().zip(&want).enumerate() {
            assert!((g - w).abs() < 0.02, "v0 {v0}: command {j}: {g} vs {w}");
        }
        let speeds = vec_f32(&case["speeds"]);
        for (k, (g, w)) in plan.speeds_mps[1..].iter().zip(&speeds).enumerate() {
            assert!(
                (g - w.max(0.0)).abs() < 0.01,
                "v0 {v0}: speed {k}: {g} vs {w}"
            );
        }
    }
}

/// The corridor's give for a car that starts outside it (`lateral::relax_corridor`), by hand:
/// rows of `e_y` with the corridor 1 m either side; the car starts at `e_y = 3`, 2 m beyond the
/// right-hand rows. A return at 1 m/s^2 takes `2 sqrt(2 / 1) = 2.828 s`; at stage `k` (the
/// state 0.1 (k + 1) s ahead) the right bound gives `2 (1 - s(t / 2.828))`, `s` the quintic
/// smoothstep: 1.99916 at 0.1 s (`s(0.035355) = 4.188e-4`), 1.0 at 1.414 s (`s(1/2) = 1/2`).
/// The left rows and the obstacle row are untouched; a car inside changes nothing.
#[test]
fn a_start_outside_the_corridor_relaxes_its_rows_by_a_tapering_give() {
    use catmodel::control::mpc::lateral::{relax_corridor, ROW_OBSTACLE};
    use catmodel::control::mpc::STEPS as MPC_STEPS;
    let corridor = |lower: f32, upper: f32| Row {
        a: 1.0,
        b: 0.0,
        lower,
        upper,
        rho: 50.0,
        soft_weight: 1000.0,
        active: true,
    };
    let fresh = || {
        let mut q = Problem::<NX, MPC_STEPS, ROWS>::zeroed();
        for st in q.stages.iter_mut() {
            st.rows[0] = corridor(-1.0, f32::INFINITY);
            st.rows[1] = corridor(f32::NEG_INFINITY, 1.0);
            st.rows[2] = corridor(-1.0, f32::INFINITY);
            st.rows[3] = corridor(f32::NEG_INFINITY, 1.0);
            st.rows[ROW_OBSTACLE] = corridor(2.5, f32::INFINITY);
        }
        q
    };
    let x = |e_y: f32| SVector::<f32, NX>::from([e_y, 0.0, 0.0, 0.0, 0.0]);

    let mut inside = fresh();
    assert_eq!(
        relax_corridor(&mut inside, &x(0.5), (1.0, 10.0, 0.2), &StageClock::UNIFORM),
        0.0
    );
    for (a, b) in inside.stages.iter().zip(fresh().stages.iter()) {
        assert_eq!(a.rows, b.rows, "a car inside its corridor changed the rows");
    }

    let mut q = fresh();
    assert_eq!(
        relax_corridor(&mut q, &x(3.0), (1.0, 10.0, 0.2), &StageClock::UNIFORM),
        2.0
    );
    let duration = 2.0 * 2.0f64.sqrt();
    let mut previous = f64::INFINITY;
    for (k, st) in q.stages.iter().enumerate() {
        let u = ((k + 1) as f64 * 0.1 / duration).min(1.0);
        let give = 2.0 * (1.0 - u * u * u * (10.0 - 15.0 * u + 6.0 * u * u));
        for slot in [1, 3] {
            let upper = f64::from(st.rows[slot].upper);
            assert!((upper - 1.0 - give).abs() < 1e-5, "stage {k}: {upper}");
            assert_eq!(st.rows[slot].lower, f32::NEG_INFINITY);
        }
        assert!(give <= previous, "the give grows at stage {k}");
        previous = give;
        for slot in [0, 2] {
            assert_eq!(st.rows[slot], corridor(-1.0, f32::INFINITY), "stage {k}");
        }
        assert_eq!(st.rows[ROW_OBSTACLE], corridor(2.5, f32::INFINITY));
    }
    // Hand values: 0.1 s and half the return's duration (stage 13 is at 1.4 s, not 1.414 s:
    // s(0.49497) = 0.49058).
    assert!((f64::from(q.stages[0].rows[1].upper) - 2.99916).abs() < 2e-5);
    assert!((f64::from(q.stages[13].rows[1].upper) - (1.0 + 2.0 * (1.0 - 0.49058))).abs() < 2e-4);

    // At 1 m/s the return is no faster than 0.2 rad of heading allows: its fastest lateral
    // speed, 1.875 x 2 m / duration, at most 1 m/s x sin 0.2, so the duration is
    // 1.875 x 2 / 0.19867 = 18.876 s, not 2.828 s. Stage 13 (1.4 s, u = 0.074170):
    // s(u) = 10 u^3 - 15 u^4 + 6 u^5 = 0.0036397, the give 2 (1 - s) = 1.99272.
    let mut slow = fresh();
    relax_corridor(&mut slow, &x(3.0), (1.0, 1.0, 0.2), &StageClock::UNIFORM);
    assert!((f64::from(slow.stages[13].rows[1].upper) - (1.0 + 1.99272)).abs() < 2e-4);
    // Standing counts as 1 m/s.
    let mut standing = fresh();
    relax_corridor(
        &mut standing,
        &x(3.0),
        (1.0, 0.0, 0.2),
        &StageClock::UNIFORM,
    );
    assert_eq!(standing.stages[13].rows[1], slow.stages[13].rows[1]);
}

/// The tracking targets' taper for a car far off its path (`lateral::taper_reference`), by
/// hand: the start 3 m right (`e_y = 3`), the taper from 1 m, so 2 m are returned along the
/// smoothstep over `2 sqrt(2 / 1) = 2.828 s`; at 10 m/s the heading target is
/// `-2 s'(u) / 2.828 / 10` with `s'(u) = 30 u^2 (1 - u)^2`. At stage 13 (1.4 s, `u = 0.49497`):
/// `e_y` target `2 (1 - 0.49058) = 1.01884`, `s'(u) = 1.87462`, heading `-0.13256` rad; the linear
/// terms are `-q x_ref`. A car within 1 m changes nothing; a car on the left mirrors it.
#[test]
fn a_start_far_off_the_path_tapers_the_tracking_targets() {
    use catmodel::control::mpc::lateral::{taper_reference, EPSI, EY};
    use catmodel::control::mpc::STEPS as MPC_STEPS;
    let fresh = || {
        let mut q = Problem::<NX, MPC_STEPS, ROWS>::zeroed();
        for st in q.stages.iter_mut() {
            st.q_diag = SVector::<f32, NX>::from([10.0, 10.0, 0.0, 0.0, 1.0]);
        }
        q
    };
    let x = |e_y: f32| SVector::<f32, NX>::from([e_y, 0.0, 0.0, 0.0, 0.0]);
    let speeds = [10.0f32; MPC_STEPS + 1];

    let mut near = fresh();
    assert_eq!(
        taper_reference(
            &mut near,
            &x(0.9),
            &speeds,
            &StageClock::UNIFORM,
            1.0,
            1.0,
            0.2
        ),
        0.0
    );
    assert!(near
        .stages
        .iter()
        .all(|st| st.q_lin == SVector::<f32, NX>::zeros()));

    let mut q = fresh();
    assert_eq!(
        taper_reference(
            &mut q,
            &x(3.0),
            &speeds,
            &StageClock::UNIFORM,
            1.0,
            1.0,
            0.2
        ),
        2.0
    );
    // Stage 13's targets (the linear terms are -10 times them), m and rad.
    let targets_at_13 = |q: &Problem<NX, MPC_STEPS, ROWS>, e_y: f64, e_psi: f64| {
        let st = &q.stages[13];
        for (got, want) in [(st.q_lin[EY], -10.0 * e_y), (st.q_lin[EPSI], -10.0 * e_psi)] {
            assert!((f64::from(got) - want).abs() < 2e-3, "{got} against {want}");
        }
    };
    targets_at_13(&q, 1.01884, -0.13256);
    // The e_y target falls and the heading target points back towards the path all along.
    let mut previous = f32::INFINITY;
    for st in &q.stages {
        let target = -st.q_lin[EY] / 10.0;
        assert!(target <= previous && target >= 0.0);
        previous = target;
        assert!(st.q_lin[EPSI] >= 0.0);
    }
    let mut left = fresh();
    assert_eq!(
        taper_reference(
            &mut left,
            &x(-3.0),
            &speeds,
            &StageClock::UNIFORM,
            1.0,
            1.0,
            0.2
        ),
        -2.0
    );
    for (l, r) in left.stages.iter().zip(&q.stages) {
        assert_eq!(l.q_lin[EY], -r.q_lin[EY]);
        assert_eq!(l.q_lin[EPSI], -r.q_lin[EPSI]);
    }
    // At 10 m/s the 2 m return at 1 m/s^2 (2.83 s, 1.33 m/s at its fastest) asks less than
    // 0.2 rad allows (1.99 m/s): the heading bound does not bind, as above. At 2 m/s it allows
    // 2 sin 0.2 = 0.397 m/s, so the return takes 1.875 x 2 / 0.397 = 9.438 s: at stage 13
    // (1.4 s, u = 0.1483) the target is 2 x 0.97419 = 1.9484 m and the heading target
    // 0.10147 m/s over the stage's 2 m/s, 0.0507 rad.
    let slow = [2.0f32; MPC_STEPS + 1];
    let mut crawl = fresh();
    assert_eq!(
        taper_reference(
            &mut crawl,
            &x(3.0),
            &slow,
            &StageClock::UNIFORM,
            1.0,
            1.0,
            0.2
        ),
        2.0
    );
    targets_at_13(&crawl, 1.94838, -0.05073);
    // Nowhere more than 0.2 rad of heading.
    assert!(crawl
        .stages
        .iter()
        .all(|st| st.q_lin[EPSI] / 10.0 <= 0.2f32.sin() + 1e-4));
}
