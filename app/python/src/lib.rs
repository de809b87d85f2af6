//! # isoscope (Python package, native part)
//!
//! The extension module `isoscope._isoscope`, re-exported by `python/isoscope/__init__.py`
//! and typed by `python/isoscope/__init__.pyi`. It is a thin layer over the `isoscope` app
//! library (built without the viewer): everything a file becomes goes through
//! [`isoscope::scene::open_scene`], every picture through
//! [`isoscope::cli::render::render_scene_with`], every `info()` through the `info --json`
//! builders, so Python and the CLI cannot disagree.
//!
//! - [`data`]: `open()` and the data classes (`Volume`, `Mesh`, `OocVolume`, `Series`) that
//!   hold one loaded [`isoscope::scene::AnyScene`]; `Volume(array)` views a numpy array's
//!   memory in place ([`numpy_source`]).
//! - [`view`]: `Scene` (render, batched `first_hit`, time steps, refresh), `Camera`, `Image`.
//! - [`run`]: long work without the GIL on a worker thread, with Ctrl+C (the calling thread
//!   polls Python's signal handlers and raises the cancel flag).
//! - Errors: [`to_py_err`] maps the Rust errors (same messages as the CLI) to `OSError`
//!   (file system) or `ValueError` (everything else); a cancel is `KeyboardInterrupt`.

// FFI: numpy's data pointer (see `numpy_source`).
#![allow(unsafe_code)]
// PyO3 hands Python arguments over as owned values (`PyRef`, `Vec`, `PathBuf`).
#![allow(clippy::needless_pass_by_value)]

use pyo3::prelude::*;

pub mod data;
pub mod numpy_source;
pub mod run;
pub mod view;

/// The Python exception for a Rust error: `KeyboardInterrupt` for a cancel; `OSError` when
/// the cause is the file system (`FileExistsError` for an output that exists); `ValueError`
/// otherwise. The message is the one the CLI prints first, followed by each cause that it
/// does not already contain (the CLI lists those under "Caused by").
pub fn to_py_err(error: &anyhow::Error) -> PyErr {
    use formats::FormatError;
    let mut message = error.to_string();
    for cause in error.chain().skip(1) {
        let cause = cause.to_string();
        if !message.contains(&cause) {
            message.push_str(": ");
            message.push_str(&cause);
        }
    }
    if isoscope::scene::is_cancelled(error) {
        return pyo3::exceptions::PyKeyboardInterrupt::new_err(message);
    }
    let format_error = error.chain().find_map(|e| e.downcast_ref::<FormatError>());
    if matches!(format_error, Some(FormatError::OutputExists { .. })) {
        return pyo3::exceptions::PyFileExistsError::new_err(message);
    }
    let file_system = matches!(
        format_error,
        Some(FormatError::OutputIsInput { .. } | FormatError::BadOutput { .. })
    ) || error
        .chain()
        .any(|e| e.downcast_ref::<std::io::Error>().is_some());
    if file_system {
        return pyo3::exceptions::PyOSError::new_err(message);
    }
    pyo3::exceptions::PyValueError::new_err(message)
}

/// `Result<T, anyhow::Error>` → `PyResult<T>` through [`to_py_err`].
pub trait IntoPyResult<T> {
    fn py_err(self) -> PyResult<T>;
}

impl<T, E: Into<anyhow::Error>> IntoPyResult<T> for Result<T, E> {
    fn py_err(self) -> PyResult<T> {
        self.map_err(|e| to_py_err(&e.into()))
    }
}

#[pymodule]
fn _isoscope(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<data::Data>()?;
    m.add_class::<data::Volume>()?;
    m.add_class::<data::Mesh>()?;
    m.add_class::<data::OocVolume>()?;
    m.add_class::<data::Series>()?;
    m.add_class::<view::Scene>()?;
    m.add_class::<view::Camera>()?;
    m.add_class::<view::Image>()?;
    m.add_function(wrap_pyfunction!(data::open, m)?)?;
    m.add_function(wrap_pyfunction!(data::preprocess, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
