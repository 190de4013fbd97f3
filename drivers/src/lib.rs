//! auvnav device drivers: the driver processes (serial and TCP devices, CAN) built on the pure
//! protocol decoders and encoders of `auvnav-protocols`, re-exported here under their names.
#![forbid(unsafe_code)]

pub use auvnav_protocols::{
    device, framing, gnss, kvh, line_time, nmea, nortek, pd0, seatrac, to_device, to_schema, ubx,
    ugps, wldvl, wldvl_json, xsens,
};

pub mod can;
pub mod can_driver;
pub mod clock;
pub mod http;
pub mod serial_driver;
pub mod ugps_driver;
