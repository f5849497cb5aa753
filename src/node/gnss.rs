//! The GNSS part of stages 1 and 3: fixes into the local frame, through the plausibility gate
//! and into the lowpass ([`super::estimator`]), gaps refilled by dead reckoning; then the
//! heading (receiver COG, else the filtered track's course) and the rear-axle position.
use crate::can::freshness::Input;
use crate::geodesy::LocalFrame;
use crate::math;
use crate::model::kinematic::Pose;

use super::estimator::{self, EstimatorConfig, EstimatorState, Xy};
use super::inputs::{GnssMessage, Inputs};
use super::{bump, NodeConfig};

/// GNSS state.
#[derive(Clone, Debug, Default)]
pub struct Gnss {
    /// The local frame, from the configured origin or the first fix.
    frame: Option<LocalFrame>,
    estimator: EstimatorState,
    /// The receiver's course (rad) and its receive time, while the car moves.
    cog: Option<(f32, u64)>,
    /// Consecutive fixes the gate rejected.
    rejects_in_row: u16,
    /// When the gate last rejected a fix.
    last_reject_us: Option<u64>,
}

impl Gnss {
    /// The local frame's origin once known (lat, lon in 1e-7 deg).
    pub fn origin_e7(&self) -> Option<(i32, i32)> {
        self.frame.map(|f| (f.origin_lat_e7(), f.origin_lon_e7()))
    }

    /// The planner's map origin (LOCAL_ORIGIN, 1e-7 deg) becomes the local frame. If it differs
    /// from the frame in use, the filters restart in the new frame (the heading survives: it
    /// is the car's); returns whether the frame changed. A frame not set yet is simply set.
    pub fn set_origin(&mut self, (lat_e7, lon_e7): (i32, i32)) -> bool {
        if self.origin_e7() == Some((lat_e7, lon_e7)) {
            return false;
        }
        let Ok(frame) = LocalFrame::new(lat_e7, lon_e7) else {
            return false;
        };
        let changed = self.frame.is_some();
        self.frame = Some(frame);
        if changed {
            self.estimator.reset();
            self.rejects_in_row = 0;
        }
        changed
    }

    /// When a fix was last rejected.
    pub fn last_reject_us(&self) -> Option<u64> {
        self.last_reject_us
    }

    /// Dead reckoning over `dt_s` (see [`EstimatorState::propagate`]).
    pub fn propagate(
        &mut self,
        cfg: &EstimatorConfig,
        speed_mps: f32,
        yaw_rate_rps: f32,
        dt_s: f32,
    ) {
        self.estimator.propagate(cfg, speed_mps, yaw_rate_rps, dt_s);
    }

    /// Applies one decoded GNSS message received before `now_us`, with the car at `speed_mps`.
    pub fn receive(
        &mut self,
        config: &NodeConfig,
        now_us: u64,
        msg: &GnssMessage,
        speed_mps: f32,
        inputs: &mut Inputs,
    ) {
        match *msg {
            GnssMessage::Fix {
                t_us,
                lat_e7,
                lon_e7,
            } => self.receive_fix(config, now_us, t_us, (lat_e7, lon_e7), speed_mps, inputs),
            GnssMessage::Course {
                t_us,
                cog_rad,
                sog_mps,
                reference,
            } => {
                // COG is meaningless when standing still; only true north is understood.
                if sog_mps >= config.estimator.course_min_speed_mps && reference == 0 {
                    self.cog = Some((math::wrap_pi(cog_rad), t_us));
                }
            }
        }
    }

    fn receive_fix(
        &mut self,
        config: &NodeConfig,
        now_us: u64,
        t_us: u64,
        (lat_e7, lon_e7): (i32, i32),
        speed_mps: f32,
        inputs: &mut Inputs,
    ) {
        let counters = &mut inputs.counters;
        if self.frame.is_none() {
            let origin = config.origin_e7.unwrap_or((lat_e7, lon_e7));
            match LocalFrame::new(origin.0, origin.1) {
                Ok(frame) => self.frame = Some(frame),
                Err(_) => {
                    bump(&mut counters.gnss_gate_rejects);
                    return;
                }
            }
        }
        let Some(enu) = self.frame.and_then(|fr| fr.to_local(lat_e7, lon_e7).ok()) else {
            bump(&mut counters.gnss_gate_rejects);
            self.last_reject_us = Some(t_us);
            return;
        };
        let fix = Xy {
            x_m: enu.east_m,
            y_m: enu.north_m,
        };
        let cfg = &config.estimator;
        // Plausibility gate against where the car should be; repeated rejections mean the car
        // really is there (e.g. after a long gap): restart the filters on the fixes.
        if let Some(p) = self.estimator.antenna_position(cfg) {
            let (dx, dy) = (fix.x_m - p.x_m, fix.y_m - p.y_m);
            if dx * dx + dy * dy > config.gnss_gate_m * config.gnss_gate_m {
                self.rejects_in_row = self.rejects_in_row.saturating_add(1);
                bump(&mut counters.gnss_gate_rejects);
                self.last_reject_us = Some(t_us);
                if self.rejects_in_row < config.gnss_reacquire_fixes {
                    return;
                }
                self.estimator.reset();
            }
        }
        self.rejects_in_row = 0;
        let age_s = math::u64_to_f32(now_us.saturating_sub(t_us)) * 1e-6;
        // The lowpass assumes one fix per period. Fixes missing since the last accepted one
        // (a dropout, or fixes the gate rejected) are filled with where dead reckoning puts
        // the antenna at those instants, oldest first; no more than the filters remember.
        if let Some(prev) = inputs.freshness.last_us(Input::Gnss) {
            let gap_periods =
                math::u64_to_f32(t_us.saturating_sub(prev)) * 1e-6 / cfg.gnss_period_s;
            let missing = ((gap_periods + 0.5) as u32)
                .saturating_sub(1)
                .min(estimator::GAP_FILL_MAX_FIXES);
            for k in (1..=missing).rev() {
                let age_k = age_s + k as f32 * cfg.gnss_period_s;
                if let Some(p) = self.estimator.dead_reckoned_antenna(cfg, age_k, speed_mps) {
                    self.estimator.add_fix(cfg, p, age_k, speed_mps);
                }
            }
        }
        self.estimator.add_fix(cfg, fix, age_s, speed_mps);
        inputs.freshness.mark(Input::Gnss, t_us);
    }

    /// Stage 3's GNSS part: the heading pulled towards the receiver's COG when it is fresh, else
    /// towards the filtered track's course, while the car moves; then the rear axle's position
    /// (`None` while invalid) and whether GNSS is fresh. A receiver silent for longer than
    /// `gnss_lost_us` restarts the filters.
    pub fn estimate(
        &mut self,
        config: &NodeConfig,
        now_us: u64,
        speed_mps: f32,
        yaw_rate_rps: f32,
        inputs: &Inputs,
    ) -> (Option<Pose>, bool) {
        let cfg = &config.estimator;
        let gnss_timeout_us = config.freshness.timeout_us(Input::Gnss);
        let moving = speed_mps >= cfg.course_min_speed_mps;
        match self.cog {
            Some((cog, t)) if moving && now_us.saturating_sub(t) <= gnss_timeout_us => {
                let age_s = math::u64_to_f32(now_us.saturating_sub(t)) * 1e-6;
                self.estimator
                    .correct_heading(cfg, cog, age_s, speed_mps, yaw_rate_rps);
            }
            _ if moving => {
                if let Some((course, age_fixes)) = self.estimator.track_course(cfg) {
                    // The chord's age at the latest fix, plus the time since that fix: with
                    // a slow receiver the same chord steers the heading for a whole period,
                    // while the car keeps turning.
                    let since_fix_us = inputs
                        .freshness
                        .last_us(Input::Gnss)
                        .map_or(0, |t| now_us.saturating_sub(t));
                    let age_s =
                        age_fixes * cfg.gnss_period_s + math::u64_to_f32(since_fix_us) * 1e-6;
                    self.estimator
                        .correct_heading(cfg, course, age_s, speed_mps, yaw_rate_rps);
                }
            }
            _ => {}
        }

        let gnss_age = inputs
            .freshness
            .last_us(Input::Gnss)
            .map(|t| now_us.saturating_sub(t));
        let gnss_fresh = matches!(gnss_age, Some(a) if a <= gnss_timeout_us);
        if matches!(gnss_age, Some(a) if a > config.gnss_lost_us) && self.estimator.fixes() > 0 {
            self.estimator.reset();
        }
        let pose = match (self.estimator.position(cfg), self.estimator.heading_rad()) {
            (Some(p), Some(h)) if p.x_m.is_finite() && p.y_m.is_finite() && h.is_finite() => {
                Some(Pose::new(p.x_m, p.y_m, h))
            }
            _ => None,
        };
        (pose, gnss_fresh)
    }
}
