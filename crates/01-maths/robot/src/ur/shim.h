/* C API over ur_rtde's RTDEControlInterface + RTDEReceiveInterface for handeye's Rust FFI.
 *
 * Every function is noexcept and catches every C++ exception: nothing unwinds into Rust.
 * Every function returns a status (URRTDE_OK, or an error code) and, on error, writes a
 * NUL-terminated message into `err` (capacity `err_len`, truncated if longer).
 * A handle is created by urrtde_connect and freed only by urrtde_disconnect.
 * Poses are UR vectors [x, y, z, rx, ry, rz] (m, rotation vector in rad); joints are rad.
 * The handle is not thread-safe: the caller serialises all calls on one handle. */
#ifndef HANDEYE_URRTDE_SHIM_H
#define HANDEYE_URRTDE_SHIM_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
#define URRTDE_NOEXCEPT noexcept
extern "C" {
#else
#define URRTDE_NOEXCEPT
#endif

enum {
  URRTDE_OK = 0,
  /* ur_rtde returned false: the controller did not run the command. */
  URRTDE_REFUSED = 1,
  /* ur_rtde threw: the message says why. */
  URRTDE_EXCEPTION = 2,
  /* A null pointer or bad argument reached the shim. */
  URRTDE_BAD_ARGUMENT = 3
};

typedef struct urrtde_handle urrtde_handle;

/* A snapshot of the controller state the driver polls during a move. */
typedef struct urrtde_state {
  /* Controller time of the receive interface's newest data package, s. */
  double receive_timestamp;
  uint32_t safety_status_bits;
  uint32_t runtime_state;
  int32_t robot_mode;
  /* output_int_register_2 of the control script: bit 15 = async operation running. */
  uint32_t async_status;
  int32_t control_connected;
  int32_t receive_connected;
} urrtde_state;

int urrtde_connect(const char *host, double frequency, uint16_t flags, urrtde_handle **out,
                   char *err, size_t err_len) URRTDE_NOEXCEPT;
/* Disconnects both interfaces (ur_rtde sleeps ~0.5 s per interface) and frees the handle.
 * A null handle is accepted. */
int urrtde_disconnect(urrtde_handle *h, char *err, size_t err_len) URRTDE_NOEXCEPT;
int urrtde_move_l(urrtde_handle *h, const double pose[6], double speed, double acceleration,
                  int32_t asynchronous, char *err, size_t err_len) URRTDE_NOEXCEPT;
int urrtde_move_j(urrtde_handle *h, const double q[6], double speed, double acceleration,
                  int32_t asynchronous, char *err, size_t err_len) URRTDE_NOEXCEPT;
int urrtde_stop_l(urrtde_handle *h, double deceleration, char *err, size_t err_len) URRTDE_NOEXCEPT;
/* Freedrive: teachMode() when `on`, endTeachMode() otherwise. */
int urrtde_teach_mode(urrtde_handle *h, int32_t on, char *err, size_t err_len) URRTDE_NOEXCEPT;
int urrtde_reupload_script(urrtde_handle *h, char *err, size_t err_len) URRTDE_NOEXCEPT;
int urrtde_get_actual_tcp_pose(urrtde_handle *h, double out[6], char *err, size_t err_len) URRTDE_NOEXCEPT;
int urrtde_get_actual_q(urrtde_handle *h, double out[6], char *err, size_t err_len) URRTDE_NOEXCEPT;
/* Joint speeds as the controller measures them (RTDE actual_qd), rad/s. */
int urrtde_get_actual_qd(urrtde_handle *h, double out[6], char *err, size_t err_len) URRTDE_NOEXCEPT;
int urrtde_get_tcp_offset(urrtde_handle *h, double out[6], char *err, size_t err_len) URRTDE_NOEXCEPT;
int urrtde_get_state(urrtde_handle *h, urrtde_state *out, char *err, size_t err_len) URRTDE_NOEXCEPT;

#ifdef __cplusplus
}
#endif

#endif
