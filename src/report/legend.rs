//! A legend drawn in a band of its own, above the panels it explains, so
//! that it never covers data (a legend inside a panel sits on whatever
//! the data puts in its corner). Entries run left to right and wrap.

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

/// Font of the legend's text.
const FONT: &str = "sans-serif";
/// Font size, px.
const FONT_SIZE: u32 = 13;
/// Height of one line of entries, px.
pub const LINE_HEIGHT: u32 = 20;
/// Length of a line sample, px.
const SAMPLE: i32 = 26;

/// How an entry's series is drawn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Swatch {
    /// A line of this colour and width; dashed when `dashed`.
    Line {
        /// Colour.
        colour: RGBAColor,
        /// Stroke width, px.
        width: u32,
        /// Dashed.
        dashed: bool,
    },
    /// A dot of this colour.
    Dot(RGBAColor),
}

/// One entry: a swatch and its name.
#[derive(Debug, Clone, PartialEq)]
pub struct Entry {
    /// The name shown.
    pub name: String,
    /// The sample drawn before it.
    pub swatch: Swatch,
}

/// Lines a band of `width` px needs for `entries` (at least 1).
pub fn lines_needed(entries: &[Entry], width: u32) -> u32 {
    let mut lines = 1;
    let mut x = 0;
    for e in entries {
        let w = entry_width(e);
        if x > 0 && x + w > width as i32 {
            lines += 1;
            x = 0;
        }
        x += w;
    }
    lines
}

/// Approximate width of an entry, px (the SVG backend does not measure
/// text; 0.6 em per character is generous for sans-serif).
fn entry_width(e: &Entry) -> i32 {
    SAMPLE + 8 + (e.name.chars().count() as i32 * FONT_SIZE as i32 * 6) / 10 + 22
}

/// Draws `entries` into `area`, from its left edge, wrapping at its width.
pub fn draw<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[Entry],
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let (width, _) = area.dim_in_pixel();
    let style = TextStyle::from((FONT, FONT_SIZE).into_font())
        .color(&BLACK)
        .pos(Pos::new(HPos::Left, VPos::Center));
    let (mut x, mut y) = (12, LINE_HEIGHT as i32 / 2);
    for e in entries {
        let w = entry_width(e);
        if x > 12 && x + w > width as i32 {
            x = 12;
            y += LINE_HEIGHT as i32;
        }
        match e.swatch {
            Swatch::Line {
                colour,
                width,
                dashed,
            } => {
                let style = ShapeStyle::from(colour).stroke_width(width);
                if dashed {
                    for k in 0..3 {
                        let x0 = x + k * 10;
                        area.draw(&PathElement::new(vec![(x0, y), (x0 + 6, y)], style))?;
                    }
                } else {
                    area.draw(&PathElement::new(vec![(x, y), (x + SAMPLE, y)], style))?;
                }
            }
            Swatch::Dot(colour) => {
                area.draw(&Circle::new((x + SAMPLE / 2, y), 4, colour.filled()))?;
            }
        }
        area.draw_text(&e.name, &style, (x + SAMPLE + 6, y))?;
        x += w;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(name: &str) -> Entry {
        Entry {
            name: name.into(),
            swatch: Swatch::Dot(BLACK.to_rgba()),
        }
    }

    #[test]
    fn entries_wrap_when_the_band_is_full() {
        let few = vec![entry("measured"), entry("model")];
        assert_eq!(lines_needed(&few, 1200), 1);
        let many: Vec<Entry> = (0..30)
            .map(|k| entry(&format!("model number {k}")))
            .collect();
        assert!(lines_needed(&many, 1200) >= 3);
        assert_eq!(lines_needed(&[], 1200), 1);
    }

    #[test]
    fn the_band_holds_every_name() {
        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, (400, 60)).into_drawing_area();
            let entries = vec![
                entry("measured"),
                Entry {
                    name: "output_error".into(),
                    swatch: Swatch::Line {
                        colour: RED.to_rgba(),
                        width: 2,
                        dashed: true,
                    },
                },
            ];
            draw(&root, &entries).unwrap();
            root.present().unwrap();
        }
        assert!(svg.contains("measured") && svg.contains("output_error"));
    }
}
