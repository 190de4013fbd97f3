//! Quality-of-service settings of the publish-subscribe services. Publishers and subscribers must
//! open a service with identical settings (iceoryx2 refuses mismatches at open), so they live here,
//! next to the types.
//!
//! Safe overflow is on everywhere: a slow subscriber (the recorder) loses its oldest samples
//! instead of throttling a driver; losses are visible as sequence gaps and counted.

/// Settings for one service.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ServiceQos {
    /// Samples a subscriber can hold before the oldest is overwritten (count).
    pub subscriber_max_buffer_size: usize,
    /// Samples delivered to a late-joining subscriber (count).
    pub history_size: usize,
    /// Maximum number of publishers (count).
    pub max_publishers: usize,
    /// Maximum number of subscribers (count).
    pub max_subscribers: usize,
}

/// Sensor topics: 2048 slots absorb two seconds without a scheduling slot at 1 kHz (measured:
/// with every core kept busy by other processes, a subscriber went unscheduled for more than the
/// 0.3 s that 256 slots held at 800 Hz). About 200 kB per subscriber of an IMU topic.
pub const SENSOR: ServiceQos = ServiceQos {
    subscriber_max_buffer_size: 2048,
    history_size: 0,
    max_publishers: 2,
    max_subscribers: 8,
};

/// Navigation outputs (solution, diagnostics) published at IMU rate: as deep as the sensors'.
pub const NAVIGATION: ServiceQos = ServiceQos {
    subscriber_max_buffer_size: 2048,
    history_size: 1,
    max_publishers: 2,
    max_subscribers: 8,
};

/// Process health: low rate, many publishers.
pub const HEALTH: ServiceQos = ServiceQos {
    subscriber_max_buffer_size: 64,
    history_size: 0,
    max_publishers: 16,
    max_subscribers: 8,
};

/// Raw device bytes for the recorder: one chunk per read, so fewer slots than a 1 kHz topic.
pub const RAW: ServiceQos = ServiceQos {
    subscriber_max_buffer_size: 128,
    history_size: 0,
    max_publishers: 2,
    max_subscribers: 4,
};
