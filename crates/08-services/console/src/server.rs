//! The HTTP side of the console: the page (`/`), the WebSocket (`/ws`) and the report
//! (`/report`), on the console's own current-thread runtime. Each page gets the event history,
//! then live events and the latest frame; a page that falls [`super::LAG`] events behind is
//! disconnected (it reconnects and catches up) so it can never hold the run back.
//!
//! Every request passes the [`Gate`](super::gate::Gate) (Host, Origin, the secret) first; a
//! refused request closes its connection. The server holds at most [`MAX_CONNECTIONS`]
//! connections and [`MAX_PAGES`] pages at a time, gives a request [`HEADER_TIMEOUT`] to send its
//! headers (also the idle deadline of a kept-alive connection), a blocked write at most
//! [`WRITE_TIMEOUT`] (a client that stops reading its answers gives its slot back) and a page's
//! message at most [`MAX_COMMAND_BYTES`]: however many connections a client opens, the run keeps
//! its file descriptors (further connections wait in the kernel's accept queue). When every slot
//! is taken, [`RESERVED_SLOTS`] more open, where a connection lives only while its requests carry
//! the secret: 1 s to send its headers, closed at its first refused request (issue #40: 64
//! connections that pipelined requests and never read held every slot, and the STOP page could
//! not be opened).

use std::sync::Arc;
use std::time::Duration;

use axum::body::Bytes;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{Request, State};
use axum::http::{header, HeaderValue, StatusCode};
use axum::middleware::{self, Next};
use axum::response::{Html, IntoResponse, Response};
use axum::routing::get;
use axum::Router;
use futures_util::stream::{SplitSink, SplitStream};
use futures_util::{SinkExt, StreamExt};
use tokio::sync::broadcast::error::RecvError;
use tokio::sync::{watch, Semaphore};

use super::events::Command;
use super::Hub;

/// The page: one self-contained HTML file (styles and script inline, no external requests).
const PAGE: &str = include_str!("page.html");

/// Connections open at once (pages, page loads, report reads, and whatever else connects).
pub(super) const MAX_CONNECTIONS: usize = 64;

/// Pages (WebSockets) connected at once.
pub(super) const MAX_PAGES: usize = 16;

/// The largest message a page may send: commands are a few dozen bytes.
pub(super) const MAX_COMMAND_BYTES: usize = 4096;

/// Messages that are no command a page may send before it is dropped.
const MAX_BAD_MESSAGES: usize = 16;

/// How long a connection may take to send a request's headers (a client that opens connections
/// and sends nothing gives its slot back after this).
const HEADER_TIMEOUT: Duration = Duration::from_secs(5);

/// How long a write may stay blocked (the client reads nothing of its answers) before the
/// connection is closed.
const WRITE_TIMEOUT: Duration = Duration::from_secs(10);

/// Slots beyond [`MAX_CONNECTIONS`], taken only when those are all in use: a connection on one
/// must send its headers within [`RESERVED_HEADER_TIMEOUT`], and a request the gate refuses
/// (no secret, a foreign Host or Origin) closes it, as on every slot.
pub(super) const RESERVED_SLOTS: usize = 4;

/// Header deadline on a reserved slot: a browser sends its request at once.
const RESERVED_HEADER_TIMEOUT: Duration = Duration::from_secs(1);

/// Pause after a failed accept that is not the client's doing (out of file descriptors: the
/// connections closing meanwhile give some back).
const ACCEPT_BACKOFF: Duration = Duration::from_millis(50);

/// Serves until `shutdown` fires (or its sender is dropped); then the runtime and every
/// connection go with it.
pub(super) fn serve(
    runtime: tokio::runtime::Runtime,
    listener: std::net::TcpListener,
    hub: Arc<Hub>,
    mut shutdown: tokio::sync::oneshot::Receiver<()>,
) {
    runtime.block_on(async move {
        let listener = match tokio::net::TcpListener::from_std(listener) {
            Ok(listener) => listener,
            Err(e) => {
                tracing::error!("console: cannot serve: {e}");
                return;
            }
        };
        let app = Router::new()
            .route("/", get(page))
            .route("/ws", get(socket))
            .route("/report", get(report))
            .layer(middleware::from_fn_with_state(hub.clone(), gate))
            .with_state(hub.clone());
        let slots = Arc::new(Semaphore::new(MAX_CONNECTIONS));
        let reserved = Arc::new(Semaphore::new(RESERVED_SLOTS));
        loop {
            // A free slot first: until one is, connections wait in the kernel's queue and take
            // no descriptor of ours. The reserved ones only when every other is taken.
            let (slot, header_timeout) = tokio::select! {
                biased;
                _ = &mut shutdown => break,
                slot = slots.clone().acquire_owned() => (slot, HEADER_TIMEOUT),
                slot = reserved.clone().acquire_owned() => (slot, RESERVED_HEADER_TIMEOUT),
            };
            let Ok(slot) = slot else { break };
            let stream = tokio::select! {
                accepted = listener.accept() => match accepted {
                    Ok((stream, _)) => stream,
                    Err(e) => {
                        hub.accept_failed(&e);
                        tokio::time::sleep(ACCEPT_BACKOFF).await;
                        continue;
                    }
                },
                _ = &mut shutdown => break,
            };
            let app = app.clone();
            tokio::spawn(async move {
                let _slot = slot;
                let mut http = hyper::server::conn::http1::Builder::new();
                // The deadline also runs while a kept-alive connection waits for its next
                // request, so an idle one gives its slot back too.
                http.timer(hyper_util::rt::TokioTimer::new())
                    .header_read_timeout(header_timeout);
                let connection = http
                    .serve_connection(
                        hyper_util::rt::TokioIo::new(WriteDeadline::new(stream)),
                        hyper_util::service::TowerToHyperService::new(app),
                    )
                    .with_upgrades();
                // A client that goes away mid-request is its own business.
                let _ = connection.await;
            });
        }
    });
    // A report read still under way (a blocking task) must not hold the process's exit.
    runtime.shutdown_timeout(Duration::from_secs(1));
}

/// Every request passes here first: Host, Origin and the secret ([`super::gate`]); what passes
/// gets headers that keep the page out of caches, frames and Referer lines (its URL holds the
/// secret).
async fn gate(State(hub): State<Arc<Hub>>, request: Request, next: Next) -> Response {
    let headers = request.headers();
    let text = |name| {
        headers
            .get(name)
            .map(|value: &HeaderValue| value.to_str().unwrap_or("(not text)"))
    };
    // An absolute-form target (`GET http://other.example/… HTTP/1.1`) names the host the
    // request is for, before any Host header (RFC 9112 §3.2.2): it must name this console too.
    let host = match request.uri().authority() {
        Some(authority) => Some(authority.as_str()),
        None => text(header::HOST),
    };
    let verdict = hub.gate.check(
        host,
        text(header::ORIGIN),
        request.uri().query(),
        headers.contains_key(header::UPGRADE),
    );
    if let Err(refusal) = verdict {
        hub.refused(&refusal);
        // The connection goes with the refusal: requests pipelined behind it are not read.
        return (
            refusal.status(),
            [(header::CONNECTION, "close")],
            refusal.to_string(),
        )
            .into_response();
    }
    let mut response = next.run(request).await;
    let headers = response.headers_mut();
    for (name, value) in [
        (header::CACHE_CONTROL, "no-store"),
        (header::REFERRER_POLICY, "no-referrer"),
        (header::X_FRAME_OPTIONS, "DENY"),
        (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
    ] {
        headers.insert(name, HeaderValue::from_static(value));
    }
    response
}

async fn page() -> Html<&'static str> {
    Html(PAGE)
}

async fn report(State(hub): State<Arc<Hub>>) -> Response {
    let Some(path) = hub.report() else {
        return (
            StatusCode::NOT_FOUND,
            "no report yet: it is written when the run ends",
        )
            .into_response();
    };
    // File reads block: off the runtime's thread.
    let read = {
        let path = path.clone();
        tokio::task::spawn_blocking(move || std::fs::read_to_string(path)).await
    };
    match read {
        Ok(Ok(text)) => Html(text).into_response(),
        Ok(Err(e)) => (
            StatusCode::NOT_FOUND,
            format!("report {}: {e}", path.display()),
        )
            .into_response(),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, e.to_string()).into_response(),
    }
}

async fn socket(upgrade: WebSocketUpgrade, State(hub): State<Arc<Hub>>) -> Response {
    let Some(seat) = hub.take_seat() else {
        return (
            StatusCode::SERVICE_UNAVAILABLE,
            format!("{MAX_PAGES} pages are open on this console already: close one"),
        )
            .into_response();
    };
    upgrade
        .max_message_size(MAX_COMMAND_BYTES)
        .max_frame_size(MAX_COMMAND_BYTES)
        .on_upgrade(move |socket| async move {
            let _seat = seat;
            client(socket, hub).await
        })
}

/// How long one message may wait for a page's socket to take it: a page that stops reading fills
/// the socket buffers and would hold its task (and its lag) forever; it is dropped instead, and
/// reconnects with the history.
const SEND_TIMEOUT: Duration = Duration::from_secs(2);

/// How long a page's commands are still read once nothing more is sent to it: a page closed
/// right after STOP resets the connection, and the STOP it sent is still to be read.
const READ_GRACE: Duration = Duration::from_secs(1);

type PageSink = SplitSink<WebSocket, Message>;

/// Sends one message; `false` when the page is gone or did not take it within [`SEND_TIMEOUT`].
async fn send(sink: &mut PageSink, message: Message) -> bool {
    matches!(
        tokio::time::timeout(SEND_TIMEOUT, sink.send(message)).await,
        Ok(Ok(()))
    )
}

/// One page. Its commands are read on a task of their own, so a STOP is taken at once even while
/// a send to the page waits, and even when the page is gone before the send fails; events and
/// frames go out here until either side ends.
async fn client(socket: WebSocket, hub: Arc<Hub>) {
    let (mut sink, stream) = socket.split();
    let mut reader = tokio::spawn(read_commands(stream, hub.clone()));
    tokio::select! {
        _ = send_events(&mut sink, &hub) => {}
        // The page went.
        _ = &mut reader => return,
    }
    if tokio::time::timeout(READ_GRACE, &mut reader).await.is_err() {
        reader.abort();
    }
}

/// The page's commands, until it goes. (A Close from the page is answered by the next read,
/// which then ends the stream.) The first message that is no command is logged, shortened; a
/// page that sends [`MAX_BAD_MESSAGES`] of them, or one larger than [`MAX_COMMAND_BYTES`] (the
/// socket ends with an error), is dropped.
async fn read_commands(mut stream: SplitStream<WebSocket>, hub: Arc<Hub>) {
    let mut bad = 0;
    while let Some(Ok(message)) = stream.next().await {
        let text = match message {
            Message::Text(text) => text,
            Message::Binary(_) => "(binary message)".into(),
            // Ping, pong and close are the socket's own.
            _ => continue,
        };
        match serde_json::from_str::<Command>(text.as_str()) {
            Ok(command) => hub.command(command),
            Err(e) => {
                bad += 1;
                if bad == 1 {
                    // Both shortened: serde's message quotes what it could not read.
                    tracing::warn!(
                        "console: a page sent what is no command ({}): {}; further ones from this page are not logged",
                        super::gate::shortened(text.as_str()),
                        super::gate::shortened(&e.to_string())
                    );
                }
                if bad == MAX_BAD_MESSAGES {
                    tracing::warn!(
                        "console: dropped a page that sent {MAX_BAD_MESSAGES} messages that are no command"
                    );
                    return;
                }
            }
        }
    }
}

/// History first, then live events and the latest frame, until the run is over (what is queued
/// goes out, then a Close), the page falls too far behind or a send fails.
async fn send_events(sink: &mut PageSink, hub: &Hub) {
    let (history, mut events) = hub.subscribe();
    for text in history {
        if !send(sink, Message::Text(text.as_ref().into())).await {
            return;
        }
    }
    let mut frames = hub.frames();
    // The frame already there is news to a new page.
    frames.mark_changed();
    let mut closing = hub.closing();
    loop {
        tokio::select! {
            // The run is over: what is queued goes out, then a Close (the page keeps its state).
            _ = async { closing.wait_for(|&closed| closed).await.is_ok() } => {
                while let Ok(text) = events.try_recv() {
                    if !send(sink, Message::Text(text.as_ref().into())).await {
                        return;
                    }
                }
                if frames.has_changed().unwrap_or(false) && !send_latest_frame(sink, &mut frames).await {
                    return;
                }
                send(sink, Message::Close(None)).await;
                return;
            }
            event = events.recv() => match event {
                Ok(text) => {
                    if !send(sink, Message::Text(text.as_ref().into())).await {
                        return;
                    }
                }
                // Too slow a page is dropped rather than waited for; it reconnects.
                Err(RecvError::Lagged(_)) => {
                    send(sink, Message::Close(None)).await;
                    return;
                }
                Err(RecvError::Closed) => return,
            },
            changed = frames.changed() => {
                if changed.is_err() || !send_latest_frame(sink, &mut frames).await {
                    return;
                }
            }
        }
    }
}

/// Sends the latest frame, if there is one; `false` when the page did not take it.
async fn send_latest_frame(
    sink: &mut PageSink,
    frames: &mut watch::Receiver<Option<Bytes>>,
) -> bool {
    let frame = frames.borrow_and_update().clone();
    match frame {
        Some(jpeg) => send(sink, Message::Binary(jpeg)).await,
        None => true,
    }
}

/// A connection whose writes may stay blocked at most [`WRITE_TIMEOUT`]: a client that stops
/// reading its answers (they pile up in the socket's buffers) gets an error on the write, so
/// hyper closes the connection and its slot comes back. Reads pass through (their deadline is
/// hyper's header timeout).
struct WriteDeadline {
    stream: tokio::net::TcpStream,
    /// Armed when a write first finds the socket full; cleared when one goes through.
    stalled: Option<std::pin::Pin<Box<tokio::time::Sleep>>>,
}

impl WriteDeadline {
    fn new(stream: tokio::net::TcpStream) -> WriteDeadline {
        WriteDeadline {
            stream,
            stalled: None,
        }
    }

    /// `poll` on the stream, with the deadline run while it is pending.
    fn deadlined<T>(
        &mut self,
        cx: &mut std::task::Context<'_>,
        poll: impl FnOnce(
            std::pin::Pin<&mut tokio::net::TcpStream>,
            &mut std::task::Context<'_>,
        ) -> std::task::Poll<std::io::Result<T>>,
    ) -> std::task::Poll<std::io::Result<T>> {
        use std::future::Future;
        use std::task::Poll;
        match poll(std::pin::Pin::new(&mut self.stream), cx) {
            Poll::Ready(result) => {
                self.stalled = None;
                Poll::Ready(result)
            }
            Poll::Pending => {
                let stalled = self
                    .stalled
                    .get_or_insert_with(|| Box::pin(tokio::time::sleep(WRITE_TIMEOUT)));
                match stalled.as_mut().poll(cx) {
                    Poll::Ready(()) => Poll::Ready(Err(std::io::Error::new(
                        std::io::ErrorKind::TimedOut,
                        "the client read nothing of its answers for the write deadline",
                    ))),
                    Poll::Pending => Poll::Pending,
                }
            }
        }
    }
}

impl tokio::io::AsyncRead for WriteDeadline {
    fn poll_read(
        self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &mut tokio::io::ReadBuf<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.get_mut().stream).poll_read(cx, buf)
    }
}

impl tokio::io::AsyncWrite for WriteDeadline {
    fn poll_write(
        self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &[u8],
    ) -> std::task::Poll<std::io::Result<usize>> {
        self.get_mut()
            .deadlined(cx, |stream, cx| stream.poll_write(cx, buf))
    }

    fn poll_write_vectored(
        self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        bufs: &[std::io::IoSlice<'_>],
    ) -> std::task::Poll<std::io::Result<usize>> {
        self.get_mut()
            .deadlined(cx, |stream, cx| stream.poll_write_vectored(cx, bufs))
    }

    fn is_write_vectored(&self) -> bool {
        self.stream.is_write_vectored()
    }

    fn poll_flush(
        self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        self.get_mut()
            .deadlined(cx, |stream, cx| stream.poll_flush(cx))
    }

    fn poll_shutdown(
        self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.get_mut().stream).poll_shutdown(cx)
    }
}
