//! The scaling table's fit (issue 15, item 5): the exponent of a power law comes back.

use texsyn::bench::scaling::power_law_exponent;

#[test]
fn a_known_power_law_gives_its_exponent_back() {
    let sizes = [1e4, 4e4, 1.6e5];
    // (exponent, value = 3.7 · (size / 10⁴)^exponent computed without logarithms)
    type Law = fn(f64) -> f64;
    let laws: [(f64, Law); 5] = [
        (0.0, |_| 1.0),
        (0.5, |r| r.sqrt()),
        (1.0, |r| r),
        (1.5, |r| r * r.sqrt()),
        (2.0, |r| r * r),
    ];
    for (k, law) in laws {
        let values: Vec<f64> = sizes.iter().map(|&s| 3.7 * law(s / 1e4)).collect();
        let got = power_law_exponent(&sizes, &values).unwrap();
        assert!((got - k).abs() < 1e-9, "exponent {k}: fitted {got}");
    }
}

#[test]
fn the_fit_is_least_squares_over_all_points() {
    // log₂ points (0, 0), (1, 2), (2, 2), (3, 3): x̄ = 1.5, ȳ = 1.75, Σ(x − x̄)(y − ȳ) = 4.5 and
    // Σ(x − x̄)² = 5, so the slope is 0.9; the end points alone would give 1.
    let sizes = [1.0, 2.0, 4.0, 8.0];
    let values = [1.0, 4.0, 4.0, 8.0];
    let got = power_law_exponent(&sizes, &values).unwrap();
    assert!((got - 0.9).abs() < 1e-12, "{got}");
}

#[test]
fn no_exponent_without_a_slope_or_with_nonpositive_values() {
    assert_eq!(power_law_exponent(&[5.0, 5.0, 5.0], &[1.0, 2.0, 3.0]), None);
    assert_eq!(power_law_exponent(&[1.0, 4.0], &[0.0, 1.0]), None);
    assert_eq!(power_law_exponent(&[1.0], &[1.0]), None);
    assert_eq!(power_law_exponent(&[1.0, 4.0], &[1.0]), None);
}
