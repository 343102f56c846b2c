//! Each GP's kernel chosen by its evidence ([`HbnParams::kernel_evidence`]).
//!
//! Before model selection, each GP's exact GP (on the `max_points` subset, as the exact
//! candidate fits it) is fitted with every listed kernel, and the kernel with the highest log
//! marginal likelihood becomes that GP's kernel for every candidate. The evidence needs no
//! held-out data, so it also chooses with `validation = 0`, and it costs one exact fit per GP
//! and kernel (run side by side), not a filter tuning per kernel as held-out selection does.
//! The fits of the chosen kernels are kept ([`Prefit`]): the exact candidate reuses them
//! instead of fitting the same GPs again.

use hbn_gp::{GaussianProcess, GpParams};
use serde::{Deserialize, Serialize};

use crate::model::{GpRole, HysteresisModel, StartSummary};
use crate::params::{CheckedHbnParams, HbnParams, KernelChoice};
use crate::{ModelError, Sequence};

/// One GP's evidence under one kernel: a row of the table [`crate::TrainingSummary`] keeps.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct KernelEvidence {
    /// Which GP.
    pub gp: GpRole,
    /// The kernel.
    pub kernel: KernelChoice,
    /// Log marginal likelihood of the exact GP with this kernel (`None`: it could not be
    /// fitted).
    pub lml: Option<f64>,
    /// Whether this kernel was chosen for the GP.
    pub chosen: bool,
}

/// A GP fitted while choosing kernels, with what makes another fit the same problem: its
/// role, its GP parameters and the parameters that shape its data.
#[derive(Clone, Debug)]
pub(crate) struct Prefit {
    role: GpRole,
    gp_params: GpParams,
    data_key: DataKey,
    pub(crate) gp: GaussianProcess,
    pub(crate) starts: Vec<StartSummary>,
}

/// The training parameters besides the GP's own that decide its table (on the same runs).
#[derive(Clone, Debug, PartialEq)]
struct DataKey {
    memory: Vec<f64>,
    lags: Vec<f64>,
    rate_hz: f64,
    sensor_inputs: crate::SensorInputs,
}

impl DataKey {
    fn of(p: &HbnParams) -> Self {
        Self {
            memory: p.memory.clone(),
            lags: p.lags.clone(),
            rate_hz: p.rate_hz,
            sensor_inputs: p.sensor_inputs,
        }
    }
}

impl Prefit {
    /// This fit, if it is the one `role` would fit with `gp_params` under `params` (on the
    /// runs it was fitted on).
    pub(crate) fn matching<'a>(
        prefit: &'a [Prefit],
        role: GpRole,
        gp_params: &GpParams,
        params: &HbnParams,
    ) -> Option<&'a Prefit> {
        let key = DataKey::of(params);
        prefit
            .iter()
            .find(|p| p.role == role && &p.gp_params == gp_params && p.data_key == key)
    }
}

/// One evidence fit: the GP parameters it used, and the GP with its optimiser starts (`None`:
/// it could not be fitted).
type Attempt = (GpParams, Option<(GaussianProcess, Vec<StartSummary>)>);

/// The position of the highest log marginal likelihood among `lmls` (`None`: a fit that
/// failed), the first of equals, so that ties keep the order listed; `None` when none fitted.
pub(crate) fn highest(lmls: impl IntoIterator<Item = Option<f64>>) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for (i, l) in lmls.into_iter().enumerate() {
        if let Some(l) = l
            && best.is_none_or(|(_, b)| l > b)
        {
            best = Some((i, l));
        }
    }
    best.map(|(i, _)| i)
}

/// What [`choose`] returns: the parameters with the chosen kernels (and no evidence list), the
/// table, and the chosen fits.
pub(crate) struct Chosen {
    pub(crate) params: CheckedHbnParams,
    pub(crate) rows: Vec<KernelEvidence>,
    pub(crate) prefit: Vec<Prefit>,
}

/// Chooses each GP's kernel by evidence when `params` asks for it
/// ([`HbnParams::chooses_kernels_by_evidence`]); otherwise returns `params` as they are. The
/// fits run side by side on the machine's cores; each is deterministic, so the choice does
/// not depend on the thread count. A GP none of whose kernels could be fitted keeps the kernel
/// set in `params` (its candidates then report why).
pub(crate) fn choose(
    trajectories: &[Sequence<'_>],
    params: &CheckedHbnParams,
) -> Result<Chosen, ModelError> {
    if !params.chooses_kernels_by_evidence() {
        return Ok(Chosen {
            params: params.clone(),
            rows: Vec::new(),
            prefit: Vec::new(),
        });
    }
    let memory = HysteresisModel::memory_for(trajectories, params)?;
    let data = crate::build_dataset(trajectories, &memory)?;
    let kernels = params.kernel_evidence.clone();
    let jobs: Vec<(GpRole, KernelChoice)> = [GpRole::Transition, GpRole::Sensor]
        .into_iter()
        .flat_map(|role| kernels.iter().map(move |&k| (role, k)))
        .collect();
    let fit = |&(role, kernel): &(GpRole, KernelChoice)| {
        let p = params.with_kernel(role, kernel);
        let (spec, table) = HysteresisModel::gp_problem(&p, &memory.input, &data, role);
        let mut gp_params = p.gp_params(spec, role);
        gp_params.sparse = None;
        let fitted = HysteresisModel::fit_gp(role, &gp_params, &table, &mut |_, _| {}).ok();
        (gp_params, fitted)
    };
    let mut fitted: Vec<Attempt> = crate::parallel::side_by_side(&jobs, fit);
    let mut rows = Vec::with_capacity(jobs.len());
    let mut prefit = Vec::new();
    let mut chosen = params.clone();
    for role in [GpRole::Transition, GpRole::Sensor] {
        let of_role: Vec<usize> = (0..jobs.len()).filter(|&i| jobs[i].0 == role).collect();
        let lml = |i: usize| {
            fitted[i]
                .1
                .as_ref()
                .map(|(gp, _)| gp.log_marginal_likelihood())
                .filter(|l| l.is_finite())
        };
        let best = highest(of_role.iter().map(|&i| lml(i))).map(|k| of_role[k]);
        for &i in &of_role {
            rows.push(KernelEvidence {
                gp: role,
                kernel: jobs[i].1,
                lml: lml(i),
                chosen: Some(i) == best,
            });
        }
        if let Some(b) = best {
            chosen = chosen.with_kernel(role, jobs[b].1);
            let (gp_params, fit) = &mut fitted[b];
            if let Some((gp, starts)) = fit.take() {
                prefit.push(Prefit {
                    role,
                    gp_params: gp_params.clone(),
                    data_key: DataKey::of(params),
                    gp,
                    starts,
                });
            }
        }
    }
    Ok(Chosen {
        params: chosen.without_kernel_evidence(),
        rows,
        prefit,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::{DEFAULT_EVIDENCE_KERNELS, Param, ParamValue};
    use hbn_sim::{SimConfig, SystemKind, simulate_random};

    /// The highest evidence wins, the first of equals, failed fits never.
    #[test]
    fn the_highest_evidence_is_the_first_of_equals() {
        assert_eq!(highest([Some(1.0), Some(3.0), Some(2.0)]), Some(1));
        assert_eq!(highest([Some(3.0), None, Some(3.0)]), Some(0));
        assert_eq!(highest([None, Some(-5.0)]), Some(1));
        assert_eq!(highest([None, None]), None);
        assert_eq!(highest(std::iter::empty()), None);
    }

    fn small() -> HbnParams {
        HbnParams {
            max_points: 80,
            n_starts: 1,
            max_iters: 40,
            validation: 0.0,
            ..HbnParams::default()
        }
    }

    /// Each GP gets the kernel with the highest evidence, the table says so, the model holds
    /// the chosen kernels without the list, and it is the model that those kernels train
    /// when set (the chosen exact fits are reused, not refitted differently).
    #[test]
    fn each_gp_takes_the_kernel_with_the_highest_evidence() {
        let log = simulate_random(&SimConfig::new(SystemKind::BoucWen), 400).unwrap();
        let runs = [Sequence::new(&log.u, &log.x, &log.y)];
        let params = small();
        assert_eq!(params.kernel_evidence, DEFAULT_EVIDENCE_KERNELS.to_vec());
        let m = HysteresisModel::fit(&runs, &params).unwrap();
        let rows = &m.summary().kernel_evidence;
        assert_eq!(rows.len(), 4, "{rows:?}");
        for role in [GpRole::Transition, GpRole::Sensor] {
            let of: Vec<_> = rows.iter().filter(|r| r.gp == role).collect();
            let best = of
                .iter()
                .max_by(|a, b| a.lml.unwrap().total_cmp(&b.lml.unwrap()))
                .unwrap();
            assert!(best.chosen && of.iter().filter(|r| r.chosen).count() == 1);
            assert_eq!(m.params().kernel(role), best.kernel);
            // The model's GP is the fit the evidence was read from.
            assert_eq!(
                m.gp(role).log_marginal_likelihood().to_bits(),
                best.lml.unwrap().to_bits()
            );
        }
        assert!(m.params().kernel_evidence.is_empty());
        let mut set = small();
        set.transition_kernel = m.params().transition_kernel;
        set.sensor_kernel = m.params().sensor_kernel;
        set.kernel_evidence.clear();
        let again = HysteresisModel::fit(&runs, &set).unwrap();
        assert!(again.summary().kernel_evidence.is_empty());
        for role in [GpRole::Transition, GpRole::Sensor] {
            assert_eq!(again.gp(role), m.gp(role));
        }
        let est = |m: &HysteresisModel| m.estimate(&log.u, &log.y, hbn_core::Mode::Ekf).unwrap().x;
        assert_eq!(est(&again), est(&m));
    }

    /// The chosen fits are the primary exact candidate's GPs (same role, GP parameters and
    /// data), so it reuses them; a sparse candidate's do not match.
    #[test]
    fn the_chosen_fits_match_the_exact_candidate() {
        let log = simulate_random(&SimConfig::new(SystemKind::Duhem), 300).unwrap();
        let runs = [Sequence::new(&log.u, &log.x, &log.y)];
        let params = small().check().unwrap();
        let chosen = choose(&runs, &params).unwrap();
        assert_eq!(chosen.prefit.len(), 2);
        let memory = HysteresisModel::memory_for(&runs, &chosen.params).unwrap();
        let data = crate::build_dataset(&runs, &memory).unwrap();
        for (candidate, reused) in [(chosen.params.candidate(), true), {
            let mut sparse = chosen.params.candidate();
            sparse.n_inducing = Some(16);
            (sparse, false)
        }] {
            let p = chosen.params.for_candidate(&candidate);
            for role in [GpRole::Transition, GpRole::Sensor] {
                let (spec, _) = HysteresisModel::gp_problem(&p, &memory.input, &data, role);
                let found = Prefit::matching(&chosen.prefit, role, &p.gp_params(spec, role), &p);
                assert_eq!(found.is_some(), reused, "{candidate} {role}");
                if let Some(f) = found {
                    assert_eq!(f.role, role);
                }
            }
        }
    }

    /// Naming a kernel turns the choice off; while it is on, the kernels have no value to
    /// read (front ends list them as chosen at training).
    #[test]
    fn a_named_kernel_turns_the_choice_off() {
        let p = HbnParams::default();
        assert!(p.chooses_kernels_by_evidence());
        assert_eq!(p.get(Param::TransitionKernel), None);
        for param in [Param::Kernel, Param::TransitionKernel, Param::SensorKernel] {
            let mut q = HbnParams::default();
            q.set(param, ParamValue::Text("matern52".into())).unwrap();
            assert!(!q.chooses_kernels_by_evidence(), "{param}");
            assert!(q.get(Param::TransitionKernel).is_some());
        }
    }
}
