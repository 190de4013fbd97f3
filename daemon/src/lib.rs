//! The auvnav navigation core. Pure: it reads no clock and no random source; time comes from the
//! messages, so the same ordered inputs give bit-identical outputs.
#![forbid(unsafe_code)]

pub mod align;
pub mod csv;
pub mod earth;
pub mod filter;
pub mod fine_align;
pub mod navigator;
pub mod session;
pub mod strapdown;
pub mod usbl;
