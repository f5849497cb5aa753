//! The lateral problem: error states along the reference, linearised per stage, discretised by
//! the trapezoidal rule, with the body's corners in the corridor and the obstacles' half-spaces
//! as constraint rows.
//!
//! State `x = [e_y, e_psi, v_y, r, delta]`: lateral offset of the rear axle from the reference
//! (m, positive right), heading error (rad, positive = pointing right of the path), lateral
//! speed at the centre of gravity and yaw rate (the dynamic model's states; held at 0 in the
//! kinematic mode), and the centre-tyre steering angle (rad). Input: the steering rate (rad/s),
//! so the actuator's rate limit is a bound on the input and the steering range a bound on a
//! state. Continuous dynamics with the speed `v` and path curvature `kappa` of the stage
//! (averages of its two ends), linearised about the previous plan's heading error `e0` and
//! steering `d0`:
//! ```text
//! e_y'   = v (sin e0 + cos e0 (e_psi - e0)) + cos e0 (v_y - l_r r)    (rear-axle velocity)
//! e_psi' = r - v kappa - v kappa^2 e_y                               (dynamic)
//!        = v (c(d0) + c'(d0) (delta - d0)) - v kappa - v kappa^2 e_y   (kinematic, eq 8 + eq 2)
//! v_y', r' = the linear-tyre single-track model (model::dynamic)      (dynamic; 0 kinematic)
//! delta' = u
//! ```
//! with `c(d) = tan(d / (1 + K v^2)) / L` the kinematic curvature. `-v kappa^2 e_y` is the
//! first-order term of the Frenet frame's `v kappa / (1 - kappa e_y)`.
//!
//! Discretisation (trapezoidal / Tustin, step h): `A = M^-1 (I + h/2 F)`, `B = M^-1 h G`,
//! `c = M^-1 h e` with `M = I - h/2 F`. A-stable (the tyre modes are fast at low speed: about
//! -(Cf + Cr) / (m v) = -14 1/s at 7 m/s), exact for the integrators, exact in steady state.
//! `M` is solved without pivoting: for these models every pivot is at least 1 (the proof is in
//! docs/mpc.md), and a pivot below 0.5 is reported as an error, never divided by.
use nalgebra::{SMatrix, SVector};

use super::admm::{Problem, Row};
use super::{clamp, max};
use super::{
    ObstacleSide, ObstacleVelocity, ReferencePoint, Sample, StageClock, Weights, MAX_OBSTACLES, NX,
    ROWS, STEPS,
};
use crate::math;
use crate::model::dynamic::DynamicParams;
use crate::model::hybrid::Mode;
use crate::vehicle::{Body, VehicleParams};

/// State indices.
pub const EY: usize = 0;
/// Heading error.
pub const EPSI: usize = 1;
/// Lateral speed at the CG.
pub const VY: usize = 2;
/// Yaw rate.
pub const R: usize = 3;
/// Steering angle.
pub const DELTA: usize = 4;

/// Row slots per stage: the body's sides in the corridor (each at the point where the corridor
/// binds it, [`super::SidePoint`]), then one per obstacle (the steering range is the solver's
/// state box).
/// Left side, front half.
pub const ROW_FRONT_LEFT: usize = 0;
/// Right side, front half.
pub const ROW_FRONT_RIGHT: usize = 1;
/// Left side, rear half.
pub const ROW_REAR_LEFT: usize = 2;
/// Right side, rear half.
pub const ROW_REAR_RIGHT: usize = 3;
/// First obstacle row (obstacle `i` is `ROW_OBSTACLE + i`).
pub const ROW_OBSTACLE: usize = 4;

/// Smallest block determinant accepted in the trapezoidal solve (>= 1 for these models).
const MIN_PIVOT: f32 = 0.5;

/// The linearisation point of every stage (0..=STEPS): the previous plan, shifted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Linearisation {
    /// Heading error, rad.
    pub e_psi: [f32; STEPS + 1],
    /// Steering angle, rad.
    pub delta: [f32; STEPS + 1],
}

/// Everything the builder needs besides the reference.
pub struct LateralSetup<'a> {
    /// Kinematic geometry and steering conversion.
    pub vehicle: &'a VehicleParams,
    /// Dynamic model parameters (`None`: the kinematic model whatever the mode).
    pub dynamics: Option<&'a DynamicParams>,
    /// Body for the corridor and obstacle rows.
    pub body: &'a Body,
    /// Cost weights and ADMM penalties.
    pub weights: &'a Weights,
    /// Lateral model of this solve.
    pub mode: Mode,
    /// Planned speed at each stage, m/s.
    pub speeds_mps: &'a [f32; STEPS + 1],
    /// Steering range, rad (symmetric).
    pub max_steer_rad: f32,
    /// Steering rate limit the plan may use, rad/s.
    pub max_steer_rate_rad_per_s: f32,
    /// The stages' lengths.
    pub stage: &'a StageClock,
}

/// Why the problem could not be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BuildError {
    /// A pivot of the trapezoidal solve was below the bound (non-finite data).
    Discretisation,
}

/// Feedforward steering for curvature `kappa` at speed `v`: the kinematic model's
/// `(1 + K v^2) atan(L kappa)` (its steady state; the dynamic model's is the same to first
/// order with its own understeer gradient).
pub fn feedforward_steer_rad(l_m: f32, understeer: f32, v_mps: f32, kappa_per_m: f32) -> f32 {
    (1.0 + understeer * v_mps * v_mps) * math::atan(l_m * kappa_per_m)
}

/// Continuous-time `F`, `e` of one stage (`G` is the unit vector of `delta`).
fn continuous(
    setup: &LateralSetup,
    v: f32,
    kappa: f32,
    e0: f32,
    d0: f32,
) -> (SMatrix<f32, NX, NX>, SVector<f32, NX>) {
    let (s0, c0) = math::sin_cos_inlined(e0);
    let mut f = SMatrix::<f32, NX, NX>::zeros();
    let mut e = SVector::<f32, NX>::zeros();
    let set = |m: &mut SMatrix<f32, NX, NX>, i: usize, j: usize, v: f32| {
        if let Some(x) = m.get_mut((i, j)) {
            *x = v;
        }
    };
    let sete = |m: &mut SVector<f32, NX>, i: usize, v: f32| {
        if let Some(x) = m.get_mut(i) {
            *x = v;
        }
    };
    set(&mut f, EY, EPSI, v * c0);
    sete(&mut e, EY, v * (s0 - c0 * e0));
    set(&mut f, EPSI, EY, -v * kappa * kappa);
    match setup.dynamics.filter(|_| setup.mode == Mode::Dynamic) {
        Some(p) => {
            // The 1/v terms need a speed; below the model's floor use the floor (the hybrid
            // switch keeps the dynamic mode above it; a plan that brakes may dip below).
            let vx = max(max(v, p.min_speed_mps), 0.1);
            let cf = p.cornering_front_n_per_rad;
            let cr = p.cornering_rear_n_per_rad;
            let (lf, lr) = (p.cg_to_front_m, p.cg_to_rear_m);
            let m = p.mass_kg;
            let iz = p.yaw_inertia_kg_m2;
            set(&mut f, EY, VY, c0);
            set(&mut f, EY, R, -lr * c0);
            set(&mut f, EPSI, R, 1.0);
            sete(&mut e, EPSI, -v * kappa);
            set(&mut f, VY, VY, -(cf + cr) / (m * vx));
            set(&mut f, VY, R, -vx - (cf * lf - cr * lr) / (m * vx));
            // The model's input is the wheel angle's tangent (`DynamicParams::steer_input`),
            // linearised about `d0` as the kinematic branch's curvature is.
            let t = DynamicParams::steer_input(d0);
            let dt = 1.0 + t * t;
            let u0 = t - dt * d0;
            set(&mut f, VY, DELTA, cf / m * dt);
            sete(&mut e, VY, cf / m * u0);
            set(&mut f, R, VY, -(cf * lf - cr * lr) / (iz * vx));
            set(&mut f, R, R, -(cf * lf * lf + cr * lr * lr) / (iz * vx));
            set(&mut f, R, DELTA, cf * lf / iz * dt);
            sete(&mut e, R, cf * lf / iz * u0);
        }
        None => {
            let veh = setup.vehicle;
            let scale = 1.0 / (1.0 + veh.understeer_s2_per_m2 * v * v);
            let t = math::tan_inlined(d0 * scale);
            let c = t / veh.wheelbase_m;
            let dc = scale * (1.0 + t * t) / veh.wheelbase_m;
            set(&mut f, EPSI, DELTA, v * dc);
            sete(&mut e, EPSI, v * (c - dc * d0) - v * kappa);
        }
    }
    (f, e)
}

/// Trapezoidal discretisation of `x' = F x + G u + e` over `h`, with `G` = unit vector of
/// `delta`: returns `(A, B, c)`, the solution `X` of `M X = [I + h/2 F | h G | h e]` with
/// `M = I - h/2 F`.
///
/// The solve uses the sparsity of the models' `F` ([`continuous`]): `delta` depends on nothing
/// (its row of `F` is zero), `v_y` and `r` only on themselves and `delta`, and `e_y`, `e_psi` on
/// everything but each other's... so `M` is block triangular: `delta`, then the 2 x 2 block of
/// `(v_y, r)`, then the 2 x 2 block of `(e_y, e_psi)`. Entries of `F` outside that pattern are
/// ignored (the reference test against scipy's `cont2discrete` covers both modes). A block
/// determinant below [`MIN_PIVOT`] (never, for these models: each block is `I - h/2` times a
/// stable 2 x 2 or a nilpotent-plus-small one) or any non-finite result gives `None`.
#[allow(clippy::type_complexity)]
pub fn tustin(
    f: &SMatrix<f32, NX, NX>,
    e: &SVector<f32, NX>,
    h: f32,
) -> Option<(SMatrix<f32, NX, NX>, SVector<f32, NX>, SVector<f32, NX>)> {
    let half = 0.5 * h;
    let fm = |i: usize, j: usize| f.get((i, j)).copied().unwrap_or(0.0) * half;
    // Right-hand side rows [I + h/2 F | h G | h e], 7 wide.
    let rhs = |i: usize| -> [f32; NX + 2] {
        let mut r = [0.0f32; NX + 2];
        for (j, v) in r.iter_mut().enumerate().take(NX) {
            *v = fm(i, j) + if i == j { 1.0 } else { 0.0 };
        }
        if let Some(g) = r.get_mut(NX) {
            *g = if i == DELTA { h } else { 0.0 };
        }
        if let Some(c) = r.get_mut(NX + 1) {
            *c = e.get(i).copied().unwrap_or(0.0) * h;
        }
        r
    };
    // x_delta: its row of M is the unit row.
    let xd = rhs(DELTA);
    // (v_y, r): M_b [x_vy; x_r] = rhs - M[., delta] x_delta, with M = I - h/2 F.
    let (vy_rows, r_rows) = solve2(
        (1.0 - fm(VY, VY), -fm(VY, R), -fm(R, VY), 1.0 - fm(R, R)),
        sub_scaled(rhs(VY), -fm(VY, DELTA), &xd),
        sub_scaled(rhs(R), -fm(R, DELTA), &xd),
    )?;
    // (e_y, e_psi): the rest of their rows moved to the right-hand side.
    let mut ey_rhs = rhs(EY);
    let mut epsi_rhs = rhs(EPSI);
    for (m_ey, m_epsi, x) in [
        (-fm(EY, VY), -fm(EPSI, VY), &vy_rows),
        (-fm(EY, R), -fm(EPSI, R), &r_rows),
        (-fm(EY, DELTA), -fm(EPSI, DELTA), &xd),
    ] {
        ey_rhs = sub_scaled(ey_rhs, m_ey, x);
        epsi_rhs = sub_scaled(epsi_rhs, m_epsi, x);
    }
    let (ey_rows, epsi_rows) = solve2(
        (
            1.0 - fm(EY, EY),
            -fm(EY, EPSI),
            -fm(EPSI, EY),
            1.0 - fm(EPSI, EPSI),
        ),
        ey_rhs,
        epsi_rhs,
    )?;
    let mut a = SMatrix::<f32, NX, NX>::zeros();
    let mut b = SVector::<f32, NX>::zeros();
    let mut c = SVector::<f32, NX>::zeros();
    for (i, row) in [
        (EY, ey_rows),
        (EPSI, epsi_rows),
        (VY, vy_rows),
        (R, r_rows),
        (DELTA, xd),
    ] {
        for (j, v) in row.iter().enumerate().take(NX) {
            if let Some(x) = a.get_mut((i, j)) {
                *x = *v;
            }
        }
        if let (Some(x), Some(v)) = (b.get_mut(i), row.get(NX)) {
            *x = *v;
        }
        if let (Some(x), Some(v)) = (c.get_mut(i), row.get(NX + 1)) {
            *x = *v;
        }
    }
    if a.iter()
        .chain(b.iter())
        .chain(c.iter())
        .all(|v| v.is_finite())
    {
        Some((a, b, c))
    } else {
        None
    }
}

/// `r - m x` element-wise (one block elimination step).
#[inline(always)]
fn sub_scaled(mut r: [f32; NX + 2], m: f32, x: &[f32; NX + 2]) -> [f32; NX + 2] {
    if m != 0.0 {
        for (a, b) in r.iter_mut().zip(x) {
            *a -= m * b;
        }
    }
    r
}

/// Solves `[[m00, m01], [m10, m11]] [x; y] = [r0; r1]` for rows of right-hand sides, by
/// Cramer's rule; `None` if the determinant is below [`MIN_PIVOT`] or not finite.
#[inline(always)]
#[allow(clippy::type_complexity)]
fn solve2(
    (m00, m01, m10, m11): (f32, f32, f32, f32),
    r0: [f32; NX + 2],
    r1: [f32; NX + 2],
) -> Option<([f32; NX + 2], [f32; NX + 2])> {
    let det = m00 * m11 - m01 * m10;
    if !(det.is_finite() && det >= MIN_PIVOT) {
        return None;
    }
    let inv = 1.0 / det;
    let mut x = [0.0f32; NX + 2];
    let mut y = [0.0f32; NX + 2];
    for (((x, y), a), b) in x.iter_mut().zip(y.iter_mut()).zip(&r0).zip(&r1) {
        *x = (m11 * a - m01 * b) * inv;
        *y = (m00 * b - m10 * a) * inv;
    }
    Some((x, y))
}

/// A point of the body in the body frame: `ahead_m` ahead of the rear axle, `right_m` to the
/// right of the centre line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BodyPoint {
    /// Ahead of the rear axle, m.
    pub ahead_m: f32,
    /// Right of the centre line, m.
    pub right_m: f32,
}

/// The lateral offset of a body point from a sample of the path, linearised in `(e_y, e_psi)`
/// about `e_psi = e0`: `offset ~ a e_y + b e_psi + k`. The body pose is the reference pose
/// `at` moved `e_y` to its right and turned by `e_psi`; the offset is measured along the
/// right normal of `sample` (exact geometry at the linearisation point, so a sample further
/// along a curved path is handled without a small-angle assumption between the two).
pub fn body_offset(
    at: &Sample,
    sample: &Sample,
    point: BodyPoint,
    sin_e0: f32,
    cos_e0: f32,
    e0: f32,
) -> (f32, f32, f32) {
    let (sr, cr) = (at.pose.sin_heading, at.pose.cos_heading);
    let (ss, cs) = (sample.pose.sin_heading, sample.pose.cos_heading);
    // Right normal of the sample: (cos, -sin); of the reference: likewise.
    let n_dot = cr * cs + sr * ss;
    // Body heading theta = psi_r + e0: t = (sin, cos), n = (cos, -sin).
    let st = sr * cos_e0 + cr * sin_e0;
    let ct = cr * cos_e0 - sr * sin_e0;
    let (s, l) = (point.ahead_m, point.right_m);
    // Body-frame vector in the world: s t + l n.
    let wx = s * st + l * ct;
    let wy = s * ct - l * st;
    // Its derivative in theta: s n - l t.
    let dx = s * ct - l * st;
    let dy = -s * st - l * ct;
    let proj = |x: f32, y: f32| x * cs - y * ss;
    let base = proj(at.pose.x_m - sample.pose.x_m, at.pose.y_m - sample.pose.y_m);
    let b = proj(dx, dy);
    let k = base + proj(wx, wy) - b * e0;
    (n_dot, b, k)
}

/// How far inside a corridor `left_m` + `right_m` wide the corner rows keep a body point
/// `half_width_m` from the centre line: [`Weights::corridor_margin_m`], but never more than
/// half of the room the body has on each side, m.
pub fn corridor_margin_m(w: &Weights, left_m: f32, right_m: f32, half_width_m: f32) -> f32 {
    let room_m = 0.5 * (left_m + right_m) - half_width_m;
    math::min(w.corridor_margin_m, math::max(0.5 * room_m, 0.0))
}

/// A corridor row for a point of the body's side: `lower <= offset` (left side) or
/// `offset <= upper` (right side).
fn corner_row(
    at: &Sample,
    sample: &Sample,
    point: BodyPoint,
    lin: (f32, f32, f32),
    w: &Weights,
) -> Row {
    let (s0, c0, e0) = lin;
    let (a, b, k) = body_offset(at, sample, point, s0, c0, e0);
    let margin_m = corridor_margin_m(w, sample.left_m, sample.right_m, point.right_m.abs());
    let (lower, upper) = if point.right_m < 0.0 {
        (-(sample.left_m - margin_m) - k, f32::INFINITY)
    } else {
        (f32::NEG_INFINITY, sample.right_m - margin_m - k)
    };
    Row {
        a,
        b,
        lower,
        upper,
        rho: w.rho_corridor,
        soft_weight: w.corridor_weight_per_m,
        active: lower.is_finite() || upper.is_finite(),
    }
}

/// Relaxes the corridor rows of a plan whose car starts outside them (`x0` violates stage 0's
/// row): each row's bound gives way by the start's violation, tapering to none along a quintic
/// smoothstep over the time a return at `return_mps2` of lateral acceleration takes,
/// `2 sqrt(violation / return_mps2)` (a bang-bang return's duration; the smoothstep's peak is
/// 1.44 times that acceleration), or longer where that return's fastest lateral speed would
/// ask more heading than `heading_rad` at the speed the car has, `speed_mps` (at least 1 m/s),
/// as [`taper_reference`]'s. Without it the exact penalty, far above the tracking cost, asks
/// for the return within the first steps whatever it costs: from 2 m outside the hatchback's
/// corridor the plan steered to the lock and the car overshot the path by 4.5 m
/// (docs/controller.md, "Starting outside the corridor"). Without the heading's bound a car
/// that had braked to 1.4 m/s 2.6 m outside its corridor was asked for the whole return within
/// 3.2 s: it steered to the lock, sped up with 0.84 rad of heading and swung 3.8 m through the
/// path (docs/controller.md, "A lost position"). A car inside its corridor is not affected.
/// Returns the largest violation at the start, m.
pub fn relax_corridor(
    problem: &mut Problem<NX, STEPS, ROWS>,
    x0: &SVector<f32, NX>,
    (return_mps2, speed_mps, heading_rad): (f32, f32, f32),
    stage: &StageClock,
) -> f32 {
    let Some(first) = problem.stages.first() else {
        return 0.0;
    };
    let mut start = [0.0f32; ROW_OBSTACLE];
    for (v, row) in start.iter_mut().zip(&first.rows) {
        if row.active {
            *v = row.violation(row.eval(x0));
        }
    }
    let worst = start.iter().copied().fold(0.0, max);
    if worst <= 0.0 {
        return 0.0;
    }
    // Per row: the start's violation and the inverse of the return's duration.
    let lateral_mps = return_lateral_mps(speed_mps, heading_rad);
    let mut taper = [(0.0f32, 0.0f32); ROW_OBSTACLE];
    for (t, v) in taper.iter_mut().zip(start) {
        if v > 0.0 {
            *t = (v, return_rate(v, return_mps2, lateral_mps));
        }
    }
    for (k, st) in problem.stages.iter_mut().enumerate() {
        let t = stage.time_s(k + 1);
        for (row, (v, rate)) in st.rows.iter_mut().zip(taper) {
            if !(row.active && v > 0.0) {
                continue;
            }
            let give = v * return_ahead(t, rate).0;
            row.lower -= give;
            row.upper += give;
        }
    }
    worst
}

/// The smoothstep's fastest rate of change, in units of its span per its duration (at the
/// midpoint: `30 u^2 (1 - u)^2` at `u = 1/2`).
const RETURN_PEAK_SPEED: f32 = 1.875;

/// The inverse of the duration of a return over `distance_m` at `accel_mps2`: a bang-bang
/// return's `2 sqrt(distance / accel)` (the smoothstep of [`return_ahead`] peaks at 1.44 times
/// that acceleration), or longer where the smoothstep's fastest lateral speed would exceed
/// `lateral_mps` ([`return_lateral_mps`]).
fn return_rate(distance_m: f32, accel_mps2: f32, lateral_mps: f32) -> f32 {
    math::min(
        0.5 * math::sqrt(accel_mps2 / distance_m),
        lateral_mps / (RETURN_PEAK_SPEED * distance_m),
    )
}

/// The fastest lateral speed a return may ask of a car at `speed_mps` (at least 1 m/s) with
/// `heading_rad` of heading: `v sin h`.
fn return_lateral_mps(speed_mps: f32, heading_rad: f32) -> f32 {
    let (sin_heading, _) = math::sin_cos(heading_rad);
    max(speed_mps, 1.0) * sin_heading
}

/// The share of a return still ahead at time `t_s` along the quintic smoothstep `10 u^3 -
/// 15 u^4 + 6 u^5` of `u = t rate` (zero slope and curvature at both ends), and its rate of
/// change, 1/s.
fn return_ahead(t_s: f32, rate: f32) -> (f32, f32) {
    let u = clamp(t_s * rate, 0.0, 1.0);
    (
        1.0 - u * u * u * (10.0 + u * (-15.0 + 6.0 * u)),
        -30.0 * u * u * (1.0 - u) * (1.0 - u) * rate,
    )
}

/// Tapers the tracking cost's target for a car that starts far off its path: of the start's
/// lateral error, the part beyond `from_m` is returned along the same quintic smoothstep as
/// [`relax_corridor`] over `2 sqrt(part / return_mps2)`, or longer where that return's fastest
/// lateral speed (1.875 part / duration, the smoothstep's peak) would ask more heading than
/// `heading_rad` at the speed the car has (at least 1 m/s), with the heading error that return
/// needs at each stage's speed (`d e_y / dt = v sin e_psi`, to first order; at least 1 m/s, at
/// most 0.5 rad) as the heading's target. The costs' linear terms get the targets (`q_lin =
/// -q_diag x_ref`, as the steering's feed-forward). Within `from_m` of the path nothing
/// changes. Without it the (then 1.5 s) horizon asks for the whole return at once and does
/// not see the far side: the van taken over 3.6 m beside its path went 4.9 m through it
/// (docs/controller.md, "Starting outside the corridor"). The heading bound is for a car that
/// is slow when it starts back: a long car braked to 2 m/s 3.4 m beside its path was asked for
/// the whole return within 3 s, steered to 90 % of its lock, sped up with 0.6 rad of heading
/// and swung 3.9 m through the path, off the road (docs/findings.md). Returns the part
/// returned along the taper, m.
pub fn taper_reference(
    problem: &mut Problem<NX, STEPS, ROWS>,
    x0: &SVector<f32, NX>,
    speeds_mps: &[f32; STEPS + 1],
    stage: &StageClock,
    return_mps2: f32,
    from_m: f32,
    heading_rad: f32,
) -> f32 {
    let e0 = x0.get(EY).copied().unwrap_or(0.0);
    let size = if e0 < 0.0 { -e0 } else { e0 };
    let part = max(size - from_m, 0.0);
    if !part.is_finite() || part <= 0.0 {
        return 0.0;
    }
    let rate = return_rate(
        part,
        return_mps2,
        return_lateral_mps(speeds_mps.first().copied().unwrap_or(0.0), heading_rad),
    );
    let part = if e0 < 0.0 { -part } else { part };
    for (k, st) in problem.stages.iter_mut().enumerate() {
        let (ahead, d_ahead) = return_ahead(stage.time_s(k + 1), rate);
        let e_y = part * ahead;
        let de_y = part * d_ahead;
        let v = max(speeds_mps.get(k + 1).copied().unwrap_or(0.0), 1.0);
        let e_psi = clamp(de_y / v, -0.5, 0.5);
        for (i, target) in [(EY, e_y), (EPSI, e_psi)] {
            if let (Some(l), Some(q)) = (st.q_lin.get_mut(i), st.q_diag.get(i)) {
                *l = -q * target;
            }
        }
    }
    part
}

/// How hard an object on the road may brake, m/s^2: a car's full braking on dry asphalt, about
/// 1 g (a tyre's friction coefficient of 0.9 to 1.0). A moving obstacle is planned around
/// wherever it can be at each stage, from where it would be had it braked at this from now to
/// where it will be at its measured velocity ([`InflatedObstacle::braked_s`]): its velocity
/// is measured over half a second and more (`control::planner::ObstacleMotion`), so a car
/// ahead that brakes is seen late, and a plan that passes it where it would have gone on
/// passes it closer than its margin (docs/bus.md, "Obstacles that move").
pub const OBSTACLE_BRAKE_MPS2: f32 = 10.0;

/// One obstacle as the rows see it (inflated radius).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InflatedObstacle {
    /// Centre, east, m.
    pub x_m: f32,
    /// Centre, north, m.
    pub y_m: f32,
    /// Radius plus uncertainty plus margin, m.
    pub radius_m: f32,
    /// Where it lies along the path, from the rear axle now, m ([`super::Obstacle::ahead_m`]).
    pub ahead_m: f32,
    /// Its centre's offset from the path there, m ([`super::Obstacle::path_offset_m`]).
    pub path_offset_m: f32,
    /// How it moves.
    pub velocity: ObstacleVelocity,
    /// Its speed, m/s (the velocity's length).
    pub speed_mps: f32,
}

impl InflatedObstacle {
    /// `ob` with its radius inflated to `radius_m`.
    pub fn new(ob: &super::Obstacle, radius_m: f32) -> Self {
        let v = &ob.velocity;
        Self {
            x_m: ob.east_m,
            y_m: ob.north_m,
            radius_m,
            ahead_m: ob.ahead_m,
            path_offset_m: ob.path_offset_m,
            velocity: ob.velocity,
            speed_mps: math::sqrt(v.east_mps * v.east_mps + v.north_mps * v.north_mps),
        }
    }

    /// Where it will be `t_s` from now (moved at its velocity; a standing one is itself).
    pub fn at(&self, t_s: f32) -> Self {
        let v = &self.velocity;
        Self {
            x_m: self.x_m + v.east_mps * t_s,
            y_m: self.y_m + v.north_mps * t_s,
            ahead_m: self.ahead_m + v.along_mps * t_s,
            path_offset_m: self.path_offset_m + v.right_mps * t_s,
            ..*self
        }
    }

    /// The time at which, going on at its velocity, it would be where braking at
    /// [`OBSTACLE_BRAKE_MPS2`] from now brings it in `t_s`: `t - a t^2 / 2 v` until it stops
    /// (`t = v / a`), then `v / 2 a` (its stopping distance over its speed). `t_s` for one
    /// that stands.
    pub fn braked_s(&self, t_s: f32) -> f32 {
        let speed = self.speed_mps;
        let moving = speed > 0.0;
        if !moving {
            return t_s;
        }
        let stop_s = speed / OBSTACLE_BRAKE_MPS2;
        if t_s < stop_s {
            t_s - 0.5 * OBSTACLE_BRAKE_MPS2 * t_s * t_s / speed
        } else {
            0.5 * stop_s
        }
    }
}

/// An end-of-horizon stage's row for an obstacle still ahead of the rear axle there (and at
/// most the preview distance `preview_m` ahead of the body's front): the whole car already
/// beside the obstacle, its centre line at least half the width plus the inflated radius from
/// the obstacle's centre, measured from the path (the obstacle's path offset). The horizon ends
/// before the car reaches the obstacle, and the stage's own geometric row would only ask the
/// front corner to clear it, which a plan can meet by yawing towards the side at the last
/// moment without moving the car aside (measured: such plans steer the wrong way first and
/// leave no room for the rest of the manoeuvre); this terminal condition asks for the
/// displacement the pass will need, early.
/// `horizon_m` is the stage's station ahead of the rear axle now.
pub fn terminal_row(
    at: &Sample,
    obstacle: &InflatedObstacle,
    side: ObstacleSide,
    body: &Body,
    lin: (f32, f32, f32),
    w: &Weights,
    (horizon_m, preview_m): (f32, f32),
) -> Option<Row> {
    let front = body.length_m - body.rear_overhang_m;
    let ahead_of_axle = obstacle.ahead_m - horizon_m;
    if !(ahead_of_axle > 0.0 && ahead_of_axle - front - obstacle.radius_m <= preview_m) {
        return None;
    }
    Some(side_row(
        at,
        body,
        0.0,
        side,
        obstacle.path_offset_m,
        obstacle.radius_m,
        lin,
        w,
    ))
}

/// The row keeping the body's side that faces an obstacle, at the point `ahead_m` ahead of the
/// rear axle, at least `clearance_m` beyond the obstacle's centre line `lateral_m` (offsets
/// from the sample `at`, positive right): at most `lateral - clearance` passing on the left, at
/// least `lateral + clearance` passing on the right.
#[allow(clippy::too_many_arguments)]
fn side_row(
    at: &Sample,
    body: &Body,
    ahead_m: f32,
    side: ObstacleSide,
    lateral_m: f32,
    clearance_m: f32,
    (s0, c0, e0): (f32, f32, f32),
    w: &Weights,
) -> Row {
    let half_width = 0.5 * body.width_m;
    let point = BodyPoint {
        ahead_m,
        right_m: match side {
            // Passing on the left: the obstacle is on the body's right.
            ObstacleSide::Left => half_width,
            ObstacleSide::Right => -half_width,
        },
    };
    let (a, b, k) = body_offset(at, at, point, s0, c0, e0);
    let (lower, upper) = match side {
        ObstacleSide::Left => (f32::NEG_INFINITY, lateral_m - clearance_m - k),
        ObstacleSide::Right => (lateral_m + clearance_m - k, f32::INFINITY),
    };
    Row {
        a,
        b,
        lower,
        upper,
        rho: w.rho_obstacle,
        soft_weight: w.obstacle_weight_per_m,
        active: true,
    }
}

/// The obstacle's half-space at a stage, if the body can reach it there: the side of the body
/// facing it stays beyond its inflated circle. `None` when it is ahead of the front or behind
/// the rear by more than its radius.
///
/// A moving one may be anywhere on the segment from where it is at `near_s` from now to where
/// it is at `far_s` (where it is at the stage had it braked, and going on:
/// [`InflatedObstacle::braked_s`]): the side is kept its inflated radius beyond the segment's
/// point that reaches furthest towards it, over the part of the segment within that radius of
/// the body's length. Beyond the body's ends that is a radius where one circle would ask only
/// its half chord, and a rectangle about the swept circles there: the row takes no square root
/// (a circle's exact reach over a segment took two, 122 instructions a row more than the one
/// circle, and the controller's bound on a long car went over its budget).
#[allow(clippy::too_many_arguments)]
pub fn obstacle_row(
    at: &Sample,
    ob: &InflatedObstacle,
    (near_s, far_s): (f32, f32),
    side: ObstacleSide,
    body: &Body,
    lin: (f32, f32, f32),
    w: &Weights,
) -> Option<Row> {
    let (sr, cr) = (at.pose.sin_heading, at.pose.cos_heading);
    let (dx, dy) = (ob.x_m - at.pose.x_m, ob.y_m - at.pose.y_m);
    let (along_now, lateral_now) = (dx * sr + dy * cr, dx * cr - dy * sr);
    let rear = -body.rear_overhang_m;
    let front = body.length_m - body.rear_overhang_m;
    let r = ob.radius_m;
    if far_s == near_s {
        // One circle (one that stands): the nearest point of the side line, and how far the
        // centre lies beyond the body's end: there the circle only reaches the side line
        // within its half chord.
        let (along, lateral) = (along_now, lateral_now);
        if !(along > rear - r && along < front + r) {
            return None;
        }
        let ahead = clamp(along, rear, front);
        let beyond = along - ahead;
        let half_chord = math::sqrt(max(r * r - beyond * beyond, 0.0));
        return Some(side_row(at, body, ahead, side, lateral, half_chord, lin, w));
    }
    // The segment, along and across the stage's heading.
    let v = &ob.velocity;
    let (along_mps, lateral_mps) = (
        v.east_mps * sr + v.north_mps * cr,
        v.east_mps * cr - v.north_mps * sr,
    );
    let (along0, lateral0) = (
        along_now + along_mps * near_s,
        lateral_now + lateral_mps * near_s,
    );
    let d_s = far_s - near_s;
    let (d_along, d_lateral) = (along_mps * d_s, lateral_mps * d_s);
    // Its part within the radius of the body's length: the parameter range (0 at `near_s`,
    // 1 at `far_s`) over which its along lies between the rear less the radius and the front
    // plus it.
    let (lo, hi) = if d_along == 0.0 {
        if !(along0 > rear - r && along0 < front + r) {
            return None;
        }
        (0.0, 1.0)
    } else {
        let s_rear = (rear - r - along0) / d_along;
        let s_front = (front + r - along0) / d_along;
        (
            max(math::min(s_rear, s_front), 0.0),
            math::min(max(s_rear, s_front), 1.0),
        )
    };
    let reaches = lo < hi;
    if !reaches {
        return None;
    }
    // The lateral is linear along it: its end towards the side reaches furthest.
    let towards = match side {
        ObstacleSide::Left => d_lateral < 0.0,
        ObstacleSide::Right => d_lateral > 0.0,
    };
    let s = if towards { hi } else { lo };
    let ahead = clamp(along0 + s * d_along, rear, front);
    Some(side_row(
        at,
        body,
        ahead,
        side,
        lateral0 + s * d_lateral,
        r,
        lin,
        w,
    ))
}

/// Stages at the end of the horizon that get [`terminal_row`]s (the last 0.5 s): the car is to
/// be beside an obstacle ahead by then, not only at the very end, which measured plans
/// otherwise postponed until the manoeuvre no longer fitted.
pub const TERMINAL_STAGES: usize = 5;

/// The row keeping the heading error within `limit_rad` either way, in an obstacle slot that
/// no obstacle row takes at its stage ([`build`]). The stages' stations advance along the path
/// at the planned speed; a car turned far from the path does not, and without a bound a plan
/// could "pass" an obstacle by turning a short car 90 degrees in its horizon's last second:
/// measured on a car of 1.87 m wheelbase at 4 m/s, such plans put the swerve off from tick to
/// tick until it no longer fitted, and the car braked 0.1 m short of the obstacle or hit it
/// (docs/findings.md). Soft, with the obstacles' weight per radian.
pub fn heading_row(limit_rad: f32, w: &Weights) -> Row {
    Row {
        a: 0.0,
        b: 1.0,
        lower: -limit_rad,
        upper: limit_rad,
        rho: w.rho_obstacle,
        soft_weight: w.obstacle_weight_per_m,
        active: true,
    }
}

/// Which rows of the obstacles' slots [`build`] filled with what, per stage: a bit per slot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SlotMasks {
    /// The slot's row is a [`terminal_row`].
    pub terminal: [u8; STEPS],
    /// The slot's row is a [`heading_row`] (no obstacle's).
    pub heading: [u8; STEPS],
}

/// Fills `problem` for this solve. `obstacles[i]` with its chosen side (or `None`);
/// `preview_m`: how far beyond a stage's body front an obstacle still gets that stage's
/// [`terminal_row`]; `heading_rad`: the [`heading_row`]'s bound, which a stage gets in its
/// first free obstacle slot while any obstacle is in the problem. Returns which slots hold
/// terminal and heading rows.
pub fn build(
    problem: &mut Problem<NX, STEPS, ROWS>,
    setup: &LateralSetup,
    reference: &[ReferencePoint; STEPS + 1],
    lin: &Linearisation,
    obstacles: &[Option<(InflatedObstacle, ObstacleSide)>; MAX_OBSTACLES],
    (preview_m, heading_rad): (f32, f32),
) -> Result<SlotMasks, BuildError> {
    let mut masks = SlotMasks {
        terminal: [0u8; STEPS],
        heading: [0u8; STEPS],
    };
    let any_obstacle = obstacles.iter().any(Option::is_some);
    let origin = reference.first().map(|r| r.at.pose);
    let w = setup.weights;
    let body = setup.body;
    let understeer = match setup.dynamics.filter(|_| setup.mode == Mode::Dynamic) {
        None => setup.vehicle.understeer_s2_per_m2,
        Some(d) => d.understeer_s2_per_m2(),
    };
    let half_width = 0.5 * body.width_m;
    problem.r = w.steer_rate;
    problem.u_rho = w.rho_steer_rate;
    problem.box_state = DELTA;
    problem.box_rho = w.rho_steer;
    for (k, st) in problem.stages.iter_mut().enumerate() {
        let (Some(r0), Some(r1)) = (reference.get(k), reference.get(k + 1)) else {
            continue;
        };
        let v0 = setup.speeds_mps.get(k).copied().unwrap_or(0.0);
        let v1 = setup.speeds_mps.get(k + 1).copied().unwrap_or(v0);
        let e_a = lin.e_psi.get(k).copied().unwrap_or(0.0);
        let e_b = lin.e_psi.get(k + 1).copied().unwrap_or(e_a);
        let d_a = lin.delta.get(k).copied().unwrap_or(0.0);
        let d_b = lin.delta.get(k + 1).copied().unwrap_or(d_a);
        let v = 0.5 * (v0 + v1);
        let kappa = 0.5 * (r0.curvature_per_m + r1.curvature_per_m);
        let (f, e) = continuous(setup, v, kappa, 0.5 * (e_a + e_b), 0.5 * (d_a + d_b));
        let h = setup.stage.stage_s(k);
        let (ad, bd, cd) = tustin(&f, &e, h).ok_or(BuildError::Discretisation)?;
        st.a = ad;
        st.b = bd;
        st.c = cd;
        // Cost of x_{k+1}: offsets and heading error to zero, steering near the feedforward;
        // weighed by the stage's length (a longer stage stands for more of the horizon).
        let terminal = if k + 1 == STEPS {
            w.terminal_factor
        } else {
            1.0
        } * (h / super::STEP_S);
        let ff = feedforward_steer_rad(
            setup.vehicle.wheelbase_m,
            understeer,
            v1,
            r1.curvature_per_m,
        );
        st.q_diag = SVector::<f32, NX>::from([
            w.lateral_per_m2,
            w.heading_per_rad2,
            w.lateral_speed_per_mps2,
            w.yaw_rate_per_rps2,
            w.steer_per_rad2,
        ]) * terminal;
        st.q_lin = SVector::<f32, NX>::zeros();
        if let Some(x) = st.q_lin.get_mut(DELTA) {
            *x = -w.steer_per_rad2 * terminal * ff;
        }
        st.r_lin = 0.0;
        st.u_lower = -setup.max_steer_rate_rad_per_s;
        st.u_upper = setup.max_steer_rate_rad_per_s;
        // Rows of x_{k+1}.
        let (s0, c0) = math::sin_cos_inlined(e_b);
        let lin_b = (s0, c0, e_b);
        st.rows = [Row::INACTIVE; ROWS];
        st.box_lower = -setup.max_steer_rad;
        st.box_upper = setup.max_steer_rad;
        let sides = [
            (ROW_FRONT_LEFT, &r1.front_left, -half_width),
            (ROW_FRONT_RIGHT, &r1.front_right, half_width),
            (ROW_REAR_LEFT, &r1.rear_left, -half_width),
            (ROW_REAR_RIGHT, &r1.rear_right, half_width),
        ];
        for (slot, side, right_m) in sides {
            let point = BodyPoint {
                ahead_m: side.ahead_m,
                right_m,
            };
            if let Some(row) = st.rows.get_mut(slot) {
                *row = corner_row(&r1.at, &side.sample, point, lin_b, w);
            }
        }
        let end = k + TERMINAL_STAGES >= STEPS;
        // The stage's station ahead of the rear axle now (chord along the first heading).
        let station_m = origin.map_or(0.0, |o| {
            (r1.at.pose.x_m - o.x_m) * o.sin_heading + (r1.at.pose.y_m - o.y_m) * o.cos_heading
        });
        // x_{k+1}'s time: each obstacle where it will be then.
        let t_s = setup.stage.time_s(k + 1);
        for (i, ob) in obstacles.iter().enumerate() {
            let Some((ob, side)) = ob else { continue };
            // Where it will be then going on, and where it would be had it braked from now:
            // the terminal row asks the car beside the nearer.
            let near_s = ob.braked_s(t_s);
            let terminal = end
                .then(|| {
                    let near = &ob.at(near_s);
                    terminal_row(&r1.at, near, *side, body, lin_b, w, (station_m, preview_m))
                })
                .flatten();
            if terminal.is_some() {
                if let Some(m) = masks.terminal.get_mut(k) {
                    *m |= 1 << i;
                }
            }
            let row =
                terminal.or_else(|| obstacle_row(&r1.at, ob, (near_s, t_s), *side, body, lin_b, w));
            if let (Some(slot), Some(r)) = (st.rows.get_mut(ROW_OBSTACLE + i), row) {
                *slot = r;
            }
        }
        // Only where the last plan came within half of the bound: a row that does not bind
        // still changes the iterations' path (its penalty joins the heading's cost), and the
        // plans of cars that never come near it stay what they were.
        let near_bound = e_b > 0.5 * heading_rad || e_b < -0.5 * heading_rad;
        if any_obstacle && near_bound {
            let free = st.rows.iter().skip(ROW_OBSTACLE).position(|r| !r.active);
            if let (Some(i), Some(m)) = (free, masks.heading.get_mut(k)) {
                if let Some(slot) = st.rows.get_mut(ROW_OBSTACLE + i) {
                    *slot = heading_row(heading_rad, w);
                    *m |= 1 << i;
                }
            }
        }
    }
    Ok(masks)
}
