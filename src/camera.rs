//! Cameras: the intrinsic model shared by detection, pose estimation and simulation
//! (`model`), and the frame simulator that renders a board through that model (`render`).
//!
//! Frames: `camera` is the optical frame (x right, y down, z forward, as OpenCV and ROS
//! `*_optical_frame`). Pixels follow OpenCV's convention for the whole project: pixel
//! centres sit at integer coordinates, pixel `(u, v)` covers `[u - 0.5, u + 0.5)`.
//! Units: metres for points, pixels for image coordinates. This module depends on
//! `geometry` and `target` (for the board the renderer draws), never on robots or sessions.

pub mod model;
pub mod render;
