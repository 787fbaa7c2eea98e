//! SVG of the held-out residuals before and after the verdict's effect,
//! one panel per region of the gap.
//!
//! A residual on a time axis carries the sensors' quantisation (an
//! encoder-derived speed jumps by one count per sample period), which
//! hides the misfit the diagnosis is about: each residual is drawn raw, as
//! a thin pale line, and as its moving mean over a window long enough to
//! average the quantisation out, as a bold line. A verdict of `none`
//! models nothing, so only the nominal residual is drawn. The legend sits
//! in a band of its own above the panels.

use std::path::Path;

use plotters::prelude::*;

use crate::report::legend;

/// One panel: a region's residual, before and after.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ResidualPanel {
    /// Title, e.g. `armature_current · segment 3 · transient`.
    pub title: String,
    /// Label of the x axis, e.g. `time in segment (s)` or `slip`.
    pub x_label: String,
    /// Unit of the residual, e.g. `A`.
    pub unit: String,
    /// Positions on the x axis.
    pub x: Vec<f64>,
    /// Residual of the nominal model (measured − simulated).
    pub before: Vec<f64>,
    /// Residual with the effect modelled.
    pub after: Vec<f64>,
}

/// Every panel of a diagnosis.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ResidualPlot {
    /// Name of the effect the "after" residual models (`none`: equal to before).
    pub effect: String,
    /// Panels, most important region first.
    pub panels: Vec<ResidualPanel>,
}

const PANEL_W: u32 = 900;
const PANEL_H: u32 = 260;
/// Colour of the nominal model's residual.
const BEFORE: RGBColor = RGBColor(214, 39, 40);
/// Colour of the residual with the effect modelled.
const AFTER: RGBColor = RGBColor(31, 119, 180);
/// Most samples a moving mean spans.
const MAX_WINDOW: usize = 50;
/// Most points a panel marks one by one (operating points, not samples).
const MARKED: usize = 60;

/// The residual plot could not be drawn or written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}: {reason}", path.display())]
pub struct ResidualPlotError {
    /// The output file.
    pub path: std::path::PathBuf,
    /// What the plotting library reported.
    pub reason: String,
}

/// Whether the "after" residual is drawn: the effect models something.
fn shows_after(plot: &ResidualPlot) -> bool {
    plot.effect != "none"
}

/// The moving-mean window of a residual of `n` samples: about a
/// hundredth of them, 1 (no smoothing) for a few operating points.
fn window(n: usize) -> usize {
    (n / 100).clamp(1, MAX_WINDOW)
}

/// The legend of `plot`'s panels (each panel's title says its window).
fn legend_entries(plot: &ResidualPlot) -> Vec<legend::Entry> {
    let smoothed = plot.panels.iter().any(|p| window(p.x.len()) > 1);
    let mut out = Vec::new();
    let mut pair = |colour: RGBColor, name: &str| {
        if smoothed {
            out.push(legend::Entry {
                name: format!("{name}, moving mean"),
                swatch: legend::Swatch::Line {
                    colour: colour.to_rgba(),
                    width: 2,
                    dashed: false,
                },
            });
            out.push(legend::Entry {
                name: format!("{name}, raw"),
                swatch: legend::Swatch::Line {
                    colour: colour.mix(0.3),
                    width: 1,
                    dashed: false,
                },
            });
        } else {
            out.push(legend::Entry {
                name: name.to_string(),
                swatch: legend::Swatch::Line {
                    colour: colour.to_rgba(),
                    width: 2,
                    dashed: false,
                },
            });
        }
    };
    if shows_after(plot) {
        pair(BEFORE, "nominal model");
        pair(AFTER, &format!("with {}", plot.effect));
    } else {
        pair(BEFORE, "nominal model (verdict: none, nothing to add)");
    }
    out
}

/// Write `plot` as one SVG, panels stacked; before in red, after in blue.
pub fn write_residual_svg(plot: &ResidualPlot, path: &Path) -> Result<(), ResidualPlotError> {
    let panels = plot.panels.len().max(1);
    let entries = legend_entries(plot);
    let band = legend::lines_needed(&entries, PANEL_W) * legend::LINE_HEIGHT + 6;
    let root = SVGBackend::new(path, (PANEL_W, band + PANEL_H * panels as u32)).into_drawing_area();
    let err = |e: &dyn std::fmt::Display| ResidualPlotError {
        path: path.to_path_buf(),
        reason: e.to_string(),
    };
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let (band_area, root) = root.split_vertically(band);
    legend::draw(&band_area.margin(4, 0, 0, 0), &entries).map_err(|e| err(&e))?;
    if plot.panels.is_empty() {
        root.titled("no residual to plot", ("sans-serif", 16))
            .map_err(|e| err(&e))?;
    }
    for (area, panel) in root.split_evenly((panels, 1)).iter().zip(&plot.panels) {
        draw_panel(area, panel, shows_after(plot)).map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))
}

/// The centred moving mean of `ys` over `w` samples (shorter at the ends);
/// non-finite samples are left out of every mean.
fn moving_mean(ys: &[f64], w: usize) -> Vec<f64> {
    let half = w / 2;
    (0..ys.len())
        .map(|k| {
            let window = &ys[k.saturating_sub(half)..(k + half + 1).min(ys.len())];
            let (sum, n) = window
                .iter()
                .filter(|v| v.is_finite())
                .fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
            if n == 0 {
                f64::NAN
            } else {
                sum / n as f64
            }
        })
        .collect()
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    panel: &ResidualPanel,
    after: bool,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let finite = |v: &&f64| v.is_finite();
    let (x0, x1) = bounds(panel.x.iter().filter(finite).copied());
    let shown: &[f64] = if after { &panel.after } else { &[] };
    let (y0, y1) = bounds(panel.before.iter().chain(shown).filter(finite).copied());
    let w = window(panel.x.len());
    let caption = if w > 1 {
        format!("{} · moving mean of {w} samples", panel.title)
    } else {
        panel.title.clone()
    };
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 15))
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1, y0..y1)?;
    chart
        .configure_mesh()
        .x_desc(&panel.x_label)
        .y_desc(format!("residual ({})", panel.unit))
        .draw()?;
    let series = |ys: &[f64]| -> Vec<(f64, f64)> {
        panel
            .x
            .iter()
            .zip(ys)
            .filter(|(x, y)| x.is_finite() && y.is_finite())
            .map(|(&x, &y)| (x, y))
            .collect()
    };
    let mut drawn = vec![(&panel.before, BEFORE)];
    if after {
        drawn.push((&panel.after, AFTER));
    }
    for (ys, colour) in &drawn {
        if w > 1 {
            chart.draw_series(LineSeries::new(series(ys), colour.mix(0.3)))?;
        }
    }
    for (ys, colour) in drawn {
        let mean = if w > 1 {
            moving_mean(ys, w)
        } else {
            ys.clone()
        };
        chart.draw_series(LineSeries::new(series(&mean), colour.stroke_width(2)))?;
        if panel.x.len() <= MARKED {
            // A few operating points: each one marked.
            chart.draw_series(
                series(ys)
                    .into_iter()
                    .map(|xy| Circle::new(xy, 3, colour.filled())),
            )?;
        }
    }
    Ok(())
}

fn bounds(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if !lo.is_finite() || !hi.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-12);
    (lo - pad, hi + pad)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_one_panel_per_region() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("r.svg");
        let panel = |t: &str| ResidualPanel {
            title: t.into(),
            x_label: "time in segment (s)".into(),
            unit: "A".into(),
            x: vec![0.0, 0.1, 0.2],
            before: vec![0.3, 0.1, f64::NAN],
            after: vec![0.01, -0.02, 0.0],
        };
        let plot = ResidualPlot {
            effect: "brush_drop".into(),
            panels: vec![panel("transient"), panel("settled")],
        };
        write_residual_svg(&plot, &path).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(svg.contains("transient") && svg.contains("settled"));
        assert!(svg.contains("with brush_drop"));
        // A verdict of none draws the nominal residual alone.
        let none = ResidualPlot {
            effect: "none".into(),
            ..plot
        };
        write_residual_svg(&none, &path).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(svg.contains("verdict: none") && !svg.contains("with none"));
    }

    #[test]
    fn the_moving_mean_averages_out_a_quantisation_step() {
        // A residual that flips between two levels one count apart.
        let ys: Vec<f64> = (0..1000)
            .map(|k| if k % 2 == 0 { 0.6 } else { -0.6 })
            .collect();
        let w = window(ys.len());
        assert_eq!(w, 10);
        let mean = moving_mean(&ys, w);
        assert!(
            mean[10..990].iter().all(|m| m.abs() < 0.2),
            "{:?}",
            &mean[..20]
        );
        assert_eq!(moving_mean(&[1.0, f64::NAN, 3.0], 3), vec![1.0, 2.0, 3.0]);
        assert_eq!(window(20), 1, "a few operating points stay as they are");
    }
}
