//! Stage 1, receive and validate: each frame is decoded against the DBC's layout (DLC, CRC-8,
//! range, invalid sentinels), its rolling counter checked ([`crate::can::counter`]), and the
//! latest valid value of each input kept with its receive time ([`crate::can::freshness`]).
//! Every rejection is counted in [`Counters`]; nothing is dropped silently. GNSS messages are
//! handed on to the GNSS stage ([`super::gnss`]), the planner's to the drive stage
//! ([`super::drive`]).
use crate::can::codec::{
    decode_input, decode_planner, DecodeError, Direction, InputMessage, PlannerMessage,
};
use crate::can::counter::CounterChecker;
use crate::can::freshness::{Freshness, Input, INPUT_COUNT};
use crate::can::TimedFrame;

use super::{bump, fresh, Counters, NodeConfig};

/// A GNSS position fix that passed decoding (PGN 129025).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GnssFix {
    /// Receive time, us.
    pub t_us: u64,
    /// Latitude, 1e-7 deg.
    pub lat_e7: i32,
    /// Longitude, 1e-7 deg.
    pub lon_e7: i32,
}

/// PGN 129026 with both fields valid: the receiver's course over ground.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GnssCourse {
    /// Receive time, us.
    pub t_us: u64,
    /// Course, rad clockwise from north (as sent: wrapped by the GNSS stage).
    pub cog_rad: f32,
    /// Speed over ground, m/s.
    pub sog_mps: f32,
    /// COG reference (0 = true north).
    pub reference: u8,
}

/// A GNSS message that passed decoding, for the GNSS stage.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GnssMessage {
    /// PGN 129025: a fix.
    Fix(GnssFix),
    /// PGN 129026: a course.
    Course(GnssCourse),
}

/// Where a valid frame goes next.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Routed {
    /// To the GNSS stage.
    Gnss(GnssMessage),
    /// To the drive stage (the planner's path, obstacles and origin).
    Planner(PlannerMessage),
}

/// The vehicle-bus inputs' state: latest values, their counters and receive times.
#[derive(Clone, Copy, Debug, Default)]
pub struct Inputs {
    /// Rejection counters since boot (the stages after this one add theirs).
    pub counters: Counters,
    /// Last receive time of each input (GNSS: the last accepted fix).
    pub freshness: Freshness,
    /// Rolling-counter checks of the steering, speed and pedal reports.
    checkers: [CounterChecker; 3],
    steer_pct: Option<f32>,
    /// (measured, commanded) speed, m/s.
    speeds: Option<(f32, f32)>,
    /// The speed report with those speeds said the car reverses (SPEED_REPORT `direction`).
    reverse: bool,
    /// (accelerator, brake), %.
    pedals: Option<(f32, f32)>,
}

/// The inputs a tick uses: the latest values that are still fresh.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Snapshot {
    /// Steering, %, positive right.
    pub steer_pct: Option<f32>,
    /// (measured, commanded) speed, m/s: magnitudes.
    pub speeds: Option<(f32, f32)>,
    /// The fresh speed report says the car reverses: it moves backwards at `speeds.0`. A
    /// report that says forward, nothing (a kit without the signal) or invalid, or no fresh
    /// report: forwards, as the node always took it.
    pub reversing: bool,
    /// The pedal report is fresh.
    pub pedal_fresh: bool,
    /// Ages for NODE_STATUS page 4, 10 ms units.
    pub ages_10ms: [u8; INPUT_COUNT],
}

impl Inputs {
    /// Decodes and applies one received frame; returns it if it is for another stage (GNSS,
    /// the planner's). Every rejection is counted.
    pub fn receive(&mut self, config: &NodeConfig, now_us: u64, f: &TimedFrame) -> Option<Routed> {
        if f.t_us > now_us {
            bump(&mut self.counters.time_errors);
            return None;
        }
        let decoded = match decode_input(&f.frame, config.gnss_source) {
            Err(DecodeError::UnknownId) => match decode_planner(&f.frame) {
                Ok(message) => return Some(Routed::Planner(message)),
                Err(e) => Err(e),
            },
            other => other,
        };
        let msg = match decoded {
            Ok(m) => m,
            Err(e) => {
                let c = &mut self.counters;
                bump(match e {
                    DecodeError::Crc { .. } => &mut c.crc_errors,
                    DecodeError::Dlc { .. } => &mut c.dlc_errors,
                    DecodeError::OutOfRange { .. } | DecodeError::Invalid { .. } => {
                        &mut c.range_errors
                    }
                    DecodeError::UnknownId
                    | DecodeError::WrongId
                    | DecodeError::WrongSource { .. } => &mut c.unknown_ids,
                });
                return None;
            }
        };
        match msg {
            InputMessage::Steering(m, counter) => match m.steer_pct {
                Some(p) => {
                    if self.accept(Input::Steer, counter, f.t_us) {
                        self.steer_pct = Some(p);
                    }
                }
                None => bump(&mut self.counters.range_errors),
            },
            InputMessage::Speed(m, counter) => match m.speed_mps {
                Some(v) => {
                    if self.accept(Input::Speed, counter, f.t_us) {
                        self.speeds = Some((v, m.speed_cmd_mps.unwrap_or(v)));
                        self.reverse = m.direction == Direction::Reverse;
                    }
                    // The kit says it does not know the direction: the speed is used, taken as
                    // forward (as from a kit that does not report it), and the invalid value
                    // counted (`input_invalid`).
                    if m.direction == Direction::Invalid {
                        bump(&mut self.counters.range_errors);
                    }
                }
                None => bump(&mut self.counters.range_errors),
            },
            InputMessage::Pedal(m, counter) => {
                if self.accept(Input::Pedal, counter, f.t_us) {
                    self.pedals = Some((m.accel_pct.unwrap_or(0.0), m.brake_pct.unwrap_or(0.0)));
                }
            }
            InputMessage::GnssPosition(p) => {
                return Some(Routed::Gnss(GnssMessage::Fix(GnssFix {
                    t_us: f.t_us,
                    lat_e7: p.lat_e7,
                    lon_e7: p.lon_e7,
                })))
            }
            InputMessage::GnssCogSog(c) => {
                if let (Some(cog_rad), Some(sog_mps)) = (c.cog_rad, c.sog_mps) {
                    return Some(Routed::Gnss(GnssMessage::Course(GnssCourse {
                        t_us: f.t_us,
                        cog_rad,
                        sog_mps,
                        reference: c.cog_reference,
                    })));
                }
            }
        }
        None
    }

    /// A report's rolling counter: a stuck counter (the sender repeating itself) is rejected,
    /// a jump (missed frames) is counted but the value is used. Returns whether to use it, and
    /// marks the input received then.
    fn accept(&mut self, input: Input, counter: u8, t_us: u64) -> bool {
        let Some(checker) = self.checkers.get_mut(input.index()) else {
            return false;
        };
        let verdict = checker.check(counter);
        if verdict.is_error() {
            bump(&mut self.counters.counter_errors);
        }
        if verdict.accepted() {
            self.freshness.mark(input, t_us);
        }
        verdict.accepted()
    }

    /// The fresh inputs at `now_us`.
    pub fn snapshot(&self, config: &NodeConfig, now_us: u64) -> Snapshot {
        let f = &self.freshness;
        Snapshot {
            steer_pct: self
                .steer_pct
                .filter(|_| fresh(config, f, Input::Steer, now_us)),
            speeds: self
                .speeds
                .filter(|_| fresh(config, f, Input::Speed, now_us)),
            reversing: self.reverse && fresh(config, f, Input::Speed, now_us),
            pedal_fresh: self.pedals.is_some() && fresh(config, f, Input::Pedal, now_us),
            ages_10ms: f.ages_10ms(now_us),
        }
    }
}
