//! Observability indices of an identification Jacobian and the selection criteria built on them.
//!
//! With `J` the identification Jacobian (readings x parameters, um of reading per um of error)
//! and `s_1 >= ... >= s_n` its singular values, the classical indices are
//! (Borm & Menq 1991, Driels & Pathre 1990, Nahvi & Hollerbach 1996):
//!
//! | index | definition | larger is better | design criterion |
//! |---|---|---|---|
//! | O1 | `(s_1 ... s_n)^(1/n)`, the geometric mean (reported with its log) | yes | D-optimal: `log det J^T J = 2 sum ln s_i` |
//! | O2 | `s_1 / s_n`, the condition number | no | |
//! | O3 | `s_n`, the minimum singular value | yes | E-optimal |
//! | O4 | `s_n^2 / s_1`, the noise amplification index | yes | |
//!
//! With sensor noise of standard deviation `sigma`, the Cramér-Rao covariance of the errors is
//! `sigma^2 (J^T J)^-1`: the worst combination has standard deviation `sigma / s_n`, and the
//! root mean square of the per-parameter standard deviations is
//! `sigma sqrt(trace (J^T J)^-1 / n)`, which A-optimal designs minimise.
//!
//! ```
//! use cpm_calib::design::indices::observability_indices;
//! use nalgebra::DMatrix;
//! // Two readings of each of two parameters, one of them half as sensitive.
//! let j = DMatrix::from_row_slice(4, 2, &[1.0, 0.0, 1.0, 0.0, 0.0, 0.5, 0.0, 0.5]);
//! let ix = observability_indices(&j, 1.0);
//! assert_eq!(ix.rank, 2);
//! assert!((ix.o2_condition - 2.0).abs() < 1e-12);
//! assert!((ix.crlb_worst_um - 2f64.sqrt()).abs() < 1e-12); // sigma / s_min, s_min = 1/sqrt(2)
//! ```
use crate::fit::identify::rms;
use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

/// Singular values below this times the largest count as zero (as [`crate::RankOptions`]).
pub const RANK_RTOL: f64 = 1e-4;

/// The optimality criterion a design maximises.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum Criterion {
    /// D-optimal: maximise `log det J^T J` (O1). Invariant to the scaling of the parameters.
    DOptimal,
    /// A-optimal: minimise `trace (J^T J)^-1`, the sum of the parameters' Cramér-Rao
    /// variances (per unit noise), i.e. the RMS Cramér-Rao standard deviation. Default: it is
    /// the figure an installation-error calibration is judged by.
    #[default]
    AOptimal,
    /// E-optimal: maximise the smallest eigenvalue of `J^T J` (O3 squared): the worst
    /// direction. Not smooth; its selection evaluates every candidate with an eigen
    /// decomposition, so it is much slower than D and A.
    EOptimal,
}

impl Criterion {
    /// Short name: `D`, `A` or `E`.
    pub fn name(&self) -> &'static str {
        match self {
            Criterion::DOptimal => "D",
            Criterion::AOptimal => "A",
            Criterion::EOptimal => "E",
        }
    }

    /// The criterion's value for an information matrix `J^T J` (larger is better):
    /// `log det M` (D), `-trace M^-1` (A), `lambda_min(M)` (E). Singular matrices give
    /// `-inf` for D and A.
    pub fn value(&self, information: &DMatrix<f64>) -> f64 {
        match self {
            Criterion::DOptimal => match information.clone().cholesky() {
                Some(c) => 2.0 * c.l().diagonal().iter().map(|d| d.ln()).sum::<f64>(),
                None => f64::NEG_INFINITY,
            },
            Criterion::AOptimal => match information.clone().cholesky() {
                Some(c) => -c.inverse().trace(),
                None => f64::NEG_INFINITY,
            },
            Criterion::EOptimal => information
                .clone()
                .symmetric_eigenvalues()
                .iter()
                .copied()
                .fold(f64::INFINITY, f64::min),
        }
    }
}

/// Observability indices and Cramér-Rao figures of a design (see the module doc).
///
/// Singular designs (rank below the number of parameters) have `o2_condition`,
/// `crlb_worst_um`, `crlb_rms_um` and `crlb_max_um` infinite (serialised as `null`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObservabilityIndices {
    /// Number of parameters.
    pub num_params: usize,
    /// Number of readings.
    pub num_readings: usize,
    /// Numerical rank (singular values above [`RANK_RTOL`] times the largest).
    pub rank: usize,
    /// Singular values, descending.
    pub singular_values: Vec<f64>,
    /// O1 as a logarithm: `mean ln s_i` (`-inf` when singular).
    pub o1_log_geometric_mean: f64,
    /// O1: the geometric mean of the singular values, `exp(o1_log_geometric_mean)`.
    pub o1_geometric_mean: f64,
    /// O1 normalised by the number of readings, `O1 / sqrt(m)` (Borm & Menq's form): compares
    /// designs of different sizes.
    pub o1_per_reading: f64,
    /// O2: the condition number `s_max / s_min`.
    pub o2_condition: f64,
    /// O3: the minimum singular value.
    pub o3_min_singular: f64,
    /// O4: the noise amplification index `s_min^2 / s_max`.
    pub o4_noise_amplification: f64,
    /// Sensor noise assumed for the bounds, um.
    pub sigma_um: f64,
    /// Cramér-Rao standard deviation of the worst-determined combination, `sigma / s_min`, um.
    pub crlb_worst_um: f64,
    /// Root mean square of the per-parameter Cramér-Rao standard deviations, um.
    pub crlb_rms_um: f64,
    /// Largest per-parameter Cramér-Rao standard deviation, um.
    pub crlb_max_um: f64,
    /// Per-parameter Cramér-Rao standard deviations, um (infinite when singular).
    pub crlb_std_um: Vec<f64>,
}

/// The indices of a Jacobian (readings x parameters, um per um) for noise `sigma_um`.
pub fn observability_indices(jacobian: &DMatrix<f64>, sigma_um: f64) -> ObservabilityIndices {
    let (m, n) = jacobian.shape();
    let information = jacobian.transpose() * jacobian;
    let mut ix = indices_from_information(&information, m, sigma_um);
    // Singular values from the SVD of J itself where it is cheap to have them exactly.
    if m > 0 && n > 0 {
        let mut sv: Vec<f64> = jacobian.singular_values().iter().copied().collect();
        sv.sort_by(|a, b| b.total_cmp(a));
        sv.resize(n, 0.0);
        fill_singular(&mut ix, sv);
    }
    ix
}

/// The indices from an information matrix `M = J^T J` of `num_readings` readings (the singular
/// values are the square roots of its eigenvalues).
pub fn indices_from_information(
    information: &DMatrix<f64>,
    num_readings: usize,
    sigma_um: f64,
) -> ObservabilityIndices {
    let n = information.nrows();
    let eig = information.clone().symmetric_eigen();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let sv: Vec<f64> = order
        .iter()
        .map(|&k| eig.eigenvalues[k].max(0.0).sqrt())
        .collect();
    let smax = sv.first().copied().unwrap_or(0.0);
    let rank = sv
        .iter()
        .filter(|&&s| s > RANK_RTOL * smax && s > 0.0)
        .count();
    let crlb_std_um: Vec<f64> = (0..n)
        .map(|k| {
            if rank < n {
                return f64::INFINITY;
            }
            let var: f64 = order
                .iter()
                .map(|&c| eig.eigenvectors[(k, c)].powi(2) / eig.eigenvalues[c])
                .sum();
            sigma_um * var.sqrt()
        })
        .collect();
    let mut ix = ObservabilityIndices {
        num_params: n,
        num_readings,
        rank,
        singular_values: Vec::new(),
        o1_log_geometric_mean: 0.0,
        o1_geometric_mean: 0.0,
        o1_per_reading: 0.0,
        o2_condition: 0.0,
        o3_min_singular: 0.0,
        o4_noise_amplification: 0.0,
        sigma_um,
        crlb_worst_um: 0.0,
        crlb_rms_um: rms(&crlb_std_um),
        crlb_max_um: crlb_std_um.iter().copied().fold(0.0, f64::max),
        crlb_std_um,
    };
    fill_singular(&mut ix, sv);
    ix
}

fn fill_singular(ix: &mut ObservabilityIndices, sv: Vec<f64>) {
    let n = sv.len();
    let smax = sv.first().copied().unwrap_or(0.0);
    let smin = sv.last().copied().unwrap_or(0.0);
    ix.rank = sv
        .iter()
        .filter(|&&s| s > RANK_RTOL * smax && s > 0.0)
        .count();
    let full = n > 0 && ix.rank == n;
    ix.o1_log_geometric_mean = if full {
        sv.iter().map(|s| s.ln()).sum::<f64>() / n as f64
    } else {
        f64::NEG_INFINITY
    };
    ix.o1_geometric_mean = ix.o1_log_geometric_mean.exp();
    ix.o1_per_reading = ix.o1_geometric_mean / (ix.num_readings.max(1) as f64).sqrt();
    ix.o2_condition = if full { smax / smin } else { f64::INFINITY };
    ix.o3_min_singular = if full { smin } else { 0.0 };
    ix.o4_noise_amplification = if full && smax > 0.0 {
        smin * smin / smax
    } else {
        0.0
    };
    ix.crlb_worst_um = if full {
        ix.sigma_um / smin
    } else {
        f64::INFINITY
    };
    if !full {
        ix.crlb_std_um.iter_mut().for_each(|v| *v = f64::INFINITY);
        ix.crlb_rms_um = f64::INFINITY;
        ix.crlb_max_um = f64::INFINITY;
    }
    ix.singular_values = sv;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn indices_of_a_diagonal_jacobian() {
        // Singular values 4, 2, 1 (one reading per parameter).
        let j = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![1.0, 4.0, 2.0]));
        let ix = observability_indices(&j, 2.0);
        assert_eq!(ix.singular_values, vec![4.0, 2.0, 1.0]);
        assert!((ix.o1_geometric_mean - 2.0).abs() < 1e-12);
        assert!((ix.o2_condition - 4.0).abs() < 1e-12);
        assert!((ix.o3_min_singular - 1.0).abs() < 1e-12);
        assert!((ix.o4_noise_amplification - 0.25).abs() < 1e-12);
        assert!((ix.crlb_worst_um - 2.0).abs() < 1e-12);
        // Per-parameter std: 2/1, 2/4, 2/2.
        let want = [2.0, 0.5, 1.0];
        for (a, b) in ix.crlb_std_um.iter().zip(want) {
            assert!((a - b).abs() < 1e-12);
        }
        assert!((ix.crlb_max_um - 2.0).abs() < 1e-12);
        assert!((ix.crlb_rms_um - ((4.0 + 0.25 + 1.0) / 3.0f64).sqrt()).abs() < 1e-12);
    }

    #[test]
    fn singular_designs_have_infinite_bounds() {
        let j = DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 2.0, 2.0]);
        let ix = observability_indices(&j, 1.0);
        assert_eq!(ix.rank, 1);
        assert!(ix.o2_condition.is_infinite());
        assert!(ix.crlb_rms_um.is_infinite());
        assert_eq!(
            Criterion::DOptimal.value(&(j.transpose() * &j)),
            f64::NEG_INFINITY
        );
    }

    #[test]
    fn criterion_values() {
        let m = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![4.0, 1.0]));
        assert!((Criterion::DOptimal.value(&m) - 4f64.ln()).abs() < 1e-12);
        assert!((Criterion::AOptimal.value(&m) + 1.25).abs() < 1e-12);
        assert!((Criterion::EOptimal.value(&m) - 1.0).abs() < 1e-12);
    }
}
