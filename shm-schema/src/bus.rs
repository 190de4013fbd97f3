//! The shared-memory bus: one iceoryx2 node per process, a publish-subscribe service per topic
//! and, beside it, an event service with the same name that publishers notify after each send so
//! that subscribers can sleep until data arrives (instead of polling).
//!
//! Every service is opened with the [`crate::qos`] settings of its topic class, so publishers and
//! subscribers always agree. Sequence numbers are assigned here: a publisher numbers its messages
//! 0, 1, 2, …, and a subscriber counts the gaps (messages lost to a full buffer).

use crate::Message;
use crate::qos::ServiceQos;
use crate::topic::service_name;
use iceoryx2::node::NodeWaitFailure;
use iceoryx2::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// Set by SIGTERM or SIGINT and never cleared: a request to stop.
static TERMINATION: AtomicBool = AtomicBool::new(false);

/// Installs (once per process) a SIGTERM and SIGINT action that sets [`TERMINATION`], chained
/// before the handler iceoryx2 installed. iceoryx2 keeps only the last signal it caught, and the
/// processes catch SIGCONT too: `systemctl stop` sends SIGTERM then SIGCONT, and without this flag
/// the SIGCONT overwrote the SIGTERM before the process looked (a driver never stopped and was
/// killed at the stop timeout).
fn watch_termination() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        for sig in [nix::libc::SIGTERM, nix::libc::SIGINT] {
            // SAFETY: the action stores to an atomic only, which is async-signal-safe.
            let r = unsafe {
                signal_hook_registry::register(sig, || TERMINATION.store(true, Ordering::SeqCst))
            };
            if let Err(e) = r {
                tracing::warn!("cannot watch signal {sig} for a stop request: {e}");
            }
        }
    });
}

/// True once SIGTERM or SIGINT reached the process (after [`Bus::new`]), whatever signals came
/// after it. Loops that wait on an iceoryx2 WaitSet check it when the wait is interrupted.
pub fn termination_signalled() -> bool {
    TERMINATION.load(Ordering::SeqCst)
}

/// An error of the bus, with the service or node it concerns.
#[derive(Debug)]
pub struct BusError(pub String);

impl std::fmt::Display for BusError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for BusError {}

impl Drop for Bus {
    /// The process is leaving the bus: it is stopping.
    fn drop(&mut self) {
        self.supervisor.get_mut().stopping();
    }
}

fn err(what: impl std::fmt::Display, e: impl std::fmt::Debug) -> BusError {
    BusError(format!("{what}: {e:?}"))
}

/// The environment variable naming the directory iceoryx2 keeps its node and service files in
/// (default `/tmp/iceoryx2/`). The units set it to `/run/auvnav/iceoryx2/`, a runtime directory
/// every bus unit shares, so that each unit keeps a private `/tmp`.
pub const BUS_ROOT_ENV: &str = "AUVNAV_BUS_ROOT";

/// The bus's root directory from [`BUS_ROOT_ENV`], if set.
fn bus_root() -> Result<Option<Path>, BusError> {
    let Some(root) = std::env::var_os(BUS_ROOT_ENV) else {
        return Ok(None);
    };
    let mut root = root.to_string_lossy().into_owned();
    if !root.starts_with('/') {
        return Err(BusError(format!(
            "{BUS_ROOT_ENV}={root:?}: the bus root must be an absolute path"
        )));
    }
    if !root.ends_with('/') {
        root.push('/');
    }
    Path::new_normalized(root.as_bytes())
        .map(Some)
        .map_err(|e| err(format!("{BUS_ROOT_ENV}={root:?}"), e))
}

/// A process's connection to the bus: its iceoryx2 node and the deployment prefix of its service
/// names.
pub struct Bus {
    node: Node<ipc::Service>,
    prefix: String,
    /// The service manager (systemd's notify protocol; silent outside systemd).
    supervisor: std::cell::RefCell<crate::supervisor::Supervisor>,
}

impl Bus {
    /// Creates the node `name` (shown in iceoryx2's node list). SIGINT and SIGTERM are caught by
    /// iceoryx2 and reported by [`Bus::termination_requested`]. Dead nodes of killed processes are
    /// cleaned up when services are opened.
    pub fn new(name: &str, prefix: &str) -> Result<Bus, BusError> {
        let node_name: NodeName = name
            .try_into()
            .map_err(|e| err(format!("node name {name:?}"), e))?;
        let mut builder = NodeBuilder::new().name(&node_name);
        if let Some(root) = bus_root()? {
            let mut config = iceoryx2::config::Config::global_config().clone();
            config.global.set_root_path(&root);
            builder = builder.config(&config);
        }
        let node = builder
            .create::<ipc::Service>()
            .map_err(|e| err(format!("creating node {name:?}"), e))?;
        restrict_global_segment(std::path::Path::new("/dev/shm"));
        // The first wait installs iceoryx2's signal handlers; ours is chained before them.
        let bus = Bus {
            node,
            prefix: prefix.to_string(),
            supervisor: std::cell::RefCell::new(crate::supervisor::Supervisor::from_env()),
        };
        let _ = bus.termination_requested();
        watch_termination();
        Ok(bus)
    }

    /// The deployment prefix.
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    /// True once SIGTERM or SIGINT was received, also when another signal came after it. Other
    /// signals (SIGCONT after a stop, a debugger's) interrupt a wait without being a request to
    /// stop.
    /// Every call is also a turn of the caller's loop: the service manager's keep-alive is sent
    /// from here when one is due ([`Bus::keep_alive`]).
    pub fn termination_requested(&self) -> bool {
        self.keep_alive();
        let iceoryx = matches!(
            self.node.wait(Duration::ZERO),
            Err(NodeWaitFailure::TerminationRequest)
        );
        iceoryx || termination_signalled()
    }

    /// Tells the service manager the process is up (the configuration read, the bus open,
    /// its ports created), with what it is doing.
    pub fn ready(&self, status: &str) {
        self.supervisor.borrow_mut().ready(status);
    }

    /// A turn of the process's main loop: a watchdog keep-alive when one is due. Call it from the
    /// loop itself, never from a helper thread (a hung loop must stop the keep-alives).
    pub fn keep_alive(&self) {
        self.supervisor.borrow_mut().alive();
    }

    /// What the process is doing, for `systemctl status` (sent when it changes).
    pub fn status(&self, status: &str) {
        self.supervisor.borrow_mut().status(status);
    }

    /// Removes the resources of dead processes (nodes killed without cleanup).
    pub fn cleanup_dead_nodes(&self) {
        let _ = self.node.try_cleanup_dead_nodes();
    }

    fn names(&self, topic: &str) -> Result<(ServiceName, String), BusError> {
        let full = service_name(&self.prefix, topic);
        let name: ServiceName = full
            .as_str()
            .try_into()
            .map_err(|e| err(format!("service name {full:?}"), e))?;
        Ok((name, full))
    }

    fn event(&self, name: &ServiceName, full: &str) -> Result<PortFactoryEvent, BusError> {
        self.node
            .service_builder(name)
            .event()
            .max_notifiers(16)
            .max_listeners(16)
            .open_or_create()
            .map_err(|e| err(format!("event service {full:?}"), e))
    }

    fn pubsub<T: Message>(
        &self,
        name: &ServiceName,
        full: &str,
        qos: ServiceQos,
    ) -> Result<PortFactoryPubSub<T>, BusError> {
        self.node
            .service_builder(name)
            .publish_subscribe::<T>()
            .enable_safe_overflow(true)
            .subscriber_max_buffer_size(qos.subscriber_max_buffer_size)
            .history_size(qos.history_size)
            .max_publishers(qos.max_publishers)
            .max_subscribers(qos.max_subscribers)
            .open_or_create()
            .map_err(|e| err(format!("service {full:?} ({})", T::TYPE_NAME), e))
    }

    /// A publisher of `T` on `topic`.
    pub fn publisher<T: Message>(
        &self,
        topic: &str,
        qos: ServiceQos,
    ) -> Result<BusPublisher<T>, BusError> {
        let (name, full) = self.names(topic)?;
        let service = self.pubsub::<T>(&name, &full, qos)?;
        let publisher = service
            .publisher_builder()
            .create()
            .map_err(|e| err(format!("publisher on {full:?}"), e))?;
        let notifier = self
            .event(&name, &full)?
            .notifier_builder()
            .create()
            .map_err(|e| err(format!("notifier on {full:?}"), e))?;
        Ok(BusPublisher {
            publisher,
            notifier,
            sequence: 0,
            service: full,
        })
    }

    /// A listener on `topic`'s event service, separate from any subscriber, for a WaitSet that
    /// wakes a process when any of its topics receives data.
    pub fn listener(
        &self,
        topic: &str,
    ) -> Result<iceoryx2::port::listener::Listener<ipc::Service>, BusError> {
        let (name, full) = self.names(topic)?;
        self.event(&name, &full)?
            .listener_builder()
            .create()
            .map_err(|e| err(format!("listener on {full:?}"), e))
    }

    /// A subscriber of `T` on `topic`. It is connected once created; call
    /// [`BusSubscriber::receive`] regularly (also when not notified) so that its side of the
    /// connection is established before the first publish.
    ///
    /// A subscriber has no listener of its own: a process that sleeps until data arrives makes
    /// one with [`Bus::listener`] (one per topic it waits on, and only those). Every listener of a
    /// topic costs each publish of it a notification (a system call), read or not.
    pub fn subscriber<T: Message>(
        &self,
        topic: &str,
        qos: ServiceQos,
    ) -> Result<BusSubscriber<T>, BusError> {
        let (name, full) = self.names(topic)?;
        let service = self.pubsub::<T>(&name, &full, qos)?;
        let subscriber = service
            .subscriber_builder()
            .create()
            .map_err(|e| err(format!("subscriber on {full:?}"), e))?;
        let _ = subscriber.receive();
        Ok(BusSubscriber {
            subscriber,
            next_sequence: Vec::new(),
            gaps: 0,
            service: full,
        })
    }
}

type PortFactoryEvent = iceoryx2::service::port_factory::event::PortFactory<ipc::Service>;
type PortFactoryPubSub<T> =
    iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>;

/// Publishes `T` and wakes the subscribers.
pub struct BusPublisher<T: Message> {
    publisher: iceoryx2::port::publisher::Publisher<ipc::Service, T, ()>,
    notifier: iceoryx2::port::notifier::Notifier<ipc::Service>,
    sequence: u64,
    service: String,
}

pub use crate::Sequenced;

impl<T: Message + Sequenced> BusPublisher<T> {
    /// Numbers `msg` with the next sequence number, sends it and notifies. Returns the sequence
    /// number used.
    pub fn publish(&mut self, mut msg: T) -> Result<u64, BusError> {
        let sequence = self.sequence;
        msg.set_sequence(sequence);
        self.publisher
            .send_copy(msg)
            .map_err(|e| err(format!("send on {:?}", self.service), e))?;
        self.sequence += 1;
        self.notifier
            .notify()
            .map_err(|e| err(format!("notify on {:?}", self.service), e))?;
        Ok(sequence)
    }

    /// Sends `msg` as it is, its sequence number kept, and notifies: for a bridge carrying
    /// another host's messages, whose numbers are their original publisher's.
    pub fn forward(&mut self, msg: T) -> Result<(), BusError> {
        self.publisher
            .send_copy(msg)
            .map_err(|e| err(format!("send on {:?}", self.service), e))?;
        self.notifier
            .notify()
            .map_err(|e| err(format!("notify on {:?}", self.service), e))?;
        Ok(())
    }

    /// The number of messages published so far.
    pub fn published(&self) -> u64 {
        self.sequence
    }
}

/// Receives `T`, counting sequence gaps.
pub struct BusSubscriber<T: Message> {
    subscriber: iceoryx2::port::subscriber::Subscriber<ipc::Service, T, ()>,
    /// The next sequence number expected from each publisher (a topic can have several: the
    /// health topic has one per process).
    next_sequence: Vec<(iceoryx2::identifiers::UniquePublisherId, u64)>,
    gaps: u64,
    service: String,
}

impl<T: Message + Sequenced> BusSubscriber<T> {
    /// The next message, if one is waiting (a copy: the types are small).
    pub fn receive(&mut self) -> Result<Option<T>, BusError> {
        let sample = self
            .subscriber
            .receive()
            .map_err(|e| err(format!("receive on {:?}", self.service), e))?;
        Ok(sample.map(|s| {
            let msg = *s.payload();
            let seq = msg.sequence();
            let publisher = s.header().publisher_id();
            match self.next_sequence.iter_mut().find(|(p, _)| *p == publisher) {
                Some((_, expected)) => {
                    if seq > *expected {
                        self.gaps += seq - *expected;
                    }
                    *expected = seq + 1;
                }
                None => self.next_sequence.push((publisher, seq + 1)),
            }
            msg
        }))
    }

    /// Messages missed so far according to the sequence numbers (count). A publisher restart
    /// (sequence back to 0) is not a gap.
    pub fn gaps(&self) -> u64 {
        self.gaps
    }
}

/// Sleeps until a publisher notifies `listener` or `timeout` passes; returns the notifications
/// seen. A signal (a child process exiting, a SIGINT handled elsewhere) ends the wait early, as a
/// wake-up with no notification.
pub fn wait(
    listener: &iceoryx2::port::listener::Listener<ipc::Service>,
    timeout: Duration,
) -> Result<u64, BusError> {
    use iceoryx2::port::listener::ListenerWaitError;
    match listener.timed_wait(|_| {}, timeout) {
        Ok(n) => Ok(n),
        Err(ListenerWaitError::InterruptSignal) => Ok(0),
        Err(e) => Err(err(format!("wait on {:?}", listener.name()), e)),
    }
}

/// iceoryx2 creates its global management segment (`/dev/shm/iox2_…global_mgmt`) readable and
/// writable by every user, whatever the umask. A segment this process owns loses the permissions
/// of other users (0666 → 0660): the bus stays open to the processes of the deployment's user and
/// group (the units run as `auvnav:auvnav`), and any other user of the host can neither read nor
/// corrupt it. A segment owned by another user is left as it is (it cannot be changed from here).
/// Returns how many segments were restricted.
pub fn restrict_global_segment(shm: &std::path::Path) -> usize {
    use std::os::unix::fs::{MetadataExt, PermissionsExt};
    let me = nix::unistd::geteuid().as_raw();
    let Ok(entries) = std::fs::read_dir(shm) else {
        return 0;
    };
    let mut n = 0;
    for e in entries.flatten() {
        let name = e.file_name();
        let name = name.to_string_lossy();
        if !(name.starts_with("iox2_") && name.ends_with("global_mgmt")) {
            continue;
        }
        let Ok(meta) = e.metadata() else { continue };
        let mode = meta.mode() & 0o777;
        if meta.uid() == me
            && mode & 0o007 != 0
            && std::fs::set_permissions(e.path(), std::fs::Permissions::from_mode(mode & !0o007))
                .is_ok()
        {
            n += 1;
        }
    }
    n
}
