//! Every value of every program's configuration is checked: for each program, a configuration
//! with every table filled is passed through the program's own `--check-config` (which prints it
//! with every default filled in), and then every number in that printout in turn is set to NaN,
//! to +1e30 and to −1e30. Each must be refused by `--check-config` with status 2 and a message
//! that names the key; none may be accepted and fail (or navigate with NaN) later.

use auvnav_tests::processes::{TempDir, binary};
use std::path::Path;
use std::process::Command;

/// The command-line arguments that check a configuration file.
type CheckArgs = fn(&Path) -> Vec<String>;

/// A program and how it checks a configuration file.
struct Program {
    name: &'static str,
    bin: &'static str,
    check: CheckArgs,
    base: String,
}

fn check_file(path: &Path) -> Vec<String> {
    vec!["--check-config".into(), path.display().to_string()]
}

fn check_flag(path: &Path) -> Vec<String> {
    vec![
        "--config".into(),
        path.display().to_string(),
        "--check-config".into(),
    ]
}

/// Runs the check: (exit code, stdout, stderr).
fn run(p: &Program, path: &Path) -> (Option<i32>, String, String) {
    let o = Command::new(binary(p.bin))
        .args((p.check)(path))
        .output()
        .expect("running the check");
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// Paths (with the last key name) of every floating-point number in `v`, arrays included.
fn numbers(v: &toml::Value, path: &mut Vec<String>, out: &mut Vec<(Vec<String>, String)>) {
    match v {
        toml::Value::Float(_) => {
            let key = path
                .iter()
                .rev()
                .find(|k| k.parse::<usize>().is_err())
                .cloned()
                .unwrap_or_default();
            out.push((path.clone(), key));
        }
        toml::Value::Table(t) => {
            for (k, x) in t {
                path.push(k.clone());
                numbers(x, path, out);
                path.pop();
            }
        }
        toml::Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                path.push(i.to_string());
                numbers(x, path, out);
                path.pop();
            }
        }
        _ => {}
    }
}

fn set(v: &mut toml::Value, path: &[String], x: f64) {
    let mut cur = v;
    for k in path {
        cur = match cur {
            toml::Value::Table(t) => t.get_mut(k).expect("key"),
            toml::Value::Array(a) => &mut a[k.parse::<usize>().expect("index")],
            _ => panic!("not a container"),
        };
    }
    *cur = toml::Value::Float(x);
}

fn programs(dir: &Path) -> Vec<Program> {
    let initial = "[initial]\nlatitude_deg = 31.0\nlongitude_deg = 120.0\nheight_m = -20.0\n\
                   velocity_ned_m_s = [1.0, 0.5, 0.0]\neuler_deg = [1.0, 2.0, 45.0]\n";
    let daemon_flat = format!(
        "[navigation]\ndvl_scale_factor = 1.001\ninitial_dvl_mounting_axis_std_deg = [1.0, 1.0, 5.0]\n{initial}\
         [alignment]\nlatitude_deg = 31.0\nlongitude_deg = 120.0\nheight_m = -20.0\n\
         [checkpoint]\npath = \"{}\"\n",
        dir.join("cp.json").display()
    );
    let daemon_tables = format!(
        "{initial}\
         [navigation.dvl]\nmount_deg = [0.1, 0.2, 0.3]\nscale_factor = 1.002\nlever_arm_m = [0.5, 0.0, 0.2]\ntime_offset_s = 0.01\n\
         [navigation.usbl]\ncoupling = \"loose\"\nfilter = \"aukf\"\narray_latitude_deg = 31.0\n\
         array_longitude_deg = 120.0\narray_height_m = -55.0\n\
         [navigation.ranges]\narray = \"moving\"\nreceivers_m = [[0.5, 1.0, 10.0], [-0.5, 1.0, 10.0]]\n\
         [navigation.magnetometer]\nmodel_date = 2026.5\n"
    );
    let serial = |protocol: &str, class: &str| {
        format!(
            "protocol = \"{protocol}\"\n[serial]\nport = \"/dev/tty{class}\"\n\
             [mounting]\nrotation_rpy_deg = [0.0, 0.0, 1.0]\nlever_arm_m = [0.1, 0.0, 0.0]\n"
        )
    };
    vec![
        Program {
            name: "auvnavd (flat keys, [initial], [alignment], [checkpoint])",
            bin: "auvnavd",
            check: check_file,
            base: daemon_flat,
        },
        Program {
            name: "auvnavd ([navigation.dvl], [navigation.usbl], [navigation.ranges], [navigation.magnetometer])",
            bin: "auvnavd",
            check: check_file,
            base: daemon_tables,
        },
        Program {
            name: "auvnav-dvl",
            bin: "auvnav-dvl",
            check: check_flag,
            base: serial("pd0", "dvl"),
        },
        Program {
            name: "auvnav-imu",
            bin: "auvnav-imu",
            check: check_flag,
            base: serial("kvh1750", "imu"),
        },
        Program {
            name: "auvnav-usbl",
            bin: "auvnav-usbl",
            check: check_flag,
            base: serial("seatrac", "usbl"),
        },
        Program {
            name: "auvnav-gnss",
            bin: "auvnav-gnss",
            check: check_flag,
            base: serial("nmea", "gnss"),
        },
        Program {
            name: "auvnav-ugps",
            bin: "auvnav-ugps",
            check: check_flag,
            base: std::fs::read_to_string(
                Path::new(env!("CARGO_MANIFEST_DIR")).join("../drivers/config/ugps.toml"),
            )
            .expect("ugps.toml")
                + "[timing]\nsilence_timeout_s = 5.0\n",
        },
        Program {
            name: "auvnav-can",
            bin: "auvnav-can",
            check: check_flag,
            base: std::fs::read_to_string(
                Path::new(env!("CARGO_MANIFEST_DIR")).join("../drivers/config/can.toml"),
            )
            .expect("can.toml"),
        },
        Program {
            name: "auvnav-mavlink",
            bin: "auvnav-mavlink",
            check: check_flag,
            // The deployed file, with the optional fixed origin.
            base: std::fs::read_to_string(
                Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/auvnav-mavlink.toml"),
            )
            .expect("mavlink toml")
                + "[origin]\nlatitude_deg = 31.0\nlongitude_deg = 120.0\naltitude_m = 0.0\n",
        },
        Program {
            name: "auvnav-bridge",
            bin: "auvnav-bridge",
            check: check_file,
            base: std::fs::read_to_string(
                Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/auvnav-bridge.toml"),
            )
            .expect("bridge toml")
                // With the ROS 2 output (deploy/auvnav-bridge-ros2.toml is checked whole in
                // the bridge's tests).
                + "[ros2]\nsolution_rate_hz = 50.0\n",
        },
        Program {
            name: "auvnav-live",
            bin: "auvnav-live",
            check: check_file,
            base: std::fs::read_to_string(
                Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/auvnav-live.toml"),
            )
            .expect("live toml"),
        },
    ]
}

#[test]
fn every_number_of_every_configuration_is_range_checked() {
    let dir = TempDir::new("cfgwalk");
    let d = dir.path();
    let mut accepted = Vec::new();
    let mut unnamed = Vec::new();
    let mut walked = 0;
    for p in programs(d) {
        let file = d.join("base.toml");
        std::fs::write(&file, &p.base).expect("write");
        let (code, printed, err) = run(&p, &file);
        assert_eq!(
            code,
            Some(0),
            "{}: the base configuration fails: {err}",
            p.name
        );
        // What the program printed has every default filled in: that is what is walked.
        let full: toml::Value = toml::from_str(&printed).unwrap_or_else(|e| {
            panic!(
                "{}: --check-config printed no TOML ({e}): {printed}",
                p.name
            )
        });
        let mut leaves = Vec::new();
        numbers(&full, &mut Vec::new(), &mut leaves);
        assert!(leaves.len() >= 3, "{}: {} numbers", p.name, leaves.len());
        for (path, key) in &leaves {
            for bad in [f64::NAN, 1e30, -1e30] {
                walked += 1;
                let mut v = full.clone();
                set(&mut v, path, bad);
                let text = toml::to_string(&v).expect("toml");
                let f = d.join("walk.toml");
                std::fs::write(&f, text).expect("write");
                let (code, _, err) = run(&p, &f);
                let at = format!("{}: {} = {bad}", p.name, path.join("."));
                if code != Some(2) {
                    accepted.push(format!("{at}: exit {code:?}"));
                } else if !err.contains(key.as_str()) {
                    unnamed.push(format!("{at}: the message does not name {key}: {err}"));
                }
            }
        }
    }
    eprintln!("{walked} out-of-range values tried");
    assert!(
        accepted.is_empty() && unnamed.is_empty(),
        "accepted:\n{}\nnot named:\n{}",
        accepted.join("\n"),
        unnamed.join("\n")
    );
}

/// Values that are not numbers but must still be refused before the program starts.
#[test]
fn addresses_paths_and_names_are_checked() {
    let dir = TempDir::new("cfgother");
    let d = dir.path();
    let cases: [(&str, &str, CheckArgs, String, &str); 5] = [
        (
            "auvnavd",
            "empty prefix",
            check_file,
            "prefix = \"\"\n[initial]\nlatitude_deg = 1.0\nlongitude_deg = 2.0\nheight_m = 0.0\neuler_deg = [0.0, 0.0, 0.0]\n".into(),
            "prefix",
        ),
        (
            "auvnavd",
            "CSV in a missing folder",
            check_file,
            "[output]\nnav_csv = \"/nonexistent-folder/nav.csv\"\n[initial]\nlatitude_deg = 1.0\nlongitude_deg = 2.0\nheight_m = 0.0\neuler_deg = [0.0, 0.0, 0.0]\n".into(),
            "output.nav_csv",
        ),
        (
            "auvnav-bridge",
            "listen address that does not parse",
            check_file,
            "[zenoh]\nlisten = [\"garbage\"]\n[[export]]\ntopics = \"nav/solution\"\nkey_prefix = \"a/b\"\n".into(),
            "zenoh.listen",
        ),
        (
            "auvnav-imu",
            "stage times in a missing folder",
            check_flag,
            "protocol = \"kvh1750\"\nstage_times_csv = \"/nonexistent-folder/t.csv\"\n[serial]\nport = \"/dev/ttyX\"\n".into(),
            "stage_times_csv",
        ),
        (
            "auvnav-live",
            "an allowed origin that is not an origin",
            check_file,
            "allowed_origins = [\"not an origin\"]\n".into(),
            "allowed_origins",
        ),
    ];
    for (bin, what, check, text, key) in cases {
        let f = d.join("c.toml");
        std::fs::write(&f, text).expect("write");
        let p = Program {
            name: bin,
            bin,
            check,
            base: String::new(),
        };
        let (code, _, err) = run(&p, &f);
        assert_eq!(code, Some(2), "{bin}: {what} accepted: {err}");
        assert!(err.contains(key), "{bin}: {what}: {err}");
    }
}

/// One convention for every on-board program: `--check-config FILE` and `--config FILE
/// --check-config` both check the file and print the same thing; `--check-config` with neither a
/// file nor `--config` is a usage error (status 2) that says what is needed, and two different
/// files are refused.
#[test]
fn every_program_accepts_both_check_config_forms() {
    let dir = TempDir::new("cfgforms");
    let d = dir.path();
    let mut seen = std::collections::HashSet::new();
    for p in programs(d) {
        if !seen.insert(p.bin) {
            continue;
        }
        let file = d.join(format!("{}.toml", p.bin));
        std::fs::write(&file, &p.base).expect("write");
        let mut printed = Vec::new();
        for form in [check_file as CheckArgs, check_flag as CheckArgs] {
            let o = Command::new(binary(p.bin))
                .args(form(&file))
                .output()
                .expect("run");
            assert_eq!(
                o.status.code(),
                Some(0),
                "{} {:?}: {}",
                p.bin,
                form(&file),
                String::from_utf8_lossy(&o.stderr)
            );
            printed.push(String::from_utf8_lossy(&o.stdout).into_owned());
        }
        assert_eq!(printed[0], printed[1], "{}: the two forms differ", p.bin);
        let other = d.join("other.toml");
        std::fs::write(&other, &p.base).expect("write");
        let o = Command::new(binary(p.bin))
            .args(["--check-config", &file.display().to_string()])
            .args(["--config", &other.display().to_string()])
            .output()
            .expect("run");
        assert_eq!(o.status.code(), Some(2), "{}: two files accepted", p.bin);
        if p.bin == "auvnav-live" {
            // The live view has defaults: `--check-config` alone prints them.
            continue;
        }
        let o = Command::new(binary(p.bin))
            .arg("--check-config")
            .output()
            .expect("run");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            o.status.code() == Some(2) && err.contains("--config FILE is required"),
            "{}: --check-config alone: {:?} {err}",
            p.bin,
            o.status.code()
        );
    }
}
