//! auvnav device protocols: pure decoders and encoders (bytes in, frames out; no I/O, no clock),
//! their conversion to the schema messages, and the registry of the protocols the drivers speak.
//! The driver processes (`auvnav-drivers`) add the serial, TCP and CAN I/O around them; a
//! decoder can be used here without that stack.
//!
//! A device is a folder: `<device>/mod.rs` (its decoder and encoder), `<device>/to_schema.rs`
//! (its frames as schema messages) and `<device>/to_device.rs` (schema messages in its protocol,
//! for the emulator). What the conversions share is [`schema_rules`]; [`to_schema`] and
//! [`to_device`] gather every device's functions under one name; [`device`] is the registry the
//! drivers start from.
#![forbid(unsafe_code)]

pub mod autopilot;
pub mod device;
pub mod framing;
pub mod gnss;
pub mod kvh;
pub mod line_time;
pub mod nmea;
pub mod nortek;
pub mod pd0;
pub mod schema_rules;
pub mod seatrac;
pub mod to_device;
pub mod to_schema;
pub mod ubx;
pub mod ugps;
pub mod wldvl;
/// The Water Linked DVL's JSON reports (its TCP service), [`wldvl::json`].
pub use wldvl::json as wldvl_json;
pub mod xsens;
