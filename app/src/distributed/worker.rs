//! A worker rank's side of a job: open the input, then render batches of chunks until told
//! to quit.
//!
//! Each frame's job sets the worker's scene to rank 0's state (time step, mesh field,
//! intersector, normals) before any ray is traced; a failure there is sent back as the
//! frame's error. The chunks of a batch are rendered in parallel, each into a frame of its own
//! size, and only their pixels travel back.

use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use rayon::prelude::*;
use volume_core::render::{Frame, RenderSettings};

use super::link::{Link, Tag};
use super::wire::{self, BatchResult, FrameJob};
use crate::scene::{AnyScene, SceneData as _, ViewOptions};

/// Tells rank 0 how opening went. Returns the scene to serve, or `None` after reporting
/// the error (the caller then waits for `Quit` with [`serve_none`]).
pub fn report_opened(link: &dyn Link, opened: anyhow::Result<AnyScene>) -> Option<AnyScene> {
    match opened {
        Ok(scene) => {
            link.send(0, Tag::Opened, &[]);
            Some(scene)
        }
        Err(e) => {
            link.send(0, Tag::Error, crate::cli::error_text(&e).as_bytes());
            None
        }
    }
}

/// After a failed open: waits for rank 0's `Quit` (a job whose open failed is sent no
/// frames: rank 0 reports the error and ends it).
pub fn serve_none(link: &dyn Link) {
    while let Some(env) = link.recv() {
        if env.tag == Tag::Quit {
            return;
        }
    }
}

/// Renders what rank 0 asks until it says quit (or the link is gone).
pub fn serve(link: &dyn Link, scene: &mut AnyScene) {
    let mut job: Option<FrameJob> = None;
    while let Some(env) = link.recv() {
        match env.tag {
            Tag::Quit => return,
            Tag::Job => {
                let prepared = wire::decode_job(&env.bytes)
                    .map_err(anyhow::Error::from)
                    .and_then(|j| prepare(scene, &j).map(|()| j));
                match prepared {
                    Ok(j) => {
                        link.send(0, Tag::Ready, &wire::encode_frame(j.frame));
                        job = Some(j);
                    }
                    Err(e) => {
                        link.send(0, Tag::Error, crate::cli::error_text(&e).as_bytes());
                        job = None;
                    }
                }
            }
            Tag::Batch => {
                let Ok((number, chunks)) = wire::decode_batch(&env.bytes) else {
                    continue;
                };
                let Some(j) = job.as_ref().filter(|j| j.frame == number) else {
                    continue;
                };
                if chunks.is_empty() {
                    continue;
                }
                let grid = j.grid();
                let start = Instant::now();
                let parts = render_chunks(scene, j, &chunks);
                let result = BatchResult::from_chunks(
                    number,
                    grid,
                    &parts,
                    start.elapsed().as_nanos() as u64,
                );
                link.send(0, Tag::Result, &result.encode());
            }
            _ => {}
        }
    }
}

/// Renders `chunks` of `job`'s frame in parallel, each into its own frame (ids outside the
/// frame are skipped). Chunks, not just the bands inside one, are what the threads share,
/// so that a rank with many cores keeps them busy.
pub fn render_chunks(scene: &AnyScene, job: &FrameJob, chunks: &[u32]) -> Vec<(u32, Frame)> {
    let grid = job.grid();
    let never = AtomicBool::new(false);
    chunks
        .par_iter()
        .filter(|&&id| (id as usize) < grid.len())
        .map(|&id| {
            let part = RenderSettings {
                region: Some(grid.region(id)),
                ..job.settings.clone()
            };
            let mut f = Frame::default();
            scene.render_local_into(&job.camera, &part, &never, &mut f);
            (id, f)
        })
        .collect()
}

/// Puts `scene` in the state `job` was made in.
fn prepare(scene: &mut AnyScene, job: &FrameJob) -> anyhow::Result<()> {
    if scene.step() != job.step {
        scene
            .set_step(job.step)
            .with_context(|| format!("time step {}", job.step))?;
    }
    if let Some(field) = &job.field
        && scene.data().field() != Some(field.as_str())
    {
        scene.data_mut().set_field(field)?;
    }
    let view = ViewOptions {
        intersector: job.intersector,
        normals: Some(if job.smooth_normals {
            volume_core::render::Normals::Smooth
        } else {
            volume_core::render::Normals::Faceted
        }),
    };
    if !scene.data().has_view_options(&view) {
        scene.data_mut().set_view_options(&view);
    }
    job.settings.validate()?;
    job.camera.validate()?;
    scene.check_colorings(&job.settings)?;
    if let AnyScene::Ooc(o) = scene {
        o.set_isovalues(&job.settings.active_isovalues().0);
        let deadline = Instant::now() + Duration::from_millis(job.level_wait_ms);
        while o.status().loaded_levels < job.levels && Instant::now() < deadline {
            if let Some(e) = o.status().error {
                anyhow::bail!("{}: {e}", o.path().display());
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }
    Ok(())
}
