//! SVG of the held-out residuals before and after the verdict's effect,
//! one panel per region of the gap.

use std::path::Path;

use plotters::prelude::*;

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

/// The residual plot could not be drawn or written.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}: {reason}", path.display())]
pub struct ResidualPlotError {
    /// The output file.
    pub path: std::path::PathBuf,
    /// What the plotting library reported.
    pub reason: String,
}

/// Write `plot` as one SVG, panels stacked; before in red, after in blue.
pub fn write_residual_svg(plot: &ResidualPlot, path: &Path) -> Result<(), ResidualPlotError> {
    let panels = plot.panels.len().max(1);
    let root = SVGBackend::new(path, (PANEL_W, PANEL_H * panels as u32)).into_drawing_area();
    let err = |e: &dyn std::fmt::Display| ResidualPlotError {
        path: path.to_path_buf(),
        reason: e.to_string(),
    };
    root.fill(&WHITE).map_err(|e| err(&e))?;
    if plot.panels.is_empty() {
        root.titled("no residual to plot", ("sans-serif", 16))
            .map_err(|e| err(&e))?;
    }
    for (area, panel) in root.split_evenly((panels, 1)).iter().zip(&plot.panels) {
        draw_panel(area, panel, &plot.effect).map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    panel: &ResidualPanel,
    effect: &str,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let finite = |v: &&f64| v.is_finite();
    let (x0, x1) = bounds(panel.x.iter().filter(finite).copied());
    let (y0, y1) = bounds(
        panel
            .before
            .iter()
            .chain(&panel.after)
            .filter(finite)
            .copied(),
    );
    let mut chart = ChartBuilder::on(area)
        .caption(&panel.title, ("sans-serif", 15))
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
    chart
        .draw_series(LineSeries::new(series(&panel.before), RED))?
        .label("nominal model")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], RED));
    chart
        .draw_series(LineSeries::new(series(&panel.after), BLUE))?
        .label(format!("with {effect}"))
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLUE));
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
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
    }
}
