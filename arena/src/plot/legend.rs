//! A legend drawn in its own area beside a chart: one row per entry, a marker and a label.

use super::{err, PlotError, FONT};
use plotters::coord::Shift;
use plotters::prelude::*;

/// What a legend row shows before its label.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Marker {
    /// A filled square of the colour (a car).
    Swatch,
    /// A line.
    Line,
    /// A dashed line.
    Dashed,
    /// A filled circle.
    Circle,
    /// A filled square with a black outline.
    Square,
    /// A diagonal cross.
    Cross,
    /// A small dot.
    Dot,
    /// A hollow diamond.
    Diamond,
}

/// Rows of a legend: `(marker, colour, label)`.
#[derive(Debug, Clone, Default)]
pub struct Legend(pub Vec<(Marker, RGBColor, String)>);

/// Height of a legend row, px.
const ROW: i32 = 22;

impl Legend {
    /// Adds a row.
    pub fn push(&mut self, marker: Marker, colour: RGBColor, label: impl Into<String>) {
        self.0.push((marker, colour, label.into()));
    }

    /// Draws the rows from the top of `area`, after a margin of `top` px.
    pub fn draw<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        top: i32,
    ) -> Result<(), PlotError> {
        let text = TextStyle::from((FONT, 17).into_font()).color(&BLACK);
        for (i, (marker, c, label)) in self.0.iter().enumerate() {
            let y = top + ROW / 2 + ROW * i as i32;
            let x = 14;
            marker_at(area, *marker, *c, (x, y))?;
            area.draw(&Text::new(label.as_str(), (x + 20, y - 8), text.clone()))
                .map_err(err)?;
        }
        Ok(())
    }
}

/// Draws `marker` centred on `(x, y)` px of `area`.
pub fn marker_at<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    marker: Marker,
    c: RGBColor,
    (x, y): (i32, i32),
) -> Result<(), PlotError> {
    let line =
        |a: (i32, i32), b: (i32, i32), w: u32| PathElement::new(vec![a, b], c.stroke_width(w));
    match marker {
        Marker::Swatch => area
            .draw(&Rectangle::new(
                [(x - 7, y - 7), (x + 7, y + 7)],
                c.filled(),
            ))
            .map_err(err),
        Marker::Line => area.draw(&line((x - 9, y), (x + 9, y), 3)).map_err(err),
        Marker::Dashed => {
            area.draw(&line((x - 9, y), (x - 3, y), 2)).map_err(err)?;
            area.draw(&line((x + 3, y), (x + 9, y), 2)).map_err(err)
        }
        Marker::Circle => area.draw(&Circle::new((x, y), 5, c.filled())).map_err(err),
        Marker::Square => {
            area.draw(&Rectangle::new(
                [(x - 5, y - 5), (x + 5, y + 5)],
                c.filled(),
            ))
            .map_err(err)?;
            area.draw(&Rectangle::new(
                [(x - 5, y - 5), (x + 5, y + 5)],
                BLACK.stroke_width(1),
            ))
            .map_err(err)
        }
        Marker::Cross => {
            area.draw(&line((x - 5, y - 5), (x + 5, y + 5), 2))
                .map_err(err)?;
            area.draw(&line((x - 5, y + 5), (x + 5, y - 5), 2))
                .map_err(err)
        }
        Marker::Dot => area.draw(&Circle::new((x, y), 2, c.filled())).map_err(err),
        Marker::Diamond => area
            .draw(&PathElement::new(diamond((x, y)), c.stroke_width(2)))
            .map_err(err),
    }
}

/// A closed diamond path around `(x, y)` px.
pub fn diamond((x, y): (i32, i32)) -> Vec<(i32, i32)> {
    vec![(x, y - 6), (x + 6, y), (x, y + 6), (x - 6, y), (x, y - 6)]
}
