//! Progress bars (indicatif) that stay out of the way.
//!
//! A [`Progress`] starts hidden. A watcher thread reveals it on stderr once the job has run for
//! [`REVEAL_AFTER`] (half a second), and only when stderr is a terminal: short jobs and piped
//! or captured output (scripts, `--json`, tests) never see a bar. Counting is thread-safe, so
//! rayon workers can tick it directly (see [`Progress::ticker`]).

use std::io::IsTerminal;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Jobs shorter than this never show a bar.
pub const REVEAL_AFTER: Duration = Duration::from_millis(500);

struct State {
    done: AtomicBool,
    revealed: AtomicBool,
}

/// A progress bar or spinner that reveals itself only for long jobs on a terminal.
pub struct Progress {
    bar: ProgressBar,
    state: Arc<State>,
    watcher: Option<JoinHandle<()>>,
}

impl Progress {
    /// A bar counting to `len` (e.g. slices or steps).
    pub fn bar(len: u64, message: impl Into<String>) -> Self {
        let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden())
            .with_message(message.into());
        if let Ok(style) = ProgressStyle::with_template(
            "{spinner} {msg} [{bar:32}] {pos}/{len} ({elapsed}, eta {eta})",
        ) {
            bar.set_style(style.progress_chars("=> "));
        }
        Self::start(bar, std::io::stderr().is_terminal(), REVEAL_AFTER)
    }

    /// A spinner for work without a count (opening, writing).
    pub fn spinner(message: impl Into<String>) -> Self {
        let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::hidden())
            .with_message(message.into());
        if let Ok(style) = ProgressStyle::with_template("{spinner} {msg} ({elapsed})") {
            bar.set_style(style);
        }
        Self::start(bar, std::io::stderr().is_terminal(), REVEAL_AFTER)
    }

    /// `terminal`: whether a revealed bar draws on stderr (otherwise it is only marked
    /// revealed, which is what the tests observe).
    fn start(bar: ProgressBar, terminal: bool, delay: Duration) -> Self {
        let state = Arc::new(State {
            done: AtomicBool::new(false),
            revealed: AtomicBool::new(false),
        });
        let watcher = {
            let (bar, state) = (bar.clone(), state.clone());
            std::thread::Builder::new()
                .name("progress".into())
                .spawn(move || {
                    let start = Instant::now();
                    while start.elapsed() < delay {
                        if state.done.load(Ordering::Acquire) {
                            return;
                        }
                        std::thread::sleep(Duration::from_millis(20).min(delay));
                    }
                    if state.done.load(Ordering::Acquire) {
                        return;
                    }
                    state.revealed.store(true, Ordering::Release);
                    if terminal {
                        bar.set_draw_target(ProgressDrawTarget::stderr());
                        bar.enable_steady_tick(Duration::from_millis(120));
                    }
                })
                .ok()
        };
        Self {
            bar,
            state,
            watcher,
        }
    }

    pub fn inc(&self, delta: u64) {
        self.bar.inc(delta);
    }

    pub fn set_message(&self, message: impl Into<String>) {
        self.bar.set_message(message.into());
    }

    /// A closure that advances the bar by one (for `on_slice` callbacks run on many threads).
    pub fn ticker(&self) -> impl Fn() + Sync + '_ {
        move || self.bar.inc(1)
    }

    pub fn position(&self) -> u64 {
        self.bar.position()
    }

    /// True once the watcher decided the job was long enough to show the bar.
    pub fn was_revealed(&self) -> bool {
        self.state.revealed.load(Ordering::Acquire)
    }

    /// Stops and clears the bar (also done on drop).
    pub fn finish(mut self) {
        self.stop();
    }

    fn stop(&mut self) {
        self.state.done.store(true, Ordering::Release);
        if let Some(w) = self.watcher.take() {
            // The watcher sleeps in 20 ms steps, so this returns quickly.
            let _ = w.join();
        }
        self.bar.finish_and_clear();
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.stop();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hidden_bar(len: u64) -> ProgressBar {
        ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden())
    }

    #[test]
    fn short_jobs_are_never_revealed() {
        let p = Progress::start(hidden_bar(10), false, Duration::from_millis(400));
        let tick = p.ticker();
        for _ in 0..10 {
            tick();
        }
        assert_eq!(p.position(), 10);
        assert!(!p.was_revealed());
        drop(tick);
        p.finish();
    }

    #[test]
    fn long_jobs_are_revealed_after_the_delay() {
        let p = Progress::start(hidden_bar(3), false, Duration::from_millis(30));
        let t0 = Instant::now();
        while !p.was_revealed() && t0.elapsed() < Duration::from_secs(5) {
            std::thread::sleep(Duration::from_millis(5));
        }
        assert!(p.was_revealed());
        assert!(t0.elapsed() >= Duration::from_millis(25));
    }

    #[test]
    fn ticks_from_many_threads_all_count() {
        use rayon::prelude::*;
        let p = Progress::start(hidden_bar(1000), false, REVEAL_AFTER);
        let tick = p.ticker();
        (0..1000).into_par_iter().for_each(|_| tick());
        assert_eq!(p.position(), 1000);
    }
}
