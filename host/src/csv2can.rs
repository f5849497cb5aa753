//! `catmodel csv2can`: a log in the CSV schema -> the node's input frames in candump format,
//! what a logger on the car's bus would have recorded. Every report carries its own rolling
//! counter (incremented per frame of that message) and CRC; GNSS goes out as NMEA 2000 PGN
//! 129025 from the default source address.
//!
//! What the bus cannot carry is never dropped silently: a negative time is an error (candump
//! timestamps count up from 0), and a negative speed (a signed sensor's noise around standstill,
//! or reversing: the log schema allows down to -10 m/s, the bus speed is unsigned) goes out as
//! 0 m/s and is counted in [`Encoded::negative_speeds`].
use anyhow::{bail, Result};
use catmodel::can::codec::{GnssPosition, PedalReport, SpeedReport, SteeringReport};
use catmodel::can::spec::N2K_DEFAULT_SOURCE;
use catmodel::can::TimedFrame;

use crate::logcsv::LogRow;

/// The frames of a log and what had to be adapted to the bus.
#[derive(Debug, Clone, PartialEq)]
pub struct Encoded {
    /// The frames, in time order.
    pub frames: Vec<TimedFrame>,
    /// Speed values (measured or commanded) below 0 m/s, sent as 0 m/s.
    pub negative_speeds: usize,
}

impl Encoded {
    /// A note for stderr when something was adapted.
    pub fn note(&self) -> Option<String> {
        (self.negative_speeds > 0).then(|| {
            format!(
                "{} speed value(s) below 0 m/s sent as 0 m/s (the bus speed is unsigned)",
                self.negative_speeds
            )
        })
    }
}

/// Timestamps: the log's `t` in seconds becomes microseconds on the candump's time base.
fn t_us(t: f64) -> Result<u64> {
    let us = (t * 1e6).round();
    if !(0.0..=u64::MAX as f64 / 2.0).contains(&us) {
        bail!("a row at t = {t} s: candump timestamps are microseconds from 0 (shift the log's time to start at or after 0)");
    }
    Ok(us as u64)
}

/// Encodes the rows (sorted by time, one row per instant as [`crate::logcsv::read_log`]
/// returns them). A speed report needs the measured speed; its commanded speed is the latest
/// `input_vel` seen (the two share one frame on the bus).
pub fn encode_log(rows: &[LogRow]) -> Result<Encoded> {
    let mut out = Vec::with_capacity(rows.len() * 2);
    let (mut c_steer, mut c_speed, mut c_pedal) = (0u8, 0u8, 0u8);
    let mut input_vel = None;
    let mut accel = None;
    let mut brake = None;
    let mut negative_speeds = 0;
    let mut unsigned = |v: f64| {
        if v < 0.0 {
            negative_speeds += 1;
            0.0
        } else {
            v as f32
        }
    };
    for r in rows {
        let t = t_us(r.t)?;
        if let Some(v) = r.input_vel {
            input_vel = Some(unsigned(v));
        }
        if let Some(steer) = r.steer {
            let frame = SteeringReport {
                steer_pct: Some(steer as f32),
            }
            .encode(c_steer);
            out.push(TimedFrame { t_us: t, frame });
            c_steer = (c_steer + 1) & 0x0F;
        }
        if let Some(vel) = r.vel {
            let frame = SpeedReport {
                speed_mps: Some(unsigned(vel)),
                speed_cmd_mps: input_vel,
            }
            .encode(c_speed);
            out.push(TimedFrame { t_us: t, frame });
            c_speed = (c_speed + 1) & 0x0F;
        }
        if r.accel.is_some() || r.brake.is_some() {
            accel = r.accel.or(accel);
            brake = r.brake.or(brake);
            let frame = PedalReport {
                accel_pct: accel.map(|v| v as f32),
                brake_pct: brake.map(|v| v as f32),
            }
            .encode(c_pedal);
            out.push(TimedFrame { t_us: t, frame });
            c_pedal = (c_pedal + 1) & 0x0F;
        }
        if let (Some(lat), Some(lon)) = (r.lat, r.lon) {
            let frame = GnssPosition {
                lat_e7: (lat * 1e7).round() as i32,
                lon_e7: (lon * 1e7).round() as i32,
            }
            .encode(N2K_DEFAULT_SOURCE);
            out.push(TimedFrame { t_us: t, frame });
        }
    }
    Ok(Encoded {
        frames: out,
        negative_speeds,
    })
}

/// The frames as candump text.
pub fn to_candump(frames: &[TimedFrame]) -> String {
    let mut s = String::with_capacity(frames.len() * 40);
    for f in frames {
        s.push_str(&crate::replay::candump_line(f.t_us, &f.frame));
        s.push('\n');
    }
    s
}
