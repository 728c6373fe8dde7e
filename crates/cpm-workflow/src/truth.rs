//! The values of a simulated machine's effects given as text (`--truth-effect EFFECT=V1,..`
//! of `cpm simulate` and `cpm validate --commands`), checked and written into a description's
//! `[calibration.known_effects]`.
use crate::calib::Effect;
use crate::error::usage_error;
use crate::io::Robot;

/// The largest magnitude of a `--truth-effect` value (in the effect's unit: um, um/mm, ...),
/// like the largest plausible installation error (100 mm in um).
pub const MAX_TRUTH_EFFECT: f64 = 1e5;

/// The largest `--truth-effect compliance` value, um/kN (100 mm per kN: a light platform's
/// soft legs, whose deflection at the declared load is still millimetres).
pub const MAX_TRUTH_COMPLIANCE: f64 = 1e8;

/// One `EFFECT=V1,V2,..` value: the effect and its values (each finite and plausible).
pub fn parse_truth_effect(s: &str) -> Result<(Effect, Vec<f64>), String> {
    let (name, values) = s
        .split_once('=')
        .ok_or_else(|| format!("{s:?}: expected EFFECT=V1,V2,..."))?;
    let effect = Effect::parse(name.trim())?;
    let values = values
        .split(',')
        .map(|v| {
            v.trim()
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| format!("{s:?}: {v:?} is not a number"))
                .and_then(|x| {
                    let max = if effect == Effect::Compliance {
                        MAX_TRUTH_COMPLIANCE
                    } else {
                        MAX_TRUTH_EFFECT
                    };
                    if x.abs() <= max {
                        Ok(x)
                    } else {
                        Err(format!(
                            "{s:?}: {x:e} is implausibly large (at most {max:e} in the effect's unit, {})",
                            effect.unit()
                        ))
                    }
                })
        })
        .collect::<Result<Vec<f64>, String>>()?;
    Ok((effect, values))
}

/// One `--truth-effect` value ([`parse_truth_effect`]) with as many values as the effect has
/// parameters on `robot` (usage errors naming `--truth-effect`).
pub fn truth_effect_for(s: &str, robot: &Robot) -> anyhow::Result<(Effect, Vec<f64>)> {
    let (e, v) = parse_truth_effect(s).map_err(|m| usage_error(format!("--truth-effect {m}")))?;
    let need = e.num_params(robot.num_links(), robot.table.sensors.len());
    if v.len() != need {
        return Err(usage_error(format!(
            "--truth-effect {s:?}: {} has {need} parameters here ({}), got {} values",
            e.name(),
            e.unit(),
            v.len()
        )));
    }
    Ok((e, v))
}

/// Adds `--truth-effect` values (`EFFECT=V1,V2,..`) to `robot`'s
/// `[calibration.known_effects]`, replacing a value of the same effect: the machine of
/// `cpm validate --commands --truth T.toml --truth-effect ...` is the one
/// `cpm simulate --truth T.toml --truth-effect ...` simulated.
pub fn add_truth_effects(robot: &mut Robot, specs: &[String]) -> anyhow::Result<()> {
    for s in specs {
        let (e, v) = truth_effect_for(s, robot)?;
        robot
            .description
            .calibration
            .get_or_insert_with(Default::default)
            .known_effects
            .insert(e.name().to_string(), v);
    }
    Ok(())
}
