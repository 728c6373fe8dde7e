//! A-priori tolerances of the parameters: how far a fit may move each group before the data
//! have spoken, as the prior of a maximum a posteriori fit.
//!
//! **Why a prior.** Real data are noisier than a design study assumes, miss effects the model
//! does not declare, and come from constrained pose grids. A least-squares fit then pours the
//! misfit into the directions the data barely see: on a real inclinometer session the plain
//! fit moved base joints by 100 mm along directions whose Cramér-Rao standard deviation at the
//! real noise was 88 mm. No machine is built that wrong, and a metrologist knows it before
//! measuring: every parameter has a tolerance (a drawing, an assembly procedure, a spool
//! diameter). The fit here minimises
//!
//! `sum_i (r_i / sigma)^2 + sum_k (p_k / t_k)^2`
//!
//! (`r_i` the weighted residuals, `sigma` their noise, `p_k` a parameter's departure from
//! nominal, `t_k` its tolerance): the posterior mode under a Gaussian prior of standard
//! deviation `t_k` centred on the nominal (Tarantola, *Inverse Problem Theory*, 2005, ch. 3;
//! the "a-priori uncertainty" of GUM Supplement 1 and of the bundle adjustments of
//! photogrammetry). A direction the data determine much better than its tolerance is
//! untouched (the prior adds `(sigma/t)^2` to a curvature of `s^2`); one whose Cramér-Rao
//! standard deviation exceeds its tolerance is held near nominal and *named* as held
//! ([`HeldDirection`]). The prior is used rather than a hard truncation of the singular values
//! because it is smooth (no direction flips in or out with a tiny change of the data),
//! because its cut is set in physical units per group rather than as a relative singular
//! value, and because the posterior covariance says per parameter how much of it the data
//! determined ([`PriorSummary::data_share`]).
//!
//! **The limit.** A Gaussian prior is not a wall: a misfit the model does not declare (a leg
//! scale, compliance) pulls strongly on the directions it resembles and can carry a joint past
//! its tolerance. The tolerance is what the machine's drawing allows, so a parameter the data
//! pull beyond [`Tolerances::limit`] tolerances (default 1) *without
//! determining it* (its data share below [`MIN_DATA_SHARE`]) is held there, with the sign it
//! was pulled to, and the fit repeated without it (an active set: the box constraint of a
//! bounded least-squares fit); it is reported as held, not measured
//! ([`Calibration::held_at_limit`](crate::Calibration::held_at_limit)), and the report names
//! it. A parameter the data determine is measured wherever it ends: its tolerance was wrong,
//! and the report says it ended beyond it.
//!
//! **Defaults** scale with the machine: `size` is the mean link length at the home pose
//! ([`machine_size_mm`]). Installation errors `4e-3 size` (2 mm for a 500 mm machine: an
//! assembled joint is off by a millimetre or two, not by centimetres), link and sensor offsets
//! `5e-2 size` (a leg's zero is often known only to tens of millimetres), link and sensor
//! scales 5 % (50,000 ppm: a spool or screw lead is known to a few per cent), link
//! non-linearity, screw periodic error and socket errors as the joints, joint clearance and
//! backlash `2e-3 size`, thermal drift 100 ppm per degree, compliance the deflection of
//! `1e-2 size` under the declared load's weight shared by the links (see
//! [`default_tolerance`]). The instruments' nuisance blocks (tracker and point frames, base
//! tilts, inclinometer mounts, target positions, one's own instruments), pose map terms and
//! user effects are free (no prior): they describe a set-up, not the machine, or have no
//! physical scale. Every default is overridden per group in the description's
//! `[calibration.tolerances]` or on the command line (`--tolerance GROUP=VALUE`).
use std::collections::BTreeMap;

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::model::Block;
use crate::{CalibError, Effect, MeasurementModel};

/// The name of the installation errors' group (the 36 joint errors of a 6-link machine).
pub const INSTALLATION_ERRORS: &str = "installation_errors";

/// Tolerances per group of parameters, in each group's own unit (um for the installation
/// errors and length effects, ppm for scales, um/kN for compliance, ...).
///
/// ```
/// use cpm_calib::fit::prior::{prior_std, Tolerances};
/// use cpm_calib::{Effect, MeasurementModel};
/// let mut model = MeasurementModel::new(cpm_geometry::JointTable::paper_cubic());
/// model.effects = vec![Effect::LinkScale];
/// let mut t = Tolerances::default();
/// t.set("link_scale", 20_000.0).unwrap(); // 2 %
/// t.hold.push("installation_errors".into());
/// let std = prior_std(&model, &t).unwrap();
/// assert_eq!(std[0], 0.0); // held at nominal
/// assert_eq!(std[36], 20_000.0); // ppm
/// ```
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Tolerances {
    /// A-priori standard deviation per group name ([`INSTALLATION_ERRORS`], an effect's name,
    /// or one's own instrument's name), in the group's unit; `f64::INFINITY` frees the group.
    /// Groups not named take [`default_tolerance`].
    pub by_group: BTreeMap<String, f64>,
    /// Groups held at their start (the nominal, or a known value), by name.
    pub hold: Vec<String>,
    /// No prior at all: every group free (the plain least-squares fit of cpm 0.1). Default
    /// false.
    pub off: bool,
    /// How many tolerances a fitted parameter may reach when the data do not determine it:
    /// one the data pull further is held at this many tolerances (with its sign) and the fit
    /// repeated
    /// ([`identify`](crate::identify())), so that a misfit the model lacks cannot carry the
    /// machine beyond what its drawing allows; the report names what was held.
    /// `f64::INFINITY`: no limit (the Gaussian prior alone). Default [`DEFAULT_LIMIT`] (1).
    #[serde(default = "default_limit")]
    pub limit: f64,
    /// Groups named here that the model may lack: a description's own (it declares the
    /// machine's tolerances for every fit it takes part in), and in `cpm refine` the
    /// candidate effects. Any other group the model lacks is refused by [`prior_std`].
    /// Default empty.
    #[serde(skip)]
    pub optional: std::collections::BTreeSet<String>,
}

/// The default [`Tolerances::limit`]: an undetermined parameter may reach its tolerance, not
/// go beyond (a value the data do not determine is not written past what the drawing allows).
/// Measured on `tests/real_data.rs` (docs/estimation.md) against a limit of 3: the real
/// figures are the same (motion capture, the tilt session whole and leaving positions out) or
/// better (`refine` from offsets and scales on nine tilt positions predicts the other eight to
/// 0.0875 deg instead of 0.0939 deg), and the simulated tilt case's joints stay within their
/// tolerance (2.561 mm instead of 3.174 mm). The limit applies to undetermined parameters only:
/// one on every parameter raised the real motion-capture session's held-out leg RMS from 0.674
/// mm to 0.896 mm.
pub const DEFAULT_LIMIT: f64 = 1.0;

fn default_limit() -> f64 {
    DEFAULT_LIMIT
}

impl Default for Tolerances {
    fn default() -> Self {
        Self {
            by_group: BTreeMap::new(),
            hold: Vec::new(),
            off: false,
            limit: DEFAULT_LIMIT,
            optional: Default::default(),
        }
    }
}

/// A tolerance at or above this (in its group's unit) frees the group, as `inf` does: its
/// prior weight, squared beside the Jacobian's columns, would overflow the fit's arithmetic
/// (from about 1e150 the fit found no parameter at all), and no physical tolerance comes near
/// it.
pub const FREE_FROM: f64 = 1e100;

impl Tolerances {
    /// Sets a group's tolerance (checked: finite and > 0, or infinite to free it; from
    /// [`FREE_FROM`] on, infinite).
    pub fn set(&mut self, group: &str, value: f64) -> Result<(), CalibError> {
        if !(value > 0.0) || value.is_nan() {
            return Err(CalibError::invalid(
                "tolerance",
                format!("{group} = {value}: a tolerance must be > 0 (inf frees the group; hold it to keep it at nominal)"),
            ));
        }
        let value = if value >= FREE_FROM {
            f64::INFINITY
        } else {
            value
        };
        self.by_group.insert(group.to_string(), value);
        Ok(())
    }

    /// Sets [`Tolerances::limit`] (checked: > 0; infinite for no limit).
    pub fn set_limit(&mut self, value: f64) -> Result<(), CalibError> {
        if !(value > 0.0) {
            return Err(CalibError::invalid(
                "tolerance limit",
                format!("{value}: the limit is a number of tolerances > 0 (inf: no limit)"),
            ));
        }
        self.limit = value;
        Ok(())
    }

    /// The plain least-squares fit: no prior, nothing held.
    pub fn none() -> Self {
        Self {
            off: true,
            ..Self::default()
        }
    }
}

/// The name of a parameter block's group.
pub fn group_name(model: &MeasurementModel, block: &Block) -> String {
    match (block.effect, block.instrument) {
        (Some(e), _) => e.name().to_string(),
        (None, Some(i)) => model.instruments[i].name().to_string(),
        (None, None) => INSTALLATION_ERRORS.to_string(),
    }
}

/// The unit of a group's tolerance.
pub fn group_unit(model: &MeasurementModel, block: &Block) -> String {
    match (block.effect, block.instrument) {
        (Some(e), _) => e.unit().to_string(),
        (None, Some(i)) => model.instruments[i].param_unit(0).to_string(),
        (None, None) => "um".into(),
    }
}

/// The machine's size for the default tolerances: the mean link length at the home pose, mm.
pub fn machine_size_mm(model: &MeasurementModel) -> f64 {
    let table = model.design.as_ref().unwrap_or(&model.nominal);
    let l = cpm_kinematics::inverse_lengths(table, &table.home);
    if l.is_empty() {
        return 0.0;
    }
    l.iter().sum::<f64>() / l.len() as f64
}

/// The default tolerance of a group, in its unit (module docs); `f64::INFINITY` for the free
/// groups.
pub fn default_tolerance(model: &MeasurementModel, block: &Block) -> f64 {
    let size_um = machine_size_mm(model) * 1e3;
    let Some(effect) = block.effect else {
        return if block.instrument.is_some() {
            f64::INFINITY
        } else {
            4e-3 * size_um
        };
    };
    match effect {
        Effect::LinkOffset | Effect::SensorOffset => 5e-2 * size_um,
        Effect::LinkScale | Effect::SensorScale => 5e4,
        Effect::LinkNonlinearity | Effect::ScrewPeriodic | Effect::SocketError => 4e-3 * size_um,
        Effect::Clearance | Effect::Backlash => 2e-4 * size_um,
        Effect::ThermalDrift => 100.0,
        Effect::Compliance => {
            // Deflection of 1 % of the size under the load's weight (and external force)
            // shared by the links: um per kN.
            let load = &model.load;
            let g = load.gravity_mm_s2.norm() * 1e-3; // m/s^2
            let force_kn = ((load.platform_mass_kg + load.payload_mass_kg) * g
                + load.external_force_n.norm())
                * 1e-3
                / model.nominal.num_links().max(1) as f64;
            if force_kn > 0.0 {
                1e-2 * size_um / force_kn
            } else {
                f64::INFINITY
            }
        }
        _ => f64::INFINITY,
    }
}

/// The prior standard deviation of every parameter of `model`, in the model's units: `0` for
/// a held parameter, `f64::INFINITY` for a free one. Fails on a group name that is not in the
/// model (naming it and the model's groups).
pub fn prior_std(
    model: &MeasurementModel,
    tolerances: &Tolerances,
) -> Result<Vec<f64>, CalibError> {
    let blocks = model.blocks();
    let names: Vec<String> = blocks.iter().map(|b| group_name(model, b)).collect();
    for name in tolerances.by_group.keys().chain(&tolerances.hold) {
        if !names.contains(name) && !tolerances.optional.contains(name) {
            return Err(CalibError::invalid(
                "tolerances",
                format!(
                    "`{name}` is not a parameter group of this fit (its groups: {})",
                    names.join(", ")
                ),
            ));
        }
    }
    if !names.is_empty() && names.iter().all(|n| tolerances.hold.contains(n)) {
        return Err(CalibError::invalid(
            "tolerances",
            format!(
                "every group is held ({}): nothing is left to fit; hold fewer",
                names.join(", ")
            ),
        ));
    }
    let mut out = vec![f64::INFINITY; model.num_params()];
    for (b, name) in blocks.iter().zip(&names) {
        let t = if tolerances.hold.contains(name) {
            0.0
        } else if tolerances.off {
            f64::INFINITY
        } else {
            tolerances
                .by_group
                .get(name)
                .copied()
                .unwrap_or_else(|| default_tolerance(model, b))
        };
        out[b.offset..b.offset + b.len].fill(t);
    }
    Ok(out)
}

/// The tolerance of each group as applied (for the reports): name, unit, value (`inf` free,
/// 0 held), and whether it was declared or the default.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GroupTolerance {
    /// Group name.
    pub group: String,
    /// Unit of the tolerance.
    pub unit: String,
    /// The a-priori standard deviation (`None`: free, no prior).
    pub tolerance: Option<f64>,
    /// True when held at its start.
    pub held: bool,
    /// True when declared (description or command line), false for the default.
    pub declared: bool,
}

/// The groups of `model` with their tolerances as [`prior_std`] applies them.
pub fn group_tolerances(model: &MeasurementModel, tolerances: &Tolerances) -> Vec<GroupTolerance> {
    model
        .blocks()
        .iter()
        .map(|b| {
            let group = group_name(model, b);
            let held = tolerances.hold.contains(&group);
            let declared = held || tolerances.by_group.contains_key(&group);
            let t = if held || tolerances.off {
                None
            } else {
                Some(
                    tolerances
                        .by_group
                        .get(&group)
                        .copied()
                        .unwrap_or_else(|| default_tolerance(model, b)),
                )
            };
            GroupTolerance {
                unit: group_unit(model, b),
                group,
                tolerance: t.filter(|t| t.is_finite()),
                held,
                declared,
            }
        })
        .collect()
}

/// A direction of the parameters that the data see less well than its tolerance: held near
/// nominal by the prior, not measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HeldDirection {
    /// The direction's Cramér-Rao standard deviation from the data alone, in tolerances (above
    /// 1: the data know it worse than the drawing does).
    pub data_std_in_tolerances: f64,
    /// The largest loadings: (parameter index, coefficient of the unit direction in
    /// tolerance-scaled parameters).
    pub loadings: Vec<(usize, f64)>,
}

/// What the prior did in a fit: per parameter, its prior and posterior standard deviation
/// and the share of its determination the data supplied.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PriorSummary {
    /// Prior standard deviation per parameter (model units); `None` free, `Some(0)` held.
    pub prior_std: Vec<Option<f64>>,
    /// Posterior standard deviation per parameter (model units); `None` where the posterior
    /// is not defined (a free parameter the data do not see) or the parameter is held.
    pub posterior_std: Vec<Option<f64>>,
    /// `1 - posterior variance / prior variance` per parameter with a prior: 1 = the data
    /// alone determine it, 0 = the data say nothing (it stayed at nominal).
    pub data_share: Vec<Option<f64>>,
    /// Directions the data see less well than their tolerance, weakest first.
    pub held_directions: Vec<HeldDirection>,
    /// Parameter-space dimensions the data determine better than their tolerance (of those
    /// with a prior), plus the free ones the data see.
    pub determined_dimensions: usize,
    /// The effective number of parameters fitted (trace of the hat matrix): the residual
    /// degrees of freedom are the observations less this.
    pub effective_params: f64,
    /// The noise (weighted, um of the reference) the prior was weighed against.
    pub sigma_um: f64,
}

/// What gives a fitted parameter its value: one word per meaning, the same in stdout,
/// report.md, calibration.json and calibrated.toml ([`Determination::word`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Determination {
    /// "determined": the data determine it on their own (the rank of the data alone: a
    /// tolerance never makes a blind direction seen) and, under a prior, supply at least
    /// [`MIN_DATA_SHARE`] of its determination. Its standard deviation is the data's
    /// Cramér-Rao bound.
    Determined,
    /// "held by tolerance": the data alone do not determine it, or supply less than
    /// [`MIN_DATA_SHARE`] of its determination, and a tolerance holds it (its own, or those of
    /// the parameters it is mixed with in a blind direction), or the tolerance limit does.
    /// Its value is where the fit ends between the data and the tolerances, its standard
    /// deviation the posterior one: not a measurement.
    HeldByTolerance,
    /// "held by user": held at its nominal value (`--hold`, a held group).
    HeldByUser,
    /// "blind": neither the data nor a tolerance determine it. No estimate exists; the
    /// written model carries the fit's minimum-norm value.
    Blind,
}

impl Determination {
    /// Every determination, in the order reports list them.
    pub const ALL: [Determination; 4] = [
        Determination::Determined,
        Determination::HeldByTolerance,
        Determination::HeldByUser,
        Determination::Blind,
    ];

    /// The word every output uses: `determined`, `held by tolerance`, `held by user`,
    /// `blind`.
    pub fn word(self) -> &'static str {
        match self {
            Determination::Determined => "determined",
            Determination::HeldByTolerance => "held by tolerance",
            Determination::HeldByUser => "held by user",
            Determination::Blind => "blind",
        }
    }
}

impl std::fmt::Display for Determination {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.word())
    }
}

/// The share of the data below which a parameter counts as held by its prior rather than
/// determined by the data (posterior standard deviation at least `1/sqrt(2)` of the prior's).
pub const MIN_DATA_SHARE: f64 = 0.5;

impl PriorSummary {
    /// True when the data determined parameter `k` (free and seen, or with a share of at
    /// least [`MIN_DATA_SHARE`]).
    pub fn determined(&self, k: usize) -> bool {
        match (self.prior_std[k], self.data_share[k]) {
            (Some(0.0), _) => false,
            (Some(_), Some(s)) => s >= MIN_DATA_SHARE,
            (Some(_), None) => false,
            (None, _) => self.posterior_std[k].is_some(),
        }
    }
}

/// The posterior of a fit with prior standard deviations `prior` (model units, 0 held,
/// infinite free), weighted Jacobian `j` (um of reference per model unit) and noise
/// `sigma_um`.
pub fn summarize(j: &DMatrix<f64>, prior: &[f64], sigma_um: f64) -> PriorSummary {
    summarize_scaled(j, prior, sigma_um, None)
}

/// The posterior of a fit under a prior, over its unheld parameters `free`: the data's
/// precision `g = J^T J / sigma^2`, the (column-scaled) precision `h` with the prior's rows,
/// its largest eigenvalue `lmax`, and the covariance `cov` (the pseudo-inverse).
struct Posterior {
    free: Vec<usize>,
    g: DMatrix<f64>,
    h: DMatrix<f64>,
    lmax: f64,
    cov: DMatrix<f64>,
}

impl Posterior {
    /// The covariance of all `np` parameters: `cov` in the unheld ones' places, zero
    /// elsewhere.
    fn full(&self, np: usize) -> DMatrix<f64> {
        let mut out = DMatrix::zeros(np, np);
        for (a, &ka) in self.free.iter().enumerate() {
            for (b, &kb) in self.free.iter().enumerate() {
                out[(ka, kb)] = self.cov[(a, b)];
            }
        }
        out
    }
}

fn posterior(
    j: &DMatrix<f64>,
    prior: &[f64],
    sigma_um: f64,
    column_scale: Option<&[f64]>,
) -> Posterior {
    let np = prior.len();
    let free: Vec<usize> = (0..np).filter(|&k| prior[k] > 0.0).collect();
    let nf = free.len();
    // Precision in the unheld parameters: J^T J / sigma^2 + diag(1 / t^2).
    let jf = j.select_columns(&free);
    let g = jf.transpose() * &jf / (sigma_um * sigma_um);
    let mut h = g.clone();
    for (a, &ka) in free.iter().enumerate() {
        if prior[ka].is_finite() {
            h[(a, a)] += 1.0 / (prior[ka] * prior[ka]);
        }
    }
    // The scaled precision D H D (D = 1 unless scaled): cut-offs are taken on it, and the
    // covariance is D (D H D)^+ D.
    let d: Vec<f64> = match column_scale.filter(|d| d.len() == np && d.iter().any(|x| *x != 1.0)) {
        Some(d) => free.iter().map(|&k| d[k]).collect(),
        None => vec![1.0; nf],
    };
    let scaled = d.iter().any(|x| *x != 1.0);
    if scaled {
        for a in 0..nf {
            for b in 0..nf {
                h[(a, b)] = d[a] * h[(a, b)] * d[b];
            }
        }
    }
    let eig = h.clone().symmetric_eigen();
    let lmax = eig.eigenvalues.iter().cloned().fold(0.0, f64::max);
    let mut cov = DMatrix::zeros(nf, nf);
    for (i, &l) in eig.eigenvalues.iter().enumerate() {
        if l > 1e-12 * lmax && l > 0.0 {
            let v = eig.eigenvectors.column(i);
            cov += v * v.transpose() / l;
        }
    }
    if scaled {
        for a in 0..nf {
            for b in 0..nf {
                cov[(a, b)] *= d[a] * d[b];
            }
        }
    }
    Posterior {
        free,
        g,
        h,
        lmax,
        cov,
    }
}

/// The posterior covariance of every parameter (model units squared) of a fit under the prior
/// `prior` (standard deviation per parameter: 0 held, infinite free) with the weighted
/// Jacobian `j` (um of the reference per unit) and noise `sigma_um`, its cut-offs taken as
/// [`summarize_scaled`] takes them: `(J^T J / sigma^2 + diag(1 / t^2))^+` over the unheld
/// parameters; held parameters and what neither the data nor a tolerance bounds carry none.
pub fn posterior_covariance(
    j: &DMatrix<f64>,
    prior: &[f64],
    sigma_um: f64,
    column_scale: Option<&[f64]>,
) -> DMatrix<f64> {
    posterior(j, prior, sigma_um, column_scale).full(prior.len())
}

/// [`summarize`] with the posterior's cut-offs taken on the precision with its parameters
/// scaled by `column_scale` ([`Identifiability::rank_column_scale`](crate::Identifiability::rank_column_scale), one factor per parameter): what the
/// posterior leaves undefined then does not depend on the units of a block (a compliance in
/// um/kN under a platform of 1 g or of 10 t). `None`, or every factor 1, is [`summarize`].
pub fn summarize_scaled(
    j: &DMatrix<f64>,
    prior: &[f64],
    sigma_um: f64,
    column_scale: Option<&[f64]>,
) -> PriorSummary {
    summarize_with_covariance(j, prior, sigma_um, column_scale).0
}

/// [`summarize_scaled`] and the posterior covariance of every parameter
/// ([`posterior_covariance`]) from one decomposition of the precision.
pub fn summarize_with_covariance(
    j: &DMatrix<f64>,
    prior: &[f64],
    sigma_um: f64,
    column_scale: Option<&[f64]>,
) -> (PriorSummary, DMatrix<f64>) {
    let np = prior.len();
    let p = posterior(j, prior, sigma_um, column_scale);
    let full = p.full(np);
    let Posterior {
        free,
        g,
        h,
        lmax,
        cov,
    } = p;
    // Which free parameters the posterior leaves undefined (inside the pseudo-inverse's null
    // space): their precision row is (numerically) zero.
    let mut posterior_std = vec![None; np];
    let mut data_share = vec![None; np];
    let mut effective = 0.0;
    for (a, &k) in free.iter().enumerate() {
        let seen = h[(a, a)] > 1e-12 * lmax.max(f64::MIN_POSITIVE);
        if seen {
            let var = cov[(a, a)].max(0.0);
            posterior_std[k] = Some(var.sqrt());
            if prior[k].is_finite() {
                data_share[k] = Some((1.0 - var / (prior[k] * prior[k])).clamp(0.0, 1.0));
            }
        }
    }
    // Effective parameters: tr(C J^T J) / sigma^2.
    effective += (&cov * &g).trace();
    // Held directions: the data's curvature in tolerance-scaled coordinates of the parameters
    // with a prior, the free ones eliminated (their best value follows the others).
    let with: Vec<usize> = free
        .iter()
        .copied()
        .filter(|&k| prior[k].is_finite())
        .collect();
    let nofree: Vec<usize> = free
        .iter()
        .copied()
        .filter(|&k| prior[k].is_infinite())
        .collect();
    let mut held_directions = Vec::new();
    let mut determined_dimensions = 0;
    if !with.is_empty() {
        let m = j.nrows();
        let mut a = DMatrix::zeros(m, with.len());
        for (c, &k) in with.iter().enumerate() {
            a.set_column(c, &(j.column(k) * (prior[k] / sigma_um)));
        }
        if !nofree.is_empty() {
            let mut f = DMatrix::zeros(m, nofree.len());
            for (c, &k) in nofree.iter().enumerate() {
                f.set_column(c, &j.column(k));
            }
            // Project out the free columns' span.
            let svd = f.svd(true, false);
            if let Some(u) = svd.u {
                let smax = svd.singular_values.iter().cloned().fold(0.0, f64::max);
                for (i, s) in svd.singular_values.iter().enumerate() {
                    if *s > 1e-10 * smax {
                        let ui = u.column(i).into_owned();
                        let proj = &ui * (ui.transpose() * &a);
                        a -= proj;
                    }
                }
            }
        }
        let ata = a.transpose() * &a;
        let eig = ata.symmetric_eigen();
        let mut order: Vec<usize> = (0..with.len()).collect();
        order.sort_by(|x, y| eig.eigenvalues[*x].total_cmp(&eig.eigenvalues[*y]));
        for i in order {
            let s2 = eig.eigenvalues[i].max(0.0);
            if s2 >= 1.0 {
                determined_dimensions += 1;
                continue;
            }
            let v = eig.eigenvectors.column(i);
            let mut load: Vec<(usize, f64)> =
                v.iter().enumerate().map(|(c, x)| (with[c], *x)).collect();
            load.sort_by(|x, y| y.1.abs().total_cmp(&x.1.abs()));
            load.truncate(4);
            held_directions.push(HeldDirection {
                data_std_in_tolerances: if s2 > 0.0 {
                    1.0 / s2.sqrt()
                } else {
                    f64::INFINITY
                },
                loadings: load,
            });
        }
        // Weakest first.
        held_directions.sort_by(|x, y| {
            y.data_std_in_tolerances
                .total_cmp(&x.data_std_in_tolerances)
        });
    }
    determined_dimensions += nofree
        .iter()
        .filter(|&&k| posterior_std[k].is_some())
        .count();
    let summary = PriorSummary {
        prior_std: prior.iter().map(|p| p.is_finite().then_some(*p)).collect(),
        posterior_std,
        data_share,
        held_directions,
        determined_dimensions,
        effective_params: effective,
        sigma_um,
    };
    (summary, full)
}

/// The leverage of each observation under the prior: the diagonal of the regularised hat
/// matrix `J C J^T / sigma^2` (`C` the posterior covariance of the unheld parameters); they add
/// up to the effective number of parameters, so that each kind of observation's redundancy
/// (`1 - h`) shares the residual's degrees of freedom as the noise estimate counts them.
pub fn leverages(j: &DMatrix<f64>, prior: &[f64], sigma_um: f64) -> Vec<f64> {
    let free: Vec<usize> = (0..prior.len()).filter(|&k| prior[k] > 0.0).collect();
    let jf = j.select_columns(&free);
    let mut h = jf.transpose() * &jf / (sigma_um * sigma_um);
    for (a, &k) in free.iter().enumerate() {
        if prior[k].is_finite() {
            h[(a, a)] += 1.0 / (prior[k] * prior[k]);
        }
    }
    let eig = h.symmetric_eigen();
    let lmax = eig.eigenvalues.iter().cloned().fold(0.0, f64::max);
    // J C J^T / s^2 = sum over eigenpairs (J v)(J v)^T / (l s^2).
    let mut out = vec![0.0; j.nrows()];
    for (i, &l) in eig.eigenvalues.iter().enumerate() {
        if l > 1e-12 * lmax && l > 0.0 {
            let u = &jf * eig.eigenvectors.column(i);
            for (o, x) in out.iter_mut().zip(u.iter()) {
                *o += x * x / (l * sigma_um * sigma_um);
            }
        }
    }
    out
}
