//! What a build reports: yosys's cell counts, nextpnr's utilization and timing.
//!
//! nextpnr-ice40 (0.4) times a DSP block used as a combinational multiplier as if it were
//! registered, clocked by its tied-off clock input (`$PACKER_GND_NET`): a path through the
//! multiplier appears as two paths, into the block and out of it, neither held against the
//! design's clock. [`Timing::dsp_bound_mhz`] adds the worst of each (and the worst path
//! between two blocks) back together, an upper bound of the path through the multiplier that
//! counts no delay inside the block, and the design's Fmax is the lower of the two.

use std::collections::BTreeMap;

use serde_json::Value;

/// The net nextpnr names a DSP block's tied-off clock after.
const DSP_CLOCK: &str = "$PACKER_GND_NET";

/// Cells after synthesis (yosys `stat` of the flattened top).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Cells {
    /// SB_LUT4.
    pub lut4: u64,
    /// SB_CARRY.
    pub carry: u64,
    /// Flip-flops (every SB_DFF* kind).
    pub ff: u64,
    /// Block RAMs (SB_RAM40_4K*).
    pub ram: u64,
    /// Single-port RAMs (SB_SPRAM256KA).
    pub spram: u64,
    /// DSP blocks (SB_MAC16).
    pub dsp: u64,
}

impl Cells {
    /// Reads the last `stat` block of a yosys log (the flattened top is printed last).
    pub fn from_yosys_log(log: &str) -> Option<Cells> {
        let start = log.rfind("Number of cells:")?;
        let mut cells = Cells::default();
        for line in log[start..].lines().skip(1) {
            let mut words = line.split_whitespace();
            let (Some(name), Some(count), None) = (words.next(), words.next(), words.next()) else {
                if line.trim().is_empty() {
                    continue;
                }
                break;
            };
            let Ok(n) = count.parse::<u64>() else {
                break;
            };
            match name {
                "SB_LUT4" => cells.lut4 += n,
                "SB_CARRY" => cells.carry += n,
                "SB_SPRAM256KA" => cells.spram += n,
                "SB_MAC16" => cells.dsp += n,
                n2 if n2.starts_with("SB_DFF") => cells.ff += n,
                n2 if n2.starts_with("SB_RAM40_4K") => cells.ram += n,
                _ => {}
            }
        }
        (cells.lut4 > 0).then_some(cells)
    }
}

/// Used and available instances of one kind of site.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Usage {
    /// Instances the design uses.
    pub used: u64,
    /// Instances the device has.
    pub available: u64,
}

impl Usage {
    /// `used/available (p %)`.
    pub fn describe(&self) -> String {
        let pct = if self.available == 0 {
            0.0
        } else {
            100.0 * self.used as f64 / self.available as f64
        };
        format!("{}/{} ({pct:.0} %)", self.used, self.available)
    }
}

/// The worst path between two clock edges (`posedge clk`, `negedge clk`, `<async>`).
#[derive(Debug, Clone, PartialEq)]
pub struct EdgePath {
    /// Launching edge.
    pub from: String,
    /// Capturing edge.
    pub to: String,
    /// Total delay in ns.
    pub delay_ns: f64,
    /// Cells along the path (the first and the last few), for the report.
    pub cells: Vec<String>,
}

/// nextpnr's timing of a routed design.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Timing {
    /// Achieved Fmax per clock net, MHz.
    pub fmax_mhz: BTreeMap<String, f64>,
    /// The worst path of each pair of edges.
    pub paths: Vec<EdgePath>,
}

fn edge_of(spec: &str) -> Option<(&str, &str)> {
    let (edge, net) = spec.split_once(' ')?;
    matches!(edge, "posedge" | "negedge").then_some((edge, net))
}

impl Timing {
    /// Reads nextpnr's `--report` JSON.
    pub fn from_report(report: &Value) -> Timing {
        let mut timing = Timing::default();
        if let Some(fmax) = report.get("fmax").and_then(Value::as_object) {
            for (net, v) in fmax {
                if let Some(a) = v.get("achieved").and_then(Value::as_f64) {
                    timing.fmax_mhz.insert(net.clone(), a);
                }
            }
        }
        for p in report
            .get("critical_paths")
            .and_then(Value::as_array)
            .into_iter()
            .flatten()
        {
            let steps: Vec<&Value> = p
                .get("path")
                .and_then(Value::as_array)
                .map(|a| a.iter().collect())
                .unwrap_or_default();
            let delay_ns = steps
                .iter()
                .filter_map(|s| s.get("delay").and_then(Value::as_f64))
                .sum();
            let mut cells: Vec<String> = steps
                .iter()
                .filter_map(|s| s.pointer("/to/cell").and_then(Value::as_str))
                .map(str::to_owned)
                .collect();
            cells.dedup();
            timing.paths.push(EdgePath {
                from: p.get("from").and_then(Value::as_str).unwrap_or("").into(),
                to: p.get("to").and_then(Value::as_str).unwrap_or("").into(),
                delay_ns,
                cells,
            });
        }
        timing
    }

    /// The clock net whose name starts with one of `prefixes` (the first that matches).
    pub fn find_clock(&self, prefixes: &[&str]) -> Option<&str> {
        prefixes.iter().find_map(|p| {
            self.fmax_mhz
                .keys()
                .find(|k| k.starts_with(p))
                .map(String::as_str)
        })
    }

    /// Fmax that the paths through DSP blocks allow `clock` (see the module comment), or
    /// `None` when no path goes through one.
    pub fn dsp_bound_mhz(&self, clock: &str) -> Option<f64> {
        let worst = |from: &dyn Fn(&str) -> bool, to: &dyn Fn(&str) -> bool| {
            self.paths
                .iter()
                .filter(|p| from(&p.from) && to(&p.to))
                .map(|p| p.delay_ns)
                .fold(None, |m: Option<f64>, d| Some(m.map_or(d, |m| m.max(d))))
        };
        // (`$PACKER_GND_NET`, or that net on a global buffer)
        let is_dsp = |s: &str| edge_of(s).is_some_and(|(_, n)| n.starts_with(DSP_CLOCK));
        let between = worst(&is_dsp, &is_dsp).unwrap_or(0.0);
        let mut bound: Option<f64> = None;
        for start in ["posedge", "negedge"] {
            for end in ["posedge", "negedge"] {
                let from_clock = |s: &str| edge_of(s) == Some((start, clock));
                let to_clock = |s: &str| edge_of(s) == Some((end, clock));
                let (Some(into), Some(out)) =
                    (worst(&from_clock, &is_dsp), worst(&is_dsp, &to_clock))
                else {
                    continue;
                };
                let total = into + between + out;
                // a path from one edge to the other has half a period
                let period = if start == end { total } else { 2.0 * total };
                let mhz = 1000.0 / period.max(1e-9);
                bound = Some(bound.map_or(mhz, |b| b.min(mhz)));
            }
        }
        bound
    }

    /// The design's Fmax at `clock`: nextpnr's figure, or the DSP bound when lower.
    pub fn fmax_of(&self, clock: &str) -> Option<f64> {
        let pnr = self.fmax_mhz.get(clock).copied()?;
        Some(self.dsp_bound_mhz(clock).map_or(pnr, |d| d.min(pnr)))
    }

    /// The worst path between edges of `clock` (including the DSP-split ones' parts).
    pub fn critical(&self, clock: &str) -> Option<&EdgePath> {
        self.paths
            .iter()
            .filter(|p| {
                edge_of(&p.from).is_some_and(|(_, n)| n == clock)
                    && edge_of(&p.to).is_some_and(|(_, n)| n == clock)
            })
            .max_by(|a, b| a.delay_ns.total_cmp(&b.delay_ns))
    }
}

/// nextpnr's utilization table (site kind -> usage).
pub fn utilization(report: &Value) -> BTreeMap<String, Usage> {
    let mut out = BTreeMap::new();
    if let Some(u) = report.get("utilization").and_then(Value::as_object) {
        for (kind, v) in u {
            let used = v.get("used").and_then(Value::as_u64);
            let available = v.get("available").and_then(Value::as_u64);
            if let (Some(used), Some(available)) = (used, available) {
                out.insert(kind.clone(), Usage { used, available });
            }
        }
    }
    out
}

/// The `ICESTORM_LC: used/ available` line of a nextpnr log (also printed when the design
/// does not fit and no report is written).
pub fn logic_cells_from_log(log: &str) -> Option<Usage> {
    // the last utilisation line (`ICESTORM_LC:  422/ 7680  5%`); the placer's progress lines
    // name the cell type too (`type ICESTORM_LC: wirelen solved = ...`) and are skipped
    log.lines().rev().find_map(|line| {
        let rest = line.split("ICESTORM_LC:").nth(1)?;
        let (used, rest) = rest.split_once('/')?;
        let available = rest.split_whitespace().next()?;
        Some(Usage {
            used: used.trim().parse().ok()?,
            available: available.trim().parse().ok()?,
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn path(from: &str, to: &str, delays: &[f64]) -> Value {
        let steps: Vec<Value> = delays
            .iter()
            .enumerate()
            .map(|(i, d)| json!({"delay": d, "to": {"cell": format!("c{i}")}}))
            .collect();
        json!({"from": from, "to": to, "path": steps})
    }

    fn sample() -> Value {
        json!({
            "fmax": {"clk": {"achieved": 20.0, "constraint": 14.8}, "$PACKER_GND_NET_$glb_clk": {"achieved": 300.0}},
            "utilization": {"ICESTORM_LC": {"used": 5176, "available": 5280}},
            "critical_paths": [
                path("posedge clk", "negedge clk", &[10.0, 15.0]),
                path("posedge clk", "posedge $PACKER_GND_NET", &[20.0, 10.0]),
                path("posedge $PACKER_GND_NET_$glb_clk", "posedge $PACKER_GND_NET", &[3.0]),
                path("posedge $PACKER_GND_NET", "posedge clk", &[27.0]),
                path("<async>", "posedge clk", &[2.0]),
            ]
        })
    }

    #[test]
    fn the_dsp_bound_adds_the_split_paths() {
        let t = Timing::from_report(&sample());
        assert_eq!(t.paths.len(), 5);
        assert_eq!(t.paths[0].delay_ns, 25.0);
        assert_eq!(t.paths[0].cells, vec!["c0", "c1"]);
        // posedge -> DSP -> DSP -> posedge: 30 + 3 + 27 = 60 ns over a whole period
        let bound = t.dsp_bound_mhz("clk").unwrap();
        assert!((bound - 1000.0 / 60.0).abs() < 1e-9, "{bound}");
        assert!((t.fmax_of("clk").unwrap() - bound).abs() < 1e-9);
        assert_eq!(t.critical("clk").unwrap().delay_ns, 25.0);
        assert_eq!(t.find_clock(&["soc_clk", "cl"]), Some("clk"));
        assert_eq!(t.find_clock(&["nothing"]), None);
    }

    #[test]
    fn a_dsp_path_between_edges_has_half_a_period() {
        let mut r = sample();
        r["critical_paths"][3]["to"] = json!("negedge clk");
        let t = Timing::from_report(&r);
        let bound = t.dsp_bound_mhz("clk").unwrap();
        assert!((bound - 1000.0 / 120.0).abs() < 1e-9, "{bound}");
    }

    #[test]
    fn without_dsp_paths_nextpnr_figure_stands() {
        let mut r = sample();
        r["critical_paths"] = json!([path("posedge clk", "posedge clk", &[30.0])]);
        let t = Timing::from_report(&r);
        assert_eq!(t.dsp_bound_mhz("clk"), None);
        assert_eq!(t.fmax_of("clk"), Some(20.0));
        assert_eq!(t.fmax_of("other"), None);
    }

    #[test]
    fn utilization_and_logic_cells() {
        let u = utilization(&sample());
        assert_eq!(u["ICESTORM_LC"].describe(), "5176/5280 (98 %)");
        let log = "Info: Device utilisation:\nInfo: \t         ICESTORM_LC:  8041/ 7680   104%\n";
        assert_eq!(
            logic_cells_from_log(log),
            Some(Usage {
                used: 8041,
                available: 7680
            })
        );
        assert_eq!(logic_cells_from_log("nothing"), None);
        // the placer's progress lines after it name the cell type as well
        let placed = format!(
            "{log}Info:     at iteration #1, type ICESTORM_LC: wirelen solved = 299, spread = 1775\n"
        );
        assert_eq!(
            logic_cells_from_log(&placed),
            Some(Usage {
                used: 8041,
                available: 7680
            })
        );
    }

    #[test]
    fn yosys_stat_is_read_from_the_last_block() {
        let log = "   Number of cells:  10\n     SB_LUT4   3\n\n=== top ===\n   Number of cells:   7297\n     SB_CARRY                      989\n     SB_DFFN                       466\n     SB_DFFNE                      335\n     SB_LUT4                      4781\n     SB_MAC16                        4\n     SB_RAM40_4KNRNW                 8\n     SB_RAM40_4KNW                   4\n     SB_SPRAM256KA                   4\n\nEnd of script.";
        let c = Cells::from_yosys_log(log).unwrap();
        assert_eq!(
            c,
            Cells {
                lut4: 4781,
                carry: 989,
                ff: 801,
                ram: 12,
                spram: 4,
                dsp: 4
            }
        );
        assert_eq!(Cells::from_yosys_log("no stat"), None);
    }

    proptest::proptest! {
        #[test]
        fn logs_of_any_text_never_panic(text in ".{0,400}") {
            let _ = Cells::from_yosys_log(&text);
            let _ = logic_cells_from_log(&text);
            let stat = format!("Number of cells: 3\n SB_LUT4 {}\n", text.len() + 1);
            proptest::prop_assert_eq!(
                Cells::from_yosys_log(&stat).map(|c| c.lut4),
                Some(text.len() as u64 + 1)
            );
        }

        #[test]
        fn reports_of_any_shape_never_panic(
            delays in proptest::collection::vec(-1e3f64..1e3, 0..6),
            from in "(posedge|negedge|<async>) [a-z$_]{0,8}",
            to in "(posedge|negedge) [a-z$_]{0,8}",
        ) {
            let r = json!({
                "fmax": {"clk": {"achieved": 1.0}},
                "critical_paths": [path(&from, &to, &delays)]
            });
            let t = Timing::from_report(&r);
            let _ = t.dsp_bound_mhz("clk");
            let _ = t.fmax_of("clk");
            proptest::prop_assert_eq!(t.paths.len(), 1);
        }
    }

    #[test]
    fn garbage_reports_give_empty_figures() {
        let t = Timing::from_report(&json!({"fmax": 3, "critical_paths": {"a": 1}}));
        assert_eq!(t, Timing::default());
        assert!(utilization(&json!([1, 2])).is_empty());
    }
}
