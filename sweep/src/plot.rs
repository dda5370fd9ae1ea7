//! Plots: each chosen metric against the plot's parameter, one line per combination of the other
//! parameters, the mean at each point with its 95 % confidence interval as an error bar. Written
//! as SVG and PNG (`plots/<metric>.svg`, `.png`).
//!
//! Text is laid out and drawn with DejaVu Sans compiled into the program (the `dejavu` crate:
//! the 2.37 release Debian ships as fonts-dejavu-core), through plotters' `ab_glyph` backend,
//! so a plot looks the same on any machine and needs no font installed, no fontconfig and no
//! system library: a fresh machine that can build the project can draw it.

use crate::error::SweepError;
use crate::path;
use crate::plan::Plan;
use crate::stats::{per_point, Stat};
use crate::table::RunRow;
use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::{Path, PathBuf};
use std::sync::Once;
use toml::Value;

/// Plot size, pixels.
const SIZE: (u32, u32) = (900, 560);
/// Line colours, one per series (cycled).
const COLOURS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(23, 190, 207),
];

fn register_font() {
    static FONT: Once = Once::new();
    FONT.call_once(|| {
        // The font is valid (it ships with the crate); a failure would only lose the text.
        let _ = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            dejavu::sans::regular(),
        );
    });
}

/// A metric's file name: characters other than letters, digits, `.`, `_`, `-` become `_`.
pub fn file_stem(metric: &str) -> String {
    metric
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-') {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// One line: the other parameters' values, and (x, stat) per point.
struct Series {
    label: String,
    points: Vec<(f64, Stat)>,
}

/// Draws every metric's plot into `dir`; the files written.
pub fn write_plots(dir: &Path, plan: &Plan, rows: &[RunRow]) -> Result<Vec<PathBuf>, SweepError> {
    register_font();
    std::fs::create_dir_all(dir).map_err(crate::error::write_err(dir))?;
    let xi = plan.x_index();
    let xs: Vec<&Value> = plan.points.iter().map(|p| &p[xi]).collect();
    let numeric = xs
        .iter()
        .all(|v| matches!(v, Value::Integer(_) | Value::Float(_)));
    // Categorical x: the distinct values in order of appearance.
    let mut categories: Vec<&Value> = Vec::new();
    for v in &xs {
        if !categories.contains(v) {
            categories.push(v);
        }
    }
    let x_of = |v: &Value| -> f64 {
        match v {
            Value::Integer(i) if numeric => *i as f64,
            Value::Float(f) if numeric => *f,
            _ => categories.iter().position(|c| *c == v).unwrap_or(0) as f64,
        }
    };
    let mut written = Vec::new();
    for metric in &plan.metrics {
        let stats = per_point(plan, rows, metric);
        let mut series: Vec<Series> = Vec::new();
        for (p, point) in plan.points.iter().enumerate() {
            let label = plan
                .parameters
                .iter()
                .zip(point)
                .enumerate()
                .filter(|(k, _)| *k != xi)
                .map(|(_, (name, v))| format!("{name} = {}", path::display(v)))
                .collect::<Vec<_>>()
                .join(", ");
            let entry = (x_of(&point[xi]), stats[p].clone());
            match series.iter_mut().find(|s| s.label == label) {
                Some(s) => s.points.push(entry),
                None => series.push(Series {
                    label,
                    points: vec![entry],
                }),
            }
        }
        for s in &mut series {
            s.points.sort_by(|a, b| a.0.total_cmp(&b.0));
        }
        let labels: Vec<String> = categories.iter().map(|v| path::display(v)).collect();
        let stem = file_stem(metric);
        let svg = dir.join(format!("{stem}.svg"));
        let png = dir.join(format!("{stem}.png"));
        let axes = Axes {
            title: format!(
                "{}: mean and 95 % interval of {} seeds",
                plan.name,
                plan.seeds.len()
            ),
            x_name: &plan.plot_x,
            y_name: metric,
            categories: (!numeric).then_some(labels.as_slice()),
        };
        draw(SVGBackend::new(&svg, SIZE), &axes, &series).map_err(|reason| SweepError::Plot {
            path: svg.clone(),
            reason,
        })?;
        draw(BitMapBackend::new(&png, SIZE), &axes, &series).map_err(|reason| {
            SweepError::Plot {
                path: png.clone(),
                reason,
            }
        })?;
        written.push(svg);
        written.push(png);
    }
    Ok(written)
}

struct Axes<'a> {
    title: String,
    x_name: &'a str,
    y_name: &'a str,
    categories: Option<&'a [String]>,
}

/// The lowest and highest value of `it`, widened by 5 % (by 1 around a single value).
fn range(it: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = it.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = if hi > lo {
        (hi - lo) * 0.05
    } else {
        1.0f64.max(lo.abs() * 0.05)
    };
    (lo - pad, hi + pad)
}

fn draw<B: DrawingBackend>(backend: B, axes: &Axes<'_>, series: &[Series]) -> Result<(), String> {
    let err = |e: &dyn std::fmt::Display| e.to_string();
    let root = backend.into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let xs = series.iter().flat_map(|s| s.points.iter().map(|p| p.0));
    let (x0, x1) = match axes.categories {
        Some(c) => (-0.5, c.len() as f64 - 0.5),
        None => range(xs),
    };
    let ys = series.iter().flat_map(|s| {
        s.points.iter().flat_map(|(_, st)| {
            let m = st.mean;
            let h = st.ci95.unwrap_or(0.0);
            m.map(|m| [m - h, m + h]).into_iter().flatten()
        })
    });
    let (y0, mut y1) = range(ys);
    let legend = series.iter().any(|s| !s.label.is_empty());
    if legend {
        // Room for the legend above the data.
        y1 += (y1 - y0) * 0.18;
    }
    let mut chart = ChartBuilder::on(&root)
        .caption(&axes.title, ("sans-serif", 22))
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(72)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|e| err(&e))?;
    let cat_label = |x: &f64| -> String {
        let k = x.round();
        match axes.categories {
            Some(c) if (x - k).abs() < 1e-6 && k >= 0.0 => {
                c.get(k as usize).cloned().unwrap_or_default()
            }
            Some(_) => String::new(),
            None => crate::stats::num(*x),
        }
    };
    let mut mesh = chart.configure_mesh();
    mesh.x_desc(axes.x_name)
        .y_desc(axes.y_name)
        .x_label_formatter(&cat_label)
        .y_label_formatter(&|y: &f64| crate::stats::num(*y))
        .light_line_style(RGBColor(238, 238, 238))
        .label_style(("sans-serif", 14));
    if let Some(c) = axes.categories {
        mesh.x_labels(c.len() * 2 + 1);
    }
    mesh.draw().map_err(|e| err(&e))?;
    // Lines side by side at one x are moved apart a little, so their error bars show.
    let dodge = (x1 - x0) * 0.012;
    for (i, s) in series.iter().enumerate() {
        let colour = COLOURS[i % COLOURS.len()];
        let shift = (i as f64 - (series.len() as f64 - 1.0) / 2.0) * dodge;
        let means: Vec<(f64, f64)> = s
            .points
            .iter()
            .filter_map(|(x, st)| st.mean.map(|m| (x + shift, m)))
            .collect();
        let line = chart
            .draw_series(LineSeries::new(means.clone(), colour.stroke_width(2)))
            .map_err(|e| err(&e))?;
        if !s.label.is_empty() {
            line.label(s.label.clone()).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
            });
        }
        chart
            .draw_series(means.iter().map(|p| Circle::new(*p, 4, colour.filled())))
            .map_err(|e| err(&e))?;
        let bars = s.points.iter().filter_map(|(x, st)| {
            let (m, h) = (st.mean?, st.ci95?);
            Some(ErrorBar::new_vertical(
                x + shift,
                m - h,
                m,
                m + h,
                colour.stroke_width(2),
                12,
            ))
        });
        chart.draw_series(bars).map_err(|e| err(&e))?;
    }
    if legend {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()
            .map_err(|e| err(&e))?;
    }
    root.present().map_err(|e| err(&e))?;
    Ok(())
}
