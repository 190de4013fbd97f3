//! The error-state Kalman filter: the state layout and the linear update ([`filter`], re-exported
//! here), the innovation gates ([`gate`]), the unscented and linearised updates for nonlinear
//! measurements ([`unscented`]) and the adaptive measurement noise ([`adaptive_noise`]).

pub mod adaptive_noise;
pub mod filter;
pub mod gate;
pub mod unscented;

pub use filter::*;
