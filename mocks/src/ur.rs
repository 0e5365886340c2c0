//! The mock Universal Robots controller: [`MockUr::start`] binds the RTDE (30004), dashboard
//! (29999) and script (30003) ports on one address, serves every connection on its own thread,
//! and drives one simulated arm ([`handeye_robot::kinematics::UrModel`]) so the joint positions
//! and the TCP pose it streams always agree. Moves are interpolated at the commanded speed
//! (joint speed for moveJ, tool speed for moveL) or finish at once.
//!
//! What it does not do: dynamics, acceleration profiles, blending, force mode, servoing. Unknown
//! script commands are acknowledged and have no effect.
//!
//! Frames and units: the TCP pose on the wire is `T_base_tcp = T_base_flange * T_flange_tcp`
//! as `[x, y, z, rx, ry, rz]` (m, rad rotation vector); joints in rad.
//!
//! Ports are fixed by ur_rtde, so mocks that run at once each take their own loopback address
//! (127.0.0.2, 127.0.0.3, ...). Any port can be set to 0 for raw protocol tests; the handle
//! reports what was bound. Readiness: `start` returns once every port is bound and accepting.

mod arm;
mod dashboard;
mod rtde;
mod script;

use std::io::ErrorKind;
use std::net::{IpAddr, Ipv4Addr, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use handeye_core::geometry::Pose;
use handeye_robot::kinematics::UrModel;
use handeye_robot::Joints;

use arm::Arm;

/// A controller software version, as `GET_URCONTROL_VERSION` and the dashboard report it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ControllerVersion {
    /// Major (3 = CB3, 5 = e-Series, 10 = PolyScope X).
    pub major: u32,
    /// Minor.
    pub minor: u32,
    /// Bug-fix.
    pub bugfix: u32,
    /// Build.
    pub build: u32,
}

impl Default for ControllerVersion {
    /// 5.11.0.0, an e-Series release.
    fn default() -> Self {
        ControllerVersion {
            major: 5,
            minor: 11,
            bugfix: 0,
            build: 0,
        }
    }
}

impl std::str::FromStr for ControllerVersion {
    type Err = MockUrError;

    /// Parses `5.11.0` or `5.11.0.108`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let parts: Vec<&str> = s.trim().split('.').collect();
        let numbers: Option<Vec<u32>> = parts.iter().map(|p| p.parse().ok()).collect();
        match numbers.as_deref() {
            Some([major, minor, bugfix]) => Ok(ControllerVersion {
                major: *major,
                minor: *minor,
                bugfix: *bugfix,
                build: 0,
            }),
            Some([major, minor, bugfix, build]) => Ok(ControllerVersion {
                major: *major,
                minor: *minor,
                bugfix: *bugfix,
                build: *build,
            }),
            _ => Err(MockUrError::BadVersion(s.to_string())),
        }
    }
}

/// Faults the mock injects, counted in completed moves unless said otherwise.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MockFaults {
    /// After this many completed moves every connection is closed and new ones are closed at
    /// once (a pulled cable that stays pulled).
    pub drop_connection_after_moves: Option<usize>,
    /// After this many completed moves, the next move raises a protective stop half-way (once):
    /// the arm halts, the control program stops, `safety_status_bits` bit 2 is set until
    /// "unlock protective stop" (dashboard) or [`MockUr::clear_stops`].
    pub protective_stop_after_moves: Option<usize>,
    /// The move with this 0-based index (in moves started) never progresses and never
    /// finishes, until a stop command or a new move replaces it.
    pub stall_move: Option<usize>,
    /// After this many completed moves RTDE data packages stop (connections stay open).
    pub stop_streaming_after_moves: Option<usize>,
}

/// The three TCP ports the mock binds (0 = any free port).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MockUrPorts {
    /// RTDE, 30004 on a real controller.
    pub rtde: u16,
    /// Dashboard server, 29999.
    pub dashboard: u16,
    /// Script receiver (real-time interface), 30003.
    pub script: u16,
}

impl Default for MockUrPorts {
    /// The real controller's ports, which ur_rtde hard-codes.
    fn default() -> Self {
        MockUrPorts {
            rtde: 30004,
            dashboard: 29999,
            script: 30003,
        }
    }
}

/// Everything that configures a mock controller.
#[derive(Debug, Clone, PartialEq)]
pub struct MockUrConfig {
    /// Address to bind (a loopback address: 127.0.0.1, 127.0.0.2, ...).
    pub address: IpAddr,
    /// Ports to bind.
    pub ports: MockUrPorts,
    /// Arm model (kinematics).
    pub model: UrModel,
    /// Joint positions at start, rad.
    pub start_joints: Joints,
    /// Reported controller version.
    pub controller_version: ControllerVersion,
    /// Active TCP offset `T_flange_tcp`; the streamed TCP pose includes it.
    pub flange_from_tcp: Pose,
    /// Moves finish at once instead of taking distance / speed.
    pub instant_moves: bool,
    /// Joint moves follow the trapezoidal profile of the commanded speed and acceleration (as a
    /// UR's `moveJ`) instead of running at constant speed.
    pub trapezoidal_moves: bool,
    /// After each joint move the arm rings down (`actual_q` and `actual_qd` show a decaying
    /// oscillation); `None`: it stops dead.
    pub ringing: Option<handeye_robot::sim::Ringing>,
    /// Injected faults.
    pub faults: MockFaults,
    /// What "get serial number" answers (digits only, as ur_rtde checks).
    pub serial_number: String,
}

impl Default for MockUrConfig {
    /// A UR5e on 127.0.0.1 at the real ports, in a typical working pose, no TCP offset, moves at
    /// the commanded speed, no faults.
    fn default() -> Self {
        MockUrConfig {
            address: IpAddr::V4(Ipv4Addr::LOCALHOST),
            ports: MockUrPorts::default(),
            model: UrModel::ur5e(),
            start_joints: Joints::from_six([0.0, -1.571, 1.571, -1.571, -1.571, 0.0]),
            controller_version: ControllerVersion::default(),
            flange_from_tcp: Pose::identity(),
            instant_moves: false,
            trapezoidal_moves: false,
            ringing: None,
            faults: MockFaults::default(),
            serial_number: "20235500001".to_string(),
        }
    }
}

/// Why the mock could not start.
#[derive(Debug, thiserror::Error)]
pub enum MockUrError {
    /// A port could not be bound.
    #[error("mock UR: cannot bind the {service} port {address}")]
    Bind {
        /// Which service (rtde, dashboard, script).
        service: &'static str,
        /// Address that was tried.
        address: SocketAddr,
        /// What the OS said.
        #[source]
        source: std::io::Error,
    },
    /// The start joints are outside the model's limits.
    #[error("mock UR: start joint {index} = {value} rad is outside the {model} joint limits")]
    StartOutsideLimits {
        /// Model name.
        model: String,
        /// Joint index (0 = base).
        index: usize,
        /// Value, rad.
        value: f64,
    },
    /// A controller version string that is not `major.minor.bugfix[.build]`.
    #[error("mock UR: controller version {0:?} is not major.minor.bugfix[.build]")]
    BadVersion(String),
}

/// State shared by the accept loops and every connection.
pub(crate) struct Shared {
    config: MockUrConfig,
    stop: AtomicBool,
    arm: Mutex<Arm>,
}

impl Shared {
    /// The arm, locked. A connection thread that panicked while holding the lock leaves the state
    /// consistent enough for a mock, so poisoning is ignored.
    fn arm(&self) -> MutexGuard<'_, Arm> {
        self.arm.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// A running mock controller. Dropping it shuts it down too.
pub struct MockUr {
    shared: Arc<Shared>,
    rtde_addr: SocketAddr,
    dashboard_addr: SocketAddr,
    script_addr: SocketAddr,
    threads: Vec<JoinHandle<()>>,
}

type Server = fn(TcpStream, Arc<Shared>);

impl MockUr {
    /// Binds all three ports and starts serving; returns once every port accepts connections.
    pub fn start(config: MockUrConfig) -> Result<MockUr, MockUrError> {
        if let Some(index) = (0..6).find(|&i| {
            let (lo, hi) = config.model.joint_limits[i];
            !(config.start_joints[i] >= lo && config.start_joints[i] <= hi)
        }) {
            return Err(MockUrError::StartOutsideLimits {
                model: config.model.name.clone(),
                index,
                value: config.start_joints[index],
            });
        }
        let bind = |service: &'static str, port: u16| {
            let address = SocketAddr::new(config.address, port);
            let listener = TcpListener::bind(address).map_err(|source| MockUrError::Bind {
                service,
                address,
                source,
            })?;
            // Non-blocking accept lets the loop notice shutdown without a wake-up connection.
            listener
                .set_nonblocking(true)
                .map_err(|source| MockUrError::Bind {
                    service,
                    address,
                    source,
                })?;
            Ok::<_, MockUrError>(listener)
        };
        let rtde = bind("rtde", config.ports.rtde)?;
        let dashboard = bind("dashboard", config.ports.dashboard)?;
        let script = bind("script", config.ports.script)?;
        let local = |l: &TcpListener| l.local_addr().expect("a bound listener has an address");
        let (rtde_addr, dashboard_addr, script_addr) =
            (local(&rtde), local(&dashboard), local(&script));

        let arm = Arm::new(
            config.model.clone(),
            config.start_joints,
            config.flange_from_tcp,
            config.instant_moves,
            config.faults,
        )
        .with_motion_model(config.trapezoidal_moves, config.ringing);
        let shared = Arc::new(Shared {
            config,
            stop: AtomicBool::new(false),
            arm: Mutex::new(arm),
        });
        let servers: [(TcpListener, Server); 3] = [
            (rtde, rtde::serve),
            (dashboard, dashboard::serve),
            (script, script::serve),
        ];
        let threads = servers
            .into_iter()
            .map(|(listener, serve)| {
                let shared = Arc::clone(&shared);
                std::thread::spawn(move || accept_loop(listener, shared, serve))
            })
            .collect();
        Ok(MockUr {
            shared,
            rtde_addr,
            dashboard_addr,
            script_addr,
            threads,
        })
    }

    /// The address the mock serves on (give this to the client as the robot's host).
    pub fn address(&self) -> IpAddr {
        self.rtde_addr.ip()
    }

    /// The bound RTDE address.
    pub fn rtde_addr(&self) -> SocketAddr {
        self.rtde_addr
    }

    /// The bound dashboard address.
    pub fn dashboard_addr(&self) -> SocketAddr {
        self.dashboard_addr
    }

    /// The bound script-port address.
    pub fn script_addr(&self) -> SocketAddr {
        self.script_addr
    }

    /// The configuration the mock runs with.
    pub fn config(&self) -> &MockUrConfig {
        &self.shared.config
    }

    /// Current joint positions, rad.
    pub fn joints(&self) -> Joints {
        let mut arm = self.shared.arm();
        arm.advance(Instant::now());
        arm.joints()
    }

    /// A probe that reads the current joint speeds (rad/s) from another thread, for as long as
    /// the mock runs.
    pub fn speed_probe(&self) -> impl Fn() -> Joints + Send + Sync + 'static {
        let shared = self.shared.clone();
        move || shared.arm().snapshot(Instant::now()).joint_speeds
    }

    /// Current flange pose `T_base_flange` (exact).
    pub fn base_from_flange(&self) -> Pose {
        let mut arm = self.shared.arm();
        arm.advance(Instant::now());
        arm.base_from_flange()
    }

    /// Current TCP pose `T_base_tcp` (what the controller streams as actual_TCP_pose).
    pub fn base_from_tcp(&self) -> Pose {
        let mut arm = self.shared.arm();
        arm.advance(Instant::now());
        arm.base_from_tcp()
    }

    /// Moves completed so far.
    pub fn moves_completed(&self) -> usize {
        let mut arm = self.shared.arm();
        arm.advance(Instant::now());
        arm.moves_completed()
    }

    /// Whether freedrive (ur_rtde's teachMode) is on.
    pub fn in_teach_mode(&self) -> bool {
        let mut arm = self.shared.arm();
        arm.advance(Instant::now());
        arm.teach_mode()
    }

    /// A person pushes the arm to `joints` (radians), as in freedrive: the arm follows only
    /// while teach mode is on. Returns whether it moved.
    pub fn hand_guide(&self, joints: Joints) -> bool {
        let mut arm = self.shared.arm();
        arm.advance(Instant::now());
        arm.hand_guide(joints)
    }

    /// Moves started so far (including stalled or interrupted ones).
    pub fn moves_started(&self) -> usize {
        self.shared.arm().moves_started()
    }

    /// Whether the arm is moving.
    pub fn is_moving(&self) -> bool {
        let mut arm = self.shared.arm();
        arm.advance(Instant::now());
        arm.is_moving()
    }

    /// Whether the control program (the uploaded script) runs.
    pub fn program_running(&self) -> bool {
        let mut arm = self.shared.arm();
        arm.advance(Instant::now());
        arm.program_running()
    }

    /// How many complete programs arrived on the script port.
    pub fn scripts_received(&self) -> usize {
        self.shared.arm().scripts_received()
    }

    /// Raises a protective stop now (the arm halts, the program stops).
    pub fn protective_stop(&self) {
        self.shared.arm().raise_stop(Instant::now(), false);
    }

    /// Raises an emergency stop now.
    pub fn emergency_stop(&self) {
        self.shared.arm().raise_stop(Instant::now(), true);
    }

    /// Clears protective and emergency stops (the program stays stopped until re-uploaded).
    pub fn clear_stops(&self) {
        self.shared.arm().clear_stops();
    }

    /// Stops serving: closes every listener and connection and joins the threads.
    pub fn shutdown(mut self) {
        self.stop_threads();
    }

    fn stop_threads(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

impl Drop for MockUr {
    fn drop(&mut self) {
        self.stop_threads();
    }
}

/// Accepts connections until shutdown; each is served on its own thread, joined at shutdown.
fn accept_loop(listener: TcpListener, shared: Arc<Shared>, serve: Server) {
    let mut connections: Vec<JoinHandle<()>> = Vec::new();
    while !shared.stop.load(Ordering::Relaxed) {
        match listener.accept() {
            Ok((stream, _)) => {
                if shared.arm().connection_dropped() {
                    drop(stream); // the cable stays pulled
                    continue;
                }
                // Accepted sockets inherit non-blocking mode on some platforms; serve blocking
                // with read timeouts instead.
                if stream.set_nonblocking(false).is_err() {
                    continue;
                }
                let shared = Arc::clone(&shared);
                connections.push(std::thread::spawn(move || serve(stream, shared)));
                connections.retain(|c| !c.is_finished());
            }
            Err(e) if e.kind() == ErrorKind::WouldBlock => {
                std::thread::sleep(Duration::from_millis(5));
            }
            Err(_) => std::thread::sleep(Duration::from_millis(5)),
        }
    }
    for c in connections {
        let _ = c.join();
    }
}

/// What one poll of a client socket brought.
pub(crate) enum Poll {
    /// New bytes were appended to the buffer.
    Data,
    /// Nothing arrived within the socket's read timeout.
    Idle,
    /// The client left, the mock is stopping, or the dropped-connection fault is active.
    Closed,
}

/// Reads what a client sent into `buffer` (through `chunk`): the one read loop step shared by the
/// RTDE, dashboard and script servers.
pub(crate) fn poll_client(
    stream: &mut TcpStream,
    shared: &Shared,
    buffer: &mut Vec<u8>,
    chunk: &mut [u8],
) -> Poll {
    use std::io::{ErrorKind, Read};
    if shared.stop.load(Ordering::Relaxed) || shared.arm().connection_dropped() {
        return Poll::Closed;
    }
    match stream.read(chunk) {
        Ok(0) => Poll::Closed,
        Ok(n) => {
            buffer.extend_from_slice(&chunk[..n]);
            Poll::Data
        }
        Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => Poll::Idle,
        Err(_) => Poll::Closed,
    }
}
