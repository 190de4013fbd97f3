//! The message types through the iceoryx2 bus (the schema's `bus` feature): every type
//! round-trips through a real shared-memory service, and the bus's management segment is not
//! left world-writable.

use auvnav_shm_schema::*;
use iceoryx2::prelude::*;

/// A value with every byte set (finite floats).
fn filled<T: Message>(seed: u8) -> T {
    let mut v = T::default();
    for (i, b) in bytemuck::bytes_of_mut(&mut v).iter_mut().enumerate() {
        *b = seed.wrapping_add(i as u8) & 0x3f;
    }
    v
}

fn roundtrip_iceoryx2<T: Message + 'static>(node: &Node<ipc::Service>, prefix: &str) {
    let name = topic::service_name(prefix, T::SCHEMA_NAME.rsplit('/').next().unwrap_or("x"));
    let service = node
        .service_builder(&name.as_str().try_into().expect("service name"))
        .publish_subscribe::<T>()
        .enable_safe_overflow(true)
        .subscriber_max_buffer_size(qos::SENSOR.subscriber_max_buffer_size)
        .open_or_create()
        .expect("service");
    let publisher = service.publisher_builder().create().expect("publisher");
    let subscriber = service.subscriber_builder().create().expect("subscriber");
    let sent: T = filled(3);
    publisher
        .loan_uninit()
        .expect("loan")
        .write_payload(sent)
        .send()
        .expect("send");
    let sample = subscriber.receive().expect("receive").expect("a sample");
    assert_eq!(
        bytemuck::bytes_of(sample.payload()),
        bytemuck::bytes_of(&sent),
        "{}",
        T::TYPE_NAME
    );
}

#[test]
fn every_type_roundtrips_through_iceoryx2() {
    let node = NodeBuilder::new().create::<ipc::Service>().expect("node");
    let prefix = format!("auvnav-test-layout-{}", std::process::id());
    roundtrip_iceoryx2::<ImuSampleV1>(&node, &prefix);
    roundtrip_iceoryx2::<DvlVelocityV1>(&node, &prefix);
    roundtrip_iceoryx2::<UsblFixV1>(&node, &prefix);
    roundtrip_iceoryx2::<DepthV1>(&node, &prefix);
    roundtrip_iceoryx2::<MagnetometerV1>(&node, &prefix);
    roundtrip_iceoryx2::<SoundVelocityV1>(&node, &prefix);
    roundtrip_iceoryx2::<AcousticRangesV1>(&node, &prefix);
    roundtrip_iceoryx2::<AcousticArrayPoseV1>(&node, &prefix);
    roundtrip_iceoryx2::<GnssFixV1>(&node, &prefix);
    roundtrip_iceoryx2::<NavSolutionV1>(&node, &prefix);
    roundtrip_iceoryx2::<AidDiagnosticsV1>(&node, &prefix);
    roundtrip_iceoryx2::<ProcessHealthV1>(&node, &prefix);
    roundtrip_iceoryx2::<LateAidV1>(&node, &prefix);
    roundtrip_iceoryx2::<TruthStateV1>(&node, &prefix);
}

/// The bus's global management segment, which iceoryx2 creates world-writable, keeps no
/// permission for other users once a bus is opened by its owner.
#[test]
fn the_global_management_segment_is_not_world_writable() {
    use std::os::unix::fs::{MetadataExt, PermissionsExt};
    let bus =
        auvnav_shm_schema::bus::Bus::new("layoutperm", &format!("perm{}", std::process::id()))
            .expect("bus");
    let me = std::fs::metadata("/proc/self").expect("proc").uid();
    let mut seen = 0;
    for e in std::fs::read_dir("/dev/shm").expect("/dev/shm").flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if name.starts_with("iox2_") && name.ends_with("global_mgmt") {
            let m = e.metadata().expect("metadata");
            if m.uid() == me {
                seen += 1;
                assert_eq!(
                    m.permissions().mode() & 0o007,
                    0,
                    "{name} is open to other users: {:o}",
                    m.permissions().mode()
                );
            }
        }
    }
    if seen == 0 {
        // Another user of this host created it first: only they can change it.
        eprintln!("the management segment belongs to another user; nothing to check");
    }
    drop(bus);
}
