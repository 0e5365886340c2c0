//! Inputs that crash the mock controller, kept in `tests/fuzz-corpus/crashes/mock-*.bin` (raw
//! RTDE client streams). Each test replays one on a timed mock with its control program running
//! and asserts that no connection thread panicked and that the mock answers both on that
//! connection (the stream ends with a protocol-version request) and on a fresh one. They are
//! each now a regression test (the fixes are in `mocks/src/ur/`).

use std::io::{Read, Write};
use std::net::{Shutdown, SocketAddr, TcpStream};
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, Once};
use std::time::{Duration, Instant};

use mocks::MockUrConfig;

mod common;

static PANICS: AtomicUsize = AtomicUsize::new(0);
static HOOK: Once = Once::new();
static SERIAL: Mutex<()> = Mutex::new(());

fn crash_input(name: &str) -> Vec<u8> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/fuzz-corpus/crashes")
        .join(name);
    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Sends `bytes`, closes the write side, returns everything the mock sent until it closed.
fn exchange(addr: SocketAddr, bytes: &[u8]) -> Vec<u8> {
    let mut s = TcpStream::connect_timeout(&addr, Duration::from_secs(2)).unwrap();
    s.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let _ = s.write_all(bytes);
    let _ = s.shutdown(Shutdown::Write);
    let deadline = Instant::now() + Duration::from_secs(3);
    let mut received = Vec::new();
    let mut chunk = [0u8; 65536];
    while Instant::now() < deadline {
        match s.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => received.extend_from_slice(&chunk[..n]),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(_) => break,
        }
    }
    received
}

/// The kinds of the RTDE packets in `stream`, in order.
fn packet_kinds(mut stream: &[u8]) -> Vec<u8> {
    let mut kinds = Vec::new();
    while stream.len() >= 3 {
        let size = u16::from_be_bytes([stream[0], stream[1]]) as usize;
        if size < 3 || size > stream.len() {
            break;
        }
        kinds.push(stream[2]);
        stream = &stream[size..];
    }
    kinds
}

fn replay(name: &str) {
    let _one_at_a_time = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    HOOK.call_once(|| {
        let default = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            PANICS.fetch_add(1, Ordering::SeqCst);
            default(info);
        }));
    });
    let m = common::loopback_mock(MockUrConfig::default());
    exchange(m.script_addr(), b"def rtde_control():\n  sync()\nend\n");
    let deadline = Instant::now() + Duration::from_secs(2);
    while !m.program_running() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(2));
    }
    assert!(m.program_running(), "the control program did not start");
    let before = PANICS.load(Ordering::SeqCst);
    let replies = exchange(m.rtde_addr(), &crash_input(name));
    assert_eq!(
        PANICS.load(Ordering::SeqCst),
        before,
        "{name}: a mock connection thread panicked"
    );
    let kinds = packet_kinds(&replies);
    if name.contains("recipes") {
        assert_eq!(
            kinds.iter().filter(|&&k| k == b'V').count(),
            2,
            "{name}: both protocol-version requests answered on the same connection"
        );
    }
    let again = exchange(m.rtde_addr(), &[0, 5, b'V', 0, 2]);
    assert_eq!(packet_kinds(&again), vec![b'V'], "a fresh client is served");
}

#[test]
fn crash_movej_at_speed_1e_300() {
    replay("mock-rtde-movej-speed-1e-300.bin");
}

#[test]
fn crash_movej_to_a_1e300_joint_target() {
    replay("mock-rtde-movej-target-1e300.bin");
}

#[test]
fn crash_256_output_recipes_on_one_connection() {
    replay("mock-rtde-256-output-recipes.bin");
}

#[test]
fn crash_256_input_recipes_on_one_connection() {
    replay("mock-rtde-256-input-recipes.bin");
}
