//! What the node's planner input refused, and why, for `sil`'s and `replay`'s closing lines.
//!
//! The counts are the node's own ([`PlannerCounters`], read from the node before and after
//! each tick): NODE_STATUS carries only the bit `planner_refused_recently` (docs/bus.md), so
//! without this a simulator whose every path was refused read a summary that said nothing was
//! rejected. The first refusal's reason is the kind of counter that rose first; for a complete
//! path refused by its geometry, the node keeps no copy of the points it refused, so
//! [`PlannerRefusals`] keeps the points and limits of the path being sent as the node decoded
//! them (same decoder, same counter check) and asks the node's own rule
//! ([`Path::validate_for`] the node's car) what is wrong, to name the points and their
//! spacing, turn or corridor.
use std::collections::BTreeMap;
use std::fmt::Write as _;

use catmodel::can::counter::CounterChecker;
use catmodel::can::{decode_planner, PlannerMessage, TimedFrame};
use catmodel::control::path::{
    Path, PathCar, PathError, Waypoint, MAX_SEGMENT_M, MAX_TURN_RAD, MIN_PLANNED_SPACING_M,
    MIN_SEGMENT_M,
};
use catmodel::control::planner::PlannerCounters;
use catmodel::node::MAX_RX_FRAMES_PER_TICK;

/// Rolling-counter slots, one per planner message (as the node's `PlannerInputs`).
const MESSAGES: usize = PlannerMessage::KINDS;

/// A path being sent: its id, and its waypoints by index (position from PATH_POINT, speed and
/// corridor from PATH_LIMITS, each the first received for its index).
type Receiving = (u8, BTreeMap<u8, Kept>);

/// One index of the path being sent, as far as its frames have come.
#[derive(Debug, Clone, Copy, Default)]
struct Kept {
    point: Option<(f32, f32)>,
    limits: Option<(f32, f32, f32)>,
}

/// The node's planner refusals over a session and the first one's reason.
#[derive(Debug, Clone, Default)]
pub struct PlannerRefusals {
    /// The node's planner counters at the end.
    pub counters: PlannerCounters,
    /// The first refusal: the tick's time, us, and why.
    pub first: Option<(u64, String)>,
    /// The waypoints received of the path being sent: its id and its waypoints by index (the
    /// first of each index, as the node keeps it).
    receiving: Option<Receiving>,
    counter_checks: [CounterChecker; MESSAGES],
    /// The last PATH_HEADER the node's decoder refused: when, us, and why. The points that
    /// follow it are strays to the node; the summary names the header.
    header_refused: Option<(u64, String)>,
}

impl PartialEq for PlannerRefusals {
    /// Equal when the node's counts and the first reason are (the points kept to describe a
    /// refusal are a means, not a result).
    fn eq(&self, other: &Self) -> bool {
        self.counters == other.counters && self.first == other.first
    }
}

impl PlannerRefusals {
    /// One tick: `rx` the frames given to the node at `now_us`, `counters` its planner
    /// counters before and after the tick, `car` what it checks paths against.
    pub fn observe(
        &mut self,
        now_us: u64,
        rx: &[TimedFrame],
        counters: (&PlannerCounters, &PlannerCounters),
        car: &PathCar,
    ) {
        let (before, after) = counters;
        self.counters = *after;
        // The frames the node reads: its per-tick cap, none stamped after the tick.
        for f in rx.iter().take(MAX_RX_FRAMES_PER_TICK) {
            if f.t_us > now_us {
                continue;
            }
            match decode_planner(&f.frame) {
                Ok(message) => self.keep(&message),
                Err(e) if f.frame.id == catmodel::can::spec::PATH_HEADER.id => {
                    let why = match e {
                        catmodel::can::codec::DecodeError::OutOfRange { signal } => {
                            format!("its `{signal}` outside the DBC's range")
                        }
                        other => format!("{other:?}"),
                    };
                    self.header_refused = Some((f.t_us, why));
                }
                Err(_) => {}
            }
        }
        if self.first.is_none() && after.rejects() != before.rejects() {
            self.first = Some((now_us, self.reason(before, after, car)));
        }
    }

    /// Keeps the points of the path being sent, skipping frames whose counter is stuck (the
    /// node refuses those).
    fn keep(&mut self, message: &PlannerMessage) {
        let (slot, counter) = message.counter();
        if let Some(checker) = self.counter_checks.get_mut(slot) {
            if !checker.check(counter).accepted() {
                return;
            }
        }
        match *message {
            PlannerMessage::PathHeader(h, _) => self.receiving = Some((h.path_id, BTreeMap::new())),
            PlannerMessage::PathPoint(p, _) => {
                if let Some((id, points)) = self.receiving.as_mut() {
                    if *id == p.path_id {
                        let kept = points.entry(p.index).or_default();
                        kept.point.get_or_insert((p.east_m, p.north_m));
                    }
                }
            }
            PlannerMessage::PathLimits(l, _) => {
                if let Some((id, points)) = self.receiving.as_mut() {
                    if *id == l.path_id {
                        let kept = points.entry(l.index).or_default();
                        kept.limits
                            .get_or_insert((l.speed_mps, l.left_m, l.right_m));
                    }
                }
            }
            _ => {}
        }
    }

    /// Why the counters moved from `before` to `after` (the first kind that rose).
    fn reason(&self, before: &PlannerCounters, after: &PlannerCounters, car: &PathCar) -> String {
        if after.paths_invalid != before.paths_invalid {
            return self.invalid_path(car);
        }
        if after.paths_abandoned != before.paths_abandoned {
            return "a path's assembly was abandoned: a PATH_POINT or PATH_LIMITS index was \
                    skipped (a frame lost), or a new PATH_HEADER came before the path was \
                    complete; send the path again with a new header"
                .into();
        }
        if after.duplicates != before.duplicates {
            return "a PATH_POINT or PATH_LIMITS index was received twice (each goes once, in \
                    index order)"
                .into();
        }
        if after.stray_frames != before.stray_frames {
            let mut why = String::from(
                "a PATH_POINT or PATH_LIMITS of a path id not being assembled (no PATH_HEADER \
                 for it, or its assembly was abandoned)",
            );
            if let Some((t_us, refused)) = &self.header_refused {
                let _ = write!(
                    why,
                    "; the PATH_HEADER at {}.{:06} s was refused, {refused} (a path has 2 to \
                     256 points; counted under `range` or `crc` above)",
                    t_us / 1_000_000,
                    t_us % 1_000_000
                );
            }
            return why;
        }
        if after.stuck_counters != before.stuck_counters {
            return "a planner frame repeated its message's rolling counter (each planner \
                    message counts +1 per frame)"
                .into();
        }
        "a LOCAL_ORIGIN longitude page did not follow its latitude page with the next counter"
            .into()
    }

    /// The rule a refused path broke, by the node's rule on the points it decoded.
    fn invalid_path(&self, car: &PathCar) -> String {
        let Some((id, points)) = &self.receiving else {
            return "a path was refused by the node's geometry checks (docs/bus.md)".into();
        };
        let waypoints: Vec<Waypoint> = points
            .values()
            .map(|kept| {
                let (east_m, north_m) = kept.point.unwrap_or_default();
                let (speed_mps, left_m, right_m) = kept.limits.unwrap_or_default();
                Waypoint {
                    east_m,
                    north_m,
                    speed_mps,
                    left_m,
                    right_m,
                }
            })
            .collect();
        let xy: Vec<(f32, f32)> = waypoints.iter().map(|w| (w.east_m, w.north_m)).collect();
        let at = |i: usize| xy.get(i).copied().unwrap_or((0.0, 0.0));
        let dist = |a: (f32, f32), b: (f32, f32)| f64::from(b.0 - a.0).hypot(f64::from(b.1 - a.1));
        let mut text = format!("path {id} refused: ");
        let _ = match Path::validate_for(&waypoints, car) {
            Err(PathError::SegmentLength(i)) => {
                let i = usize::from(i);
                let d = dist(at(i), at(i + 1));
                let _ = write!(
                    text,
                    "points {i} and {} are {d:.3} m apart as decoded (at least {MIN_SEGMENT_M}, \
                     at most {MAX_SEGMENT_M}",
                    i + 1
                );
                if d < f64::from(MIN_SEGMENT_M) {
                    write!(
                        text,
                        "; PATH_POINT rounds each coordinate to 0.02 m: space the points at \
                         least {MIN_PLANNED_SPACING_M} m apart before encoding them)"
                    )
                } else {
                    write!(text, ")")
                }
            }
            Err(PathError::Turn(i)) => {
                let i = usize::from(i);
                let (a, b, c) = (at(i.saturating_sub(1)), at(i), at(i + 1));
                let h1 = f64::from(b.0 - a.0).atan2(f64::from(b.1 - a.1));
                let h2 = f64::from(c.0 - b.0).atan2(f64::from(c.1 - b.1));
                let mut turn = (h2 - h1).abs() % std::f64::consts::TAU;
                if turn > std::f64::consts::PI {
                    turn = std::f64::consts::TAU - turn;
                }
                write!(
                    text,
                    "it turns {:.0} degrees at point {i} (at most {:.0})",
                    turn.to_degrees(),
                    f64::from(MAX_TURN_RAD).to_degrees()
                )
            }
            Err(PathError::Corridor(i)) => {
                let w = waypoints.get(usize::from(i)).copied().unwrap_or_default();
                write!(
                    text,
                    "the corridor at point {i} is {:.2} m wide (left {:.2} + right {:.2}), \
                     narrower than the car's body ({:.2} m, the model file's vehicle width)",
                    w.left_m + w.right_m,
                    w.left_m,
                    w.right_m,
                    car.body_width_m
                )
            }
            Err(PathError::BadValue(i)) => write!(text, "point {i} has a value out of range"),
            Err(PathError::PointCount) => write!(
                text,
                "{} points (2..{})",
                xy.len(),
                catmodel::control::path::MAX_PATH_POINTS
            ),
            Ok(()) => write!(text, "by the node's geometry checks (docs/bus.md)"),
        };
        text
    }
}

impl std::fmt::Display for PlannerRefusals {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let c = &self.counters;
        write!(
            f,
            "planner: {} paths loaded, {} refused (invalid paths {}, abandoned {}, duplicate \
             indices {}, stray frames {}, stuck counters {}, unpaired origin pages {})",
            c.paths_activated,
            c.rejects(),
            c.paths_invalid,
            c.paths_abandoned,
            c.duplicates,
            c.stray_frames,
            c.stuck_counters,
            c.origin_mismatches
        )?;
        if let Some((t_us, reason)) = &self.first {
            write!(
                f,
                "; the first at {}.{:06} s: {reason}",
                t_us / 1_000_000,
                t_us % 1_000_000
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use catmodel::can::codec::{PathHeader, PathPoint};

    /// A PATH_HEADER the decoder refuses (a count over 256 goes out as 0) makes every point
    /// after it a stray; the first refusal names the header, not only the strays (a black-box
    /// probe's summary named 602 stray frames and never the header).
    #[test]
    fn a_refused_header_is_named_beside_the_strays_it_made() {
        let header = PathHeader {
            path_id: 3,
            count: 301,
        }
        .encode(0);
        let point = PathPoint {
            path_id: 3,
            index: 0,
            east_m: 1.0,
            north_m: 2.0,
        }
        .encode(0);
        let frames = [
            TimedFrame {
                t_us: 18_000,
                frame: header,
            },
            TimedFrame {
                t_us: 19_000,
                frame: point,
            },
        ];
        let before = PlannerCounters::default();
        let after = PlannerCounters {
            stray_frames: 1,
            ..before
        };
        let mut r = PlannerRefusals::default();
        let car = catmodel::node::drive::path_car(&crate::node_config(None).unwrap());
        r.observe(20_000, &frames, (&before, &after), &car);
        let (t_us, why) = r.first.clone().unwrap();
        assert_eq!(t_us, 20_000);
        assert!(
            why.contains("the PATH_HEADER at 0.018000 s was refused, its `count` outside"),
            "{why}"
        );
        // Without the refused header, the strays alone.
        let mut r = PlannerRefusals::default();
        r.observe(20_000, &frames[1..], (&before, &after), &car);
        let (_, why) = r.first.unwrap();
        assert!(!why.contains("PATH_HEADER at"), "{why}");
    }
}
