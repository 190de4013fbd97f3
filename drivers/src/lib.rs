//! auvnav device drivers: pure protocol decoders and encoders (bytes in, frames out; no I/O, no
//! clock), and the driver processes built on them.

pub mod can;
pub mod can_driver;
pub mod clock;
pub mod convert;
pub mod device;
pub mod emulate;
pub mod framing;
pub mod gnss;
pub mod kvh;
pub mod nmea;
pub mod nortek;
pub mod pd0;
pub mod seatrac;
pub mod serial_driver;
pub mod ubx;
pub mod wldvl;
pub mod wldvl_json;
pub mod xsens;
