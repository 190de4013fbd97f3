//! No crate of the workspace has a module cycle, file by file or between top-level modules: a
//! module's `crate::…` and `super::…` paths (outside comments) are its dependencies.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Module path of a source file: `aid/usbl/mod.rs` → `aid::usbl`, `aid/dvl.rs` → `aid::dvl`.
fn module_of(rel: &Path) -> String {
    let mut parts: Vec<String> = rel
        .iter()
        .map(|p| p.to_string_lossy().trim_end_matches(".rs").to_string())
        .collect();
    if parts.last().is_some_and(|p| p == "mod" || p == "lib") {
        parts.pop();
    }
    parts.join("::")
}

fn sources(dir: &Path, root: &Path, out: &mut Vec<(String, String)>) {
    for e in std::fs::read_dir(dir).expect("read_dir").flatten() {
        let p = e.path();
        if p.is_dir() {
            sources(&p, root, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            let rel = p.strip_prefix(root).expect("under src");
            out.push((module_of(rel), std::fs::read_to_string(&p).expect("read")));
        }
    }
}

/// The modules a file refers to, resolved to the longest known module path.
fn dependencies(module: &str, text: &str, known: &BTreeSet<String>) -> BTreeSet<String> {
    let mut deps = BTreeSet::new();
    let parent: Vec<&str> = module.split("::").filter(|s| !s.is_empty()).collect();
    for line in text.lines() {
        let code = line.split("//").next().unwrap_or_default();
        for (prefix, base) in [
            ("crate::", Vec::new()),
            ("super::", {
                let mut b = parent.clone();
                b.pop();
                b
            }),
        ] {
            let mut rest = code;
            while let Some(i) = rest.find(prefix) {
                rest = &rest[i + prefix.len()..];
                let path: Vec<&str> = rest
                    .split(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':'))
                    .next()
                    .unwrap_or_default()
                    .split("::")
                    .filter(|s| !s.is_empty())
                    .collect();
                let mut full: Vec<&str> = base.clone();
                full.extend(path);
                // The longest prefix that is a module (or the module `base` itself).
                let target = (0..=full.len())
                    .rev()
                    .map(|n| full[..n].join("::"))
                    .find(|m| known.contains(m));
                if let Some(t) = target
                    && t != module
                    && !t.is_empty()
                {
                    deps.insert(t);
                }
            }
        }
    }
    deps
}

fn find_cycle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        n: &str,
        g: &BTreeMap<String, BTreeSet<String>>,
        state: &mut BTreeMap<String, u8>,
        stack: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        state.insert(n.to_string(), 1);
        stack.push(n.to_string());
        for m in g.get(n).into_iter().flatten() {
            match state.get(m.as_str()).copied().unwrap_or(0) {
                1 => {
                    let start = stack.iter().position(|s| s == m).unwrap_or(0);
                    let mut c = stack[start..].to_vec();
                    c.push(m.clone());
                    return Some(c);
                }
                0 => {
                    if let Some(c) = visit(m, g, state, stack) {
                        return Some(c);
                    }
                }
                _ => {}
            }
        }
        stack.pop();
        state.insert(n.to_string(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for n in graph.keys() {
        if state.get(n.as_str()).copied().unwrap_or(0) == 0 {
            let mut stack = Vec::new();
            if let Some(c) = visit(n, graph, &mut state, &mut stack) {
                return Some(c);
            }
        }
    }
    None
}

/// A crate's modules by file and by top-level module.
struct Graphs {
    by_file: BTreeMap<String, BTreeSet<String>>,
    by_top: BTreeMap<String, BTreeSet<String>>,
}

fn graphs(src: &Path) -> Graphs {
    let mut files = Vec::new();
    sources(src, src, &mut files);
    let known: BTreeSet<String> = files.iter().map(|(m, _)| m.clone()).collect();
    let mut by_file = BTreeMap::new();
    let mut by_top: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    let top = |m: &str| m.split("::").next().unwrap_or_default().to_string();
    for (m, text) in &files {
        if m.is_empty() {
            continue; // lib.rs declares the modules
        }
        let deps = dependencies(m, text, &known);
        let entry = by_top.entry(top(m)).or_default();
        for d in &deps {
            if top(d) != top(m) {
                entry.insert(top(d));
            }
        }
        by_file.insert(m.clone(), deps);
    }
    Graphs { by_file, by_top }
}

#[test]
fn no_crate_has_a_module_cycle() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the workspace root")
        .to_path_buf();
    let manifest: toml::Table = std::fs::read_to_string(root.join("Cargo.toml"))
        .expect("workspace manifest")
        .parse()
        .expect("TOML");
    let core = graphs(&root.join("daemon/core/src"));
    assert!(
        core.by_file.len() > 15,
        "{} modules found",
        core.by_file.len()
    );
    assert!(
        core.by_file["navigator"].contains("aid::dvl"),
        "the scan sees dependencies: {:?}",
        core.by_file["navigator"]
    );
    let mut cycles = Vec::new();
    for member in manifest["workspace"]["members"]
        .as_array()
        .expect("members")
        .iter()
        .filter_map(|m| m.as_str())
    {
        let src = root.join(member).join("src");
        if !src.is_dir() {
            continue;
        }
        let g = graphs(&src);
        if let Some(c) = find_cycle(&g.by_file) {
            cycles.push(format!("{member}, between files: {}", c.join(" -> ")));
        }
        if let Some(c) = find_cycle(&g.by_top) {
            cycles.push(format!(
                "{member}, between top-level modules: {}",
                c.join(" -> ")
            ));
        }
    }
    assert!(cycles.is_empty(), "module cycles:\n{}", cycles.join("\n"));
}
