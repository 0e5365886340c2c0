//! `handeye._handeye`: the compiled half of the `handeye` Python package (PyO3, the stable ABI of
//! CPython >= 3.9). The pure-Python half (`python/handeye/`) re-exports it with the exception
//! classes, the OpenCV-shaped calls and the type stubs.
//!
//! - [`calibrate`]: `calibrate(T_base_flange, T_camera_target, setup, ...)` → `Calibration`;
//! - [`detect`]: `Board`, `Camera`, `detect(image, board, camera)` → `Detection`;
//! - [`session`]: `Session(path)`, `read_dataset`, `read_result`;
//! - [`convert`]: numpy ↔ poses, serde values → Python; [`errors`]: Rust errors → exceptions.
//!
//! Frames: `T_a_b` maps points of frame `b` into frame `a` (4x4 homogeneous, metres); names as
//! in the CLI's files. Nothing here panics on bad input: every check raises a Python exception.

mod calibrate;
mod convert;
mod detect;
mod errors;
mod run;
mod session;

use pyo3::prelude::*;

/// The compiled module.
#[pymodule]
fn _handeye(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(calibrate::calibrate, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate::calibrate_rt, m)?)?;
    m.add_function(wrap_pyfunction!(run::run, m)?)?;
    m.add_function(wrap_pyfunction!(detect::detect, m)?)?;
    m.add_function(wrap_pyfunction!(session::read_dataset, m)?)?;
    m.add_function(wrap_pyfunction!(session::read_result_py, m)?)?;
    m.add_class::<calibrate::Calibration>()?;
    m.add_class::<calibrate::VerdictPy>()?;
    m.add_class::<detect::Board>()?;
    m.add_class::<detect::Camera>()?;
    m.add_class::<detect::Detection>()?;
    m.add_class::<session::Session>()?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
