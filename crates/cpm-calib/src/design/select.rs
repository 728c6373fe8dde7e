//! Choosing poses: greedy addition and DETMAX-style exchange on the information matrix.
//!
//! A candidate pose contributes a block `J_c` of rows to the identification Jacobian (one row
//! per sensor read there), and the information matrix of a set `S` of poses is
//! `M = sum_{c in S} J_c^T J_c`. Adding or removing one pose changes `M` by a rank-k term, so
//! with `W = M^-1` kept up to date (Woodbury) the change of the criterion is a k x k problem:
//!
//! - D-optimal gain: `log det (I + J_c W J_c^T)`; loss on removal: `-log det (I - J_c W J_c^T)`;
//! - A-optimal gain (decrease of `trace W`): `trace (S^-1 B B^T)` with `B = J_c W`,
//!   `S = I + B J_c^T`; on removal `trace (T^-1 B B^T)`, `T = I - B J_c^T`;
//! - E-optimal: the change of `M`'s smallest eigenvalue, evaluated directly (slow).
//!
//! To start from nothing, `M` carries a tiny ridge `eps I` (relative to a typical block's
//! information), so directions nothing has seen yet are worth the most.
//!
//! 1. **Greedy**: add the candidate with the largest gain until `n` are chosen. Gains only
//!    fall as the set grows (exactly so for D, whose `log det` is submodular), so the search is
//!    *lazy*: stale gains are upper bounds and only the front-runner is re-evaluated.
//! 2. **Exchange** (Mitchell's DETMAX): add the best candidate, drop the worst member, keep the
//!    change when the criterion improves; when it does not, try longer excursions (add the 2,
//!    3, ... best in turn, then drop as many) up to `max_excursion`; stop when none improves.
//!
//! ```
//! use cpm_calib::design::select::{select_blocks, SelectOptions};
//! use cpm_calib::design::Criterion;
//! use nalgebra::DMatrix;
//! // Straight line y = a + b x, one reading per candidate x in [-1, 1]:
//! // the D-optimal pair is the two ends.
//! let xs: Vec<f64> = (0..11).map(|i| -1.0 + 0.2 * i as f64).collect();
//! let blocks: Vec<DMatrix<f64>> =
//!     xs.iter().map(|x| DMatrix::from_row_slice(1, 2, &[1.0, *x])).collect();
//! let opts = SelectOptions { criterion: Criterion::DOptimal, ..SelectOptions::default() };
//! let s = select_blocks(&blocks, 2, None, None, &opts).unwrap();
//! assert_eq!(s.chosen, vec![0, 10]);
//! ```
use std::collections::BinaryHeap;

use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::indices::Criterion;
use crate::CalibError;

/// Options of [`select_blocks`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SelectOptions {
    /// The criterion. Default A-optimal.
    pub criterion: Criterion,
    /// Improve the greedy set by exchange. Default true.
    pub exchange: bool,
    /// Most exchange rounds (excursions tried). Default 2000.
    pub max_exchanges: usize,
    /// Longest excursion: when adding the best and dropping the worst candidate no longer
    /// improves the criterion, DETMAX adds the 2, 3, ... best in turn and then drops as many,
    /// up to this many. Default 3.
    pub max_excursion: usize,
    /// Extra random starts, each improved by exchange; the best set is kept. Default 0.
    pub restarts: usize,
    /// Seed of the random starts. Default 1.
    pub seed: u64,
    /// Ridge added to the information matrix during the search, relative to the mean
    /// per-parameter information of one candidate. Default 1e-6.
    pub ridge: f64,
    /// An exchange must improve the criterion by at least this (relative for D's log det and
    /// A's trace) to continue. Default 1e-10.
    pub tolerance: f64,
}

impl Default for SelectOptions {
    fn default() -> Self {
        Self {
            criterion: Criterion::AOptimal,
            exchange: true,
            max_exchanges: 2000,
            max_excursion: 3,
            restarts: 0,
            seed: 1,
            ridge: 1e-6,
            tolerance: 1e-10,
        }
    }
}

/// The outcome of [`select_blocks`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Selection {
    /// Chosen candidate indices, ascending.
    pub chosen: Vec<usize>,
    /// Criterion value of the chosen set (without the search ridge, with the prior), see
    /// [`Criterion::value`].
    pub value: f64,
    /// Criterion value after the greedy phase (or of the start set).
    pub greedy_value: f64,
    /// Excursions that improved the criterion.
    pub exchanges: usize,
    /// Candidate gain or loss evaluations.
    pub evaluations: usize,
}

/// Information matrix `sum J_c^T J_c` of the chosen blocks.
pub fn information(blocks: &[DMatrix<f64>], chosen: &[usize]) -> DMatrix<f64> {
    let n = blocks.first().map_or(0, |b| b.ncols());
    let mut m = DMatrix::zeros(n, n);
    for &c in chosen {
        m += blocks[c].transpose() * &blocks[c];
    }
    m
}

struct State {
    criterion: Criterion,
    m: DMatrix<f64>,
    w: DMatrix<f64>,
    since_refresh: usize,
}

impl State {
    fn new(criterion: Criterion, m: DMatrix<f64>) -> Result<Self, CalibError> {
        let mut s = State {
            criterion,
            w: m.clone(),
            m,
            since_refresh: 0,
        };
        s.refresh()?;
        Ok(s)
    }

    fn refresh(&mut self) -> Result<(), CalibError> {
        let c = self.m.clone().cholesky().ok_or_else(|| {
            CalibError::NoInformation(
                "the information matrix of the design lost positive definiteness".into(),
            )
        })?;
        self.w = c.inverse();
        self.since_refresh = 0;
        Ok(())
    }

    fn min_eig(m: &DMatrix<f64>) -> f64 {
        m.clone()
            .symmetric_eigenvalues()
            .iter()
            .copied()
            .fold(f64::INFINITY, f64::min)
    }

    /// Gain (sign +1) or loss (sign -1) of adding or removing block `j`; the loss is the
    /// decrease of the criterion. Infinite loss when removal would make `M` singular.
    fn change(&self, j: &DMatrix<f64>, sign: f64) -> f64 {
        let k = j.nrows();
        if let Criterion::EOptimal = self.criterion {
            let jtj = j.transpose() * j;
            let now = Self::min_eig(&self.m);
            let then = Self::min_eig(&(&self.m + jtj * sign));
            return sign * (then - now);
        }
        let b = j * &self.w; // k x n
        let mut s = &b * j.transpose() * sign; // k x k
        for d in 0..k {
            s[(d, d)] += 1.0;
        }
        let Some(ch) = s.cholesky() else {
            return if sign > 0.0 { 0.0 } else { f64::INFINITY };
        };
        match self.criterion {
            Criterion::DOptimal => {
                let ld = 2.0 * ch.l().diagonal().iter().map(|d| d.ln()).sum::<f64>();
                sign * ld
            }
            _ => {
                let x = ch.solve(&b);
                x.component_mul(&b).sum()
            }
        }
    }

    fn update(&mut self, j: &DMatrix<f64>, sign: f64) -> Result<(), CalibError> {
        let k = j.nrows();
        self.m += j.transpose() * j * sign;
        self.since_refresh += 1;
        if self.since_refresh >= 16 {
            return self.refresh();
        }
        let b = j * &self.w;
        let mut s = &b * j.transpose() * sign;
        for d in 0..k {
            s[(d, d)] += 1.0;
        }
        match s.cholesky() {
            Some(ch) => {
                let x = ch.solve(&b);
                self.w -= b.transpose() * x * sign;
                Ok(())
            }
            None => self.refresh(),
        }
    }
}

/// Stale candidates re-evaluated together in the lazy greedy phase.
const LAZY_BATCH: usize = 32;

#[derive(PartialEq)]
struct Entry(f64, usize);
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Entry {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        // Larger gain first; ties to the lower index.
        self.0
            .total_cmp(&other.0)
            .then_with(|| other.1.cmp(&self.1))
    }
}

/// Chooses `n` of the candidate blocks (rows x parameters each, same parameters) to maximise
/// the criterion of `prior + sum J_c^T J_c`. `start`, when given, replaces the greedy phase
/// (it must hold `n` distinct indices). Each candidate is used at most once. With
/// `options.restarts`, random starts are exchanged too and the best set is kept.
pub fn select_blocks(
    blocks: &[DMatrix<f64>],
    n: usize,
    prior: Option<&DMatrix<f64>>,
    start: Option<&[usize]>,
    options: &SelectOptions,
) -> Result<Selection, CalibError> {
    let np = blocks
        .first()
        .map(|b| b.ncols())
        .ok_or_else(|| CalibError::invalid("candidates", "none given"))?;
    if let Some((i, b)) = blocks.iter().enumerate().find(|(_, b)| b.ncols() != np) {
        return Err(CalibError::invalid(
            "candidates",
            format!(
                "block {} has {} columns, the first has {np}",
                i + 1,
                b.ncols()
            ),
        ));
    }
    if n == 0 || n > blocks.len() {
        return Err(CalibError::invalid(
            "n",
            format!("{n}: must be between 1 and the {} candidates", blocks.len()),
        ));
    }
    if let Some(p) = prior {
        if p.shape() != (np, np) {
            return Err(CalibError::invalid(
                "prior",
                format!("{:?}, expected {np} x {np}", p.shape()),
            ));
        }
    }
    if !(options.ridge.is_finite() && options.ridge > 0.0) {
        return Err(CalibError::invalid("ridge", "must be finite and > 0"));
    }
    // Sequential, so that the ridge (and hence every tie) does not depend on thread timing.
    let scale = blocks.iter().map(|b| b.norm_squared()).sum::<f64>() / (blocks.len() * np) as f64;
    let eps = options.ridge * scale.max(f64::MIN_POSITIVE);
    let mut base = prior.cloned().unwrap_or_else(|| DMatrix::zeros(np, np));
    for d in 0..np {
        base[(d, d)] += eps;
    }
    let mut evaluations = 0usize;
    let first = match start {
        Some(s) => {
            if s.len() != n {
                return Err(CalibError::invalid(
                    "start",
                    format!("{} indices, expected {n}", s.len()),
                ));
            }
            let mut chosen = vec![false; blocks.len()];
            for &c in s {
                if c >= blocks.len() || chosen[c] {
                    return Err(CalibError::invalid(
                        "start",
                        format!("index {c} out of range or repeated"),
                    ));
                }
                chosen[c] = true;
            }
            chosen
        }
        None => greedy(blocks, n, &base, options.criterion, &mut evaluations)?,
    };
    let greedy_value = value_of(blocks, &first, prior, options.criterion);
    let (mut best, mut exchanges) = exchange(blocks, n, &base, first, options, &mut evaluations)?;
    let mut value = value_of(blocks, &best, prior, options.criterion);
    let mut rng = rand::rngs::StdRng::seed_from_u64(options.seed);
    for _ in 0..options.restarts {
        let mut idx: Vec<usize> = (0..blocks.len()).collect();
        for i in 0..n {
            let j = rng.random_range(i..idx.len());
            idx.swap(i, j);
        }
        let mut chosen = vec![false; blocks.len()];
        for &c in &idx[..n] {
            chosen[c] = true;
        }
        let mut m = base.clone();
        for &c in &idx[..n] {
            m += blocks[c].transpose() * &blocks[c];
        }
        if m.clone().cholesky().is_none() {
            continue;
        }
        let (set, ex) = exchange(blocks, n, &base, chosen, options, &mut evaluations)?;
        let v = value_of(blocks, &set, prior, options.criterion);
        if v > value {
            best = set;
            value = v;
            exchanges = ex;
        }
    }
    Ok(Selection {
        chosen: (0..blocks.len()).filter(|i| best[*i]).collect(),
        value,
        greedy_value,
        exchanges,
        evaluations,
    })
}

/// Lazy greedy addition of `n` candidates from nothing (information `base`).
fn greedy(
    blocks: &[DMatrix<f64>],
    n: usize,
    base: &DMatrix<f64>,
    criterion: Criterion,
    evaluations: &mut usize,
) -> Result<Vec<bool>, CalibError> {
    let mut state = State::new(criterion, base.clone())?;
    let mut chosen = vec![false; blocks.len()];
    let gains: Vec<f64> = blocks.par_iter().map(|b| state.change(b, 1.0)).collect();
    *evaluations += gains.len();
    let mut heap: BinaryHeap<Entry> = gains
        .into_iter()
        .enumerate()
        .map(|(i, g)| Entry(g, i))
        .collect();
    let mut picked = 0;
    let mut stamp = vec![0usize; blocks.len()];
    while picked < n {
        let Some(top) = heap.peek() else { break };
        let c = top.1;
        if stamp[c] == picked {
            heap.pop();
            chosen[c] = true;
            state.update(&blocks[c], 1.0)?;
            picked += 1;
            continue;
        }
        // Re-evaluate the stale front-runners together (in parallel).
        let mut stale = Vec::with_capacity(LAZY_BATCH);
        while stale.len() < LAZY_BATCH {
            match heap.peek() {
                Some(e) if stamp[e.1] != picked => stale.push(heap.pop().map_or(0, |e| e.1)),
                _ => break,
            }
        }
        let fresh: Vec<Entry> = stale
            .par_iter()
            .map(|&c| Entry(state.change(&blocks[c], 1.0), c))
            .collect();
        *evaluations += fresh.len();
        for e in fresh {
            stamp[e.1] = picked;
            heap.push(e);
        }
    }
    Ok(chosen)
}

/// DETMAX exchange from the set `chosen` (see the module doc); returns the improved set and
/// the number of improving excursions.
fn exchange(
    blocks: &[DMatrix<f64>],
    n: usize,
    base: &DMatrix<f64>,
    mut chosen: Vec<bool>,
    options: &SelectOptions,
    evaluations: &mut usize,
) -> Result<(Vec<bool>, usize), CalibError> {
    let mut exchanges = 0;
    if !options.exchange || n >= blocks.len() {
        return Ok((chosen, 0));
    }
    let mut m = base.clone();
    for (c, _) in chosen.iter().enumerate().filter(|(_, k)| **k) {
        m += blocks[c].transpose() * &blocks[c];
    }
    let mut state = State::new(options.criterion, m)?;
    let mut current = options.criterion.value(&state.m);
    let mut k = 1;
    let mut rounds = 0;
    while k <= options.max_excursion.min(blocks.len() - n) && rounds < options.max_exchanges {
        rounds += 1;
        let saved = (chosen.clone(), state.m.clone(), state.w.clone());
        // Excursion: add the k best, one at a time, then drop the k worst.
        for _ in 0..k {
            let best = blocks
                .par_iter()
                .enumerate()
                .filter(|(i, _)| !chosen[*i])
                .map(|(i, b)| Entry(state.change(b, 1.0), i))
                .max();
            *evaluations += blocks.len() - n;
            let Some(Entry(_, add)) = best else { break };
            chosen[add] = true;
            state.update(&blocks[add], 1.0)?;
        }
        let mut size = chosen.iter().filter(|c| **c).count();
        while size > n {
            let members: Vec<usize> = (0..blocks.len()).filter(|i| chosen[*i]).collect();
            *evaluations += members.len();
            let worst = members
                .par_iter()
                .map(|&i| Entry(-state.change(&blocks[i], -1.0), i))
                .max();
            let Some(Entry(_, drop)) = worst else { break };
            chosen[drop] = false;
            state.update(&blocks[drop], -1.0)?;
            size -= 1;
        }
        state.refresh()?;
        let next = options.criterion.value(&state.m);
        if next - current > options.tolerance * current.abs().max(1e-300) {
            exchanges += 1;
            current = next;
            k = 1;
        } else {
            // No gain: undo, and try a longer excursion.
            chosen = saved.0;
            state.m = saved.1;
            state.w = saved.2;
            k += 1;
        }
    }
    Ok((chosen, exchanges))
}

fn value_of(
    blocks: &[DMatrix<f64>],
    chosen: &[bool],
    prior: Option<&DMatrix<f64>>,
    criterion: Criterion,
) -> f64 {
    let idx: Vec<usize> = (0..blocks.len()).filter(|i| chosen[*i]).collect();
    let mut m = information(blocks, &idx);
    if let Some(p) = prior {
        m += p;
    }
    criterion.value(&m)
}
