//! Long work (opening, building, rendering) without the GIL, interruptible by Ctrl+C.
//!
//! Python runs signal handlers only on its main thread and only when Rust hands control back,
//! so the work runs on a scoped worker thread while the calling thread, with the GIL
//! released, waits for it in short slices and asks Python between slices whether a signal
//! arrived (`PyErr_CheckSignals`). On `KeyboardInterrupt` it raises the work's cancel flag
//! (which the renderer checks per tile and the opener between phases) and, once the worker
//! has stopped, raises the interrupt.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Duration;

use pyo3::prelude::*;

/// How often the waiting thread looks for signals.
const SIGNAL_POLL: Duration = Duration::from_millis(50);

/// Runs `work` on a worker thread with the GIL released; Ctrl+C raises `cancel` and, after
/// `work` returns, `KeyboardInterrupt`. A panic in `work` becomes a `RuntimeError` (never a
/// crash of the interpreter).
pub fn interruptible<T: Send>(
    py: Python<'_>,
    cancel: &AtomicBool,
    work: impl FnOnce() -> T + Send,
) -> PyResult<T> {
    let (out, interrupt) = py.detach(|| {
        std::thread::scope(|s| {
            let (done_tx, done_rx) = mpsc::channel::<()>();
            let handle = s.spawn(move || {
                let out = work();
                // The receiver lives until the join below.
                let _ = done_tx.send(());
                out
            });
            let mut interrupt = None;
            loop {
                match done_rx.recv_timeout(SIGNAL_POLL) {
                    Ok(()) | Err(mpsc::RecvTimeoutError::Disconnected) => break,
                    Err(mpsc::RecvTimeoutError::Timeout) => {
                        // A closure, not the method path: `attach` needs a callable for any
                        // `Python<'_>` lifetime.
                        #[allow(clippy::redundant_closure_for_method_calls)]
                        if interrupt.is_none()
                            && let Err(e) = Python::attach(|py| py.check_signals())
                        {
                            cancel.store(true, Ordering::Relaxed);
                            interrupt = Some(e);
                        }
                    }
                }
            }
            (handle.join(), interrupt)
        })
    });
    if let Some(e) = interrupt {
        return Err(e);
    }
    out.map_err(|payload| {
        let what = payload
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| payload.downcast_ref::<&str>().copied())
            .unwrap_or("a panic");
        pyo3::exceptions::PyRuntimeError::new_err(format!("isoscope internal error: {what}"))
    })
}
