//! SVG of an induction-machine slip sweep: line current, input power and
//! (where measured) shaft torque against slip, the measured operating
//! points as dots and the fitted models as curves at each segment's mean
//! voltage, in one colour per segment (supply voltage), so each voltage's
//! points are read against its own curve; the legend sits above the
//! panels, off the data.

use std::path::{Path, PathBuf};

use plotters::prelude::*;

use crate::identify::{predict, ImIdentification, SweepPoint};
use crate::model::ImCircuit;
use crate::report::legend;
use crate::report::plot::tab10;

const FONT: &str = "sans-serif";
/// One colour per supply voltage (segment), for its points and curves.
const SEGMENT_COLOURS: [RGBColor; 6] = [
    tab10::BLUE,
    tab10::RED,
    tab10::GREEN,
    tab10::PURPLE,
    tab10::ORANGE,
    tab10::BROWN,
];

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

/// What a panel plots against slip.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Quantity {
    LineCurrent,
    InputPower,
    Torque,
}

impl Quantity {
    fn title(self) -> &'static str {
        match self {
            Quantity::LineCurrent => "line current",
            Quantity::InputPower => "input power",
            Quantity::Torque => "shaft torque (measured only)",
        }
    }

    fn axis(self) -> &'static str {
        match self {
            Quantity::LineCurrent => "line current (RMS) [A]",
            Quantity::InputPower => "input power [W]",
            Quantity::Torque => "torque [N·m]",
        }
    }

    /// The measured value of a point, if it has one.
    fn measured(self, p: &SweepPoint) -> Option<f64> {
        match self {
            Quantity::LineCurrent => Some(p.line_current),
            Quantity::InputPower => Some(p.input_power),
            Quantity::Torque => p.torque,
        }
    }
}

/// Render the sweep and the fitted curves as an SVG document: one panel
/// per quantity against slip (line current, input power, and the
/// measured shaft torque where the record has one), one colour per supply
/// voltage for its points and its model curves (LM solid, the recursive
/// estimate dashed), the legend in a band above the panels.
pub fn render_im_svg(id: &ImIdentification) -> Result<String, DrawError> {
    let draw_err = |e: &dyn std::fmt::Display| DrawError(e.to_string());
    let mut quantities = vec![Quantity::LineCurrent, Quantity::InputPower];
    if id.sweep.points.iter().any(|p| p.torque.is_some()) {
        quantities.push(Quantity::Torque);
    }
    let width = 600 * quantities.len() as u32;
    let conn = id.sweep.connection;
    let mut segments: Vec<u32> = id.sweep.points.iter().map(|p| p.segment).collect();
    segments.sort_unstable();
    segments.dedup();
    let mean_voltage = |seg: u32| {
        let v: Vec<f64> = id
            .sweep
            .points
            .iter()
            .filter(|p| p.segment == seg)
            .map(|p| p.line_voltage)
            .collect();
        v.iter().sum::<f64>() / v.len().max(1) as f64
    };
    let models = models(id);

    let mut entries = Vec::new();
    for (k, &seg) in segments.iter().enumerate() {
        let colour = SEGMENT_COLOURS[k % SEGMENT_COLOURS.len()].to_rgba();
        entries.push(legend::Entry {
            name: format!("measured, segment {seg} ({:.0} V)", mean_voltage(seg)),
            swatch: legend::Swatch::Dot(colour),
        });
    }
    for (m, (name, _)) in models.iter().enumerate() {
        entries.push(legend::Entry {
            name: format!("{name} (a curve per segment voltage)"),
            swatch: legend::Swatch::Line {
                colour: BLACK.to_rgba(),
                width: 2,
                dashed: m > 0,
            },
        });
    }
    let band = legend::lines_needed(&entries, width) * legend::LINE_HEIGHT + 8;

    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (width, 460 + band)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_err(&e))?;
        let (band_area, root) = root.split_vertically(band);
        legend::draw(&band_area.margin(6, 0, 0, 0), &entries).map_err(|e| draw_err(&e))?;
        let panels = root.split_evenly((1, quantities.len()));
        for (panel, &q) in panels.iter().zip(&quantities) {
            let values: Vec<f64> = id
                .sweep
                .points
                .iter()
                .filter_map(|p| q.measured(p))
                .collect();
            let ymax = values.iter().copied().fold(0.0f64, f64::max) * 1.1;
            let ymin = values.iter().copied().fold(0.0f64, f64::min) * 1.1;
            let mut chart = ChartBuilder::on(panel)
                .caption(q.title(), (FONT, 16))
                .margin(10)
                .x_label_area_size(36)
                .y_label_area_size(64)
                .build_cartesian_2d(0.0..1.0, ymin..ymax.max(1e-9))
                .map_err(|e| draw_err(&e))?;
            chart
                .configure_mesh()
                .x_desc("slip (0 synchronous, 1 locked rotor)")
                .y_desc(q.axis())
                .label_style((FONT, 12))
                .draw()
                .map_err(|e| draw_err(&e))?;
            for (k, &seg) in segments.iter().enumerate() {
                let colour = SEGMENT_COLOURS[k % SEGMENT_COLOURS.len()];
                if q != Quantity::Torque {
                    let v_phase = conn.phase_voltage(mean_voltage(seg));
                    for (m, (_, circuit)) in models.iter().enumerate() {
                        let curve = (0..=400).map(|j| {
                            let s = f64::from(j) / 400.0;
                            let (i, p) = predict(circuit, s, v_phase);
                            let y = if q == Quantity::InputPower {
                                p
                            } else {
                                conn.line_current(i)
                            };
                            (s, y.clamp(ymin, ymax))
                        });
                        let style = colour.stroke_width(2);
                        if m == 0 {
                            chart.draw_series(LineSeries::new(curve, style))
                        } else {
                            chart.draw_series(DashedLineSeries::new(curve, 7, 5, style))
                        }
                        .map_err(|e| draw_err(&e))?;
                    }
                }
                chart
                    .draw_series(
                        id.sweep
                            .points
                            .iter()
                            .filter(|p| p.segment == seg)
                            .filter_map(|p| Some((p.slip, q.measured(p)?)))
                            .map(|xy| Circle::new(xy, 4, colour.filled())),
                    )
                    .map_err(|e| draw_err(&e))?;
            }
        }
        root.present().map_err(|e| draw_err(&e))?;
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
            texts
                .iter()
                .filter(|t| **t == "lm (a curve per segment voltage)")
                .count(),
            1,
            "the legend names the LM curve once, above both panels"
        );
        assert!(!svg.contains("shaft torque"), "no torque was measured");
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
