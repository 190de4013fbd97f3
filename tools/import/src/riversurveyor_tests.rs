//! Tests of the RiverSurveyor import's time fields and refusals.
use super::*;

#[test]
fn utc_fields_and_wrapping() {
    let t = utc_seconds(150339.9).expect("a time");
    assert!(
        (t - (15.0 * 3600.0 + 3.0 * 60.0 + 39.9)).abs() < 1e-9,
        "{t}"
    );
    assert_eq!(utc_seconds(0.0), Some(0.0));
    assert!(utc_seconds(f64::NAN).is_none());
    assert!(utc_seconds(156_000.0).is_none(), "minute 60");
    assert!(utc_seconds(-1.0).is_none());
    assert!(utc_seconds(126_000.0).is_none());
    assert!((wrap(86_399.0, DAY_S) + 1.0).abs() < 1e-9);
    assert!((wrap(3607.9, DAY_S) - 3607.9).abs() < 1e-9);
}

#[test]
fn a_mat_file_without_the_structs_is_refused_with_the_reason() {
    let f = MatFile {
        header: "MATLAB 5.0 MAT-file".into(),
        variables: Vec::new(),
    };
    let Err(e) = riversurveyor_messages(&f, GpsVelocity::Auto, 1.0) else {
        panic!("accepted");
    };
    assert!(e.to_string().contains("coordinateSystem"), "{e}");
}
