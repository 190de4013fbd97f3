//! Progress bars of the long tools (`indicatif`), on standard error, shown only on a terminal and
//! never with `--json`: scripts and logs see nothing of them.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;

/// A sequence of labelled stages, each a bar of `done/total`.
pub struct Progress {
    enabled: bool,
    bar: Option<ProgressBar>,
    label: String,
}

fn new_bar(label: &str, total: u64) -> ProgressBar {
    let style = ProgressStyle::with_template(
        "{msg:<28} [{bar:30}] {pos}/{len} {elapsed_precise} (about {eta} left)",
    )
    .unwrap_or_else(|_| ProgressStyle::default_bar())
    .progress_chars("#> ");
    let bar = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr_with_hz(5));
    bar.set_style(style);
    bar.set_message(label.to_string());
    bar
}

impl Progress {
    /// A progress display; `enabled` false (with `--json`) or standard error not a terminal:
    /// nothing is drawn.
    pub fn new(enabled: bool) -> Progress {
        Progress {
            enabled: enabled && std::io::stderr().is_terminal(),
            bar: None,
            label: String::new(),
        }
    }

    /// `done` of `total` in stage `label`; a new label starts a new bar under the last.
    pub fn update(&mut self, label: &str, done: usize, total: usize) {
        if !self.enabled {
            return;
        }
        let total = total.max(1) as u64;
        if self.bar.is_none() || self.label != label {
            if let Some(b) = self.bar.take() {
                b.abandon();
            }
            self.bar = Some(new_bar(label, total));
            self.label = label.to_string();
        }
        if let Some(b) = &self.bar {
            b.set_length(total);
            b.set_position((done as u64).min(total));
            if done as u64 >= total {
                b.finish();
            }
        }
    }

    /// A bar for `total` independent runs, advanced from any thread with `inc(1)`; hidden when
    /// the display is disabled.
    pub fn runs(&mut self, label: &str, total: usize) -> ProgressBar {
        if !self.enabled {
            return ProgressBar::hidden();
        }
        if let Some(b) = self.bar.take() {
            b.abandon();
        }
        new_bar(label, total as u64)
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        if let Some(b) = self.bar.take() {
            b.abandon();
        }
    }
}
