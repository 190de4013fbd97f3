//! Stage times of the on-board chain, for latency breakdowns: a process configured with a
//! stage-times file writes one CSV row per message it handles, holding the host clock
//! (`CLOCK_MONOTONIC`, ns) at each stage, keyed by the message's `host_time_ns` (the driver's
//! read time stamp, which the daemon's solution carries on). `auvnav bench e2e` joins the rows of
//! the IMU driver and the daemon with its own write and receive times.
//!
//! Off by default: an empty path writes nothing. A row is a few integers into a buffered file
//! (one `write` per 8 KiB), so the measurement barely disturbs what it measures. A write error
//! (a full disk) is reported once and ends the file; the process goes on.

use std::fs::File;
use std::io::{BufWriter, Write};

/// A CSV file of stage times.
pub struct StageTimes {
    w: BufWriter<File>,
    path: String,
    failed: bool,
}

impl StageTimes {
    /// Creates `path` with the CSV `header` (comma-separated column names); `None` for an
    /// empty path.
    pub fn create(path: &str, header: &str) -> std::io::Result<Option<StageTimes>> {
        if path.is_empty() {
            return Ok(None);
        }
        let mut w = BufWriter::new(File::create(path)?);
        writeln!(w, "{header}")?;
        Ok(Some(StageTimes {
            w,
            path: path.to_string(),
            failed: false,
        }))
    }

    /// Appends one row.
    pub fn row(&mut self, fields: &[u64]) {
        if self.failed {
            return;
        }
        let mut r = Ok(());
        for (i, v) in fields.iter().enumerate() {
            let sep = if i + 1 == fields.len() { '\n' } else { ',' };
            r = r.and_then(|_| write!(self.w, "{v}{sep}"));
        }
        self.check(r);
    }

    /// Writes the buffered rows to the file.
    pub fn flush(&mut self) {
        if !self.failed {
            let r = self.w.flush();
            self.check(r);
        }
    }

    fn check(&mut self, r: std::io::Result<()>) {
        if let Err(e) = r {
            tracing::warn!(path = %self.path, error = %e, "stage times: writing {} failed ({e}); no more rows", self.path);
            self.failed = true;
        }
    }
}

impl Drop for StageTimes {
    fn drop(&mut self) {
        self.flush();
    }
}

/// What is wrong with `path` as a file a program will create or replace (`None`: nothing, or the
/// path is empty, meaning no file): its folder must exist and it must not be a folder itself.
/// Configuration checks use it so that `--check-config` refuses what would fail at start.
pub fn output_path_problem(path: &str) -> Option<String> {
    if path.is_empty() {
        return None;
    }
    let p = std::path::Path::new(path);
    if p.is_dir() {
        return Some("is a folder, expected a file".into());
    }
    let parent = match p.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => std::path::Path::new("."),
    };
    (!parent.is_dir()).then(|| {
        format!(
            "the folder {0} does not exist: create it (`install -d -o auvnav {0}`; under systemd \
             the daemon's unit creates /var/lib/auvnav, StateDirectory=auvnav) or name another path",
            parent.display()
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_are_written_under_the_header_and_an_empty_path_writes_nothing() {
        assert!(StageTimes::create("", "a,b").expect("no file").is_none());
        let dir = std::env::temp_dir().join(format!("stage-times-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temporary directory");
        let path = dir.join("t.csv");
        {
            let path_text = path.to_str().expect("UTF-8 path");
            let mut s = StageTimes::create(path_text, "a,b")
                .expect("created")
                .expect("a path was given");
            s.row(&[1, 2]);
            s.row(&[3, u64::MAX]);
        }
        let text = std::fs::read_to_string(&path).expect("reading back");
        assert_eq!(text, format!("a,b\n1,2\n3,{}\n", u64::MAX));
        std::fs::remove_dir_all(&dir).expect("removing the directory");
    }

    #[test]
    fn a_full_disk_is_reported_once_and_ends_the_file() {
        // /dev/full accepts the open and fails every write with ENOSPC.
        let Ok(Some(mut s)) = StageTimes::create("/dev/full", "a") else {
            eprintln!("/dev/full cannot be opened here: nothing to test");
            return;
        };
        for i in 0..10_000 {
            s.row(&[i]);
        }
        s.flush();
        assert!(s.failed);
    }
}
