//! SVG plots of measured and modelled segment responses.
//!
//! Each test segment becomes one row of two panels: armature current \[A\] and
//! speed \[rad/s\], both against the time since the start of the test \[s\].
//! The first trace of each panel is the measurement, drawn first as a wide
//! light-grey band, so that it stays visible around the models drawn over
//! it; every further trace is a model response, a narrower line in its own
//! colour, every second one dashed so that two models that agree both show.
//! Model `k` has the same colour and dash in both panels of every row, and
//! the row's legend sits in a band of its own under the row's title, never
//! on the data.
//!
//! Records are long (kilohertz sampling, seconds per segment), so every trace
//! is reduced with min/max bucketing before drawing: the samples are split
//! into at most 750 consecutive buckets and both the smallest and the
//! largest sample of each bucket are kept, in time order (at most 1500
//! points per trace). Spikes survive,
//! and the SVG stays small. Samples whose time or value is not finite are
//! skipped; a trace longer or shorter than its time vector is cut to the
//! common prefix.
//!
//! Text (titles, tick labels, legend) is emitted by the SVG backend as
//! `<text>` elements, so no font files are needed to render.

use std::fmt;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::legend;
use crate::record::ClockCut;

/// Total width of the picture in pixels.
const WIDTH: u32 = 1200;
/// Height of one segment row in pixels.
const ROW_HEIGHT: u32 = 300;
/// Most buckets a trace is reduced to; each bucket yields at most two points,
/// so a drawn trace has at most `2 * MAX_BUCKETS` points.
const MAX_BUCKETS: usize = 750;
/// Largest magnitude shown on an axis; larger values are drawn clamped.
const AXIS_LIMIT: f64 = 1e12;
/// Relative margin added above and below the data on the y axis.
const Y_MARGIN: f64 = 0.05;
/// Font family for all text.
const FONT: &str = "sans-serif";

/// Colour of the measured trace: a light band under the models.
const MEASURED_COLOUR: RGBColor = RGBColor(175, 175, 175);
/// Width of the measured band, px.
const MEASURED_WIDTH: u32 = 5;
/// Width of a model's line, px.
const MODEL_WIDTH: u32 = 2;
/// Colour of the line that marks a cut in the time axis (drawn dashed).
const CUT_COLOUR: RGBColor = RGBColor(90, 90, 90);
/// Width of the line that marks a cut, px.
const CUT_WIDTH: u32 = 1;
/// Colours of model traces, cycled when there are more models than colours.
const MODEL_COLOURS: [RGBColor; 8] = [
    tab10::BLUE,
    tab10::RED,
    tab10::GREEN,
    tab10::ORANGE,
    tab10::PURPLE,
    tab10::CYAN,
    tab10::BROWN,
    tab10::PINK,
];

/// The plots' colours by name: those of matplotlib's `tab10` palette.
pub(crate) mod tab10 {
    use plotters::style::RGBColor;

    /// Blue.
    pub const BLUE: RGBColor = RGBColor(31, 119, 180);
    /// Red.
    pub const RED: RGBColor = RGBColor(214, 39, 40);
    /// Green.
    pub const GREEN: RGBColor = RGBColor(44, 160, 44);
    /// Orange.
    pub const ORANGE: RGBColor = RGBColor(255, 127, 14);
    /// Purple.
    pub const PURPLE: RGBColor = RGBColor(148, 103, 189);
    /// Cyan.
    pub const CYAN: RGBColor = RGBColor(23, 190, 207);
    /// Brown.
    pub const BROWN: RGBColor = RGBColor(140, 86, 75);
    /// Pink.
    pub const PINK: RGBColor = RGBColor(227, 119, 194);
}

/// One named curve.
#[derive(Debug, Clone, PartialEq)]
pub struct Trace {
    /// Name shown in the legend.
    pub name: String,
    /// One value per sample, aligned with [`SegmentPlot::time`].
    pub values: Vec<f64>,
}

/// One segment's panel pair: current and speed against time; the first trace
/// of each is the measurement, the others are models.
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentPlot {
    /// Row title, usually naming the segment.
    pub title: String,
    /// Sample times in seconds, shared by every trace of the segment.
    pub time: Vec<f64>,
    /// Armature current traces in amperes: measurement first, then models.
    pub current: Vec<Trace>,
    /// Speed traces in rad/s: measurement first, then models.
    pub speed: Vec<Trace>,
    /// Where the time axis leaves out part of a long hold the analysis
    /// does not read, at or before this segment: one within the segment
    /// is drawn as a dashed line marked with what it leaves out; any of
    /// them says so on the time axis.
    pub cuts: Vec<ClockCut>,
}

/// Why a plot could not be produced.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The plotting library failed to draw the chart.
    #[error("cannot render segment plot{}: {reason}", target_suffix(.path.as_deref()))]
    Render {
        /// The output file, when rendering for [`write_segments_svg`].
        path: Option<PathBuf>,
        /// What the plotting library reported.
        reason: String,
    },
    /// The SVG could not be written to its file.
    #[error("cannot write segment plot to {}", .path.display())]
    Write {
        /// The output file.
        path: PathBuf,
        /// The I/O failure.
        #[source]
        source: std::io::Error,
    },
}

/// `" for PATH"` when there is an output path, nothing otherwise.
fn target_suffix(path: Option<&Path>) -> String {
    path.map(|p| format!(" for {}", p.display()))
        .unwrap_or_default()
}

/// Wraps a plotting-library error without an output path.
fn render_error(err: impl fmt::Display) -> PlotError {
    PlotError::Render {
        path: None,
        reason: err.to_string(),
    }
}

/// Render all segments into one SVG: one row per segment, two panels per row
/// (armature current \[A\], speed \[rad/s\] against time \[s\]), measured drawn as a
/// wide light-grey band under the models, each model trace in a distinct
/// colour (every second dashed), a legend band naming each trace under the
/// row title = segment title. Width 1200 px, height 300 px per row.
///
/// Every trace is reduced to at most 1500 points by min/max bucketing, so the
/// output size does not grow with the record length. Non-finite samples are
/// skipped. An empty `plots` gives a single row saying "no segments".
///
/// # Errors
///
/// [`PlotError::Render`] when the plotting library fails (not expected for
/// the in-memory SVG backend).
pub fn render_segments_svg(plots: &[SegmentPlot]) -> Result<String, PlotError> {
    let rows = u32::try_from(plots.len().max(1)).unwrap_or(u32::MAX);
    let height = ROW_HEIGHT.saturating_mul(rows);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (WIDTH, height)).into_drawing_area();
        root.fill(&WHITE).map_err(render_error)?;
        if plots.is_empty() {
            let style = TextStyle::from((FONT, 20).into_font())
                .color(&BLACK)
                .pos(Pos::new(HPos::Center, VPos::Center));
            root.draw_text(
                "no segments",
                &style,
                (WIDTH as i32 / 2, ROW_HEIGHT as i32 / 2),
            )
            .map_err(render_error)?;
        } else {
            let areas = root.split_evenly((plots.len(), 1));
            for (plot, area) in plots.iter().zip(&areas) {
                draw_row(area, plot)?;
            }
        }
        root.present().map_err(render_error)?;
    }
    Ok(dash(svg, plots))
}

/// The stroke attributes of the model lines drawn dashed: every model
/// whose position makes it dashed (see `curves`), by its colour.
fn dashed_strokes(plots: &[SegmentPlot]) -> Vec<String> {
    let most = plots
        .iter()
        .map(|p| p.current.len().max(p.speed.len()))
        .max()
        .unwrap_or(0);
    let stroke = |RGBColor(r, g, b): RGBColor, width: u32| {
        format!("stroke=\"#{r:02X}{g:02X}{b:02X}\" stroke-width=\"{width}\"")
    };
    (2..most)
        .filter(|&i| is_dashed(i))
        .map(|i| stroke(MODEL_COLOURS[(i - 1) % MODEL_COLOURS.len()], MODEL_WIDTH))
        .chain(
            plots
                .iter()
                .any(|p| !p.cuts.is_empty())
                .then(|| stroke(CUT_COLOUR, CUT_WIDTH)),
        )
        .collect()
}

/// `svg` with every dashed model's lines given a dash pattern.
fn dash(mut svg: String, plots: &[SegmentPlot]) -> String {
    for stroke in dashed_strokes(plots) {
        svg = svg.replace(&stroke, &format!("{stroke} stroke-dasharray=\"7 5\""));
    }
    svg
}

/// Render with [`render_segments_svg`] and write the SVG to `path`,
/// replacing any existing file.
///
/// # Errors
///
/// [`PlotError::Render`] when drawing fails, [`PlotError::Write`] when the
/// file cannot be written; both name `path`.
pub fn write_segments_svg(path: &Path, plots: &[SegmentPlot]) -> Result<(), PlotError> {
    let svg = render_segments_svg(plots).map_err(|err| match err {
        PlotError::Render { reason, .. } => PlotError::Render {
            path: Some(path.to_path_buf()),
            reason,
        },
        other => other,
    })?;
    std::fs::write(path, svg).map_err(|source| PlotError::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// A trace ready to draw: decimated finite points, legend name, colour.
struct Curve<'a> {
    name: &'a str,
    points: Vec<(f64, f64)>,
    colour: RGBColor,
    width: u32,
    dashed: bool,
}

impl Curve<'_> {
    fn legend_entry(&self) -> legend::Entry {
        legend::Entry {
            name: self.name.to_string(),
            swatch: legend::Swatch::Line {
                colour: self.colour.to_rgba(),
                width: self.width,
                dashed: self.dashed,
            },
        }
    }
}

/// Which quantity a panel shows.
#[derive(Clone, Copy)]
enum Quantity {
    Current,
    Speed,
}

impl Quantity {
    fn axis_label(self) -> &'static str {
        match self {
            Quantity::Current => "armature current [A]",
            Quantity::Speed => "speed [rad/s]",
        }
    }
}

/// Draw one segment row: title over a current panel and a speed panel.
fn draw_row<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    plot: &SegmentPlot,
) -> Result<(), PlotError> {
    let body = area
        .titled(&plot.title, (FONT, 18).into_font().color(&BLACK))
        .map_err(render_error)?;
    let current = curves(&plot.time, &plot.current);
    let speed = curves(&plot.time, &plot.speed);

    // One legend for the row: every name of either panel, once.
    let mut entries: Vec<legend::Entry> = Vec::new();
    for c in current.iter().chain(&speed) {
        if !entries.iter().any(|e| e.name == c.name) {
            entries.push(c.legend_entry());
        }
    }
    let band = legend::lines_needed(&entries, WIDTH) * legend::LINE_HEIGHT + 2;
    let (band_area, body) = body.split_vertically(band);
    legend::draw(&band_area, &entries).map_err(render_error)?;

    // Both panels share the time axis so they line up.
    let time_range = padded_range(
        current
            .iter()
            .chain(&speed)
            .flat_map(|c| c.points.iter().map(|p| p.0)),
        0.0,
    );

    let panels = body.split_evenly((1, 2));
    draw_panel(
        &panels[0],
        Quantity::Current,
        time_range,
        &current,
        &plot.cuts,
    )?;
    draw_panel(&panels[1], Quantity::Speed, time_range, &speed, &plot.cuts)?;
    Ok(())
}

/// Whether the trace at position `i` of a panel (0: the measurement) is
/// drawn dashed: every second model, so two models that agree both show.
fn is_dashed(i: usize) -> bool {
    i >= 2 && i % 2 == 0
}

/// Decimated curves of one panel, with colours by position.
fn curves<'a>(time: &[f64], traces: &'a [Trace]) -> Vec<Curve<'a>> {
    traces
        .iter()
        .enumerate()
        .map(|(i, trace)| {
            let (colour, width) = if i == 0 {
                (MEASURED_COLOUR, MEASURED_WIDTH)
            } else {
                (MODEL_COLOURS[(i - 1) % MODEL_COLOURS.len()], MODEL_WIDTH)
            };
            Curve {
                name: &trace.name,
                points: decimate_min_max(time, &trace.values, MAX_BUCKETS),
                colour,
                width,
                dashed: is_dashed(i),
            }
        })
        .collect()
}

/// Draw one panel: axes, grid, every curve and a legend.
fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    quantity: Quantity,
    time_range: (f64, f64),
    curves: &[Curve<'_>],
    cuts: &[ClockCut],
) -> Result<(), PlotError> {
    let value_range = padded_range(
        curves.iter().flat_map(|c| c.points.iter().map(|p| p.1)),
        Y_MARGIN,
    );
    let mut chart = ChartBuilder::on(area)
        .margin_left(4)
        .margin_right(12)
        .margin_top(4)
        .margin_bottom(2)
        .x_label_area_size(34)
        .y_label_area_size(62)
        .build_cartesian_2d(time_range.0..time_range.1, value_range.0..value_range.1)
        .map_err(render_error)?;

    let x_span = time_range.1 - time_range.0;
    let y_span = value_range.1 - value_range.0;
    let x_format = move |v: &f64| format_tick(*v, x_span);
    let y_format = move |v: &f64| format_tick(*v, y_span);
    chart
        .configure_mesh()
        .x_desc(match cuts {
            [] => "time since the start [s]",
            _ => "time since the start, less what is left out [s]",
        })
        .y_desc(quantity.axis_label())
        .x_labels(8)
        .y_labels(6)
        .max_light_lines(0)
        .bold_line_style(RGBColor(225, 225, 225))
        .label_style((FONT, 12))
        .axis_desc_style((FONT, 13))
        .x_label_formatter(&x_format)
        .y_label_formatter(&y_format)
        .draw()
        .map_err(render_error)?;

    for curve in curves {
        let style = ShapeStyle::from(&curve.colour).stroke_width(curve.width);
        // Clamp so out-of-range values (beyond `AXIS_LIMIT`) stay inside the
        // panel instead of reaching far outside the picture.
        let points = curve.points.iter().map(|&(t, v)| {
            (
                t.clamp(time_range.0, time_range.1),
                v.clamp(value_range.0, value_range.1),
            )
        });
        // Dashed curves are dashed by the SVG itself (see `dash`): one
        // polyline, not one element per dash.
        chart
            .draw_series(LineSeries::new(points, style))
            .map_err(render_error)?;
    }
    // A cut: a dashed line where the clock jumps (dashed by `dash`), and
    // what it leaves out beside it at the top.
    let label = TextStyle::from((FONT, 12).into_font())
        .color(&CUT_COLOUR)
        .pos(Pos::new(HPos::Left, VPos::Top));
    for cut in cuts
        .iter()
        .filter(|c| (time_range.0..=time_range.1).contains(&c.at_s))
    {
        let style = ShapeStyle::from(&CUT_COLOUR).stroke_width(CUT_WIDTH);
        let line = [(cut.at_s, value_range.0), (cut.at_s, value_range.1)];
        chart
            .draw_series(LineSeries::new(line, style))
            .map_err(render_error)?;
        let text = format!("{:.1} s left out", cut.left_out_s);
        let mark = EmptyElement::at((cut.at_s, value_range.1)) + Text::new(text, (4, 2), &label);
        chart
            .draw_series(std::iter::once(mark))
            .map_err(render_error)?;
    }
    Ok(())
}

/// Reduce `(time, values)` to at most `2 * max_buckets` points.
///
/// Uses the common prefix of `time` and `values`, drops samples whose time
/// or value is not finite, then splits the rest into `max_buckets`
/// consecutive buckets of (nearly) equal sample count and keeps the
/// smallest and the largest sample of each bucket, in their original order.
/// The global extremes therefore always survive.
fn decimate_min_max(time: &[f64], values: &[f64], max_buckets: usize) -> Vec<(f64, f64)> {
    let finite: Vec<(f64, f64)> = time
        .iter()
        .zip(values)
        .filter(|(t, v)| t.is_finite() && v.is_finite())
        .map(|(&t, &v)| (t, v))
        .collect();
    let n = finite.len();
    let buckets = max_buckets.max(1);
    if n <= 2 * buckets {
        return finite;
    }
    let mut out = Vec::with_capacity(2 * buckets);
    for b in 0..buckets {
        let start = b * n / buckets;
        let end = (b + 1) * n / buckets;
        let bucket = &finite[start..end];
        let Some(first) = bucket.first() else {
            continue;
        };
        let (mut lo, mut hi) = (0, 0);
        let (mut lo_v, mut hi_v) = (first.1, first.1);
        for (i, p) in bucket.iter().enumerate().skip(1) {
            if p.1 < lo_v {
                lo = i;
                lo_v = p.1;
            }
            if p.1 > hi_v {
                hi = i;
                hi_v = p.1;
            }
        }
        let (a, b) = if lo <= hi { (lo, hi) } else { (hi, lo) };
        out.push(bucket[a]);
        if b != a {
            out.push(bucket[b]);
        }
    }
    out
}

/// Finite axis range of `values`, widened by `margin` of its span on each
/// side.
///
/// Values are first clamped to `±AXIS_LIMIT`. A single value, a flat series
/// or one whose spread is lost in rounding (relative spread below 1e-9) gets
/// a window of ±5 % around its centre, or ±1 around zero; no values give
/// `0..1`. The plotting library's tick search does not terminate on
/// infinite or rounding-sized ranges, so every range drawn comes from here.
fn padded_range(values: impl Iterator<Item = f64>, margin: f64) -> (f64, f64) {
    let Some((lo, hi)) = values
        .filter(|v| v.is_finite())
        .map(|v| v.clamp(-AXIS_LIMIT, AXIS_LIMIT))
        .fold(None, |acc: Option<(f64, f64)>, v| match acc {
            None => Some((v, v)),
            Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
        })
    else {
        return (0.0, 1.0);
    };
    let centre = lo / 2.0 + hi / 2.0;
    let span = hi - lo;
    if span > (centre.abs() * 1e-9).max(1e-12) {
        let pad = span * margin;
        (lo - pad, hi + pad)
    } else {
        let half = if centre.abs() > 1e-9 {
            centre.abs() * 0.05
        } else {
            1.0
        };
        (centre - half, centre + half)
    }
}

/// Tick label text for `value` on an axis spanning `span`.
///
/// Fixed-point with enough decimals to resolve a tenth of the span; values
/// of a million or more, and non-zero ticks of an axis narrower than 1e-5,
/// in scientific notation.
fn format_tick(value: f64, span: f64) -> String {
    let magnitude = value.abs();
    let narrow = span.is_finite() && span < 1e-5;
    if magnitude >= 1e6 || (narrow && magnitude >= span * 1e-3) {
        return format!("{value:.2e}");
    }
    let decimals = if span.is_finite() && span > 0.0 {
        // Clamped to 0..=6, so the cast cannot truncate.
        (1.0 - span.log10().floor()).clamp(0.0, 6.0) as usize
    } else {
        2
    };
    let text = format!("{value:.decimals$}");
    // Avoid "-0.00" for a value that rounds to zero.
    match text.strip_prefix('-') {
        Some(rest) if rest.chars().all(|c| c == '0' || c == '.') => rest.to_string(),
        _ => text,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trace(name: &str, values: Vec<f64>) -> Trace {
        Trace {
            name: name.to_string(),
            values,
        }
    }

    /// A 2 kHz segment of `n` samples with a measured trace and two models.
    fn segment(title: &str, n: usize) -> SegmentPlot {
        let time: Vec<f64> = (0..n).map(|i| i as f64 / 2000.0).collect();
        let wave = |k: f64| -> Vec<f64> {
            time.iter()
                .enumerate()
                .map(|(i, t)| (t * k).sin() * 3.0 + ((i * 7919) % 101) as f64 * 0.01)
                .collect()
        };
        SegmentPlot {
            title: title.to_string(),
            time: time.clone(),
            current: vec![
                trace("measured", wave(5.0)),
                trace("model dc", wave(5.1)),
                trace("model friction", wave(4.9)),
            ],
            speed: vec![
                trace("measured", wave(2.0)),
                trace("model dc", wave(2.1)),
                trace("model friction", wave(1.9)),
            ],
            cuts: vec![],
        }
    }

    fn assert_svg_document(svg: &str) {
        assert!(svg.starts_with("<svg"), "starts with {:?}", &svg[..20]);
        assert!(svg.trim_end().ends_with("</svg>"));
        assert_eq!(svg.matches("<svg").count(), 1);
        assert_eq!(svg.matches("</svg>").count(), 1);
        assert_eq!(svg.matches("<text").count(), svg.matches("</text>").count());
    }

    #[test]
    fn svg_names_titles_axes_and_legend() {
        let plots = vec![segment("step 1: 12 V", 400), segment("ramp to 24 V", 300)];
        let svg = render_segments_svg(&plots).unwrap();
        assert_svg_document(&svg);
        for needle in [
            "step 1: 12 V",
            "ramp to 24 V",
            "measured",
            "model dc",
            "model friction",
            "armature current [A]",
            "speed [rad/s]",
            "time since the start [s]",
        ] {
            assert!(svg.contains(needle), "missing {needle:?}");
        }
        assert!(svg.contains(r#"height="600""#));
        assert!(svg.contains(r#"width="1200""#));
    }

    #[test]
    fn text_is_escaped() {
        let mut plot = segment("load <50 % & \"hot\"", 100);
        plot.current[1].name = "model <a>".to_string();
        let svg = render_segments_svg(&[plot]).unwrap();
        assert!(svg.contains("load &lt;50 % &amp; &quot;hot&quot;"));
        assert!(svg.contains("model &lt;a&gt;"));
    }

    #[test]
    fn empty_list_says_no_segments() {
        let svg = render_segments_svg(&[]).unwrap();
        assert_svg_document(&svg);
        assert!(svg.contains("no segments"));
    }

    #[test]
    fn decimation_keeps_spikes_and_order() {
        let n = 20_000;
        let time: Vec<f64> = (0..n).map(|i| i as f64 * 5e-4).collect();
        let mut values: Vec<f64> = (0..n).map(|i| (i as f64 * 0.01).sin()).collect();
        values[12_345] = 40.0;
        values[777] = -25.0;
        let points = decimate_min_max(&time, &values, MAX_BUCKETS);
        assert!(points.len() <= 2 * MAX_BUCKETS);
        assert!(points.contains(&(time[12_345], 40.0)));
        assert!(points.contains(&(time[777], -25.0)));
        assert!(points.windows(2).all(|w| w[0].0 < w[1].0));
        let max = points.iter().map(|p| p.1).fold(f64::MIN, f64::max);
        let min = points.iter().map(|p| p.1).fold(f64::MAX, f64::min);
        assert_eq!((min, max), (-25.0, 40.0));
    }

    #[test]
    fn decimation_short_input_is_unchanged_and_cut_to_prefix() {
        let time = [0.0, 1.0, 2.0, 3.0];
        let values = [5.0, f64::NAN, 7.0];
        assert_eq!(
            decimate_min_max(&time, &values, MAX_BUCKETS),
            vec![(0.0, 5.0), (2.0, 7.0)]
        );
        assert!(decimate_min_max(&[], &[1.0], MAX_BUCKETS).is_empty());
    }

    #[test]
    fn spike_reaches_the_svg() {
        let mut plot = segment("spike", 20_000);
        plot.current[0].values[9_999] = 1000.0;
        let svg = render_segments_svg(&[plot.clone()]).unwrap();
        // The y axis is scaled to include the spike: a top tick near 1000.
        let range = padded_range(
            curves(&plot.time, &plot.current)
                .iter()
                .flat_map(|c| c.points.iter().map(|p| p.1)),
            Y_MARGIN,
        );
        assert!(range.1 > 1000.0 && range.1 < 1100.0, "{range:?}");
        assert!(svg.contains(">\n1000") || svg.contains(">\n1000.0"));
    }

    #[test]
    fn the_measurement_is_a_wide_band_drawn_under_the_models() {
        let svg = render_segments_svg(&[segment("band", 400)]).unwrap();
        // The last panel (after the legend band): its band, then its models.
        let measured = svg
            .rfind(r##"stroke="#AFAFAF" stroke-width="5" points"##)
            .expect("the measured band");
        let model = svg
            .rfind(r##"stroke="#1F77B4" stroke-width="2" points"##)
            .expect("the first model's line");
        assert!(
            measured < model,
            "the band is drawn first, under the models"
        );
    }

    #[test]
    fn every_second_model_is_dashed_by_the_svg() {
        let svg = render_segments_svg(&[segment("dashes", 400)]).unwrap();
        // "model friction" is the second model: red, dashed.
        assert!(svg.contains(r##"stroke="#D62728" stroke-width="2" stroke-dasharray="7 5""##));
        // The first model is solid.
        assert!(svg.contains(r##"stroke="#1F77B4" stroke-width="2" points"##));
        assert!(!svg.contains(r##"stroke="#1F77B4" stroke-width="2" stroke-dasharray"##));
    }

    #[test]
    fn a_cut_in_the_time_axis_is_marked_and_said() {
        let plain = render_segments_svg(&[segment("whole", 400)]).unwrap();
        assert!(plain.contains("time since the start [s]"));
        assert!(!plain.contains("left out"));
        let mut cut = segment("cut", 400);
        cut.cuts = vec![
            // Before this segment: it shifts its clock, not drawn here.
            ClockCut {
                segment: 0,
                at_s: -1.0,
                left_out_s: 3.0,
            },
            ClockCut {
                segment: 1,
                at_s: 0.1,
                left_out_s: 58.04,
            },
        ];
        let svg = render_segments_svg(&[cut]).unwrap();
        assert_svg_document(&svg);
        // In both panels, once each: the drawn cut only.
        assert_eq!(svg.matches("58.0 s left out").count(), 2);
        assert!(!svg.contains("3.0 s left out"));
        assert_eq!(
            svg.matches("time since the start, less what is left out [s]")
                .count(),
            2
        );
        // The line is dashed by the SVG.
        assert!(svg.contains(r##"stroke="#5A5A5A" stroke-width="1" stroke-dasharray="7 5""##));
    }

    #[test]
    fn ten_long_segments_stay_small() {
        let plots: Vec<SegmentPlot> = (0..10)
            .map(|i| segment(&format!("segment {i}"), 20_000))
            .collect();
        let svg = render_segments_svg(&plots).unwrap();
        assert_svg_document(&svg);
        assert!(svg.len() < 2_000_000, "svg is {} bytes", svg.len());
        for i in 0..10 {
            assert!(svg.contains(&format!("segment {i}")));
        }
    }

    #[test]
    fn non_finite_and_degenerate_input_does_not_panic() {
        let time: Vec<f64> = (0..50).map(|i| i as f64 * 0.01).collect();
        let mut bad_time = time.clone();
        bad_time[3] = f64::NAN;
        bad_time[4] = f64::INFINITY;
        let plots = vec![
            SegmentPlot {
                title: "all nan".into(),
                time: time.clone(),
                current: vec![trace("measured", vec![f64::NAN; 50])],
                speed: vec![trace("measured", vec![f64::INFINITY; 50])],
                cuts: vec![],
            },
            SegmentPlot {
                title: "empty traces".into(),
                time: time.clone(),
                current: vec![trace("measured", vec![]), trace("model", vec![])],
                speed: vec![],
                cuts: vec![],
            },
            SegmentPlot {
                title: "no time".into(),
                time: vec![],
                current: vec![trace("measured", vec![1.0, 2.0])],
                speed: vec![trace("measured", vec![1.0])],
                cuts: vec![],
            },
            SegmentPlot {
                title: "flat and single".into(),
                time: bad_time,
                current: vec![trace("measured", vec![2.5; 50])],
                speed: vec![trace("measured", vec![0.0])],
                cuts: vec![],
            },
            SegmentPlot {
                title: "huge".into(),
                time,
                current: vec![trace("measured", vec![f64::MAX, f64::MIN, 0.0])],
                speed: vec![trace("measured", vec![1e-300, -1e-300])],
                cuts: vec![],
            },
        ];
        let svg = render_segments_svg(&plots).unwrap();
        assert_svg_document(&svg);
        for title in ["all nan", "empty traces", "no time", "flat and single"] {
            assert!(svg.contains(title));
        }
    }

    #[test]
    fn awkward_ranges_render() {
        // Ranges on which an unguarded tick search would never finish.
        let n = 200;
        let cases: [(&str, f64, f64, f64); 6] = [
            ("epoch time", 1.7e9, 5e-4, 1.0),
            ("offset with rounding-sized noise", 0.0, 5e-4, 1e6),
            ("tiny amplitude", 0.0, 5e-4, 0.0),
            ("beyond the axis limit", 0.0, 5e-4, 1e300),
            ("subnormal", 0.0, 5e-4, 0.0),
            ("huge time step", -1e200, 1e199, 3.0),
        ];
        let plots: Vec<SegmentPlot> = cases
            .iter()
            .enumerate()
            .map(|(k, &(title, t0, dt, offset))| {
                let time = (0..n).map(|i| t0 + i as f64 * dt).collect();
                let values = (0..n)
                    .map(|i| {
                        let wiggle = (i % 3) as f64;
                        match k {
                            1 => offset + wiggle * 1e-11,
                            2 => wiggle * 1e-13,
                            3 => offset * (wiggle - 1.0),
                            4 => wiggle * 1e-310,
                            _ => offset + wiggle,
                        }
                    })
                    .collect();
                SegmentPlot {
                    title: title.into(),
                    time,
                    current: vec![trace("measured", values)],
                    speed: vec![],
                    cuts: vec![],
                }
            })
            .collect();
        let svg = render_segments_svg(&plots).unwrap();
        assert_svg_document(&svg);
        for (title, ..) in cases {
            assert!(svg.contains(title));
        }
    }

    #[test]
    fn tick_labels_are_short() {
        assert_eq!(format_tick(0.5, 1.5), "0.5");
        assert_eq!(format_tick(-1e-17, 1.5), "0.0");
        assert_eq!(format_tick(200.0, 1100.0), "200");
        assert_eq!(format_tick(0.02, 0.14), "0.02");
        assert_eq!(format_tick(2e6, 4e6), "2.00e6");
        assert_eq!(format_tick(3e-7, 1e-6), "3.00e-7");
        assert_eq!(format_tick(1.0, f64::NAN), "1.00");
    }

    #[test]
    fn ranges_are_padded_and_never_empty() {
        assert_eq!(padded_range([0.0, 10.0].into_iter(), 0.05), (-0.5, 10.5));
        let (lo, hi) = padded_range([3.0, 3.0].into_iter(), 0.05);
        assert!(lo < 3.0 && hi > 3.0);
        let (lo, hi) = padded_range([0.0].into_iter(), 0.05);
        assert!(lo < 0.0 && hi > 0.0);
        assert_eq!(padded_range(std::iter::empty(), 0.05), (0.0, 1.0));
        let (lo, hi) = padded_range([f64::MAX, f64::MIN].into_iter(), 0.05);
        assert!(lo.is_finite() && hi.is_finite() && lo < hi);
    }

    #[test]
    fn write_reports_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("plot.svg");
        write_segments_svg(&path, &[segment("written", 100)]).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(text.contains("written"));

        let missing = dir.path().join("no such dir").join("plot.svg");
        let err = write_segments_svg(&missing, &[]).unwrap_err();
        assert!(matches!(err, PlotError::Write { .. }));
        assert!(err.to_string().contains("no such dir"), "{err}");
    }
}
