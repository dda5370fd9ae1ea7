//! Plots of a run, fit for a paper, drawn with `plotters` as SVG and PNG:
//!
//! - `trajectories`: the arena (walls, axes in metres) with each car's track in its own
//!   colour, start and end markers, dots at regular times along each track, go-to points and
//!   waypoints, the circles of circle phases and where each later phase began;
//! - `phase_error`: each phase's error against time, with its tolerance;
//! - `separation`: the smallest distance between two cars' body centres against time, with
//!   the collision distance;
//! - `radio`: radio state broadcasts of each car the ground station heard per second.
//!
//! Every legend sits beside its chart, so no label covers data or another label. Text is
//! measured with DejaVu Sans compiled into the program (the `dejavu` crate, the release Debian
//! ships as fonts-dejavu-core, through plotters' `ab_glyph` backend), and the PNG is the SVG
//! rendered by `resvg` with that font as its only one: no font is looked up on the machine,
//! and a PNG is the same byte for byte on any machine.

mod legend;
mod series;
mod trajectories;

use crate::metrics::Sample;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::FontStyle;
use std::sync::Once;

pub use legend::{Legend, Marker};

/// Car colours, by configuration index (cycled): the same in every plot, the report and the
/// live view's scene.
pub const COLOURS: [(u8, u8, u8); 8] = [
    (31, 119, 180),
    (214, 39, 40),
    (44, 160, 44),
    (255, 127, 14),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (23, 190, 207),
];

/// Car `k`'s colour (configuration order).
pub fn colour_of(k: usize) -> (u8, u8, u8) {
    COLOURS[k % COLOURS.len()]
}

fn rgb(c: (u8, u8, u8)) -> RGBColor {
    RGBColor(c.0, c.1, c.2)
}

/// The font family every plot uses (DejaVu Sans, registered on first use).
const FONT: &str = "sans-serif";

fn register_font() {
    static FONT_ONCE: Once = Once::new();
    FONT_ONCE.call_once(|| {
        // The font ships with the crate and is valid; a failure would only lose the text.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
    });
}

/// A phase of the run, for the plots.
#[derive(Debug, Clone, PartialEq)]
pub struct PhaseSpan {
    /// Phase number, from 1.
    pub phase: usize,
    /// `goto`, `formation`, ...
    pub kind: String,
    /// Start and end, s since the first phase started.
    pub start_s: f64,
    pub end_s: f64,
    /// The completion test's bound, mm.
    pub tolerance_mm: f64,
}

/// Everything the plots show of a run. Times are s since the first phase started.
#[derive(Debug, Clone, Default)]
pub struct RunPlots {
    /// Experiment name (titles).
    pub title: String,
    /// Car IDs, configuration order.
    pub ids: Vec<u8>,
    /// Each car's true poses.
    pub tracks: Vec<Vec<Sample>>,
    /// Each car's go-to points and (a leader's) waypoints, mm.
    pub targets: Vec<Vec<(f64, f64)>>,
    /// Circles of circle phases: centre mm, radius mm.
    pub circles: Vec<((f64, f64), f64)>,
    /// The phases.
    pub phases: Vec<PhaseSpan>,
    /// `(t, phase, error_mm)` every sample.
    pub phase_errors: Vec<(f64, usize, f64)>,
    /// Each car's count of radio state broadcasts heard by the ground station, `(t, count)`.
    pub states_heard: Vec<Vec<(f64, u64)>>,
}

/// One plot, drawn.
#[derive(Debug, Clone)]
pub struct Figure {
    /// File stem: `trajectories`, `phase_error`, `separation`, `radio`.
    pub name: &'static str,
    /// What it shows (the report's caption).
    pub caption: String,
    /// The SVG document.
    pub svg: String,
    /// The PNG file.
    pub png: Vec<u8>,
}

/// Why a plot could not be drawn.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PlotError(pub String);

impl std::fmt::Display for PlotError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "cannot draw a plot: {}", self.0)
    }
}

impl std::error::Error for PlotError {}

fn err<E: std::fmt::Display>(e: E) -> PlotError {
    PlotError(e.to_string())
}

/// A plot drawn the same way on any backend.
trait Draw {
    /// Size, pixels.
    fn size(&self) -> (u32, u32);
    /// Draws onto `root`.
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), PlotError>;
}

/// Draws `d` as SVG, and renders that SVG as PNG.
fn render<D: Draw>(d: &D) -> Result<(String, Vec<u8>), PlotError> {
    register_font();
    let (w, h) = d.size();
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(err)?;
        d.draw(&root)?;
        root.present().map_err(err)?;
    }
    let png = to_png(&svg)?;
    Ok((svg, png))
}

/// Renders an SVG document as PNG with DejaVu Sans as its only font.
pub fn to_png(svg: &str) -> Result<Vec<u8>, PlotError> {
    use resvg::{tiny_skia, usvg};
    let mut opt = usvg::Options::default();
    let db = opt.fontdb_mut();
    db.load_font_data(dejavu::sans::regular().to_vec());
    db.set_sans_serif_family("DejaVu Sans");
    let tree = usvg::Tree::from_str(svg, &opt).map_err(err)?;
    let size = tree.size().to_int_size();
    let mut pixmap = tiny_skia::Pixmap::new(size.width(), size.height())
        .ok_or_else(|| PlotError("empty plot".into()))?;
    pixmap.fill(tiny_skia::Color::WHITE);
    resvg::render(
        &tree,
        tiny_skia::Transform::identity(),
        &mut pixmap.as_mut(),
    );
    pixmap.encode_png().map_err(err)
}

/// Every plot of a run.
pub fn render_all(p: &RunPlots) -> Result<Vec<Figure>, PlotError> {
    let mut out = Vec::new();
    let traj = trajectories::Trajectories(p);
    let (svg, png) = render(&traj)?;
    out.push(Figure {
        name: "trajectories",
        caption: format!(
            "Trajectories of {}: each car's true path over the 1.5 x 2 m arena",
            p.title
        ),
        svg,
        png,
    });
    for (name, plot) in series::all(p) {
        let (svg, png) = render(&plot)?;
        out.push(Figure {
            name,
            caption: plot.caption(),
            svg,
            png,
        });
    }
    Ok(out)
}

/// A round step for marks along `span` so that there are about `n` of them.
pub fn nice_step(span: f64, n: f64) -> f64 {
    let raw = (span / n.max(1.0)).max(1e-9);
    let mag = 10f64.powf(raw.log10().floor());
    let m = raw / mag;
    let f = if m <= 1.0 {
        1.0
    } else if m <= 2.0 {
        2.0
    } else if m <= 5.0 {
        5.0
    } else {
        10.0
    };
    f * mag
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t: f64, x: f64, y: f64) -> Sample {
        Sample {
            t,
            x_mm: x,
            y_mm: y,
            heading_mrad: 0.0,
            v_mm_s: 0.0,
        }
    }

    fn two_cars() -> RunPlots {
        RunPlots {
            title: "a<b".into(),
            ids: vec![3, 7],
            tracks: vec![
                (0..50)
                    .map(|i| sample(f64::from(i) * 0.1, 300.0 + 10.0 * f64::from(i), 400.0))
                    .collect(),
                (0..50)
                    .map(|i| sample(f64::from(i) * 0.1, 900.0, 1500.0 - 10.0 * f64::from(i)))
                    .collect(),
            ],
            targets: vec![vec![(800.0, 400.0)], vec![]],
            circles: vec![((750.0, 1000.0), 375.0)],
            phases: vec![
                PhaseSpan {
                    phase: 1,
                    kind: "goto".into(),
                    start_s: 0.0,
                    end_s: 2.5,
                    tolerance_mm: 62.5,
                },
                PhaseSpan {
                    phase: 2,
                    kind: "circle".into(),
                    start_s: 2.5,
                    end_s: 4.9,
                    tolerance_mm: 75.0,
                },
            ],
            phase_errors: (0..50)
                .map(|i| {
                    (
                        f64::from(i) * 0.1,
                        if i < 25 { 1 } else { 2 },
                        500.0 - 10.0 * f64::from(i),
                    )
                })
                .collect(),
            states_heard: vec![
                (0..50)
                    .map(|i| (f64::from(i) * 0.1, 3 * i as u64))
                    .collect(),
                (0..50)
                    .map(|i| (f64::from(i) * 0.1, 2 * i as u64))
                    .collect(),
            ],
        }
    }

    #[test]
    fn every_plot_is_drawn_as_svg_and_png_the_same_each_time() {
        let p = two_cars();
        let a = render_all(&p).unwrap();
        let names: Vec<&str> = a.iter().map(|f| f.name).collect();
        assert_eq!(
            names,
            ["trajectories", "phase_error", "separation", "radio"]
        );
        for f in &a {
            assert!(f.svg.starts_with("<svg"), "{}", f.name);
            assert!(f.svg.contains("car 3") || f.name == "phase_error" || f.name == "separation");
            assert_eq!(&f.png[1..4], b"PNG");
        }
        assert!(a[0].svg.contains("a&lt;b"), "title escaped");
        let b = render_all(&p).unwrap();
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.png, y.png, "{}", x.name);
            assert_eq!(x.svg, y.svg, "{}", x.name);
        }
    }

    #[test]
    fn an_empty_run_still_draws() {
        let p = RunPlots {
            title: "empty".into(),
            ids: vec![1],
            tracks: vec![Vec::new()],
            targets: vec![Vec::new()],
            states_heard: vec![Vec::new()],
            ..RunPlots::default()
        };
        assert_eq!(render_all(&p).unwrap().len(), 4);
    }

    #[test]
    fn steps_are_round() {
        assert_eq!(nice_step(80.0, 10.0), 10.0);
        assert_eq!(nice_step(12.0, 10.0), 2.0);
        assert_eq!(nice_step(3.0, 10.0), 0.5);
    }
}
