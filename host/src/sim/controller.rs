//! What sits in front of the plant inside the car: the ByWire speed controller and the steering
//! actuator. Both are discrete-time, like the ECUs they stand for.
//!
//! Speed: commanded speed -> transport delay -> PI loop on the wheel speed (anti-windup by
//! conditional integration) -> acceleration limits -> first-order powertrain/brake lag ->
//! drive or brake force. The pedal percentages on the bus are the *commanded* acceleration as a
//! share of its limit (100 % accelerator = `max_accel_mps2`, 100 % brake = `max_decel_mps2`).
//! Steering: commanded percent -> rate limit -> first-order lag -> measured percent -> wheel angle.
use super::config::{SpeedController as SpeedParams, SteeringActuator as SteerParams};
use std::collections::VecDeque;

/// Output of the speed controller for the plant and the pedal report.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SpeedOutput {
    /// Delivered drive force at the front wheels, N.
    pub drive_force_n: f64,
    /// Delivered brake force, N.
    pub brake_force_n: f64,
    /// Accelerator pedal, % 0..100.
    pub accel_pct: f64,
    /// Brake pedal, % 0..100.
    pub brake_pct: f64,
}

/// The car's speed controller, stepped at the plant rate; the PI part updates every
/// `period_s`.
#[derive(Debug, Clone)]
pub struct SpeedController {
    params: SpeedParams,
    mass_kg: f64,
    /// Commands waiting out the transport delay, one per controller period.
    delay_line: VecDeque<f64>,
    integral_mps2: f64,
    accel_cmd_mps2: f64,
    accel_delivered_mps2: f64,
    lag_alpha: f64,
    ticks_per_update: u32,
    tick: u32,
}

impl SpeedController {
    /// A controller at rest (zero command held for the whole delay), for a plant stepping at
    /// `dt_s`.
    pub fn new(params: &SpeedParams, mass_kg: f64, dt_s: f64) -> Self {
        let delay_updates = libm::round(params.command_delay_s / params.period_s) as usize;
        let ticks_per_update = libm::round(params.period_s / dt_s).max(1.0) as u32;
        let lag_alpha = if params.actuator_lag_s > 0.0 {
            1.0 - libm::exp(-dt_s / params.actuator_lag_s)
        } else {
            1.0
        };
        Self {
            params: params.clone(),
            mass_kg,
            delay_line: std::iter::repeat_n(0.0, delay_updates).collect(),
            integral_mps2: 0.0,
            accel_cmd_mps2: -params.standstill_hold_decel_mps2,
            accel_delivered_mps2: -params.standstill_hold_decel_mps2,
            lag_alpha,
            ticks_per_update,
            tick: 0,
        }
    }

    /// One plant step: `command_mps` is the speed command as sent now, `speed_mps` the wheel
    /// speed.
    pub fn step(&mut self, command_mps: f64, speed_mps: f64) -> SpeedOutput {
        if self.tick == 0 {
            self.update(command_mps, speed_mps);
        }
        self.tick = (self.tick + 1) % self.ticks_per_update;
        self.accel_delivered_mps2 +=
            self.lag_alpha * (self.accel_cmd_mps2 - self.accel_delivered_mps2);
        let force = self.mass_kg * self.accel_delivered_mps2;
        let p = &self.params;
        SpeedOutput {
            drive_force_n: force.max(0.0),
            brake_force_n: (-force).max(0.0),
            accel_pct: (100.0 * self.accel_cmd_mps2 / p.max_accel_mps2).clamp(0.0, 100.0),
            brake_pct: (-100.0 * self.accel_cmd_mps2 / p.max_decel_mps2).clamp(0.0, 100.0),
        }
    }

    fn update(&mut self, command_mps: f64, speed_mps: f64) {
        self.delay_line.push_back(command_mps.max(0.0));
        let reference = self.delay_line.pop_front().unwrap_or(0.0);
        let p = &self.params;
        if reference < 0.05 && speed_mps < 0.3 {
            // Standstill: hold the brake, forget the integral.
            self.integral_mps2 = 0.0;
            self.accel_cmd_mps2 = -p.standstill_hold_decel_mps2;
            return;
        }
        let error = reference - speed_mps;
        let unclamped = p.kp_per_s * error + self.integral_mps2;
        let saturated_high = unclamped >= p.max_accel_mps2 && error > 0.0;
        let saturated_low = unclamped <= -p.max_decel_mps2 && error < 0.0;
        if !(saturated_high || saturated_low) {
            self.integral_mps2 += p.ki_per_s2 * error * p.period_s;
        }
        self.accel_cmd_mps2 =
            (p.kp_per_s * error + self.integral_mps2).clamp(-p.max_decel_mps2, p.max_accel_mps2);
    }
}

/// Steering actuator.
#[derive(Debug, Clone)]
pub struct SteeringActuator {
    rate_pct_per_step: f64,
    lag_alpha: f64,
    rate_limited_pct: f64,
    position_pct: f64,
}

impl SteeringActuator {
    /// Actuator at `initial_pct`, stepping every `dt_s`.
    pub fn new(params: &SteerParams, dt_s: f64, initial_pct: f64) -> Self {
        let lag_alpha = if params.lag_s > 0.0 {
            1.0 - libm::exp(-dt_s / params.lag_s)
        } else {
            1.0
        };
        Self {
            rate_pct_per_step: params.rate_limit_pct_per_s * dt_s,
            lag_alpha,
            rate_limited_pct: initial_pct,
            position_pct: initial_pct,
        }
    }

    /// One step towards `command_pct` (clamped to +-100); returns the position, %.
    pub fn step(&mut self, command_pct: f64) -> f64 {
        let target = command_pct.clamp(-100.0, 100.0);
        let change =
            (target - self.rate_limited_pct).clamp(-self.rate_pct_per_step, self.rate_pct_per_step);
        self.rate_limited_pct += change;
        self.position_pct += self.lag_alpha * (self.rate_limited_pct - self.position_pct);
        self.position_pct
    }
}
