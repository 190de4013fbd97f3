//! The crates depend on each other only as `docs/architecture.md` ("What each crate may depend
//! on") allows: every workspace member has a row, uses no workspace crate its row does not name,
//! and none of the outside crates its row forbids. And every crate root forbids unsafe code but
//! the two that say why they need it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the workspace root")
        .to_path_buf()
}

fn read_toml(path: &Path) -> toml::Table {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.parse()
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The crate names in back-ticks of one table cell.
fn names(cell: &str) -> BTreeSet<String> {
    cell.split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect()
}

struct Rule {
    allowed: Option<BTreeSet<String>>,
    never: BTreeSet<String>,
}

/// The table's rows: crate → what it may use (None: any crate) and what it must not.
fn rules() -> BTreeMap<String, Rule> {
    let doc = std::fs::read_to_string(root().join("docs/architecture.md")).expect("architecture");
    let section = doc
        .split("### What each crate may depend on")
        .nth(1)
        .expect("the dependency section of docs/architecture.md");
    let mut rules = BTreeMap::new();
    for line in section.lines().skip_while(|l| !l.starts_with('|')) {
        if !line.starts_with('|') {
            break;
        }
        let cells: Vec<&str> = line.trim_matches('|').split('|').map(str::trim).collect();
        let [name, allowed, never] = cells[..] else {
            panic!("a row of three cells: {line}");
        };
        let Some(name) = names(name).into_iter().next() else {
            continue; // the header and its rule
        };
        let allowed = (!allowed.starts_with("every")).then(|| names(allowed));
        rules.insert(
            name,
            Rule {
                allowed,
                never: names(never),
            },
        );
    }
    rules
}

#[test]
fn crates_depend_only_on_what_the_architecture_allows() {
    let rules = rules();
    let workspace = read_toml(&root().join("Cargo.toml"));
    let members: Vec<String> = workspace["workspace"]["members"]
        .as_array()
        .expect("members")
        .iter()
        .map(|m| m.as_str().expect("member path").to_string())
        .collect();
    let mut crates = BTreeMap::new();
    for m in &members {
        let manifest = read_toml(&root().join(m).join("Cargo.toml"));
        let name = manifest["package"]["name"]
            .as_str()
            .expect("name")
            .to_string();
        let table = manifest.get("dependencies").and_then(|d| d.as_table());
        let mut deps: BTreeSet<String> = table
            .map(|d| d.keys().cloned().collect())
            .unwrap_or_default();
        // The schema's `bus` feature is iceoryx2: a crate that turns it on links iceoryx2.
        let schema_features = table
            .and_then(|d| d.get("auvnav-shm-schema"))
            .and_then(|d| d.get("features"))
            .and_then(|f| f.as_array())
            .into_iter()
            .flatten()
            .filter_map(|f| f.as_str());
        if schema_features.into_iter().any(|f| f == "bus") {
            deps.insert("iceoryx2".to_string());
        }
        crates.insert(name, deps);
    }
    let workspace_names: BTreeSet<String> = crates.keys().cloned().collect();
    let mut problems = Vec::new();
    for (name, deps) in &crates {
        let Some(rule) = rules.get(name) else {
            problems.push(format!("{name}: no row in docs/architecture.md"));
            continue;
        };
        for d in deps {
            let inside = workspace_names.contains(d);
            if inside && rule.allowed.as_ref().is_some_and(|a| !a.contains(d)) {
                problems.push(format!(
                    "{name} depends on {d}, which its row does not allow"
                ));
            }
            if rule.never.contains(d) {
                problems.push(format!("{name} depends on {d}, which its row forbids"));
            }
        }
    }
    for name in rules.keys() {
        if !crates.contains_key(name) {
            problems.push(format!(
                "docs/architecture.md names {name}, not a workspace member"
            ));
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

/// The crates whose roots may not forbid unsafe code, and why.
const UNSAFE_WITH_A_REASON: [(&str, &str); 2] = [
    (
        "shm-schema",
        "with its `bus` feature, iceoryx2's zero-copy derive emits `unsafe impl` and SIGHUP is \
         ignored through libc (without it, the root forbids unsafe code)",
    ),
    (
        "daemon/core",
        "the covariance propagation's AVX2 path (`#![deny(unsafe_code)]`, one `allow`)",
    ),
];

#[test]
fn every_crate_root_forbids_unsafe_code_unless_it_says_why() {
    let workspace = read_toml(&root().join("Cargo.toml"));
    let mut missing = Vec::new();
    for m in workspace["workspace"]["members"]
        .as_array()
        .expect("members")
        .iter()
        .map(|m| m.as_str().expect("member path"))
    {
        let dir = root().join(m);
        let manifest = read_toml(&dir.join("Cargo.toml"));
        let mut roots: Vec<PathBuf> = ["src/lib.rs", "src/main.rs"]
            .iter()
            .map(|f| dir.join(f))
            .filter(|p| p.exists())
            .collect();
        if let Ok(bins) = std::fs::read_dir(dir.join("src/bin")) {
            roots.extend(bins.filter_map(|e| e.ok()).map(|e| e.path()));
        }
        for bin in manifest
            .get("bin")
            .and_then(|b| b.as_array())
            .into_iter()
            .flatten()
        {
            if let Some(path) = bin.get("path").and_then(|p| p.as_str()) {
                roots.push(dir.join(path));
            }
        }
        roots.sort();
        roots.dedup();
        let reason = UNSAFE_WITH_A_REASON.iter().find(|(d, _)| *d == m);
        for r in roots {
            let text = std::fs::read_to_string(&r).expect("crate root");
            let forbids = text.contains("#![forbid(unsafe_code)]");
            match reason {
                None if !forbids => missing.push(r.display().to_string()),
                Some((_, why)) if forbids => {
                    panic!(
                        "{}: forbids unsafe code, but is listed as needing it ({why})",
                        r.display()
                    )
                }
                _ => {}
            }
        }
    }
    assert!(
        missing.is_empty(),
        "crate roots without #![forbid(unsafe_code)]: {missing:?}"
    );
}
