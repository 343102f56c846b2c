//! Helpers the harness programs share.

/// A value of `T` by its `FromStr`, the error as text (for clap's `value_parser`).
pub fn parse<T: std::str::FromStr>(s: &str) -> Result<T, String>
where
    T::Err: std::fmt::Display,
{
    s.parse().map_err(|e: T::Err| e.to_string())
}

/// Row-major `(T, d)` from component-major signals (one `Vec` per component, equal lengths;
/// a shorter one reads as NaN).
pub fn rows(signals: &[Vec<f64>]) -> Vec<f64> {
    let t = signals.first().map_or(0, Vec::len);
    (0..t)
        .flat_map(|k| {
            signals
                .iter()
                .map(move |s| s.get(k).copied().unwrap_or(f64::NAN))
        })
        .collect()
}
