//! Report tables (one header, rows of cells) written as CSV and as GitHub markdown, and
//! the summary statistics the bench and sweep reports quote (mean ± sample std,
//! nearest-rank percentiles).

use std::path::Path;

use anyhow::Result;

/// A table of text cells; numbers are formatted by the caller, so the CSV and the
/// markdown show the same digits.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Table {
    pub header: Vec<String>,
    pub rows: Vec<Vec<String>>,
}

impl Table {
    pub fn new<S: Into<String>>(header: impl IntoIterator<Item = S>) -> Table {
        Table {
            header: header.into_iter().map(Into::into).collect(),
            rows: Vec::new(),
        }
    }

    /// Appends a row; it must have one cell per column.
    pub fn push(&mut self, row: Vec<String>) {
        debug_assert_eq!(row.len(), self.header.len());
        self.rows.push(row);
    }

    /// RFC 4180 CSV: cells with a comma, quote or newline are quoted.
    pub fn to_csv(&self) -> String {
        let cell = |c: &String| {
            if c.contains([',', '"', '\n']) {
                format!("\"{}\"", c.replace('"', "\"\""))
            } else {
                c.clone()
            }
        };
        let mut s = String::new();
        for r in std::iter::once(&self.header).chain(&self.rows) {
            s.push_str(&r.iter().map(cell).collect::<Vec<_>>().join(","));
            s.push('\n');
        }
        s
    }

    /// A GitHub markdown table (pipes in cells escaped).
    pub fn to_markdown(&self) -> String {
        let line = |r: &[String]| {
            format!(
                "| {} |\n",
                r.iter()
                    .map(|c| c.replace('|', "\\|"))
                    .collect::<Vec<_>>()
                    .join(" | ")
            )
        };
        let mut s = line(&self.header);
        s.push_str(&format!("|{}\n", "---|".repeat(self.header.len())));
        for r in &self.rows {
            s.push_str(&line(r));
        }
        s
    }

    /// Writes `<stem>.csv` and `<stem>.md` (the markdown after `preamble`) atomically.
    pub fn write(&self, dir: &Path, stem: &str, preamble: &str) -> Result<()> {
        crate::util::write_atomic(&dir.join(format!("{stem}.csv")), self.to_csv().as_bytes())?;
        let md = format!("{preamble}{}", self.to_markdown());
        crate::util::write_atomic(&dir.join(format!("{stem}.md")), md.as_bytes())
    }
}

/// Mean and sample standard deviation (n − 1; 0 for a single value).
pub fn mean_std(v: &[f64]) -> (f64, f64) {
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    if v.len() < 2 {
        return (m, 0.0);
    }
    let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0);
    (m, var.sqrt())
}

/// Nearest-rank percentile `p` (0–100) of `v` (NaN when empty).
pub fn percentile(v: &[f64], p: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let rank = ((p / 100.0) * s.len() as f64).ceil() as usize;
    s[rank.clamp(1, s.len()) - 1]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_quotes_and_markdown_escapes() {
        let mut t = Table::new(["a", "b"]);
        t.push(vec!["1,5".into(), "x|y".into()]);
        assert_eq!(t.to_csv(), "a,b\n\"1,5\",x|y\n");
        assert_eq!(t.to_markdown(), "| a | b |\n|---|---|\n| 1,5 | x\\|y |\n");
    }

    #[test]
    fn stats_match_hand_values() {
        let (m, s) = mean_std(&[1.0, 2.0, 3.0, 4.0]);
        assert_eq!(m, 2.5);
        assert!((s - 1.2909944487358056).abs() < 1e-12);
        assert_eq!(mean_std(&[0.7]), (0.7, 0.0));
        let v: Vec<f64> = (1..=10).map(f64::from).collect();
        assert_eq!(percentile(&v, 50.0), 5.0);
        assert_eq!(percentile(&v, 10.0), 1.0);
        assert_eq!(percentile(&v, 90.0), 9.0);
        assert_eq!(percentile(&v, 100.0), 10.0);
        assert!(percentile(&[], 50.0).is_nan());
    }
}
