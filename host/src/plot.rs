//! Small SVG plotting helpers on top of `plotters`: a [`Figure`] is a title, two axis labels and
//! a list of line or scatter [`Series`]; [`Figure::write_svg`] renders it.
//!
//! Text goes into the SVG as `<text>` elements (plotters' SVG backend without the `ttf` feature
//! estimates text extents itself), so rendering needs no font files and no fontconfig; the viewer
//! picks a sans-serif font.
use std::path::Path;

use anyhow::{anyhow, Result};
use plotters::prelude::*;

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Style {
    /// Points joined in order.
    Line,
    /// One small filled circle per point.
    Points,
}

/// One named set of points.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// `(x, y)` in data units; non-finite points are skipped.
    pub points: Vec<(f64, f64)>,
    /// Line or points.
    pub style: Style,
    /// RGB colour; `None` = [`PALETTE`] by the series' index.
    pub color: Option<(u8, u8, u8)>,
}

/// A chart: title, axis labels, series, size.
#[derive(Clone, Debug, PartialEq)]
pub struct Figure {
    /// Caption above the chart.
    pub title: String,
    /// x axis description (with its unit).
    pub x_label: String,
    /// y axis description (with its unit).
    pub y_label: String,
    /// Drawn in order; colours follow [`PALETTE`] by index.
    pub series: Vec<Series>,
    /// Same data units per pixel on both axes (maps, paths).
    pub equal_aspect: bool,
    /// Start the y axis at 0 (error magnitudes).
    pub y_from_zero: bool,
    /// Width and height in pixels.
    pub size: (u32, u32),
}

/// Series colours, in order: black, blue, red, green, orange, purple.
pub const PALETTE: [(u8, u8, u8); 6] = [
    (0, 0, 0),
    (31, 119, 180),
    (214, 39, 40),
    (44, 160, 44),
    (255, 127, 14),
    (148, 103, 189),
];

// Layout in pixels (also used to make equal-aspect ranges).
const MARGIN_PX: u32 = 15;
const X_LABEL_AREA_PX: u32 = 45;
const Y_LABEL_AREA_PX: u32 = 65;
const CAPTION_PX: u32 = 40;

impl Figure {
    /// An empty 900 x 600 figure.
    pub fn new(title: &str, x_label: &str, y_label: &str) -> Self {
        Self {
            title: title.to_string(),
            x_label: x_label.to_string(),
            y_label: y_label.to_string(),
            series: Vec::new(),
            equal_aspect: false,
            y_from_zero: false,
            size: (900, 600),
        }
    }

    /// Adds a line series.
    pub fn line(mut self, label: &str, points: Vec<(f64, f64)>) -> Self {
        self.series.push(Series {
            label: label.to_string(),
            points,
            style: Style::Line,
            color: None,
        });
        self
    }

    /// Adds a scatter series.
    pub fn scatter(mut self, label: &str, points: Vec<(f64, f64)>) -> Self {
        self.series.push(Series {
            label: label.to_string(),
            points,
            style: Style::Points,
            color: None,
        });
        self
    }

    /// Sets the colour of the series added last.
    pub fn color(mut self, rgb: (u8, u8, u8)) -> Self {
        if let Some(s) = self.series.last_mut() {
            s.color = Some(rgb);
        }
        self
    }

    /// Same scale on both axes.
    pub fn equal_aspect(mut self) -> Self {
        self.equal_aspect = true;
        self
    }

    /// y axis from 0.
    pub fn y_from_zero(mut self) -> Self {
        self.y_from_zero = true;
        self
    }

    /// Data ranges `(x0..x1, y0..y1)` covering every finite point, padded by 3 %.
    fn ranges(&self) -> ((f64, f64), (f64, f64)) {
        let finite = self
            .series
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|p| p.0.is_finite() && p.1.is_finite());
        let (mut x0, mut x1, mut y0, mut y1) = (
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        );
        for &(x, y) in finite {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        if x0 > x1 {
            (x0, x1) = (0.0, 1.0);
        }
        if y0 > y1 {
            (y0, y1) = (0.0, 1.0);
        }
        if self.y_from_zero {
            y0 = y0.min(0.0);
        }
        let pad = |a: f64, b: f64| {
            let span = if b > a { b - a } else { a.abs().max(1.0) };
            (a - 0.03 * span, b + 0.03 * span)
        };
        let (x0, x1) = pad(x0, x1);
        let (mut y0, y1) = pad(y0, y1);
        if self.y_from_zero && y0 < 0.0 {
            y0 = 0.0;
        }
        if !self.equal_aspect {
            return ((x0, x1), (y0, y1));
        }
        let (w, h) = self.size;
        let plot_w = f64::from(w.saturating_sub(2 * MARGIN_PX + Y_LABEL_AREA_PX).max(1));
        let plot_h = f64::from(
            h.saturating_sub(2 * MARGIN_PX + X_LABEL_AREA_PX + CAPTION_PX)
                .max(1),
        );
        let per_px = ((x1 - x0) / plot_w).max((y1 - y0) / plot_h);
        let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
        let (hw, hh) = (per_px * plot_w / 2.0, per_px * plot_h / 2.0);
        ((cx - hw, cx + hw), (cy - hh, cy + hh))
    }

    /// Renders the figure as an SVG document.
    pub fn to_svg(&self) -> Result<String> {
        let mut out = String::new();
        {
            let root = SVGBackend::with_string(&mut out, self.size).into_drawing_area();
            root.fill(&WHITE).map_err(|e| anyhow!("plot: {e:?}"))?;
            let ((x0, x1), (y0, y1)) = self.ranges();
            let mut chart = ChartBuilder::on(&root)
                .caption(&self.title, ("sans-serif", 22))
                .margin(MARGIN_PX)
                .x_label_area_size(X_LABEL_AREA_PX)
                .y_label_area_size(Y_LABEL_AREA_PX)
                .build_cartesian_2d(x0..x1, y0..y1)
                .map_err(|e| anyhow!("plot: {e:?}"))?;
            chart
                .configure_mesh()
                .x_desc(&self.x_label)
                .y_desc(&self.y_label)
                .light_line_style(RGBColor(235, 235, 235))
                .draw()
                .map_err(|e| anyhow!("plot: {e:?}"))?;
            for (i, s) in self.series.iter().enumerate() {
                let (r, g, b) = s.color.unwrap_or(PALETTE[i % PALETTE.len()]);
                let color = RGBColor(r, g, b);
                let pts = s
                    .points
                    .iter()
                    .copied()
                    .filter(|p| p.0.is_finite() && p.1.is_finite());
                let anno = match s.style {
                    Style::Line => chart
                        .draw_series(LineSeries::new(pts, color.stroke_width(2)))
                        .map_err(|e| anyhow!("plot: {e:?}"))?,
                    Style::Points => chart
                        .draw_series(pts.map(|p| Circle::new(p, 2, color.filled())))
                        .map_err(|e| anyhow!("plot: {e:?}"))?,
                };
                let anno = anno.label(s.label.as_str());
                match s.style {
                    Style::Line => anno.legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3))
                    }),
                    Style::Points => {
                        anno.legend(move |(x, y)| Circle::new((x + 10, y), 3, color.filled()))
                    }
                };
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperLeft)
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .label_font(("sans-serif", 14))
                .draw()
                .map_err(|e| anyhow!("plot: {e:?}"))?;
            root.present().map_err(|e| anyhow!("plot: {e:?}"))?;
        }
        Ok(out)
    }

    /// Renders the figure into `path` (parent directories are created).
    pub fn write_svg(&self, path: &Path) -> Result<()> {
        let svg = self.to_svg()?;
        crate::replay::write_file(path, &svg)
    }
}

/// At most `max` points, evenly strided (first point kept), to keep SVG files small.
pub fn decimate(points: &[(f64, f64)], max: usize) -> Vec<(f64, f64)> {
    if max == 0 {
        return Vec::new();
    }
    let stride = points.len().div_ceil(max).max(1);
    points.iter().step_by(stride).copied().collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn svg_has_title_labels_legend_and_one_circle_per_point() {
        let fig = Figure::new("Title <&>", "time (s)", "error (m)")
            .line("a line", vec![(0.0, 0.0), (1.0, 2.0), (2.0, 1.0)])
            .scatter("some points", vec![(0.5, 0.5), (1.5, f64::NAN), (1.0, 1.0)]);
        let svg = fig.to_svg().unwrap();
        assert!(svg.starts_with("<svg"), "{}", &svg[..40]);
        assert!(svg.trim_end().ends_with("</svg>"));
        // Text is escaped, and present as text elements (no rasterised glyphs).
        assert!(svg.contains("Title &lt;&amp;&gt;"));
        for t in ["time (s)", "error (m)", "a line", "some points"] {
            assert!(svg.contains(t), "missing {t}");
        }
        // Two finite scatter points (the NaN one is skipped) and the legend's marker.
        assert_eq!(svg.matches("<circle").count(), 3);
    }

    #[test]
    fn equal_aspect_gives_equal_units_per_pixel() {
        let fig = Figure::new("t", "x", "y")
            .line("l", vec![(0.0, 0.0), (100.0, 10.0)])
            .equal_aspect();
        let ((x0, x1), (y0, y1)) = fig.ranges();
        let plot_w = f64::from(900 - 2 * MARGIN_PX - Y_LABEL_AREA_PX);
        let plot_h = f64::from(600 - 2 * MARGIN_PX - X_LABEL_AREA_PX - CAPTION_PX);
        assert!((((x1 - x0) / plot_w) - ((y1 - y0) / plot_h)).abs() < 1e-12);
        assert!(x0 < 0.0 && x1 > 100.0 && y0 < 0.0 && y1 > 10.0);
    }

    #[test]
    fn y_from_zero_and_empty_figures() {
        let fig = Figure::new("t", "x", "y")
            .line("l", vec![(0.0, 5.0), (1.0, 6.0)])
            .y_from_zero();
        assert_eq!(fig.ranges().1 .0, 0.0);
        // No points at all still renders.
        assert!(Figure::new("t", "x", "y")
            .to_svg()
            .unwrap()
            .contains("</svg>"));
    }

    #[test]
    fn decimate_bounds_the_count() {
        let pts: Vec<_> = (0..1001).map(|i| (i as f64, 0.0)).collect();
        let d = decimate(&pts, 100);
        assert!(d.len() <= 100 && d.len() >= 90, "{}", d.len());
        assert_eq!(d[0], pts[0]);
        assert_eq!(decimate(&pts[..5], 100).len(), 5);
    }
}
