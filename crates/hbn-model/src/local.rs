//! Owned training samples with the grid index the EKF+BLR step queries (see [`hbn_core::blr`]).

use crate::ModelError;
use crate::dataset::Table;
use crate::params::{ConfigError, Param, Problem};
use hbn_core::CoreError;
use hbn_core::blr::{BLR_MAX_DIM, CELL_BITS};
use hbn_core::{Neighbourhood, NeighbourhoodParts};
use serde::{Deserialize, Serialize};

/// Training samples of one GP sorted into grid cells, ready to borrow as a [`Neighbourhood`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LocalData {
    dim: usize,
    inputs: Vec<f64>,
    targets: Vec<f64>,
    cell_keys: Vec<u64>,
    cell_start: Vec<u32>,
    origin: Vec<f64>,
    half_window: Vec<f64>,
    input_var: Vec<f64>,
    /// The window as a fraction of each coordinate's range.
    window_fraction: f64,
    /// Most samples in one cell (bounds the query time).
    max_cell: usize,
}

impl LocalData {
    /// Indexes `table` with windows of `+-window_fraction` of each coordinate's range
    /// (`max - min`; for signals starting at 0 this is the thesis' "fraction of the maximum").
    pub fn build(table: &Table, window_fraction: f64) -> Result<Self, ModelError> {
        let d = table.dim;
        if d == 0 || d > BLR_MAX_DIM {
            return Err(
                CoreError::InvalidSpec("local regression supports 1..=BLR_MAX_DIM inputs").into(),
            );
        }
        if !(window_fraction.is_finite() && window_fraction > 0.0 && window_fraction <= 0.5) {
            return Err(ConfigError {
                param: Param::BlrWindow,
                problem: Problem::OutOfRange {
                    value: window_fraction,
                    min: 0.0,
                    max: 0.5,
                },
            }
            .into());
        }
        let n = table.len();
        if n == 0 {
            return Err(CoreError::Empty.into());
        }
        if n > u32::MAX as usize {
            return Err(
                CoreError::InvalidSpec("local regression indexes at most 2^32 samples").into(),
            );
        }
        let col = |j: usize| table.inputs.iter().skip(j).step_by(d).copied();
        let mut origin = Vec::with_capacity(d);
        let mut half_window = Vec::with_capacity(d);
        let mut input_var = Vec::with_capacity(d);
        for j in 0..d {
            let (lo, hi) = col(j).fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
                (l.min(v), h.max(v))
            });
            let mean = col(j).sum::<f64>() / n as f64;
            let var = col(j).map(|v| (v - mean) * (v - mean)).sum::<f64>() / n as f64;
            let range = (hi - lo).max(1e-12 * hi.abs().max(1.0));
            // Cells are 2 * half_window wide; keep the grid within CELL_BITS per axis.
            let hw =
                (window_fraction * range).max(range / (2.0 * ((1u64 << CELL_BITS) - 2) as f64));
            origin.push(lo);
            half_window.push(hw);
            input_var.push(var.max(1e-12 * range * range).max(f64::MIN_POSITIVE));
        }
        let mut order: Vec<(u64, usize)> = (0..n)
            .map(|i| {
                let coords: Vec<u64> = (0..d)
                    .map(|j| {
                        Neighbourhood::cell_coord(
                            origin[j],
                            half_window[j],
                            table.inputs[i * d + j],
                        )
                    })
                    .collect();
                (Neighbourhood::key(&coords), i)
            })
            .collect();
        order.sort_unstable();
        let mut cell_keys = Vec::new();
        let mut cell_start = Vec::new();
        for (pos, (k, _)) in order.iter().enumerate() {
            if cell_keys.last() != Some(k) {
                cell_keys.push(*k);
                cell_start.push(pos as u32);
            }
        }
        cell_start.push(n as u32);
        let max_cell = cell_start
            .windows(2)
            .map(|w| (w[1] - w[0]) as usize)
            .max()
            .unwrap_or(0);
        Ok(Self {
            dim: d,
            inputs: order
                .iter()
                .flat_map(|&(_, i)| table.inputs[i * d..i * d + d].iter().copied())
                .collect(),
            targets: order.iter().map(|&(_, i)| table.targets[i]).collect(),
            cell_keys,
            cell_start,
            origin,
            half_window,
            input_var,
            window_fraction,
            max_cell,
        })
    }

    /// The borrowed, validated view the step uses.
    pub fn view(&self) -> Result<Neighbourhood<'_>, hbn_core::CoreError> {
        Neighbourhood::new(
            self.dim,
            NeighbourhoodParts {
                inputs: &self.inputs,
                targets: &self.targets,
                cell_keys: &self.cell_keys,
                cell_start: &self.cell_start,
                origin: &self.origin,
                half_window: &self.half_window,
                input_var: &self.input_var,
            },
        )
    }

    /// Samples indexed.
    pub fn len(&self) -> usize {
        self.targets.len()
    }
    /// Whether no samples are indexed.
    pub fn is_empty(&self) -> bool {
        self.targets.is_empty()
    }
    /// Non-empty grid cells.
    pub fn cells(&self) -> usize {
        self.cell_keys.len()
    }
    /// Largest cell occupancy.
    pub fn max_cell(&self) -> usize {
        self.max_cell
    }
    /// Window as a fraction of each coordinate's range.
    pub fn window_fraction(&self) -> f64 {
        self.window_fraction
    }
}
