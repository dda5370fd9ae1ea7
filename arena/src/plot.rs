//! SVG plot of an experiment's trajectories over the arena, written by hand: no font or
//! system library is needed, and the file opens in any browser.
//!
//! The arena (1500 x 2000 mm) is drawn with +Y up; each car's track is a polyline in its own
//! colour, with a circle at the start, a square at the end and crosses on its targets.

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

fn px(x_mm: f64, y_mm: f64) -> (f64, f64) {
    (MARGIN + x_mm * SCALE, MARGIN + (ARENA_MM.1 - y_mm) * SCALE)
}

/// The SVG document.
pub fn svg(title: &str, tracks: &[Track<'_>]) -> String {
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
    }
}
