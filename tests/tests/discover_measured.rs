//! Model discovery on measured data: the 13 Snapir segments (DVL against the reference
//! solution), with nothing said about what to look for. `docs/measured-data.md` found by hand a
//! DVL about 1.85 m aft of the IMU and a DVL/reference lag near 1 s; discovery must name the same
//! two causes with compatible values in most segments, and lower the held-out DVL residual.
//! Under CI the data must be present.

use auvnav_tools::discover::command::{Collector, discover};
use auvnav_tools::discover::fit::Selection;
use auvnav_tools::import::{TimeBase, snapir_messages};

#[test]
fn snapir_dvl_lever_arm_and_lag_are_found_without_being_asked() {
    let Some(dir) = auvnav_tests::measured_data("snapir-auv", "imu_01.csv") else {
        return;
    };
    let mut agree = 0;
    for segment in 1..=13 {
        let (messages, _) =
            snapir_messages(&dir, segment, TimeBase::Nominal, true).expect("import");
        let mut c = Collector::new();
        for (_, m) in &messages {
            c.add(m);
        }
        let (channels, reference) = c.finish();
        let r = discover(
            &channels,
            &reference,
            &Default::default(),
            0.7,
            &Selection::default(),
        );
        let value = |name: &str| {
            r.effects
                .iter()
                .find(|e| e.name == name)
                .map(|e| e.value.clone())
        };
        let lever_x = value("dvl.lever_arm").and_then(|v| v[0].as_f64());
        let offset = value("dvl.time_offset").and_then(|v| v.as_f64());
        let g = r
            .gain
            .iter()
            .find(|g| g.channel == auvnav_tools::discover::ChannelKind::Dvl)
            .expect("DVL gain");
        let (before, after): (f64, f64) = (
            g.rms_before.iter().map(|x| x * x).sum::<f64>().sqrt(),
            g.rms_after.iter().map(|x| x * x).sum::<f64>().sqrt(),
        );
        eprintln!(
            "segment {segment:2}: lever arm x {lever_x:?} m, time offset {offset:?} s, held-out DVL rms {before:.3} -> {after:.3} m/s; found {:?}",
            r.effects.iter().map(|e| &e.name).collect::<Vec<_>>()
        );
        assert!(after < before, "segment {segment}: no held-out gain");
        if lever_x.is_some_and(|x| (x + 1.85).abs() < 0.3)
            && offset.is_some_and(|t| (t + 1.0).abs() < 0.2)
        {
            agree += 1;
        }
    }
    assert!(
        agree >= 10,
        "only {agree} of 13 segments agree with the hand analysis"
    );
}
