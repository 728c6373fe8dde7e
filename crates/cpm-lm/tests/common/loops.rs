//! A problem shaped like an implicit-loop calibration of a hexapod: `blocks` poses of 6 local
//! parameters (translation and small rotation), 36 global parameters (per leg, a base and
//! a platform joint offset), 22 residuals per pose (6 leg lengths that see the pose and the
//! globals of their leg, 16 distance sensors that see the pose only), 168 Jacobian entries
//! per pose. The pattern is listed row by row in CSR order, as a calibration builds it.
//! Shared by the Schur tests, the benchmarks and the `schur_memory` example
//! (`#[path]`-included).
#![allow(dead_code)]

use cpm_lm::{Damping, LinearSolver, ModelError, Options, Problem, SparseJacobian};

pub const LOCAL: usize = 6;

/// Options for `blocks` poses: the Schur solver over the pose blocks, `damping`, default
/// tolerances, no statistics.
pub fn schur_options(blocks: usize, damping: Damping) -> Options {
    Options {
        damping,
        linear_solver: LinearSolver::Schur {
            local_block_sizes: vec![LOCAL; blocks],
        },
        statistics: cpm_lm::StatisticsMode::Off,
        ..Options::default()
    }
}
pub const GLOBAL: usize = 36;
pub const LEGS: usize = 6;
pub const SENSORS: usize = 16;
pub const ROWS: usize = LEGS + SENSORS;

type V3 = [f64; 3];

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn norm(a: V3) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}
fn v3(s: &[f64]) -> V3 {
    [s[0], s[1], s[2]]
}

/// Deterministic pseudo-random numbers in `[-1, 1)` (SplitMix64).
pub struct Rng(u64);
impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }
    pub fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

/// The calibration-shaped problem.
pub struct Loops {
    pub blocks: usize,
    /// Nominal pose of each block, position and rotation (the local parameters correct it).
    centre: Vec<V3>,
    rotation: Vec<[V3; 3]>,
    base: [V3; LEGS],
    platform: [V3; LEGS],
    sensor_platform: [V3; SENSORS],
    sensor_base: [V3; SENSORS],
    y: Vec<f64>,
    /// The parameters the data were simulated with.
    pub truth: Vec<f64>,
    /// Stream the pattern through `visit_pattern` instead of building the list.
    pub stream_pattern: bool,
}

impl Loops {
    pub fn new(blocks: usize, seed: u64) -> Self {
        let mut rng = Rng::new(seed);
        let ring = |radius: f64, z: f64, k: usize, count: usize| -> V3 {
            let a = 2.0 * std::f64::consts::PI * k as f64 / count as f64;
            [radius * a.cos(), radius * a.sin(), z]
        };
        let base = std::array::from_fn(|i| ring(300.0, 0.0, i, LEGS));
        let platform = std::array::from_fn(|i| ring(150.0, 0.0, i, LEGS));
        let sensor_platform =
            std::array::from_fn(|j| ring(120.0, 10.0 * (j % 3) as f64, j, SENSORS));
        let sensor_base =
            std::array::from_fn(|j| ring(350.0, -50.0 + 20.0 * (j % 4) as f64, j, SENSORS));
        let centre = (0..blocks)
            .map(|_| {
                [
                    50.0 * rng.next(),
                    50.0 * rng.next(),
                    400.0 + 30.0 * rng.next(),
                ]
            })
            .collect();
        // Rotations up to about 20 degrees about random axes (Rodrigues' formula).
        let rotation = (0..blocks)
            .map(|_| {
                let w = [0.35 * rng.next(), 0.35 * rng.next(), 0.35 * rng.next()];
                let th = norm(w);
                let k = [w[0] / th, w[1] / th, w[2] / th];
                let (s, c) = th.sin_cos();
                std::array::from_fn(|r| {
                    std::array::from_fn(|col| {
                        let id = if r == col { 1.0 } else { 0.0 };
                        let kx = [[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]];
                        let kk: f64 = (0..3).map(|m| kx[r][m] * kx[m][col]).sum();
                        id + s * kx[r][col] + (1.0 - c) * kk
                    })
                })
            })
            .collect();
        let n = blocks * LOCAL + GLOBAL;
        let truth: Vec<f64> = (0..n)
            .map(|p| {
                if p < blocks * LOCAL {
                    if p % LOCAL < 3 {
                        0.05 * rng.next()
                    } else {
                        2e-4 * rng.next()
                    }
                } else {
                    0.5 * rng.next()
                }
            })
            .collect();
        let mut p = Self {
            blocks,
            centre,
            rotation,
            base,
            platform,
            sensor_platform,
            sensor_base,
            y: vec![0.0; blocks * ROWS],
            truth: Vec::new(),
            stream_pattern: false,
        };
        let mut y = vec![0.0; blocks * ROWS];
        p.eval(&truth, Some(&mut y), None);
        for v in &mut y {
            *v += 1e-3 * rng.next();
        }
        p.y = y;
        p.truth = truth;
        p
    }

    /// Residuals and, when `jac` is given, the Jacobian values in pattern order.
    fn eval(&self, x: &[f64], mut r: Option<&mut [f64]>, mut jac: Option<&mut [f64]>) {
        let g = &x[self.blocks * LOCAL..];
        let mut v = 0;
        for k in 0..self.blocks {
            let l = &x[k * LOCAL..(k + 1) * LOCAL];
            let (t, w) = (v3(&l[..3]), v3(&l[3..]));
            let c = add(self.centre[k], t);
            let rot = &self.rotation[k];
            let rotate = |v: V3| -> V3 {
                std::array::from_fn(|r| rot[r][0] * v[0] + rot[r][1] * v[1] + rot[r][2] * v[2])
            };
            let rotate_t = |v: V3| -> V3 {
                std::array::from_fn(|r| rot[0][r] * v[0] + rot[1][r] * v[1] + rot[2][r] * v[2])
            };
            // Leg i: v = R (a + ga), q = c + v + w x v - (b + gb), r = |q| - y.
            for i in 0..LEGS {
                let a = rotate(add(self.platform[i], v3(&g[6 * i + 3..6 * i + 6])));
                let b = add(self.base[i], v3(&g[6 * i..6 * i + 3]));
                let q = sub(add(add(c, a), cross(w, a)), b);
                let len = norm(q);
                let row = k * ROWS + i;
                if let Some(r) = r.as_deref_mut() {
                    r[row] = len - self.y[row];
                }
                if let Some(j) = jac.as_deref_mut() {
                    let u = [q[0] / len, q[1] / len, q[2] / len];
                    let dw = cross(a, u);
                    let da = rotate_t(sub(u, cross(w, u)));
                    j[v..v + 3].copy_from_slice(&u);
                    j[v + 3..v + 6].copy_from_slice(&dw);
                    j[v + 6..v + 9].copy_from_slice(&[-u[0], -u[1], -u[2]]);
                    j[v + 9..v + 12].copy_from_slice(&da);
                    v += 12;
                }
            }
            // Sensor s: v = R s, q = c + v + w x v - e, r = |q| - y.
            for s in 0..SENSORS {
                let a = rotate(self.sensor_platform[s]);
                let q = sub(add(add(c, a), cross(w, a)), self.sensor_base[s]);
                let len = norm(q);
                let row = k * ROWS + LEGS + s;
                if let Some(r) = r.as_deref_mut() {
                    r[row] = len - self.y[row];
                }
                if let Some(j) = jac.as_deref_mut() {
                    let u = [q[0] / len, q[1] / len, q[2] / len];
                    j[v..v + 3].copy_from_slice(&u);
                    j[v + 3..v + 6].copy_from_slice(&cross(a, u));
                    v += 6;
                }
            }
        }
    }

    /// The pattern, row by row.
    fn entries(&self, visit: &mut dyn FnMut(usize, usize)) {
        let g0 = self.blocks * LOCAL;
        for k in 0..self.blocks {
            for i in 0..LEGS {
                let row = k * ROWS + i;
                (0..LOCAL).for_each(|c| visit(row, k * LOCAL + c));
                (0..6).for_each(|c| visit(row, g0 + 6 * i + c));
            }
            for s in 0..SENSORS {
                let row = k * ROWS + LEGS + s;
                (0..LOCAL).for_each(|c| visit(row, k * LOCAL + c));
            }
        }
    }

    /// Number of Jacobian entries.
    pub fn nnz(&self) -> usize {
        self.blocks * (LEGS * (LOCAL + 6) + SENSORS * LOCAL)
    }
}

impl Problem for Loops {
    fn num_params(&self) -> usize {
        self.blocks * LOCAL + GLOBAL
    }
    fn num_residuals(&self) -> usize {
        self.blocks * ROWS
    }
    fn residuals(&mut self, x: &[f64], r: &mut [f64]) -> Result<(), ModelError> {
        self.eval(x, Some(r), None);
        Ok(())
    }
}

impl SparseJacobian for Loops {
    fn pattern(&self) -> Vec<(usize, usize)> {
        let mut p = Vec::with_capacity(self.nnz());
        self.entries(&mut |r, c| p.push((r, c)));
        p
    }
    fn visit_pattern(&self, visit: &mut dyn FnMut(usize, usize)) {
        if self.stream_pattern {
            self.entries(visit);
        } else {
            for (r, c) in self.pattern() {
                visit(r, c);
            }
        }
    }
    fn jacobian_values(&mut self, x: &[f64], values: &mut [f64]) -> Result<(), ModelError> {
        self.eval(x, None, Some(values));
        Ok(())
    }
}
