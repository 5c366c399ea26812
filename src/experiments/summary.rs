//! A study's summary over seeds: each variant's runs grouped, every column as mean and
//! sample standard deviation ([`group`]), and the cells its reports share — the per-run
//! table of the 24 COCO stats ([`runs_table`]), `<metric>_mean` / `<metric>_std` CSV
//! columns and cells, and the markdown cell that shows the spread only when there is one.

use crate::eval::report::{stat_cells, stat_columns, Table};
use crate::util::stats::mean_std;

/// One variant's row: its key, how many runs it has and each column's (mean, sample std).
#[derive(Clone, Debug, PartialEq)]
pub struct Group<K> {
    pub key: K,
    pub runs: usize,
    pub columns: Vec<(f64, f64)>,
}

/// Groups `rows` by `key` in the order the keys first appear; each of the columns
/// `values` gives per row is summarised as mean and sample std (0 for a single run).
pub fn group<R, K: PartialEq + Clone>(
    rows: &[R],
    key: impl Fn(&R) -> K,
    values: impl Fn(&R) -> Vec<f64>,
) -> Vec<Group<K>> {
    let mut keys: Vec<K> = Vec::new();
    for r in rows {
        if !keys.contains(&key(r)) {
            keys.push(key(r));
        }
    }
    keys.into_iter()
        .map(|k| {
            let vs: Vec<Vec<f64>> = rows.iter().filter(|r| key(r) == k).map(&values).collect();
            let n = vs.first().map_or(0, Vec::len);
            let columns = (0..n)
                .map(|j| mean_std(&vs.iter().map(|v| v[j]).collect::<Vec<_>>()))
                .collect();
            Group {
                key: k,
                runs: vs.len(),
                columns,
            }
        })
        .collect()
}

/// The `runs.csv` table: the given identifying columns, then the 24 COCO stats of each
/// run (bbox then segm).
pub fn runs_table<'a>(
    id_columns: &[&str],
    rows: impl IntoIterator<Item = (Vec<String>, &'a [f64; 12], &'a [f64; 12])>,
) -> Table {
    let mut t = Table::new(
        id_columns
            .iter()
            .map(|c| c.to_string())
            .chain(stat_columns()),
    );
    for (mut ids, bbox, segm) in rows {
        ids.extend(stat_cells(bbox, segm));
        t.push(ids);
    }
    t
}

/// `<name>_mean`, `<name>_std` for each metric name (spaces become underscores).
pub fn mean_std_columns<'a>(names: &'a [&'a str]) -> impl Iterator<Item = String> + 'a {
    names.iter().flat_map(|n| {
        let n = n.replace(' ', "_");
        [format!("{n}_mean"), format!("{n}_std")]
    })
}

/// Each (mean, std) as two CSV cells, 4 decimals.
pub fn mean_std_cells(ms: &[(f64, f64)]) -> impl Iterator<Item = String> + '_ {
    ms.iter()
        .flat_map(|(m, sd)| [format!("{m:.4}"), format!("{sd:.4}")])
}

/// A markdown cell: `mean ± std` (3 decimals) over several runs, the mean alone over one.
pub fn md_cell((m, sd): (f64, f64), runs: usize) -> String {
    if runs > 1 {
        format!("{m:.3} ± {sd:.3}")
    } else {
        format!("{m:.3}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn groups_keep_first_appearance_order_with_sample_std() {
        let rows = [("b", 1.0), ("a", 0.4), ("b", 3.0), ("a", 0.6)];
        let g = group(&rows, |r| r.0, |r| vec![r.1, 2.0 * r.1]);
        assert_eq!(g.len(), 2);
        assert_eq!((g[0].key, g[0].runs), ("b", 2));
        assert_eq!(g[0].columns[0].0, 2.0);
        assert!((g[0].columns[0].1 - std::f64::consts::SQRT_2).abs() < 1e-12);
        assert!((g[1].columns[1].0 - 1.0).abs() < 1e-12);
        let one = group(&rows[..1], |r| r.0, |r| vec![r.1]);
        assert_eq!(one[0].columns, [(1.0, 0.0)]);
    }

    #[test]
    fn cells_and_columns() {
        assert_eq!(
            mean_std_columns(&["segm AP", "x"]).collect::<Vec<_>>(),
            ["segm_AP_mean", "segm_AP_std", "x_mean", "x_std"]
        );
        assert_eq!(
            mean_std_cells(&[(0.5, 0.14142), (1.0, 0.0)]).collect::<Vec<_>>(),
            ["0.5000", "0.1414", "1.0000", "0.0000"]
        );
        assert_eq!(md_cell((0.5, 0.14142), 2), "0.500 ± 0.141");
        assert_eq!(md_cell((0.5, 0.14142), 1), "0.500");
        let s = [0.25; 12];
        let t = runs_table(&["v", "seed"], [(vec!["a".into(), "0".into()], &s, &s)]);
        assert_eq!(t.header.len(), 26);
        assert_eq!(t.header[2], "bbox_AP");
        assert_eq!(t.rows[0][2], "0.2500");
    }
}
