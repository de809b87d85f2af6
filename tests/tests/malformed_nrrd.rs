//! The malformed-file corpus: every file gives its specific error —
//! the variant and the field it names — and nothing panics.
//!
//! The corpus is generated from the table below into a temporary directory (so it needs no
//! binary files in git); each row is (name, files, file to open, expected error).

use formats::{FormatError, OpenOptions};
use volume_core::{Grid, RectilinearVolume};

/// The error a corpus file must give.
#[derive(Debug, Clone, Copy)]
enum Want {
    Magic,
    Line,
    Unknown(&'static str),
    Dup(&'static str),
    Missing(&'static str),
    Bad(&'static str),
    Contra(&'static str, &'static str),
    Unsup(&'static str),
    TooShort,
    TooLong,
    Decode(&'static str),
    Text,
    Geometry,
    Io,
    Sidecar,
    UnknownFormat,
}

fn matches(e: &FormatError, want: Want) -> bool {
    match (e, want) {
        (FormatError::BadMagic { .. }, Want::Magic)
        | (FormatError::BadLine { .. }, Want::Line)
        | (FormatError::TooShort { .. }, Want::TooShort)
        | (FormatError::TooLong { .. }, Want::TooLong)
        | (FormatError::BadText { .. }, Want::Text)
        | (FormatError::Geometry { .. }, Want::Geometry)
        | (FormatError::Io { .. }, Want::Io)
        | (FormatError::Sidecar { .. }, Want::Sidecar)
        | (FormatError::UnknownFormat { .. }, Want::UnknownFormat) => true,
        (FormatError::UnknownField { field, .. }, Want::Unknown(f))
        | (FormatError::DuplicateField { field, .. }, Want::Dup(f))
        | (FormatError::BadValue { field, .. }, Want::Bad(f))
        | (FormatError::Unsupported { field, .. }, Want::Unsup(f)) => field == f,
        (FormatError::MissingField { field, .. }, Want::Missing(f)) => *field == f,
        (FormatError::Contradiction { field, other, .. }, Want::Contra(f, o)) => {
            field == f && other == o
        }
        (FormatError::Decode { encoding, .. }, Want::Decode(enc)) => *encoding == enc,
        _ => false,
    }
}

const BASE: &str = "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n";

/// A header from BASE with `extra` fields appended, followed by `data`.
fn nrrd(extra: &str, data: &[u8]) -> Vec<u8> {
    let mut b = if extra.is_empty() {
        format!("{BASE}\n")
    } else {
        format!("{BASE}{extra}\n\n")
    }
    .into_bytes();
    b.extend_from_slice(data);
    b
}

/// A whole header text (own fields), followed by 8 bytes of data.
fn whole(header: &str) -> Vec<u8> {
    let mut b = format!("{header}\n\n").into_bytes();
    b.extend_from_slice(&[0u8; 8]);
    b
}

/// The gzip stream of `n` bytes 0, 1, 2, ... made by the Isoscope writer.
fn gzip_stream(n: usize) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("g.nrrd");
    let g = Grid::uniform([n, 1, 1], [0.0; 3], [1.0; 3]).unwrap();
    let v = RectilinearVolume::new(g, (0..n).map(|i| i as u8).collect::<Vec<_>>().into()).unwrap();
    formats::nrrd::write_nrrd(
        &p,
        &v,
        formats::nrrd::NrrdEncoding::Gzip,
        formats::output::Replace::Refuse,
    )
    .unwrap();
    let bytes = std::fs::read(&p).unwrap();
    let end = bytes.windows(2).position(|w| w == b"\n\n").unwrap() + 2;
    bytes[end..].to_vec()
}

struct Case {
    name: &'static str,
    files: Vec<(&'static str, Vec<u8>)>,
    open: &'static str,
    want: Want,
}

fn one(name: &'static str, bytes: Vec<u8>, want: Want) -> Case {
    Case {
        name,
        files: vec![("f.nrrd", bytes)],
        open: "f.nrrd",
        want,
    }
}

fn corpus() -> Vec<Case> {
    let z8 = [0u8; 8];
    let gz8 = gzip_stream(8);
    let gz9 = gzip_stream(9);
    let detached = |header: &str, files: Vec<(&'static str, Vec<u8>)>, want| {
        let mut all = vec![("h.nhdr", header.as_bytes().to_vec())];
        all.extend(files);
        (all, want)
    };
    let mut c = vec![
        // Magic and line structure.
        one("empty file", vec![], Want::Magic),
        one(
            "version 6",
            whole(&BASE.replace("NRRD0004", "NRRD0006")),
            Want::Magic,
        ),
        one(
            "version 0",
            whole(&BASE.replace("NRRD0004", "NRRD0000")),
            Want::Magic,
        ),
        one(
            "lower-case magic",
            whole(&BASE.replace("NRRD", "nrrd")),
            Want::Magic,
        ),
        one(
            "pgm named .nrrd",
            b"P5\n2 2\n255\n\x00\x01\x02\x03".to_vec(),
            Want::Magic,
        ),
        one("line without colon", nrrd("garbage line", &z8), Want::Line),
        one(
            "invalid utf-8",
            nrrd("content: \u{0}", &z8)
                .into_iter()
                .map(|b| if b == 0 { 0xff } else { b })
                .collect(),
            Want::Line,
        ),
        one(
            "unknown field",
            nrrd("colour: red", &z8),
            Want::Unknown("colour"),
        ),
        one(
            "duplicate sizes",
            nrrd("sizes: 2 2 2", &z8),
            Want::Dup("sizes"),
        ),
        one(
            "duplicate via alias",
            nrrd("lineskip: 0\nline skip: 0", &z8),
            Want::Dup("line skip"),
        ),
        // Required fields.
        one(
            "no dimension",
            whole("NRRD0004\ntype: uint8\nsizes: 2 2 2\nencoding: raw"),
            Want::Missing("dimension"),
        ),
        one(
            "no type",
            whole("NRRD0004\ndimension: 3\nsizes: 2 2 2\nencoding: raw"),
            Want::Missing("type"),
        ),
        one(
            "no sizes",
            whole("NRRD0004\ntype: uint8\ndimension: 3\nencoding: raw"),
            Want::Missing("sizes"),
        ),
        one(
            "no encoding",
            whole("NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2"),
            Want::Missing("encoding"),
        ),
        one(
            "no endian for short",
            whole("NRRD0004\ntype: short\ndimension: 3\nsizes: 2 2 1\nencoding: raw"),
            Want::Missing("endian"),
        ),
        // Basic field values.
        one(
            "dimension 0",
            whole("NRRD0004\ntype: uint8\ndimension: 0\nsizes: 2\nencoding: raw"),
            Want::Bad("dimension"),
        ),
        one(
            "dimension word",
            whole("NRRD0004\ntype: uint8\ndimension: three\nsizes: 2 2 2\nencoding: raw"),
            Want::Bad("dimension"),
        ),
        one(
            "dimension 17",
            whole("NRRD0004\ntype: uint8\ndimension: 17\nsizes: 2 2 2\nencoding: raw"),
            Want::Bad("dimension"),
        ),
        one(
            "dimension 2",
            whole("NRRD0004\ntype: uint8\ndimension: 2\nsizes: 2 4\nencoding: raw"),
            Want::Unsup("dimension"),
        ),
        one(
            "dimension 5",
            whole("NRRD0004\ntype: uint8\ndimension: 5\nsizes: 2 2 2 1 1\nencoding: raw"),
            Want::Unsup("dimension"),
        ),
        one(
            "unknown type",
            whole(&BASE.replace("uint8", "complex")),
            Want::Bad("type"),
        ),
        one(
            "64-bit type",
            whole(&format!("{}endian: little", BASE.replace("uint8", "int64"))),
            Want::Unsup("type"),
        ),
        one(
            "block type",
            whole(&BASE.replace("uint8", "block")),
            Want::Unsup("type"),
        ),
        one(
            "two sizes for dimension 3",
            whole(&BASE.replace("sizes: 2 2 2", "sizes: 2 2")),
            Want::Bad("sizes"),
        ),
        one(
            "size zero",
            whole(&BASE.replace("sizes: 2 2 2", "sizes: 2 0 2")),
            Want::Bad("sizes"),
        ),
        one(
            "negative size",
            whole(&BASE.replace("sizes: 2 2 2", "sizes: -2 2 2")),
            Want::Bad("sizes"),
        ),
        one(
            "sizes overflow",
            whole(&BASE.replace("sizes: 2 2 2", "sizes: 4294967296 4294967296 4294967296")),
            Want::Bad("sizes"),
        ),
        one(
            "unknown encoding",
            whole(&BASE.replace("encoding: raw", "encoding: lzma")),
            Want::Bad("encoding"),
        ),
        one(
            "zrl encoding",
            whole(&BASE.replace("encoding: raw", "encoding: zrl")),
            Want::Unsup("encoding"),
        ),
        one(
            "endian middle",
            nrrd("endian: middle", &z8),
            Want::Bad("endian"),
        ),
        one(
            "byte skip -2",
            nrrd("byte skip: -2", &z8),
            Want::Bad("byte skip"),
        ),
        one(
            "byte skip -1 with gzip",
            whole(&format!(
                "{}byte skip: -1",
                BASE.replace("encoding: raw", "encoding: gzip")
            )),
            Want::Contra("byte skip", "encoding"),
        ),
        one(
            "line skip negative",
            nrrd("line skip: -1", &z8),
            Want::Bad("line skip"),
        ),
        one("min not a number", nrrd("min: abc", &z8), Want::Bad("min")),
        one(
            "block size not a number",
            nrrd("block size: x", &z8),
            Want::Bad("block size"),
        ),
        // Per-axis fields.
        one(
            "spacings count",
            nrrd("spacings: 1 1", &z8),
            Want::Bad("spacings"),
        ),
        one(
            "spacing zero",
            nrrd("spacings: 1 0 1", &z8),
            Want::Bad("spacings"),
        ),
        one(
            "spacing word",
            nrrd("spacings: 1 abc 1", &z8),
            Want::Bad("spacings"),
        ),
        one(
            "negative spacing",
            nrrd("spacings: 1 -1 1", &z8),
            Want::Unsup("spacings"),
        ),
        one(
            "kinds unknown",
            nrrd("kinds: domain domain banana", &z8),
            Want::Bad("kinds"),
        ),
        one(
            "kind size mismatch",
            nrrd("kinds: 3-vector domain domain", &z8),
            Want::Contra("kinds", "sizes"),
        ),
        one(
            "centers unknown",
            nrrd("centers: cell middle cell", &z8),
            Want::Bad("centers"),
        ),
        one(
            "labels unquoted",
            nrrd("labels: x y z", &z8),
            Want::Bad("labels"),
        ),
        one(
            "labels unterminated",
            nrrd("labels: \"x\" \"y\" \"z", &z8),
            Want::Bad("labels"),
        ),
        one(
            "axis min above max",
            nrrd("axis mins: 0 5 0\naxis maxs: 1 1 1", &z8),
            Want::Contra("axis mins", "axis maxs"),
        ),
        one(
            "spacing contradicts min/max",
            nrrd("spacings: 1 1 1\naxis mins: 0 0 0\naxis maxs: 5 1 1", &z8),
            Want::Contra("axis maxs", "spacings"),
        ),
        // Space and orientation.
        one(
            "spacings with space directions",
            nrrd(
                "space: RAS\nspace directions: (1,0,0) (0,1,0) (0,0,1)\nspacings: 1 1 1",
                &z8,
            ),
            Want::Contra("spacings", "space directions"),
        ),
        one(
            "axis mins with space directions",
            nrrd(
                "space: RAS\nspace directions: (1,0,0) (0,1,0) (0,0,1)\naxis mins: 0 0 0",
                &z8,
            ),
            Want::Contra("axis mins", "space directions"),
        ),
        one(
            "spacings with space",
            nrrd("space: LPS\nspacings: 1 1 1", &z8),
            Want::Contra("spacings", "space"),
        ),
        one(
            "space and space dimension",
            nrrd("space: LPS\nspace dimension: 3", &z8),
            Want::Contra("space dimension", "space"),
        ),
        one(
            "unknown space",
            nrrd("space: up-down-sideways", &z8),
            Want::Bad("space"),
        ),
        one(
            "directions without space",
            nrrd("space directions: (1,0,0) (0,1,0) (0,0,1)", &z8),
            Want::Missing("space"),
        ),
        one(
            "origin without space",
            nrrd("space origin: (0,0,0)", &z8),
            Want::Missing("space"),
        ),
        one(
            "directions count",
            nrrd("space: RAS\nspace directions: (1,0,0) (0,1,0)", &z8),
            Want::Bad("space directions"),
        ),
        one(
            "direction with 2 components",
            nrrd("space: RAS\nspace directions: (1,0) (0,1,0) (0,0,1)", &z8),
            Want::Bad("space directions"),
        ),
        one(
            "direction unclosed",
            nrrd("space: RAS\nspace directions: (1,0,0) (0,1,0) (0,0,1", &z8),
            Want::Bad("space directions"),
        ),
        one(
            "direction word",
            nrrd("space: RAS\nspace directions: (a,0,0) (0,1,0) (0,0,1)", &z8),
            Want::Bad("space directions"),
        ),
        one(
            "direction zero",
            nrrd("space: RAS\nspace directions: (0,0,0) (0,1,0) (0,0,1)", &z8),
            Want::Bad("space directions"),
        ),
        one(
            "directions singular",
            nrrd("space: RAS\nspace directions: (1,1,0) (2,2,0) (0,0,1)", &z8),
            Want::Geometry,
        ),
        one(
            "space dimension 2",
            nrrd(
                "space dimension: 2\nspace directions: (1,0) (0,1) (1,1)",
                &z8,
            ),
            Want::Unsup("space dimension"),
        ),
        one(
            "origin components",
            nrrd("space: RAS\nspace origin: (0,0)", &z8),
            Want::Bad("space origin"),
        ),
        one(
            "origin nan",
            nrrd("space: RAS\nspace origin: (0,nan,0)", &z8),
            Want::Bad("space origin"),
        ),
        one(
            "measurement frame count",
            nrrd("space: RAS\nmeasurement frame: (1,0,0) (0,1,0)", &z8),
            Want::Bad("measurement frame"),
        ),
        one(
            "space units count",
            nrrd("space: RAS\nspace units: \"mm\" \"mm\"", &z8),
            Want::Bad("space units"),
        ),
        // 4D.
        one(
            "vector voxels",
            whole(
                "NRRD0004\ntype: uint8\ndimension: 4\nsizes: 3 2 2 2\nencoding: raw\nkinds: 3-vector domain domain domain",
            ),
            Want::Unsup("sizes"),
        ),
        one(
            "two none axes",
            whole(
                "NRRD0004\ntype: uint8\ndimension: 4\nsizes: 1 2 2 2\nencoding: raw\nspace: RAS\nspace directions: none none (0,1,0) (0,0,1)",
            ),
            Want::Bad("space directions"),
        ),
        one(
            "time axis in the middle",
            whole(
                "NRRD0004\ntype: uint8\ndimension: 4\nsizes: 2 2 2 1\nencoding: raw\nkinds: domain time domain domain",
            ),
            Want::Unsup("sizes"),
        ),
        // Data size and decoding.
        one("raw data short", nrrd("", &[0u8; 7]), Want::TooShort),
        one("raw data long", nrrd("", &[0u8; 9]), Want::TooLong),
        one("no data at all", BASE.as_bytes().to_vec(), Want::TooShort),
        one(
            "byte skip past end",
            nrrd("byte skip: 100", &z8),
            Want::TooShort,
        ),
        one(
            "byte skip -1 file too small",
            nrrd("byte skip: -1", &[0u8; 3]),
            Want::TooShort,
        ),
        one(
            "line skip past end",
            nrrd("line skip: 5", b"a\nb\n"),
            Want::Bad("line skip"),
        ),
        one(
            "huge raw sizes, tiny file",
            whole(&BASE.replace("sizes: 2 2 2", "sizes: 1048576 1048576 1024")),
            Want::TooShort,
        ),
        one(
            "gzip truncated",
            {
                let mut b =
                    format!("{}\n", BASE.replace("encoding: raw", "encoding: gzip")).into_bytes();
                b.extend_from_slice(&gz8[..gz8.len() - 6]);
                b
            },
            Want::Decode("gzip"),
        ),
        one(
            "gzip garbage",
            whole(&BASE.replace("encoding: raw", "encoding: gzip")),
            Want::Decode("gzip"),
        ),
        one(
            "gzip decodes too long",
            {
                let mut b =
                    format!("{}\n", BASE.replace("encoding: raw", "encoding: gzip")).into_bytes();
                b.extend_from_slice(&gz9);
                b
            },
            Want::TooLong,
        ),
        one(
            "huge gzip sizes, tiny stream",
            {
                let mut b = format!(
                    "{}\n",
                    BASE.replace("encoding: raw", "encoding: gzip")
                        .replace("sizes: 2 2 2", "sizes: 100000 100000 100")
                )
                .into_bytes();
                b.extend_from_slice(&gz8);
                b
            },
            Want::Decode("gzip"),
        ),
        one(
            "bzip2 garbage",
            whole(&BASE.replace("encoding: raw", "encoding: bzip2")),
            Want::Decode("bzip2"),
        ),
        one(
            "ascii too few values",
            {
                let mut b = format!("{}\n", BASE.replace("raw", "ascii")).into_bytes();
                b.extend_from_slice(b"1 2 3 4 5 6 7");
                b
            },
            Want::Text,
        ),
        one(
            "ascii word",
            {
                let mut b = format!("{}\n", BASE.replace("raw", "ascii")).into_bytes();
                b.extend_from_slice(b"1 2 3 x 5 6 7 8");
                b
            },
            Want::Text,
        ),
        one(
            "ascii out of range",
            {
                let mut b = format!("{}\n", BASE.replace("raw", "ascii")).into_bytes();
                b.extend_from_slice(b"1 2 3 300 5 6 7 8");
                b
            },
            Want::Text,
        ),
        one(
            "ascii too many values",
            {
                let mut b = format!("{}\n", BASE.replace("raw", "ascii")).into_bytes();
                b.extend_from_slice(b"1 2 3 4 5 6 7 8 9");
                b
            },
            Want::TooLong,
        ),
        one(
            "hex bad digit",
            {
                let mut b = format!("{}\n", BASE.replace("raw", "hex")).into_bytes();
                b.extend_from_slice(b"00010203040506zz");
                b
            },
            Want::Text,
        ),
        one(
            "hex short",
            {
                let mut b = format!("{}\n", BASE.replace("raw", "hex")).into_bytes();
                b.extend_from_slice(b"000102");
                b
            },
            Want::Text,
        ),
    ];
    // Detached headers.
    for (name, (files, want)) in [
        (
            "data file missing",
            detached(&format!("{BASE}data file: nothere.raw\n"), vec![], Want::Io),
        ),
        (
            "LIST count",
            detached(
                &format!("{BASE}data file: LIST\na.raw\n"),
                vec![("a.raw", vec![0; 4])],
                Want::Bad("data file"),
            ),
        ),
        (
            "LIST subdim too big",
            detached(
                &format!("{BASE}data file: LIST 9\na.raw\n"),
                vec![],
                Want::Bad("data file"),
            ),
        ),
        (
            "pattern step 0",
            detached(
                &format!("{BASE}data file: s%d.raw 1 2 0\n"),
                vec![],
                Want::Bad("data file"),
            ),
        ),
        (
            "pattern %s",
            detached(
                &format!("{BASE}data file: s%s.raw 1 2 1\n"),
                vec![],
                Want::Bad("data file"),
            ),
        ),
        (
            "pattern count",
            detached(
                &format!("{BASE}data file: s%d.raw 1 5 1\n"),
                vec![],
                Want::Bad("data file"),
            ),
        ),
        (
            "pattern file short",
            detached(
                &format!("{BASE}data file: s%d.raw 1 2 1\n"),
                vec![("s1.raw", vec![0; 4]), ("s2.raw", vec![0; 3])],
                Want::TooShort,
            ),
        ),
        (
            "detached data long",
            detached(
                &format!("{BASE}data file: d.raw\n"),
                vec![("d.raw", vec![0; 12])],
                Want::TooLong,
            ),
        ),
    ] {
        c.push(Case {
            name,
            files,
            open: "h.nhdr",
            want,
        });
    }
    // Raw files and others.
    let side = |json: &str, data: usize, want| Case {
        name: "raw sidecar",
        files: vec![
            ("r.raw", vec![0u8; data]),
            ("r.json", json.as_bytes().to_vec()),
        ],
        open: "r.raw",
        want,
    };
    c.push(side("{\"dims\":[2,2,2],\"type\":\"u8\"", 8, Want::Sidecar));
    c.push(side(
        "{\"dims\":[2,2,2],\"type\":\"u8\",\"endian\":\"little\",\"spacing\":[1,1,1],\"extra\":0}",
        8,
        Want::Sidecar,
    ));
    c.push(side(
        "{\"dims\":[2,2,2],\"type\":\"u16\",\"endian\":\"little\",\"spacing\":[1,1,1]}",
        8,
        Want::TooShort,
    ));
    c.push(side(
        "{\"dims\":[2,2,2],\"type\":\"u8\",\"endian\":\"little\",\"spacing\":[1,-1,1]}",
        8,
        Want::Geometry,
    ));
    c.push(Case {
        name: "unknown extension",
        files: vec![("x.xyz", b"hello".to_vec())],
        open: "x.xyz",
        want: Want::UnknownFormat,
    });
    c
}

#[test]
fn every_malformed_file_gives_its_specific_error() {
    let corpus = corpus();
    assert!(corpus.len() >= 50, "corpus has only {} files", corpus.len());
    let mut failures = Vec::new();
    for (n, case) in corpus.iter().enumerate() {
        let dir = tempfile::tempdir().unwrap();
        for (name, bytes) in &case.files {
            std::fs::write(dir.path().join(name), bytes).unwrap();
        }
        let path = dir.path().join(case.open);
        let result = std::panic::catch_unwind(|| formats::open(&path, &OpenOptions::default()));
        match result {
            Err(_) => failures.push(format!("#{n} {}: PANIC", case.name)),
            Ok(Ok(_)) => failures.push(format!("#{n} {}: opened without error", case.name)),
            Ok(Err(e)) => {
                if !matches(&e, case.want) {
                    failures.push(format!(
                        "#{n} {}: expected {:?}, got {e:?}",
                        case.name, case.want
                    ));
                }
                // Every message names the file it is about.
                let msg = e.to_string();
                if !msg.contains(&dir.path().display().to_string()) {
                    failures.push(format!("#{n} {}: message names no file: {msg}", case.name));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn header_errors_name_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("l.nrrd");
    std::fs::write(&p, nrrd("# a comment\nspacings: 1 x 1", &[0; 8])).unwrap();
    let e = formats::open(&p, &OpenOptions::default()).unwrap_err();
    let FormatError::BadValue { line, field, .. } = &e else {
        panic!("{e}")
    };
    assert_eq!((*line, field.as_str()), (7, "spacings"));
    assert!(e.to_string().contains("line 7"), "{e}");
}
