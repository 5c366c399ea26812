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

/// The 24 COCO stat columns of a per-run table, bbox then segm (`bbox_AP` … `segm_AR_large`),
/// so every `runs.csv` names them alike.
pub fn stat_columns() -> impl Iterator<Item = String> {
    ["bbox", "segm"]
        .into_iter()
        .flat_map(|k| super::STAT_NAMES.iter().map(move |n| format!("{k}_{n}")))
}

/// A run's 24 stats as cells in [`stat_columns`] order, 4 decimals.
pub fn stat_cells<'a>(
    bbox: &'a [f64; 12],
    segm: &'a [f64; 12],
) -> impl Iterator<Item = String> + 'a {
    bbox.iter().chain(segm).map(|v| format!("{v:.4}"))
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
}
