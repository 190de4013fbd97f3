//! `auvnav bench`: throughput figures.

use crate::sim::{self, SimConfig, scenario::Scenario};
use anyhow::Context;
use serde::Serialize;

#[derive(Debug, Serialize)]
pub struct SimBench {
    pub simulated_hours: f64,
    pub imu_hz: u32,
    pub dvl_hz: u32,
    pub usbl_hz: u32,
    pub depth_hz: u32,
    pub truth_hz: u32,
    pub messages: u64,
    pub file_bytes: u64,
    pub runs_wall_s: Vec<f64>,
    pub median_wall_s: f64,
    pub simulated_seconds_per_wall_second: f64,
}

/// Simulates `hours` of the docking scenario (200 Hz IMU, 5 Hz DVL, 1 Hz USBL, 1 Hz depth, plus
/// the 20 Hz truth channel; no magnetometer) into a temporary log, `repeat` times.
pub fn sim(hours: f64, repeat: usize, json: bool) -> anyhow::Result<()> {
    let mut scenario = Scenario::load("docking")?;
    scenario.rates.magnetometer_hz = 0;
    scenario.rates.gnss_hz = 0;
    let mut effects = scenario.effects()?;
    effects.set("usbl.max_range", &[10000.0])?;
    let cfg = SimConfig {
        scenario,
        effects,
        seed: 1,
        duration_s: Some(hours * 3600.0),
    };
    let dir = std::env::temp_dir().join(format!("auvnav-bench-sim-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let path = dir.join("bench.mcap");
    let mut runs = Vec::new();
    let mut messages = 0;
    for _ in 0..repeat.max(1) {
        let t = std::time::Instant::now();
        let s = sim::simulate_to_log(&cfg, &path)?;
        runs.push(t.elapsed().as_secs_f64());
        messages = s.imu + s.dvl + s.usbl + s.depth + s.truth;
    }
    let file_bytes = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
    let _ = std::fs::remove_dir_all(&dir);
    let median = median(&runs);
    let r = &cfg.scenario.rates;
    let out = SimBench {
        simulated_hours: hours,
        imu_hz: r.imu_hz,
        dvl_hz: r.dvl_hz,
        usbl_hz: r.usbl_hz,
        depth_hz: r.depth_hz,
        truth_hz: r.truth_hz,
        messages,
        file_bytes,
        runs_wall_s: runs,
        median_wall_s: median,
        simulated_seconds_per_wall_second: hours * 3600.0 / median,
    };
    if json {
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        println!(
            "sim: {} h in {:.3} s (median of {}), {} messages, {} bytes",
            hours,
            median,
            out.runs_wall_s.len(),
            messages,
            file_bytes
        );
    }
    Ok(())
}

#[derive(Debug, Serialize)]
pub struct ReplayBench {
    pub log_hours: f64,
    pub imu_hz: u32,
    pub dvl_hz: u32,
    pub depth_hz: u32,
    pub truth_hz: u32,
    pub imu_samples: u64,
    /// Wall time of each run of `auvnav replay` on the log file (read, decode, navigate).
    pub runs_wall_s: Vec<f64>,
    pub median_wall_s: f64,
    /// Log seconds per wall second of the median run.
    pub real_time_factor: f64,
    /// The same with the messages already decoded in memory: the navigation core alone.
    pub core_runs_wall_s: Vec<f64>,
    pub core_median_wall_s: f64,
    pub core_real_time_factor: f64,
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[s.len() / 2]
}

/// Replays `hours` of simulated INS/DVL/depth (200 Hz IMU, 1 Hz DVL, 1 Hz depth, 1 Hz truth for
/// the initial state and the accuracy) through the navigation core, `repeat` times, from the log
/// file and from memory. One thread.
pub fn replay(hours: f64, repeat: usize, json: bool) -> anyhow::Result<()> {
    use crate::replay::{Replay, ReplayArgs, ReplayConfig};
    let mut scenario = Scenario::load("lawnmower")?;
    scenario.rates.imu_hz = 200;
    scenario.rates.dvl_hz = 1;
    scenario.rates.depth_hz = 1;
    scenario.rates.truth_hz = 1;
    scenario.rates.usbl_hz = 0;
    scenario.rates.magnetometer_hz = 0;
    scenario.rates.gnss_hz = 0;
    let effects = scenario.effects()?;
    let cfg = SimConfig {
        scenario,
        effects,
        seed: 1,
        duration_s: Some(hours * 3600.0),
    };
    let dir = std::env::temp_dir().join(format!("auvnav-bench-replay-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let path = dir.join("bench.mcap");
    let result = (|| -> anyhow::Result<ReplayBench> {
        let summary = sim::simulate_to_log(&cfg, &path)?;
        let args = ReplayArgs {
            log: path.clone(),
            config: None,
            out: None,
            decimate: 1,
            min_distance: 100.0,
            usbl: None,
            json: false,
        };
        let mut runs = Vec::new();
        let mut log_seconds = 0.0;
        for _ in 0..repeat.max(1) {
            let t = std::time::Instant::now();
            let r = crate::replay::run(&args)?;
            runs.push(t.elapsed().as_secs_f64());
            log_seconds = r.log_seconds;
        }
        let (messages, _) = sim::simulate_to_vec(&cfg)?;
        let mut core_runs = Vec::new();
        for _ in 0..repeat.max(1) {
            let t = std::time::Instant::now();
            let mut replay = Replay::new(&ReplayConfig::default(), 100.0);
            for m in &messages {
                replay.process(m, &mut |_| Ok(()))?;
            }
            replay.finish(&mut |_| Ok(()))?;
            std::hint::black_box(replay.accuracy());
            core_runs.push(t.elapsed().as_secs_f64());
        }
        let r = &cfg.scenario.rates;
        let (m, cm) = (median(&runs), median(&core_runs));
        Ok(ReplayBench {
            log_hours: log_seconds / 3600.0,
            imu_hz: r.imu_hz,
            dvl_hz: r.dvl_hz,
            depth_hz: r.depth_hz,
            truth_hz: r.truth_hz,
            imu_samples: summary.imu,
            runs_wall_s: runs,
            median_wall_s: m,
            real_time_factor: log_seconds / m,
            core_runs_wall_s: core_runs,
            core_median_wall_s: cm,
            core_real_time_factor: log_seconds / cm,
        })
    })();
    let _ = std::fs::remove_dir_all(&dir);
    let out = result?;
    if json {
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        println!(
            "replay: {:.2} h of {} Hz IMU / {} Hz DVL / {} Hz depth in {:.3} s from the log (real-time factor {:.0}), {:.3} s from memory ({:.0}); median of {}",
            out.log_hours,
            out.imu_hz,
            out.dvl_hz,
            out.depth_hz,
            out.median_wall_s,
            out.real_time_factor,
            out.core_median_wall_s,
            out.core_real_time_factor,
            out.runs_wall_s.len()
        );
    }
    Ok(())
}

#[derive(Debug, Serialize)]
pub struct AccuracyBench {
    pub scenario: String,
    pub seeds: Vec<u64>,
    pub distance_m: f64,
    /// Error/distance CEP50 (S-CAL formula) per seed (%).
    pub error_per_distance_cep50_percent: Vec<f64>,
    pub median_error_per_distance_cep50_percent: f64,
    pub final_error_m: Vec<f64>,
    pub median_final_error_m: f64,
}

/// INS/DVL/depth accuracy of the navigation core on a simulated scenario over several seeds.
pub fn accuracy(scenario_name: &str, seeds: u64, json: bool) -> anyhow::Result<()> {
    let scenario = Scenario::load(scenario_name)?;
    let effects = scenario.effects()?;
    let mut out = AccuracyBench {
        scenario: scenario.name.clone(),
        seeds: (1..=seeds.max(1)).collect(),
        distance_m: 0.0,
        error_per_distance_cep50_percent: Vec::new(),
        median_error_per_distance_cep50_percent: 0.0,
        final_error_m: Vec::new(),
        median_final_error_m: 0.0,
    };
    for &seed in &out.seeds {
        let cfg = SimConfig {
            scenario: scenario.clone(),
            effects: effects.clone(),
            seed,
            duration_s: None,
        };
        let (_, acc, _) =
            crate::demo::run_voyage(&cfg, auvnav_core::navigator::NavConfig::default(), None)?;
        out.distance_m = acc.distance_travelled_m;
        out.error_per_distance_cep50_percent
            .push(acc.error_per_distance_cep50_percent);
        out.final_error_m.push(acc.horizontal_error_final_m);
    }
    out.median_error_per_distance_cep50_percent = median(&out.error_per_distance_cep50_percent);
    out.median_final_error_m = median(&out.final_error_m);
    if json {
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        println!(
            "accuracy: scenario {} ({:.0} m), {} seeds: error/distance CEP50 median {:.4} % (max {:.4} %), final error median {:.2} m",
            out.scenario,
            out.distance_m,
            out.seeds.len(),
            out.median_error_per_distance_cep50_percent,
            out.error_per_distance_cep50_percent
                .iter()
                .cloned()
                .fold(0.0, f64::max),
            out.median_final_error_m
        );
    }
    Ok(())
}

#[derive(Debug, Serialize)]
pub struct DecodeBench {
    pub protocol: &'static str,
    pub frames: u64,
    pub bytes: u64,
    pub runs_wall_s: Vec<f64>,
    pub median_wall_s: f64,
    pub megabytes_per_second: f64,
    pub frames_per_second: f64,
}

/// Times decoding `stream` in 4 KiB reads with a fresh decoder, `repeat` times.
fn time_decoder<D: auvnav_drivers::framing::StreamDecoder>(
    protocol: &'static str,
    stream: &[u8],
    repeat: usize,
    new: impl Fn() -> D,
) -> DecodeBench {
    let mut runs = Vec::new();
    let mut frames = 0;
    for _ in 0..repeat.max(1) {
        let t = std::time::Instant::now();
        let mut d = new();
        auvnav_drivers::framing::decode_stream(&mut d, stream, 4096, |f| {
            std::hint::black_box(&f);
        });
        runs.push(t.elapsed().as_secs_f64());
        frames = d.stats().frames;
    }
    let m = median(&runs);
    DecodeBench {
        protocol,
        frames,
        bytes: stream.len() as u64,
        runs_wall_s: runs,
        median_wall_s: m,
        megabytes_per_second: stream.len() as f64 / m / 1e6,
        frames_per_second: frames as f64 / m,
    }
}

/// Decoder throughput per protocol: synthetic streams of typical navigation frames (PD0
/// variable leader + bottom track, Water Linked `wrz`, KVH format A, Xsens MTData2 with
/// counter/time/status/acceleration/rate/delta-v/delta-q, SeaTrac fixes with range, USBL and
/// position) fed in 4 KiB reads, as a driver reads a serial port.
pub fn decode(repeat: usize, pty_seconds: f64, json: bool) -> anyhow::Result<()> {
    use auvnav_drivers::{kvh, pd0, seatrac, wldvl, xsens};
    let n = 100_000u32;
    let mut results = Vec::new();

    let mut stream = Vec::new();
    for k in 0..n {
        let e = pd0::Ensemble {
            variable: Some(pd0::VariableLeader {
                ensemble_number: k,
                rtc: [26, 11, 22, 6, 0, (k % 60) as u8, 0],
                rtc_y2k: Some([20, 26, 11, 22, 6, 0, (k % 60) as u8, 0]),
                bit_result: 0,
                sound_speed_m_s: 1500.0,
                depth_m: 20.0,
                heading_deg: f64::from(k % 36000) * 0.01,
                pitch_deg: 1.0,
                roll_deg: -0.5,
                salinity_ppt: 35.0,
                temperature_c: 12.5,
                pressure_pa: Some(2.0e5),
            }),
            bottom_track: Some(pd0::BottomTrack {
                pings_per_ensemble: 1,
                range_m: [Some(30.0), Some(31.0), Some(29.5), Some(30.5)],
                velocity_m_s: [Some(-1.5), Some(0.01), Some(0.02), Some(0.0)],
                correlation: [250; 4],
                evaluation_amplitude: [60; 4],
                percent_good: [100; 4],
                max_depth_m: 200.0,
            }),
            ..Default::default()
        };
        stream.extend(pd0::encode_ensemble(&e));
    }
    results.push(time_decoder("pd0", &stream, repeat, pd0::Pd0Decoder::new));

    let mut stream = Vec::new();
    for k in 0..n {
        stream.extend(wldvl::encode(&wldvl::WlFrame::Velocity(wldvl::Velocity {
            velocity_m_s: [1.5, 0.01 * f64::from(k % 7), -0.02],
            valid: true,
            altitude_m: 12.3,
            figure_of_merit_m_s: 0.004,
            covariance: [1e-5, 0.0, 0.0, 0.0, 1e-5, 0.0, 0.0, 0.0, 1e-5],
            time_of_validity_us: u64::from(k) * 100_000,
            time_of_transmission_us: u64::from(k) * 100_000 + 5_000,
            time_since_last_ms: 100.0,
            status: 0,
        })));
    }
    results.push(time_decoder(
        "wldvl",
        &stream,
        repeat,
        wldvl::WlDecoder::new,
    ));

    let mut stream = Vec::new();
    for k in 0..n {
        stream.extend(kvh::encode(&kvh::KvhSample {
            gyro: [1e-5, -2e-5, 3e-5],
            accel: [0.01, -0.02, 1.0],
            status: 0x77,
            sequence: (k % 128) as u8,
            temperature_raw: 29,
            timestamp_us: None,
        }));
    }
    results.push(time_decoder(
        "kvh1750",
        &stream,
        repeat,
        kvh::KvhDecoder::new,
    ));

    let mut stream = Vec::new();
    for k in 0..n {
        stream.extend(xsens::encode_mtdata2(&xsens::MtData2 {
            packet_counter: Some(k as u16),
            sample_time_fine: Some(k * 10),
            status_word: Some(3),
            acceleration: Some([0.1, -0.2, -9.8]),
            rate_of_turn: Some([0.01, 0.02, -0.03]),
            delta_v: Some([0.001, -0.002, -0.098]),
            delta_q: Some([1.0, 1e-4, -1e-4, 2e-4]),
            ..Default::default()
        }));
    }
    results.push(time_decoder(
        "xsens",
        &stream,
        repeat,
        xsens::XbusDecoder::new,
    ));

    let mut stream = Vec::new();
    for k in 0..n {
        let fix = seatrac::AcoFix {
            destination_id: 15,
            source_id: 1,
            flags: seatrac::AcoFix::RANGE_VALID
                | seatrac::AcoFix::USBL_VALID
                | seatrac::AcoFix::POSITION_VALID,
            message_type: 4,
            attitude_deg: [f64::from(k % 3600) * 0.1, 1.0, -1.0],
            local_depth_m: 2.0,
            sound_speed_m_s: 1500.0,
            rssi_db: -50.0,
            range: Some(seatrac::FixRange {
                count: 1000,
                travel_time_s: 0.1,
                distance_m: 75.0,
            }),
            usbl: Some(seatrac::FixUsbl {
                channel_rssi_db: vec![-50.0; 4],
                azimuth_deg: 45.0,
                elevation_deg: -30.0,
                fit_error: 0.2,
            }),
            position_m: Some([40.0, 40.0, 37.5]),
        };
        stream.extend(seatrac::encode_line(
            seatrac::CID_XCVR_FIX,
            &seatrac::encode_aco_fix(&fix),
        ));
    }
    results.push(time_decoder(
        "seatrac",
        &stream,
        repeat,
        seatrac::SeatracDecoder::new,
    ));

    let mut latency = Vec::new();
    if pty_seconds > 0.0 {
        for rate in [200.0, 1000.0] {
            latency.push(pty_latency(rate, pty_seconds)?);
        }
    }
    if json {
        println!(
            "{}",
            serde_json::to_string_pretty(
                &serde_json::json!({ "throughput": results, "pty_latency": latency })
            )?
        );
    } else {
        for l in &latency {
            println!(
                "pty {} at {} Hz: {}/{} frames; write->read p50 {:.0} us p99 {:.0} us; read->subscriber p50 {:.0} us p99 {:.0} us; total p50 {:.0} us p99 {:.0} us max {:.0} us",
                l.protocol,
                l.rate_hz,
                l.frames_received,
                l.frames_written,
                l.pty_to_read_us.p50,
                l.pty_to_read_us.p99,
                l.read_to_subscriber_us.p50,
                l.read_to_subscriber_us.p99,
                l.total_us.p50,
                l.total_us.p99,
                l.total_us.max
            );
        }
        for out in &results {
            println!(
                "decode {:8}: {} frames, {:.1} MB in {:.3} s (median of {}): {:.0} MB/s, {:.0} frames/s",
                out.protocol,
                out.frames,
                out.bytes as f64 / 1e6,
                out.median_wall_s,
                out.runs_wall_s.len(),
                out.megabytes_per_second,
                out.frames_per_second
            );
        }
    }
    Ok(())
}

/// Latency through a real pseudo-terminal and a real driver process at one frame rate.
#[derive(Debug, Clone, Serialize)]
pub struct PtyLatency {
    pub protocol: String,
    pub rate_hz: f64,
    pub frames_written: u64,
    pub frames_received: u64,
    /// Write call of the frame → the driver's read returned (its host time stamp): the
    /// terminal and the driver's wake-up (µs).
    pub pty_to_read_us: Percentiles,
    /// Read return → message received by a subscriber in another process: decode, publish and
    /// the shared-memory hop with event wake-up (µs).
    pub read_to_subscriber_us: Percentiles,
    /// Write call → message received by the subscriber: an upper bound of byte arrival →
    /// publish (µs).
    pub total_us: Percentiles,
}

/// p50, p99 and maximum.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Percentiles {
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
}

fn percentiles(mut v: Vec<f64>) -> Percentiles {
    if v.is_empty() {
        return Percentiles {
            p50: f64::NAN,
            p99: f64::NAN,
            max: f64::NAN,
        };
    }
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    Percentiles {
        p50: at(0.5),
        p99: at(0.99),
        max: v[v.len() - 1],
    }
}

/// Plays KVH 1750 frames (format B, the frame index in the device time stamp) into a
/// pseudo-terminal read by a real `auvnav-imu` process, and times each frame from its write call
/// to its arrival at a subscriber in this process.
pub fn pty_latency(rate_hz: f64, seconds: f64) -> anyhow::Result<PtyLatency> {
    use auvnav_drivers::clock::monotonic_ns;
    use auvnav_shm_schema::bus::Bus;
    use auvnav_shm_schema::{ImuSampleV1, qos, topic};
    use std::io::Write;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::time::{Duration, Instant};

    let exe = std::env::current_exe()?;
    let driver = exe
        .parent()
        .context("executable directory")?
        .join("auvnav-imu");
    if !driver.exists() {
        anyhow::bail!(
            "{} not found: build the drivers (cargo build --release -p auvnav-drivers)",
            driver.display()
        );
    }
    let tag = format!("benchpty{}r{}", std::process::id(), rate_hz as u64);
    let dir = std::env::temp_dir().join(&tag);
    std::fs::create_dir_all(&dir)?;
    let (mut master, slave) = serialport::TTYPort::pair().context("pseudo-terminal")?;
    use serialport::SerialPort;
    let slave_path = slave.name().context("slave path")?;
    let cfg = dir.join("imu.toml");
    std::fs::write(
        &cfg,
        format!(
            "prefix = \"{tag}\"\nprotocol = \"kvh1750\"\n[serial]\nport = \"{slave_path}\"\n\
             baud = 921600\n[settings.kvh]\nincrements = false\ndegrees = false\n\
             rate_hz = {rate_hz}\ntemperature_centi = false\n"
        ),
    )?;
    let done = std::sync::Arc::new(AtomicBool::new(false));
    let ready = std::sync::Arc::new(AtomicBool::new(false));
    // The subscriber lives in its own thread (iceoryx2 ports stay on the thread that made them).
    let sub_thread = {
        let done = done.clone();
        let ready = ready.clone();
        let tag = tag.clone();
        std::thread::spawn(move || -> anyhow::Result<Vec<(u64, u64, u64)>> {
            let bus = Bus::new(&format!("{tag}sub"), &tag)?;
            let mut sub = bus.subscriber::<ImuSampleV1>(topic::IMU, qos::SENSOR)?;
            ready.store(true, Ordering::SeqCst);
            let mut got = Vec::new();
            while !done.load(Ordering::SeqCst) {
                sub.wait(Duration::from_millis(20))?;
                while let Some(m) = sub.receive()? {
                    got.push((m.device_time_ns / 1000, m.host_time_ns, monotonic_ns()));
                }
            }
            Ok(got)
        })
    };
    while !ready.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_millis(5));
    }
    let mut child = std::process::Command::new(&driver)
        .arg("--config")
        .arg(&cfg)
        .stderr(std::process::Stdio::null())
        .spawn()
        .with_context(|| format!("starting {}", driver.display()))?;
    // Let the driver open the terminal and its publisher connect.
    std::thread::sleep(Duration::from_millis(1500));
    let n = (rate_hz * seconds).round() as u64;
    let mut written = vec![0u64; n as usize];
    let start = Instant::now();
    for i in 0..n {
        let due = start + Duration::from_secs_f64(i as f64 / rate_hz);
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
        let frame = auvnav_drivers::kvh::encode(&auvnav_drivers::kvh::KvhSample {
            gyro: [1e-4, 0.0, 0.0],
            accel: [0.0, 0.0, -1.0],
            status: 0x77,
            sequence: (i % 128) as u8,
            temperature_raw: 20,
            timestamp_us: Some(i as u32),
        });
        written[i as usize] = monotonic_ns();
        master.write_all(&frame)?;
    }
    std::thread::sleep(Duration::from_millis(300));
    let _ = nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    );
    let _ = child.wait();
    done.store(true, Ordering::SeqCst);
    let got = sub_thread
        .join()
        .map_err(|_| anyhow::anyhow!("subscriber thread panicked"))??;
    drop(slave);
    let _ = std::fs::remove_dir_all(&dir);
    let (mut pty, mut hop, mut total) = (Vec::new(), Vec::new(), Vec::new());
    for (idx, read_ns, recv_ns) in &got {
        let Some(&w) = written.get(*idx as usize) else {
            continue;
        };
        pty.push(read_ns.saturating_sub(w) as f64 * 1e-3);
        hop.push(recv_ns.saturating_sub(*read_ns) as f64 * 1e-3);
        total.push(recv_ns.saturating_sub(w) as f64 * 1e-3);
    }
    Ok(PtyLatency {
        protocol: "kvh1750".into(),
        rate_hz,
        frames_written: n,
        frames_received: got.len() as u64,
        pty_to_read_us: percentiles(pty),
        read_to_subscriber_us: percentiles(hop),
        total_us: percentiles(total),
    })
}

/// End-to-end latency of the on-board chain at one IMU rate.
#[derive(Debug, Clone, Serialize)]
pub struct E2eLatency {
    pub imu_rate_hz: f64,
    pub seconds: f64,
    pub imu_frames_written: u64,
    pub solutions_received: u64,
    /// IMU frame written to its pseudo-terminal → navigation solution received by a subscriber
    /// (µs): terminal, driver, shared memory, daemon (strapdown + filter), shared memory.
    pub frame_to_solution_us: Percentiles,
    /// IPC only: the IMU driver's read time stamp → the IMU message received by a subscriber in
    /// another process (µs): decode, publish and the shared-memory hop with event wake-up.
    pub driver_to_subscriber_us: Percentiles,
    /// CPU use of the daemon and of the recorder over the run (% of one core).
    pub daemon_cpu_percent: f64,
    pub recorder_cpu_percent: f64,
    pub dvl_frames_written: u64,
    pub usbl_frames_written: u64,
}

/// CPU time (s) a process has used so far (`/proc/PID/stat` utime + stime).
fn cpu_seconds(pid: u32) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // Fields after the command name (which is in parentheses and may hold spaces).
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    let hz = std::process::Command::new("getconf")
        .arg("CLK_TCK")
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .and_then(|s| s.trim().parse::<f64>().ok())
        .unwrap_or(100.0);
    Some(ticks / hz)
}

/// Runs the chain with real processes — `auvnav-imu`, `auvnav-dvl` (Water Linked, 5 Hz),
/// `auvnav-usbl` (SeaTrac, 1 Hz), `auvnavd` and `auvnav record` — on pseudo-terminals written by
/// this process, and times each IMU frame to its navigation solution.
pub fn e2e(rate_hz: f64, seconds: f64) -> anyhow::Result<E2eLatency> {
    use auvnav_drivers::clock::monotonic_ns;
    use auvnav_drivers::emulate as enc;
    use auvnav_shm_schema::bus::Bus;
    use auvnav_shm_schema::{DvlVelocityV1, ImuSampleV1, NavSolutionV1, UsblFixV1, qos, topic};
    use serialport::SerialPort;
    use std::io::Write;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::time::{Duration, Instant};

    let exe = std::env::current_exe()?;
    let bin_dir = exe.parent().context("executable directory")?.to_path_buf();
    let bin = |n: &str| -> anyhow::Result<std::path::PathBuf> {
        let p = bin_dir.join(n);
        anyhow::ensure!(
            p.exists(),
            "{} not found: build all binaries (cargo build --release)",
            p.display()
        );
        Ok(p)
    };
    let tag = format!("benche2e{}r{}", std::process::id(), rate_hz as u64);
    let dir = std::env::temp_dir().join(&tag);
    std::fs::create_dir_all(&dir)?;
    // Pseudo-terminals, one at a time.
    let mut ports = Vec::new();
    for _ in 0..3 {
        let (master, slave) = serialport::TTYPort::pair().context("pseudo-terminal")?;
        let path = slave.name().context("slave path")?;
        ports.push((master, slave, path));
    }
    let driver_cfg = |class: &str,
                      protocol: &str,
                      port: &str|
     -> anyhow::Result<std::path::PathBuf> {
        let p = dir.join(format!("{class}.toml"));
        std::fs::write(
            &p,
            format!(
                "prefix = \"{tag}\"\nprotocol = \"{protocol}\"\n[serial]\nport = \"{port}\"\nbaud = 921600\n\
                 [settings.kvh]\nincrements = false\ndegrees = false\nrate_hz = {rate_hz}\ntemperature_centi = false\n"
            ),
        )?;
        Ok(p)
    };
    let imu_cfg = driver_cfg("imu", "kvh1750", &ports[0].2)?;
    let dvl_cfg = driver_cfg("dvl", "wldvl", &ports[1].2)?;
    let usbl_cfg = driver_cfg("usbl", "seatrac", &ports[2].2)?;
    let daemon_cfg = dir.join("auvnavd.toml");
    let daemon = auvnav_core::config::DaemonConfig {
        prefix: tag.clone(),
        navigation: auvnav_core::config::NavConfig {
            imu_dt_from_device_time: true,
            ..Default::default()
        },
        initial: Some(auvnav_core::config::InitialState {
            latitude_deg: 31.0,
            longitude_deg: 120.0,
            height_m: -20.0,
            velocity_ned_m_s: [0.0; 3],
            euler_deg: [0.0; 3],
        }),
        ..Default::default()
    };
    std::fs::write(&daemon_cfg, daemon.to_toml()?)?;
    let done = std::sync::Arc::new(AtomicBool::new(false));
    let ready = std::sync::Arc::new(AtomicBool::new(false));
    type Seen = (Vec<(u64, u64)>, Vec<(u64, u64)>);
    let watcher = {
        let (done, ready, tag) = (done.clone(), ready.clone(), tag.clone());
        std::thread::spawn(move || -> anyhow::Result<Seen> {
            let bus = Bus::new(&format!("{tag}sub"), &tag)?;
            let mut sol = bus.subscriber::<NavSolutionV1>(topic::NAV_SOLUTION, qos::NAVIGATION)?;
            let mut imu = bus.subscriber::<ImuSampleV1>(topic::IMU, qos::SENSOR)?;
            ready.store(true, Ordering::SeqCst);
            let (mut sols, mut imus) = (Vec::new(), Vec::new());
            while !done.load(Ordering::SeqCst) {
                sol.wait(Duration::from_millis(20))?;
                while let Some(m) = sol.receive()? {
                    sols.push((m.sequence, monotonic_ns()));
                }
                while let Some(m) = imu.receive()? {
                    imus.push((m.host_time_ns, monotonic_ns()));
                }
            }
            Ok((sols, imus))
        })
    };
    while !ready.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_millis(5));
    }
    let spawn = |name: &str, args: &[&std::ffi::OsStr]| -> anyhow::Result<std::process::Child> {
        std::process::Command::new(bin(name)?)
            .args(args)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .with_context(|| format!("starting {name}"))
    };
    let record_path = dir.join("record.mcap");
    let mut children = [
        spawn(
            "auvnav",
            &[
                "record".as_ref(),
                "--out".as_ref(),
                record_path.as_os_str(),
                "--prefix".as_ref(),
                tag.as_ref(),
            ],
        )?,
        spawn("auvnavd", &["--config".as_ref(), daemon_cfg.as_os_str()])?,
        spawn("auvnav-imu", &["--config".as_ref(), imu_cfg.as_os_str()])?,
        spawn("auvnav-dvl", &["--config".as_ref(), dvl_cfg.as_os_str()])?,
        spawn("auvnav-usbl", &["--config".as_ref(), usbl_cfg.as_os_str()])?,
    ];
    std::thread::sleep(Duration::from_millis(1500));
    let (recorder_pid, daemon_pid) = (children[0].id(), children[1].id());
    let cpu0 = (cpu_seconds(daemon_pid), cpu_seconds(recorder_pid));
    let n = (rate_hz * seconds).round() as u64;
    let mut written = vec![0u64; n as usize];
    let (mut dvl_n, mut usbl_n) = (0u64, 0u64);
    let start = Instant::now();
    for i in 0..n {
        let due = start + Duration::from_secs_f64(i as f64 / rate_hz);
        if let Some(d) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(d);
        }
        let t_ns = (i as f64 / rate_hz * 1e9) as u64;
        let imu = ImuSampleV1 {
            angular: [1e-5, 0.0, 7.3e-5],
            specific: [0.0, 0.0, -9.79],
            device_time_ns: t_ns,
            status: ImuSampleV1::STATUS_GYRO_VALID
                | ImuSampleV1::STATUS_ACCEL_VALID
                | ImuSampleV1::STATUS_DEVICE_TIME_VALID,
            ..Default::default()
        };
        let cfg = auvnav_drivers::convert::KvhConfig {
            increments: false,
            degrees: false,
            rate_hz,
            temperature_centi: false,
        };
        let frame = enc::kvh_from_imu(&imu, &cfg, (i % 128) as u8);
        written[i as usize] = monotonic_ns();
        ports[0].0.write_all(&frame)?;
        // DVL at 5 Hz and USBL at 1 Hz, written between IMU frames.
        if (i as f64 * 5.0 / rate_hz).fract() == 0.0 {
            let v = DvlVelocityV1 {
                velocity_dvl_m_s: [0.0, 0.0, 0.0],
                altitude_m: 10.0,
                device_time_ns: t_ns,
                validity_time_ns: t_ns,
                validity: DvlVelocityV1::VALID_VELOCITY | DvlVelocityV1::VALID_ALTITUDE,
                ..Default::default()
            };
            ports[1].0.write_all(&enc::wrz_from_dvl(&v, 0.0))?;
            dvl_n += 1;
        }
        if (i as f64 / rate_hz).fract() == 0.0 {
            let u = UsblFixV1 {
                slant_range_m: 50.0,
                sound_speed_m_s: 1500.0,
                validity: UsblFixV1::VALID_RANGE | UsblFixV1::VALID_SOUND_SPEED,
                ..Default::default()
            };
            ports[2].0.write_all(&enc::seatrac_from_usbl(&u, 1))?;
            usbl_n += 1;
        }
    }
    let wall = start.elapsed().as_secs_f64();
    let cpu1 = (cpu_seconds(daemon_pid), cpu_seconds(recorder_pid));
    std::thread::sleep(Duration::from_millis(300));
    for c in children.iter_mut().rev() {
        let _ = nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(c.id() as i32),
            nix::sys::signal::Signal::SIGTERM,
        );
        let _ = c.wait();
    }
    done.store(true, Ordering::SeqCst);
    let (sols, imus) = watcher
        .join()
        .map_err(|_| anyhow::anyhow!("subscriber thread panicked"))??;
    for p in &mut ports {
        let _ = p.0.set_timeout(Duration::from_millis(1));
    }
    drop(ports);
    let _ = std::fs::remove_dir_all(&dir);
    // Bus sequence k = the k-th solution = IMU frame k (the first frame starts the session).
    let total: Vec<f64> = sols
        .iter()
        .filter_map(|(seq, recv)| {
            written
                .get(*seq as usize)
                .map(|w| recv.saturating_sub(*w) as f64 * 1e-3)
        })
        .collect();
    let hop: Vec<f64> = imus
        .iter()
        .map(|(read, recv)| recv.saturating_sub(*read) as f64 * 1e-3)
        .collect();
    let cpu = |a: Option<f64>, b: Option<f64>| match (a, b) {
        (Some(a), Some(b)) if wall > 0.0 => 100.0 * (b - a) / wall,
        _ => f64::NAN,
    };
    Ok(E2eLatency {
        imu_rate_hz: rate_hz,
        seconds,
        imu_frames_written: n,
        solutions_received: sols.len() as u64,
        frame_to_solution_us: percentiles(total),
        driver_to_subscriber_us: percentiles(hop),
        daemon_cpu_percent: cpu(cpu0.0, cpu1.0),
        recorder_cpu_percent: cpu(cpu0.1, cpu1.1),
        dvl_frames_written: dvl_n,
        usbl_frames_written: usbl_n,
    })
}

/// `auvnav bench e2e`.
pub fn e2e_bench(seconds: f64, json: bool) -> anyhow::Result<()> {
    let mut results = Vec::new();
    for rate in [200.0, 1000.0] {
        results.push(e2e(rate, seconds)?);
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&results)?);
    } else {
        for r in &results {
            println!(
                "e2e at {} Hz IMU (+ DVL 5 Hz, USBL 1 Hz, recorder): {}/{} solutions; frame -> solution p50 {:.0} us, p99 {:.0} us, max {:.0} us; driver -> subscriber p50 {:.0} us, p99 {:.0} us; CPU daemon {:.1} %, recorder {:.1} %",
                r.imu_rate_hz,
                r.solutions_received,
                r.imu_frames_written,
                r.frame_to_solution_us.p50,
                r.frame_to_solution_us.p99,
                r.frame_to_solution_us.max,
                r.driver_to_subscriber_us.p50,
                r.driver_to_subscriber_us.p99,
                r.daemon_cpu_percent,
                r.recorder_cpu_percent
            );
        }
    }
    Ok(())
}

/// Wall time of the alignment Monte Carlo for one model.
#[derive(Debug, Clone, Serialize)]
pub struct AlignBench {
    pub model: u8,
    pub runs: usize,
    pub seconds_simulated_per_run: f64,
    pub threads: usize,
    pub wall_seconds: f64,
}

/// `auvnav bench align`: the seed's Monte Carlo (turning, 30° heading error, random mounting),
/// one model at a time (each includes simulating the runs).
pub fn align(runs: usize, json: bool) -> anyhow::Result<()> {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let mut out = Vec::new();
    for model in [1u8, 2, 3] {
        let a = crate::align::AlignArgs {
            models: vec![model],
            scenario: "turning".into(),
            runs,
            heading_error: 30.0,
            mount: "random".into(),
            seed: 1,
            seconds: 1200.0,
            converged_deg: 1.0,
            threads: None,
            json: false,
        };
        let r = crate::align::run(&a)?;
        out.push(AlignBench {
            model,
            runs,
            seconds_simulated_per_run: 1200.0,
            threads,
            wall_seconds: r.wall_seconds,
        });
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        for b in &out {
            println!(
                "align model {}: {} runs x {:.0} s in {:.1} s on {} threads",
                b.model, b.runs, b.seconds_simulated_per_run, b.wall_seconds, b.threads
            );
        }
    }
    Ok(())
}

/// Cost of one USBL update per coupling and filter.
#[derive(Debug, Clone, Serialize)]
pub struct UsblBench {
    pub coupling: auvnav_core::aid::usbl::Coupling,
    pub filter: auvnav_core::aid::usbl::UsblFilter,
    /// States the update runs over (every state with non-zero variance).
    pub states: usize,
    pub updates: usize,
    pub median_us: f64,
    pub p90_us: f64,
    pub max_us: f64,
}

/// `auvnav bench usbl`: the wall time of `Navigator::on_usbl` on the docking scenario, each
/// update timed alone on a copy of the navigator taken just before it (the copy is not timed). An
/// update includes the covariance propagation pending since the last one (at most one
/// `covariance_interval_s`, 50 ms). One thread.
pub fn usbl(seconds: f64, json: bool) -> anyhow::Result<()> {
    use crate::log::LogMessage;
    use crate::sim::StationGeometry;
    use anyhow::bail;
    use auvnav_core::aid::usbl::{Coupling, UsblFilter};
    use auvnav_core::feed::SensorMessage;
    use auvnav_core::navigator::initial_state;
    use auvnav_core::session::{Session, SessionConfig};
    use std::time::Instant;
    let scenario = Scenario::load("docking")?;
    let station =
        StationGeometry::from_scenario(&scenario).context("the docking scenario has no station")?;
    let (messages, _) = crate::sim::simulate_to_vec(&SimConfig {
        scenario: scenario.clone(),
        effects: scenario.effects()?,
        seed: 1,
        duration_s: Some(seconds),
    })?;
    let mut out = Vec::new();
    let cases = [Coupling::Loose, Coupling::Tight]
        .into_iter()
        .flat_map(|c| [UsblFilter::Ukf, UsblFilter::Akf, UsblFilter::Aukf].map(|f| (c, f, false)))
        .chain([(Coupling::Tight, UsblFilter::Aukf, true)]);
    for (coupling, filter, all_states) in cases {
        {
            let mut cfg = crate::usbl::navigation_config(&station, coupling, filter);
            if all_states {
                // Every DVL parameter state switched on as well: all 26 error states.
                cfg.estimate_dvl_mounting = true;
                cfg.estimate_dvl_lever_arm = true;
                cfg.estimate_dvl_time_offset = true;
            }
            // The state is reached through the daemon's feed path; each fix's update is timed on
            // a copy of the navigator as it stands when the fix arrives.
            let mut session = Session::new(&SessionConfig {
                navigation: cfg.clone(),
                ..Default::default()
            });
            let mut times = Vec::new();
            for m in &messages {
                match m {
                    LogMessage::Truth(t) if !session.started() => {
                        let pos = auvnav_core::earth::Geodetic {
                            latitude_rad: t.latitude_rad,
                            longitude_rad: t.longitude_rad,
                            height_m: t.height_m,
                        };
                        let s = initial_state(
                            t.host_time_ns as f64 * 1e-9,
                            pos,
                            t.velocity_ned_m_s,
                            t.euler_rad,
                        );
                        session.start(s, "truth", &mut |_| Ok::<(), anyhow::Error>(()))?;
                    }
                    other if session.started() => {
                        let Some(x) = other.sensor() else { continue };
                        if let (SensorMessage::Usbl(fix), Some(n)) = (&x, session.navigator()) {
                            let mut copy = n.clone();
                            let t0 = Instant::now();
                            std::hint::black_box(copy.on_usbl(std::hint::black_box(fix)));
                            times.push(t0.elapsed().as_secs_f64() * 1e6);
                        }
                        session.feed(&x, &mut |_| Ok::<(), anyhow::Error>(()))?;
                    }
                    _ => {}
                }
            }
            let n = session
                .navigator()
                .context("the simulation produced no truth")?;
            if times.is_empty() {
                bail!("no USBL fix in {seconds} s of the docking scenario");
            }
            let states = (0..auvnav_core::ekf::N)
                .filter(|&i| n.covariance()[(i, i)] > 0.0)
                .count();
            let mut sorted = times.clone();
            sorted.sort_by(f64::total_cmp);
            out.push(UsblBench {
                coupling,
                filter,
                states,
                updates: times.len(),
                median_us: median(&times),
                p90_us: sorted[sorted.len() * 9 / 10],
                max_us: sorted[sorted.len() - 1],
            });
        }
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        for b in &out {
            println!(
                "usbl {:?} {:?}: {} updates over {} states: median {:.1} us, p90 {:.1} us, max {:.1} us",
                b.coupling, b.filter, b.updates, b.states, b.median_us, b.p90_us, b.max_us
            );
        }
    }
    Ok(())
}
