//! The HTTP side of the console: the page (`/`), the WebSocket (`/ws`) and the report
//! (`/report`), on the console's own current-thread runtime. Each page gets the event history,
//! then live events and the latest frame; a page that falls [`super::LAG`] events behind is
//! disconnected (it reconnects and catches up) so it can never hold the run back.

use std::sync::Arc;
use std::time::Duration;

use axum::body::Bytes;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::State;
use axum::http::StatusCode;
use axum::response::{Html, IntoResponse, Response};
use axum::routing::get;
use axum::Router;
use futures_util::stream::{SplitSink, SplitStream};
use futures_util::{SinkExt, StreamExt};
use tokio::sync::broadcast::error::RecvError;
use tokio::sync::watch;

use super::events::Command;
use super::Hub;

/// The page: one self-contained HTML file (styles and script inline, no external requests).
const PAGE: &str = include_str!("page.html");

/// Serves until `shutdown` fires (or its sender is dropped); then the runtime and every
/// connection go with it.
pub(super) fn serve(
    runtime: tokio::runtime::Runtime,
    listener: std::net::TcpListener,
    hub: Arc<Hub>,
    shutdown: tokio::sync::oneshot::Receiver<()>,
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
            .with_state(hub);
        let server = std::future::IntoFuture::into_future(axum::serve(listener, app));
        tokio::select! {
            result = server => {
                if let Err(e) = result {
                    tracing::error!("console: server stopped: {e}");
                }
            }
            _ = shutdown => {}
        }
    });
    // A report read still under way (a blocking task) must not hold the process's exit.
    runtime.shutdown_timeout(Duration::from_secs(1));
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
    upgrade.on_upgrade(move |socket| client(socket, hub))
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
/// which then ends the stream.)
async fn read_commands(mut stream: SplitStream<WebSocket>, hub: Arc<Hub>) {
    while let Some(Ok(message)) = stream.next().await {
        if let Message::Text(text) = message {
            match serde_json::from_str::<Command>(text.as_str()) {
                Ok(command) => hub.command(command),
                Err(e) => tracing::warn!("console: unknown command {text:?}: {e}"),
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
