//! `auvnav-ugps` as a real process against a loopback HTTP server that plays a Water Linked
//! Underwater GPS topside: the API's documented responses (`/api/v1/config/receivers/`,
//! `/api/v1/position/acoustic/raw`, `/api/v1/position/master`) carrying the measured G2 dive's
//! first readings (`../shared/data/ugps-g2`), with broken answers between them — a body that is
//! not JSON, a field missing, a field of the wrong type, a range out of bounds, an HTTP 500, a
//! connection closed without an answer, a repeated reading, the topside's "no data" markers and
//! a topside that stops answering for a while. Every reading is published with the dive's
//! values, every fault is counted by its kind, none stops the driver, and it reconnects.

use auvnav_shm_schema::bus::Bus;
use auvnav_shm_schema::{AcousticArrayPoseV1, AcousticRangesV1, ProcessHealthV1, qos, topic};
use auvnav_tests::processes::{Proc, TempDir, binary, unique};
use std::collections::{HashMap, VecDeque};
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::process::Command;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// What the server does for one request.
#[derive(Clone)]
enum Answer {
    Json(String),
    Status500,
    /// Accepts and closes without a byte.
    Hangup,
    /// Stops accepting for this long (the topside unreachable: requests time out).
    Stall(Duration),
}

/// One dive row: the acoustic reading as the API gives it, and what the driver must publish.
struct Reading {
    body: String,
    /// The body with receiver `k`'s distance replaced by `text`.
    distance_at: Vec<String>,
    ranges: [Option<f64>; 4],
    position: Option<[f64; 3]>,
}

/// The dive's acoustic rows from the first one with a valid range: `n` readings that differ
/// from the one before (the API repeats a reading until the next).
fn dive_readings(dir: &std::path::Path, n: usize) -> Vec<Reading> {
    let file = std::fs::read_dir(dir)
        .expect("the dive")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.to_string_lossy().ends_with("_g2_acoustic.csv"))
        .expect("an acoustic log");
    let text = std::fs::read_to_string(file).expect("readable");
    let mut lines = text.lines();
    let head: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| head.iter().position(|h| *h == name).expect(name);
    let mut out: Vec<Reading> = Vec::new();
    let mut last = String::new();
    for line in lines {
        let f: Vec<&str> = line.split(',').collect();
        let get = |name: &str| f[col(name)];
        let valid: Vec<bool> = (0..4).map(|k| get(&format!("valid_r{k}")) == "1").collect();
        if out.is_empty() && !valid.iter().any(|v| *v) {
            continue;
        }
        let key = format!(
            "{}{}{}{}",
            get("position_valid"),
            get("x"),
            get("y"),
            (0..4)
                .map(|k| get(&format!("distance_r{k}")))
                .collect::<String>()
        );
        if key == last {
            continue;
        }
        last = key;
        let list = |p: &str| {
            (0..4)
                .map(|k| get(&format!("{p}_r{k}")))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let position_valid = get("position_valid") == "True";
        let body = format!(
            "{{\"position_valid\": {}, \"receiver_distance\": [{}], \"receiver_nsd\": [{}], \
             \"receiver_rssi\": [{}], \"receiver_valid\": [{}], \"std\": {}, \"x\": {}, \"y\": {}, \"z\": {}}}",
            position_valid,
            list("distance"),
            list("nsd"),
            list("rssi"),
            valid
                .iter()
                .map(|v| v.to_string())
                .collect::<Vec<_>>()
                .join(", "),
            get("std"),
            get("x"),
            get("y"),
            get("z")
        );
        let num = |name: &str| get(name).parse::<f64>().expect(name);
        let distance_at = (0..4)
            .map(|k| {
                let mut d: Vec<String> = (0..4)
                    .map(|i| get(&format!("distance_r{i}")).to_string())
                    .collect();
                d[k] = "1e9".into();
                body.replace(&list("distance"), &d.join(", "))
            })
            .collect();
        out.push(Reading {
            body,
            distance_at,
            ranges: std::array::from_fn(|k| {
                let d = num(&format!("distance_r{k}"));
                (valid[k] && d > 0.0).then_some(d)
            }),
            position: position_valid.then(|| [num("x"), num("y"), num("z")]),
        });
        if out.len() == n {
            break;
        }
    }
    out
}

/// Serves each path's answers in order (the last one again once they run out).
fn serve(listener: TcpListener, script: Arc<Mutex<HashMap<String, VecDeque<Answer>>>>) {
    std::thread::spawn(move || {
        let mut last: HashMap<String, Answer> = HashMap::new();
        for conn in listener.incoming() {
            let Ok(mut c) = conn else { continue };
            let _ = c.set_read_timeout(Some(Duration::from_secs(2)));
            let Some(path) = request_path(&mut c) else {
                continue;
            };
            let answer = {
                let mut s = script.lock().expect("script");
                s.get_mut(&path).and_then(VecDeque::pop_front)
            }
            .or_else(|| last.get(&path).cloned())
            .unwrap_or(Answer::Status500);
            if let Answer::Json(_) = &answer {
                last.insert(path.clone(), answer.clone());
            }
            match answer {
                Answer::Json(body) => {
                    let _ = c.write_all(
                        format!(
                            "HTTP/1.1 200 OK\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
                            body.len()
                        )
                        .as_bytes(),
                    );
                }
                Answer::Status500 => {
                    let _ = c.write_all(
                        b"HTTP/1.1 500 Internal Server Error\r\nContent-Length: 0\r\n\r\n",
                    );
                }
                Answer::Hangup => {}
                Answer::Stall(d) => {
                    std::thread::sleep(d);
                    drop(c);
                    // The requests that queued meanwhile were given up by the driver.
                    let _ = listener.set_nonblocking(true);
                    while listener.accept().is_ok() {}
                    let _ = listener.set_nonblocking(false);
                }
            }
        }
    });
}

fn request_path(c: &mut TcpStream) -> Option<String> {
    let mut buf = Vec::new();
    let mut chunk = [0u8; 1024];
    while !buf.windows(4).any(|w| w == b"\r\n\r\n") {
        let n = c.read(&mut chunk).ok()?;
        if n == 0 {
            return None;
        }
        buf.extend_from_slice(&chunk[..n]);
    }
    let text = String::from_utf8_lossy(&buf);
    let line = text.lines().next()?;
    let mut parts = line.split(' ');
    (parts.next()? == "GET").then_some(())?;
    Some(parts.next()?.to_string())
}

/// Each path's answers: the dive's readings with one fault of each kind between them, and the
/// receiver whose range the out-of-bounds answer replaces.
fn scripted_topside(readings: &[Reading]) -> (HashMap<String, VecDeque<Answer>>, usize) {
    let json = |s: &str| Answer::Json(s.to_string());
    let r = |k: usize| json(&readings[k].body);
    // Faults between the readings; each kind once.
    let no_std = readings[0].body.replace("\"std\": ", "\"sd\": ");
    let text_x = readings[0]
        .body
        .replace("\"x\": ", "\"x\": \"")
        .replace(", \"y\"", "\", \"y\"");
    // The first receiver reading 5 has a valid range on gets a range beyond the schema's bound.
    let far_receiver = (0..4)
        .find(|&i| readings[5].ranges[i].is_some())
        .expect("reading 5 has a range");
    let far = readings[5].distance_at[far_receiver].clone();
    let acoustic = vec![
        r(0),
        r(0), // the API repeats its reading: not published again
        r(1),
        json(&readings[2].body[..40]), // cut short: not JSON
        r(2),
        json(&no_std), // a required field missing
        r(3),
        json(&text_x), // a field of the wrong type
        r(4),
        Answer::Status500,
        Answer::Json(far), // one range out of bounds: the rest published
        Answer::Hangup,    // closed without an answer
        r(6),
        Answer::Stall(Duration::from_millis(800)), // the topside stops answering
        r(7),
        r(8),
        r(9),
        r(10),
        r(11),
    ];
    let master = vec![
        json(
            r#"{"cog": 0, "fix_quality": 2, "hdop": 0.8, "lat": 48.684827928333334, "lon": -123.19206392333334, "numsats": 24, "orientation": 52.5, "sog": 0}"#,
        ),
        json(r#"{"fix_quality": 2, "lat": 48.68482808, "orientation": 53.8}"#), // no lon
        json(
            r#"{"cog": -1, "fix_quality": 0, "hdop": -1, "lat": 0, "lon": 0, "numsats": -1, "orientation": -1, "sog": -1}"#,
        ), // no data at all: nothing published
        json(
            r#"{"cog": 0, "fix_quality": 2, "hdop": 0.7, "lat": 48.684828081666666, "lon": -123.19206343, "numsats": 25, "orientation": -1, "sog": 0}"#,
        ), // position without a heading
    ];
    let receivers = vec![json(
        r#"[{"id": 1, "x": 0.0, "y": -1.5, "z": 3.0}, {"id": 2, "x": 1.5, "y": 0.0, "z": 3.0},
            {"id": 3, "x": 0.0, "y": 1.5, "z": 3.0}, {"id": 4, "x": -1.5, "y": 0.0, "z": 3.0}]"#,
    )];
    let script = HashMap::from([
        (
            "/api/v1/position/acoustic/raw".to_string(),
            VecDeque::from(acoustic),
        ),
        (
            "/api/v1/position/master".to_string(),
            VecDeque::from(master),
        ),
        (
            "/api/v1/config/receivers/".to_string(),
            VecDeque::from(receivers),
        ),
    ]);
    (script, far_receiver)
}

/// The driver's configuration for the loopback topside, fast polls and back-off, checked by
/// the program.
fn checked_config(
    dir: &std::path::Path,
    prefix: &str,
    address: std::net::SocketAddr,
) -> std::path::PathBuf {
    let cfg = dir.join("ugps.toml");
    std::fs::write(
        &cfg,
        format!(
            "prefix = \"{prefix}\"\nurl = \"http://{address}\"\n\
             [poll]\nacoustic_hz = 40.0\nmaster_hz = 10.0\nreceivers_period_s = 600.0\nrequest_timeout_s = 0.2\n\
             [timing]\nreconnect_initial_s = 0.05\nreconnect_max_s = 0.2\nhealth_period_s = 0.05\n"
        ),
    )
    .expect("config");
    let check = Command::new(binary("auvnav-ugps"))
        .args(["--config", &cfg.display().to_string(), "--check-config"])
        .output()
        .expect("check");
    assert!(
        check.status.success(),
        "{}",
        String::from_utf8_lossy(&check.stderr)
    );

    cfg
}

#[test]
fn the_topsides_readings_are_published_and_every_broken_answer_counted() {
    let Some(dir) = auvnav_tests::shared::shared("data/ugps-g2") else {
        return;
    };
    let readings = dive_readings(&dir, 12);
    assert_eq!(readings.len(), 12);
    let (script, far_receiver) = scripted_topside(&readings);
    let script = Arc::new(Mutex::new(script));
    let listener = TcpListener::bind("127.0.0.1:0").expect("loopback listener");
    let address = listener.local_addr().expect("address");
    serve(listener, script.clone());

    let tmp = TempDir::new("ugps");
    let prefix = unique("ugps");
    let cfg = checked_config(tmp.path(), &prefix, address);
    let bus = Bus::new(&unique("ugpstest"), &prefix).expect("bus");
    let mut ranges = bus
        .subscriber::<AcousticRangesV1>(topic::ACOUSTIC_RANGES, qos::SENSOR)
        .expect("ranges");
    let mut poses = bus
        .subscriber::<AcousticArrayPoseV1>(topic::ACOUSTIC_ARRAY_POSE, qos::SENSOR)
        .expect("poses");
    let mut health = bus
        .subscriber::<ProcessHealthV1>(topic::HEALTH, qos::HEALTH)
        .expect("health");
    let err_path = tmp.path().join("ugps.err");
    let err = std::fs::File::create(&err_path).expect("stderr");
    let mut driver = Proc::spawn(
        "ugps",
        Command::new(binary("auvnav-ugps"))
            .arg("--config")
            .arg(&cfg)
            .stderr(err),
    )
    .expect("spawn");

    let (mut got, mut got_poses, mut healths) = (Vec::new(), Vec::new(), Vec::new());
    let deadline = Instant::now() + Duration::from_secs(30);
    let expected = readings.len(); // readings 0–11, 5 with its far range left out
    loop {
        while let Some(m) = ranges.receive().expect("receive") {
            got.push(m);
        }
        while let Some(m) = poses.receive().expect("receive") {
            got_poses.push(m);
        }
        while let Some(h) = health.receive().expect("receive") {
            healths.push(h);
        }
        let drained = script
            .lock()
            .expect("script")
            .values()
            .all(VecDeque::is_empty);
        if got.len() >= expected && drained {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "{} of {expected} readings arrived; driver: {}",
            got.len(),
            std::fs::read_to_string(&err_path).unwrap_or_default()
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    std::thread::sleep(Duration::from_millis(200));
    let status = driver.terminate(Duration::from_secs(10));
    assert!(status.is_some_and(|s| s.success()), "{status:?}");
    std::thread::sleep(Duration::from_millis(50));
    while let Some(h) = health.receive().expect("receive") {
        healths.push(h);
    }
    let log = std::fs::read_to_string(&err_path).unwrap_or_default();

    // Every reading, once, in order, with the dive's values.
    assert_eq!(got.len(), expected, "{log}");
    for (k, (m, want)) in got.iter().zip(&readings).enumerate() {
        for i in 0..4 {
            let want_range = if k == 5 && i == far_receiver {
                None
            } else {
                want.ranges[i]
            };
            assert_eq!(
                m.range_valid(i).then_some(m.range_m[i]),
                want_range,
                "reading {k}, receiver {i}"
            );
        }
        let fix =
            (m.validity & AcousticRangesV1::VALID_POSITION != 0).then_some(m.position_array_m);
        assert_eq!(fix, want.position, "reading {k}");
        assert_ne!(m.validity & AcousticRangesV1::VALID_RECEIVER_POSITIONS, 0);
        assert_eq!(m.receiver_position_m[3..6], [1.5, 0.0, 3.0]);
        assert_eq!(m.sequence, k as u64, "numbered by the publisher");
    }
    assert!(
        got.windows(2)
            .all(|w| w[0].host_time_ns < w[1].host_time_ns)
    );
    // The poses: the first complete, the one without lon refused, the empty one not published,
    // the last with its position only.
    assert_eq!(got_poses.len(), 2, "{log}");
    assert_eq!(
        got_poses[0].validity,
        AcousticArrayPoseV1::VALID_POSITION | AcousticArrayPoseV1::VALID_HEADING
    );
    assert!((got_poses[0].euler_rad[2] - 52.5f64.to_radians()).abs() < 1e-12);
    assert_eq!(got_poses[1].validity, AcousticArrayPoseV1::VALID_POSITION);

    let last = healths
        .iter()
        .rev()
        .find(|h| h.name() == "ugps")
        .expect("health");
    assert_eq!(last.frames, expected as u64 + 2, "{last:?}");
    // Refused: not JSON, a field missing (acoustic and master), a wrong field, the hang-up (not
    // an HTTP answer); out of range: the 1e9 m range.
    assert_eq!(last.invalid, 6, "{last:?}\n{log}");
    assert_eq!(last.drops, 1, "the HTTP 500: {last:?}");
    assert!(last.timeouts >= 1, "the stall: {last:?}");
    assert!(last.reconnects >= 1, "{last:?}");
    for says in [
        "does not answer",
        "answers again",
        "bodies not JSON",
        "1 values out of range",
        "1 HTTP errors",
    ] {
        assert!(log.contains(says), "the log says {says:?}:\n{log}");
    }
}
