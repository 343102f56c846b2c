//! Resampling several signals onto one uniform time grid.

use crate::{IoError, RawSignal};

/// Resampling options.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResampleOptions {
    /// Grid rate in Hz (finite, > 0).
    pub rate_hz: f64,
    /// Largest allowed interval between consecutive samples of a signal inside the grid's span,
    /// in seconds (finite, > 0). Default 0.5.
    pub max_gap_s: f64,
}

impl ResampleOptions {
    /// The default largest gap between two samples of a signal (s).
    pub const DEFAULT_MAX_GAP_S: f64 = 0.5;

    /// Options with the given rate and the default `max_gap_s` ([`Self::DEFAULT_MAX_GAP_S`]).
    pub fn new(rate_hz: f64) -> Self {
        ResampleOptions {
            rate_hz,
            max_gap_s: Self::DEFAULT_MAX_GAP_S,
        }
    }
}

impl Default for ResampleOptions {
    /// 100 Hz, `max_gap_s` 0.5.
    fn default() -> Self {
        ResampleOptions::new(100.0)
    }
}

/// Signals on one uniform grid.
#[derive(Clone, Debug, PartialEq)]
pub struct Aligned {
    /// The grid rate (Hz).
    pub rate_hz: f64,
    /// Absolute time of the first grid point (ns, on the signals' clock).
    pub t0_ns: u64,
    /// Grid times, seconds since `t0_ns`: `k / rate_hz`.
    pub t_s: Vec<f64>,
    /// One column per signal, in the order given, each `t_s.len()` long.
    pub columns: Vec<Vec<f64>>,
}

fn secs(ns: i128) -> f64 {
    ns as f64 * 1e-9
}

/// A gap longer than the largest allowed: where a log splits ([`split_at_gaps`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SignalGap {
    /// The signal with the gap.
    pub path: String,
    /// The last sample before the gap (ns, on the signals' clock).
    pub start_ns: u64,
    /// Its length (s).
    pub gap_s: f64,
}

/// The windows of the signals' overlap that no gap longer than `max_gap_s` crosses, in time
/// order (`[start_ns, end_ns]` each), and the gaps between them. A log with no such gap is one
/// window, the whole overlap; signals that do not overlap give none.
pub fn split_at_gaps(signals: &[RawSignal], max_gap_s: f64) -> (Vec<(u64, u64)>, Vec<SignalGap>) {
    let start = signals.iter().filter_map(|s| s.t_ns.first().copied()).max();
    let end = signals.iter().filter_map(|s| s.t_ns.last().copied()).min();
    let (Some(start), Some(end)) = (start, end) else {
        return (Vec::new(), Vec::new());
    };
    if end <= start {
        return (Vec::new(), Vec::new());
    }
    let max_gap_ns = max_gap_s * 1e9;
    let mut gaps: Vec<SignalGap> = Vec::new();
    let mut cuts: Vec<(u64, u64)> = Vec::new();
    for s in signals {
        for w in s.t_ns.windows(2) {
            let (a, b) = (w[0], w[1]);
            if b > start && a < end && (b - a) as f64 > max_gap_ns {
                cuts.push((a.max(start), b.min(end)));
                gaps.push(SignalGap {
                    path: s.path.to_string(),
                    start_ns: a,
                    gap_s: secs(i128::from(b - a)),
                });
            }
        }
    }
    cuts.sort_unstable();
    gaps.sort_by_key(|g| g.start_ns);
    let mut windows = Vec::new();
    let mut from = start;
    for (a, b) in cuts {
        if a > from {
            windows.push((from, a));
        }
        from = from.max(b);
    }
    if end > from {
        windows.push((from, end));
    }
    (windows, gaps)
}

/// For each grid point of `aligned`, whether it lies inside an interval between two
/// consecutive samples of `signal` longer than `factor` times the signal's median interval: a
/// dropout shorter than the largest gap allowed, over which the grid value is interpolated,
/// not measured.
pub fn dropouts_on_grid(signal: &RawSignal, aligned: &Aligned, factor: f64) -> Vec<bool> {
    let Some(rate) = native_rate_hz(signal) else {
        return vec![false; aligned.t_s.len()];
    };
    let limit_ns = factor * 1e9 / rate;
    aligned
        .t_s
        .iter()
        .map(|t| {
            let at = aligned.t0_ns as f64 + t * 1e9;
            let k = signal.t_ns.partition_point(|&s| (s as f64) <= at);
            match (
                k.checked_sub(1).and_then(|i| signal.t_ns.get(i)),
                signal.t_ns.get(k),
            ) {
                (Some(&a), Some(&b)) => (b - a) as f64 > limit_ns,
                _ => false,
            }
        })
        .collect()
}

/// A sample of a signal placed on a grid: it lies between grid points `k - 1` and `k` (at `k`
/// itself when `weight` is 1), and `weight` is its distance from grid point `k - 1` in grid
/// steps, so that linear interpolation between the grid points gives its value at
/// `weight * v_k + (1 - weight) * v_{k-1}`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridSample {
    /// The grid point at or after the sample.
    pub k: usize,
    /// Position between grid points `k - 1` (0) and `k` (1).
    pub weight: f64,
    /// The value recorded.
    pub value: f64,
}

/// The samples of `signal` inside the grid's span of `aligned`, each placed between the grid
/// points around it ([`GridSample`]), in time order. A sample at the grid's first point is at
/// `k = 0` with weight 1.
pub fn samples_on_grid(signal: &RawSignal, aligned: &Aligned) -> Vec<GridSample> {
    let n = aligned.t_s.len();
    if n == 0 || aligned.rate_hz.is_nan() || aligned.rate_hz <= 0.0 {
        return Vec::new();
    }
    let step_ns = 1e9 / aligned.rate_hz;
    let t0 = aligned.t0_ns as f64;
    let last = (n - 1) as f64;
    signal
        .t_ns
        .iter()
        .zip(&signal.value)
        .filter_map(|(&t, &value)| {
            let pos = (t as f64 - t0) / step_ns;
            // Within a nanosecond of a grid point counts as on it.
            let tol = 1.0 / step_ns;
            if !(pos >= -tol && pos <= last + tol && value.is_finite()) {
                return None;
            }
            let k = (pos - tol).ceil().max(0.0);
            let weight = if k == 0.0 {
                1.0
            } else {
                (pos - (k - 1.0)).clamp(0.0, 1.0)
            };
            Some(GridSample {
                k: k as usize,
                weight,
                value,
            })
        })
        .collect()
}

/// The samples of `signal` at times in `[start_ns, end_ns]`.
pub fn window(signal: &RawSignal, start_ns: u64, end_ns: u64) -> RawSignal {
    let (t_ns, value) = signal
        .t_ns
        .iter()
        .zip(&signal.value)
        .filter(|(t, _)| (start_ns..=end_ns).contains(*t))
        .map(|(t, v)| (*t, *v))
        .unzip();
    RawSignal {
        path: signal.path.clone(),
        t_ns,
        value,
    }
}

/// Resamples `signals` onto one uniform grid.
///
/// The grid covers the overlap of all signals' time spans (from the latest first sample to the
/// earliest last sample), starting at the overlap's start, with step `1 / rate_hz`. Values are
/// interpolated linearly. A gap between consecutive samples of a signal longer than `max_gap_s`
/// that intersects the overlap is [`IoError::Gap`] naming the path and the time (seconds since
/// `t0`). Each signal needs at least 2 samples and the grid at least 2 points.
pub fn resample(signals: &[RawSignal], opts: &ResampleOptions) -> Result<Aligned, IoError> {
    if !(opts.rate_hz.is_finite() && opts.rate_hz > 0.0) {
        return Err(IoError::BadOption {
            name: "rate_hz",
            value: opts.rate_hz,
            requirement: "the resampling rate must be a finite number of Hz > 0",
        });
    }
    if !(opts.max_gap_s.is_finite() && opts.max_gap_s > 0.0) {
        return Err(IoError::BadOption {
            name: "max_gap_s",
            value: opts.max_gap_s,
            requirement: "the largest allowed gap must be a finite number of seconds > 0",
        });
    }
    if signals.is_empty() {
        return Err(IoError::TooFewSamples {
            what: "resample input (no signals)".into(),
            n: 0,
            need: 1,
        });
    }
    for s in signals {
        let n = s.t_ns.len().min(s.value.len());
        if n < 2 {
            return Err(IoError::TooFewSamples {
                what: s.path.to_string(),
                n,
                need: 2,
            });
        }
        for w in s.t_ns.windows(2) {
            if w[1] < w[0] {
                return Err(IoError::TimeBackwards {
                    path: s.path.to_string(),
                    t_prev: w[0],
                    t: w[1],
                });
            }
        }
    }
    // Overlap [start, end] in ns.
    let mut start = 0u64;
    let mut end = u64::MAX;
    for s in signals {
        let n = s.t_ns.len().min(s.value.len());
        start = start.max(s.t_ns[0]);
        end = end.min(s.t_ns[n - 1]);
    }
    if end <= start {
        let spans = signals
            .iter()
            .map(|s| {
                let n = s.t_ns.len().min(s.value.len());
                format!(
                    "{}: {:.3}..{:.3} s",
                    s.path,
                    secs(i128::from(s.t_ns[0])),
                    secs(i128::from(s.t_ns[n - 1]))
                )
            })
            .collect::<Vec<_>>()
            .join("; ");
        return Err(IoError::NoOverlap { spans });
    }
    let t0 = start;
    let span_s = secs(i128::from(end - start));
    let max_gap_ns = opts.max_gap_s * 1e9;
    for s in signals {
        let n = s.t_ns.len().min(s.value.len());
        for k in 1..n {
            let (a, b) = (s.t_ns[k - 1], s.t_ns[k]);
            if b > start && a < end && (b - a) as f64 > max_gap_ns {
                return Err(IoError::Gap {
                    path: s.path.to_string(),
                    at_s: secs(i128::from(a) - i128::from(t0)),
                    gap_s: secs(i128::from(b - a)),
                    max_gap_s: opts.max_gap_s,
                });
            }
        }
    }
    let steps = (span_s * opts.rate_hz * (1.0 + 1e-12)).floor();
    if !(steps.is_finite() && steps < 1e9) {
        return Err(IoError::GridTooLarge {
            span_s,
            rate_hz: opts.rate_hz,
        });
    }
    let npts = steps as usize + 1;
    if npts < 2 {
        return Err(IoError::TooFewSamples {
            what: format!(
                "aligned grid ({span_s:.6} s of overlap at {} Hz)",
                opts.rate_hz
            ),
            n: npts,
            need: 2,
        });
    }
    let t_s: Vec<f64> = (0..npts)
        .map(|k| (k as f64 / opts.rate_hz).min(span_s))
        .collect();
    let columns = signals
        .iter()
        .map(|s| {
            let n = s.t_ns.len().min(s.value.len());
            // Sample times relative to t0, in seconds.
            let ts: Vec<f64> = s.t_ns[..n]
                .iter()
                .map(|&t| secs(i128::from(t) - i128::from(t0)))
                .collect();
            let mut j = 0usize;
            t_s.iter()
                .map(|&t| {
                    while j + 2 < n && ts[j + 1] <= t {
                        j += 1;
                    }
                    let (ta, tb) = (ts[j], ts[j + 1]);
                    let (va, vb) = (s.value[j], s.value[j + 1]);
                    if tb > ta {
                        let w = ((t - ta) / (tb - ta)).clamp(0.0, 1.0);
                        va + (vb - va) * w
                    } else {
                        vb
                    }
                })
                .collect()
        })
        .collect();
    Ok(Aligned {
        rate_hz: opts.rate_hz,
        t0_ns: t0,
        t_s,
        columns,
    })
}

/// Median sample interval of a signal as a rate (Hz); `None` with fewer than 2 samples or a
/// zero median interval.
pub fn native_rate_hz(signal: &RawSignal) -> Option<f64> {
    let mut d: Vec<u64> = signal
        .t_ns
        .windows(2)
        .map(|w| w[1].saturating_sub(w[0]))
        .collect();
    if d.is_empty() {
        return None;
    }
    d.sort_unstable();
    let m = d.len();
    let med = if m % 2 == 1 {
        d[m / 2] as f64
    } else {
        (d[m / 2 - 1] as f64 + d[m / 2] as f64) / 2.0
    };
    (med > 0.0).then(|| 1e9 / med)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize, rate_hz: f64, t0_ns: u64) -> Aligned {
        Aligned {
            rate_hz,
            t0_ns,
            t_s: (0..n).map(|k| k as f64 / rate_hz).collect(),
            columns: Vec::new(),
        }
    }

    #[test]
    fn samples_between_grid_points_get_their_interpolation_weights() {
        // Grid at 100 Hz from 1 s; samples at 30 Hz from 1 s.
        let t0 = 1_000_000_000u64;
        let a = grid(11, 100.0, t0);
        let signal = RawSignal {
            path: "/state.data".parse().unwrap(),
            t_ns: (0..5).map(|j| t0 + j * 33_333_333).collect(),
            value: vec![0.0, 1.0, 2.0, 3.0, 4.0],
        };
        let s = samples_on_grid(&signal, &a);
        // The fourth sample (t = 0.1 s) is at grid point 10; the fifth is past the grid.
        assert_eq!(s.len(), 4);
        assert_eq!((s[0].k, s[0].weight), (0, 1.0));
        assert_eq!(s[1].k, 4);
        assert!((s[1].weight - 0.3333333).abs() < 1e-6);
        assert_eq!(s[2].k, 7);
        assert!((s[2].weight - 0.6666666).abs() < 1e-6);
        // 99,999,999 ns: a nanosecond before grid point 10.
        assert_eq!(s[3].k, 10);
        assert!((s[3].weight - 1.0).abs() < 1e-6);
        assert_eq!(s[3].value, 3.0);
    }

    #[test]
    fn samples_outside_the_grid_or_not_finite_are_left_out() {
        let t0 = 1_000_000_000u64;
        let a = grid(5, 100.0, t0);
        let signal = RawSignal {
            path: "/x.data".parse().unwrap(),
            t_ns: vec![
                t0 - 5_000_000,
                t0 + 15_000_000,
                t0 + 25_000_000,
                t0 + 60_000_000,
            ],
            value: vec![1.0, 2.0, f64::NAN, 4.0],
        };
        let s = samples_on_grid(&signal, &a);
        assert_eq!(s.len(), 1);
        assert_eq!(s[0].k, 2);
        assert!((s[0].weight - 0.5).abs() < 1e-9);
        assert!(samples_on_grid(&signal, &grid(0, 100.0, t0)).is_empty());
    }
}
