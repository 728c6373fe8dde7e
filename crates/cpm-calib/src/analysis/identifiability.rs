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
    analyze_with(jacobian, sigma_um, options, patterns, false)
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
    analyze_with(jacobian, sigma_um, options, patterns, true)
}

fn analyze_with(
    jacobian: &DMatrix<f64>,
    sigma_um: f64,
    options: &RankOptions,
    patterns: &[Pattern],
    strict: bool,
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
    let threshold = options.rank_rtol * smax;
    let rank = sv.iter().filter(|&&s| s > threshold && s > 0.0).count();
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
            // Its largest singular value, by the crate's accurate SVD (no readings: no gain).
            let jb = jacobian * &b;
            let gain = if jb.nrows() == 0 {
                0.0
            } else {
                crate::linalg::svd_values_and_v(&jb)
                    .map_or(f64::INFINITY, |(s, _)| s.first().copied().unwrap_or(0.0))
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
