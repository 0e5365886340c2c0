//! One script-port connection (TCP 30003): receives URScript programs. A complete
//! `def ...():` ... `end` program starts the emulated control program; bytes are otherwise
//! ignored (the real port also streams robot state, which ur_rtde does not read). More than
//! [`MAX_PROGRAM_BYTES`] without a complete program ends the connection, so the buffer stays
//! bounded.

use std::net::TcpStream;
use std::sync::Arc;
use std::time::{Duration, Instant};

use super::{poll_client, Poll, Shared};

/// Largest program the mock buffers, bytes (ur_rtde's control script is about 60 kB).
pub(crate) const MAX_PROGRAM_BYTES: usize = 1 << 20;

/// Whether `text` holds a complete program: a `def` line and a final `end` line.
pub(crate) fn is_complete_program(text: &str) -> bool {
    let trimmed = text.trim_end();
    trimmed.trim_start().starts_with("def ")
        && trimmed.lines().last().is_some_and(|l| l.trim() == "end")
}

/// Serves one script client until it disconnects, or the mock stops or drops it.
pub(crate) fn serve(mut stream: TcpStream, shared: Arc<Shared>) {
    if stream
        .set_read_timeout(Some(Duration::from_millis(20)))
        .is_err()
    {
        return;
    }
    let mut buffer: Vec<u8> = Vec::new();
    let mut chunk = [0u8; 16384];
    loop {
        match poll_client(&mut stream, &shared, &mut buffer, &mut chunk) {
            Poll::Closed => return,
            Poll::Idle => continue,
            Poll::Data => {}
        }
        if is_complete_program(&String::from_utf8_lossy(&buffer)) {
            buffer.clear();
            shared.arm().start_program(Instant::now());
        } else if buffer.len() > MAX_PROGRAM_BYTES {
            eprintln!(
                "mock-ur: script port: {} bytes without a complete program (limit {MAX_PROGRAM_BYTES}); connection closed",
                buffer.len()
            );
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn detects_complete_programs_only() {
        assert!(is_complete_program("def rtde_control():\n  sync()\nend\n"));
        assert!(!is_complete_program("def rtde_control():\n  sync()\n"));
        assert!(!is_complete_program("textmsg(\"hi\")\n"));
    }
}
