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
    }
}

/// A WebSocket client's connection to the console (tokio-tungstenite).
pub type Socket =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;
