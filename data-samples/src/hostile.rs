//! # A corpus of malformed, hostile and edge-case input files
//!
//! [`write_corpus`] writes several hundred small files into a directory, one subdirectory per
//! case, and returns the [`Case`] list: what to open, which reader it exercises, what kind of
//! damage it carries, and what is expected. It covers every reader of `formats`: NRRD
//! (attached and detached, every encoding, `LIST` and printf-pattern data files), raw voxels
//! with a `.json` sidecar, numbered time series, legacy VTK, VTU (every encoding), PVD,
//! Gmsh 2.2 and 4.1 (ASCII and binary), TetGen, `.isot`, (in `hostile/images.rs`) MetaImage,
//! VTK image data and TIFF stacks, (in `hostile/nifti.rs`) NIfTI-1/NIfTI-2 and Analyze 7.5,
//! and (in `hostile/dicom.rs`) DICOM (folders, single files, DICOMDIRs,
//! native/RLE/deflated/JPEG/JPEG 2000 pixel data, enhanced multi-frame).
//!
//! ## The truth is the construction
//! Whether a case is valid is decided here, by how the file was built, never by what a
//! reader makes of it: a valid base file is written field by field from the format's
//! specification (seed: VTK file formats, Gmsh reference manual §10, TetGen manual, NRRD
//! format definition, DICOM PS3.5 §7 and Annex G, PS3.10 §7), and every damaged case is derived from a valid base by one change that
//! the specification forbids — a cut inside a region whose length the file itself declares, a
//! count larger than the bytes that follow, a stream that is not the declared encoding, a
//! reference to itself. Truncations of text files cut only inside such declared regions (a
//! cut between two complete sections could leave a shorter but valid file).
//!
//! Valid edge cases (1×1×1, constant, all-NaN, one tet, degenerate tets, oriented grids,
//! skips) must open and render; all-NaN data has no value to put a default isosurface at, so
//! its case carries an explicit `--iso` in [`Case::render_args`].
//!
//! ## Layout on disk
//! `DIR/<case name>/...`: the files of one case never share a directory with another's, so a
//! case's error can be checked to name one of *its* files ([`Case::names`], relative to
//! `DIR`). Special files are made as such: FIFOs with the `mkfifo` command, symbolic links to
//! `/dev/zero`, directories named like volumes (Unix only).

// Cut regions are lists of byte ranges; many formats have one region (`&[0..len]`).
#![allow(clippy::single_range_in_vec_init)]

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

mod dicom;
mod images;
mod nifti;

/// The files of one case: (name inside the case's folder, what to put there).
type Files = Vec<(String, Entry)>;

/// The reader a case exercises (the row of the outcome table).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Reader {
    /// Attached NRRD (`.nrrd`, header and data in one file).
    Nrrd,
    /// Detached NRRD (`.nhdr` + data files, `LIST`, printf patterns).
    NrrdDetached,
    /// Raw voxels with a `NAME.json` sidecar.
    RawSidecar,
    /// Numbered or globbed volume series, and 4D NRRD.
    Series,
    /// Legacy VTK `.vtk` (ASCII, BINARY, 4.2 and 5.1 cells).
    VtkLegacy,
    /// VTK XML `.vtu` (ascii, binary, appended raw/base64, zlib).
    Vtu,
    /// `.pvd` collections.
    Pvd,
    /// Gmsh MSH 2.2, ASCII and binary.
    Gmsh22,
    /// Gmsh MSH 4.1, ASCII and binary.
    Gmsh41,
    /// TetGen `.node` + `.ele`.
    TetGen,
    /// `.isot` treelet files.
    Isot,
    /// MetaImage `.mha` / `.mhd` (local, detached, pattern, `LIST`; raw and zlib; 4D).
    MetaImage,
    /// VTK image data: `.vti` (every encoding) and legacy `.vtk` structured points and
    /// rectilinear grids.
    VtkImage,
    /// TIFF stacks (multi-page, numbered 2D slices).
    Tiff,
    /// NIfTI-1/NIfTI-2 (`.nii`, `.nii.gz`, `.hdr`/`.img`) and Analyze 7.5.
    Nifti,
    /// DICOM series (folders, files, DICOMDIRs).
    Dicom,
}

impl Reader {
    pub const ALL: [Reader; 16] = [
        Reader::Nrrd,
        Reader::NrrdDetached,
        Reader::RawSidecar,
        Reader::Series,
        Reader::VtkLegacy,
        Reader::Vtu,
        Reader::Pvd,
        Reader::Gmsh22,
        Reader::Gmsh41,
        Reader::TetGen,
        Reader::Isot,
        Reader::MetaImage,
        Reader::VtkImage,
        Reader::Tiff,
        Reader::Nifti,
        Reader::Dicom,
    ];

    pub const fn name(self) -> &'static str {
        match self {
            Reader::Nrrd => "NRRD attached",
            Reader::NrrdDetached => "NRRD detached",
            Reader::RawSidecar => "raw + .json",
            Reader::Series => "volume series",
            Reader::VtkLegacy => "legacy VTK",
            Reader::Vtu => "VTU",
            Reader::Pvd => "PVD",
            Reader::Gmsh22 => "Gmsh 2.2",
            Reader::Gmsh41 => "Gmsh 4.1",
            Reader::TetGen => "TetGen",
            Reader::Isot => ".isot",
            Reader::MetaImage => "MetaImage",
            Reader::VtkImage => "VTK image",
            Reader::Tiff => "TIFF",
            Reader::Nifti => "NIfTI/Analyze",
            Reader::Dicom => "DICOM",
        }
    }
}

/// What was done to the file (the column of the outcome table).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Kind {
    /// A valid file (edge cases included); must render.
    Valid,
    /// Cut at an offset inside a region the file declares the length of.
    Truncated,
    /// A header field that contradicts the data (sizes, type, counts, version, missing field).
    LyingHeader,
    /// Sizes or counts whose product or value overflows 64 bits.
    Overflow,
    /// Byte or line skips (or header bytes) far beyond the file.
    HugeSkip,
    /// Compressed or encoded data that is not a valid stream of the declared encoding.
    BadStream,
    /// `.pvd` collections that reference themselves or each other, or nest too deep.
    Cycle,
    /// Point indices, node tags or file numbers outside their declared range.
    OutOfRange,
    /// NaN, infinite, zero or overflowing spacing, singular space directions.
    BadGeometry,
    /// Bytes that are not UTF-8 where the format requires text.
    NonUtf8,
    /// A multi-megabyte line where a short field is expected.
    LongLine,
    /// A FIFO, a link to `/dev/zero`, a directory, a dangling link or a missing file.
    SpecialFile,
}

impl Kind {
    pub const ALL: [Kind; 12] = [
        Kind::Valid,
        Kind::Truncated,
        Kind::LyingHeader,
        Kind::Overflow,
        Kind::HugeSkip,
        Kind::BadStream,
        Kind::Cycle,
        Kind::OutOfRange,
        Kind::BadGeometry,
        Kind::NonUtf8,
        Kind::LongLine,
        Kind::SpecialFile,
    ];

    pub const fn name(self) -> &'static str {
        match self {
            Kind::Valid => "valid",
            Kind::Truncated => "truncated",
            Kind::LyingHeader => "lying header",
            Kind::Overflow => "overflow",
            Kind::HugeSkip => "huge skip",
            Kind::BadStream => "bad stream",
            Kind::Cycle => "cycle",
            Kind::OutOfRange => "out of range",
            Kind::BadGeometry => "bad geometry",
            Kind::NonUtf8 => "non-UTF-8",
            Kind::LongLine => "long line",
            Kind::SpecialFile => "special file",
        }
    }
}

/// What opening the case must give.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Expect {
    /// A clean error (no panic, no hang) that names one of [`Case::names`].
    Error,
    /// Opens and renders.
    Renders,
}

/// One file (or set of files) of the corpus.
#[derive(Debug, Clone)]
pub struct Case {
    /// Unique, also the case's subdirectory.
    pub name: String,
    /// The path to open (a file, or a series pattern that names no file).
    pub open: PathBuf,
    pub reader: Reader,
    pub kind: Kind,
    pub expect: Expect,
    /// Extra arguments for `render` (an isovalue for data without one).
    pub render_args: Vec<String>,
    /// For a series whose damage is in a later step: that step (opening shows step 0 first,
    /// which is valid; `render --step N` and the viewer's step switch must fail).
    pub bad_step: Option<usize>,
    /// Paths relative to the corpus directory (`case/file`), one of which an error must name.
    pub names: Vec<String>,
}

/// A file of a case as it is made on disk.
enum Entry {
    File(Vec<u8>),
    /// `mkfifo`.
    Fifo,
    /// A symbolic link to this target.
    Link(PathBuf),
    Dir,
}

struct Corpus {
    root: PathBuf,
    cases: Vec<Case>,
}

fn io_err(e: impl std::fmt::Display) -> std::io::Error {
    std::io::Error::other(e.to_string())
}

impl Corpus {
    /// Writes the entries of case `name` and records it (expects an error by default; the
    /// error may name any of the case's files).
    fn add(
        &mut self,
        reader: Reader,
        kind: Kind,
        name: &str,
        entries: Vec<(String, Entry)>,
        open: &str,
    ) -> std::io::Result<&mut Case> {
        assert!(
            !self.cases.iter().any(|c| c.name == name),
            "duplicate case {name}"
        );
        let dir = self.root.join(name);
        std::fs::create_dir_all(&dir)?;
        let mut names = vec![format!("{name}/{open}")];
        for (file, entry) in entries {
            let path = dir.join(&file);
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent)?;
            }
            match entry {
                Entry::File(bytes) => std::fs::write(&path, bytes)?,
                Entry::Dir => std::fs::create_dir_all(&path)?,
                Entry::Fifo => mkfifo(&path)?,
                Entry::Link(target) => symlink(&target, &path)?,
            }
            let n = format!("{name}/{file}");
            if !names.contains(&n) {
                names.push(n);
            }
        }
        self.cases.push(Case {
            name: name.into(),
            open: dir.join(open),
            reader,
            kind,
            expect: Expect::Error,
            render_args: Vec::new(),
            bad_step: None,
            names,
        });
        Ok(self.cases.last_mut().expect("just pushed"))
    }

    /// A one-file case.
    fn one(
        &mut self,
        reader: Reader,
        kind: Kind,
        name: &str,
        file: &str,
        bytes: Vec<u8>,
    ) -> std::io::Result<&mut Case> {
        self.add(
            reader,
            kind,
            name,
            vec![(file.into(), Entry::File(bytes))],
            file,
        )
    }

    /// A valid one-file case that must render.
    fn valid(
        &mut self,
        reader: Reader,
        name: &str,
        file: &str,
        bytes: Vec<u8>,
    ) -> std::io::Result<&mut Case> {
        let c = self.one(reader, Kind::Valid, name, file, bytes)?;
        c.expect = Expect::Renders;
        Ok(c)
    }

    /// Truncations of `bytes` at `count` offsets spread over `regions` (half-open byte
    /// ranges in which any cut leaves the file invalid).
    fn truncations(
        &mut self,
        reader: Reader,
        stem: &str,
        file: &str,
        bytes: &[u8],
        regions: &[std::ops::Range<usize>],
        count: usize,
    ) -> std::io::Result<()> {
        for at in spread(regions, count) {
            self.one(
                reader,
                Kind::Truncated,
                &format!("{stem}_cut{at}"),
                file,
                bytes[..at].to_vec(),
            )?;
        }
        Ok(())
    }

    /// The special-file cases of a main file named `file`: a FIFO, a link to `/dev/zero`, a
    /// directory and a dangling link.
    fn special(&mut self, reader: Reader, stem: &str, file: &str) -> std::io::Result<()> {
        self.add(
            reader,
            Kind::SpecialFile,
            &format!("{stem}_fifo"),
            vec![(file.into(), Entry::Fifo)],
            file,
        )?;
        self.add(
            reader,
            Kind::SpecialFile,
            &format!("{stem}_devzero"),
            vec![(file.into(), Entry::Link("/dev/zero".into()))],
            file,
        )?;
        self.add(
            reader,
            Kind::SpecialFile,
            &format!("{stem}_dir"),
            vec![(file.into(), Entry::Dir)],
            file,
        )?;
        self.add(
            reader,
            Kind::SpecialFile,
            &format!("{stem}_dangling"),
            vec![(file.into(), Entry::Link("does-not-exist".into()))],
            file,
        )?;
        Ok(())
    }
}

fn mkfifo(path: &Path) -> std::io::Result<()> {
    let status = std::process::Command::new("mkfifo").arg(path).status()?;
    if status.success() {
        Ok(())
    } else {
        Err(io_err(format!("mkfifo {} failed", path.display())))
    }
}

#[cfg(unix)]
fn symlink(target: &Path, link: &Path) -> std::io::Result<()> {
    std::os::unix::fs::symlink(target, link)
}

#[cfg(not(unix))]
fn symlink(_target: &Path, link: &Path) -> std::io::Result<()> {
    Err(io_err(format!(
        "{}: symbolic links are made on Unix only",
        link.display()
    )))
}

/// `count` distinct offsets spread evenly over the union of `regions`.
fn spread(regions: &[std::ops::Range<usize>], count: usize) -> Vec<usize> {
    let all: Vec<usize> = regions.iter().flat_map(Clone::clone).collect();
    if all.is_empty() {
        return Vec::new();
    }
    let mut out: Vec<usize> = (0..count)
        .map(|i| all[i * all.len() / count.max(1)])
        .collect();
    out.dedup();
    out
}

/// The byte range of the first occurrence of `needle` in `hay` (panics if absent: the
/// generator's own text).
fn find(hay: &[u8], needle: &str) -> std::ops::Range<usize> {
    let n = needle.as_bytes();
    let at = hay
        .windows(n.len())
        .position(|w| w == n)
        .unwrap_or_else(|| panic!("{needle:?} not in the generated file"));
    at..at + n.len()
}

/// Start of the last whitespace-separated token at or before `end` (a cut there or earlier
/// removes that token entirely, so a number cannot be shortened into another number).
fn last_token_start(bytes: &[u8], end: usize) -> usize {
    let mut i = end;
    while i > 0 && bytes[i - 1].is_ascii_whitespace() {
        i -= 1;
    }
    while i > 0 && !bytes[i - 1].is_ascii_whitespace() {
        i -= 1;
    }
    i
}

/// The region of a text block from `after` (exclusive end of a marker) to the start of its
/// last token before `before`.
fn text_block(bytes: &[u8], after: &str, before: &str) -> std::ops::Range<usize> {
    let a = find(bytes, after).end;
    let b = a + find(&bytes[a..], before).start;
    a..last_token_start(bytes, b)
}

// ---- compression and encodings -------------------------------------------------------------

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    e.write_all(bytes).expect("in memory");
    e.finish().expect("in memory")
}

fn zlib(bytes: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    e.write_all(bytes).expect("in memory");
    e.finish().expect("in memory")
}

fn bzip2(bytes: &[u8]) -> Vec<u8> {
    let mut e = bzip2::write::BzEncoder::new(Vec::new(), bzip2::Compression::default());
    e.write_all(bytes).expect("in memory");
    e.finish().expect("in memory")
}

fn b64(bytes: &[u8]) -> String {
    use base64::Engine as _;
    base64::engine::general_purpose::STANDARD.encode(bytes)
}

fn cat(parts: &[&[u8]]) -> Vec<u8> {
    parts.concat()
}

// ---- volumes ------------------------------------------------------------------------------

/// The test volume: 5×4×3 samples `i + 2j + 3k` (x fastest), range 0..=16.
const DIMS: [usize; 3] = [5, 4, 3];

fn gradient() -> Vec<f64> {
    let mut v = Vec::new();
    for k in 0..DIMS[2] {
        for j in 0..DIMS[1] {
            for i in 0..DIMS[0] {
                v.push((i + 2 * j + 3 * k) as f64);
            }
        }
    }
    v
}

fn u8s(values: &[f64]) -> Vec<u8> {
    values.iter().map(|&x| x as u8).collect()
}

fn f32s_le(values: &[f64]) -> Vec<u8> {
    values
        .iter()
        .flat_map(|&x| (x as f32).to_le_bytes())
        .collect()
}

fn ascii_values(values: &[f64]) -> Vec<u8> {
    let mut s = String::new();
    for (i, x) in values.iter().enumerate() {
        let _ = write!(s, "{x}{}", if i % 5 == 4 { '\n' } else { ' ' });
    }
    s.push('\n');
    s.into_bytes()
}

fn hex_values(bytes: &[u8]) -> Vec<u8> {
    let mut s = String::new();
    for (i, b) in bytes.iter().enumerate() {
        let _ = write!(s, "{b:02x}{}", if i % 16 == 15 { "\n" } else { "" });
    }
    s.push('\n');
    s.into_bytes()
}

/// A NRRD header (NRRD0004, 3 axes, unit spacing unless `extra` says otherwise) ending in
/// the blank line of an attached file; `detached` adds no blank line.
fn nrrd_header(ty: &str, sizes: &str, encoding: &str, extra: &[&str]) -> String {
    let mut h = format!(
        "NRRD0004\n# made by data_samples::hostile\ntype: {ty}\ndimension: 3\nsizes: {sizes}\nendian: little\n"
    );
    if !extra.iter().any(|e| e.starts_with("spac")) {
        h.push_str("spacings: 1 1 1\n");
    }
    for e in extra {
        h.push_str(e);
        h.push('\n');
    }
    let _ = writeln!(h, "encoding: {encoding}");
    h
}

const SIZES: &str = "5 4 3";

fn attached(ty: &str, encoding: &str, extra: &[&str], data: &[u8]) -> Vec<u8> {
    cat(&[
        nrrd_header(ty, SIZES, encoding, extra).as_bytes(),
        b"\n",
        data,
    ])
}

fn nrrd_cases(c: &mut Corpus) -> std::io::Result<()> {
    let r = Reader::Nrrd;
    let g = gradient();
    let raw = u8s(&g);
    let nan_some: Vec<f64> = g
        .iter()
        .enumerate()
        .map(|(i, &x)| if i % 7 == 3 { f64::NAN } else { x })
        .collect();
    // Valid: every encoding and several types.
    c.valid(
        r,
        "nrrd_raw_u8",
        "v.nrrd",
        attached("uint8", "raw", &[], &raw),
    )?;
    c.valid(
        r,
        "nrrd_gzip_u8",
        "v.nrrd",
        attached("uchar", "gzip", &[], &gzip(&raw)),
    )?;
    c.valid(
        r,
        "nrrd_bzip2_u8",
        "v.nrrd",
        attached("uint8", "bzip2", &[], &bzip2(&raw)),
    )?;
    c.valid(
        r,
        "nrrd_ascii_u8",
        "v.nrrd",
        attached("uint8", "ascii", &[], &ascii_values(&g)),
    )?;
    c.valid(
        r,
        "nrrd_hex_u8",
        "v.nrrd",
        attached("uint8", "hex", &[], &hex_values(&raw)),
    )?;
    c.valid(
        r,
        "nrrd_raw_f32",
        "v.nrrd",
        attached("float", "raw", &[], &f32s_le(&g)),
    )?;
    let be: Vec<u8> = g.iter().flat_map(|&x| (x as i16).to_be_bytes()).collect();
    let h = nrrd_header("short", SIZES, "raw", &[]).replace("endian: little", "endian: big");
    c.valid(
        r,
        "nrrd_raw_i16_big",
        "v.nrrd",
        cat(&[h.as_bytes(), b"\n", &be]),
    )?;
    let f64gz: Vec<u8> = g.iter().flat_map(|&x| x.to_le_bytes()).collect();
    c.valid(
        r,
        "nrrd_gzip_f64",
        "v.nrrd",
        attached("double", "gz", &[], &gzip(&f64gz)),
    )?;
    c.valid(
        r,
        "nrrd_nan_some_f32",
        "v.nrrd",
        attached("float", "raw", &[], &f32s_le(&nan_some)),
    )?;
    c.valid(
        r,
        "nrrd_oriented",
        "v.nrrd",
        attached(
            "uint8",
            "raw",
            &[
                "spacings: nan nan nan",
                "space: right-anterior-superior",
                "space directions: (0,0.5,0) (0.7,0,0.7) (0,0,-2)",
                "space origin: (10,-20,5.5)",
            ],
            &raw,
        ),
    )?;
    c.valid(
        r,
        "nrrd_byte_skip",
        "v.nrrd",
        attached("uint8", "raw", &["byte skip: 3"], &cat(&[b"xyz", &raw])),
    )?;
    c.valid(
        r,
        "nrrd_line_skip",
        "v.nrrd",
        attached(
            "uint8",
            "raw",
            &["line skip: 2"],
            &cat(&[b"junk line\nanother\n", &raw]),
        ),
    )?;
    // The NRRD format definition: a NaN spacing or axis min is "unknown", not an error (the
    // reader falls back to unit spacing / the origin).
    c.valid(
        r,
        "nrrd_spacing_nan_unknown",
        "v.nrrd",
        attached("uint8", "raw", &["spacings: nan 1 1"], &raw),
    )?;
    c.valid(
        r,
        "nrrd_axis_mins_nan_unknown",
        "v.nrrd",
        attached(
            "uint8",
            "raw",
            &[
                "spacings: nan nan nan",
                "axis mins: nan 0 0",
                "axis maxs: 4 3 2",
            ],
            &raw,
        ),
    )?;
    let one = cat(&[
        nrrd_header("uint8", "1 1 1", "raw", &[]).as_bytes(),
        b"\n",
        &[42],
    ]);
    c.valid(r, "nrrd_1x1x1", "v.nrrd", one)?;
    let flat = cat(&[
        nrrd_header("uint8", "5 4 1", "raw", &[]).as_bytes(),
        b"\n",
        &raw[..20],
    ]);
    c.valid(r, "nrrd_5x4x1", "v.nrrd", flat)?;
    c.valid(
        r,
        "nrrd_constant",
        "v.nrrd",
        attached("float", "raw", &[], &f32s_le(&[7.0; 60])),
    )?;
    c.valid(
        r,
        "nrrd_all_nan",
        "v.nrrd",
        attached("float", "raw", &[], &f32s_le(&[f64::NAN; 60])),
    )?
    .render_args = vec!["--iso".into(), "0.5".into()];

    // Truncations: anywhere in a raw file (the data length is declared by the header, and a
    // cut in the header loses all data); inside the compressed stream (including the gzip
    // trailer, which carries the CRC and length); before the last value of ascii and hex.
    let base = attached("uint8", "raw", &[], &raw);
    c.truncations(r, "nrrd_raw", "v.nrrd", &base, &[0..base.len()], 24)?;
    let base = attached("uint8", "gzip", &[], &gzip(&raw));
    c.truncations(r, "nrrd_gzip", "v.nrrd", &base, &[0..base.len()], 16)?;
    let base = attached("uint8", "bzip2", &[], &bzip2(&raw));
    c.truncations(r, "nrrd_bzip2", "v.nrrd", &base, &[0..base.len()], 12)?;
    let base = attached("uint8", "ascii", &[], &ascii_values(&g));
    let end = last_token_start(&base, base.len());
    c.truncations(r, "nrrd_ascii", "v.nrrd", &base, &[0..end + 1], 10)?;
    let base = attached("uint8", "hex", &[], &hex_values(&raw));
    let end = base.len() - 2; // the last hex digit
    c.truncations(r, "nrrd_hex", "v.nrrd", &base, &[0..end], 10)?;

    // Lying headers.
    let lies: &[(&str, Vec<u8>)] = &[
        (
            "sizes_larger",
            cat(&[
                nrrd_header("uint8", "50 40 30", "raw", &[]).as_bytes(),
                b"\n",
                &raw,
            ]),
        ),
        (
            "sizes_larger_gzip",
            cat(&[
                nrrd_header("uint8", "50 40 30", "gzip", &[]).as_bytes(),
                b"\n",
                &gzip(&raw),
            ]),
        ),
        (
            "sizes_smaller_gzip",
            cat(&[
                nrrd_header("uint8", "2 2 2", "gzip", &[]).as_bytes(),
                b"\n",
                &gzip(&raw),
            ]),
        ),
        ("type_float_u8_data", attached("float", "raw", &[], &raw)),
        (
            "type_double_gzip",
            attached("double", "gzip", &[], &gzip(&raw)),
        ),
        (
            "dimension_4_of_3",
            attached("uint8", "raw", &[], &raw).replace_first("dimension: 3", "dimension: 4"),
        ),
        (
            "dimension_2_of_3",
            attached("uint8", "raw", &[], &raw).replace_first("dimension: 3", "dimension: 2"),
        ),
        (
            "dimension_0",
            attached("uint8", "raw", &[], &raw).replace_first("dimension: 3", "dimension: 0"),
        ),
        (
            "sizes_zero",
            cat(&[
                nrrd_header("uint8", "0 4 3", "raw", &[]).as_bytes(),
                b"\n",
                &raw,
            ]),
        ),
        (
            "sizes_negative",
            cat(&[
                nrrd_header("uint8", "-5 4 3", "raw", &[]).as_bytes(),
                b"\n",
                &raw,
            ]),
        ),
        (
            "sizes_not_numbers",
            cat(&[
                nrrd_header("uint8", "five 4 3", "raw", &[]).as_bytes(),
                b"\n",
                &raw,
            ]),
        ),
        ("type_unknown", attached("uint128", "raw", &[], &raw)),
        ("encoding_unknown", attached("uint8", "zip", &[], &raw)),
        (
            "endian_unknown",
            attached("uint8", "raw", &[], &raw).replace_first("endian: little", "endian: sideways"),
        ),
        (
            "magic_version_9",
            attached("uint8", "raw", &[], &raw).replace_first("NRRD0004", "NRRD0009"),
        ),
        (
            "magic_wrong",
            attached("uint8", "raw", &[], &raw).replace_first("NRRD0004", "NRDR0004"),
        ),
        (
            "no_type",
            attached("uint8", "raw", &[], &raw).replace_first("type: uint8\n", ""),
        ),
        (
            "no_sizes",
            attached("uint8", "raw", &[], &raw).replace_first("sizes: 5 4 3\n", ""),
        ),
        (
            "no_encoding",
            attached("uint8", "raw", &[], &raw).replace_first("encoding: raw\n", ""),
        ),
        (
            "no_dimension",
            attached("uint8", "raw", &[], &raw).replace_first("dimension: 3\n", ""),
        ),
        (
            "spacings_two_of_3",
            attached("uint8", "raw", &["spacings: 1 1"], &raw),
        ),
        (
            "directions_two_of_3",
            attached(
                "uint8",
                "raw",
                &["space: RAS", "space directions: (1,0,0) (0,1,0)"],
                &raw,
            ),
        ),
        (
            "field_without_colon",
            attached("uint8", "raw", &["spacings 1 1 1"], &raw),
        ),
        (
            "ascii_letters",
            attached("uint8", "ascii", &[], b"0 1 2 x 4 5\n"),
        ),
        ("ascii_short", attached("uint8", "ascii", &[], b"0 1 2 3\n")),
        (
            "ascii_out_of_range_u8",
            attached(
                "uint8",
                "ascii",
                &[],
                &ascii_values(&g.iter().map(|x| x + 300.0).collect::<Vec<_>>()),
            ),
        ),
        (
            "hex_bad_digits",
            attached(
                "uint8",
                "hex",
                &[],
                &hex_values(&raw).replace_first("00", "zz"),
            ),
        ),
        ("empty_file", Vec::new()),
        (
            "header_only",
            nrrd_header("uint8", SIZES, "raw", &[]).into_bytes(),
        ),
    ];
    for (n, bytes) in lies {
        c.one(
            r,
            Kind::LyingHeader,
            &format!("nrrd_{n}"),
            "v.nrrd",
            bytes.clone(),
        )?;
    }

    // Overflowing products.
    let big = [
        (
            "sizes_2pow32_cubed",
            "uint8",
            "4294967296 4294967296 4294967296",
            "raw",
        ),
        ("sizes_u64max", "uint8", "18446744073709551615 1 1", "raw"),
        (
            "sizes_beyond_u64",
            "uint8",
            "18446744073709551616 1 1",
            "raw",
        ),
        (
            "sizes_times_type",
            "double",
            "2305843009213693952 1 1",
            "raw",
        ),
        (
            "sizes_huge_gzip",
            "uint8",
            "4294967296 4294967296 4294967296",
            "gzip",
        ),
        ("sizes_huge_ascii", "float", "100000 100000 100000", "ascii"),
        ("sizes_huge_bzip2", "uint8", "1000000 1000000 1000", "bzip2"),
    ];
    for (n, ty, sizes, enc) in big {
        let data = match enc {
            "gzip" => gzip(&raw),
            "bzip2" => bzip2(&raw),
            "ascii" => ascii_values(&g),
            _ => raw.clone(),
        };
        let bytes = cat(&[nrrd_header(ty, sizes, enc, &[]).as_bytes(), b"\n", &data]);
        c.one(r, Kind::Overflow, &format!("nrrd_{n}"), "v.nrrd", bytes)?;
    }
    c.one(
        r,
        Kind::Overflow,
        "nrrd_dimension_huge",
        "v.nrrd",
        attached("uint8", "raw", &[], &raw)
            .replace_first("dimension: 3", "dimension: 18446744073709551615"),
    )?;

    // Huge skips.
    let skips = [
        ("byte_skip_1e15", "raw", "byte skip: 1000000000000000"),
        ("byte_skip_i64max", "raw", "byte skip: 9223372036854775807"),
        ("byte_skip_minus2", "raw", "byte skip: -2"),
        ("line_skip_1e12", "raw", "line skip: 1000000000000"),
        ("line_skip_negative", "raw", "line skip: -1"),
        ("byte_skip_gzip_1e12", "gzip", "byte skip: 1000000000000"),
        ("line_skip_ascii_1e9", "ascii", "line skip: 1000000000"),
    ];
    for (n, enc, field) in skips {
        let data = match enc {
            "gzip" => gzip(&raw),
            "ascii" => ascii_values(&g),
            _ => raw.clone(),
        };
        c.one(
            r,
            Kind::HugeSkip,
            &format!("nrrd_{n}"),
            "v.nrrd",
            attached("uint8", enc, &[field], &data),
        )?;
    }

    // Bad streams.
    let gz = gzip(&raw);
    let mut flipped = gz.clone();
    for b in &mut flipped[12..gz.len() - 10] {
        *b ^= 0x5a;
    }
    let mut bad_crc = gz.clone();
    let n = bad_crc.len();
    bad_crc[n - 8] ^= 0xff;
    let mut bz = bzip2(&raw);
    let m = bz.len() / 2;
    bz[m] ^= 0xff;
    bz[m + 1] ^= 0x33;
    let bomb = gzip(&vec![0u8; 64 << 20]);
    let streams: &[(&str, &str, Vec<u8>)] = &[
        ("gzip_of_raw", "gzip", raw.clone()),
        ("gzip_flipped", "gzip", flipped),
        ("gzip_bad_crc", "gzip", bad_crc),
        (
            "gzip_text",
            "gzip",
            b"this is not a gzip stream at all\n".to_vec(),
        ),
        ("bzip2_of_gzip", "bzip2", gz.clone()),
        ("bzip2_flipped", "bzip2", bz),
        ("gzip_bomb_64mib", "gzip", bomb),
        ("gzip_twice", "gzip", gzip(&gz)),
    ];
    for (n, enc, data) in streams {
        c.one(
            r,
            Kind::BadStream,
            &format!("nrrd_{n}"),
            "v.nrrd",
            attached("uint8", enc, &[], data),
        )?;
    }

    // Geometry.
    let geo: &[(&str, &[&str])] = &[
        ("spacing_inf", &["spacings: inf 1 1"]),
        ("spacing_minus_inf", &["spacings: 1 -inf 1"]),
        ("spacing_zero", &["spacings: 1 0 1"]),
        ("spacing_1e30", &["spacings: 1e30 1 1"]),
        ("spacing_1e400", &["spacings: 1e400 1 1"]),
        (
            "directions_zero_vector",
            &["space: RAS", "space directions: (0,0,0) (0,1,0) (0,0,1)"],
        ),
        (
            "directions_parallel",
            &["space: RAS", "space directions: (1,0,0) (2,0,0) (0,0,1)"],
        ),
        (
            "directions_coplanar",
            &["space: RAS", "space directions: (1,0,0) (0,1,0) (1,1,0)"],
        ),
        (
            "directions_nan",
            &["space: RAS", "space directions: (nan,0,0) (0,1,0) (0,0,1)"],
        ),
        (
            "directions_inf",
            &["space: RAS", "space directions: (inf,0,0) (0,1,0) (0,0,1)"],
        ),
        (
            "origin_inf",
            &[
                "space: RAS",
                "space directions: (1,0,0) (0,1,0) (0,0,1)",
                "space origin: (inf,0,0)",
            ],
        ),
        (
            "origin_nan",
            &[
                "space: RAS",
                "space directions: (1,0,0) (0,1,0) (0,0,1)",
                "space origin: (0,nan,0)",
            ],
        ),
        (
            "origin_1e20",
            &[
                "space: RAS",
                "space directions: (1,0,0) (0,1,0) (0,0,1)",
                "space origin: (0,0,1e20)",
            ],
        ),
        (
            "axis_mins_minus_inf",
            &[
                "spacings: nan nan nan",
                "axis mins: -inf 0 0",
                "axis maxs: 4 3 2",
            ],
        ),
    ];
    for (n, extra) in geo {
        c.one(
            r,
            Kind::BadGeometry,
            &format!("nrrd_{n}"),
            "v.nrrd",
            attached("uint8", "raw", extra, &raw),
        )?;
    }

    // Non-UTF-8 where text is required.
    let base = attached("uint8", "raw", &[], &raw);
    let bad_utf8: &[(&str, &str, &[u8])] = &[
        ("type", "type: uint8", b"type: \xff\xfeuint8"),
        ("sizes", "sizes: 5 4 3", b"sizes: 5 4 \xc3"),
        ("encoding", "encoding: raw", b"encoding: r\xe9w"),
        ("magic", "NRRD0004", b"NRRD\xff\xff04"),
    ];
    for (n, from, to) in bad_utf8 {
        c.one(
            r,
            Kind::NonUtf8,
            &format!("nrrd_utf8_{n}"),
            "v.nrrd",
            replace_bytes(&base, from, to),
        )?;
    }

    // Long lines.
    let long_type = format!("type: {}", "a".repeat(4 << 20));
    c.one(
        r,
        Kind::LongLine,
        "nrrd_long_type",
        "v.nrrd",
        replace_bytes(&base, "type: uint8", long_type.as_bytes()),
    )?;
    let long_sizes = format!("sizes: 5 4 3{}", " 1".repeat(1 << 20));
    c.one(
        r,
        Kind::LongLine,
        "nrrd_long_sizes",
        "v.nrrd",
        replace_bytes(&base, "sizes: 5 4 3", long_sizes.as_bytes()),
    )?;
    c.one(
        r,
        Kind::LongLine,
        "nrrd_one_line_no_newline",
        "v.nrrd",
        cat(&[b"NRRD0004\n", "x".repeat(4 << 20).as_bytes()]),
    )?;

    c.special(r, "nrrd_special", "x.nrrd")?;
    Ok(())
}

/// Byte-level replacement of the first `from` (which must occur).
fn replace_bytes(hay: &[u8], from: &str, to: &[u8]) -> Vec<u8> {
    let at = find(hay, from);
    cat(&[&hay[..at.start], to, &hay[at.end..]])
}

trait ReplaceFirst {
    fn replace_first(&self, from: &str, to: &str) -> Vec<u8>;
}

impl ReplaceFirst for Vec<u8> {
    fn replace_first(&self, from: &str, to: &str) -> Vec<u8> {
        replace_bytes(self, from, to.as_bytes())
    }
}

fn detached_header(encoding: &str, data_file: &str, extra: &[&str]) -> Vec<u8> {
    let mut h = nrrd_header("uint8", SIZES, encoding, extra);
    let _ = writeln!(h, "data file: {data_file}");
    h.into_bytes()
}

fn nhdr_cases(c: &mut Corpus) -> std::io::Result<()> {
    let r = Reader::NrrdDetached;
    let raw = u8s(&gradient());
    let f = |s: &str, b: Vec<u8>| (s.to_string(), Entry::File(b));
    let slices: Vec<Vec<u8>> = raw.chunks(20).map(<[u8]>::to_vec).collect();
    // Valid.
    let valid: Vec<(&str, Vec<(String, Entry)>)> = vec![
        (
            "raw",
            vec![
                f("h.nhdr", detached_header("raw", "d.raw", &[])),
                f("d.raw", raw.clone()),
            ],
        ),
        (
            "gzip",
            vec![
                f("h.nhdr", detached_header("gzip", "d.raw.gz", &[])),
                f("d.raw.gz", gzip(&raw)),
            ],
        ),
        (
            "bzip2",
            vec![
                f("h.nhdr", detached_header("bzip2", "d.raw.bz2", &[])),
                f("d.raw.bz2", bzip2(&raw)),
            ],
        ),
        (
            "ascii",
            vec![
                f("h.nhdr", detached_header("ascii", "d.txt", &[])),
                f("d.txt", ascii_values(&gradient())),
            ],
        ),
        (
            "subdir",
            vec![
                f("h.nhdr", detached_header("raw", "sub/d.raw", &[])),
                f("sub/d.raw", raw.clone()),
            ],
        ),
        (
            "byte_skip_minus1",
            vec![
                f(
                    "h.nhdr",
                    detached_header("raw", "d.raw", &["byte skip: -1"]),
                ),
                f("d.raw", cat(&[b"a header of another program\n", &raw])),
            ],
        ),
        (
            "list",
            vec![
                f(
                    "h.nhdr",
                    detached_header("raw", "LIST", &[])
                        .into_iter()
                        .chain(b"s0.raw\ns1.raw\ns2.raw\n".iter().copied())
                        .collect(),
                ),
                f("s0.raw", slices[0].clone()),
                f("s1.raw", slices[1].clone()),
                f("s2.raw", slices[2].clone()),
            ],
        ),
        (
            "pattern",
            vec![
                f("h.nhdr", detached_header("raw", "s%02d.raw 0 2 1", &[])),
                f("s00.raw", slices[0].clone()),
                f("s01.raw", slices[1].clone()),
                f("s02.raw", slices[2].clone()),
            ],
        ),
        (
            "pattern_descending",
            vec![
                f("h.nhdr", detached_header("raw", "s%d.raw 2 0 -1", &[])),
                f("s2.raw", slices[0].clone()),
                f("s1.raw", slices[1].clone()),
                f("s0.raw", slices[2].clone()),
            ],
        ),
    ];
    for (n, entries) in valid {
        c.add(r, Kind::Valid, &format!("nhdr_{n}"), entries, "h.nhdr")?
            .expect = Expect::Renders;
    }

    // Truncated data files.
    for at in spread(&[0..raw.len()], 6) {
        c.add(
            r,
            Kind::Truncated,
            &format!("nhdr_raw_cut{at}"),
            vec![
                f("h.nhdr", detached_header("raw", "d.raw", &[])),
                f("d.raw", raw[..at].to_vec()),
            ],
            "h.nhdr",
        )?;
    }
    let gz = gzip(&raw);
    for at in spread(&[0..gz.len()], 5) {
        c.add(
            r,
            Kind::Truncated,
            &format!("nhdr_gzip_cut{at}"),
            vec![
                f("h.nhdr", detached_header("gzip", "d.gz", &[])),
                f("d.gz", gz[..at].to_vec()),
            ],
            "h.nhdr",
        )?;
    }
    c.add(
        r,
        Kind::Truncated,
        "nhdr_list_slice_cut",
        vec![
            f(
                "h.nhdr",
                detached_header("raw", "LIST", &[])
                    .into_iter()
                    .chain(b"s0.raw\ns1.raw\ns2.raw\n".iter().copied())
                    .collect(),
            ),
            f("s0.raw", slices[0].clone()),
            f("s1.raw", slices[1][..11].to_vec()),
            f("s2.raw", slices[2].clone()),
        ],
        "h.nhdr",
    )?;
    let hdr = detached_header("raw", "d.raw", &[]);
    for at in spread(&[0..hdr.len() - 1], 4) {
        // A cut header loses its `data file` line (or part of it): nothing names the data.
        c.add(
            r,
            Kind::Truncated,
            &format!("nhdr_header_cut{at}"),
            vec![f("h.nhdr", hdr[..at].to_vec()), f("d.raw", raw.clone())],
            "h.nhdr",
        )?;
    }

    // Lying headers and references.
    let lies: Vec<(&str, Kind, Files)> = vec![
        (
            "missing_data_file",
            Kind::SpecialFile,
            vec![f("h.nhdr", detached_header("raw", "gone.raw", &[]))],
        ),
        (
            "data_file_is_header",
            Kind::LyingHeader,
            vec![f("h.nhdr", detached_header("raw", "h.nhdr", &[]))],
        ),
        (
            "data_file_empty_name",
            Kind::LyingHeader,
            vec![f("h.nhdr", detached_header("raw", "", &[]))],
        ),
        (
            "list_short",
            Kind::LyingHeader,
            vec![
                f(
                    "h.nhdr",
                    detached_header("raw", "LIST", &[])
                        .into_iter()
                        .chain(b"s0.raw\ns1.raw\n".iter().copied())
                        .collect(),
                ),
                f("s0.raw", slices[0].clone()),
                f("s1.raw", slices[1].clone()),
            ],
        ),
        (
            "list_missing_entry",
            Kind::SpecialFile,
            vec![
                f(
                    "h.nhdr",
                    detached_header("raw", "LIST", &[])
                        .into_iter()
                        .chain(b"s0.raw\nnope.raw\ns2.raw\n".iter().copied())
                        .collect(),
                ),
                f("s0.raw", slices[0].clone()),
                f("s2.raw", slices[2].clone()),
            ],
        ),
        (
            "list_subdim_7",
            Kind::OutOfRange,
            vec![
                f(
                    "h.nhdr",
                    detached_header("raw", "LIST 7", &[])
                        .into_iter()
                        .chain(b"s0.raw\n".iter().copied())
                        .collect(),
                ),
                f("s0.raw", raw.clone()),
            ],
        ),
        (
            "list_subdim_0",
            Kind::OutOfRange,
            vec![
                f(
                    "h.nhdr",
                    detached_header("raw", "LIST 0", &[])
                        .into_iter()
                        .chain(b"s0.raw\n".iter().copied())
                        .collect(),
                ),
                f("s0.raw", raw.clone()),
            ],
        ),
        (
            "pattern_too_few_files",
            Kind::OutOfRange,
            vec![
                f("h.nhdr", detached_header("raw", "s%02d.raw 0 5 1", &[])),
                f("s00.raw", slices[0].clone()),
                f("s01.raw", slices[1].clone()),
                f("s02.raw", slices[2].clone()),
            ],
        ),
        (
            "pattern_step_zero",
            Kind::OutOfRange,
            vec![
                f("h.nhdr", detached_header("raw", "s%02d.raw 0 2 0", &[])),
                f("s00.raw", slices[0].clone()),
            ],
        ),
        (
            "pattern_wrong_direction",
            Kind::OutOfRange,
            vec![
                f("h.nhdr", detached_header("raw", "s%02d.raw 0 2 -1", &[])),
                f("s00.raw", slices[0].clone()),
            ],
        ),
        (
            "pattern_huge_max",
            Kind::OutOfRange,
            vec![
                f(
                    "h.nhdr",
                    detached_header("raw", "s%02d.raw 0 9223372036854775807 1", &[]),
                ),
                f("s00.raw", slices[0].clone()),
            ],
        ),
        (
            "pattern_huge_width",
            Kind::LyingHeader,
            vec![
                f(
                    "h.nhdr",
                    detached_header("raw", "s%999999999d.raw 0 2 1", &[]),
                ),
                f("s0.raw", slices[0].clone()),
            ],
        ),
        (
            "pattern_percent_n",
            Kind::LyingHeader,
            vec![f("h.nhdr", detached_header("raw", "s%n%s.raw 0 2 1", &[]))],
        ),
        (
            "byte_skip_1e15",
            Kind::HugeSkip,
            vec![
                f(
                    "h.nhdr",
                    detached_header("raw", "d.raw", &["byte skip: 1000000000000000"]),
                ),
                f("d.raw", raw.clone()),
            ],
        ),
        (
            "line_skip_1e12",
            Kind::HugeSkip,
            vec![
                f(
                    "h.nhdr",
                    detached_header("raw", "d.raw", &["line skip: 1000000000000"]),
                ),
                f("d.raw", raw.clone()),
            ],
        ),
        (
            "gzip_of_garbage",
            Kind::BadStream,
            vec![
                f("h.nhdr", detached_header("gzip", "d.gz", &[])),
                f("d.gz", b"garbage, not gzip".to_vec()),
            ],
        ),
        (
            "sizes_overflow",
            Kind::Overflow,
            vec![
                f(
                    "h.nhdr",
                    detached_header("raw", "d.raw", &[])
                        .replace_first("sizes: 5 4 3", "sizes: 4294967296 4294967296 4294967296"),
                ),
                f("d.raw", raw.clone()),
            ],
        ),
        (
            "data_file_fifo",
            Kind::SpecialFile,
            vec![
                f("h.nhdr", detached_header("raw", "d.raw", &[])),
                ("d.raw".into(), Entry::Fifo),
            ],
        ),
        (
            "data_file_fifo_gzip",
            Kind::SpecialFile,
            vec![
                f("h.nhdr", detached_header("gzip", "d.gz", &[])),
                ("d.gz".into(), Entry::Fifo),
            ],
        ),
        (
            "data_file_devzero",
            Kind::SpecialFile,
            vec![
                f("h.nhdr", detached_header("raw", "d.raw", &[])),
                ("d.raw".into(), Entry::Link("/dev/zero".into())),
            ],
        ),
        (
            "data_file_abs_devzero",
            Kind::SpecialFile,
            vec![f("h.nhdr", detached_header("gzip", "/dev/zero", &[]))],
        ),
        (
            "data_file_dir",
            Kind::SpecialFile,
            vec![
                f("h.nhdr", detached_header("raw", "d.raw", &[])),
                ("d.raw".into(), Entry::Dir),
            ],
        ),
        (
            "list_entry_fifo",
            Kind::SpecialFile,
            vec![
                f(
                    "h.nhdr",
                    detached_header("raw", "LIST", &[])
                        .into_iter()
                        .chain(b"s0.raw\ns1.raw\ns2.raw\n".iter().copied())
                        .collect(),
                ),
                f("s0.raw", slices[0].clone()),
                ("s1.raw".into(), Entry::Fifo),
                f("s2.raw", slices[2].clone()),
            ],
        ),
        (
            "pattern_entry_devzero",
            Kind::SpecialFile,
            vec![
                f("h.nhdr", detached_header("raw", "s%02d.raw 0 2 1", &[])),
                f("s00.raw", slices[0].clone()),
                ("s01.raw".into(), Entry::Link("/dev/zero".into())),
                f("s02.raw", slices[2].clone()),
            ],
        ),
        (
            "data_file_non_utf8",
            Kind::NonUtf8,
            vec![
                f(
                    "h.nhdr",
                    replace_bytes(
                        &detached_header("raw", "d.raw", &[]),
                        "data file: d.raw",
                        b"data file: \xff\xfe.raw",
                    ),
                ),
                f("d.raw", raw.clone()),
            ],
        ),
        (
            "data_file_long_name",
            Kind::LongLine,
            vec![f(
                "h.nhdr",
                detached_header("raw", &"d".repeat(1 << 20), &[]),
            )],
        ),
    ];
    for (n, kind, entries) in lies {
        c.add(r, kind, &format!("nhdr_{n}"), entries, "h.nhdr")?;
    }
    c.special(r, "nhdr_special", "x.nhdr")?;
    Ok(())
}

fn sidecar(dims: &str, ty: &str, extra: &str) -> Vec<u8> {
    format!(
        r#"{{"dims": {dims}, "type": "{ty}", "endian": "little", "spacing": [1, 1, 1]{extra}}}"#
    )
    .into_bytes()
}

fn raw_cases(c: &mut Corpus) -> std::io::Result<()> {
    let r = Reader::RawSidecar;
    let g = gradient();
    let raw = u8s(&g);
    let f = |s: &str, b: Vec<u8>| (s.to_string(), Entry::File(b));
    let pair = |json: Vec<u8>, data: Vec<u8>| vec![f("r.raw", data), f("r.json", json)];
    let be16: Vec<u8> = g.iter().flat_map(|&x| (x as u16).to_be_bytes()).collect();
    let valid: Vec<(&str, Files, Vec<String>)> = vec![
        (
            "u8",
            pair(sidecar("[5, 4, 3]", "u8", ""), raw.clone()),
            vec![],
        ),
        (
            "u16_big",
            pair(
                sidecar("[5, 4, 3]", "u16", "").replace_first("little", "big"),
                be16,
            ),
            vec![],
        ),
        (
            "f32_header_bytes",
            pair(
                sidecar("[5, 4, 3]", "f32", r#", "header_bytes": 16"#),
                cat(&[&[9u8; 16], &f32s_le(&g)]),
            ),
            vec![],
        ),
        (
            "origin",
            pair(
                sidecar("[5, 4, 3]", "u8", r#", "origin": [-3.5, 100, 1e3]"#),
                raw.clone(),
            ),
            vec![],
        ),
        (
            "1x1x1",
            pair(sidecar("[1, 1, 1]", "f32", ""), f32s_le(&[3.0])),
            vec![],
        ),
        (
            "constant",
            pair(sidecar("[5, 4, 3]", "u8", ""), vec![200; 60]),
            vec![],
        ),
        (
            "all_nan",
            pair(sidecar("[5, 4, 3]", "f32", ""), f32s_le(&[f64::NAN; 60])),
            vec!["--iso".into(), "1".into()],
        ),
        (
            "raw_json_name",
            vec![
                f("r.raw", raw.clone()),
                f("r.raw.json", sidecar("[5, 4, 3]", "u8", "")),
            ],
            vec![],
        ),
    ];
    for (n, entries, args) in valid {
        let case = c.add(r, Kind::Valid, &format!("raw_{n}"), entries, "r.raw")?;
        case.expect = Expect::Renders;
        case.render_args = args;
    }
    for at in spread(&[0..raw.len()], 8) {
        c.add(
            r,
            Kind::Truncated,
            &format!("raw_data_cut{at}"),
            pair(sidecar("[5, 4, 3]", "u8", ""), raw[..at].to_vec()),
            "r.raw",
        )?;
    }
    let js = sidecar("[5, 4, 3]", "u8", "");
    for at in spread(&[0..js.len()], 6) {
        c.add(
            r,
            Kind::Truncated,
            &format!("raw_json_cut{at}"),
            pair(js[..at].to_vec(), raw.clone()),
            "r.raw",
        )?;
    }
    let bad: Vec<(&str, Kind, Vec<u8>)> = vec![
        (
            "dims_larger",
            Kind::LyingHeader,
            sidecar("[50, 40, 30]", "u8", ""),
        ),
        (
            "dims_smaller",
            Kind::LyingHeader,
            sidecar("[2, 2, 2]", "u8", ""),
        ),
        (
            "type_larger",
            Kind::LyingHeader,
            sidecar("[5, 4, 3]", "f64", ""),
        ),
        (
            "dims_zero",
            Kind::LyingHeader,
            sidecar("[0, 4, 3]", "u8", ""),
        ),
        ("dims_two", Kind::LyingHeader, sidecar("[5, 4]", "u8", "")),
        (
            "dims_negative",
            Kind::LyingHeader,
            sidecar("[-5, 4, 3]", "u8", ""),
        ),
        (
            "type_unknown",
            Kind::LyingHeader,
            sidecar("[5, 4, 3]", "u128", ""),
        ),
        (
            "endian_unknown",
            Kind::LyingHeader,
            sidecar("[5, 4, 3]", "u8", "").replace_first("little", "middle"),
        ),
        (
            "unknown_key",
            Kind::LyingHeader,
            sidecar("[5, 4, 3]", "u8", r#", "compression": "zstd""#),
        ),
        ("not_json", Kind::LyingHeader, b"dims=5,4,3\n".to_vec()),
        ("empty_json", Kind::LyingHeader, Vec::new()),
        (
            "dims_overflow",
            Kind::Overflow,
            sidecar("[1099511627776, 1099511627776, 1099511627776]", "u8", ""),
        ),
        (
            "dims_times_type",
            Kind::Overflow,
            sidecar("[4611686018427387904, 1, 1]", "f64", ""),
        ),
        (
            "dims_beyond_u64",
            Kind::Overflow,
            sidecar("[18446744073709551616, 1, 1]", "u8", ""),
        ),
        (
            "header_bytes_2pow62",
            Kind::HugeSkip,
            sidecar(
                "[5, 4, 3]",
                "u8",
                r#", "header_bytes": 4611686018427387904"#,
            ),
        ),
        (
            "header_bytes_u64max",
            Kind::HugeSkip,
            sidecar(
                "[5, 4, 3]",
                "u8",
                r#", "header_bytes": 18446744073709551615"#,
            ),
        ),
        (
            "spacing_zero",
            Kind::BadGeometry,
            sidecar("[5, 4, 3]", "u8", "").replace_first("[1, 1, 1]", "[1, 0, 1]"),
        ),
        (
            "spacing_1e400",
            Kind::BadGeometry,
            sidecar("[5, 4, 3]", "u8", "").replace_first("[1, 1, 1]", "[1e400, 1, 1]"),
        ),
        (
            "spacing_1e30",
            Kind::BadGeometry,
            sidecar("[5, 4, 3]", "u8", "").replace_first("[1, 1, 1]", "[1e30, 1, 1]"),
        ),
        (
            "spacing_nan_string",
            Kind::BadGeometry,
            sidecar("[5, 4, 3]", "u8", "").replace_first("[1, 1, 1]", r#"["nan", 1, 1]"#),
        ),
        (
            "origin_3e20",
            Kind::BadGeometry,
            sidecar("[5, 4, 3]", "u8", r#", "origin": [0, 3e20, 0]"#),
        ),
        (
            "non_utf8",
            Kind::NonUtf8,
            replace_bytes(&sidecar("[5, 4, 3]", "u8", ""), "u8", b"u\xff8"),
        ),
        (
            "long_line",
            Kind::LongLine,
            cat(&[b"{", " ".repeat(4 << 20).as_bytes(), b"\"dims\": }"]),
        ),
        (
            "deep_nesting",
            Kind::LongLine,
            format!("{}{}", "[".repeat(100_000), "]".repeat(100_000)).into_bytes(),
        ),
    ];
    for (n, kind, json) in bad {
        c.add(
            r,
            kind,
            &format!("raw_{n}"),
            pair(json, raw.clone()),
            "r.raw",
        )?;
    }
    let specials: Vec<(&str, Vec<(String, Entry)>)> = vec![
        (
            "sidecar_fifo",
            vec![f("r.raw", raw.clone()), ("r.json".into(), Entry::Fifo)],
        ),
        (
            "sidecar_dir",
            vec![f("r.raw", raw.clone()), ("r.json".into(), Entry::Dir)],
        ),
        (
            "sidecar_devzero",
            vec![
                f("r.raw", raw.clone()),
                ("r.json".into(), Entry::Link("/dev/zero".into())),
            ],
        ),
        (
            "data_fifo",
            vec![
                ("r.raw".into(), Entry::Fifo),
                f("r.json", sidecar("[5, 4, 3]", "u8", "")),
            ],
        ),
        (
            "data_devzero",
            vec![
                ("r.raw".into(), Entry::Link("/dev/zero".into())),
                f("r.json", sidecar("[5, 4, 3]", "u8", "")),
            ],
        ),
        (
            "data_dir",
            vec![
                ("r.raw".into(), Entry::Dir),
                f("r.json", sidecar("[5, 4, 3]", "u8", "")),
            ],
        ),
    ];
    for (n, entries) in specials {
        c.add(r, Kind::SpecialFile, &format!("raw_{n}"), entries, "r.raw")?;
    }
    Ok(())
}

fn series_cases(c: &mut Corpus) -> std::io::Result<()> {
    let r = Reader::Series;
    let g = gradient();
    let step = |s: usize| {
        let v: Vec<f64> = g.iter().map(|x| x + s as f64).collect();
        attached("uint8", "raw", &[], &u8s(&v))
    };
    let f = |s: &str, b: Vec<u8>| (s.to_string(), Entry::File(b));
    let three = || {
        vec![
            f("v_000.nrrd", step(0)),
            f("v_001.nrrd", step(1)),
            f("v_002.nrrd", step(2)),
        ]
    };
    c.add(r, Kind::Valid, "series_printf", three(), "v_%03d.nrrd")?
        .expect = Expect::Renders;
    c.add(r, Kind::Valid, "series_glob", three(), "v_*.nrrd")?
        .expect = Expect::Renders;
    let mut v4 = nrrd_header("uint8", "5 4 3 2", "raw", &["spacings: 1 1 1 nan"])
        .into_bytes()
        .replace_first("dimension: 3", "dimension: 4");
    v4.extend_from_slice(b"\n");
    let data4: Vec<u8> = [
        u8s(&g),
        u8s(&g.iter().map(|x| 16.0 - x).collect::<Vec<_>>()),
    ]
    .concat();
    let v4full = cat(&[&v4, &data4]);
    c.one(r, Kind::Valid, "series_4d_nrrd", "v4.nrrd", v4full.clone())?
        .expect = Expect::Renders;
    for at in spread(&[v4.len()..v4full.len()], 4) {
        c.one(
            r,
            Kind::Truncated,
            &format!("series_4d_cut{at}"),
            "v4.nrrd",
            v4full[..at].to_vec(),
        )?;
    }
    c.one(
        r,
        Kind::Overflow,
        "series_4d_sizes_overflow",
        "v4.nrrd",
        cat(&[
            &v4.replace_first("sizes: 5 4 3 2", "sizes: 5 4 3 4611686018427387904"),
            &data4,
        ]),
    )?;

    c.add(
        r,
        Kind::SpecialFile,
        "series_matches_nothing",
        vec![f("other.nrrd", step(0))],
        "v_%03d.nrrd",
    )?;
    c.add(
        r,
        Kind::SpecialFile,
        "series_glob_matches_nothing",
        vec![f("other.nrrd", step(0))],
        "v_*.nrrd",
    )?;
    // Damage in step 0 fails on open; in a later step, when that step is loaded.
    let base = step(1);
    let later: Vec<(&str, Kind, usize, Entry)> = vec![
        (
            "step0_cut",
            Kind::Truncated,
            0,
            Entry::File(step(0)[..70].to_vec()),
        ),
        (
            "step1_cut",
            Kind::Truncated,
            1,
            Entry::File(base[..base.len() - 5].to_vec()),
        ),
        (
            "step1_other_dims",
            Kind::LyingHeader,
            1,
            Entry::File(cat(&[
                nrrd_header("uint8", "4 4 3", "raw", &[]).as_bytes(),
                b"\n",
                &[1u8; 48],
            ])),
        ),
        (
            "step1_other_type",
            Kind::LyingHeader,
            1,
            Entry::File(attached("float", "raw", &[], &f32s_le(&g))),
        ),
        (
            "step1_gzip_garbage",
            Kind::BadStream,
            1,
            Entry::File(attached("uint8", "gzip", &[], b"not gzip")),
        ),
        (
            "step2_spacing_inf",
            Kind::BadGeometry,
            2,
            Entry::File(attached("uint8", "raw", &["spacings: inf 1 1"], &u8s(&g))),
        ),
        (
            "step1_devzero",
            Kind::SpecialFile,
            1,
            Entry::Link("/dev/zero".into()),
        ),
        (
            "step1_link_to_fifo",
            Kind::SpecialFile,
            1,
            Entry::Link("pipe".into()),
        ),
        (
            "step1_non_utf8",
            Kind::NonUtf8,
            1,
            Entry::File(replace_bytes(&base, "type: uint8", b"type: \xffint8")),
        ),
    ];
    for (n, kind, bad, entry) in later {
        let mut entries: Vec<(String, Entry)> = (0..3)
            .filter(|&s| s != bad)
            .map(|s| f(&format!("v_{s:03}.nrrd"), step(s)))
            .collect();
        entries.push((format!("v_{bad:03}.nrrd"), entry));
        if n.ends_with("fifo") {
            entries.push(("pipe".into(), Entry::Fifo));
        }
        let case = c.add(r, kind, &format!("series_{n}"), entries, "v_%03d.nrrd")?;
        if bad > 0 {
            case.bad_step = Some(bad);
        }
    }
    Ok(())
}

// ---- meshes -------------------------------------------------------------------------------

/// The test mesh: 5 points, 2 tets sharing a face, field `f` = x + 2y + 3z.
const PTS: [[f64; 3]; 5] = [
    [0.0, 0.0, 0.0],
    [1.0, 0.0, 0.0],
    [0.0, 1.0, 0.0],
    [0.0, 0.0, 1.0],
    [1.0, 1.0, 1.0],
];
const TETS: [[usize; 4]; 2] = [[0, 1, 2, 3], [1, 2, 3, 4]];

fn field_of(p: &[f64; 3]) -> f64 {
    p[0] + 2.0 * p[1] + 3.0 * p[2]
}

/// A mesh for the writers below.
struct Mesh {
    points: Vec<[f64; 3]>,
    tets: Vec<[usize; 4]>,
    field: Vec<f64>,
}

fn mesh() -> Mesh {
    Mesh {
        points: PTS.to_vec(),
        tets: TETS.to_vec(),
        field: PTS.iter().map(field_of).collect(),
    }
}

fn one_tet() -> Mesh {
    Mesh {
        points: PTS[..4].to_vec(),
        tets: vec![[0, 1, 2, 3]],
        field: PTS[..4].iter().map(field_of).collect(),
    }
}

/// One good tet plus two of zero volume (four coplanar points; a repeated point).
fn degenerate() -> Mesh {
    let mut m = mesh();
    m.points.push([0.5, 0.5, 0.0]);
    m.field.push(field_of(&[0.5, 0.5, 0.0]));
    m.tets = vec![[0, 1, 2, 3], [0, 1, 2, 5], [1, 1, 2, 3]];
    m
}

fn fmt_f(x: f64) -> String {
    if x.is_nan() {
        "nan".into()
    } else {
        format!("{x}")
    }
}

fn vtk_ascii(m: &Mesh, version51: bool) -> Vec<u8> {
    let mut s = String::from(
        "# vtk DataFile Version 4.2\nhostile corpus\nASCII\nDATASET UNSTRUCTURED_GRID\n",
    );
    if version51 {
        s = s.replace("4.2", "5.1");
    }
    let _ = writeln!(s, "POINTS {} double", m.points.len());
    for p in &m.points {
        let _ = writeln!(s, "{} {} {}", p[0], p[1], p[2]);
    }
    if version51 {
        let _ = writeln!(s, "CELLS {} {}", m.tets.len() + 1, 4 * m.tets.len());
        s.push_str("OFFSETS vtktypeint64\n");
        for i in 0..=m.tets.len() {
            let _ = write!(s, "{} ", 4 * i);
        }
        s.push_str("\nCONNECTIVITY vtktypeint64\n");
        for t in &m.tets {
            let _ = writeln!(s, "{} {} {} {}", t[0], t[1], t[2], t[3]);
        }
    } else {
        let _ = writeln!(s, "CELLS {} {}", m.tets.len(), 5 * m.tets.len());
        for t in &m.tets {
            let _ = writeln!(s, "4 {} {} {} {}", t[0], t[1], t[2], t[3]);
        }
    }
    let _ = writeln!(s, "CELL_TYPES {}", m.tets.len());
    for _ in &m.tets {
        s.push_str("10\n");
    }
    let _ = writeln!(
        s,
        "POINT_DATA {}\nSCALARS f double 1\nLOOKUP_TABLE default",
        m.points.len()
    );
    for v in &m.field {
        let _ = writeln!(s, "{}", fmt_f(*v));
    }
    s.into_bytes()
}

fn vtk_binary(m: &Mesh) -> Vec<u8> {
    let mut b = format!(
        "# vtk DataFile Version 4.2\nhostile corpus\nBINARY\nDATASET UNSTRUCTURED_GRID\nPOINTS {} double\n",
        m.points.len()
    )
    .into_bytes();
    for p in &m.points {
        for x in p {
            b.extend(x.to_be_bytes());
        }
    }
    b.extend(format!("\nCELLS {} {}\n", m.tets.len(), 5 * m.tets.len()).bytes());
    for t in &m.tets {
        b.extend(4i32.to_be_bytes());
        for &i in t {
            b.extend((i as i32).to_be_bytes());
        }
    }
    b.extend(format!("\nCELL_TYPES {}\n", m.tets.len()).bytes());
    for _ in &m.tets {
        b.extend(10i32.to_be_bytes());
    }
    b.extend(
        format!(
            "\nPOINT_DATA {}\nSCALARS f float 1\nLOOKUP_TABLE default\n",
            m.points.len()
        )
        .bytes(),
    );
    for v in &m.field {
        b.extend((*v as f32).to_be_bytes());
    }
    b.push(b'\n');
    b
}

fn vtk_cases(c: &mut Corpus) -> std::io::Result<()> {
    let r = Reader::VtkLegacy;
    let m = mesh();
    c.valid(r, "vtk_ascii", "m.vtk", vtk_ascii(&m, false))?;
    c.valid(r, "vtk_ascii_51", "m.vtk", vtk_ascii(&m, true))?;
    c.valid(r, "vtk_binary", "m.vtk", vtk_binary(&m))?;
    c.valid(r, "vtk_one_tet", "m.vtk", vtk_ascii(&one_tet(), false))?;
    c.valid(
        r,
        "vtk_degenerate",
        "m.vtk",
        vtk_ascii(&degenerate(), false),
    )?;
    let mut constant = mesh();
    constant.field = vec![2.5; 5];
    c.valid(r, "vtk_constant", "m.vtk", vtk_ascii(&constant, false))?;
    let mut nan = mesh();
    nan.field = vec![f64::NAN; 5];
    c.valid(r, "vtk_all_nan", "m.vtk", vtk_ascii(&nan, false))?
        .render_args = vec!["--iso".into(), "1".into()];

    // Cuts inside the declared blocks: the points, the cells, the cell types, the values.
    let a = vtk_ascii(&m, false);
    let regions = [
        0..find(&a, "\n").start,
        text_block(&a, "double\n", "CELLS"),
        text_block(&a, "CELLS 2 10\n", "CELL_TYPES"),
        text_block(&a, "CELL_TYPES 2\n", "POINT_DATA"),
        find(&a, "LOOKUP_TABLE default\n").end..last_token_start(&a, a.len()),
    ];
    c.truncations(r, "vtk_ascii", "m.vtk", &a, &regions, 16)?;
    let b = vtk_binary(&m);
    let pts = find(&b, "double\n").end;
    let cells = find(&b, "CELLS 2 10\n").end;
    let types = find(&b, "CELL_TYPES 2\n").end;
    let vals = find(&b, "LOOKUP_TABLE default\n").end;
    let regions = [
        pts..pts + 120,
        cells..cells + 40,
        types..types + 8,
        vals..vals + 20,
    ];
    c.truncations(r, "vtk_binary", "m.vtk", &b, &regions, 12)?;

    let bad: Vec<(&str, Kind, Vec<u8>)> = vec![
        (
            "points_more",
            Kind::LyingHeader,
            a.replace_first("POINTS 5", "POINTS 50"),
        ),
        (
            "cells_more",
            Kind::LyingHeader,
            a.replace_first("CELLS 2 10", "CELLS 3 15"),
        ),
        (
            "cells_size_wrong",
            Kind::LyingHeader,
            a.replace_first("CELLS 2 10", "CELLS 2 12"),
        ),
        (
            "cell_types_fewer",
            Kind::LyingHeader,
            a.replace_first("CELL_TYPES 2\n10\n", "CELL_TYPES 1\n10\n"),
        ),
        (
            "point_data_more",
            Kind::LyingHeader,
            a.replace_first("POINT_DATA 5", "POINT_DATA 6"),
        ),
        (
            "dataset_polydata",
            Kind::LyingHeader,
            a.replace_first("UNSTRUCTURED_GRID", "POLYDATA"),
        ),
        (
            "encoding_unknown",
            Kind::LyingHeader,
            a.replace_first("ASCII", "EBCDIC"),
        ),
        (
            "version_line_missing",
            Kind::LyingHeader,
            a.replace_first("# vtk DataFile Version 4.2\n", ""),
        ),
        (
            "binary_says_ascii",
            Kind::LyingHeader,
            b.replace_first("BINARY", "ASCII"),
        ),
        (
            "binary_points_more",
            Kind::LyingHeader,
            b.replace_first("POINTS 5", "POINTS 9"),
        ),
        (
            "points_overflow",
            Kind::Overflow,
            a.replace_first("POINTS 5", "POINTS 10000000000000000000"),
        ),
        (
            "points_i64max",
            Kind::Overflow,
            b.replace_first("POINTS 5", "POINTS 9223372036854775807"),
        ),
        (
            "cells_overflow",
            Kind::Overflow,
            a.replace_first(
                "CELLS 2 10",
                "CELLS 4611686018427387904 4611686018427387904",
            ),
        ),
        (
            "cells_51_offsets_huge",
            Kind::Overflow,
            vtk_ascii(&m, true).replace_first("CELLS 3 8", "CELLS 18446744073709551615 8"),
        ),
        (
            "index_out_of_range",
            Kind::OutOfRange,
            a.replace_first("4 1 2 3 4", "4 1 2 3 5"),
        ),
        (
            "index_negative",
            Kind::OutOfRange,
            a.replace_first("4 1 2 3 4", "4 1 2 3 -1"),
        ),
        (
            "index_i64min",
            Kind::OutOfRange,
            a.replace_first("4 1 2 3 4", "4 1 2 3 -9223372036854775808"),
        ),
        (
            "cell_count_negative",
            Kind::OutOfRange,
            a.replace_first("4 0 1 2 3", "-4 0 1 2 3"),
        ),
        (
            "offsets_51_decreasing",
            Kind::OutOfRange,
            vtk_ascii(&m, true).replace_first("0 4 8", "0 8 4"),
        ),
        (
            "offsets_51_past_end",
            Kind::OutOfRange,
            vtk_ascii(&m, true).replace_first("0 4 8", "0 4 80"),
        ),
        ("binary_index_huge", Kind::OutOfRange, {
            let mut x = b.clone();
            let at = cells + 4;
            x[at..at + 4].copy_from_slice(&0x7fff_ffffi32.to_be_bytes());
            x
        }),
        (
            "cell_type_unknown",
            Kind::OutOfRange,
            a.replace_first("CELL_TYPES 2\n10\n10", "CELL_TYPES 2\n99999\n99999"),
        ),
        (
            "points_nan",
            Kind::BadGeometry,
            a.replace_first("\n1 1 1\n", "\nnan 1 1\n"),
        ),
        (
            "points_inf",
            Kind::BadGeometry,
            a.replace_first("\n1 1 1\n", "\n1 inf 1\n"),
        ),
        (
            "points_1e30",
            Kind::BadGeometry,
            a.replace_first("\n1 1 1\n", "\n1 1 1e30\n"),
        ),
        (
            "utf8_keyword",
            Kind::NonUtf8,
            replace_bytes(
                &a,
                "DATASET UNSTRUCTURED_GRID",
                b"DATASET \xffUNSTRUCTURED_GRID",
            ),
        ),
        (
            "utf8_number",
            Kind::NonUtf8,
            replace_bytes(&a, "POINTS 5", b"POINTS \xc35"),
        ),
        (
            "long_keyword_line",
            Kind::LongLine,
            replace_bytes(
                &a,
                "DATASET UNSTRUCTURED_GRID",
                format!("DATASET {}", "U".repeat(4 << 20)).as_bytes(),
            ),
        ),
        (
            "long_number",
            Kind::LongLine,
            replace_bytes(
                &a,
                "POINTS 5",
                format!("POINTS {}", "5".repeat(1 << 20)).as_bytes(),
            ),
        ),
        ("empty_file", Kind::Truncated, Vec::new()),
    ];
    for (n, kind, bytes) in bad {
        c.one(r, kind, &format!("vtk_{n}"), "m.vtk", bytes)?;
    }
    c.special(r, "vtk_special", "x.vtk")?;
    Ok(())
}

/// How a VTU's arrays are stored.
#[derive(Clone, Copy, PartialEq)]
enum VtuEnc {
    Ascii,
    /// Inline base64; `true`: UInt64 block headers.
    Binary(bool),
    AppendedRaw,
    AppendedBase64,
    /// zlib blocks, inline base64.
    Zlib,
    /// zlib blocks, appended raw.
    ZlibAppended,
}

/// A VTU of `m` (Float64 points, Int64 connectivity/offsets, UInt8 types, Float32 `f`).
fn vtu(m: &Mesh, enc: VtuEnc) -> Vec<u8> {
    let arrays: Vec<(&str, &str, usize, Vec<u8>, String)> = vec![
        (
            "Float64",
            "",
            3,
            m.points
                .iter()
                .flatten()
                .flat_map(|x| x.to_le_bytes())
                .collect(),
            m.points
                .iter()
                .flatten()
                .map(|x| fmt_f(*x))
                .collect::<Vec<_>>()
                .join(" "),
        ),
        (
            "Int64",
            "connectivity",
            1,
            m.tets
                .iter()
                .flatten()
                .flat_map(|&i| (i as i64).to_le_bytes())
                .collect(),
            m.tets
                .iter()
                .flatten()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join(" "),
        ),
        (
            "Int64",
            "offsets",
            1,
            (1..=m.tets.len())
                .flat_map(|i| (4 * i as i64).to_le_bytes())
                .collect(),
            (1..=m.tets.len())
                .map(|i| (4 * i).to_string())
                .collect::<Vec<_>>()
                .join(" "),
        ),
        (
            "UInt8",
            "types",
            1,
            vec![10u8; m.tets.len()],
            vec!["10"; m.tets.len()].join(" "),
        ),
        (
            "Float32",
            "f",
            1,
            m.field
                .iter()
                .flat_map(|&x| (x as f32).to_le_bytes())
                .collect(),
            m.field
                .iter()
                .map(|x| fmt_f(*x))
                .collect::<Vec<_>>()
                .join(" "),
        ),
    ];
    let u64h = matches!(
        enc,
        VtuEnc::Binary(true) | VtuEnc::Zlib | VtuEnc::ZlibAppended
    );
    let header = |n: usize| -> Vec<u8> {
        if u64h {
            (n as u64).to_le_bytes().to_vec()
        } else {
            (n as u32).to_le_bytes().to_vec()
        }
    };
    let mut appended = Vec::new();
    let mut tags = Vec::new();
    for (ty, name, comps, bytes, text) in &arrays {
        let name_attr = if name.is_empty() {
            String::new()
        } else {
            format!(" Name=\"{name}\"")
        };
        let comps_attr = if *comps > 1 {
            format!(" NumberOfComponents=\"{comps}\"")
        } else {
            String::new()
        };
        let open = format!("<DataArray type=\"{ty}\"{name_attr}{comps_attr}");
        let block = match enc {
            VtuEnc::Zlib | VtuEnc::ZlibAppended => {
                let z = zlib(bytes);
                let mut h = Vec::new();
                for w in [1, bytes.len(), bytes.len(), z.len()] {
                    h.extend(header(w));
                }
                (h, z)
            }
            _ => (header(bytes.len()), bytes.clone()),
        };
        tags.push(match enc {
            VtuEnc::Ascii => format!("{open} format=\"ascii\">{text}</DataArray>"),
            VtuEnc::Binary(_) => format!(
                "{open} format=\"binary\">{}</DataArray>",
                b64(&cat(&[&block.0, &block.1]))
            ),
            VtuEnc::Zlib => format!(
                "{open} format=\"binary\">{}{}</DataArray>",
                b64(&block.0),
                b64(&block.1)
            ),
            VtuEnc::AppendedRaw | VtuEnc::ZlibAppended => {
                let t = format!("{open} format=\"appended\" offset=\"{}\"/>", appended.len());
                appended.extend(cat(&[&block.0, &block.1]));
                t
            }
            VtuEnc::AppendedBase64 => {
                let t = format!("{open} format=\"appended\" offset=\"{}\"/>", appended.len());
                appended.extend(b64(&cat(&[&block.0, &block.1])).bytes());
                t
            }
        });
    }
    let attrs = match enc {
        VtuEnc::Zlib | VtuEnc::ZlibAppended => {
            " header_type=\"UInt64\" compressor=\"vtkZLibDataCompressor\""
        }
        VtuEnc::Binary(true) => " header_type=\"UInt64\"",
        _ => "",
    };
    let mut s = format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\"{attrs}>\n<UnstructuredGrid>\n<Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">\n<PointData Scalars=\"f\">\n{}\n</PointData>\n<Points>\n{}\n</Points>\n<Cells>\n{}\n{}\n{}\n</Cells>\n</Piece>\n</UnstructuredGrid>\n",
        m.points.len(), m.tets.len(), tags[4], tags[0], tags[1], tags[2], tags[3]
    )
    .into_bytes();
    if !appended.is_empty() {
        let enc_name = if enc == VtuEnc::AppendedBase64 {
            "base64"
        } else {
            "raw"
        };
        s.extend(format!("<AppendedData encoding=\"{enc_name}\">\n_").bytes());
        s.extend(&appended);
        s.extend(b"\n</AppendedData>\n");
    }
    s.extend(b"</VTKFile>\n");
    s
}

fn vtu_cases(c: &mut Corpus) -> std::io::Result<()> {
    let r = Reader::Vtu;
    let m = mesh();
    let encs = [
        ("ascii", VtuEnc::Ascii),
        ("binary32", VtuEnc::Binary(false)),
        ("binary64", VtuEnc::Binary(true)),
        ("appended_raw", VtuEnc::AppendedRaw),
        ("appended_b64", VtuEnc::AppendedBase64),
        ("zlib", VtuEnc::Zlib),
        ("zlib_appended", VtuEnc::ZlibAppended),
    ];
    for (n, e) in encs {
        c.valid(r, &format!("vtu_{n}"), "m.vtu", vtu(&m, e))?;
    }
    c.valid(r, "vtu_one_tet", "m.vtu", vtu(&one_tet(), VtuEnc::Ascii))?;
    c.valid(
        r,
        "vtu_degenerate",
        "m.vtu",
        vtu(&degenerate(), VtuEnc::Binary(false)),
    )?;
    let mut nan = mesh();
    nan.field = vec![f64::NAN; 5];
    c.valid(r, "vtu_all_nan", "m.vtu", vtu(&nan, VtuEnc::AppendedRaw))?
        .render_args = vec!["--iso".into(), "1".into()];

    // Cuts before the end of the last array's data: the XML is unclosed or an array short.
    for (n, e) in encs {
        let doc = vtu(&m, e);
        let end = match e {
            VtuEnc::AppendedRaw | VtuEnc::AppendedBase64 | VtuEnc::ZlibAppended => {
                find(&doc, "\n</AppendedData>").start
            }
            _ => find(&doc, "</Cells>").start,
        };
        c.truncations(
            r,
            &format!("vtu_{n}"),
            "m.vtu",
            &doc,
            &[0..end],
            if e == VtuEnc::Ascii { 8 } else { 5 },
        )?;
    }
    let a = vtu(&m, VtuEnc::Ascii);
    let b = vtu(&m, VtuEnc::Binary(false));
    let z = vtu(&m, VtuEnc::Zlib);
    let ap = vtu(&m, VtuEnc::AppendedRaw);
    let bad: Vec<(&str, Kind, Vec<u8>)> = vec![
        (
            "points_more",
            Kind::LyingHeader,
            a.replace_first("NumberOfPoints=\"5\"", "NumberOfPoints=\"50\""),
        ),
        (
            "cells_more",
            Kind::LyingHeader,
            a.replace_first("NumberOfCells=\"2\"", "NumberOfCells=\"3\""),
        ),
        (
            "binary_points_more",
            Kind::LyingHeader,
            b.replace_first("NumberOfPoints=\"5\"", "NumberOfPoints=\"7\""),
        ),
        (
            "zlib_points_more",
            Kind::LyingHeader,
            z.replace_first("NumberOfPoints=\"5\"", "NumberOfPoints=\"7\""),
        ),
        (
            "type_not_unstructured",
            Kind::LyingHeader,
            a.replace_first("type=\"UnstructuredGrid\"", "type=\"ImageData\""),
        ),
        (
            "datatype_unknown",
            Kind::LyingHeader,
            a.replace_first("type=\"Float64\"", "type=\"Float128\""),
        ),
        (
            "format_unknown",
            Kind::LyingHeader,
            a.replace_first("format=\"ascii\"", "format=\"octal\""),
        ),
        ("no_points", Kind::LyingHeader, {
            let s = find(&a, "<Points>").start;
            let e = find(&a, "</Points>").end;
            cat(&[&a[..s], &a[e..]])
        }),
        (
            "appended_offset_past_end",
            Kind::OutOfRange,
            ap.replace_first("offset=\"0\"", "offset=\"100000\""),
        ),
        (
            "appended_offset_huge",
            Kind::Overflow,
            ap.replace_first("offset=\"0\"", "offset=\"18446744073709551615\""),
        ),
        (
            "points_overflow",
            Kind::Overflow,
            b.replace_first(
                "NumberOfPoints=\"5\"",
                "NumberOfPoints=\"6148914691236517206\"",
            ),
        ),
        (
            "zlib_points_1e11",
            Kind::Overflow,
            z.replace_first("NumberOfPoints=\"5\"", "NumberOfPoints=\"100000000000\""),
        ),
        (
            "points_not_number",
            Kind::LyingHeader,
            a.replace_first("NumberOfPoints=\"5\"", "NumberOfPoints=\"five\""),
        ),
        (
            "index_out_of_range",
            Kind::OutOfRange,
            a.replace_first("1 2 3 4<", "1 2 3 5<"),
        ),
        (
            "index_negative",
            Kind::OutOfRange,
            a.replace_first("1 2 3 4<", "1 2 3 -4<"),
        ),
        (
            "offsets_decreasing",
            Kind::OutOfRange,
            a.replace_first(">4 8<", ">8 4<"),
        ),
        (
            "offsets_past_end",
            Kind::OutOfRange,
            a.replace_first(">4 8<", ">4 80<"),
        ),
        (
            "binary_bad_base64",
            Kind::BadStream,
            b.replace_first("format=\"binary\">", "format=\"binary\">!!!*"),
        ),
        ("binary_block_header_lies", Kind::LyingHeader, {
            // The Points block claims 4000 bytes (UInt32 header 0xa00f0000 = "oA8AAA" in base64).
            let pts = find(&b, "NumberOfComponents=\"3\" format=\"binary\">").end;
            cat(&[&b[..pts], b"oA8AAA", &b[pts + 6..]])
        }),
        ("zlib_garbage", Kind::BadStream, {
            let zz = vtu(&m, VtuEnc::ZlibAppended);
            let at = find(&zz, "\n_").end + 32;
            let mut x = zz.clone();
            for v in &mut x[at..at + 8] {
                *v ^= 0xa5;
            }
            x
        }),
        ("zlib_bomb", Kind::BadStream, {
            // Points block: 120 bytes declared, the stream inflates to 64 MiB.
            let big = zlib(&vec![0u8; 64 << 20]);
            let mut h = Vec::new();
            for w in [1u64, 120, 120, big.len() as u64] {
                h.extend(w.to_le_bytes());
            }
            let s = find(&z, "NumberOfComponents=\"3\" format=\"binary\">").end;
            let e = s + find(&z[s..], "</DataArray>").start;
            cat(&[&z[..s], b64(&h).as_bytes(), b64(&big).as_bytes(), &z[e..]])
        }),
        (
            "compressor_unknown",
            Kind::BadStream,
            z.replace_first("vtkZLibDataCompressor", "vtkLZMADataCompressor"),
        ),
        (
            "points_nan",
            Kind::BadGeometry,
            a.replace_first(">0 0 0 1", ">nan 0 0 1"),
        ),
        (
            "points_1e30",
            Kind::BadGeometry,
            a.replace_first(">0 0 0 1", ">1e30 0 0 1"),
        ),
        (
            "utf8_attribute",
            Kind::NonUtf8,
            replace_bytes(&a, "NumberOfPoints=\"5\"", b"NumberOfPoints=\"\xff5\""),
        ),
        (
            "utf8_text",
            Kind::NonUtf8,
            replace_bytes(&a, ">0 0 0 1", b">0 \xfe\xff 0 1"),
        ),
        (
            "long_attribute",
            Kind::LongLine,
            replace_bytes(
                &a,
                "NumberOfPoints=\"5\"",
                format!("NumberOfPoints=\"{}\"", "5".repeat(1 << 20)).as_bytes(),
            ),
        ),
        (
            "long_text",
            Kind::LongLine,
            replace_bytes(
                &a,
                ">0 0 0 1",
                format!(">0 {} 0 1", "x".repeat(4 << 20)).as_bytes(),
            ),
        ),
        ("not_xml", Kind::LyingHeader, b"this is not XML\n".to_vec()),
        ("empty_file", Kind::Truncated, Vec::new()),
    ];
    for (n, kind, bytes) in bad {
        c.one(r, kind, &format!("vtu_{n}"), "m.vtu", bytes)?;
    }
    c.special(r, "vtu_special", "x.vtu")?;
    Ok(())
}

fn pvd(files: &[&str]) -> Vec<u8> {
    let mut s = String::from(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\">\n<Collection>\n",
    );
    for (i, f) in files.iter().enumerate() {
        let _ = writeln!(
            s,
            "<DataSet timestep=\"{}\" part=\"0\" file=\"{f}\"/>",
            i as f64 * 0.5
        );
    }
    s.push_str("</Collection>\n</VTKFile>\n");
    s.into_bytes()
}

fn pvd_cases(c: &mut Corpus) -> std::io::Result<()> {
    let r = Reader::Pvd;
    let f = |s: &str, b: Vec<u8>| (s.to_string(), Entry::File(b));
    let step = |s: usize| {
        let mut m = mesh();
        m.field = m.field.iter().map(|x| x + s as f64).collect();
        vtu(&m, VtuEnc::Ascii)
    };
    let steps = || vec![f("s_0.vtu", step(0)), f("s_1.vtu", step(1))];
    let with = |pvd_bytes: Vec<u8>, mut rest: Vec<(String, Entry)>| {
        rest.insert(0, ("c.pvd".into(), Entry::File(pvd_bytes)));
        rest
    };
    c.add(
        r,
        Kind::Valid,
        "pvd_two_steps",
        with(pvd(&["s_0.vtu", "s_1.vtu"]), steps()),
        "c.pvd",
    )?
    .expect = Expect::Renders;
    c.add(
        r,
        Kind::Valid,
        "pvd_nested_once",
        vec![
            f("c.pvd", pvd(&["inner.pvd"])),
            f("inner.pvd", pvd(&["s_0.vtu"])),
            f("s_0.vtu", step(0)),
        ],
        "c.pvd",
    )?
    .expect = Expect::Renders;
    c.add(
        r,
        Kind::Valid,
        "pvd_legacy_step",
        vec![
            f("c.pvd", pvd(&["m.vtk"])),
            f("m.vtk", vtk_ascii(&mesh(), false)),
        ],
        "c.pvd",
    )?
    .expect = Expect::Renders;

    let p = pvd(&["s_0.vtu", "s_1.vtu"]);
    let end = find(&p, "file=\"s_0.vtu\"/>").end - 3;
    c.truncations(r, "pvd", "c.pvd", &p, &[0..end], 8)?;

    let cycles: Vec<(&str, Vec<(String, Entry)>)> = vec![
        ("self", vec![f("c.pvd", pvd(&["c.pvd"]))]),
        ("self_dot_slash", vec![f("c.pvd", pvd(&["./c.pvd"]))]),
        (
            "mutual",
            vec![f("c.pvd", pvd(&["b.pvd"])), f("b.pvd", pvd(&["c.pvd"]))],
        ),
        (
            "three",
            vec![
                f("c.pvd", pvd(&["b.pvd"])),
                f("b.pvd", pvd(&["d.pvd"])),
                f("d.pvd", pvd(&["c.pvd"])),
            ],
        ),
        (
            "self_second_step",
            vec![
                f("c.pvd", pvd(&["s_0.vtu", "c.pvd"])),
                f("s_0.vtu", step(0)),
            ],
        ),
        (
            "via_symlink",
            vec![
                f("c.pvd", pvd(&["l.pvd"])),
                ("l.pvd".into(), Entry::Link("c.pvd".into())),
            ],
        ),
        (
            "deep_20",
            (0..20)
                .map(|i| f(&format!("n{i}.pvd"), pvd(&[&format!("n{}.pvd", i + 1)])))
                .chain([
                    f("n20.pvd", pvd(&["s_0.vtu"])),
                    f("s_0.vtu", step(0)),
                    f("c.pvd", pvd(&["n0.pvd"])),
                ])
                .collect(),
        ),
    ];
    for (n, entries) in cycles {
        let case = c.add(r, Kind::Cycle, &format!("pvd_cycle_{n}"), entries, "c.pvd")?;
        if n == "self_second_step" {
            case.bad_step = Some(1);
        }
    }
    let bad: Vec<(&str, Kind, Files, Option<usize>)> = vec![
        (
            "no_datasets",
            Kind::LyingHeader,
            vec![f("c.pvd", pvd(&[]))],
            None,
        ),
        (
            "not_collection",
            Kind::LyingHeader,
            vec![
                f(
                    "c.pvd",
                    pvd(&["s_0.vtu"]).replace_first("Collection\"", "UnstructuredGrid\""),
                ),
                f("s_0.vtu", step(0)),
            ],
            None,
        ),
        (
            "no_file_attribute",
            Kind::LyingHeader,
            vec![
                f(
                    "c.pvd",
                    pvd(&["s_0.vtu"]).replace_first(" file=\"s_0.vtu\"", ""),
                ),
                f("s_0.vtu", step(0)),
            ],
            None,
        ),
        (
            "timestep_nan",
            Kind::LyingHeader,
            vec![
                f(
                    "c.pvd",
                    pvd(&["s_0.vtu"]).replace_first("timestep=\"0\"", "timestep=\"nan\""),
                ),
                f("s_0.vtu", step(0)),
            ],
            None,
        ),
        (
            "timestep_text",
            Kind::LyingHeader,
            vec![
                f(
                    "c.pvd",
                    pvd(&["s_0.vtu"]).replace_first("timestep=\"0\"", "timestep=\"soon\""),
                ),
                f("s_0.vtu", step(0)),
            ],
            None,
        ),
        (
            "step0_missing",
            Kind::SpecialFile,
            vec![f("c.pvd", pvd(&["gone.vtu"]))],
            None,
        ),
        (
            "step1_missing",
            Kind::SpecialFile,
            with(pvd(&["s_0.vtu", "gone.vtu"]), vec![f("s_0.vtu", step(0))]),
            Some(1),
        ),
        (
            "step0_truncated",
            Kind::Truncated,
            with(
                pvd(&["s_0.vtu", "s_1.vtu"]),
                vec![f("s_0.vtu", step(0)[..200].to_vec()), f("s_1.vtu", step(1))],
            ),
            None,
        ),
        (
            "step1_truncated",
            Kind::Truncated,
            with(
                pvd(&["s_0.vtu", "s_1.vtu"]),
                vec![f("s_0.vtu", step(0)), f("s_1.vtu", step(1)[..300].to_vec())],
            ),
            Some(1),
        ),
        (
            "step1_index_out_of_range",
            Kind::OutOfRange,
            with(
                pvd(&["s_0.vtu", "s_1.vtu"]),
                vec![
                    f("s_0.vtu", step(0)),
                    f("s_1.vtu", step(1).replace_first("1 2 3 4<", "1 2 3 9<")),
                ],
            ),
            Some(1),
        ),
        (
            "step0_devzero",
            Kind::SpecialFile,
            vec![
                f("c.pvd", pvd(&["z.vtu"])),
                ("z.vtu".into(), Entry::Link("/dev/zero".into())),
            ],
            None,
        ),
        (
            "step1_devzero",
            Kind::SpecialFile,
            with(
                pvd(&["s_0.vtu", "z.vtu"]),
                vec![
                    f("s_0.vtu", step(0)),
                    ("z.vtu".into(), Entry::Link("/dev/zero".into())),
                ],
            ),
            Some(1),
        ),
        (
            "step1_fifo",
            Kind::SpecialFile,
            with(
                pvd(&["s_0.vtu", "p.vtu"]),
                vec![f("s_0.vtu", step(0)), ("p.vtu".into(), Entry::Fifo)],
            ),
            Some(1),
        ),
        (
            "step0_dir",
            Kind::SpecialFile,
            vec![f("c.pvd", pvd(&["d.vtu"])), ("d.vtu".into(), Entry::Dir)],
            None,
        ),
        (
            "step_abs_devzero",
            Kind::SpecialFile,
            vec![f("c.pvd", pvd(&["/dev/zero"]))],
            None,
        ),
        (
            "step_non_utf8",
            Kind::NonUtf8,
            vec![
                f(
                    "c.pvd",
                    replace_bytes(&pvd(&["s_0.vtu"]), "s_0.vtu", b"s_\xff.vtu"),
                ),
                f("s_0.vtu", step(0)),
            ],
            None,
        ),
        (
            "long_file_name",
            Kind::LongLine,
            vec![f("c.pvd", pvd(&[&"s".repeat(1 << 20)]))],
            None,
        ),
    ];
    for (n, kind, entries, bad_step) in bad {
        c.add(r, kind, &format!("pvd_{n}"), entries, "c.pvd")?
            .bad_step = bad_step;
    }
    c.special(r, "pvd_special", "x.pvd")?;
    Ok(())
}

/// Gmsh ASCII (`v4`: MSH 4.1, else 2.2), with `$NodeData` "f". Node tags are 1-based.
fn msh_ascii(m: &Mesh, v4: bool) -> Vec<u8> {
    let n = m.points.len();
    let mut s = format!(
        "$MeshFormat\n{} 0 8\n$EndMeshFormat\n$Nodes\n",
        if v4 { "4.1" } else { "2.2" }
    );
    if v4 {
        let _ = writeln!(s, "1 {n} 1 {n}\n3 1 0 {n}");
        for i in 1..=n {
            let _ = writeln!(s, "{i}");
        }
        for p in &m.points {
            let _ = writeln!(s, "{} {} {}", p[0], p[1], p[2]);
        }
    } else {
        let _ = writeln!(s, "{n}");
        for (i, p) in m.points.iter().enumerate() {
            let _ = writeln!(s, "{} {} {} {}", i + 1, p[0], p[1], p[2]);
        }
    }
    s.push_str("$EndNodes\n$Elements\n");
    let k = m.tets.len();
    if v4 {
        let _ = writeln!(s, "1 {k} 1 {k}\n3 1 4 {k}");
        for (e, t) in m.tets.iter().enumerate() {
            let _ = writeln!(
                s,
                "{} {} {} {} {}",
                e + 1,
                t[0] + 1,
                t[1] + 1,
                t[2] + 1,
                t[3] + 1
            );
        }
    } else {
        let _ = writeln!(s, "{k}");
        for (e, t) in m.tets.iter().enumerate() {
            let _ = writeln!(
                s,
                "{} 4 2 0 1 {} {} {} {}",
                e + 1,
                t[0] + 1,
                t[1] + 1,
                t[2] + 1,
                t[3] + 1
            );
        }
    }
    let _ = writeln!(s, "$EndElements\n$NodeData\n1\n\"f\"\n1\n0.0\n3\n0\n1\n{n}");
    for (i, v) in m.field.iter().enumerate() {
        let _ = writeln!(s, "{} {}", i + 1, fmt_f(*v));
    }
    s.push_str("$EndNodeData\n");
    s.into_bytes()
}

/// Gmsh binary (little-endian, size_t 8).
fn msh_binary(m: &Mesh, v4: bool) -> Vec<u8> {
    let n = m.points.len();
    let k = m.tets.len();
    let mut b = format!("$MeshFormat\n{} 1 8\n", if v4 { "4.1" } else { "2.2" }).into_bytes();
    b.extend(1i32.to_le_bytes());
    b.extend(b"\n$EndMeshFormat\n$Nodes\n");
    let sz = |b: &mut Vec<u8>, x: usize| b.extend((x as u64).to_le_bytes());
    let int = |b: &mut Vec<u8>, x: i32| b.extend(x.to_le_bytes());
    if v4 {
        for x in [1, n, 1, n] {
            sz(&mut b, x);
        }
        int(&mut b, 3);
        int(&mut b, 1);
        int(&mut b, 0);
        sz(&mut b, n);
        for i in 1..=n {
            sz(&mut b, i);
        }
        for p in &m.points {
            for x in p {
                b.extend(x.to_le_bytes());
            }
        }
    } else {
        b.extend(format!("{n}\n").bytes());
        for (i, p) in m.points.iter().enumerate() {
            int(&mut b, i as i32 + 1);
            for x in p {
                b.extend(x.to_le_bytes());
            }
        }
    }
    b.extend(b"\n$EndNodes\n$Elements\n");
    if v4 {
        for x in [1, k, 1, k] {
            sz(&mut b, x);
        }
        int(&mut b, 3);
        int(&mut b, 1);
        int(&mut b, 4);
        sz(&mut b, k);
        for (e, t) in m.tets.iter().enumerate() {
            sz(&mut b, e + 1);
            for &i in t {
                sz(&mut b, i + 1);
            }
        }
    } else {
        b.extend(format!("{k}\n").bytes());
        int(&mut b, 4);
        int(&mut b, k as i32);
        int(&mut b, 2);
        for (e, t) in m.tets.iter().enumerate() {
            int(&mut b, e as i32 + 1);
            int(&mut b, 0);
            int(&mut b, 1);
            for &i in t {
                int(&mut b, i as i32 + 1);
            }
        }
    }
    b.extend(format!("\n$EndElements\n$NodeData\n1\n\"f\"\n1\n0.0\n3\n0\n1\n{n}\n").bytes());
    for (i, v) in m.field.iter().enumerate() {
        int(&mut b, i as i32 + 1);
        b.extend(v.to_le_bytes());
    }
    b.extend(b"\n$EndNodeData\n");
    b
}

fn gmsh_cases(c: &mut Corpus, v4: bool) -> std::io::Result<()> {
    let r = if v4 { Reader::Gmsh41 } else { Reader::Gmsh22 };
    let v = if v4 { "msh41" } else { "msh22" };
    let m = mesh();
    let a = msh_ascii(&m, v4);
    let b = msh_binary(&m, v4);
    c.valid(r, &format!("{v}_ascii"), "m.msh", a.clone())?;
    c.valid(r, &format!("{v}_binary"), "m.msh", b.clone())?;
    c.valid(
        r,
        &format!("{v}_one_tet"),
        "m.msh",
        msh_ascii(&one_tet(), v4),
    )?;
    c.valid(
        r,
        &format!("{v}_degenerate"),
        "m.msh",
        msh_binary(&degenerate(), v4),
    )?;
    let with_comments = cat(&[b"$Comments\nwritten by a test, ignored\n$EndComments\n", &a]);
    c.valid(r, &format!("{v}_comments"), "m.msh", with_comments)?;

    // Cuts inside the node, element and value blocks (their counts are declared).
    let regions = [
        text_block(&a, "$Nodes\n", "$EndNodes"),
        text_block(&a, "$Elements\n", "$EndElements"),
        text_block(&a, "\n1\n5\n", "$EndNodeData"),
    ];
    c.truncations(r, &format!("{v}_ascii"), "m.msh", &a, &regions, 12)?;
    let nodes = find(&b, "$Nodes\n").end;
    let elems = find(&b, "$Elements\n").end;
    let vals = find(&b, "\n1\n5\n").end;
    let regions = [
        nodes..find(&b, "\n$EndNodes").start,
        elems..find(&b, "\n$EndElements").start,
        vals..find(&b, "\n$EndNodeData").start,
    ];
    c.truncations(r, &format!("{v}_binary"), "m.msh", &b, &regions, 10)?;

    let ver = if v4 { "4.1" } else { "2.2" };
    let mut bad: Vec<(String, Kind, Vec<u8>)> = vec![
        (
            "version_3".into(),
            Kind::LyingHeader,
            a.replace_first(&format!("{ver} 0 8"), "3.0 0 8"),
        ),
        (
            "file_type_7".into(),
            Kind::LyingHeader,
            a.replace_first(&format!("{ver} 0 8"), &format!("{ver} 7 8")),
        ),
        (
            "data_size_5".into(),
            Kind::LyingHeader,
            a.replace_first(&format!("{ver} 0 8"), &format!("{ver} 0 5")),
        ),
        (
            "binary_says_ascii".into(),
            Kind::LyingHeader,
            b.replace_first(&format!("{ver} 1 8"), &format!("{ver} 0 8")),
        ),
        (
            "ascii_says_binary".into(),
            Kind::LyingHeader,
            a.replace_first(&format!("{ver} 0 8"), &format!("{ver} 1 8")),
        ),
        (
            "no_end_nodes".into(),
            Kind::LyingHeader,
            a.replace_first("$EndNodes", "$EndNotes"),
        ),
        (
            "no_mesh_format".into(),
            Kind::LyingHeader,
            a.replace_first(&format!("$MeshFormat\n{ver} 0 8\n$EndMeshFormat\n"), ""),
        ),
        ("elements_before_nodes".into(), Kind::LyingHeader, {
            let s = find(&a, "$Nodes").start;
            let e = find(&a, "$EndNodes\n").end;
            let es = find(&a, "$Elements").start;
            let ee = find(&a, "$EndElements\n").end;
            cat(&[&a[..s], &a[es..ee], &a[s..e], &a[ee..]])
        }),
        ("endianness_marker".into(), Kind::BadStream, {
            let at = find(&b, &format!("{ver} 1 8\n")).end;
            let mut x = b.clone();
            x[at..at + 4].copy_from_slice(&[7, 7, 7, 7]);
            x
        }),
        (
            "node_data_components_0".into(),
            Kind::LyingHeader,
            a.replace_first("\n3\n0\n1\n5\n", "\n3\n0\n0\n5\n"),
        ),
        (
            "node_data_count_more".into(),
            Kind::LyingHeader,
            a.replace_first("\n3\n0\n1\n5\n", "\n3\n0\n1\n50\n"),
        ),
        (
            "node_data_count_overflow".into(),
            Kind::Overflow,
            a.replace_first("\n3\n0\n1\n5\n", "\n3\n0\n9\n2305843009213693952\n"),
        ),
        (
            "node_data_tag_unknown".into(),
            Kind::OutOfRange,
            a.replace_first("\n5 ", "\n55 "),
        ),
    ];
    if v4 {
        bad.extend([
            (
                "nodes_count_more".to_string(),
                Kind::LyingHeader,
                a.replace_first("1 5 1 5\n3 1 0 5", "1 9 1 9\n3 1 0 5"),
            ),
            (
                "block_more_nodes".into(),
                Kind::LyingHeader,
                a.replace_first("1 5 1 5\n3 1 0 5", "1 5 1 5\n3 1 0 9"),
            ),
            (
                "blocks_overflow".into(),
                Kind::Overflow,
                a.replace_first("$Nodes\n1 5 1 5", "$Nodes\n18446744073709551615 5 1 5"),
            ),
            (
                "nodes_overflow".into(),
                Kind::Overflow,
                a.replace_first("$Nodes\n1 5 1 5", "$Nodes\n1 4611686018427387904 1 5"),
            ),
            (
                "elements_overflow".into(),
                Kind::Overflow,
                a.replace_first("$Elements\n1 2 1 2", "$Elements\n1 4611686018427387904 1 2"),
            ),
            ("binary_nodes_huge".into(), Kind::Overflow, {
                let at = find(&b, "$Nodes\n").end + 8;
                let mut x = b.clone();
                x[at..at + 8].copy_from_slice(&u64::MAX.to_le_bytes());
                x
            }),
            (
                "node_tag_zero".into(),
                Kind::OutOfRange,
                a.replace_first("3 1 0 5\n1\n", "3 1 0 5\n0\n"),
            ),
            (
                "element_tag_unknown".into(),
                Kind::OutOfRange,
                a.replace_first("\n1 1 2 3 4\n", "\n1 1 2 3 99\n"),
            ),
            (
                "element_tag_negative".into(),
                Kind::OutOfRange,
                a.replace_first("\n1 1 2 3 4\n", "\n1 1 2 3 -4\n"),
            ),
            ("element_type_unknown_binary".into(), Kind::OutOfRange, {
                let at = find(&b, "$Elements\n").end + 32 + 8;
                let mut x = b.clone();
                x[at..at + 4].copy_from_slice(&9999i32.to_le_bytes());
                x
            }),
            ("binary_element_node_huge".into(), Kind::OutOfRange, {
                let at = find(&b, "$Elements\n").end + 32 + 12 + 8 + 8;
                let mut x = b.clone();
                x[at..at + 8].copy_from_slice(&u64::MAX.to_le_bytes());
                x
            }),
        ]);
    } else {
        bad.extend([
            (
                "nodes_count_more".to_string(),
                Kind::LyingHeader,
                a.replace_first("$Nodes\n5\n", "$Nodes\n9\n"),
            ),
            (
                "elements_count_more".into(),
                Kind::LyingHeader,
                a.replace_first("$Elements\n2\n", "$Elements\n3\n"),
            ),
            (
                "nodes_overflow".into(),
                Kind::Overflow,
                a.replace_first("$Nodes\n5\n", "$Nodes\n9223372036854775807\n"),
            ),
            (
                "elements_overflow".into(),
                Kind::Overflow,
                a.replace_first("$Elements\n2\n", "$Elements\n18446744073709551616\n"),
            ),
            ("binary_block_count_huge".into(), Kind::Overflow, {
                let at = find(&b, "$Elements\n2\n").end + 4;
                let mut x = b.clone();
                x[at..at + 4].copy_from_slice(&i32::MAX.to_le_bytes());
                x
            }),
            (
                "negative_tag_count".into(),
                Kind::OutOfRange,
                a.replace_first("\n1 4 2 0 1 1 2 3 4\n", "\n1 4 -5 1 2 3 4\n"),
            ),
            (
                "tag_count_past_line".into(),
                Kind::OutOfRange,
                a.replace_first(
                    "\n1 4 2 0 1 1 2 3 4\n",
                    "\n1 4 9223372036854775807 1 2 3 4\n",
                ),
            ),
            (
                "node_tag_negative".into(),
                Kind::OutOfRange,
                a.replace_first("\n1 0 0 0\n", "\n-1 0 0 0\n"),
            ),
            (
                "element_tag_unknown".into(),
                Kind::OutOfRange,
                a.replace_first(" 1 2 3 4\n", " 1 2 3 99\n"),
            ),
            ("element_type_unknown_binary".into(), Kind::OutOfRange, {
                let at = find(&b, "$Elements\n2\n").end;
                let mut x = b.clone();
                x[at..at + 4].copy_from_slice(&9999i32.to_le_bytes());
                x
            }),
            ("binary_negative_tags".into(), Kind::OutOfRange, {
                let at = find(&b, "$Elements\n2\n").end + 8;
                let mut x = b.clone();
                x[at..at + 4].copy_from_slice(&(-3i32).to_le_bytes());
                x
            }),
            ("binary_element_node_huge".into(), Kind::OutOfRange, {
                let at = find(&b, "$Elements\n2\n").end + 12 + 12;
                let mut x = b.clone();
                x[at..at + 4].copy_from_slice(&i32::MAX.to_le_bytes());
                x
            }),
        ]);
    }
    bad.extend([
        (
            "points_nan".to_string(),
            Kind::BadGeometry,
            a.replace_first("1 1 1\n", "nan 1 1\n"),
        ),
        (
            "points_1e30".into(),
            Kind::BadGeometry,
            a.replace_first("1 1 1\n", "1 1e30 1\n"),
        ),
        (
            "utf8_version".into(),
            Kind::NonUtf8,
            replace_bytes(
                &a,
                &format!("{ver} 0 8"),
                &cat(&[ver.as_bytes(), b"\xff 0 8"]),
            ),
        ),
        (
            "utf8_nodes".into(),
            Kind::NonUtf8,
            replace_bytes(&a, "$Nodes\n", b"$Nodes\n\xfe\xff"),
        ),
        (
            "long_section_name".into(),
            Kind::LongLine,
            cat(&[&a, b"$", "X".repeat(4 << 20).as_bytes(), b"\n"]),
        ),
        (
            "long_number".into(),
            Kind::LongLine,
            replace_bytes(
                &a,
                "$Nodes\n",
                format!("$Nodes\n{}", "7".repeat(1 << 20)).as_bytes(),
            ),
        ),
        ("empty_file".into(), Kind::Truncated, Vec::new()),
    ]);
    for (n, kind, bytes) in bad {
        c.one(r, kind, &format!("{v}_{n}"), "m.msh", bytes)?;
    }
    c.special(r, &format!("{v}_special"), "x.msh")?;
    Ok(())
}

fn tetgen_node(m: &Mesh) -> Vec<u8> {
    let mut s = format!("# nodes\n{} 3 1 0\n", m.points.len());
    for (i, p) in m.points.iter().enumerate() {
        let _ = writeln!(
            s,
            "{} {} {} {} {}",
            i + 1,
            p[0],
            p[1],
            p[2],
            fmt_f(m.field[i])
        );
    }
    s.into_bytes()
}

fn tetgen_ele(m: &Mesh) -> Vec<u8> {
    let mut s = format!("{} 4 0\n", m.tets.len());
    for (e, t) in m.tets.iter().enumerate() {
        let _ = writeln!(
            s,
            "{} {} {} {} {}",
            e + 1,
            t[0] + 1,
            t[1] + 1,
            t[2] + 1,
            t[3] + 1
        );
    }
    s.into_bytes()
}

fn tetgen_cases(c: &mut Corpus) -> std::io::Result<()> {
    let r = Reader::TetGen;
    let f = |s: &str, b: Vec<u8>| (s.to_string(), Entry::File(b));
    let m = mesh();
    let (node, ele) = (tetgen_node(&m), tetgen_ele(&m));
    let pair = |n: Vec<u8>, e: Vec<u8>| vec![f("t.node", n), f("t.ele", e)];
    c.add(
        r,
        Kind::Valid,
        "tetgen_node",
        pair(node.clone(), ele.clone()),
        "t.node",
    )?
    .expect = Expect::Renders;
    c.add(
        r,
        Kind::Valid,
        "tetgen_ele",
        pair(node.clone(), ele.clone()),
        "t.ele",
    )?
    .expect = Expect::Renders;
    c.add(
        r,
        Kind::Valid,
        "tetgen_one_tet",
        pair(tetgen_node(&one_tet()), tetgen_ele(&one_tet())),
        "t.node",
    )?
    .expect = Expect::Renders;
    c.add(
        r,
        Kind::Valid,
        "tetgen_degenerate",
        pair(tetgen_node(&degenerate()), tetgen_ele(&degenerate())),
        "t.node",
    )?
    .expect = Expect::Renders;
    let zero_based: Vec<u8> = String::from_utf8_lossy(&node)
        .lines()
        .map(|l| {
            let mut w: Vec<String> = l.split(' ').map(str::to_owned).collect();
            if w.len() == 5 && !l.starts_with('#') {
                w[0] = (w[0].parse::<usize>().unwrap_or(1) - 1).to_string();
            }
            w.join(" ") + "\n"
        })
        .collect::<String>()
        .into_bytes();
    let zero_ele = b"2 4 0\n0 0 1 2 3\n1 1 2 3 4\n".to_vec();
    c.add(
        r,
        Kind::Valid,
        "tetgen_zero_based",
        pair(zero_based, zero_ele),
        "t.node",
    )?
    .expect = Expect::Renders;

    let nregion = text_block(&node, "0\n", "\n5 1 1 1 6");
    let nregion = nregion.start..last_token_start(&node, node.len());
    for at in spread(&[nregion], 8) {
        c.add(
            r,
            Kind::Truncated,
            &format!("tetgen_node_cut{at}"),
            pair(node[..at].to_vec(), ele.clone()),
            "t.node",
        )?;
    }
    let eregion = find(&ele, "\n").end..last_token_start(&ele, ele.len());
    for at in spread(&[eregion], 6) {
        c.add(
            r,
            Kind::Truncated,
            &format!("tetgen_ele_cut{at}"),
            pair(node.clone(), ele[..at].to_vec()),
            "t.node",
        )?;
    }
    let bad: Vec<(&str, Kind, Files)> = vec![
        (
            "node_count_more",
            Kind::LyingHeader,
            pair(node.replace_first("5 3 1 0", "9 3 1 0"), ele.clone()),
        ),
        (
            "ele_count_more",
            Kind::LyingHeader,
            pair(node.clone(), ele.replace_first("2 4 0", "5 4 0")),
        ),
        (
            "dimension_2",
            Kind::LyingHeader,
            pair(node.replace_first("5 3 1 0", "5 2 1 0"), ele.clone()),
        ),
        (
            "nodes_per_tet_7",
            Kind::LyingHeader,
            pair(node.clone(), ele.replace_first("2 4 0", "2 7 0")),
        ),
        (
            "attributes_99",
            Kind::LyingHeader,
            pair(node.replace_first("5 3 1 0", "5 3 99 0"), ele.clone()),
        ),
        (
            "region_flag_7",
            Kind::LyingHeader,
            pair(node.clone(), ele.replace_first("2 4 0", "2 4 7")),
        ),
        (
            "node_count_overflow",
            Kind::Overflow,
            pair(
                node.replace_first("5 3 1 0", "18446744073709551615 3 1 0"),
                ele.clone(),
            ),
        ),
        (
            "ele_count_overflow",
            Kind::Overflow,
            pair(
                node.clone(),
                ele.replace_first("2 4 0", "4611686018427387904 4 0"),
            ),
        ),
        (
            "index_out_of_range",
            Kind::OutOfRange,
            pair(node.clone(), ele.replace_first("2 2 3 4 5", "2 2 3 4 6")),
        ),
        (
            "index_zero_in_one_based",
            Kind::OutOfRange,
            pair(node.clone(), ele.replace_first("2 2 3 4 5", "2 2 3 4 0")),
        ),
        (
            "index_i64min",
            Kind::OutOfRange,
            pair(
                node.clone(),
                ele.replace_first("2 2 3 4 5", "2 2 3 4 -9223372036854775808"),
            ),
        ),
        (
            "node_numbering_gap",
            Kind::OutOfRange,
            pair(node.replace_first("\n3 0 1 0", "\n7 0 1 0"), ele.clone()),
        ),
        (
            "first_index_5",
            Kind::OutOfRange,
            pair(node.replace_first("\n1 0 0 0", "\n5 0 0 0"), ele.clone()),
        ),
        (
            "points_nan",
            Kind::BadGeometry,
            pair(node.replace_first("\n5 1 1 1", "\n5 nan 1 1"), ele.clone()),
        ),
        (
            "points_1e30",
            Kind::BadGeometry,
            pair(node.replace_first("\n5 1 1 1", "\n5 1 1 1e30"), ele.clone()),
        ),
        (
            "utf8_node",
            Kind::NonUtf8,
            pair(replace_bytes(&node, "5 3 1 0", b"5\xff 3 1 0"), ele.clone()),
        ),
        (
            "utf8_ele",
            Kind::NonUtf8,
            pair(node.clone(), replace_bytes(&ele, "2 4 0", b"2 4\xfe 0")),
        ),
        (
            "long_line",
            Kind::LongLine,
            pair(
                replace_bytes(
                    &node,
                    "5 3 1 0",
                    format!("5 3 1 0{}", " 1".repeat(2 << 20)).as_bytes(),
                ),
                ele.clone(),
            ),
        ),
        (
            "ele_missing",
            Kind::SpecialFile,
            vec![f("t.node", node.clone())],
        ),
        (
            "ele_fifo",
            Kind::SpecialFile,
            vec![f("t.node", node.clone()), ("t.ele".into(), Entry::Fifo)],
        ),
        (
            "ele_devzero",
            Kind::SpecialFile,
            vec![
                f("t.node", node.clone()),
                ("t.ele".into(), Entry::Link("/dev/zero".into())),
            ],
        ),
        (
            "node_devzero",
            Kind::SpecialFile,
            vec![
                ("t.node".into(), Entry::Link("/dev/zero".into())),
                f("t.ele", ele.clone()),
            ],
        ),
        (
            "ele_dir",
            Kind::SpecialFile,
            vec![f("t.node", node.clone()), ("t.ele".into(), Entry::Dir)],
        ),
        (
            "node_fifo_open_ele",
            Kind::SpecialFile,
            vec![("t.node".into(), Entry::Fifo), f("t.ele", ele.clone())],
        ),
    ];
    for (n, kind, entries) in bad {
        let open = if n == "node_fifo_open_ele" {
            "t.ele"
        } else {
            "t.node"
        };
        c.add(r, kind, &format!("tetgen_{n}"), entries, open)?;
    }
    Ok(())
}

fn isot_cases(c: &mut Corpus) -> std::io::Result<()> {
    let r = Reader::Isot;
    let volume =
        crate::marschner_lobb::generate([9, 9, 9], volume_core::VoxelType::U8).map_err(io_err)?;
    let layout = volume_core::ooc::TreeletLayout::new([9, 9, 9], 2).map_err(io_err)?;
    let tmp = c.root.join("isot_base.tmp.isot");
    formats::treelet::write_isot_volume(
        &tmp,
        &volume,
        layout,
        formats::output::Replace::Refuse,
        &mut |_, _| {},
    )
    .map_err(io_err)?;
    let base = std::fs::read(&tmp)?;
    std::fs::remove_file(&tmp)?;
    c.valid(r, "isot_valid", "v.isot", base.clone())?;
    c.truncations(r, "isot", "v.isot", &base, &[0..base.len()], 14)?;
    // Any changed header byte breaks the header checksum (or the magic, or a field check).
    for at in [0usize, 4, 8, 12, 16, 24, 32, 48, 64, 100] {
        let mut x = base.clone();
        x[at] ^= 0xff;
        c.one(
            r,
            Kind::LyingHeader,
            &format!("isot_header_byte{at}"),
            "v.isot",
            x,
        )?;
    }
    c.one(
        r,
        Kind::LyingHeader,
        "isot_longer",
        "v.isot",
        cat(&[&base, &[0u8; 4096]]),
    )?;
    c.one(
        r,
        Kind::LyingHeader,
        "isot_magic_only",
        "v.isot",
        base[..8].to_vec(),
    )?;
    c.one(
        r,
        Kind::LongLine,
        "isot_text",
        "v.isot",
        "ISOT".repeat(1 << 20).into_bytes(),
    )?;
    c.one(
        r,
        Kind::NonUtf8,
        "isot_random_bytes",
        "v.isot",
        (0..8192u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
            .collect(),
    )?;
    c.special(r, "isot_special", "x.isot")?;
    Ok(())
}

/// Writes the corpus into `dir` (which must exist and should be empty) and returns its
/// cases. Unix only (FIFOs and symbolic links are part of it).
pub fn write_corpus(dir: &Path) -> std::io::Result<Vec<Case>> {
    let mut c = Corpus {
        root: dir.to_path_buf(),
        cases: Vec::new(),
    };
    nrrd_cases(&mut c)?;
    nhdr_cases(&mut c)?;
    raw_cases(&mut c)?;
    series_cases(&mut c)?;
    vtk_cases(&mut c)?;
    vtu_cases(&mut c)?;
    pvd_cases(&mut c)?;
    gmsh_cases(&mut c, false)?;
    gmsh_cases(&mut c, true)?;
    tetgen_cases(&mut c)?;
    isot_cases(&mut c)?;
    images::metaimage_cases(&mut c)?;
    images::vtk_image_cases(&mut c)?;
    images::tiff_cases(&mut c)?;
    nifti::nifti_cases(&mut c)?;
    dicom::dcm_cases(&mut c)?;
    for (case, name) in REFERENCED {
        let c = c
            .cases
            .iter_mut()
            .find(|c| c.name == *case)
            .unwrap_or_else(|| panic!("no case {case}"));
        c.names.push(if name.starts_with('/') {
            (*name).to_string()
        } else {
            format!("{case}/{name}")
        });
    }
    Ok(c.cases)
}

/// Files that cases refer to without writing them (missing, outside the corpus, or of a
/// name no file can have): an error may name these instead of the referring file. A prefix
/// stands for a name too long to spell here or formatted by the reader.
const REFERENCED: &[(&str, &str)] = &[
    ("nhdr_missing_data_file", "gone.raw"),
    ("nhdr_list_missing_entry", "nope.raw"),
    ("nhdr_pattern_huge_width", "s"),
    ("nhdr_data_file_abs_devzero", "/dev/zero"),
    ("nhdr_data_file_long_name", "ddd"),
    ("pvd_step0_missing", "gone.vtu"),
    ("pvd_step1_missing", "gone.vtu"),
    ("pvd_step_abs_devzero", "/dev/zero"),
    ("pvd_step_non_utf8", "s_\u{fffd}.vtu"),
    ("pvd_long_file_name", "sss"),
    ("tetgen_ele_missing", "t.ele"),
    ("mhd_missing_data_file", "gone.raw"),
    ("mhd_pattern_missing_slice", "s2.raw"),
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_corpus_covers_every_reader_and_kind_with_at_least_300_cases() {
        let dir = tempfile::tempdir().unwrap();
        let cases = write_corpus(dir.path()).unwrap();
        assert!(cases.len() >= 300, "{} cases", cases.len());
        for r in Reader::ALL {
            assert!(
                cases
                    .iter()
                    .any(|c| c.reader == r && c.expect == Expect::Renders),
                "{r:?} valid"
            );
            assert!(
                cases
                    .iter()
                    .any(|c| c.reader == r && c.kind == Kind::Truncated),
                "{r:?} truncated"
            );
        }
        for k in Kind::ALL {
            assert!(cases.iter().any(|c| c.kind == k), "{k:?}");
        }
        // Every case's files exist as made (a FIFO is a FIFO, a link a link).
        for c in &cases {
            assert!(dir.path().join(&c.name).is_dir(), "{}", c.name);
            assert_eq!(
                c.expect == Expect::Renders,
                c.kind == Kind::Valid,
                "{}",
                c.name
            );
        }
    }

    #[test]
    fn spread_picks_distinct_offsets_inside_the_regions() {
        let got = spread(&[2..5, 10..12], 4);
        assert_eq!(got, vec![2, 3, 4, 10]);
        assert!(spread(&[0..100], 10).iter().all(|&x| x < 100));
        assert_eq!(last_token_start(b"1 22 333\n", 9), 5);
    }
}
