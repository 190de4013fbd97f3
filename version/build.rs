//! Records the commit the binaries are built from: `AUVNAV_COMMIT` from the environment (for
//! builds from a source archive), else `git rev-parse`, else "unknown". Reruns when HEAD moves.

use std::path::{Path, PathBuf};
use std::process::Command;

fn git(dir: &Path, args: &[&str]) -> Option<String> {
    let out = Command::new("git")
        .args(args)
        .current_dir(dir)
        .output()
        .ok()?;
    if !out.status.success() {
        return None;
    }
    let s = String::from_utf8(out.stdout).ok()?.trim().to_string();
    (!s.is_empty()).then_some(s)
}

fn main() {
    println!("cargo::rerun-if-env-changed=AUVNAV_COMMIT");
    let dir = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR").unwrap_or_else(|_| ".".into()));
    let commit = match std::env::var("AUVNAV_COMMIT") {
        Ok(c) if !c.trim().is_empty() => c.trim().to_string(),
        _ => git(&dir, &["rev-parse", "--short=12", "HEAD"]).unwrap_or_else(|| "unknown".into()),
    };
    // Rerun when HEAD or the branch it names moves (a commit, a checkout, a fetch into it).
    if let Some(git_dir) = git(&dir, &["rev-parse", "--absolute-git-dir"]) {
        let git_dir = PathBuf::from(git_dir);
        println!("cargo::rerun-if-changed={}", git_dir.join("HEAD").display());
        let common = git(
            &dir,
            &["rev-parse", "--path-format=absolute", "--git-common-dir"],
        )
        .map(PathBuf::from)
        .unwrap_or_else(|| git_dir.clone());
        // Only paths that exist: cargo reruns the script on every build for a missing one. A
        // branch is a loose ref file, or a line of packed-refs (after `git gc`).
        let branch = git(&dir, &["symbolic-ref", "-q", "HEAD"]).map(|b| common.join(b));
        for path in branch.into_iter().chain([common.join("packed-refs")]) {
            if path.exists() {
                println!("cargo::rerun-if-changed={}", path.display());
            }
        }
    }
    println!("cargo::rustc-env=AUVNAV_COMMIT={commit}");
}
