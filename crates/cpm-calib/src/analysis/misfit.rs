//! Does the model fit? A chi-square test of the residual against the declared noise.
//!
//! With the noise declared (`sigma_um`), the weighted residuals of a correct model are
//! Gaussian with that standard deviation, so their sum of squares over sigma squared follows
//! a chi-square law with `m - rank` degrees of freedom. A fit is called inconsistent with the
//! declared noise when both
//! - the test rejects it: the upper-tail probability is below [`MISFIT_P`] (1e-3), and
//! - the discrepancy is material: chi2/dof is above [`MISFIT_CHI2_PER_DOF`] (1.5, a residual
//!   RMS about 22 % above the declared noise),
//!
//! since with thousands of observations the test alone rejects a noise declared a few per
//! cent too small. Observations flagged as outliers are left out (they are listed apart).
//!
//! The statistic and its tail are the crate's one chi-square rule ([`statistic`],
//! [`upper_tail`]); [`diagnostics`](crate::diagnostics) uses them too. Its verdict
//! (`consistent_with_noise`) means something else on purpose: the plain test at the
//! diagnostics' level `alpha` on every residual, the stopping rule of [`refine`](mod@crate::refine),
//! where the outliers are part of what is studied; the verdict here adds materiality and
//! leaves the outliers out, for the report of a fit.
//!
//! ```
//! use cpm_calib::misfit::chi_square;
//! // 100 residuals of 6.4 um against a declared 1 um noise, 36 parameters determined.
//! let m = chi_square(&vec![6.4; 100], 1.0, 36, &[]).unwrap();
//! assert!(m.inconsistent());
//! assert!((m.chi2_per_dof - 6.4 * 6.4 * 100.0 / 64.0).abs() < 1e-9);
//! // Residuals at the noise are consistent.
//! let ok = chi_square(&vec![1.0; 100], 1.0, 0, &[]).unwrap();
//! assert!(!ok.inconsistent());
//! ```
use statrs::distribution::{ChiSquared, ContinuousCDF};

/// Upper-tail probability below which the chi-square test rejects the fit.
pub const MISFIT_P: f64 = 1e-3;
/// chi2/dof above which a rejected fit is reported as not fitting.
pub const MISFIT_CHI2_PER_DOF: f64 = 1.5;

/// The chi-square test of a fit (serialised as `calibration.json`'s `misfit` figures).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Misfit {
    /// Sum of squared residuals over the declared noise squared.
    pub chi2: f64,
    /// Degrees of freedom: observations used minus the rank.
    pub dof: usize,
    /// chi2 / dof (1 expected).
    pub chi2_per_dof: f64,
    /// Probability of a chi2 this large or larger under the declared noise.
    pub p_value: f64,
    /// RMS of the residuals used, um.
    pub residual_rms_um: f64,
    /// The declared noise, um.
    pub sigma_um: f64,
    /// Observations left out as outliers.
    pub outliers_left_out: usize,
}

impl Misfit {
    /// True when the residual is inconsistent with the declared noise (see the module
    /// documentation).
    pub fn inconsistent(&self) -> bool {
        self.p_value < MISFIT_P && self.chi2_per_dof > MISFIT_CHI2_PER_DOF
    }

    /// True when the residual is smaller than the declared noise beyond chance: a chi2 this
    /// small has a probability below [`MISFIT_P`] and chi2/dof is below 1 /
    /// [`MISFIT_CHI2_PER_DOF`]. The standard deviations, which use the declared noise, are
    /// then too large by about `1 / sqrt(chi2_per_dof)`.
    pub fn too_small(&self) -> bool {
        self.chi2_per_dof < 1.0 / MISFIT_CHI2_PER_DOF
            && ChiSquared::new(self.dof as f64)
                .map(|c| c.cdf(self.chi2) < MISFIT_P)
                .unwrap_or(false)
    }
}

/// The chi-square test of residuals `residuals_um` (weighted to the noise `sigma_um`) of a
/// fit of rank `rank`, without the observations in `outliers`. `None` when no degree of
/// freedom is left or the noise is not a positive number.
pub fn chi_square(
    residuals_um: &[f64],
    sigma_um: f64,
    rank: usize,
    outliers: &[usize],
) -> Option<Misfit> {
    if !(sigma_um.is_finite() && sigma_um > 0.0) {
        return None;
    }
    let (ssr, count) = sum_of_squares(residuals_um, outliers);
    let chi2 = ssr / (sigma_um * sigma_um);
    let dof = count.checked_sub(rank).filter(|d| *d > 0)?;
    let p_value = upper_tail(chi2, dof)?;
    Some(Misfit {
        chi2,
        dof,
        chi2_per_dof: chi2 / dof as f64,
        p_value,
        residual_rms_um: (ssr / count as f64).sqrt(),
        sigma_um,
        outliers_left_out: residuals_um.len() - count,
    })
}

/// The chi-square statistic of residuals `residuals_um` against the noise `sigma_um`:
/// `sum r^2 / sigma^2` over the residuals not in `outliers`, and how many were used.
pub fn statistic(residuals_um: &[f64], sigma_um: f64, outliers: &[usize]) -> (f64, usize) {
    let (ssr, count) = sum_of_squares(residuals_um, outliers);
    (ssr / (sigma_um * sigma_um), count)
}

/// Sum of squared residuals not in `outliers`, and how many.
fn sum_of_squares(residuals_um: &[f64], outliers: &[usize]) -> (f64, usize) {
    residuals_um
        .iter()
        .enumerate()
        .filter(|(k, _)| !outliers.contains(k))
        .fold((0.0, 0usize), |(s, n), (_, r)| (s + r * r, n + 1))
}

/// Probability of a chi-square this large or larger with `dof` degrees of freedom (the upper
/// tail, computed as such rather than as `1 - cdf`). `None` for zero degrees of freedom.
pub fn upper_tail(chi2: f64, dof: usize) -> Option<f64> {
    Some(ChiSquared::new(dof as f64).ok()?.sf(chi2))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    #[test]
    fn gaussian_residuals_at_the_declared_noise_pass_and_three_times_larger_fail() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(1);
        let g = Normal::new(0.0, 2.0).unwrap();
        let r: Vec<f64> = (0..2000).map(|_| g.sample(&mut rng)).collect();
        let m = chi_square(&r, 2.0, 36, &[]).unwrap();
        assert!(!m.inconsistent(), "{m:?}");
        assert!((m.chi2_per_dof - 1.0).abs() < 0.1);
        assert!(m.p_value > 1e-3);
        let m = chi_square(&r, 2.0 / 3.0, 36, &[]).unwrap();
        assert!(m.inconsistent(), "{m:?}");
        assert!((m.chi2_per_dof - 9.0).abs() < 1.0);
    }

    #[test]
    fn outliers_are_left_out_and_no_dof_gives_none() {
        let mut r = vec![1.0; 50];
        r[3] = 1e3;
        let m = chi_square(&r, 1.0, 6, &[3]).unwrap();
        assert_eq!(m.outliers_left_out, 1);
        assert!(!m.inconsistent());
        assert!(chi_square(&r, 1.0, 6, &[]).unwrap().inconsistent());
        assert!(chi_square(&r, 1.0, 50, &[]).is_none());
        assert!(chi_square(&r, 0.0, 6, &[]).is_none());
    }

    #[test]
    fn diagnostics_uses_the_same_rule() {
        let r: Vec<f64> = (0..80).map(|k| (k as f64 * 0.7).sin() * 2.5).collect();
        let m = chi_square(&r, 2.0, 30, &[]).unwrap();
        let d = crate::diagnostics::diagnose(&r, m.dof, Some(2.0), &[], 0.05);
        assert_eq!(d.chi2, Some(m.chi2));
        assert_eq!(d.chi2_p, Some(m.p_value));
    }
}
