//! Byte-level checks of the mock's RTDE and dashboard servers with a tiny hand-written client
//! (independent of ur_rtde): field sizes, kinematic consistency of the streamed state, the
//! command handshake, and the injected faults. Every mock binds port 0 on 127.0.0.1.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::time::{Duration, Instant};

use handeye_core::geometry::{pose_from_rotvec, rotvec};
use handeye_robot::Joints;
use mocks::{MockFaults, MockUrConfig};
use nalgebra::Vector3;

mod common;

use common::loopback_mock as mock;

struct Rtde(TcpStream);

impl Rtde {
    fn connect(addr: SocketAddr) -> Rtde {
        let s = TcpStream::connect_timeout(&addr, Duration::from_secs(2)).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(3))).unwrap();
        Rtde(s)
    }
    fn send(&mut self, kind: u8, payload: &[u8]) {
        let mut p = ((payload.len() + 3) as u16).to_be_bytes().to_vec();
        p.push(kind);
        p.extend_from_slice(payload);
        self.0.write_all(&p).unwrap();
    }
    fn recv(&mut self) -> (u8, Vec<u8>) {
        let mut header = [0u8; 3];
        self.0.read_exact(&mut header).unwrap();
        let size = u16::from_be_bytes([header[0], header[1]]) as usize;
        let mut payload = vec![0u8; size - 3];
        self.0.read_exact(&mut payload).unwrap();
        (header[2], payload)
    }
    /// The next packet of `kind`, skipping data packages of other kinds.
    fn recv_kind(&mut self, kind: u8) -> Vec<u8> {
        loop {
            let (k, p) = self.recv();
            if k == kind {
                return p;
            }
        }
    }
}

fn f64s(bytes: &[u8]) -> Vec<f64> {
    bytes
        .chunks(8)
        .map(|c| f64::from_be_bytes(c.try_into().unwrap()))
        .collect()
}

#[test]
fn streams_kinematically_consistent_state_with_ur_rtde_field_sizes() {
    let offset = pose_from_rotvec(Vector3::new(0.0, 0.0, 0.15), Vector3::new(0.0, 0.0, 0.3));
    let m = mock(MockUrConfig {
        flange_from_tcp: offset,
        ..MockUrConfig::default()
    });
    let mut c = Rtde::connect(m.rtde_addr());
    c.send(b'V', &2u16.to_be_bytes());
    assert_eq!(c.recv_kind(b'V'), vec![1]);
    c.send(b'v', &[]);
    let v = c.recv_kind(b'v');
    assert_eq!(v.len(), 16);
    assert_eq!(u32::from_be_bytes(v[0..4].try_into().unwrap()), 5);

    // An unknown field is answered NOT_FOUND (ur_rtde throws on that).
    let mut p = 500f64.to_be_bytes().to_vec();
    p.extend_from_slice(b"timestamp,no_such_field,");
    c.send(b'O', &p);
    let reply = c.recv_kind(b'O');
    assert!(String::from_utf8_lossy(&reply[1..]).contains("NOT_FOUND"));

    let mut p = 500f64.to_be_bytes().to_vec();
    p.extend_from_slice(b"timestamp,actual_q,actual_TCP_pose,payload_cog,runtime_state,");
    c.send(b'O', &p);
    let reply = c.recv_kind(b'O');
    assert_eq!(
        String::from_utf8_lossy(&reply[1..]),
        "DOUBLE,VECTOR6D,VECTOR6D,VECTOR3D,UINT32"
    );
    let id = reply[0];
    c.send(b'S', &[]);
    assert_eq!(c.recv_kind(b'S'), vec![1]);
    let data = c.recv_kind(b'U');
    assert_eq!(data[0], id);
    assert_eq!(
        data.len(),
        1 + 8 + 48 + 48 + 24 + 4,
        "field sizes as ur_rtde decodes them"
    );
    let q = f64s(&data[9..57]);
    let tcp = f64s(&data[57..105]);
    let expected = m.config().model.forward(&Joints::from_slice(&q).unwrap()) * offset;
    let t = expected.translation.vector;
    let r = rotvec(&expected.rotation);
    let want = [t.x, t.y, t.z, r.x, r.y, r.z];
    for (a, b) in tcp.iter().zip(want) {
        assert!((a - b).abs() < 1e-12, "{tcp:?} vs {want:?}");
    }
    assert_eq!(u32::from_be_bytes(data[129..133].try_into().unwrap()), 1);
    // Streaming goes on at the asked rate: 50 packages at 500 Hz arrive within a second.
    let t0 = Instant::now();
    for _ in 0..50 {
        c.recv_kind(b'U');
    }
    assert!(t0.elapsed() < Duration::from_secs(1));
}

#[test]
fn dashboard_answers_ur_rtde_connect_queries_and_unlocks_stops() {
    let m = mock(MockUrConfig::default());
    let s = TcpStream::connect(m.dashboard_addr()).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(3))).unwrap();
    let mut reader = BufReader::new(s.try_clone().unwrap());
    let mut writer = s;
    let mut welcome = String::new();
    reader.read_line(&mut welcome).unwrap();
    assert_eq!(
        welcome.trim(),
        "Connected: Universal Robots Dashboard Server"
    );
    let mut ask = |q: &str| {
        writer.write_all(format!("{q}\n").as_bytes()).unwrap();
        let mut line = String::new();
        reader.read_line(&mut line).unwrap();
        line.trim().to_string()
    };
    assert!(ask("PolyscopeVersion").contains("URSoftware 5.11.0.0"));
    assert!(ask("get serial number").chars().all(|c| c.is_ascii_digit()));
    assert_eq!(ask("is in remote control"), "true");
    assert_eq!(ask("safetystatus"), "Safetystatus: NORMAL");
    m.protective_stop();
    assert_eq!(ask("safetystatus"), "Safetystatus: PROTECTIVE_STOP");
    assert_eq!(ask("unlock protective stop"), "Protective stop releasing");
    assert_eq!(ask("safetystatus"), "Safetystatus: NORMAL");
    assert_eq!(ask("quit"), "Disconnected");
}

#[test]
fn dropped_connection_fault_closes_and_refuses() {
    let m = mock(MockUrConfig {
        faults: MockFaults {
            drop_connection_after_moves: Some(0),
            ..MockFaults::default()
        },
        ..MockUrConfig::default()
    });
    let mut s = TcpStream::connect(m.rtde_addr()).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(3))).unwrap();
    let mut buf = [0u8; 16];
    // Closed at once: the read sees end of stream (or a reset), never data.
    assert!(matches!(s.read(&mut buf), Ok(0) | Err(_)));
}

#[test]
fn issue13_dashboard_line_without_end_is_answered_and_dropped_not_buffered_forever() {
    let m = mock(MockUrConfig::default());
    let s = TcpStream::connect(m.dashboard_addr()).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(3))).unwrap();
    let mut reader = BufReader::new(s.try_clone().unwrap());
    let mut writer = s;
    let mut welcome = String::new();
    reader.read_line(&mut welcome).unwrap();
    // 64 kB and no newline: the mock answers once and closes (it used to keep every byte).
    let junk = vec![b'x'; 64 * 1024];
    let _ = writer.write_all(&junk);
    let mut line = String::new();
    reader.read_line(&mut line).unwrap();
    assert_eq!(
        line.trim(),
        "could not understand: command longer than 4096 bytes"
    );
    let mut rest = Vec::new();
    // End of stream (or a reset when unread junk was still in flight): never more data.
    assert!(
        matches!(reader.read_to_end(&mut rest), Ok(0) | Err(_)),
        "{rest:?}"
    );
    // The mock still serves new clients.
    let s = TcpStream::connect(m.dashboard_addr()).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(3))).unwrap();
    let mut welcome = String::new();
    BufReader::new(s).read_line(&mut welcome).unwrap();
    assert!(welcome.starts_with("Connected"));
}

#[test]
fn issue13_script_port_drops_a_client_that_never_completes_a_program() {
    let m = mock(MockUrConfig::default());
    let mut s = TcpStream::connect(m.script_addr()).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    s.set_write_timeout(Some(Duration::from_secs(5))).unwrap();
    // 2 MiB of a program that never ends: past the 1 MiB limit the mock closes the socket, so
    // writing fails (reset or broken pipe) or a read sees the end of the stream.
    let block = b"def p():\n"
        .iter()
        .copied()
        .chain(std::iter::repeat_n(b'#', 64 * 1024 - 9))
        .collect::<Vec<u8>>();
    let mut refused = false;
    for _ in 0..32 {
        if s.write_all(&block).is_err() {
            refused = true;
            break;
        }
    }
    if !refused {
        let mut buf = [0u8; 16];
        refused = match s.read(&mut buf) {
            Ok(n) => n == 0,
            // A timeout means the mock is still holding the connection open.
            Err(e) => !matches!(
                e.kind(),
                std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
            ),
        };
    }
    assert!(refused, "the script port kept buffering past its limit");
    assert_eq!(m.scripts_received(), 0);
}
