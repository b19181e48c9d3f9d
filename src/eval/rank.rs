//! Best-of-N: the order in which a job's or a `generate` run's samples are ranked, so the CLI and
//! the service pick the same best sample from the same scores.
//!
//! Today a sample's score is its D_pc (mean distance from the scan's points to its mesh, lower
//! is better); a sample with no finite score (no mesh, no points) ranks last; ties keep the
//! samples' own order.

/// The order of `scores` from best to worst: indices into `scores`, ascending by score,
/// non-finite scores last, equal scores in index order.
pub fn rank_order(scores: &[f64]) -> Vec<usize> {
    let key = |v: f64| if v.is_finite() { v } else { f64::INFINITY };
    let mut order: Vec<usize> = (0..scores.len()).collect();
    order.sort_by(|&a, &b| key(scores[a]).total_cmp(&key(scores[b])).then(a.cmp(&b)));
    order
}

/// `items` reordered best first by `rank_order` of their scores.
pub fn ranked<T>(items: Vec<T>, score: impl Fn(&T) -> f64) -> Vec<T> {
    let scores: Vec<f64> = items.iter().map(&score).collect();
    let mut slots: Vec<Option<T>> = items.into_iter().map(Some).collect();
    rank_order(&scores)
        .into_iter()
        .map(|i| slots[i].take().expect("rank_order is a permutation"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ascending_with_non_finite_last_and_ties_in_order() {
        let s = [0.3, f64::NAN, 0.1, 0.3, f64::INFINITY, 0.2];
        assert_eq!(rank_order(&s), vec![2, 5, 0, 3, 1, 4]);
        assert_eq!(
            ranked(vec!["a", "b", "c"], |x| if *x == "b" { 0.0 } else { 1.0 }),
            vec!["b", "a", "c"]
        );
        assert!(rank_order(&[]).is_empty());
    }
}
