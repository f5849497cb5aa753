//! Parameters of the simulated car: chassis, tyres, resistances, the car's internal speed
//! controller, the steering actuator and the sensors. Read from TOML
//! (`host/vehicles/cat-vehicle.toml`); [`VehicleConfig::default`] is the CAT Vehicle and equals
//! that file (a test checks it).
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Everything the simulator needs to know about the car.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VehicleConfig {
    /// Rigid body and geometry.
    pub chassis: Chassis,
    /// The body's outline, for clearance to cones and obstacles.
    pub body: Body,
    /// Front axle tyres (both tyres lumped: single-track model).
    pub tyre_front: Tyre,
    /// Rear axle tyres.
    pub tyre_rear: Tyre,
    /// Rolling resistance and aerodynamic drag.
    pub resistance: Resistance,
    /// Steering actuator (steer-by-wire motor on the column).
    pub steering: SteeringActuator,
    /// The car's own speed controller (ByWire): delay, PI loop, powertrain lag, limits.
    pub speed_controller: SpeedController,
    /// Vehicle-bus reports and the GNSS receiver.
    pub sensors: Sensors,
    /// Sensor faults, applied only when a run asks for them (`SimOptions::faults`).
    pub faults: Faults,
}

/// Rigid body and geometry. Sources: models/paper.toml and host/vehicles/cat-vehicle.toml
/// (wheelbase, track, mass, CG, yaw inertia, each with its source).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Chassis {
    /// Wheelbase L, m.
    pub wheelbase_m: f64,
    /// Track (tread), m. Not used by the single-track plant; kept for the Ackermann conversion.
    pub track_m: f64,
    /// Total mass, kg.
    pub mass_kg: f64,
    /// CG to front axle a, m.
    pub cg_to_front_m: f64,
    /// CG to rear axle b, m (a + b must equal L).
    pub cg_to_rear_m: f64,
    /// Yaw moment of inertia about the CG, kg m^2.
    pub yaw_inertia_kg_m2: f64,
    /// CG height above ground, m (longitudinal load transfer a_x h / L).
    pub cg_height_m: f64,
    /// Centre-wheel angle at 100 % steering, degrees (paper: 35.5).
    pub max_steer_deg: f64,
    /// Share of the brake force on the front axle, 0..1.
    pub brake_front_share: f64,
}

/// The body seen from above: a rectangle around the centreline, placed by its rear overhang
/// behind the rear axle (mirrors not included, as in the published width).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Body {
    /// Overall width, m (ISO 3888-2's `b`).
    pub width_m: f64,
    /// Overall length, m.
    pub length_m: f64,
    /// Rear bumper behind the rear axle, m.
    pub rear_overhang_m: f64,
}

/// Simplified Pacejka magic formula for one axle (both tyres):
/// `Fy = D sin(C atan(B alpha - E (B alpha - atan(B alpha))))`, `D = mu Fz`.
/// B is derived so that `B C D` equals `cornering_stiffness_n_per_rad` at the static axle load;
/// under load transfer D (hence the stiffness) scales with the axle load.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tyre {
    /// Axle cornering stiffness at static load, N/rad (the initial slope B C D).
    pub cornering_stiffness_n_per_rad: f64,
    /// Shape factor C (about 1.3 longitudinal, 1.9 lateral for passenger-car tyres).
    pub shape_c: f64,
    /// Curvature factor E (<= 1).
    pub curvature_e: f64,
    /// Peak friction coefficient mu (D = mu Fz).
    pub friction_mu: f64,
}

/// Driving resistances.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Resistance {
    /// Rolling resistance coefficient (force / normal load).
    pub rolling_coefficient: f64,
    /// Drag coefficient times frontal area, m^2.
    pub drag_area_m2: f64,
    /// Air density, kg/m^3.
    pub air_density_kg_m3: f64,
}

/// Steering actuator: commanded percent -> rate limit -> first-order lag -> wheel angle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SteeringActuator {
    /// Maximum steering rate, % per second (100 % = `max_steer_deg` at the wheel).
    pub rate_limit_pct_per_s: f64,
    /// Time constant of the actuator after the rate limit, s.
    pub lag_s: f64,
}

/// The car's internal speed controller (what the paper's eq 5 identifies).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpeedController {
    /// Update period of the controller, s.
    pub period_s: f64,
    /// Transport delay of the speed command (command path, ByWire), s.
    pub command_delay_s: f64,
    /// Proportional gain, (m/s^2) per (m/s).
    pub kp_per_s: f64,
    /// Integral gain, (m/s^2) per m.
    pub ki_per_s2: f64,
    /// Largest commanded acceleration, m/s^2 (= 100 % accelerator).
    pub max_accel_mps2: f64,
    /// Largest commanded deceleration, m/s^2, positive (= 100 % brake).
    pub max_decel_mps2: f64,
    /// Powertrain/brake first-order lag from commanded to delivered acceleration, s.
    pub actuator_lag_s: f64,
    /// Deceleration held at standstill when the command is zero, m/s^2, positive.
    pub standstill_hold_decel_mps2: f64,
}

/// Sensor models.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sensors {
    /// Vehicle-bus reports (speed, steering, pedals), each on its own clock.
    pub bus: BusSensors,
    /// GNSS receiver.
    pub gnss: Gnss,
}

/// Vehicle-bus reports. Each report (speed: vel + input_vel; steering; pedals: accel + brake)
/// runs on its own clock with the same nominal period.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BusSensors {
    /// Nominal report period, s (paper II-B: 0.02 s).
    pub period_s: f64,
    /// Clock rate error of each report, drawn uniformly in +-this, parts per million.
    pub clock_error_ppm: f64,
    /// Logging delay after the measurement, uniform in [min, max], s (timestamp jitter).
    pub timestamp_delay_min_s: f64,
    /// See `timestamp_delay_min_s`.
    pub timestamp_delay_max_s: f64,
    /// White noise on measured speed, m/s (1 sigma).
    pub speed_noise_mps: f64,
    /// Resolution of speeds on the bus, m/s.
    pub speed_resolution_mps: f64,
    /// Below this true speed the wheel-speed sensor reads exactly 0, m/s.
    pub speed_dead_band_mps: f64,
    /// White noise on measured steering, % (1 sigma).
    pub steer_noise_pct: f64,
    /// White noise on pedal readings, % (1 sigma).
    pub pedal_noise_pct: f64,
    /// Resolution of steering and pedal percentages, %.
    pub percent_resolution: f64,
}

/// GNSS receiver: white noise plus a first-order Gauss-Markov bias per axis.
/// Horizontal RMS error = sqrt(2 (white^2 + bias^2)) (about 1.2 m: NovAtel's figure, paper II-A).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Gnss {
    /// Fix period, s (paper II-B: 0.01 s); 0.01..1 s (100 Hz down to 1 Hz).
    pub period_s: f64,
    /// Clock rate error, drawn uniformly in +-this, parts per million.
    pub clock_error_ppm: f64,
    /// Logging delay after the fix, uniform in [min, max], s.
    pub timestamp_delay_min_s: f64,
    /// See `timestamp_delay_min_s`.
    pub timestamp_delay_max_s: f64,
    /// White noise per axis (east, north), m (1 sigma).
    pub white_noise_m: f64,
    /// Stationary standard deviation of the Gauss-Markov bias per axis, m.
    pub bias_sigma_m: f64,
    /// Correlation time of the bias, s.
    pub bias_correlation_s: f64,
    /// Antenna position ahead of the rear axle, m (the truth reference point is the rear axle).
    pub antenna_ahead_of_rear_axle_m: f64,
    /// Antenna position left of the car's centre line, m (negative: right; absent: 0, on the
    /// centre line).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub antenna_left_of_centre_line_m: f64,
    /// Resolution of latitude and longitude in the log, degrees.
    pub resolution_deg: f64,
}

/// Fault injection (off unless the run asks for it).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Faults {
    /// Rate at which GNSS outages start, per second.
    pub gnss_outage_rate_per_s: f64,
    /// Mean outage length (exponential), s.
    pub gnss_outage_mean_s: f64,
    /// Probability that one fix is an outlier.
    pub gnss_outlier_probability: f64,
    /// Outlier offset per axis, uniform in +-this, m.
    pub gnss_outlier_m: f64,
    /// Probability that one vehicle-bus report is lost.
    pub bus_drop_probability: f64,
}

impl Default for VehicleConfig {
    /// The CAT Vehicle (Ford Escape Hybrid), as in `host/vehicles/cat-vehicle.toml`.
    fn default() -> Self {
        Self {
            chassis: Chassis {
                wheelbase_m: 2.62,
                track_m: 1.55,
                mass_kg: 1741.0,
                cg_to_front_m: 1.142,
                cg_to_rear_m: 1.478,
                yaw_inertia_kg_m2: 2500.0,
                cg_height_m: 0.65,
                max_steer_deg: 35.5,
                brake_front_share: 0.6,
            },
            body: Body {
                width_m: 1.806,
                length_m: 4.437,
                rear_overhang_m: 0.85,
            },
            tyre_front: Tyre {
                cornering_stiffness_n_per_rad: 80_000.0,
                shape_c: 1.9,
                curvature_e: -0.5,
                friction_mu: 0.9,
            },
            tyre_rear: Tyre {
                cornering_stiffness_n_per_rad: 91_000.0,
                shape_c: 1.9,
                curvature_e: -0.5,
                friction_mu: 0.9,
            },
            resistance: Resistance {
                rolling_coefficient: 0.012,
                drag_area_m2: 1.0,
                air_density_kg_m3: 1.2,
            },
            steering: SteeringActuator {
                rate_limit_pct_per_s: 60.0,
                lag_s: 0.05,
            },
            speed_controller: SpeedController {
                period_s: 0.01,
                command_delay_s: 0.4,
                kp_per_s: 0.8,
                ki_per_s2: 0.15,
                max_accel_mps2: 2.0,
                max_decel_mps2: 3.5,
                actuator_lag_s: 0.4,
                standstill_hold_decel_mps2: 1.5,
            },
            sensors: Sensors {
                bus: BusSensors {
                    period_s: 0.02,
                    clock_error_ppm: 50.0,
                    timestamp_delay_min_s: 0.0005,
                    timestamp_delay_max_s: 0.004,
                    speed_noise_mps: 0.03,
                    speed_resolution_mps: 0.01,
                    speed_dead_band_mps: 0.05,
                    steer_noise_pct: 0.2,
                    pedal_noise_pct: 0.3,
                    percent_resolution: 0.1,
                },
                gnss: Gnss {
                    period_s: 0.01,
                    clock_error_ppm: 20.0,
                    timestamp_delay_min_s: 0.0005,
                    timestamp_delay_max_s: 0.003,
                    white_noise_m: 0.3,
                    bias_sigma_m: 0.8,
                    bias_correlation_s: 60.0,
                    antenna_ahead_of_rear_axle_m: 1.478,
                    antenna_left_of_centre_line_m: 0.0,
                    resolution_deg: 1e-9,
                },
            },
            faults: Faults {
                gnss_outage_rate_per_s: 0.02,
                gnss_outage_mean_s: 2.0,
                gnss_outlier_probability: 0.002,
                gnss_outlier_m: 15.0,
                bus_drop_probability: 0.002,
            },
        }
    }
}

/// GNSS fix periods the simulator (and the node) support, s: 100 Hz down to 1 Hz.
pub const GNSS_PERIOD_RANGE_S: (f64, f64) = (0.01, 1.0);

/// A vehicle file that cannot be used.
#[derive(Debug)]
pub enum ConfigError {
    /// The file could not be read.
    Io(std::path::PathBuf, std::io::Error),
    /// The TOML is malformed or has unknown/missing keys.
    Toml(std::path::PathBuf, toml::de::Error),
    /// A value is physically impossible (named, with the reason).
    Invalid(String),
}

impl std::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ConfigError::Io(p, e) => write!(f, "{}: {e}", p.display()),
            ConfigError::Toml(p, e) => write!(f, "{}: {e}", p.display()),
            ConfigError::Invalid(s) => write!(f, "invalid vehicle parameters: {s}"),
        }
    }
}

impl std::error::Error for ConfigError {}

impl VehicleConfig {
    /// Reads and validates a vehicle file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text =
            std::fs::read_to_string(path).map_err(|e| ConfigError::Io(path.to_path_buf(), e))?;
        let cfg: Self =
            toml::from_str(&text).map_err(|e| ConfigError::Toml(path.to_path_buf(), e))?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Parses and validates vehicle TOML text.
    pub fn from_toml_str(text: &str) -> Result<Self, ConfigError> {
        let cfg: Self = toml::from_str(text)
            .map_err(|e| ConfigError::Toml(std::path::PathBuf::from("<string>"), e))?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// The node's linear-tyre single-track model of this car (its true mass, inertia, CG and
    /// tyres' cornering stiffnesses, in f32).
    pub fn dynamic_params(&self) -> catmodel::model::dynamic::DynamicParams {
        let c = &self.chassis;
        catmodel::model::dynamic::DynamicParams {
            mass_kg: c.mass_kg as f32,
            yaw_inertia_kg_m2: c.yaw_inertia_kg_m2 as f32,
            cg_to_front_m: c.cg_to_front_m as f32,
            cg_to_rear_m: c.cg_to_rear_m as f32,
            cornering_front_n_per_rad: self.tyre_front.cornering_stiffness_n_per_rad as f32,
            cornering_rear_n_per_rad: self.tyre_rear.cornering_stiffness_n_per_rad as f32,
            min_speed_mps: catmodel::model::dynamic::MIN_SPEED_MPS,
        }
    }

    /// Understeer term K of `R = L / tan(delta / (1 + K v^2))` implied by the linear tyre
    /// stiffnesses: `K = m (b / C_f - a / C_r) / L^2`, s^2/m^2 (0.0015 for the CAT Vehicle).
    pub fn understeer_s2_per_m2(&self) -> f64 {
        let c = &self.chassis;
        c.mass_kg
            * (c.cg_to_rear_m / self.tyre_front.cornering_stiffness_n_per_rad
                - c.cg_to_front_m / self.tyre_rear.cornering_stiffness_n_per_rad)
            / (c.wheelbase_m * c.wheelbase_m)
    }

    /// Checks every value the simulator divides by or relies on.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let c = &self.chassis;
        let positive = [
            ("chassis.wheelbase_m", c.wheelbase_m),
            ("chassis.track_m", c.track_m),
            ("chassis.mass_kg", c.mass_kg),
            ("chassis.cg_to_front_m", c.cg_to_front_m),
            ("chassis.cg_to_rear_m", c.cg_to_rear_m),
            ("chassis.yaw_inertia_kg_m2", c.yaw_inertia_kg_m2),
            ("chassis.max_steer_deg", c.max_steer_deg),
            ("body.width_m", self.body.width_m),
            ("body.length_m", self.body.length_m),
            (
                "tyre_front.cornering_stiffness_n_per_rad",
                self.tyre_front.cornering_stiffness_n_per_rad,
            ),
            ("tyre_front.shape_c", self.tyre_front.shape_c),
            ("tyre_front.friction_mu", self.tyre_front.friction_mu),
            (
                "tyre_rear.cornering_stiffness_n_per_rad",
                self.tyre_rear.cornering_stiffness_n_per_rad,
            ),
            ("tyre_rear.shape_c", self.tyre_rear.shape_c),
            ("tyre_rear.friction_mu", self.tyre_rear.friction_mu),
            (
                "steering.rate_limit_pct_per_s",
                self.steering.rate_limit_pct_per_s,
            ),
            ("speed_controller.period_s", self.speed_controller.period_s),
            (
                "speed_controller.max_accel_mps2",
                self.speed_controller.max_accel_mps2,
            ),
            (
                "speed_controller.max_decel_mps2",
                self.speed_controller.max_decel_mps2,
            ),
            ("sensors.bus.period_s", self.sensors.bus.period_s),
            ("sensors.gnss.period_s", self.sensors.gnss.period_s),
            (
                "sensors.gnss.bias_correlation_s",
                self.sensors.gnss.bias_correlation_s,
            ),
            (
                "sensors.gnss.resolution_deg",
                self.sensors.gnss.resolution_deg,
            ),
            (
                "sensors.bus.speed_resolution_mps",
                self.sensors.bus.speed_resolution_mps,
            ),
            (
                "sensors.bus.percent_resolution",
                self.sensors.bus.percent_resolution,
            ),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(ConfigError::Invalid(format!("{name} = {v} must be > 0")));
            }
        }
        let non_negative = [
            ("chassis.cg_height_m", c.cg_height_m),
            ("body.rear_overhang_m", self.body.rear_overhang_m),
            ("steering.lag_s", self.steering.lag_s),
            (
                "speed_controller.command_delay_s",
                self.speed_controller.command_delay_s,
            ),
            ("speed_controller.kp_per_s", self.speed_controller.kp_per_s),
            (
                "speed_controller.ki_per_s2",
                self.speed_controller.ki_per_s2,
            ),
            (
                "speed_controller.actuator_lag_s",
                self.speed_controller.actuator_lag_s,
            ),
            (
                "speed_controller.standstill_hold_decel_mps2",
                self.speed_controller.standstill_hold_decel_mps2,
            ),
            (
                "resistance.rolling_coefficient",
                self.resistance.rolling_coefficient,
            ),
            ("resistance.drag_area_m2", self.resistance.drag_area_m2),
            (
                "resistance.air_density_kg_m3",
                self.resistance.air_density_kg_m3,
            ),
            (
                "sensors.bus.clock_error_ppm",
                self.sensors.bus.clock_error_ppm,
            ),
            (
                "sensors.bus.timestamp_delay_min_s",
                self.sensors.bus.timestamp_delay_min_s,
            ),
            (
                "sensors.bus.speed_noise_mps",
                self.sensors.bus.speed_noise_mps,
            ),
            (
                "sensors.bus.speed_dead_band_mps",
                self.sensors.bus.speed_dead_band_mps,
            ),
            (
                "sensors.bus.steer_noise_pct",
                self.sensors.bus.steer_noise_pct,
            ),
            (
                "sensors.bus.pedal_noise_pct",
                self.sensors.bus.pedal_noise_pct,
            ),
            (
                "sensors.gnss.clock_error_ppm",
                self.sensors.gnss.clock_error_ppm,
            ),
            (
                "sensors.gnss.timestamp_delay_min_s",
                self.sensors.gnss.timestamp_delay_min_s,
            ),
            (
                "sensors.gnss.white_noise_m",
                self.sensors.gnss.white_noise_m,
            ),
            ("sensors.gnss.bias_sigma_m", self.sensors.gnss.bias_sigma_m),
            (
                "faults.gnss_outage_rate_per_s",
                self.faults.gnss_outage_rate_per_s,
            ),
            ("faults.gnss_outage_mean_s", self.faults.gnss_outage_mean_s),
            (
                "faults.gnss_outlier_probability",
                self.faults.gnss_outlier_probability,
            ),
            ("faults.gnss_outlier_m", self.faults.gnss_outlier_m),
            (
                "faults.bus_drop_probability",
                self.faults.bus_drop_probability,
            ),
        ];
        for (name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(ConfigError::Invalid(format!("{name} = {v} must be >= 0")));
            }
        }
        if ((c.cg_to_front_m + c.cg_to_rear_m) - c.wheelbase_m).abs() > 1e-3 {
            return Err(ConfigError::Invalid(format!(
                "cg_to_front_m + cg_to_rear_m = {} must equal wheelbase_m = {}",
                c.cg_to_front_m + c.cg_to_rear_m,
                c.wheelbase_m
            )));
        }
        if self.body.rear_overhang_m + c.wheelbase_m >= self.body.length_m {
            return Err(ConfigError::Invalid(
                "body.length_m must exceed body.rear_overhang_m + chassis.wheelbase_m".into(),
            ));
        }
        if !(0.0..=1.0).contains(&c.brake_front_share) {
            return Err(ConfigError::Invalid(
                "chassis.brake_front_share must be in 0..1".into(),
            ));
        }
        for (name, t) in [
            ("tyre_front", &self.tyre_front),
            ("tyre_rear", &self.tyre_rear),
        ] {
            if !(t.curvature_e.is_finite() && t.curvature_e <= 1.0) {
                return Err(ConfigError::Invalid(format!(
                    "{name}.curvature_e must be <= 1"
                )));
            }
            if t.shape_c >= 2.0 {
                return Err(ConfigError::Invalid(format!(
                    "{name}.shape_c must be < 2 (force would change sign at large slip)"
                )));
            }
        }
        let b = &self.sensors.bus;
        let g = &self.sensors.gnss;
        if !(GNSS_PERIOD_RANGE_S.0..=GNSS_PERIOD_RANGE_S.1).contains(&g.period_s) {
            return Err(ConfigError::Invalid(format!(
                "sensors.gnss.period_s = {} s: receivers from 1 to 100 Hz are supported (0.01..1 s)",
                g.period_s
            )));
        }
        if !(b.timestamp_delay_max_s >= b.timestamp_delay_min_s
            && b.timestamp_delay_max_s - b.timestamp_delay_min_s < b.period_s)
        {
            return Err(ConfigError::Invalid(
                "sensors.bus timestamp delay range must be ordered and narrower than the period"
                    .into(),
            ));
        }
        if !(g.timestamp_delay_max_s >= g.timestamp_delay_min_s
            && g.timestamp_delay_max_s - g.timestamp_delay_min_s < g.period_s)
        {
            return Err(ConfigError::Invalid(
                "sensors.gnss timestamp delay range must be ordered and narrower than the period"
                    .into(),
            ));
        }
        for (name, p) in [
            (
                "faults.gnss_outlier_probability",
                self.faults.gnss_outlier_probability,
            ),
            (
                "faults.bus_drop_probability",
                self.faults.bus_drop_probability,
            ),
        ] {
            if p > 1.0 {
                return Err(ConfigError::Invalid(format!("{name} must be <= 1")));
            }
        }
        Ok(())
    }
}

/// For `skip_serializing_if`: an optional key at its default is not written.
fn is_zero(x: &f64) -> bool {
    *x == 0.0
}
