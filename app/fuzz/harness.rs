//! What the `session_json` fuzz target runs on one input, shared with the corpus replay in
//! `app/tests/fuzz_session.rs` (which includes this file): the crate that includes it has the
//! session module at `crate::state` (the fuzz target compiles `app/src/ui/state.rs` there, the
//! test re-exports `isoscope::ui::state`).
//!
//! Returns `Ok` when the session is accepted, `Err(message)` when it is refused; a panic is
//! the finding. An accepted session must survive what the viewer does with it: saved again
//! (`to_json`) it must load again, to the same JSON.

use crate::state::ViewerState;

pub fn session_json(data: &[u8]) -> Result<(), String> {
    // The viewer reads session files as UTF-8 text.
    let text = std::str::from_utf8(data).map_err(|e| e.to_string())?;
    let state = ViewerState::from_json(text)?;
    let saved = state.to_json();
    let again = ViewerState::from_json(&saved)
        .unwrap_or_else(|e| panic!("a loaded session does not load again once saved: {e}"));
    assert_eq!(again.to_json(), saved, "saving is not stable");
    Ok(())
}
