//! Reader defects found by the hostile corpus (`data_samples::hostile`, run through the CLI
//! in `app/tests/cli_hostile_corpus.rs`). Each test failed before its fix.

use std::path::Path;

use formats::nrrd::parse_header_at;

/// `axis mins: -inf 0 0` used to be taken for "unknown" (as nan is) and the file opened with
/// the origin at 0; Teem refuses infinite axis mins and maxs.
#[test]
fn infinite_axis_min_or_max_is_an_error_naming_the_field() {
    for (field, line) in [
        ("axis mins", "axis mins: -inf 0 0\naxis maxs: 4 3 2\n"),
        ("axis maxs", "axis mins: 0 0 0\naxis maxs: 4 inf 2\n"),
    ] {
        let h = format!(
            "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 5 4 3\nspacings: nan nan nan\n{line}encoding: raw\n\n"
        );
        let e = parse_header_at(Path::new("inf.nrrd"), h.as_bytes()).unwrap_err();
        assert_eq!(e.field(), Some(field), "{e}");
        let s = e.to_string();
        assert!(s.contains("inf.nrrd") && s.contains("finite"), "{s}");
    }
    // nan stays "unknown".
    let h = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 5 4 3\nspacings: nan nan nan\naxis mins: nan 0 0\naxis maxs: 4 3 2\nencoding: raw\n\n";
    assert!(parse_header_at(Path::new("nan.nrrd"), h.as_bytes()).is_ok());
}
