//! Registration of tracker (motion-capture) frames and rough link reading offsets, in closed
//! form then by a few Gauss-Newton steps, before any fit.
//!
//! A tracker logs the platform pose in its own frame, some tens to hundreds of millimetres and
//! a few degrees away from the base frame, and the link readings of a machine are often known
//! only up to a zero (motor revolutions, encoder counts). The calibration model handles only
//! small registrations (`tracker_frame`, um and urad) and small offsets (`link_offset`, um), so
//! the large part is found here from the data alone, against the nominal machine:
//!
//! 1. forward kinematics of the commanded lengths of every pose, nominal geometry;
//! 2. per session (one tracker file, one set-up of the instrument) the rigid transform that
//!    best maps these poses onto the measured ones: a weighted Procrustes (Horn / Umeyama)
//!    problem on positions and orientations together, solved by an SVD (nalgebra's fixed-size
//!    3x3 one, a start value only);
//! 3. Gauss-Newton on all session frames and one offset per link together (the offsets are
//!    a property of the machine, shared by every session), from the closed-form start, with
//!    forward kinematics re-run at every step. Offsets are left out when the poses cannot
//!    tell them from the frames (the scaled normal matrix's condition number is over 1e10).
//!
//! Each session frame `T = (R, t)` maps base coordinates into tracker coordinates,
//! `p_tracker = R p_base + t` (the convention of the `tracker_frame` effect). The standard
//! deviations come from the Gauss-Newton normal matrix scaled by the a-posteriori variance
//! factor (weighted residual sum of squares over its degrees of freedom): they include the
//! nominal model's misfit, not only the tracker's noise.
//!
//! ```
//! use cpm_calib::registration::{register, RegistrationOptions, Session};
//! use cpm_geometry::{JointTable, Pose};
//! let table = JointTable::paper_cubic();
//! let home = table.home;
//! let poses: Vec<Pose> = (0..8)
//!     .map(|k| {
//!         let a = k as f64;
//!         Pose::from_xyz_rpy_deg(
//!             [home.position_mm.x + 20.0 * a.sin(), home.position_mm.y + 15.0 * a.cos(), home.position_mm.z + 2.0 * a],
//!             [3.0 * (1.3 * a).sin(), 3.0 * (0.7 * a).cos(), 4.0 * (0.4 * a).sin()],
//!         )
//!     })
//!     .collect();
//! let lengths: Vec<Vec<f64>> = poses.iter().map(|p| cpm_kinematics::inverse_lengths(&table, p)).collect();
//! // The tracker is 100 mm and 5 degrees away.
//! let frame = Pose::from_xyz_rpy_deg([100.0, -40.0, 20.0], [1.0, -2.0, 5.0]);
//! let measured: Vec<Pose> = poses
//!     .iter()
//!     .map(|p| Pose::new(frame.rotation * p.position_mm + frame.position_mm, frame.rotation * p.rotation))
//!     .collect();
//! let r = register(&table, &[Session { lengths_mm: lengths, measured }], &RegistrationOptions::default()).unwrap();
//! assert!((r.frames[0].translation_mm - frame.position_mm).norm() < 1e-6);
//! assert!(r.frames[0].rms_after_mm < 1e-6);
//! ```
use cpm_geometry::rotation::left_jacobian_inverse;
use cpm_geometry::{JointTable, Pose};
use cpm_kinematics::{forward, ForwardOptions};
use nalgebra::{DMatrix, DVector, Matrix3, Rotation3, Vector3};

use crate::CalibError;

/// Options of [`register`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegistrationOptions {
    /// Standard deviation of a measured position coordinate, mm (weights positions against
    /// orientations). Default 0.01.
    pub position_sigma_mm: f64,
    /// Standard deviation of a measured orientation component, rad. Default 20e-6.
    pub orientation_sigma_rad: f64,
    /// Estimate one reading offset per link (the same for every session). Default true.
    pub estimate_link_offsets: bool,
    /// Most Gauss-Newton iterations. Default 30.
    pub max_iterations: usize,
    /// Forward kinematics options.
    pub fk: ForwardOptions,
}

impl Default for RegistrationOptions {
    fn default() -> Self {
        Self {
            position_sigma_mm: 0.01,
            orientation_sigma_rad: 20e-6,
            estimate_link_offsets: true,
            max_iterations: 30,
            fk: ForwardOptions::default(),
        }
    }
}

impl RegistrationOptions {
    fn check(&self) -> Result<(), CalibError> {
        for (v, name) in [
            (self.position_sigma_mm, "position_sigma_mm"),
            (self.orientation_sigma_rad, "orientation_sigma_rad"),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(CalibError::invalid(name, format!("{v}: must be > 0")));
            }
        }
        Ok(())
    }
}

/// One measurement session: the commanded link lengths of each pose (from the readings, mm)
/// and the pose the tracker measured there (tracker frame).
#[derive(Debug, Clone, PartialEq)]
pub struct Session {
    /// Commanded link lengths per pose, mm.
    pub lengths_mm: Vec<Vec<f64>>,
    /// Measured pose per pose, tracker frame.
    pub measured: Vec<Pose>,
}

/// The registration of one session's tracker frame: `p_tracker = rotation p_base +
/// translation_mm`.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame {
    /// Rotation from base to tracker axes.
    pub rotation: Rotation3<f64>,
    /// Base origin in the tracker frame, mm.
    pub translation_mm: Vector3<f64>,
    /// Standard deviation of each translation component, mm.
    pub translation_sd_mm: [f64; 3],
    /// Standard deviation of each component of a small rotation `exp(d) rotation` about the
    /// tracker's axes, deg.
    pub rotation_sd_deg: [f64; 3],
    /// RMS distance between measured positions and the nominal forward kinematics of the
    /// raw commanded lengths, before any registration, mm.
    pub rms_before_mm: f64,
    /// RMS distance after registration (frame and offsets), mm.
    pub rms_after_mm: f64,
    /// RMS orientation difference before registration, deg.
    pub orientation_rms_before_deg: f64,
    /// RMS orientation difference after registration, deg.
    pub orientation_rms_after_deg: f64,
    /// Poses of the session.
    pub poses: usize,
}

impl Frame {
    /// A measured pose (tracker frame) in the base frame: `T^-1 measured`.
    pub fn to_base(&self, measured: &Pose) -> Pose {
        let rt = self.rotation.inverse();
        Pose::new(
            rt * (measured.position_mm - self.translation_mm),
            rt * measured.rotation,
        )
    }

    /// The frame as a pose (tracker frame seen as a transform of base coordinates).
    pub fn as_pose(&self) -> Pose {
        Pose::new(self.translation_mm, self.rotation)
    }

    /// Rotation angle, deg.
    pub fn rotation_angle_deg(&self) -> f64 {
        cpm_geometry::rotation::log(&self.rotation)
            .norm()
            .to_degrees()
    }

    /// Rotation vector (axis times angle), deg.
    pub fn rotation_vector_deg(&self) -> [f64; 3] {
        let w = cpm_geometry::rotation::log(&self.rotation);
        [w.x.to_degrees(), w.y.to_degrees(), w.z.to_degrees()]
    }
}

/// The result of [`register`].
#[derive(Debug, Clone, PartialEq)]
pub struct Registration {
    /// One frame per session, in order.
    pub frames: Vec<Frame>,
    /// Reading offset per link, mm: the true length is the commanded length plus this
    /// (zeros when not estimated).
    pub link_offset_mm: Vec<f64>,
    /// Standard deviation of each link offset, mm (zeros when not estimated).
    pub link_offset_sd_mm: Vec<f64>,
    /// Whether the offsets were estimated (false when asked not to, or when the poses could
    /// not tell them from the frames).
    pub offsets_estimated: bool,
    /// A-posteriori variance factor: weighted residual sum of squares over its degrees of
    /// freedom (1 when the nominal machine and the declared noise explain the data).
    pub variance_factor: f64,
    /// Gauss-Newton iterations taken (trial steps of cpm-lm's engine).
    pub iterations: usize,
    /// How the Gauss-Newton iteration ended (`None` when `max_iterations` is 0).
    pub termination: Option<cpm_lm::TerminationReason>,
}

/// Registers every session's tracker frame and, optionally, one reading offset per link (see
/// the module documentation). Poses are given per session; errors name the pose by its index
/// counted over all sessions in order.
pub fn register(
    table: &JointTable,
    sessions: &[Session],
    options: &RegistrationOptions,
) -> Result<Registration, CalibError> {
    register_with_corrections(table, sessions, options, &|_: &Pose| {
        vec![0.0; table.num_links()]
    })
}

/// [`register`] with a correction of the link lengths (mm) that depends on the pose (base
/// frame), added to the commanded lengths before forward kinematics: the joint clearance
/// shift of the measurement model, say (`MeasurementModel::clearance`), evaluated at the
/// current estimate of each pose.
pub fn register_with_corrections(
    table: &JointTable,
    sessions: &[Session],
    options: &RegistrationOptions,
    correction_mm: &dyn Fn(&Pose) -> Vec<f64>,
) -> Result<Registration, CalibError> {
    options.check()?;
    let n = table.num_links();
    if sessions.is_empty() || sessions.iter().any(|s| s.measured.is_empty()) {
        return Err(CalibError::NoInformation(
            "registration needs at least one pose per session".into(),
        ));
    }
    for s in sessions {
        if s.lengths_mm.len() != s.measured.len() || s.lengths_mm.iter().any(|l| l.len() != n) {
            return Err(CalibError::invalid(
                "lengths_mm",
                format!("one row of {n} lengths per measured pose"),
            ));
        }
    }
    // 1. Nominal forward kinematics of the raw lengths, from home (poses where it fails are
    // left out of the closed-form start).
    let mut fk: Vec<Vec<Option<Pose>>> = sessions
        .iter()
        .map(|s| {
            s.lengths_mm
                .iter()
                .map(|l| {
                    forward(table, l, &table.home, &options.fk)
                        .ok()
                        .map(|r| r.0)
                })
                .collect()
        })
        .collect();
    // 2. Closed-form frames.
    let w_rot = options.position_sigma_mm.powi(2) / (2.0 * options.orientation_sigma_rad.powi(2));
    let mut frames: Vec<RigidFrame> = Vec::with_capacity(sessions.len());
    let mut before = Vec::with_capacity(sessions.len());
    for (si, s) in sessions.iter().enumerate() {
        let pairs: Vec<(Pose, Pose)> = fk[si]
            .iter()
            .zip(&s.measured)
            .filter_map(|(p, q)| p.map(|p| (p, *q)))
            .collect();
        if pairs.is_empty() {
            return Err(CalibError::NoInformation(format!(
                "session {}: forward kinematics of the commanded lengths fails at every pose",
                si + 1
            )));
        }
        before.push(rms(&pairs));
        frames.push(procrustes(&pairs, w_rot));
    }
    // 3. Gauss-Newton on the frames and the offsets.
    let mut offsets = vec![0.0; n];
    let mut estimate_offsets = options.estimate_link_offsets;
    // Starting poses of forward kinematics: the registered measured poses.
    for (si, s) in sessions.iter().enumerate() {
        let (r, t) = frames[si];
        for (p, q) in fk[si].iter_mut().zip(&s.measured) {
            if p.is_none() {
                *p = Some(Pose::new(
                    r.inverse() * (q.position_mm - t),
                    r.inverse() * q.rotation,
                ));
            }
        }
    }
    // Which parameters the poses determine, at the closed-form start: the offsets are left
    // out when they cannot be told from the frames.
    loop {
        let lin = linearise(
            table,
            sessions,
            &frames,
            &offsets,
            &mut fk,
            options,
            correction_mm,
        )?;
        let np = 6 * sessions.len() + if estimate_offsets { n } else { 0 };
        let (js, _) = scaled_columns(&lin.jacobian, np);
        let (sv, _) = checked_svd(&js)?;
        let smax = sv.first().copied().unwrap_or(0.0);
        let smin = sv.last().copied().unwrap_or(0.0);
        if estimate_offsets && !(smin > 1e-5 * smax) {
            // The poses do not tell the offsets from the frames: register without them.
            estimate_offsets = false;
            offsets.iter_mut().for_each(|o| *o = 0.0);
            continue;
        }
        if !(smin > 1e-12 * smax) {
            return Err(CalibError::NoInformation(
                "the poses do not determine the tracker frame (too few, or all alike)".into(),
            ));
        }
        break;
    }
    // Gauss-Newton steps on cpm-lm's engine (Gauss-Newton while the steps gain well, then
    // Nielsen's damping) in the corrections `d` to the start: per session a translation
    // (mm) and a rotation `exp(d_w) R_0` (rad), then the offsets (mm). The Jacobian in `d`
    // is the one in a small rotation about the current frame times the left Jacobian of
    // SO(3) at `d_w`. Forward kinematics starts from the poses of the last Jacobian (the
    // last accepted point); a pose where it fails makes the trial's cost infinite (the step
    // is rejected).
    let mut problem = Frames {
        table,
        sessions,
        options,
        correction_mm,
        start: (frames.clone(), offsets.clone()),
        with_offsets: estimate_offsets,
        fk: fk.clone(),
    };
    let mut d = vec![0.0; cpm_lm::Problem::num_params(&problem)];
    let report = if options.max_iterations > 0 {
        let lm = cpm_lm::Options {
            max_iterations: options.max_iterations,
            statistics: cpm_lm::StatisticsMode::Off,
            evaporation_restart: None,
            ..cpm_lm::Options::normal_equations()
        };
        let lm = cpm_lm::Options {
            linear_solver: cpm_lm::LinearSolver::DenseQr,
            ..lm
        };
        Some(cpm_lm::minimize(&mut problem, &mut d, &lm)?)
    } else {
        None
    };
    (frames, offsets) = problem.at(&d);
    fk = problem.fk;
    let iterations = report.as_ref().map_or(0, |r| r.num_iterations());
    let termination = report.map(|r| r.termination);
    let lin = linearise(
        table,
        sessions,
        &frames,
        &offsets,
        &mut fk,
        options,
        correction_mm,
    )?;
    let cost = lin.residual.norm_squared();
    let np = 6 * sessions.len() + if estimate_offsets { n } else { 0 };
    let (js, scale) = scaled_columns(&lin.jacobian, np);
    let m = js.nrows();
    let np = js.ncols();
    let variance_factor = if m > np {
        cost / (m - np) as f64
    } else {
        f64::NAN
    };
    // Covariance of the scaled parameters: (Js^T Js)^-1 by the SVD.
    let (sv, vm) = checked_svd(&js)?;
    let sd = |k: usize| -> f64 {
        let mut v = 0.0;
        for (i, s) in sv.iter().enumerate() {
            v += (vm[(k, i)] / s).powi(2);
        }
        (v * variance_factor).sqrt() * scale[k]
    };
    let mut out_frames = Vec::with_capacity(sessions.len());
    for (si, s) in sessions.iter().enumerate() {
        let (r, t) = frames[si];
        let pairs: Vec<(Pose, Pose)> = fk[si]
            .iter()
            .zip(&s.measured)
            .map(|(p, q)| {
                let p = p.expect("forward kinematics ran");
                (Pose::new(r * p.position_mm + t, r * p.rotation), *q)
            })
            .collect();
        let after = rms(&pairs);
        out_frames.push(Frame {
            rotation: r,
            translation_mm: t,
            translation_sd_mm: [sd(6 * si), sd(6 * si + 1), sd(6 * si + 2)],
            rotation_sd_deg: [
                sd(6 * si + 3).to_degrees(),
                sd(6 * si + 4).to_degrees(),
                sd(6 * si + 5).to_degrees(),
            ],
            rms_before_mm: before[si].0,
            rms_after_mm: after.0,
            orientation_rms_before_deg: before[si].1,
            orientation_rms_after_deg: after.1,
            poses: s.measured.len(),
        });
    }
    let k0 = 6 * sessions.len();
    Ok(Registration {
        frames: out_frames,
        link_offset_sd_mm: (0..n)
            .map(|i| if estimate_offsets { sd(k0 + i) } else { 0.0 })
            .collect(),
        link_offset_mm: offsets,
        offsets_estimated: estimate_offsets,
        variance_factor,
        iterations,
        termination,
    })
}

/// Forward-kinematics poses per session and pose (`None` where not yet solved).
type FkPoses = Vec<Vec<Option<Pose>>>;

/// The registration's least-squares problem for cpm-lm (see `register_with_corrections`):
/// corrections `d` to the start frames and offsets.
struct Frames<'a> {
    table: &'a JointTable,
    sessions: &'a [Session],
    options: &'a RegistrationOptions,
    correction_mm: &'a dyn Fn(&Pose) -> Vec<f64>,
    start: (Vec<RigidFrame>, Vec<f64>),
    with_offsets: bool,
    fk: FkPoses,
}
impl Frames<'_> {
    fn at(&self, d: &[f64]) -> (Vec<RigidFrame>, Vec<f64>) {
        let n = self.table.num_links();
        apply_step(&self.start.0, &self.start.1, d, 1.0, self.with_offsets, n)
    }
    /// The linearisation at `d`, and the poses forward kinematics found there.
    fn linearise(&self, d: &[f64]) -> Result<(Linearised, FkPoses), CalibError> {
        let (f, o) = self.at(d);
        let mut fk = self.fk.clone();
        let lin = linearise(
            self.table,
            self.sessions,
            &f,
            &o,
            &mut fk,
            self.options,
            self.correction_mm,
        )?;
        Ok((lin, fk))
    }
}
impl cpm_lm::Problem for Frames<'_> {
    fn num_params(&self) -> usize {
        6 * self.sessions.len()
            + if self.with_offsets {
                self.table.num_links()
            } else {
                0
            }
    }
    fn num_residuals(&self) -> usize {
        self.sessions.iter().map(|s| 6 * s.measured.len()).sum()
    }
    fn residuals(&mut self, d: &[f64], r: &mut [f64]) -> Result<(), cpm_lm::ModelError> {
        match self.linearise(d) {
            Ok((lin, _)) => r.copy_from_slice(lin.residual.as_slice()),
            Err(CalibError::Kinematics { .. }) => r.fill(f64::INFINITY),
            Err(e) => return Err(e.into()),
        }
        Ok(())
    }
}
impl cpm_lm::DenseJacobian for Frames<'_> {
    fn jacobian(
        &mut self,
        d: &[f64],
        mut jac: cpm_lm::faer::MatMut<'_, f64>,
    ) -> Result<(), cpm_lm::ModelError> {
        let (lin, fk) = self.linearise(d)?;
        self.fk = fk;
        for c in 0..jac.ncols() {
            for i in 0..jac.nrows() {
                jac[(i, c)] = lin.jacobian[(i, c)];
            }
        }
        // Rotations: d/d(d_w) = (d/d small rotation) J_l(d_w).
        for si in 0..self.sessions.len() {
            let w = Vector3::new(d[6 * si + 3], d[6 * si + 4], d[6 * si + 5]);
            let (th, k) = (w.norm(), w.cross_matrix());
            let jl = if th < 1e-8 {
                Matrix3::identity() + k * 0.5 + k * k / 6.0
            } else {
                Matrix3::identity()
                    + k * ((1.0 - th.cos()) / (th * th))
                    + k * k * ((th - th.sin()) / (th * th * th))
            };
            for i in 0..jac.nrows() {
                let row: Vec<f64> = (0..3).map(|b| lin.jacobian[(i, 6 * si + 3 + b)]).collect();
                for a in 0..3 {
                    jac[(i, 6 * si + 3 + a)] = (0..3).map(|b| row[b] * jl[(b, a)]).sum();
                }
            }
        }
        Ok(())
    }
}

/// RMS position distance (mm) and orientation angle (deg) between predicted and measured.
fn rms(pairs: &[(Pose, Pose)]) -> (f64, f64) {
    let k = pairs.len().max(1) as f64;
    let p = pairs
        .iter()
        .map(|(a, b)| (a.position_mm - b.position_mm).norm_squared())
        .sum::<f64>();
    let o = pairs
        .iter()
        .map(|(a, b)| {
            cpm_geometry::rotation::log(&(a.rotation * b.rotation.inverse())).norm_squared()
        })
        .sum::<f64>();
    ((p / k).sqrt(), (o / k).sqrt().to_degrees())
}

/// The rigid transform `(R, t)` minimising `sum |q - (R p + t)|^2 + w_rot sum |R R_p -
/// R_q|_F^2` over pairs `(p, q)` (weighted Procrustes / Umeyama, by an SVD).
fn procrustes(pairs: &[(Pose, Pose)], w_rot: f64) -> (Rotation3<f64>, Vector3<f64>) {
    let k = pairs.len() as f64;
    let pbar = pairs
        .iter()
        .map(|(p, _)| p.position_mm)
        .sum::<Vector3<f64>>()
        / k;
    let qbar = pairs
        .iter()
        .map(|(_, q)| q.position_mm)
        .sum::<Vector3<f64>>()
        / k;
    let mut m = Matrix3::zeros();
    for (p, q) in pairs {
        m += (q.position_mm - qbar) * (p.position_mm - pbar).transpose();
        m += (q.rotation.matrix() * p.rotation.matrix().transpose()) * w_rot;
    }
    let svd = m.svd(true, true);
    let (u, vt) = (svd.u.expect("u"), svd.v_t.expect("v_t"));
    let d = (u * vt).determinant().signum();
    let r = u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * vt;
    let r = Rotation3::from_matrix_unchecked(r);
    (r, qbar - r * pbar)
}

/// Singular values (largest first) and right singular vectors (`n x min(m, n)`) of a finite
/// matrix, by the crate's accurate SVD ([`crate::linalg::svd_values_and_v`]: faer after an
/// exact power-of-two scaling; nalgebra's `try_svd` loses accuracy on small matrices, see
/// [`cpm_kinematics::linalg`]): an error, never a hang, for a non-finite matrix or no
/// convergence.
fn checked_svd(m: &DMatrix<f64>) -> Result<(Vec<f64>, DMatrix<f64>), CalibError> {
    if m.iter().any(|v| !v.is_finite()) {
        return Err(CalibError::invalid(
            "registration",
            "the Jacobian has non-finite entries (an implausible pose or robot)",
        ));
    }
    crate::linalg::svd_values_and_v(m).map_err(|_| {
        CalibError::invalid("registration", "the SVD of the Jacobian did not converge")
    })
}

/// The first `np` columns of `jac` scaled to unit norm, and the scale factors.
fn scaled_columns(jac: &DMatrix<f64>, np: usize) -> (DMatrix<f64>, Vec<f64>) {
    let mut js = jac.columns(0, np).into_owned();
    let scale: Vec<f64> = (0..np)
        .map(|k| {
            let v = js.column(k).norm();
            if v > 0.0 {
                1.0 / v
            } else {
                1.0
            }
        })
        .collect();
    for (k, s) in scale.iter().enumerate() {
        js.column_mut(k).scale_mut(*s);
    }
    (js, scale)
}

/// A session frame in the making: rotation and translation (mm).
type RigidFrame = (Rotation3<f64>, Vector3<f64>);

struct Linearised {
    residual: DVector<f64>,
    /// Columns: per session (translation mm, rotation rad), then the link offsets, mm.
    jacobian: DMatrix<f64>,
}

fn apply_step(
    frames: &[RigidFrame],
    offsets: &[f64],
    step: &[f64],
    lambda: f64,
    with_offsets: bool,
    n: usize,
) -> (Vec<RigidFrame>, Vec<f64>) {
    let f = frames
        .iter()
        .enumerate()
        .map(|(si, (r, t))| {
            let s = &step[6 * si..6 * si + 6];
            let d = Vector3::new(s[3], s[4], s[5]) * lambda;
            (
                Rotation3::new(d) * r,
                t + Vector3::new(s[0], s[1], s[2]) * lambda,
            )
        })
        .collect();
    let mut o = offsets.to_vec();
    if with_offsets {
        let k0 = 6 * frames.len();
        for i in 0..n {
            o[i] += step[k0 + i] * lambda;
        }
    }
    (f, o)
}

/// Weighted residuals (predicted minus measured) and their Jacobian at the given frames and
/// offsets; `fk` holds the starting poses of forward kinematics and receives the solutions.
fn linearise(
    table: &JointTable,
    sessions: &[Session],
    frames: &[RigidFrame],
    offsets: &[f64],
    fk: &mut [Vec<Option<Pose>>],
    options: &RegistrationOptions,
    correction_mm: &dyn Fn(&Pose) -> Vec<f64>,
) -> Result<Linearised, CalibError> {
    let n = table.num_links();
    let m: usize = sessions.iter().map(|s| 6 * s.measured.len()).sum();
    let np = 6 * sessions.len() + n;
    let mut residual = DVector::zeros(m);
    let mut jacobian = DMatrix::zeros(m, np);
    let (wp, wo) = (
        1.0 / options.position_sigma_mm,
        1.0 / options.orientation_sigma_rad,
    );
    let mut row = 0;
    let mut global = 0;
    for (si, s) in sessions.iter().enumerate() {
        let (r, t) = frames[si];
        for (j, q) in s.measured.iter().enumerate() {
            let start = fk[si][j].unwrap_or(table.home);
            let corr = correction_mm(&start);
            let lengths: Vec<f64> = s.lengths_mm[j]
                .iter()
                .zip(offsets)
                .zip(corr.iter().chain(std::iter::repeat(&0.0)))
                .map(|((l, o), c)| l + o + c)
                .collect();
            let (x, _) = forward(table, &lengths, &start, &options.fk).map_err(|source| {
                CalibError::Kinematics {
                    pose: global,
                    source,
                }
            })?;
            fk[si][j] = Some(x);
            let pred = r * x.position_mm + t;
            let rp = pred - q.position_mm;
            let w = cpm_geometry::rotation::log(&(r * x.rotation * q.rotation.inverse()));
            let jl = left_jacobian_inverse(&w);
            for a in 0..3 {
                residual[row + a] = rp[a] * wp;
                residual[row + 3 + a] = w[a] * wo;
            }
            // Frame columns.
            let c = 6 * si;
            let sk = -(r * x.position_mm).cross_matrix();
            for a in 0..3 {
                jacobian[(row + a, c + a)] = wp;
                for b in 0..3 {
                    jacobian[(row + a, c + 3 + b)] = sk[(a, b)] * wp;
                    jacobian[(row + 3 + a, c + 3 + b)] = jl[(a, b)] * wo;
                }
            }
            // Offset columns: the pose twist per unit length change, J1^-1 e_k.
            let links = cpm_kinematics::inverse(table, &x);
            let mut j1 = nalgebra::Matrix6::zeros();
            for (i, ls) in links.iter().enumerate() {
                let mm = ls.s_mm.cross(&ls.unit);
                j1.set_row(
                    i,
                    &nalgebra::Vector6::new(ls.unit.x, ls.unit.y, ls.unit.z, mm.x, mm.y, mm.z)
                        .transpose(),
                );
            }
            if n == 6 {
                if let Some(inv) = cpm_kinematics::lu6::try_inverse6(&j1) {
                    let k0 = 6 * sessions.len();
                    for i in 0..n {
                        let tw = inv.column(i);
                        let dp = r * Vector3::new(tw[0], tw[1], tw[2]);
                        let dw = jl * (r * Vector3::new(tw[3], tw[4], tw[5]));
                        for a in 0..3 {
                            jacobian[(row + a, k0 + i)] = dp[a] * wp;
                            jacobian[(row + 3 + a, k0 + i)] = dw[a] * wo;
                        }
                    }
                }
            }
            row += 6;
            global += 1;
        }
    }
    Ok(Linearised { residual, jacobian })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::{Distribution, Normal};

    fn hexapod() -> JointTable {
        JointTable::paper_cubic()
    }

    /// Random poses about home: +-30 mm, +-6 deg.
    fn poses(table: &JointTable, k: usize, rng: &mut rand::rngs::StdRng) -> Vec<Pose> {
        let h = table.home;
        (0..k)
            .map(|_| {
                let d = [0, 1, 2].map(|_| rng.random_range(-30.0..30.0));
                let a = [0, 1, 2].map(|_| rng.random_range(-6.0..6.0));
                let [r, p, y] = h.rpy_deg();
                Pose::from_xyz_rpy_deg(
                    [
                        h.position_mm.x + d[0],
                        h.position_mm.y + d[1],
                        h.position_mm.z + d[2],
                    ],
                    [r + a[0], p + a[1], y + a[2]],
                )
            })
            .collect()
    }

    /// A noisy measurement of `p` in the frame `frame`: position noise `sp` mm, orientation
    /// noise `so` rad (independent of the code under test: composed with nalgebra directly).
    fn measure(frame: &Pose, p: &Pose, sp: f64, so: f64, rng: &mut rand::rngs::StdRng) -> Pose {
        let g = Normal::new(0.0, 1.0).unwrap();
        let mut pos = frame.rotation * p.position_mm + frame.position_mm;
        for a in 0..3 {
            pos[a] += sp * g.sample(rng);
        }
        let d = Vector3::new(g.sample(rng), g.sample(rng), g.sample(rng)) * so;
        Pose::new(pos, Rotation3::new(d) * frame.rotation * p.rotation)
    }

    #[test]
    fn recovers_a_known_frame_and_link_offsets_within_three_sigma() {
        let table = hexapod();
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let truth_offsets = [20.0, -18.0, 15.0, -22.0, 19.0, -16.0];
        let frame = Pose::from_xyz_rpy_deg([180.0, -95.0, 60.0], [4.0, -3.0, 8.5]);
        let ps = poses(&table, 60, &mut rng);
        let (sp, so) = (0.01, 20e-6);
        let measured: Vec<Pose> = ps
            .iter()
            .map(|p| measure(&frame, p, sp, so, &mut rng))
            .collect();
        // Readings whose zero is off: the commanded lengths are the true ones minus the offsets.
        let lengths: Vec<Vec<f64>> = ps
            .iter()
            .map(|p| {
                cpm_kinematics::inverse_lengths(&table, p)
                    .iter()
                    .zip(truth_offsets)
                    .map(|(l, o)| l - o)
                    .collect()
            })
            .collect();
        let r = register(
            &table,
            &[Session {
                lengths_mm: lengths,
                measured,
            }],
            &RegistrationOptions::default(),
        )
        .unwrap();
        assert!(r.offsets_estimated);
        let f = &r.frames[0];
        assert!(f.rms_before_mm > 50.0, "{}", f.rms_before_mm);
        assert!(f.rms_after_mm < 0.05, "{}", f.rms_after_mm);
        assert!(
            (r.variance_factor - 1.0).abs() < 0.3,
            "{}",
            r.variance_factor
        );
        for a in 0..3 {
            let e = f.translation_mm[a] - frame.position_mm[a];
            assert!(
                e.abs() < 3.0 * f.translation_sd_mm[a],
                "t{a}: {e} vs {:?}",
                f.translation_sd_mm
            );
        }
        let dw = cpm_geometry::rotation::log(&(f.rotation * frame.rotation.inverse()));
        for a in 0..3 {
            assert!(
                dw[a].to_degrees().abs() < 3.0 * f.rotation_sd_deg[a],
                "r{a}: {} vs {:?}",
                dw[a].to_degrees(),
                f.rotation_sd_deg
            );
        }
        for i in 0..6 {
            let e = r.link_offset_mm[i] - truth_offsets[i];
            assert!(
                e.abs() < 3.0 * r.link_offset_sd_mm[i],
                "offset {i}: {e} vs {}",
                r.link_offset_sd_mm[i]
            );
        }
    }

    #[test]
    fn two_sessions_get_their_own_frames() {
        let table = hexapod();
        let mut rng = rand::rngs::StdRng::seed_from_u64(9);
        let frames = [
            Pose::from_xyz_rpy_deg([60.0, 250.0, -40.0], [-2.0, 1.5, -7.0]),
            Pose::from_xyz_rpy_deg([-120.0, 80.0, 210.0], [6.0, -1.0, 3.0]),
        ];
        let sessions: Vec<Session> = frames
            .iter()
            .map(|fr| {
                let ps = poses(&table, 30, &mut rng);
                Session {
                    measured: ps
                        .iter()
                        .map(|p| measure(fr, p, 0.01, 20e-6, &mut rng))
                        .collect(),
                    lengths_mm: ps
                        .iter()
                        .map(|p| cpm_kinematics::inverse_lengths(&table, p))
                        .collect(),
                }
            })
            .collect();
        let r = register(&table, &sessions, &RegistrationOptions::default()).unwrap();
        for (f, truth) in r.frames.iter().zip(&frames) {
            for a in 0..3 {
                let e = f.translation_mm[a] - truth.position_mm[a];
                assert!(
                    e.abs() < 3.0 * f.translation_sd_mm[a],
                    "{e} {:?}",
                    f.translation_sd_mm
                );
            }
            let dw = cpm_geometry::rotation::log(&(f.rotation * truth.rotation.inverse()));
            assert!(
                dw.norm().to_degrees()
                    < 3.0 * f.rotation_sd_deg.iter().fold(0.0, |a: f64, b| a.max(*b)) * 1.8
            );
            // The base-frame view of a measured pose is near the nominal one.
            let back = f.to_base(&sessions[0].measured[0]);
            assert!(back.is_finite());
        }
        for o in &r.link_offset_mm {
            assert!(o.abs() < 0.05, "{o}");
        }
    }

    #[test]
    fn one_pose_still_gives_a_frame_from_its_orientation() {
        let table = hexapod();
        let frame = Pose::from_xyz_rpy_deg([10.0, 20.0, 30.0], [1.0, 2.0, 3.0]);
        let p = table.home;
        let r = register(
            &table,
            &[Session {
                lengths_mm: vec![cpm_kinematics::inverse_lengths(&table, &p)],
                measured: vec![Pose::new(
                    frame.rotation * p.position_mm + frame.position_mm,
                    frame.rotation * p.rotation,
                )],
            }],
            &RegistrationOptions {
                estimate_link_offsets: false,
                ..Default::default()
            },
        )
        .unwrap();
        assert!((r.frames[0].translation_mm - frame.position_mm).norm() < 1e-6);
    }

    #[test]
    fn bad_options_and_empty_sessions_are_refused() {
        let table = hexapod();
        let o = RegistrationOptions {
            position_sigma_mm: 0.0,
            ..Default::default()
        };
        assert!(register(&table, &[], &RegistrationOptions::default()).is_err());
        assert!(register(
            &table,
            &[Session {
                lengths_mm: vec![],
                measured: vec![]
            }],
            &o
        )
        .is_err());
    }

    /// The Jacobian the registration hands to cpm-lm (small-rotation columns times the left
    /// Jacobian of SO(3) at the rotation corrections) against central differences, at
    /// corrections of a few milliradians and tenths of a millimetre.
    #[test]
    fn registration_jacobian_matches_finite_differences() {
        let table = hexapod();
        let mut rng = rand::rngs::StdRng::seed_from_u64(17);
        let ps = poses(&table, 8, &mut rng);
        let frame = Pose::from_xyz_rpy_deg([100.0, -40.0, 20.0], [1.0, -2.0, 5.0]);
        let sessions = [Session {
            lengths_mm: ps
                .iter()
                .map(|p| cpm_kinematics::inverse_lengths(&table, p))
                .collect(),
            measured: ps
                .iter()
                .map(|p| measure(&frame, p, 0.01, 2e-5, &mut rng))
                .collect(),
        }];
        let options = RegistrationOptions::default();
        let zero = |_: &Pose| vec![0.0; 6];
        let mut problem = Frames {
            table: &table,
            sessions: &sessions,
            options: &options,
            correction_mm: &zero,
            start: (vec![(frame.rotation, frame.position_mm)], vec![0.0; 6]),
            with_offsets: true,
            fk: vec![ps.iter().map(|p| Some(*p)).collect()],
        };
        let d: Vec<f64> = (0..12)
            .map(|k| if k % 6 >= 3 && k < 6 { 3e-3 } else { 0.2 } * ((k as f64) * 0.7 + 0.3).sin())
            .collect();
        // A relative step of 1e-4: the residuals are differences of terms near 1e5 (weighted
        // positions of about a metre), which the checker's first-order estimate of the terms
        // misses at corrections this small. The link-offset columns (through forward
        // kinematics) agree to about 2e-6 at any step, the rotation columns to 1e-8.
        let c = cpm_lm::check_jacobian(&mut problem, &d, 1e-4).unwrap();
        assert!(c.is_consistent(1e-5), "{c}");
        let (r0, r1) = (c.max_rel_entry.1, c.max_abs_entry.1);
        assert!(r0 >= 6 && r1 < 12, "{c}");
    }
}
