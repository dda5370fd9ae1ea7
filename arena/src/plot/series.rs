//! Plots against time: each phase's error, the closest approach of two cars, and the radio
//! state broadcasts heard per second of each car.

use super::{colour_of, err, rgb, Draw, Legend, Marker, PlotError, RunPlots, FONT};
use crate::metrics::{self, COLLISION_MM};
use plotters::coord::Shift;
use plotters::prelude::*;

/// Width of the chart part, px (the legend takes the rest).
const CHART_W: u32 = 660;
/// Phase colours (a palette apart from the cars').
const PHASE_COLOURS: [(u8, u8, u8); 6] = [
    (33, 33, 33),
    (0, 114, 178),
    (213, 94, 0),
    (0, 158, 115),
    (204, 121, 167),
    (230, 159, 0),
];
const GREY: RGBColor = RGBColor(150, 150, 150);

/// One line of a time plot.
struct Line {
    colour: RGBColor,
    points: Vec<(f64, f64)>,
    dashed: bool,
}

/// A plot of values against time (s since the first phase started).
pub struct TimePlot {
    title: String,
    y_desc: String,
    caption: String,
    lines: Vec<Line>,
    legend: Legend,
    /// Times at which a later phase began (thin vertical lines).
    boundaries: Vec<f64>,
    x_max: f64,
}

impl TimePlot {
    /// The report's caption.
    pub fn caption(&self) -> String {
        self.caption.clone()
    }

    fn y_max(&self) -> f64 {
        let top = self
            .lines
            .iter()
            .flat_map(|l| l.points.iter().map(|p| p.1))
            .filter(|v| v.is_finite())
            .fold(0.0, f64::max);
        if top > 0.0 {
            top * 1.1
        } else {
            1.0
        }
    }
}

impl Draw for TimePlot {
    fn size(&self) -> (u32, u32) {
        (920, 500)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), PlotError> {
        let (chart_area, legend_area) = root.split_horizontally(CHART_W);
        let y_max = self.y_max();
        let mut chart = ChartBuilder::on(&chart_area)
            .caption(self.title.as_str(), (FONT, 22))
            .margin(12)
            .x_label_area_size(48)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..self.x_max, 0.0..y_max)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("time since the first phase started (s)")
            .y_desc(self.y_desc.as_str())
            .x_labels(10)
            .y_labels(8)
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.0}"))
            .label_style((FONT, 16))
            .axis_desc_style((FONT, 18))
            .max_light_lines(1)
            .light_line_style(RGBColor(242, 242, 242))
            .bold_line_style(RGBColor(220, 220, 220))
            .draw()
            .map_err(err)?;
        for &t in &self.boundaries {
            chart
                .draw_series(LineSeries::new(
                    [(t, 0.0), (t, y_max)],
                    GREY.stroke_width(1),
                ))
                .map_err(err)?;
        }
        for l in &self.lines {
            let style = l.colour.stroke_width(2);
            if l.dashed {
                chart
                    .draw_series(DashedLineSeries::new(l.points.clone(), 8, 5, style))
                    .map_err(err)?;
            } else {
                chart
                    .draw_series(LineSeries::new(l.points.clone(), style))
                    .map_err(err)?;
            }
        }
        let mut legend = Legend(self.legend.0.clone());
        if !self.boundaries.is_empty() {
            legend.push(Marker::Line, GREY, "a later phase began");
        }
        legend.draw(&legend_area, 60)
    }
}

/// The end of the run on the time axis.
fn x_max(p: &RunPlots) -> f64 {
    let end = p
        .tracks
        .iter()
        .filter_map(|t| t.last().map(|s| s.t))
        .chain(p.phases.iter().map(|s| s.end_s))
        .fold(0.0, f64::max);
    end.max(1.0)
}

fn plot(p: &RunPlots, title: &str, y_desc: &str, caption: String) -> TimePlot {
    TimePlot {
        title: format!("{}: {title}", p.title),
        y_desc: y_desc.into(),
        caption,
        lines: Vec::new(),
        legend: Legend::default(),
        boundaries: p.phases.iter().skip(1).map(|s| s.start_s).collect(),
        x_max: x_max(p),
    }
}

fn phase_error(p: &RunPlots) -> TimePlot {
    let mut out = plot(
        p,
        "phase error",
        "phase error (mm)",
        "Each phase's error against time (formation: the largest slot error; rendezvous: the \
         spread; circle: the circle error; go-to: the largest distance from the last point), \
         dashed: its tolerance"
            .into(),
    );
    for (i, ph) in p.phases.iter().enumerate() {
        let colour = rgb(PHASE_COLOURS[i % PHASE_COLOURS.len()]);
        let points: Vec<(f64, f64)> = p
            .phase_errors
            .iter()
            .filter(|r| r.1 == ph.phase)
            .map(|r| (r.0, r.2))
            .collect();
        out.lines.push(Line {
            colour,
            points,
            dashed: false,
        });
        out.lines.push(Line {
            colour,
            points: vec![(ph.start_s, ph.tolerance_mm), (ph.end_s, ph.tolerance_mm)],
            dashed: true,
        });
        out.legend.push(
            Marker::Line,
            colour,
            format!("phase {} ({})", ph.phase, ph.kind),
        );
        out.legend.push(
            Marker::Dashed,
            colour,
            format!("its tolerance ({} mm)", round_text(ph.tolerance_mm)),
        );
    }
    out
}

fn separation(p: &RunPlots) -> TimePlot {
    let mut out = plot(
        p,
        "closest approach",
        "smallest distance between cars (mm)",
        format!(
            "The smallest distance between two cars' body centres against time; dashed: the \
             collision distance ({COLLISION_MM:.0} mm)"
        ),
    );
    let series: Vec<(f64, f64)> = metrics::separation_series(&p.tracks);
    let red = RGBColor(214, 39, 40);
    out.lines.push(Line {
        colour: BLACK,
        points: series,
        dashed: false,
    });
    out.lines.push(Line {
        colour: red,
        points: vec![(0.0, COLLISION_MM), (out.x_max, COLLISION_MM)],
        dashed: true,
    });
    out.legend.push(Marker::Line, BLACK, "closest pair of cars");
    out.legend.push(
        Marker::Dashed,
        red,
        format!("collision ({COLLISION_MM:.0} mm)"),
    );
    out
}

/// `v` with one decimal, or none when it is whole.
fn round_text(v: f64) -> String {
    let r = (v * 10.0).round() / 10.0;
    if r.fract() == 0.0 {
        format!("{r:.0}")
    } else {
        format!("{r:.1}")
    }
}

/// Per-second rates from a counter sampled over time: one point at the end of each second.
pub fn per_second(counts: &[(f64, u64)]) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    let Some(&(mut t0, mut c0)) = counts.first() else {
        return out;
    };
    for &(t, c) in counts {
        let dt = t - t0;
        if dt >= 1.0 - 1e-6 {
            out.push((t, c.saturating_sub(c0) as f64 / dt));
            (t0, c0) = (t, c);
        }
    }
    out
}

fn radio(p: &RunPlots) -> TimePlot {
    let mut out = plot(
        p,
        "radio delivery",
        "states heard per second",
        "Radio state broadcasts of each car that the ground station heard, per second".into(),
    );
    for (k, id) in p.ids.iter().enumerate() {
        let colour = rgb(colour_of(k));
        let points = p
            .states_heard
            .get(k)
            .map(|c| per_second(c))
            .unwrap_or_default();
        out.lines.push(Line {
            colour,
            points,
            dashed: false,
        });
        out.legend.push(Marker::Swatch, colour, format!("car {id}"));
    }
    out
}

/// The time plots, with their file stems.
pub fn all(p: &RunPlots) -> Vec<(&'static str, TimePlot)> {
    vec![
        ("phase_error", phase_error(p)),
        ("separation", separation(p)),
        ("radio", radio(p)),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_are_per_whole_second() {
        let counts: Vec<(f64, u64)> = (0..=30)
            .map(|i| (f64::from(i) * 0.1, 3 * i as u64))
            .collect();
        let r = per_second(&counts);
        assert_eq!(r.len(), 3);
        for (t, v) in r {
            assert!((v - 30.0).abs() < 1e-6, "{t} {v}");
        }
        assert!(per_second(&[]).is_empty());
    }
}
