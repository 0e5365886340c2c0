//! One dashboard-server connection (TCP 29999): a line protocol ("\n"-terminated). Answers the
//! queries ur_rtde sends on connect (PolyScope version, serial number, remote control) and the
//! common commands a person or a driver uses (stop, play, safety status, unlock protective stop).
//! A line longer than [`MAX_LINE_BYTES`] ends the connection.

use std::io::Write;
use std::net::TcpStream;
use std::sync::Arc;
use std::time::{Duration, Instant};

use super::arm::{SAFETY_EMERGENCY_STOP, SAFETY_PROTECTIVE_STOP};
use super::{poll_client, Poll, Shared};

/// Longest command line the mock buffers, bytes (the longest real command is under 100 bytes). A
/// client that sends more without a newline is answered once and disconnected, so the buffer
/// stays bounded.
pub(crate) const MAX_LINE_BYTES: usize = 4096;

/// The reply to one dashboard command line; `None` closes the connection ("quit").
fn reply(shared: &Shared, line: &str) -> Option<String> {
    let v = shared.config.controller_version;
    let now = Instant::now();
    let command = line.trim();
    let answer = match command {
        "PolyscopeVersion" => format!(
            "URSoftware {}.{}.{}.{} (Nov 27 2026)",
            v.major, v.minor, v.bugfix, v.build
        ),
        "version" => format!("Version: {}.{}.{}.{}", v.major, v.minor, v.bugfix, v.build),
        "get serial number" => shared.config.serial_number.clone(),
        "get robot model" => shared
            .config
            .model
            .name
            .to_ascii_uppercase()
            .replace('E', ""),
        "is in remote control" => "true".to_string(),
        "stop" => {
            shared.arm().stop_program(now);
            "Stopped".to_string()
        }
        "play" => {
            if shared.arm().safety_stopped() {
                "Failed to execute: play".to_string()
            } else {
                "Starting program".to_string()
            }
        }
        "pause" => "Pausing program".to_string(),
        "running" => format!("Program running: {}", shared.arm().program_running()),
        "programState" => {
            if shared.arm().program_running() {
                "PLAYING rtde_control".to_string()
            } else {
                "STOPPED <unnamed>".to_string()
            }
        }
        "robotmode" => "Robotmode: RUNNING".to_string(),
        "safetymode" | "safetystatus" => {
            let bits = shared.arm().safety_bits();
            let state = if bits & SAFETY_EMERGENCY_STOP != 0 {
                "ROBOT_EMERGENCY_STOP"
            } else if bits & SAFETY_PROTECTIVE_STOP != 0 {
                "PROTECTIVE_STOP"
            } else {
                "NORMAL"
            };
            if command == "safetymode" {
                format!("Safetymode: {state}")
            } else {
                format!("Safetystatus: {state}")
            }
        }
        "unlock protective stop" => {
            let mut arm = shared.arm();
            if arm.safety_bits() & SAFETY_PROTECTIVE_STOP != 0 {
                arm.clear_stops();
            }
            "Protective stop releasing".to_string()
        }
        "close safety popup" => "closing safety popup".to_string(),
        "close popup" => "closing popup".to_string(),
        "power on" => "Powering on".to_string(),
        "power off" => "Powering off".to_string(),
        "brake release" => "Brake releasing".to_string(),
        "quit" => return None,
        other => format!("could not understand: '{other}'"),
    };
    Some(answer)
}

/// Serves one dashboard client until it quits or disconnects, or the mock stops or drops it.
pub(crate) fn serve(mut stream: TcpStream, shared: Arc<Shared>) {
    if stream
        .set_read_timeout(Some(Duration::from_millis(20)))
        .is_err()
        || stream
            .write_all(b"Connected: Universal Robots Dashboard Server\n")
            .is_err()
    {
        return;
    }
    let mut buffer: Vec<u8> = Vec::new();
    let mut chunk = [0u8; 1024];
    loop {
        match poll_client(&mut stream, &shared, &mut buffer, &mut chunk) {
            Poll::Closed => return,
            Poll::Idle => continue,
            Poll::Data => {}
        }
        if buffer.len() > MAX_LINE_BYTES && !buffer[..=MAX_LINE_BYTES].contains(&b'\n') {
            let _ = stream.write_all(
                format!("could not understand: command longer than {MAX_LINE_BYTES} bytes\n")
                    .as_bytes(),
            );
            return;
        }
        while let Some(end) = buffer.iter().position(|&b| b == b'\n') {
            let line = String::from_utf8_lossy(&buffer[..end]).to_string();
            buffer.drain(..=end);
            match reply(&shared, &line) {
                Some(answer) => {
                    if stream.write_all(format!("{answer}\n").as_bytes()).is_err() {
                        return;
                    }
                }
                None => {
                    let _ = stream.write_all(b"Disconnected\n");
                    return;
                }
            }
        }
    }
}
