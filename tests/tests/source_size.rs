//! No source file over 600 lines and no function over 150 lines without a reason: a long file says
//! why in its leading comment, a long function in the comment or doc comment just above it, with a
//! line that starts `Long on purpose:` and gives the reason (docs/architecture.md, "Size").
//!
//! Every `.rs` file of the workspace is read (the fuzz targets and build outputs aside); functions
//! are found by parsing (syn), so strings, comments and macros do not fool the count.

use std::path::{Path, PathBuf};
use syn::visit::Visit;

const FILE_LIMIT: usize = 600;
const FUNCTION_LIMIT: usize = 150;
const MARK: &str = "Long on purpose:";

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).expect("read_dir").flatten() {
        let p = e.path();
        let name = e.file_name().to_string_lossy().to_string();
        if p.is_dir() {
            if !matches!(name.as_str(), "target" | "fuzz" | ".git" | "node_modules") {
                rust_files(&p, out);
            }
        } else if name.ends_with(".rs") {
            out.push(p);
        }
    }
}

/// The reason given by a `MARK` line among `lines` (comment lines), if it says something.
fn reason_in<'a>(lines: impl Iterator<Item = &'a str>) -> bool {
    lines
        .map(|l| {
            l.trim_start()
                .trim_start_matches("//!")
                .trim_start_matches("///")
                .trim_start_matches("//")
                .trim()
        })
        .any(|l| l.strip_prefix(MARK).is_some_and(|r| r.trim().len() >= 20))
}

/// The leading comment of a file: its lines up to the first line that is neither a comment,
/// an inner attribute nor blank.
fn file_has_reason(text: &str) -> bool {
    reason_in(text.lines().take_while(|l| {
        let t = l.trim_start();
        t.is_empty() || t.starts_with("//") || t.starts_with("#![")
    }))
}

/// The comments and attributes just above line `line` (1-based) of `lines`.
fn function_has_reason(lines: &[&str], line: usize) -> bool {
    let above = lines[..line.saturating_sub(1)]
        .iter()
        .rev()
        .take_while(|l| {
            let t = l.trim_start();
            t.starts_with("//") || t.starts_with("#[") || t.starts_with(')') || t.starts_with('"')
        })
        .copied();
    reason_in(above)
}

#[derive(Default)]
struct Functions {
    /// (name, first line, last line).
    found: Vec<(String, usize, usize)>,
}

impl Functions {
    fn add(&mut self, name: &syn::Ident, first: proc_macro2::Span, last: proc_macro2::Span) {
        self.found
            .push((name.to_string(), first.start().line, last.end().line));
    }
}

fn first_span(attrs: &[syn::Attribute], fallback: proc_macro2::Span) -> proc_macro2::Span {
    // Functions start at their signature: doc comments and attributes above are not counted.
    let _ = attrs;
    fallback
}

impl<'ast> Visit<'ast> for Functions {
    fn visit_item_fn(&mut self, f: &'ast syn::ItemFn) {
        let first = first_span(&f.attrs, f.sig.fn_token.span);
        self.add(&f.sig.ident, first, f.block.brace_token.span.close());
        syn::visit::visit_item_fn(self, f);
    }
    fn visit_impl_item_fn(&mut self, f: &'ast syn::ImplItemFn) {
        let first = first_span(&f.attrs, f.sig.fn_token.span);
        self.add(&f.sig.ident, first, f.block.brace_token.span.close());
        syn::visit::visit_impl_item_fn(self, f);
    }
    fn visit_trait_item_fn(&mut self, f: &'ast syn::TraitItemFn) {
        if let Some(b) = &f.default {
            self.add(
                &f.sig.ident,
                f.sig.fn_token.span,
                b.brace_token.span.close(),
            );
        }
        syn::visit::visit_trait_item_fn(self, f);
    }
}

#[test]
fn long_files_and_functions_say_why() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut files = Vec::new();
    rust_files(&root, &mut files);
    files.sort();
    assert!(files.len() > 100, "only {} source files found", files.len());
    let mut missing = Vec::new();
    let mut checked = (0, 0);
    for path in &files {
        let text = std::fs::read_to_string(path).expect("read");
        let rel = path
            .strip_prefix(&root)
            .unwrap_or(path)
            .display()
            .to_string();
        let lines: Vec<&str> = text.lines().collect();
        if lines.len() > FILE_LIMIT {
            checked.0 += 1;
            if !file_has_reason(&text) {
                missing.push(format!(
                    "{rel}: {} lines, no `{MARK}` at its top",
                    lines.len()
                ));
            }
        }
        let file = match syn::parse_file(&text) {
            Ok(f) => f,
            Err(e) => panic!("{rel} does not parse: {e}"),
        };
        let mut fns = Functions::default();
        fns.visit_file(&file);
        for (name, first, last) in fns.found {
            let n = last + 1 - first;
            if n > FUNCTION_LIMIT {
                checked.1 += 1;
                if !function_has_reason(&lines, first) {
                    missing.push(format!(
                        "{rel}:{first}: fn {name} is {n} lines, no `{MARK}` above it"
                    ));
                }
            }
        }
    }
    assert!(
        missing.is_empty(),
        "{} of {} long files and functions give no reason:\n{}",
        missing.len(),
        checked.0 + checked.1,
        missing.join("\n")
    );
}

#[test]
fn a_reason_must_say_something() {
    assert!(file_has_reason(
        "//! A module.\n//!\n//! Long on purpose: the whole schema in one file, reviewed as one.\n\nuse x;\n"
    ));
    assert!(!file_has_reason(
        "//! A module.\n//! Long on purpose: yes\nuse x;\n"
    ));
    assert!(!file_has_reason(
        "//! A module.\nuse x;\n// Long on purpose: a reason too late to count.\n"
    ));
    let lines = [
        "/// Does things.",
        "// Long on purpose: one state machine whose arms share its locals.",
        "#[allow(clippy::too_many_lines)]",
        "fn f() {",
    ];
    assert!(function_has_reason(&lines, 4));
    assert!(!function_has_reason(&lines[2..], 2));
}
