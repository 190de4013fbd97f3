//! Helpers shared by the end-to-end tests: the workspace's binaries, child processes that are
//! killed when a test fails, and per-test names so concurrent tests never share topics or files.

pub mod shared;

/// The measured data set `name` under `<shared>/data` when its file `probe` exists, or `None`
/// (with a SKIPPED message) outside CI; under CI (`CI=true`) its absence is a failure.
pub fn measured_data(name: &str, probe: &str) -> Option<std::path::PathBuf> {
    let dir = shared::shared(&format!("data/{name}"))?;
    if dir.join(probe).exists() {
        return Some(dir);
    }
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!(
            "{} is missing: measured data is required under CI",
            dir.join(probe).display()
        );
    }
    eprintln!("SKIPPED: {} is absent", dir.join(probe).display());
    None
}

pub mod processes {
    use std::path::{Path, PathBuf};
    use std::process::{Child, Command, ExitStatus};
    use std::sync::atomic::{AtomicU32, Ordering};
    use std::time::{Duration, Instant};

    /// The path of a workspace binary built for this test run (`target/<profile>/<name>`). The
    /// first call brings the binaries of the driver, daemon and tool packages up to date with one
    /// `cargo build` (a no-op after `cargo test --workspace`; needed when only this package's
    /// tests were built, or a binary would be stale).
    pub fn binary(name: &str) -> PathBuf {
        static BUILT: std::sync::OnceLock<Result<(), String>> = std::sync::OnceLock::new();
        let exe = std::env::current_exe().expect("the test executable's path");
        let dir = exe
            .parent()
            .and_then(Path::parent)
            .expect("target/<profile>/deps")
            .to_path_buf();
        let built = BUILT.get_or_init(|| {
            let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_string());
            let mut cmd = Command::new(cargo);
            cmd.args([
                "build",
                "--bins",
                "-p",
                "auvnav-drivers",
                "-p",
                "auvnav-tools",
                "-p",
                "auvnavd",
            ]);
            if dir.file_name().is_some_and(|n| n == "release") {
                cmd.arg("--release");
            }
            match cmd.output() {
                Ok(o) if o.status.success() => Ok(()),
                Ok(o) => Err(String::from_utf8_lossy(&o.stderr).into_owned()),
                Err(e) => Err(e.to_string()),
            }
        });
        if let Err(e) = built {
            panic!("building the workspace binaries failed: {e}");
        }
        dir.join(name)
    }

    /// A name unique to this test process and call, for service prefixes and directories.
    pub fn unique(tag: &str) -> String {
        static N: AtomicU32 = AtomicU32::new(0);
        format!(
            "{tag}{}x{}",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        )
    }

    /// A fresh directory under the system temp directory, removed on drop.
    pub struct TempDir(pub PathBuf);

    impl TempDir {
        pub fn new(tag: &str) -> TempDir {
            let p = std::env::temp_dir().join(unique(tag));
            std::fs::create_dir_all(&p).expect("creating a temp dir");
            TempDir(p)
        }
        pub fn path(&self) -> &Path {
            &self.0
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    /// A child process that is killed if the test ends before it was stopped.
    pub struct Proc {
        pub name: String,
        pub child: Child,
    }

    impl Proc {
        pub fn spawn(name: &str, cmd: &mut Command) -> Proc {
            let child = cmd
                .spawn()
                .unwrap_or_else(|e| panic!("starting {name}: {e}"));
            Proc {
                name: name.to_string(),
                child,
            }
        }

        /// Sends SIGTERM and waits up to `timeout` for the exit.
        pub fn terminate(&mut self, timeout: Duration) -> Option<ExitStatus> {
            let pid = nix::unistd::Pid::from_raw(self.child.id() as i32);
            let _ = nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM);
            self.wait_for(timeout)
        }

        /// Waits up to `timeout` for the process to exit by itself.
        pub fn wait_for(&mut self, timeout: Duration) -> Option<ExitStatus> {
            let end = Instant::now() + timeout;
            while Instant::now() < end {
                if let Ok(Some(s)) = self.child.try_wait() {
                    return Some(s);
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            None
        }

        /// SIGKILL, as a crash would.
        pub fn kill(&mut self) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }

    impl Drop for Proc {
        fn drop(&mut self) {
            if let Ok(None) = self.child.try_wait() {
                let _ = self.child.kill();
                let _ = self.child.wait();
            }
        }
    }
}
