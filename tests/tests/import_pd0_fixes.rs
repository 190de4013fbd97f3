//! `auvnav import pd0 --fixes`: a PD0 recording without GPS of its own (the Ocean Surveyor file,
//! bottom track in beam coordinates) gets position fixes logged elsewhere, written as GNSS fixes
//! in time order; bad lines and fixes outside the recording are counted, and without any fix the
//! import says why it has nothing to compare with.

use auvnav_log::{LogMessage, LogReader};
use auvnav_shm_schema::DvlVelocityV1;
use auvnav_tests::processes::{TempDir, binary};
use std::process::Command;

#[test]
fn fixes_logged_elsewhere_become_gnss_fixes_of_the_imported_log() {
    let Some(dir) = auvnav_tests::measured_data("rdi-pd0", "raw/vmdas02_os.ENR") else {
        return;
    };
    let raw = dir.join("raw/vmdas02_os.ENR");
    let tmp = TempDir::new("pd0fixes");
    let fixes = tmp.path().join("fixes.csv");
    std::fs::write(
        &fixes,
        "time_s,latitude_deg,longitude_deg,depth_m,std_m\n\
         10.0,21.30,-157.90,0.0,3.0\n\
         this line is not a fix\n\
         600.0,21.31,-157.91,0.0,3.0\n\
         99999.0,21.32,-157.92,0.0,3.0\n",
    )
    .expect("fix file");
    let out = tmp.path().join("os.mcap");
    let run = |with_fixes: bool| {
        let mut c = Command::new(binary("auvnav"));
        c.arg("import")
            .arg("pd0")
            .arg(&raw)
            .arg("--out")
            .arg(&out)
            .arg("--json");
        if with_fixes {
            c.arg("--fixes").arg(&fixes);
        }
        c.output().expect("running auvnav import pd0")
    };
    let without = run(false);
    assert!(!without.status.success());
    let err = String::from_utf8_lossy(&without.stderr);
    assert!(
        err.contains("no ensemble has GPS") && err.contains("--fixes"),
        "{err}"
    );

    let with = run(true);
    assert!(
        with.status.success(),
        "{}",
        String::from_utf8_lossy(&with.stderr)
    );
    let s: serde_json::Value = serde_json::from_slice(&with.stdout).expect("JSON");
    assert_eq!(s["coordinate_system"], "beam", "{s}");
    assert_eq!(s["fixes_written"], 2, "{s}");
    assert_eq!(s["fixes_outside"], 1, "{s}");
    assert_eq!(s["fixes_unparsable_lines"], 1, "{s}");

    let mut r = LogReader::open(&out).expect("open");
    r.read_header().expect("header");
    let (mut gnss, mut dvl_valid, mut last_ns) = (Vec::new(), 0, 0u64);
    while let Some(raw) = r.next_message().expect("read") {
        let m = raw.decode_any().expect("decode");
        let t = match &m {
            LogMessage::Gnss(g) => {
                gnss.push(*g);
                g.host_time_ns
            }
            LogMessage::Dvl(d) => {
                dvl_valid += usize::from(d.validity & DvlVelocityV1::VALID_VELOCITY != 0);
                d.host_time_ns
            }
            _ => continue,
        };
        assert!(t >= last_ns, "messages out of time order");
        last_ns = t;
    }
    assert_eq!(gnss.len(), 2);
    assert_eq!(gnss[0].host_time_ns, 10_000_000_000);
    assert!((gnss[1].latitude_rad.to_degrees() - 21.31).abs() < 1e-12);
    assert_eq!(gnss[1].horizontal_std_m, 3.0);
    // Beam coordinates now give velocities (three or four beams).
    assert!(dvl_valid > 100, "{dvl_valid}");
}
