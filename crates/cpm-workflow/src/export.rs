//! `cpm export` as a library function: a (calibrated) robot's joint coordinates for a machine
//! controller ([`export`] with [`ExportOptions`]).
//!
//! `linuxcnc`: HAL `setp` lines for the genhexkins kinematics module,
//! `genhexkins.base.N.x|y|z` (base joints in the base frame) and
//! `genhexkins.platform.N.x|y|z` (platform joints in the platform frame), N = 0..5 (cpm's
//! link N+1), the screw-lead pins when a screw lead is declared, and an INI snippet with each
//! joint's `HOME_OFFSET`, `SCALE` and `BACKLASH`; units mm or inch.
//!
//! ```
//! use cpm_workflow::export::{export, ExportOptions, Units};
//! use cpm_workflow::Silent;
//!
//! let mut options = ExportOptions::new("../../examples/hexapod_66.toml");
//! options.units = Units::Inch;
//! options.ini = Some("joints.ini".into());
//! let job = export(&options, &Silent)?;
//! assert!(job.hal.contains("setp genhexkins.base.0.x "));
//! assert!(job.ini.as_deref().is_some_and(|i| i.contains("[JOINT_5]")));
//! // Nothing was written: the caller writes the texts where it wants them.
//! assert!(!std::path::Path::new("joints.ini").exists());
//! # Ok::<(), anyhow::Error>(())
//! ```
use std::path::{Path, PathBuf};

use crate::error::input_error;
use crate::io::Robot;
use crate::progress::{check_cancelled, Progress};

/// Export formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Format {
    #[default]
    /// LinuxCNC genhexkins HAL settings (`setp genhexkins.base.0.x ...`).
    Linuxcnc,
}

/// Length units of the exported controller settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
#[serde(rename_all = "kebab-case")]
pub enum Units {
    /// Millimetres (LinuxCNC `LINEAR_UNITS = mm`), the default.
    #[default]
    Mm,
    /// Inches (`LINEAR_UNITS = inch`): every length divided by 25.4.
    Inch,
}

impl Units {
    /// Millimetres per unit.
    pub fn mm_per_unit(self) -> f64 {
        match self {
            Units::Mm => 1.0,
            Units::Inch => 25.4,
        }
    }
    /// The LinuxCNC name.
    pub fn name(self) -> &'static str {
        match self {
            Units::Mm => "mm",
            Units::Inch => "inch",
        }
    }
}

/// Writes a number for a HAL or INI file: fixed decimals, never `-0`.
fn num(v: f64, decimals: usize) -> String {
    let s = format!("{:.decimals$}", v + 0.0);
    if s.trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        s.trim_start_matches('-').to_string()
    } else {
        s
    }
}

/// The genhexkins settings of a six-link robot in millimetres (see [`linuxcnc_in`]).
pub fn linuxcnc(robot: &Robot) -> String {
    linuxcnc_in(robot, Units::Mm)
}

/// The LinuxCNC settings of a six-link robot: the genhexkins HAL `setp` lines (joints, and
/// the screw-lead correction when the description declares a screw lead), then an INI
/// snippet with each joint's `HOME_OFFSET`, `SCALE` and, where a backlash is known,
/// `BACKLASH`, all in `units`.
///
/// cpm's link `N` (1-based, the order of `[[link]]`) is genhexkins' joint / strut `N - 1`.
/// The INI values assume the joint's feedback is the link's reading
/// (`length = length_at_zero_mm + mm_per_unit * reading`) with the home switch at reading 0: `SCALE = 1 / mm_per_unit`
/// feedback units per machine unit and `HOME_OFFSET = length_at_zero_mm` (the strut length at
/// home). cpm's `backlash` is half the lost motion, signed as a change of the effective length
/// after extending; LinuxCNC's `BACKLASH` is the whole lost motion, added in the direction of
/// motion, so `BACKLASH = -2 backlash` (a positive cpm value, a link that overshoots, has no
/// LinuxCNC setting and is written as a comment).
pub fn linuxcnc_in(robot: &Robot, units: Units) -> String {
    let k = units.mm_per_unit();
    let u = units.name();
    let mut s = format!(
        "# LinuxCNC genhexkins settings of {}{}, written by cpm {}.\n",
        robot.file,
        robot
            .description
            .name
            .as_ref()
            .map(|n| format!(" ({n})"))
            .unwrap_or_default(),
        env!("CARGO_PKG_VERSION")
    );
    if simulated(robot) {
        s.push_str("# SIMULATED: this robot was calibrated from simulated data; these are not a real machine's settings.\n");
    }
    s.push_str(&format!(
        "# Units: {u} (LinuxCNC LINEAR_UNITS = {u}). cpm link N (1-based, [[link]] order) = genhexkins joint N-1.\n"
    ));
    s.push_str(&format!(
        "# Base joints in the base (world) frame, platform joints in the platform frame, {u}.\n"
    ));
    s.push_str("# Load with `loadrt genhexkins` in the HAL file; the INI snippet at the end goes in the machine's INI file.\n");
    // Checked when the description was loaded.
    let known = robot.known_effects().unwrap_or_default();
    let other: Vec<&str> = known
        .iter()
        .map(|e| e.effect.name())
        .filter(|n| !matches!(*n, "backlash" | "link_offset" | "link_scale"))
        .collect();
    if !other.is_empty() {
        s.push_str(&format!(
            "# Not in LinuxCNC: the known effects {} of [calibration.known_effects]; `cpm compensate` applies them to target poses.\n",
            other.join(", ")
        ));
    }
    for (side, name) in [(0, "base"), (1, "platform")] {
        for (i, l) in robot.table.links.iter().enumerate() {
            let p = if side == 0 { l.base_mm } else { l.platform_mm };
            for (a, axis) in ["x", "y", "z"].iter().enumerate() {
                s.push_str(&format!(
                    "setp genhexkins.{name}.{i}.{axis} {}\n",
                    num(p[a] / k, 6)
                ));
            }
        }
    }
    let lead = robot
        .description
        .calibration
        .as_ref()
        .and_then(|c| c.screw_lead_mm);
    if let Some(lead) = lead {
        s.push_str(&format!(
            "# Screw lead {lead} mm declared. genhexkins corrects strut lengths for non-captive screws with\n\
             # universal joints from the joints' axis unit vectors, which a cpm description does not hold.\n\
             # The lines below assume each joint axis lies in its base / platform plane, tangent to the circle\n\
             # through the joint around the frame's z axis; check them against the machine, then uncomment.\n"
        ));
        s.push_str(&format!(
            "# setp genhexkins.screw-lead {}\n",
            num(lead / k, 6)
        ));
        for (side, name) in [(0, "base-n"), (1, "platform-n")] {
            for (i, l) in robot.table.links.iter().enumerate() {
                let p = if side == 0 { l.base_mm } else { l.platform_mm };
                let r = (p[0] * p[0] + p[1] * p[1]).sqrt();
                let t = if r > 0.0 {
                    [-p[1] / r, p[0] / r, 0.0]
                } else {
                    [1.0, 0.0, 0.0]
                };
                for (a, axis) in ["x", "y", "z"].iter().enumerate() {
                    s.push_str(&format!(
                        "# setp genhexkins.{name}.{i}.{axis} {}\n",
                        num(t[a], 6)
                    ));
                }
            }
        }
    }
    s.push_str(&format!(
        "\n# ---- INI snippet ({u}; `cpm export --ini FILE` writes it uncommented) ----\n"
    ));
    for line in linuxcnc_ini(robot, units).lines() {
        s.push_str(&format!("# {line}\n"));
    }
    s
}

pub use crate::load::simulated;

/// The INI snippet of [`linuxcnc_in`]: one `[JOINT_n]` section per link with `HOME_OFFSET`,
/// `SCALE` and, where a backlash is known, `BACKLASH`, in `units`.
pub fn linuxcnc_ini(robot: &Robot, units: Units) -> String {
    let k = units.mm_per_unit();
    let u = units.name();
    let backlash = robot
        .known_effects()
        .unwrap_or_default()
        .into_iter()
        .find(|e| e.effect == crate::calib::Effect::Backlash)
        .map(|e| e.values);
    let mut s = format!(
        "; LinuxCNC joints of {} by cpm {} ({u}): HOME_OFFSET = strut length at reading 0,\n; SCALE = feedback (reading) units per {u}; cpm link N = [JOINT_(N-1)].\n",
        robot.file,
        env!("CARGO_PKG_VERSION")
    );
    if simulated(robot) {
        s.push_str("; SIMULATED: this robot was calibrated from simulated data; these are not a real machine's settings.\n");
    }
    for i in 0..robot.description.links.len() {
        // The calibrated link_offset and link_scale folded into the reading model.
        let (length_at_zero_mm, mm_per_unit) = crate::io::robot::folded_reading_model(robot, i);
        s.push_str(&format!("\n[JOINT_{i}]\n; cpm link {}\n", i + 1));
        s.push_str(&format!(
            "HOME_OFFSET = {}\n",
            num(length_at_zero_mm / k, 6)
        ));
        s.push_str(&format!("SCALE = {}\n", num(k / mm_per_unit, 9)));
        if let Some(b) = backlash.as_ref().and_then(|b| b.get(i)) {
            let lash_mm = -2.0 * b * 1e-3;
            if lash_mm >= 0.0 {
                s.push_str(&format!("BACKLASH = {}\n", num(lash_mm / k, 6)));
            } else {
                s.push_str(&format!(
                    "; backlash {} um: the link overshoots; LinuxCNC's BACKLASH cannot hold it (`cpm compensate` applies it)\n",
                    crate::report::format::sig(*b, 3)
                ));
            }
        }
    }
    s
}

/// The options of `cpm export`. [`ExportOptions::new`] gives the defaults.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ExportOptions {
    /// The robot description (usually a `calibrated.toml`).
    pub robot: PathBuf,
    /// The format; default [`Format::Linuxcnc`].
    pub format: Format,
    /// Length units of the settings; default [`Units::Mm`].
    pub units: Units,
    /// Where the settings go (`-`: standard output); default `None`: standard output. Checked
    /// by [`ExportOptions::validate`]; the job itself writes nothing.
    pub out: Option<PathBuf>,
    /// Where the INI snippet goes, uncommented, besides the comments of the settings; default
    /// `None`: no separate snippet.
    pub ini: Option<PathBuf>,
}

impl ExportOptions {
    /// The options for exporting `robot`, every other option at its default.
    pub fn new(robot: impl Into<PathBuf>) -> Self {
        Self {
            robot: robot.into(),
            format: Format::default(),
            units: Units::default(),
            out: None,
            ini: None,
        }
    }

    /// Every input file (an output may not replace one).
    pub fn inputs(&self) -> [&Path; 1] {
        [self.robot.as_path()]
    }

    /// Checks the output file before any work: never a device, FIFO, socket or directory,
    /// never the input (usage errors).
    pub fn validate(&self) -> anyhow::Result<()> {
        if let Some(out) = &self.out {
            crate::load::out_target("--out", out, &self.inputs())?;
        }
        Ok(())
    }
}

/// What [`export`] gives: the texts, for the caller to write (nothing is written).
#[derive(Debug)]
pub struct Exported {
    /// The robot as read.
    pub robot: Robot,
    /// The controller settings (for `out`).
    pub hal: String,
    /// The INI snippet, when `ini` was asked for.
    pub ini: Option<String>,
}

/// `cpm export`: the robot's settings for the controller in `options.format`.
pub fn export(options: &ExportOptions, progress: &dyn Progress) -> anyhow::Result<Exported> {
    export_in(options, crate::sources::InMemory::none(), progress)
}

/// [`export`] with the robot held in memory (as loaded: see
/// [`InMemory`](crate::sources::InMemory)) in place of the description the options name.
pub fn export_in(
    options: &ExportOptions,
    mut held: crate::sources::InMemory,
    progress: &dyn Progress,
) -> anyhow::Result<Exported> {
    options.validate()?;
    check_cancelled(progress)?;
    let robot = held.robot_or_load(&options.robot, progress)?;
    let hal = match options.format {
        Format::Linuxcnc => {
            if robot.num_links() != 6 {
                return Err(input_error(format!(
                    "{}: genhexkins has six struts; this robot has {} links",
                    robot.file,
                    robot.num_links()
                )));
            }
            linuxcnc_in(&robot, options.units)
        }
    };
    let ini = options
        .ini
        .as_ref()
        .map(|_| linuxcnc_ini(&robot, options.units));
    Ok(Exported { robot, hal, ini })
}
