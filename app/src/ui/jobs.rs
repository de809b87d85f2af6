//! Background jobs: loading, scene building, rendering and writing files run on their own
//! std threads so the UI thread never waits.
//!
//! A [`Job`] owns the receiving end of a one-shot channel; the viewer polls it at the start
//! of every frame. Progress is an `AtomicU32` (the `f32` bits of a fraction in [0, 1]) and
//! cancellation an `AtomicBool` the worker checks; both live in a shared [`JobControl`].
//! When the worker finishes it asks egui for a repaint, so a finished job is noticed even if
//! the user does not move the mouse.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::mpsc::{Receiver, TryRecvError, channel};
use std::time::Instant;

/// Shared between the UI and a worker thread.
#[derive(Debug, Default)]
pub struct JobControl {
    cancel: AtomicBool,
    progress_bits: AtomicU32,
}

impl JobControl {
    pub fn cancel_flag(&self) -> &AtomicBool {
        &self.cancel
    }

    pub fn is_cancelled(&self) -> bool {
        self.cancel.load(Ordering::Relaxed)
    }

    pub fn cancel(&self) {
        self.cancel.store(true, Ordering::Relaxed);
    }

    /// Fraction done in [0, 1].
    pub fn set_progress(&self, fraction: f32) {
        self.progress_bits
            .store(fraction.clamp(0.0, 1.0).to_bits(), Ordering::Relaxed);
    }

    pub fn progress(&self) -> f32 {
        f32::from_bits(self.progress_bits.load(Ordering::Relaxed))
    }
}

/// What polling a job found.
#[derive(Debug)]
pub enum JobPoll<T> {
    Pending,
    Done(T),
    /// The worker panicked (the channel closed without a result).
    Failed,
}

/// A running background computation producing one `T`.
pub struct Job<T> {
    pub label: String,
    pub started: Instant,
    control: Arc<JobControl>,
    rx: Receiver<T>,
}

impl<T: Send + 'static> Job<T> {
    /// Starts `work` on a new thread. `repaint` is called when the result is ready.
    pub fn spawn(
        label: impl Into<String>,
        repaint: impl Fn() + Send + 'static,
        work: impl FnOnce(&JobControl) -> T + Send + 'static,
    ) -> Self {
        let label = label.into();
        let control = Arc::new(JobControl::default());
        let (tx, rx) = channel();
        let worker_control = Arc::clone(&control);
        let spawned = std::thread::Builder::new()
            .name(format!("isoscope job: {label}"))
            .spawn(move || {
                let result = work(&worker_control);
                // The receiver may be gone (job dropped): then nobody wants the result.
                let _ = tx.send(result);
                repaint();
            });
        if let Err(e) = spawned {
            // Without a thread the job can never finish: report it as failed on first poll.
            eprintln!("isoscope: cannot start a thread for {label}: {e}");
        }
        Self {
            label,
            started: Instant::now(),
            control,
            rx,
        }
    }
}

impl<T> Job<T> {
    /// Non-blocking check for the result.
    pub fn poll(&self) -> JobPoll<T> {
        match self.rx.try_recv() {
            Ok(v) => JobPoll::Done(v),
            Err(TryRecvError::Empty) => JobPoll::Pending,
            Err(TryRecvError::Disconnected) => JobPoll::Failed,
        }
    }

    pub fn cancel(&self) {
        self.control.cancel();
    }

    pub fn progress(&self) -> f32 {
        self.control.progress()
    }
}

impl<T> Drop for Job<T> {
    /// A dropped job's result is unwanted: tell the worker to stop early.
    fn drop(&mut self) {
        self.control.cancel();
    }
}

/// Polls `slot` and takes the result out when it is done (the job is removed).
pub fn take_finished<T>(slot: &mut Option<Job<T>>) -> Option<Result<T, String>> {
    let poll = slot.as_ref()?.poll();
    match poll {
        JobPoll::Pending => None,
        JobPoll::Done(v) => {
            *slot = None;
            Some(Ok(v))
        }
        JobPoll::Failed => {
            let label = slot.take().map(|j| j.label.clone()).unwrap_or_default();
            Some(Err(format!("{label}: the background job failed")))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn wait<T>(job: &mut Option<Job<T>>) -> Result<T, String> {
        for _ in 0..2000 {
            if let Some(r) = take_finished(job) {
                return r;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        panic!("job did not finish");
    }

    #[test]
    fn job_delivers_its_result_and_progress() {
        let mut job = Some(Job::spawn(
            "sum",
            || {},
            |c| {
                c.set_progress(0.5);
                (1..=10).sum::<u32>()
            },
        ));
        assert_eq!(wait(&mut job), Ok(55));
        assert!(job.is_none());
    }

    #[test]
    fn cancel_reaches_the_worker() {
        let (started_tx, started_rx) = channel();
        let mut job = Some(Job::spawn(
            "spin",
            || {},
            move |c| {
                started_tx.send(()).unwrap();
                let mut spins = 0u64;
                while !c.is_cancelled() {
                    spins += 1;
                    std::thread::yield_now();
                }
                spins
            },
        ));
        started_rx.recv().unwrap();
        job.as_ref().unwrap().cancel();
        assert!(wait(&mut job).is_ok());
    }

    #[test]
    fn a_panicking_worker_is_reported_not_hung() {
        let mut job: Option<Job<u8>> = Some(Job::spawn("boom", || {}, |_| panic!("test panic")));
        let err = wait(&mut job).unwrap_err();
        assert!(err.contains("boom"), "{err}");
    }

    #[test]
    fn progress_is_clamped() {
        let c = JobControl::default();
        c.set_progress(2.0);
        assert_eq!(c.progress(), 1.0);
        c.set_progress(-1.0);
        assert_eq!(c.progress(), 0.0);
    }
}
