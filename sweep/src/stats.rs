//! `aggregate.csv`: for every point and every chosen metric, over the point's complete runs
//! that have a value: n, mean, sample standard deviation and the 95 % confidence interval of
//! the mean (Student t with n - 1 degrees of freedom; empty for n < 2); and the point's failed
//! runs (every run that is not complete). Booleans count as 0 and 1, so their mean is a rate.

use crate::error::{write_err, SweepError};
use crate::plan::Plan;
use crate::table::{csv_err, RunRow};
use statrs::distribution::{ContinuousCDF, StudentsT};
use std::path::Path;

/// Summary statistics of one metric at one point.
#[derive(Debug, Clone, PartialEq)]
pub struct Stat {
    /// Values.
    pub n: usize,
    /// Runs of the point that are not complete.
    pub failures: usize,
    /// Mean (`None` without values).
    pub mean: Option<f64>,
    /// Sample standard deviation (n >= 2).
    pub sd: Option<f64>,
    /// Half width of the 95 % confidence interval of the mean (n >= 2).
    pub ci95: Option<f64>,
}

impl Stat {
    /// The statistics of `values`.
    pub fn of(values: &[f64], failures: usize) -> Stat {
        let n = values.len();
        let mean = (n > 0).then(|| values.iter().sum::<f64>() / n as f64);
        let sd = mean.filter(|_| n >= 2).map(|m| {
            let ss: f64 = values.iter().map(|v| (v - m) * (v - m)).sum();
            (ss / (n - 1) as f64).sqrt()
        });
        let ci95 = sd.and_then(|s| Some(t_975(n - 1)? * s / (n as f64).sqrt()));
        Stat {
            n,
            failures,
            mean,
            sd,
            ci95,
        }
    }
}

/// The 97.5 % quantile of Student's t with `dof` degrees of freedom.
pub fn t_975(dof: usize) -> Option<f64> {
    StudentsT::new(0.0, 1.0, dof as f64)
        .ok()
        .map(|t| t.inverse_cdf(0.975))
}

/// `metric` at every point: statistics over the point's rows.
pub fn per_point(plan: &Plan, rows: &[RunRow], metric: &str) -> Vec<Stat> {
    (0..plan.points.len())
        .map(|p| {
            let mine = rows.iter().filter(|r| r.run.point == p);
            let failures = mine.clone().filter(|r| !r.state.is_complete()).count();
            let values: Vec<f64> = mine
                .filter(|r| r.state.is_complete())
                .filter_map(|r| r.metric(metric))
                .collect();
            Stat::of(&values, failures)
        })
        .collect()
}

/// `v` to 6 significant digits, as short as it goes.
pub fn num(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{}", if v == 0.0 { 0.0 } else { v });
    }
    let digits = 5 - v.abs().log10().floor() as i32;
    let f = 10f64.powi(digits);
    let r = if digits >= 0 {
        (v * f).round() / f
    } else {
        (v / 10f64.powi(-digits)).round() * 10f64.powi(-digits)
    };
    format!("{r}")
}

fn opt(v: Option<f64>) -> String {
    v.map(num).unwrap_or_default()
}

/// Writes `aggregate.csv`: one row per point and metric, points in order, metrics in the
/// sweep's order.
pub fn write_aggregate(path: &Path, plan: &Plan, rows: &[RunRow]) -> Result<(), SweepError> {
    let mut w = csv::Writer::from_path(path).map_err(|e| csv_err(path, e))?;
    let mut header: Vec<String> = vec!["point".into()];
    header.extend(plan.parameters.iter().cloned());
    header.extend(
        [
            "metric",
            "n",
            "failures",
            "mean",
            "sd",
            "ci95_low",
            "ci95_high",
        ]
        .iter()
        .map(|s| (*s).to_owned()),
    );
    w.write_record(&header).map_err(|e| csv_err(path, e))?;
    let stats: Vec<Vec<Stat>> = plan
        .metrics
        .iter()
        .map(|m| per_point(plan, rows, m))
        .collect();
    for p in 0..plan.points.len() {
        for (metric, per_point) in plan.metrics.iter().zip(&stats) {
            let s = &per_point[p];
            let mut rec: Vec<String> = vec![p.to_string()];
            rec.extend(plan.point_labels(p));
            rec.push(metric.clone());
            rec.push(s.n.to_string());
            rec.push(s.failures.to_string());
            rec.push(opt(s.mean));
            rec.push(opt(s.sd));
            let (lo, hi) = match (s.mean, s.ci95) {
                (Some(m), Some(h)) => (Some(m - h), Some(m + h)),
                _ => (None, None),
            };
            rec.push(opt(lo));
            rec.push(opt(hi));
            w.write_record(&rec).map_err(|e| csv_err(path, e))?;
        }
    }
    w.flush().map_err(write_err(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn t_quantiles_match_the_tables() {
        for (dof, t) in [(1, 12.706), (2, 4.303), (4, 2.776), (9, 2.262), (30, 2.042)] {
            let q = t_975(dof).unwrap();
            assert!((q - t).abs() < 1e-3, "dof {dof}: {q}");
        }
    }

    #[test]
    fn mean_sd_and_interval() {
        let s = Stat::of(&[1.0, 2.0, 3.0, 4.0, 5.0], 1);
        assert_eq!(s.n, 5);
        assert_eq!(s.failures, 1);
        assert_eq!(s.mean, Some(3.0));
        let sd = s.sd.unwrap();
        assert!((sd - 2.5f64.sqrt()).abs() < 1e-12);
        let h = s.ci95.unwrap();
        assert!((h - 2.776445 * sd / 5f64.sqrt()).abs() < 1e-4, "{h}");
        let one = Stat::of(&[7.0], 0);
        assert_eq!((one.mean, one.sd, one.ci95), (Some(7.0), None, None));
        let none = Stat::of(&[], 2);
        assert_eq!((none.n, none.mean), (0, None));
    }

    #[test]
    fn numbers_are_short() {
        assert_eq!(num(0.1 + 0.2), "0.3");
        assert_eq!(num(1234567.0), "1234570");
        assert_eq!(num(-0.000123456789), "-0.000123457");
        assert_eq!(num(0.0), "0");
        assert_eq!(num(42.0), "42");
    }
}
