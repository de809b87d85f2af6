//! Replays the `session_json` fuzz corpus (`app/fuzz/corpus/session_json/`, minimised) and the
//! hand-made seeds (`app/fuzz/seeds/session_json/`) through the function the fuzz target runs
//! (`app/fuzz/harness.rs`, included below): nothing may panic, and the `ok_*` seeds (valid
//! sessions) must load and survive a save/load round trip.

use std::path::{Path, PathBuf};

use isoscope::ui::state;

#[path = "../fuzz/harness.rs"]
mod harness;

fn files_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<_> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    v.sort();
    v
}

fn replay(dir: &str) -> (usize, Vec<String>) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz").join(dir);
    let files = files_in(&dir);
    assert!(!files.is_empty(), "{}: empty", dir.display());
    let mut accepted_ok = 0;
    let mut failures = Vec::new();
    for path in &files {
        let bytes = std::fs::read(path).unwrap();
        let must_accept = path
            .file_name()
            .is_some_and(|n| n.to_string_lossy().starts_with("ok_"));
        match std::panic::catch_unwind(|| harness::session_json(&bytes)) {
            Err(_) => failures.push(format!("{}: PANIC", path.display())),
            Ok(Err(e)) if must_accept => failures.push(format!("{}: {e}", path.display())),
            Ok(Ok(())) if must_accept => accepted_ok += 1,
            Ok(_) => {}
        }
    }
    (accepted_ok, failures)
}

#[test]
fn session_corpus_replays_without_panics() {
    let (_, failures) = replay("corpus/session_json");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn valid_session_seeds_load_and_round_trip() {
    let (accepted, failures) = replay("seeds/session_json");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    assert!(accepted >= 3, "only {accepted} valid seeds accepted");
    // The seed with every field set loads to what it says (not to defaults).
    let full = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/seeds/session_json/ok_full.json"),
    )
    .unwrap();
    let s = state::ViewerState::from_json(&full).unwrap();
    assert_eq!(s.surfaces.len(), 2);
    assert_eq!(s.files.len(), 2);
    assert!(!s.time.looping);
}

#[test]
fn session_with_a_number_beyond_f32_is_refused_naming_the_field() {
    // Found by the `session_json` fuzz target: `1e39` read into an `f32` is infinity, which
    // a save writes as `null`, so the saved session no longer loaded.
    for (text, field) in [
        (r#"{"camera": {"vfov_deg": 1e39}}"#, "camera"),
        (
            r#"{"surfaces": [{"isovalue": 1, "color": [1, 1, 1e39], "opacity": 1, "visible": true}]}"#,
            "surfaces",
        ),
        (r#"{"time": {"fps": -1e40}}"#, "time"),
    ] {
        let e = state::ViewerState::from_json(text).unwrap_err();
        assert!(e.contains(field) && e.contains("finite"), "{e}");
        assert!(harness::session_json(text.as_bytes()).is_err());
    }
    // Large but finite values still load, and load again once saved.
    let ok = r#"{"surfaces": [{"isovalue": 1e300, "color": [1, 1, 3e38], "opacity": 1, "visible": true}]}"#;
    assert_eq!(harness::session_json(ok.as_bytes()), Ok(()));
}

#[test]
fn saved_sessions_reload_bit_for_bit() {
    // Found by the `session_json` fuzz target: serde_json's default float parser is not
    // correctly rounded, so this isovalue came back one unit in the last place off. The
    // workspace reads JSON with `float_roundtrip`.
    let text = r#"{"surfaces": [{"isovalue": -2.3022222222222225e92, "color": [1, 1, 1], "opacity": 1, "visible": true}]}"#;
    let first = state::ViewerState::from_json(text).unwrap();
    let want: f64 = -2.302_222_222_222_222_5e92;
    assert_eq!(first.surfaces[0].isovalue.to_bits(), want.to_bits());
    let mut s = first;
    for _ in 0..3 {
        let again = state::ViewerState::from_json(&s.to_json()).unwrap();
        assert_eq!(
            again.surfaces[0].isovalue.to_bits(),
            s.surfaces[0].isovalue.to_bits()
        );
        s = again;
    }
}
