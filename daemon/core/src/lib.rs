//! The auvnav navigation core. Pure: it reads no clock and no random source; time comes from the
//! messages, so the same ordered inputs give bit-identical outputs.
//!
//! Map: [`earth`] and [`strapdown`] (the inertial mechanisation), [`ekf`] (error-state filter,
//! gates, unscented update, adaptive noise), [`aid`] (one module per aiding sensor),
//! [`nav_core`] (strapdown, covariance, correction), [`navigator`] (the core plus its aids), [`align`] (coarse and fine alignment), [`session`]
//! (how a run starts and the order in which messages meet the navigator), [`feed`] (the one
//! message → session path), [`smoother`] (the forward–backward smoother over the session), [`config`] (the configuration types and their validation), [`csv`]
//! (solution and diagnostics files).
#![deny(unsafe_code)]

pub mod aid;
pub mod align;
pub mod config;
pub mod csv;
pub mod dead_reckoning;
pub mod earth;
pub mod ekf;
pub mod feed;
pub mod nav_core;
pub mod navigator;
#[cfg(test)]
mod range_aid_tests;
#[cfg(test)]
mod range_station_tests;
pub mod session;
pub mod smoother;
pub mod strapdown;
pub mod wmm;
