//! The magnetic-field channel (a magnetometer without a reference attitude) on a turning
//! vehicle: the specific force's direction is its vertical, and a turn leans it by the
//! centripetal acceleration, which must not be read as iron. Seed and scenario are the test's
//! own.

#[test]
fn turns_are_not_read_as_iron_without_a_reference_attitude() {
    // A survey's 4°/s turns at 2 m/s lean the specific force by 0.8°: taken for the vertical,
    // a dip error of 0.7 µT that follows the turns and reads as a hard iron. With the
    // centripetal acceleration (gyro rate × bottom-track velocity) taken off, a noise-free
    // magnetometer with nothing hidden leaves nothing to name or point at on the field channel.
    use auvnav_sim::{SimConfig, scenario::Scenario};
    use auvnav_tools::discover::ChannelKind;
    use auvnav_tools::discover::command::discover_messages;
    let mut effects = auvnav_sim::effects::Effects::default();
    effects.set("dvl.noise", &[0.005]).expect("noise");
    let messages: Vec<auvnav_log::LogMessage> = auvnav_tests::grade::simulate(&SimConfig {
        scenario: Scenario::load("lawnmower").expect("scenario"),
        effects,
        seed: 9311,
        duration_s: Some(400.0),
    })
    .into_iter()
    .filter(|m| !matches!(m, auvnav_log::LogMessage::Truth(_)))
    .collect();
    let r = discover_messages(&messages);
    let field = r
        .channels
        .iter()
        .find(|c| c.channel == ChannelKind::MagneticField)
        .expect("the field channel analysed");
    let dip_rms = field.nominal[1].rms;
    println!(
        "dip residual rms {dip_rms:.4} µT; effects {:?}; pointed at {:?}",
        r.effects.iter().map(|e| &e.name).collect::<Vec<_>>(),
        r.undetermined.iter().map(|u| &u.note).collect::<Vec<_>>()
    );
    assert!(r.effects.is_empty(), "{:#?}", r.effects);
    assert!(
        !r.undetermined
            .iter()
            .any(|u| u.channel == ChannelKind::MagneticField),
        "{:#?}",
        r.undetermined
    );
    // Uncorrected, the turns leave 0.20 µT and a hard iron pointed at (0.42 µT, 3.6σ).
    assert!(dip_rms < 0.03, "{dip_rms}");
}
