//! Value parsers shared by the commands' options (and by the option structs of the libraries,
//! with their `clap` feature). A value is checked when the command line is
//! parsed, so a malformed one is a usage error (exit status 2) named by its option before
//! anything runs; the commands keep their own checks for values that arrive other ways (files,
//! tests). The parsers return the text unchanged, for the commands' own parsing.

/// `NAME=V` or `NAME=V1,V2,V3`: an effect of the simulator's vocabulary (`auvnav sim
/// --list-effects`) with the right number of values, each in its range.
pub fn effect_setting(s: &str) -> Result<String, String> {
    let (name, values) = auvnav_sim::effects::parse_setting(s).map_err(|e| e.to_string())?;
    auvnav_sim::effects::Effects::default()
        .set(&name, &values)
        .map_err(|e| e.to_string())?;
    Ok(s.to_string())
}

/// `NAME=A,B` with two numbers (`--bound NAME=MIN,MAX`, `--prior NAME=MEAN,STD`).
pub fn name_and_two_numbers(s: &str) -> Result<String, String> {
    let Some((name, v)) = s.split_once('=') else {
        return Err("expected NAME=A,B".into());
    };
    if name.trim().is_empty() {
        return Err("no name before '='".into());
    }
    let nums: Result<Vec<f64>, _> = v.split(',').map(|x| x.trim().parse::<f64>()).collect();
    match nums {
        Ok(n) if n.len() == 2 && n.iter().all(|x| x.is_finite()) => Ok(s.to_string()),
        _ => Err(format!("expected two numbers after '=', got {v:?}")),
    }
}

/// `KEY=VALUE` with a non-empty key and value (`--set`).
pub fn key_value(s: &str) -> Result<String, String> {
    match s.split_once('=') {
        Some((k, v)) if !k.trim().is_empty() && !v.trim().is_empty() => Ok(s.to_string()),
        _ => Err("expected KEY=VALUE".into()),
    }
}

#[cfg(feature = "clap")]
/// A parser for a configuration enum of the core (which has no clap): one of `names`, parsed by
/// the type's `FromStr`, with the names listed in `--help` and in the error.
pub fn config_enum<T>(
    names: &'static [&'static str],
) -> impl clap::builder::TypedValueParser<Value = T>
where
    T: std::str::FromStr + Clone + Send + Sync + 'static,
{
    use clap::builder::TypedValueParser as _;
    clap::builder::PossibleValuesParser::new(names).map(|s| {
        s.parse::<T>()
            .unwrap_or_else(|_| unreachable!("{s} is one of the names the parser accepts"))
    })
}

/// `base` with `settings` (`key=value`, TOML values) applied, each key one of `base`'s own
/// (`what` names the table in messages).
pub fn apply_settings<T>(base: &T, settings: &[String], what: &str) -> Result<T, crate::StudyError>
where
    T: serde::Serialize + serde::de::DeserializeOwned,
{
    use crate::error::usage;
    let mut table = match toml::Table::try_from(base) {
        Ok(t) => t,
        Err(e) => usage!("the {what} configuration as a table: {e}"),
    };
    for s in settings {
        let Some((k, v)) = s.split_once('=') else {
            usage!("--set {s:?}: expected KEY=VALUE")
        };
        let Ok(value) = toml::from_str::<toml::Table>(&format!("x = {}", v.trim())) else {
            usage!("--set {s:?}: the value is not a TOML value")
        };
        let k = k.trim();
        if !table.contains_key(k) {
            usage!("--set {s:?}: no {what} setting {k:?}");
        }
        table.insert(k.to_owned(), value["x"].clone());
    }
    match table.try_into() {
        Ok(c) => Ok(c),
        Err(e) => usage!("--set: {e}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn effect_settings_are_checked_against_the_vocabulary() {
        assert!(effect_setting("dvl.scale_factor=1.003").is_ok());
        assert!(effect_setting("dvl.lever_arm=1,0,0.3").is_ok());
        assert!(effect_setting("dvl.scale_factr=1.003").is_err());
        assert!(effect_setting("dvl.scale_factor").is_err());
        assert!(effect_setting("dvl.scale_factor=abc").is_err());
        assert!(effect_setting("dvl.lever_arm=1,0").is_err());
    }

    #[test]
    fn pairs_and_key_values_need_their_form() {
        assert!(name_and_two_numbers("dvl.mount_yaw=-5,5").is_ok());
        assert!(name_and_two_numbers("dvl.mount_yaw=-5").is_err());
        assert!(name_and_two_numbers("=1,2").is_err());
        assert!(name_and_two_numbers("x=1,nan").is_err());
        assert!(key_value("gate_sigma=4").is_ok());
        assert!(key_value("gate_sigma=").is_err());
        assert!(key_value("gate_sigma").is_err());
    }
}
