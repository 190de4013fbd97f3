//! Latency: a frame on a pseudo-terminal to the bus (`pty_latency`), and to the navigation solution through real driver, daemon and recorder processes (`auvnav bench e2e`).
//!
//! Long on purpose: both latency benchmarks share the pseudo-terminal writers, the frame makers and
//! the statistics.

#[allow(unused_imports)]
use super::*;

/// Latency through a real pseudo-terminal and a real driver process at one frame rate.
#[derive(Debug, Clone, Serialize)]
pub struct PtyLatency {
    pub protocol: String,
    pub rate_hz: f64,
    pub frames_written: u64,
    pub frames_received: u64,
    /// Write call of the frame → its time stamp (µs): the first byte's estimated arrival,
    /// through the model of the device's clock. A pseudo-terminal carries a frame written whole
    /// at no line rate, so a stamp placed back at 921 600 baud can come before the write.
    pub write_to_stamp_us: Percentiles,
    /// The message's time stamp → received by a subscriber in another process: the terminal,
    /// the driver's wake-up, decode, publish and the shared-memory hop with event wake-up (µs).
    pub stamp_to_subscriber_us: Percentiles,
    /// Write call → message received by the subscriber: an upper bound of byte arrival →
    /// publish (µs).
    pub total_us: Percentiles,
}

pub use crate::percentiles::{Percentiles, percentiles};

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

    let driver = crate::process::sibling("auvnav-imu")?;
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
            let wake = bus.listener(topic::IMU)?;
            ready.store(true, Ordering::SeqCst);
            let mut got = Vec::new();
            while !done.load(Ordering::SeqCst) {
                auvnav_shm_schema::bus::wait(&wake, Duration::from_millis(20))?;
                while let Some(m) = sub.receive()? {
                    let index = (m.device_time_ns as f64 * 1e-9 * rate_hz).round() as u64;
                    got.push((index, m.host_time_ns, monotonic_ns()));
                }
            }
            Ok(got)
        })
    };
    while !ready.load(Ordering::SeqCst) {
        std::thread::sleep(Duration::from_millis(5));
    }
    let mut child = crate::process::ChildProcess::spawn(
        "auvnav-imu",
        std::process::Command::new(&driver)
            .arg("--config")
            .arg(&cfg)
            .stderr(std::process::Stdio::null()),
    )?;
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
            // The device's clock: microseconds since the first frame.
            timestamp_us: Some((i as f64 * 1e6 / rate_hz).round() as u32),
        });
        written[i as usize] = monotonic_ns();
        master.write_all(&frame)?;
    }
    std::thread::sleep(Duration::from_millis(300));
    child.stop(Duration::from_secs(10));
    done.store(true, Ordering::SeqCst);
    let got = sub_thread
        .join()
        .map_err(|_| anyhow::anyhow!("subscriber thread panicked"))??;
    drop(slave);
    let _ = std::fs::remove_dir_all(&dir);
    let (mut pty, mut hop, mut total) = (Vec::new(), Vec::new(), Vec::new());
    let us = |a: u64, b: u64| (b as f64 - a as f64) * 1e-3;
    for &(idx, stamp_ns, recv_ns) in &got {
        let Some(&w) = written.get(idx as usize) else {
            continue;
        };
        pty.push(us(w, stamp_ns));
        hop.push(us(stamp_ns, recv_ns));
        total.push(us(w, recv_ns));
    }
    Ok(PtyLatency {
        protocol: "kvh1750".into(),
        rate_hz,
        frames_written: n,
        frames_received: got.len() as u64,
        write_to_stamp_us: percentiles(pty),
        stamp_to_subscriber_us: percentiles(hop),
        total_us: percentiles(total),
    })
}

/// End-to-end latency of the on-board chain at one IMU rate.
#[derive(Debug, Clone, Serialize)]
pub struct E2eLatency {
    pub imu_rate_hz: f64,
    pub duration_s: f64,
    /// How the processes were scheduled (`--scheduling`; SCHED_FIFO where permitted).
    pub scheduling: String,
    /// The host's floor: one thread woken through a socket by another at the IMU rate, under
    /// the same scheduling, measured after the chain (µs). The chain has four such wake-ups
    /// (terminal → driver, driver → daemon, daemon → subscriber, and the writer's own timer).
    pub wake_up_floor_us: Percentiles,
    pub imu_frames_written: u64,
    pub solutions_received: u64,
    /// IMU frame written to its pseudo-terminal → navigation solution received by a subscriber
    /// (µs): terminal, driver, shared memory, daemon (strapdown + filter), shared memory.
    pub frame_to_solution_us: Percentiles,
    /// IPC only: the IMU driver's read return (from its stage times) → the IMU message received
    /// by a subscriber in another process (µs): decode, publish and the shared-memory hop with
    /// event wake-up.
    pub driver_to_subscriber_us: Percentiles,
    /// Where the time goes, per solution (µs): the stages of `frame_to_solution_us`, from the
    /// stage times the IMU driver and the daemon write (their `stage_times_csv`). Percentiles of
    /// stages do not add up to the total's (only the per-solution values do).
    pub stages_us: Vec<StageLatency>,
    /// Solutions whose every stage time was found (the IMU driver's and the daemon's rows
    /// joined on the read time stamp); the stage percentiles are over these.
    pub solutions_with_stages: u64,
    /// CPU use of the daemon and of the recorder over the run (% of one core).
    pub daemon_cpu_percent: f64,
    pub recorder_cpu_percent: f64,
    pub dvl_frames_written: u64,
    pub usbl_frames_written: u64,
    /// The live view's load when it ran beside the chain (`auvnav bench bridge`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub live_view: Option<LiveViewLoad>,
    /// The vehicle's outputs when they ran beside the chain (`auvnav bench e2e --outputs`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub outputs: Option<OutputsLoad>,
}

/// The outputs a vehicle runs beside the chain: `auvnav-mavlink` (ODOMETRY at 10 Hz to a UDP
/// socket of this benchmark) and `auvnav-bridge` (the solution exported at 10 Hz, and the ROS 2
/// topics: odometry and fix at 50 Hz, the IMU at its rate, DVL, diagnostics).
#[derive(Debug, Clone, Serialize)]
pub struct OutputsLoad {
    /// MAVLink datagrams received from `auvnav-mavlink` during the run.
    pub mavlink_datagrams: u64,
    /// CPU of the two processes over the run (% of one core).
    pub mavlink_cpu_percent: f64,
    pub bridge_cpu_percent: f64,
}

/// The live view (`auvnav-live`, no rate limit) with one WebSocket client subscribed to every
/// channel, beside the on-board chain.
#[derive(Debug, Clone, Serialize)]
pub struct LiveViewLoad {
    /// Channels the client subscribed to.
    pub channels: usize,
    /// Messages the client received during the run.
    pub messages_received: u64,
    /// Solutions among them.
    pub solutions_received: u64,
    /// CPU of the live view process over the run (% of one core).
    pub live_view_cpu_percent: f64,
}

/// One stage of the chain and its latency over the run.
#[derive(Debug, Clone, Serialize)]
pub struct StageLatency {
    pub stage: &'static str,
    pub what: &'static str,
    #[serde(flatten)]
    pub us: Percentiles,
}

/// A row of the IMU driver's stage times (host clock, ns).
#[derive(Debug, Clone, Copy, serde::Deserialize)]
struct DriverStages {
    /// The message's time stamp (the daemon's and the solution's key).
    stamp_ns: u64,
    read_ns: u64,
    decoded_ns: u64,
    published_ns: u64,
}

/// A row of the daemon's stage times (host clock, ns).
#[derive(Debug, Clone, Copy, serde::Deserialize)]
struct DaemonStages {
    imu_host_time_ns: u64,
    woke_ns: u64,
    received_ns: u64,
    computed_ns: u64,
    published_ns: u64,
}

fn read_stage_rows<T: serde::de::DeserializeOwned>(
    path: &std::path::Path,
) -> anyhow::Result<Vec<T>> {
    let mut r =
        csv::Reader::from_path(path).with_context(|| format!("reading {}", path.display()))?;
    r.deserialize()
        .collect::<Result<Vec<T>, _>>()
        .with_context(|| format!("reading {}", path.display()))
}

/// The stages of each solution: frame written (`written`, by frame index = solution sequence)
/// → driver read → decoded → published → daemon woke → topics drained → solution published →
/// received by the subscriber (`sols`: sequence, the IMU message's time stamp, receive time).
fn stage_latencies(
    written: &[u64],
    sols: &[(u64, u64, u64)],
    driver: &[DriverStages],
    daemon: &[DaemonStages],
) -> (Vec<StageLatency>, u64) {
    let driver: std::collections::HashMap<u64, DriverStages> =
        driver.iter().map(|r| (r.stamp_ns, *r)).collect();
    let daemon: std::collections::HashMap<u64, DaemonStages> =
        daemon.iter().map(|r| (r.imu_host_time_ns, *r)).collect();
    const STAGES: [(&str, &str); 8] = [
        (
            "pty",
            "frame written to the pseudo-terminal → the driver's read returned",
        ),
        ("decode", "driver: read returned → message decoded"),
        (
            "publish",
            "driver: decoded → published and listeners notified",
        ),
        (
            "wake_up",
            "driver published → the daemon's wait returned (negative: the daemon was already awake)",
        ),
        (
            "drain",
            "daemon: wait returned → every sensor topic drained",
        ),
        (
            "navigate",
            "daemon: topics drained → solution computed (strapdown, filter)",
        ),
        (
            "publish_solution",
            "daemon: solution computed → published and listeners notified",
        ),
        (
            "solution_hop",
            "daemon published → solution received by a subscriber in another process",
        ),
    ];
    let mut values: Vec<Vec<f64>> = vec![Vec::new(); STAGES.len()];
    let mut joined = 0;
    let us = |a: u64, b: u64| (b as f64 - a as f64) * 1e-3;
    for &(seq, stamp, recv) in sols {
        let (Some(&w), Some(d), Some(m)) = (
            written.get(seq as usize),
            driver.get(&stamp),
            daemon.get(&stamp),
        ) else {
            continue;
        };
        let times = [
            w,
            d.read_ns,
            d.decoded_ns,
            d.published_ns,
            m.woke_ns,
            m.received_ns,
            m.computed_ns,
            m.published_ns,
            recv,
        ];
        for (k, v) in values.iter_mut().enumerate() {
            v.push(us(times[k], times[k + 1]));
        }
        joined += 1;
    }
    let stages = STAGES
        .iter()
        .zip(values)
        .map(|(&(stage, what), v)| StageLatency {
            stage,
            what,
            us: percentiles(v),
        })
        .collect();
    (stages, joined)
}

/// CPU time (s) a process has used so far (`/proc/PID/stat` utime + stime).
pub(crate) fn cpu_seconds(pid: u32) -> Option<f64> {
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
// Long on purpose: starts the chain of real processes, times it and tears it down; the processes
// and pseudo-terminals it owns are its locals, released in order on every path.
pub fn e2e(
    rate_hz: f64,
    seconds: f64,
    live_view: bool,
    outputs: bool,
    scheduling: crate::process::Scheduling,
) -> anyhow::Result<E2eLatency> {
    use auvnav_drivers::clock::monotonic_ns;
    use auvnav_drivers::to_device as enc;
    use auvnav_shm_schema::bus::Bus;
    use auvnav_shm_schema::{DvlVelocityV1, ImuSampleV1, NavSolutionV1, UsblFixV1, qos, topic};
    use serialport::SerialPort;
    use std::io::Write;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::time::{Duration, Instant};

    // As the units run them, where SCHED_FIFO is permitted: drivers 60, daemon 50; this
    // process's writer (the devices) at 70, so that frames go out on time.
    let fifo = scheduling == crate::process::Scheduling::Unit
        && crate::process::realtime_permitted().is_ok()
        && crate::process::schedule_this_thread(Some(70)).is_ok();
    let scheduled = if fifo {
        "as the units: drivers SCHED_FIFO 60, daemon 50, the frame writer 70"
    } else if scheduling == crate::process::Scheduling::Unit {
        "normal (SCHED_FIFO not permitted)"
    } else {
        "normal"
    };
    let priority = |p: u8| fifo.then_some(p);
    let tag = format!("benche2e{}r{}", std::process::id(), rate_hz as u64);
    let dir = std::env::temp_dir().join(&tag);
    std::fs::create_dir_all(&dir)?;
    let imu_stages = dir.join("imu-stages.csv");
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
        let stages = if class == "imu" {
            imu_stages.display().to_string()
        } else {
            String::new()
        };
        std::fs::write(
            &p,
            format!(
                "prefix = \"{tag}\"\nprotocol = \"{protocol}\"\nstage_times_csv = \"{stages}\"\n[serial]\nport = \"{port}\"\nbaud = 921600\n\
                 [settings.kvh]\nincrements = false\ndegrees = false\nrate_hz = {rate_hz}\ntemperature_centi = false\n"
            ),
        )?;
        Ok(p)
    };
    let imu_cfg = driver_cfg("imu", "kvh1750", &ports[0].2)?;
    let dvl_cfg = driver_cfg("dvl", "wldvl", &ports[1].2)?;
    let usbl_cfg = driver_cfg("usbl", "seatrac", &ports[2].2)?;
    let daemon_cfg = dir.join("auvnavd.toml");
    let daemon_stages = dir.join("auvnavd-stages.csv");
    let daemon = auvnav_core::config::DaemonConfig {
        prefix: tag.clone(),
        output: auvnav_core::config::OutputConfig {
            stage_times_csv: daemon_stages.display().to_string(),
            ..Default::default()
        },
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
        // As deployed: a checkpoint every 2 s (written by the daemon's own thread).
        checkpoint: auvnav_core::config::CheckpointConfig {
            path: dir.join("auvnavd.checkpoint.json").display().to_string(),
            ..Default::default()
        },
        ..Default::default()
    };
    std::fs::write(&daemon_cfg, daemon.to_toml()?)?;
    let done = std::sync::Arc::new(AtomicBool::new(false));
    let ready = std::sync::Arc::new(AtomicBool::new(false));
    type Seen = (Vec<(u64, u64, u64)>, Vec<(u64, u64)>);
    let watcher = {
        let (done, ready, tag) = (done.clone(), ready.clone(), tag.clone());
        std::thread::spawn(move || -> anyhow::Result<Seen> {
            // A consumer of the solution, as a vehicle's outputs are: the normal scheduler.
            if fifo {
                let _ = crate::process::schedule_this_thread(None);
            }
            let bus = Bus::new(&format!("{tag}sub"), &tag)?;
            let mut sol = bus.subscriber::<NavSolutionV1>(topic::NAV_SOLUTION, qos::NAVIGATION)?;
            let wake = bus.listener(topic::NAV_SOLUTION)?;
            let mut imu = bus.subscriber::<ImuSampleV1>(topic::IMU, qos::SENSOR)?;
            ready.store(true, Ordering::SeqCst);
            let (mut sols, mut imus) = (Vec::new(), Vec::new());
            while !done.load(Ordering::SeqCst) {
                auvnav_shm_schema::bus::wait(&wake, Duration::from_millis(20))?;
                while let Some(m) = sol.receive()? {
                    sols.push((m.sequence, m.host_time_ns, monotonic_ns()));
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
    let spawn = |name: &str, args: &[&std::ffi::OsStr]| {
        let p = match name {
            "auvnavd" => priority(50),
            "auvnav-imu" | "auvnav-dvl" | "auvnav-usbl" => priority(60),
            _ => None,
        };
        crate::process::ChildProcess::spawn(
            name,
            crate::process::scheduled_command(&crate::process::sibling(name)?, p)
                .args(args)
                .stdout(std::process::Stdio::null())
                .stderr(std::process::Stdio::null()),
        )
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
    let live_done = std::sync::Arc::new(AtomicBool::new(false));
    let mut live = if live_view {
        let port = std::net::TcpListener::bind("127.0.0.1:0")?
            .local_addr()?
            .port()
            .to_string();
        let process = spawn(
            "auvnav-live",
            &[
                "--prefix".as_ref(),
                tag.as_ref(),
                "--port".as_ref(),
                port.as_ref(),
            ],
        )?;
        Some((
            process,
            live_view_client(format!("127.0.0.1:{port}"), live_done.clone()),
        ))
    } else {
        None
    };
    // The vehicle's outputs: MAVLink to a UDP socket counted here, the bridge with ROS 2.
    let outputs_done = std::sync::Arc::new(AtomicBool::new(false));
    let mut outputs = if outputs {
        let socket = std::net::UdpSocket::bind("127.0.0.1:0")?;
        socket.set_read_timeout(Some(Duration::from_millis(50)))?;
        let udp_port = socket.local_addr()?.port();
        let counter = {
            let done = outputs_done.clone();
            std::thread::spawn(move || {
                let mut buf = [0u8; 512];
                let mut n = 0u64;
                while !done.load(Ordering::SeqCst) {
                    if socket.recv(&mut buf).is_ok() {
                        n += 1;
                    }
                }
                n
            })
        };
        let mavlink_cfg = dir.join("mavlink.toml");
        std::fs::write(
            &mavlink_cfg,
            format!(
                "prefix = \"{tag}\"\naddress = \"udpout:127.0.0.1:{udp_port}\"\nrate_hz = 10.0\n"
            ),
        )?;
        let zenoh_port = std::net::TcpListener::bind("127.0.0.1:0")?
            .local_addr()?
            .port();
        let bridge_cfg = dir.join("bridge.toml");
        std::fs::write(
            &bridge_cfg,
            format!(
                "prefix = \"{tag}\"\nname = \"bridge\"\n[zenoh]\nlisten = [\"tcp/127.0.0.1:{zenoh_port}\"]\n\
                 [[export]]\ntopics = \"nav/solution\"\nkey_prefix = \"bench\"\nmax_rate_hz = 10.0\n\
                 [ros2]\nsolution_rate_hz = 50.0\n"
            ),
        )?;
        let mavlink = spawn(
            "auvnav-mavlink",
            &["--config".as_ref(), mavlink_cfg.as_os_str()],
        )?;
        let bridge = spawn(
            "auvnav-bridge",
            &["--config".as_ref(), bridge_cfg.as_os_str()],
        )?;
        Some((mavlink, bridge, counter))
    } else {
        None
    };
    std::thread::sleep(Duration::from_millis(1500));
    let outputs_pids = outputs.as_ref().map(|(m, b, _)| (m.pid(), b.pid()));
    let outputs_cpu0 = outputs_pids.map(|(m, b)| (cpu_seconds(m), cpu_seconds(b)));
    let (recorder_pid, daemon_pid) = (children[0].pid(), children[1].pid());
    let live_pid = live.as_ref().map(|(p, _)| p.pid());
    let cpu0 = (cpu_seconds(daemon_pid), cpu_seconds(recorder_pid));
    let live_cpu0 = live_pid.and_then(cpu_seconds);
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
        let cfg = auvnav_drivers::to_schema::KvhConfig {
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
    let live_cpu1 = live_pid.and_then(cpu_seconds);
    let outputs_cpu1 = outputs_pids.map(|(m, b)| (cpu_seconds(m), cpu_seconds(b)));
    std::thread::sleep(Duration::from_millis(300));
    outputs_done.store(true, Ordering::SeqCst);
    let outputs_counts = match outputs.as_mut() {
        Some((mavlink, bridge, counter)) => {
            mavlink.stop(Duration::from_secs(10));
            bridge.stop(Duration::from_secs(10));
            let n = std::mem::replace(counter, std::thread::spawn(|| 0))
                .join()
                .map_err(|_| anyhow::anyhow!("UDP counter thread panicked"))?;
            Some(n)
        }
        None => None,
    };
    live_done.store(true, Ordering::SeqCst);
    let live_load = match live.as_mut() {
        Some((process, client)) => {
            let counts = std::mem::replace(client, std::thread::spawn(|| Ok((0, 0, 0))))
                .join()
                .map_err(|_| anyhow::anyhow!("live view client thread panicked"))??;
            process.stop(Duration::from_secs(10));
            Some(counts)
        }
        None => None,
    };
    for c in children.iter_mut().rev() {
        c.stop(Duration::from_secs(10));
    }
    done.store(true, Ordering::SeqCst);
    let (sols, imus) = watcher
        .join()
        .map_err(|_| anyhow::anyhow!("subscriber thread panicked"))??;
    for p in &mut ports {
        let _ = p.0.set_timeout(Duration::from_millis(1));
    }
    drop(ports);
    let driver_rows: Vec<DriverStages> = read_stage_rows(&imu_stages)?;
    let (stages, solutions_with_stages) = stage_latencies(
        &written,
        &sols,
        &driver_rows,
        &read_stage_rows(&daemon_stages)?,
    );
    let _ = std::fs::remove_dir_all(&dir);
    // Bus sequence k = the k-th solution = IMU frame k (the first frame starts the session).
    let total: Vec<f64> = sols
        .iter()
        .filter_map(|(seq, _, recv)| {
            written
                .get(*seq as usize)
                .map(|w| recv.saturating_sub(*w) as f64 * 1e-3)
        })
        .collect();
    // The driver's read return of each IMU message, found by its time stamp.
    let read_of: std::collections::HashMap<u64, u64> = driver_rows
        .iter()
        .map(|r| (r.stamp_ns, r.read_ns))
        .collect();
    let hop: Vec<f64> = imus
        .iter()
        .filter_map(|(stamp, recv)| {
            read_of
                .get(stamp)
                .map(|read| (*recv as f64 - *read as f64) * 1e-3)
        })
        .collect();
    let cpu = |a: Option<f64>, b: Option<f64>| match (a, b) {
        (Some(a), Some(b)) if wall > 0.0 => 100.0 * (b - a) / wall,
        _ => f64::NAN,
    };
    let wake_up_floor_us = super::wake_up_floor(rate_hz, seconds.min(10.0), priority(60))?;
    if fifo {
        let _ = crate::process::schedule_this_thread(None);
    }
    Ok(E2eLatency {
        imu_rate_hz: rate_hz,
        duration_s: seconds,
        scheduling: scheduled.to_string(),
        wake_up_floor_us,
        imu_frames_written: n,
        solutions_received: sols.len() as u64,
        frame_to_solution_us: percentiles(total),
        driver_to_subscriber_us: percentiles(hop),
        stages_us: stages,
        solutions_with_stages,
        daemon_cpu_percent: cpu(cpu0.0, cpu1.0),
        recorder_cpu_percent: cpu(cpu0.1, cpu1.1),
        dvl_frames_written: dvl_n,
        usbl_frames_written: usbl_n,
        live_view: live_load.map(|(channels, messages, solutions)| LiveViewLoad {
            channels,
            messages_received: messages,
            solutions_received: solutions,
            live_view_cpu_percent: cpu(live_cpu0, live_cpu1),
        }),
        outputs: outputs_counts.map(|datagrams| {
            let (a, b) = (
                outputs_cpu0.unwrap_or_default(),
                outputs_cpu1.unwrap_or_default(),
            );
            OutputsLoad {
                mavlink_datagrams: datagrams,
                mavlink_cpu_percent: cpu(a.0, b.0),
                bridge_cpu_percent: cpu(a.1, b.1),
            }
        }),
    })
}

/// A WebSocket client of the live view on its own thread: subscribes to every channel and
/// counts what arrives until `done`; returns (channels, messages, solutions).
fn live_view_client(
    addr: String,
    done: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> std::thread::JoinHandle<anyhow::Result<(usize, u64, u64)>> {
    use auvnav_bridge::live_client::LiveClient;
    use auvnav_shm_schema::topic;
    use std::sync::atomic::Ordering;
    use std::time::Duration;
    std::thread::spawn(move || {
        let mut c = LiveClient::connect_retrying(&addr, Duration::from_secs(20))?;
        c.wait_for_channels(&[topic::NAV_SOLUTION, topic::IMU], Duration::from_secs(10))?;
        let topics: Vec<String> = c.channels.keys().cloned().collect();
        c.subscribe(&topics.iter().map(String::as_str).collect::<Vec<_>>())?;
        c.set_read_timeout(Duration::from_millis(100))?;
        let (mut messages, mut solutions) = (0u64, 0u64);
        while !done.load(Ordering::SeqCst) {
            if let Some(m) = c.read()? {
                messages += 1;
                solutions += u64::from(m.topic == topic::NAV_SOLUTION);
            }
        }
        c.close();
        Ok((topics.len(), messages, solutions))
    })
}

/// `auvnav bench e2e`.
pub fn e2e_bench(
    seconds: f64,
    outputs: bool,
    scheduling: crate::process::Scheduling,
    json: bool,
) -> anyhow::Result<()> {
    let mut results = Vec::new();
    for rate in [200.0, 1000.0] {
        results.push(e2e(rate, seconds, false, outputs, scheduling)?);
    }
    if json {
        crate::json::print(&results)?;
    } else {
        for r in &results {
            println!(
                "e2e at {} Hz IMU (+ DVL 5 Hz, USBL 1 Hz, recorder), scheduling {}: {}/{} solutions; frame -> solution p50 {:.0} us, p99 {:.0} us, max {:.0} us; driver -> subscriber p50 {:.0} us, p99 {:.0} us; CPU daemon {:.1} %, recorder {:.1} %; the host's wake-up floor p50 {:.0} us, p99 {:.0} us",
                r.imu_rate_hz,
                r.scheduling,
                r.solutions_received,
                r.imu_frames_written,
                r.frame_to_solution_us.p50,
                r.frame_to_solution_us.p99,
                r.frame_to_solution_us.max,
                r.driver_to_subscriber_us.p50,
                r.driver_to_subscriber_us.p99,
                r.daemon_cpu_percent,
                r.recorder_cpu_percent,
                r.wake_up_floor_us.p50,
                r.wake_up_floor_us.p99,
            );
            if let Some(o) = &r.outputs {
                println!(
                    "  with the outputs: auvnav-mavlink {:.1} % CPU ({} datagrams), auvnav-bridge (export + ROS 2) {:.1} % CPU",
                    o.mavlink_cpu_percent, o.mavlink_datagrams, o.bridge_cpu_percent
                );
            }
            for s in &r.stages_us {
                println!(
                    "  {:<16} p50 {:>6.1} us  p99 {:>7.1} us  max {:>7.0} us  ({})",
                    s.stage, s.us.p50, s.us.p99, s.us.max, s.what
                );
            }
        }
    }
    Ok(())
}
