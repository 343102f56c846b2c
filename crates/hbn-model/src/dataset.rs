//! Training sets of the two GPs (thesis Eq. 16), built from aligned trajectories.
//!
//! From each trajectory of samples `(u_k, x_k, y_k)`, `k = 0..N`:
//! - transition set `D_D`: inputs `[x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2}]`, target `x_k`, `k >= 2`;
//! - sensor set `D_S`: inputs `[x_{k-1}, y_{k-1}, x_k]`, target `y_k`, `k >= 1`... taken from
//!   `k >= 2` too, so both sets describe the same samples. Each row goes on with the plays of
//!   the state after `x_k` ([`Memory::state`], `q^1_k, q^2_k`, started at the trajectory's
//!   `x_0`; `x_k` itself where there are none), which a sensor with memory reads with `x_k`
//!   ([`crate::SensorInputs::Memory`]).
//!
//! With play operators ([`hbn_core::play`]) the transition's inputs go on with the plays after
//! `u_{k-1}`, each play started at the trajectory's `u_0`.
//!
//! Rows never straddle two trajectories. The direction signs of the advantage kernel
//! (Eq. 19) are functions of these inputs: `sgn(u_{k-1} - u_{k-2})` for `D_D` (inputs 2, 3) and
//! `sgn(x_k - x_{k-1})` for `D_S` (inputs 2, 0); see [`TRANSITION_DIRECTION`] and
//! [`SENSOR_DIRECTION`].

use crate::error::{DataError, Signal};
use hbn_core::{MAX_PLAYS, MAX_SENSOR_MEMORY, Plays, transition_input};

/// Inputs of the transition GP without play operators (with them: one more per play).
pub const TRANSITION_DIM: usize = 4;
/// Inputs of the thesis' sensor GP (the first three columns of the rows [`build_dataset`]
/// writes; each sensor reads its [`crate::SensorInputs::columns`]).
pub const SENSOR_DIM: usize = hbn_core::SENSOR_DIM;
/// Columns of the sensor rows [`build_dataset`] writes: `[x_{k-1}, y_{k-1}, x_k]` and the
/// plays of the state after `x_k`.
pub const SENSOR_ROW: usize = SENSOR_DIM + MAX_SENSOR_MEMORY;
/// Direction pair of the transition: `sgn(u_{k-1} - u_{k-2})`.
pub const TRANSITION_DIRECTION: [usize; 2] = [2, 3];
/// Direction pair of the sensor: `sgn(x_k - x_{k-1})`.
pub const SENSOR_DIRECTION: [usize; 2] = [2, 0];

/// Fewest samples in a training trajectory (the transition reads two past samples).
pub const MIN_SAMPLES: usize = 3;

/// One trajectory of aligned samples at the model's rate (borrowed).
#[derive(Clone, Copy, Debug)]
pub struct Sequence<'a> {
    /// Input `u`.
    pub u: &'a [f64],
    /// State `x`.
    pub x: &'a [f64],
    /// Sensor output `y`.
    pub y: &'a [f64],
    /// Where `x` was measured, one flag per sample; `None` when it was measured at every
    /// sample. Elsewhere `x` holds a stand-in (interpolated between the measurements, or a
    /// smoothed estimate): the GPs train on it, but held-out scores
    /// ([`crate::tuning`]) compare the filter with measured samples only.
    pub observed: Option<&'a [bool]>,
}

impl<'a> Sequence<'a> {
    /// The three signals of one trajectory, the state measured at every sample.
    pub fn new(u: &'a [f64], x: &'a [f64], y: &'a [f64]) -> Self {
        Self {
            u,
            x,
            y,
            observed: None,
        }
    }

    /// The same trajectory with the state measured only where `observed` is true
    /// ([`Sequence::observed`]).
    pub fn with_observed(self, observed: &'a [bool]) -> Self {
        Self {
            observed: Some(observed),
            ..self
        }
    }

    /// Samples `a..b` of every signal (and of the mask). The range must lie inside the
    /// sequence: callers slice within [`Sequence::validate`]d lengths.
    pub(crate) fn slice(&self, a: usize, b: usize) -> Self {
        let cut = |s: &'a [f64]| s.get(a..b).unwrap_or(&[]);
        Self {
            u: cut(self.u),
            x: cut(self.x),
            y: cut(self.y),
            observed: self.observed.map(|o| o.get(a..b).unwrap_or(&[])),
        }
    }

    /// Whether `x_k` was measured.
    pub fn is_observed(&self, k: usize) -> bool {
        self.observed
            .is_none_or(|o| o.get(k).copied().unwrap_or(false))
    }

    /// Checks lengths (equal, at least [`MIN_SAMPLES`]) and values (finite). `index` names the
    /// trajectory.
    pub fn validate(&self, index: usize) -> Result<(), DataError> {
        let n = self.u.len();
        if self.x.len() != n || self.y.len() != n {
            return Err(DataError::LengthMismatch {
                trajectory: index,
                u: n,
                x: self.x.len(),
                y: self.y.len(),
            });
        }
        if let Some(o) = self.observed
            && o.len() != n
        {
            return Err(DataError::ObservedLength {
                trajectory: index,
                observed: o.len(),
                samples: n,
            });
        }
        if n < MIN_SAMPLES {
            return Err(DataError::TooShort {
                trajectory: index,
                len: n,
                min: MIN_SAMPLES,
            });
        }
        for (signal, s) in [
            (Signal::Input, self.u),
            (Signal::State, self.x),
            (Signal::Output, self.y),
        ] {
            if let Some(k) = s.iter().position(|v| !v.is_finite()) {
                return Err(DataError::NonFinite {
                    trajectory: index,
                    signal,
                    index: k,
                    value: s[k],
                });
            }
        }
        Ok(())
    }
}

/// Row-major inputs and targets of one GP.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Table {
    /// Input dimension.
    pub dim: usize,
    /// `rows x dim` inputs.
    pub inputs: Vec<f64>,
    /// `rows` targets.
    pub targets: Vec<f64>,
}

impl Table {
    /// The table of the first `n` input columns (all of them when `n >= dim`).
    pub fn first_columns(&self, n: usize) -> Table {
        if n >= self.dim {
            return self.clone();
        }
        Table {
            dim: n,
            inputs: self
                .inputs
                .chunks_exact(self.dim.max(1))
                .flat_map(|row| row.iter().take(n).copied())
                .collect(),
            targets: self.targets.clone(),
        }
    }

    /// The table of the input columns `columns`, in that order (each below `dim`; others are
    /// skipped): the sensor table of a sensor that reads fewer inputs
    /// ([`crate::SensorInputs::columns`]).
    pub fn columns(&self, columns: &[usize]) -> Table {
        let keep: Vec<usize> = columns.iter().copied().filter(|&j| j < self.dim).collect();
        if keep.len() == self.dim && keep.iter().enumerate().all(|(i, &j)| i == j) {
            return self.clone();
        }
        Table {
            dim: keep.len(),
            inputs: self
                .inputs
                .chunks_exact(self.dim.max(1))
                .flat_map(|row| keep.iter().map(move |&j| row[j]))
                .collect(),
            targets: self.targets.clone(),
        }
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.targets.len()
    }
    /// Whether there are no rows.
    pub fn is_empty(&self) -> bool {
        self.targets.is_empty()
    }
}

/// Both training sets.
#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    /// `D_D`.
    pub transition: Table,
    /// `D_S`.
    pub sensor: Table,
}

/// The memory operators whose values extend the rows: the input's plays and lags (the
/// transition's) and the state's plays (the sensor's, [`crate::SensorInputs::Memory`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Memory {
    /// Plays and lags of `u` ([`hbn_core::HbnView::plays`]).
    pub input: Plays,
    /// Plays of `x` ([`hbn_core::HbnView::sensor_memory`]).
    pub state: Plays,
}

impl Memory {
    /// The input's operators alone (no plays of the state).
    pub fn of_input(input: Plays) -> Self {
        Self {
            input,
            state: Plays::NONE,
        }
    }
}

/// Builds `D_D` (with the values of `memory.input` after `u_{k-1}` as extra inputs) and `D_S`
/// (with those of `memory.state` after `x_k`) from trajectories, never crossing a boundary.
pub fn build_dataset(trajectories: &[Sequence<'_>], memory: &Memory) -> Result<Dataset, DataError> {
    if trajectories.is_empty() {
        return Err(DataError::NoTrajectories);
    }
    let plays = &memory.input;
    let mut tr = Table {
        dim: TRANSITION_DIM + plays.len(),
        ..Table::default()
    };
    let mut se = Table {
        dim: SENSOR_ROW,
        ..Table::default()
    };
    for (i, t) in trajectories.iter().enumerate() {
        t.validate(i)?;
        // `after[k]`: the plays after `u_0..=u_k`, as the filter carries them.
        let mut after = vec![[0.0; MAX_PLAYS]; t.u.len()];
        plays.run(t.u, &mut after);
        // `held[k]`: the plays of the state after `x_0..=x_k`.
        let mut held = vec![[0.0; MAX_PLAYS]; t.x.len()];
        memory.state.run(t.x, &mut held);
        for k in 2..t.u.len() {
            let input = transition_input(
                t.x[k - 1],
                t.x[k - 2],
                t.u[k - 1],
                t.u[k - 2],
                &after[k - 1],
            );
            tr.inputs.extend(input.iter().take(tr.dim));
            tr.targets.push(t.x[k]);
            se.inputs.extend([t.x[k - 1], t.y[k - 1], t.x[k]]);
            se.inputs
                .extend(held[k].iter().take(MAX_SENSOR_MEMORY).copied());
            se.targets.push(t.y[k]);
        }
    }
    Ok(Dataset {
        transition: tr,
        sensor: se,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_follow_eq16_and_respect_boundaries() {
        let u1 = [0.0, 1.0, 2.0, 3.0];
        let x1 = [10.0, 11.0, 12.0, 13.0];
        let y1 = [20.0, 21.0, 22.0, 23.0];
        let u2 = [5.0, 6.0, 7.0];
        let x2 = [15.0, 16.0, 17.0];
        let y2 = [25.0, 26.0, 27.0];
        let d = build_dataset(
            &[Sequence::new(&u1, &x1, &y1), Sequence::new(&u2, &x2, &y2)],
            &Memory::default(),
        )
        .unwrap();
        assert_eq!(d.transition.len(), 3);
        assert_eq!(&d.transition.inputs[..4], &[11.0, 10.0, 1.0, 0.0]);
        assert_eq!(d.transition.targets, vec![12.0, 13.0, 17.0]);
        // The third row comes from trajectory 2 only.
        assert_eq!(&d.transition.inputs[8..], &[16.0, 15.0, 6.0, 5.0]);
        assert_eq!(&d.sensor.inputs[..3], &[11.0, 21.0, 12.0]);
        assert_eq!(d.sensor.targets, vec![22.0, 23.0, 27.0]);
    }

    #[test]
    fn plays_extend_the_transition_rows() {
        // Radius 1: the play starts at u_0 = 0, holds to u = 1, then trails u by 1.
        let u = [0.0, 1.0, 3.0, 2.5, 0.0];
        let x = [0.0; 5];
        let plays = Plays::new(&[1.0]).unwrap();
        let d = build_dataset(&[Sequence::new(&u, &x, &x)], &Memory::of_input(plays)).unwrap();
        assert_eq!(d.transition.dim, 5);
        // Row for x_k holds the play after u_{k-1}: k = 2, 3, 4 -> after 1.0, 3.0, 2.5.
        let plays_col: Vec<f64> = d.transition.inputs.chunks(5).map(|r| r[4]).collect();
        assert_eq!(plays_col, vec![0.0, 2.0, 2.0]);
        assert_eq!(&d.transition.inputs[..4], &[0.0, 0.0, 1.0, 0.0]);
        let state_sensor = d.sensor.columns(&[0, 2]);
        assert_eq!(state_sensor.dim, 2);
        assert_eq!(state_sensor.targets, d.sensor.targets);
        let pairs: Vec<&[f64]> = state_sensor.inputs.chunks(2).collect();
        let thesis: Vec<&[f64]> = d.sensor.inputs.chunks(SENSOR_ROW).collect();
        for (p, t) in pairs.iter().zip(&thesis) {
            assert_eq!(*p, &[t[0], t[2]][..]);
        }
        let first4 = d.transition.first_columns(4);
        assert_eq!(first4.dim, 4);
        assert_eq!(first4.inputs.len(), 12);
        assert_eq!(&first4.inputs[4..8], &[0.0, 0.0, 3.0, 1.0]);
    }

    #[test]
    fn plays_of_the_state_extend_the_sensor_rows() {
        // Radius 1: the play starts at x_0 = 0, holds to x = 1, then trails x by 1.
        let x = [0.0, 1.0, 3.0, 2.5, 0.0];
        let memory = Memory {
            input: Plays::NONE,
            state: Plays::new(&[1.0]).unwrap(),
        };
        let d = build_dataset(&[Sequence::new(&x, &x, &x)], &memory).unwrap();
        assert_eq!(d.sensor.dim, SENSOR_ROW);
        // The sensor with memory reads `[x_k, q^1_k, q^2_k]`, the plays after `x_k`; the
        // second slot, unused, follows `x_k`.
        let rows = d.sensor.columns(crate::SensorInputs::Memory.columns());
        assert_eq!(rows.dim, crate::SensorInputs::Memory.dim());
        assert_eq!(
            rows.inputs,
            vec![3.0, 2.0, 3.0, 2.5, 2.0, 2.5, 0.0, 1.0, 0.0]
        );
        // The thesis' columns are as without the plays.
        let plain = build_dataset(&[Sequence::new(&x, &x, &x)], &Memory::default()).unwrap();
        assert_eq!(
            d.sensor.columns(&[0, 1, 2]),
            plain.sensor.columns(&[0, 1, 2])
        );
    }

    #[test]
    fn bad_trajectories_are_rejected() {
        assert!(build_dataset(&[], &Memory::default()).is_err());
        let ok = [0.0, 1.0, 2.0];
        assert!(build_dataset(&[Sequence::new(&ok, &ok[..2], &ok)], &Memory::default()).is_err());
        assert!(
            build_dataset(
                &[Sequence::new(&ok[..2], &ok[..2], &ok[..2])],
                &Memory::default()
            )
            .is_err()
        );
        let nan = [0.0, f64::NAN, 2.0];
        let e = build_dataset(&[Sequence::new(&ok, &nan, &ok)], &Memory::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("x[1]"), "{e}");
    }
}
