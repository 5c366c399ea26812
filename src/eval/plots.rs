//! Small PNG charts for run, sweep and bench reports: panels of line / point series with
//! a title, axis labels and a legend, drawn with `plotters` into an RGB buffer and
//! encoded by `image`.
//!
//! Text uses the DejaVu Sans subset embedded from `assets/fonts/` (registered with
//! plotters' `ab_glyph` backend), so plots look the same on every machine and never
//! touch system fonts (ultralytics #7645: a font download hanging offline runs). Output
//! is deterministic: same data, same bytes.

use std::path::Path;
use std::sync::Once;

use anyhow::{anyhow, Result};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::FontStyle;

/// The embedded font: a 10.7 KB subset of DejaVu Sans (licence in
/// `assets/fonts/LICENSE.txt`). Use even pixel sizes only: plotters' ab_glyph backend
/// places each glyph at `size / 2` truncated, which lifts a '.' at odd sizes.
static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans-subset.ttf");
pub(crate) const FAMILY: &str = "sans-serif";

/// A palette that stays distinguishable on white (Tableau 10).
pub const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// How a series is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mark {
    /// Polyline with a dot on each point.
    Line,
    /// Dots only.
    Points,
    /// Dashed-looking thin polyline without dots (e.g. a Pareto front under the points).
    Front,
    /// Thick polyline without dots, for dense curves (precision-recall, F1-confidence).
    Curve,
}

/// One labelled series of a panel.
#[derive(Clone, Debug)]
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
    /// ± error per point (drawn as a vertical bar), empty for none.
    pub err: Vec<f64>,
    /// Text next to each point (e.g. a variant name), empty for none.
    pub tags: Vec<String>,
    pub color: RGBColor,
    pub mark: Mark,
}

impl Series {
    pub fn new(label: impl Into<String>, points: Vec<(f64, f64)>, color: RGBColor) -> Series {
        Series {
            label: label.into(),
            points,
            err: Vec::new(),
            tags: Vec::new(),
            color,
            mark: Mark::Line,
        }
    }

    pub fn mark(mut self, m: Mark) -> Series {
        self.mark = m;
        self
    }

    pub fn err(mut self, e: Vec<f64>) -> Series {
        self.err = e;
        self
    }

    pub fn tags(mut self, t: Vec<String>) -> Series {
        self.tags = t;
        self
    }
}

/// One chart: title, axis labels, series; the y range is fixed when given (e.g. AP in
/// 0–1), else fitted to the data.
#[derive(Clone, Debug)]
pub struct Panel {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    pub y_range: Option<(f64, f64)>,
}

impl Panel {
    pub fn new(title: impl Into<String>, x_label: &str, y_label: &str) -> Panel {
        Panel {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series: Vec::new(),
            y_range: None,
        }
    }

    pub fn y_range(mut self, lo: f64, hi: f64) -> Panel {
        self.y_range = Some((lo, hi));
        self
    }

    pub fn push(mut self, s: Series) -> Panel {
        self.series.push(s);
        self
    }
}

pub(crate) fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The bytes are a valid TrueType file checked in with the source; a failure here
        // would show as missing text, which the plot tests catch.
        let _ = plotters::style::register_font(FAMILY, FontStyle::Normal, FONT);
    });
}

/// Data range padded by 5 % (a single value gets ±1, or ±5 % of itself).
fn fit(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if hi - lo < 1e-12 {
        let d = if lo.abs() > 1e-9 {
            lo.abs() * 0.05
        } else {
            1.0
        };
        return (lo - d, hi + d);
    }
    let pad = (hi - lo) * 0.05;
    (lo - pad, hi + pad)
}

/// A tick label with as many decimals as the axis span needs.
fn tick(v: f64, (lo, hi): (f64, f64)) -> String {
    let span = (hi - lo).abs();
    let d = if span >= 10.0 {
        0
    } else if span >= 2.0 {
        1
    } else if span >= 0.2 {
        2
    } else {
        3
    };
    format!("{v:.d$}")
}

fn draw_panel<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, p: &Panel) -> Result<()>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing {:?}: {e:?}", p.title);
    // Tagged points (scatter plots): room on the right for the tags.
    let tagged = p.series.iter().any(|s| !s.tags.is_empty());
    let mut xr = fit(p.series.iter().flat_map(|s| s.points.iter().map(|q| q.0)));
    if tagged {
        xr.1 += (xr.1 - xr.0) * 0.2;
    }
    let yr = p.y_range.unwrap_or_else(|| {
        fit(p.series.iter().flat_map(|s| {
            s.points.iter().enumerate().flat_map(|(i, q)| {
                let e = s.err.get(i).copied().unwrap_or(0.0);
                [q.1 - e, q.1 + e]
            })
        }))
    });
    let mut chart = ChartBuilder::on(area)
        .caption(&p.title, (FAMILY, 16))
        .margin(8)
        .x_label_area_size(34)
        .y_label_area_size(46)
        .build_cartesian_2d(xr.0..xr.1, yr.0..yr.1)
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc(&p.x_label)
        .y_desc(&p.y_label)
        .x_labels(6)
        .y_labels(6)
        .x_label_formatter(&|v| tick(*v, xr))
        .y_label_formatter(&|v| tick(*v, yr))
        .label_style((FAMILY, 12))
        .axis_desc_style((FAMILY, 12))
        .light_line_style(WHITE.mix(0.0))
        .bold_line_style(BLACK.mix(0.08))
        .draw()
        .map_err(err)?;
    for s in &p.series {
        let c = s.color;
        let pts = s.points.clone();
        let anno = match s.mark {
            Mark::Line => chart
                .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))
                .map_err(err)?,
            Mark::Front => chart
                .draw_series(LineSeries::new(pts.clone(), c.mix(0.6).stroke_width(1)))
                .map_err(err)?,
            Mark::Curve => chart
                .draw_series(LineSeries::new(pts.clone(), c.stroke_width(3)))
                .map_err(err)?,
            Mark::Points => chart
                .draw_series(pts.iter().map(|&q| Circle::new(q, 4, c.filled())))
                .map_err(err)?,
        };
        anno.label(s.label.clone())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], c.stroke_width(3)));
        if s.mark == Mark::Line {
            chart
                .draw_series(pts.iter().map(|&q| Circle::new(q, 2, c.filled())))
                .map_err(err)?;
        }
        for (i, &(x, y)) in pts.iter().enumerate() {
            if let Some(&e) = s.err.get(i).filter(|e| **e > 0.0) {
                chart
                    .draw_series(std::iter::once(PathElement::new(
                        vec![(x, y - e), (x, y + e)],
                        c.stroke_width(1),
                    )))
                    .map_err(err)?;
            }
            if let Some(t) = s.tags.get(i).filter(|t| !t.is_empty()) {
                chart
                    .draw_series(std::iter::once(Text::new(
                        t.clone(),
                        (x, y),
                        (FAMILY, 12).into_font().color(&BLACK.mix(0.8)),
                    )))
                    .map_err(err)?;
            }
        }
    }
    // Tagged scatter plots name their points; a legend box would cover some of them.
    if !tagged && p.series.iter().any(|s| !s.label.is_empty()) {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::LowerRight)
            .label_font((FAMILY, 12))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.3))
            .draw()
            .map_err(err)?;
    }
    Ok(())
}

/// PNG bytes of `panels` laid out in `cols` columns, each `panel_w` × `panel_h` pixels.
pub fn render_png(panels: &[Panel], cols: usize, panel_w: u32, panel_h: u32) -> Result<Vec<u8>> {
    register_font();
    let cols = cols.clamp(1, panels.len().max(1));
    let rows = panels.len().div_ceil(cols).max(1);
    let (w, h) = (panel_w * cols as u32, panel_h * rows as u32);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        let areas = root.split_evenly((rows, cols));
        for (a, p) in areas.iter().zip(panels) {
            draw_panel(a, p)?;
        }
        root.present()
            .map_err(|e| anyhow!("finishing the plot: {e:?}"))?;
    }
    let png = crate::util::png::encode_rgb8(&buf, w, h, image::codecs::png::CompressionType::Best)?;
    Ok(png)
}

/// Renders `panels` and writes them atomically to `path`.
pub fn write_png(
    path: &Path,
    panels: &[Panel],
    cols: usize,
    panel_w: u32,
    panel_h: u32,
) -> Result<()> {
    let png = render_png(panels, cols, panel_w, panel_h)?;
    crate::util::write_atomic(path, &png)
}

/// Indices of the points on the upper-left Pareto front of (cost, value) pairs: no
/// other point is at most as costly and strictly better, or strictly cheaper and at least
/// as good. Sorted by cost.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..points.len())
        .filter(|&i| points[i].0.is_finite() && points[i].1.is_finite())
        .collect();
    idx.sort_by(|&a, &b| {
        points[a]
            .0
            .total_cmp(&points[b].0)
            .then(points[b].1.total_cmp(&points[a].1))
    });
    let mut front = Vec::new();
    let mut best = f64::NEG_INFINITY;
    for i in idx {
        if points[i].1 > best {
            best = points[i].1;
            front.push(i);
        }
    }
    front
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_front_keeps_only_undominated_points() {
        let p = [(1.0, 0.5), (2.0, 0.4), (3.0, 0.7), (0.5, 0.1), (3.0, 0.6)];
        assert_eq!(pareto_front(&p), vec![3, 0, 2]);
        assert!(pareto_front(&[]).is_empty());
        assert_eq!(pareto_front(&[(1.0, f64::NAN), (2.0, 0.3)]), vec![1]);
    }

    #[test]
    fn fit_pads_and_handles_constants() {
        assert_eq!(fit([2.0, 2.0].into_iter()), (1.9, 2.1));
        assert_eq!(fit(std::iter::empty()), (0.0, 1.0));
        let (lo, hi) = fit([0.0, 10.0].into_iter());
        assert!((lo + 0.5).abs() < 1e-12 && (hi - 10.5).abs() < 1e-12);
    }

    fn panel() -> Panel {
        Panel::new("AP per epoch", "epoch", "AP")
            .y_range(0.0, 1.0)
            .push(Series::new(
                "segm AP",
                vec![(1.0, 0.2), (2.0, 0.5)],
                PALETTE[0],
            ))
            .push(
                Series::new("points", vec![(1.5, 0.3)], PALETTE[1])
                    .mark(Mark::Points)
                    .err(vec![0.1])
                    .tags(vec!["n".into()]),
            )
    }

    #[test]
    fn png_is_deterministic_and_has_text() {
        let a = render_png(&[panel()], 1, 320, 240).unwrap();
        let b = render_png(&[panel()], 1, 320, 240).unwrap();
        assert_eq!(a, b);
        let img = image::load_from_memory(&a).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (320, 240));
        // The title is drawn: dark pixels in the top 20 rows around the centre, where no
        // axis or series reaches.
        let dark = (0..20)
            .flat_map(|y| (100..220).map(move |x| (x, y)))
            .filter(|&(x, y)| img.get_pixel(x, y).0.iter().all(|&c| c < 128))
            .count();
        assert!(dark > 20, "no title text drawn ({dark} dark pixels)");
    }
}
