//! `mock-ur`: runs the mock Universal Robots controller from the command line until killed
//! (Ctrl-C), for trying a driver by hand.

use std::net::IpAddr;

use anyhow::{bail, Context};
use clap::Parser;
use handeye_core::geometry::pose_from_rotvec;
use handeye_robot::kinematics::UrModel;
use handeye_robot::Joints;
use mocks::{ControllerVersion, MockFaults, MockUr, MockUrConfig, MockUrPorts};
use nalgebra::Vector3;

/// A mock Universal Robots controller: RTDE (30004), dashboard (29999) and script (30003)
/// servers driving a simulated arm, for testing UR drivers without a robot.
#[derive(Debug, Parser)]
#[command(name = "mock-ur", version)]
struct Args {
    /// Address to bind (use 127.0.0.2, 127.0.0.3, ... to run several mocks at once).
    #[arg(long, default_value = "127.0.0.1")]
    address: IpAddr,
    /// Arm model: ur5e or ur10e.
    #[arg(long, default_value = "ur5e")]
    model: String,
    /// Controller version reported to clients, major.minor.bugfix[.build].
    #[arg(long, default_value = "5.11.0.0")]
    controller_version: ControllerVersion,
    /// Start joint positions, rad, comma-separated (6 values).
    #[arg(
        long,
        value_delimiter = ',',
        num_args = 6,
        allow_negative_numbers = true,
        default_value = "0,-1.571,1.571,-1.571,-1.571,0"
    )]
    start_joints: Vec<f64>,
    /// Active TCP offset T_flange_tcp as x,y,z,rx,ry,rz (m, rad rotation vector).
    #[arg(
        long,
        value_delimiter = ',',
        num_args = 6,
        allow_negative_numbers = true,
        default_value = "0,0,0,0,0,0"
    )]
    tcp_offset: Vec<f64>,
    /// Finish every move at once instead of at the commanded speed.
    #[arg(long)]
    instant: bool,
    /// Fault: close every connection after this many completed moves.
    #[arg(long)]
    drop_connection_after_moves: Option<usize>,
    /// Fault: raise a protective stop during the move after this many completed moves.
    #[arg(long)]
    protective_stop_after_moves: Option<usize>,
    /// Fault: the move with this 0-based index never finishes.
    #[arg(long)]
    stall_move: Option<usize>,
    /// Fault: stop streaming RTDE data after this many completed moves.
    #[arg(long)]
    stop_streaming_after_moves: Option<usize>,
    /// RTDE port.
    #[arg(long, default_value_t = 30004)]
    rtde_port: u16,
    /// Dashboard port.
    #[arg(long, default_value_t = 29999)]
    dashboard_port: u16,
    /// Script port.
    #[arg(long, default_value_t = 30003)]
    script_port: u16,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let Some(model) = UrModel::by_name(&args.model) else {
        bail!("unknown --model {:?}: expected ur5e or ur10e", args.model);
    };
    let j = &args.start_joints;
    let t = &args.tcp_offset;
    let config = MockUrConfig {
        address: args.address,
        ports: MockUrPorts {
            rtde: args.rtde_port,
            dashboard: args.dashboard_port,
            script: args.script_port,
        },
        model,
        start_joints: Joints::from_six([j[0], j[1], j[2], j[3], j[4], j[5]]),
        controller_version: args.controller_version,
        flange_from_tcp: pose_from_rotvec(
            Vector3::new(t[0], t[1], t[2]),
            Vector3::new(t[3], t[4], t[5]),
        ),
        instant_moves: args.instant,
        faults: MockFaults {
            drop_connection_after_moves: args.drop_connection_after_moves,
            protective_stop_after_moves: args.protective_stop_after_moves,
            stall_move: args.stall_move,
            stop_streaming_after_moves: args.stop_streaming_after_moves,
        },
        ..MockUrConfig::default()
    };
    let mock = MockUr::start(config).context("starting the mock controller")?;
    println!(
        "mock-ur: {} on {} (RTDE {}, dashboard {}, script {}); Ctrl-C to stop",
        mock.config().model.name,
        mock.address(),
        mock.rtde_addr().port(),
        mock.dashboard_addr().port(),
        mock.script_addr().port()
    );
    loop {
        std::thread::park();
    }
}
