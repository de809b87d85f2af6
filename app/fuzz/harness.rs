//! What the `session_json` fuzz target runs on one input, shared with the corpus replay in
//! `app/tests/fuzz_session.rs` (which includes this file): the crate that includes it has the
//! session module at `crate::state` (the fuzz target compiles `app/src/ui/state.rs` there, the
//! test re-exports `isoscope::ui::state`).
//!
//! Returns `Ok` when the session is accepted, `Err(message)` when it is refused; a panic is
//! the finding. An accepted session must survive what the viewer does with it: saved again
//! (`to_json`) it must load again, with the same files, surfaces and clips. (Not to the same
//! bits: serde_json's default float parser may land one unit in the last place off for long
//! mantissas, e.g. `-2.3022222222222225e92`; see docs/reliability.md, "Fuzzing".)

use crate::state::ViewerState;

pub fn session_json(data: &[u8]) -> Result<(), String> {
    // The viewer reads session files as UTF-8 text.
    let text = std::str::from_utf8(data).map_err(|e| e.to_string())?;
    let state = ViewerState::from_json(text)?;
    let saved = state.to_json();
    let again = ViewerState::from_json(&saved)
        .unwrap_or_else(|e| panic!("a loaded session does not load again once saved: {e}"));
    assert_eq!(again.version, state.version);
    assert_eq!(again.files, state.files);
    assert_eq!(again.surfaces.len(), state.surfaces.len());
    assert_eq!(again.clip_boxes.len(), state.clip_boxes.len());
    assert_eq!(again.clip_planes.len(), state.clip_planes.len());
    assert_eq!(again.bookmarks.len(), state.bookmarks.len());
    Ok(())
}
