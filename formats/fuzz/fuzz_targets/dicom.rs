//! Fuzz target `dicom`: runs `harness::dicom` (see `formats/fuzz/harness.rs`, which the corpus
//! replay in `formats/tests/fuzz_corpus.rs` shares). Any input must be accepted or refused with
//! an error; a panic, an overflow, a hang or a huge allocation is a finding.
#![no_main]

#[path = "../harness.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| {
    let _ = harness::dicom(data);
});
