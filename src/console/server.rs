//! The HTTP side of the console: the page (`/`), the WebSocket (`/ws`) and the report
//! (`/report`), on the console's own current-thread runtime. Each page gets the event history,
//! then live events and the latest frame; a page that falls [`super::LAG`] events behind is
//! disconnected (it reconnects and catches up) so it can never hold the run back.

use std::sync::Arc;

use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::State;
use axum::http::StatusCode;
use axum::response::{Html, IntoResponse, Response};
use axum::routing::get;
use axum::Router;
use tokio::sync::broadcast::error::RecvError;

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
const SEND_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(2);

/// Sends one message; `false` when the page is gone or did not take it within [`SEND_TIMEOUT`].
async fn send(socket: &mut WebSocket, message: Message) -> bool {
    matches!(
        tokio::time::timeout(SEND_TIMEOUT, socket.send(message)).await,
        Ok(Ok(()))
    )
}

/// One page: history first, then events, frames and commands until either side goes.
async fn client(mut socket: WebSocket, hub: Arc<Hub>) {
    let (history, mut events) = hub.subscribe();
    for text in history {
        if !send(&mut socket, Message::Text(text.as_ref().into())).await {
            return;
        }
    }
    let mut frames = hub.frames();
    // The frame already there is news to a new page.
    frames.mark_changed();
    loop {
        tokio::select! {
            event = events.recv() => match event {
                Ok(text) => {
                    if !send(&mut socket, Message::Text(text.as_ref().into())).await {
                        return;
                    }
                }
                // Too slow a page is dropped rather than waited for; it reconnects.
                Err(RecvError::Lagged(_)) => {
                    send(&mut socket, Message::Close(None)).await;
                    return;
                }
                Err(RecvError::Closed) => return,
            },
            changed = frames.changed() => {
                if changed.is_err() {
                    return;
                }
                let frame = frames.borrow_and_update().clone();
                if let Some(jpeg) = frame {
                    if !send(&mut socket, Message::Binary(jpeg)).await {
                        return;
                    }
                }
            }
            message = socket.recv() => match message {
                Some(Ok(Message::Text(text))) => match serde_json::from_str::<Command>(text.as_str()) {
                    Ok(command) => hub.command(command),
                    Err(e) => tracing::warn!("console: unknown command {text:?}: {e}"),
                },
                Some(Ok(_)) => {}
                Some(Err(_)) | None => return,
            },
        }
    }
}
