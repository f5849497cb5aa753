//! `catmodel csv2can`: a log in the CSV schema -> the node's input frames in candump format,
//! what a logger on the car's bus would have recorded. Every report carries its own rolling
//! counter (incremented per frame of that message) and CRC; GNSS goes out as NMEA 2000 PGN
//! 129025 from the default source address.
use catmodel::can::codec::{GnssPosition, PedalReport, SpeedReport, SteeringReport};
use catmodel::can::spec::N2K_DEFAULT_SOURCE;
use catmodel::can::TimedFrame;

use crate::logcsv::LogRow;

/// Timestamps: the log's `t` in seconds becomes microseconds on the candump's time base.
fn t_us(t: f64) -> u64 {
    (t * 1e6).round().max(0.0) as u64
}

/// Encodes the rows (sorted by time). A speed report needs the measured speed; its commanded
/// speed is the latest `input_vel` seen (the two share one frame on the bus).
pub fn encode_log(rows: &[LogRow]) -> Vec<TimedFrame> {
    let mut out = Vec::with_capacity(rows.len() * 2);
    let (mut c_steer, mut c_speed, mut c_pedal) = (0u8, 0u8, 0u8);
    let mut input_vel = None;
    let mut accel = None;
    let mut brake = None;
    for r in rows {
        let t = t_us(r.t);
        if r.input_vel.is_some() {
            input_vel = r.input_vel;
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
                speed_mps: Some(vel as f32),
                speed_cmd_mps: input_vel.map(|v| v as f32),
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
    out
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
