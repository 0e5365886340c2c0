"""Drives the mock UR controller with the real ur_rtde 1.6.5 client (the PyPI wheel).

Usage: python3 ur_rtde_client.py HOST
Connects the receive and control interfaces, reads the TCP pose and joints, runs moveL and
moveJ, checks the arm arrived, and prints one "OK ..." line per check. Exits non-zero on any
failure. Exit code 77 means the wheel is not installed (the Rust test then skips).
"""
import math
import sys
import time

try:
    import rtde_control
    import rtde_receive
except ImportError as exc:  # the caller skips with this reason
    print(f"SKIP: ur_rtde wheel not importable: {exc}")
    sys.exit(77)


def close(a, b, tol):
    return all(abs(x - y) <= tol for x, y in zip(a, b))


def main():
    host = sys.argv[1]
    receive = rtde_receive.RTDEReceiveInterface(host)
    control = rtde_control.RTDEControlInterface(host)
    assert control.isConnected() and receive.isConnected()
    print("OK connected")

    pose = receive.getActualTCPPose()
    q = receive.getActualQ()
    assert len(pose) == 6 and len(q) == 6, (pose, q)
    print(f"OK pose {pose}")

    # moveL: 5 cm down, at 0.25 m/s.
    target = list(pose)
    target[2] -= 0.05
    assert control.moveL(target, 0.25, 1.2), "moveL returned false"
    time.sleep(0.05)  # the receive interface's copy lags the controller by up to one cycle
    reached = receive.getActualTCPPose()
    assert close(reached[:3], target[:3], 1e-6), (reached, target)
    print(f"OK moveL {reached}")

    # moveJ: turn the base by 0.2 rad at 1 rad/s.
    q_target = list(receive.getActualQ())
    q_target[0] += 0.2
    assert control.moveJ(q_target, 1.0, 1.4), "moveJ returned false"
    time.sleep(0.05)
    q_reached = receive.getActualQ()
    assert close(q_reached, q_target, 1e-9), (q_reached, q_target)
    print(f"OK moveJ {q_reached}")

    # The TCP pose must follow the joints (kinematic consistency): base turn keeps the height.
    after = receive.getActualTCPPose()
    assert abs(after[2] - reached[2]) < 1e-9, (after, reached)
    radius_before = math.hypot(reached[0], reached[1])
    radius_after = math.hypot(after[0], after[1])
    assert abs(radius_before - radius_after) < 1e-9
    print("OK consistent")

    control.stopScript()
    control.disconnect()
    receive.disconnect()
    print("OK done")


if __name__ == "__main__":
    main()
