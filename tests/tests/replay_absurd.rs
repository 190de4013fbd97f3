//! A recorded log holding absurd but finite IMU samples (1e30 under a valid checksum, a rate of
//! 1 000 rad/s) replays to finite solutions only: `auvnav replay` counts the samples invalid and
//! the solution CSV holds no NaN (before the plausibility checks, such a log replayed to NaN for
//! the rest of the run).

use auvnav_log::{LogHeader, LogMessage, LogWriter, write_log_atomically};
use auvnav_shm_schema::topic;
use auvnav_sim::{self as sim, SimConfig, scenario::Scenario};
use auvnav_tools::replay::{ReplayArgs, run};

#[test]
fn absurd_imu_samples_in_a_log_replay_to_finite_solutions() {
    let scenario = Scenario::load("straight").expect("scenario");
    let effects = scenario.effects().expect("effects");
    let msgs = sim::simulate_to_vec(&SimConfig {
        scenario,
        effects,
        seed: 21,
        duration_s: Some(100.0),
    })
    .expect("simulate")
    .0;
    let dir = std::env::temp_dir().join(format!("auvnav-absurd-log-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("tmp dir");
    let log = dir.join("absurd.mcap");
    let mut k = 0u64;
    write_log_atomically(&log, &LogHeader::new("test", ""), |w: &mut LogWriter<_>| {
        for m in &msgs {
            match m {
                LogMessage::Imu(x) => {
                    k += 1;
                    let mut x = *x;
                    if (8000..8010).contains(&k) {
                        x.angular = [1e30; 3];
                        x.specific = [1e30; 3];
                    } else if k == 12_000 {
                        x.angular[2] = 1000.0;
                    }
                    w.write(topic::IMU, &x)?
                }
                LogMessage::Dvl(x) => w.write(topic::DVL, x)?,
                LogMessage::Depth(x) => w.write(topic::DEPTH, x)?,
                LogMessage::Truth(x) => w.write(topic::TRUTH, x)?,
                _ => {}
            }
        }
        Ok(())
    })
    .expect("write log");
    let csv = dir.join("nav.csv");
    let report = run(&ReplayArgs {
        log: log.clone(),
        config: None,
        out: Some(csv.clone()),
        decimate: 1,
        min_distance: 100.0,
        usbl: None,
        json: false,
        compare_recorded: false,
        reference_lever_arm: None,
    })
    .expect("replay");
    let text = std::fs::read_to_string(&csv).expect("csv");
    let rows = text.lines().count();
    let nan_rows = text
        .lines()
        .filter(|l| l.to_ascii_lowercase().contains("nan") || l.contains("inf"))
        .count();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(rows > 15_000, "{rows} rows");
    assert_eq!(
        nan_rows, 0,
        "{nan_rows} of {rows} rows hold NaN or infinity"
    );
    assert!(
        report.navigator.imu_invalid >= 11,
        "the absurd samples are counted: {:?}",
        report.navigator
    );
}
