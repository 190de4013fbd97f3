//! `auvnav replay` on damaged logs: gaps, duplicated and out-of-order time stamps, NaN values,
//! malformed messages, missing channels and a truncated file are skipped and counted or end with
//! a clear error; nothing panics.

use auvnav_log::{CDR_HEADER, LogHeader, LogMessage, LogWriter, write_log_atomically};
use auvnav_shm_schema::{DvlVelocityV1, ImuSampleV1, Message, TruthStateV1, topic};
use auvnav_sim::{self as sim, SimConfig, scenario::Scenario};
use auvnav_tools::replay::{ReplayArgs, ReplayReport, run};
use std::path::{Path, PathBuf};

fn messages(seconds: f64) -> Vec<LogMessage> {
    let scenario = Scenario::load("straight").expect("scenario");
    let effects = scenario.effects().expect("effects");
    let cfg = SimConfig {
        scenario,
        effects,
        seed: 7,
        duration_s: Some(seconds),
    };
    sim::simulate_to_vec(&cfg).expect("simulate").0
}

fn write(path: &Path, msgs: &[LogMessage]) {
    write_log_atomically(path, &LogHeader::new("test", ""), |w: &mut LogWriter<_>| {
        for m in msgs {
            match m {
                LogMessage::Imu(x) => w.write(topic::IMU, x)?,
                LogMessage::Dvl(x) => w.write(topic::DVL, x)?,
                LogMessage::Depth(x) => w.write(topic::DEPTH, x)?,
                LogMessage::Truth(x) => w.write(topic::TRUTH, x)?,
                LogMessage::Usbl(x) => w.write(topic::USBL, x)?,
                _ => {}
            }
        }
        Ok(())
    })
    .expect("write log");
}

fn replay(path: &Path) -> anyhow::Result<ReplayReport> {
    run(&ReplayArgs {
        log: path.to_path_buf(),
        config: None,
        out: None,
        decimate: 1,
        min_distance: 100.0,
        usbl: None,
        json: false,
        compare_recorded: false,
        reference_lever_arm: None,
    })
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("auvnav-bad-input-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("tmp dir");
    dir.join(name)
}

#[test]
fn gaps_duplicates_out_of_order_and_nan_are_skipped_and_counted() {
    let clean = messages(120.0);
    let mut msgs = Vec::new();
    let (mut dup, mut swapped, mut nan_imu, mut nan_dvl, mut gap) = (0, 0, 0, 0, 0);
    let mut imu_index = 0u64;
    let mut held: Option<LogMessage> = None;
    for m in &clean {
        match m {
            LogMessage::Imu(x) => {
                imu_index += 1;
                let t = x.host_time_ns as f64 * 1e-9;
                if (50.0..52.0).contains(&t) {
                    gap += 1; // two seconds of IMU lost
                    continue;
                }
                if imu_index.is_multiple_of(997) {
                    msgs.push(*m);
                    msgs.push(*m); // duplicated
                    dup += 1;
                    continue;
                }
                if imu_index.is_multiple_of(1499) {
                    held = Some(*m); // written after its successor: put back in its place
                    swapped += 1;
                    continue;
                }
                if imu_index.is_multiple_of(2003) {
                    let mut bad = *x;
                    bad.angular[1] = f64::NAN;
                    msgs.push(LogMessage::Imu(bad));
                    nan_imu += 1;
                    continue;
                }
                msgs.push(*m);
                if let Some(h) = held.take() {
                    msgs.push(h);
                }
            }
            LogMessage::Dvl(x) if x.sequence % 50 == 7 => {
                let mut bad: DvlVelocityV1 = *x;
                bad.velocity_dvl_m_s[0] = f64::NAN;
                msgs.push(LogMessage::Dvl(bad));
                nan_dvl += 1;
            }
            _ => msgs.push(*m),
        }
    }
    assert!(gap > 0 && dup > 0 && swapped > 0 && nan_imu > 0 && nan_dvl > 0);
    let path = tmp("damaged.mcap");
    write(&path, &msgs);
    let r = replay(&path).expect("replay of a damaged log");
    let n = &r.navigator;
    eprintln!("{n:?}");
    // Duplicates are skipped; a sample written after its successor is fed in its place.
    assert_eq!(n.imu_out_of_order, dup, "{n:?}");
    assert_eq!(r.counts.written_out_of_order, swapped, "{:?}", r.counts);
    assert_eq!(n.imu_invalid, nan_imu, "{n:?}");
    assert_eq!(n.imu_gaps, 1, "{n:?}");
    assert_eq!(n.dvl_invalid, nan_dvl, "{n:?}");
    let acc = r.accuracy.expect("truth");
    // Two seconds without IMU are bridged with one long step, and the DVL then pulls the
    // solution back: the error stays at the metre level.
    assert!(acc.horizontal_error_final_m < 5.0, "{acc:?}");
}

#[test]
fn a_log_without_truth_or_initial_state_is_a_clear_error() {
    let msgs: Vec<LogMessage> = messages(10.0)
        .into_iter()
        .filter(|m| !matches!(m, LogMessage::Truth(_)))
        .collect();
    let path = tmp("no-truth.mcap");
    write(&path, &msgs);
    let e = replay(&path).expect_err("no initial state").to_string();
    assert!(e.contains("no initial state"), "{e}");
}

#[test]
fn a_log_without_dvl_runs_degraded_and_says_so() {
    let msgs: Vec<LogMessage> = messages(30.0)
        .into_iter()
        .filter(|m| !matches!(m, LogMessage::Dvl(_)))
        .collect();
    let path = tmp("no-dvl.mcap");
    write(&path, &msgs);
    let r = replay(&path).expect("replay");
    assert_eq!(r.counts.dvl, 0);
    assert_eq!(r.navigator.dvl_fused, 0);
    assert!(r.samples_processed > 0);
}

#[test]
fn a_truncated_log_replays_what_was_written_and_reports_the_end() {
    let path = tmp("full.mcap");
    write(&path, &messages(60.0));
    let bytes = std::fs::read(&path).expect("read");
    let cut = tmp("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).expect("write");
    let r = replay(&cut).expect("replay of a truncated log");
    assert!(r.log_error.is_some(), "{r:?}");
    assert!(
        r.log_duration_s > 10.0 && r.log_duration_s < 60.0,
        "{}",
        r.log_duration_s
    );
}

#[test]
fn messages_of_the_wrong_size_are_counted_as_malformed() {
    // Written with a plain MCAP writer: a valid header, truth and IMU, plus one message on a
    // channel that claims the IMU schema but carries 4 bytes after the CDR header.
    let path = tmp("malformed.mcap");
    let msgs = messages(5.0);
    let mut out = mcap::Writer::new(std::io::Cursor::new(Vec::new())).expect("mcap writer");
    out.write_metadata(&LogHeader::new("test", "").to_metadata())
        .expect("metadata");
    let imu_schema = out
        .add_schema(
            ImuSampleV1::SCHEMA_NAME,
            "ros2msg",
            ImuSampleV1::ros2msg_definition().as_bytes(),
        )
        .expect("schema");
    let truth_schema = out
        .add_schema(
            TruthStateV1::SCHEMA_NAME,
            "ros2msg",
            TruthStateV1::ros2msg_definition().as_bytes(),
        )
        .expect("schema");
    let no_meta = Default::default();
    let imu = out
        .add_channel(imu_schema, topic::IMU, "cdr", &no_meta)
        .expect("channel");
    let truth = out
        .add_channel(truth_schema, topic::TRUTH, "cdr", &no_meta)
        .expect("channel");
    let short = out
        .add_channel(imu_schema, "imu/short", "cdr", &no_meta)
        .expect("channel");
    {
        let mut put = |channel_id: u16, t: u64, body: &[u8]| {
            let mut data = CDR_HEADER.to_vec();
            data.extend_from_slice(body);
            out.write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id,
                    sequence: 0,
                    log_time: t,
                    publish_time: t,
                },
                &data,
            )
            .expect("write");
        };
        for m in &msgs {
            match m {
                LogMessage::Truth(x) => put(truth, x.host_time_ns, bytemuck::bytes_of(x)),
                LogMessage::Imu(x) => put(imu, x.host_time_ns, bytemuck::bytes_of(x)),
                _ => {}
            }
        }
        put(short, 5_000_000_000, &[1, 2, 3, 4]);
    }
    out.finish().expect("finish");
    std::fs::write(&path, out.into_inner().into_inner()).expect("write file");
    let r = replay(&path).expect("replay");
    assert_eq!(r.counts.malformed, 1, "{:?}", r.counts);
    assert!(r.samples_processed > 0);
}
