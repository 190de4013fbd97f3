//! The daemon's CSV outputs (the solution and the diagnostics): created at start, or continued
//! after a restart that continues from the checkpoint.

use std::io::Write;

pub(crate) struct Csv {
    pub(crate) w: std::io::BufWriter<std::fs::File>,
}

impl Csv {
    /// The output `path` with `header`. With `continuing` (a restart that continues from the
    /// checkpoint) a file of the same header is continued, after its last complete row (a row a
    /// killed predecessor left half-written is dropped), so the mission's rows before the restart
    /// are kept; otherwise the file is created anew.
    pub(crate) fn create(
        path: &str,
        header: &str,
        continuing: bool,
    ) -> Result<Option<Csv>, String> {
        if path.is_empty() {
            return Ok(None);
        }
        if continuing && let Some(f) = Self::continued(path, header) {
            return Ok(Some(Csv {
                w: std::io::BufWriter::new(f),
            }));
        }
        let f = std::fs::File::create(path).map_err(|e| format!("creating {path}: {e}"))?;
        let mut w = std::io::BufWriter::new(f);
        writeln!(w, "{header}").map_err(|e| format!("writing {path}: {e}"))?;
        Ok(Some(Csv { w }))
    }

    /// The existing file at `path` opened after its last complete row, when it starts with
    /// `header`.
    fn continued(path: &str, header: &str) -> Option<std::fs::File> {
        use std::io::{Read, Seek};
        let mut f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .ok()?;
        let mut first = vec![0u8; header.len() + 1];
        f.read_exact(&mut first).ok()?;
        if first[..header.len()] != *header.as_bytes() || first[header.len()] != b'\n' {
            return None;
        }
        // The end of the last complete row: the file's end, or after its last newline.
        let len = f.seek(std::io::SeekFrom::End(0)).ok()?;
        let tail = len.min(64 * 1024);
        f.seek(std::io::SeekFrom::Start(len - tail)).ok()?;
        let mut buf = Vec::with_capacity(tail as usize);
        f.read_to_end(&mut buf).ok()?;
        let keep = len - tail + buf.iter().rposition(|&b| b == b'\n')? as u64 + 1;
        f.set_len(keep).ok()?;
        f.seek(std::io::SeekFrom::Start(keep)).ok()?;
        Some(f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A restart continues its predecessor's file after the last complete row; a file of another
    /// header, or a start that does not continue, begins anew.
    #[test]
    fn a_continuing_start_keeps_the_rows_before_and_drops_a_torn_one() {
        let dir = std::env::temp_dir().join(format!("auvnav-csv-out-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let path = dir.join("nav.csv");
        let p = path.to_str().expect("utf-8");
        std::fs::write(&path, "a,b\n1,2\n3,4\n5,").expect("write");
        let mut c = Csv::create(p, "a,b", true).expect("open").expect("a file");
        writeln!(c.w, "6,7").expect("row");
        drop(c);
        assert_eq!(
            std::fs::read_to_string(&path).expect("read"),
            "a,b\n1,2\n3,4\n6,7\n"
        );
        let mut c = Csv::create(p, "x,y", true).expect("open").expect("a file");
        writeln!(c.w, "8,9").expect("row");
        drop(c);
        assert_eq!(std::fs::read_to_string(&path).expect("read"), "x,y\n8,9\n");
        drop(Csv::create(p, "x,y", false).expect("open"));
        assert_eq!(std::fs::read_to_string(&path).expect("read"), "x,y\n");
        std::fs::remove_dir_all(&dir).ok();
    }
}
