// The extern "C" shim over ur_rtde (see shim.h for the contract). Each entry point wraps its
// whole body in try/catch so no C++ exception crosses into Rust, and reports failures as a
// status plus a message.
#include "shim.h"

#include <cstring>
#include <exception>
#include <memory>
#include <string>
#include <vector>

#include <ur_rtde/rtde_control_interface.h>
#include <ur_rtde/rtde_receive_interface.h>

struct urrtde_handle {
  // Receive first: it is the one we read poses from; control second (it uploads the script).
  std::unique_ptr<ur_rtde::RTDEReceiveInterface> receive;
  std::unique_ptr<ur_rtde::RTDEControlInterface> control;
};

namespace {

void set_error(char *err, size_t err_len, const std::string &message) noexcept {
  if (err == nullptr || err_len == 0) return;
  size_t n = message.size() < err_len - 1 ? message.size() : err_len - 1;
  std::memcpy(err, message.data(), n);
  err[n] = '\0';
}

// Runs `body` (returning a status), turning exceptions into URRTDE_EXCEPTION.
template <typename F>
int guarded(const char *what, char *err, size_t err_len, F body) noexcept {
  try {
    return body();
  } catch (const std::exception &e) {
    set_error(err, err_len, std::string(what) + ": " + e.what());
  } catch (...) {
    set_error(err, err_len, std::string(what) + ": unknown C++ exception");
  }
  return URRTDE_EXCEPTION;
}

bool valid(const urrtde_handle *h) { return h != nullptr && h->control && h->receive; }

int copy6(const std::vector<double> &v, double out[6], const char *what, char *err,
          size_t err_len) {
  if (v.size() != 6) {
    set_error(err, err_len, std::string(what) + ": expected 6 values, got " + std::to_string(v.size()));
    return URRTDE_EXCEPTION;
  }
  for (int i = 0; i < 6; ++i) out[i] = v[i];
  return URRTDE_OK;
}

}  // namespace

extern "C" {

int urrtde_connect(const char *host, double frequency, uint16_t flags, urrtde_handle **out,
                   char *err, size_t err_len) noexcept {
  return guarded("connect", err, err_len, [&]() -> int {
    if (host == nullptr || out == nullptr) {
      set_error(err, err_len, "connect: null argument");
      return URRTDE_BAD_ARGUMENT;
    }
    *out = nullptr;
    auto h = std::make_unique<urrtde_handle>();
    h->receive = std::make_unique<ur_rtde::RTDEReceiveInterface>(std::string(host), frequency);
    h->control = std::make_unique<ur_rtde::RTDEControlInterface>(std::string(host), frequency, flags);
    *out = h.release();
    return URRTDE_OK;
  });
}

int urrtde_disconnect(urrtde_handle *h, char *err, size_t err_len) noexcept {
  std::unique_ptr<urrtde_handle> owned(h);
  return guarded("disconnect", err, err_len, [&]() -> int {
    if (!owned) return URRTDE_OK;
    if (owned->control) owned->control->disconnect();
    if (owned->receive) owned->receive->disconnect();
    return URRTDE_OK;
  });
}

#define URRTDE_CHECK_HANDLE(what)                         \
  if (!valid(h)) {                                        \
    set_error(err, err_len, std::string(what) + ": null handle"); \
    return URRTDE_BAD_ARGUMENT;                           \
  }

int urrtde_move_l(urrtde_handle *h, const double pose[6], double speed, double acceleration,
                  int32_t asynchronous, char *err, size_t err_len) noexcept {
  return guarded("moveL", err, err_len, [&]() -> int {
    URRTDE_CHECK_HANDLE("moveL");
    std::vector<double> p(pose, pose + 6);
    if (!h->control->moveL(p, speed, acceleration, asynchronous != 0)) {
      set_error(err, err_len, "moveL: the controller did not run the command");
      return URRTDE_REFUSED;
    }
    return URRTDE_OK;
  });
}

int urrtde_move_j(urrtde_handle *h, const double q[6], double speed, double acceleration,
                  int32_t asynchronous, char *err, size_t err_len) noexcept {
  return guarded("moveJ", err, err_len, [&]() -> int {
    URRTDE_CHECK_HANDLE("moveJ");
    std::vector<double> v(q, q + 6);
    if (!h->control->moveJ(v, speed, acceleration, asynchronous != 0)) {
      set_error(err, err_len, "moveJ: the controller did not run the command");
      return URRTDE_REFUSED;
    }
    return URRTDE_OK;
  });
}

int urrtde_stop_l(urrtde_handle *h, double deceleration, char *err, size_t err_len) noexcept {
  return guarded("stopL", err, err_len, [&]() -> int {
    URRTDE_CHECK_HANDLE("stopL");
    h->control->stopL(deceleration, false);
    return URRTDE_OK;
  });
}

int urrtde_teach_mode(urrtde_handle *h, int32_t on, char *err, size_t err_len) noexcept {
  const char *call = on ? "teachMode" : "endTeachMode";
  return guarded(call, err, err_len, [&]() -> int {
    URRTDE_CHECK_HANDLE(call);
    const bool done = on ? h->control->teachMode() : h->control->endTeachMode();
    if (!done) {
      set_error(err, err_len, on ? "teachMode: the controller did not enter freedrive"
                                 : "endTeachMode: the controller did not leave freedrive");
      return URRTDE_REFUSED;
    }
    return URRTDE_OK;
  });
}

int urrtde_reupload_script(urrtde_handle *h, char *err, size_t err_len) noexcept {
  return guarded("reuploadScript", err, err_len, [&]() -> int {
    URRTDE_CHECK_HANDLE("reuploadScript");
    if (!h->control->reuploadScript()) {
      set_error(err, err_len, "reuploadScript: the control script did not start");
      return URRTDE_REFUSED;
    }
    return URRTDE_OK;
  });
}

int urrtde_get_actual_tcp_pose(urrtde_handle *h, double out[6], char *err, size_t err_len) noexcept {
  return guarded("getActualTCPPose", err, err_len, [&]() -> int {
    URRTDE_CHECK_HANDLE("getActualTCPPose");
    return copy6(h->receive->getActualTCPPose(), out, "getActualTCPPose", err, err_len);
  });
}

int urrtde_get_actual_q(urrtde_handle *h, double out[6], char *err, size_t err_len) noexcept {
  return guarded("getActualQ", err, err_len, [&]() -> int {
    URRTDE_CHECK_HANDLE("getActualQ");
    return copy6(h->receive->getActualQ(), out, "getActualQ", err, err_len);
  });
}

int urrtde_get_actual_qd(urrtde_handle *h, double out[6], char *err, size_t err_len) noexcept {
  return guarded("getActualQd", err, err_len, [&]() -> int {
    URRTDE_CHECK_HANDLE("getActualQd");
    return copy6(h->receive->getActualQd(), out, "getActualQd", err, err_len);
  });
}

int urrtde_get_tcp_offset(urrtde_handle *h, double out[6], char *err, size_t err_len) noexcept {
  return guarded("getTCPOffset", err, err_len, [&]() -> int {
    URRTDE_CHECK_HANDLE("getTCPOffset");
    return copy6(h->control->getTCPOffset(), out, "getTCPOffset", err, err_len);
  });
}

int urrtde_get_state(urrtde_handle *h, urrtde_state *out, char *err, size_t err_len) noexcept {
  return guarded("getState", err, err_len, [&]() -> int {
    URRTDE_CHECK_HANDLE("getState");
    if (out == nullptr) {
      set_error(err, err_len, "getState: null output");
      return URRTDE_BAD_ARGUMENT;
    }
    out->control_connected = h->control->isConnected() ? 1 : 0;
    out->receive_connected = h->receive->isConnected() ? 1 : 0;
    out->receive_timestamp = h->receive->getTimestamp();
    out->safety_status_bits = h->receive->getSafetyStatusBits();
    out->runtime_state = h->receive->getRuntimeState();
    out->robot_mode = h->receive->getRobotMode();
    out->async_status = h->control->getAsyncOperationProgressEx().value();
    return URRTDE_OK;
  });
}

}  // extern "C"
