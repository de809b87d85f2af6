//! Jobs of threads over [`LocalLink`]: the same protocol and code as MPI ranks, checked
//! against a single-process render of the same scene (bit for bit).

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use data_samples::Generator;
use volume_core::VoxelType;
use volume_core::render::{Camera, Frame, LightKind, RenderSettings, Surface};

use super::link::{Link, LocalLink, Tag};
use super::{Cluster, worker};
use crate::scene::{AnyScene, SceneOptions, open_scene};

fn write_grid(dir: &Path, steps: usize) -> PathBuf {
    let g = Generator::Blobs;
    for step in 0..steps {
        let v = g
            .generate_step([24, 20, 18], VoxelType::F32, step, steps.max(2), &|| {})
            .unwrap();
        formats::nrrd::write_nrrd(
            &dir.join(format!("b_{step:03}.nrrd")),
            &v,
            formats::nrrd::NrrdEncoding::Raw,
            formats::output::Replace::Refuse,
        )
        .unwrap();
    }
    if steps == 1 {
        dir.join("b_000.nrrd")
    } else {
        dir.join("b_%03d.nrrd")
    }
}

fn write_ball(dir: &Path) -> PathBuf {
    let mesh = data_samples::tets::tet_mesh(data_samples::tets::TetShape::Ball, 7).unwrap();
    let p = dir.join("ball.vtu");
    formats::mesh::write_vtu(&p, &mesh, formats::output::Replace::Refuse).unwrap();
    p
}

/// Runs `body` on rank 0's cluster while `ranks - 1` worker threads open `path` and serve.
fn with_job<R>(
    path: &Path,
    ranks: usize,
    timeout: Duration,
    body: impl FnOnce(&mut Cluster) -> R,
) -> R {
    let mut links = LocalLink::group(ranks).into_iter();
    let root = links.next().unwrap();
    std::thread::scope(|s| {
        for link in links {
            s.spawn(move || {
                let opened = open_scene(path, &SceneOptions::default());
                match worker::report_opened(&link, opened) {
                    Some(mut scene) => worker::serve(&link, &mut scene),
                    None => worker::serve_none(&link),
                }
            });
        }
        let mut cluster = Cluster::new(Box::new(root), path, timeout);
        let out = body(&mut cluster);
        cluster.shut_down();
        out
    })
}

fn local(scene: &AnyScene, camera: &Camera, settings: &RenderSettings) -> Frame {
    let mut f = Frame::default();
    assert!(scene.render_local_into(camera, settings, &AtomicBool::new(false), &mut f));
    f
}

fn assert_same(a: &Frame, b: &Frame, what: &str) {
    assert_eq!((a.width, a.height), (b.width, b.height), "{what}");
    assert!(a.rgba8 == b.rgba8, "{what}: colours differ");
    let bits = |f: &Frame| f.depth.iter().map(|d| d.to_bits()).collect::<Vec<_>>();
    assert!(bits(a) == bits(b), "{what}: depths differ");
    assert_eq!(a.rays.primary, b.rays.primary, "{what}");
}

fn variants(iso: f32) -> Vec<(&'static str, RenderSettings)> {
    let base = RenderSettings {
        width: 150,
        height: 130,
        surfaces: vec![Surface::new(iso, [0.9, 0.8, 0.6])],
        ..RenderSettings::default()
    };
    vec![
        ("opaque", base.clone()),
        (
            "preview at scale 4",
            RenderSettings {
                scale: 4,
                ..base.clone()
            },
        ),
        (
            "transparent over opaque, shadows",
            RenderSettings {
                surfaces: vec![
                    Surface {
                        opacity: 0.4,
                        ..Surface::new(iso * 0.7, [0.2, 0.5, 0.9])
                    },
                    Surface::new(iso, [0.9, 0.8, 0.6]),
                ],
                shadows: true,
                light: volume_core::render::Light {
                    kind: LightKind::Directional {
                        dir: glam::Vec3::new(0.4, 1.0, 0.3),
                    },
                    ..volume_core::render::Light::default()
                },
                ..base.clone()
            },
        ),
        (
            "supersampled",
            RenderSettings {
                supersample: 2,
                width: 90,
                height: 70,
                ..base
            },
        ),
    ]
}

#[test]
fn a_grid_and_a_mesh_render_across_ranks_exactly_as_in_one_process() {
    let dir = tempfile::tempdir().unwrap();
    for path in [write_grid(dir.path(), 1), write_ball(dir.path())] {
        let scene = open_scene(&path, &SceneOptions::default()).unwrap();
        let (lo, hi) = scene.value_range().unwrap();
        let iso = (lo + 0.5 * (hi - lo)) as f32;
        for ranks in [2, 3] {
            with_job(&path, ranks, Duration::from_mins(1), |cluster| {
                for (k, (what, settings)) in variants(iso).into_iter().enumerate() {
                    let camera =
                        Camera::orbit(&scene.world_bounds(), 30.0 + 20.0 * k as f32, 25.0, 40.0);
                    let want = local(&scene, &camera, &settings);
                    let got = cluster
                        .render(&scene, &camera, &settings, &AtomicBool::new(false))
                        .unwrap()
                        .unwrap();
                    let what = format!("{} on {ranks} ranks: {what}", path.display());
                    assert_same(&got, &want, &what);
                    let report = cluster.last_report().unwrap();
                    assert_eq!(report.ranks.len(), ranks);
                    let chunks: usize = report.ranks.iter().map(|r| r.chunks).sum();
                    let grid = super::schedule::ChunkGrid {
                        width: settings.width,
                        height: settings.height,
                        scale: settings.scale,
                    };
                    assert_eq!(chunks, grid.len(), "{what}");
                }
                assert!(
                    cluster.last_report().unwrap().gather_bytes > 0,
                    "the workers sent pixels"
                );
            });
        }
    }
}

#[test]
fn a_time_step_the_intersector_and_the_normals_reach_every_rank() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_grid(dir.path(), 3);
    let mut scene = open_scene(&path, &SceneOptions::default()).unwrap();
    scene.set_step(2).unwrap();
    let view = crate::scene::ViewOptions {
        intersector: volume_core::intersect::Intersector::Linear,
        normals: Some(volume_core::render::Normals::Faceted),
    };
    scene.data_mut().set_view_options(&view);
    let (lo, hi) = scene.value_range().unwrap();
    let (_, settings) = variants((lo + 0.4 * (hi - lo)) as f32).swap_remove(0);
    let camera = Camera::orbit(&scene.world_bounds(), 40.0, 30.0, 40.0);
    let want = local(&scene, &camera, &settings);
    let step0 = open_scene(&path, &SceneOptions::default()).unwrap();
    assert_ne!(
        local(&step0, &camera, &settings).depth,
        want.depth,
        "the steps differ, so the test can tell them apart"
    );
    with_job(&path, 3, Duration::from_mins(1), |cluster| {
        let got = cluster
            .render(&scene, &camera, &settings, &AtomicBool::new(false))
            .unwrap()
            .unwrap();
        assert_same(&got, &want, "step 2, linear intersector");
    });
}

#[test]
fn a_rank_that_cannot_open_the_input_fails_the_job_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_grid(dir.path(), 1);
    let scene = open_scene(&path, &SceneOptions::default()).unwrap();
    let mut links = LocalLink::group(3).into_iter();
    let root = links.next().unwrap();
    let start = Instant::now();
    let err = std::thread::scope(|s| {
        for link in links {
            let path = path.clone();
            s.spawn(move || {
                // Rank 2 sees another file system: its input is missing.
                let mine = if link.rank() == 2 {
                    path.with_file_name("missing.nrrd")
                } else {
                    path
                };
                let opened = open_scene(&mine, &SceneOptions::default());
                match worker::report_opened(&link, opened) {
                    Some(mut scene) => worker::serve(&link, &mut scene),
                    None => worker::serve_none(&link),
                }
            });
        }
        let mut cluster = Cluster::new(Box::new(root), &path, Duration::from_mins(1));
        let camera = Camera::orbit(&scene.world_bounds(), 30.0, 20.0, 40.0);
        let (_, settings) = variants(0.5).swap_remove(0);
        let err = cluster
            .render(&scene, &camera, &settings, &AtomicBool::new(false))
            .unwrap_err();
        assert!(!cluster.serves(&path), "a failed job serves no more frames");
        cluster.shut_down();
        crate::cli::error_text(&err)
    });
    assert!(err.starts_with("rank 2: "), "{err}");
    assert!(err.contains("missing.nrrd"), "{err}");
    assert!(start.elapsed() < Duration::from_secs(30));
}

#[test]
fn a_rank_that_stops_answering_fails_the_frame_within_the_timeout() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_grid(dir.path(), 1);
    let scene = open_scene(&path, &SceneOptions::default()).unwrap();
    let mut links = LocalLink::group(2).into_iter();
    let root = links.next().unwrap();
    let silent = links.next().unwrap();
    // Rank 1 opens, then hangs: it reads its messages and never answers.
    silent.send(0, Tag::Opened, &[]);
    let hung =
        std::thread::spawn(move || while silent.recv().is_some_and(|e| e.tag != Tag::Quit) {});
    let mut cluster = Cluster::new(Box::new(root), &path, Duration::from_millis(300));
    let camera = Camera::orbit(&scene.world_bounds(), 30.0, 20.0, 40.0);
    let (_, settings) = variants(0.5).swap_remove(0);
    let start = Instant::now();
    let err = cluster
        .render(&scene, &camera, &settings, &AtomicBool::new(false))
        .unwrap_err();
    assert!(start.elapsed() < Duration::from_secs(10));
    let text = crate::cli::error_text(&err);
    assert!(text.contains("rank 1 sent no tile results"), "{text}");
    assert!(cluster.failure().is_some());
    cluster.shut_down();
    hung.join().unwrap();
}

#[test]
fn a_cancelled_frame_returns_none_and_the_job_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_grid(dir.path(), 1);
    let scene = open_scene(&path, &SceneOptions::default()).unwrap();
    let camera = Camera::orbit(&scene.world_bounds(), 30.0, 20.0, 40.0);
    let (_, settings) = variants(0.5).swap_remove(0);
    with_job(&path, 2, Duration::from_mins(1), |cluster| {
        let got = cluster
            .render(&scene, &camera, &settings, &AtomicBool::new(true))
            .unwrap();
        assert!(got.is_none());
        let again = cluster
            .render(&scene, &camera, &settings, &AtomicBool::new(false))
            .unwrap()
            .unwrap();
        assert_same(&again, &local(&scene, &camera, &settings), "after a cancel");
    });
}
