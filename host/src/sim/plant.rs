//! The plant: a nonlinear single-track (bicycle) vehicle with magic-formula tyres, longitudinal
//! load transfer and driving resistances, integrated with classical RK4 at a fixed step.
//!
//! Frame: x east, y north (m); heading psi clockwise from north; body axes forward and *right*,
//! so steering delta, lateral speed v_y and yaw rate r are all positive for a right turn. This is
//! the mirror image of the ISO (left-positive) frame, and the usual single-track equations hold
//! unchanged:
//! ```text
//! m (dv_x/dt - v_y r) = F_xf cos d - F_yf sin d + F_xr - F_res
//! m (dv_y/dt + v_x r) = F_xf sin d + F_yf cos d + F_yr
//! I_z dr/dt           = a (F_xf sin d + F_yf cos d) - b F_yr
//! dx/dt = v_x sin psi + v_y cos psi,  dy/dt = v_x cos psi - v_y sin psi,  dpsi/dt = r
//! alpha_f = d - atan2(v_y + a r, v_x),  alpha_r = -atan2(v_y - b r, v_x)
//! ```
//! Low speed: the tyre slip angles are meaningless as v_x -> 0, so below `BLEND_HI_MPS` the lateral
//! states are blended towards the kinematic (no-slip) values r = v_x tan(d) / L, v_y = b r, fully
//! kinematic below `BLEND_LO_MPS`. Standstill: brake and rolling resistance act as static
//! friction at v_x = 0, so the car stops and stays stopped, never reverses.
//!
//! Why RK4 at 1 ms: the fastest mode is the lateral tyre mode, time constant about
//! m v_x / (C_f + C_r) = 5 ms at 0.5 m/s (where the blend weight is still small), well inside
//! RK4's stability region at h = 1 ms (|h lambda| <= 0.2 < 2.8); RK4's O(h^4) error keeps
//! integration error far below every effect the tests look at (the steady-state radius check
//! sees < 1e-6 relative), at 4 derivative evaluations per step (measured cost in the README).
use super::config::VehicleConfig;

/// Fully kinematic below this longitudinal speed, m/s.
pub const BLEND_LO_MPS: f64 = 0.5;
/// Fully dynamic above this longitudinal speed, m/s.
pub const BLEND_HI_MPS: f64 = 1.5;
/// Time constant with which the lateral states follow the kinematic values at low speed, s.
const KINEMATIC_RELAXATION_S: f64 = 0.02;
const GRAVITY_MPS2: f64 = 9.80665;

/// The plant state (CG motion).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlantState {
    /// CG position east of the origin, m.
    pub x_m: f64,
    /// CG position north of the origin, m.
    pub y_m: f64,
    /// Heading, clockwise from north, rad (unwrapped).
    pub heading_rad: f64,
    /// Longitudinal speed, m/s (>= 0).
    pub vx_mps: f64,
    /// Lateral speed at the CG, positive to the right, m/s.
    pub vy_mps: f64,
    /// Yaw rate, positive clockwise (right turn), rad/s.
    pub yaw_rate_rps: f64,
}

/// Inputs held constant over one integration step.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlantInput {
    /// Front (single-track) wheel angle, rad, positive right.
    pub steer_rad: f64,
    /// Drive force at the front wheels (front-wheel drive), N, >= 0.
    pub drive_force_n: f64,
    /// Total brake force available, N, >= 0 (acts against motion; static at standstill).
    pub brake_force_n: f64,
}

/// Precomputed plant coefficients.
#[derive(Debug, Clone)]
pub struct Plant {
    mass_kg: f64,
    inertia_kg_m2: f64,
    a_m: f64,
    b_m: f64,
    wheelbase_m: f64,
    cg_height_m: f64,
    brake_front_share: f64,
    fz_front_static_n: f64,
    fz_rear_static_n: f64,
    front: MagicFormula,
    rear: MagicFormula,
    rolling_n: f64,
    drag_n_per_mps2: f64,
}

#[derive(Debug, Clone, Copy)]
struct MagicFormula {
    b_per_rad: f64,
    c: f64,
    e: f64,
    mu: f64,
}

impl MagicFormula {
    /// Lateral force for slip angle `alpha` under normal load `fz`, with the friction ellipse
    /// reducing the peak when the axle also carries longitudinal force `fx`.
    fn lateral_force_n(&self, alpha_rad: f64, fz_n: f64, fx_n: f64) -> f64 {
        let peak = self.mu * fz_n;
        let d = libm::sqrt((peak * peak - fx_n * fx_n).max(0.01 * peak * peak));
        let ba = self.b_per_rad * alpha_rad;
        d * libm::sin(self.c * libm::atan(ba - self.e * (ba - libm::atan(ba))))
    }
}

impl Plant {
    /// Coefficients from a (validated) vehicle configuration.
    pub fn new(cfg: &VehicleConfig) -> Self {
        let c = &cfg.chassis;
        let g = GRAVITY_MPS2;
        let fz_front = c.mass_kg * g * c.cg_to_rear_m / c.wheelbase_m;
        let fz_rear = c.mass_kg * g * c.cg_to_front_m / c.wheelbase_m;
        let mf = |t: &super::config::Tyre, fz: f64| MagicFormula {
            b_per_rad: t.cornering_stiffness_n_per_rad / (t.shape_c * t.friction_mu * fz),
            c: t.shape_c,
            e: t.curvature_e,
            mu: t.friction_mu,
        };
        Self {
            mass_kg: c.mass_kg,
            inertia_kg_m2: c.yaw_inertia_kg_m2,
            a_m: c.cg_to_front_m,
            b_m: c.cg_to_rear_m,
            wheelbase_m: c.wheelbase_m,
            cg_height_m: c.cg_height_m,
            brake_front_share: c.brake_front_share,
            fz_front_static_n: fz_front,
            fz_rear_static_n: fz_rear,
            front: mf(&cfg.tyre_front, fz_front),
            rear: mf(&cfg.tyre_rear, fz_rear),
            rolling_n: cfg.resistance.rolling_coefficient * c.mass_kg * g,
            drag_n_per_mps2: 0.5 * cfg.resistance.air_density_kg_m3 * cfg.resistance.drag_area_m2,
        }
    }

    /// Distance CG -> rear axle, m.
    pub fn cg_to_rear_m(&self) -> f64 {
        self.b_m
    }

    /// State derivative. `ax_mps2` is the longitudinal acceleration used for load transfer
    /// (the previous step's, which breaks the algebraic loop Fz <- a_x <- Fx(Fz)).
    fn derivative(&self, s: &[f64; 6], u: &Trig, ax_mps2: f64) -> [f64; 6] {
        let [_, _, psi, vx_raw, vy, r] = *s;
        let vx = vx_raw.max(0.0);
        let (s_psi, c_psi) = u.sin_cos_heading(psi);
        let dx = vx * s_psi + vy * c_psi;
        let dy = vx * c_psi - vy * s_psi;

        // Longitudinal forces. Brake and rolling resistance oppose motion; at standstill they
        // are static friction and only let the car move forward if the drive overcomes them.
        let brake_f = u.brake_n * self.brake_front_share;
        let brake_r = u.brake_n - brake_f;
        let drag = self.drag_n_per_mps2 * vx * vx;
        let moving = vx_raw > 0.0;

        // Load transfer, clamped so that an axle never loses more than 90 % of its load.
        let shift = self.mass_kg * ax_mps2 * self.cg_height_m / self.wheelbase_m;
        let fz_f = (self.fz_front_static_n - shift).max(0.1 * self.fz_front_static_n);
        let fz_r = (self.fz_rear_static_n + shift).max(0.1 * self.fz_rear_static_n);

        let weight = ((vx - BLEND_LO_MPS) / (BLEND_HI_MPS - BLEND_LO_MPS)).clamp(0.0, 1.0);

        let (fxf, fxr) = if moving {
            (
                u.drive_n - brake_f - self.rolling_n * fz_f / (fz_f + fz_r),
                -brake_r - self.rolling_n * fz_r / (fz_f + fz_r),
            )
        } else {
            // At rest: only a net forward push moves the car.
            let net = u.drive_n - u.brake_n - self.rolling_n;
            (net.max(0.0), 0.0)
        };

        let (fyf, fyr) = if weight > 0.0 {
            let alpha_f = u.steer - libm::atan2(vy + self.a_m * r, vx);
            let alpha_r = -libm::atan2(vy - self.b_m * r, vx);
            (
                self.front.lateral_force_n(alpha_f, fz_f, fxf),
                self.rear.lateral_force_n(alpha_r, fz_r, fxr),
            )
        } else {
            (0.0, 0.0)
        };

        let long = fxf * u.cos - fyf * u.sin + fxr - drag;
        let mut dvx = long / self.mass_kg + vy * r;
        if !moving && dvx < 0.0 {
            dvx = 0.0;
        }
        let lat_f = fxf * u.sin + fyf * u.cos;
        let dvy_dyn = (lat_f + fyr) / self.mass_kg - vx * r;
        let dr_dyn = (self.a_m * lat_f - self.b_m * fyr) / self.inertia_kg_m2;

        // Kinematic (no-slip) lateral states and the relaxation towards them.
        let r_kin = vx * u.tan / self.wheelbase_m;
        let vy_kin = self.b_m * r_kin;
        let dvy_kin = (vy_kin - vy) / KINEMATIC_RELAXATION_S;
        let dr_kin = (r_kin - r) / KINEMATIC_RELAXATION_S;

        [
            dx,
            dy,
            r,
            dvx,
            weight * dvy_dyn + (1.0 - weight) * dvy_kin,
            weight * dr_dyn + (1.0 - weight) * dr_kin,
        ]
    }

    /// Advances `state` by `dt_s` with RK4, inputs held; returns the longitudinal acceleration
    /// over the step (for the next step's load transfer). Speed never goes below zero.
    pub fn step(&self, state: &mut PlantState, input: &PlantInput, ax_mps2: f64, dt_s: f64) -> f64 {
        let trig = Trig {
            heading0: state.heading_rad,
            sin_heading0: libm::sin(state.heading_rad),
            cos_heading0: libm::cos(state.heading_rad),
            steer: input.steer_rad,
            sin: libm::sin(input.steer_rad),
            cos: libm::cos(input.steer_rad),
            tan: libm::tan(input.steer_rad),
            drive_n: input.drive_force_n.max(0.0),
            brake_n: input.brake_force_n.max(0.0),
        };
        let s0 = [
            state.x_m,
            state.y_m,
            state.heading_rad,
            state.vx_mps,
            state.vy_mps,
            state.yaw_rate_rps,
        ];
        let add = |a: &[f64; 6], k: &[f64; 6], h: f64| {
            let mut out = *a;
            for (o, d) in out.iter_mut().zip(k) {
                *o += h * d;
            }
            out
        };
        let k1 = self.derivative(&s0, &trig, ax_mps2);
        let k2 = self.derivative(&add(&s0, &k1, 0.5 * dt_s), &trig, ax_mps2);
        let k3 = self.derivative(&add(&s0, &k2, 0.5 * dt_s), &trig, ax_mps2);
        let k4 = self.derivative(&add(&s0, &k3, dt_s), &trig, ax_mps2);
        let mut s1 = s0;
        for (i, v) in s1.iter_mut().enumerate() {
            *v += dt_s / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        let vx_before = state.vx_mps;
        *state = PlantState {
            x_m: s1[0],
            y_m: s1[1],
            heading_rad: s1[2],
            vx_mps: s1[3],
            vy_mps: s1[4],
            yaw_rate_rps: s1[5],
        };
        if state.vx_mps <= 0.0 {
            // Stopped within this step: clamp (no reversing), no residual sideways motion.
            *state = PlantState {
                vx_mps: 0.0,
                vy_mps: 0.0,
                yaw_rate_rps: 0.0,
                ..*state
            };
        }
        (state.vx_mps - vx_before) / dt_s
    }
}

struct Trig {
    /// Heading at the start of the step and its sine and cosine: the RK4 stages only move it by
    /// |h r| <= a few mrad, so the stage values come from the angle-addition formula with a
    /// Taylor series of the small increment (error < d^7/5040, far below rounding), which
    /// saves most of the trigonometry of a step.
    heading0: f64,
    sin_heading0: f64,
    cos_heading0: f64,
    steer: f64,
    sin: f64,
    cos: f64,
    tan: f64,
    drive_n: f64,
    brake_n: f64,
}

impl Trig {
    fn sin_cos_heading(&self, heading: f64) -> (f64, f64) {
        let d = heading - self.heading0;
        if d.abs() > 0.05 {
            return (libm::sin(heading), libm::cos(heading));
        }
        let d2 = d * d;
        let sin_d = d * (1.0 - d2 / 6.0 * (1.0 - d2 / 20.0 * (1.0 - d2 / 42.0)));
        let cos_d = 1.0 - d2 / 2.0 * (1.0 - d2 / 12.0 * (1.0 - d2 / 30.0));
        (
            self.sin_heading0 * cos_d + self.cos_heading0 * sin_d,
            self.cos_heading0 * cos_d - self.sin_heading0 * sin_d,
        )
    }
}
