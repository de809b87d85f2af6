//! Replays the fuzz seed corpus (`formats/fuzz/corpus-seed/`) through what the fuzz target
//! runs: the NRRD header parser, then the axis/geometry interpretation and the data file
//! list. `ok_*` seeds must be accepted, `bad_*` seeds rejected, and nothing may panic (files
//! with other names, e.g. crash reproductions copied from `fuzz/artifacts`, only must not panic).

use std::path::Path;

fn run(bytes: &[u8]) -> Result<(), formats::FormatError> {
    let header = formats::nrrd::parse_header(bytes)?;
    header.volume_layout(Path::new("seed.nhdr"))?;
    let files = formats::nrrd::header::data_file_paths(&header, Path::new("/seed/h.nhdr"));
    assert!(!files.is_empty());
    Ok(())
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
