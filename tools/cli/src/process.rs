//! The one harness for child processes, used by `auvnav demo` (drivers, daemon, recorder and
//! emulator as real processes), the latency benchmarks and the end-to-end tests: spawn, stop with
//! SIGTERM and a deadline (SIGKILL after it), read the last line a process logged, and never leave
//! a process behind (killed on drop).

use anyhow::{Context, bail};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// A child process that is killed when dropped while still running.
pub struct ChildProcess {
    pub name: String,
    pub child: Child,
    /// Where its stderr goes, when spawned with [`ChildProcess::spawn_logged`].
    log: Option<PathBuf>,
}

impl ChildProcess {
    /// Spawns `cmd` as configured by the caller.
    pub fn spawn(name: &str, cmd: &mut Command) -> anyhow::Result<ChildProcess> {
        let child = cmd.spawn().with_context(|| format!("starting {name}"))?;
        Ok(ChildProcess {
            name: name.to_string(),
            child,
            log: None,
        })
    }

    /// Spawns `cmd` with stdout discarded and stderr written to `dir/<name>.log`.
    pub fn spawn_logged(name: &str, dir: &Path, cmd: &mut Command) -> anyhow::Result<ChildProcess> {
        let log = dir.join(format!("{name}.log"));
        let file =
            std::fs::File::create(&log).with_context(|| format!("creating {}", log.display()))?;
        let mut p = Self::spawn(name, cmd.stdout(Stdio::null()).stderr(file))?;
        p.log = Some(log);
        Ok(p)
    }

    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Waits up to `timeout` for the process to exit by itself.
    pub fn wait_for(&mut self, timeout: Duration) -> Option<ExitStatus> {
        let end = Instant::now() + timeout;
        loop {
            if let Ok(Some(s)) = self.child.try_wait() {
                return Some(s);
            }
            if Instant::now() >= end {
                return None;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Sends SIGTERM and waits up to `timeout` for the exit.
    pub fn terminate(&mut self, timeout: Duration) -> Option<ExitStatus> {
        let pid = nix::unistd::Pid::from_raw(self.child.id() as i32);
        let _ = nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM);
        self.wait_for(timeout)
    }

    /// SIGTERM, then SIGKILL after `timeout`; true for a clean exit (status 0).
    pub fn stop(&mut self, timeout: Duration) -> bool {
        match self.terminate(timeout) {
            Some(s) => s.success(),
            None => {
                self.kill();
                false
            }
        }
    }

    /// Waits up to `timeout` for the process to exit by itself (SIGKILL after it); true for a
    /// clean exit (status 0).
    pub fn wait_clean(&mut self, timeout: Duration) -> bool {
        match self.wait_for(timeout) {
            Some(s) => s.success(),
            None => {
                self.kill();
                false
            }
        }
    }

    /// SIGKILL, as a crash would.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// The last line the process wrote to its log (empty without one).
    pub fn last_log_line(&self) -> String {
        self.log
            .as_ref()
            .and_then(|p| std::fs::read_to_string(p).ok())
            .unwrap_or_default()
            .lines()
            .last()
            .unwrap_or_default()
            .to_string()
    }
}

impl Drop for ChildProcess {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            self.kill();
        }
    }
}

/// A workspace binary installed next to this program (`target/<profile>/` or the install
/// directory).
pub fn sibling(name: &str) -> anyhow::Result<PathBuf> {
    let exe = std::env::current_exe()?;
    let path = exe.parent().context("executable directory")?.join(name);
    if !path.exists() {
        // The bridge, the live view and the MAVLink output are not default members of the
        // workspace (`cargo build --release` leaves them out).
        let build = match name {
            "auvnav-bridge" | "auvnav-live" => "cargo build --release -p auvnav-bridge",
            "auvnav-mavlink" => "cargo build --release -p auvnav-mavlink",
            _ => "cargo build --release",
        };
        bail!(
            "{} not found: this command runs it as a process; build it with `{build}` (every \
             program: `cargo build --release --workspace --bins`)",
            path.display()
        );
    }
    Ok(path)
}

/// How `auvnav demo` schedules the processes it starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Scheduling {
    /// As the units run them: drivers SCHED_FIFO 60, the daemon SCHED_FIFO 50 (the emulated
    /// devices at 70, so that the "world" sends on time); the recorder and the tools normal.
    /// Falls back to normal where SCHED_FIFO is not permitted, and says so.
    Unit,
    /// Every process under the normal scheduler (the time stamps alone against the load).
    Normal,
}

/// Whether this process may start programs under SCHED_FIFO (through `chrt`, from util-linux):
/// `Err` says why not.
pub fn realtime_permitted() -> Result<(), String> {
    match Command::new("chrt")
        .args(["-f", "1", "true"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
    {
        Ok(s) if s.success() => Ok(()),
        Ok(s) => Err(format!("`chrt -f 1 true` exited with {s}")),
        Err(e) => Err(format!("cannot run chrt: {e}")),
    }
}

/// A command running `program` under SCHED_FIFO at `priority` (its threads inherit it), or
/// normally with `None`.
pub fn scheduled_command(program: &Path, priority: Option<u8>) -> Command {
    match priority {
        Some(p) => {
            let mut c = Command::new("chrt");
            c.args(["-f", &p.to_string()]).arg(program);
            c
        }
        None => Command::new(program),
    }
}

/// Puts the calling thread under SCHED_FIFO at `priority`, or back under the normal scheduler
/// with `None` (through `chrt -p` on its thread id); `Err` says why not.
pub fn schedule_this_thread(priority: Option<u8>) -> Result<(), String> {
    let tid = nix::unistd::gettid().as_raw().to_string();
    let mut c = Command::new("chrt");
    match priority {
        Some(p) => c.args(["-f", "-p", &p.to_string(), &tid]),
        None => c.args(["-o", "-p", "0", &tid]),
    };
    match c.stdout(Stdio::null()).stderr(Stdio::null()).status() {
        Ok(s) if s.success() => Ok(()),
        Ok(s) => Err(format!("chrt on thread {tid} exited with {s}")),
        Err(e) => Err(format!("cannot run chrt: {e}")),
    }
}
