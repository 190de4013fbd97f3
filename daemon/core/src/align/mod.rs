//! Initial alignment (S-ALIGN): [`coarse`] (static analytic, and DVL-aided in motion by
//! optimisation in the initial inertial frames) and [`fine`] (a Kalman filter by one of the three
//! error models), run in that order by the navigation session before the navigator starts.

pub mod coarse;
pub mod fine;
