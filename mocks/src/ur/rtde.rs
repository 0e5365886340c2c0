//! One RTDE connection (TCP 30004): the protocol-version, controller-version, recipe-setup,
//! start/pause and data-package messages of RTDE protocol 2, as ur_rtde 1.6.5 speaks them.
//!
//! Every packet is `u16 size (big-endian, header included) | u8 type | payload`; all numbers are
//! big-endian. Output fields are encoded with the sizes ur_rtde decodes them with (its own type
//! table, not the types we announce), so the table below must match it exactly.

use std::io::Write;
use std::net::TcpStream;
use std::sync::Arc;
use std::time::{Duration, Instant};

use super::arm::{Snapshot, REGISTERS};
use super::{poll_client, Poll, Shared};

const REQUEST_PROTOCOL_VERSION: u8 = b'V';
const GET_URCONTROL_VERSION: u8 = b'v';
const SETUP_OUTPUTS: u8 = b'O';
const SETUP_INPUTS: u8 = b'I';
const START: u8 = b'S';
const PAUSE: u8 = b'P';
const DATA_PACKAGE: u8 = b'U';

/// Wire types of RTDE fields, with their encoded size.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FieldType {
    Double,
    Vector3D,
    Vector6D,
    Int32,
    UInt32,
    UInt64,
    Vector6Int32,
    UInt8,
}

impl FieldType {
    fn name(self) -> &'static str {
        match self {
            FieldType::Double => "DOUBLE",
            FieldType::Vector3D => "VECTOR3D",
            FieldType::Vector6D => "VECTOR6D",
            FieldType::Int32 => "INT32",
            FieldType::UInt32 => "UINT32",
            FieldType::UInt64 => "UINT64",
            FieldType::Vector6Int32 => "VECTOR6INT32",
            FieldType::UInt8 => "UINT8",
        }
    }

    fn size(self) -> usize {
        match self {
            FieldType::Double => 8,
            FieldType::Vector3D => 24,
            FieldType::Vector6D => 48,
            FieldType::Int32 | FieldType::UInt32 => 4,
            FieldType::UInt64 => 8,
            FieldType::Vector6Int32 => 24,
            FieldType::UInt8 => 1,
        }
    }
}

/// `name_N` → N when N < REGISTERS.
fn register_index(name: &str, prefix: &str) -> Option<usize> {
    name.strip_prefix(prefix)?
        .parse::<usize>()
        .ok()
        .filter(|&i| i < REGISTERS)
}

/// The type of an output field, or `None` if the controller does not know it.
fn output_type(name: &str) -> Option<FieldType> {
    use FieldType::*;
    if register_index(name, "output_int_register_").is_some() {
        return Some(Int32);
    }
    if register_index(name, "output_double_register_").is_some() {
        return Some(Double);
    }
    Some(match name {
        "timestamp"
        | "actual_execution_time"
        | "speed_scaling"
        | "target_speed_fraction"
        | "actual_momentum"
        | "actual_main_voltage"
        | "actual_robot_voltage"
        | "actual_robot_current"
        | "standard_analog_input0"
        | "standard_analog_input1"
        | "standard_analog_output0"
        | "standard_analog_output1"
        | "payload" => Double,
        "target_q"
        | "target_qd"
        | "target_qdd"
        | "target_current"
        | "target_moment"
        | "actual_q"
        | "actual_qd"
        | "actual_qdd"
        | "actual_current"
        | "actual_current_as_torque"
        | "actual_moment"
        | "joint_control_output"
        | "actual_TCP_pose"
        | "actual_TCP_speed"
        | "actual_TCP_force"
        | "target_TCP_pose"
        | "target_TCP_speed"
        | "joint_temperatures"
        | "actual_joint_voltage"
        | "ft_raw_wrench"
        | "payload_inertia" => Vector6D,
        "actual_tool_accelerometer" | "payload_cog" | "elbow_position" | "elbow_velocity" => {
            Vector3D
        }
        "actual_digital_input_bits" | "actual_digital_output_bits" => UInt64,
        "robot_mode" | "safety_mode" => Int32,
        "runtime_state"
        | "robot_status_bits"
        | "safety_status_bits"
        | "output_bit_registers0_to_31"
        | "output_bit_registers32_to_63" => UInt32,
        "joint_mode" => Vector6Int32,
        _ => return None,
    })
}

/// The type of an input field, or `None` if the controller does not know it.
fn input_type(name: &str) -> Option<FieldType> {
    use FieldType::*;
    if register_index(name, "input_int_register_").is_some() {
        return Some(Int32);
    }
    if register_index(name, "input_double_register_").is_some() {
        return Some(Double);
    }
    Some(match name {
        "external_force_torque" => Vector6D,
        "speed_slider_mask" => UInt32,
        "speed_slider_fraction" | "standard_analog_output_0" | "standard_analog_output_1" => Double,
        "standard_digital_output_mask"
        | "standard_digital_output"
        | "configurable_digital_output_mask"
        | "configurable_digital_output"
        | "tool_digital_output_mask"
        | "tool_digital_output"
        | "standard_analog_output_mask"
        | "standard_analog_output_type" => UInt8,
        _ => return None,
    })
}

struct OutputRecipe {
    id: u8,
    fields: Vec<(String, FieldType)>,
    period: Duration,
    next_send: Instant,
}

fn packet(kind: u8, payload: &[u8]) -> Vec<u8> {
    let size = (payload.len() + 3) as u16;
    let mut out = Vec::with_capacity(payload.len() + 3);
    out.extend_from_slice(&size.to_be_bytes());
    out.push(kind);
    out.extend_from_slice(payload);
    out
}

fn put_f64s(out: &mut Vec<u8>, values: &[f64]) {
    for v in values {
        out.extend_from_slice(&v.to_be_bytes());
    }
}

/// Encodes one output field from the snapshot.
fn encode_field(out: &mut Vec<u8>, name: &str, kind: FieldType, s: &Snapshot) {
    if let Some(i) = register_index(name, "output_int_register_") {
        out.extend_from_slice(&s.out_int[i].to_be_bytes());
        return;
    }
    if let Some(i) = register_index(name, "output_double_register_") {
        out.extend_from_slice(&s.out_double[i].to_be_bytes());
        return;
    }
    match name {
        "timestamp" => put_f64s(out, &[s.timestamp]),
        "actual_q" => put_f64s(out, &s.joints),
        "target_q" => put_f64s(out, &s.target_joints),
        "actual_qd" | "target_qd" => put_f64s(out, &s.joint_speeds),
        "actual_TCP_pose" => put_f64s(out, &s.tcp_pose),
        "target_TCP_pose" => put_f64s(out, &s.target_tcp_pose),
        "speed_scaling" | "target_speed_fraction" => put_f64s(out, &[1.0]),
        "actual_main_voltage" | "actual_robot_voltage" => put_f64s(out, &[48.0]),
        "joint_temperatures" => put_f64s(out, &[30.0; 6]),
        "actual_tool_accelerometer" => put_f64s(out, &[0.0, 0.0, 9.81]),
        "robot_mode" => out.extend_from_slice(&7i32.to_be_bytes()), // RUNNING
        "safety_mode" => out.extend_from_slice(&s.safety_mode.to_be_bytes()),
        "joint_mode" => {
            for _ in 0..6 {
                out.extend_from_slice(&253i32.to_be_bytes()); // JOINT_RUNNING_MODE
            }
        }
        "runtime_state" => out.extend_from_slice(&s.runtime_state.to_be_bytes()),
        "robot_status_bits" => out.extend_from_slice(&s.robot_status_bits.to_be_bytes()),
        "safety_status_bits" => out.extend_from_slice(&s.safety_status_bits.to_be_bytes()),
        // Everything else (currents, forces, I/O, ...) reads as zero.
        _ => out.resize(out.len() + kind.size(), 0),
    }
}

/// Serves one RTDE client until it disconnects, the mock shuts down, or a fault drops it.
pub(crate) fn serve(mut stream: TcpStream, shared: Arc<Shared>) {
    if stream
        .set_read_timeout(Some(Duration::from_millis(1)))
        .is_err()
    {
        return;
    }
    let _ = stream.set_nodelay(true);
    let mut buffer: Vec<u8> = Vec::with_capacity(4096);
    let mut chunk = [0u8; 4096];
    let mut outputs: Vec<OutputRecipe> = Vec::new();
    let mut inputs: Vec<(u8, Vec<(String, FieldType)>)> = Vec::new();
    let mut started = false;
    loop {
        // Returning drops the stream, which closes the socket; an idle poll still streams.
        if let Poll::Closed = poll_client(&mut stream, &shared, &mut buffer, &mut chunk) {
            return;
        }
        while buffer.len() >= 3 {
            let size = u16::from_be_bytes([buffer[0], buffer[1]]) as usize;
            if size < 3 {
                return; // malformed: a real controller drops such a client too
            }
            if buffer.len() < size {
                break;
            }
            let kind = buffer[2];
            let payload: Vec<u8> = buffer[3..size].to_vec();
            buffer.drain(..size);
            let reply = match kind {
                REQUEST_PROTOCOL_VERSION => Some(packet(kind, &[1])),
                GET_URCONTROL_VERSION => {
                    let v = shared.config.controller_version;
                    let mut p = Vec::with_capacity(16);
                    for x in [v.major, v.minor, v.bugfix, v.build] {
                        p.extend_from_slice(&x.to_be_bytes());
                    }
                    Some(packet(kind, &p))
                }
                SETUP_OUTPUTS => match setup_outputs(&payload, &mut outputs) {
                    Some(p) => Some(packet(kind, &p)),
                    None => return,
                },
                SETUP_INPUTS => Some(packet(kind, &setup_inputs(&payload, &mut inputs, &shared))),
                START => {
                    started = true;
                    let now = Instant::now();
                    for r in &mut outputs {
                        r.next_send = now;
                    }
                    Some(packet(kind, &[1]))
                }
                PAUSE => {
                    started = false;
                    Some(packet(kind, &[1]))
                }
                DATA_PACKAGE => {
                    if let Some((&id, fields)) = payload.split_first() {
                        if let Some((_, recipe)) = inputs.iter().find(|(rid, _)| *rid == id) {
                            apply_inputs(&shared, recipe, fields);
                        }
                    }
                    None
                }
                _ => None,
            };
            if let Some(reply) = reply {
                if stream.write_all(&reply).is_err() {
                    return;
                }
            }
        }
        if started && stream_outputs(&mut stream, &shared, &mut outputs).is_err() {
            return;
        }
    }
}

/// A `SETUP_OUTPUTS` request: the reply's payload (recipe id and field types), the recipe kept
/// when every field is known; `None` for a malformed request (the client is dropped).
fn setup_outputs(payload: &[u8], outputs: &mut Vec<OutputRecipe>) -> Option<Vec<u8>> {
    if payload.len() < 8 {
        return None;
    }
    let frequency = f64::from_be_bytes(payload[..8].try_into().unwrap_or([0; 8]));
    let names = String::from_utf8_lossy(&payload[8..]).to_string();
    let fields: Vec<(String, Option<FieldType>)> = names
        .split(',')
        .filter(|n| !n.is_empty())
        .map(|n| (n.to_string(), output_type(n)))
        .collect();
    let types: Vec<&str> = fields
        .iter()
        .map(|(_, t)| t.map_or("NOT_FOUND", FieldType::name))
        .collect();
    // Recipe ids are one byte: past 255 recipes on a connection the setup fails (id 0, nothing
    // stored) instead of wrapping onto an earlier recipe.
    let id = u8::try_from(outputs.len() + 1).unwrap_or(0);
    let mut p = vec![id];
    p.extend_from_slice(types.join(",").as_bytes());
    if id != 0 && fields.iter().all(|(_, t)| t.is_some()) {
        let hz = if frequency.is_finite() {
            frequency.clamp(1.0, 500.0)
        } else {
            125.0
        };
        outputs.push(OutputRecipe {
            id,
            fields: fields
                .into_iter()
                .map(|(n, t)| (n, t.unwrap_or(FieldType::Double)))
                .collect(),
            period: Duration::from_secs_f64(1.0 / hz),
            next_send: Instant::now(),
        });
    }
    Some(p)
}

/// A `SETUP_INPUTS` request: the reply's payload (recipe id and field types), the recipe kept
/// when every field is known.
fn setup_inputs(
    payload: &[u8],
    inputs: &mut Vec<(u8, Vec<(String, FieldType)>)>,
    shared: &Shared,
) -> Vec<u8> {
    let names = String::from_utf8_lossy(payload).to_string();
    let fields: Vec<(String, Option<FieldType>)> = names
        .split(',')
        .filter(|n| !n.is_empty())
        .map(|n| (n.to_string(), input_type(n)))
        .collect();
    // ur_rtde hard-codes recipe ids 1, 2, 3, ... in setup order, per connection. One byte, as
    // for the outputs: past 255 recipes the setup fails (id 0).
    let id = u8::try_from(inputs.len() + 1).unwrap_or(0);
    if fields
        .iter()
        .any(|(n, _)| register_index(n, "input_int_register_") == Some(24))
    {
        shared.arm().set_register_offset(24);
    }
    let types: Vec<&str> = fields
        .iter()
        .map(|(_, t)| t.map_or("NOT_FOUND", FieldType::name))
        .collect();
    let mut p = vec![id];
    p.extend_from_slice(types.join(",").as_bytes());
    if id != 0 && fields.iter().all(|(_, t)| t.is_some()) {
        inputs.push((
            id,
            fields
                .into_iter()
                .map(|(n, t)| (n, t.unwrap_or(FieldType::Double)))
                .collect(),
        ));
    }
    p
}

/// Sends every output recipe that is due (one arm snapshot for all of them); an error when the
/// client is gone.
fn stream_outputs(
    stream: &mut TcpStream,
    shared: &Shared,
    outputs: &mut [OutputRecipe],
) -> std::io::Result<()> {
    let now = Instant::now();
    if outputs.is_empty() || !outputs.iter().any(|r| now >= r.next_send) {
        return Ok(());
    }
    let snapshot = {
        let mut arm = shared.arm();
        if arm.streaming_stopped() {
            return Ok(());
        }
        arm.snapshot(now)
    };
    for r in outputs.iter_mut().filter(|r| now >= r.next_send) {
        let mut p = vec![r.id];
        for (name, kind) in &r.fields {
            encode_field(&mut p, name, *kind, &snapshot);
        }
        stream.write_all(&packet(DATA_PACKAGE, &p))?;
        r.next_send += r.period;
        if r.next_send < now {
            r.next_send = now + r.period; // fell behind: do not burst
        }
    }
    Ok(())
}

/// Writes one input data package into the registers, then lets the script react.
fn apply_inputs(shared: &Shared, recipe: &[(String, FieldType)], mut data: &[u8]) {
    let mut arm = shared.arm();
    for (name, kind) in recipe {
        let size = kind.size();
        if data.len() < size {
            break;
        }
        let (field, rest) = data.split_at(size);
        data = rest;
        if let Some(i) = register_index(name, "input_int_register_") {
            arm.in_int[i] = i32::from_be_bytes(field.try_into().unwrap_or([0; 4]));
        } else if let Some(i) = register_index(name, "input_double_register_") {
            arm.in_double[i] = f64::from_be_bytes(field.try_into().unwrap_or([0; 8]));
        }
    }
    arm.advance(Instant::now());
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn control_and_receive_fields_have_ur_rtde_sizes() {
        // Sizes ur_rtde decodes with (RobotState::state_types_ and RTDE::receiveData).
        assert_eq!(
            output_type("actual_TCP_pose").map(FieldType::size),
            Some(48)
        );
        assert_eq!(output_type("payload_cog").map(FieldType::size), Some(24));
        assert_eq!(output_type("joint_mode").map(FieldType::size), Some(24));
        assert_eq!(
            output_type("actual_digital_input_bits").map(FieldType::size),
            Some(8)
        );
        assert_eq!(output_type("runtime_state").map(FieldType::size), Some(4));
        assert_eq!(
            output_type("output_double_register_47").map(FieldType::size),
            Some(8)
        );
        assert_eq!(output_type("output_double_register_48"), None);
        assert_eq!(output_type("no_such_field"), None);
        assert_eq!(input_type("input_int_register_24"), Some(FieldType::Int32));
        assert_eq!(
            input_type("external_force_torque"),
            Some(FieldType::Vector6D)
        );
    }
}
