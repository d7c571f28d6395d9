//! `vbim bench decode --gpu --fit`: a GPU's decode costs from its own timestamps. Each
//! dispatch of a segment's decode is timed (timestamps between dispatches) and knows its
//! pass and its work in the pass's unit; a least-squares fit of
//! `time = latency + cost[pass] × work` over every dispatch gives the adapter's latency
//! per step and cost per unit of each pass, which `DecodeShape::step_cost` and
//! `PassWeights` express in quarter-blocks, the decode budget's unit (taking `key_add` at
//! the weight this adapter's shape gives it). The shipped
//! `DecodeShape::GPU` was fitted by hand on one H100; this puts the same fit in one
//! command for any card.

/// One dispatch: the index of its pass, its work in the pass's unit, its GPU time (ns).
pub type Sample = (usize, f64, f64);

/// The fit of `ns = latency + cost[pass] × units` over `samples`, by least squares with
/// none of them below 0: `(latency, cost per unit of each of the `passes` passes)`. An
/// unknown that the plain fit puts below 0 (on lavapipe, whose time follows work, the
/// latency came out at −0.6 ms; a pass whose time is its latency alone can get a
/// negative cost) is held at 0 and the others fitted again, the most negative first,
/// until none is. `None` where the samples cannot separate them (a pass whose work never
/// varies, and no other to tell its cost from the latency; or no samples).
pub fn fit(samples: &[Sample], passes: usize) -> Option<(f64, Vec<f64>)> {
    let mut held = vec![false; passes + 1];
    loop {
        let x = fit_free(samples, passes, &held)?;
        let below = (0..=passes)
            .filter(|&i| !held[i] && x[i] < 0.0)
            .min_by(|&a, &b| x[a].total_cmp(&x[b]));
        match below {
            Some(i) => held[i] = true,
            None => return Some((x[0], x[1..].to_vec())),
        }
    }
}

/// The least-squares fit with the unknowns `held` at 0: the latency, then each pass's
/// cost per unit.
fn fit_free(samples: &[Sample], passes: usize, held: &[bool]) -> Option<Vec<f64>> {
    if samples.is_empty() {
        return None;
    }
    // Each pass's units scaled by their mean, so that the normal equations are of one
    // magnitude (a parse's tens of units beside a zero pass's millions).
    let mut scale = vec![0.0f64; passes];
    let mut count = vec![0usize; passes];
    for &(p, u, _) in samples {
        scale[p] += u;
        count[p] += 1;
    }
    for (s, &c) in scale.iter_mut().zip(&count) {
        *s = if c > 0 && *s > 0.0 {
            *s / c as f64
        } else {
            1.0
        };
    }
    // Unknowns: the latency, then each pass's cost. The normal equations AᵀA x = Aᵀt,
    // with A's row for a sample 1 in the latency's column and its scaled units in its
    // pass's (a held unknown's column left out).
    let n = passes + 1;
    let mut m = vec![vec![0.0f64; n + 1]; n];
    for &(p, u, t) in samples {
        let cols = [(0, 1.0), (p + 1, u / scale[p])];
        let cols = cols.iter().filter(|c| !held[c.0]);
        for &(i, a) in cols.clone() {
            for &(j, b) in cols.clone() {
                m[i][j] += a * b;
            }
            m[i][n] += a * t;
        }
    }
    // A held unknown, or a pass without samples: 0 (an equation of its own).
    for i in 0..n {
        if held[i] || (i > 0 && count[i - 1] == 0) {
            m[i][i] = 1.0;
        }
    }
    let mut x = solve(m)?;
    for p in 0..passes {
        x[p + 1] /= scale[p];
    }
    Some(x)
}

/// Gaussian elimination with partial pivoting on the augmented matrix `m` (n × n + 1).
fn solve(mut m: Vec<Vec<f64>>) -> Option<Vec<f64>> {
    let n = m.len();
    let size = m
        .iter()
        .flat_map(|r| r[..n].iter())
        .fold(0.0f64, |a, v| a.max(v.abs()));
    for col in 0..n {
        let pivot = (col..n).max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))?;
        if m[pivot][col].abs() <= size * 1e-12 {
            return None;
        }
        m.swap(col, pivot);
        let pivot_row = m[col].clone();
        for (row, r) in m.iter_mut().enumerate() {
            if row != col {
                let f = r[col] / pivot_row[col];
                if f != 0.0 {
                    for (v, p) in r[col..].iter_mut().zip(&pivot_row[col..]) {
                        *v -= f * p;
                    }
                }
            }
        }
    }
    Some((0..n).map(|i| m[i][n] / m[i][i]).collect())
}

/// Prints the fit of `samples` (pass names in `names`) and what it makes of a decode
/// shape for the adapter: the step cost and each pass's weight in quarter-blocks, the
/// unit of `PlayerConfig::decode_budget`, with `key_add` at `key_add_weight` (the weight
/// the adapter's shape gives it: the budget's unit has no pass of its own since bubble
/// planes stay coefficients).
pub fn print(names: &[&'static str], samples: &[Sample], key_add_weight: u32) {
    let Some((latency, costs)) = fit(samples, names.len()) else {
        println!("fit: the dispatches do not separate latency from work (too few, or work that never varies)");
        return;
    };
    println!(
        "fit over {} dispatches, time = latency + cost × work (least squares, none below 0): latency {:.1} µs per dispatch",
        samples.len(),
        latency / 1e3
    );
    let unit = names
        .iter()
        .position(|&n| n == "key_add")
        .map(|i| costs[i] * 4.0 / key_add_weight.max(1) as f64)
        .filter(|&c| c > 0.0);
    for (name, cost) in names.iter().zip(&costs) {
        let n = samples.iter().filter(|s| names[s.0] == *name).count();
        let weight = unit.map_or(String::new(), |u| {
            format!(", weight {:.1} quarter-blocks", 4.0 * cost / u)
        });
        println!("  {name:<14} {cost:>9.3} ns per unit ({n} dispatches){weight}");
    }
    match unit {
        Some(u) => println!(
            "as a DecodeShape for this adapter: step_cost {:.0} blocks (the latency in blocks of the budget's unit at {u:.3} ns each, key_add at weight {key_add_weight}), weights as above (0: the pass's time is its latency alone; use 1)",
            latency / u
        ),
        None => println!("no key_add dispatch with a cost: no weights in the budget's unit"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Dispatches made from a known latency and known costs, with a little noise, give
    /// them back.
    #[test]
    fn the_fit_recovers_a_known_latency_and_costs() {
        let (latency, costs) = (20_000.0, [35.0, 0.42, 0.58, 2.5]);
        let mut s = 7u32;
        let mut next = move || {
            s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (s >> 8) as f64 / (1u32 << 24) as f64
        };
        let mut samples = Vec::new();
        for i in 0..400 {
            let p = i % costs.len();
            let units = [300.0, 200_000.0, 150_000.0, 40_000.0][p] * (0.2 + next());
            let ns = latency + costs[p] * units + 50.0 * (next() - 0.5);
            samples.push((p, units, ns));
        }
        let (l, c) = fit(&samples, costs.len()).expect("a fit");
        assert!((l - latency).abs() < 100.0, "latency {l}");
        for (got, want) in c.iter().zip(costs) {
            assert!(
                (got - want).abs() < want * 0.01,
                "cost {got} against {want}"
            );
        }
    }

    /// Times that a plain fit would give a negative latency (time falling short of work
    /// in proportion), and a pass whose time falls as its work grows: each held at 0,
    /// the others fitted again.
    #[test]
    fn no_latency_or_cost_is_fitted_below_zero() {
        let us = (0..100).map(|i| 1000.0 + 10.0 * i as f64);
        let short: Vec<Sample> = us.clone().map(|u| (0, u, 2.0 * u - 1500.0)).collect();
        let (l, c) = fit(&short, 1).expect("a fit");
        assert_eq!(l, 0.0, "latency held at 0");
        // Then through the origin: Σ u t / Σ u².
        let (ut, uu) = short
            .iter()
            .fold((0.0, 0.0), |(a, b), s| (a + s.1 * s.2, b + s.1 * s.1));
        assert!(
            (c[0] - ut / uu).abs() < 1e-9 * c[0],
            "{} against {}",
            c[0],
            ut / uu
        );
        // A latency of 1000 ns that the first pass pins down, and a second pass below it.
        let mut mixed: Vec<Sample> = us.clone().map(|u| (0, u, 1000.0 + u)).collect();
        mixed.extend(us.map(|u| (1, u, 1100.0 - 0.2 * u)));
        let (l, c) = fit(&mixed, 2).expect("a fit");
        assert_eq!(c[1], 0.0, "a cost that falls with work held at 0");
        assert!(l > 0.0 && c[0] > 0.0, "latency {l}, costs {c:?}");
    }

    /// One pass whose work never varies cannot be told from the latency: no fit.
    #[test]
    fn a_pass_of_constant_work_alone_cannot_be_fitted() {
        let samples: Vec<Sample> = (0..10).map(|_| (0, 100.0, 5000.0)).collect();
        assert!(fit(&samples, 1).is_none());
        assert!(fit(&[], 3).is_none());
    }
}
