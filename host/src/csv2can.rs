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

/// Encodes log rows into frames one at a time, keeping what the bus keeps between rows: each
/// report's rolling counter, and the latest commanded speed and pedals (a report carries them
/// with its own measurement).
#[derive(Debug, Clone, Default)]
pub struct LogEncoder {
    counters: [u8; 3],
    input_vel: Option<f64>,
    accel: Option<f64>,
    brake: Option<f64>,
}

impl LogEncoder {
    /// An encoder that has sent nothing.
    pub fn new() -> Self {
        Self::default()
    }

    fn next_counter(&mut self, slot: usize) -> u8 {
        let c = self.counters[slot];
        self.counters[slot] = (c + 1) & 0x0F;
        c
    }

    /// Appends the frames of one row, stamped with its `t`. A speed report needs the measured
    /// speed; its commanded speed is the latest `input_vel` seen (the two share one frame).
    pub fn encode_row(&mut self, r: &LogRow, out: &mut Vec<TimedFrame>) {
        let t = t_us(r.t);
        if r.input_vel.is_some() {
            self.input_vel = r.input_vel;
        }
        if let Some(steer) = r.steer {
            let c = self.next_counter(0);
            let frame = SteeringReport {
                steer_pct: Some(steer as f32),
            }
            .encode(c);
            out.push(TimedFrame { t_us: t, frame });
        }
        if let Some(vel) = r.vel {
            let c = self.next_counter(1);
            let frame = SpeedReport {
                speed_mps: Some(vel as f32),
                speed_cmd_mps: self.input_vel.map(|v| v as f32),
            }
            .encode(c);
            out.push(TimedFrame { t_us: t, frame });
        }
        if r.accel.is_some() || r.brake.is_some() {
            self.accel = r.accel.or(self.accel);
            self.brake = r.brake.or(self.brake);
            let c = self.next_counter(2);
            let frame = PedalReport {
                accel_pct: self.accel.map(|v| v as f32),
                brake_pct: self.brake.map(|v| v as f32),
            }
            .encode(c);
            out.push(TimedFrame { t_us: t, frame });
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
}

/// Encodes the rows (sorted by time), as [`LogEncoder::encode_row`] one after the other.
pub fn encode_log(rows: &[LogRow]) -> Vec<TimedFrame> {
    let mut out = Vec::with_capacity(rows.len() * 2);
    let mut encoder = LogEncoder::new();
    for r in rows {
        encoder.encode_row(r, &mut out);
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
