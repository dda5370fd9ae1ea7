//! `report.html`: one self-contained page per run (no script, no network, the plots inline as
//! PNG data URIs): the summary as tables and every plot. Built from `summary.json`'s value, so
//! every field the summary has is shown without this page knowing each one.

use crate::plot::{colour_of, Figure};
use base64::Engine;
use serde_json::Value;
use std::fmt::Write;

/// HTML-escapes `s`.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A summary value as table text: numbers as written, `-` for null, nested values as JSON.
fn cell(v: &Value) -> String {
    match v {
        Value::Null => "-".into(),
        Value::Bool(b) => if *b { "yes" } else { "no" }.into(),
        Value::Number(n) => n.to_string(),
        Value::String(s) => esc(s),
        Value::Array(a) if a.is_empty() => "-".into(),
        Value::Array(a) if a.iter().all(|x| x.is_number()) => esc(&a
            .iter()
            .map(|x| x.to_string())
            .collect::<Vec<_>>()
            .join(", ")),
        other => esc(&other.to_string()),
    }
}

/// A table of the objects `rows` with the columns `cols` (`(key, heading)`); `first` gives
/// an extra leading cell per row (HTML).
fn table(
    out: &mut String,
    rows: &[Value],
    cols: &[(&str, &str)],
    first: Option<&dyn Fn(usize) -> String>,
) {
    out.push_str("<table><thead><tr>");
    if first.is_some() {
        out.push_str("<th></th>");
    }
    for (_, h) in cols {
        let _ = write!(out, "<th>{}</th>", esc(h));
    }
    out.push_str("</tr></thead><tbody>");
    for (i, r) in rows.iter().enumerate() {
        out.push_str("<tr>");
        if let Some(f) = first {
            let _ = write!(out, "<td>{}</td>", f(i));
        }
        for (k, _) in cols {
            let v = k.split('.').fold(r, |v, part| &v[part]);
            let _ = write!(out, "<td>{}</td>", cell(v));
        }
        out.push_str("</tr>");
    }
    out.push_str("</tbody></table>\n");
}

/// A two-column table of an object's fields (nested objects flattened as `a.b`).
fn fields(out: &mut String, v: &Value, skip: &[&str]) {
    let mut rows = Vec::new();
    if let Value::Object(m) = v {
        for (k, x) in m.iter().filter(|(k, _)| !skip.contains(&k.as_str())) {
            flatten(k, x, &mut rows);
        }
    }
    out.push_str("<table class=\"kv\"><tbody>");
    for (k, x) in rows {
        let _ = write!(out, "<tr><th>{}</th><td>{x}</td></tr>", esc(&k));
    }
    out.push_str("</tbody></table>\n");
}

/// `(key, text)` of an object's fields, nested objects flattened as `a.b`.
fn flatten(prefix: &str, v: &Value, rows: &mut Vec<(String, String)>) {
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                flatten(&key, x, rows);
            }
        }
        other => rows.push((prefix.to_owned(), cell(other))),
    }
}

/// The cars' firmware counters (`stats`): one row per counter, one column per car.
fn counters(out: &mut String, cars: &[Value]) {
    let per_car: Vec<Vec<(String, String)>> = cars
        .iter()
        .map(|c| {
            let mut rows = Vec::new();
            flatten("", &c["stats"], &mut rows);
            rows
        })
        .collect();
    let mut keys: Vec<&String> = per_car.iter().flatten().map(|(k, _)| k).collect();
    keys.sort();
    keys.dedup();
    out.push_str("<table class=\"kv\"><thead><tr><th>counter</th>");
    for (k, c) in cars.iter().enumerate() {
        let _ = write!(out, "<th>{} car {}</th>", swatch(k), cell(&c["id"]));
    }
    out.push_str("</tr></thead><tbody>");
    for key in keys {
        let _ = write!(out, "<tr><th>{}</th>", esc(key));
        for rows in &per_car {
            let v = rows.iter().find(|(k, _)| k == key).map_or("-", |(_, v)| v);
            let _ = write!(out, "<td>{v}</td>");
        }
        out.push_str("</tr>");
    }
    out.push_str("</tbody></table>\n");
}

fn swatch(k: usize) -> String {
    let (r, g, b) = colour_of(k);
    format!("<span class=\"sw\" style=\"background:#{r:02x}{g:02x}{b:02x}\"></span>")
}

fn img(f: &Figure) -> String {
    let data = base64::engine::general_purpose::STANDARD.encode(&f.png);
    format!(
        "<figure id=\"{name}\"><img src=\"data:image/png;base64,{data}\" alt=\"{alt}\"><figcaption>{alt} \
         (<code>{name}.svg</code>, <code>{name}.png</code>)</figcaption></figure>\n",
        name = f.name,
        alt = esc(&f.caption),
    )
}

const STYLE: &str = "body{font-family:'DejaVu Sans',sans-serif;margin:24px;color:#222;max-width:1900px}\
h1{font-size:24px;margin:0 0 8px}h2{font-size:19px;margin:28px 0 8px;border-bottom:1px solid #ccc}\
table{border-collapse:collapse;font-size:13px;margin:6px 0}th,td{border:1px solid #ccc;padding:3px 7px;text-align:right}\
th{background:#f2f2f2}table.kv th{text-align:left}td:first-child{text-align:left}\
.sw{display:inline-block;width:16px;height:16px;vertical-align:middle}\
.top{display:flex;gap:24px;align-items:flex-start;flex-wrap:wrap}figure{margin:0 0 16px}\
figcaption{font-size:13px;color:#555;max-width:900px}.ok{color:#1a7f1a}.bad{color:#c62828}";

/// The page for `summary` (the value of `summary.json`) with `figures`.
pub fn html(summary: &Value, figures: &[Figure]) -> String {
    let mut s = String::new();
    let name = summary["name"].as_str().unwrap_or("experiment");
    let _ = write!(
        s,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{n}</title>\
         <style>{STYLE}</style></head><body>\n<h1>Experiment {n}</h1>\n",
        n = esc(name)
    );
    let verdict = |key: &str| summary[key].as_bool().unwrap_or(false);
    let (class, word) =
        if verdict("completed") && summary["collisions"].as_array().is_some_and(Vec::is_empty) {
            ("ok", "every phase completed without a collision")
        } else {
            ("bad", "not every phase completed, or cars collided")
        };
    let _ = writeln!(s, "<p class=\"{class}\">{word}</p>");
    s.push_str("<div class=\"top\">");
    if let Some(f) = figures.iter().find(|f| f.name == "trajectories") {
        s.push_str(&img(f));
    }
    s.push_str("<div><h2>Result</h2>");
    fields(
        &mut s,
        summary,
        &["phases", "cars", "radio", "collisions", "failed_cars"],
    );
    s.push_str("<h2>Cars</h2>");
    let cars = summary["cars"].as_array().cloned().unwrap_or_default();
    table(
        &mut s,
        &cars,
        &[
            ("id", "car"),
            ("distance_mm", "travelled (mm)"),
            ("arrived", "arrived"),
            ("arrival_s", "arrival (s)"),
            ("final_error_mm", "from last point (mm)"),
            ("wall_violations_s", "wall violations (s)"),
            ("states_heard", "states heard"),
            ("processor_load", "processor load"),
            ("lbc.stream_frames", "LBC stream frames"),
            ("lbc.errors", "LBC errors"),
            ("lbc.resets", "LBC resets"),
            ("tracking.delivered", "fixes"),
            ("tracking.dropped", "fixes dropped"),
            ("failed.reason", "failed"),
        ],
        Some(&|k| swatch(k)),
    );
    s.push_str("</div></div>\n<h2>Phases</h2>");
    let phases = summary["phases"].as_array().cloned().unwrap_or_default();
    table(
        &mut s,
        &phases,
        &[
            ("phase", "phase"),
            ("kind", "kind"),
            ("start_s", "start (s)"),
            ("end_s", "end (s)"),
            ("completed", "completed"),
            ("timed_out", "timed out"),
            ("started_s", "started (s)"),
            ("settled_s", "settled (s)"),
            ("converged_s", "converged (s)"),
            ("reported_converged_s", "cars reported (s)"),
            ("tolerance_mm", "tolerance (mm)"),
            (
                "error_after_settled.max_mm",
                "max error after settling (mm)",
            ),
            ("error_after_settled.p95_mm", "p95 (mm)"),
            ("error_after_settled.mean_mm", "mean (mm)"),
            ("final_error_mm", "final error (mm)"),
            ("waypoints_sent", "waypoints"),
            ("command_retries", "retries"),
            ("command_failures", "failures"),
        ],
        None,
    );
    s.push_str("<h2>Plots</h2>\n");
    for f in figures.iter().filter(|f| f.name != "trajectories") {
        s.push_str(&img(f));
    }
    let collisions = summary["collisions"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    if !collisions.is_empty() {
        s.push_str("<h2>Collisions</h2>");
        table(
            &mut s,
            &collisions,
            &[
                ("cars", "cars"),
                ("t_s", "t (s)"),
                ("distance_mm", "distance (mm)"),
                ("phase", "phase"),
            ],
            None,
        );
    }
    let failed = summary["failed_cars"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    if !failed.is_empty() {
        s.push_str("<h2>Failed cars</h2>");
        table(
            &mut s,
            &failed,
            &[("car", "car"), ("t_s", "t (s)"), ("reason", "reason")],
            None,
        );
    }
    s.push_str("<h2>Radio</h2>");
    fields(&mut s, &summary["radio"], &["nodes"]);
    let nodes = summary["radio"]["nodes"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    table(
        &mut s,
        &nodes,
        &[
            ("node", "node"),
            ("bytes_in", "bytes written by its host"),
            ("bytes_out", "bytes delivered to its host"),
        ],
        None,
    );
    s.push_str("<h2>Firmware counters</h2>");
    counters(&mut s, &cars);
    s.push_str(
        "<p>Every value is in <code>summary.json</code>; trajectories in <code>car&lt;ID&gt;.csv</code>; \
         everything the world saw (poses, estimates, radio frames, LBC messages, firmware logs, \
         events) in <code>run.mcap</code>, which Foxglove opens.</p>\n</body></html>\n",
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn the_page_is_self_contained_and_escapes_text() {
        let summary = json!({
            "name": "x<y", "completed": true, "collisions": [],
            "cars": [{"id": 1, "distance_mm": 12.5, "stats": {"radio": {"tx": 3}}}],
            "phases": [{"phase": 1, "kind": "goto", "error_after_settled": null}],
            "radio": {"ground": {"requests": 2}, "nodes": [{"node": "ground", "bytes_in": 1}]},
        });
        let fig = Figure {
            name: "trajectories",
            caption: "t & c".into(),
            svg: String::new(),
            png: vec![0x89, b'P', b'N', b'G'],
        };
        let page = html(&summary, &[fig]);
        assert!(page.contains("<title>x&lt;y</title>"));
        assert!(page.contains("data:image/png;base64,iVBORw=="));
        assert!(page.contains("t &amp; c"));
        assert!(page.contains("radio.tx"));
        assert!(page.contains("background:#1f77b4"));
        assert!(!page.contains("http://") && !page.contains("https://"));
    }
}
