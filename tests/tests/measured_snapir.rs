//! The navigation core on measured data: the 13 segments of the Snapir AUV data set in
//! ../shared/data/snapir-auv, imported and replayed with the default configuration (no
//! per-segment tuning). Outside CI the test is skipped with a message when the data is absent;
//! under CI (`CI=true`) its absence is a failure.

use auvnav_tools::import::{TimeBase, snapir_messages};
use auvnav_tools::replay::{Replay, ReplayConfig};
use std::path::PathBuf;

fn data_dir() -> Option<PathBuf> {
    auvnav_tests::measured_data("snapir-auv", "imu_01.csv")
}

#[test]
fn all_segments_replay_within_the_accuracy_target() {
    let Some(dir) = data_dir() else { return };
    let mut end_per_distance = Vec::new();
    for segment in 1..=13 {
        let (messages, summary) =
            snapir_messages(&dir, segment, TimeBase::Nominal, true).expect("import");
        assert_eq!(summary.imu.malformed + summary.dvl.malformed, 0);
        let al = summary.alignment.expect("aligned");
        // The gyro and the reference agree to the Earth rate (0.004 deg/s) once the clocks are
        // aligned; the offsets in this data set are about half a second.
        assert!(
            al.residual_deg < 0.02 && al.offset_s.abs() < 1.0,
            "segment {segment}: {al:?}"
        );
        let mut replay = Replay::new(&ReplayConfig::default(), 100.0);
        for (_, m) in &messages {
            replay.process(m, &mut |_| Ok(())).expect("replay");
        }
        replay.finish(&mut |_| Ok(())).expect("replay");
        let acc = replay.accuracy().expect("truth channel");
        let ratio = 100.0 * acc.horizontal_error_final_m / acc.distance_travelled_m;
        eprintln!(
            "segment {segment:2}: end {:6.2} m over {:4.0} m = {ratio:.3} %, heading RMS {:.3} deg, clock offset {:+.2} s",
            acc.horizontal_error_final_m,
            acc.distance_travelled_m,
            acc.heading_error_rms_deg,
            al.offset_s
        );
        assert!(acc.distance_travelled_m > 600.0, "segment {segment}");
        // No segment may diverge (before the DVL covariance re-opening, four did, by km).
        assert!(ratio < 5.0, "segment {segment}: {ratio} %");
        end_per_distance.push(ratio);
    }
    end_per_distance.sort_by(f64::total_cmp);
    let median = end_per_distance[end_per_distance.len() / 2];
    eprintln!("median end error/distance {median:.3} %");
    assert!(median <= 0.5, "median end error/distance {median} %");
}

#[test]
fn the_reference_clock_offset_is_found_where_it_was_put() {
    // Stamp segment 12's reference 0.3 s later (file time base, so the stamps are kept): the
    // estimated offset moves by the same amount.
    let Some(dir) = data_dir() else { return };
    let tmp = std::env::temp_dir().join(format!("auvnav-snapir-shift-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).expect("tmp");
    for kind in ["imu", "dvl"] {
        std::fs::copy(
            dir.join(format!("{kind}_12.csv")),
            tmp.join(format!("{kind}_12.csv")),
        )
        .expect("copy");
    }
    let text = std::fs::read_to_string(dir.join("ref_12.csv")).expect("ref");
    let mut lines = text.lines();
    let mut shifted = format!("{}\n", lines.next().expect("header"));
    for line in lines {
        let (t, rest) = line.split_once(',').expect("row");
        let t: f64 = t.parse().expect("time");
        shifted.push_str(&format!("{},{rest}\n", t + 0.3));
    }
    std::fs::write(tmp.join("ref_12.csv"), shifted).expect("write");
    let (_, base) = snapir_messages(&dir, 12, TimeBase::File, true).expect("import");
    let (_, moved) = snapir_messages(&tmp, 12, TimeBase::File, true).expect("import");
    let _ = std::fs::remove_dir_all(&tmp);
    let (b, m) = (base.alignment.expect("a"), moved.alignment.expect("a"));
    assert!(
        ((b.offset_s - m.offset_s) - 0.3).abs() <= 0.011,
        "{b:?} -> {m:?}"
    );
}
