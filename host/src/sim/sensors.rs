//! Sensors, each on its own clock: three vehicle-bus reports (speed: `vel` + `input_vel`;
//! steering: `steer`; pedals: `accel` + `brake`) and the GNSS receiver (`lat` + `lon`).
//!
//! A report's clock has a random phase and a rate error of a few ppm; its value is the quantity
//! at the sampling instant (linearly interpolated between plant steps), and it is logged a
//! random 0.5..4 ms later (the timestamp jitter of a logger). Timestamps are whole microseconds
//! (the candump resolution). GNSS error = white noise + a first-order Gauss-Markov bias per axis.
use super::config::{BusSensors, Faults, Gnss};
use super::geo::enu_to_lat_lon;
use super::rng::{SimRng, Stream};
use crate::logcsv::LogRow;

/// What the sensors can see at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Snapshot {
    /// Longitudinal (wheel) speed, m/s.
    pub speed_mps: f64,
    /// Steering actuator position, %.
    pub steer_pct: f64,
    /// GNSS antenna east of the origin, m.
    pub antenna_east_m: f64,
    /// GNSS antenna north of the origin, m.
    pub antenna_north_m: f64,
}

impl Snapshot {
    fn lerp(&self, other: &Snapshot, f: f64) -> Snapshot {
        let l = |a: f64, b: f64| a + (b - a) * f;
        Snapshot {
            speed_mps: l(self.speed_mps, other.speed_mps),
            steer_pct: l(self.steer_pct, other.steer_pct),
            antenna_east_m: l(self.antenna_east_m, other.antenna_east_m),
            antenna_north_m: l(self.antenna_north_m, other.antenna_north_m),
        }
    }
}

/// Discrete values held between controller updates.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Held {
    /// Speed command as sent (before the car's transport delay), m/s.
    pub command_mps: f64,
    /// Accelerator pedal, %.
    pub accel_pct: f64,
    /// Brake pedal, %.
    pub brake_pct: f64,
}

#[derive(Debug, Clone)]
struct Clock {
    next_sample_s: f64,
    period_s: f64,
    delay_min_s: f64,
    delay_max_s: f64,
    last_log_us: i64,
}

impl Clock {
    fn new(rng: &mut SimRng, period_s: f64, ppm: f64, delay_min_s: f64, delay_max_s: f64) -> Self {
        Clock {
            next_sample_s: rng.uniform_in(0.0, period_s),
            period_s: period_s * (1.0 + 1e-6 * rng.uniform_in(-ppm, ppm)),
            delay_min_s,
            delay_max_s,
            last_log_us: -1,
        }
    }

    /// Log time (us) of the sample taken at `sample_s`: strictly after the previous one.
    fn log_time_us(&mut self, rng: &mut SimRng, sample_s: f64) -> i64 {
        let t = sample_s + rng.uniform_in(self.delay_min_s, self.delay_max_s);
        let us = (libm::round(t * 1e6) as i64).max(self.last_log_us + 1);
        self.last_log_us = us;
        us
    }
}

fn quantize(x: f64, resolution: f64) -> f64 {
    // Dividing by the integer reciprocal gives the double nearest the decimal (short CSV text).
    let inv = libm::round(1.0 / resolution);
    if inv >= 1.0 {
        libm::round(x * inv) / inv
    } else {
        libm::round(x / resolution) * resolution
    }
}

fn us_to_s(us: i64) -> f64 {
    us as f64 / 1e6
}

#[derive(Debug, Clone)]
enum Kind {
    Speed,
    Steer,
    Pedals,
}

#[derive(Debug, Clone)]
struct BusReport {
    kind: Kind,
    clock: Clock,
    rng: SimRng,
}

#[derive(Debug, Clone)]
struct GnssReceiver {
    clock: Clock,
    rng: SimRng,
    bias_m: [f64; 2],
    bias_phi: f64,
    bias_drive_m: f64,
    outage_until_s: f64,
}

/// All sensors of the car, producing log rows (one per report, unmerged).
#[derive(Debug, Clone)]
pub struct SensorSuite {
    bus: BusSensors,
    gnss_params: Gnss,
    faults: Option<Faults>,
    fault_rng: SimRng,
    reports: Vec<BusReport>,
    gnss: GnssReceiver,
    origin_lat_deg: f64,
    origin_lon_deg: f64,
    /// Rows in production order (each stream in increasing time; streams interleaved).
    pub rows: Vec<(i64, LogRow)>,
}

impl SensorSuite {
    /// Sensors for a run with `seed`; `faults` enables fault injection.
    pub fn new(
        bus: &BusSensors,
        gnss: &Gnss,
        faults: Option<&Faults>,
        seed: u64,
        origin: (f64, f64),
    ) -> Self {
        let mut reports = Vec::new();
        for (kind, stream) in [
            (Kind::Speed, Stream::SpeedReport),
            (Kind::Steer, Stream::SteerReport),
            (Kind::Pedals, Stream::PedalReport),
        ] {
            let mut rng = SimRng::new(seed, stream);
            let clock = Clock::new(
                &mut rng,
                bus.period_s,
                bus.clock_error_ppm,
                bus.timestamp_delay_min_s,
                bus.timestamp_delay_max_s,
            );
            reports.push(BusReport { kind, clock, rng });
        }
        let mut rng = SimRng::new(seed, Stream::Gnss);
        let clock = Clock::new(
            &mut rng,
            gnss.period_s,
            gnss.clock_error_ppm,
            gnss.timestamp_delay_min_s,
            gnss.timestamp_delay_max_s,
        );
        let bias_m = [
            gnss.bias_sigma_m * rng.normal(),
            gnss.bias_sigma_m * rng.normal(),
        ];
        let bias_phi = libm::exp(-gnss.period_s / gnss.bias_correlation_s);
        let bias_drive_m = gnss.bias_sigma_m * libm::sqrt(1.0 - bias_phi * bias_phi);
        Self {
            bus: bus.clone(),
            gnss_params: gnss.clone(),
            faults: faults.cloned(),
            fault_rng: SimRng::new(seed, Stream::Faults),
            reports,
            gnss: GnssReceiver {
                clock,
                rng,
                bias_m,
                bias_phi,
                bias_drive_m,
                outage_until_s: -1.0,
            },
            origin_lat_deg: origin.0,
            origin_lon_deg: origin.1,
            rows: Vec::new(),
        }
    }

    /// Takes every sample due in (t0, t1], the plant having moved from `s0` to `s1`.
    pub fn observe(&mut self, t0_s: f64, t1_s: f64, s0: &Snapshot, s1: &Snapshot, held: &Held) {
        let bus = &self.bus;
        for report in &mut self.reports {
            while report.clock.next_sample_s <= t1_s {
                let ts = report.clock.next_sample_s;
                report.clock.next_sample_s += report.clock.period_s;
                let snap = s0.lerp(s1, (ts - t0_s) / (t1_s - t0_s));
                let rng = &mut report.rng;
                let mut row = LogRow::empty(0.0);
                match report.kind {
                    Kind::Speed => {
                        let measured = if snap.speed_mps < bus.speed_dead_band_mps {
                            0.0
                        } else {
                            (snap.speed_mps + bus.speed_noise_mps * rng.normal()).max(0.0)
                        };
                        row.vel = Some(quantize(measured, bus.speed_resolution_mps));
                        row.input_vel = Some(quantize(held.command_mps, bus.speed_resolution_mps));
                    }
                    Kind::Steer => {
                        let measured = (snap.steer_pct + bus.steer_noise_pct * rng.normal())
                            .clamp(-100.0, 100.0);
                        row.steer = Some(quantize(measured, bus.percent_resolution));
                    }
                    Kind::Pedals => {
                        // A released pedal reads exactly 0: noise only on a pressed pedal.
                        let mut pedal = |p: f64| {
                            if p <= 0.0 {
                                0.0
                            } else {
                                quantize(
                                    (p + bus.pedal_noise_pct * rng.normal()).clamp(0.0, 100.0),
                                    bus.percent_resolution,
                                )
                            }
                        };
                        row.accel = Some(pedal(held.accel_pct));
                        row.brake = Some(pedal(held.brake_pct));
                    }
                }
                let t_us = report.clock.log_time_us(rng, ts);
                let dropped = match &self.faults {
                    Some(f) => self.fault_rng.chance(f.bus_drop_probability),
                    None => false,
                };
                if !dropped {
                    row.t = us_to_s(t_us);
                    self.rows.push((t_us, row));
                }
            }
        }
        let g = &self.gnss_params;
        let rx = &mut self.gnss;
        while rx.clock.next_sample_s <= t1_s {
            let ts = rx.clock.next_sample_s;
            rx.clock.next_sample_s += rx.clock.period_s;
            let snap = s0.lerp(s1, (ts - t0_s) / (t1_s - t0_s));
            for b in &mut rx.bias_m {
                *b = rx.bias_phi * *b + rx.bias_drive_m * rx.rng.normal();
            }
            let mut east = snap.antenna_east_m + rx.bias_m[0] + g.white_noise_m * rx.rng.normal();
            let mut north = snap.antenna_north_m + rx.bias_m[1] + g.white_noise_m * rx.rng.normal();
            let t_us = rx.clock.log_time_us(&mut rx.rng, ts);
            if let Some(f) = &self.faults {
                let fr = &mut self.fault_rng;
                if ts >= rx.outage_until_s && fr.chance(f.gnss_outage_rate_per_s * g.period_s) {
                    rx.outage_until_s = ts + fr.exponential(f.gnss_outage_mean_s);
                }
                if ts < rx.outage_until_s {
                    continue;
                }
                if fr.chance(f.gnss_outlier_probability) {
                    east += fr.uniform_in(-f.gnss_outlier_m, f.gnss_outlier_m);
                    north += fr.uniform_in(-f.gnss_outlier_m, f.gnss_outlier_m);
                }
            }
            let (lat, lon) = enu_to_lat_lon(self.origin_lat_deg, self.origin_lon_deg, east, north);
            let mut row = LogRow::empty(us_to_s(t_us));
            row.lat = Some(quantize(lat, g.resolution_deg));
            row.lon = Some(quantize(lon, g.resolution_deg));
            self.rows.push((t_us, row));
        }
    }
}
