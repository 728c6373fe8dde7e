//! The reports of `cpm validate`: on held-out measurements ([`ValidateReport`]:
//! validation.json, validation.md, validation.svg and the `--json` summary), and of a
//! compensation checked on a simulated machine ([`CompensationReport`]: compensation.json,
//! compensation.md and the `--json` summary).
//!
//! The command line predicts the held-out files with each robot ([`PredictionErrors`]); the
//! figures of the report (RMS, maximum, mean and spread) are computed here.
use serde::Serialize;

/// Prediction errors of one robot on one group of observations.
#[derive(Debug, Clone, Default)]
pub struct GroupErrors {
    /// Reading or position errors, um (per coordinate for positions).
    pub values_um: Vec<f64>,
    /// Orientation errors, urad (per component).
    pub orientation_urad: Vec<f64>,
}

/// Root mean square (NaN when empty).
pub fn rms(v: &[f64]) -> f64 {
    if v.is_empty() {
        f64::NAN
    } else {
        (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
    }
}

/// Largest absolute value (NaN when empty).
pub fn max_abs(v: &[f64]) -> f64 {
    v.iter().fold(
        f64::NAN,
        |m, x| if m.is_nan() { x.abs() } else { m.max(x.abs()) },
    )
}

/// Mean and sample standard deviation (NaN when empty; sd 0 for one value).
pub fn mean_sd(v: &[f64]) -> (f64, f64) {
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let sd = if v.len() > 1 {
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    } else {
        0.0
    };
    (m, sd)
}

/// The full frame of a session as fitted against one robot: the reader's rough registration
/// composed with the increment fitted on top of it (`p_instrument = R p_base + t`), with the
/// increment's standard deviations (the rough registration is held fixed). An inclinometer
/// session's frame is the levelling of the base: a rotation about x and y, no translation.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SessionFrame {
    /// Base origin in the instrument's frame, mm (`null` for an inclinometer session).
    pub translation_mm: Option<[f64; 3]>,
    /// Standard deviation of each translation component, um (`null` for an inclinometer
    /// session).
    pub translation_sd_um: Option<[f64; 3]>,
    /// Unit axis of the rotation from base to instrument axes (`[0, 0, 1]` for none).
    pub rotation_axis: [f64; 3],
    /// Its angle, deg.
    pub rotation_angle_deg: f64,
    /// Standard deviation of each component of the rotation (small rotation about x, y, z),
    /// urad.
    pub rotation_sd_urad: [f64; 3],
}

impl SessionFrame {
    /// The frame `rough ∘ increment` of a tracker or point session: `rough` as (translation
    /// mm, rotation), `increment` and `sd` as fitted (tx ty tz um, rx ry rz urad).
    pub fn rigid(
        rough: (cpm_geometry::Vector3<f64>, cpm_geometry::Rotation3<f64>),
        increment: &[f64; 6],
        sd: &[f64; 6],
    ) -> Self {
        let (t0, r0) = rough;
        let ti = cpm_geometry::Vector3::new(increment[0], increment[1], increment[2]) * 1e-3;
        let ri = cpm_geometry::Rotation3::new(
            cpm_geometry::Vector3::new(increment[3], increment[4], increment[5]) * 1e-6,
        );
        let r = r0 * ri;
        let t = r0 * ti + t0;
        let (axis, angle) = axis_angle(&r);
        Self {
            translation_mm: Some([t.x, t.y, t.z]),
            translation_sd_um: Some([sd[0], sd[1], sd[2]]),
            rotation_axis: axis,
            rotation_angle_deg: angle,
            rotation_sd_urad: [sd[3], sd[4], sd[5]],
        }
    }

    /// The levelling of an inclinometer session: the base tilted by `rx`, `ry` urad
    /// (`frame[0..2]`), standard deviations `sd[0..2]`.
    pub fn tilt(frame: &[f64; 6], sd: &[f64; 6]) -> Self {
        let r = cpm_geometry::Rotation3::new(
            cpm_geometry::Vector3::new(frame[0], frame[1], 0.0) * 1e-6,
        );
        let (axis, angle) = axis_angle(&r);
        Self {
            translation_mm: None,
            translation_sd_um: None,
            rotation_axis: axis,
            rotation_angle_deg: angle,
            rotation_sd_urad: [sd[0], sd[1], 0.0],
        }
    }
}

fn axis_angle(r: &cpm_geometry::Rotation3<f64>) -> ([f64; 3], f64) {
    match r.axis_angle() {
        Some((axis, angle)) => ([axis.x, axis.y, axis.z], angle.to_degrees()),
        None => ([0.0, 0.0, 1.0], 0.0),
    }
}

/// One held-out session (a tracker, point or inclinometer file) registered afresh against one
/// robot (held fixed).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SessionCheck {
    /// The file.
    pub file: String,
    /// What it holds: `tracker` (6-D poses), `points` (targets) or `tilts` (inclinometer
    /// angles).
    pub kind: String,
    /// The rough registration the reader applied: translation (mm) and rotation angle (deg)
    /// of the tracker frame from the base frame (zero for an inclinometer session).
    pub rough_translation_mm: [f64; 3],
    /// Its rotation angle, deg.
    pub rough_rotation_deg: f64,
    /// The increment fitted on top of it with the machine held fixed: tx ty tz um, rx ry rz
    /// urad (a tracker or point session); the base tilt rx ry urad and four zeros (an
    /// inclinometer session).
    pub frame: [f64; 6],
    /// Standard deviations of `frame`, in its units.
    pub frame_sd: [f64; 6],
    /// The full frame: rough registration and increment together, with standard deviations.
    pub full_frame: SessionFrame,
    /// RMS of the weighted residual the frame fit minimises, in standard deviations of each
    /// observation's noise (a mix of kinds: no unit), with the rough registration only.
    pub weighted_rms_before: f64,
    /// The same with the session frame fitted.
    pub weighted_rms_after: f64,
    /// Position error RMS (um, per coordinate) with the rough registration only (`null`
    /// without positions).
    pub position_rms_before_um: Option<f64>,
    /// Position error RMS (um, per coordinate) with the session frame fitted.
    pub position_rms_after_um: Option<f64>,
    /// Angle error RMS (urad: tracker orientation components or inclinometer angles) with the
    /// rough registration only (`null` without angles).
    pub angle_rms_before_urad: Option<f64>,
    /// The same with the session frame fitted.
    pub angle_rms_after_urad: Option<f64>,
}

/// What one robot predicts on the held-out files.
#[derive(Debug, Clone, Default)]
pub struct PredictionErrors {
    /// The groups' names (a gauge sensor, a tracker, point or tilt file).
    pub names: Vec<String>,
    /// The errors of each group.
    pub groups: Vec<GroupErrors>,
    /// The files are marked simulated.
    pub simulated: bool,
    /// Each held-out tracker file re-registered.
    pub sessions: Vec<SessionCheck>,
    /// Logged link lengths minus those the model needs for the measured poses, mm.
    pub link_mm: Vec<f64>,
    /// Position error per tracker pose (norm), um.
    pub position_norm_um: Vec<f64>,
    /// Tracker poses outside the pose range a known pose map was fitted on.
    pub outside_pose_map: usize,
    /// Tracker poses.
    pub tracker_poses: usize,
    /// The poses the readers left out (the machine cannot be there), file after file.
    pub excluded: Vec<cpm_io::ExcludedPose>,
}

/// RMS of `v`, `None` when it is empty.
fn rms_of(v: &[f64]) -> Option<f64> {
    (!v.is_empty()).then(|| rms(v))
}

/// Error figures of one robot over one group of observations.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ErrorSummary {
    /// Reading or position error RMS, um.
    pub rms_um: f64,
    /// Its largest absolute value, um.
    pub max_um: f64,
    /// Orientation (or inclinometer angle) error RMS, urad (`null` without angles).
    pub orientation_rms_urad: Option<f64>,
    /// Its largest absolute value, urad (`null` without angles).
    pub orientation_max_urad: Option<f64>,
}

impl ErrorSummary {
    fn new(g: &GroupErrors) -> Self {
        Self {
            rms_um: rms(&g.values_um),
            max_um: max_abs(&g.values_um),
            orientation_rms_urad: rms_of(&g.orientation_urad),
            orientation_max_urad: (!g.orientation_urad.is_empty())
                .then(|| max_abs(&g.orientation_urad)),
        }
    }
}

/// One group of held-out observations, both robots.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GroupSummary {
    /// The group's name.
    pub name: String,
    /// Its length and position observations (readings or position coordinates), um.
    pub count: usize,
    /// Its angle observations (tracker orientation components or inclinometer angles), urad.
    pub angles: usize,
    /// The calibrated robot's errors.
    pub calibrated: ErrorSummary,
    /// The reference robot's errors.
    pub reference: ErrorSummary,
}

/// One robot's errors over every held-out observation.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RobotSummary {
    /// Reading or position error RMS, um.
    pub rms_um: f64,
    /// Its largest absolute value, um.
    pub max_um: f64,
    /// Orientation error RMS, urad (`null` without orientations).
    pub orientation_rms_urad: Option<f64>,
    /// Link-length error RMS, mm (`null` without logged readings of tracker poses).
    pub link_rms_mm: Option<f64>,
    /// Mean position error per tracker pose, um (`null` without tracker poses).
    pub position_error_mean_um: Option<f64>,
    /// Its standard deviation, um.
    pub position_error_sd_um: Option<f64>,
    /// Each held-out tracker session re-registered.
    pub sessions: Vec<SessionCheck>,
    /// The share of tracker poses outside a known pose map's range (`null` without poses).
    pub outside_pose_map_share: Option<f64>,
}

/// What only validation.md and the console line say about one robot.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RobotText {
    /// Observations (readings and position coordinates) in all.
    pub observations: usize,
    /// Orientation and angle components in all.
    pub angles: usize,
    /// Largest absolute orientation error, urad.
    pub orientation_max_urad: f64,
    /// Tracker poses.
    pub tracker_poses: usize,
    /// Tracker poses outside a known pose map's range.
    pub outside_pose_map: usize,
}

/// Lists taken one after the other as one: [`rms`] and [`max_abs`] of them, in the same
/// order (the same figures, bit for bit), without the list.
#[derive(Clone)]
struct Chained<I>(I);

impl<'a, I: Iterator<Item = &'a [f64]> + Clone> Chained<I> {
    fn values(&self) -> impl Iterator<Item = f64> + use<'a, I> {
        self.0.clone().flat_map(|v| v.iter().copied())
    }

    fn len(&self) -> usize {
        self.0.clone().map(<[f64]>::len).sum()
    }

    /// [`rms`] of the values.
    fn rms(&self) -> f64 {
        match self.len() {
            0 => f64::NAN,
            n => (self.values().map(|x| x * x).sum::<f64>() / n as f64).sqrt(),
        }
    }

    /// [`max_abs`] of the values.
    fn max_abs(&self) -> f64 {
        self.values().fold(
            f64::NAN,
            |m, x| if m.is_nan() { x.abs() } else { m.max(x.abs()) },
        )
    }
}

impl RobotSummary {
    fn new(e: &PredictionErrors) -> (Self, RobotText) {
        // Every group's values one after the other, as one list would hold them.
        let all = Chained(e.groups.iter().map(|g| g.values_um.as_slice()));
        let rot = Chained(e.groups.iter().map(|g| g.orientation_urad.as_slice()));
        let (mean, sd) = mean_sd(&e.position_norm_um);
        let poses = !e.position_norm_um.is_empty();
        let summary = Self {
            rms_um: all.rms(),
            max_um: all.max_abs(),
            orientation_rms_urad: (rot.len() > 0).then(|| rot.rms()),
            link_rms_mm: rms_of(&e.link_mm),
            position_error_mean_um: poses.then_some(mean),
            position_error_sd_um: poses.then_some(sd),
            sessions: e.sessions.clone(),
            outside_pose_map_share: (e.tracker_poses > 0)
                .then(|| e.outside_pose_map as f64 / e.tracker_poses as f64),
        };
        let text = RobotText {
            observations: all.len(),
            angles: rot.len(),
            orientation_max_urad: rot.max_abs(),
            tracker_poses: e.tracker_poses,
            outside_pose_map: e.outside_pose_map,
        };
        (summary, text)
    }
}

/// The report of `cpm validate` on held-out files: `validation.json` (and the `--json`
/// summary) when serialised, validation.md through [`ValidateReport::markdown`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ValidateReport {
    /// The held-out files are marked simulated.
    pub simulated: bool,
    /// The calibrated robot's description.
    pub robot: String,
    /// The reference robot's description.
    pub reference_robot: String,
    /// The held-out files.
    pub data: Vec<String>,
    /// The calibrated robot over every observation.
    pub calibrated: RobotSummary,
    /// The reference robot over every observation.
    pub reference: RobotSummary,
    /// Per group.
    pub groups: Vec<GroupSummary>,
    /// Per one's own instrument and source of its measurements, each in the instrument's
    /// unit (absent when none: such instruments are written in code and given to the job).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub instruments: Vec<InstrumentSummary>,
    /// What only the text says: calibrated, reference.
    #[serde(skip)]
    pub text: (RobotText, RobotText),
}

/// The held-out errors of one's own instrument over the measurements of one source, both
/// robots, in the instrument's unit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct InstrumentSummary {
    /// The instrument's name.
    pub name: String,
    /// The source of the measurements.
    pub file: String,
    /// The unit of its values (and of the figures).
    pub unit: String,
    /// Its values (measured minus predicted, one each).
    pub count: usize,
    /// The calibrated robot's RMS and largest absolute error.
    pub calibrated: (f64, f64),
    /// The reference robot's RMS and largest absolute error.
    pub reference: (f64, f64),
}

impl InstrumentSummary {
    /// The summary of the errors `calibrated` and `reference` (measured minus predicted).
    pub fn new(name: &str, file: &str, unit: &str, calibrated: &[f64], reference: &[f64]) -> Self {
        Self {
            name: name.to_string(),
            file: file.to_string(),
            unit: unit.to_string(),
            count: calibrated.len(),
            calibrated: (rms(calibrated), max_abs(calibrated)),
            reference: (rms(reference), max_abs(reference)),
        }
    }
}

impl ValidateReport {
    /// The report of the calibrated robot `robot` (its errors `cal`) against the reference
    /// `reference_robot` (`reference`) on the held-out files `data`. The groups are
    /// `cal`'s (the caller checks that both robots name the same).
    pub fn new(
        robot: &str,
        reference_robot: &str,
        data: Vec<String>,
        cal: &PredictionErrors,
        reference: &PredictionErrors,
    ) -> Self {
        use rayon::prelude::*;
        // The two robots' summaries side by side, and the groups' in parallel (passes over
        // every observation: 10^6 of them take milliseconds each); the same numbers.
        let ((calibrated, cal_text), (reference_summary, ref_text)) =
            rayon::join(|| RobotSummary::new(cal), || RobotSummary::new(reference));
        Self {
            simulated: cal.simulated,
            robot: robot.to_string(),
            reference_robot: reference_robot.to_string(),
            data,
            calibrated,
            reference: reference_summary,
            groups: cal
                .names
                .par_iter()
                .zip(cal.groups.par_iter().zip(&reference.groups))
                .map(|(n, (c, r))| GroupSummary {
                    name: n.clone(),
                    count: c.values_um.len(),
                    angles: c.orientation_urad.len(),
                    calibrated: ErrorSummary::new(c),
                    reference: ErrorSummary::new(r),
                })
                .collect(),
            instruments: Vec::new(),
            text: (cal_text, ref_text),
        }
    }

    /// `validation.json` and the `--json` summary, pretty-printed (keys sorted).
    pub fn to_json(&self) -> serde_json::Result<String> {
        serde_json::to_string_pretty(&serde_json::to_value(self)?)
    }

    /// validation.md; `figure`: validation.svg is written beside it.
    pub fn markdown(&self, figure: bool) -> String {
        let (c, r) = (&self.calibrated, &self.reference);
        let mut md = String::from("# Validation on held-out data\n\n");
        if self.simulated {
            md.push_str("**The measurements are SIMULATED.**\n\n");
        }
        md.push_str(&format!(
            "Calibrated robot `{}` against the reference `{}`, on {}; predictions with every known effect applied, nothing estimated. Gauge rows: reading errors; tracker rows: position errors per coordinate.\n\n",
            self.robot,
            self.reference_robot,
            self.data
                .iter()
                .map(|p| format!("`{p}`"))
                .collect::<Vec<_>>()
                .join(", ")
        ));
        md.push_str("Every figure in its unit: um for readings and positions, urad for angles (tracker orientations, inclinometer angles).\n\n| group | observations | unit | calibrated RMS | calibrated max | reference RMS | reference max |\n|---|---|---|---|---|---|---|\n");
        let row =
            |md: &mut String, name: &str, n: usize, unit: &str, c: (f64, f64), r: (f64, f64)| {
                md.push_str(&format!(
                    "| {name} | {n} | {unit} | {:.3} | {:.3} | {:.3} | {:.3} |\n",
                    c.0, c.1, r.0, r.1
                ));
            };
        let nan = |v: Option<f64>| v.unwrap_or(f64::NAN);
        for g in &self.groups {
            let (gc, gr) = (&g.calibrated, &g.reference);
            if g.count > 0 {
                row(
                    &mut md,
                    &g.name,
                    g.count,
                    "um",
                    (gc.rms_um, gc.max_um),
                    (gr.rms_um, gr.max_um),
                );
            }
            if g.angles > 0 {
                row(
                    &mut md,
                    &g.name,
                    g.angles,
                    "urad",
                    (nan(gc.orientation_rms_urad), nan(gc.orientation_max_urad)),
                    (nan(gr.orientation_rms_urad), nan(gr.orientation_max_urad)),
                );
            }
        }
        if self.text.0.observations > 0 {
            row(
                &mut md,
                "**all lengths and positions**",
                self.text.0.observations,
                "um",
                (c.rms_um, c.max_um),
                (r.rms_um, r.max_um),
            );
        }
        if self.text.0.angles > 0 {
            row(
                &mut md,
                "**all angles**",
                self.text.0.angles,
                "urad",
                (
                    nan(c.orientation_rms_urad),
                    self.text.0.orientation_max_urad,
                ),
                (
                    nan(r.orientation_rms_urad),
                    self.text.1.orientation_max_urad,
                ),
            );
        }
        for i in &self.instruments {
            row(
                &mut md,
                &format!("{} (`{}`)", i.name, i.file),
                i.count,
                &i.unit,
                i.calibrated,
                i.reference,
            );
        }
        self.session_markdown(&mut md);
        if figure {
            md.push_str("\n![held-out RMS per group](validation.svg)\n");
        }
        md
    }

    /// The console line (without the files written).
    pub fn console_line(&self) -> String {
        let (c, r) = (&self.calibrated, &self.reference);
        let sim = if self.simulated {
            "SIMULATED data: "
        } else {
            ""
        };
        if self.text.0.observations == 0 && self.text.0.angles > 0 {
            // Angles only (inclinometers, orientations).
            format!(
                "{sim}held-out: calibrated RMS {:.3} urad (max {:.3}), reference RMS {:.3} urad (max {:.3}) over {} angles",
                c.orientation_rms_urad.unwrap_or(f64::NAN),
                self.text.0.orientation_max_urad,
                r.orientation_rms_urad.unwrap_or(f64::NAN),
                self.text.1.orientation_max_urad,
                self.text.0.angles
            )
        } else {
            let mut line = format!(
                "{sim}held-out: calibrated RMS {:.3} um (max {:.3}), reference RMS {:.3} um (max {:.3}) over {} observations",
                c.rms_um, c.max_um, r.rms_um, r.max_um, self.text.0.observations
            );
            if self.text.0.angles > 0 {
                line.push_str(&format!(
                    "; angles: calibrated RMS {:.3} urad, reference RMS {:.3} urad over {}",
                    c.orientation_rms_urad.unwrap_or(f64::NAN),
                    r.orientation_rms_urad.unwrap_or(f64::NAN),
                    self.text.0.angles
                ));
            }
            line
        }
    }

    /// validation.svg: the RMS error of each group, both robots.
    #[cfg(feature = "svg")]
    pub fn figure(&self) -> Result<String, crate::figures::PlotError> {
        let names: Vec<String> = self.groups.iter().map(|g| g.name.clone()).collect();
        crate::figures::grouped_bars(
            &format!(
                "Held-out prediction error{}",
                if self.simulated {
                    " (SIMULATED data)"
                } else {
                    ""
                }
            ),
            "RMS error (um)",
            &names,
            &[
                (
                    "calibrated".to_string(),
                    self.groups.iter().map(|g| g.calibrated.rms_um).collect(),
                ),
                (
                    "reference".to_string(),
                    self.groups.iter().map(|g| g.reference.rms_um).collect(),
                ),
            ],
        )
    }

    /// The sessions, link-length and pose-accuracy sections of validation.md.
    fn session_markdown(&self, md: &mut String) {
        let (cal, reference) = (&self.calibrated, &self.reference);
        if cal.sessions.is_empty() {
            return;
        }
        md.push_str("\n## Sessions\n\nEach held-out tracker, point or inclinometer file is a session: its frame is registered afresh against each robot (held fixed), the rough registration of the reader first, then the frame parameters through the prediction model (an inclinometer session: the base's levelling). Frame: translation mm, rotation axis and angle deg, +- one standard deviation (translation um, rotation urad). The weighted RMS is in standard deviations of each observation's noise.\n\n| file | kind | robot | translation (mm) | +- (um) | rotation axis | angle (deg) | +- (urad) | weighted RMS before (in sigma) | after (in sigma) | position RMS after (um) | angle RMS after (urad) |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n");
        let opt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.3}"));
        for (label, e) in [("calibrated", cal), ("reference", reference)] {
            for s in &e.sessions {
                let f = &s.full_frame;
                let (t, tsd) = match (f.translation_mm, f.translation_sd_um) {
                    (Some(t), Some(sd)) => (
                        format!("({:.4}, {:.4}, {:.4})", t[0], t[1], t[2]),
                        format!("{:.1}, {:.1}, {:.1}", sd[0], sd[1], sd[2]),
                    ),
                    _ => ("-".to_string(), "-".to_string()),
                };
                let a = f.rotation_axis;
                let rsd = f.rotation_sd_urad;
                md.push_str(&format!(
                    "| {} | {} | {label} | {t} | {tsd} | ({:.4}, {:.4}, {:.4}) | {:.6} | {:.1}, {:.1}, {:.1} | {:.3} | {:.3} | {} | {} |\n",
                    s.file, s.kind, a[0], a[1], a[2], f.rotation_angle_deg, rsd[0], rsd[1], rsd[2], s.weighted_rms_before, s.weighted_rms_after, opt(s.position_rms_after_um), opt(s.angle_rms_after_urad)
                ));
            }
        }
        if cal.position_error_mean_um.is_none() && cal.link_rms_mm.is_none() {
            return;
        }
        md.push_str("\n| figure | calibrated | reference |\n|---|---|---|\n");
        if let Some(link) = cal.link_rms_mm {
            md.push_str(&format!(
                "| link-length error RMS (logged readings against the lengths the model needs for the measured poses), mm | {:.4} | {:.4} |\n",
                link,
                reference.link_rms_mm.unwrap_or(f64::NAN)
            ));
        }
        let nan = |v: Option<f64>| v.unwrap_or(f64::NAN);
        let (cm, cs) = (
            nan(cal.position_error_mean_um),
            nan(cal.position_error_sd_um),
        );
        let (rm, rs) = (
            nan(reference.position_error_mean_um),
            nan(reference.position_error_sd_um),
        );
        let (ct, rt) = (&self.text.0, &self.text.1);
        md.push_str(&format!(
            "| pose accuracy (ISO 9283 style): mean position error, um | {cm:.3} | {rm:.3} |\n| its spread (standard deviation), um | {cs:.3} | {rs:.3} |\n| held-out poses | {} | {} |\n",
            ct.tracker_poses, rt.tracker_poses
        ));
        if ct.outside_pose_map > 0 {
            md.push_str(&format!(
                "\n{} of {} held-out poses lie outside the pose range the calibrated pose error map was fitted on: the map does not extrapolate there.\n",
                ct.outside_pose_map, ct.tracker_poses
            ));
        }
    }
}

/// The errors of the poses a simulated machine reached, over every target.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReachedSummary {
    /// Position error RMS, um.
    pub position_rms_um: f64,
    /// Its largest absolute value, um.
    pub position_max_um: f64,
    /// Orientation error RMS, urad.
    pub orientation_rms_urad: f64,
    /// Its largest absolute value, urad.
    pub orientation_max_urad: f64,
}

impl ReachedSummary {
    /// The figures of the position (um) and orientation (urad) errors per target.
    pub fn new(position_um: &[f64], orientation_urad: &[f64]) -> Self {
        Self {
            position_rms_um: rms(position_um),
            position_max_um: max_abs(position_um),
            orientation_rms_urad: rms(orientation_urad),
            orientation_max_urad: max_abs(orientation_urad),
        }
    }
}

/// One target of a compensation check.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TargetError {
    /// The target's pose label.
    pub pose: String,
    /// Position error with the compensated commands, um.
    pub position_um: f64,
    /// Orientation error with them, urad.
    pub orientation_urad: f64,
    /// Position error with the reference's inverse kinematics, um.
    pub reference_position_um: f64,
}

/// The report of `cpm validate --commands`: `compensation.json` (and the `--json` summary)
/// when serialised, compensation.md through [`CompensationReport::markdown`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CompensationReport {
    /// Always true: the machine is a description.
    pub simulated: bool,
    /// The true machine's description.
    pub truth: String,
    /// The reference robot's description.
    pub reference_robot: String,
    /// The commands file.
    pub commands: String,
    /// Targets.
    pub targets: usize,
    /// With the compensated commands.
    pub compensated: ReachedSummary,
    /// With the reference's inverse kinematics.
    pub reference: ReachedSummary,
    /// Per target.
    pub per_target: Vec<TargetError>,
}

impl CompensationReport {
    /// `compensation.json` and the `--json` summary, pretty-printed (keys sorted).
    pub fn to_json(&self) -> serde_json::Result<String> {
        serde_json::to_string_pretty(&serde_json::to_value(self)?)
    }

    /// compensation.md.
    pub fn markdown(&self) -> String {
        let (c, r) = (&self.compensated, &self.reference);
        let mut md = String::from("# Compensation checked on a simulated machine\n\n**SIMULATED: the machine is the description ");
        md.push_str(&format!(
            "`{}`, not a measurement.**\n\nIt executes `{}` (compensated) and, for reference, the inverse kinematics of `{}` (uncompensated), aiming at the same {} targets.\n\n| commands | position RMS (um) | position max (um) | orientation RMS (urad) | orientation max (urad) |\n|---|---|---|---|---|\n| compensated | {:.3} | {:.3} | {:.2} | {:.2} |\n| uncompensated | {:.3} | {:.3} | {:.2} | {:.2} |\n",
            self.truth,
            self.commands,
            self.reference_robot,
            self.targets,
            c.position_rms_um, c.position_max_um, c.orientation_rms_urad, c.orientation_max_urad,
            r.position_rms_um, r.position_max_um, r.orientation_rms_urad, r.orientation_max_urad,
        ));
        md
    }

    /// The console line (without the files written).
    pub fn console_line(&self) -> String {
        let (c, r) = (&self.compensated, &self.reference);
        format!(
            "SIMULATED machine {}: compensated position error RMS {:.3} um (max {:.3}), uncompensated {:.3} um (max {:.3}) over {} targets",
            self.truth,
            c.position_rms_um,
            c.position_max_um,
            r.position_rms_um,
            r.position_max_um,
            self.targets
        )
    }
}
