//! `catmodel csv2can`: a log in the CSV schema -> the node's input frames in candump format,
//! what a logger on the car's bus would have recorded. Every report carries its own rolling
//! counter (incremented per frame of that message) and CRC; GNSS goes out as NMEA 2000 PGN
//! 129025 from the default source address.
//!
//! What the bus cannot carry is never dropped silently: a negative time is an error (candump
//! timestamps count up from 0). A negative measured speed `vel` (the log schema allows down to
//! -10 m/s: a car reversing, or a signed sensor's noise around standstill) goes out as its
//! magnitude with SPEED_REPORT `direction` = reverse, counted in [`Encoded::reverse_speeds`]
//! and noted; every other row's report says no direction (0, as every log before the signal:
//! the node takes it as forward), so a log without a negative speed gives the frames it always
//! gave. A negative commanded speed `input_vel` (the bus field is a magnitude, and the node's
//! speed model knows no reverse) goes out as 0 m/s, counted in [`Encoded::negative_speeds`].
use anyhow::{bail, Result};
use catmodel::can::codec::{Direction, GnssPosition, PedalReport, SpeedReport, SteeringReport};
use catmodel::can::spec::N2K_DEFAULT_SOURCE;
use catmodel::can::TimedFrame;

use crate::logcsv::LogRow;

/// The frames of a log and what had to be adapted to the bus.
#[derive(Debug, Clone, PartialEq)]
pub struct Encoded {
    /// The frames, in time order.
    pub frames: Vec<TimedFrame>,
    /// Commanded speeds below 0 m/s, sent as 0 m/s.
    pub negative_speeds: usize,
    /// Measured speeds below 0 m/s, sent as their magnitude with the direction "reverse".
    pub reverse_speeds: usize,
    /// Fixes a logger repeated ([`crate::logcsv::held_fix_repeats`]), not sent: a receiver
    /// sends each fix once.
    pub held_fixes: Option<crate::logcsv::HeldFixes>,
}

impl Encoded {
    /// A note for stderr when something was adapted.
    pub fn note(&self) -> Option<String> {
        let mut notes = Vec::new();
        if self.reverse_speeds > 0 {
            notes.push(format!(
                "{} measured speed(s) `vel` below 0 m/s sent as reversing: SPEED_REPORT carries \
                 the magnitude with direction = 2 (reverse); the other rows' reports say no \
                 direction (0), which the node takes as forward",
                self.reverse_speeds
            ));
        }
        if self.negative_speeds > 0 {
            notes.push(format!(
                "{} commanded speed(s) `input_vel` below 0 m/s sent as 0 m/s (the bus's commanded \
                 speed is unsigned)",
                self.negative_speeds
            ));
        }
        if let Some(held) = &self.held_fixes {
            notes.push(format!(
                "{}: not sent as GNSS frames (a receiver sends each fix once, and the node \
                 takes a fix that comes faster than its model file's `gnss_rate_hz` for another \
                 receiver's); the fixes that change go out at the receiver's {:.1} Hz",
                held.describe(),
                1.0 / held.receiver_period_s
            ));
        }
        (!notes.is_empty()).then(|| notes.join("; "))
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

/// Encodes log rows into frames one at a time, keeping what the bus keeps between rows: each
/// report's rolling counter, the latest commanded speed and pedals (a report carries them with
/// its own measurement), and the count of negative speeds sent as 0.
#[derive(Debug, Clone, Default)]
pub struct LogEncoder {
    counters: [u8; 3],
    input_vel: Option<f32>,
    accel: Option<f64>,
    brake: Option<f64>,
    negative_speeds: usize,
    reverse_speeds: usize,
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

    /// A speed for the unsigned bus field: negative values go out as 0, counted.
    fn unsigned(&mut self, v: f64) -> f32 {
        if v < 0.0 {
            self.negative_speeds += 1;
            0.0
        } else {
            v as f32
        }
    }

    /// Commanded speeds below 0 m/s sent as 0 m/s so far.
    pub fn negative_speeds(&self) -> usize {
        self.negative_speeds
    }

    /// Measured speeds below 0 m/s sent as reversing so far.
    pub fn reverse_speeds(&self) -> usize {
        self.reverse_speeds
    }

    /// Appends the frames of one row, stamped with its `t`. A speed report needs the measured
    /// speed; its commanded speed is the latest `input_vel` seen (the two share one frame).
    pub fn encode_row(&mut self, r: &LogRow, out: &mut Vec<TimedFrame>) -> Result<()> {
        let t = t_us(r.t)?;
        if let Some(v) = r.input_vel {
            self.input_vel = Some(self.unsigned(v));
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
            let direction = if vel < 0.0 {
                self.reverse_speeds += 1;
                Direction::Reverse
            } else {
                Direction::NotReported
            };
            let c = self.next_counter(1);
            let frame = SpeedReport {
                speed_mps: Some(vel.abs() as f32),
                speed_cmd_mps: self.input_vel,
                direction,
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
        Ok(())
    }
}

/// Encodes the rows (sorted by time, one row per instant as [`crate::logcsv::read_log`]
/// returns them), as [`LogEncoder::encode_row`] one after the other.
///
/// Fixes a logger repeated (sample and hold, [`crate::logcsv::held_fix_repeats`]) are not
/// sent: the row goes out without its GNSS frame. Before, a 10 Hz receiver held at 100 Hz went
/// out as 100 fixes a second, which no receiver sends, and a node declared for 10 Hz took
/// nine in ten for another receiver's.
pub fn encode_log(rows: &[LogRow]) -> Result<Encoded> {
    let mut frames = Vec::with_capacity(rows.len() * 2);
    let mut encoder = LogEncoder::new();
    let fix_rows: Vec<usize> = (0..rows.len())
        .filter(|&i| rows[i].lat.is_some() && rows[i].lon.is_some())
        .collect();
    let t: Vec<f64> = fix_rows.iter().map(|&i| rows[i].t).collect();
    let fixes: Vec<(f64, f64)> = fix_rows
        .iter()
        .map(|&i| (rows[i].lat.unwrap_or(0.0), rows[i].lon.unwrap_or(0.0)))
        .collect();
    let held_fixes = crate::logcsv::held_fix_repeats(&t, &fixes);
    let mut held_row = vec![false; rows.len()];
    for &k in held_fixes.iter().flat_map(|h| &h.repeats) {
        held_row[fix_rows[k]] = true;
    }
    for (r, held) in rows.iter().zip(held_row) {
        if held {
            let r = LogRow {
                lat: None,
                lon: None,
                ..*r
            };
            encoder.encode_row(&r, &mut frames)?;
        } else {
            encoder.encode_row(r, &mut frames)?;
        }
    }
    Ok(Encoded {
        frames,
        negative_speeds: encoder.negative_speeds(),
        reverse_speeds: encoder.reverse_speeds(),
        held_fixes,
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
