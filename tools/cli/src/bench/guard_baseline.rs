//! The baseline file of `auvnav bench guard` (`tools/cli/guard-baseline.json`): per build profile
//! and processor, the ratios of the judged workloads to the reference workload.

use serde::Serialize;
use std::collections::BTreeMap;

/// A baseline file: per build profile and processor, the ratios of the judged workloads to the
/// reference workload. The ratio of the project's code to the reference depends on the
/// processor's design (vector units, caches), so each processor the guard runs on keeps its own.
#[derive(Debug, Clone, Default, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GuardBaseline {
    pub baselines: Vec<Baseline>,
}

/// One build profile's ratios on one processor.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Baseline {
    /// "dev" or "release" (`profile`).
    pub profile: String,
    /// Where it was measured (`guard::cpu_model`); judged only on the same.
    pub processor: String,
    /// Per workload: the median ratio to the reference workload.
    pub ratios: BTreeMap<String, f64>,
    /// When, from which commit and how the ratios were measured.
    pub measured: String,
}

/// The first layout of the file (one processor per profile), still read.
#[derive(Debug, serde::Deserialize)]
struct BaselinePerProfile {
    profiles: BTreeMap<String, BTreeMap<String, f64>>,
    measured: BTreeMap<String, String>,
    #[serde(default)]
    processors: BTreeMap<String, String>,
}

impl GuardBaseline {
    /// The file's text, in either layout.
    pub fn parse(text: &str) -> anyhow::Result<GuardBaseline> {
        // The layout is told by its top-level key, so that a malformed file is reported in the
        // terms of its own layout.
        let value: serde_json::Value = serde_json::from_str(text)?;
        if value.get("baselines").is_some() {
            return Ok(serde_json::from_value(value)?);
        }
        let old: BaselinePerProfile = serde_json::from_value(value)?;
        Ok(GuardBaseline {
            baselines: old
                .profiles
                .into_iter()
                .map(|(profile, ratios)| Baseline {
                    processor: old
                        .processors
                        .get(&profile)
                        .cloned()
                        .unwrap_or_else(|| "unknown processor".into()),
                    measured: old.measured.get(&profile).cloned().unwrap_or_default(),
                    profile,
                    ratios,
                })
                .collect(),
        })
    }

    /// The baseline of `profile` measured on `processor`; `Err` with the processors that have
    /// one for `profile` (empty: none at all).
    pub fn find(&self, profile: &str, processor: &str) -> Result<&Baseline, Vec<&str>> {
        let of_profile = || self.baselines.iter().filter(|b| b.profile == profile);
        of_profile()
            .find(|b| b.processor == processor)
            .ok_or_else(|| of_profile().map(|b| b.processor.as_str()).collect())
    }

    /// Adds `b`, replacing the baseline of its profile and processor (the others kept).
    pub fn insert(&mut self, b: Baseline) {
        self.baselines
            .retain(|x| !(x.profile == b.profile && x.processor == b.processor));
        self.baselines.push(b);
        self.baselines
            .sort_by(|x, y| (&x.profile, &x.processor).cmp(&(&y.profile, &y.processor)));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn baseline(profile: &str, processor: &str, replay: f64) -> Baseline {
        Baseline {
            profile: profile.into(),
            processor: processor.into(),
            ratios: [("replay core".to_string(), replay)].into(),
            measured: String::new(),
        }
    }

    /// Each processor keeps its own baseline: one found for its profile and processor, replaced
    /// in place when written again; another processor's is not taken for it.
    #[test]
    fn baselines_are_kept_per_profile_and_processor() {
        let mut b = GuardBaseline::default();
        b.insert(baseline("dev", "A", 1.0));
        b.insert(baseline("dev", "B", 2.0));
        b.insert(baseline("release", "A", 3.0));
        b.insert(baseline("dev", "A", 1.5));
        assert_eq!(b.baselines.len(), 3);
        assert_eq!(
            b.find("dev", "A").expect("dev on A").ratios["replay core"],
            1.5
        );
        assert_eq!(
            b.find("dev", "B").expect("dev on B").ratios["replay core"],
            2.0
        );
        assert_eq!(
            b.find("release", "B").expect_err("no release on B"),
            vec!["A"]
        );
        assert!(
            b.find("bench", "A")
                .expect_err("no such profile")
                .is_empty()
        );
        let text = serde_json::to_string(&b).expect("written");
        let again = GuardBaseline::parse(&text).expect("read back");
        assert_eq!(again.baselines.len(), 3);
    }

    /// A file in the first layout (one processor per profile) is read as baselines per processor.
    #[test]
    fn the_first_layout_is_read() {
        let text = r#"{
            "profiles": {"dev": {"replay core": 0.9}, "release": {"replay core": 0.7}},
            "measured": {"dev": "then", "release": "then"},
            "processors": {"dev": "AMD EPYC, 2 CPUs", "release": "AMD EPYC, 2 CPUs"}
        }"#;
        let b = GuardBaseline::parse(text).expect("read");
        let dev = b.find("dev", "AMD EPYC, 2 CPUs").expect("dev");
        assert_eq!(
            (dev.ratios["replay core"], dev.measured.as_str()),
            (0.9, "then")
        );
        assert!(b.find("release", "AMD EPYC, 2 CPUs").is_ok());
    }

    /// The committed baseline file reads, and has the dev profile CI judges.
    #[test]
    fn the_committed_baselines_read() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("guard-baseline.json");
        let text = std::fs::read_to_string(&path).expect("the committed baseline file");
        let b: GuardBaseline = serde_json::from_str(&text).expect("in the current layout");
        assert!(b.baselines.iter().any(|x| x.profile == "dev"));
    }
}
