//! SVG of an induction-machine slip sweep: line current and input power
//! against slip, the measured operating points as dots (one colour per
//! segment) and the fitted models as curves at each segment's mean voltage.

use std::path::{Path, PathBuf};

use plotters::prelude::*;

use crate::identify::{predict, ImIdentification};
use crate::model::ImCircuit;

const FONT: &str = "sans-serif";
const SEGMENT_COLOURS: [RGBColor; 4] = [
    RGBColor(60, 60, 60),
    RGBColor(120, 120, 120),
    RGBColor(31, 119, 180),
    RGBColor(148, 103, 189),
];
const MODEL_COLOURS: [RGBColor; 2] = [RGBColor(214, 39, 40), RGBColor(44, 160, 44)];

/// The models worth drawing: LM, and the recursive estimate when it applies.
fn models(id: &ImIdentification) -> Vec<(&'static str, ImCircuit)> {
    let mut out = Vec::new();
    if let Some(f) = &id.lm {
        out.push(("lm", f.circuit));
    }
    if let (Some(r), Some(m)) = (&id.recursive, id.report.methods.get("recursive")) {
        if m.applies {
            out.push(("recursive", r.circuit));
        }
    }
    out
}

/// The plotting library could not draw the sweep plot: its error's text.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct DrawError(pub String);

/// Why the sweep plot could not be written.
#[derive(Debug, thiserror::Error)]
pub enum SweepPlotError {
    /// The plot could not be drawn.
    #[error("cannot render the sweep plot for {}: {source}", path.display())]
    Render {
        /// The output file.
        path: PathBuf,
        /// The plotting library's error.
        #[source]
        source: DrawError,
    },
    /// The SVG could not be written to its file.
    #[error("cannot write {}: {source}", path.display())]
    Write {
        /// The output file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
}

/// Render the sweep and the fitted curves as an SVG document.
pub fn render_im_svg(id: &ImIdentification) -> Result<String, DrawError> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1200, 460)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| DrawError(e.to_string()))?;
        let panels = root.split_evenly((1, 2));
        let conn = id.sweep.connection;
        let mut segments: Vec<u32> = id.sweep.points.iter().map(|p| p.segment).collect();
        segments.sort_unstable();
        segments.dedup();
        for (panel, power) in panels.iter().zip([false, true]) {
            let value = |line_current: f64, input_power: f64| {
                if power {
                    input_power
                } else {
                    line_current
                }
            };
            let ymax = id
                .sweep
                .points
                .iter()
                .map(|p| value(p.line_current, p.input_power))
                .fold(0.0f64, f64::max)
                * 1.1;
            let ymin = id
                .sweep
                .points
                .iter()
                .map(|p| value(p.line_current, p.input_power))
                .fold(0.0f64, f64::min);
            let mut chart = ChartBuilder::on(panel)
                .caption(
                    if power { "input power" } else { "line current" },
                    (FONT, 16),
                )
                .margin(10)
                .x_label_area_size(36)
                .y_label_area_size(64)
                .build_cartesian_2d(0.0..1.0, ymin..ymax.max(1e-9))
                .map_err(|e| DrawError(e.to_string()))?;
            chart
                .configure_mesh()
                .x_desc("slip")
                .y_desc(if power { "P [W]" } else { "I [A]" })
                .label_style((FONT, 12))
                .draw()
                .map_err(|e| DrawError(e.to_string()))?;
            for (k, seg) in segments.iter().enumerate() {
                let pts: Vec<_> = id
                    .sweep
                    .points
                    .iter()
                    .filter(|p| p.segment == *seg)
                    .collect();
                let colour = SEGMENT_COLOURS[k % SEGMENT_COLOURS.len()];
                let mean_v = pts.iter().map(|p| p.line_voltage).sum::<f64>() / pts.len() as f64;
                chart
                    .draw_series(pts.iter().map(|p| {
                        Circle::new(
                            (p.slip, value(p.line_current, p.input_power)),
                            3,
                            colour.filled(),
                        )
                    }))
                    .map_err(|e| DrawError(e.to_string()))?
                    .label(format!("measured, segment {seg} ({mean_v:.0} V)"))
                    .legend(move |(x, y)| Circle::new((x + 8, y), 3, colour.filled()));
                for (m, (name, circuit)) in models(id).into_iter().enumerate() {
                    let colour = MODEL_COLOURS[m % MODEL_COLOURS.len()];
                    let v_phase = conn.phase_voltage(mean_v);
                    let curve = (0..=400).map(|j| {
                        let s = f64::from(j) / 400.0;
                        let (i, p) = predict(&circuit, s, v_phase);
                        (s, if power { p } else { conn.line_current(i) })
                    });
                    let series = chart
                        .draw_series(LineSeries::new(curve, colour.stroke_width(2)))
                        .map_err(|e| DrawError(e.to_string()))?;
                    if k == 0 {
                        series.label(name).legend(move |(x, y)| {
                            PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
                        });
                    }
                }
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::LowerRight)
                .background_style(WHITE.mix(0.85))
                .border_style(RGBColor(160, 160, 160))
                .label_font((FONT, 12))
                .draw()
                .map_err(|e| DrawError(e.to_string()))?;
        }
        root.present().map_err(|e| DrawError(e.to_string()))?;
    }
    Ok(svg)
}

/// Write [`render_im_svg`] to `path`.
pub fn write_im_svg(path: &Path, id: &ImIdentification) -> Result<(), SweepPlotError> {
    let svg = render_im_svg(id).map_err(|source| SweepPlotError::Render {
        path: path.to_path_buf(),
        source,
    })?;
    std::fs::write(path, svg).map_err(|source| SweepPlotError::Write {
        path: path.to_path_buf(),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::{identify_im, slip_grid, SlipSweep, SweepNoise};
    use crate::model::im_fixtures::{single_cage, STAR_400V_50HZ};
    use crate::model::{Connection, ImModel};
    use crate::record::Record;

    #[test]
    fn svg_shows_points_and_curves() {
        let c = single_cage(1.5, 3.0, 90.0, None, 1.6, 3.0);
        let sw = SlipSweep::simulate_seeded(
            &c,
            &STAR_400V_50HZ,
            &slip_grid(20, 0.002),
            &SweepNoise::relative(0.003),
            2,
        );
        let points = sw.operating_points(50.0);
        let id = identify_im(
            &Record {
                operating_points: points,
                ..Record::default()
            },
            Some(Connection::Star),
            ImModel::Single,
        );
        let svg = render_im_svg(&id).unwrap();
        assert!(
            svg.starts_with("<svg") && svg.contains("line current") && svg.contains("input power")
        );
        assert!(svg.contains("measured, segment 0"));
        assert!(svg.matches("<circle").count() >= 40, "dots of both panels");
        let texts: Vec<&str> = svg
            .split("</text>")
            .filter_map(|chunk| chunk.rsplit('>').next())
            .map(str::trim)
            .collect();
        assert_eq!(
            texts.iter().filter(|t| **t == "lm").count(),
            2,
            "legend names the LM curve in both panels"
        );
        // A file that cannot be written is told from a plot that cannot
        // be drawn.
        let path = Path::new("/nonexistent-directory/sweep.svg");
        let e = write_im_svg(path, &id).unwrap_err();
        assert!(matches!(e, SweepPlotError::Write { .. }), "{e:?}");
        assert!(e
            .to_string()
            .starts_with("cannot write /nonexistent-directory/sweep.svg: "));
    }
}
