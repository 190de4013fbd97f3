//! The service manager's protocol (`sd_notify`): READY once the process is up, WATCHDOG from the
//! main loop while it makes progress, STATUS with what it is doing, STOPPING on the way out.
//!
//! Outside systemd (no `NOTIFY_SOCKET`) every call does nothing. Under a unit with `Type=notify`
//! and `WatchdogSec=`, the main loop calls [`Supervisor::alive`] on every turn; it sends WATCHDOG=1
//! at most four times per watchdog period, so a loop that stops turning (a deadlock, a stuck bus, a
//! SIGSTOP) stops the keep-alives and systemd kills and restarts the process. The keep-alive is
//! never sent from a helper thread: a helper would keep a hung loop alive.

use std::time::{Duration, Instant};

/// A process's link to its service manager.
#[derive(Debug)]
pub struct Supervisor {
    /// Whether a service manager listens (`NOTIFY_SOCKET` set).
    listening: bool,
    /// Interval between keep-alives (a quarter of `WATCHDOG_USEC`), when the watchdog is on.
    keep_alive: Option<Duration>,
    last_keep_alive: Option<Instant>,
    last_status: String,
    failures: u64,
}

impl Supervisor {
    /// The service manager the environment names (none outside systemd).
    pub fn from_env() -> Supervisor {
        Supervisor {
            listening: std::env::var_os("NOTIFY_SOCKET").is_some(),
            keep_alive: sd_notify::watchdog_enabled().map(|d| d / 4),
            last_keep_alive: None,
            last_status: String::new(),
            failures: 0,
        }
    }

    /// The watchdog period the service manager asked for, if any.
    pub fn watchdog_period(&self) -> Option<Duration> {
        self.keep_alive.map(|d| d * 4)
    }

    /// Notifications that could not be sent (the socket gone, a full buffer).
    pub fn failures(&self) -> u64 {
        self.failures
    }

    fn send(&mut self, state: &[sd_notify::NotifyState]) {
        if !self.listening {
            return;
        }
        if let Err(e) = sd_notify::notify(state) {
            self.failures += 1;
            if self.failures == 1 {
                tracing::warn!("cannot notify the service manager: {e}");
            }
        }
    }

    /// The process is up: the bus is open and the configuration checked.
    pub fn ready(&mut self, status: &str) {
        self.last_status = status.to_string();
        self.send(&[
            sd_notify::NotifyState::Ready,
            sd_notify::NotifyState::Status(status),
        ]);
        self.last_keep_alive = Some(Instant::now());
    }

    /// One turn of the main loop: a keep-alive when one is due.
    pub fn alive(&mut self) {
        let Some(every) = self.keep_alive else {
            return;
        };
        let now = Instant::now();
        if self.last_keep_alive.is_some_and(|t| now - t < every) {
            return;
        }
        self.last_keep_alive = Some(now);
        self.send(&[sd_notify::NotifyState::Watchdog]);
    }

    /// What the process is doing (`systemctl status` shows it); sent when it changes.
    pub fn status(&mut self, status: &str) {
        if status != self.last_status {
            self.last_status = status.to_string();
            self.send(&[sd_notify::NotifyState::Status(status)]);
        }
    }

    /// The process is stopping.
    pub fn stopping(&mut self) {
        self.send(&[sd_notify::NotifyState::Stopping]);
    }
}
