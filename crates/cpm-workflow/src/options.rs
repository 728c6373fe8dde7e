//! The typed values of the jobs' options that a caller gives as text (the effects, the robust
//! loss, the tolerances, the held groups), each parsed in one place: clap's value parsers in
//! the command line and the binding's options by name (serde) both call these, so a job never
//! splits a command-line string.
//!
//! A refused value is an [`OptionError`] whose text names the option as `cpm` does
//! (`--robust "pink:3": unknown loss ...`); the command line prints it as it is (exit code 2).
use std::fmt;
use std::str::FromStr;

use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::{Deserialize, Serialize, Serializer};

use crate::calib::{Effect, Tolerances};
use cpm_lm::Loss;

/// A value of an option that does not parse; its text names the option (a usage error,
/// exit code 2: [`crate::error::exit_kind`]).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct OptionError {
    /// The option, as on the command line (`--robust`).
    pub option: &'static str,
    /// What is wrong, the option named first.
    pub message: String,
}

impl OptionError {
    fn new(option: &'static str, message: String) -> Self {
        Self { option, message }
    }
}

/// `--effects LIST`: the effects modelled beside the installation errors, comma-separated
/// names ([`Effect::parse`]); `none` or an empty list for none. An unknown or repeated name is
/// refused (`--effects: unknown effect ...`).
pub fn parse_effects(list: &str) -> Result<Vec<Effect>, OptionError> {
    match list.trim() {
        "none" | "" => Ok(Vec::new()),
        list => crate::io::parse_effects(list)
            .map_err(|m| OptionError::new("--effects", format!("--effects: {m}"))),
    }
}

/// `cpm refine --candidates LIST`: candidate effects, comma-separated names (no `none`: an
/// empty list is none).
pub fn parse_candidates(list: &str) -> Result<Vec<Effect>, OptionError> {
    crate::io::parse_effects(list)
        .map_err(|m| OptionError::new("--candidates", format!("--candidates: {m}")))
}

/// `--robust LOSS:K`: `huber:K`, `cauchy:K` or `tukey:K` with K in um (> 0), or `none`
/// (also `squared`) for least squares.
pub fn parse_loss(spec: &str) -> Result<Loss, OptionError> {
    let refuse = |m: String| OptionError::new("--robust", format!("--robust {m}"));
    let spec = spec.trim();
    if spec == "none" || spec == "squared" {
        return Ok(Loss::Squared);
    }
    let (kind, value) = spec.split_once(':').ok_or_else(|| {
        refuse(format!(
            "{spec:?}: expected huber:K, cauchy:K or tukey:K (K in um, > 0) or none"
        ))
    })?;
    let k: f64 = value
        .trim()
        .parse()
        .ok()
        .filter(|v: &f64| v.is_finite() && *v > 0.0)
        .ok_or_else(|| {
            refuse(format!(
                "{spec:?}: K = {value:?} must be a number of um > 0"
            ))
        })?;
    match kind.trim() {
        "huber" => Ok(Loss::Huber(k)),
        "cauchy" => Ok(Loss::Cauchy(k)),
        "tukey" => Ok(Loss::Tukey(k)),
        other => Err(refuse(format!(
            "{spec:?}: unknown loss {other:?} (huber, cauchy, tukey, none)"
        ))),
    }
}

/// A loss as `--robust` takes it: [`parse_loss`] of this text gives the loss back.
pub fn loss_text(loss: &Loss) -> String {
    match loss {
        Loss::Squared => "none".to_string(),
        Loss::Huber(k) => format!("huber:{k}"),
        Loss::Cauchy(k) => format!("cauchy:{k}"),
        Loss::Tukey(k) => format!("tukey:{k}"),
    }
}

/// Checks a loss made in code (one parsed by [`parse_loss`] always passes): its K is a
/// number > 0.
pub fn check_loss(loss: &Loss) -> Result<(), OptionError> {
    match loss {
        Loss::Squared => Ok(()),
        Loss::Huber(k) | Loss::Cauchy(k) | Loss::Tukey(k) if k.is_finite() && *k > 0.0 => Ok(()),
        Loss::Huber(k) | Loss::Cauchy(k) | Loss::Tukey(k) => Err(OptionError::new(
            "--robust",
            format!(
                "--robust {:?}: K = {:?} must be a number of um > 0",
                loss_text(loss),
                k.to_string()
            ),
        )),
    }
}

/// A group of parameters by name: `installation_errors`, an effect's name, or an
/// instrument's. Checked against the model's groups when the job builds its prior (a name
/// the model lacks is refused there, naming it).
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Group(pub String);

impl Group {
    /// The group's name.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for Group {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl FromStr for Group {
    type Err = std::convert::Infallible;
    /// Any name (`--hold GROUP`): it is checked against the model's groups later.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ok(Group(s.to_string()))
    }
}

impl From<&str> for Group {
    fn from(s: &str) -> Self {
        Group(s.to_string())
    }
}

/// An a-priori tolerance of a group of parameters (`--tolerance GROUP=VALUE`), in the
/// group's unit; `f64::INFINITY` frees the group.
#[derive(Debug, Clone, PartialEq)]
pub struct Tolerance {
    /// The group.
    pub group: Group,
    /// The tolerance, > 0 (infinite: free).
    pub value: f64,
}

impl Tolerance {
    /// The tolerance `value` of `group`, checked (> 0, `inf` frees the group); refused as
    /// `--tolerance` refuses `spec`, the text it came from.
    fn checked(group: &str, value: f64, spec: &str) -> Result<Self, OptionError> {
        Tolerances::default()
            .set(group, value)
            .map_err(|e| OptionError::new("--tolerance", format!("--tolerance {spec:?}: {e}")))?;
        Ok(Tolerance {
            group: Group(group.to_string()),
            value,
        })
    }

    /// The tolerance `value` of `group`, checked: > 0 (`f64::INFINITY` frees the group).
    pub fn new(group: &str, value: f64) -> Result<Self, OptionError> {
        Self::checked(group, value, &format!("{group}={value}"))
    }
}

/// A tolerance's value: a number, or `inf` / `infinity`.
fn tolerance_value(text: &str) -> Option<f64> {
    match text.trim() {
        "inf" | "infinity" => Some(f64::INFINITY),
        x => x.parse().ok(),
    }
}

/// `--tolerance GROUP=VALUE`: the group's tolerance in its unit (`inf` frees the group), > 0.
pub fn parse_tolerance(spec: &str) -> Result<Tolerance, OptionError> {
    let refuse = |m: String| OptionError::new("--tolerance", format!("--tolerance {spec:?}: {m}"));
    let (group, value) = spec
        .split_once('=')
        .ok_or_else(|| refuse("expected GROUP=VALUE, e.g. installation_errors=2000".to_string()))?;
    let v = tolerance_value(value)
        .ok_or_else(|| refuse(format!("{:?} is not a number", value.trim())))?;
    Tolerance::checked(group.trim(), v, spec)
}

impl FromStr for Tolerance {
    type Err = OptionError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        parse_tolerance(s)
    }
}

/// `GROUP=VALUE`, as `--tolerance` takes it ([`parse_tolerance`] gives it back).
impl fmt::Display for Tolerance {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}={}", self.group, self.value)
    }
}

/// As `"GROUP=VALUE"`, the text `--tolerance` takes.
impl Serialize for Tolerance {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

/// From `"GROUP=VALUE"` or `{"group": GROUP, "value": VALUE}` (VALUE a number or `"inf"`).
impl<'de> Deserialize<'de> for Tolerance {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Tolerance;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("GROUP=VALUE or {\"group\": GROUP, \"value\": VALUE}")
            }
            fn visit_str<E: de::Error>(self, s: &str) -> Result<Tolerance, E> {
                parse_tolerance(s).map_err(E::custom)
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Tolerance, A::Error> {
                #[derive(Deserialize)]
                #[serde(untagged)]
                enum Value {
                    Number(f64),
                    Text(String),
                }
                let (mut group, mut value): (Option<String>, Option<Value>) = (None, None);
                while let Some(key) = map.next_key::<String>()? {
                    match key.as_str() {
                        "group" => group = Some(map.next_value()?),
                        "value" => value = Some(map.next_value()?),
                        other => return Err(de::Error::unknown_field(other, &["group", "value"])),
                    }
                }
                let group = group.ok_or_else(|| de::Error::missing_field("group"))?;
                match value.ok_or_else(|| de::Error::missing_field("value"))? {
                    Value::Number(v) => Tolerance::new(&group, v).map_err(de::Error::custom),
                    Value::Text(t) => {
                        parse_tolerance(&format!("{group}={t}")).map_err(de::Error::custom)
                    }
                }
            }
        }
        d.deserialize_any(V)
    }
}

/// Serde of an `Option<Vec<Effect>>` option: `null` (the description's), a list of names
/// (`[]`: none), or `cpm`'s text (`"link_offset,link_scale"`, `"none"`), parsed by `parse`.
/// A list of names is taken as the text of its items joined by commas.
fn effects_of<'de, D: Deserializer<'de>>(
    d: D,
    parse: fn(&str) -> Result<Vec<Effect>, OptionError>,
) -> Result<Option<Vec<Effect>>, D::Error> {
    struct V(fn(&str) -> Result<Vec<Effect>, OptionError>);
    impl<'de> Visitor<'de> for V {
        type Value = Option<Vec<Effect>>;
        fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
            f.write_str("effect names: a list, or comma-separated text")
        }
        fn visit_none<E: de::Error>(self) -> Result<Self::Value, E> {
            Ok(None)
        }
        fn visit_unit<E: de::Error>(self) -> Result<Self::Value, E> {
            Ok(None)
        }
        fn visit_some<D: Deserializer<'de>>(self, d: D) -> Result<Self::Value, D::Error> {
            d.deserialize_any(self)
        }
        fn visit_str<E: de::Error>(self, s: &str) -> Result<Self::Value, E> {
            (self.0)(s).map(Some).map_err(E::custom)
        }
        fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
            let mut names: Vec<String> = Vec::new();
            while let Some(n) = seq.next_element::<String>()? {
                names.push(n);
            }
            (self.0)(&names.join(","))
                .map(Some)
                .map_err(de::Error::custom)
        }
    }
    d.deserialize_option(V(parse))
}

/// Serde of [`FitOptions::effects`](crate::fit::FitOptions::effects) and the other jobs'
/// `effects`: `null`, a list of names, or `--effects`' text ([`parse_effects`]).
pub mod effects {
    use super::*;
    /// As `null` or the list of names.
    pub fn serialize<S: Serializer>(e: &Option<Vec<Effect>>, s: S) -> Result<S::Ok, S::Error> {
        e.serialize(s)
    }
    /// From `null`, a list of names or `--effects`' text.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Vec<Effect>>, D::Error> {
        effects_of(d, parse_effects)
    }
}

/// Serde of [`RefineOptions::candidates`](crate::refine::RefineOptions::candidates): `null`,
/// a list of names, or `--candidates`' text ([`parse_candidates`]).
pub mod candidates {
    use super::*;
    /// As `null` or the list of names.
    pub fn serialize<S: Serializer>(e: &Option<Vec<Effect>>, s: S) -> Result<S::Ok, S::Error> {
        e.serialize(s)
    }
    /// From `null`, a list of names or `--candidates`' text.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Vec<Effect>>, D::Error> {
        effects_of(d, parse_candidates)
    }
}

/// Serde of [`FitOptions::robust`](crate::fit::FitOptions::robust): `null` or `--robust`'s
/// text (`"huber:1.5"`, `"none"`; [`parse_loss`], [`loss_text`]).
pub mod robust {
    use super::*;
    /// As `null` or `--robust`'s text.
    pub fn serialize<S: Serializer>(l: &Option<Loss>, s: S) -> Result<S::Ok, S::Error> {
        l.as_ref().map(loss_text).serialize(s)
    }
    /// From `null` or `--robust`'s text.
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Loss>, D::Error> {
        Option::<String>::deserialize(d)?
            .map(|s| parse_loss(&s).map_err(de::Error::custom))
            .transpose()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn effects_take_todays_forms() {
        assert_eq!(parse_effects("none").unwrap(), Vec::<Effect>::new());
        assert_eq!(parse_effects(" ").unwrap(), Vec::<Effect>::new());
        assert_eq!(
            parse_effects("link_offset, link_scale").unwrap(),
            vec![Effect::LinkOffset, Effect::LinkScale]
        );
        let e = parse_effects("nosuch").unwrap_err();
        assert!(
            e.to_string()
                .starts_with("--effects: unknown effect `nosuch`"),
            "{e}"
        );
        assert_eq!(
            parse_effects("link_offset,link_offset")
                .unwrap_err()
                .to_string(),
            "--effects: effect `link_offset` given twice"
        );
        assert_eq!(parse_candidates("").unwrap(), Vec::<Effect>::new());
        let e = parse_candidates("none").unwrap_err();
        assert!(
            e.to_string()
                .starts_with("--candidates: unknown effect `none`"),
            "{e}"
        );
    }

    #[test]
    fn losses_take_todays_forms_and_refuse_with_todays_words() {
        assert_eq!(parse_loss("none").unwrap(), Loss::Squared);
        assert_eq!(parse_loss("squared").unwrap(), Loss::Squared);
        assert_eq!(parse_loss(" huber:1.5 ").unwrap(), Loss::Huber(1.5));
        assert_eq!(parse_loss("cauchy: 3").unwrap(), Loss::Cauchy(3.0));
        assert_eq!(parse_loss("tukey:4e1").unwrap(), Loss::Tukey(40.0));
        for (bad, message) in [
            (
                "pink:3",
                "--robust \"pink:3\": unknown loss \"pink\" (huber, cauchy, tukey, none)",
            ),
            (
                "huber:-1",
                "--robust \"huber:-1\": K = \"-1\" must be a number of um > 0",
            ),
            (
                "huber:inf",
                "--robust \"huber:inf\": K = \"inf\" must be a number of um > 0",
            ),
            (
                "huber",
                "--robust \"huber\": expected huber:K, cauchy:K or tukey:K (K in um, > 0) or none",
            ),
        ] {
            assert_eq!(parse_loss(bad).unwrap_err().to_string(), message);
        }
        for l in [
            Loss::Squared,
            Loss::Huber(0.1),
            Loss::Cauchy(1e-7),
            Loss::Tukey(3.0),
        ] {
            assert_eq!(parse_loss(&loss_text(&l)).unwrap(), l);
            assert!(check_loss(&l).is_ok());
        }
        assert_eq!(
            check_loss(&Loss::Huber(-2.0)).unwrap_err().to_string(),
            "--robust \"huber:-2\": K = \"-2\" must be a number of um > 0"
        );
    }

    #[test]
    fn tolerances_take_todays_forms_and_refuse_with_todays_words() {
        let t = parse_tolerance("link_scale=50000").unwrap();
        assert_eq!((t.group.as_str(), t.value), ("link_scale", 50000.0));
        let t = parse_tolerance(" installation_errors = inf").unwrap();
        assert_eq!(
            (t.group.as_str(), t.value),
            ("installation_errors", f64::INFINITY)
        );
        assert_eq!(parse_tolerance("x=infinity").unwrap().value, f64::INFINITY);
        assert_eq!(
            parse_tolerance("link_scale").unwrap_err().to_string(),
            "--tolerance \"link_scale\": expected GROUP=VALUE, e.g. installation_errors=2000"
        );
        assert_eq!(
            parse_tolerance("link_scale=big").unwrap_err().to_string(),
            "--tolerance \"link_scale=big\": \"big\" is not a number"
        );
        let e = parse_tolerance("link_scale=-1").unwrap_err().to_string();
        assert!(
            e.starts_with("--tolerance \"link_scale=-1\": ") && e.contains("must be > 0"),
            "{e}"
        );
        assert!(parse_tolerance("link_scale=0").is_err());
        assert!(parse_tolerance("link_scale=nan").is_err());
        // Text and back.
        for spec in ["a=2000", "b=inf", "c=0.125", "d=1e-9"] {
            let t = parse_tolerance(spec).unwrap();
            assert_eq!(parse_tolerance(&t.to_string()).unwrap(), t);
        }
    }

    #[test]
    fn options_by_name_take_text_and_structured_values() {
        #[derive(Debug, PartialEq, Serialize, Deserialize)]
        struct O {
            #[serde(with = "effects")]
            effects: Option<Vec<Effect>>,
            #[serde(with = "candidates")]
            candidates: Option<Vec<Effect>>,
            #[serde(with = "robust")]
            robust: Option<Loss>,
            tolerance: Vec<Tolerance>,
            hold: Vec<Group>,
        }
        let o: O = serde_json::from_str(
            r#"{"effects": "link_offset,link_scale", "candidates": ["backlash"],
                "robust": "huber:1.5",
                "tolerance": ["link_scale=2000", {"group": "installation_errors", "value": "inf"},
                              {"group": "link_offset", "value": 50}],
                "hold": ["link_scale"]}"#,
        )
        .unwrap();
        assert_eq!(o.effects, Some(vec![Effect::LinkOffset, Effect::LinkScale]));
        assert_eq!(o.candidates, Some(vec![Effect::Backlash]));
        assert_eq!(o.robust, Some(Loss::Huber(1.5)));
        assert_eq!(o.tolerance[1].value, f64::INFINITY);
        assert_eq!(o.tolerance[2].value, 50.0);
        assert_eq!(o.hold, vec![Group::from("link_scale")]);
        // Back and forth, and today's text: `{"robust": "huber:1.5"}`, `["link_scale=2000"]`.
        let v = serde_json::to_value(&o).unwrap();
        assert_eq!(v["robust"], "huber:1.5");
        assert_eq!(v["tolerance"][0], "link_scale=2000");
        assert_eq!(v["tolerance"][1], "installation_errors=inf");
        assert_eq!(
            v["effects"],
            serde_json::json!(["link_offset", "link_scale"])
        );
        assert_eq!(serde_json::from_value::<O>(v).unwrap(), o);
        // None, and none.
        let o: O = serde_json::from_str(
            r#"{"effects": null, "candidates": [], "robust": null, "tolerance": [], "hold": []}"#,
        )
        .unwrap();
        assert_eq!((o.effects, o.candidates), (None, Some(vec![])));
        let o: O = serde_json::from_str(
            r#"{"effects": "none", "candidates": null, "robust": "none", "tolerance": [], "hold": []}"#,
        )
        .unwrap();
        assert_eq!((o.effects, o.robust), (Some(vec![]), Some(Loss::Squared)));
        // Refused with the command's words.
        let bad = |text: &str| serde_json::from_str::<O>(text).unwrap_err().to_string();
        let e = bad(
            r#"{"effects": ["nosuch"], "candidates": null, "robust": null, "tolerance": [], "hold": []}"#,
        );
        assert!(e.starts_with("--effects: unknown effect `nosuch`"), "{e}");
        let e = bad(
            r#"{"effects": null, "candidates": null, "robust": "pink:3", "tolerance": [], "hold": []}"#,
        );
        assert!(e.starts_with("--robust \"pink:3\": unknown loss"), "{e}");
        let e = bad(
            r#"{"effects": null, "candidates": null, "robust": null, "tolerance": ["x"], "hold": []}"#,
        );
        assert!(
            e.starts_with("--tolerance \"x\": expected GROUP=VALUE"),
            "{e}"
        );
    }

    #[test]
    fn refine_options_by_name_read_the_typed_values_through_the_flattened_fit() {
        let mut v =
            serde_json::to_value(crate::refine::RefineOptions::new("R", vec![], "O")).unwrap();
        assert_eq!(v["effects"], serde_json::Value::Null);
        assert_eq!(v["tolerance"], serde_json::json!([]));
        v["effects"] = serde_json::json!(["link_offset"]);
        v["robust"] = serde_json::json!("cauchy:2");
        v["tolerance"] = serde_json::json!([
            {"group": "link_offset", "value": 50},
            "installation_errors=inf"
        ]);
        v["hold"] = serde_json::json!(["link_scale"]);
        v["candidates"] = serde_json::json!("backlash,link_scale");
        let o: crate::refine::RefineOptions = serde_json::from_value(v.clone()).unwrap();
        assert_eq!(o.fit.effects, Some(vec![Effect::LinkOffset]));
        assert_eq!(o.fit.robust, Some(Loss::Cauchy(2.0)));
        assert_eq!(
            o.fit.tolerance,
            vec![
                Tolerance::new("link_offset", 50.0).unwrap(),
                Tolerance::new("installation_errors", f64::INFINITY).unwrap()
            ]
        );
        assert_eq!(o.fit.hold, vec![Group::from("link_scale")]);
        assert_eq!(
            o.candidates,
            Some(vec![Effect::Backlash, Effect::LinkScale])
        );
        v["robust"] = serde_json::json!("pink:3");
        let e = serde_json::from_value::<crate::refine::RefineOptions>(v)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("--robust \"pink:3\": unknown loss"), "{e}");
    }
}
