//! Helpers shared by the end-to-end tests: the workspace's binaries, child processes that are
//! killed when a test fails, and per-test names so concurrent tests never share topics or files.
#![forbid(unsafe_code)]

pub mod shared;

/// xorshift64*: a fixed, dependency-free stream of test bits (the same sequence for a seed on
/// every machine), for tests that inject random faults.
pub struct Bits(pub u64);

impl Bits {
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
}

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
    use std::process::Command;
    use std::sync::atomic::{AtomicU32, Ordering};

    /// The path of a workspace binary built for this test run (`target/<profile>/<name>`). The
    /// first call brings the workspace's binaries up to date with one `cargo build --workspace
    /// --bins --test source_size` (needed when only this package's tests were built, or a binary
    /// would be stale). Cargo resolves the dependencies' features per selection: `--bins` alone
    /// leaves out this package's dev-dependencies (`syn` with `visit`, `proc-macro2` with
    /// `span-locations`, for the source-size guard), and so every procedural macro and
    /// everything derived with one was built a second time after `cargo test --workspace`
    /// (about 90 s of every CI run). With
    /// the one test target that uses them the selection resolves as `cargo test --workspace`
    /// does, and after it the command has nothing to build. (Measured on 2026-12-07: the
    /// program built either way replays and smooths at the same speed, pair ratio 0.99.)
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
            // `.ci/run`'s performance guard runs the `auvnav` this builds.
            let mut cmd = Command::new(cargo);
            cmd.args(["build", "--workspace", "--bins", "--test", "source_size"]);
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

    /// Runs `auvnav ARGS…` to success and returns what it printed as JSON (`Null` when it
    /// printed no JSON, e.g. a command without `--json`).
    pub fn auvnav_json(args: &[&str]) -> serde_json::Value {
        let o = Command::new(binary("auvnav"))
            .args(args)
            .output()
            .expect("running auvnav");
        assert!(
            o.status.success(),
            "auvnav {args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        serde_json::from_slice(&o.stdout).unwrap_or(serde_json::Value::Null)
    }

    /// `auvnav import pd0 FILE --out OUT`: a PD0 file with GPS as a surface run.
    pub fn import_pd0(file: &Path, out: &Path) {
        auvnav_json(&[
            "import",
            "pd0",
            &file.display().to_string(),
            "--out",
            &out.display().to_string(),
            "--json",
        ]);
    }

    /// `auvnav import riversurveyor` of the measured M9 lake run (`20250117160335.mat`) into
    /// `out`, with `extra` importer arguments; `None` where the measured data is absent (outside
    /// CI, said by [`crate::measured_data`]).
    pub fn import_lake_run(out: &Path, extra: &[&str]) -> Option<PathBuf> {
        let dir = crate::measured_data("riversurveyor-m9", "20250117160335.mat")?;
        let (file, log) = (
            dir.join("20250117160335.mat").display().to_string(),
            out.display().to_string(),
        );
        let mut args = vec!["import", "riversurveyor", &file, "--out", &log, "--json"];
        args.extend_from_slice(extra);
        auvnav_json(&args);
        Some(out.to_path_buf())
    }

    /// `auvnav import pd0` of the measured RDI river crossing (`winriver02_transect.PD0`, bottom
    /// track with GPS) into `out`; `None` where the measured data is absent (outside CI, said by
    /// [`crate::measured_data`]).
    pub fn import_river_crossing(out: &Path) -> Option<PathBuf> {
        let dir = crate::measured_data("rdi-pd0", "raw/winriver02_transect.PD0")?;
        import_pd0(&dir.join("raw/winriver02_transect.PD0"), out);
        Some(out.to_path_buf())
    }

    /// `auvnav perturb LOG --out OUT --effect E…` to success.
    pub fn perturb(log: &Path, out: &Path, effects: &[String]) {
        let mut cmd = Command::new(binary("auvnav"));
        cmd.arg("perturb").arg(log).arg("--out").arg(out);
        for e in effects {
            cmd.args(["--effect", e]);
        }
        let o = cmd.output().expect("running auvnav perturb");
        assert!(
            o.status.success(),
            "auvnav perturb {effects:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }

    /// `auvnav import snapir DATA --segment N --out OUT`: one Snapir segment as a log.
    pub fn import_snapir(data: &Path, segment: u32, out: &Path) {
        auvnav_json(&[
            "import",
            "snapir",
            &data.display().to_string(),
            "--segment",
            &segment.to_string(),
            "--out",
            &out.display().to_string(),
        ]);
    }

    /// True when `python3` imports `modules` (`"zenoh, rosbags"`). When it does not, a test
    /// skips with a message naming what to `pip install` — outside CI; under CI (`CI` set, where
    /// `.ci/run` installs them) it fails instead.
    pub fn python_modules_or_skip(modules: &str, pip_install: &str) -> bool {
        let has = Command::new("python3")
            .args(["-c", &format!("import {modules}")])
            .status()
            .is_ok_and(|s| s.success());
        if !has {
            assert!(
                std::env::var("CI").is_err(),
                "python3 cannot import {modules} under CI (.ci/run installs {pip_install})"
            );
            eprintln!(
                "SKIP: python3 cannot import {modules} (python3 -m pip install {pip_install})"
            );
        }
        has
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

    /// Sends `sig` (as `kill` names it: `-CONT`, `-HUP`, …) to `p`.
    pub fn signal(p: &Proc, sig: &str) {
        let ok = Command::new("kill")
            .args([sig, &p.pid().to_string()])
            .status()
            .expect("kill");
        assert!(ok.success(), "kill {sig} {}", p.pid());
    }

    /// A child process that is killed if the test ends before it was stopped: the harness the
    /// `auvnav` program uses for its own processes.
    pub use auvnav_tools::process::ChildProcess as Proc;

    /// The smallest daemon configuration it navigates with: a vehicle at rest at 45° N, 10° E on
    /// `prefix`, its checkpoint in `dir` (`dir/cp.json`). Written to `dir/auvnavd.toml`.
    pub fn still_daemon_config(dir: &Path, prefix: &str) -> PathBuf {
        let cfg = dir.join("auvnavd.toml");
        std::fs::write(
            &cfg,
            format!(
                "prefix = \"{prefix}\"\n[initial]\nlatitude_deg = 45.0\nlongitude_deg = 10.0\n\
                 height_m = 0.0\neuler_deg = [0.0, 0.0, 0.0]\n[checkpoint]\npath = \"{}\"\n",
                dir.join("cp.json").display()
            ),
        )
        .expect("daemon configuration");
        cfg
    }

    /// Publishes `n` IMU samples of a vehicle at rest at 100 Hz (earth rate, gravity) on `bus`
    /// and counts the navigation solutions received meanwhile.
    pub fn feed_still_imu(bus: &auvnav_shm_schema::bus::Bus, n: u64) -> usize {
        use auvnav_shm_schema::{NavSolutionV1, qos, topic};
        let mut imu = bus
            .publisher::<auvnav_shm_schema::ImuSampleV1>(topic::IMU, qos::SENSOR)
            .expect("publisher");
        let mut solutions = bus
            .subscriber::<NavSolutionV1>(topic::NAV_SOLUTION, qos::NAVIGATION)
            .expect("subscriber");
        use auvnav_shm_schema::ImuSampleV1;
        let mut got = 0;
        for k in 1..=n {
            imu.publish(ImuSampleV1 {
                host_time_ns: auvnav_shm_schema::clock::monotonic_ns(),
                device_time_ns: k * 10_000_000,
                angular: [1e-5, 0.0, 7.3e-5],
                specific: [0.0, 0.0, -9.79],
                interval_s: 0.01,
                status: ImuSampleV1::STATUS_GYRO_VALID
                    | ImuSampleV1::STATUS_ACCEL_VALID
                    | ImuSampleV1::STATUS_DEVICE_TIME_VALID,
                ..Default::default()
            })
            .expect("publish");
            std::thread::sleep(std::time::Duration::from_millis(10));
            while solutions.receive().expect("receive").is_some() {
                got += 1;
            }
        }
        got
    }
}

/// Simulated voyages for the DVL-outage tests (water track, beams): IMU grades below the
/// built-in scenarios' navigation-grade FOG (on which half a minute without the DVL costs
/// little), each with the filter told its grade, and the messages in memory.
pub mod grade {
    use auvnav_log::LogMessage;
    use auvnav_sim::SimConfig;
    use auvnav_sim::effects::Effects;

    /// An IMU's effects and the filter settings that describe it.
    pub struct ImuGrade {
        pub effects: &'static [(&'static str, &'static [f64])],
        pub angle_random_walk_deg_sqrt_h: f64,
        pub velocity_random_walk_m_s_sqrt_h: f64,
        pub gyro_bias_walk_deg_h_sqrt_h: f64,
        pub accel_bias_walk_ug_sqrt_h: f64,
        pub initial_gyro_bias_std_deg_h: f64,
        pub initial_accel_bias_std_ug: f64,
    }

    impl ImuGrade {
        /// Sets the IMU's effects.
        pub fn set_imu(&self, effects: &mut Effects) {
            for (name, value) in self.effects {
                effects.set(name, value).expect("IMU effect");
            }
        }

        /// The navigation told the grade (noise, bias walks, initial bias spreads).
        pub fn configure(&self, n: &mut auvnav_core::config::NavConfig) {
            n.gyro_angle_random_walk_deg_sqrt_h = self.angle_random_walk_deg_sqrt_h;
            n.accel_velocity_random_walk_m_s_sqrt_h = self.velocity_random_walk_m_s_sqrt_h;
            n.gyro_bias_walk_deg_h_sqrt_h = self.gyro_bias_walk_deg_h_sqrt_h;
            n.accel_bias_walk_ug_sqrt_h = self.accel_bias_walk_ug_sqrt_h;
            n.initial_gyro_bias_std_deg_h = self.initial_gyro_bias_std_deg_h;
            n.initial_accel_bias_std_ug = self.initial_accel_bias_std_ug;
        }
    }

    /// A tactical-grade IMU: gyro bias near 1 deg/h, accelerometer bias near 250 ug.
    pub const TACTICAL: ImuGrade = ImuGrade {
        effects: &[
            ("imu.gyro_bias", &[1.0, -0.8, 1.2]),
            ("imu.gyro_bias_instability", &[0.2]),
            ("imu.angle_random_walk", &[0.05]),
            ("imu.accel_bias", &[300.0, -200.0, 250.0]),
            ("imu.accel_bias_instability", &[50.0]),
            ("imu.velocity_random_walk", &[0.03]),
        ],
        angle_random_walk_deg_sqrt_h: 0.06,
        velocity_random_walk_m_s_sqrt_h: 0.04,
        gyro_bias_walk_deg_h_sqrt_h: 0.05,
        accel_bias_walk_ug_sqrt_h: 20.0,
        initial_gyro_bias_std_deg_h: 2.0,
        initial_accel_bias_std_ug: 500.0,
    };

    /// An industrial MEMS IMU (the class of small vehicles' attitude units): gyro bias near
    /// 10 deg/h, accelerometer bias near 1 mg. Its heading needs the magnetometer; half a
    /// minute without the DVL costs metres.
    pub const MEMS: ImuGrade = ImuGrade {
        effects: &[
            ("imu.gyro_bias", &[8.0, -10.0, 12.0]),
            ("imu.gyro_bias_instability", &[3.0]),
            ("imu.angle_random_walk", &[0.3]),
            ("imu.accel_bias", &[1000.0, -800.0, 900.0]),
            ("imu.accel_bias_instability", &[100.0]),
            ("imu.velocity_random_walk", &[0.06]),
        ],
        angle_random_walk_deg_sqrt_h: 0.35,
        velocity_random_walk_m_s_sqrt_h: 0.07,
        gyro_bias_walk_deg_h_sqrt_h: 1.0,
        accel_bias_walk_ug_sqrt_h: 60.0,
        initial_gyro_bias_std_deg_h: 20.0,
        initial_accel_bias_std_ug: 2000.0,
    };

    /// The voyage's messages, in memory.
    pub fn simulate(cfg: &SimConfig) -> Vec<LogMessage> {
        let mut messages = Vec::new();
        auvnav_sim::simulate(cfg, |m| -> Result<(), auvnav_sim::SimError> {
            messages.push(*m);
            Ok(())
        })
        .expect("simulate");
        messages
    }
}
