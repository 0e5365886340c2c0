//! `handeye.detect`: a numpy image and a board in, the corners with their ids and the board pose
//! `T_camera_target` out. Boards ([`Board`]) come from a board YAML file or text (the form
//! `handeye target` reads: Kalibr aprilgrid, ChArUco, chessboard); intrinsics ([`Camera`]) from a
//! ROS/OpenCV `camera_info` or Kalibr YAML file, or from numbers, checked as every intrinsics
//! file is.
//!
//! Frames and units: corners in pixels (OpenCV convention: pixel centres at integers), board
//! points in the `target` frame (metres; origin and axes as the board kind defines them),
//! `T_camera_target` maps target points into the camera optical frame.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use handeye_core::camera_model::{CameraModel, Distortion};
use handeye_vision::{estimate_board_pose, DetectorOptions, Target, TargetDetector, TargetError};
use image::GrayImage;
use numpy::ndarray::{Array1, Array2};
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArrayDescrMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods,
};
use pyo3::prelude::*;

use crate::convert::pose_to_py;
use crate::errors;

/// A board's points: ids, subs, and the points in the target frame (m).
type BoardPoints<'py> = (
    Bound<'py, PyArray1<u32>>,
    Bound<'py, PyArray1<u8>>,
    Bound<'py, PyArray2<f64>>,
);

/// A calibration board (aprilgrid, ChArUco or chessboard).
#[pyclass(name = "Board", module = "handeye", frozen)]
pub(crate) struct Board {
    pub(crate) target: Target,
    /// Started on the first detection and kept (the AprilTag detector runs on its own thread).
    detector: OnceLock<TargetDetector>,
}

impl Board {
    fn new(target: Target) -> Board {
        Board {
            target,
            detector: OnceLock::new(),
        }
    }

    fn detector(&self, py: Python<'_>) -> PyResult<&TargetDetector> {
        if let Some(detector) = self.detector.get() {
            return Ok(detector);
        }
        let detector = TargetDetector::spawn(&self.target, DetectorOptions::default())
            .map_err(|e| errors::from_error(py, &e))?;
        Ok(self.detector.get_or_init(|| detector))
    }
}

#[pymethods]
impl Board {
    /// Reads a board YAML file (`target_type: aprilgrid | charuco | checkerboard`).
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Board> {
        Target::load(&path)
            .map(Board::new)
            .map_err(|e| errors::from_error(py, &e))
    }

    /// Parses board YAML text (the board file's form).
    #[staticmethod]
    fn from_yaml(py: Python<'_>, text: &str) -> PyResult<Board> {
        Target::from_yaml_str(text, Path::new("<python>"))
            .map(Board::new)
            .map_err(|e| errors::from_error(py, &e))
    }

    /// A Kalibr aprilgrid: `cols` x `rows` tags, `tag_size` the black square's edge (m),
    /// `tag_spacing` the gap as a fraction of `tag_size` (the board file's keys).
    #[staticmethod]
    #[pyo3(signature = (cols, rows, tag_size, tag_spacing, *, family = "tag36h11", first_id = 0, border_bits = 2))]
    #[allow(clippy::too_many_arguments)]
    fn aprilgrid(
        py: Python<'_>,
        cols: u32,
        rows: u32,
        tag_size: f64,
        tag_spacing: f64,
        family: &str,
        first_id: u32,
        border_bits: u32,
    ) -> PyResult<Board> {
        Board::from_yaml(
            py,
            &format!(
                "target_type: aprilgrid\ntagCols: {cols}\ntagRows: {rows}\ntagSize: {}\n\
                 tagSpacing: {}\nfamily: {family:?}\nfirst_id: {first_id}\nborder_bits: {border_bits}\n",
                yaml_number(tag_size),
                yaml_number(tag_spacing)
            ),
        )
    }

    /// An OpenCV ChArUco board: `squares_x` x `squares_y` squares of `square_length` (m), markers
    /// of `marker_length` (m) from `dictionary` (`DICT_4X4_50`, ...).
    #[staticmethod]
    #[pyo3(signature = (squares_x, squares_y, square_length, marker_length, dictionary = "DICT_4X4_50"))]
    fn charuco(
        py: Python<'_>,
        squares_x: u32,
        squares_y: u32,
        square_length: f64,
        marker_length: f64,
        dictionary: &str,
    ) -> PyResult<Board> {
        Board::from_yaml(
            py,
            &format!(
                "target_type: charuco\nsquaresX: {squares_x}\nsquaresY: {squares_y}\n\
                 squareLength: {}\nmarkerLength: {}\ndictionary: {dictionary:?}\n",
                yaml_number(square_length),
                yaml_number(marker_length)
            ),
        )
    }

    /// A chessboard of `cols` x `rows` inner corners, `spacing` (m) apart (Kalibr's
    /// `checkerboard`).
    #[staticmethod]
    fn checkerboard(py: Python<'_>, cols: u32, rows: u32, spacing: f64) -> PyResult<Board> {
        let s = yaml_number(spacing);
        Board::from_yaml(
            py,
            &format!(
                "target_type: checkerboard\ntargetCols: {cols}\ntargetRows: {rows}\n\
                 rowSpacingMeters: {s}\ncolSpacingMeters: {s}\n"
            ),
        )
    }

    /// Every point of the board: `(ids (N,), subs (N,), points (N, 3) in the target frame, m)`.
    fn points<'py>(&self, py: Python<'py>) -> BoardPoints<'py> {
        let points = self.target.points();
        let ids: Array1<u32> = points.iter().map(|p| p.0).collect();
        let subs: Array1<u8> = points.iter().map(|p| p.1).collect();
        let xyz = Array2::from_shape_fn((points.len(), 3), |(i, k)| points[i].2[k]);
        (
            ids.into_pyarray(py),
            subs.into_pyarray(py),
            xyz.into_pyarray(py),
        )
    }

    fn __repr__(&self) -> String {
        format!("<handeye.Board {}>", self.target.describe())
    }
}

/// A number as YAML writes it (NaN and infinities in YAML's spelling, so the board's own
/// range check names them).
fn yaml_number(v: f64) -> String {
    if v.is_nan() {
        ".nan".into()
    } else if v.is_infinite() {
        if v > 0.0 { ".inf" } else { "-.inf" }.into()
    } else {
        format!("{v:?}")
    }
}

/// Camera intrinsics: pinhole (px) plus distortion, for one image size.
#[pyclass(name = "Camera", module = "handeye", frozen)]
pub(crate) struct Camera {
    pub(crate) model: CameraModel,
}

#[pymethods]
impl Camera {
    /// Intrinsics from numbers: image size (px), focal lengths and principal point (px,
    /// OpenCV convention), and `distortion` coefficients: `plumb_bob` `[k1, k2, p1, p2, k3]`
    /// (OpenCV's order; fewer are padded with zeros) or `equidistant` `[k1, k2, k3, k4]`.
    #[new]
    #[pyo3(signature = (width, height, fx, fy, cx, cy, distortion = None, model = "plumb_bob"))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        width: u32,
        height: u32,
        fx: f64,
        fy: f64,
        cx: f64,
        cy: f64,
        distortion: Option<Vec<f64>>,
        model: &str,
    ) -> PyResult<Camera> {
        let d = distortion.unwrap_or_default();
        let distortion = match model {
            "plumb_bob" | "radtan" if d.len() <= 5 => {
                let k = |i: usize| d.get(i).copied().unwrap_or(0.0);
                Distortion::RadTan {
                    k1: k(0),
                    k2: k(1),
                    p1: k(2),
                    p2: k(3),
                    k3: k(4),
                }
            }
            "equidistant" | "fisheye" if d.len() == 4 => Distortion::Equidistant {
                k1: d[0],
                k2: d[1],
                k3: d[2],
                k4: d[3],
            },
            "plumb_bob" | "radtan" | "equidistant" | "fisheye" => {
                return Err(errors::input(
                    py,
                    format!(
                        "distortion: {} coefficients for model `{model}`: plumb_bob takes up to 5 [k1, k2, p1, p2, k3], equidistant exactly 4 [k1, k2, k3, k4]",
                        d.len()
                    ),
                ))
            }
            other => {
                return Err(errors::input(
                    py,
                    format!("model `{other}`: expected `plumb_bob` or `equidistant`"),
                ))
            }
        };
        let model = CameraModel {
            width,
            height,
            fx,
            fy,
            cx,
            cy,
            distortion,
        };
        model
            .validate(Path::new("<python>"))
            .map_err(|e| errors::from_error(py, &e))?;
        Ok(Camera { model })
    }

    /// Reads a ROS/OpenCV `camera_info` YAML or a Kalibr camchain YAML.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Camera> {
        CameraModel::load(&path)
            .map(|model| Camera { model })
            .map_err(|e| errors::from_error(py, &e))
    }

    /// The 3x3 camera matrix K (px).
    #[getter]
    fn matrix<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let m = &self.model;
        let k = [[m.fx, 0.0, m.cx], [0.0, m.fy, m.cy], [0.0, 0.0, 1.0]];
        Array2::from_shape_fn((3, 3), |(r, c)| k[r][c]).into_pyarray(py)
    }

    /// The distortion coefficients (OpenCV's order for `plumb_bob`).
    #[getter]
    fn distortion(&self) -> Vec<f64> {
        self.model.distortion_coefficients()
    }

    /// `(width, height)`, px.
    #[getter]
    fn size(&self) -> (u32, u32) {
        (self.model.width, self.model.height)
    }

    fn __repr__(&self) -> String {
        let m = &self.model;
        format!(
            "<handeye.Camera {}x{} fx {} fy {} cx {} cy {}>",
            m.width, m.height, m.fx, m.fy, m.cx, m.cy
        )
    }
}

/// One detection: corners with ids, their board points, and the board pose when intrinsics
/// were given.
#[pyclass(name = "Detection", module = "handeye", frozen, get_all)]
pub(crate) struct Detection {
    /// Corner ids (N,): the tag id for an aprilgrid, the inner-corner id for ChArUco and
    /// chessboards.
    ids: Py<PyArray1<u32>>,
    /// Corner index within the tag (0..=3) for an aprilgrid, 0 otherwise (N,).
    subs: Py<PyArray1<u8>>,
    /// Corner pixels (N, 2), px, OpenCV convention (pixel centres at integers).
    corners: Py<PyArray2<f64>>,
    /// The same corners' points on the board (N, 3), target frame, metres.
    object_points: Py<PyArray2<f64>>,
    /// `T_camera_target` (4x4, m), or None (no camera given, or the pose failed: see
    /// `pose_error`).
    #[pyo3(name = "T_camera_target")]
    camera_from_target: Option<Py<PyArray2<f64>>>,
    /// RMS reprojection error of the pose, px (None without a pose).
    rms_px: Option<f64>,
    /// Why there is no pose (or no corners at all), None when there is one or no camera was given.
    pose_error: Option<String>,
    /// `(width, height)` of the image, px.
    image_size: (u32, u32),
}

#[pymethods]
impl Detection {
    fn __repr__(&self, py: Python<'_>) -> String {
        format!(
            "<handeye.Detection {} corners, {}>",
            self.ids.bind(py).len(),
            match (&self.rms_px, &self.pose_error) {
                (Some(rms), _) => format!("pose RMS {rms:.3} px"),
                (None, Some(e)) => format!("no pose: {e}"),
                (None, None) => "no pose (no camera given)".into(),
            }
        )
    }
}

/// A grey image from a numpy array: `(H, W)` uint8, or `(H, W, 3)` uint8 in `channels` order
/// (`bgr`, as OpenCV loads images, or `rgb`) converted with OpenCV's weights.
fn grey_image(py: Python<'_>, image: &Bound<'_, PyAny>, channels: &str) -> PyResult<GrayImage> {
    let array = image.cast::<numpy::PyUntypedArray>().map_err(|_| {
        errors::input(
            py,
            format!(
                "image must be a numpy array, found {}",
                image
                    .get_type()
                    .name()
                    .map(|n| n.to_string())
                    .unwrap_or_default()
            ),
        )
    })?;
    let dtype = array.dtype();
    let is_u8 = dtype.is_equiv_to(&numpy::dtype::<u8>(py));
    let shape = array.shape().to_vec();
    let ok_shape = shape.len() == 2 || (shape.len() == 3 && shape[2] == 3);
    if !is_u8 || !ok_shape {
        return Err(errors::input(
            py,
            format!(
                "image must be an 8-bit grey (H, W) or colour (H, W, 3) array (uint8), found shape {} of {dtype}",
                crate::convert::shape_text(&shape)
            ),
        ));
    }
    let typed: PyReadonlyArrayDyn<'_, u8> = array.extract()?;
    let view = typed.as_array();
    let (h, w) = (shape[0], shape[1]);
    let too_big = |_| errors::input(py, format!("image {w}x{h} px is too large"));
    let (width, height) = (
        u32::try_from(w).map_err(too_big)?,
        u32::try_from(h).map_err(too_big)?,
    );
    let pixels: Vec<u8> = if shape.len() == 2 {
        view.iter().copied().collect()
    } else {
        let (r, b) = match channels {
            "bgr" => (2, 0),
            "rgb" => (0, 2),
            other => {
                return Err(errors::input(
                    py,
                    format!("channels `{other}`: expected `bgr` (OpenCV) or `rgb`"),
                ))
            }
        };
        let mut out = Vec::with_capacity(w * h);
        for y in 0..h {
            for x in 0..w {
                let v = 0.299 * f64::from(view[[y, x, r]])
                    + 0.587 * f64::from(view[[y, x, 1]])
                    + 0.114 * f64::from(view[[y, x, b]]);
                out.push(v.round().clamp(0.0, 255.0) as u8);
            }
        }
        out
    };
    GrayImage::from_raw(width, height, pixels)
        .ok_or_else(|| errors::input(py, format!("image {w}x{h} px: pixel count mismatch")))
}

/// Detects `board` in `image`; with `camera`, also estimates `T_camera_target` by PnP (with the
/// lens distortion). A board not found gives a detection with no corners and `pose_error`
/// saying why; a bad image or board raises `InputError`.
#[pyfunction]
#[pyo3(signature = (image, board, camera = None, *, channels = "bgr"))]
pub(crate) fn detect(
    py: Python<'_>,
    image: &Bound<'_, PyAny>,
    board: &Board,
    camera: Option<&Camera>,
    channels: &str,
) -> PyResult<Detection> {
    let grey = grey_image(py, image, channels)?;
    let size = (grey.width(), grey.height());
    let detector = board.detector(py)?;
    let detection = match py.detach(|| detector.detect(&grey)) {
        Ok(detection) => detection,
        Err(e @ (TargetError::NoTagsFound { .. } | TargetError::BoardNotFound { .. })) => {
            return empty_detection(py, size, handeye_core::error_text::error_chain(&e))
        }
        Err(e) => return Err(errors::from_error(py, &e)),
    };
    let observations = detection.observations();
    if observations.is_empty() {
        let none = TargetError::NoTagsFound {
            rejected: detection.rejected.len(),
        };
        return empty_detection(py, size, handeye_core::error_text::error_chain(&none));
    }
    let n = observations.len();
    let ids: Array1<u32> = observations.iter().map(|o| o.tag_id).collect();
    let subs: Array1<u8> = observations.iter().map(|o| o.corner).collect();
    let corners = Array2::from_shape_fn((n, 2), |(i, k)| observations[i].pixel[k]);
    let points: Vec<_> = observations
        .iter()
        .map(|o| board.target.observation_point(o))
        .collect();
    let object_points =
        Array2::from_shape_fn((n, 3), |(i, k)| points[i].map_or(f64::NAN, |p| p[k]));
    let (pose, rms_px, pose_error) = match camera {
        None => (None, None, None),
        Some(camera) => {
            match py.detach(|| estimate_board_pose(&board.target, &camera.model, &detection)) {
                Ok(pose) => (
                    Some(pose_to_py(py, &pose.camera_from_target).unbind()),
                    Some(pose.rms_px),
                    None,
                ),
                Err(e) => (None, None, Some(handeye_core::error_text::error_chain(&e))),
            }
        }
    };
    Ok(Detection {
        ids: ids.into_pyarray(py).unbind(),
        subs: subs.into_pyarray(py).unbind(),
        corners: corners.into_pyarray(py).unbind(),
        object_points: object_points.into_pyarray(py).unbind(),
        camera_from_target: pose,
        rms_px,
        pose_error,
        image_size: size,
    })
}

fn empty_detection(py: Python<'_>, size: (u32, u32), why: String) -> PyResult<Detection> {
    Ok(Detection {
        ids: Array1::<u32>::zeros(0).into_pyarray(py).unbind(),
        subs: Array1::<u8>::zeros(0).into_pyarray(py).unbind(),
        corners: Array2::<f64>::zeros((0, 2)).into_pyarray(py).unbind(),
        object_points: Array2::<f64>::zeros((0, 3)).into_pyarray(py).unbind(),
        camera_from_target: None,
        rms_px: None,
        pose_error: Some(why),
        image_size: size,
    })
}
