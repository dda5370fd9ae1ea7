//! The trajectory plot: the arena in metres with every car's true path.

use super::legend::diamond;
use super::{colour_of, err, nice_step, rgb, Draw, Legend, Marker, PlotError, RunPlots, FONT};
use crate::metrics::{Sample, ARENA_MM};
use plotters::coord::Shift;
use plotters::prelude::*;

/// Width of the chart part, px (the legend takes the rest).
const CHART_W: u32 = 620;
/// Margin around the walls in the chart, m.
const PAD: f64 = 0.05;

/// The plot of `RunPlots`' tracks.
pub struct Trajectories<'a>(pub &'a RunPlots);

fn m(mm: f64) -> f64 {
    mm / 1000.0
}

fn at(s: &Sample) -> (f64, f64) {
    (m(s.x_mm), m(s.y_mm))
}

impl Trajectories<'_> {
    /// Seconds between two dots along a track: about 12 on the longest.
    fn dot_every(&self) -> f64 {
        let end = self
            .0
            .tracks
            .iter()
            .filter_map(|t| t.last().map(|s| s.t))
            .fold(0.0, f64::max);
        nice_step(end.max(1.0), 12.0).max(1.0)
    }
}

impl Draw for Trajectories<'_> {
    fn size(&self) -> (u32, u32) {
        (920, 820)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), PlotError> {
        let p = self.0;
        let (chart_area, legend_area) = root.split_horizontally(CHART_W);
        let (w, l) = (m(ARENA_MM.0), m(ARENA_MM.1));
        let mut chart = ChartBuilder::on(&chart_area)
            .caption(format!("{}: trajectories", p.title), (FONT, 22))
            .margin(12)
            .x_label_area_size(48)
            .y_label_area_size(60)
            .build_cartesian_2d(-PAD..w + PAD, -PAD..l + PAD)
            .map_err(err)?;
        chart
            .configure_mesh()
            .x_desc("x (m)")
            .y_desc("y (m)")
            .x_labels(9)
            .y_labels(12)
            .x_label_formatter(&|v| format!("{v:.2}"))
            .y_label_formatter(&|v| format!("{v:.2}"))
            .label_style((FONT, 16))
            .axis_desc_style((FONT, 18))
            .max_light_lines(1)
            .light_line_style(RGBColor(242, 242, 242))
            .bold_line_style(RGBColor(220, 220, 220))
            .draw()
            .map_err(err)?;
        // The walls, 20 mm thick, outside the floor.
        let t = 0.02;
        let walls = [
            [(-t, -t), (w + t, 0.0)],
            [(-t, l), (w + t, l + t)],
            [(-t, 0.0), (0.0, l)],
            [(w, 0.0), (w + t, l)],
        ];
        chart
            .draw_series(
                walls
                    .into_iter()
                    .map(|r| Rectangle::new(r, RGBColor(70, 70, 70).filled())),
            )
            .map_err(err)?;
        let grey = RGBColor(128, 128, 128);
        for &((cx, cy), r) in &p.circles {
            let pts: Vec<(f64, f64)> = (0..=120)
                .map(|i| {
                    let a = f64::from(i) * std::f64::consts::TAU / 120.0;
                    (m(cx + r * a.cos()), m(cy + r * a.sin()))
                })
                .collect();
            chart
                .draw_series(DashedLineSeries::new(pts, 8, 5, grey.stroke_width(2)))
                .map_err(err)?;
        }
        let every = self.dot_every();
        let later_phases: Vec<f64> = p.phases.iter().skip(1).map(|s| s.start_s).collect();
        for (k, track) in p.tracks.iter().enumerate() {
            let c = rgb(colour_of(k));
            chart
                .draw_series(LineSeries::new(track.iter().map(at), c.stroke_width(2)))
                .map_err(err)?;
            // Dots at every multiple of `every` seconds.
            let mut next = every;
            let dots: Vec<(f64, f64)> = track
                .iter()
                .filter(|s| {
                    let due = s.t + 1e-6 >= next;
                    if due {
                        next = (s.t / every).floor() * every + every;
                    }
                    due
                })
                .map(at)
                .collect();
            chart
                .draw_series(dots.into_iter().map(|d| Circle::new(d, 3, c.filled())))
                .map_err(err)?;
            for &start in &later_phases {
                if let Some(s) = track.iter().find(|s| s.t + 1e-6 >= start) {
                    chart
                        .draw_series(std::iter::once(
                            EmptyElement::at(at(s))
                                + PathElement::new(diamond((0, 0)), c.stroke_width(2)),
                        ))
                        .map_err(err)?;
                }
            }
            if let Some(targets) = p.targets.get(k) {
                chart
                    .draw_series(
                        targets
                            .iter()
                            .map(|&(x, y)| Cross::new((m(x), m(y)), 6, c.stroke_width(2))),
                    )
                    .map_err(err)?;
            }
            if let (Some(a), Some(b)) = (track.first(), track.last()) {
                chart
                    .draw_series(std::iter::once(Circle::new(at(a), 6, c.filled())))
                    .map_err(err)?;
                chart
                    .draw_series(std::iter::once(
                        EmptyElement::at(at(b))
                            + Rectangle::new([(-6, -6), (6, 6)], c.filled())
                            + Rectangle::new([(-6, -6), (6, 6)], BLACK.stroke_width(1)),
                    ))
                    .map_err(err)?;
            }
        }
        let mut legend = Legend::default();
        for (k, id) in p.ids.iter().enumerate() {
            legend.push(Marker::Swatch, rgb(colour_of(k)), format!("car {id}"));
        }
        legend.push(
            Marker::Swatch,
            RGBColor(70, 70, 70),
            "wall (arena 1.5 x 2 m)",
        );
        legend.push(Marker::Circle, grey, "start");
        legend.push(Marker::Square, grey, "end");
        legend.push(Marker::Dot, grey, format!("every {every:.0} s"));
        if p.targets.iter().any(|t| !t.is_empty()) {
            legend.push(Marker::Cross, grey, "go-to point or waypoint");
        }
        if !later_phases.is_empty() {
            legend.push(Marker::Diamond, grey, "a later phase began");
        }
        if !p.circles.is_empty() {
            legend.push(Marker::Dashed, grey, "circle of a circle phase");
        }
        legend.draw(&legend_area, 60)
    }
}
