//! Rank 0's side of a job: hands out chunks, renders its own share, assembles the frame.
//!
//! Per frame: the job goes to every worker; each answers `Ready` (or `Error`); from then
//! on every `Ready` or `Result` is answered with the rank's next batch
//! ([`super::schedule::Schedule`]), an empty batch when none is left. Rank 0 renders its own
//! batches on a second thread (its chunks in parallel, [`super::worker::render_chunks`]) while
//! this one answers the others and pastes their pixels in, so nobody waits on it. A
//! rank with work outstanding that sends nothing for `timeout` fails the frame with an
//! error naming it; a frame is otherwise only finished when every chunk is in, and the
//! picture is the single-process one bit for bit (the renderer's tiles are independent).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, MutexGuard, mpsc};
use std::time::{Duration, Instant};

use anyhow::{anyhow, bail};
use volume_core::render::{Camera, Frame, RenderSettings};

use super::link::{Envelope, Link, Tag};
use super::schedule::{ChunkGrid, Schedule};
use super::wire::{self, BatchResult, FrameJob};
use super::worker;
use crate::scene::AnyScene;

/// Largest batch handed to a worker at once.
const MAX_BATCH: usize = 16;

/// How often rank 0 looks for the other ranks' messages while it renders.
const POLL: Duration = Duration::from_micros(200);

/// Per rank, what it did in the last frame.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct RankReport {
    pub chunks: usize,
    pub primary_rays: u64,
    /// Time the rank spent rendering.
    pub render_seconds: f64,
}

/// One distributed frame: who did what, and what assembling it cost rank 0.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct FrameReport {
    pub ranks: Vec<RankReport>,
    /// Pixel bytes received from the other ranks.
    pub gather_bytes: u64,
    /// Rank 0's time receiving, decoding and pasting them.
    pub gather_seconds: f64,
    pub seconds: f64,
}

/// Rank 0's handle on the job.
pub struct Cluster {
    link: Box<dyn Link>,
    /// The input every rank opened; frames of other scenes render locally.
    path: PathBuf,
    opened: bool,
    timeout: Duration,
    open_timeout: Duration,
    level_wait: Duration,
    frame: u64,
    history: Option<(ChunkGrid, Vec<u32>)>,
    last: Option<FrameReport>,
    /// Set when the job failed; then every frame renders locally.
    failure: Option<String>,
    /// A rank stopped answering (the job can only be aborted).
    hung: bool,
}

/// A worker's state during a frame.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Peer {
    /// Sent the job or a batch at this time, waiting for its answer.
    Waiting(Instant),
    /// Has had its empty batch (or failed): nothing more this frame.
    Done,
}

impl Cluster {
    /// Rank 0 of `link`, whose other ranks open `path` and then serve
    /// ([`super::worker::serve`]). `timeout`: how long a rank may stay silent during a frame.
    pub fn new(link: Box<dyn Link>, path: &Path, timeout: Duration) -> Self {
        Self {
            link,
            path: path.to_path_buf(),
            opened: false,
            timeout,
            open_timeout: timeout.saturating_mul(10),
            level_wait: Duration::ZERO,
            frame: 0,
            history: None,
            last: None,
            failure: None,
            hung: false,
        }
    }

    pub fn size(&self) -> usize {
        self.link.size()
    }

    /// Out-of-core: how long a worker waits to reach rank 0's loaded levels (the CLI's
    /// `--level-timeout`; the viewer does not wait).
    pub fn set_level_wait(&mut self, t: Duration) {
        self.level_wait = t;
    }

    /// Whether frames of the scene opened from `path` go to the job.
    pub fn serves(&self, path: &Path) -> bool {
        self.failure.is_none() && same_file(&self.path, path)
    }

    /// Why the job stopped (then frames render locally).
    pub fn failure(&self) -> Option<&str> {
        self.failure.as_deref()
    }

    /// Whether a rank stopped answering, so that only [`Self::abort`] can end the job.
    pub fn hung(&self) -> bool {
        self.hung
    }

    /// The last distributed frame's report.
    pub fn last_report(&self) -> Option<&FrameReport> {
        self.last.as_ref()
    }

    /// Waits until every worker has opened the input; the first error names its rank.
    pub fn wait_opened(&mut self) -> anyhow::Result<()> {
        if self.opened {
            return Ok(());
        }
        let mut pending: Vec<bool> = (0..self.size()).map(|r| r != 0).collect();
        let start = Instant::now();
        let result = loop {
            if !pending.contains(&true) {
                break Ok(());
            }
            match self.link.try_recv() {
                Some(Envelope {
                    from,
                    tag: Tag::Opened,
                    ..
                }) => pending[from] = false,
                Some(Envelope {
                    from,
                    tag: Tag::Error,
                    bytes,
                }) => break Err(anyhow!("rank {from}: {}", String::from_utf8_lossy(&bytes))),
                Some(_) => {}
                None => {
                    if start.elapsed() > self.open_timeout {
                        self.hung = true;
                        let silent: Vec<String> = (0..pending.len())
                            .filter(|&r| pending[r])
                            .map(|r| r.to_string())
                            .collect();
                        break Err(anyhow!(
                            "rank {} did not open {} within {:.0} s",
                            silent.join(", "),
                            self.path.display(),
                            self.open_timeout.as_secs_f64()
                        ));
                    }
                    std::thread::sleep(Duration::from_millis(1));
                }
            }
        };
        match result {
            Ok(()) => {
                self.opened = true;
                Ok(())
            }
            Err(e) => Err(self.fail(e)),
        }
    }

    fn fail(&mut self, e: anyhow::Error) -> anyhow::Error {
        self.failure = Some(crate::cli::error_text(&e));
        e
    }

    /// Renders one frame of `scene` across the job (`Ok(None)` if `cancel` was raised).
    /// An error names the rank that failed; the job then serves no more frames.
    pub fn render(
        &mut self,
        scene: &AnyScene,
        camera: &Camera,
        settings: &RenderSettings,
        cancel: &AtomicBool,
    ) -> anyhow::Result<Option<Frame>> {
        if let Some(f) = &self.failure {
            bail!("the MPI job failed earlier: {f}");
        }
        self.wait_opened()?;
        let result = self.render_frame(scene, camera, settings, cancel);
        result.map_err(|e| self.fail(e))
    }

    fn render_frame(
        &mut self,
        scene: &AnyScene,
        camera: &Camera,
        settings: &RenderSettings,
        cancel: &AtomicBool,
    ) -> anyhow::Result<Option<Frame>> {
        let start = Instant::now();
        self.frame += 1;
        let view = scene.data().view_options();
        let job = FrameJob {
            frame: self.frame,
            camera: *camera,
            settings: RenderSettings {
                region: None,
                ..settings.clone()
            },
            step: scene.step(),
            field: scene.data().field().map(str::to_string),
            intersector: view.intersector,
            smooth_normals: view.normals == Some(volume_core::render::Normals::Smooth),
            levels: scene.as_ooc().map_or(0, |o| o.status().loaded_levels),
            level_wait_ms: self.level_wait.as_millis() as u64,
        };
        let grid = job.grid();
        let ranks = self.size();
        if ranks == 1 {
            // Nobody to share with: the whole frame at once, as without MPI.
            let mut frame = Frame::default();
            let t = Instant::now();
            if !scene.render_local_into(camera, &job.settings, cancel, &mut frame) {
                return Ok(None);
            }
            self.last = Some(FrameReport {
                ranks: vec![RankReport {
                    chunks: grid.len(),
                    primary_rays: frame.rays.primary,
                    render_seconds: t.elapsed().as_secs_f64(),
                }],
                seconds: t.elapsed().as_secs_f64(),
                ..FrameReport::default()
            });
            return Ok(Some(frame));
        }
        let bytes = wire::encode_job(&job);
        let mut peers = vec![Peer::Done; ranks];
        for (r, p) in peers.iter_mut().enumerate().skip(1) {
            self.link.send(r, Tag::Job, &bytes);
            // An out-of-core rank may first wait for its levels: that is not silence.
            *p = Peer::Waiting(Instant::now() + self.level_wait);
        }
        let previous = self
            .history
            .as_ref()
            .filter(|(g, _)| *g == grid)
            .map(|(_, o)| o.as_slice());
        let schedule = Mutex::new(Schedule::new(grid, ranks, previous));
        let mut frame = Frame::default();
        size_frame(&mut frame, grid);
        let mut report = FrameReport {
            ranks: vec![RankReport::default(); ranks],
            ..FrameReport::default()
        };
        let mut rays = [0u64; 3];
        let stop = AtomicBool::new(false);
        let timeout = self.timeout;
        let link = &*self.link;
        let number = self.frame;
        let (to_me, local) = mpsc::channel::<(Vec<(u32, Frame)>, f64)>();
        let mut hung = false;
        let outcome = std::thread::scope(|s| {
            // Rank 0's own share, on its threads, while this thread answers the others.
            let (job, schedule, stop) = (&job, &schedule, &stop);
            s.spawn(move || {
                while !stop.load(Ordering::Relaxed) && !cancel.load(Ordering::Relaxed) {
                    let batch = lock(schedule).next_batch(0, MAX_BATCH);
                    if batch.is_empty() {
                        break;
                    }
                    let t = Instant::now();
                    let parts = worker::render_chunks(scene, job, &batch);
                    if to_me.send((parts, t.elapsed().as_secs_f64())).is_err() {
                        break;
                    }
                }
            });
            let mut local_done = false;
            loop {
                // Wait a little for rank 0's own chunks, then take all that are ready.
                let mut next = if local_done {
                    std::thread::sleep(POLL);
                    None
                } else {
                    match local.recv_timeout(POLL) {
                        Ok(x) => Some(x),
                        Err(mpsc::RecvTimeoutError::Timeout) => None,
                        Err(mpsc::RecvTimeoutError::Disconnected) => {
                            local_done = true;
                            None
                        }
                    }
                };
                while let Some((parts, secs)) = next {
                    let rr = &mut report.ranks[0];
                    rr.chunks += parts.len();
                    rr.render_seconds += secs;
                    for (id, f) in &parts {
                        wire::paste_chunk(grid, *id, &f.rgba8, &f.depth, &mut frame);
                        rr.primary_rays += f.rays.primary;
                        rays[0] += f.rays.primary;
                        rays[1] += f.rays.transparency;
                        rays[2] += f.rays.shadow;
                    }
                    next = match local.try_recv() {
                        Ok(x) => Some(x),
                        Err(mpsc::TryRecvError::Empty) => None,
                        Err(mpsc::TryRecvError::Disconnected) => {
                            local_done = true;
                            None
                        }
                    };
                }
                // Answer every message that has arrived.
                while let Some(env) = link.try_recv() {
                    let r = env.from;
                    if r == 0 || r >= ranks {
                        continue;
                    }
                    match env.tag {
                        Tag::Ready => {
                            if wire::decode_frame(&env.bytes).ok() != Some(number) {
                                continue;
                            }
                        }
                        Tag::Result => {
                            let t = Instant::now();
                            let res = match BatchResult::decode(&env.bytes, grid) {
                                Ok(res) => res,
                                Err(e) => return Err(anyhow!("rank {r} sent a bad result: {e}")),
                            };
                            if res.frame != number {
                                continue;
                            }
                            res.paste_into(grid, &mut frame);
                            report.gather_bytes += env.bytes.len() as u64;
                            report.gather_seconds += t.elapsed().as_secs_f64();
                            let rr = &mut report.ranks[r];
                            rr.chunks += res.chunks.len();
                            rr.primary_rays += res.rays[0];
                            rr.render_seconds += res.render_ns as f64 * 1e-9;
                            for (a, b) in rays.iter_mut().zip(res.rays) {
                                *a += b;
                            }
                        }
                        Tag::Error => {
                            peers[r] = Peer::Done;
                            stop.store(true, Ordering::Relaxed);
                            return Err(anyhow!(
                                "rank {r}: {}",
                                String::from_utf8_lossy(&env.bytes)
                            ));
                        }
                        _ => continue,
                    }
                    if peers[r] == Peer::Done {
                        continue;
                    }
                    let batch = if stop.load(Ordering::Relaxed) || cancel.load(Ordering::Relaxed) {
                        Vec::new()
                    } else {
                        lock(schedule).next_batch(r, MAX_BATCH)
                    };
                    link.send(r, Tag::Batch, &wire::encode_batch(number, &batch));
                    peers[r] = if batch.is_empty() {
                        Peer::Done
                    } else {
                        Peer::Waiting(Instant::now())
                    };
                }
                if local_done && peers.iter().all(|p| *p == Peer::Done) {
                    return Ok(());
                }
                if let Some((r, _)) = peers
                    .iter()
                    .enumerate()
                    .find(|(_, p)| matches!(p, Peer::Waiting(since) if since.elapsed() > timeout))
                {
                    stop.store(true, Ordering::Relaxed);
                    hung = true;
                    return Err(anyhow!(
                        "rank {r} sent no tile results for {:.1} s (--mpi-timeout); it may have died or hung",
                        timeout.as_secs_f64()
                    ));
                }
            }
        });
        if let Err(e) = outcome {
            self.hung = hung;
            // The others may still answer this frame; they are told to stop (or aborted)
            // with the job.
            return Err(e);
        }
        if cancel.load(Ordering::Relaxed) || lock(&schedule).remaining() > 0 {
            return Ok(None);
        }
        frame.rays.primary = rays[0];
        frame.rays.transparency = rays[1];
        frame.rays.shadow = rays[2];
        frame.elapsed = start.elapsed();
        report.seconds = frame.elapsed.as_secs_f64();
        self.history = Some((grid, lock(&schedule).owners().to_vec()));
        self.last = Some(report);
        Ok(Some(frame))
    }

    /// Tells every worker to stop serving.
    pub fn shut_down(&mut self) {
        for r in 1..self.size() {
            self.link.send(r, Tag::Quit, &[]);
        }
    }

    /// Ends every rank at once (a rank stopped answering: a clean shutdown would wait on it).
    pub fn abort(&self, code: i32) {
        self.link.abort(code);
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

fn size_frame(frame: &mut Frame, grid: ChunkGrid) {
    let pixels = grid.width as usize * grid.height as usize;
    frame.width = grid.width;
    frame.height = grid.height;
    frame.scale = grid.scale;
    frame.rgba8.resize(pixels * 4, 0);
    frame.depth.resize(pixels, f32::INFINITY);
}

fn same_file(a: &Path, b: &Path) -> bool {
    a == b
        || match (a.canonicalize(), b.canonicalize()) {
            (Ok(a), Ok(b)) => a == b,
            _ => false,
        }
}
