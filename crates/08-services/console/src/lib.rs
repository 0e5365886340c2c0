//! The live browser console: `handeye run --console` and `handeye console` serve one
//! self-contained page (embedded) and a WebSocket that carries the run's typed events (JSON text
//! messages), the latest annotated frame (a downscaled JPEG, binary messages) and the page's
//! commands (STOP, confirm, capture, freedrive, go to the suggested view, finish).
//!
//! Threads: the server is one current-thread tokio runtime on a thread of its own; the run stays
//! on the caller's threads (blocking hardware calls never touch the runtime), frame rendering and
//! the running estimate on an analysis thread ([`observer`]). A slow or closed browser never
//! slows the run: events go out on a `tokio::sync::broadcast` channel whose lagging receivers are
//! dropped (the page reconnects and gets the history again), and frames through a one-slot
//! `watch` channel that only ever holds the latest.
//!
//! The console serves on a loopback address unless the caller asks for more explicitly
//! ([`ConsoleOptions::allow_remote`]), and only to requests that name it as their Host, come
//! from its own page and carry the secret made for this start ([`gate`]); STOP sets the run's
//! stop flag — the very flag Ctrl-C sets.
//! Depends on `cell`, `session`, `plan`, `robot`, `vision`, `solve`, `verdict` and the floor.

mod analysis;
pub mod events;
mod gate;
pub mod manual;
pub mod observer;
mod server;

use std::collections::VecDeque;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{mpsc, Arc, Mutex, MutexGuard};
use std::time::Duration;

pub use events::{Command, ConsoleEvent, PoseState, PoseView};
pub use observer::ConsoleObserver;

/// The address the console serves on unless told otherwise.
pub const DEFAULT_ADDR: &str = "127.0.0.1:8765";

/// Events kept for a page that connects late (or reconnects after lagging): the newest ones.
/// A 1000-pose plan makes about 3000; older events beyond this are dropped, so memory stays
/// bounded however long a session runs.
const HISTORY: usize = 8000;

/// Commands waiting for the run to take them, at most.
const COMMAND_QUEUE: usize = 64;

/// Events a connected page may fall behind by before it is dropped (it reconnects and catches
/// up from the history).
const LAG: usize = 1024;

/// Where and how to serve.
#[derive(Debug, Clone)]
pub struct ConsoleOptions {
    /// The address to listen on (port 0: any free port).
    pub addr: SocketAddr,
    /// Serve on a non-loopback address (the page has a STOP button and, for a manual session,
    /// buttons that move the arm: anyone who can reach it and has the URL with its secret can
    /// use them).
    pub allow_remote: bool,
}

impl Default for ConsoleOptions {
    fn default() -> Self {
        ConsoleOptions {
            addr: SocketAddr::from(([127, 0, 0, 1], 8765)),
            allow_remote: false,
        }
    }
}

/// Why the console could not start.
#[derive(Debug, thiserror::Error)]
pub enum ConsoleError {
    /// A non-loopback address without the explicit permission.
    #[error("console address {addr}: not a loopback address; the console serves only this machine (127.0.0.1, ::1) unless asked: pass --public to serve it on {addr} (anyone who reaches it with the printed URL, secret included, can stop or move the arm)")]
    NotLoopback {
        /// The address asked for.
        addr: SocketAddr,
    },
    /// The address could not be bound.
    #[error(
        "console address {addr}: cannot listen there (in use? choose another with --console ADDR)"
    )]
    Bind {
        /// The address asked for.
        addr: SocketAddr,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The server thread or its runtime could not start.
    #[error("cannot start the console server")]
    Start(#[source] std::io::Error),
}

/// What the server and the run share.
pub(crate) struct Hub {
    events: tokio::sync::broadcast::Sender<Arc<str>>,
    /// Events kept for late pages, each with its snapshot kind (see [`ConsoleEvent::snapshot`]).
    history: Mutex<VecDeque<(Option<&'static str>, Arc<str>)>>,
    frame: tokio::sync::watch::Sender<Option<axum::body::Bytes>>,
    /// Set when the run is over: each page gets what is queued for it, then a Close.
    closing: tokio::sync::watch::Sender<bool>,
    stop: Arc<AtomicBool>,
    /// Bounded: a page that sends commands faster than the run takes them cannot grow it.
    commands: Mutex<mpsc::SyncSender<Command>>,
    report: Mutex<Option<PathBuf>>,
    /// Host, Origin and secret checks.
    gate: gate::Gate,
    /// Pages (WebSockets) connected or being connected.
    pages: AtomicUsize,
    /// Requests refused by the gate (logged in full for the first few only).
    refusals: AtomicUsize,
    /// Accepts that failed on our side (out of descriptors, say).
    accept_failures: AtomicUsize,
    /// Commands dropped because the queue was full.
    dropped_commands: AtomicUsize,
}

/// A page's place among the [`server::MAX_PAGES`]; given back when dropped.
pub(crate) struct Seat(Arc<Hub>);

impl Drop for Seat {
    fn drop(&mut self) {
        self.0.pages.fetch_sub(1, Ordering::SeqCst);
    }
}

/// Whether the `n`-th of a repeated message is logged: the first few, then every thousandth,
/// so a flood of refused requests cannot flood the terminal.
fn log_nth(n: usize) -> bool {
    n <= 5 || n.is_multiple_of(1000)
}

impl Hub {
    /// A seat for one more page, unless [`server::MAX_PAGES`] are taken.
    pub(crate) fn take_seat(self: &Arc<Self>) -> Option<Seat> {
        let taken = self.pages.fetch_add(1, Ordering::SeqCst);
        let seat = Seat(self.clone());
        (taken < server::MAX_PAGES).then_some(seat)
    }

    /// Notes a request the gate refused.
    fn refused(&self, refusal: &gate::Refusal) {
        let n = self.refusals.fetch_add(1, Ordering::Relaxed) + 1;
        if log_nth(n) {
            tracing::warn!("console: {refusal} ({n} refused so far)");
        }
    }

    /// Notes an accept that failed for a reason of ours.
    fn accept_failed(&self, error: &std::io::Error) {
        let n = self.accept_failures.fetch_add(1, Ordering::Relaxed) + 1;
        if log_nth(n) {
            tracing::warn!(
                "console: cannot accept a connection ({error}; {n} so far): the run goes on"
            );
        }
    }

    /// How many pages are connected.
    fn clients(&self) -> usize {
        self.events.receiver_count()
    }

    fn history(&self) -> MutexGuard<'_, VecDeque<(Option<&'static str>, Arc<str>)>> {
        // A panic elsewhere while holding it leaves plain data: keep serving.
        self.history.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The history so far and a receiver for everything after it (taken under one lock, so no
    /// event is missed or doubled).
    pub(crate) fn subscribe(&self) -> (Vec<Arc<str>>, tokio::sync::broadcast::Receiver<Arc<str>>) {
        let history = self.history();
        (
            history.iter().map(|(_, text)| text.clone()).collect(),
            self.events.subscribe(),
        )
    }

    fn publish(&self, snapshot: Option<&'static str>, text: Arc<str>) {
        let mut history = self.history();
        // A snapshot (the estimate, the coverage, ...) replaces the one before: a late page
        // needs only the newest, and the history stays small however long the run.
        if snapshot.is_some() {
            history.retain(|(kind, _)| *kind != snapshot);
        }
        if history.len() == HISTORY {
            history.pop_front();
        }
        history.push_back((snapshot, text.clone()));
        // No page connected is fine.
        let _ = self.events.send(text);
    }

    /// A command from a page. STOP sets the stop flag here, at once: the run sees it even while
    /// it is busy and not reading commands.
    pub(crate) fn command(&self, command: Command) {
        if command == Command::Stop {
            self.stop.store(true, Ordering::SeqCst);
        }
        let sender = self.commands.lock().unwrap_or_else(|e| e.into_inner());
        // A full queue means commands arrive faster than a person could mean them: the extra
        // ones are dropped (STOP has already set the flag above).
        if let Err(mpsc::TrySendError::Full(command)) = sender.try_send(command) {
            let n = self.dropped_commands.fetch_add(1, Ordering::Relaxed) + 1;
            if log_nth(n) {
                tracing::warn!("console: {command:?} dropped: {COMMAND_QUEUE} commands are waiting for the run ({n} dropped so far)");
            }
        }
    }

    pub(crate) fn frames(&self) -> tokio::sync::watch::Receiver<Option<axum::body::Bytes>> {
        self.frame.subscribe()
    }

    pub(crate) fn closing(&self) -> tokio::sync::watch::Receiver<bool> {
        self.closing.subscribe()
    }

    pub(crate) fn report(&self) -> Option<PathBuf> {
        self.report
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }
}

/// A running console. Dropping it stops the server.
pub struct Console {
    addr: SocketAddr,
    hub: Arc<Hub>,
    commands: Mutex<mpsc::Receiver<Command>>,
    shutdown: Option<tokio::sync::oneshot::Sender<()>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Console {
    /// Binds `options.addr` (refusing a non-loopback address unless allowed) and serves the page
    /// on a thread of its own. STOP on the page sets `stop`.
    pub fn start(options: &ConsoleOptions, stop: Arc<AtomicBool>) -> Result<Console, ConsoleError> {
        if !options.addr.ip().is_loopback() && !options.allow_remote {
            return Err(ConsoleError::NotLoopback { addr: options.addr });
        }
        let listener =
            std::net::TcpListener::bind(options.addr).map_err(|source| ConsoleError::Bind {
                addr: options.addr,
                source,
            })?;
        listener
            .set_nonblocking(true)
            .map_err(ConsoleError::Start)?;
        let addr = listener.local_addr().map_err(ConsoleError::Start)?;
        let (commands_tx, commands_rx) = mpsc::sync_channel(COMMAND_QUEUE);
        let hub = Arc::new(Hub {
            events: tokio::sync::broadcast::channel(LAG).0,
            history: Mutex::new(VecDeque::new()),
            frame: tokio::sync::watch::channel(None).0,
            closing: tokio::sync::watch::channel(false).0,
            stop,
            commands: Mutex::new(commands_tx),
            report: Mutex::new(None),
            gate: gate::Gate::new(addr, options.allow_remote),
            pages: AtomicUsize::new(0),
            refusals: AtomicUsize::new(0),
            accept_failures: AtomicUsize::new(0),
            dropped_commands: AtomicUsize::new(0),
        });
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_io()
            .enable_time()
            .build()
            .map_err(ConsoleError::Start)?;
        let (shutdown_tx, shutdown_rx) = tokio::sync::oneshot::channel();
        let server_hub = hub.clone();
        let thread = std::thread::Builder::new()
            .name("console".into())
            .spawn(move || server::serve(runtime, listener, server_hub, shutdown_rx))
            .map_err(ConsoleError::Start)?;
        Ok(Console {
            addr,
            hub,
            commands: Mutex::new(commands_rx),
            shutdown: Some(shutdown_tx),
            thread: Some(thread),
        })
    }

    /// The address served (with the real port when 0 was asked for).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The page's URL, with the secret every request must carry.
    pub fn url(&self) -> String {
        format!(
            "http://{}/?{}={}",
            self.addr,
            gate::TOKEN_PARAM,
            self.hub.gate.token()
        )
    }

    /// The secret of this start (in [`Console::url`]; a page passes it on its WebSocket as
    /// `/ws?token=…`).
    pub fn token(&self) -> &str {
        self.hub.gate.token()
    }

    /// Whether the console serves beyond this machine.
    pub fn is_remote(&self) -> bool {
        !self.addr.ip().is_loopback()
    }

    /// Sends an event to every page (and keeps it for pages that connect later).
    pub fn publish(&self, event: &ConsoleEvent) {
        self.publisher().publish(event);
    }

    /// Replaces the latest frame (a JPEG); pages that have not shown the previous one yet skip it.
    pub fn set_frame(&self, jpeg: Vec<u8>) {
        self.publisher().set_frame(jpeg);
    }

    /// A handle other threads publish with.
    pub fn publisher(&self) -> Publisher {
        Publisher(self.hub.clone())
    }

    /// The report the page's link serves (`/report`).
    pub fn set_report(&self, path: PathBuf) {
        *self.hub.report.lock().unwrap_or_else(|e| e.into_inner()) = Some(path);
    }

    /// The stop flag STOP sets.
    pub fn stop_flag(&self) -> Arc<AtomicBool> {
        self.hub.stop.clone()
    }

    /// Pages connected now.
    pub fn clients(&self) -> usize {
        self.hub.clients()
    }

    /// The next command from a page, waiting up to `timeout`.
    pub fn next_command(&self, timeout: Duration) -> Option<Command> {
        let commands = self.commands.lock().unwrap_or_else(|e| e.into_inner());
        commands.recv_timeout(timeout).ok()
    }

    /// A sender that feeds the same command queue (the terminal's Enter, say).
    pub fn command_sender(&self) -> CommandSender {
        CommandSender(self.hub.clone())
    }

    /// Ends the pages' connections: each gets every event published so far and the latest
    /// frame, then a Close; returns when all have (at once with no page), or after `timeout`.
    /// Publishing after this reaches no page.
    pub fn close(&self, timeout: Duration) {
        self.hub.closing.send_replace(true);
        let deadline = std::time::Instant::now() + timeout;
        while self.clients() > 0 && std::time::Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// Waits up to `timeout` for a page to connect.
    pub fn wait_for_client(&self, timeout: Duration) -> bool {
        let deadline = std::time::Instant::now() + timeout;
        while self.clients() == 0 {
            if std::time::Instant::now() >= deadline {
                return false;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        true
    }
}

/// Publishes events and frames to a console's pages, from any thread.
#[derive(Clone)]
pub struct Publisher(Arc<Hub>);

impl Publisher {
    /// Sends an event to every page (and keeps it for pages that connect later).
    pub fn publish(&self, event: &ConsoleEvent) {
        match serde_json::to_string(event) {
            Ok(text) => self.0.publish(event.snapshot(), text.into()),
            Err(e) => tracing::warn!("console event not serialisable: {e}"),
        }
    }

    /// Replaces the latest frame (a JPEG).
    pub fn set_frame(&self, jpeg: Vec<u8>) {
        self.0.frame.send_replace(Some(jpeg.into()));
    }

    /// Whether a page is connected (frames for nobody are not worth rendering).
    pub fn watched(&self) -> bool {
        self.0.clients() > 0
    }
}

/// Feeds commands to a console as a page would (the terminal's Enter for a capture, say).
#[derive(Clone)]
pub struct CommandSender(Arc<Hub>);

impl CommandSender {
    /// Sends `command` (STOP also sets the stop flag).
    pub fn send(&self, command: Command) {
        self.0.command(command);
    }
}

impl Drop for Console {
    fn drop(&mut self) {
        if let Some(shutdown) = self.shutdown.take() {
            let _ = shutdown.send(());
        }
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}
