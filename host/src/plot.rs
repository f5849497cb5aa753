//! Small SVG plotting helpers on top of `plotters`, for `evaluate --plots` and `identify
//! --report`: a [`Figure`] is a title, one or more [`Panel`]s side by side (each with its own
//! subtitle, axes and line or scatter [`Series`]), and one legend for all of them.
//!
//! Layout rules, so that a reader can use every figure:
//! - the legend sits in its own strip below the panels, never over the data, and lists every
//!   series that is drawn, markers included (a series without a label is not allowed: give it
//!   one);
//! - series are drawn in the order given: put the one that must stay visible (the truth line)
//!   last, on top of dense dots;
//! - equal-aspect panels (maps, paths) get the same metres per pixel on both axes.
//!
//! Text goes into the SVG as `<text>` elements (plotters' SVG backend without the `ttf` feature
//! estimates text extents itself), so rendering needs no font files and no fontconfig; the viewer
//! picks a sans-serif font.
use std::path::Path;

use anyhow::{anyhow, Result};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Style {
    /// Points joined in order, `width_px` wide.
    Line {
        /// Stroke width, pixels.
        width_px: u32,
    },
    /// One filled circle per point.
    Points {
        /// Circle radius, pixels.
        radius_px: u32,
    },
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
    /// RGB colour; `None` = [`PALETTE`] by the series' index in its panel.
    pub color: Option<(u8, u8, u8)>,
}

/// One chart: subtitle, axes, series.
#[derive(Clone, Debug, PartialEq)]
pub struct Panel {
    /// Caption above the panel (may be empty).
    pub subtitle: String,
    /// x axis description (with its unit).
    pub x_label: String,
    /// y axis description (with its unit).
    pub y_label: String,
    /// Drawn in order.
    pub series: Vec<Series>,
    /// Same data units per pixel on both axes (maps, paths).
    pub equal_aspect: bool,
    /// Start the y axis at 0 (error magnitudes).
    pub y_from_zero: bool,
}

/// A figure: a title, panels side by side, one legend below them.
#[derive(Clone, Debug, PartialEq)]
pub struct Figure {
    /// Title above everything.
    pub title: String,
    /// Panels, left to right.
    pub panels: Vec<Panel>,
    /// Width and height in pixels, legend included.
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

// Layout in pixels.
const MARGIN_PX: u32 = 12;
const X_LABEL_AREA_PX: u32 = 48;
const Y_LABEL_AREA_PX: u32 = 70;
const TITLE_FONT_PX: u32 = 22;
const SUBTITLE_FONT_PX: u32 = 16;
const LEGEND_FONT_PX: u32 = 14;
const TICK_FONT_PX: u32 = 13;
const AXIS_FONT_PX: u32 = 14;
/// Height of one legend row.
const LEGEND_ROW_PX: u32 = 22;
/// Width of a legend entry's sample (line or marker) and the gap to its text.
const LEGEND_SAMPLE_PX: u32 = 30;
/// Gap between legend entries on one row.
const LEGEND_GAP_PX: u32 = 28;
/// Estimated width of one character of legend text: DejaVu Sans (librsvg's default) averages
/// 0.42 em over these labels, Arial and Helvetica about 0.47 em; 0.5 em keeps entries apart.
const LEGEND_CHAR_PX: f64 = 0.5 * LEGEND_FONT_PX as f64;

impl Panel {
    /// An empty panel.
    pub fn new(subtitle: &str, x_label: &str, y_label: &str) -> Self {
        Self {
            subtitle: subtitle.to_string(),
            x_label: x_label.to_string(),
            y_label: y_label.to_string(),
            series: Vec::new(),
            equal_aspect: false,
            y_from_zero: false,
        }
    }

    /// Data ranges `(x0..x1, y0..y1)` covering every finite point, padded by 3 %; for an
    /// equal-aspect panel widened so that a plot area of `plot_px` pixels has the same units
    /// per pixel on both axes.
    fn ranges(&self, plot_px: (u32, u32)) -> ((f64, f64), (f64, f64)) {
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
        let (plot_w, plot_h) = (f64::from(plot_px.0.max(1)), f64::from(plot_px.1.max(1)));
        let per_px = ((x1 - x0) / plot_w).max((y1 - y0) / plot_h);
        let (cx, cy) = ((x0 + x1) / 2.0, (y0 + y1) / 2.0);
        let (hw, hh) = (per_px * plot_w / 2.0, per_px * plot_h / 2.0);
        ((cx - hw, cx + hw), (cy - hh, cy + hh))
    }
}

/// One legend entry's position within the legend strip.
#[derive(Clone, Debug, PartialEq)]
struct LegendEntry {
    label: String,
    style: Style,
    color: (u8, u8, u8),
    x_px: u32,
    row: u32,
}

impl Figure {
    /// An empty 900 x 600 figure with one panel (no subtitle).
    pub fn new(title: &str, x_label: &str, y_label: &str) -> Self {
        Self {
            title: title.to_string(),
            panels: vec![Panel::new("", x_label, y_label)],
            size: (900, 600),
        }
    }

    /// Sets the subtitle of the last panel.
    pub fn subtitle(mut self, subtitle: &str) -> Self {
        if let Some(p) = self.panels.last_mut() {
            p.subtitle = subtitle.to_string();
        }
        self
    }

    /// Adds a panel to the right; the series added next go into it.
    pub fn panel(mut self, subtitle: &str, x_label: &str, y_label: &str) -> Self {
        self.panels.push(Panel::new(subtitle, x_label, y_label));
        self
    }

    /// Sets the size in pixels (legend included).
    pub fn size(mut self, width_px: u32, height_px: u32) -> Self {
        self.size = (width_px, height_px);
        self
    }

    fn push(mut self, label: &str, points: Vec<(f64, f64)>, style: Style) -> Self {
        if let Some(p) = self.panels.last_mut() {
            p.series.push(Series {
                label: label.to_string(),
                points,
                style,
                color: None,
            });
        }
        self
    }

    /// Adds a line series (2 px) to the last panel.
    pub fn line(self, label: &str, points: Vec<(f64, f64)>) -> Self {
        self.push(label, points, Style::Line { width_px: 2 })
    }

    /// Adds a scatter series (3 px dots) to the last panel.
    pub fn scatter(self, label: &str, points: Vec<(f64, f64)>) -> Self {
        self.push(label, points, Style::Points { radius_px: 2 })
    }

    /// Adds a series drawn in `style` to the last panel.
    pub fn series(self, label: &str, points: Vec<(f64, f64)>, style: Style) -> Self {
        self.push(label, points, style)
    }

    /// Sets the colour of the series added last.
    pub fn color(mut self, rgb: (u8, u8, u8)) -> Self {
        if let Some(s) = self.panels.last_mut().and_then(|p| p.series.last_mut()) {
            s.color = Some(rgb);
        }
        self
    }

    /// Same scale on both axes of the last panel.
    pub fn equal_aspect(mut self) -> Self {
        if let Some(p) = self.panels.last_mut() {
            p.equal_aspect = true;
        }
        self
    }

    /// y axis from 0 in the last panel.
    pub fn y_from_zero(mut self) -> Self {
        if let Some(p) = self.panels.last_mut() {
            p.y_from_zero = true;
        }
        self
    }

    /// Every series' colour: its own, or [`PALETTE`] by its index in its panel.
    fn color_of(index: usize, s: &Series) -> (u8, u8, u8) {
        s.color.unwrap_or(PALETTE[index % PALETTE.len()])
    }

    /// Legend entries (one per distinct label, style and colour, in drawing order), laid out
    /// in rows that fit the figure's width; and the number of rows.
    fn legend(&self) -> (Vec<LegendEntry>, u32) {
        let mut entries: Vec<LegendEntry> = Vec::new();
        for panel in &self.panels {
            for (i, s) in panel.series.iter().enumerate() {
                let color = Self::color_of(i, s);
                if !entries
                    .iter()
                    .any(|e| e.label == s.label && e.style == s.style && e.color == color)
                {
                    entries.push(LegendEntry {
                        label: s.label.clone(),
                        style: s.style,
                        color,
                        x_px: 0,
                        row: 0,
                    });
                }
            }
        }
        let usable = self.size.0.saturating_sub(2 * MARGIN_PX);
        // Rows filled left to right, then each row centred.
        let (mut x, mut row) = (0u32, 0u32);
        let mut row_widths = vec![0u32];
        for e in &mut entries {
            let width = LEGEND_SAMPLE_PX + (e.label.chars().count() as f64 * LEGEND_CHAR_PX) as u32;
            if x > 0 && x + width > usable {
                row += 1;
                x = 0;
                row_widths.push(0);
            }
            e.x_px = x;
            e.row = row;
            x += width + LEGEND_GAP_PX;
            if let Some(w) = row_widths.last_mut() {
                *w = x - LEGEND_GAP_PX;
            }
        }
        for e in &mut entries {
            let row_width = row_widths.get(e.row as usize).copied().unwrap_or(0);
            e.x_px += MARGIN_PX + usable.saturating_sub(row_width) / 2;
        }
        let rows = if entries.is_empty() { 0 } else { row + 1 };
        (entries, rows)
    }

    /// Height of the legend strip below the panels.
    fn legend_px(rows: u32) -> u32 {
        rows * LEGEND_ROW_PX + MARGIN_PX
    }

    /// Renders the figure as an SVG document.
    pub fn to_svg(&self) -> Result<String> {
        let (legend, rows) = self.legend();
        let mut out = String::new();
        {
            let root = SVGBackend::with_string(&mut out, self.size).into_drawing_area();
            root.fill(&WHITE).map_err(|x| anyhow!("plot: {x:?}"))?;
            let body = root
                .titled(&self.title, ("sans-serif", TITLE_FONT_PX))
                .map_err(|x| anyhow!("plot: {x:?}"))?;
            let (_, body_h) = body.dim_in_pixel();
            let (charts, legend_area) =
                body.split_vertically(body_h.saturating_sub(Self::legend_px(rows)));
            let panels = charts.split_evenly((1, self.panels.len().max(1)));
            for (panel, area) in self.panels.iter().zip(&panels) {
                draw_panel(panel, area).map_err(|x| anyhow!("plot: {x:?}"))?;
            }
            draw_legend(&legend, &legend_area).map_err(|x| anyhow!("plot: {x:?}"))?;
            root.present().map_err(|x| anyhow!("plot: {x:?}"))?;
        }
        Ok(out)
    }

    /// Renders the figure into `path` (parent directories are created).
    pub fn write_svg(&self, path: &Path) -> Result<()> {
        let svg = self.to_svg()?;
        crate::replay::write_file(path, &svg)
    }
}

type Area<'a> = DrawingArea<SVGBackend<'a>, plotters::coord::Shift>;
type DrawResult = std::result::Result<(), DrawingAreaErrorKind<std::io::Error>>;

/// The pixel size of the plot area (inside the axes) that [`draw_panel`] gets in `area`: the
/// area less the margins, the axis label areas and the subtitle (plotters' `titled` takes the
/// text's height plus twice `min(height / 2, 5)`).
fn plot_area_px(area: &Area<'_>, subtitle: &str) -> (u32, u32) {
    let (w, h) = area.dim_in_pixel();
    let text_h = area
        .estimate_text_size(
            subtitle,
            &("sans-serif", SUBTITLE_FONT_PX).into_text_style(area),
        )
        .map_or(0, |(_, h)| h);
    let caption_h = text_h + 2 * (text_h / 2).min(5);
    (
        w.saturating_sub(2 * MARGIN_PX + Y_LABEL_AREA_PX),
        h.saturating_sub(2 * MARGIN_PX + X_LABEL_AREA_PX + caption_h),
    )
}

/// One panel: subtitle, axes, series in order.
fn draw_panel(panel: &Panel, area: &Area<'_>) -> DrawResult {
    let ((x0, x1), (y0, y1)) = panel.ranges(plot_area_px(area, &panel.subtitle));
    let mut chart = ChartBuilder::on(area)
        .caption(&panel.subtitle, ("sans-serif", SUBTITLE_FONT_PX))
        .margin(MARGIN_PX)
        .x_label_area_size(X_LABEL_AREA_PX)
        .y_label_area_size(Y_LABEL_AREA_PX)
        .build_cartesian_2d(x0..x1, y0..y1)?;
    chart
        .configure_mesh()
        .x_desc(&panel.x_label)
        .y_desc(&panel.y_label)
        .label_style(("sans-serif", TICK_FONT_PX))
        .axis_desc_style(("sans-serif", AXIS_FONT_PX))
        .light_line_style(RGBColor(238, 238, 238))
        .draw()?;
    for (i, s) in panel.series.iter().enumerate() {
        let (r, g, b) = Figure::color_of(i, s);
        let color = RGBColor(r, g, b);
        let pts = s
            .points
            .iter()
            .copied()
            .filter(|p| p.0.is_finite() && p.1.is_finite());
        match s.style {
            Style::Line { width_px } => {
                chart.draw_series(LineSeries::new(pts, color.stroke_width(width_px)))?;
            }
            Style::Points { radius_px } => {
                chart.draw_series(pts.map(|p| Circle::new(p, radius_px, color.filled())))?;
            }
        }
    }
    Ok(())
}

/// The legend strip: a sample of each series (line or marker as drawn) and its label.
fn draw_legend(entries: &[LegendEntry], area: &Area<'_>) -> DrawResult {
    let font = ("sans-serif", LEGEND_FONT_PX)
        .into_font()
        .color(&BLACK)
        .pos(Pos::new(HPos::Left, VPos::Center));
    for e in entries {
        let (r, g, b) = e.color;
        let color = RGBColor(r, g, b);
        let x = e.x_px as i32;
        let y = (e.row * LEGEND_ROW_PX + LEGEND_ROW_PX / 2) as i32;
        match e.style {
            Style::Line { width_px } => area.draw(&PathElement::new(
                vec![(x, y), (x + 22, y)],
                color.stroke_width(width_px.max(2)),
            ))?,
            Style::Points { radius_px } => {
                area.draw(&Circle::new((x + 11, y), radius_px.max(3), color.filled()))?
            }
        }
        area.draw(&Text::new(
            e.label.clone(),
            (x + LEGEND_SAMPLE_PX as i32, y),
            font.clone(),
        ))?;
    }
    Ok(())
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
            .subtitle("sub")
            .line("a line", vec![(0.0, 0.0), (1.0, 2.0), (2.0, 1.0)])
            .scatter("some points", vec![(0.5, 0.5), (1.5, f64::NAN), (1.0, 1.0)]);
        let svg = fig.to_svg().unwrap();
        assert!(svg.starts_with("<svg"), "{}", &svg[..40]);
        assert!(svg.trim_end().ends_with("</svg>"));
        // Text is escaped, and present as text elements (no rasterised glyphs).
        assert!(svg.contains("Title &lt;&amp;&gt;"));
        for t in ["sub", "time (s)", "error (m)", "a line", "some points"] {
            assert!(svg.contains(t), "missing {t}");
        }
        // Two finite scatter points (the NaN one is skipped) and the legend's marker.
        assert_eq!(svg.matches("<circle").count(), 3);
    }

    /// The legend is below the plot area: every legend text's y is below the x axis and its
    /// label area, i.e. no legend entry can cover data.
    #[test]
    fn legend_lies_below_the_panels() {
        let fig = Figure::new("t", "x", "y")
            .line("first series", vec![(0.0, 0.0), (1.0, 1.0)])
            .scatter("second series", vec![(0.5, 0.5)]);
        let (entries, rows) = fig.legend();
        assert_eq!((entries.len(), rows), (2, 1));
        let svg = fig.to_svg().unwrap();
        let legend_top = 600 - Figure::legend_px(rows);
        // The y attribute of the <text> element holding exactly `text`.
        let text_y = |text: &str| -> f64 {
            let at = svg.find(&format!("\n{text}\n</text>")).unwrap();
            let tag = &svg[svg[..at].rfind("<text").unwrap()..at];
            tag.split(" y=\"")
                .nth(1)
                .and_then(|s| s.split('"').next())
                .unwrap()
                .parse()
                .unwrap()
        };
        for label in ["first series", "second series"] {
            let y = text_y(label);
            assert!(y > f64::from(legend_top) && y < 600.0, "{label} at y {y}");
        }
        // The x axis description sits above the legend strip.
        let axis_y = text_y("x");
        assert!(axis_y < f64::from(legend_top), "axis label at {axis_y}");
    }

    #[test]
    fn long_legends_wrap_into_rows_within_the_width() {
        let mut fig = Figure::new("t", "x", "y");
        for i in 0..8 {
            fig = fig.line(
                &format!("a rather long series label number {i}"),
                vec![(0.0, 0.0)],
            );
        }
        let (entries, rows) = fig.legend();
        assert!(rows >= 3, "{rows}");
        for e in &entries {
            let end =
                e.x_px as f64 + f64::from(LEGEND_SAMPLE_PX) + e.label.len() as f64 * LEGEND_CHAR_PX;
            assert!(end <= 900.0, "{} ends at {end}", e.label);
        }
        // A repeated series (same label, style, colour) in a second panel is listed once.
        let two = Figure::new("t", "x", "y")
            .line("truth", vec![(0.0, 0.0)])
            .panel("zoom", "x", "y")
            .line("truth", vec![(0.0, 0.0)]);
        assert_eq!(two.legend().0.len(), 1);
    }

    /// A panel with one line through `points`.
    fn one_line(points: Vec<(f64, f64)>) -> Panel {
        let mut panel = Panel::new("", "x", "y");
        panel.series.push(Series {
            label: "l".into(),
            points,
            style: Style::Line { width_px: 1 },
            color: None,
        });
        panel
    }

    #[test]
    fn equal_aspect_gives_equal_units_per_pixel() {
        let mut panel = one_line(vec![(0.0, 0.0), (100.0, 10.0)]);
        panel.equal_aspect = true;
        let ((x0, x1), (y0, y1)) = panel.ranges((800, 400));
        assert!((((x1 - x0) / 800.0) - ((y1 - y0) / 400.0)).abs() < 1e-12);
        assert!(x0 < 0.0 && x1 > 100.0 && y0 < 0.0 && y1 > 10.0);
    }

    /// The plot area the ranges are computed for is the one plotters draws: the left panel of
    /// a two-panel 1400 px figure.
    #[test]
    fn plot_area_size_matches_what_plotters_draws() {
        let mut out = String::new();
        let root = SVGBackend::with_string(&mut out, (1400, 700)).into_drawing_area();
        let body = root.titled("t", ("sans-serif", TITLE_FONT_PX)).unwrap();
        let (_, body_h) = body.dim_in_pixel();
        let (charts, _) = body.split_vertically(body_h - Figure::legend_px(2));
        let panels = charts.split_evenly((1, 2));
        for subtitle in ["Enlarged: t = 1 .. 2 s", ""] {
            let chart = ChartBuilder::on(&panels[0])
                .caption(subtitle, ("sans-serif", SUBTITLE_FONT_PX))
                .margin(MARGIN_PX)
                .x_label_area_size(X_LABEL_AREA_PX)
                .y_label_area_size(Y_LABEL_AREA_PX)
                .build_cartesian_2d(0.0..100.0, 0.0..100.0)
                .unwrap();
            let drawn = chart.plotting_area().dim_in_pixel();
            let computed = plot_area_px(&panels[0], subtitle);
            assert!(
                drawn.0.abs_diff(computed.0) <= 1 && drawn.1.abs_diff(computed.1) <= 1,
                "{subtitle:?}: drawn {drawn:?}, computed {computed:?}"
            );
        }
    }

    #[test]
    fn y_from_zero_and_empty_figures() {
        let mut panel = one_line(vec![(0.0, 5.0), (1.0, 6.0)]);
        panel.y_from_zero = true;
        assert_eq!(panel.ranges((100, 100)).1 .0, 0.0);
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
