//! What each fuzz target runs on one input, shared by the targets (`fuzz_targets/*.rs`) and by
//! the corpus replay in `cargo test` (`formats/tests/fuzz_corpus.rs` includes this file), so
//! that the committed corpus is replayed through exactly the code that was fuzzed.
//!
//! Every function takes the raw fuzz input and returns `Ok` when the reader accepted it and
//! `Err(message)` when it refused it cleanly; a panic (including an integer overflow under
//! `--debug-assertions`) is the finding. Cheap invariants of accepted results are asserted:
//! a volume holds exactly the product of its dims in voxels, a tet mesh's indices are in
//! range and its fields have one value per point, and so on.
//!
//! Multi-file inputs are split at the first NUL byte (TetGen `.node` / `.ele`, raw sidecar /
//! data); text formats never contain one, so a seed is two files joined by `\0`. Readers that
//! only read from paths (NRRD data files, `.pvd` steps) get their files written under a
//! per-process, per-thread directory in `/dev/shm` (memory, no disk I/O).

#![allow(dead_code)] // each target uses one function

use std::path::{Path, PathBuf};

use formats::mesh::{LoadedMesh, RawMesh};
use volume_core::RectilinearVolume;
use volume_core::ooc::{OocMeta, TreeletRecord, TreeletStorage};
use volume_core::{Voxel, VoxelType};

/// Result of one input: accepted, or the reader's error message.
pub type Outcome = Result<(), String>;

fn err(e: impl std::fmt::Display) -> String {
    e.to_string()
}

/// A scratch directory for this process and thread (tests replay on several threads). Also
/// empties the readers' input log ([`formats::input::forget_inputs`]): each execution reads
/// its files as a fresh process would, and the log, which only grows, does not gain an entry
/// for every scratch file an earlier execution removed (it slowed the file-based targets to a
/// crawl as it grew). No target writes an output, so emptying it while another replay thread
/// reads changes nothing.
pub fn scratch_dir(name: &str) -> PathBuf {
    formats::input::forget_inputs();
    let thread = format!("{:?}", std::thread::current().id());
    let thread: String = thread.chars().filter(char::is_ascii_digit).collect();
    let dir = Path::new("/dev/shm").join(format!(
        "isoscope-fuzz-{name}-{}-{thread}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).expect("create the scratch directory in /dev/shm");
    dir
}

/// Splits a two-file input at the first NUL byte (the second part empty if there is none).
pub fn split_nul(data: &[u8]) -> (&[u8], &[u8]) {
    match data.iter().position(|&b| b == 0) {
        Some(i) => (&data[..i], &data[i + 1..]),
        None => (data, &[]),
    }
}

/// A volume holds one voxel per grid sample, and its world bounds are finite.
pub fn check_volume(v: &RectilinearVolume) {
    let dims = v.dims();
    let product = dims.iter().try_fold(1usize, |acc, &d| acc.checked_mul(d));
    assert_eq!(product, Some(v.grid.voxel_count()), "dims {dims:?}");
    assert_eq!(v.data.len(), v.grid.voxel_count(), "dims {dims:?}");
    assert!(dims.iter().all(|&d| d >= 1), "dims {dims:?}");
}

/// A tet mesh: indices within the points, one value per point in every field, finite points.
pub fn check_mesh(m: &LoadedMesh) {
    let n = m.mesh.points.len();
    for t in &m.mesh.tets {
        assert!(
            t.iter().all(|&i| (i as usize) < n),
            "tet {t:?} with {n} points"
        );
    }
    for f in &m.mesh.fields {
        assert_eq!(f.values.len(), n, "field {}", f.name);
    }
    assert!(m.mesh.points.iter().flatten().all(|c| c.is_finite()));
    assert!(m.skipped.total() <= m.source_cells);
}

/// A parsed mesh, validated and split into tets as the readers' callers do.
fn finish_mesh(path: &Path, raw: Result<RawMesh, formats::mesh::MeshError>) -> Outcome {
    let raw = raw.map_err(err)?;
    let loaded = raw.into_tet_mesh(path).map_err(err)?;
    check_mesh(&loaded);
    Ok(())
}

// ---------------------------------------------------------------- NRRD

/// `nrrd_header`: the header parser, axis/geometry interpretation and data file list.
pub fn nrrd_header(data: &[u8]) -> Outcome {
    let header = formats::nrrd::parse_header(data).map_err(err)?;
    let layout = header.volume_layout(Path::new("fuzz.nhdr")).map_err(err)?;
    assert!(layout.steps >= 1);
    let files = formats::nrrd::header::data_file_paths(&header, Path::new("/fuzz/h.nhdr"));
    assert!(!files.is_empty());
    Ok(())
}

/// At most this many detached data files are written for one input (a pattern may name more;
/// then the missing ones are an error, which is also worth exercising).
const MAX_DATA_FILES: usize = 16;

/// `nrrd_data`: a whole NRRD through `formats::nrrd::read_nrrd` (header, data files, skips,
/// every encoding, time steps). The input up to its first blank line is the header; if it
/// names detached data files inside the scratch directory (`data file: d.raw`, `LIST`,
/// patterns), the rest of the input is divided evenly among them and the header alone goes to
/// `h.nhdr`; otherwise the whole input is the attached file `a.nrrd`.
pub fn nrrd_data(data: &[u8]) -> Outcome {
    let dir = scratch_dir("nrrd");
    let header_end = data
        .windows(2)
        .position(|w| w == b"\n\n")
        .map_or(data.len(), |i| i + 2);
    let detached = formats::nrrd::parse_header(&data[..header_end])
        .ok()
        .filter(|h| h.data_files != formats::nrrd::DataFiles::Attached);
    let mut written = Vec::new();
    let path = if let Some(header) = detached {
        let path = dir.join("h.nhdr");
        let files = formats::nrrd::header::data_file_paths(&header, &path);
        let ours: Vec<_> = files
            .iter()
            .filter(|f| f.parent() == Some(dir.as_path()))
            .take(MAX_DATA_FILES)
            .collect();
        let rest = &data[header_end..];
        let per = rest.len() / ours.len().max(1);
        for (i, f) in ours.iter().enumerate() {
            let chunk = if i + 1 == ours.len() {
                &rest[i * per..]
            } else {
                &rest[i * per..(i + 1) * per]
            };
            // A name that is not a plain file name (e.g. `d/`) cannot be written: skip.
            if std::fs::write(f, chunk).is_ok() {
                written.push((*f).clone());
            }
        }
        std::fs::write(&path, &data[..header_end]).expect("write h.nhdr");
        path
    } else {
        let path = dir.join("a.nrrd");
        std::fs::write(&path, data).expect("write a.nrrd");
        path
    };
    let result = read_nrrd_checked(&path);
    for f in written {
        let _ = std::fs::remove_file(f);
    }
    result
}

fn read_nrrd_checked(path: &Path) -> Outcome {
    match formats::nrrd::read_nrrd(path).map_err(err)? {
        formats::Dataset::Volume(v) => check_volume(&v),
        formats::Dataset::Series(s) => {
            let dims = s.first().dims();
            // Each step must decode to the first step's shape (or be a clean error).
            for i in 0..s.step_count().min(8) {
                if let Ok(v) = s.step(i) {
                    check_volume(&v);
                    assert_eq!(v.dims(), dims, "step {i}");
                }
            }
        }
    }
    Ok(())
}

// ---------------------------------------------------------------- NIfTI

/// `nifti`: a NIfTI-1/NIfTI-2/Analyze file through `formats::nifti::read_nifti` (header,
/// geometry, value map, memory-mapped or gzip data, time steps). The first byte selects how
/// the rest is laid out in the scratch directory: `0` as `v.nii`; `1` gzip-compressed here
/// into `v.nii.gz` (so mutations reach the decoded header and data); `2` as `v.nii.gz`
/// unchanged (the gzip stream itself); `3` a pair, the first 348 bytes as `v.hdr` and the
/// rest as `v.img`. (Bits above the second are ignored.)
pub fn nifti(data: &[u8]) -> Outcome {
    let Some((&selector, rest)) = data.split_first() else {
        return Err("empty input".into());
    };
    let dir = scratch_dir("nifti");
    // Files of an earlier input (a `v.img` beside this input's `v.hdr`) must not be found.
    for name in ["v.nii", "v.nii.gz", "v.hdr", "v.img"] {
        let _ = std::fs::remove_file(dir.join(name));
    }
    let path = match selector & 3 {
        0 => {
            let p = dir.join("v.nii");
            std::fs::write(&p, rest).expect("write v.nii");
            p
        }
        1 | 2 => {
            let p = dir.join("v.nii.gz");
            let bytes = if selector & 3 == 1 {
                let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
                std::io::Write::write_all(&mut e, rest).expect("in memory");
                e.finish().expect("in memory")
            } else {
                rest.to_vec()
            };
            std::fs::write(&p, bytes).expect("write v.nii.gz");
            p
        }
        _ => {
            let (h, img) = rest.split_at(rest.len().min(348));
            let p = dir.join("v.hdr");
            std::fs::write(&p, h).expect("write v.hdr");
            std::fs::write(dir.join("v.img"), img).expect("write v.img");
            p
        }
    };
    match formats::nifti::read_nifti(&path).map_err(err)? {
        formats::Dataset::Volume(v) => check_volume(&v),
        formats::Dataset::Series(s) => {
            let dims = s.first().dims();
            for i in 0..s.step_count().min(8) {
                if let Ok(v) = s.step(i) {
                    check_volume(&v);
                    assert_eq!(v.dims(), dims, "step {i}");
                    assert_eq!(v.value_map, s.first().value_map, "step {i}");
                }
            }
        }
    }
    Ok(())
}

// ---------------------------------------------------------------- raw + sidecar

/// `raw_sidecar`: JSON sidecar text, NUL, raw file bytes: the sidecar parser, then the layout
/// checks and voxel decoding of `formats::raw::parse_raw` (what `read_raw` does on a map).
pub fn raw_sidecar(data: &[u8]) -> Outcome {
    let (json, raw) = split_nul(data);
    // `from_sidecar` reads the sidecar as UTF-8 text: non-UTF-8 is an I/O error there.
    let text = std::str::from_utf8(json).map_err(err)?;
    let path = Path::new("fuzz.json");
    let layout = formats::raw::RawLayout::from_sidecar_text(path, text).map_err(err)?;
    let volume = formats::raw::parse_raw(Path::new("fuzz.raw"), &layout, raw).map_err(err)?;
    check_volume(&volume);
    assert_eq!(volume.dims(), layout.dims);
    assert_eq!(volume.data.voxel_type(), layout.voxel_type);
    Ok(())
}

// ---------------------------------------------------------------- meshes

/// `vtk_legacy`: `formats::mesh::vtk_legacy::parse` (ASCII and binary, v4 and v5 cells).
pub fn vtk_legacy(data: &[u8]) -> Outcome {
    let path = Path::new("fuzz.vtk");
    finish_mesh(path, formats::mesh::vtk_legacy::parse(path, data))
}

/// `vtu`: `formats::mesh::vtu::parse` (ascii, base64 binary, appended raw/base64, zlib).
pub fn vtu(data: &[u8]) -> Outcome {
    let path = Path::new("fuzz.vtu");
    finish_mesh(path, formats::mesh::vtu::parse(path, data))
}

/// `gmsh`: `formats::mesh::gmsh::parse` (2.2 and 4.1, ASCII and binary).
pub fn gmsh(data: &[u8]) -> Outcome {
    let path = Path::new("fuzz.msh");
    finish_mesh(path, formats::mesh::gmsh::parse(path, data))
}

/// `tetgen`: `.node` bytes, NUL, `.ele` bytes, through `formats::mesh::tetgen::parse`.
pub fn tetgen(data: &[u8]) -> Outcome {
    let (node, ele) = split_nul(data);
    let node_path = Path::new("fuzz.node");
    let raw = formats::mesh::tetgen::parse(node_path, node, Path::new("fuzz.ele"), ele);
    finish_mesh(node_path, raw)
}

/// A small valid `.vtu` step that `.pvd` inputs can name (`s.vtu`).
const PVD_STEP: &[u8] = include_bytes!("../tests/data/mesh/mixed_ascii.vtu");

/// `pvd`: the collection parser on the bytes (`formats::mesh::parse_pvd`), then the input
/// written as `a.pvd` beside a valid step `s.vtu` and a collection `b.pvd` that names `a.pvd`,
/// and read as the readers' callers do: `mesh::read_raw` (the first step, following nested
/// collections: cycles) and `load_step` of the first steps.
pub fn pvd(data: &[u8]) -> Outcome {
    let dir = scratch_dir("pvd");
    let path = dir.join("a.pvd");
    let series = formats::mesh::parse_pvd(&path, data).map_err(err)?;
    assert!(!series.is_empty());
    assert!(series.steps.iter().all(|s| s.time.is_finite()));
    assert!(series.steps.windows(2).all(|w| w[0].time <= w[1].time));
    let step = dir.join("s.vtu");
    if !step.exists() {
        std::fs::write(&step, PVD_STEP).expect("write s.vtu");
        std::fs::write(
            dir.join("b.pvd"),
            "<VTKFile type=\"Collection\"><Collection>\
             <DataSet timestep=\"0\" file=\"a.pvd\"/></Collection></VTKFile>",
        )
        .expect("write b.pvd");
    }
    // Only steps inside the scratch directory are followed (a fuzzed name could point at
    // any file on the machine; reading is harmless but slow and not what is being tested).
    if !series
        .steps
        .iter()
        .all(|s| s.path.parent() == Some(dir.as_path()))
    {
        return Ok(());
    }
    std::fs::write(&path, data).expect("write a.pvd");
    let read = formats::mesh::read_pvd(&path).map_err(err)?;
    assert_eq!(read, series);
    let first = formats::mesh::read_raw(&path).map_err(err)?;
    let first = first.into_tet_mesh(&path).map_err(err)?;
    check_mesh(&first);
    for i in 1..series.len().min(4) {
        if let Ok(step) = series.load_step_data(i, &first.mesh) {
            assert!(step.time.is_finite());
        }
    }
    Ok(())
}

// ---------------------------------------------------------------- .isot

/// Byte offset of the header length in an `.isot` file (magic 8, version 4, page size 4).
const ISOT_HEADER_LEN_AT: usize = 16;

/// Rewrites the CRCs of an `.isot` image so that mutations get past them: bit 0 of `fix`
/// the data page CRCs, bit 1 the header CRC. Values that do not fit the image are left.
pub fn fix_isot_crcs(bytes: &mut [u8], fix: u8) {
    let page = formats::treelet::PAGE as usize;
    let Some(hl) = bytes
        .get(ISOT_HEADER_LEN_AT..ISOT_HEADER_LEN_AT + 8)
        .map(|b| u64::from_le_bytes(b.try_into().expect("8")) as usize)
        .filter(|&hl| (28..=bytes.len()).contains(&hl))
    else {
        return;
    };
    if fix & 1 != 0 && hl >= 44 {
        // The header ends with: data pages u64, checksum table offset u64, header CRC u32.
        let at = |o: usize| u64::from_le_bytes(bytes[o..o + 8].try_into().expect("8"));
        let pages = at(hl - 20) as usize;
        let crc_at = at(hl - 12) as usize;
        let data_at = hl.next_multiple_of(page);
        for p in 0..pages.min(bytes.len() / page) {
            let (start, slot) = (data_at + p * page, crc_at.saturating_add(p * 4));
            if start + page > bytes.len() || slot.saturating_add(4) > bytes.len() {
                break;
            }
            let crc = crc32fast::hash(&bytes[start..start + page]);
            bytes[slot..slot + 4].copy_from_slice(&crc.to_le_bytes());
        }
    }
    if fix & 2 != 0 {
        let crc = crc32fast::hash(&bytes[..hl - 4]);
        bytes[hl - 4..hl].copy_from_slice(&crc.to_le_bytes());
    }
}

/// Treelets fetched and decoded per level, at most (a level can hold millions).
const MAX_TREELETS_PER_LEVEL: u64 = 64;

fn decode_all<T: Voxel>(file: &formats::treelet::IsotFile, meta: &OocMeta) -> Outcome {
    for (level, plan) in file.plans().iter().enumerate() {
        for index in 0..plan.treelet_count.min(MAX_TREELETS_PER_LEVEL) {
            let bytes = file.fetch(level, index).map_err(err)?;
            let record = TreeletRecord::<T>::decode(meta, level, index, &bytes).map_err(err)?;
            assert_eq!((record.level, record.index), (level, index));
        }
    }
    Ok(())
}

/// `isot`: a selector byte (bit 0: fix the page CRCs, bit 1: fix the header CRC), then an
/// `.isot` image through `IsotFile::from_bytes` (header, level table, lengths), `verify`, and
/// the fetch and decode of the first treelets of every level.
pub fn isot(data: &[u8]) -> Outcome {
    let Some((&fix, image)) = data.split_first() else {
        return Err("empty".into());
    };
    let mut image = image.to_vec();
    fix_isot_crcs(&mut image, fix);
    let path = Path::new("fuzz.isot");
    let file = formats::treelet::IsotFile::from_bytes(path, image).map_err(err)?;
    let meta = file.meta().clone();
    assert!(!file.plans().is_empty());
    file.verify().map_err(err)?;
    match meta.voxel_type {
        VoxelType::U8 => decode_all::<u8>(&file, &meta),
        VoxelType::I8 => decode_all::<i8>(&file, &meta),
        VoxelType::U16 => decode_all::<u16>(&file, &meta),
        VoxelType::I16 => decode_all::<i16>(&file, &meta),
        VoxelType::U32 => decode_all::<u32>(&file, &meta),
        VoxelType::I32 => decode_all::<i32>(&file, &meta),
        VoxelType::F32 => decode_all::<f32>(&file, &meta),
        VoxelType::F64 => decode_all::<f64>(&file, &meta),
    }
}

// ---------------------------------------------------------------- image formats

/// A dataset's volumes: each step (at most 8) has the first step's dims.
fn check_dataset(d: &formats::Dataset) {
    match d {
        formats::Dataset::Volume(v) => check_volume(v),
        formats::Dataset::Series(s) => {
            let dims = s.first().dims();
            check_volume(s.first());
            for i in 0..s.step_count().min(8) {
                if let Ok(v) = s.step(i) {
                    check_volume(&v);
                    assert_eq!(v.dims(), dims, "step {i}");
                }
            }
        }
    }
}

/// `metaimage`: a MetaImage through `formats::metaimage::read_metaimage` (header, data
/// files, raw and zlib, `HeaderSize`, 4D steps). If the header parses and names detached
/// data files inside the scratch directory (a file name, a pattern, a `LIST`), the bytes
/// after the header are divided evenly among them (at most [`MAX_DATA_FILES`]) and the
/// header goes to `h.mhd`; otherwise the whole input is `a.mha`.
pub fn metaimage(data: &[u8]) -> Outcome {
    let dir = scratch_dir("metaimage");
    let parsed = formats::metaimage::parse_header(Path::new("fuzz.mhd"), data).ok();
    let mut written = Vec::new();
    let detached = parsed
        .as_ref()
        .filter(|h| h.data_file != formats::metaimage::DataFile::Local);
    let path = if let Some(header) = detached {
        let path = dir.join("h.mhd");
        // Names are made one at a time: a pattern can name 2^20 files, and listing them all
        // for every input made such headers time out here, not in the reader.
        let ours: Vec<_> = (0..formats::metaimage::data_file_count(header))
            .map(|i| formats::metaimage::data_file_path(header, &path, i))
            .filter(|f| f.parent() == Some(dir.as_path()))
            .take(MAX_DATA_FILES)
            .collect();
        let rest = &data[header.header_len.min(data.len())..];
        let per = rest.len() / ours.len().max(1);
        for (i, f) in ours.iter().enumerate() {
            let chunk = if i + 1 == ours.len() {
                &rest[i * per..]
            } else {
                &rest[i * per..(i + 1) * per]
            };
            if std::fs::write(f, chunk).is_ok() {
                written.push(f.clone());
            }
        }
        std::fs::write(&path, &data[..header.header_len.min(data.len())]).expect("write h.mhd");
        path
    } else {
        let path = dir.join("a.mha");
        std::fs::write(&path, data).expect("write a.mha");
        path
    };
    let result = formats::metaimage::read_metaimage(&path).map(|d| check_dataset(&d));
    for f in written {
        let _ = std::fs::remove_file(f);
    }
    result.map_err(err)
}

/// `vti`: VTK image data from memory: legacy `.vtk` images (input starting `# vtk`) through
/// `formats::vtk_image::legacy::parse`, anything else through `vti::parse` (the XML walk,
/// every encoding, zlib and LZ4 blocks); the default array, then the array list.
pub fn vti(data: &[u8]) -> Outcome {
    use formats::vtk_image::{legacy, vti};
    let legacy_file = data.starts_with(b"# vtk");
    let path = Path::new(if legacy_file { "fuzz.vtk" } else { "fuzz.vti" });
    let volume = if legacy_file {
        legacy::parse(path, data, None)
    } else {
        vti::parse(path, data, None)
    }
    .map_err(err)?;
    check_volume(&volume);
    let arrays = if legacy_file {
        legacy::point_arrays(path, data)
    } else {
        vti::point_arrays(path, data)
    }
    .map_err(err)?;
    assert!(arrays.default_name().is_some());
    Ok(())
}

/// `tiff`: a TIFF from memory through `formats::tiff::parse_tiff` (every page, the size and
/// sample-type checks, ImageJ frames as steps).
pub fn tiff(data: &[u8]) -> Outcome {
    let d = formats::tiff::parse_tiff(
        Path::new("fuzz.tif"),
        data,
        &formats::OpenOptions::default(),
    )
    .map_err(err)?;
    check_dataset(&d);
    Ok(())
}

// ---------------------------------------------------------------- camera JSON

/// `camera_json`: a camera file as `isoscope render --camera` loads it (`load_camera` in
/// `app/src/cli/render.rs`: UTF-8 text, serde, then `Camera::validate`).
pub fn camera_json(data: &[u8]) -> Outcome {
    let text = std::str::from_utf8(data).map_err(err)?;
    let camera: volume_core::render::Camera = serde_json::from_str(text).map_err(err)?;
    camera.validate().map_err(err)?;
    assert!(camera.eye.is_finite() && camera.target.is_finite() && camera.up.is_finite());
    Ok(())
}

// ---------------------------------------------------------------- DICOM

/// `dicom`: one DICOM file, alone in its folder, opened as `formats::open` opens a `.dcm`
/// (its series from its folder: itself) and listed as `isoscope info` lists it: the element
/// walk, dicom-rs's attribute parser, the attribute reader, every pixel decoder (native, RLE,
/// deflate, JPEG, JPEG 2000) and the series geometry.
pub fn dicom(data: &[u8]) -> Outcome {
    let dir = scratch_dir("dicom");
    let path = dir.join("in.dcm");
    std::fs::write(&path, data).map_err(err)?;
    let listing = formats::dicom::list(&path).map_err(err);
    let opened = formats::dicom::open(&path, None).map_err(err)?;
    let listing = listing?;
    assert!(
        listing.series.len() <= 1,
        "one file, {} series",
        listing.series.len()
    );
    check_volume(opened.first_volume());
    Ok(())
}
