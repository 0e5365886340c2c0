//! A `handeye` process serving the live console, driven from a test: its console URL (with the
//! secret) read from what it prints, its output collected, its end awaited.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// How long any one step may take (debug build on a loaded 2-core machine).
pub const STEP: Duration = Duration::from_secs(60);

/// A `handeye` process serving the console; its stdout and stderr collected.
pub struct Live {
    child: Child,
    lines: mpsc::Receiver<String>,
    output: Vec<String>,
}

impl Live {
    /// Starts `handeye ARGS` in `cwd`.
    pub fn start(args: &[&str], cwd: &Path) -> Live {
        Live::spawn(super::handeye().args(args).current_dir(cwd))
    }

    /// Starts a new hand-guided session of `config` into `session` on the console
    /// (`handeye console --config CONFIG --output SESSION --addr 127.0.0.1:0`) in `cwd`.
    pub fn console(config: &Path, session: &Path, cwd: &Path) -> Live {
        Live::spawn(&mut console_command(config, session, cwd))
    }

    /// Starts `command` (a `handeye` command, or a shell that execs one).
    pub fn spawn(command: &mut Command) -> Live {
        let mut child = command
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("handeye starts");
        let (tx, lines) = mpsc::channel();
        let stdout = child.stdout.take().expect("piped");
        let stderr = child.stderr.take().expect("piped");
        for stream in [
            Box::new(stdout) as Box<dyn std::io::Read + Send>,
            Box::new(stderr),
        ] {
            let tx = tx.clone();
            std::thread::spawn(move || {
                for line in BufReader::new(stream).lines().map_while(Result::ok) {
                    let _ = tx.send(line);
                }
            });
        }
        Live {
            child,
            lines,
            output: Vec::new(),
        }
    }

    /// The console URL it prints.
    pub fn url(&mut self) -> String {
        let deadline = Instant::now() + STEP;
        while let Ok(line) = self.lines.recv_timeout(deadline - Instant::now()) {
            self.output.push(line.clone());
            if let Some(url) = line.strip_prefix("console: ") {
                return url.trim().to_string();
            }
        }
        panic!(
            "no console URL within {STEP:?}:\n{}",
            self.output.join("\n")
        );
    }

    /// Whether the process is still running.
    pub fn running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    /// Waits for the process to end: its success and everything it printed.
    pub fn finish(mut self) -> (bool, String) {
        let deadline = Instant::now() + STEP;
        let status = loop {
            if let Some(status) = self.child.try_wait().expect("waits") {
                break status;
            }
            if Instant::now() >= deadline {
                let _ = self.child.kill();
                while let Ok(line) = self.lines.recv_timeout(Duration::from_secs(5)) {
                    self.output.push(line);
                }
                panic!(
                    "handeye did not end within {STEP:?}:\n{}",
                    self.output.join("\n")
                );
            }
            std::thread::sleep(Duration::from_millis(50));
        };
        // The readers end with the pipes.
        while let Ok(line) = self.lines.recv_timeout(Duration::from_secs(5)) {
            self.output.push(line);
        }
        (status.success(), self.output.join("\n"))
    }
}

impl Drop for Live {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        // A failing test shows what handeye said (a console that closed under a page: why).
        if std::thread::panicking() {
            self.output.extend(self.lines.try_iter());
            eprintln!("handeye's output:\n{}", self.output.join("\n"));
        }
    }
}

/// A WebSocket client's connection to the console (tokio-tungstenite).
pub type Socket =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

/// The console's page, as a WebSocket client (no browser): sends commands, waits for events.
pub struct Page {
    ws: Socket,
}

impl Page {
    /// Connects to the console at `url` (the printed URL, with its secret).
    pub async fn open(url: &str) -> Page {
        let (ws, _) = tokio_tungstenite::connect_async(super::console_socket(url))
            .await
            .expect("the console accepts a WebSocket");
        Page { ws }
    }

    /// Sends `{"cmd": cmd}`.
    pub async fn send(&mut self, cmd: &str) {
        self.send_json(serde_json::json!({ "cmd": cmd })).await;
    }

    /// Sends a command with its fields (`{"cmd": "freedrive", "on": true}`).
    pub async fn send_json(&mut self, command: serde_json::Value) {
        use futures_util::SinkExt;
        self.ws
            .send(tokio_tungstenite::tungstenite::Message::Text(
                command.to_string().into(),
            ))
            .await
            .expect("sends");
    }

    /// The next event of `kind` (JSON `type`), skipping the rest; within [`STEP`].
    pub async fn next(&mut self, kind: &str) -> serde_json::Value {
        use futures_util::StreamExt;
        use tokio_tungstenite::tungstenite::Message;
        let wait = async {
            loop {
                match self.ws.next().await {
                    Some(Ok(Message::Text(text))) => {
                        let event: serde_json::Value =
                            serde_json::from_str(&text).expect("events are JSON");
                        if event["type"] == kind {
                            return event;
                        }
                    }
                    Some(Ok(_)) => {}
                    other => panic!("the console closed while waiting for {kind}: {other:?}"),
                }
            }
        };
        tokio::time::timeout(STEP, wait)
            .await
            .unwrap_or_else(|_| panic!("no {kind} event within {STEP:?}"))
    }
}

/// A runtime for a test's page.
pub fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("a runtime")
}

/// The command [`Live::console`] runs, to add to (an environment variable, say).
pub fn console_command(config: &Path, session: &Path, cwd: &Path) -> Command {
    let mut command = super::handeye();
    command
        .arg("console")
        .arg("--config")
        .arg(config)
        .arg("--output")
        .arg(session)
        .args(["--addr", "127.0.0.1:0"])
        .current_dir(cwd);
    command
}
