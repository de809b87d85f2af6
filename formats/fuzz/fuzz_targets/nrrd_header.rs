//! Fuzzes the NRRD header parser and the axis/geometry interpretation that follows it: any
//! input must give a header or an error, never a panic, an overflow or a huge allocation.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(header) = formats::nrrd::parse_header(data) {
        let _ = header.volume_layout(Path::new("fuzz.nhdr"));
        let _ = formats::nrrd::header::data_file_paths(&header, Path::new("/fuzz/h.nhdr"));
    }
});
