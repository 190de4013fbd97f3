//! auvnav device protocols: pure decoders and encoders (bytes in, frames out; no I/O, no clock),
//! their conversion to the schema messages, and the registry of the protocols the drivers speak.
//! The driver processes (`auvnav-drivers`) add the serial, TCP and CAN I/O around them; a
//! decoder can be used here without that stack.
#![forbid(unsafe_code)]

pub mod device;
pub mod framing;
pub mod gnss;
pub mod kvh;
pub mod nmea;
pub mod nortek;
pub mod pd0;
pub mod seatrac;
pub mod to_device;
pub mod to_schema;
pub mod ubx;
pub mod wldvl;
pub mod wldvl_json;
pub mod xsens;
