//! `auvnav bench decode`: the protocol decoders' throughput, from memory and through a pseudo-terminal.

#[allow(unused_imports)]
use super::*;

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
pub(crate) fn time_decoder<D: auvnav_drivers::framing::StreamDecoder>(
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
/// variable leader + bottom track, Water Linked `wrz`, Nortek bottom track, KVH format A, Xsens MTData2 with
/// counter/time/status/acceleration/rate/delta-v/delta-q, SeaTrac fixes with range, USBL and
/// position) fed in 4 KiB reads, as a driver reads a serial port.
// Long on purpose: one benchmark per protocol in the same form (a synthetic stream, timed 4 KiB
// reads); the table of protocols is the function.
pub fn decode(repeat: usize, pty_seconds: f64, json: bool) -> anyhow::Result<()> {
    use auvnav_drivers::{kvh, nortek, pd0, seatrac, wldvl, xsens};
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
                reference_layer_velocity_m_s: [None; 4],
                reference_layer_percent_good: [0; 4],
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
        stream.extend(auvnav_drivers::to_device::nortek_from_dvl(
            &auvnav_shm_schema::DvlVelocityV1 {
                device_time_ns: 1_795_000_000_000_000_000 + u64::from(k) * 100_000_000,
                velocity_dvl_m_s: [1.5, 0.01 * f64::from(k % 7), -0.02],
                altitude_m: 12.3,
                figure_of_merit_m_s: 0.004,
                sound_speed_m_s: 1500.0,
                validity: auvnav_shm_schema::DvlVelocityV1::VALID_VELOCITY
                    | auvnav_shm_schema::DvlVelocityV1::VALID_ALTITUDE
                    | auvnav_shm_schema::DvlVelocityV1::VALID_FOM
                    | auvnav_shm_schema::DvlVelocityV1::VALID_SOUND_SPEED
                    | auvnav_shm_schema::DvlVelocityV1::VALID_DEVICE_TIME,
                ..Default::default()
            },
        ));
    }
    results.push(time_decoder(
        "nortek",
        &stream,
        repeat,
        nortek::NortekDecoder::new,
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
        crate::json::print(&serde_json::json!({ "throughput": results, "pty_latency": latency }))?;
    } else {
        for l in &latency {
            println!(
                "pty {} at {} Hz: {}/{} frames; write->stamp p50 {:+.0} us p99 {:+.0} us; stamp->subscriber p50 {:.0} us p99 {:.0} us; total p50 {:.0} us p99 {:.0} us max {:.0} us",
                l.protocol,
                l.rate_hz,
                l.frames_received,
                l.frames_written,
                l.write_to_stamp_us.p50,
                l.write_to_stamp_us.p99,
                l.stamp_to_subscriber_us.p50,
                l.stamp_to_subscriber_us.p99,
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
