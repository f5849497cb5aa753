//! A closed loop for the controller's tests: the host simulator's plant (single-track,
//! magic-formula tyres, RK4 at 1 ms) and the car's own steering actuator (rate limit + lag) and
//! speed controller (delay, PI, limits, lag), driven by `control::mpc` every 20 ms with the
//! plant's state as the measurement (plus an optional position error: a constant bias and
//! white noise, the node's estimate error in two lines). The path, its corridor and the
//! reference the controller reads are built here from a function of the station.
//!
//! This is the controller's test bench, not the product's closed-loop simulator (that one runs
//! the whole node over the bus).
use catmodel::control::mpc::{
    CarState, MpcConfig, MpcInput, MpcOutput, MpcState, MpcTuning, Obstacle, ObstacleVelocity,
    ReferencePoint, Sample, SidePoint, StageClock, MAX_OBSTACLES, PLAN_STEPS, STEPS,
};
use catmodel::model::dynamic::LateralState;
use catmodel::model::hybrid::{HybridConfig, HybridState};
use catmodel::model::kinematic::Pose;
use catmodel::model::{paper, SsBlock, SsBlockState};
use catmodel::vehicle::{Body, VehicleParams};
use catmodel_host::sim::config::VehicleConfig;
use catmodel_host::sim::controller::{SpeedController, SteeringActuator};
use catmodel_host::sim::plant::{Plant, PlantInput, PlantState};

/// Path resolution, m.
pub const PATH_STEP_M: f64 = 0.05;

/// A path sampled every [`PATH_STEP_M`], with its corridor and target speed.
pub struct TestPath {
    x: Vec<f64>,
    y: Vec<f64>,
    heading: Vec<f64>,
    curvature: Vec<f64>,
    left: Vec<f64>,
    right: Vec<f64>,
    speed: Vec<f64>,
}

/// Heading clockwise from north of the vector (dx east, dy north).
fn heading_of(dx: f64, dy: f64) -> f64 {
    dx.atan2(dy)
}

fn wrap(a: f64) -> f64 {
    let mut a = a % (2.0 * std::f64::consts::PI);
    if a > std::f64::consts::PI {
        a -= 2.0 * std::f64::consts::PI;
    }
    if a < -std::f64::consts::PI {
        a += 2.0 * std::f64::consts::PI;
    }
    a
}

impl TestPath {
    /// `point(s)` gives (east, north) at arc length s (approximately; the path is re-measured),
    /// `corridor(s)` (left, right) and `speed(s)`.
    pub fn new(
        length_m: f64,
        point: impl Fn(f64) -> (f64, f64),
        corridor: impl Fn(f64) -> (f64, f64),
        speed: impl Fn(f64) -> f64,
    ) -> Self {
        let n = (length_m / PATH_STEP_M).round() as usize + 1;
        let pts: Vec<(f64, f64)> = (0..n).map(|i| point(i as f64 * PATH_STEP_M)).collect();
        let mut heading = Vec::with_capacity(n);
        for i in 0..n {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
            heading.push(heading_of(pts[b].0 - pts[a].0, pts[b].1 - pts[a].1));
        }
        let mut curvature = Vec::with_capacity(n);
        for i in 0..n {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
            let ds = ((b - a) as f64) * PATH_STEP_M;
            curvature.push(if ds > 0.0 {
                wrap(heading[b] - heading[a]) / ds
            } else {
                0.0
            });
        }
        let (left, right): (Vec<f64>, Vec<f64>) =
            (0..n).map(|i| corridor(i as f64 * PATH_STEP_M)).unzip();
        Self {
            x: pts.iter().map(|p| p.0).collect(),
            y: pts.iter().map(|p| p.1).collect(),
            heading,
            curvature,
            left,
            right,
            speed: (0..n).map(|i| speed(i as f64 * PATH_STEP_M)).collect(),
        }
    }

    /// Length, m.
    pub fn length_m(&self) -> f64 {
        (self.x.len() - 1) as f64 * PATH_STEP_M
    }

    fn index(&self, s: f64) -> (usize, f64) {
        let f = (s / PATH_STEP_M).clamp(0.0, (self.x.len() - 1) as f64);
        let i = (f.floor() as usize).min(self.x.len() - 2);
        (i, f - i as f64)
    }

    fn lerp(v: &[f64], i: usize, t: f64) -> f64 {
        v[i] + (v[i + 1] - v[i]) * t
    }

    /// Pose on the path at station `s` (extrapolated along the end tangents beyond the ends).
    pub fn pose(&self, s: f64) -> (f64, f64, f64) {
        let len = self.length_m();
        if s > len || s < 0.0 {
            let (end, extra) = if s > len {
                (self.x.len() - 1, s - len)
            } else {
                (0, s)
            };
            let h = self.heading[end];
            return (
                self.x[end] + extra * h.sin(),
                self.y[end] + extra * h.cos(),
                h,
            );
        }
        let (i, t) = self.index(s);
        let h = self.heading[i] + wrap(self.heading[i + 1] - self.heading[i]) * t;
        (
            Self::lerp(&self.x, i, t),
            Self::lerp(&self.y, i, t),
            wrap(h),
        )
    }

    /// Curvature at `s`, 1/m.
    pub fn curvature(&self, s: f64) -> f64 {
        let (i, t) = self.index(s);
        Self::lerp(&self.curvature, i, t)
    }

    /// Target speed at `s`.
    pub fn speed(&self, s: f64) -> f64 {
        let (i, _) = self.index(s);
        self.speed[i]
    }

    /// Corridor (left, right) at `s`.
    pub fn corridor(&self, s: f64) -> (f64, f64) {
        let (i, _) = self.index(s);
        (self.left[i], self.right[i])
    }

    /// Where the corridor binds a body's sides between the axle at station `axle` and the end
    /// at `end` (the node's rule, `Path::narrowest_corridor`: the narrowest corridor, ties to
    /// the station farther from the axle): ((left width, station), (right width, station)).
    pub fn binding(&self, axle: f64, end: f64) -> ((f64, f64), (f64, f64)) {
        let (ia, _) = self.index(axle.min(end));
        let (ib, _) = self.index(axle.max(end));
        let last = (ib + 1).min(self.x.len() - 1);
        let mut left = (f64::INFINITY, axle);
        let mut right = (f64::INFINITY, axle);
        let indices: Vec<usize> = if end >= axle {
            (ia..=last).collect()
        } else {
            (ia..=last).rev().collect()
        };
        for i in indices {
            let s = (i as f64 * PATH_STEP_M).clamp(axle.min(end), axle.max(end));
            for (best, w) in [(&mut left, self.left[i]), (&mut right, self.right[i])] {
                if w <= best.0 + 0.01 {
                    best.1 = s;
                }
                best.0 = best.0.min(w);
            }
        }
        (left, right)
    }

    /// Station of the point nearest to (x, y), searching around `hint`.
    pub fn project(&self, x: f64, y: f64, hint: f64) -> f64 {
        let (h, _) = self.index(hint);
        let lo = h.saturating_sub(400);
        let hi = (h + 400).min(self.x.len() - 1);
        let mut best = (f64::INFINITY, h);
        for i in lo..=hi {
            let d = (self.x[i] - x).powi(2) + (self.y[i] - y).powi(2);
            if d < best.0 {
                best = (d, i);
            }
        }
        // Refine along the local tangent.
        let i = best.1;
        let h = self.heading[i];
        let along = (x - self.x[i]) * h.sin() + (y - self.y[i]) * h.cos();
        (i as f64 * PATH_STEP_M + along).clamp(0.0, self.length_m())
    }

    /// Station of the point nearest to (x, y) over the whole path.
    pub fn project_anywhere(&self, x: f64, y: f64) -> f64 {
        let mut best = (f64::INFINITY, 0);
        for (i, (px, py)) in self.x.iter().zip(&self.y).enumerate() {
            let d = (px - x).powi(2) + (py - y).powi(2);
            if d < best.0 {
                best = (d, i);
            }
        }
        self.project(x, y, best.1 as f64 * PATH_STEP_M)
    }

    /// Signed lateral offset (right positive) of (x, y) from the path at station `s`.
    pub fn offset(&self, x: f64, y: f64, s: f64) -> f64 {
        let (px, py, h) = self.pose(s);
        (x - px) * h.cos() - (y - py) * h.sin()
    }

    fn sample(&self, s: f64, corridor: (f64, f64)) -> Sample {
        let (x, y, h) = self.pose(s);
        Sample {
            pose: Pose::new(x as f32, y as f32, h as f32),
            left_m: corridor.0 as f32,
            right_m: corridor.1 as f32,
        }
    }

    fn side_point(&self, axle: f64, (_, station): (f64, f64), widths: (f64, f64)) -> SidePoint {
        SidePoint {
            sample: self.sample(station, widths),
            ahead_m: (station - axle) as f32,
        }
    }

    /// An obstacle at (east, north) with radius `r`, placed along the path as the controller
    /// reads it, seen from a rear axle at station `car_station`.
    pub fn place(&self, east: f64, north: f64, r: f64, car_station: f64) -> Obstacle {
        let s = self.project_anywhere(east, north);
        let (left, right) = self.corridor(s);
        Obstacle {
            east_m: east as f32,
            north_m: north as f32,
            radius_m: r as f32,
            ahead_m: (s - car_station) as f32,
            path_offset_m: self.offset(east, north, s) as f32,
            left_m: left as f32,
            right_m: right as f32,
            velocity: ObstacleVelocity::ZERO,
        }
    }

    /// The controller's reference from station `s0` at the given speeds per step of the speed
    /// plan, at the steering plan's stages (`stage`).
    pub fn reference(
        &self,
        s0: f64,
        speeds: &[f32; PLAN_STEPS + 1],
        body: &Body,
        stage: &StageClock,
    ) -> [ReferencePoint; STEPS + 1] {
        let front = (body.length_m - body.rear_overhang_m) as f64;
        let rear = body.rear_overhang_m as f64;
        let speeds = stage.stage_speeds(speeds);
        let mut s = s0;
        std::array::from_fn(|k| {
            if k > 0 {
                s += 0.5 * (speeds[k - 1] + speeds[k]) as f64 * stage.stage_s(k - 1) as f64;
            }
            let (left_f, right_f) = self.binding(s, s + front);
            let (left_r, right_r) = self.binding(s, s - rear);
            ReferencePoint {
                at: self.sample(s, self.corridor(s)),
                curvature_per_m: self.curvature(s) as f32,
                speed_mps: self.speed(s) as f32,
                front_left: self.side_point(s, left_f, (left_f.0, right_f.0)),
                front_right: self.side_point(s, right_f, (left_f.0, right_f.0)),
                rear_left: self.side_point(s, left_r, (left_r.0, right_r.0)),
                rear_right: self.side_point(s, right_r, (left_r.0, right_r.0)),
            }
        })
    }
}

/// An obstacle circle for [`Loop::obstacles`]; the loop fills in where it lies along the path
/// every tick.
pub fn circle(east_m: f32, north_m: f32, radius_m: f32) -> Obstacle {
    Obstacle {
        east_m,
        north_m,
        radius_m,
        ahead_m: 0.0,
        path_offset_m: 0.0,
        left_m: 0.0,
        right_m: 0.0,
        velocity: ObstacleVelocity::ZERO,
    }
}

/// The error of the measured pose: a constant position bias plus white noise on position and
/// heading (the node's estimate error, to first order).
#[derive(Clone, Copy, Debug)]
pub struct PositionError {
    /// Constant error east, north, m.
    pub bias_m: (f64, f64),
    /// Standard deviation of the white part, m.
    pub white_m: f64,
    /// Standard deviation of the heading error, rad.
    pub heading_white_rad: f64,
    /// The bound the controller is told (inflates obstacles), m.
    pub uncertainty_m: f32,
}

impl PositionError {
    /// No error.
    pub const NONE: Self = Self {
        bias_m: (0.0, 0.0),
        white_m: 0.0,
        heading_white_rad: 0.0,
        uncertainty_m: 0.0,
    };
    /// A survey-grade (RTK) receiver after the node's filter: centimetres (RTK fixes are
    /// specified at about 1 cm + 1 ppm horizontal), heading a few milliradians.
    pub const RTK: Self = Self {
        bias_m: (0.01, -0.01),
        white_m: 0.01,
        heading_white_rad: 0.003,
        uncertainty_m: 0.05,
    };
    /// The simulator's standard receiver after the node's filter: the bias dominates (the
    /// simulator draws it with 0.8 m sigma per axis; the node's filtered position is 0.92 m RMS
    /// off on the 5-minute drive, README), `bias_m` is set per test; white part 0.1 m; the
    /// controller is told 1.6 m (2 sigma).
    pub fn standard(bias_m: (f64, f64)) -> Self {
        Self {
            bias_m,
            white_m: 0.1,
            heading_white_rad: 0.01,
            uncertainty_m: 1.6,
        }
    }
}

/// How old what the controller is told is, in 20 ms ticks, as on a real node: its heading
/// estimate lags the truth in transients, the steering report is a tick old when it is used,
/// and the command reaches the actuator a tick later. All zero: the truth, at once.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Delays {
    /// The pose's heading is the true heading this many ticks ago.
    pub heading_ticks: usize,
    /// The measured steering is the actuator's this many ticks ago.
    pub steer_ticks: usize,
    /// Commands act this many ticks after they are computed.
    pub command_ticks: usize,
}

/// One tick of the log.
#[derive(Clone, Copy, Debug)]
pub struct TickLog {
    /// Time, s.
    pub t_s: f64,
    /// True rear-axle position and heading.
    pub x_m: f64,
    /// North, m.
    pub y_m: f64,
    /// Heading, rad.
    pub heading_rad: f64,
    /// Station of the rear axle.
    pub station_m: f64,
    /// True lateral offset of the rear axle, m.
    pub e_y_m: f64,
    /// Speed, m/s.
    pub speed_mps: f64,
    /// How far the body's corners are outside the corridor (0 inside), m.
    pub corridor_violation_m: f64,
    /// The controller's output.
    pub out: MpcOutput,
}

/// The simulated car and the controller.
pub struct Loop {
    /// Vehicle parameters of the plant.
    pub cfg: VehicleConfig,
    plant: Plant,
    state: PlantState,
    steering: SteeringActuator,
    speed_ctl: SpeedController,
    ax_mps2: f64,
    steer_pct: f64,
    /// The controller.
    pub mpc: MpcConfig,
    /// Its state.
    pub mpc_state: MpcState,
    speed_model: SsBlock<2>,
    speed_model_state: SsBlockState<2>,
    hybrid: HybridConfig,
    hybrid_state: HybridState,
    station_m: f64,
    last_speed_cmd: f32,
    last_steer_cmd: f32,
    planned_speeds: [f32; PLAN_STEPS + 1],
    rng: u64,
    /// Measurement error.
    pub position_error: PositionError,
    /// Obstacles (true; the controller sees the same).
    pub obstacles: [Option<Obstacle>; MAX_OBSTACLES],
    /// Per tick.
    pub log: Vec<TickLog>,
    /// Measurement and command delays.
    pub delays: Delays,
    /// Past true headings and steering (newest last), commands not yet acting (oldest first).
    heading_history: std::collections::VecDeque<f64>,
    steer_history: std::collections::VecDeque<f64>,
    command_queue: std::collections::VecDeque<(f32, f32)>,
}

/// The CAT Vehicle's body for the tests: 2010 Ford Escape Hybrid, 4.44 m long, 1.81 m wide
/// (manufacturer's figures); rear overhang about 0.9 m (length minus wheelbase 2.62 m minus a
/// front overhang of about 0.92 m, estimated from side views).
pub const ESCAPE_BODY: Body = Body {
    width_m: 1.81,
    length_m: 4.44,
    rear_overhang_m: 0.9,
};

/// The figures that make one test car differ from the CAT Vehicle's defaults.
struct CarSpec {
    wheelbase_m: f64,
    track_m: f64,
    mass_kg: f64,
    cg_to_front_m: f64,
    yaw_inertia_kg_m2: f64,
    cg_height_m: f64,
    max_steer_deg: f64,
    cornering_n_per_rad: (f64, f64),
    steer_rate_pct_per_s: f64,
    steer_lag_s: f64,
    speed_delay_s: f64,
    max_accel_mps2: f64,
    speed_lag_s: f64,
    body: Body,
}

impl CarSpec {
    fn build(&self) -> (VehicleConfig, Body) {
        let mut cfg = VehicleConfig::default();
        let c = &mut cfg.chassis;
        c.wheelbase_m = self.wheelbase_m;
        c.track_m = self.track_m;
        c.mass_kg = self.mass_kg;
        c.cg_to_front_m = self.cg_to_front_m;
        c.cg_to_rear_m = self.wheelbase_m - self.cg_to_front_m;
        c.yaw_inertia_kg_m2 = self.yaw_inertia_kg_m2;
        c.cg_height_m = self.cg_height_m;
        c.max_steer_deg = self.max_steer_deg;
        cfg.tyre_front.cornering_stiffness_n_per_rad = self.cornering_n_per_rad.0;
        cfg.tyre_rear.cornering_stiffness_n_per_rad = self.cornering_n_per_rad.1;
        cfg.steering.rate_limit_pct_per_s = self.steer_rate_pct_per_s;
        cfg.steering.lag_s = self.steer_lag_s;
        cfg.speed_controller.command_delay_s = self.speed_delay_s;
        cfg.speed_controller.max_accel_mps2 = self.max_accel_mps2;
        cfg.speed_controller.actuator_lag_s = self.speed_lag_s;
        // The plant's dynamics do not use the body; the bench's rows use the controller's.
        cfg.body = catmodel_host::sim::config::Body {
            width_m: f64::from(self.body.width_m),
            length_m: f64::from(self.body.length_m),
            rear_overhang_m: f64::from(self.body.rear_overhang_m),
        };
        cfg.validate().expect("a valid vehicle");
        (cfg, self.body)
    }
}

/// A second car the controller's defaults were not tuned on: a compact hatchback (2.55 m
/// wheelbase, 1.3 t, CG further forward, softer tyres, 33 deg lock with a 75 %/s actuator and a
/// 40 ms lag, a quicker but more delayed speed loop), 1.75 m wide and 4.1 m long. Typical
/// figures of the class, chosen to differ from the CAT Vehicle in every parameter the
/// controller uses, not a specific model.
pub fn hatchback() -> (VehicleConfig, Body) {
    CarSpec {
        wheelbase_m: 2.55,
        track_m: 1.5,
        mass_kg: 1300.0,
        cg_to_front_m: 1.0,
        yaw_inertia_kg_m2: 1900.0,
        cg_height_m: 0.55,
        max_steer_deg: 33.0,
        cornering_n_per_rad: (65_000.0, 72_000.0),
        steer_rate_pct_per_s: 75.0,
        steer_lag_s: 0.04,
        speed_delay_s: 0.5,
        max_accel_mps2: 2.5,
        speed_lag_s: 0.3,
        body: Body {
            width_m: 1.75,
            length_m: 4.1,
            rear_overhang_m: 0.75,
        },
    }
    .build()
}

/// A long-wheelbase van (3.0 m wheelbase, 2.4 t, 32 deg lock at 60 %/s with an 80 ms lag),
/// 2.0 m wide, 5.0 m long with a 1.0 m rear overhang: the case the defaults do not cover
/// (docs/mpc.md, "Limits": it does not pass the ISO 3888-2 lanes sized for its width).
pub fn van() -> (VehicleConfig, Body) {
    CarSpec {
        wheelbase_m: 3.0,
        track_m: 1.7,
        mass_kg: 2400.0,
        cg_to_front_m: 1.4,
        yaw_inertia_kg_m2: 4200.0,
        cg_height_m: 0.8,
        max_steer_deg: 32.0,
        cornering_n_per_rad: (100_000.0, 120_000.0),
        steer_rate_pct_per_s: 60.0,
        steer_lag_s: 0.08,
        speed_delay_s: 0.4,
        max_accel_mps2: 1.5,
        speed_lag_s: 0.5,
        body: Body {
            width_m: 2.0,
            length_m: 5.0,
            rear_overhang_m: 1.0,
        },
    }
    .build()
}

/// A long truck with slow steering (4.8 m wheelbase, 5.5 t, 32 deg lock at 40 %/s with a
/// 60 ms lag), 2.3 m wide and 7.6 m long: its steering changes its curvature at a third of the
/// CAT Vehicle's rate (0.047 against 0.142 1/m per s; `mpc::StageClock`). Figures of the class
/// (`scripts/sil-drive.py`'s truck), not a specific model.
pub fn truck() -> (VehicleConfig, Body) {
    let (mut cfg, body) = CarSpec {
        wheelbase_m: 4.8,
        track_m: 2.0,
        mass_kg: 5500.0,
        cg_to_front_m: 2.0,
        yaw_inertia_kg_m2: 28_000.0,
        cg_height_m: 1.1,
        max_steer_deg: 32.0,
        cornering_n_per_rad: (160_000.0, 240_000.0),
        steer_rate_pct_per_s: 40.0,
        steer_lag_s: 0.06,
        speed_delay_s: 0.4,
        max_accel_mps2: 1.5,
        speed_lag_s: 0.6,
        body: Body {
            width_m: 2.3,
            length_m: 7.6,
            rear_overhang_m: 1.4,
        },
    }
    .build();
    cfg.tyre_front.friction_mu = 0.8;
    cfg.tyre_rear.friction_mu = 0.8;
    cfg.validate().expect("a valid vehicle");
    (cfg, body)
}

/// The controller configuration for a plant vehicle: its geometry and linear tyre figures,
/// the steering actuator's rate limit, eq 5 (published) as the speed model.
pub fn mpc_for(cfg: &VehicleConfig, body: Body, tuning: MpcTuning) -> MpcConfig {
    let c = &cfg.chassis;
    let vehicle = VehicleParams {
        wheelbase_m: c.wheelbase_m as f32,
        track_m: c.track_m as f32,
        max_steer_rad: (c.max_steer_deg as f32).to_radians(),
        understeer_s2_per_m2: cfg.understeer_s2_per_m2() as f32,
    };
    let dynamics = cfg.dynamic_params();
    let rate = (cfg.steering.rate_limit_pct_per_s / 100.0 * c.max_steer_deg.to_radians()) as f32;
    let speed_model = SsBlock::<2>::from_tf(&paper::EQ5_INTERNAL_CONTROLLER, paper::PAPER_TS_S)
        .expect("eq 5 discretises");
    MpcConfig::new(vehicle, Some(dynamics), body, rate, &speed_model, tuning).expect("valid config")
}

impl Loop {
    /// The car at rest or moving at `speed_mps` on the path's start, `offset_m` to the right,
    /// heading `heading_error_rad` off the path.
    pub fn new(
        cfg: VehicleConfig,
        mpc: MpcConfig,
        path: &TestPath,
        speed_mps: f64,
        offset_m: f64,
        heading_error_rad: f64,
    ) -> Self {
        let (x, y, h) = path.pose(0.0);
        let heading = h + heading_error_rad;
        let b = cfg.chassis.cg_to_rear_m;
        let rx = x + offset_m * h.cos();
        let ry = y - offset_m * h.sin();
        let state = PlantState {
            x_m: rx + b * heading.sin(),
            y_m: ry + b * heading.cos(),
            heading_rad: heading,
            vx_mps: speed_mps,
            vy_mps: 0.0,
            yaw_rate_rps: 0.0,
        };
        let dt = catmodel_host::sim::PLANT_STEP_S;
        let plant = Plant::new(&cfg);
        let steering = SteeringActuator::new(&cfg.steering, dt, 0.0);
        let mut speed_ctl = SpeedController::new(&cfg.speed_controller, cfg.chassis.mass_kg, dt);
        // Settle the car's speed loop at the initial speed (its delay line full of it).
        let mut settle = state;
        for _ in 0..20_000 {
            let out = speed_ctl.step(speed_mps, settle.vx_mps);
            let _ = out;
            settle.vx_mps = speed_mps;
        }
        let speed_model = SsBlock::<2>::from_tf(&paper::EQ5_INTERNAL_CONTROLLER, paper::PAPER_TS_S)
            .expect("eq 5");
        let speed_model_state = speed_model
            .steady_state_for_output(speed_mps as f32)
            .expect("equilibrium");
        let last_speed_cmd = speed_mps as f32 / speed_model.dc_gain().unwrap_or(1.0);
        let hybrid_state = HybridState::default();
        Self {
            plant,
            state,
            steering,
            speed_ctl,
            ax_mps2: 0.0,
            steer_pct: 0.0,
            mpc,
            mpc_state: MpcState::default(),
            speed_model,
            speed_model_state,
            // The published model file's switching thresholds.
            hybrid: catmodel_model_file::paper().hybrid.config(),
            hybrid_state,
            station_m: 0.0,
            last_speed_cmd,
            last_steer_cmd: 0.0,
            planned_speeds: [speed_mps as f32; PLAN_STEPS + 1],
            rng: 0x9E37_79B9_7F4A_7C15,
            position_error: PositionError::NONE,
            obstacles: [None; MAX_OBSTACLES],
            log: Vec::new(),
            delays: Delays::default(),
            heading_history: Default::default(),
            steer_history: Default::default(),
            command_queue: Default::default(),
            cfg,
        }
    }

    fn normal(&mut self) -> f64 {
        // xorshift64* and Box-Muller: deterministic noise for the tests.
        let mut next = || {
            self.rng ^= self.rng >> 12;
            self.rng ^= self.rng << 25;
            self.rng ^= self.rng >> 27;
            ((self.rng.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 + 0.5)
                / (1u64 << 53) as f64
        };
        let (u1, u2) = (next(), next());
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }

    /// True rear-axle pose (x, y, heading).
    pub fn rear_axle(&self) -> (f64, f64, f64) {
        let b = self.cfg.chassis.cg_to_rear_m;
        let h = self.state.heading_rad;
        (
            self.state.x_m - b * h.sin(),
            self.state.y_m - b * h.cos(),
            h,
        )
    }

    /// The body's corners (FL, FR, RL, RR) in the world, from the true pose.
    pub fn corners(&self) -> [(f64, f64); 4] {
        let (x, y, h) = self.rear_axle();
        let body = self.mpc.body();
        let front = (body.length_m - body.rear_overhang_m) as f64;
        let rear = -(body.rear_overhang_m as f64);
        let half = 0.5 * body.width_m as f64;
        let at = |s: f64, l: f64| (x + s * h.sin() + l * h.cos(), y + s * h.cos() - l * h.sin());
        [
            at(front, -half),
            at(front, half),
            at(rear, -half),
            at(rear, half),
        ]
    }

    /// Distance from a circle to the body rectangle (negative inside), true pose.
    pub fn clearance(&self, ob: &Obstacle) -> f64 {
        let (x, y, h) = self.rear_axle();
        let body = self.mpc.body();
        let (dx, dy) = (ob.east_m as f64 - x, ob.north_m as f64 - y);
        let along = dx * h.sin() + dy * h.cos();
        let lateral = dx * h.cos() - dy * h.sin();
        let front = (body.length_m - body.rear_overhang_m) as f64;
        let rear = -(body.rear_overhang_m as f64);
        let half = 0.5 * body.width_m as f64;
        let ox = (along - along.clamp(rear, front)).abs();
        let oy = (lateral.abs() - half).max(0.0);
        let inside = along > rear && along < front && lateral.abs() < half;
        let d = if inside {
            -0.0
        } else {
            (ox * ox + oy * oy).sqrt()
        };
        d - ob.radius_m as f64
    }

    /// One 20 ms tick: measure, solve, then run the plant for 20 ms with the commands.
    pub fn tick(&mut self, path: &TestPath, t_s: f64) -> MpcOutput {
        let (x, y, h) = self.rear_axle();
        let ex = self.position_error.bias_m.0 + self.position_error.white_m * self.normal();
        let ey = self.position_error.bias_m.1 + self.position_error.white_m * self.normal();
        let (mx, my) = (x + ex, y + ey);
        self.heading_history.push_back(h);
        self.steer_history.push_back(self.steer_pct);
        while self.heading_history.len() > self.delays.heading_ticks + 1 {
            self.heading_history.pop_front();
        }
        while self.steer_history.len() > self.delays.steer_ticks + 1 {
            self.steer_history.pop_front();
        }
        let h_told = self.heading_history.front().copied().unwrap_or(h);
        let steer_told = self
            .steer_history
            .front()
            .copied()
            .unwrap_or(self.steer_pct);
        let mh = h_told + self.position_error.heading_white_rad * self.normal();
        self.station_m = path.project(mx, my, self.station_m);
        let vx = self.state.vx_mps;
        let r = self.state.yaw_rate_rps;
        let mode = self
            .hybrid
            .update(&mut self.hybrid_state, vx as f32, (vx * r) as f32);
        let max_steer = (self.cfg.chassis.max_steer_deg as f32).to_radians();
        let reference = path.reference(
            self.station_m,
            &self.planned_speeds,
            self.mpc.body(),
            self.mpc.stage(),
        );
        let mut obstacles = [None; MAX_OBSTACLES];
        for (o, ob) in obstacles.iter_mut().zip(&self.obstacles) {
            *o = ob.map(|b| {
                path.place(
                    b.east_m as f64,
                    b.north_m as f64,
                    b.radius_m as f64,
                    self.station_m,
                )
            });
        }
        // The speed model's output now (its next step consumes the command sent now).
        let mut peek = self.speed_model_state;
        let modelled = self.speed_model.step(&mut peek, 0.0);
        let input = MpcInput {
            reference: &reference,
            obstacles: &obstacles,
            car: CarState {
                pose: Pose::new(mx as f32, my as f32, mh as f32),
                speed_mps: vx as f32,
                lateral: LateralState {
                    vy_mps: self.state.vy_mps as f32,
                    yaw_rate_rps: r as f32,
                },
                steer_rad: steer_told as f32 / 100.0 * max_steer,
                mode,
                speed_model: &self.speed_model_state,
                speed_bias_mps: vx as f32 - modelled,
                last_speed_cmd_mps: self.last_speed_cmd,
            },
            position_uncertainty_m: self.position_error.uncertainty_m,
            // The bench's path is the horizon's reference (its cars' paths ask for less of the
            // lock than MpcTuning::line_rule looks for).
            path_max_curvature_per_m: reference
                .iter()
                .map(|r| r.curvature_per_m.abs())
                .fold(0.0, f32::max),
            // The bench drives its paths at speed to a station short of their end: no stop.
            to_end_m: f32::INFINITY,
            in_held_turn: false,
            slow_ahead: None,
        };
        let out = self.mpc.solve(&mut self.mpc_state, &input);
        for (p, pt) in self.planned_speeds.iter_mut().zip(&out.plan) {
            *p = pt.speed_mps;
        }
        self.last_speed_cmd = out.speed_cmd_mps;
        self.last_steer_cmd = out.steer_cmd_pct;
        self.speed_model
            .step(&mut self.speed_model_state, out.speed_cmd_mps);
        self.command_queue
            .push_back((out.steer_cmd_pct, out.speed_cmd_mps));
        // The first commands also stand for the ticks before them.
        let first = (out.steer_cmd_pct, out.speed_cmd_mps);
        while self.command_queue.len() <= self.delays.command_ticks {
            self.command_queue.push_front(first);
        }
        let (steer_cmd_pct, speed_cmd_mps) = self.command_queue.pop_front().unwrap_or(first);
        let dt = catmodel_host::sim::PLANT_STEP_S;
        let max_steer_rad = self.cfg.chassis.max_steer_deg.to_radians();
        for _ in 0..20 {
            self.steer_pct = self.steering.step(steer_cmd_pct as f64);
            let drive = self.speed_ctl.step(speed_cmd_mps as f64, self.state.vx_mps);
            let input = PlantInput {
                steer_rad: self.steer_pct / 100.0 * max_steer_rad,
                drive_force_n: drive.drive_force_n,
                brake_force_n: drive.brake_force_n,
            };
            self.ax_mps2 = self.plant.step(&mut self.state, &input, self.ax_mps2, dt);
        }
        let (tx, ty, th) = self.rear_axle();
        let s_true = path.project(tx, ty, self.station_m);
        let mut violation = 0.0f64;
        for (i, (cx, cy)) in self.corners().into_iter().enumerate() {
            let s_c = path.project(cx, cy, s_true);
            let off = path.offset(cx, cy, s_c);
            let (left, right) = path.corridor(s_c);
            let v = if i % 2 == 0 { -off - left } else { off - right };
            violation = violation.max(v);
        }
        self.log.push(TickLog {
            t_s,
            x_m: tx,
            y_m: ty,
            heading_rad: th,
            station_m: s_true,
            e_y_m: path.offset(tx, ty, s_true),
            speed_mps: self.state.vx_mps,
            corridor_violation_m: violation,
            out,
        });
        out
    }

    /// Runs until the rear axle reaches `station_m` or `max_s` seconds pass.
    pub fn run(&mut self, path: &TestPath, station_m: f64, max_s: f64) {
        let mut t = 0.0;
        while t < max_s {
            self.tick(path, t);
            t += 0.02;
            if self.log.last().is_some_and(|l| l.station_m >= station_m) {
                break;
            }
        }
    }

    /// The largest corridor violation of the body over the log, m (0 when it stayed inside).
    pub fn worst_corridor_violation_m(&self) -> f64 {
        self.log
            .iter()
            .fold(0.0f64, |m, t| m.max(t.corridor_violation_m))
    }

    /// The plant's state (CG).
    pub fn plant_state(&self) -> &PlantState {
        &self.state
    }
}
