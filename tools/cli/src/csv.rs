//! CSV output of navigation solutions: the core's writer (`auvnav_core::csv`), shared with the
//! daemon so that live and replayed solutions give byte-identical files.

pub use auvnav_core::csv::*;
