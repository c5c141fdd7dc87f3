//! The arithmetic every measurement program reports with, written once so that their tables
//! agree: the median of timed runs, and PSNR of 8-bit samples.

/// The median of `values` (the mean of the middle two for an even count); NaN for none. Sorts
/// `values`.
pub fn median(values: &mut [f64]) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    match n {
        0 => f64::NAN,
        _ if n % 2 == 1 => values[n / 2],
        _ => (values[n / 2 - 1] + values[n / 2]) / 2.0,
    }
}

/// PSNR in dB of 8-bit samples (peak 255) from the sum of their squared errors over `samples`
/// samples; infinite when nothing differs.
pub fn psnr_8bit(squared_errors: f64, samples: f64) -> f64 {
    if squared_errors == 0.0 { f64::INFINITY } else { 10.0 * (255.0f64 * 255.0 * samples / squared_errors).log10() }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn medians_and_psnr_of_known_values() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
        assert!(median(&mut []).is_nan());
        // Every sample off by 1: 10 log10(255²) = 48.13 dB.
        assert!((psnr_8bit(100.0, 100.0) - 48.1308).abs() < 1e-4);
        assert_eq!(psnr_8bit(0.0, 5.0), f64::INFINITY);
    }
}
