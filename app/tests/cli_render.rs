//! `isoscope render` and `isoscope bench` end to end on a generated sphere distance field:
//! the depth image equals the analytic ray–sphere distance within the trilinear
//! interpolation bound, the PNG has the requested size, bad input gives clear errors, and the
//! bench JSON carries its documented fields. NIfTI files (written by nibabel,
//! `formats/tests/data/nifti`) render like their NRRD twins written by `isoscope convert`,
//! and a scaled file's isovalues are physical: the surface lies where nibabel's scaled data
//! crosses the value.

mod common;
use common::{fails, ok};

use std::path::Path;

use data_samples::analytic::Sphere;
use formats::nrrd::{NrrdEncoding, write_nrrd};
use glam::Vec3;
use volume_core::VoxelType;
use volume_core::render::Camera;

/// A 41³ f32 sphere distance field over [−1, 1]³ (spacing 0.05).
fn sphere_volume(dir: &Path) -> std::path::PathBuf {
    let v = data_samples::Generator::Sphere
        .generate([41; 3], VoxelType::F32)
        .unwrap();
    let path = dir.join("sphere.nrrd");
    write_nrrd(
        &path,
        &v,
        NrrdEncoding::Raw,
        formats::output::Replace::Refuse,
    )
    .unwrap();
    path
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn render_depth_matches_the_analytic_sphere() {
    let dir = tempfile::tempdir().unwrap();
    let vol = sphere_volume(dir.path());
    let cam = Camera {
        eye: Vec3::new(0.3, -0.2, 4.0),
        target: Vec3::new(0.1, -0.05, 0.0),
        up: Vec3::Y,
        vfov_deg: 30.0,
        projection: volume_core::render::Projection::Pinhole,
        ortho_height: None,
    };
    let cam_path = dir.path().join("cam.json");
    std::fs::write(&cam_path, serde_json::to_string(&cam).unwrap()).unwrap();
    let png = dir.path().join("out.png");
    let npy = dir.path().join("depth.npy");
    let (w, h) = (61u32, 45u32);
    ok(&[
        "render",
        s(&vol),
        "--iso",
        "0.6",
        "--camera",
        s(&cam_path),
        "--size",
        &format!("{w}x{h}"),
        "-o",
        s(&png),
        "--depth-out",
        s(&npy),
    ]);
    let img = image::open(&png).unwrap();
    assert_eq!((img.width(), img.height()), (w, h));

    let ((rows, cols), depth) =
        isoscope::cli::npy::read_f32_2d(std::fs::File::open(&npy).unwrap()).unwrap();
    assert_eq!((rows, cols), (h as usize, w as usize));

    let sphere = Sphere::of_sphere_field(0.6);
    let tol = sphere.trilinear_error_bound([0.05; 3]).unwrap() + 1e-4;
    let (mut compared, mut centre_checked) = (0, false);
    for j in 0..h {
        for i in 0..w {
            let ray = cam.primary_ray(i, j, w, h);
            let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
            let got = depth[(j * w + i) as usize];
            match sphere.intersect(o, d) {
                None => {
                    // Well outside the silhouette nothing is hit.
                    let perp = (sphere.centre - o) - d * (sphere.centre - o).dot(d);
                    if perp.length() > 0.6 + tol * 4.0 {
                        assert_eq!(got, f32::INFINITY, "pixel ({i},{j})");
                    }
                }
                Some([t0, _]) => {
                    // Away from grazing incidence the depth error is the value error.
                    let n = sphere.normal(o + d * t0);
                    if n.dot(-d) > 0.5 {
                        assert!(
                            (f64::from(got) - t0).abs() <= tol / n.dot(-d),
                            "pixel ({i},{j}): depth {got} vs analytic {t0} (tol {tol})"
                        );
                        compared += 1;
                        centre_checked |= i == w / 2 && j == h / 2;
                    }
                }
            }
        }
    }
    assert!(compared > 300, "{compared}");
    assert!(centre_checked);
    // The centre pixel's ray points at the target, which is inside the sphere.
    assert!(depth[(h / 2 * w + w / 2) as usize].is_finite());
}

#[test]
fn render_options_reach_the_image() {
    let dir = tempfile::tempdir().unwrap();
    let vol = sphere_volume(dir.path());
    let plain = dir.path().join("plain.png");
    let fancy = dir.path().join("fancy.png");
    let npy = dir.path().join("d.npy");
    ok(&["render", s(&vol), "--size", "48x32", "-o", s(&plain)]);
    ok(&[
        "render",
        s(&vol),
        "--size",
        "48x32",
        "--iso",
        "0.5:#ff0000:0.5",
        "--iso",
        "0.3:#00ff00",
        "--orbit",
        "-40,10",
        "--shadows",
        "--light-dir",
        "1,1,1",
        "--clip-box",
        "-2,-2,-2,2,2,0:inside",
        "--clip-plane",
        "1,0,0,0.5",
        "--layers",
        "3",
        "--background",
        "#ffffff",
        "--intersector",
        "neubauer:4",
        "-o",
        s(&fancy),
        "--depth-out",
        s(&npy),
    ]);
    let a = image::open(&plain).unwrap().to_rgba8();
    let b = image::open(&fancy).unwrap().to_rgba8();
    assert_ne!(a.as_raw(), b.as_raw());
    // White background in the corner.
    assert_eq!(b.get_pixel(0, 0).0, [255, 255, 255, 255]);
}

#[test]
fn render_errors_are_clear() {
    let dir = tempfile::tempdir().unwrap();
    let vol = sphere_volume(dir.path());
    let out = dir.path().join("o.png");
    let e = fails(&["render", s(&vol), "--iso", "abc", "-o", s(&out)]);
    assert!(
        e.contains("abc") && e.contains("not a finite number"),
        "{e}"
    );
    let e = fails(&["render", s(&vol), "-o", s(&vol)]);
    assert!(e.contains("is the input file"), "{e}");
    let e = fails(&["render", s(&vol), "--size", "10x0", "-o", s(&out)]);
    assert!(e.contains("10x0"), "{e}");
    let e = fails(&["render", s(&vol), "--step", "2", "-o", s(&out)]);
    assert!(e.contains("not a time series"), "{e}");
    let cam = dir.path().join("cam.json");
    std::fs::write(&cam, "{\"eye\": [0, 0, 1]}").unwrap();
    let e = fails(&["render", s(&vol), "--camera", s(&cam), "-o", s(&out)]);
    assert!(e.contains("cam.json"), "{e}");
    let e = fails(&[
        "render",
        dir.path().join("missing.nrrd").to_str().unwrap(),
        "-o",
        s(&out),
    ]);
    assert!(e.contains("missing.nrrd"), "{e}");
    assert!(!out.exists());
}

/// Flags meant for another kind of file are errors, messages say each thing once, an
/// isovalue outside the data draws an empty picture with a warning, and `-o` writes what its
/// extension names.
#[test]
fn render_refuses_foreign_flags_and_writes_what_the_name_says() {
    let dir = tempfile::tempdir().unwrap();
    let vol = sphere_volume(dir.path());
    let out = dir.path().join("o.png");
    // A header gives the layout: --dims/--type are not silently ignored.
    let e = fails(&[
        "render",
        s(&vol),
        "--dims",
        "41x41x41",
        "--type",
        "f32",
        "--endian",
        "little",
        "-o",
        s(&out),
    ]);
    assert!(e.contains("sphere.nrrd") && e.contains("own layout"), "{e}");
    let e = fails(&["render", s(&vol), "--dims", "41x41x41", "-o", s(&out)]);
    assert!(e.contains("--type") && e.contains("NRRD"), "{e}");
    // A mesh has no cell intersector.
    let mesh = dir.path().join("ball.vtu");
    ok(&["generate", "tet-ball", "--tets", "500", "-o", s(&mesh)]);
    let e = fails(&["render", s(&mesh), "--intersector", "linear", "-o", s(&out)]);
    assert!(
        e.contains("--intersector linear") && e.contains("ball.vtu"),
        "{e}"
    );
    // Arrays are listed as names, not as a Rust debug list.
    let e = fails(&["render", s(&mesh), "--field", "zzz", "-o", s(&out)]);
    assert!(
        e.contains("available: distance, gaussians, moving_gaussian") && !e.contains('['),
        "{e}"
    );
    // A missing file is reported once.
    let missing = dir.path().join("missing.nrrd");
    let e = fails(&["render", s(&missing), "-o", s(&out)]);
    assert_eq!(e.matches("No such file or directory").count(), 1, "{e}");
    assert!(!out.exists());

    // An isovalue beyond the data: a warning, and every pixel misses (the depth says so).
    let depth = dir.path().join("d.npy");
    let run = common::isoscope(&[
        "render",
        s(&vol),
        "--iso",
        "1e9",
        "--size",
        "24x16",
        "-o",
        s(&out),
        "--depth-out",
        s(&depth),
    ]);
    let e = String::from_utf8_lossy(&run.stderr);
    assert!(
        run.status.success() && e.contains("outside the data's value range"),
        "{e}"
    );
    assert!(read_depth(&depth).iter().all(|d| d.is_infinite()));

    // JPEG by name: JPEG bytes, decoding to the PNG's picture within JPEG's error.
    let png = dir.path().join("a.png");
    let jpg = dir.path().join("a.JPG");
    ok(&["render", s(&vol), "--size", "64x48", "-o", s(&png)]);
    ok(&["render", s(&vol), "--size", "64x48", "-o", s(&jpg)]);
    let bytes = std::fs::read(&jpg).unwrap();
    assert_eq!(&bytes[..3], &[0xFF, 0xD8, 0xFF]);
    let a = image::open(&png).unwrap().to_rgb8();
    let b = image::load_from_memory_with_format(&bytes, image::ImageFormat::Jpeg)
        .unwrap()
        .to_rgb8();
    assert_eq!(a.dimensions(), b.dimensions());
    let mean_error = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| f64::from(x.abs_diff(*y)))
        .sum::<f64>()
        / a.as_raw().len() as f64;
    assert!(mean_error < 3.0, "{mean_error}");
    // Any other extension is refused before rendering, and nothing is written.
    let bmp = dir.path().join("a.bmp");
    let e = fails(&["render", s(&vol), "-o", s(&bmp)]);
    assert!(e.contains("a.bmp") && e.contains(".jpg"), "{e}");
    assert!(!bmp.exists());
}

/// `info` prints values the way their type reads: integers without decimals, `f32` values
/// that read back as the same `f32`, tiny values in exponent notation.
#[test]
fn info_prints_values_as_their_type_reads() {
    let dir = tempfile::tempdir().unwrap();
    // A raw f32 file of tiny and ordinary values.
    let values: [f32; 8] = [
        3.673_669_7e-22,
        0.8,
        1.5e-21,
        2.0e-22,
        1.0e-21,
        0.25,
        0.5,
        0.75,
    ];
    let raw = dir.path().join("tiny.raw");
    std::fs::write(&raw, bytemuck::cast_slice::<f32, u8>(&values)).unwrap();
    let text = ok(&[
        "info",
        s(&raw),
        "--dims",
        "2x2x2",
        "--type",
        "f32",
        "--endian",
        "little",
    ]);
    let range = text
        .lines()
        .find_map(|l| l.strip_prefix("value range:"))
        .unwrap();
    let mut ends = range.split_whitespace();
    let lo: f32 = ends.next().unwrap().parse().unwrap();
    assert_eq!(ends.next(), Some(".."));
    let hi: f32 = ends.next().unwrap().parse().unwrap();
    assert_eq!((lo, hi), (2.0e-22, 0.8));
    assert!(range.len() < 40, "{range}");
    // Integer data: the range and histogram edges are whole numbers.
    let phantom =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../data-samples/samples/phantom64_i16.nrrd");
    let text = ok(&["info", s(&phantom)]);
    let range = text
        .lines()
        .find_map(|l| l.strip_prefix("value range:"))
        .unwrap();
    assert!(!range.replace("..", "").contains('.'), "{range}");
    let edges: Vec<&str> = text
        .lines()
        .filter(|l| l.contains(" | "))
        .map(|l| l.split(" | ").next().unwrap().trim())
        .collect();
    assert_eq!(edges.len(), 64);
    assert!(edges.iter().all(|e| e.parse::<i64>().is_ok()), "{edges:?}");
}

/// `render` of the sphere volume at iso 0.6 in blue, orbit 30°/20°, 40×30, with `extra`
/// flags: the picture and the depth map (of that shape), written as `tag.png` and `tag.npy`
/// in `dir`.
fn render_blue_sphere(
    dir: &Path,
    vol: &Path,
    tag: &str,
    extra: &[&str],
) -> (image::RgbaImage, Vec<f32>) {
    let (png, npy) = (
        dir.join(format!("{tag}.png")),
        dir.join(format!("{tag}.npy")),
    );
    let mut args = vec![
        "render",
        s(vol),
        "--iso",
        "0.6:#3080ff",
        "--orbit",
        "30,20",
        "--size",
        "40x30",
        "-o",
        s(&png),
        "--depth-out",
        s(&npy),
    ];
    args.extend_from_slice(extra);
    ok(&args);
    let ((rows, cols), depth) =
        isoscope::cli::npy::read_f32_2d(std::fs::File::open(&npy).unwrap()).unwrap();
    assert_eq!((rows, cols), (30, 40));
    (image::open(&png).unwrap().to_rgba8(), depth)
}

/// `--normals faceted` on a volume: the same hits (depth map bit for bit), shaded with the
/// cells' own normals (another picture); `bench` reports the normals of its frames.
#[test]
fn faceted_normals_shade_the_same_hits_of_a_volume() {
    let dir = tempfile::tempdir().unwrap();
    let vol = sphere_volume(dir.path());
    let render = |tag: &str, extra: &[&str]| render_blue_sphere(dir.path(), &vol, tag, extra);
    let (smooth_png, smooth) = render("smooth", &[]);
    let (faceted_png, faceted) = render("faceted", &["--normals", "faceted"]);
    let (again_png, _) = render("again", &["--normals", "smooth"]);
    let bits = |d: &[f32]| d.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&faceted), bits(&smooth));
    assert!(smooth.iter().filter(|d| d.is_finite()).count() > 40);
    assert_eq!(
        again_png.as_raw(),
        smooth_png.as_raw(),
        "smooth is the default"
    );
    let differ = smooth_png
        .pixels()
        .zip(faceted_png.pixels())
        .filter(|(a, b)| a != b)
        .count();
    assert!(differ > 0, "faceted normals shade otherwise");
    let err = fails(&[
        "render",
        s(&vol),
        "--normals",
        "bumpy",
        "-o",
        s(&dir.path().join("x.png")),
    ]);
    assert!(err.contains("faceted or smooth"), "{err}");

    let normals_of = |extra: &[&str]| {
        let mut args = vec![
            "bench",
            s(&vol),
            "--iso",
            "0.6",
            "--size",
            "16x16",
            "--frames",
            "1",
            "--skip-dda",
            "--skip-single",
            "--json",
        ];
        args.extend_from_slice(extra);
        let v: serde_json::Value = serde_json::from_str(&ok(&args)).unwrap();
        v["normals"].as_str().unwrap().to_string()
    };
    assert_eq!(normals_of(&[]), "smooth");
    assert_eq!(normals_of(&["--normals", "faceted"]), "faceted");
}

/// `render --depth-only` writes the shaded render's depth map bit for bit and an image of
/// flat colours; `bench --depth-only` says so in its JSON; neither takes shadows.
#[test]
fn depth_only_renders_the_same_depth_unshaded() {
    let dir = tempfile::tempdir().unwrap();
    let vol = sphere_volume(dir.path());
    let render = |tag: &str, extra: &[&str]| render_blue_sphere(dir.path(), &vol, tag, extra);
    let (shaded_png, shaded) = render("shaded", &[]);
    let (flat_png, flat) = render("flat", &["--depth-only"]);
    let bits = |d: &[f32]| d.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&flat), bits(&shaded));
    let hit_colours: std::collections::BTreeSet<[u8; 4]> = flat_png
        .pixels()
        .zip(&flat)
        .filter(|(_, d)| d.is_finite())
        .map(|(p, _)| p.0)
        .collect();
    let shaded_colours = shaded_png
        .pixels()
        .zip(&shaded)
        .filter(|(_, d)| d.is_finite())
        .map(|(p, _)| p.0)
        .collect::<std::collections::BTreeSet<_>>();
    assert!(flat.iter().filter(|d| d.is_finite()).count() > 40);
    assert_eq!(hit_colours.len(), 1, "one flat colour: {hit_colours:?}");
    assert!(shaded_colours.len() > 10, "the shaded image is lit");
    let err = fails(&[
        "render",
        s(&vol),
        "--depth-only",
        "--shadows",
        "-o",
        s(&dir.path().join("x.png")),
    ]);
    assert!(err.contains("--shadows"), "{err}");

    let json = ok(&[
        "bench",
        s(&vol),
        "--iso",
        "0.6",
        "--size",
        "32x32",
        "--frames",
        "1",
        "--skip-dda",
        "--skip-single",
        "--depth-only",
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    assert_eq!(v["depth_only"], true);
    assert!(v["configs"][0]["median_ms"].as_f64().unwrap() > 0.0);
}

#[test]
fn bench_json_has_the_documented_fields() {
    let dir = tempfile::tempdir().unwrap();
    let vol = sphere_volume(dir.path());
    let json = ok(&[
        "bench",
        s(&vol),
        "--iso",
        "0.6",
        "--size",
        "48x48",
        "--frames",
        "2",
        "--threads",
        "2",
        "--intersectors",
        "linear,exact",
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    assert!(v["rays_per_second"].as_f64().unwrap() > 0.0);
    assert_eq!(v["threads"], 2);
    assert_eq!(v["dims"], serde_json::json!([41, 41, 41]));
    let configs = v["configs"].as_array().unwrap();
    let names: Vec<&str> = configs
        .iter()
        .map(|c| c["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["kdtree-packet", "kdtree-single", "dda"]);
    assert_eq!(v["rays_per_second"], configs[0]["rays_per_second"]);
    for c in configs {
        assert!(c["median_ms"].as_f64().unwrap() > 0.0);
        assert!(c["nodes_per_ray"].as_f64().unwrap() >= 0.0);
        assert!(c["speedup_vs_dda"].as_f64().unwrap() > 0.0);
    }
    assert!(v["memory_overhead"].as_f64().unwrap() > 0.0);
    let rows = v["intersectors"].as_array().unwrap();
    assert_eq!(rows.len(), 2);
    let exact = &rows[1];
    assert_eq!(exact["name"], "exact");
    assert!(exact["rays"].as_u64().unwrap() == 48 * 48);
    assert!(exact["reference_hits"].as_u64().unwrap() > 100);
    assert_eq!(exact["missed_percent"], 0.0);
    assert_eq!(exact["false_hits_percent"], 0.0);
}

#[test]
fn bench_shadows_trace_one_shadow_ray_per_lit_hit() {
    let dir = tempfile::tempdir().unwrap();
    let vol = sphere_volume(dir.path());
    let bench = |extra: &[&str]| -> serde_json::Value {
        let mut args = vec![
            "bench",
            s(&vol),
            "--size",
            "32x32",
            "--frames",
            "1",
            "--skip-dda",
            "--skip-single",
            "--json",
        ];
        args.extend_from_slice(extra);
        serde_json::from_str(ok(&args).trim()).unwrap()
    };
    let plain = &bench(&[])["configs"][0];
    let shadowed = &bench(&["--shadows"])["configs"][0];
    assert_eq!(plain["shadow_rays_per_frame"], 0);
    // The same frame with a key light: a shadow ray from every hit that faces the light (at
    // most one per pixel, and the sphere fills a good part of the frame).
    let shadow_rays = shadowed["shadow_rays_per_frame"].as_u64().unwrap();
    assert!(shadow_rays > 50 && shadow_rays <= 32 * 32, "{shadow_rays}");
}

#[test]
fn bench_iso_sweep_changes_the_isovalue_every_frame() {
    let dir = tempfile::tempdir().unwrap();
    let vol = sphere_volume(dir.path());
    let json = ok(&[
        "bench",
        s(&vol),
        "--size",
        "32x32",
        "--frames",
        "3",
        "--skip-dda",
        "--iso-sweep",
        "4",
        "--json",
    ]);
    let v: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    assert_eq!(v["kind"], "grid");
    let w = &v["iso_sweep"];
    let isos: Vec<f64> = w["isovalues"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert_eq!(isos.len(), 4);
    assert!(isos.windows(2).all(|p| p[1] > p[0]), "{isos:?}");
    // Over the middle half of the value range of the file.
    let info: serde_json::Value = serde_json::from_str(&ok(&["info", s(&vol), "--json"])).unwrap();
    let [lo, hi] = [0, 1].map(|i| info["value_range"][i].as_f64().unwrap());
    assert!((isos[0] - (lo + 0.25 * (hi - lo))).abs() < 1e-5, "{isos:?}");
    assert!((isos[3] - (lo + 0.75 * (hi - lo))).abs() < 1e-5, "{isos:?}");
    assert_eq!(w["frame_ms"].as_array().unwrap().len(), 4);
    assert_eq!(w["steady_median_ms"], v["configs"][0]["median_ms"]);
    assert!(w["max_ratio"].as_f64().unwrap() >= w["median_ratio"].as_f64().unwrap());
    assert!(w["build_ms"].as_f64().unwrap() > 0.0);
}

/// Every twin listed in `formats/tests/data/<format>/truth.json`: the file to open (a
/// pattern for numbered TIFF slices), its NRRD twin (same voxels and geometry, written by
/// pynrrd) and an isovalue.
fn image_twins() -> Vec<(std::path::PathBuf, std::path::PathBuf, f64)> {
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../formats/tests/data");
    let mut twins = Vec::new();
    for folder in ["metaimage", "vtk_image", "tiff"] {
        let dir = data.join(folder);
        let text = std::fs::read_to_string(dir.join("truth.json")).unwrap();
        let entries: serde_json::Value = serde_json::from_str(&text).unwrap();
        for e in entries.as_array().unwrap() {
            if let Some(twin) = e["twin"].as_str() {
                twins.push((
                    dir.join(e["open"].as_str().unwrap()),
                    dir.join(twin),
                    e["iso"].as_f64().unwrap(),
                ));
            }
        }
    }
    twins
}

#[test]
fn image_formats_render_like_their_nrrd_twins() {
    // MetaImage (oblique, compressed, permuted, flipped), VTK XML and legacy images, TIFF
    // stacks and numbered slices: the same depth image as the NRRD of the same voxels and
    // geometry, from the same default camera (which follows the world bounds).
    let dir = tempfile::tempdir().unwrap();
    let twins = image_twins();
    assert!(twins.len() >= 8, "{} twins", twins.len());
    let depth = |file: &Path, iso: f64, name: &str| {
        let npy = dir.path().join(format!("{name}.npy"));
        let png = dir.path().join(format!("{name}.png"));
        ok(&[
            "render",
            s(file),
            "--iso",
            &iso.to_string(),
            "--size",
            "40x30",
            "-o",
            s(&png),
            "--depth-out",
            s(&npy),
        ]);
        isoscope::cli::npy::read_f32_2d(std::fs::File::open(&npy).unwrap())
            .unwrap()
            .1
    };
    for (i, (file, twin, iso)) in twins.iter().enumerate() {
        let a = depth(file, *iso, &format!("a{i}"));
        let b = depth(twin, *iso, &format!("b{i}"));
        let hits = a.iter().filter(|d| d.is_finite()).count();
        assert!(hits > 50, "{}: only {hits} pixels hit", file.display());
        assert_eq!(a, b, "{} and its twin {}", file.display(), twin.display());
    }
}
fn nifti_data(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../formats/tests/data/nifti")
        .join(name)
}

fn read_depth(path: &Path) -> Vec<f32> {
    isoscope::cli::npy::read_f32_2d(std::fs::File::open(path).unwrap())
        .unwrap()
        .1
}

#[test]
fn nifti_renders_like_its_nrrd_twin() {
    let dir = tempfile::tempdir().unwrap();
    // (file, isovalue in physical units, extra flags): oblique float sform, scaled int16
    // (its twin holds the physical values as i16), step 1 of an oblique 4D gzip file.
    let cases: [(&str, &str, &[&str]); 3] = [
        ("sform_oblique.nii", "1.2", &[]),
        ("scaled_i16.nii", "500", &[]),
        ("example4d.nii.gz", "300", &["--step", "1"]),
    ];
    for (name, iso, extra) in cases {
        let nii = nifti_data(name);
        let twin = dir.path().join(format!("{name}.nrrd"));
        let mut args = vec!["convert", s(&nii), "-o", s(&twin)];
        args.extend_from_slice(extra);
        ok(&args);
        let mut depths = Vec::new();
        for (tag, input) in [("nii", &nii), ("nrrd", &twin)] {
            let png = dir.path().join(format!("{name}.{tag}.png"));
            let npy = dir.path().join(format!("{name}.{tag}.npy"));
            let mut args = vec![
                "render",
                s(input),
                "--iso",
                iso,
                "--size",
                "41x33",
                "--orbit",
                "35,25",
                "-o",
                s(&png),
                "--depth-out",
                s(&npy),
            ];
            if tag == "nii" {
                args.extend_from_slice(extra);
            }
            ok(&args);
            depths.push(read_depth(&npy));
        }
        let (a, b) = (&depths[0], &depths[1]);
        let hits = a.iter().filter(|d| d.is_finite()).count();
        assert!(hits > 100, "{name}: {hits} hits");
        for (i, (x, y)) in a.iter().zip(b).enumerate() {
            assert!(
                x == y || (x - y).abs() <= 1e-5 * (1.0 + x.abs()),
                "{name} pixel {i}: {x} vs {y}"
            );
        }
    }
}

#[test]
fn a_scaled_nifti_is_physical_in_info_and_render() {
    let dir = tempfile::tempdir().unwrap();
    let exp: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(nifti_data("expected.json")).unwrap())
            .unwrap();
    let e = exp["files"]
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f["file"] == "scaled_i16.nii")
        .unwrap();
    let nii = nifti_data("scaled_i16.nii");
    let info: serde_json::Value = serde_json::from_str(&ok(&["info", s(&nii), "--json"])).unwrap();
    assert_eq!(info["value_map"]["slope"], e["scl_slope"]);
    assert_eq!(info["value_map"]["intercept"], e["scl_inter"]);
    assert_eq!(info["value_range"][0], e["min"]);
    assert_eq!(info["value_range"][1], e["max"]);
    assert_eq!(info["voxel_type"], "i16");
    assert_eq!(info["world_frame"], "RAS");
    // A ray along +x at (y, z) = (5.25, 4.5) (the file's affine is the identity): trilinear
    // interpolation there is linear in x between samples of the bilinear mix of nibabel's four
    // rows around it, so the first crossing of the isovalue is known exactly.
    let (y, z, iso) = (5.25, 4.5, 500.0);
    let rows = exp["profiles"].as_array().unwrap();
    let row = |j: u64, k: u64| -> Vec<f64> {
        let r = rows.iter().find(|r| r["j"] == j && r["k"] == k).unwrap();
        r["values"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect()
    };
    let (fy, fz) = (y - 5.0, z - 4.0);
    let (r00, r10, r01, r11) = (row(5, 4), row(6, 4), row(5, 5), row(6, 5));
    let mix: Vec<f64> = (0..r00.len())
        .map(|i| {
            (1.0 - fy) * (1.0 - fz) * r00[i]
                + fy * (1.0 - fz) * r10[i]
                + (1.0 - fy) * fz * r01[i]
                + fy * fz * r11[i]
        })
        .collect();
    assert!(mix[0] < iso, "the ray enters below the isovalue");
    let i = mix.windows(2).position(|w| w[1] >= iso).unwrap();
    let x_cross = i as f64 + (iso - mix[i]) / (mix[i + 1] - mix[i]);
    let cam = Camera {
        eye: Vec3::new(-20.0, y as f32, z as f32),
        target: Vec3::new(5.0, y as f32, z as f32),
        up: Vec3::Z,
        vfov_deg: 20.0,
        projection: volume_core::render::Projection::Pinhole,
        ortho_height: None,
    };
    let cam_path = dir.path().join("cam.json");
    std::fs::write(&cam_path, serde_json::to_string(&cam).unwrap()).unwrap();
    let (png, npy) = (dir.path().join("s.png"), dir.path().join("s.npy"));
    let (w, h) = (9u32, 7u32);
    ok(&[
        "render",
        s(&nii),
        "--iso",
        "500",
        "--camera",
        s(&cam_path),
        "--size",
        &format!("{w}x{h}"),
        "-o",
        s(&png),
        "--depth-out",
        s(&npy),
    ]);
    let ray = cam.primary_ray(w / 2, h / 2, w, h);
    assert!((ray.dir - Vec3::X).length() < 1e-6, "{:?}", ray.dir);
    let want = x_cross - f64::from(ray.origin.x);
    let got = f64::from(read_depth(&npy)[(h / 2 * w + w / 2) as usize]);
    assert!(
        (got - want).abs() < 1e-3,
        "depth {got} vs {want} (crossing at x = {x_cross})"
    );
}

/// A DICOM series (oblique, written by pydicom: `formats/tests/data/dicom/synthetic/twin`)
/// and its NRRD twin — the voxels and geometry pydicom + numpy report (`truth.json`), written
/// as NRRD here — render to the same depth image from the same auto camera.
#[test]
fn a_dicom_series_renders_like_its_nrrd_twin() {
    use glam::{DAffine3, DMat3, DVec3};
    use volume_core::{AxisCoords, Grid, RectilinearVolume, WorldFrame};

    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../formats/tests/data/dicom");
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data.join("truth.json")).unwrap()).unwrap();
    let case = &truth["cases"]["twin"];
    let nums = |v: &serde_json::Value| -> Vec<f64> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let dims: Vec<usize> = nums(&case["dims"]).iter().map(|&d| d as usize).collect();
    let w = &case["world_from_grid"];
    let cols: Vec<Vec<f64>> = w["columns"].as_array().unwrap().iter().map(nums).collect();
    let col = |c: &Vec<f64>| DVec3::new(c[0], c[1], c[2]);
    let origin = nums(&w["origin"]);
    let spacing = nums(&w["spacing"]);
    let m = DAffine3::from_mat3_translation(
        DMat3::from_cols(col(&cols[0]), col(&cols[1]), col(&cols[2])),
        DVec3::new(origin[0], origin[1], origin[2]),
    );
    let axes = [0, 1, 2].map(|a| AxisCoords::Uniform {
        origin: 0.0,
        spacing: spacing[a],
    });
    let grid = Grid::new([dims[0], dims[1], dims[2]], axes, Some(m))
        .unwrap()
        .with_world_frame(WorldFrame::Lps);
    let voxels: Vec<u16> = nums(&case["voxels"]).iter().map(|&v| v as u16).collect();
    let twin = RectilinearVolume::new(grid, voxels.into()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let nrrd = dir.path().join("twin.nrrd");
    write_nrrd(
        &nrrd,
        &twin,
        NrrdEncoding::Raw,
        formats::output::Replace::Refuse,
    )
    .unwrap();

    let render = |input: &Path, name: &str| {
        let npy = dir.path().join(format!("{name}.npy"));
        let png = dir.path().join(format!("{name}.png"));
        ok(&[
            "render",
            s(input),
            "--iso",
            "250",
            "--orbit",
            "35,25",
            "--size",
            "64x48",
            "-o",
            s(&png),
            "--depth-out",
            s(&npy),
        ]);
        isoscope::cli::npy::read_f32_2d(std::fs::File::open(&npy).unwrap())
            .unwrap()
            .1
    };
    let from_dicom = render(&data.join("synthetic/twin"), "dicom");
    let from_nrrd = render(&nrrd, "nrrd");
    assert_eq!(from_dicom.len(), from_nrrd.len());
    let hits = from_dicom.iter().filter(|d| d.is_finite()).count();
    assert!(hits > 100, "{hits} pixels hit the surface");
    let mut mismatched = 0;
    let mut worst = 0.0f32;
    for (a, b) in from_dicom.iter().zip(&from_nrrd) {
        if a.is_finite() != b.is_finite() {
            mismatched += 1;
        } else if a.is_finite() {
            worst = worst.max((a - b).abs());
        }
    }
    // The DICOM positions and direction cosines are 6-digit decimal strings; the twin's
    // geometry is pydicom's reading of the same strings: the images agree to float precision.
    assert_eq!(mismatched, 0, "pixels hit in one image only");
    assert!(worst < 1e-3, "depths differ by up to {worst} mm");
}

/// A DICOM series (LPS) and the NIfTI `isoscope convert` writes from it (RAS) put every voxel
/// at the same place in the patient: their corners agree after each file's frame is mapped to
/// RAS, and the DICOM's first corner is where pydicom reads ImagePositionPatient
/// (`truth.json`), with x and y negated for RAS.
#[test]
fn a_dicom_series_and_its_nifti_line_up_in_patient_space() {
    use glam::DVec3;

    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../formats/tests/data/dicom");
    let series = data.join("synthetic/twin");
    let dir = tempfile::tempdir().unwrap();
    let nii = dir.path().join("twin.nii.gz");
    ok(&["convert", s(&series), "-o", s(&nii)]);
    let open = |p: &Path| match formats::open(p, &formats::OpenOptions::default()).unwrap() {
        formats::Dataset::Volume(v) => v,
        formats::Dataset::Series(_) => panic!("{} is one volume", p.display()),
    };
    let (dcm, nif) = (open(&series), open(&nii));
    assert_eq!(dcm.grid.world_frame(), volume_core::WorldFrame::Lps);
    assert_eq!(nif.grid.world_frame(), volume_core::WorldFrame::Ras);
    assert_eq!(dcm.dims(), nif.dims());
    let ras = |v: &volume_core::RectilinearVolume, i: usize, j: usize, k: usize| -> DVec3 {
        let g = &v.grid;
        let p = g.grid_position(i, j, k);
        let world = g.world_from_grid().map_or(p, |m| m.transform_point3(p));
        g.world_frame()
            .ras_from_world()
            .unwrap()
            .transform_point3(world)
    };
    let [nx, ny, nz] = dcm.dims();
    for (i, j, k) in [
        (0, 0, 0),
        (nx - 1, 0, 0),
        (0, ny - 1, 0),
        (0, 0, nz - 1),
        (nx - 1, ny - 1, nz - 1),
    ] {
        let (a, b) = (ras(&dcm, i, j, k), ras(&nif, i, j, k));
        assert!(
            (a - b).length() < 1e-3,
            "voxel ({i}, {j}, {k}): DICOM {a} vs NIfTI {b} (RAS mm)"
        );
    }
    let truth: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(data.join("truth.json")).unwrap()).unwrap();
    let o: Vec<f64> = truth["cases"]["twin"]["world_from_grid"]["origin"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    let first = ras(&dcm, 0, 0, 0);
    assert!(
        (first - DVec3::new(-o[0], -o[1], o[2])).length() < 1e-3,
        "first voxel {first} (RAS) vs pydicom's ImagePositionPatient {o:?} (LPS)"
    );
    // The same voxels, not only the same geometry.
    assert_eq!(dcm.value_f64(1, 2, 3), nif.value_f64(1, 2, 3));
}

/// `movie`: an orbit's frames are `render` frames turned about z (frame 0 is the default
/// view, the frame half a turn on is the orbit camera's opposite azimuth), a time series
/// plays step by step like `render --step`, without ffmpeg a note says so, and old frames
/// are replaced only with --force.
#[test]
fn movie_writes_orbit_and_time_series_frames() {
    let dir = tempfile::tempdir().unwrap();
    let vol = sphere_volume(dir.path());
    let frames = dir.path().join("orbit");
    let no_ffmpeg = tempfile::tempdir().unwrap();
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_isoscope"))
        .args(["movie", s(&vol), "--frames", "4", "--size", "40x30", "-o"])
        .arg(&frames)
        .env("PATH", no_ffmpeg.path())
        .env_remove("RUST_BACKTRACE")
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{e}");
    assert!(e.contains("ffmpeg is not on the PATH"), "{e}");
    let frame = |k: usize| {
        image::open(frames.join(format!("frame_{k:04}.png")))
            .unwrap()
            .to_rgba8()
    };
    for k in 0..4 {
        assert_eq!(frame(k).dimensions(), (40, 30));
    }
    assert!(!frames.join("frame_0004.png").exists());
    assert!(!frames.join("movie.mp4").exists());
    let still = |orbit: &str, name: &str| {
        let p = dir.path().join(name);
        ok(&[
            "render",
            s(&vol),
            "--size",
            "40x30",
            "--orbit",
            orbit,
            "-o",
            s(&p),
        ]);
        image::open(&p).unwrap().to_rgba8()
    };
    assert_eq!(frame(0), still("30,20", "r0.png"));
    // Half a turn: azimuth 210°. The cube's bounds frame alike from both sides; the eye
    // differs by rounding only, so compare the mean pixel difference.
    let (a, b) = (frame(2), still("210,20", "r2.png"));
    let mean = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .map(|(x, y)| f64::from(x.abs_diff(*y)))
        .sum::<f64>()
        / a.as_raw().len() as f64;
    assert!(mean < 1.0, "{mean}");
    assert_ne!(frame(0), frame(1));
    // With ffmpeg (where the machine has it): movie.mp4 holds the frames, as ffprobe counts.
    let ffprobe = std::process::Command::new("ffprobe")
        .arg("-version")
        .output();
    if ffprobe.is_ok_and(|o| o.status.success()) {
        let encoded = dir.path().join("encoded");
        ok(&[
            "movie",
            s(&vol),
            "--frames",
            "6",
            "--size",
            "40x30",
            "-o",
            s(&encoded),
        ]);
        let probe = std::process::Command::new("ffprobe")
            .args(["-v", "error", "-count_frames", "-select_streams", "v:0"])
            .args([
                "-show_entries",
                "stream=nb_read_frames,width,height",
                "-of",
                "csv=p=0",
            ])
            .arg(encoded.join("movie.mp4"))
            .output()
            .unwrap();
        assert_eq!(String::from_utf8_lossy(&probe.stdout).trim(), "40,30,6");
    }
    // Again without --force: refused, naming the frame.
    let e = fails(&["movie", s(&vol), "--frames", "4", "-o", s(&frames)]);
    assert!(e.contains("frame_0000.png") && e.contains("--force"), "{e}");

    // A time series: frame k is `render --step k`.
    let samples = Path::new(env!("CARGO_MANIFEST_DIR")).join("../data-samples/samples");
    let pattern = samples.join("blobs24_%03d.nrrd");
    let played = dir.path().join("played");
    ok(&[
        "movie",
        s(&pattern),
        "--time",
        "--size",
        "32x32",
        "--iso",
        "0.5",
        "-o",
        s(&played),
    ]);
    for k in 0..5 {
        let p = dir.path().join(format!("step{k}.png"));
        ok(&[
            "render",
            s(&pattern),
            "--step",
            &k.to_string(),
            "--size",
            "32x32",
            "--iso",
            "0.5",
            "-o",
            s(&p),
        ]);
        let step = image::open(&p).unwrap().to_rgba8();
        let shown = image::open(played.join(format!("frame_{k:04}.png")))
            .unwrap()
            .to_rgba8();
        assert_eq!(shown, step, "step {k}");
    }
    assert!(!played.join("frame_0005.png").exists());
    let e = fails(&["movie", s(&vol), "--time", "-o", s(&played)]);
    assert!(e.contains("one step"), "{e}");
}

/// `probe` returns a linear field exactly (trilinear interpolation reproduces it) with its
/// gradient and voxel index, on a volume and on a mesh written with the same field, and
/// `null`/"outside" beyond the data; `render --pick` reports the sphere a pixel shows: the
/// distance is the depth image's, the point lies on the analytic sphere, the value is the
/// isovalue and the normal is radial.
#[test]
fn probe_and_pick_report_values_against_analytic_fields() {
    let dir = tempfile::tempdir().unwrap();
    let field = |p: glam::DVec3| 3.0 * p.x - 2.0 * p.y + 0.5 * p.z + 7.0;
    let grid = volume_core::Grid::uniform([6, 5, 4], [-1.0, 0.0, 2.0], [0.5, 1.0, 2.0]).unwrap();
    let d = grid.dims();
    let mut values = Vec::new();
    for k in 0..d[2] {
        for j in 0..d[1] {
            for i in 0..d[0] {
                values.push(field(grid.grid_position(i, j, k)) as f32);
            }
        }
    }
    let v = volume_core::RectilinearVolume::new(grid, values.into()).unwrap();
    let linear = dir.path().join("linear.nrrd");
    write_nrrd(
        &linear,
        &v,
        NrrdEncoding::Raw,
        formats::output::Replace::Refuse,
    )
    .unwrap();
    let out = ok(&[
        "probe",
        s(&linear),
        "--at",
        "0.3,1.7,4.1",
        "--at",
        "9,9,9",
        "--json",
    ]);
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    let p = glam::DVec3::new(0.3, 1.7, 4.1);
    let got = j[0]["value"].as_f64().unwrap();
    assert!((got - field(p)).abs() < 1e-4, "{got} vs {}", field(p));
    let grad: Vec<f64> = (0..3)
        .map(|a| j[0]["gradient_world"][a].as_f64().unwrap())
        .collect();
    for (g, want) in grad.iter().zip([3.0, -2.0, 0.5]) {
        assert!((g - want).abs() < 1e-4, "{grad:?}");
    }
    // Continuous index: (x − origin) / spacing per axis.
    let index: Vec<f64> = (0..3)
        .map(|a| j[0]["location"]["index"][a].as_f64().unwrap())
        .collect();
    for (i, want) in index.iter().zip([2.6, 1.7, 1.05]) {
        assert!((i - want).abs() < 1e-5, "{index:?}");
    }
    assert_eq!(j[0]["location"]["kind"], "voxel");
    assert!(j[1].is_null());
    let text = ok(&["probe", s(&linear), "--at", "9,9,9"]);
    assert!(text.contains("outside the data"), "{text}");

    // A mesh: tet-ball's `distance` array is the distance from its centre, linear only
    // inside each tet; at a mesh point it is exact.
    let mesh = dir.path().join("ball.vtu");
    ok(&["generate", "tet-ball", "--tets", "2000", "-o", s(&mesh)]);
    let loaded = formats::mesh::read_mesh(&mesh).unwrap();
    let m = &loaded.mesh;
    let values = m.field("distance").unwrap();
    let q = m.points[m.tets[0][2] as usize];
    let at = format!("{},{},{}", q[0], q[1], q[2]);
    let out = ok(&[
        "probe",
        s(&mesh),
        "--field",
        "distance",
        "--at",
        &at,
        "--json",
    ]);
    let j: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(j[0]["location"]["kind"], "tet");
    let want = f64::from(values.values[m.tets[0][2] as usize]);
    assert!((j[0]["value"].as_f64().unwrap() - want).abs() < 1e-5);

    // Picking the sphere's centre pixel and one off-centre.
    let vol = sphere_volume(dir.path());
    let png = dir.path().join("p.png");
    let npy = dir.path().join("p.npy");
    let (w, h) = (64u32, 48u32);
    ok(&[
        "render",
        s(&vol),
        "--iso",
        "0.6",
        "--size",
        "64x48",
        "-o",
        s(&png),
        "--depth-out",
        s(&npy),
    ]);
    // An off-centre pixel that shows the sphere: the last hit along row 20.
    let depth = read_depth(&npy);
    let px = (0..w)
        .rev()
        .find(|&x| depth[(20 * w + x) as usize].is_finite())
        .unwrap();
    let off_centre = format!("{px},20");
    let out = ok(&[
        "render",
        s(&vol),
        "--iso",
        "0.6",
        "--size",
        "64x48",
        "--pick",
        "32,24",
        "--pick",
        &off_centre,
        "--pick",
        "0,0",
        "-o",
        s(&png),
        "--depth-out",
        s(&npy),
        "--force",
    ]);
    let depth = read_depth(&npy);
    let lines: Vec<&str> = out.lines().filter(|l| l.starts_with("pick ")).collect();
    assert_eq!(lines.len(), 3, "{out}");
    assert_eq!(lines[2], "pick 0,0: no surface");
    let sphere = Sphere::of_sphere_field(0.6);
    let tol = sphere.trilinear_error_bound([0.05; 3]).unwrap() + 1e-4;
    for (line, [px, py]) in lines[..2].iter().zip([[32u32, 24u32], [px, 20]]) {
        assert!(line.contains("surface 0 (iso 0.6"), "{line}");
        let number = |key: &str| -> Vec<f64> {
            let rest = line.split(key).nth(1).unwrap();
            rest.split([';', '('])
                .next()
                .unwrap()
                .split(',')
                .map(|x| x.trim().parse::<f64>().unwrap())
                .collect()
        };
        let t = number("t = ")[0];
        assert!(
            (t - f64::from(depth[(py * w + px) as usize])).abs() < 1e-5,
            "{line}"
        );
        let world = glam::DVec3::from_slice(&number("world "));
        assert!((sphere.centre_distance(world) - 0.6).abs() < tol, "{line}");
        let value = number("value ")[0];
        assert!((value - 0.6).abs() < tol, "{line}");
        let normal = glam::DVec3::from_slice(&number("normal "));
        let radial = (world - sphere.centre).normalize();
        assert!(normal.dot(radial) > 0.99, "{line}");
    }
    assert!(px > 32 + 4, "the off-centre pixel {px} is near the middle");
    let e = fails(&[
        "render",
        s(&vol),
        "--size",
        "64x48",
        "--pick",
        "64,0",
        "-o",
        s(&dir.path().join("q.png")),
    ]);
    assert!(e.contains("--pick 64,0") && e.contains("64x48"), "{e}");
    assert_eq!(depth.len(), (w * h) as usize);
}

/// `--supersample K` averages the K×K rays of each pixel: the image is the box filter of the
/// same view rendered K times larger (decoded and averaged here), and the depth is the
/// nearest of each block's hits.
#[test]
fn supersampling_is_the_box_filter_of_the_larger_render() {
    let dir = tempfile::tempdir().unwrap();
    let vol = sphere_volume(dir.path());
    let (small, big) = (dir.path().join("aa.png"), dir.path().join("big.png"));
    let (small_depth, big_depth) = (dir.path().join("aa.npy"), dir.path().join("big.npy"));
    let k = 3u32;
    let view = ["--iso", "0.5", "--orbit", "20,30"];
    let mut args = vec!["render", s(&vol), "--size", "31x23", "--supersample", "3"];
    args.extend(view);
    args.extend(["-o", s(&small), "--depth-out", s(&small_depth)]);
    ok(&args);
    let mut args = vec!["render", s(&vol), "--size", "93x69"];
    args.extend(view);
    args.extend(["-o", s(&big), "--depth-out", s(&big_depth)]);
    ok(&args);
    let (aa, fine) = (
        image::open(&small).unwrap().to_rgba8(),
        image::open(&big).unwrap().to_rgba8(),
    );
    let (aa_t, fine_t) = (read_depth(&small_depth), read_depth(&big_depth));
    assert_eq!(aa.dimensions(), (31, 23));
    let mut blended = 0;
    for y in 0..23 {
        for x in 0..31 {
            for c in 0..4 {
                let sum: u32 = (0..k * k)
                    .map(|s| u32::from(fine.get_pixel(x * k + s % k, y * k + s / k)[c]))
                    .sum();
                let want = (sum + k * k / 2) / (k * k);
                assert_eq!(u32::from(aa.get_pixel(x, y)[c]), want, "pixel {x},{y}");
            }
            let nearest = (0..k * k)
                .map(|s| fine_t[((y * k + s / k) * 93 + x * k + s % k) as usize])
                .fold(f32::INFINITY, f32::min);
            assert_eq!(aa_t[(y * 31 + x) as usize], nearest, "depth {x},{y}");
            let block: Vec<_> = (0..k * k)
                .map(|s| fine.get_pixel(x * k + s % k, y * k + s / k)[0])
                .collect();
            blended += usize::from(block.iter().any(|&v| v != block[0]));
        }
    }
    assert!(
        blended > 10,
        "the silhouette is anti-aliased: {blended} mixed pixels"
    );
    let e = fails(&[
        "render",
        s(&vol),
        "--supersample",
        "9",
        "-o",
        s(&dir.path().join("x.png")),
    ]);
    assert!(e.contains("supersampling 9 must be between 1 and 8"), "{e}");
}

/// `--color-by` with another volume on the same grid: f = x. Shading is linear in the base
/// colour per channel (`c·L + S`), so two flat renders (grey 128 and black) give `L` and `S`
/// at each pixel, and the coloured pixel must be `coolwarm(x_hit)·L + S`, with `x_hit` from
/// the depth image and the camera's rays. The scalar bar is drawn unless `--no-scalar-bar`,
/// on the right only.
#[test]
fn color_by_another_volume_colours_pixels_by_its_value_at_the_hit() {
    use volume_core::render::{Colormap, RayGen};
    let dir = tempfile::tempdir().unwrap();
    let vol = sphere_volume(dir.path());
    // f = x on the sphere's grid, as i16 x·1000 with a value map would test native types:
    // here a plain f32 volume (trilinear interpolation of a linear field is exact).
    let sphere = formats::open(&vol, &formats::OpenOptions::default()).unwrap();
    let formats::Dataset::Volume(sphere) = sphere else {
        panic!("one volume")
    };
    let g = sphere.grid.clone();
    let d = g.dims();
    let mut xs = Vec::new();
    for k in 0..d[2] {
        for j in 0..d[1] {
            for i in 0..d[0] {
                xs.push(g.grid_position(i, j, k).x as f32);
            }
        }
    }
    let x_vol = volume_core::RectilinearVolume::new(g, xs.into()).unwrap();
    let x_path = dir.path().join("x.nrrd");
    write_nrrd(
        &x_path,
        &x_vol,
        NrrdEncoding::Raw,
        formats::output::Replace::Refuse,
    )
    .unwrap();
    let cam = Camera {
        eye: Vec3::new(0.4, 0.3, 4.0),
        target: Vec3::new(0.1, -0.05, 0.0),
        up: Vec3::Y,
        vfov_deg: 30.0,
        projection: volume_core::render::Projection::Pinhole,
        ortho_height: None,
    };
    let cam_path = dir.path().join("cam.json");
    std::fs::write(&cam_path, serde_json::to_string(&cam).unwrap()).unwrap();
    let (w, h) = (160u32, 100u32);
    let size = format!("{w}x{h}");
    let render = |name: &str, extra: &[&str]| {
        let png = dir.path().join(format!("{name}.png"));
        let npy = dir.path().join(format!("{name}.npy"));
        let mut args = vec![
            "render",
            s(&vol),
            "--camera",
            s(&cam_path),
            "--size",
            &size,
            "-o",
            s(&png),
            "--depth-out",
            s(&npy),
        ];
        args.extend_from_slice(extra);
        ok(&args);
        let img = image::open(&png).unwrap().to_rgb8().into_raw();
        (img, read_depth(&npy))
    };
    let (grey, depth) = render("grey", &["--iso", "0.6:#808080"]);
    let (black, _) = render("black", &["--iso", "0.6:#000000"]);
    let colour_args = [
        "--iso",
        "0.6:#808080",
        "--color-by",
        s(&x_path),
        "--colormap",
        "coolwarm",
        "--color-range",
        "-0.6,0.8",
    ];
    let mut plain_args = colour_args.to_vec();
    plain_args.push("--no-scalar-bar");
    let (coloured, depth_c) = render("coloured", &plain_args);
    assert_eq!(
        depth.iter().map(|t| t.to_bits()).collect::<Vec<_>>(),
        depth_c.iter().map(|t| t.to_bits()).collect::<Vec<_>>(),
        "colouring changes no geometry"
    );
    let raygen = RayGen::new(&cam, w, h);
    let (mut compared, mut worst) = (0, 0.0f32);
    let (mut low, mut high) = (false, false);
    for py in 0..h {
        for px in 0..w {
            let p = (py * w + px) as usize;
            let t = depth[p];
            if !t.is_finite() {
                continue;
            }
            let ray = raygen.ray_at(px as f32 + 0.5, py as f32 + 0.5);
            let x = ray.origin.x + ray.dir.x * t;
            let base = Colormap::Coolwarm.map(x, [-0.6, 0.8]);
            low |= x < -0.3;
            high |= x > 0.5;
            for c in 0..3 {
                let (g, k) = (f32::from(grey[3 * p + c]), f32::from(black[3 * p + c]));
                let light = (g - k) * 255.0 / 128.0;
                let want = (base[c] * light + k).min(255.0);
                let got = f32::from(coloured[3 * p + c]);
                worst = worst.max((got - want).abs());
            }
            compared += 1;
        }
    }
    assert!(compared > 1000 && low && high, "{compared} {low} {high}");
    // Rounding of three 8-bit images (the lit factor is doubled from the grey render).
    assert!(worst <= 4.0, "worst channel error {worst}");

    // With the scalar bar: the same picture except in a panel on the right.
    let (barred, _) = render("barred", &colour_args);
    let changed: Vec<u32> = (0..(w * h) as usize)
        .filter(|&p| barred[3 * p..3 * p + 3] != coloured[3 * p..3 * p + 3])
        .map(|p| p as u32 % w)
        .collect();
    assert!(changed.len() > 200, "{} pixels changed", changed.len());
    assert!(
        changed.iter().all(|&x| x >= w / 2),
        "the bar sits on the right"
    );
}

/// `--color-by` errors name what the data can be coloured by; the gradient of a volume and
/// the point arrays of a mesh colour pictures.
#[test]
fn color_by_errors_list_the_available_fields() {
    let dir = tempfile::tempdir().unwrap();
    let ball = dir.path().join("ball.vtu");
    ok(&["generate", "tet-ball", "--tets", "2000", "-o", s(&ball)]);
    let out = dir.path().join("o.png");
    let e = fails(&["render", s(&ball), "--color-by", "nope", "-o", s(&out)]);
    assert!(
        e.contains("nope") && e.contains("distance, gaussians, moving_gaussian"),
        "{e}"
    );
    let e = fails(&["render", s(&ball), "--color-by", "gradient", "-o", s(&out)]);
    assert!(e.contains("gradient") && e.contains("distance"), "{e}");
    let e = fails(&["render", s(&ball), "--colormap", "magma", "-o", s(&out)]);
    assert!(e.contains("--color-by"), "{e}");
    let e = fails(&[
        "render",
        s(&ball),
        "--color-by",
        "distance",
        "--colormap",
        "jet",
        "-o",
        s(&out),
    ]);
    assert!(
        e.contains("jet") && e.contains("viridis, magma, coolwarm, grey"),
        "{e}"
    );
    let e = fails(&[
        "render",
        s(&ball),
        "--color-by",
        "distance",
        "--color-range",
        "2,1",
        "-o",
        s(&out),
    ]);
    assert!(e.contains("2,1") && e.contains("MIN < MAX"), "{e}");
    assert!(!out.exists());
    // A mesh array and a volume's gradient render (and differ from the flat picture).
    let flat = dir.path().join("flat.png");
    ok(&[
        "render",
        s(&ball),
        "--iso",
        "0.5",
        "--size",
        "64x48",
        "-o",
        s(&flat),
    ]);
    let by_array = dir.path().join("array.png");
    ok(&[
        "render",
        s(&ball),
        "--iso",
        "0.5",
        "--size",
        "64x48",
        "--color-by",
        "gaussians",
        "-o",
        s(&by_array),
    ]);
    assert_ne!(
        std::fs::read(&flat).unwrap(),
        std::fs::read(&by_array).unwrap()
    );
    let vol = sphere_volume(dir.path());
    let by_gradient = dir.path().join("gradient.png");
    ok(&[
        "render",
        s(&vol),
        "--iso",
        "0.6",
        "--size",
        "64x48",
        "--color-by",
        "gradient",
        "--colormap",
        "magma",
        "-o",
        s(&by_gradient),
    ]);
    // Another volume must have the same grid.
    let small = dir.path().join("small.nrrd");
    let v = data_samples::Generator::Sphere
        .generate([21; 3], VoxelType::F32)
        .unwrap();
    write_nrrd(
        &small,
        &v,
        NrrdEncoding::Raw,
        formats::output::Replace::Refuse,
    )
    .unwrap();
    let e = fails(&["render", s(&vol), "--color-by", s(&small), "-o", s(&out)]);
    assert!(
        e.contains("small.nrrd") && e.contains("21x21x21") && e.contains("41x41x41"),
        "{e}"
    );
    let e = fails(&[
        "render",
        s(&vol),
        "--color-by",
        "missing.nrrd",
        "-o",
        s(&out),
    ]);
    assert!(e.contains("missing.nrrd"), "{e}");
}
