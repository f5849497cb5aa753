//! The figures of a closed-loop run (SVG, `crate::plot`):
//! - `path.svg`: the planned path, the driven path (truth, rear axle), the cones or the
//!   obstacle, and the body's outline every [`OUTLINE_EVERY_M`] of travel while the controller
//!   drives (dotted rectangles), east/north at equal scale;
//! - `lateral_error.svg`: the rear axle's lateral error from the path against station (truth),
//!   over the scored range and a little around it;
//! - `steering.svg`: steering command and the actuator's steering against time;
//! - `speed.svg`: speed command and the truth speed against time.
use std::path::{Path, PathBuf};

use anyhow::Result;

use super::metrics::body_corners;
use super::RunOutput;
use crate::plot::{decimate, Figure};
use crate::sim::config::Body;

/// Travel between two drawn body outlines, m (about a car's length apart: they do not overlap
/// on a straight).
pub const OUTLINE_EVERY_M: f64 = 5.0;
/// Points per drawn metre of a body outline or circle.
const OUTLINE_POINTS_PER_M: f64 = 8.0;
/// Largest number of points of a line in a figure.
const MAX_LINE_POINTS: usize = 4000;

/// Points along the closed polygon `corners`.
fn dotted_polygon(corners: &[(f64, f64)], out: &mut Vec<(f64, f64)>) {
    for (i, &(x0, y0)) in corners.iter().enumerate() {
        let (x1, y1) = corners[(i + 1) % corners.len()];
        let length = ((x1 - x0).powi(2) + (y1 - y0).powi(2)).sqrt();
        let n = (length * OUTLINE_POINTS_PER_M).ceil().max(1.0) as usize;
        out.extend((0..n).map(|k| {
            let f = k as f64 / n as f64;
            (x0 + (x1 - x0) * f, y0 + (y1 - y0) * f)
        }));
    }
}

/// A circle as a closed line.
fn circle(east: f64, north: f64, radius: f64) -> Vec<(f64, f64)> {
    (0..=72)
        .map(|k| {
            let a = k as f64 * std::f64::consts::TAU / 72.0;
            (east + radius * a.cos(), north + radius * a.sin())
        })
        .collect()
}

/// Writes the four figures into `dir`; returns their paths.
pub fn write_plots(dir: &Path, output: &RunOutput, body: &Body) -> Result<Vec<PathBuf>> {
    let run = &output.metrics;
    let title = format!(
        "{} with {} ({} receiver), target {:.1} m/s",
        run.scenario, run.controller, run.receiver, run.target_speed_mps
    );
    let samples = &output.samples;
    let (from, to) = output.course.scored_stations_m;
    let margin = 15.0;
    let in_view = |s: &super::Sample| s.station_m >= from - margin && s.station_m <= to + margin;

    // The path figure, around the scored range.
    let planned: Vec<(f64, f64)> = output
        .course
        .path
        .iter()
        .map(|p| (p.east_m, p.north_m))
        .collect();
    let view: Vec<&super::Sample> = samples.iter().filter(|s| in_view(s)).collect();
    let (e0, e1, n0, n1) = view.iter().fold(
        (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ),
        |(a, b, c, d), s| {
            (
                a.min(s.truth.x),
                b.max(s.truth.x),
                c.min(s.truth.y),
                d.max(s.truth.y),
            )
        },
    );
    let near = |&(e, n): &(f64, f64)| {
        e >= e0 - margin && e <= e1 + margin && n >= n0 - margin && n <= n1 + margin
    };
    let driven: Vec<(f64, f64)> = view.iter().map(|s| (s.truth.x, s.truth.y)).collect();
    let mut outlines = Vec::new();
    let mut next_outline = f64::NEG_INFINITY;
    for s in view.iter().filter(|s| s.engaged) {
        if s.station_m >= next_outline {
            dotted_polygon(
                &body_corners(body, s.truth.x, s.truth.y, s.truth.heading),
                &mut outlines,
            );
            next_outline = s.station_m + OUTLINE_EVERY_M;
        }
    }
    let mut fig = Figure::new(&title, "east (m)", "north (m)")
        .line(
            "planned path (rear axle)",
            planned.iter().copied().filter(near).collect(),
        )
        .color((120, 120, 120))
        .scatter("body outline every 5 m", outlines)
        .color((160, 190, 230));
    if !output.course.cones.is_empty() {
        let cones: Vec<(f64, f64)> = output
            .course
            .cones
            .iter()
            .map(|c| (c.east_m, c.north_m))
            .collect();
        fig = fig.scatter("cones", cones).color((255, 127, 14));
    }
    for o in &output.course.obstacles {
        fig = fig
            .line("obstacle", circle(o.east_m, o.north_m, o.radius_m))
            .color((214, 39, 40));
        if let Some(w) = o.walk {
            // Where it walks: its first 8 s from where it sets off.
            let walk = vec![
                (o.east_m, o.north_m),
                (o.east_m + 8.0 * w.east_mps, o.north_m + 8.0 * w.north_mps),
            ];
            fig = fig.line("its walk, 8 s", walk).color((214, 39, 40));
        }
    }
    fig = fig
        .line(
            "driven path (truth, rear axle)",
            decimate(&driven, MAX_LINE_POINTS),
        )
        .color((31, 119, 180))
        .equal_aspect();
    // As wide as the course is long: a lane change is 60 m by 5 m.
    let aspect = (n1 - n0 + 10.0) / (e1 - e0 + 10.0);
    fig.size = (1600, (1500.0 * aspect + 180.0).clamp(350.0, 1200.0) as u32);
    let mut written = Vec::new();
    let path_svg = dir.join("path.svg");
    fig.write_svg(&path_svg)?;
    written.push(path_svg);

    let lateral: Vec<(f64, f64)> = view
        .iter()
        .filter(|s| s.lateral_m.is_finite())
        .map(|s| (s.station_m - from, s.lateral_m))
        .collect();
    let lateral_svg = dir.join("lateral_error.svg");
    Figure::new(
        &format!("{title}: lateral error (truth; 0 = start of the scored range)"),
        "station (m)",
        "lateral error of the rear axle, + right (m)",
    )
    .line("lateral error", decimate(&lateral, MAX_LINE_POINTS))
    .write_svg(&lateral_svg)?;
    written.push(lateral_svg);

    let series = |f: &dyn Fn(&super::Sample) -> Option<f64>| -> Vec<(f64, f64)> {
        let points: Vec<(f64, f64)> = samples
            .iter()
            .filter_map(|s| f(s).map(|v| (s.t_s, v)))
            .collect();
        decimate(&points, MAX_LINE_POINTS)
    };
    let driving = |s: &super::Sample| s.engaged;
    let steering_svg = dir.join("steering.svg");
    Figure::new(
        &format!("{title}: steering"),
        "time (s)",
        "steering (%, + right)",
    )
    .line(
        "command (while driving)",
        series(&|s| {
            driving(s)
                .then_some(s.command.steer_cmd_pct.map(f64::from))
                .flatten()
        }),
    )
    .line("actuator", series(&|s| Some(s.steer_pct)))
    .write_svg(&steering_svg)?;
    written.push(steering_svg);
    let speed_svg = dir.join("speed.svg");
    Figure::new(&format!("{title}: speed"), "time (s)", "speed (m/s)")
        .line(
            "command (while driving)",
            series(&|s| {
                driving(s)
                    .then_some(s.command.speed_cmd_mps.map(f64::from))
                    .flatten()
            }),
        )
        .line("truth", series(&|s| Some(s.truth.speed)))
        .y_from_zero()
        .write_svg(&speed_svg)?;
    written.push(speed_svg);
    Ok(written)
}

/// The offline optimiser's best run at `speed_mps` (rows of `optimal::TrackAtSpeed::record`):
/// `optimal_path.svg` (the planned path, the cones, the driven path and the body every
/// [`OUTLINE_EVERY_M`]) and `optimal_steering.svg` (the actuator's steering), into `dir`.
pub fn write_optimal_plots(
    dir: &Path,
    course: &super::scenario::Course,
    body: &Body,
    speed_mps: f64,
    rows: &[[f64; 6]],
) -> Result<Vec<PathBuf>> {
    let title = format!(
        "{}: offline optimiser's limit, {speed_mps:.2} m/s (perfect plant knowledge)",
        course.kind.name()
    );
    let driven: Vec<(f64, f64)> = rows.iter().map(|r| (r[1], r[2])).collect();
    let (e0, e1, n0, n1) = driven.iter().fold(
        (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ),
        |(a, b, c, d), p| (a.min(p.0), b.max(p.0), c.min(p.1), d.max(p.1)),
    );
    let mut outlines = Vec::new();
    let mut travelled = 0.0;
    let mut next = 0.0;
    for (i, r) in rows.iter().enumerate() {
        if i > 0 {
            let q = &rows[i - 1];
            travelled += ((r[1] - q[1]).powi(2) + (r[2] - q[2]).powi(2)).sqrt();
        }
        if travelled >= next {
            dotted_polygon(&body_corners(body, r[1], r[2], r[3]), &mut outlines);
            next = travelled + OUTLINE_EVERY_M;
        }
    }
    let near =
        |&(e, n): &(f64, f64)| e >= e0 - 10.0 && e <= e1 + 10.0 && n >= n0 - 10.0 && n <= n1 + 10.0;
    let planned: Vec<(f64, f64)> = course
        .path
        .iter()
        .map(|p| (p.east_m, p.north_m))
        .filter(near)
        .collect();
    let cones: Vec<(f64, f64)> = course.cones.iter().map(|c| (c.east_m, c.north_m)).collect();
    let mut fig = Figure::new(&title, "east (m)", "north (m)")
        .line("planned path (rear axle)", planned)
        .color((120, 120, 120))
        .scatter("body outline every 5 m", outlines)
        .color((160, 190, 230))
        .scatter("cones", cones)
        .color((255, 127, 14))
        .line(
            "driven path (rear axle)",
            decimate(&driven, MAX_LINE_POINTS),
        )
        .color((31, 119, 180))
        .equal_aspect();
    let aspect = (n1 - n0 + 10.0) / (e1 - e0 + 10.0);
    fig.size = (1600, (1500.0 * aspect + 180.0).clamp(350.0, 1200.0) as u32);
    let path_svg = dir.join("optimal_path.svg");
    fig.write_svg(&path_svg)?;
    let steer: Vec<(f64, f64)> = rows.iter().map(|r| (r[0], r[5])).collect();
    let steering_svg = dir.join("optimal_steering.svg");
    Figure::new(
        &format!("{title}: steering"),
        "time from the start of the trial (s)",
        "steering (%, + right)",
    )
    .line("actuator", decimate(&steer, MAX_LINE_POINTS))
    .write_svg(&steering_svg)?;
    Ok(vec![path_svg, steering_svg])
}
