//! Logging of the on-board processes (daemon, drivers, recorder) through `tracing`.
//!
//! - Levels and targets from `RUST_LOG` (`tracing-subscriber`'s filter syntax, e.g.
//!   `RUST_LOG=debug` or `RUST_LOG=info,auvnavd=debug`); `info` when unset or unreadable.
//! - Output on standard error. Under systemd (`JOURNAL_STREAM` set: standard error is the
//!   journal) each line starts with the syslog priority `<N>` that journald turns into the entry's
//!   priority, and carries no time stamp or colour (the journal has its own); on a terminal or in
//!   a file, lines carry the UTC time and the level.
//! - Structured fields (`device = "/dev/ttyUSB0"`, `lost = 3`) follow the message as
//!   `key=value`.
//! - iceoryx2's own events (built with its `tracing` feature) go through the same subscriber,
//!   under the target `iceoryx2_bb_loggers::tracing`; their level is `IOX2_LOG_LEVEL` (default
//!   `warn`), filtered again by `RUST_LOG`.

use std::fmt;
use tracing::{Event, Level, Subscriber};
use tracing_subscriber::fmt::format::{FormatEvent, FormatFields, Writer};
use tracing_subscriber::fmt::{FmtContext, FormattedFields};
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::registry::LookupSpan;
use tracing_subscriber::util::SubscriberInitExt;
use tracing_subscriber::{EnvFilter, Layer, Registry};

/// The syslog priority journald reads from a `<N>` line prefix.
fn syslog_priority(level: &Level) -> u8 {
    match *level {
        Level::ERROR => 3,
        Level::WARN => 4,
        Level::INFO => 6,
        Level::DEBUG | Level::TRACE => 7,
    }
}

/// One line per event for the journal: `<N>message key=value ...` (span fields first).
struct JournalFormat;

impl<S, N> FormatEvent<S, N> for JournalFormat
where
    S: Subscriber + for<'a> LookupSpan<'a>,
    N: for<'a> FormatFields<'a> + 'static,
{
    fn format_event(
        &self,
        ctx: &FmtContext<'_, S, N>,
        mut writer: Writer<'_>,
        event: &Event<'_>,
    ) -> fmt::Result {
        let meta = event.metadata();
        write!(writer, "<{}>", syslog_priority(meta.level()))?;
        if !meta.target().starts_with("auvnav") {
            // Events of libraries (iceoryx2) name where they come from.
            write!(writer, "{}: ", meta.target())?;
        }
        if let Some(scope) = ctx.event_scope() {
            for span in scope.from_root() {
                if let Some(fields) = span.extensions().get::<FormattedFields<N>>()
                    && !fields.is_empty()
                {
                    write!(writer, "{fields} ")?;
                }
            }
        }
        ctx.field_format().format_fields(writer.by_ref(), event)?;
        writeln!(writer)
    }
}

/// Installs the subscriber for a process (call once, first thing in `main`). A second call, or a
/// subscriber already installed (tests), is ignored.
pub fn init() {
    init_with(None);
}

/// Ignores SIGHUP in this process (and the programs it starts): the on-board processes offer no
/// configuration reload, and a hang-up (a closed terminal, a stray `kill -HUP`) must not end
/// navigation. Only SIGTERM and SIGINT stop them. Called first thing by [`init`]. (Blocking the
/// signal is not enough: a blocked mask does not survive every library's threads.)
pub fn ignore_hangup() {
    use nix::sys::signal::{SigHandler, Signal, signal};
    // SAFETY: SIG_IGN installs no handler, so no code runs in signal context; the previous
    // disposition (the default, terminate) is not needed.
    let _ = unsafe { signal(Signal::SIGHUP, SigHandler::SigIgn) };
}

/// A layer given to [`init_with`]: it sees every event of every level, before `RUST_LOG`'s filter
/// (which applies to the printed lines only), and should filter for itself.
pub type ExtraLayer = Box<dyn Layer<Registry> + Send + Sync + 'static>;

/// [`init`] with one more layer beside the printed lines: a process counting a library's
/// reports (the live view counts the WebSocket server's slow-client reports), say.
pub fn init_with(extra: Option<ExtraLayer>) {
    ignore_hangup();
    use iceoryx2::prelude::{LogLevel, set_log_level_from_env_or};
    set_log_level_from_env_or(LogLevel::Warn);
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    let journal = std::env::var_os("JOURNAL_STREAM").is_some();
    let lines: ExtraLayer = if journal {
        tracing_subscriber::fmt::layer()
            .with_writer(std::io::stderr)
            .with_ansi(false)
            .event_format(JournalFormat)
            .with_filter(filter)
            .boxed()
    } else {
        tracing_subscriber::fmt::layer()
            .with_writer(std::io::stderr)
            .with_ansi(false)
            .with_target(false)
            .with_timer(tracing_subscriber::fmt::time::SystemTime)
            .with_filter(filter)
            .boxed()
    };
    let mut layers = vec![lines];
    layers.extend(extra);
    let _ = tracing_subscriber::registry().with(layers).try_init();
}
