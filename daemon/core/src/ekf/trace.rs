//! What the error filter hands to a smoother while it runs (`crate::smoother`): at every
//! covariance-propagation epoch the covariance before the propagation (the updated covariance of
//! the previous epoch), the transition and the covariance after it (the predicted covariance of
//! the new epoch), and every error-state correction applied to the nominal state in between.
//!
//! The trace is off unless a smoother asks for it (the daemon never does); its events are taken
//! by the session after each message, so a navigator copied for a restart carries at most the
//! events of one message.

use super::filter::{CORE, Covariance, N, PARAMS, StateVector};
use nalgebra::{SMatrix, SVector};

/// Rows of the transition that differ from the identity: position, velocity, attitude (the bias
/// rows of the error dynamics are zero, the parameter states' transition is diagonal).
pub const NAV_ROWS: usize = 9;

/// One covariance propagation, from the previous epoch to `time_ns`.
#[derive(Debug, Clone, PartialEq)]
pub struct Propagation {
    /// The epoch the propagation reaches (ns, the time stamp of the IMU sample integrated last).
    pub time_ns: u64,
    /// The covariance before the propagation: the previous epoch's, after its updates.
    pub p_updated: Covariance,
    /// The navigation rows of the core transition `Phi = I + F dt + (F dt)^2 / 2`.
    pub transition_nav: SMatrix<f64, NAV_ROWS, CORE>,
    /// The parameter states' transition factors (1 for the constants).
    pub transition_params: SVector<f64, PARAMS>,
    /// The covariance after the propagation and the growth for unobserved motion (an IMU gap).
    pub p_predicted: Covariance,
}

impl Propagation {
    /// The whole transition matrix.
    pub fn transition(&self) -> Covariance {
        transition_matrix(&self.transition_nav, &self.transition_params)
    }
}

/// The full transition from its navigation rows and the parameter factors: identity bias rows,
/// diagonal parameter block.
pub fn transition_matrix(
    nav: &SMatrix<f64, NAV_ROWS, CORE>,
    params: &SVector<f64, PARAMS>,
) -> Covariance {
    let mut phi = Covariance::identity();
    phi.fixed_view_mut::<NAV_ROWS, CORE>(0, 0).copy_from(nav);
    for j in 0..PARAMS {
        phi[(CORE + j, CORE + j)] = params[j];
    }
    phi
}

/// One event of the trace.
#[derive(Debug, Clone, PartialEq)]
pub enum TraceEvent {
    Propagation(Box<Propagation>),
    /// An error-state estimate removed from the nominal state at the current epoch.
    Correction(Box<StateVector>),
}

/// The events since the session last took them.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trace {
    pub events: Vec<TraceEvent>,
}

impl Trace {
    /// Adds variances to the last propagation's predicted covariance when nothing was fused
    /// since it (the growth over an IMU gap belongs to the propagation); otherwise the growth
    /// is part of the epoch's update stage and the smoother sees it in the next propagation's
    /// updated covariance.
    pub fn grow(&mut self, variances: &StateVector) {
        if let Some(TraceEvent::Propagation(p)) = self.events.last_mut() {
            for i in 0..N {
                p.p_predicted[(i, i)] += variances[i];
            }
        }
    }
}
