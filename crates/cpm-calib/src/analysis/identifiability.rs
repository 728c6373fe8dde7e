//! What a campaign can identify: rank, singular values, blind directions in physical terms,
//! and Cramér-Rao bounds.
//!
//! The identification Jacobian `J` (readings x parameters, dimensionless: um of reading per um
//! of error) is decomposed `J = U S V^T`. Its numerical rank `r` counts the singular values
//! above `rank_rtol * s_max` (default `rank_rtol` = 1e-4: a combination that moves the readings
//! ten thousand times less than the best-seen one would need an error ten thousand times
//! larger to show as much; for installation errors of 0.1 mm that is metres, so it is treated
//! as invisible). The last `n - r` columns of `V` span the *blind directions*: error patterns
//! the readings cannot see. A single parameter is *determined* when its unit vector has
//! (almost) no component in that null space (below `determined_tol`, default 1e-3: whatever
//! happens along the blind directions leaks into its estimate at most a thousandth); only
//! determined parameters get an estimate and a standard deviation. With sensor
//! noise `sigma`, the Cramér-Rao covariance of the identifiable part is
//! `sigma^2 V_r S_r^-2 V_r^T`, and `sigma / s_i` is the standard deviation of the i-th
//! identifiable combination `v_i^T e`.
//!
//! A fit decides the rank scale-free ([`try_analyze_scaled`] with a [`RankScaling`]): on `J`
//! with each kind of observation and each unit of parameters brought to one scale, so that a
//! mass written in grams or an exact instrument beside a noisy one does not change it.
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::{CalibError, Campaign, MeasurementModel};
use cpm_geometry::InstallationErrors;

/// Thresholds of the identifiability analysis.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RankOptions {
    /// Singular values below `rank_rtol * s_max` count as zero. Default 1e-4.
    pub rank_rtol: f64,
    /// A parameter is determined when the norm of its unit vector's projection on the null
    /// space is below this. Default 1e-3.
    pub determined_tol: f64,
}

impl Default for RankOptions {
    fn default() -> Self {
        Self {
            rank_rtol: 1e-4,
            determined_tol: 1e-3,
        }
    }
}

/// A physical error pattern that the data cannot see.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BlindDirection {
    /// What moves, in words.
    pub description: String,
    /// How many independent null-space directions this pattern accounts for.
    pub dimensions: usize,
}

/// The Cramér-Rao bounds of the determined parameters of one unit
/// ([`Identifiability::crlb_per_unit`]).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CrlbOfUnit {
    /// The unit (`um`, `ppm`, `urad`, ...).
    pub unit: String,
    /// Determined parameters of this unit.
    pub determined: usize,
    /// RMS of their standard deviations, in the unit.
    pub rms: f64,
    /// The largest of them, in the unit.
    pub worst: f64,
}

/// The result of an identifiability analysis.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Identifiability {
    /// Number of parameters.
    pub num_params: usize,
    /// Number of readings.
    pub num_readings: usize,
    /// Numerical rank.
    pub rank: usize,
    /// The relative rank threshold used.
    pub rank_rtol: f64,
    /// The absolute threshold used: `rank_rtol * s_max`.
    pub threshold: f64,
    /// Singular values, descending.
    pub singular_values: Vec<f64>,
    /// The singular values the rank was decided on when the columns were scaled
    /// ([`try_analyze_scaled`]: `threshold` is `rank_rtol` times the first of them), descending;
    /// empty when they were not (the rank is then decided on `singular_values`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub scaled_singular_values: Vec<f64>,
    /// The column factors the rank was decided with ([`RankScaling`]), one per parameter;
    /// empty when the columns were not scaled.
    #[serde(skip)]
    pub rank_column_scale: Vec<f64>,
    /// Right singular vectors, one per column, in the order of `singular_values`.
    #[serde(skip)]
    pub v: DMatrix<f64>,
    /// Per parameter: true when the data determine it on its own.
    pub determined: Vec<bool>,
    /// Per parameter: norm of its unit vector's projection on the null space (0 = determined,
    /// 1 = completely invisible).
    pub null_fraction: Vec<f64>,
    /// Blind directions in physical terms, with the dimensions each explains.
    pub blind_directions: Vec<BlindDirection>,
    /// Null-space dimensions that no listed physical pattern explains.
    pub unexplained_null_dimensions: usize,
    /// Sensor noise assumed for the bounds, um (standard deviation).
    pub sigma_um: f64,
    /// Cramér-Rao standard deviation per parameter, um; `None` when not determined.
    pub crlb_std_um: Vec<Option<f64>>,
    /// Cramér-Rao standard deviation of each identifiable combination `v_i^T e`, um.
    pub combination_std_um: Vec<f64>,
}

impl Identifiability {
    /// Basis of the identifiable subspace (first `rank` right singular vectors).
    pub fn row_space(&self) -> DMatrix<f64> {
        self.v.columns(0, self.rank).into_owned()
    }

    /// Basis of the null space (blind directions).
    pub fn null_space(&self) -> DMatrix<f64> {
        self.v
            .columns(self.rank, self.num_params - self.rank)
            .into_owned()
    }

    /// Root mean square of the Cramér-Rao bounds of the determined parameters, um
    /// (`None` when none is determined).
    pub fn crlb_rms_um(&self) -> Option<f64> {
        let v: Vec<f64> = self.crlb_std_um.iter().flatten().copied().collect();
        if v.is_empty() {
            None
        } else {
            Some((v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt())
        }
    }

    /// The Cramér-Rao bounds of the determined parameters per unit (`units`: one per
    /// parameter, [`MeasurementModel::parameter_units`](crate::MeasurementModel::parameter_units)),
    /// in the order the units first appear: no RMS over parameters of different units.
    pub fn crlb_per_unit(&self, units: &[String]) -> Vec<CrlbOfUnit> {
        let mut out: Vec<CrlbOfUnit> = Vec::new();
        for (sd, unit) in self.crlb_std_um.iter().zip(units) {
            let Some(sd) = sd else { continue };
            let k = match out.iter().position(|g| &g.unit == unit) {
                Some(k) => k,
                None => {
                    out.push(CrlbOfUnit {
                        unit: unit.clone(),
                        determined: 0,
                        rms: 0.0,
                        worst: 0.0,
                    });
                    out.len() - 1
                }
            };
            let g = &mut out[k];
            g.determined += 1;
            g.rms += sd * sd;
            g.worst = g.worst.max(*sd);
        }
        for g in &mut out {
            g.rms = (g.rms / g.determined as f64).sqrt();
        }
        out
    }

    /// The worst Cramér-Rao standard deviation among determined parameters, um.
    pub fn crlb_max_um(&self) -> Option<f64> {
        self.crlb_std_um.iter().flatten().copied().reduce(f64::max)
    }

    /// Number of determined parameters.
    pub fn num_determined(&self) -> usize {
        self.determined.iter().filter(|d| **d).count()
    }

    /// A few lines in words.
    pub fn summary(&self) -> String {
        let mut s = format!(
            "rank {} of {} from {} readings (threshold {:.3e} = rtol x s_max); {} parameters determined on their own\n",
            self.rank,
            self.num_params,
            self.num_readings,
            self.threshold,
            self.num_determined()
        );
        if self.rank < self.num_params {
            s.push_str(&format!(
                "{} blind directions:\n",
                self.num_params - self.rank
            ));
            for b in &self.blind_directions {
                s.push_str(&format!("  - {} ({} dim)\n", b.description, b.dimensions));
            }
            if self.unexplained_null_dimensions > 0 {
                s.push_str(&format!(
                    "  - {} further combined directions (mixtures of several joints; see the null-space vectors)\n",
                    self.unexplained_null_dimensions
                ));
            }
        }
        s
    }
}

/// A named physical error pattern (defined with the model, whose parameters it names).
pub use crate::model::patterns::Pattern;

/// Physical error patterns worth naming for a machine and campaign: per-link rigid
/// translation, joints moved along their link, all base joints rotated about each sensor's
/// base socket, all platform joints rotated about each sensor's platform socket, all base or
/// all platform joints translated together.
pub fn physical_patterns(model: &MeasurementModel, campaign: &Campaign) -> Vec<Pattern> {
    let table = &model.nominal;
    let n = table.num_links();
    let np = model.num_params();
    let r0 = campaign
        .poses
        .first()
        .map(|p| p.rotation)
        .unwrap_or(table.home.rotation);
    let rt = r0.inverse();
    let mut out = Vec::new();
    for i in 0..n {
        // Rigid translation of link i: db = v, dp = R^T v (the link vector does not change at
        // the orientation of the first pose).
        let vectors = (0..3)
            .map(|a| {
                let mut v = DVector::zeros(np);
                let mut d = nalgebra::Vector3::zeros();
                d[a] = 1.0;
                let dp = rt * d;
                v[6 * i + a] = 1.0;
                for b in 0..3 {
                    v[6 * i + 3 + b] = dp[b];
                }
                v
            })
            .collect();
        out.push(Pattern {
            description: format!(
                "base and platform joint of link {} moved together by the same vector",
                i + 1
            ),
            vectors,
        });
    }
    let home = cpm_kinematics::inverse(table, &table.home);
    for (i, ls) in home.iter().enumerate() {
        let z = ls.unit;
        let zp = rt * z;
        let mut vb = DVector::zeros(np);
        let mut vp = DVector::zeros(np);
        for b in 0..3 {
            vb[6 * i + b] = z[b];
            vp[6 * i + 3 + b] = zp[b];
        }
        out.push(Pattern {
            description: format!("base joint of link {} moved along the link", i + 1),
            vectors: vec![vb],
        });
        out.push(Pattern {
            description: format!("platform joint of link {} moved along the link", i + 1),
            vectors: vec![vp],
        });
        let mut vsame = DVector::zeros(np);
        for b in 0..3 {
            vsame[6 * i + b] = z[b];
            vsame[6 * i + 3 + b] = zp[b];
        }
        out.push(Pattern {
            description: format!(
                "base and platform joint of link {} moved together along the link",
                i + 1
            ),
            vectors: vec![vsame],
        });
    }
    for side in 0..2 {
        let name = if side == 0 { "base" } else { "platform" };
        let vs: Vec<DVector<f64>> = (0..3)
            .map(|a| {
                let mut v = DVector::zeros(np);
                for i in 0..n {
                    v[6 * i + 3 * side + a] = 1.0;
                }
                v
            })
            .collect();
        out.push(Pattern {
            description: format!("all {name} joints translated together"),
            vectors: vs,
        });
    }
    // Moving every base joint by v moves the platform by v; a tracker registration moved by
    // -v hides it. Moving every platform joint by v moves the platform frame by -v under the
    // legs; a marker frame moved by v keeps the measured body where it was. Likewise for a
    // rotation about the base (platform) origin.
    for (effect, side, sign, what, origin) in [
        (
            crate::Effect::TrackerFrame,
            0,
            -1.0,
            "base joints and the tracker frame",
            "base",
        ),
        (
            crate::Effect::MarkerFrame,
            1,
            1.0,
            "platform joints and the marker frame",
            "platform",
        ),
    ] {
        let Some(b) = model
            .blocks()
            .into_iter()
            .find(|b| b.effect == Some(effect))
        else {
            continue;
        };
        let frame = |v: &mut DVector<f64>, k: usize| {
            for f in 0..b.len / 6 {
                v[b.offset + 6 * f + k] = sign;
            }
        };
        let trans = (0..3)
            .map(|a| {
                let mut v = DVector::zeros(np);
                for i in 0..n {
                    v[6 * i + 3 * side + a] = 1.0;
                }
                frame(&mut v, a);
                v
            })
            .collect();
        out.push(Pattern {
            description: format!("all {what} translated together"),
            vectors: trans,
        });
        let rot = (0..3)
            .map(|a| {
                let mut w = nalgebra::Vector3::zeros();
                w[a] = 1.0;
                let mut v = DVector::zeros(np);
                for (i, l) in table.links.iter().enumerate() {
                    let joint = if side == 0 { l.base_mm } else { l.platform_mm };
                    let d = w.cross(&joint) * 1e-3;
                    for c in 0..3 {
                        v[6 * i + 3 * side + c] = d[c];
                    }
                }
                frame(&mut v, 3 + a);
                v
            })
            .collect();
        out.push(Pattern {
            description: format!("all {what} rotated together about the {origin} origin"),
            vectors: rot,
        });
    }
    out.extend(crate::model::points::patterns(model));
    out.extend(crate::model::tilts::patterns(model));
    let mut used = Vec::new();
    for s in &campaign.readings {
        if !used.contains(&s.sensor) {
            used.push(s.sensor);
        }
    }
    for &si in &used {
        let sensor = &table.sensors[si];
        for side in 0..2 {
            let (centre, name) = if side == 0 {
                (sensor.base_mm, "base")
            } else {
                (sensor.platform_mm, "platform")
            };
            let vs: Vec<DVector<f64>> = (0..3)
                .map(|a| {
                    let mut w = nalgebra::Vector3::zeros();
                    w[a] = 1.0;
                    let mut v = DVector::zeros(np);
                    for (i, l) in table.links.iter().enumerate() {
                        let p = if side == 0 { l.base_mm } else { l.platform_mm };
                        let d = w.cross(&(p - centre));
                        for b in 0..3 {
                            v[6 * i + 3 * side + b] = d[b];
                        }
                    }
                    v
                })
                .collect();
            out.push(Pattern {
                description: format!(
                    "all {name} joints rotated about sensor `{}`'s {name} socket",
                    sensor.name
                ),
                vectors: vs,
            });
        }
    }
    out
}

/// Orthonormal basis of the span of `vectors` (modified Gram-Schmidt), dropping dependent ones.
fn orthonormalise(vectors: &[DVector<f64>], against: Option<&DMatrix<f64>>) -> Vec<DVector<f64>> {
    let mut basis: Vec<DVector<f64>> = Vec::new();
    for v in vectors {
        let mut w = v.clone();
        let n0 = w.norm();
        if n0 == 0.0 {
            continue;
        }
        if let Some(a) = against {
            let c = a.transpose() * &w;
            w -= a * c;
        }
        for b in &basis {
            let c = b.dot(&w);
            w -= b * c;
        }
        let n = w.norm();
        if n > 1e-8 * n0 {
            basis.push(w / n);
        }
    }
    basis
}

/// Identifiability of the parameters from a Jacobian (readings x parameters, um per um).
///
/// A Jacobian whose SVD cannot be computed (a non-finite entry) is reported as rank 0, every
/// parameter undetermined; [`try_analyze`] returns that failure as an error instead.
pub fn analyze(
    jacobian: &DMatrix<f64>,
    sigma_um: f64,
    options: &RankOptions,
    patterns: &[Pattern],
) -> Identifiability {
    analyze_with(
        jacobian,
        sigma_um,
        options,
        patterns,
        false,
        &RankScaling::NONE,
    )
    .expect("analyze_with(strict = false) does not fail")
}

/// [`analyze`] with the rank decided on the scaled Jacobian ([`try_analyze_scaled`]).
pub fn analyze_scaled(
    jacobian: &DMatrix<f64>,
    sigma_um: f64,
    options: &RankOptions,
    patterns: &[Pattern],
    scaling: &RankScaling<'_>,
) -> Identifiability {
    analyze_with(jacobian, sigma_um, options, patterns, false, scaling)
        .expect("analyze_with(strict = false) does not fail")
}

/// Like [`analyze`], with an SVD failure (a non-finite entry in the Jacobian, faer not
/// converging) reported as [`CalibError::Svd`].
pub fn try_analyze(
    jacobian: &DMatrix<f64>,
    sigma_um: f64,
    options: &RankOptions,
    patterns: &[Pattern],
) -> Result<Identifiability, CalibError> {
    analyze_with(
        jacobian,
        sigma_um,
        options,
        patterns,
        true,
        &RankScaling::NONE,
    )
}

/// Like [`try_analyze`], with the rank decided on the Jacobian scaled by `scaling`: the
/// rank, the threshold and the blind patterns are those of `W J D`, so that they do not change
/// with the unit of a block of parameters (a platform mass in grams or in tonnes, an angle in
/// urad or in degrees) or with the weight of a kind of observation (an exact instrument beside
/// a noisy one). The singular values and vectors, the determined parameters and the
/// Cramér-Rao bounds stay those of `J` (the bounds of determined parameters do not depend on
/// the scaling), taken to the rank so decided. [`RankScaling::NONE`] is [`try_analyze`]
/// exactly.
pub fn try_analyze_scaled(
    jacobian: &DMatrix<f64>,
    sigma_um: f64,
    options: &RankOptions,
    patterns: &[Pattern],
    scaling: &RankScaling<'_>,
) -> Result<Identifiability, CalibError> {
    analyze_with(jacobian, sigma_um, options, patterns, true, scaling)
}

/// How the rank is decided scale-free ([`try_analyze_scaled`]): the Jacobian's rows scaled per
/// group (`row_groups`: one group per observation, its kind) so that every group's RMS row
/// norm is 1, then its columns scaled per group (`column_groups`: one group per parameter,
/// its unit, group 0 the installation errors' (um), [`MeasurementModel::rank_groups`]) so
/// that every group's
/// median non-zero column norm is that of group 0. A single group scales nothing; so does a
/// group 0 without a non-zero column (every installation error held).
#[derive(Debug, Clone, Copy, Default)]
pub struct RankScaling<'a> {
    /// One group per parameter; `None`: no column scaling.
    pub column_groups: Option<&'a [usize]>,
    /// One group per observation; `None`: no row scaling.
    pub row_groups: Option<&'a [usize]>,
}

impl RankScaling<'_> {
    /// No scaling: the rank of `J` itself.
    pub const NONE: RankScaling<'static> = RankScaling {
        column_groups: None,
        row_groups: None,
    };

    /// The column factors `D` and the Gram matrix `D J^T W^2 J D` of the scaled Jacobian
    /// (`J = U S V^T`, `V` square), or `None` when nothing is scaled.
    fn gram(
        &self,
        j: &DMatrix<f64>,
        sv: &[f64],
        v: &DMatrix<f64>,
    ) -> Option<(Vec<f64>, DMatrix<f64>)> {
        let (m, np) = j.shape();
        let rows = self
            .row_groups
            .filter(|g| g.len() == m && g.iter().any(|x| *x != g[0]));
        let columns = self.column_groups.filter(|g| g.len() == np);
        let mut g = match rows {
            // The Gram matrix of J is that of S V^T.
            None => {
                columns?;
                let b =
                    DMatrix::from_fn(np, np, |i, k| sv.get(i).copied().unwrap_or(0.0) * v[(k, i)]);
                b.transpose() * b
            }
            Some(groups) => {
                let ng = groups.iter().copied().max().unwrap_or(0) + 1;
                let mut grams = vec![DMatrix::<f64>::zeros(np, np); ng];
                let mut counts = vec![0usize; ng];
                for (r, &grp) in groups.iter().enumerate() {
                    let row = j.row(r).transpose();
                    grams[grp].ger(1.0, &row, &row, 1.0);
                    counts[grp] += 1;
                }
                let mut total = DMatrix::<f64>::zeros(np, np);
                for (gm, c) in grams.iter().zip(&counts) {
                    let mean_square = gm.trace() / (*c).max(1) as f64;
                    if mean_square > 0.0 && mean_square.is_finite() {
                        total += gm / mean_square;
                    }
                }
                total
            }
        };
        let norms: Vec<f64> = (0..np).map(|k| g[(k, k)].max(0.0).sqrt()).collect();
        let d = columns
            .and_then(|c| column_factors(&norms, c))
            .unwrap_or_else(|| vec![1.0; np]);
        if rows.is_none() && d.iter().all(|x| *x == 1.0) {
            return None;
        }
        for a in 0..np {
            for b in 0..np {
                g[(a, b)] *= d[a] * d[b];
            }
        }
        Some((d, g))
    }
}

/// Column factors from the column norms: each group's median non-zero norm brought to group
/// 0's; `None` when group 0 has no non-zero norm.
fn column_factors(norms: &[f64], groups: &[usize]) -> Option<Vec<f64>> {
    let ng = groups.iter().copied().max()? + 1;
    let mut by_group: Vec<Vec<f64>> = vec![Vec::new(); ng];
    for (n, g) in norms.iter().zip(groups) {
        if *n > 0.0 && n.is_finite() {
            by_group[*g].push(*n);
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied()
    };
    let reference = median(&mut by_group[0])?;
    let factors: Vec<f64> = by_group
        .iter_mut()
        .map(|v| median(v).map_or(1.0, |m| reference / m))
        .collect();
    Some(groups.iter().map(|g| factors[*g]).collect())
}

/// Singular values below this fraction of the largest are rounding, whatever a column scaling
/// says: the rank decided on a scaled Jacobian never counts them.
const ROUNDING_RTOL: f64 = 1e-13;

fn analyze_with(
    jacobian: &DMatrix<f64>,
    sigma_um: f64,
    options: &RankOptions,
    patterns: &[Pattern],
    strict: bool,
    scaling: &RankScaling<'_>,
) -> Result<Identifiability, CalibError> {
    let (m, np) = jacobian.shape();
    // SVD of J (thin). For m < np pad with zero rows so that V is square.
    let padded;
    let jm = if m < np {
        padded = {
            let mut p = DMatrix::zeros(np, np);
            p.rows_mut(0, m).copy_from(jacobian);
            p
        };
        &padded
    } else {
        jacobian
    };
    // faer's SVD (nalgebra's bidiagonal SVD loses accuracy on some small matrices); the
    // padded matrix is square, so V is complete.
    let (sv, v) = match crate::linalg::svd_values_and_v(jm) {
        Ok(sv_v) => sv_v,
        Err(e) if strict => return Err(e.into()),
        Err(_) => (vec![0.0; np], DMatrix::identity(np, np)),
    };
    let smax = sv.first().copied().unwrap_or(0.0);
    let gram = scaling.gram(jacobian, &sv, &v);
    let (threshold, rank, scaled_singular_values) = match &gram {
        None => {
            let threshold = options.rank_rtol * smax;
            let rank = sv.iter().filter(|&&s| s > threshold && s > 0.0).count();
            (threshold, rank, Vec::new())
        }
        Some((_, g)) => {
            let mut svs: Vec<f64> = g
                .clone()
                .symmetric_eigen()
                .eigenvalues
                .iter()
                .map(|l| l.max(0.0).sqrt())
                .collect();
            svs.sort_by(|a, b| b.total_cmp(a));
            let threshold = options.rank_rtol * svs.first().copied().unwrap_or(0.0);
            let rank = svs.iter().filter(|&&s| s > threshold && s > 0.0).count();
            let numerical = sv.iter().filter(|&&s| s > ROUNDING_RTOL * smax).count();
            (threshold, rank.min(numerical), svs)
        }
    };
    let null = v.columns(rank, np - rank).into_owned();
    let null_fraction: Vec<f64> = (0..np).map(|k| null.row(k).norm()).collect();
    let determined: Vec<bool> = null_fraction
        .iter()
        .map(|f| *f <= options.determined_tol)
        .collect();
    // Cramér-Rao: cov = sigma^2 V_r S^-2 V_r^T.
    let mut crlb = Vec::with_capacity(np);
    for k in 0..np {
        if determined[k] {
            let var: f64 = (0..rank).map(|c| (v[(k, c)] / sv[c]).powi(2)).sum();
            crlb.push(Some(sigma_um * var.sqrt()));
        } else {
            crlb.push(None);
        }
    }
    let combination_std_um: Vec<f64> = sv[..rank].iter().map(|s| sigma_um / s).collect();
    // Blind directions: patterns that lie in the null space, greedily, counting new dimensions.
    let mut blind = Vec::new();
    let mut explained: Vec<DVector<f64>> = Vec::new();
    if rank < np {
        for p in patterns {
            let basis = orthonormalise(&p.vectors, None);
            if basis.is_empty() {
                continue;
            }
            // Blind: the pattern moves the readings less than the rank threshold does, in
            // every direction of its span.
            let b = DMatrix::from_columns(&basis);
            let gain = match &gram {
                // With the rank decided on the scaled Jacobian, the pattern's gain is measured
                // there too: its span in the scaled parameters (`D^-1 p`, orthonormal).
                Some((d, g)) => {
                    let scaled: Vec<DVector<f64>> = basis
                        .iter()
                        .map(|p| DVector::from_fn(np, |k, _| p[k] / d[k]))
                        .collect();
                    let bs = DMatrix::from_columns(&orthonormalise(&scaled, None));
                    let gb = bs.transpose() * g * &bs;
                    gb.symmetric_eigen()
                        .eigenvalues
                        .iter()
                        .fold(0.0_f64, |a, l| a.max(*l))
                        .sqrt()
                }
                // Its largest singular value, by the crate's accurate SVD (no readings: no
                // gain).
                None => {
                    let jb = jacobian * &b;
                    if jb.nrows() == 0 {
                        0.0
                    } else {
                        crate::linalg::svd_values_and_v(&jb)
                            .map_or(f64::INFINITY, |(s, _)| s.first().copied().unwrap_or(0.0))
                    }
                }
            };
            if gain > threshold {
                continue;
            }
            let ex = if explained.is_empty() {
                None
            } else {
                Some(DMatrix::from_columns(&explained))
            };
            let new = orthonormalise(&basis, ex.as_ref());
            if new.is_empty() {
                continue;
            }
            blind.push(BlindDirection {
                description: p.description.clone(),
                dimensions: new.len(),
            });
            explained.extend(new);
        }
    }
    Ok(Identifiability {
        num_params: np,
        num_readings: m,
        rank,
        rank_rtol: options.rank_rtol,
        threshold,
        singular_values: sv,
        scaled_singular_values,
        rank_column_scale: match &gram {
            Some((d, _)) if d.iter().any(|x| *x != 1.0) => d.clone(),
            _ => Vec::new(),
        },
        v,
        determined,
        null_fraction,
        unexplained_null_dimensions: (np - rank).saturating_sub(explained.len()),
        blind_directions: blind,
        sigma_um,
        crlb_std_um: crlb,
        combination_std_um,
    })
}

/// Names of the installation-error parameters, e.g. `link 2 platform dy`.
pub fn parameter_names(num_links: usize) -> Vec<String> {
    (0..6 * num_links)
        .map(InstallationErrors::component_name)
        .collect()
}

/// The leverage `h_ii` of every observation: the diagonal of the hat matrix of the weighted
/// Jacobian `j` in the identifiable subspace of its analysis `id`, `|| (J V_r S_r^-1)_i ||^2`.
pub(crate) fn leverages(j: &DMatrix<f64>, id: &Identifiability) -> Vec<f64> {
    let r = id.rank.min(id.v.ncols());
    if r == 0 {
        return vec![0.0; j.nrows()];
    }
    let mut jv: DMatrix<f64> = j * id.v.columns(0, r);
    for c in 0..r {
        jv.column_mut(c).unscale_mut(id.singular_values[c]);
    }
    jv.row_iter().map(|row| row.norm_squared()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Jacobian of 20 observations and 6 parameters: the first 10 observations see only
    /// the first 3 parameters, the others see all 6 (deterministic, well conditioned).
    fn jacobian() -> DMatrix<f64> {
        DMatrix::from_fn(20, 6, |r, k| {
            if r < 10 && k >= 3 {
                0.0
            } else {
                ((r * 7 + k * 13) as f64 * 0.37).sin() + if r % 6 == k { 2.0 } else { 0.0 }
            }
        })
    }

    /// The rank of the data does not change with the unit of a block of parameters or the
    /// weight of a kind of observation (issue 60 item 3); unscaled, it did.
    #[test]
    fn the_rank_does_not_depend_on_units_or_weights() {
        let o = RankOptions::default();
        let base = try_analyze(&jacobian(), 1.0, &o, &[]).unwrap();
        assert_eq!(base.rank, 6);
        // A block in a unit a million times smaller (a mass in tonnes for kilograms).
        let mut j = jacobian();
        for k in 3..6 {
            j.column_mut(k).scale_mut(1e-6);
        }
        assert!(try_analyze(&j, 1.0, &o, &[]).unwrap().rank < 6);
        let columns = [0, 0, 0, 1, 1, 1];
        let scaling = RankScaling {
            column_groups: Some(&columns),
            row_groups: None,
        };
        let id = try_analyze_scaled(&j, 1.0, &o, &[], &scaling).unwrap();
        assert_eq!(id.rank, 6);
        assert!(id.determined.iter().all(|d| *d));
        // The bounds of determined parameters are the unscaled ones, in the block's unit.
        let b = base.crlb_std_um[4].unwrap() * 1e6;
        assert!((id.crlb_std_um[4].unwrap() - b).abs() < 1e-6 * b);
        // An observation kind weighed a hundred million times more (an exact instrument).
        let mut j = jacobian();
        for r in 0..10 {
            j.row_mut(r).scale_mut(1e8);
        }
        assert!(try_analyze(&j, 1.0, &o, &[]).unwrap().rank < 6);
        let rows: Vec<usize> = (0..20).map(|r| usize::from(r >= 10)).collect();
        let scaling = RankScaling {
            column_groups: None,
            row_groups: Some(&rows),
        };
        assert_eq!(
            try_analyze_scaled(&j, 1.0, &o, &[], &scaling).unwrap().rank,
            6
        );
        // One group of each scales nothing: the analysis is the unscaled one, bit for bit.
        let one = vec![0; 6];
        let same = RankScaling {
            column_groups: Some(&one),
            row_groups: Some(&[0; 20]),
        };
        let a = try_analyze_scaled(&jacobian(), 1.0, &o, &[], &same).unwrap();
        assert_eq!(a.threshold, base.threshold);
        assert!(a.scaled_singular_values.is_empty() && a.rank_column_scale.is_empty());
    }
}
