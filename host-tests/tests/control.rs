//! The controller's core parts (`catmodel::control`): path geometry against hand-derived cases
//! and properties, path assembly from the planner's frames with every rejection rule, and the
//! reference controller (pure pursuit + PI) against hand-derived steering.
use catmodel::can::codec::{
    ControlStatus, LocalOrigin, Obstacle, ObstacleCircle, PathHeader, PathLimits, PathPoint,
    PlannerMessage,
};
use catmodel::control::path::{
    LateralLimit, Narrowest, Path, PathCar, PathError, Projection, Waypoint, CORRIDOR_TOLERANCE_M,
    MAX_PATH_POINTS, MIN_PLANNED_SPACING_M, MIN_SEGMENT_M, NARROWEST_TIE_M,
};
use catmodel::control::planner::{
    ObstacleMotion, PlannerEvent, PlannerInputs, OBSTACLE_STILL_MPS, OBSTACLE_VELOCITY_SPAN_US,
};
use catmodel::control::pure_pursuit::{
    CarState, PurePursuitConfig, PurePursuitState, PurePursuitTuning, DEFAULT_TUNING,
};
use catmodel::model::kinematic::Pose;
use catmodel::vehicle::{Body, VehicleParams};
use proptest::prelude::*;
use std::f32::consts::FRAC_PI_2;
use std::f64::consts::PI;

fn wp(east: f64, north: f64) -> Waypoint {
    Waypoint {
        east_m: east as f32,
        north_m: north as f32,
        speed_mps: 5.0,
        left_m: 1.0,
        right_m: 1.5,
    }
}

fn path_of(points: &[Waypoint]) -> Path {
    let mut p = Path::new();
    p.load(points).expect("valid path");
    p
}

/// Straight path from `(e0, n0)` with heading `h` (clockwise from north), `n` points `d` apart.
fn straight(e0: f64, n0: f64, h: f64, n: usize, d: f64) -> Vec<Waypoint> {
    (0..n)
        .map(|i| wp(e0 + i as f64 * d * h.sin(), n0 + i as f64 * d * h.cos()))
        .collect()
}

/// Circle of radius `r` centred at the origin, driven clockwise (a right turn) from north
/// of... `n` points, arc spacing `d`, starting at angle 0 (the point (0, r), heading east).
fn clockwise_circle(r: f64, n: usize, d: f64) -> Vec<Waypoint> {
    (0..n)
        .map(|i| {
            let a = i as f64 * d / r;
            wp(r * a.sin(), r * a.cos())
        })
        .collect()
}

// ------------------------------------------------------------------------------------------
// Geometry, hand-derived

#[test]
fn straight_path_north_projection_and_reference() {
    let p = path_of(&straight(0.0, 0.0, 0.0, 11, 1.0));
    assert_eq!(p.len(), 11);
    assert_eq!(p.length_m(), 10.0);
    // Heading north: right of the path is east.
    let q = p.project(0.7, 4.25, None).unwrap();
    assert!((q.station_m - 4.25).abs() < 1e-6 && (q.lateral_m - 0.7).abs() < 1e-6);
    let q = p.project(-2.0, 9.5, None).unwrap();
    assert!((q.station_m - 9.5).abs() < 1e-6 && (q.lateral_m + 2.0).abs() < 1e-6);
    // The end segments extend: before the start and beyond the end.
    let q = p.project(0.0, -3.0, None).unwrap();
    assert!((q.station_m + 3.0).abs() < 1e-6);
    let q = p.project(0.5, 12.0, None).unwrap();
    assert!((q.station_m - 12.0).abs() < 1e-6 && (q.lateral_m - 0.5).abs() < 1e-6);
    let s = p.sample(4.5, 0).unwrap();
    assert_eq!((s.east_m, s.north_m, s.heading_rad), (0.0, 4.5, 0.0));
    assert_eq!((s.curvature_per_m, s.speed_mps, s.left_m), (0.0, 5.0, 1.0));
    // Beyond the end: straight on, at speed 0; before the start: the first point.
    let s = p.sample(13.0, 0).unwrap();
    assert_eq!((s.north_m, s.station_m, s.speed_mps), (13.0, 13.0, 0.0));
    let s = p.sample(-1.0, 5).unwrap();
    assert_eq!((s.north_m, s.station_m, s.speed_mps), (0.0, 0.0, 5.0));
}

#[test]
fn corner_reference_is_continuous_and_its_curvature_hand_derived() {
    // East 10 m then a 30 deg turn to the right (heading pi/2 -> pi/2 + pi/6), 1 m points.
    let mut pts = straight(0.0, 0.0, PI / 2.0, 6, 1.0);
    let h2 = PI / 2.0 + PI / 6.0;
    for i in 1..6 {
        pts.push(wp(5.0 + i as f64 * h2.sin(), i as f64 * h2.cos()));
    }
    let p = path_of(&pts);
    // Points 1 m apart, baseline 1 m: the reference heading at point i is the direction of the
    // chord from point i - 1 to point i + 1: pi/2 up to point 4, at the corner (point 5) the
    // chord (4, 0) -> (5 + sin h2, cos h2) = (1.866, -0.5), pi/2 + atan(0.5 / 1.866) =
    // pi/2 + pi/12, from point 6 on h2 = pi/2 + pi/6. The curvature at point i is the heading
    // change from i - 1 to i + 1 over 2 m: pi/24 at points 4 and 6, pi/12 at 5, 0 elsewhere;
    // linear in between (at 4.5: pi/16). Positive: a right turn.
    for (s, k) in [
        (3.0, 0.0),
        (3.5, PI / 48.0),
        (4.0, PI / 24.0),
        (4.5, PI / 16.0),
        (5.0, PI / 12.0),
        (6.0, PI / 24.0),
        (7.0, 0.0),
    ] {
        let sample = p.sample(s as f32, 0).unwrap();
        assert!(
            (f64::from(sample.curvature_per_m) - k).abs() < 1e-5,
            "{s}: {}",
            sample.curvature_per_m
        );
    }
    // The curvature integrates to the corner's 30 degrees (trapezoids between the points).
    let turn: f64 = (0..10)
        .map(|i| {
            let k = |s: f64| f64::from(p.sample(s as f32, 0).unwrap().curvature_per_m);
            0.5 * (k(i as f64) + k(i as f64 + 1.0))
        })
        .sum();
    assert!((turn - PI / 6.0).abs() < 1e-5, "{turn}");
    // Heading: pi/2 up to 4, then linear between the points' values.
    let h = |s: f32| f64::from(p.sample(s, 0).unwrap().heading_rad);
    assert!((h(4.0) - PI / 2.0).abs() < 1e-5);
    assert!((h(4.5) - (PI / 2.0 + PI / 24.0)).abs() < 1e-5);
    assert!((h(5.0) - (PI / 2.0 + PI / 12.0)).abs() < 1e-5);
    assert!((h(5.5) - (PI / 2.0 + PI / 8.0)).abs() < 1e-5);
    assert!((h(6.0) - h2).abs() < 1e-5);
    // Continuity: no step anywhere along the path.
    let mut prev = h(0.0);
    for k in 1..=1000 {
        let now = h(k as f32 * 0.01);
        assert!(
            (now - prev).abs() < 0.01,
            "heading step at {}",
            k as f32 * 0.01
        );
        prev = now;
    }
    // A point outside the corner projects onto the corner itself: its offset is the distance.
    let q = p.project(5.0 - 0.3, 1.0, None).unwrap();
    assert!(q.lateral_m < 0.0, "left of the path: {q:?}");
}

#[test]
fn circle_curvature_within_the_documented_bound() {
    // The car's tightest circle, R = 5.58 m, points 1 m of arc apart (chords c = 2 R sin(phi/2)).
    let r = 5.58;
    let p = path_of(&clockwise_circle(r, 30, 1.0));
    let phi: f64 = 1.0 / r;
    let c = 2.0 * r * (phi / 2.0).sin();
    let expected = phi / c;
    assert!((expected * r - 1.0).abs() <= c * c / (24.0 * r * r) * 1.01);
    // From two baselines (two points here: the chords are just under 1 m) after the start, the
    // chords around a point are symmetric: the heading is the tangent's and the curvature
    // phi / c. (Closer to an end, the one-sided chord rounds it: 0.875 phi / c at 3 m.)
    for s in [4.5f32, 7.7, 12.2, 20.0] {
        let k = f64::from(p.sample(s, 0).unwrap().curvature_per_m);
        assert!(
            (k - expected).abs() < 1e-5 * expected,
            "{s}: {k} vs {expected}"
        );
    }
}

/// A straight path north, a point every metre to 100 m, at `fast` m/s up to station
/// `step_at` and `slow` from there on.
fn stepped(fast: f32, slow: f32, step_at: usize) -> Vec<Waypoint> {
    straight(0.0, 0.0, 0.0, 101, 1.0)
        .into_iter()
        .enumerate()
        .map(|(i, w)| Waypoint {
            speed_mps: if i < step_at { fast } else { slow },
            ..w
        })
        .collect()
}

#[test]
fn the_target_speed_meets_every_later_target_and_the_end_at_the_paths_braking() {
    // Hand-derived: at braking a, the speed at station s is no more than
    // sqrt(v_j^2 + 2 a (s_j - s)) for every later point j, the end (100 m) at 0.
    let mut p = path_of(&stepped(20.0, 5.0, 60));
    assert_eq!(p.braking_mps2(), 3.0);
    let speed = |p: &Path, s: f32| p.sample(s, 0).expect("on the path").speed_mps;
    let close = |got: f32, want: f64| {
        assert!((f64::from(got) - want).abs() < 2e-3, "{got} vs {want}");
    };
    // 60 m before the step its 5 m/s binds already (19.62 < 20).
    close(speed(&p, 0.0), (25.0f64 + 6.0 * 60.0).sqrt());
    // Before the step: the step's 5 m/s at 3 m/s^2.
    close(speed(&p, 30.0), (25.0f64 + 6.0 * 30.0).sqrt());
    close(speed(&p, 59.5), (25.0f64 + 6.0 * 0.5).sqrt());
    // Between the step's points (59 -> 60) the points' own line is lower: 20 -> 5.
    close(
        speed(&p, 59.9),
        (20.0 - 15.0 * 0.9f64).min((25.0f64 + 0.6).sqrt()),
    );
    // After it the points' 5 m/s, until the end's stop binds: sqrt(2 a (100 - s)) < 5 from
    // 95.83 m on.
    close(speed(&p, 80.0), 5.0);
    close(speed(&p, 99.0), 6.0f64.sqrt());
    close(speed(&p, 100.0), 0.0);
    // The geometry's sample is the same but for the speed: the points' own.
    let (full, geometry) = (
        p.sample(30.0, 0).unwrap(),
        p.sample_geometry(30.0, 0).unwrap(),
    );
    assert_eq!(geometry.speed_mps, 20.0);
    assert_eq!(
        catmodel::control::path::PathSample {
            speed_mps: full.speed_mps,
            ..geometry
        },
        full
    );
    // Another braking envelopes the loaded path again, and every later one.
    assert!(p.set_braking(1.5));
    close(speed(&p, 30.0), (25.0f64 + 3.0 * 30.0).sqrt());
    assert!(!p.set_braking(f32::NAN) && !p.set_braking(0.0) && !p.set_braking(-1.0));
    assert_eq!(p.braking_mps2(), 1.5);
    p.load(&stepped(10.0, 10.0, 0)).expect("valid path");
    close(speed(&p, 90.0), 10.0f64.min((3.0f64 * 10.0).sqrt()));
}

/// 50 m north, a half circle of radius `r` to the right, 50 m south: a point every metre, the
/// corridor 1.5 m each side, every target 30 m/s. Returns the points and the arc's stations.
fn hairpin(r: f64) -> (Vec<Waypoint>, (f64, f64)) {
    hairpin_in(r, 1.5)
}

/// [`hairpin`]'s path in a corridor `half_m` to either side: 50 m north, a right half circle
/// of radius `r` (points about a metre apart, the first at its start), 50 m back south; the
/// arc's stations.
fn hairpin_in(r: f64, half_m: f32) -> (Vec<Waypoint>, (f64, f64)) {
    let mut points = Vec::new();
    let mut push = |e: f64, n: f64| {
        points.push(Waypoint {
            speed_mps: 30.0,
            left_m: half_m,
            right_m: half_m,
            ..wp(e, n)
        })
    };
    for i in 0..50 {
        push(0.0, f64::from(i));
    }
    let arc = PI * r;
    let steps = arc.round() as usize;
    for i in 0..steps {
        let a = PI * i as f64 / steps as f64;
        push(r - r * a.cos(), 50.0 + r * a.sin());
    }
    for i in 0..=50 {
        push(2.0 * r, 50.0 - f64::from(i));
    }
    (points, (50.0, 50.0 + arc))
}

#[test]
fn a_turn_is_held_to_the_lateral_limit_cut_through_its_corridor() {
    // Hand-derived bounds: every window's turn phi over L metres is driven on a radius of
    // L / phi + w / (1 - cos(phi / 2)) (the racing line through it, w the corridor's room),
    // which for a window of a circle's arc is at least R + w (half a turn or more), and every
    // point of the half circle (62.8 m) is an end of a window of 32 m that holds a quarter turn
    // of it or more: 32 / (pi / 2) + w / (1 - cos(pi / 4)) at most. Between points the
    // envelope allows the braking from the next point's limit (3 m/s^2 over at most a metre).
    // So the speed on the arc lies between sqrt(a (R + w)) and that radius's speed.
    let (r, a, width) = (20.0f64, 6.0f64, 1.8f64);
    let w = 3.0 - width;
    let (points, (arc_start, arc_end)) = hairpin(r);
    let mut p = path_of(&points);
    let speed = |p: &Path, s: f64| f64::from(p.sample(s as f32, 0).unwrap().speed_mps);
    let unlimited: Vec<f64> = (0..300).map(|k| speed(&p, f64::from(k))).collect();
    assert!(p.set_lateral_limit(Some(LateralLimit {
        accel_mps2: a as f32,
        width_m: width as f32,
    })));
    let low = (a * (r + w)).sqrt();
    let high = (a * (32.0 / (PI / 2.0) + w / (1.0 - (PI / 4.0).cos())) + 6.0).sqrt();
    let mut s = arc_start;
    while s <= arc_end {
        let v = speed(&p, s);
        assert!(
            v >= low * 0.999 && v <= high * 1.001,
            "{s} m: {v} m/s, not within {low}..{high}"
        );
        s += 0.25;
    }
    // Before the arc the car brakes for it at the path's 3 m/s^2, and 30 m past it is as
    // without the limit (the stop at the path's end).
    let before = speed(&p, arc_start - 20.0);
    assert!(before <= (high * high + 6.0 * 20.0).sqrt(), "{before}");
    let past = (arc_end + 30.0).round();
    assert_eq!(speed(&p, past), unlimited[past as usize]);
    // Refused: a limit or width that is not finite and positive (the limit stays); lifted:
    // the envelope as before, to the bit.
    for (accel, width) in [(f32::NAN, 1.8), (0.0, 1.8), (-1.0, 1.8), (6.0, 0.0)] {
        assert!(!p.set_lateral_limit(Some(LateralLimit {
            accel_mps2: accel,
            width_m: width
        })));
    }
    assert!(speed(&p, arc_start + 30.0) <= high * 1.001);
    assert!(p.set_lateral_limit(None));
    let lifted: Vec<f64> = (0..300).map(|k| speed(&p, f64::from(k))).collect();
    assert_eq!(lifted, unlimited);
}

#[test]
fn a_straight_path_or_a_turn_within_the_limit_is_not_slowed() {
    // No turn: the targets as they were, to the bit. A wide arc (R = 200 m) at 25 m/s asks
    // 3.1 m/s^2, under a limit of 6.
    let limit = Some(LateralLimit {
        accel_mps2: 6.0,
        width_m: 1.8,
    });
    let straight_path = stepped(20.0, 5.0, 60);
    let mut p = path_of(&straight_path);
    let before: Vec<f32> = (0..101)
        .map(|k| p.sample(k as f32, 0).unwrap().speed_mps)
        .collect();
    assert!(p.set_lateral_limit(limit));
    let after: Vec<f32> = (0..101)
        .map(|k| p.sample(k as f32, 0).unwrap().speed_mps)
        .collect();
    assert_eq!(before, after);
    let wide: Vec<Waypoint> = (0..200)
        .map(|i| {
            let a = f64::from(i) * 0.5 / 200.0;
            Waypoint {
                speed_mps: 25.0,
                ..wp(200.0 - 200.0 * a.cos(), 200.0 * a.sin())
            }
        })
        .collect();
    let mut p = path_of(&wide);
    let speeds = |p: &Path| -> Vec<f32> {
        (0..100)
            .map(|k| p.sample(k as f32, 0).unwrap().speed_mps)
            .collect()
    };
    let before = speeds(&p);
    assert!(p.set_lateral_limit(limit));
    assert_eq!(speeds(&p), before);
}

#[test]
fn a_stop_ahead_is_the_first_point_with_no_speed_or_the_end() {
    // A stop line at 70 m (every point from there at 0), from a launch at 0 m/s.
    let mut points = stepped(8.0, 0.0, 70);
    points[0].speed_mps = 0.0;
    let p = path_of(&points);
    // The launch point behind the car is not a stop ahead of it.
    assert_eq!(p.stop_ahead_m(0.5, 0), 69.5);
    assert_eq!(p.stop_ahead_m(10.0, 0), 60.0);
    // At the line, and past it (on the line's own segment: negative).
    assert_eq!(p.stop_ahead_m(69.5, 0), 0.5);
    assert_eq!(p.stop_ahead_m(70.0, 69), 0.0);
    assert_eq!(p.stop_ahead_m(70.5, 69), -0.5);
    // A launch from several points at 0 has no stop either.
    let mut launch = stepped(8.0, 8.0, 0);
    launch[0].speed_mps = 0.0;
    launch[1].speed_mps = 0.0;
    assert_eq!(path_of(&launch).stop_ahead_m(0.0, 0), 100.0);
    // No zero point: the end; beyond it negative.
    let q = path_of(&stepped(8.0, 8.0, 0));
    assert_eq!(q.stop_ahead_m(25.0, 0), 75.0);
    assert_eq!(q.stop_ahead_m(101.0, 99), -1.0);
    assert!(Path::new().stop_ahead_m(1.0, 0) < 0.0);
}

#[test]
fn the_largest_curvature_is_the_loaded_paths_and_follows_every_load() {
    // A circle's largest reference curvature is its own, phi / c (the chords' rounding, as
    // above); mirrored into a left turn it counts without its sign.
    let r = 5.58;
    let circle = clockwise_circle(r, 30, 1.0);
    let phi: f64 = 1.0 / r;
    let expected = phi / (2.0 * r * (phi / 2.0).sin());
    let mut p = path_of(&circle);
    let k = f64::from(p.max_curvature_per_m());
    assert!((k - expected).abs() < 1e-5 * expected, "{k} vs {expected}");
    let left: Vec<Waypoint> = circle
        .iter()
        .map(|w| Waypoint {
            east_m: -w.east_m,
            ..*w
        })
        .collect();
    let mut q = path_of(&left);
    assert_eq!(q.max_curvature_per_m(), p.max_curvature_per_m());
    // A refused load leaves the path, and its largest curvature, as they were.
    let mut bad = circle.clone();
    bad[3].east_m = f32::NAN;
    assert!(p.load(&bad).is_err());
    assert_eq!(p.max_curvature_per_m(), q.max_curvature_per_m());
    // A straight path loaded over the circle has none; a cleared path none either.
    p.load(&straight(0.0, 0.0, 0.3, 20, 1.0))
        .expect("valid path");
    assert!(
        p.max_curvature_per_m() < 1e-4,
        "{}",
        p.max_curvature_per_m()
    );
    q.clear();
    assert_eq!(q.max_curvature_per_m(), 0.0);
    assert_eq!(Path::new().max_curvature_per_m(), 0.0);
}

#[test]
fn reference_is_insensitive_to_the_bus_quantisation() {
    // A right-hand circle of R = 25 m from north (heading = arc / R; 0.04 1/m: the double lane change's curves at 10 m/s) sampled
    // every 0.5 m and rounded to the bus's 0.02 m: the single segments' headings scatter by up
    // to 0.02 / 0.5 = 0.04 rad (0.08 1/m of curvature); the reference stays within 0.014 rad of the tangent and
    // 0.014 1/m of the curvature (the bounds in the module doc).
    let r = 25.0;
    let pts: Vec<Waypoint> = (0..120)
        .map(|i| {
            let a = i as f64 * 0.5 / r;
            let (e, n) = (r * (1.0 - a.cos()), r * a.sin());
            wp((e / 0.02).round() * 0.02, (n / 0.02).round() * 0.02)
        })
        .collect();
    let p = path_of(&pts);
    let mut s = 4.0f32;
    while s < 55.0 {
        let x = p.sample(s, 0).unwrap();
        // The tangent where the sample lies (centre (R, 0)): stations of rounded points are
        // not quite arc lengths.
        let tangent = f64::from(x.north_m).atan2(r - f64::from(x.east_m));
        let heading_error = (f64::from(x.heading_rad) - tangent).abs();
        assert!(
            heading_error < 0.014,
            "{s}: heading {} vs {tangent}",
            x.heading_rad
        );
        assert!(
            (f64::from(x.curvature_per_m) - 1.0 / r).abs() < 0.014,
            "{s}: curvature {}",
            x.curvature_per_m
        );
        s += 0.1;
    }
}

#[test]
fn a_loop_whose_end_points_at_its_start_is_not_taken_for_its_end() {
    // An octagon-like loop (45 degree turns) whose last segment runs west along north = 0
    // towards the start: extended beyond the end, it passes through the start. A car just right
    // of the start is 0.2 m from the first segment and on the extension's line, but 5.8 m from
    // the end itself: it is at the start (station 0), not 6 m beyond the end (found by the
    // property below; its seed is in control.proptest-regressions).
    let p = path_of(&[
        wp(0.0, 0.0),
        wp(0.0, 10.0),
        wp(5.0, 15.0),
        wp(10.0, 15.0),
        wp(15.0, 10.0),
        wp(15.0, 5.0),
        wp(10.0, 0.0),
        wp(6.0, 0.0),
    ]);
    let length = 24.0 + 3.0 * 50f32.sqrt();
    assert!((p.length_m() - length).abs() < 1e-4);
    let q = p.project(0.2, 0.0, None).unwrap();
    assert_eq!(q.segment, 0);
    assert!(
        q.station_m.abs() < 1e-6 && (q.lateral_m - 0.2).abs() < 1e-6,
        "{q:?}"
    );
    // Beyond the end (2 m on, 0.1 m north of the line, which is its right: heading west), the
    // last segment is the nearest still, and the station is measured along its extension.
    let q = p.project(4.0, 0.1, None).unwrap();
    assert_eq!(q.segment, 6);
    assert!((q.station_m - (length + 2.0)).abs() < 1e-4, "{q:?}");
    assert!((q.lateral_m - 0.1).abs() < 1e-5, "{q:?}");
    // Before the start, the first segment extends backwards the same way.
    let q = p.project(-0.3, -1.5, None).unwrap();
    assert_eq!(q.segment, 0);
    assert!(
        (q.station_m + 1.5).abs() < 1e-5 && (q.lateral_m + 0.3).abs() < 1e-5,
        "{q:?}"
    );
}

/// The rig's parking loop (`closed-loop --scenario loop`): east 40 m, a half circle of radius
/// 20 m to the left, west 40 m, a half circle back to the start; points about 1 m apart, the
/// last one the first.
fn closed_loop() -> Vec<Waypoint> {
    catmodel_host::closed_loop::scenario::parking_loop(5.0)
        .path
        .iter()
        .map(|p| wp(p.east_m, p.north_m))
        .collect()
}

#[test]
fn a_car_without_a_projection_is_at_the_start_of_a_closed_loop() {
    let p = path_of(&closed_loop());
    let length = p.length_m();
    // Heading east at the start: a fix 0.5 m behind it lies on the loop's last segment, nearer
    // than to the first one's extension (0.5 m); the car is starting the loop all the same.
    for (east, north) in [(-0.5f32, 0.02f32), (-0.5, -0.3), (0.0, 0.0), (0.3, 0.1)] {
        let pose = Pose::new(east, north, FRAC_PI_2);
        let t = p.track(&pose, None).unwrap();
        assert_eq!(t.projection.segment, 0, "({east}, {north}): {t:?}");
        assert!((t.projection.station_m - east).abs() < 1e-4, "{t:?}");
        // The same fix, tracked from the loop's last metres, is at its end.
        let late = Projection {
            segment: p.len() - 3,
            station_m: length - 1.5,
            lateral_m: 0.0,
        };
        let t = p.track(&pose, Some(&late)).unwrap();
        assert!(
            t.projection.station_m > length - 1.0,
            "({east}, {north}): {t:?}"
        );
    }
    // Halfway along the loop's far straight the car is there, not at the start (the half
    // circle's chords make its stations a little short of the arc's).
    let t = p.track(&Pose::new(20.0, 40.1, -FRAC_PI_2), None).unwrap();
    let expected = 40.0 + PI as f32 * 20.0 + 20.0;
    assert!((t.projection.station_m - expected).abs() < 0.1, "{t:?}");
}

#[test]
fn a_car_ahead_of_a_paths_start_is_placed_where_it_is() {
    // A planner's path that starts 15 m behind the car (north, points 1 m apart): the first
    // 10 m end 5 m behind it, a corner of the stretch, not a foot; the whole path's nearest
    // point is taken.
    let p = path_of(&straight(0.0, 0.0, 0.0, 40, 1.0));
    for north in [10.5f32, 11.5, 15.0, 30.0] {
        let t = p.track(&Pose::new(0.4, north, 0.0), None).unwrap();
        assert!(
            (t.projection.station_m - north).abs() < 1e-4,
            "{north}: {t:?}"
        );
        assert!(
            (t.projection.lateral_m - 0.4).abs() < 1e-4,
            "{north}: {t:?}"
        );
    }
    assert!(p.track(&Pose::new(f32::NAN, 1.0, 0.0), None).is_none());
}

// ------------------------------------------------------------------------------------------
// Properties

fn arb_path() -> impl Strategy<Value = Vec<Waypoint>> {
    // A random path a car can drive: start, heading, then per point a spacing of 0.3..3 m and
    // a curvature within +-0.15 1/m (radius >= 6.7 m; the CAT Vehicle's tightest is 5.6 m).
    (
        -500.0f64..500.0,
        -500.0f64..500.0,
        -PI..PI,
        prop::collection::vec((-0.15f64..0.15, 0.3f64..3.0), 2..120),
    )
        .prop_map(|(e, n, h0, steps)| {
            let mut pts = vec![wp(e, n)];
            let (mut e, mut n, mut h) = (e, n, h0);
            for (curvature, d) in steps {
                h += curvature * d;
                e += d * h.sin();
                n += d * h.cos();
                pts.push(wp(e, n));
            }
            pts
        })
}

proptest! {
    /// A point of the path projects onto itself: zero lateral error, its own station.
    #[test]
    fn a_point_on_the_path_projects_to_itself(pts in arb_path(), f in 0.0f32..1.0) {
        let p = path_of(&pts);
        let s = f * p.length_m();
        let on = p.sample(s, 0).unwrap();
        let q = p.project(on.east_m, on.north_m, None).unwrap();
        prop_assert!(q.lateral_m.abs() < 2e-3, "{q:?}");
        // The path may pass near itself elsewhere; the point found is as near (0 m).
        let back = p.sample(q.station_m, q.segment).unwrap();
        let d = ((back.east_m - on.east_m).powi(2) + (back.north_m - on.north_m).powi(2)).sqrt();
        prop_assert!(d < 2e-3, "{d}");
    }

    /// Walking along the path (or beside it, closer than its radius of curvature), the tracked
    /// projection's station never goes back, from the first (a random path may cross itself
    /// at its start, or end pointing at it: seeds in control.proptest-regressions).
    #[test]
    fn station_is_monotone_along_the_path(pts in arb_path(), offset in -0.5f32..0.5) {
        let p = path_of(&pts);
        let mut prev = None;
        let mut last_station = f32::NEG_INFINITY;
        let n = 200;
        for k in 0..=n {
            let s = p.length_m() * k as f32 / n as f32;
            let on = p.sample(s, 0).unwrap();
            let (sin_h, cos_h) = (on.heading_rad.sin(), on.heading_rad.cos());
            // A car beside the path (its right normal is (cos h, -sin h)).
            let (e, nn) = (on.east_m + offset * cos_h, on.north_m - offset * sin_h);
            let q = p.track(&Pose::new(e, nn, on.heading_rad), prev.as_ref()).unwrap().projection;
            prop_assert!(q.station_m >= last_station - 0.05, "{} after {}", q.station_m, last_station);
            if k == 0 {
                // Beside the start along the rounded heading's normal, which is not the first
                // segment's: within the offset of station 0.
                prop_assert!(q.station_m.abs() <= offset.abs() + 1e-3, "starts at {q:?}");
            }
            last_station = q.station_m;
            prev = Some(q);
        }
    }

    /// On a straight path in any direction, an offset along the right normal is the lateral
    /// error, exactly (to f32 rounding at the path's distance from the origin).
    #[test]
    fn lateral_error_is_the_offset_on_straight_paths(
        e0 in -1000.0f64..1000.0, n0 in -1000.0f64..1000.0, h in -PI..PI,
        f in 0.05f64..0.95, offset in -5.0f64..5.0,
    ) {
        let p = path_of(&straight(e0, n0, h, 20, 1.0));
        let s = 19.0 * f;
        let (e, n) = (e0 + s * h.sin() + offset * h.cos(), n0 + s * h.cos() - offset * h.sin());
        let q = p.project(e as f32, n as f32, None).unwrap();
        prop_assert!((f64::from(q.lateral_m) - offset).abs() < 1e-3, "{q:?} vs {offset}");
        prop_assert!((f64::from(q.station_m) - s).abs() < 1e-3, "{q:?} vs {s}");
    }

    /// Sampling many stations at once equals sampling each alone.
    #[test]
    fn sample_stations_equals_single_samples(pts in arb_path(), fs in prop::collection::vec(0.0f32..1.2, 1..20)) {
        let p = path_of(&pts);
        let mut stations: Vec<f32> = fs.iter().map(|f| f * p.length_m()).collect();
        stations.sort_by(f32::total_cmp);
        let mut out = vec![Default::default(); stations.len()];
        prop_assert_eq!(p.sample_stations(&stations, 0, &mut out), stations.len());
        for (s, o) in stations.iter().zip(&out) {
            prop_assert_eq!(*o, p.sample(*s, 0).unwrap());
        }
    }

    /// The segment of a station is the same whatever segment its search starts from, and a
    /// sample from it is the sample from the path's start: the drive stage chains each
    /// reference station's search from the previous one's (`Path::segment_hint`).
    #[test]
    fn a_stations_segment_and_sample_do_not_depend_on_the_hint(
        pts in arb_path(),
        fs in prop::collection::vec(-0.2f32..1.2, 1..20),
        hint in 0usize..300,
    ) {
        let p = path_of(&pts);
        let mut stations: Vec<f32> = fs.iter().map(|f| f * p.length_m()).collect();
        stations.sort_by(f32::total_cmp);
        let mut chained = 0;
        for s in stations {
            let from_start = p.segment_hint(s, 0);
            prop_assert_eq!(p.segment_hint(s, hint), from_start);
            chained = p.segment_hint(s, chained);
            prop_assert_eq!(chained, from_start);
            prop_assert_eq!(p.sample(s, chained).unwrap(), p.sample(s, 0).unwrap());
        }
    }
}

fn narrowest(left_m: f32, left_station_m: f32, right_m: f32, right_station_m: f32) -> Narrowest {
    Narrowest {
        left_m,
        left_station_m,
        right_m,
        right_station_m,
    }
}

#[test]
fn narrowest_corridor_between_two_stations() {
    // Points 1 m apart northwards; the left corridor narrows to 0.5 m at point 5, the right to
    // 0.2 m at point 8 (elsewhere 1.0 and 1.5).
    let mut pts = straight(0.0, 0.0, 0.0, 12, 1.0);
    pts[5].left_m = 0.5;
    pts[8].right_m = 0.2;
    let p = path_of(&pts);
    // Between 2.5 and 4.5: no narrowing point inside; at 4.5 the left corridor is halfway
    // between 1.0 and 0.5. The right one is 1.5 throughout: it binds farthest from the axle.
    assert_eq!(
        p.narrowest_corridor(2.5, 4.5, 0),
        Some(narrowest(0.75, 4.5, 1.5, 4.5))
    );
    assert_eq!(
        p.narrowest_corridor(4.5, 2.5, 7),
        Some(narrowest(0.75, 4.5, 1.5, 2.5))
    );
    // Across both points.
    assert_eq!(
        p.narrowest_corridor(1.0, 9.5, 0),
        Some(narrowest(0.5, 5.0, 0.2, 8.0))
    );
    // Beyond the ends: the path's ends' corridor, at the stations asked for.
    assert_eq!(
        p.narrowest_corridor(-3.0, 0.5, 0),
        Some(narrowest(1.0, 0.5, 1.5, 0.5))
    );
    assert_eq!(
        p.narrowest_corridor(11.0, 13.0, 0),
        Some(narrowest(1.0, 13.0, 1.5, 13.0))
    );
    assert_eq!(Path::new().narrowest_corridor(0.0, 1.0, 0), None);
    assert_eq!(p.narrowest_corridor(0.0, f32::NAN, 0), None);
}

/// A lane that ends beside the body binds its side at the lane's last point, one that goes
/// on past the body's end at the end's corner; the same seen from the rear half.
#[test]
fn narrowest_corridor_binds_where_a_lane_ends() {
    // Left corridor 0.5 m up to point 5, 2.0 m from point 6 on (a lane that ends at 5).
    let mut pts = straight(0.0, 0.0, 0.0, 12, 1.0);
    for w in pts.iter_mut().skip(6) {
        w.left_m = 2.0;
    }
    for w in pts.iter_mut().take(6) {
        w.left_m = 0.5;
    }
    let p = path_of(&pts);
    // Axle at 3, front end at 8: the side meets the lane's end at 5.
    let n = p.narrowest_corridor(3.0, 8.0, 0).expect("path");
    assert_eq!((n.left_m, n.left_station_m), (0.5, 5.0));
    // Axle at 1, front at 4: the lane goes on past the front: the corner.
    let n = p.narrowest_corridor(1.0, 4.0, 0).expect("path");
    assert_eq!((n.left_m, n.left_station_m), (0.5, 4.0));
    // Rear half, axle at 8, rear end at 3: the lane lies behind, past the rear end: the rear
    // corner.
    let n = p.narrowest_corridor(8.0, 3.0, 0).expect("path");
    assert_eq!((n.left_m, n.left_station_m), (0.5, 3.0));
    // A lane that starts at 5 (wide before): the rear half of a body whose axle is at 8 meets
    // it at its first point; the front half of one at 3 at the front corner.
    for w in pts.iter_mut() {
        w.left_m = if w.north_m < 4.5 { 2.0 } else { 0.5 };
    }
    let p = path_of(&pts);
    let n = p.narrowest_corridor(8.0, 3.0, 0).expect("path");
    assert_eq!((n.left_m, n.left_station_m), (0.5, 5.0));
    let n = p.narrowest_corridor(3.0, 8.0, 0).expect("path");
    assert_eq!((n.left_m, n.left_station_m), (0.5, 8.0));
}

/// The projection `Path::project` documents without a previous one, by brute force over
/// every segment with the node's own arithmetic: the least squared distance to the segment
/// itself, a corner's (a foot clamped to an end point, except beyond the path's ends) counted
/// 0.2 % farther, the first segment of equal ones.
fn nearest_by_brute_force(p: &Path, east: f32, north: f32) -> Projection {
    let pts = p.points();
    let last = pts.len() - 2;
    let mut best: Option<(f32, Projection)> = None;
    for i in 0..=last {
        let (a, b) = (pts[i], pts[i + 1]);
        let (sin_h, cos_h) = catmodel::math::sin_cos(catmodel::math::atan2(
            b.east_m - a.east_m,
            b.north_m - a.north_m,
        ));
        let (s_a, s_b) = (p.station_of(i).unwrap(), p.station_of(i + 1).unwrap());
        let length = s_b - s_a;
        let (px, py) = (east - a.east_m, north - a.north_m);
        let along = px * sin_h + py * cos_h;
        let lateral = px * cos_h - py * sin_h;
        let ex = along - along.clamp(0.0, length);
        let d2 = ex * ex + lateral * lateral;
        let clamped = (along < 0.0 && i != 0) || (along > length && i != last);
        let key = if clamped { d2 * (1.0 + 2e-3) } else { d2 };
        if best.is_none_or(|(k, _)| key < k) {
            let t = match (clamped, along < 0.0) {
                (false, _) => along,
                (true, true) => 0.0,
                (true, false) => length,
            };
            let lateral_m = if clamped {
                catmodel::math::sqrt(d2).copysign(lateral)
            } else {
                lateral
            };
            best = Some((
                key,
                Projection {
                    segment: i,
                    station_m: s_a + t,
                    lateral_m,
                },
            ));
        }
    }
    best.unwrap().1
}

/// A path that starts north from the origin, turns round and comes back south 8 m east of
/// it: the point (3, -4), before the path's start, is 5 m from its first point and 5 m from
/// the segment from (8, -3) to (8, -5), an exact tie in f32 (found by the search's old form,
/// which tested the path's ends in the loop). Reversed, the first point is the last.
fn u_turn() -> Vec<Waypoint> {
    [
        (0.0, 0.0),
        (0.0, 1.0),
        (0.0, 2.0),
        (1.0, 3.5),
        (3.0, 4.5),
        (5.0, 4.5),
        (7.0, 3.5),
        (8.0, 2.0),
        (8.0, 1.0),
        (8.0, -1.0),
        (8.0, -3.0),
        (8.0, -5.0),
        (8.0, -7.0),
    ]
    .iter()
    .map(|&(e, n)| wp(e, n))
    .collect()
}

/// A point beyond the path's start (not a corner: the first segment extends) as near as a
/// later segment projects onto the first segment, the first of equals; beyond the path's end,
/// onto the earlier segment. Each as the brute force finds it, and for the obstacles' search
/// (`Path::project_each`, the whole path in one pass).
#[test]
fn a_point_beyond_an_end_as_near_as_another_segment_takes_the_first_of_them() {
    let forward = path_of(&u_turn());
    let mut back = u_turn();
    back.reverse();
    let back = path_of(&back);
    for (p, segment) in [(&forward, 0), (&back, 1)] {
        let brute = nearest_by_brute_force(p, 3.0, -4.0);
        assert_eq!(brute.segment, segment);
        assert_eq!(p.project_each([(3.0, -4.0); 4]), [Some(brute); 4]);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1024))]
    /// The node's search (every segment tested in full, a foot off its segment a corner but
    /// at the path's ends, which are tested again after) finds what the brute force does, for
    /// points anywhere near a path or far from it, on it, and at its corners.
    #[test]
    fn the_projection_is_the_brute_forces(
        pts in arb_path(),
        f in -0.1f32..1.1,
        offset in prop_oneof![Just(0.0f32), -3.0f32..3.0, -300.0f32..300.0],
        at_point in 0usize..120,
    ) {
        let p = path_of(&pts);
        // A point beside the path at a station, or exactly at one of its points.
        let (east, north) = if at_point < p.len() && offset == 0.0 {
            let w = p.points()[at_point];
            (w.east_m, w.north_m)
        } else {
            let on = p.sample(f * p.length_m(), 0).unwrap();
            let (s, c) = (on.heading_rad.sin(), on.heading_rad.cos());
            (on.east_m + offset * c, on.north_m - offset * s)
        };
        prop_assert_eq!(
            p.project(east, north, None).unwrap(),
            nearest_by_brute_force(&p, east, north)
        );
    }
}

proptest! {
    /// Four points projected in one pass are where each is projected alone.
    #[test]
    fn projections_in_one_pass_are_each_ones(
        pts in arb_path(),
        offsets in prop::collection::vec((-0.1f32..1.1, -20.0f32..20.0), 4),
    ) {
        let p = path_of(&pts);
        let mut points = [(0.0, 0.0); 4];
        for (q, &(f, offset)) in points.iter_mut().zip(&offsets) {
            let on = p.sample(f * p.length_m(), 0).unwrap();
            let (s, c) = (on.heading_rad.sin(), on.heading_rad.cos());
            *q = (on.east_m + offset * c, on.north_m - offset * s);
        }
        let each = p.project_each(points);
        for (q, one) in points.iter().zip(each) {
            prop_assert_eq!(one, p.project(q.0, q.1, None));
        }
    }
}

/// The rule `Path::narrowest_corridor` documents, by brute force over every candidate (the
/// two ends as sampled, every point strictly between): per side the narrowest width, and the
/// candidate farthest from `from` among those within `NARROWEST_TIE_M` of it.
fn narrowest_by_brute_force(p: &Path, from: f32, to: f32) -> Narrowest {
    let (lo, hi) = (from.min(to), from.max(to));
    let (start, end) = (p.sample(lo, 0).unwrap(), p.sample(hi, 0).unwrap());
    let (a, b) = (lo.clamp(0.0, p.length_m()), hi.clamp(0.0, p.length_m()));
    let mut candidates = vec![(lo, start.left_m, start.right_m)];
    for (i, w) in p.points().iter().enumerate() {
        let s = p.station_of(i).unwrap();
        if s > a && s < b {
            candidates.push((s, w.left_m, w.right_m));
        }
    }
    candidates.push((hi, end.left_m, end.right_m));
    let farthest = |width: &dyn Fn(&(f32, f32, f32)) -> f32| {
        let min = candidates.iter().map(width).fold(f32::INFINITY, f32::min);
        let within = candidates
            .iter()
            .filter(|c| width(c) <= min + NARROWEST_TIE_M);
        let station = if from <= to {
            within.map(|c| c.0).fold(f32::NEG_INFINITY, f32::max)
        } else {
            within.map(|c| c.0).fold(f32::INFINITY, f32::min)
        };
        (min, station)
    };
    let (left_m, left_station_m) = farthest(&|c| c.1);
    let (right_m, right_station_m) = farthest(&|c| c.2);
    narrowest(left_m, left_station_m, right_m, right_station_m)
}

/// A lane that narrows by less than the tie from point to point is bound at its narrow end
/// from either half of the body: the farthest station within the tie of the narrowest width,
/// not the first point of the taper.
#[test]
fn a_slow_taper_binds_at_its_narrow_end() {
    // Left corridor 2.0 m at point 0 narrowing by 5 mm per point, 1 m apart.
    let mut pts = straight(0.0, 0.0, 0.0, 41, 1.0);
    for (i, w) in pts.iter_mut().enumerate() {
        w.left_m = 2.0 - 0.005 * i as f32;
    }
    let p = path_of(&pts);
    // Rear half, axle at 30, rear end at 10: the narrowest is at the axle's end (1.85 m); the
    // stations within 0.01 m of it are 28-30, of which 28 is the farthest from the axle.
    let n = p.narrowest_corridor(30.0, 10.0, 0).unwrap();
    assert!((n.left_m - 1.85).abs() < 1e-5, "{n:?}");
    assert_eq!(n.left_station_m, 28.0);
    assert_eq!(n, narrowest_by_brute_force(&p, 30.0, 10.0));
}

/// A path of `n` points `d` apart northwards whose corridors are drawn, per point and side,
/// either anywhere from 0.3 to 3 m or within a few millimetres of 1 m (so that ties within
/// `NARROWEST_TIE_M` are frequent).
fn arb_corridor_path() -> impl Strategy<Value = Vec<Waypoint>> {
    let width = prop_oneof![
        0.3f32..3.0,
        (0u8..5).prop_map(|k| 1.0 + 0.004 * f32::from(k))
    ];
    (2usize..=MAX_PATH_POINTS, 0.05f64..2.0).prop_flat_map(move |(n, d)| {
        prop::collection::vec((width.clone(), width.clone()), n).prop_map(move |widths| {
            let mut pts = straight(0.0, 0.0, 0.0, widths.len(), d);
            for (w, (l, r)) in pts.iter_mut().zip(widths) {
                (w.left_m, w.right_m) = (l, r);
            }
            pts
        })
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2048))]
    /// The node's search (block minima, bounded whatever the body's length and the points'
    /// density) finds what the brute force does, in both directions, from any hint, with the
    /// ends anywhere (before, on or beyond the path).
    #[test]
    fn the_narrowest_corridor_is_the_brute_forces(
        pts in arb_corridor_path(),
        f in -0.2f32..1.2,
        g in -0.2f32..1.2,
        hint in 0usize..MAX_PATH_POINTS,
        to_hint in 0usize..MAX_PATH_POINTS,
    ) {
        let p = path_of(&pts);
        let (from, to) = (f * p.length_m(), g * p.length_m());
        let brute = narrowest_by_brute_force(&p, from, to);
        prop_assert_eq!(p.narrowest_corridor(from, to, hint).unwrap(), brute);
        // The ends' searches started apart (the node starts the far end's from where it was at
        // the station before): the same stretch, and the far end's segment as sampling finds it.
        let located = p.narrowest_corridor_located(from, to, (hint, to_hint)).unwrap();
        prop_assert_eq!(located.narrowest, brute);
        let last = p.len() - 2;
        let s_to = to.clamp(0.0, p.length_m());
        let on = (0..=last).rev().find(|&i| p.station_of(i).unwrap() <= s_to).unwrap_or(0);
        prop_assert_eq!(located.to_segment, on);
    }
}

/// The lower target ahead a speed plan slows for (`Path::slow_ahead`), by hand: a straight
/// 1 m between points, targets 12 m/s to 50 m, 4 to 60 m, 8 to 70 m, 1 to 80 m, then a stop.
/// The least room, distance plus the coasted sum times the target, decides between the 4 and
/// the 1; the stop is not one (it is `Path::stop_ahead_m`'s); from within the 4's stretch only
/// what is below half of 4 counts; nothing below the car's speed bound, nothing.
#[test]
fn the_lower_target_ahead_leaves_the_least_room() {
    let mut pts = straight(0.0, 0.0, 0.0, 100, 1.0);
    for (k, p) in pts.iter_mut().enumerate() {
        p.speed_mps = match k {
            0..50 => 12.0,
            50..60 => 4.0,
            60..70 => 8.0,
            70..80 => 1.0,
            _ => 0.0,
        };
    }
    let path = path_of(&pts);
    // 50 + 2 x 4 = 58 against 70 + 2 x 1 = 72; with 10 s: 90 against 80.
    assert_eq!(path.slow_ahead(0.0, 0, 2.0, (20.0, 0.5)), Some((50.0, 4.0)));
    assert_eq!(
        path.slow_ahead(0.0, 0, 10.0, (20.0, 0.5)),
        Some((70.0, 1.0))
    );
    // From 0.5 m the 4's distance is 49.5 m; from within its stretch only the 1 (below 2).
    assert_eq!(path.slow_ahead(0.5, 0, 2.0, (20.0, 0.5)), Some((49.5, 4.0)));
    assert_eq!(
        path.slow_ahead(55.0, 0, 2.0, (20.0, 0.5)),
        Some((15.0, 1.0))
    );
    // Below the car's bound (0.5 m/s) only the stop is, and it is not a lower target.
    assert_eq!(path.slow_ahead(0.0, 0, 2.0, (0.5, 0.5)), None);
    // A share of 0.3 of 12 is 3.6: the 4 no longer counts.
    assert_eq!(path.slow_ahead(0.0, 0, 2.0, (20.0, 0.3)), Some((70.0, 1.0)));
    assert_eq!(Path::new().slow_ahead(0.0, 0, 2.0, (20.0, 0.5)), None);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(1024))]
    /// The stop ahead (read off the bits marked at load, a word per 32 points) is the brute
    /// force's: the first point from the station's segment on with a target of 0 after one
    /// with a speed, else the end; over paths up to the longest, stops anywhere (a path loaded
    /// over a longer one with stops beyond its end too).
    #[test]
    fn the_stop_ahead_is_the_brute_forces(
        speeds in prop::collection::vec(prop_oneof![Just(0.0f32), 0.5f32..10.0], 2..=MAX_PATH_POINTS),
        f in -0.1f32..1.1,
        hint in 0usize..MAX_PATH_POINTS,
    ) {
        let mut pts = straight(0.0, 0.0, 0.0, speeds.len(), 0.3);
        for (w, &v) in pts.iter_mut().zip(&speeds) {
            w.speed_mps = v;
        }
        let mut over = straight(0.0, 0.0, 0.0, MAX_PATH_POINTS, 0.3);
        for (k, w) in over.iter_mut().enumerate() {
            w.speed_mps = if k % 3 == 0 { 0.0 } else { 5.0 };
        }
        let mut p = path_of(&over);
        p.load(&pts).unwrap();
        let station = f * p.length_m();
        let first = (0..p.len() - 1)
            .rev()
            .find(|&i| p.station_of(i).unwrap() <= station.clamp(0.0, p.length_m()))
            .unwrap_or(0);
        let stop = (first.max(1)..p.len())
            .find(|&k| speeds[k] <= 0.0 && speeds[k - 1] > 0.0)
            .map_or(p.length_m(), |k| p.station_of(k).unwrap());
        prop_assert_eq!(p.stop_ahead_m(station, hint), stop - station);
    }
}

#[test]
fn a_loop_is_followed_in_order_where_it_meets_itself() {
    // A full circle whose last point is next to its first: without history the start is
    // ambiguous; with the previous projection the car at the end stays at the end.
    let r = 10.0;
    let n = (2.0 * PI * r / 0.5) as usize;
    let p = path_of(&clockwise_circle(r, n + 1, 0.5));
    let length = p.length_m();
    let mut prev = None;
    for k in 0..=400 {
        let s = length * k as f32 / 400.0;
        let on = p.sample(s, 0).unwrap();
        let q = p.project(on.east_m, on.north_m, prev.as_ref()).unwrap();
        assert!((q.station_m - s).abs() < 0.01, "{} vs {s}", q.station_m);
        prev = Some(q);
    }
}

/// A car moved onto another part of the path, beyond its window's reach, has left its window
/// (the node's controller moves its last plan on rather than solving in that tick) and is
/// found there; one past the path's end, or beside it, whose nearest point is still in the
/// window, has not; nor has one placed on the path afresh.
#[test]
fn a_car_moved_to_another_part_of_the_path_has_left_its_window() {
    // 51 m north, 0.2 m apart (256 points: the most a path has).
    let p = path_of(&straight(0.0, 0.0, 0.0, 256, 0.2));
    let pose = |north: f32, east: f32| Pose::new(east, north, 0.0);
    let at_30 = p.track(&pose(30.0, 0.0), None).unwrap();
    assert!(!at_30.left_window);
    let prev = Some(at_30.projection);
    // Within the window (3 m behind to 10 m ahead), or beyond it by less than 5 m: windowed,
    // at the window's end for the latter (the next tick's window reaches it).
    for north in [27.5, 35.0, 40.0, 44.9, 22.1] {
        let t = p.track(&pose(north, 0.3), prev.as_ref()).unwrap();
        assert!(!t.left_window, "{north}");
        let within = north.clamp(27.0, 40.0);
        assert!((t.projection.station_m - within).abs() < 1e-3, "{north}");
    }
    // 8.5 m behind the window's start, 6 m past its end, and at the path's start: found on
    // the rest of the path.
    for north in [18.5, 46.0, 1.0] {
        let t = p.track(&pose(north, 0.3), prev.as_ref()).unwrap();
        assert!(t.left_window, "{north}");
        assert!((t.projection.station_m - north).abs() < 1e-3, "{north}");
        assert!((t.projection.lateral_m - 0.3).abs() < 1e-3);
    }
    // 6 m beside its projection: farther than 5 m from the window, but nothing is nearer.
    let beside = p.track(&pose(30.0, 6.0), prev.as_ref()).unwrap();
    assert!(!beside.left_window);
    assert!((beside.projection.station_m - 30.0).abs() < 1e-3);
    // 8 m past the path's end with the projection at its end.
    let end = p.track(&pose(50.9, 0.0), None).unwrap();
    let past = p.track(&pose(59.0, 0.0), Some(&end.projection)).unwrap();
    assert!(!past.left_window);
    // The projection runs on along the last segment: 8 m past the end, beside nothing.
    assert!((past.projection.station_m - (p.length_m() + 8.0)).abs() < 1e-3);
}

/// `points` as the node decodes them from PATH_POINT (each coordinate rounded to 0.02 m).
fn through_the_bus(points: &[Waypoint]) -> Vec<Waypoint> {
    points
        .iter()
        .enumerate()
        .map(|(i, w)| {
            let frame = PathPoint {
                path_id: 0,
                index: i as u8,
                east_m: w.east_m,
                north_m: w.north_m,
            }
            .encode(0);
            let (p, _) = PathPoint::decode(&frame).unwrap();
            Waypoint {
                east_m: p.east_m,
                north_m: p.north_m,
                ..*w
            }
        })
        .collect()
}

#[test]
fn the_documented_minimum_spacing_survives_path_points_rounding() {
    // The documented minimum is on the decoded points: 0.06 m along an axis (three steps)
    // passes, 0.04 m (two) is refused.
    assert!(Path::validate(&through_the_bus(&straight(0.0, 0.0, 0.0, 20, 0.06))).is_ok());
    assert_eq!(
        Path::validate(&through_the_bus(&straight(0.0, 0.0, 0.0, 20, 0.04))),
        Err(PathError::SegmentLength(0))
    );
    // A planner spacing its points MIN_SEGMENT_M apart before encoding them is refused (the
    // probe's path: 0.05 m becomes 0.06 and 0.04 m) ...
    assert_eq!(
        Path::validate(&through_the_bus(&straight(0.0, 0.0, 0.0, 20, 0.05))),
        Err(PathError::SegmentLength(1))
    );
    // ... and one spacing them MIN_PLANNED_SPACING_M apart is accepted at every heading and
    // offset from the bus's grid, straight or on its tightest circle (the car's, 5.6 m).
    let d = f64::from(MIN_PLANNED_SPACING_M);
    let mut worst = f64::INFINITY;
    for deg in 0..360 {
        let h = f64::from(deg).to_radians();
        for k in 0..10 {
            let (e0, n0) = (0.0037 * f64::from(k), 100.0 - 0.0051 * f64::from(k));
            let points = through_the_bus(&straight(e0, n0, h, 64, d));
            assert_eq!(
                Path::validate(&points),
                Ok(()),
                "heading {deg} deg, offset {k}"
            );
            for pair in points.windows(2) {
                let (dx, dy) = (
                    pair[1].east_m - pair[0].east_m,
                    pair[1].north_m - pair[0].north_m,
                );
                worst = worst.min(f64::from(dx.hypot(dy)));
            }
        }
    }
    assert!(worst >= f64::from(MIN_SEGMENT_M), "{worst}");
    let circle: Vec<Waypoint> = clockwise_circle(5.6, MAX_PATH_POINTS, d)
        .into_iter()
        .map(|w| Waypoint {
            east_m: w.east_m + 37.011,
            ..w
        })
        .collect();
    assert_eq!(Path::validate(&through_the_bus(&circle)), Ok(()));
}

#[test]
fn invalid_paths_are_refused_with_the_reason_and_the_old_path_stays() {
    let good = straight(0.0, 0.0, 0.0, 5, 1.0);
    let mut p = path_of(&good);
    let mut bad = good.clone();
    bad[2].north_m = bad[1].north_m + 0.01;
    assert_eq!(p.load(&bad), Err(PathError::SegmentLength(1)));
    let mut far = good.clone();
    far[4].north_m = 100.0;
    assert_eq!(Path::validate(&far), Err(PathError::SegmentLength(3)));
    let mut sharp = good.clone();
    sharp[3] = wp(1.0, 2.0); // 90 degrees at point 2
    assert_eq!(Path::validate(&sharp), Err(PathError::Turn(2)));
    let mut nan = good.clone();
    nan[1].east_m = f32::NAN;
    assert_eq!(Path::validate(&nan), Err(PathError::BadValue(1)));
    let mut negative = good.clone();
    negative[0].speed_mps = -1.0;
    assert_eq!(Path::validate(&negative), Err(PathError::BadValue(0)));
    assert_eq!(Path::validate(&good[..1]), Err(PathError::PointCount));
    let too_many = straight(0.0, 0.0, 0.0, MAX_PATH_POINTS + 1, 0.5);
    assert_eq!(Path::validate(&too_many), Err(PathError::PointCount));
    assert!(Path::validate(&too_many[..MAX_PATH_POINTS]).is_ok());
    // Every refusal left the first path in place.
    assert_eq!(p.points(), &good[..]);
    assert!(p.project(f32::NAN, 0.0, None).is_none());
    assert!(Path::new().project(0.0, 0.0, None).is_none());
    assert!(Path::new().sample(0.0, 0).is_none());
}

// ------------------------------------------------------------------------------------------
// Assembly from the planner's frames

/// The frames of a path, each message with its own counter starting at `c0`.
fn path_messages(path_id: u8, pts: &[Waypoint], c0: u8) -> Vec<PlannerMessage> {
    let mut out = vec![PlannerMessage::PathHeader(
        PathHeader {
            path_id,
            count: pts.len() as u16,
        },
        c0,
    )];
    for (i, w) in pts.iter().enumerate() {
        let c = (c0 + 1 + i as u8) & 0x0F;
        out.push(PlannerMessage::PathPoint(
            PathPoint {
                path_id,
                index: i as u8,
                east_m: w.east_m,
                north_m: w.north_m,
            },
            c,
        ));
        out.push(PlannerMessage::PathLimits(
            PathLimits {
                path_id,
                index: i as u8,
                speed_mps: w.speed_mps,
                left_m: w.left_m,
                right_m: w.right_m,
            },
            c,
        ));
    }
    out
}

fn feed(inputs: &mut PlannerInputs, messages: &[PlannerMessage]) -> Vec<PlannerEvent> {
    messages
        .iter()
        .map(|m| inputs.receive(m, 0))
        .filter(|e| *e != PlannerEvent::None)
        .collect()
}

#[test]
fn a_complete_path_becomes_active_only_when_complete() {
    let mut inputs = PlannerInputs::new();
    let pts = straight(0.0, 0.0, 0.0, 40, 1.0);
    let messages = path_messages(3, &pts, 0);
    // All but the last frame: still no path.
    assert!(feed(&mut inputs, &messages[..messages.len() - 1]).is_empty());
    assert!(inputs.path().is_none());
    assert_eq!(inputs.receiving(), Some((3, 40, 39, 40)));
    assert_eq!(
        feed(&mut inputs, &messages[messages.len() - 1..]),
        [PlannerEvent::PathActivated(3)]
    );
    assert_eq!(inputs.path().unwrap().points(), &pts[..]);
    assert_eq!(inputs.path_id(), Some(3));
    // A second path: the first stays active until the second is complete.
    let pts2 = straight(5.0, 0.0, 0.0, 10, 2.0);
    let messages2 = path_messages(4, &pts2, 9);
    feed(&mut inputs, &messages2[..5]);
    assert_eq!(inputs.path().unwrap().points(), &pts[..]);
    assert_eq!(
        feed(&mut inputs, &messages2[5..]),
        [PlannerEvent::PathActivated(4)]
    );
    assert_eq!(inputs.path().unwrap().points(), &pts2[..]);
    assert_eq!(inputs.counters().paths_activated, 2);
}

#[test]
fn points_then_limits_in_separate_runs_also_assemble() {
    // The two streams each in order, but not interleaved.
    let mut inputs = PlannerInputs::new();
    let pts = straight(0.0, 0.0, 1.0, 8, 1.0);
    let m = path_messages(0, &pts, 0);
    let (points, limits): (Vec<_>, Vec<_>) = m[1..]
        .iter()
        .partition(|x| matches!(x, PlannerMessage::PathPoint(..)));
    feed(&mut inputs, &m[..1]);
    feed(&mut inputs, &points);
    assert_eq!(feed(&mut inputs, &limits), [PlannerEvent::PathActivated(0)]);
}

#[test]
fn a_lost_frame_abandons_the_assembly_and_duplicates_are_counted() {
    let mut inputs = PlannerInputs::new();
    let pts = straight(0.0, 0.0, 0.0, 10, 1.0);
    let m = path_messages(1, &pts, 0);
    // Duplicate of point 2 (same index again, next counter): counted, assembly continues.
    let mut with_dup = m[..7].to_vec();
    if let PlannerMessage::PathPoint(p, _) = m[5] {
        with_dup.push(PlannerMessage::PathPoint(p, 4));
    }
    feed(&mut inputs, &with_dup);
    assert_eq!(inputs.counters().duplicates, 1);
    assert!(inputs.receiving().is_some());
    // Skip point 3's PATH_POINT (index 4 arrives): a lost frame.
    if let PlannerMessage::PathPoint(p, _) = m[9] {
        inputs.receive(&PlannerMessage::PathPoint(p, 5), 0);
    }
    assert_eq!(inputs.counters().paths_abandoned, 1);
    assert!(inputs.receiving().is_none() && inputs.path().is_none());
    // The rest of that path is stray now.
    feed(&mut inputs, &m[10..12]);
    assert!(inputs.counters().stray_frames >= 1);
    // The planner sends it again with a new header: it completes.
    assert_eq!(
        feed(&mut inputs, &path_messages(2, &pts, 7)),
        [PlannerEvent::PathActivated(2)]
    );
}

#[test]
fn a_header_change_midway_abandons_and_restarts() {
    let mut inputs = PlannerInputs::new();
    let a = straight(0.0, 0.0, 0.0, 10, 1.0);
    let b = straight(3.0, 0.0, 0.0, 6, 1.0);
    feed(&mut inputs, &path_messages(5, &a, 0)[..9]);
    let events = feed(&mut inputs, &path_messages(6, &b, 1));
    assert_eq!(events, [PlannerEvent::PathActivated(6)]);
    assert_eq!(inputs.counters().paths_abandoned, 1);
    assert_eq!(inputs.path().unwrap().points(), &b[..]);
}

#[test]
fn an_invalid_path_is_refused_and_the_active_one_stays() {
    let mut inputs = PlannerInputs::new();
    let good = straight(0.0, 0.0, 0.0, 10, 1.0);
    feed(&mut inputs, &path_messages(1, &good, 0));
    let mut bad = good.clone();
    bad[5] = bad[4]; // zero-length segment
    let events = feed(&mut inputs, &path_messages(2, &bad, 3));
    assert_eq!(
        events,
        [PlannerEvent::PathInvalid(2, PathError::SegmentLength(4))]
    );
    assert_eq!(inputs.path_id(), Some(1));
    assert_eq!(inputs.path().unwrap().points(), &good[..]);
    assert_eq!(inputs.counters().paths_invalid, 1);
}

/// A car 1.9 m wide.
const CAR: PathCar = PathCar { body_width_m: 1.9 };

#[test]
fn a_corridor_the_body_does_not_fit_in_is_refused() {
    let mut points = straight(0.0, 0.0, 0.0, 20, 1.0);
    for w in &mut points {
        (w.left_m, w.right_m) = (0.95, 0.95);
    }
    // Exactly the car's width, and the bus's rounding of it: taken.
    assert_eq!(Path::validate_for(&points, &CAR), Ok(()));
    points[7].right_m = 0.95 - CORRIDOR_TOLERANCE_M + 0.001;
    assert_eq!(Path::validate_for(&points, &CAR), Ok(()));
    // One point 2 cm too narrow, or a corridor of nothing (the probe's left = right = 0).
    points[7].right_m = 0.93;
    assert_eq!(
        Path::validate_for(&points, &CAR),
        Err(PathError::Corridor(7))
    );
    for w in &mut points {
        (w.left_m, w.right_m) = (0.0, 0.0);
    }
    assert_eq!(
        Path::validate_for(&points, &CAR),
        Err(PathError::Corridor(0))
    );
    // Without a car (zero width) only the geometry is checked.
    assert_eq!(Path::validate_for(&points, &PathCar::default()), Ok(()));
}

#[test]
fn a_path_the_body_does_not_fit_is_refused_and_the_active_one_stays() {
    let mut inputs = PlannerInputs::new();
    inputs.set_car(CAR);
    let good = straight(0.0, 0.0, 0.0, 10, 1.0);
    assert_eq!(
        feed(&mut inputs, &path_messages(1, &good, 0)),
        [PlannerEvent::PathActivated(1)]
    );
    let mut narrow = good.clone();
    narrow[3].left_m = 0.9;
    narrow[3].right_m = 0.9;
    assert_eq!(
        feed(&mut inputs, &path_messages(2, &narrow, 3)),
        [PlannerEvent::PathInvalid(2, PathError::Corridor(3))]
    );
    assert_eq!(inputs.path_id(), Some(1));
    assert_eq!(inputs.path().unwrap().points(), &good[..]);
    assert_eq!(inputs.counters().paths_invalid, 1);
    assert_eq!(*inputs.car(), CAR);
}

/// Slot `id`'s circles from `track(t_s)` once a tick (20 ms) for `seconds`, as the bus carries
/// them (0.02 m resolution), starting at `t0_s`; the slot's motion after the last.
fn obstacle_track(
    inputs: &mut PlannerInputs,
    id: u8,
    (t0_s, seconds): (f64, f64),
    track: impl Fn(f64) -> Option<(f64, f64)>,
) -> ObstacleMotion {
    let ticks = (seconds / 0.02).round() as u64;
    let start = (t0_s / 0.02).round() as u64;
    for tick in start..start + ticks {
        let t = tick as f64 * 0.02;
        let circle = track(t).map(|(e, n)| ObstacleCircle {
            east_m: ((e / 0.02).round() * 0.02) as f32,
            north_m: ((n / 0.02).round() * 0.02) as f32,
            radius_m: 0.5,
        });
        let message = PlannerMessage::Obstacle(
            Obstacle {
                obstacle_id: id,
                circle,
            },
            (tick % 16) as u8,
        );
        inputs.receive(&message, tick * 20_000);
    }
    inputs.obstacle_motion()[usize::from(id)]
}

#[test]
fn an_obstacle_sent_as_it_moves_has_its_velocity() {
    // A pedestrian crossing at 1.5 m/s north-west: its velocity once a span of frames is in,
    // to the bus's resolution; none before.
    let walk = |t: f64| Some((40.0 - 1.2 * t, -6.0 + 0.9 * t));
    let mut inputs = PlannerInputs::new();
    let early = obstacle_track(&mut inputs, 1, (0.0, 0.3), walk);
    assert_eq!((early.east_mps, early.north_mps), (0.0, 0.0));
    let m = obstacle_track(&mut inputs, 1, (0.3, 1.0), walk);
    assert!(
        (m.east_mps + 1.2).abs() < 0.03 && (m.north_mps - 0.9).abs() < 0.03,
        "{m:?}"
    );
    // The other slots stand.
    assert_eq!(inputs.obstacle_motion()[0], ObstacleMotion::STILL);
    // Stopped: the next span measures it standing.
    let stop = obstacle_track(&mut inputs, 1, (1.3, 1.2), |_| Some((38.44, -4.92)));
    assert_eq!((stop.east_mps, stop.north_mps), (0.0, 0.0));
}

#[test]
fn a_standing_obstacle_whose_circle_jitters_stands() {
    // A detector's noise, 0.1 m either way and more at random, on a standing object: below
    // the still speed on every span. (A deterministic scatter: a fixed LCG.)
    let state = std::cell::Cell::new(7u64);
    let noise = || {
        let s = state
            .get()
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1);
        state.set(s);
        ((s >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.3
    };
    let mut inputs = PlannerInputs::new();
    for span in 0..20 {
        let m = obstacle_track(&mut inputs, 2, (span as f64 * 0.5, 0.5), |_| {
            Some((12.0 + noise(), 30.0 + noise()))
        });
        assert_eq!((m.east_mps, m.north_mps), (0.0, 0.0), "span {span}: {m:?}");
    }
    // Just above the still speed, it moves.
    let creep = 1.2 * f64::from(OBSTACLE_STILL_MPS);
    let m = obstacle_track(&mut inputs, 3, (0.0, 1.2), |t| Some((creep * t, 0.0)));
    assert!(m.east_mps > OBSTACLE_STILL_MPS, "{m:?}");
}

/// A detector's scatter: Gaussian (the sum of twelve uniforms), standard deviation `sigma`, from
/// a fixed LCG seeded with `seed`.
fn detector_noise(seed: u64, sigma: f64) -> impl FnMut() -> f64 {
    let mut state = seed;
    move || {
        let mut sum = 0.0;
        for _ in 0..12 {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            sum += (state >> 11) as f64 / (1u64 << 53) as f64;
        }
        (sum - 6.0) * sigma
    }
}

/// One tick of [`obstacle_frames`]: t, the centre sent, the centre the node holds, its motion.
type ObstacleFrame = (f64, (f32, f32), (f32, f32), ObstacleMotion);

/// Sends slot `id` the circles of `track` once a tick from `t0_s` for `seconds`, as the bus
/// carries them; returns per tick what [`ObstacleFrame`] holds.
fn obstacle_frames(
    inputs: &mut PlannerInputs,
    id: u8,
    (t0_s, seconds): (f64, f64),
    mut track: impl FnMut(f64) -> (f64, f64),
) -> Vec<ObstacleFrame> {
    let start = (t0_s / 0.02).round() as u64;
    (start..start + (seconds / 0.02).round() as u64)
        .map(|tick| {
            let t = tick as f64 * 0.02;
            let (e, n) = track(t);
            let sent = (
                ((e / 0.02).round() * 0.02) as f32,
                ((n / 0.02).round() * 0.02) as f32,
            );
            let circle = ObstacleCircle {
                east_m: sent.0,
                north_m: sent.1,
                radius_m: 0.5,
            };
            let message = PlannerMessage::Obstacle(
                Obstacle {
                    obstacle_id: id,
                    circle: Some(circle),
                },
                (tick % 16) as u8,
            );
            inputs.receive(&message, tick * 20_000);
            let held = inputs.obstacles()[usize::from(id)].unwrap();
            let motion = inputs.obstacle_motion()[usize::from(id)];
            (t, sent, (held.east_m, held.north_m), motion)
        })
        .collect()
}

/// The least-squares speed of a span of frames (the test's own fit).
fn span_speed(frames: &[ObstacleFrame]) -> f64 {
    let k = frames.len() as f64;
    let mean = |f: &dyn Fn(&ObstacleFrame) -> f64| frames.iter().map(f).sum::<f64>() / k;
    let t0 = mean(&|f| f.0);
    let e0 = mean(&|f| f64::from(f.1 .0));
    let n0 = mean(&|f| f64::from(f.1 .1));
    let stt: f64 = frames.iter().map(|f| (f.0 - t0).powi(2)).sum();
    let ve: f64 = frames
        .iter()
        .map(|f| (f.0 - t0) * (f64::from(f.1 .0) - e0))
        .sum::<f64>()
        / stt;
    let vn: f64 = frames
        .iter()
        .map(|f| (f.0 - t0) * (f64::from(f.1 .1) - n0))
        .sum::<f64>()
        / stt;
    ve.hypot(vn)
}

#[test]
fn a_standing_object_seen_by_a_noisy_detector_stands_at_its_mean() {
    // 0.1 m of Gaussian scatter per axis, 60 s: spans whose fitted speed passes the still speed
    // (which moved the object by that speed times the time to meet it), and circles 0.25 m
    // and more from the object, which the side decision took as they came.
    let mut noise = detector_noise(11, 0.1);
    let mut inputs = PlannerInputs::new();
    let frames = obstacle_frames(&mut inputs, 3, (0.0, 60.0), |_| {
        (12.0 + noise(), 30.0 + noise())
    });
    let off = |p: (f32, f32)| f64::from(p.0 - 12.0).hypot(f64::from(p.1 - 30.0));
    let fast_spans = frames
        .chunks(26)
        .filter(|c| span_speed(c) > f64::from(OBSTACLE_STILL_MPS))
        .count();
    assert!(
        fast_spans >= 2,
        "the scatter makes no span look moving: {fast_spans}"
    );
    assert!(frames.iter().any(|f| off(f.1) > 0.25));
    for (t, _, held, motion) in &frames {
        assert_eq!((motion.east_mps, motion.north_mps), (0.0, 0.0), "t {t}");
        if *t >= 1.0 {
            assert!(off(*held) < 0.06, "t {t}: held {held:?}");
        }
    }
}

#[test]
fn an_object_that_sets_off_is_followed_within_its_detectors_scatter() {
    // Standing 3 s with 0.05 m of scatter, then walking north at 1.5 m/s: the circle the node
    // holds is never more than the reach and two frames of walking from the object; the
    // walk is measured within a span or two.
    let mut noise = detector_noise(5, 0.05);
    let mut inputs = PlannerInputs::new();
    let truth = |t: f64| (20.0, -6.0 + 1.5 * (t - 3.0).max(0.0));
    let frames = obstacle_frames(&mut inputs, 0, (0.0, 6.0), |t| {
        let (e, n) = truth(t);
        (e + noise(), n + noise())
    });
    for (t, _, held, _) in frames.iter().filter(|f| f.0 >= 1.0) {
        let (e, n) = truth(*t);
        let lag = f64::from(held.0 - e as f32).hypot(f64::from(held.1 - n as f32));
        // Three sigmas of 0.07 m (both axes), two ticks at 1.5 m/s, and one frame's scatter.
        assert!(lag < 0.21 + 0.06 + 0.15, "t {t}: held {held:?}, lag {lag}");
    }
    let last = frames.last().unwrap().3;
    assert!((last.north_mps - 1.5).abs() < 0.1, "{last:?}");
}

#[test]
fn a_slow_walk_under_a_detectors_scatter_keeps_moving_and_its_stop_is_seen() {
    // A walk of 0.5 m/s under 0.1 m of scatter per axis: a span's fitted speed falls below the
    // still speed about one span in sixteen, and while the node held it standing the car took
    // a crossing pedestrian for one standing and passed ahead of it (docs/findings.md). Once
    // the walk is measured it stays measured, crossing north at 0.3 m/s or more, until it
    // stops; then it stands within two spans.
    let span_s = OBSTACLE_VELOCITY_SPAN_US as f64 * 1e-6;
    for seed in [7, 8, 9, 10] {
        let mut noise = detector_noise(seed, 0.1);
        let mut inputs = PlannerInputs::new();
        let truth = |t: f64| (45.0, -6.0 + 0.5 * t.min(20.0));
        let frames = obstacle_frames(&mut inputs, 2, (0.0, 24.0), |t| {
            let (e, n) = truth(t);
            (e + noise(), n + noise())
        });
        let walking: Vec<ObstacleFrame> = frames.iter().filter(|f| f.0 < 20.0).copied().collect();
        let slow_spans = walking
            .chunks(26)
            .filter(|c| span_speed(c) < f64::from(OBSTACLE_STILL_MPS))
            .count();
        let first = walking
            .iter()
            .position(|f| f.3.north_mps != 0.0)
            .expect("the walk is measured");
        assert!(
            walking[first].0 < 2.0,
            "seed {seed}: measured at {}",
            walking[first].0
        );
        for (t, _, _, motion) in &walking[first..] {
            assert!(
                motion.north_mps >= 0.3,
                "seed {seed}, t {t}: {motion:?} ({slow_spans} spans of the test's fit below the still speed)"
            );
        }
        let stood = frames
            .iter()
            .filter(|f| f.0 >= 20.0 + 2.0 * span_s + 0.1)
            .all(|f| (f.3.east_mps, f.3.north_mps) == (0.0, 0.0));
        assert!(stood, "seed {seed}: the stop is not seen within two spans");
    }
}

#[test]
fn a_detectors_outlier_does_not_move_a_standing_object() {
    let mut noise = detector_noise(3, 0.03);
    let mut inputs = PlannerInputs::new();
    let mut tick = 0;
    let frames = obstacle_frames(&mut inputs, 1, (0.0, 4.0), |_| {
        tick += 1;
        // One circle off every second by turns 1 m (within the jump a tick allows) and 1.4 m
        // (beyond it: the velocity starts afresh, the centre keeps its mean).
        let outlier = match tick % 100 {
            50 => 1.0,
            0 => 1.4,
            _ => 0.0,
        };
        (5.0 + noise(), 8.0 + outlier + noise())
    });
    for (t, sent, held, _) in frames.iter().filter(|f| f.0 >= 1.0) {
        assert!(
            (held.1 - 8.0).abs() < 0.05,
            "t {t}: sent {sent:?}, held {held:?}"
        );
    }
}

#[test]
fn a_jump_a_silence_or_a_cleared_slot_starts_the_motion_afresh() {
    let mut inputs = PlannerInputs::new();
    let run = |t: f64| Some((3.0 * t, 50.0));
    let m = obstacle_track(&mut inputs, 0, (0.0, 1.0), run);
    assert!((m.east_mps - 3.0).abs() < 0.03, "{m:?}");
    // Another object in the slot, 20 m away: no velocity from the jump, and none until a span
    // of its own frames.
    let span_s = OBSTACLE_VELOCITY_SPAN_US as f64 * 1e-6;
    let jumped = obstacle_track(&mut inputs, 0, (1.0, span_s - 0.1), |_| Some((23.0, 50.0)));
    assert_eq!((jumped.east_mps, jumped.north_mps), (0.0, 0.0));
    // Silent for 3 s, then moving elsewhere at 1 m/s: measured from the frames after it.
    let m = obstacle_track(&mut inputs, 0, (4.5, 1.0), |t| {
        Some((23.0 + (t - 4.5), 50.0))
    });
    assert!((m.east_mps - 1.0).abs() < 0.05, "{m:?}");
    // Cleared.
    let cleared = obstacle_track(&mut inputs, 0, (5.5, 0.02), |_| None);
    assert_eq!(cleared, ObstacleMotion::STILL);
}

#[test]
fn stuck_counters_obstacles_and_origin_pairing() {
    let mut inputs = PlannerInputs::new();
    let circle = ObstacleCircle {
        east_m: 3.0,
        north_m: 20.0,
        radius_m: 0.5,
    };
    let set = |id, c| {
        PlannerMessage::Obstacle(
            Obstacle {
                obstacle_id: id,
                circle: Some(circle),
            },
            c,
        )
    };
    inputs.receive(&set(2, 0), 0);
    assert_eq!(inputs.obstacles()[2], Some(circle));
    // The same counter again: a stuck sender, rejected (slot 1 stays empty).
    inputs.receive(&set(1, 0), 0);
    assert_eq!(inputs.obstacles()[1], None);
    assert_eq!(inputs.counters().stuck_counters, 1);
    inputs.receive(
        &PlannerMessage::Obstacle(
            Obstacle {
                obstacle_id: 2,
                circle: None,
            },
            1,
        ),
        0,
    );
    assert_eq!(inputs.obstacles(), &[None; 4]);
    // Origin: latitude then longitude with the next counter.
    let lat = PlannerMessage::LocalOrigin(
        LocalOrigin::Latitude {
            lat_e7: 322_319_000,
        },
        14,
    );
    let lon = |c| {
        PlannerMessage::LocalOrigin(
            LocalOrigin::Longitude {
                lon_e7: -1_109_501_000,
            },
            c,
        )
    };
    assert_eq!(inputs.receive(&lat, 0), PlannerEvent::None);
    assert_eq!(
        inputs.receive(&lon(15), 0),
        PlannerEvent::Origin {
            lat_e7: 322_319_000,
            lon_e7: -1_109_501_000
        }
    );
    // A longitude page on its own (its latitude lost): a counted mismatch, no origin.
    assert_eq!(inputs.receive(&lon(0), 0), PlannerEvent::None);
    assert_eq!(inputs.counters().origin_mismatches, 1);
}

proptest! {
    /// Whatever frames arrive, in whatever order, assembly never panics, and an active path is
    /// always one that passes validation.
    #[test]
    fn assembly_never_panics_and_only_valid_paths_activate(
        ops in prop::collection::vec((0u8..3, 0u8..4, 0u8..12, -20.0f32..20.0, 0u8..16, 1u16..14), 0..300)
    ) {
        let mut inputs = PlannerInputs::new();
        for (kind, id, index, v, counter, count) in ops {
            let m = match kind {
                0 => PlannerMessage::PathHeader(PathHeader { path_id: id, count: count.max(2) }, counter),
                1 => PlannerMessage::PathPoint(PathPoint { path_id: id, index, east_m: v, north_m: f32::from(index) * 1.5 }, counter),
                _ => PlannerMessage::PathLimits(PathLimits { path_id: id, index, speed_mps: v.abs(), left_m: 1.0, right_m: 1.0 }, counter),
            };
            inputs.receive(&m, 0);
            if let Some(p) = inputs.path() {
                prop_assert!(Path::validate(p.points()).is_ok());
            }
        }
    }
}

// ------------------------------------------------------------------------------------------
// Pure pursuit

/// The CAT Vehicle as the hand derivations below use it: L = 2.62 m, 35.5 deg at 100 %,
/// K = 0.0015 s^2/m^2; body 1.806 x 4.437 m, rear overhang 0.85 m.
const CAT: VehicleParams = VehicleParams {
    wheelbase_m: 2.62,
    track_m: 1.55,
    max_steer_rad: 35.5 * std::f32::consts::PI / 180.0,
    understeer_s2_per_m2: 0.0015,
};

fn pursuit(tuning: PurePursuitTuning) -> PurePursuitConfig {
    PurePursuitConfig {
        tuning,
        vehicle: CAT,
        body: Body {
            width_m: 1.806,
            length_m: 4.437,
            rear_overhang_m: 0.85,
        },
        max_speed_mps: 40.0,
        period_s: 0.02,
    }
}

fn car(east: f32, north: f32, heading: f32, speed: f32) -> CarState {
    CarState {
        pose: Some(Pose::new(east, north, heading)),
        speed_mps: speed,
        rear_side_mps: 0.0,
    }
}

#[test]
fn pure_pursuit_steering_hand_derived() {
    // Path north along east = 0; the car 1 m to the right, heading north, at standstill:
    // lookahead 3 m, goal (0, 3): right = -1, d^2 = 10, kappa = 2 (-1) / 10 = -0.2 1/m;
    // delta = atan(-0.2 * 2.62) = -0.48255 rad = -77.88 % of 35.5 deg.
    let path = path_of(&straight(0.0, 0.0, 0.0, 30, 1.0));
    let cfg = pursuit(DEFAULT_TUNING);
    assert_eq!(cfg.lookahead_m(0.0), 3.0);
    let mut state = PurePursuitState::default();
    let out = cfg.process(&mut state, Some(&path), &[], &car(1.0, 0.0, 0.0, 0.0));
    let expected_pct = (-0.2f64 * 2.62).atan() / 35.5f64.to_radians() * 100.0;
    assert_eq!(out.status, ControlStatus::Tracking);
    assert!(
        (f64::from(out.steer_cmd_pct) - expected_pct).abs() < 1e-3,
        "{} vs {expected_pct}",
        out.steer_cmd_pct
    );
    assert_eq!(out.goal, Some((0.0, 3.0)));
    let t = out.tracking.unwrap();
    assert!((t.projection.lateral_m - 1.0).abs() < 1e-6);
    // Mirror image: 1 m to the left steers right by the same amount.
    let out = cfg.process(
        &mut PurePursuitState::default(),
        Some(&path),
        &[],
        &car(-1.0, 0.0, 0.0, 0.0),
    );
    assert!((f64::from(out.steer_cmd_pct) + expected_pct).abs() < 1e-3);
}

#[test]
fn pure_pursuit_arc_starts_along_the_rear_axles_course() {
    // A rear axle sliding right at 0.5 m/s at 10 m/s travels 0.04996 rad right of its heading:
    // pure pursuit's arc is tangent to that course, so the car steers as one without slip
    // whose heading is the course. Heading along the path, the goal lies left of the course:
    // it steers left.
    let path = path_of(&straight(0.0, 0.0, 0.0, 60, 1.0));
    let cfg = pursuit(DEFAULT_TUNING);
    let sliding = CarState {
        rear_side_mps: 0.5,
        ..car(0.0, 5.0, 0.0, 10.0)
    };
    let slid = cfg.process(&mut PurePursuitState::default(), Some(&path), &[], &sliding);
    let course = (0.5f32 / 10.0).atan();
    let turned = cfg.process(
        &mut PurePursuitState::default(),
        Some(&path),
        &[],
        &car(0.0, 5.0, course, 10.0),
    );
    assert!(slid.steer_cmd_pct < -1.0, "{}", slid.steer_cmd_pct);
    assert!(
        (slid.steer_cmd_pct - turned.steer_cmd_pct).abs() < 1e-3,
        "{} vs {}",
        slid.steer_cmd_pct,
        turned.steer_cmd_pct
    );
}

#[test]
fn pure_pursuit_on_a_circle_steers_for_its_curvature() {
    // On a circle with the car on it and tangent, the goal lies on the same circle, so the
    // pure-pursuit arc is the circle: kappa = 1/R, steering = atan(L / R) (1 + K v^2).
    // With the car at a point and the goal at a point (lookaheads 4.0 and 5.5 m on 0.5 m
    // chords), both lie exactly on the circle and the reference heading at a point is the
    // circle's tangent there, so this holds to rounding.
    let r = 20.0;
    let path = path_of(&clockwise_circle(r, 120, 0.5));
    let cfg = pursuit(PurePursuitTuning {
        lookahead_time_s: 0.5,
        ..DEFAULT_TUNING
    });
    for v in [2.0f32, 5.0] {
        let s = path.station_of(20).unwrap();
        let on = path.sample(s, 0).unwrap();
        let out = cfg.process(
            &mut PurePursuitState::default(),
            Some(&path),
            &[],
            &car(on.east_m, on.north_m, on.heading_rad, v),
        );
        let expected =
            (2.62f64 / r).atan() * (1.0 + 0.0015 * f64::from(v * v)) / 35.5f64.to_radians() * 100.0;
        assert!(
            (f64::from(out.steer_cmd_pct) - expected).abs() < 1e-4 * expected,
            "{v}: {} vs {expected}",
            out.steer_cmd_pct
        );
    }
}

#[test]
fn pure_pursuit_speed_loop_and_stops() {
    let cfg = pursuit(PurePursuitTuning {
        speed_preview_s: 0.0,
        ..DEFAULT_TUNING
    });
    let t = cfg.tuning;
    let front = cfg.body.length_m - cfg.body.rear_overhang_m;
    let path = path_of(&straight(0.0, 0.0, 0.0, 200, 1.0));
    // At the target speed: the command is the target (plus the integral, zero here).
    let mut state = PurePursuitState::default();
    let out = cfg.process(&mut state, Some(&path), &[], &car(0.0, 10.0, 0.0, 5.0));
    assert!((out.speed_cmd_mps - 5.0).abs() < 1e-6);
    // 0.5 m/s slow: kp * 0.5 + ki * 0.5 * dt above the target, and the integral grows each
    // tick.
    let mut state = PurePursuitState::default();
    let a = cfg.process(&mut state, Some(&path), &[], &car(0.0, 10.0, 0.0, 4.5));
    let expected = 5.0 + 0.5 * t.speed_kp + 0.5 * t.speed_ki_per_s * cfg.period_s;
    assert!(
        (a.speed_cmd_mps - expected).abs() < 1e-5,
        "{}",
        a.speed_cmd_mps
    );
    let b = cfg.process(&mut state, Some(&path), &[], &car(0.0, 10.0, 0.0, 4.5));
    assert!(b.speed_cmd_mps > a.speed_cmd_mps);
    // At rest (a launch): the correction is capped, the integral does not run.
    let mut state = PurePursuitState::default();
    let out = cfg.process(&mut state, Some(&path), &[], &car(0.0, 10.0, 0.0, 0.0));
    assert!((out.speed_cmd_mps - (5.0 + t.speed_correction_limit_mps)).abs() < 1e-6);
    assert_eq!(state.integral_mps, 0.0);
    // Near the end: at rest 4 m before it, the stopping limit is sqrt(2 a 4), and the
    // correction never goes past it; at speed, the response time's travel comes off.
    let out = cfg.process(
        &mut PurePursuitState::default(),
        Some(&path),
        &[],
        &car(0.0, 195.0, 0.0, 0.0),
    );
    let limit = (2.0 * t.stop_decel_mps2 * 4.0).sqrt();
    assert!(
        (out.speed_cmd_mps - limit).abs() < 1e-5,
        "{}",
        out.speed_cmd_mps
    );
    let v = 1.5;
    let out = cfg.process(
        &mut PurePursuitState::default(),
        Some(&path),
        &[],
        &car(0.0, 195.0, 0.0, v),
    );
    let limit = (2.0 * t.stop_decel_mps2 * (4.0 - v * t.speed_response_s)).sqrt();
    assert!(
        (out.speed_cmd_mps - limit).abs() < 1e-5,
        "{}",
        out.speed_cmd_mps
    );
    // An obstacle on the path 10 m ahead of the rear axle: the target drops so that the front
    // bumper stops a margin short of it: free distance = 20 - 0.5 - margin - front - 10.
    let obstacle = [Some(ObstacleCircle {
        east_m: 0.2,
        north_m: 20.0,
        radius_m: 0.5,
    })];
    let free = 20.0 - 0.5 - t.obstacle_margin_m - front - 10.0;
    let limit = (2.0 * t.stop_decel_mps2 * free).sqrt();
    assert!(limit < 5.0);
    let out = cfg.process(
        &mut PurePursuitState::default(),
        Some(&path),
        &obstacle,
        &car(0.0, 10.0, 0.0, 0.0),
    );
    assert!(
        (out.speed_cmd_mps - limit).abs() < 1e-3,
        "{} vs {limit}",
        out.speed_cmd_mps
    );
    // Stopped at the margin (and past it): it stays stopped while the obstacle is there.
    for north in [10.0 + free, 10.0 + free + 1.0] {
        let out = cfg.process(
            &mut PurePursuitState::default(),
            Some(&path),
            &obstacle,
            &car(0.0, north, 0.0, 0.0),
        );
        assert_eq!(out.speed_cmd_mps, 0.0, "{north}");
    }
    // Beside the path (2.7 m off, beyond half the width plus margin and radius): no stop.
    let beside = [Some(ObstacleCircle {
        east_m: 2.7,
        north_m: 20.0,
        radius_m: 0.5,
    })];
    let out = cfg.process(
        &mut PurePursuitState::default(),
        Some(&path),
        &beside,
        &car(0.0, 10.0, 0.0, 5.0),
    );
    assert!((out.speed_cmd_mps - 5.0).abs() < 1e-6);
}

#[test]
fn pure_pursuit_without_path_or_position_holds_the_car() {
    let mut state = PurePursuitState::default();
    let out = pursuit(DEFAULT_TUNING).process(&mut state, None, &[], &car(0.0, 0.0, 0.0, 3.0));
    assert_eq!(
        (out.status, out.speed_cmd_mps),
        (ControlStatus::NoPath, 0.0)
    );
    let path = path_of(&straight(0.0, 0.0, 0.0, 10, 1.0));
    let lost = CarState {
        pose: None,
        speed_mps: 3.0,
        rear_side_mps: 0.0,
    };
    let out = pursuit(DEFAULT_TUNING).process(&mut state, Some(&path), &[], &lost);
    assert_eq!(
        (out.status, out.speed_cmd_mps),
        (ControlStatus::Fallback, 0.0)
    );
    // Non-finite speed never leaks into the command.
    let out = pursuit(DEFAULT_TUNING).process(
        &mut state,
        Some(&path),
        &[],
        &car(0.0, 1.0, 0.0, f32::NAN),
    );
    assert!(out.steer_cmd_pct.is_finite() && out.speed_cmd_mps.is_finite());
}

#[test]
fn a_car_beside_its_corridor_past_its_end_or_against_the_path_has_lost_it() {
    // Path north, corridor 1.0 m left (west) and 1.5 m right (east); a body 1.8 m wide is lost
    // when its rear axle is more than 1.8 m outside: east of 3.3 m or west of -2.8 m.
    let p = path_of(&straight(0.0, 0.0, 0.0, 30, 1.0));
    let lost = |east: f32, heading: f32| {
        let t = p.track(&Pose::new(east, 10.0, heading), None).unwrap();
        (t.outside_corridor_m(), t.has_lost_path(1.8))
    };
    let close = |(outside, was_lost): (f32, bool), expect_outside: f32, expect_lost: bool| {
        assert!((outside - expect_outside).abs() < 1e-5, "{outside}");
        assert_eq!(was_lost, expect_lost, "outside {outside}");
    };
    close(lost(0.7, 0.0), 0.0, false);
    close(lost(-0.9, 0.0), 0.0, false);
    close(lost(3.25, 0.0), 1.75, false);
    close(lost(3.35, 0.0), 1.85, true);
    close(lost(-2.75, 0.0), 1.75, false);
    close(lost(-2.85, 0.0), 1.85, true);
    // Turned across the path is still following it; facing against it is not.
    close(lost(0.0, FRAC_PI_2 - 0.01), 0.0, false);
    close(lost(0.0, -(FRAC_PI_2 - 0.01)), 0.0, false);
    close(lost(0.0, FRAC_PI_2 + 0.01), 0.0, true);
    close(lost(0.0, std::f32::consts::PI), 0.0, true);
    // Past the path's end (its last point 29 m north) on its line: lost beyond a body width
    // (a black-box probe's path behind the car was "tracking" with the car 46 m past its end).
    // Before its start it is not: the car drives onto it.
    let along = |north: f32| {
        p.track(&Pose::new(0.0, north, 0.0), None)
            .unwrap()
            .has_lost_path(1.8)
    };
    assert!(!along(29.0 + 1.75));
    assert!(along(29.0 + 1.85));
    assert!(along(29.0 + 46.0));
    assert!(!along(-10.0));
}

#[test]
fn pure_pursuit_stops_with_the_wheels_straight_when_it_has_lost_the_path() {
    let path = path_of(&straight(0.0, 0.0, 0.0, 60, 1.0));
    let cfg = pursuit(DEFAULT_TUNING);
    let mut state = PurePursuitState::default();
    // Tracking at speed, steering hard left towards the path from 1.7 m right of its corridor.
    let out = cfg.process(&mut state, Some(&path), &[], &car(3.2, 5.0, 0.0, 8.0));
    assert_eq!(out.status, ControlStatus::Tracking);
    assert!(out.steer_cmd_pct < -20.0, "{}", out.steer_cmd_pct);
    // Facing against the path: brake, wheels straight.
    let out = cfg.process(&mut state, Some(&path), &[], &car(0.0, 6.0, 3.0, 8.0));
    assert_eq!(out.status, ControlStatus::Fallback);
    assert_eq!((out.speed_cmd_mps, out.steer_cmd_pct), (0.0, 0.0));
    // Beside the corridor by more than the body's width: the same.
    let out = cfg.process(&mut state, Some(&path), &[], &car(3.4, 7.0, 0.0, 8.0));
    assert_eq!(out.status, ControlStatus::Fallback);
    assert_eq!((out.speed_cmd_mps, out.steer_cmd_pct), (0.0, 0.0));
}

/// A whole turn is held to its racing line's speed at every point, and the segments whose
/// speed the lateral limit holds are marked (`Path::in_held_turn`), hand-checked on an 8 m
/// hairpin (points 1.005 m apart) in a corridor 0.594 m wider than the body at 5.9 m/s^2: the
/// half turn cut through that room is driven on a radius of 8 + 0.594 / (1 - cos(pi / 2)) =
/// 8.594 m, so each arc point's own limit is 5.9 x 8.594 m^2/s^2 (7.12 m/s), up to 3 % more
/// where the reference's 2 m chords round the arc's ends into the turn's measure (2 %
/// measured), and the envelope sampled at a point allows the braking from the next one,
/// 2 x 3 m/s^2 x 1.005 m more (7.65 m/s at most). The windows alone (their lengths a factor
/// of two apart, each credited with a cut inside the turn) held it to 7.86 m/s, a radius 10 %
/// above the racing line's. The arc's segments are held, the straights 10 m before and after
/// it are not, and nothing is without the limit.
#[test]
fn the_turns_the_lateral_limit_holds_are_marked() {
    // The arc: points 50 (its start) to 75 (its end), 25 steps of pi x 8 / 25 m.
    let r = 8.0f64;
    let (points, _) = hairpin_in(r, 1.2);
    let n = 25;
    let mut p = path_of(&points);
    let segments = p.len() - 1;
    assert!((0..segments).all(|k| !p.in_held_turn(k)));
    assert!(p.set_lateral_limit(Some(LateralLimit {
        accel_mps2: 5.9,
        width_m: 1.806,
    })));
    let arc = 51..75;
    let spacing = PI * r / n as f64;
    let (low, high) = (
        (5.9f64 * 8.594).sqrt(),
        (5.9f64 * 8.594 * 1.03 + 6.0 * spacing).sqrt(),
    );
    for k in arc.clone() {
        let s = p.station_of(k).unwrap();
        let v = f64::from(p.sample(s, k).unwrap().speed_mps);
        assert!(
            v >= low * 0.999 && v <= high * 1.001,
            "point {k}: {v} m/s, not in {low}..{high}"
        );
    }
    for k in 0..segments {
        let held = p.in_held_turn(k);
        if arc.contains(&k) {
            assert!(held, "segment {k} in the arc");
        }
        if k < 40 || k > 50 + n + 10 {
            assert!(!held, "segment {k} on a straight");
        }
    }
    assert!(!p.in_held_turn(segments + 5));
    assert!(p.set_lateral_limit(None));
    assert!((0..segments).all(|k| !p.in_held_turn(k)));
}
