//! Tests of [`super`]: how a navigation's change is judged.
use super::*;

fn accuracy(rms_m: f64, velocity_m_s: f64, own_m: f64) -> Accuracy {
    Accuracy {
        horizontal_error_rms_m: rms_m,
        horizontal_velocity_error_rms_m_s: velocity_m_s,
        truth_position_against_velocity_rms_m: own_m,
        ..Default::default()
    }
}

#[test]
fn a_growth_in_position_or_in_velocity_is_worse() {
    let (worse, text) =
        NavigationGain::judge(&accuracy(1.93, 0.0666, 1.10), &accuracy(1.45, 0.0183, 1.10));
    assert!(!worse && text.starts_with("not worse"), "{text}");
    // A growth within the reference's own departure counts, and is said to be within it.
    let (worse, text) =
        NavigationGain::judge(&accuracy(0.98, 0.0167, 0.75), &accuracy(1.25, 0.0125, 0.75));
    assert!(worse && text.starts_with("worse in position"), "{text}");
    assert!(text.contains("less than the 0.75 m"), "{text}");
    let (worse, text) =
        NavigationGain::judge(&accuracy(1.67, 0.091, 0.76), &accuracy(2.89, 0.025, 0.76));
    assert!(worse && !text.contains("less than"), "{text}");
    // The velocity error grows, the position falls.
    let (worse, text) =
        NavigationGain::judge(&accuracy(1.42, 0.0128, 1.41), &accuracy(0.95, 0.0134, 1.41));
    assert!(worse && text.starts_with("worse in velocity:"), "{text}");
    // No velocity compared (a reference without one): the position alone.
    let (worse, text) =
        NavigationGain::judge(&accuracy(0.12, 0.0, 0.001), &accuracy(0.10, 0.0, 0.001));
    assert!(!worse && !text.contains("velocity"), "{text}");
}
