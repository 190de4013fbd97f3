//! The DVL's sound speed: a voyage simulated with a true sound speed of 1480 m/s where the DVL
//! assumed 1500 (`dvl.sound_speed`). With the true sound speed configured
//! (`dvl_sound_speed_source = "value"`) the navigation is as good as the clean voyage's; without
//! it, model discovery names the cause (`dvl.sound_speed`, beside the DVL scale it aliases).

use auvnav_tests::processes::{TempDir, binary};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn auvnav(args: &[&str]) -> Value {
    let out = Command::new(binary("auvnav"))
        .args(args)
        .output()
        .expect("running auvnav");
    assert!(
        out.status.success(),
        "auvnav {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON")
}

fn simulate(dir: &Path, name: &str, effects: &[&str]) -> PathBuf {
    let log = dir.join(format!("{name}.mcap"));
    let mut args = vec![
        "sim",
        "--scenario",
        "lawnmower",
        "--seed",
        "9101",
        "--duration",
        "900",
    ];
    for e in effects {
        args.extend(["--effect", e]);
    }
    let log_s = log.display().to_string();
    args.extend(["--out", &log_s, "--json"]);
    auvnav(&args);
    log
}

fn error_per_distance(log: &Path, config: Option<&Path>) -> f64 {
    let log_s = log.display().to_string();
    let mut args = vec!["replay", log_s.as_str(), "--json"];
    let config_s = config.map(|c| c.display().to_string());
    if let Some(c) = &config_s {
        args.extend(["--config", c]);
    }
    let r = auvnav(&args);
    r["accuracy"]["error_per_distance_cep50_percent"]
        .as_f64()
        .expect("an accuracy figure")
}

#[test]
fn a_configured_sound_speed_restores_the_navigation_and_discovery_names_it() {
    let dir = TempDir::new("soundspeed");
    let clean = simulate(dir.path(), "clean", &[]);
    let hidden = simulate(dir.path(), "hidden", &["dvl.sound_speed=1480"]);
    let config = dir.path().join("sound-speed.toml");
    std::fs::write(
        &config,
        "[navigation]\ndvl_sound_speed_source = \"value\"\nsound_speed_m_s = 1480.0\n",
    )
    .expect("config");
    let e_clean = error_per_distance(&clean, None);
    let e_hidden = error_per_distance(&hidden, None);
    let e_corrected = error_per_distance(&hidden, Some(&config));
    eprintln!(
        "error/distance CEP50: clean {e_clean:.4} %, 1480 m/s unconfigured {e_hidden:.4} %, configured {e_corrected:.4} %"
    );
    assert!(
        (e_corrected - e_clean).abs() <= 0.1 * e_clean,
        "configured {e_corrected} % against clean {e_clean} %"
    );
    assert!(e_hidden > 5.0 * e_clean, "{e_hidden} against {e_clean}");

    let hidden_s = hidden.display().to_string();
    let report = auvnav(&["discover", &hidden_s, "--json"]);
    let effects = report["effects"].as_array().expect("effects");
    let scale = effects
        .iter()
        .find(|e| e["name"] == "dvl.scale_factor")
        .unwrap_or_else(|| panic!("no DVL scale found: {effects:?}"));
    let q = &scale["equivalent"];
    assert_eq!(q["name"], "dvl.sound_speed", "{scale}");
    let c = q["value"].as_f64().expect("a sound speed");
    assert!((c - 1480.0).abs() < 2.0, "{c}");

    // On the clean voyage nothing of the kind is found.
    let clean_s = clean.display().to_string();
    let report = auvnav(&["discover", &clean_s, "--json"]);
    assert!(
        !report["effects"]
            .as_array()
            .expect("effects")
            .iter()
            .any(|e| e["name"] == "dvl.scale_factor"),
        "{report}"
    );
}

/// The true sound speed from a CTD on the bus (`sound_velocity`, `dvl_sound_speed_source =
/// "topic"`): the voyage with a CTD reporting the true 1480 m/s with every DVL ping navigates
/// exactly as with the sound speed configured as a value (the same solution, byte for byte), so
/// as well as the clean voyage; the readings are counted in the replay.
#[test]
fn a_ctd_on_the_sound_velocity_topic_corrects_the_dvl() {
    let dir = TempDir::new("soundspeedctd");
    let mut scenario = auvnav_sim::scenario::Scenario::load("lawnmower").expect("scenario");
    scenario.rates.ctd_hz = scenario.rates.dvl_hz;
    let scenario_file = dir.path().join("lawnmower-ctd.toml");
    std::fs::write(
        &scenario_file,
        toml::to_string(&scenario).expect("scenario as TOML"),
    )
    .expect("scenario file");
    let sim = |name: &str, effects: &[&str]| {
        let log = dir.path().join(format!("{name}.mcap"));
        let mut args = vec![
            "sim".to_string(),
            "--scenario".into(),
            scenario_file.display().to_string(),
            "--seed".into(),
            "9101".into(),
            "--duration".into(),
            "900".into(),
        ];
        for e in effects {
            args.extend(["--effect".to_string(), e.to_string()]);
        }
        args.extend(["--out".into(), log.display().to_string(), "--json".into()]);
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        let summary = auvnav(&a);
        assert_eq!(summary["sound_velocity"], 4500, "{summary}");
        log
    };
    let clean = sim("clean", &[]);
    let hidden = sim("hidden", &["dvl.sound_speed=1480"]);
    let config = dir.path().join("ctd.toml");
    std::fs::write(
        &config,
        "[navigation]\ndvl_sound_speed_source = \"topic\"\n",
    )
    .expect("config");
    let e_clean = error_per_distance(&clean, None);
    let e_topic = error_per_distance(&hidden, Some(&config));
    let e_hidden = error_per_distance(&hidden, None);
    eprintln!(
        "error/distance CEP50: clean {e_clean:.4} %, 1480 m/s with the CTD topic {e_topic:.4} %, without {e_hidden:.4} %"
    );
    assert!(
        (e_topic - e_clean).abs() <= 0.1 * e_clean,
        "CTD topic {e_topic} % against clean {e_clean} %"
    );
    assert!(e_hidden > 5.0 * e_clean);
    let hidden_s = hidden.display().to_string();
    let config_s = config.display().to_string();
    let topic_csv = dir.path().join("topic.csv");
    let r = auvnav(&[
        "replay",
        &hidden_s,
        "--config",
        &config_s,
        "--out",
        &topic_csv.display().to_string(),
        "--json",
    ]);
    assert_eq!(r["counts"]["sound_velocity"], 4500, "{}", r["counts"]);
    assert_eq!(
        r["navigator"]["sound_velocity_used"], 4500,
        "{}",
        r["navigator"]
    );
    let value = dir.path().join("value.toml");
    std::fs::write(
        &value,
        "[navigation]\ndvl_sound_speed_source = \"value\"\nsound_speed_m_s = 1480.0\n",
    )
    .expect("config");
    let value_csv = dir.path().join("value.csv");
    auvnav(&[
        "replay",
        &hidden_s,
        "--config",
        &value.display().to_string(),
        "--out",
        &value_csv.display().to_string(),
        "--json",
    ]);
    assert!(
        std::fs::read(&topic_csv).expect("topic") == std::fs::read(&value_csv).expect("value"),
        "the CTD topic and the configured value give different solutions"
    );
}
