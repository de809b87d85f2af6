//! Numbered files named relative to the working directory (`isoscope blobs_000.nrrd …
//! blobs_004.nrrd`, as a shell's glob expands them) open as one time series. Its own test
//! binary: it changes the process's working directory.

use std::path::PathBuf;

use isoscope::ui::files::{FileGroup, group_files};

#[test]
fn numbered_files_in_the_working_directory_form_a_series() {
    let dir = tempfile::tempdir().unwrap();
    let samples = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data-samples/samples");
    let names: Vec<String> = (0..5).map(|i| format!("blobs24_{i:03}.nrrd")).collect();
    for n in &names {
        std::fs::copy(samples.join(n), dir.path().join(n)).unwrap();
    }
    std::env::set_current_dir(dir.path()).unwrap();
    let given: Vec<PathBuf> = names.iter().map(PathBuf::from).collect();
    match group_files(&given) {
        FileGroup::Series { pattern, steps } => {
            assert_eq!(steps, 5);
            // The pattern opens exactly these files, in order.
            let files = formats::series::expand_pattern(&pattern).unwrap();
            let opened: Vec<String> = files
                .iter()
                .map(|f| f.file_name().unwrap().to_string_lossy().into_owned())
                .collect();
            assert_eq!(opened, names);
        }
        other => panic!("not a series: {other:?}"),
    }
}
