//! The daemon's checkpoint file: the navigation state, biases, covariance and DVL installation
//! ([`auvnav_core::navigator::Checkpoint`]), written atomically (a temporary file in the same
//! folder, synced, then renamed over the old one) on a thread of its own so that a slow disk never
//! holds up the navigation, and read at start.
//!
//! A checkpoint is used only for the mission it belongs to: the file records the configured start
//! (`[initial]` and `[alignment]`), and a file written under another start (the operator set up a
//! new mission) is ignored. One older than `checkpoint.max_age_s`, unreadable or not sound is not
//! used either: the daemon then starts with its position flagged unknown, never from the
//! configured start with a small standard deviation.

use auvnav_core::config::{AlignmentConfig, DaemonConfig, InitialState};
use auvnav_core::navigator::Checkpoint;
use auvnav_core::session::Session;
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};

/// The file's content.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CheckpointFile {
    pub format_version: u32,
    /// Wall-clock time of writing (s since the Unix epoch): the age at the next start.
    pub written_unix_s: f64,
    /// The configured start of the mission it belongs to.
    pub initial: Option<InitialState>,
    pub alignment: Option<AlignmentConfig>,
    pub navigation: Checkpoint,
}

/// How the daemon starts.
#[derive(Debug)]
pub enum Start {
    /// No checkpoint configured, none written yet, or one of another mission: the configured
    /// start.
    Configured,
    /// Continue from the checkpoint, written this many seconds ago.
    Resume(Box<Checkpoint>, f64),
    /// A checkpoint of this mission exists but cannot be used (why): the configured start with
    /// the position unknown.
    PositionUnknown(String),
}

/// Seconds since the Unix epoch.
fn unix_now_s() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// Decides how the daemon starts from its configuration and the checkpoint file.
pub fn load(cfg: &DaemonConfig) -> Start {
    let path = &cfg.checkpoint.path;
    if path.is_empty() {
        return Start::Configured;
    }
    let text = match std::fs::read(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Start::Configured,
        Err(e) => return Start::PositionUnknown(format!("reading the checkpoint {path}: {e}")),
    };
    let file: CheckpointFile = match serde_json::from_slice(&text) {
        Ok(f) => f,
        Err(e) => return Start::PositionUnknown(format!("the checkpoint {path} is corrupt: {e}")),
    };
    if file.initial != cfg.initial || file.alignment != cfg.alignment {
        tracing::info!(
            "auvnavd: the checkpoint {path} belongs to another configured start ([initial] or \
             [alignment] changed): a new mission, not used"
        );
        return Start::Configured;
    }
    let age = unix_now_s() - file.written_unix_s;
    if !(age.is_finite() && age >= -1.0) {
        return Start::PositionUnknown(format!(
            "the checkpoint {path} was written in the future ({:.0} s ahead): the clock changed",
            -age
        ));
    }
    if age > cfg.checkpoint.max_age_s {
        return Start::PositionUnknown(format!(
            "the checkpoint {path} is {age:.0} s old (checkpoint.max_age_s = {})",
            cfg.checkpoint.max_age_s
        ));
    }
    // The navigator checks soundness when it starts from it; a checkpoint that is not sound is
    // refused here already so that the start can say so.
    if auvnav_core::navigator::Navigator::from_checkpoint(cfg.navigation.clone(), &file.navigation)
        .is_none()
    {
        return Start::PositionUnknown(format!(
            "the checkpoint {path} holds a state or covariance that is not sound"
        ));
    }
    Start::Resume(Box::new(file.navigation), age.max(0.0))
}

/// Writes `file` to `path` atomically: a temporary file beside it, synced, renamed over it, and
/// the folder synced.
pub fn write_atomically(path: &Path, file: &CheckpointFile) -> std::io::Result<()> {
    let bytes = serde_json::to_vec(file).map_err(std::io::Error::other)?;
    let mut tmp = PathBuf::from(path);
    tmp.as_mut_os_string().push(".tmp");
    {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(&bytes)?;
        f.sync_all()?;
    }
    std::fs::rename(&tmp, path)?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty())
        && let Ok(d) = std::fs::File::open(dir)
    {
        let _ = d.sync_all();
    }
    Ok(())
}

/// The writer thread and the channel to it (one checkpoint waiting at most: a newer one replaces
/// nothing, it is dropped while the disk is busy, and the next interval brings another).
pub struct Writer {
    /// The configured start the checkpoints belong to (written into each file).
    initial: Option<InitialState>,
    alignment: Option<AlignmentConfig>,
    tx: Option<SyncSender<CheckpointFile>>,
    thread: Option<std::thread::JoinHandle<u64>>,
}

impl Writer {
    /// Starts the writer when `[checkpoint] path` is set.
    pub fn start(cfg: &DaemonConfig) -> Option<Writer> {
        if cfg.checkpoint.path.is_empty() {
            return None;
        }
        let (tx, rx) = sync_channel::<CheckpointFile>(1);
        let path = PathBuf::from(&cfg.checkpoint.path);
        let thread = std::thread::Builder::new()
            .name("checkpoint".into())
            .spawn(move || write_loop(&path, rx))
            .ok()?;
        Some(Writer {
            initial: cfg.initial.clone(),
            alignment: cfg.alignment.clone(),
            tx: Some(tx),
            thread: Some(thread),
        })
    }

    /// Hands a checkpoint to the writer (dropped when it is still writing the previous one).
    pub fn submit(&mut self, cp: Checkpoint) {
        let file = CheckpointFile {
            format_version: 1,
            written_unix_s: unix_now_s(),
            initial: self.initial.clone(),
            alignment: self.alignment.clone(),
            navigation: cp,
        };
        if let Some(tx) = &self.tx
            && let Err(TrySendError::Disconnected(_)) = tx.try_send(file)
        {
            self.tx = None;
        }
    }

    /// Writes what is waiting and stops the thread; the number of failed writes.
    pub fn finish(mut self) -> u64 {
        self.tx = None;
        self.thread.take().map_or(0, |t| t.join().unwrap_or(1))
    }
}

fn write_loop(path: &Path, rx: Receiver<CheckpointFile>) -> u64 {
    let mut errors = 0u64;
    while let Ok(file) = rx.recv() {
        if let Err(e) = write_atomically(path, &file) {
            errors += 1;
            if errors <= 5 {
                tracing::error!(
                    "auvnavd: writing the checkpoint {}: {e} (the previous checkpoint stays)",
                    path.display()
                );
            }
        }
    }
    errors
}

/// The session the daemon starts with: from the configuration, or continued from the checkpoint
/// a predecessor left (then true).
pub fn start_session(cfg: &DaemonConfig) -> (Session, bool) {
    let mut session_cfg = cfg.session();
    let resume = load(cfg);
    if let Start::PositionUnknown(why) = &resume {
        tracing::warn!(
            "auvnavd: {why}: starting from the configured start with the position unknown \
             (standard deviation {} m)",
            cfg.checkpoint.unknown_position_std_m
        );
        session_cfg.navigation.initial_position_std_m = cfg.checkpoint.unknown_position_std_m;
    }
    let mut session = Session::new(&session_cfg);
    if let Start::Resume(cp, elapsed_s) = resume {
        tracing::warn!(
            elapsed_s,
            "auvnavd: continuing from the checkpoint {} written {:.1} s ago (covariance grown by \
             a drift of {} m/s over that time)",
            cfg.checkpoint.path,
            elapsed_s,
            cfg.checkpoint.drift_m_s
        );
        session.resume_from(*cp, elapsed_s, cfg.checkpoint.drift_m_s);
        return (session, true);
    }
    (session, false)
}

#[cfg(test)]
mod tests {
    use super::*;
    use auvnav_core::navigator::Navigator;

    fn config(dir: &Path) -> DaemonConfig {
        let mut cfg = DaemonConfig::from_toml(
            "[initial]\nlatitude_deg = 31.0\nlongitude_deg = 120.0\nheight_m = -20.0\neuler_deg = [0.0, 0.0, 30.0]\n",
        )
        .expect("config");
        cfg.checkpoint.path = dir.join("cp.json").display().to_string();
        cfg
    }

    fn file(cfg: &DaemonConfig, written_unix_s: f64) -> CheckpointFile {
        let s = cfg.initial.as_ref().expect("initial").state(1.0);
        let nav = Navigator::new(cfg.navigation.clone(), s);
        CheckpointFile {
            format_version: 1,
            written_unix_s,
            initial: cfg.initial.clone(),
            alignment: None,
            navigation: nav.checkpoint(),
        }
    }

    #[test]
    fn which_start_a_checkpoint_gives() {
        let dir = std::env::temp_dir().join(format!("auvnavd-cp-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let cfg = config(&dir);
        let path = PathBuf::from(&cfg.checkpoint.path);
        // None written yet: the configured start.
        assert!(matches!(load(&cfg), Start::Configured));
        // A fresh one of this mission, written atomically: continue from it (bit for bit).
        let f = file(&cfg, unix_now_s() - 3.0);
        write_atomically(&path, &f).expect("write");
        match load(&cfg) {
            Start::Resume(cp, age) => {
                assert_eq!(*cp, f.navigation);
                assert!((2.5..10.0).contains(&age), "age {age}");
            }
            other => panic!("{other:?}"),
        }
        // Too old: position unknown.
        write_atomically(&path, &file(&cfg, unix_now_s() - 7200.0)).expect("write");
        assert!(matches!(load(&cfg), Start::PositionUnknown(w) if w.contains("old")));
        // Corrupt (cut short): position unknown.
        let bytes = serde_json::to_vec(&file(&cfg, unix_now_s())).expect("json");
        std::fs::write(&path, &bytes[..bytes.len() / 2]).expect("write");
        assert!(matches!(load(&cfg), Start::PositionUnknown(w) if w.contains("corrupt")));
        // Not sound (a NaN variance): position unknown.
        let mut bad = file(&cfg, unix_now_s());
        bad.navigation.covariance[0] = -1.0;
        write_atomically(&path, &bad).expect("write");
        assert!(matches!(load(&cfg), Start::PositionUnknown(w) if w.contains("not sound")));
        // Another mission (the operator changed [initial]): the configured start.
        let mut other = cfg.clone();
        if let Some(i) = other.initial.as_mut() {
            i.latitude_deg += 0.5;
        }
        write_atomically(&path, &file(&cfg, unix_now_s())).expect("write");
        assert!(matches!(load(&other), Start::Configured));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
