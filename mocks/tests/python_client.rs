//! The mock against an independent client: the ur_rtde 1.6.5 Python wheel connects, reads the
//! TCP pose, and runs moveL and moveJ (`ur_rtde_client.py`). Skips with a printed reason when
//! python3 or the wheel is missing (`.ci/run` installs the wheel).

use std::net::{IpAddr, Ipv4Addr};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use mocks::{MockUr, MockUrConfig};

/// The whole client run must finish within this; a broken mock fails instead of hanging.
const TIMEOUT: Duration = Duration::from_secs(60);

fn wheel_available() -> Result<(), String> {
    match Command::new("python3")
        .args(["-c", "import rtde_control, rtde_receive"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
    {
        Ok(s) if s.success() => Ok(()),
        Ok(_) => Err("the ur_rtde wheel is not installed (pip install ur_rtde==1.6.5)".into()),
        Err(e) => Err(format!("python3 is not runnable: {e}")),
    }
}

#[test]
fn ur_rtde_python_client_reads_pose_and_moves() {
    if let Err(reason) = wheel_available() {
        eprintln!("SKIPPED ur_rtde_python_client_reads_pose_and_moves: {reason}");
        return;
    }
    // Its own loopback address: ur_rtde's ports are fixed, other tests use other addresses.
    let config = MockUrConfig {
        address: IpAddr::V4(Ipv4Addr::new(127, 0, 0, 2)),
        ..MockUrConfig::default()
    };
    {
        let mock = MockUr::start(config.clone()).expect("mock starts");
        let start_tcp = mock.base_from_tcp();
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/ur_rtde_client.py");
        let mut child = Command::new("python3")
            .arg(&script)
            .arg(mock.address().to_string())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("python3 starts");
        let deadline = Instant::now() + TIMEOUT;
        let status = loop {
            if let Some(status) = child.try_wait().expect("wait on python") {
                break status;
            }
            if Instant::now() > deadline {
                let _ = child.kill();
                let _ = child.wait();
                panic!("the ur_rtde client did not finish within {TIMEOUT:?}");
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        let output = child.wait_with_output().expect("collect python output");
        let stdout = String::from_utf8_lossy(&output.stdout);
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(
            status.success(),
            "client failed ({status}):\n{stdout}\n{stderr}"
        );
        for check in [
            "OK connected",
            "OK moveL",
            "OK moveJ",
            "OK consistent",
            "OK done",
        ] {
            assert!(stdout.contains(check), "missing {check:?} in:\n{stdout}");
        }
        // The mock's own view agrees with what the client commanded: 5 cm down, base +0.2 rad.
        assert_eq!(mock.moves_completed(), 2);
        let q = mock.joints();
        assert!(
            (q[0] - (config.start_joints[0] + 0.2)).abs() < 1e-9,
            "{q:?}"
        );
        let tcp = mock.base_from_tcp();
        assert!((tcp.translation.z - (start_tcp.translation.z - 0.05)).abs() < 1e-9);
        assert!(!mock.program_running(), "stopScript ends the program");
        mock.shutdown();
    }
}
