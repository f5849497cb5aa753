//! Step 3a: correlation analysis ranking candidate regressors (the paper starts from 17
//! measured and computed variables: "the steering angle measured in radians, the cosine, sine,
//! and tangent of the steering angle, and the position of the vehicle in meters", II-D-2).
use serde::Serialize;

use super::preprocess::Experiment;
use crate::model_file::VehicleSection;

/// One candidate's correlation with the output.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Ranked {
    /// Candidate name.
    pub name: String,
    /// Pearson correlation with the output over all training samples.
    pub r: f64,
}

/// Pearson correlation (0 when either signal is constant).
pub fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()) as f64;
    if n < 2.0 {
        return 0.0;
    }
    let ma = a.iter().sum::<f64>() / n;
    let mb = b.iter().sum::<f64>() / n;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    if saa <= 0.0 || sbb <= 0.0 {
        0.0
    } else {
        sab / (saa * sbb).sqrt()
    }
}

/// The 17 candidates of one experiment, by name.
pub fn candidates(e: &Experiment, v: &VehicleSection) -> Vec<(&'static str, Vec<f64>)> {
    let half_t = v.track_m / 2.0;
    let radius: Vec<f64> = e
        .delta_rad
        .iter()
        .zip(&e.vel)
        .map(|(d, s)| {
            let eff = d / (1.0 + v.understeer_s2_per_m2 * s * s);
            eff.tan() / v.wheelbase_m
        })
        .collect();
    let inner_outer = |sign: f64| -> Vec<f64> {
        radius
            .iter()
            .map(|k| {
                if *k == 0.0 {
                    0.0
                } else {
                    let r = 1.0 / k.abs();
                    (v.wheelbase_m / (r - sign * half_t)).atan() * k.signum()
                }
            })
            .collect()
    };
    vec![
        ("vel", e.vel.clone()),
        ("input_vel", e.input_vel.clone()),
        ("accel", e.accel_pct.clone()),
        ("brake", e.brake_pct.clone()),
        ("steer_pct", e.steer_pct.clone()),
        ("phi (centre angle, rad)", e.delta_rad.clone()),
        ("cos(phi)", e.delta_rad.iter().map(|d| d.cos()).collect()),
        ("sin(phi)", e.delta_rad.iter().map(|d| d.sin()).collect()),
        ("tan(phi)", e.delta_rad.iter().map(|d| d.tan()).collect()),
        ("delta_inner (eq 3)", inner_outer(1.0)),
        ("delta_outer (eq 4)", inner_outer(-1.0)),
        ("curvature (eq 2)", radius.clone()),
        ("x", e.x.clone()),
        ("y", e.y.clone()),
        ("heading", e.heading.clone()),
        ("sin(heading)", e.heading.iter().map(|h| h.sin()).collect()),
        (
            "vel sin(heading)",
            e.heading
                .iter()
                .zip(&e.vel)
                .map(|(h, s)| s * h.sin())
                .collect(),
        ),
    ]
}

/// Ranks the candidates by |r| with `output(e)` over all experiments.
pub fn rank(
    experiments: &[Experiment],
    v: &VehicleSection,
    output: impl Fn(&Experiment) -> &[f64],
) -> Vec<Ranked> {
    let mut names: Vec<&'static str> = Vec::new();
    let mut cols: Vec<Vec<f64>> = Vec::new();
    let mut y = Vec::new();
    for e in experiments {
        for (i, (n, c)) in candidates(e, v).into_iter().enumerate() {
            if cols.len() <= i {
                names.push(n);
                cols.push(Vec::new());
            }
            cols[i].extend(c);
        }
        y.extend_from_slice(output(e));
    }
    let mut out: Vec<Ranked> = names
        .iter()
        .zip(&cols)
        .map(|(n, c)| Ranked {
            name: (*n).to_string(),
            r: pearson(c, &y),
        })
        .collect();
    out.sort_by(|a, b| b.r.abs().total_cmp(&a.r.abs()));
    out
}
