//! The configuration options every on-board program shares, so one convention holds for all of
//! them: `PROGRAM --config FILE` runs, and both `PROGRAM --check-config FILE` and `PROGRAM
//! --config FILE --check-config` check the file, print it with the defaults filled in and exit
//! (status 2 when it does not parse or validate).

/// `--config FILE` and `--check-config [FILE]` (flatten into a program's arguments).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ConfigArgs {
    /// The program's TOML configuration.
    #[arg(long, value_name = "FILE")]
    pub config: Option<String>,
    /// Check the configuration (this FILE, or the one --config names), print it with the
    /// defaults filled in, and exit.
    #[arg(long, value_name = "FILE", num_args = 0..=1)]
    pub check_config: Option<Option<String>>,
}

/// What the options ask for.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ConfigRequest {
    /// Run with this configuration.
    Run(String),
    /// Check this configuration and exit.
    Check(String),
    /// Neither option: the program's defaults (only where a program has them).
    Defaults { check: bool },
}

impl ConfigArgs {
    /// The request, or why the options contradict each other.
    pub fn request(&self) -> Result<ConfigRequest, String> {
        match (&self.check_config, &self.config) {
            (Some(Some(f)), Some(c)) if f != c => Err(format!(
                "--check-config {f} and --config {c} name different files"
            )),
            (Some(Some(f)), _) => Ok(ConfigRequest::Check(f.clone())),
            (Some(None), Some(c)) => Ok(ConfigRequest::Check(c.clone())),
            (Some(None), None) => Ok(ConfigRequest::Defaults { check: true }),
            (None, Some(c)) => Ok(ConfigRequest::Run(c.clone())),
            (None, None) => Ok(ConfigRequest::Defaults { check: false }),
        }
    }

    /// The request of a program that needs a file: (path, check only).
    pub fn required(&self) -> Result<(String, bool), String> {
        match self.request()? {
            ConfigRequest::Run(p) => Ok((p, false)),
            ConfigRequest::Check(p) => Ok((p, true)),
            ConfigRequest::Defaults { .. } => {
                Err("--config FILE is required (or --check-config FILE)".into())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct P {
        #[command(flatten)]
        c: ConfigArgs,
    }

    fn parse(args: &[&str]) -> Result<(String, bool), String> {
        let mut v = vec!["p"];
        v.extend_from_slice(args);
        P::try_parse_from(v)
            .map_err(|e| e.to_string())?
            .c
            .required()
    }

    #[test]
    fn both_forms_check_and_config_alone_runs() {
        assert_eq!(parse(&["--config", "a.toml"]), Ok(("a.toml".into(), false)));
        assert_eq!(
            parse(&["--check-config", "a.toml"]),
            Ok(("a.toml".into(), true))
        );
        assert_eq!(
            parse(&["--config", "a.toml", "--check-config"]),
            Ok(("a.toml".into(), true))
        );
        assert_eq!(
            parse(&["--check-config", "--config", "a.toml"]),
            Ok(("a.toml".into(), true))
        );
        assert!(parse(&[]).is_err());
        assert!(parse(&["--check-config"]).is_err());
        assert!(parse(&["--check-config", "a.toml", "--config", "b.toml"]).is_err());
    }
}
