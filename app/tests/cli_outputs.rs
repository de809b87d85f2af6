//! Output safety, end to end through the real binary: no command writes over a file its
//! input reads (by path, hard link or symbolic link; detached data files, sidecars, series
//! and `.pvd` steps, TetGen partners, `.isot`), an existing output is replaced only with
//! `--force`, two outputs may not be one file, and a write that fails (a device, a file-size
//! limit) exits non-zero and leaves no file behind. See `formats::output`.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::{fails, ok};
use formats::nrrd::{NrrdEncoding, write_nrrd};
use formats::output::Replace;
use volume_core::VoxelType;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn sphere(path: &Path) {
    let v = data_samples::Generator::Sphere
        .generate([17; 3], VoxelType::F32)
        .unwrap();
    write_nrrd(path, &v, NrrdEncoding::Raw, Replace::Refuse).unwrap();
}

/// The bytes of every file in `dir`, to show that a refused command changed nothing.
fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .map(|p| {
            let b = std::fs::read(&p).unwrap();
            (p, b)
        })
        .collect();
    files.sort();
    files
}

/// `render INPUT -o OUTPUT --force` fails naming the output and `input_named`, and no file in
/// the folder changes.
fn render_refused(input: &Path, output: &Path, input_named: &str) {
    let dir = input.parent().unwrap();
    let before = snapshot(dir);
    let e = fails(&[
        "render",
        s(input),
        "--size",
        "16x16",
        "-o",
        s(output),
        "--force",
    ]);
    let out_name = output.file_name().unwrap().to_str().unwrap();
    assert!(
        e.contains("is the input file") && e.contains(out_name) && e.contains(input_named),
        "render {} -o {}: {e}",
        input.display(),
        output.display()
    );
    assert!(!e.contains("panicked"), "{e}");
    assert_eq!(snapshot(dir), before, "a refused render changed a file");
}

#[test]
fn render_never_writes_over_a_file_the_input_reads() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();

    // The input itself, and a hard link and a symbolic link to it.
    let v = d.join("v.nrrd");
    sphere(&v);
    render_refused(&v, &v, "v.nrrd");
    std::fs::hard_link(&v, d.join("hard.png")).unwrap();
    render_refused(&v, &d.join("hard.png"), "v.nrrd");
    std::os::unix::fs::symlink(&v, d.join("soft.png")).unwrap();
    render_refused(&v, &d.join("soft.png"), "v.nrrd");

    // The detached data file of a .nhdr.
    let nhdr_dir = tempfile::tempdir().unwrap();
    let raw: Vec<u8> = (0..4 * 4 * 4).map(|i: u32| (i * 9 % 251) as u8).collect();
    std::fs::write(nhdr_dir.path().join("d.raw"), &raw).unwrap();
    std::fs::write(
        nhdr_dir.path().join("d.nhdr"),
        "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 4 4 4\nencoding: raw\ndata file: d.raw\n",
    )
    .unwrap();
    render_refused(
        &nhdr_dir.path().join("d.nhdr"),
        &nhdr_dir.path().join("d.raw"),
        "d.raw",
    );

    // A raw file's .json sidecar.
    let raw_dir = tempfile::tempdir().unwrap();
    std::fs::write(raw_dir.path().join("r.raw"), &raw).unwrap();
    std::fs::write(
        raw_dir.path().join("r.json"),
        r#"{"dims": [4, 4, 4], "type": "u8", "endian": "little", "spacing": [1, 1, 1]}"#,
    )
    .unwrap();
    render_refused(
        &raw_dir.path().join("r.raw"),
        &raw_dir.path().join("r.json"),
        "r.json",
    );

    // A later step of a series pattern (read lazily, long after the open).
    let series_dir = tempfile::tempdir().unwrap();
    for k in 0..3 {
        sphere(&series_dir.path().join(format!("s_{k:03}.nrrd")));
    }
    render_refused(
        &series_dir.path().join("s_%03d.nrrd"),
        &series_dir.path().join("s_002.nrrd"),
        "s_002.nrrd",
    );

    // An .isot file.
    let isot = d.join("v.isot");
    ok(&["preprocess", s(&v), "-o", s(&isot), "--treelet-height", "3"]);
    render_refused(&isot, &isot, "v.isot");
}

#[test]
fn mesh_partners_and_pvd_steps_are_inputs_too() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // TetGen: one tetrahedron, the .node read with its .ele partner.
    std::fs::write(
        d.join("t.node"),
        "4 3 1 0\n0 0 0 0 0\n1 1 0 0 1\n2 0 1 0 2\n3 0 0 1 3\n",
    )
    .unwrap();
    std::fs::write(d.join("t.ele"), "1 4 0\n0 0 1 2 3\n").unwrap();
    render_refused(&d.join("t.node"), &d.join("t.ele"), "t.ele");

    // A .pvd collection's step.
    let pvd_dir = tempfile::tempdir().unwrap();
    let p = pvd_dir.path();
    ok(&[
        "generate",
        "tet-ball",
        "--tets",
        "500",
        "--steps",
        "2",
        "-o",
        s(&p.join("m.vtu")),
    ]);
    render_refused(&p.join("m.pvd"), &p.join("m_001.vtu"), "m_001.vtu");
}

#[test]
fn existing_outputs_are_replaced_only_with_force_in_every_command() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let v = d.join("v.nrrd");
    sphere(&v);
    let png = d.join("out.png");
    ok(&["render", s(&v), "--size", "16x16", "-o", s(&png)]);
    let e = fails(&["render", s(&v), "--size", "16x16", "-o", s(&png)]);
    assert!(e.contains("already exists") && e.contains("--force"), "{e}");
    ok(&["render", s(&v), "--size", "24x16", "-o", s(&png), "--force"]);
    assert_eq!(image::open(&png).unwrap().width(), 24);

    let isot = d.join("v.isot");
    ok(&["preprocess", s(&v), "-o", s(&isot), "--treelet-height", "3"]);
    let e = fails(&["preprocess", s(&v), "-o", s(&isot), "--treelet-height", "3"]);
    assert!(e.contains("already exists") && e.contains("--force"), "{e}");
    ok(&[
        "preprocess",
        s(&v),
        "-o",
        s(&isot),
        "--treelet-height",
        "3",
        "--force",
    ]);

    let g = d.join("g.nrrd");
    ok(&["generate", "sphere", "--size", "8", "-o", s(&g)]);
    let e = fails(&["generate", "sphere", "--size", "8", "-o", s(&g)]);
    assert!(e.contains("already exists") && e.contains("--force"), "{e}");
    ok(&["generate", "sphere", "--size", "8", "-o", s(&g), "--force"]);

    // convert: each output format; a detached header's data file counts as an output too.
    for name in ["c.nii", "c.nii.gz", "c.nrrd", "c.nhdr"] {
        let out = d.join(name);
        ok(&["convert", s(&v), "-o", s(&out)]);
        let e = fails(&["convert", s(&v), "-o", s(&out)]);
        assert!(e.contains("already exists") && e.contains("--force"), "{e}");
        ok(&["convert", s(&v), "-o", s(&out), "--force"]);
    }
    std::fs::remove_file(d.join("c.nhdr")).unwrap();
    let e = fails(&["convert", s(&v), "-o", s(&d.join("c.nhdr"))]);
    assert!(e.contains("already exists") && e.contains("c.raw"), "{e}");
    // Never over the input, or over a file it reads (a detached header's data file).
    let e = fails(&["convert", s(&v), "-o", s(&v), "--force"]);
    assert!(e.contains("is the input file"), "{e}");
    let e = fails(&[
        "convert",
        s(&d.join("c.nii")),
        "-o",
        s(&d.join("c.nii")),
        "--force",
    ]);
    assert!(e.contains("is the input file"), "{e}");

    // accuracy checks every report and image path before its long measurement.
    let md = d.join("acc.md");
    std::fs::write(&md, "keep").unwrap();
    let e = fails(&[
        "accuracy",
        "--quick",
        "-o",
        s(&md),
        "--images",
        s(&d.join("img")),
    ]);
    assert!(e.contains("already exists") && e.contains("acc.md"), "{e}");
    assert_eq!(std::fs::read_to_string(&md).unwrap(), "keep");
}

#[test]
fn convert_errors_are_clear() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let v = d.join("v.nrrd");
    sphere(&v);
    let e = fails(&["convert", s(&v), "-o", s(&d.join("v.png"))]);
    assert!(e.contains(".nii.gz") && e.contains("v.png"), "{e}");
    let e = fails(&["convert", s(&v), "--step", "1", "-o", s(&d.join("v.nii"))]);
    assert!(e.contains("single volume"), "{e}");
    let e = fails(&[
        "convert",
        s(&v),
        "--encoding",
        "gzip",
        "-o",
        s(&d.join("v.nii")),
    ]);
    assert!(e.contains(".nii.gz"), "{e}");
    // A series: whole to NIfTI, one step to NRRD, never all steps to NRRD.
    ok(&[
        "generate",
        "blobs",
        "--size",
        "8",
        "--steps",
        "3",
        "-o",
        s(&d.join("b_%03d.nrrd")),
    ]);
    let series = d.join("b_%03d.nrrd");
    let e = fails(&["convert", s(&series), "-o", s(&d.join("b.nrrd"))]);
    assert!(e.contains("3 time steps") && e.contains("--step"), "{e}");
    let e = fails(&[
        "convert",
        s(&series),
        "--step",
        "3",
        "-o",
        s(&d.join("b.nrrd")),
    ]);
    assert!(e.contains("step 3"), "{e}");
    ok(&[
        "convert",
        s(&series),
        "--step",
        "2",
        "-o",
        s(&d.join("b.nrrd")),
    ]);
    ok(&["convert", s(&series), "-o", s(&d.join("b.nii.gz"))]);
    let info: serde_json::Value =
        serde_json::from_str(&ok(&["info", s(&d.join("b.nii.gz")), "--json"])).unwrap();
    assert_eq!(info["time_steps"], 3);
    // Meshes are not volumes.
    let mesh = d.join("m.vtu");
    ok(&["generate", "tet-ball", "--size", "4", "-o", s(&mesh)]);
    let e = fails(&["convert", s(&mesh), "-o", s(&d.join("m.nii"))]);
    assert!(e.contains("tetrahedral mesh"), "{e}");
    assert!(!d.join("m.nii").exists() && !d.join("v.nii").exists());
}

#[test]
fn new_outputs_get_the_mode_of_any_new_file() {
    use std::os::unix::fs::PermissionsExt as _;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let reference = d.join("reference");
    std::fs::File::create(&reference).unwrap();
    let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
    ok(&[
        "generate",
        "sphere",
        "--size",
        "8",
        "-o",
        s(&d.join("g.nrrd")),
    ]);
    ok(&[
        "generate",
        "tet-ball",
        "--tets",
        "300",
        "-o",
        s(&d.join("m.vtu")),
    ]);
    ok(&[
        "render",
        s(&d.join("g.nrrd")),
        "--size",
        "8x8",
        "-o",
        s(&d.join("g.png")),
    ]);
    for f in ["g.nrrd", "m.vtu", "g.png"] {
        assert_eq!(mode(&d.join(f)), mode(&reference), "{f}");
    }
}

#[test]
fn two_outputs_may_not_be_one_file() {
    let dir = tempfile::tempdir().unwrap();
    let v = dir.path().join("v.nrrd");
    sphere(&v);
    let out = dir.path().join("o.png");
    let e = fails(&[
        "render",
        s(&v),
        "--size",
        "8x8",
        "-o",
        s(&out),
        "--depth-out",
        s(&out),
    ]);
    assert!(e.contains("is also the output"), "{e}");
    assert!(!out.exists());
}

/// Runs `isoscope ARGS` under a file-size limit of `blocks` × 512 bytes, with SIGXFSZ
/// ignored so that a write past the limit fails with EFBIG instead of killing the process.
fn isoscope_with_file_limit(blocks: u32, args: &[&str]) -> std::process::Output {
    Command::new("sh")
        .arg("-c")
        .arg(format!(
            "trap '' XFSZ; ulimit -f {blocks}; exec \"$0\" \"$@\""
        ))
        .arg(env!("CARGO_BIN_EXE_isoscope"))
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .output()
        .unwrap()
}

fn leftovers(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.to_ascii_lowercase().ends_with(".tmp"))
        .collect()
}

#[test]
fn failed_writes_exit_non_zero_and_leave_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let v = d.join("v.nrrd");
    sphere(&v);

    // A device is not an output (it used to "succeed" writing into /dev/full).
    let e = fails(&[
        "render",
        s(&v),
        "--size",
        "8x8",
        "-o",
        "/dev/full",
        "--force",
    ]);
    assert!(e.contains("/dev/full") && e.contains("device"), "{e}");

    // A file-size limit that the image crosses: no PNG, truncated or otherwise.
    let png = d.join("big.png");
    let out = isoscope_with_file_limit(2, &["render", s(&v), "--size", "256x256", "-o", s(&png)]);
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success(),
        "render under a 1 KiB limit succeeded"
    );
    assert!(e.contains("big.png"), "{e}");
    assert!(!png.exists(), "a truncated PNG was left behind");

    // The depth map crosses it: neither the image nor a partial .npy is left.
    let small = d.join("small.png");
    let npy = d.join("depth.npy");
    let out = isoscope_with_file_limit(
        16,
        &[
            "render",
            s(&v),
            "--size",
            "128x128",
            "-o",
            s(&small),
            "--depth-out",
            s(&npy),
        ],
    );
    assert!(!out.status.success());
    assert!(!npy.exists() && !small.exists());

    // Mesh and volume generators under the limit.
    let mesh = d.join("m.vtu");
    let out = isoscope_with_file_limit(
        2,
        &["generate", "tet-ball", "--tets", "5000", "-o", s(&mesh)],
    );
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("m.vtu"));
    assert!(!mesh.exists());
    let vol = d.join("g.nrrd");
    let out = isoscope_with_file_limit(2, &["generate", "sphere", "--size", "32", "-o", s(&vol)]);
    assert!(!out.status.success());
    assert!(!vol.exists());
    assert!(leftovers(d).is_empty(), "{:?}", leftovers(d));
}

#[test]
fn a_failing_series_step_is_named_with_its_series() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    sphere(&d.join("s_000.nrrd"));
    sphere(&d.join("s_001.nrrd"));
    // Step 1 truncated after the header.
    let bytes = std::fs::read(d.join("s_001.nrrd")).unwrap();
    std::fs::write(d.join("s_001.nrrd"), &bytes[..bytes.len() / 2]).unwrap();
    let e = fails(&["info", s(&d.join("s_%03d.nrrd"))]);
    assert!(
        e.contains("s_%03d.nrrd") && e.contains("time step 1") && e.contains("s_001.nrrd"),
        "{e}"
    );
}
