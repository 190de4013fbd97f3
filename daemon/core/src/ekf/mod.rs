//! The error-state Kalman filter: the state layout and the linear update ([`filter`], re-exported
//! here), the innovation gates ([`gate`]), the unscented and linearised updates for nonlinear
//! measurements ([`unscented`]) the adaptive measurement noise ([`adaptive_noise`]) and what a smoother needs of each epoch
//! ([`trace`]).

pub mod adaptive_noise;
pub mod filter;
pub mod gate;
pub mod trace;
pub mod unscented;

pub use filter::*;
