//! SVG plot of an experiment's trajectories over the arena, written by hand: no font or
//! system library is needed, and the file opens in any browser.
//!
//! The arena (1500 x 2000 mm) is drawn with +Y up; each car's track is a polyline in its own
//! colour, with a circle at the start, a square at the end and crosses on its targets. An
//! [`Overlay`] adds the circles of circle maneuvers (dashed) and numbers every track where
//! each phase of the experiment began.

use crate::metrics::{Sample, ARENA_MM};
use std::fmt::Write;

/// Pixels per mm.
const SCALE: f64 = 0.3;
/// Margin around the arena, px.
const MARGIN: f64 = 20.0;
const COLOURS: [&str; 8] = [
    "#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf",
];

/// One car's track and targets.
#[derive(Debug, Clone, Copy)]
pub struct Track<'a> {
    /// Car ID (shown as a label).
    pub id: u8,
    /// Samples.
    pub samples: &'a [Sample],
    /// Target points, mm.
    pub targets: &'a [(f64, f64)],
}

/// Extra marks: where phases began and the circles of circle maneuvers.
#[derive(Debug, Clone, Default)]
pub struct Overlay {
    /// `(phase number, start time s)`: a numbered dot on each track at that time.
    pub phase_starts: Vec<(usize, f64)>,
    /// `(centre mm, radius mm)`, drawn dashed.
    pub circles: Vec<((f64, f64), f64)>,
}

fn px(x_mm: f64, y_mm: f64) -> (f64, f64) {
    (MARGIN + x_mm * SCALE, MARGIN + (ARENA_MM.1 - y_mm) * SCALE)
}

/// The SVG document.
pub fn svg(title: &str, tracks: &[Track<'_>]) -> String {
    svg_with(title, tracks, &Overlay::default())
}

/// The SVG document with an [`Overlay`].
pub fn svg_with(title: &str, tracks: &[Track<'_>], overlay: &Overlay) -> String {
    let w = ARENA_MM.0 * SCALE + 2.0 * MARGIN;
    let h = ARENA_MM.1 * SCALE + 2.0 * MARGIN + 20.0;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w:.0}" height="{h:.0}" viewBox="0 0 {w:.0} {h:.0}">"#
    );
    let _ = writeln!(s, "<title>{}</title>", escape(title));
    let _ = writeln!(
        s,
        r##"<rect x="{MARGIN}" y="{MARGIN}" width="{:.1}" height="{:.1}" fill="#fafafa" stroke="#000" stroke-width="2"/>"##,
        ARENA_MM.0 * SCALE,
        ARENA_MM.1 * SCALE
    );
    for &((cx, cy), r) in &overlay.circles {
        let (x, y) = px(cx, cy);
        let _ = writeln!(
            s,
            r##"<circle cx="{x:.1}" cy="{y:.1}" r="{:.1}" fill="none" stroke="#888" stroke-dasharray="6 4"/>"##,
            r * SCALE
        );
    }
    for (i, t) in tracks.iter().enumerate() {
        let c = COLOURS[i % COLOURS.len()];
        let mut pts = String::new();
        for p in t.samples {
            let (x, y) = px(p.x_mm, p.y_mm);
            let _ = write!(pts, "{x:.1},{y:.1} ");
        }
        let _ = writeln!(
            s,
            r#"<polyline fill="none" stroke="{c}" stroke-width="2" points="{}"/>"#,
            pts.trim_end()
        );
        if let (Some(a), Some(b)) = (t.samples.first(), t.samples.last()) {
            let (x, y) = px(a.x_mm, a.y_mm);
            let _ = writeln!(s, r#"<circle cx="{x:.1}" cy="{y:.1}" r="5" fill="{c}"/>"#);
            let _ = writeln!(
                s,
                r#"<text x="{:.1}" y="{:.1}" font-size="12" fill="{c}">car {}</text>"#,
                x + 7.0,
                y - 7.0,
                t.id
            );
            let (x, y) = px(b.x_mm, b.y_mm);
            let _ = writeln!(
                s,
                r#"<rect x="{:.1}" y="{:.1}" width="8" height="8" fill="{c}"/>"#,
                x - 4.0,
                y - 4.0
            );
        }
        for &(phase, start) in overlay.phase_starts.iter().filter(|(n, _)| *n > 1) {
            if let Some(p) = t.samples.iter().find(|p| p.t >= start) {
                let (x, y) = px(p.x_mm, p.y_mm);
                let _ = writeln!(
                    s,
                    r##"<circle cx="{x:.1}" cy="{y:.1}" r="7" fill="#fff" stroke="{c}" stroke-width="2"/><text x="{:.1}" y="{:.1}" font-size="9" text-anchor="middle" fill="{c}">{phase}</text>"##,
                    x,
                    y + 3.0
                );
            }
        }
        for &(tx, ty) in t.targets {
            let (x, y) = px(tx, ty);
            let _ = writeln!(
                s,
                r#"<path d="M{:.1},{:.1}L{:.1},{:.1}M{:.1},{:.1}L{:.1},{:.1}" stroke="{c}" stroke-width="2"/>"#,
                x - 6.0,
                y - 6.0,
                x + 6.0,
                y + 6.0,
                x - 6.0,
                y + 6.0,
                x + 6.0,
                y - 6.0
            );
        }
    }
    let _ = writeln!(
        s,
        r#"<text x="{MARGIN}" y="{:.0}" font-size="12">{} (arena 1500 x 2000 mm, +Y up)</text>"#,
        h - 6.0,
        escape(title)
    );
    s.push_str("</svg>\n");
    s
}

fn escape(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn track_is_drawn_with_flipped_y() {
        let samples = [
            Sample {
                t: 0.0,
                x_mm: 0.0,
                y_mm: 0.0,
                heading_mrad: 0.0,
                v_mm_s: 0.0,
            },
            Sample {
                t: 1.0,
                x_mm: 1500.0,
                y_mm: 2000.0,
                heading_mrad: 0.0,
                v_mm_s: 0.0,
            },
        ];
        let doc = svg(
            "a<b",
            &[Track {
                id: 3,
                samples: &samples,
                targets: &[(750.0, 1000.0)],
            }],
        );
        assert!(doc.starts_with("<svg "));
        assert!(doc.ends_with("</svg>\n"));
        assert!(doc.contains(r#"points="20.0,620.0 470.0,20.0""#), "{doc}");
        assert!(doc.contains("a&lt;b"));
        assert!(doc.contains(">car 3<"));
        assert_eq!(doc.matches("<path ").count(), 1);
        assert_eq!(doc.matches("stroke-dasharray").count(), 0);
    }

    #[test]
    fn overlay_marks_phases_and_circles() {
        let samples: Vec<Sample> = (0..10)
            .map(|i| Sample {
                t: f64::from(i),
                x_mm: 100.0 * f64::from(i),
                y_mm: 0.0,
                heading_mrad: 0.0,
                v_mm_s: 0.0,
            })
            .collect();
        let overlay = Overlay {
            phase_starts: vec![(1, 0.0), (2, 4.5)],
            circles: vec![((750.0, 1000.0), 250.0)],
        };
        let doc = svg_with(
            "p",
            &[Track {
                id: 1,
                samples: &samples,
                targets: &[],
            }],
            &overlay,
        );
        assert_eq!(doc.matches("stroke-dasharray").count(), 1);
        assert!(doc.contains(r#"r="75.0""#), "{doc}");
        // Phase 2 is marked at the first sample from 4.5 s: x = 500 mm -> 170 px.
        assert!(
            doc.contains(r#"<circle cx="170.0" cy="620.0" r="7""#),
            "{doc}"
        );
        assert!(doc.contains(">2</text>"));
    }
}
