//! Minimum-cost linear assignment (the Hungarian problem) by shortest augmenting paths,
//! the Jonker–Volgenant-style algorithm of Crouse (2016) that scipy's
//! `linear_sum_assignment` implements. Mask2Former's matcher needs it once per image and
//! decoder layer; it lives here (no tensors, no model) so any stage can use it.
//!
//! Same contract as scipy, so results can be compared one to one (committed fixtures in
//! `tests/fixtures/mask2former/lsap.json`, made by `make_lsap.py` beside them):
//! rectangular matrices assign `min(rows, cols)` pairs, rows ascending; `+inf` marks a
//! forbidden pair; NaN or `-inf` anywhere is [`AssignError::Invalid`]; a matrix with no
//! finite complete assignment is [`AssignError::Infeasible`] (scipy raises on both). Ties
//! break as scipy's: the same visiting order, the same "prefer a free column" rule.

use thiserror::Error;

#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum AssignError {
    #[error("cost matrix has {got} entries, {rows}×{cols} needs {}", rows * cols)]
    Shape {
        rows: usize,
        cols: usize,
        got: usize,
    },
    #[error("cost matrix contains NaN or -inf entries")]
    Invalid,
    #[error("cost matrix is infeasible (no assignment avoids +inf costs)")]
    Infeasible,
}

/// Pairs `(row, col)` of a minimum-cost assignment of the row-major `rows × cols` matrix
/// `cost`, rows ascending; `min(rows, cols)` pairs.
pub fn linear_sum_assignment(
    cost: &[f64],
    rows: usize,
    cols: usize,
) -> Result<Vec<(usize, usize)>, AssignError> {
    if cost.len() != rows * cols {
        return Err(AssignError::Shape {
            rows,
            cols,
            got: cost.len(),
        });
    }
    if rows == 0 || cols == 0 {
        return Ok(Vec::new());
    }
    if cost.iter().any(|c| c.is_nan() || *c == f64::NEG_INFINITY) {
        return Err(AssignError::Invalid);
    }
    // The solver wants rows ≤ cols: a tall matrix is solved transposed.
    let transpose = cols < rows;
    let (nr, nc) = if transpose {
        (cols, rows)
    } else {
        (rows, cols)
    };
    let c: Vec<f64> = if transpose {
        let mut t = vec![0.0; rows * cols];
        for i in 0..rows {
            for j in 0..cols {
                t[j * rows + i] = cost[i * cols + j];
            }
        }
        t
    } else {
        cost.to_vec()
    };
    let col4row = solve(&c, nr, nc)?;
    let mut pairs: Vec<(usize, usize)> = if transpose {
        col4row.iter().enumerate().map(|(r, &cj)| (cj, r)).collect()
    } else {
        col4row.iter().enumerate().map(|(r, &cj)| (r, cj)).collect()
    };
    pairs.sort_unstable();
    Ok(pairs)
}

/// Column of each row for `nr ≤ nc`.
fn solve(cost: &[f64], nr: usize, nc: usize) -> Result<Vec<usize>, AssignError> {
    const NONE: usize = usize::MAX;
    let mut u = vec![0.0f64; nr];
    let mut v = vec![0.0f64; nc];
    let mut spc = vec![f64::INFINITY; nc];
    let mut path = vec![NONE; nc];
    let mut col4row = vec![NONE; nr];
    let mut row4col = vec![NONE; nc];
    let mut sr = vec![false; nr];
    let mut sc = vec![false; nc];
    let mut remaining = vec![0usize; nc];
    for cur in 0..nr {
        // Dijkstra-like search for the cheapest path from row `cur` to a free column.
        let mut min_val = 0.0f64;
        let mut n_rem = nc;
        for (it, r) in remaining.iter_mut().enumerate() {
            // Reverse order: a constant matrix gives the identity (scipy #11602).
            *r = nc - it - 1;
        }
        sr.fill(false);
        sc.fill(false);
        spc.fill(f64::INFINITY);
        let mut i = cur;
        let sink = loop {
            let mut index = NONE;
            let mut lowest = f64::INFINITY;
            sr[i] = true;
            for (it, &j) in remaining[..n_rem].iter().enumerate() {
                let r = min_val + cost[i * nc + j] - u[i] - v[j];
                if r < spc[j] {
                    path[j] = i;
                    spc[j] = r;
                }
                // On ties prefer a column that ends the path.
                if spc[j] < lowest || (spc[j] == lowest && row4col[j] == NONE) {
                    lowest = spc[j];
                    index = it;
                }
            }
            min_val = lowest;
            if min_val == f64::INFINITY || index == NONE {
                return Err(AssignError::Infeasible);
            }
            let j = remaining[index];
            sc[j] = true;
            n_rem -= 1;
            remaining[index] = remaining[n_rem];
            if row4col[j] == NONE {
                break j;
            }
            i = row4col[j];
        };
        // Dual update.
        u[cur] += min_val;
        for r in 0..nr {
            if sr[r] && r != cur {
                u[r] += min_val - spc[col4row[r]];
            }
        }
        for j in 0..nc {
            if sc[j] {
                v[j] -= min_val - spc[j];
            }
        }
        // Augment along the path.
        let mut j = sink;
        loop {
            let r = path[j];
            row4col[j] = r;
            std::mem::swap(&mut col4row[r], &mut j);
            if r == cur {
                break;
            }
        }
    }
    Ok(col4row)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::Value;

    fn num(v: &Value) -> f64 {
        match v {
            Value::String(s) if s == "inf" => f64::INFINITY,
            Value::String(s) if s == "-inf" => f64::NEG_INFINITY,
            Value::String(s) if s == "nan" => f64::NAN,
            v => v.as_f64().expect("number"),
        }
    }

    #[test]
    fn equals_scipy_on_committed_matrices() {
        let text = include_str!("../../tests/fixtures/mask2former/lsap.json");
        let cases: Vec<Value> = serde_json::from_str(text).unwrap();
        assert!(cases.len() >= 40, "{} cases", cases.len());
        let mut kinds = std::collections::BTreeSet::new();
        for (k, case) in cases.iter().enumerate() {
            let rows = case["rows"].as_u64().unwrap() as usize;
            let cols = case["cols"].as_u64().unwrap() as usize;
            let cost: Vec<f64> = case["cost"].as_array().unwrap().iter().map(num).collect();
            let got = linear_sum_assignment(&cost, rows, cols);
            kinds.insert(case["kind"].as_str().unwrap().to_string());
            match case["error"].as_str() {
                Some("infeasible") => assert_eq!(got, Err(AssignError::Infeasible), "case {k}"),
                Some("invalid") => assert_eq!(got, Err(AssignError::Invalid), "case {k}"),
                Some(e) => panic!("unknown error kind {e}"),
                None => {
                    let want: Vec<(usize, usize)> = case["row_ind"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .zip(case["col_ind"].as_array().unwrap())
                        .map(|(r, c)| (r.as_u64().unwrap() as usize, c.as_u64().unwrap() as usize))
                        .collect();
                    let got = got.unwrap_or_else(|e| panic!("case {k} ({rows}×{cols}): {e}"));
                    let total: f64 = got.iter().map(|&(r, c)| cost[r * cols + c]).sum();
                    let want_total = case["total"].as_f64().unwrap();
                    assert!(
                        (total - want_total).abs() <= 1e-9 * want_total.abs().max(1.0),
                        "case {k}: total {total} vs scipy {want_total}"
                    );
                    assert_eq!(got, want, "case {k} ({rows}×{cols}, {})", case["kind"]);
                }
            }
        }
        for k in [
            "square",
            "wide",
            "tall",
            "ties",
            "inf",
            "infeasible",
            "invalid",
            "empty",
        ] {
            assert!(kinds.contains(k), "fixture lacks {k} cases: {kinds:?}");
        }
    }

    #[test]
    fn brute_force_optimum_on_small_matrices() {
        // Independent of scipy: exhaustive search over permutations of ≤ 5 columns.
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for _ in 0..200 {
            let rows = rng.random_range(1..=4);
            let cols = rng.random_range(rows..=5);
            let cost: Vec<f64> = (0..rows * cols)
                .map(|_| rng.random_range(0..10) as f64)
                .collect();
            let got = linear_sum_assignment(&cost, rows, cols).unwrap();
            let total: f64 = got.iter().map(|&(r, c)| cost[r * cols + c]).sum();
            fn best(cost: &[f64], r: usize, rows: usize, cols: usize, used: &mut Vec<bool>) -> f64 {
                if r == rows {
                    return 0.0;
                }
                let mut b = f64::INFINITY;
                for c in 0..cols {
                    if !used[c] {
                        used[c] = true;
                        b = b.min(cost[r * cols + c] + best(cost, r + 1, rows, cols, used));
                        used[c] = false;
                    }
                }
                b
            }
            assert_eq!(total, best(&cost, 0, rows, cols, &mut vec![false; cols]));
            let mut cs: Vec<usize> = got.iter().map(|p| p.1).collect();
            cs.sort_unstable();
            cs.dedup();
            assert_eq!(cs.len(), rows, "each column at most once");
        }
    }

    #[test]
    fn shape_errors_are_reported() {
        assert_eq!(
            linear_sum_assignment(&[1.0, 2.0], 2, 2),
            Err(AssignError::Shape {
                rows: 2,
                cols: 2,
                got: 2
            })
        );
        assert_eq!(linear_sum_assignment(&[], 0, 5), Ok(vec![]));
    }
}
