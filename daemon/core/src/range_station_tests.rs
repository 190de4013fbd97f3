//! The range aid configured as a docking station (`RangesConfig::docking_station`): the same
//! measurement as the tight USBL's model, each part gated alone, and where the error states go.

use crate::aid::ranges::{ErrorStates, RangesConfig};
use crate::aid::usbl::{UsblConfig, predict_tight};
use crate::earth::{Geodetic, ned_offset, offset_position};
use crate::navigator::{NavConfig, Navigator};
use crate::strapdown::initial_state;
use auvnav_shm_schema::{AidDiagnosticsV1, AidSource, UsblFixV1};
use nalgebra::Vector3;

fn station() -> UsblConfig {
    let mut hydrophone_offset_m = [0.0; 12];
    hydrophone_offset_m[0] = 0.004;
    hydrophone_offset_m[7] = -0.003;
    UsblConfig {
        array_latitude_deg: 31.0,
        array_longitude_deg: 120.0,
        array_height_m: -80.0,
        array_yaw_deg: 35.0,
        baseline_m: 0.6,
        hydrophone_offset_m,
        responder_lever_arm_m: [0.8, -0.2, -0.4],
        ..UsblConfig::default()
    }
}

/// The fix the tight USBL's own model gives for a vehicle at `at` (north, east, down of the
/// station, m) with attitude `euler`, valid at `t_s`.
fn fix_for(u: &UsblConfig, at: Vector3<f64>, euler: [f64; 3], t_s: f64) -> UsblFixV1 {
    let array = u.array();
    let s = initial_state(t_s, offset_position(&array.position, &at), [0.0; 3], euler);
    let c = s.q_body_to_ned.to_rotation_matrix().into_inner();
    let p_a = array.responder_in_array(&s.position, &c, &Vector3::from(u.responder_lever_arm_m));
    let z = predict_tight(&array, &p_a);
    let t_ns = (t_s * 1e9) as u64;
    UsblFixV1 {
        host_time_ns: t_ns,
        validity_time_ns: t_ns,
        slant_range_m: z[0],
        range_difference_m: [z[1], z[2]],
        validity: UsblFixV1::VALID_RANGE | UsblFixV1::VALID_RANGE_DIFFERENCES,
        ..Default::default()
    }
}

fn navigator(u: &UsblConfig, position: Geodetic, euler: [f64; 3], t_s: f64) -> Navigator {
    let cfg = NavConfig {
        ranges: Some(RangesConfig::docking_station(u)),
        initial_position_std_m: 5.0,
        ..Default::default()
    };
    assert!(cfg.problems().is_empty(), "{:?}", cfg.problems());
    Navigator::new(cfg, initial_state(t_s, position, [0.0; 3], euler))
}

/// At the truth, the slant range and both range differences are predicted as the tight USBL's
/// model predicts them (turned array, displaced hydrophones, a lever arm under a tilted
/// vehicle): innovations of micrometres.
#[test]
fn the_station_configuration_predicts_the_tight_usbl_measurement() {
    let u = station();
    let at = Vector3::new(-320.0, 140.0, 35.0);
    let euler = [0.1, -0.05, 2.0];
    let mut nav = navigator(&u, offset_position(&u.array().position, &at), euler, 5.0);
    let parts = nav
        .on_usbl_as_ranges(&fix_for(&u, at, euler, 5.0))
        .expect("the range aid takes the fixes");
    let sources = [
        AidSource::AcousticRange,
        AidSource::AcousticRangeDifference,
        AidSource::AcousticRangeDifference,
    ];
    for (d, source) in parts.iter().zip(sources) {
        let d = d.expect("every part fused");
        assert_eq!(d.source, source as u32);
        assert!(d.flags & AidDiagnosticsV1::FLAG_FUSED != 0);
        assert!(d.innovation[0].abs() < 1e-6, "{:?}", d.innovation);
    }
    assert_eq!(nav.counters().ranges_fused, 3);
    assert_eq!(nav.counters().usbl_unconfigured, 0);
}

/// A vehicle believed 4 m east of where it is, 300 m north of the station: the range
/// differences (across the line of sight) pull it back west, by about half in one fix (the
/// differences' error states, 0.01 m on a 0.6 m baseline, are worth 5 m across at 300 m, as
/// much as the position's prior); an absurd difference is refused alone, the range still taken.
#[test]
fn the_range_differences_correct_across_the_line_of_sight() {
    let u = station();
    let at = Vector3::new(-300.0, 0.0, 20.0);
    let truth = offset_position(&u.array().position, &at);
    let believed = offset_position(&truth, &Vector3::new(0.0, 4.0, 0.0));
    let mut nav = navigator(&u, believed, [0.0; 3], 5.0);
    nav.on_usbl_as_ranges(&fix_for(&u, at, [0.0; 3], 5.0));
    let err = ned_offset(&truth, &nav.state().position);
    assert!(
        err.y > 1.0 && err.y < 2.5 && err.x.abs() < 0.1,
        "error after one fix {err}"
    );
    let mut bad = fix_for(&u, at, [0.0; 3], 5.0);
    bad.range_difference_m[1] = 0.9 * u.baseline_m;
    let parts = nav.on_usbl_as_ranges(&bad).expect("taken");
    assert!(parts[0].is_some_and(|d| d.flags & AidDiagnosticsV1::FLAG_FUSED != 0));
    assert!(parts[2].is_some_and(|d| d.flags & AidDiagnosticsV1::FLAG_FUSED == 0));
    // Beyond the baseline: not a range difference at all.
    bad.range_difference_m[0] = 2.0 * u.baseline_m;
    nav.on_usbl_as_ranges(&bad);
    assert_eq!(nav.counters().ranges_invalid, 1);
}

/// The error states' slots: the shared bias and the scale where they always were, a bias per
/// receiver, the differences' errors after them, and a configuration asking for more slots than
/// the filter has refused with what to switch off.
#[test]
fn error_states_take_the_acoustic_slots_in_order() {
    let shared = ErrorStates::of(&RangesConfig::default());
    assert_eq!((shared.bias, shared.scale), ([Some(0); 5], Some(1)));
    let each = ErrorStates::of(&RangesConfig {
        bias_per_receiver: true,
        receivers_m: vec![[0.0; 3]; 4],
        ..RangesConfig::default()
    });
    assert_eq!(each.bias[..4], [Some(0), Some(1), Some(2), Some(3)]);
    assert_eq!((each.scale, each.count), (Some(4), 5));
    // Placed by the device: a slot for each of the four receivers a message can carry.
    let placed = ErrorStates::of(&RangesConfig {
        bias_per_receiver: true,
        receivers_from_device: true,
        scale_std: 0.0,
        ..RangesConfig::default()
    });
    assert_eq!(placed.bias[..4], [Some(0), Some(1), Some(2), Some(3)]);
    let docking = RangesConfig::docking_station(&station());
    let s = ErrorStates::of(&docking);
    assert_eq!(
        (s.bias[0], s.difference, s.scale),
        (Some(0), [Some(1), Some(2)], None)
    );
    let too_many = RangesConfig {
        bias_per_receiver: true,
        scale_std: 0.003,
        ..docking
    };
    let problems = too_many.problems();
    assert!(
        problems.iter().any(|p| p.contains("8 error states")),
        "{problems:?}"
    );
    // Both aids on the station's fixes: refused.
    let both = NavConfig {
        usbl: Some(station()),
        ranges: Some(RangesConfig::docking_station(&station())),
        ..Default::default()
    };
    assert!(
        both.problems().iter().any(|p| p.contains("usbl_fixes")),
        "{:?}",
        both.problems()
    );
}

/// A checkpoint written by a build with three acoustic slots (28 states) restores: its states
/// keep their places, the water current moves after the two new slots, which start off.
#[test]
fn a_checkpoint_of_28_states_restores_into_the_wider_filter() {
    use crate::ekf;
    let nav = Navigator::new(
        NavConfig::default(),
        initial_state(1.0, crate::aid::ranges::tests::origin(), [0.0; 3], [0.0; 3]),
    );
    let mut cp = nav.checkpoint();
    let old_n = 28;
    let p = nav.covariance();
    let to_new = |i: usize| if i < 26 { i } else { i + 2 };
    // Correlated a little everywhere, so that a misplaced entry shows.
    let marked = |i: usize, j: usize| {
        if i == j {
            p[(i, i)]
        } else {
            0.01 * (p[(i, i)] * p[(j, j)]).sqrt()
        }
    };
    let mut old = vec![0.0; old_n * old_n];
    for j in 0..old_n {
        for i in 0..old_n {
            old[i + old_n * j] = marked(to_new(i), to_new(j));
        }
    }
    cp.covariance = old;
    let restored = Navigator::from_checkpoint(NavConfig::default(), &cp).expect("restores");
    let q = restored.covariance();
    for i in 0..ekf::N {
        for j in 0..ekf::N {
            let new_slot = |k: usize| (26..28).contains(&k);
            let expected = if new_slot(i) || new_slot(j) {
                0.0
            } else {
                marked(i, j)
            };
            assert_eq!(q[(i, j)], expected, "({i}, {j})");
        }
    }
    cp.covariance.truncate(100);
    assert!(Navigator::from_checkpoint(NavConfig::default(), &cp).is_none());
}
