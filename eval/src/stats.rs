//! The statistics every report of qicp uses: one place for each.

/// Mean, population standard deviation and maximum; NaN for no values.
pub fn summary(v: impl Iterator<Item = f64> + Clone) -> (f64, f64, f64) {
    let (mut n, mut sum, mut max) = (0usize, 0.0, f64::NAN);
    for x in v.clone() {
        n += 1;
        sum += x;
        max = x.max(max);
    }
    if n == 0 {
        return (f64::NAN, f64::NAN, f64::NAN);
    }
    let mean = sum / n as f64;
    let var = v.map(|x| (x - mean) * (x - mean)).sum::<f64>() / n as f64;
    (mean, var.sqrt(), max)
}

/// The `q`-quantile of the finite `values` by nearest rank (an observed value); NaN for none.
#[must_use]
pub fn quantile(values: &[f64], q: f64) -> f64 {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let rank = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[rank - 1]
}

/// The median: the middle value, the mean of the middle two for an even count; `None` for
/// none.
#[must_use]
pub fn median(values: &[f64]) -> Option<f64> {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    match n {
        0 => None,
        _ if n % 2 == 1 => v.get(n / 2).copied(),
        _ => Some((v.get(n / 2 - 1)? + v.get(n / 2)?) / 2.0),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_and_even_counts() {
        assert_eq!(median(&[]), None);
        assert_eq!(median(&[3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), Some(2.5));
    }

    #[test]
    fn quantiles_are_observed_values_by_nearest_rank() {
        let v = [5.0, 1.0, f64::NAN, 3.0, 2.0, 4.0];
        assert_eq!(quantile(&v, 0.5), 3.0);
        assert_eq!(quantile(&v, 0.0), 1.0);
        assert_eq!(quantile(&v, 1.0), 5.0);
        assert!(quantile(&[f64::NAN], 0.5).is_nan());
    }

    #[test]
    fn summary_is_mean_population_std_and_max() {
        let (mean, std, max) = summary([1.0, 3.0].into_iter());
        assert_eq!((mean, std, max), (2.0, 1.0, 3.0));
        assert!(summary(std::iter::empty()).0.is_nan());
    }
}
