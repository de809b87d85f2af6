//! Fuzz target `session_json`: runs `harness::session_json` (see `app/fuzz/harness.rs`, which
//! the corpus replay in `app/tests/fuzz_session.rs` shares) on the session parser compiled
//! from `app/src/ui/state.rs`. A panic is a finding.
#![no_main]

#[path = "../../src/ui/state.rs"]
#[allow(dead_code)] // the viewer's helpers around the parsed state
mod state;

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = harness::session_json(data);
});
