//! Raw declarations of the C shim (`shim.h`); nothing else. Only `robot::ur` calls these, each
//! call with a `// SAFETY:` note.

use std::ffi::{c_char, c_int};

/// Success.
pub(super) const URRTDE_OK: c_int = 0;
/// ur_rtde returned false: the controller did not run the command.
pub(super) const URRTDE_REFUSED: c_int = 1;

/// Opaque ur_rtde handle (control + receive interfaces).
#[repr(C)]
pub(super) struct UrrtdeHandle {
    _private: [u8; 0],
}

/// Mirrors `urrtde_state` in shim.h.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct UrrtdeState {
    pub receive_timestamp: f64,
    pub safety_status_bits: u32,
    pub runtime_state: u32,
    pub robot_mode: i32,
    pub async_status: u32,
    pub control_connected: i32,
    pub receive_connected: i32,
}

extern "C" {
    pub(super) fn urrtde_connect(
        host: *const c_char,
        frequency: f64,
        flags: u16,
        out: *mut *mut UrrtdeHandle,
        err: *mut c_char,
        err_len: usize,
    ) -> c_int;
    pub(super) fn urrtde_disconnect(
        h: *mut UrrtdeHandle,
        err: *mut c_char,
        err_len: usize,
    ) -> c_int;
    pub(super) fn urrtde_move_l(
        h: *mut UrrtdeHandle,
        pose: *const f64,
        speed: f64,
        acceleration: f64,
        asynchronous: i32,
        err: *mut c_char,
        err_len: usize,
    ) -> c_int;
    pub(super) fn urrtde_move_j(
        h: *mut UrrtdeHandle,
        q: *const f64,
        speed: f64,
        acceleration: f64,
        asynchronous: i32,
        err: *mut c_char,
        err_len: usize,
    ) -> c_int;
    pub(super) fn urrtde_stop_l(
        h: *mut UrrtdeHandle,
        deceleration: f64,
        err: *mut c_char,
        err_len: usize,
    ) -> c_int;
    pub(super) fn urrtde_teach_mode(
        h: *mut UrrtdeHandle,
        on: i32,
        err: *mut c_char,
        err_len: usize,
    ) -> c_int;
    pub(super) fn urrtde_reupload_script(
        h: *mut UrrtdeHandle,
        err: *mut c_char,
        err_len: usize,
    ) -> c_int;
    pub(super) fn urrtde_get_actual_tcp_pose(
        h: *mut UrrtdeHandle,
        out: *mut f64,
        err: *mut c_char,
        err_len: usize,
    ) -> c_int;
    pub(super) fn urrtde_get_actual_q(
        h: *mut UrrtdeHandle,
        out: *mut f64,
        err: *mut c_char,
        err_len: usize,
    ) -> c_int;
    pub(super) fn urrtde_get_actual_qd(
        h: *mut UrrtdeHandle,
        out: *mut f64,
        err: *mut c_char,
        err_len: usize,
    ) -> c_int;
    pub(super) fn urrtde_get_tcp_offset(
        h: *mut UrrtdeHandle,
        out: *mut f64,
        err: *mut c_char,
        err_len: usize,
    ) -> c_int;
    pub(super) fn urrtde_get_state(
        h: *mut UrrtdeHandle,
        out: *mut UrrtdeState,
        err: *mut c_char,
        err_len: usize,
    ) -> c_int;
}
