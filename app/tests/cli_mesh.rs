//! Tetrahedral meshes through the `isoscope` binary: `generate tet-*`, `info` (counts against
//! the generator's cell count and the file read back), `render` (the tet-ball's `distance`
//! isosurface against the analytic sphere), `bench --json` for meshes, mesh time series
//! (`.pvd`), and clear errors for bad files and flags.

mod common;
use common::{fails, ok};

use std::path::{Path, PathBuf};

use data_samples::tets::{BALL_RADIUS, CENTRE};
use glam::{DVec3, Vec3};
use volume_core::render::{Camera, Projection};

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Cells of an `n`³ grid on [−1, 1]³ whose centre lies in the ball: counted here from the
/// ball's definition, not by the generator.
fn ball_cells(n: usize) -> usize {
    let h = 2.0 / n as f64;
    let c = DVec3::from(CENTRE);
    let mut count = 0;
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let p = DVec3::new(i as f64 + 0.5, j as f64 + 0.5, k as f64 + 0.5) * h - DVec3::ONE;
                if p.distance(c) <= BALL_RADIUS {
                    count += 1;
                }
            }
        }
    }
    count
}

fn ball(dir: &Path, n: usize) -> PathBuf {
    let p = dir.join("ball.vtu");
    ok(&[
        "generate",
        "tet-ball",
        "--size",
        &n.to_string(),
        "-o",
        s(&p),
    ]);
    p
}

fn info_json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&ok(&["info", s(p), "--json"])).unwrap()
}

#[test]
fn info_counts_tets_points_arrays_and_bounds() {
    let dir = tempfile::tempdir().unwrap();
    let n = 10;
    let p = ball(dir.path(), n);
    let v = info_json(&p);
    assert_eq!(v["kind"], "tet");
    // 6 tets per kept hexahedral cell.
    assert_eq!(v["tets"].as_u64().unwrap() as usize, 6 * ball_cells(n));
    // The file read back independently of the CLI.
    let mesh = formats::mesh::read_mesh(&p).unwrap().mesh;
    assert_eq!(v["points"].as_u64().unwrap() as usize, mesh.num_points());
    assert_eq!(
        v["arrays"],
        serde_json::json!(["distance", "gaussians", "moving_gaussian"])
    );
    let b = mesh.bounds();
    assert_eq!(
        v["bounds"],
        serde_json::json!([b.min.as_dvec3().to_array(), b.max.as_dvec3().to_array()])
    );
    // Every point lies on the [−1, 1]³ grid within the ball's reach.
    for a in 0..3 {
        let lo = v["bounds"][0][a].as_f64().unwrap();
        let hi = v["bounds"][1][a].as_f64().unwrap();
        assert!(
            (-1.0..-0.7).contains(&lo) && (0.7..=1.0).contains(&hi),
            "{lo} {hi}"
        );
    }
    let d = &v["array_ranges"][0];
    assert_eq!(d["name"], "distance");
    let [lo, hi] = [0, 1].map(|i| d["value_range"][i].as_f64().unwrap());
    assert!(
        (0.0..0.2).contains(&lo) && hi > BALL_RADIUS && hi < 1.2,
        "{lo} {hi}"
    );
    assert_eq!(v["time_steps"], 1);

    let text = ok(&["info", s(&p)]);
    assert!(text.contains("tetrahedral mesh"), "{text}");
    for name in ["distance", "gaussians", "moving_gaussian"] {
        assert!(text.contains(name), "{text}");
    }
}

#[test]
fn generate_tets_targets_a_count_and_writes_legacy_vtk() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("torus.vtk");
    let out = ok(&["generate", "tet-torus", "--tets", "20000", "-o", s(&p)]);
    assert!(out.contains("tets"), "{out}");
    let v = info_json(&p);
    let tets = v["tets"].as_u64().unwrap();
    assert!((12_000..=30_000).contains(&tets), "{tets}");
    // No overwrite without --force.
    let e = fails(&["generate", "tet-torus", "--tets", "2000", "-o", s(&p)]);
    assert!(e.contains("--force"), "{e}");
    let e = fails(&["generate", "tet-shell", "-o", s(&dir.path().join("x.nrrd"))]);
    assert!(e.contains(".vtu or .vtk"), "{e}");
}

/// Pinhole camera looking at the ball from +z, slightly off-axis.
fn camera() -> Camera {
    Camera {
        eye: Vec3::new(0.2, -0.1, 3.5),
        target: Vec3::new(0.0, 0.0, 0.0),
        up: Vec3::Y,
        vfov_deg: 30.0,
        projection: Projection::Pinhole,
        ortho_height: None,
    }
}

fn render_depth(dir: &Path, mesh: &Path, name: &str, extra: &[&str]) -> (usize, usize, Vec<f32>) {
    let cam = dir.join("cam.json");
    std::fs::write(&cam, serde_json::to_string(&camera()).unwrap()).unwrap();
    let png = dir.join(format!("{name}.png"));
    let npy = dir.join(format!("{name}.npy"));
    let mut args = vec![
        "render",
        s(mesh),
        "--field",
        "distance",
        "--iso",
        "0.5",
        "--camera",
        s(&cam),
        "--size",
        "64x48",
        "-o",
        s(&png),
        "--depth-out",
        s(&npy),
    ];
    args.extend_from_slice(extra);
    ok(&args);
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (64, 48));
    let ((rows, cols), depth) =
        isoscope::cli::npy::read_f32_2d(std::fs::File::open(&npy).unwrap()).unwrap();
    (rows, cols, depth)
}

#[test]
fn rendered_tet_ball_matches_the_analytic_sphere() {
    let dir = tempfile::tempdir().unwrap();
    let n = 24;
    let mesh = ball(dir.path(), n);
    let (h, w, depth) = render_depth(dir.path(), &mesh, "faceted", &[]);
    assert_eq!((h, w), (48, 64));
    let cam = camera();
    let centre = DVec3::from(CENTRE);
    let r = 0.5;
    // Linear interpolation of |x − c| over tets of diameter d = √3·(2/n): the isosurface
    // moves by at most max|Hessian|·d²/2 = d²/(2(r − d)).
    let d = 3f64.sqrt() * 2.0 / n as f64;
    let err = d * d / (2.0 * (r - d));
    let (mut inside, mut outside) = (0, 0);
    for j in 0..h {
        for i in 0..w {
            let ray = cam.primary_ray(i as u32, j as u32, w as u32, h as u32);
            let (o, dir) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
            let oc = centre - o;
            let along = oc.dot(dir);
            let perp = (oc - dir * along).length();
            let got = depth[j * w + i];
            if perp < r - 2.0 * err {
                let t = along - (r * r - perp * perp).sqrt();
                let cos = (r * r - perp * perp).sqrt() / r;
                assert!(
                    (f64::from(got) - t).abs() <= err / cos + 1e-4,
                    "pixel ({i},{j}): depth {got}, sphere {t}, bound {}",
                    err / cos
                );
                inside += 1;
            } else if perp > r + 2.0 * err {
                assert!(
                    got.is_infinite(),
                    "pixel ({i},{j}) outside the silhouette hit {got}"
                );
                outside += 1;
            }
        }
    }
    assert!(inside > 300 && outside > 300, "{inside} {outside}");

    // Other packet sizes, the SAH builder and smooth normals hit the same points.
    for (name, extra) in [
        ("p2", &["--packet", "2"][..]),
        ("p1", &["--packet", "1"][..]),
        ("sah", &["--bvh", "sah", "--leaf-size", "4"][..]),
        ("smooth", &["--normals", "smooth"][..]),
    ] {
        let (_, _, other) = render_depth(dir.path(), &mesh, name, extra);
        for (k, (a, b)) in depth.iter().zip(&other).enumerate() {
            assert!(
                a == b || (a - b).abs() <= 1e-5 * a.abs(),
                "{name}: pixel {k}: {a} vs {b}"
            );
        }
    }
    let a = std::fs::read(dir.path().join("faceted.png")).unwrap();
    let b = std::fs::read(dir.path().join("smooth.png")).unwrap();
    assert_ne!(a, b, "smooth normals shade differently");
}

#[test]
fn bench_json_for_meshes_compares_packets() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = ball(dir.path(), 16);
    let json = ok(&[
        "bench",
        s(&mesh),
        "--iso",
        "0.5",
        "--size",
        "64x64",
        "--frames",
        "2",
        "--threads",
        "2",
        "--compare-bvh",
        "--iso-sweep",
        "3",
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    assert_eq!(v["kind"], "tet");
    assert!(v.get("dims").is_none());
    let configs = v["configs"].as_array().unwrap();
    let names: Vec<&str> = configs
        .iter()
        .map(|c| c["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["bvh-packet-16x16", "bvh-packet-2x2", "bvh-single"]);
    assert_eq!(v["rays_per_second"], configs[0]["rays_per_second"]);
    for c in configs {
        assert!(c["median_ms"].as_f64().unwrap() > 0.0);
        assert!(c["frames_per_second"].as_f64().unwrap() > 0.0);
        assert!(c["box_tests_per_frame"].as_u64().unwrap() > 0);
        assert!(c["isopolygon_tests_per_frame"].as_u64().unwrap() > 0);
    }
    let m = &v["mesh"];
    assert_eq!(m["tets"].as_u64().unwrap() as usize, 6 * ball_cells(16));
    assert_eq!(m["builder"], "sah");
    assert_eq!(m["packet_side"], 16);
    // Packets test boxes for the whole packet at once: 2×2 needs more tests.
    assert!(m["box_test_ratio_2x2"].as_f64().unwrap() > 1.0, "{m}");
    assert_eq!(m["other_builder"]["builder"], "bih");
    assert!(v["build_seconds"].as_f64().unwrap() > 0.0);
    let sweep = &v["iso_sweep"];
    assert_eq!(sweep["frame_ms"].as_array().unwrap().len(), 3);
    assert!(sweep["median_ratio"].as_f64().unwrap() > 0.0);
}

#[test]
fn mesh_series_from_a_pvd() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("moving.vtu");
    ok(&[
        "generate",
        "tet-ball",
        "--size",
        "8",
        "--steps",
        "3",
        "-o",
        s(&p),
    ]);
    let pvd = dir.path().join("moving.pvd");
    assert!(pvd.exists() && dir.path().join("moving_002.vtu").exists());
    let v = info_json(&pvd);
    assert_eq!(v["time_steps"], 3);
    assert_eq!(v["time_values"], serde_json::json!([0.0, 1.0, 2.0]));
    let out = dir.path().join("s.png");
    ok(&[
        "render",
        s(&pvd),
        "--field",
        "moving_gaussian",
        "--iso",
        "0.3",
        "--step",
        "2",
        "--size",
        "32x32",
        "-o",
        s(&out),
    ]);
    assert!(out.exists());
    let e = fails(&["render", s(&pvd), "--step", "3", "-o", s(&out)]);
    assert!(e.contains("3 time steps"), "{e}");
    // The same through a printf pattern.
    let pattern = dir.path().join("moving_%03d.vtu");
    let v = info_json(&pattern);
    assert_eq!(v["time_steps"], 3);
}

#[test]
fn bad_meshes_and_flags_give_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = ball(dir.path(), 4);
    let out = dir.path().join("o.png");
    let e = fails(&["render", s(&mesh), "--field", "pressure", "-o", s(&out)]);
    assert!(e.contains("pressure") && e.contains("distance"), "{e}");
    let e = fails(&["render", s(&mesh), "--packet", "3", "-o", s(&out)]);
    assert!(e.contains("packet side"), "{e}");
    let e = fails(&[
        "render",
        s(&mesh),
        "--dims",
        "4x4x4",
        "--type",
        "u8",
        "-o",
        s(&out),
    ]);
    assert!(e.contains("raw"), "{e}");
    let e = fails(&["render", s(&mesh), "--level-timeout", "1", "-o", s(&out)]);
    assert!(e.contains(".isot"), "{e}");

    // A volume does not take mesh flags, nor a --field (a NRRD has no named arrays; VTK
    // image data does).
    let vol = dir.path().join("v.nrrd");
    ok(&["generate", "sphere", "--size", "8", "-o", s(&vol)]);
    let e = fails(&["render", s(&vol), "--bvh", "sah", "-o", s(&out)]);
    assert!(e.contains("tetrahedral meshes"), "{e}");
    let e = fails(&["render", s(&vol), "--field", "distance", "-o", s(&out)]);
    assert!(
        e.contains("named point arrays") && e.contains("v.nrrd"),
        "{e}"
    );

    // Garbage and truncated files name the file.
    let bad = dir.path().join("bad.vtu");
    std::fs::write(
        &bad,
        b"<VTKFile type=\"UnstructuredGrid\"><Piece NumberOfPoints=\"9",
    )
    .unwrap();
    let e = fails(&["render", s(&bad), "-o", s(&out)]);
    assert!(e.contains("bad.vtu"), "{e}");
    let e = fails(&["info", s(&bad)]);
    assert!(e.contains("bad.vtu"), "{e}");
    let bytes = std::fs::read(&mesh).unwrap();
    let cut = dir.path().join("cut.vtu");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let e = fails(&["info", s(&cut)]);
    assert!(e.contains("cut.vtu"), "{e}");
    assert!(!out.exists());
    // A mesh without scalar arrays has nothing to draw.
    let m = formats::mesh::read_mesh(&mesh).unwrap().mesh;
    let bare = volume_core::tet::TetMesh::new(m.points, m.tets, Vec::new()).unwrap();
    let bare_path = dir.path().join("bare.vtu");
    formats::mesh::write_vtu(&bare_path, &bare, formats::output::Replace::Refuse).unwrap();
    let e = fails(&["render", s(&bare_path), "-o", s(&out)]);
    assert!(e.contains("no scalar point array"), "{e}");
}
