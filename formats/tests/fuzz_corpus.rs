//! Replays the fuzz inputs in the normal test run, through the very functions the fuzz
//! targets call (`formats/fuzz/harness.rs`, included below):
//!
//! - the NRRD header seeds (`formats/fuzz/corpus-seed/`): `ok_*` must be accepted, `bad_*`
//!   rejected, every prefix must not panic (files with other names, e.g. crash reproductions
//!   copied from `fuzz/artifacts`, only must not panic);
//! - the minimised corpus of every target (`formats/fuzz/corpus/<target>/`): no panic;
//! - the hand-made seeds (`formats/fuzz/seeds/<target>/`, `ok_*` must be accepted) and the
//!   reader test files under `tests/data/mesh`, all known good: each must be accepted.

use std::path::{Path, PathBuf};

#[path = "../fuzz/harness.rs"]
mod harness;

fn run(bytes: &[u8]) -> Result<(), String> {
    harness::nrrd_header(bytes)
}

type Target = fn(&[u8]) -> harness::Outcome;

/// Every fuzz target: its name (the corpus directory) and what it runs.
const TARGETS: [(&str, Target); 15] = [
    ("nrrd_header", harness::nrrd_header),
    ("nrrd_data", harness::nrrd_data),
    ("raw_sidecar", harness::raw_sidecar),
    ("vtk_legacy", harness::vtk_legacy),
    ("vtu", harness::vtu),
    ("pvd", harness::pvd),
    ("gmsh", harness::gmsh),
    ("tetgen", harness::tetgen),
    ("isot", harness::isot),
    ("nifti", harness::nifti),
    ("camera_json", harness::camera_json),
    ("metaimage", harness::metaimage),
    ("vti", harness::vti),
    ("tiff", harness::tiff),
    ("dicom", harness::dicom),
];

fn fuzz_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz")
}

fn files_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<_> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .collect();
    v.sort();
    v
}

/// Runs `target` on every file; returns the failures (panics, and rejections of `must_accept`
/// files) as messages.
fn replay(target: Target, files: &[PathBuf], must_accept: impl Fn(&Path) -> bool) -> Vec<String> {
    let mut failures = Vec::new();
    for path in files {
        let bytes = std::fs::read(path).unwrap();
        match std::panic::catch_unwind(|| target(&bytes)) {
            Err(_) => failures.push(format!("{}: PANIC", path.display())),
            Ok(Err(e)) if must_accept(path) => {
                failures.push(format!("{}: rejected: {e}", path.display()));
            }
            Ok(_) => {}
        }
    }
    failures
}

fn named_ok(path: &Path) -> bool {
    path.file_name()
        .is_some_and(|n| n.to_string_lossy().starts_with("ok_"))
}

#[test]
fn every_target_has_a_committed_corpus_that_replays_without_panics() {
    let mut failures = Vec::new();
    for (name, target) in TARGETS {
        let files = files_in(&fuzz_dir().join("corpus").join(name));
        assert!(!files.is_empty(), "no corpus for {name}");
        failures.extend(replay(target, &files, |_| false));
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn hand_made_seeds_replay_and_the_valid_ones_are_accepted() {
    let mut failures = Vec::new();
    let mut accepted = 0;
    for (name, target) in TARGETS {
        let dir = fuzz_dir().join("seeds").join(name);
        if !dir.is_dir() {
            continue; // targets seeded only from tests/data or corpus-seed
        }
        let files = files_in(&dir);
        accepted += files.iter().filter(|p| named_ok(p)).count();
        failures.extend(replay(target, &files, named_ok));
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    assert!(accepted >= 30, "only {accepted} known-good seeds");
}

#[test]
fn reader_test_files_are_accepted_by_their_targets() {
    // The mesh readers' own test files (known good, checked against independent truth in
    // mesh_readers.rs) must pass the fuzz harness, invariants included.
    let mesh = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/mesh");
    let mut failures = Vec::new();
    for (ext, target) in [
        ("vtk", harness::vtk_legacy as Target),
        ("vtu", harness::vtu),
        ("msh", harness::gmsh),
    ] {
        let files: Vec<_> = files_in(&mesh)
            .into_iter()
            .filter(|p| p.extension().is_some_and(|e| e == ext))
            .collect();
        assert!(files.len() >= 4, "{ext}: {} files", files.len());
        failures.extend(replay(target, &files, |_| true));
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn image_test_files_are_accepted_by_their_targets() {
    // The image readers' test files (checked against SimpleITK, VTK and tifffile in
    // image_readers.rs) must pass the fuzz harness, invariants included. Detached MetaImage
    // headers are left out: the harness writes its own data files.
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let mut failures = Vec::new();
    for (folder, exts, target) in [
        ("metaimage", &["mha"][..], harness::metaimage as Target),
        ("vtk_image", &["vti", "vtk"][..], harness::vti),
        ("tiff", &["tif"][..], harness::tiff),
    ] {
        let files: Vec<_> = files_in(&data.join(folder))
            .into_iter()
            .filter(|p| p.extension().is_some_and(|e| exts.iter().any(|x| e == *x)))
            .collect();
        assert!(files.len() >= 4, "{folder}: {} files", files.len());
        failures.extend(replay(target, &files, |_| true));
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn seed_corpus_replays_without_panics() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus-seed");
    let mut entries: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    assert!(
        entries.len() >= 15,
        "seed corpus too small: {}",
        entries.len()
    );
    let mut failures = Vec::new();
    for path in &entries {
        let bytes = std::fs::read(path).unwrap();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        match std::panic::catch_unwind(|| run(&bytes)) {
            Err(_) => failures.push(format!("{name}: PANIC")),
            Ok(Ok(())) if name.starts_with("bad_") => failures.push(format!("{name}: accepted")),
            Ok(Err(e)) if name.starts_with("ok_") => failures.push(format!("{name}: {e}")),
            Ok(_) => {}
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn truncations_of_every_seed_never_panic() {
    // Cheap stand-in for fuzzing in CI: every prefix of every seed.
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus-seed");
    for entry in std::fs::read_dir(&dir).unwrap() {
        let bytes = std::fs::read(entry.unwrap().path()).unwrap();
        for cut in 0..=bytes.len() {
            let prefix = &bytes[..cut];
            assert!(
                std::panic::catch_unwind(|| run(prefix)).is_ok(),
                "panic on a {cut}-byte prefix"
            );
        }
    }
}
