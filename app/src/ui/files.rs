//! Several files opened together (command line, drag and drop, the file dialog).
//!
//! As ParaView groups numbered files (`blob_000.nrrd`, `blob_001.nrrd`, ...) into one time
//! series, files of one kind in one folder whose names differ only in a number open as a
//! series: the viewer hands the series pattern (`blob_*.nrrd`) to
//! [`crate::scene::open_scene`], which loads steps lazily and checks that every step has the
//! first one's shape (dims and voxel type for grids, topology for meshes). Anything else
//! stays a list of files, shown one at a time.
//!
//! Two probes decide how a single file opens before any job runs: [`is_session_file`]
//! (a viewer session rather than data) and [`needs_raw_dialog`] (a raw file without its
//! layout). Both run on the UI thread, so they read at most a small prefix of the file.

use std::collections::BTreeSet;
use std::io::Read as _;
use std::path::{Path, PathBuf};

use super::state::{RawLayoutState, ViewerState};
use crate::scene::{SceneKind, detect_kind};

/// How a set of files opens.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FileGroup {
    Single(PathBuf),
    /// A numbered series: the glob pattern matching exactly the given files.
    Series {
        pattern: PathBuf,
        steps: usize,
    },
    /// Files shown one at a time, with the reason they are not a series.
    List {
        files: Vec<PathBuf>,
        reason: String,
    },
}

fn name_of(p: &Path) -> Option<&str> {
    p.file_name().and_then(|n| n.to_str())
}

/// `files` without the `.img`/`.img.gz` of an Analyze/NIfTI pair whose `.hdr` is also
/// given: the pair is one volume (dropping both parts opens it once).
fn without_pair_images(files: &[PathBuf]) -> Vec<PathBuf> {
    // (folder, lower-case stem, is the image part) of a pair's file.
    fn part(p: &Path) -> Option<(Option<&Path>, String, bool)> {
        let n = name_of(p)?.to_ascii_lowercase();
        [
            (".img", true),
            (".img.gz", true),
            (".hdr", false),
            (".hdr.gz", false),
        ]
        .iter()
        .find_map(|(e, image)| Some((p.parent(), n.strip_suffix(e)?.to_owned(), *image)))
    }
    let headers: Vec<_> = files
        .iter()
        .filter_map(|f| part(f))
        .filter(|(_, _, image)| !image)
        .map(|(dir, stem, _)| (dir, stem))
        .collect();
    files
        .iter()
        .filter(|f| match part(f) {
            Some((dir, stem, true)) => !headers.contains(&(dir, stem)),
            _ => true,
        })
        .cloned()
        .collect()
}

/// Groups `files` (see the module docs). Empty input gives an empty list.
pub fn group_files(files: &[PathBuf]) -> FileGroup {
    let files = &without_pair_images(files)[..];
    let list = |reason: &str| FileGroup::List {
        files: files.to_vec(),
        reason: reason.to_owned(),
    };
    match files {
        [] => return list("no files"),
        [one] => return FileGroup::Single(one.clone()),
        _ => {}
    }
    let kinds: BTreeSet<&str> = files.iter().map(|f| detect_kind(f).name()).collect();
    if kinds.len() > 1 {
        return list("the files are of different kinds (grid, mesh, .isot)");
    }
    if detect_kind(&files[0]) == SceneKind::Ooc {
        return list(".isot files do not form time series");
    }
    let dir = files[0].parent();
    if files.iter().any(|f| f.parent() != dir) {
        return list("the files are in different folders");
    }
    let Some(names) = files
        .iter()
        .map(|f| name_of(f))
        .collect::<Option<Vec<&str>>>()
    else {
        return list("a file name is not valid UTF-8");
    };
    // Common prefix and suffix, without digits: the rest of every name must be a number.
    let first = names[0];
    let mut prefix = first.len();
    let mut suffix = first.len();
    for n in &names[1..] {
        prefix = prefix.min(
            first
                .bytes()
                .zip(n.bytes())
                .take_while(|(a, b)| a == b)
                .count(),
        );
        suffix = suffix.min(
            first
                .bytes()
                .rev()
                .zip(n.bytes().rev())
                .take_while(|(a, b)| a == b)
                .count(),
        );
    }
    while !first.is_char_boundary(prefix) {
        prefix -= 1;
    }
    while !first.is_char_boundary(first.len() - suffix) {
        suffix -= 1;
    }
    let pre = first[..prefix].trim_end_matches(|c: char| c.is_ascii_digit());
    let post = first[first.len() - suffix..].trim_start_matches(|c: char| c.is_ascii_digit());
    let numbered = names.iter().all(|n| {
        n.len() > pre.len() + post.len()
            && n.starts_with(pre)
            && n.ends_with(post)
            && n[pre.len()..n.len() - post.len()]
                .bytes()
                .all(|b| b.is_ascii_digit())
    });
    if !numbered {
        return list("the file names do not differ only in a number");
    }
    let pattern = dir.unwrap_or(Path::new("")).join(format!("{pre}*{post}"));
    // The pattern must match exactly the given files (not more siblings). By name: the
    // folder is the same, and a relative one comes back as `./name` from the listing.
    let given: BTreeSet<&str> = names.iter().copied().collect();
    match formats::series::expand_pattern(&pattern) {
        Ok(found)
            if found
                .iter()
                .filter_map(|f| name_of(f))
                .collect::<BTreeSet<_>>()
                == given =>
        {
            FileGroup::Series {
                pattern,
                steps: files.len(),
            }
        }
        Ok(_) => list(&format!(
            "the folder holds other files matching {pre}*{post}; open that pattern to see them all"
        )),
        Err(e) => list(&e.to_string()),
    }
}

/// `path` made absolute, so that the recent-files list and saved sessions name the same file
/// from any working directory: its name under its canonical folder (`..` and linked folders
/// resolved). The name itself is kept, not resolved: a link `x.nrrd` to another file stays
/// `x.nrrd`, the name the user chose and errors should quote. A series pattern
/// (`blob_*.nrrd`) or a missing file is handled alike; a path without a name (`..`) is
/// canonicalized, else joined to the working directory.
pub fn absolute_path(path: &Path) -> PathBuf {
    let in_canonical_dir = path.file_name().and_then(|name| {
        let dir = path.parent().filter(|d| !d.as_os_str().is_empty());
        std::fs::canonicalize(dir.unwrap_or(Path::new(".")))
            .ok()
            .map(|d| d.join(name))
    });
    in_canonical_dir
        .or_else(|| std::fs::canonicalize(path).ok())
        .or_else(|| std::path::absolute(path).ok())
        .unwrap_or_else(|| path.to_path_buf())
}

/// Bytes of a `.json` file [`is_session_file`] reads at most: sessions are a few KiB, and
/// serde writes `version` and `files` first.
const SESSION_PROBE_BYTES: u64 = 64 * 1024;

/// The largest session file read (a session lists files and settings: kilobytes).
pub const MAX_SESSION_BYTES: u64 = 16 << 20;

/// Session files on disk (kept out of `state.rs`, which is plain data).
impl ViewerState {
    /// Writes the session through `crate::output` (atomic; an existing file is replaced, as a
    /// save dialog asked; an input data file never is).
    pub fn save(&self, path: &Path) -> Result<(), String> {
        crate::output::save_text(path, &self.to_json(), formats::output::Replace::Allow)
            .map_err(|e| crate::cli::error_text(&e))
    }

    /// Reads a session: a regular file of at most [`MAX_SESSION_BYTES`], not recorded as an
    /// input, so that Save can replace the session it came from.
    pub fn load(path: &Path) -> Result<Self, String> {
        let text = formats::input::read_settings_to_string(path, MAX_SESSION_BYTES)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        Self::from_json(&text).map_err(|e| format!("{}: {e}", path.display()))
    }
}

/// A `.json` file holding a viewer session (a `version` and at least one of the session's
/// sections), not a raw file's layout sidecar. Reads at most the first 64 KiB: a file that
/// fits is parsed; in a longer one the keys are looked for as text.
pub fn is_session_file(path: &Path) -> bool {
    const SECTIONS: [&str; 3] = ["files", "surfaces", "camera"];
    let is_json = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("json"));
    if !is_json {
        return false;
    }
    let mut prefix = Vec::new();
    // Regular files only: a FIFO named `x.json` would block the viewer.
    let read = formats::input::open_settings(path)
        .and_then(|f| f.take(SESSION_PROBE_BYTES + 1).read_to_end(&mut prefix));
    if read.is_err() {
        return false;
    }
    if prefix.len() as u64 <= SESSION_PROBE_BYTES {
        return serde_json::from_slice::<serde_json::Value>(&prefix).is_ok_and(|v| {
            v.get("version").is_some() && SECTIONS.iter().any(|k| v.get(k).is_some())
        });
    }
    let text = String::from_utf8_lossy(&prefix);
    let has_key = |k: &str| text.contains(&format!("\"{k}\""));
    text.trim_start().starts_with('{') && has_key("version") && SECTIONS.iter().any(|k| has_key(k))
}

/// A raw file needs its layout from the user unless a sidecar (`NAME.json` or
/// `NAME.raw.json`) gives it.
pub fn needs_raw_dialog(path: &Path) -> bool {
    let is_raw = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "raw" | "bin" | "dat"));
    // The same sidecar lookup as the reader (`NAME.json`, else `NAME.raw.json`): a file that
    // `isoscope render` opens by its sidecar opens in the viewer without the dialog.
    is_raw && formats::raw::sidecar_path(path).is_none()
}

/// Voxel types tried when guessing a raw layout, in order: 8-bit, 16-bit signed (CT), 32-bit
/// float, 64-bit float.
pub const GUESS_TYPES: [volume_core::VoxelType; 4] = [
    volume_core::VoxelType::U8,
    volume_core::VoxelType::I16,
    volume_core::VoxelType::F32,
    volume_core::VoxelType::F64,
];

/// Slice widths tried after cubes (square slices of common scanner and simulation sizes).
pub const GUESS_SLICE_SIDES: [usize; 7] = [512, 256, 1024, 128, 64, 2048, 32];

/// Every `[nx, ny, nz]` × voxel type that `bytes` of voxels fill exactly: cubes first, then
/// square slices of [`GUESS_SLICE_SIDES`] with 1 to 4·side slices; each type in
/// [`GUESS_TYPES`] order.
pub fn raw_shapes_for_size(bytes: u64) -> Vec<([usize; 3], volume_core::VoxelType)> {
    let mut fits = Vec::new();
    for t in GUESS_TYPES {
        let size = t.size_bytes() as u64;
        if bytes == 0 || !bytes.is_multiple_of(size) {
            continue;
        }
        let voxels = bytes / size;
        let side = (voxels as f64).cbrt().round() as u64;
        if side >= 2 && side * side * side == voxels {
            fits.push(([side as usize; 3], t));
        }
    }
    for t in GUESS_TYPES {
        let size = t.size_bytes() as u64;
        if !bytes.is_multiple_of(size) {
            continue;
        }
        let voxels = bytes / size;
        for side in GUESS_SLICE_SIDES {
            let slice = (side * side) as u64;
            let slices = voxels / slice;
            let shape = ([side, side, slices as usize], t);
            if voxels.is_multiple_of(slice)
                && (1..=4 * side as u64).contains(&slices)
                && !fits.contains(&shape)
            {
                fits.push(shape);
            }
        }
    }
    fits
}

/// The raw dialog's starting layout for `path`, and a sentence saying where it came from:
/// the file's sidecar (`NAME.json` or `NAME.raw.json`) when it parses, else the first of
/// [`raw_shapes_for_size`] (little-endian, no header, unit spacing), else the default. Reads
/// the file's size and at most the small sidecar.
pub fn guess_raw_layout(path: &Path) -> (RawLayoutState, String) {
    if let Some(sidecar) = formats::raw::sidecar_path(path)
        && let Ok(l) = formats::raw::RawLayout::from_sidecar(&sidecar)
    {
        let layout = RawLayoutState {
            dims: l.dims,
            voxel_type: l.voxel_type.to_string(),
            little_endian: l.endian == formats::raw::Endian::Little,
            header_bytes: l.header_bytes,
            spacing: l.spacing,
        };
        let name = sidecar.file_name().unwrap_or_default().to_string_lossy();
        return (layout, format!("from the sidecar {name}"));
    }
    let Ok(bytes) = std::fs::metadata(path).map(|m| m.len()) else {
        return (
            RawLayoutState::default(),
            "the file cannot be read: enter the layout".to_string(),
        );
    };
    let shape = |(d, t): &([usize; 3], volume_core::VoxelType)| {
        format!("{} × {} × {} {t}", d[0], d[1], d[2])
    };
    let fits = raw_shapes_for_size(bytes);
    let Some(first) = fits.first() else {
        return (
            RawLayoutState::default(),
            format!(
                "the file size ({bytes} bytes) fits no common shape (a header?): enter the layout"
            ),
        );
    };
    let layout = RawLayoutState {
        dims: first.0,
        voxel_type: first.1.to_string(),
        ..RawLayoutState::default()
    };
    let others: Vec<String> = fits[1..].iter().take(3).map(shape).collect();
    let also = if others.is_empty() {
        String::new()
    } else {
        format!("; also fits {}", others.join(", "))
    };
    let note = format!(
        "guessed from the file size ({bytes} bytes): {}, little-endian, no header{also}. \
         Check before opening.",
        shape(first)
    );
    (layout, note)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn touch(dir: &Path, names: &[&str]) -> Vec<PathBuf> {
        names
            .iter()
            .map(|n| {
                let p = dir.join(n);
                std::fs::write(&p, b"x").unwrap();
                p
            })
            .collect()
    }

    #[test]
    fn paths_become_absolute_from_any_working_directory() {
        let dir = tempfile::tempdir().unwrap();
        let file = touch(dir.path(), &["a.nrrd"]).remove(0);
        let canonical_dir = std::fs::canonicalize(dir.path()).unwrap();
        // `..` and a symbolic-link-free detour resolve to the canonical file.
        let detour = dir
            .path()
            .join("..")
            .join(dir.path().file_name().unwrap())
            .join("a.nrrd");
        assert_eq!(absolute_path(&detour), canonical_dir.join("a.nrrd"));
        assert_eq!(absolute_path(&file), canonical_dir.join("a.nrrd"));
        // A link keeps its own name (errors quote what the user opened).
        #[cfg(unix)]
        {
            let link = dir.path().join("link.nrrd");
            std::os::unix::fs::symlink(&file, &link).unwrap();
            assert_eq!(absolute_path(&link), canonical_dir.join("link.nrrd"));
        }
        // A pattern (no such file): its name under the canonical folder.
        let pattern = dir.path().join("blob_*.nrrd");
        assert_eq!(absolute_path(&pattern), canonical_dir.join("blob_*.nrrd"));
        // A relative name: under the working directory.
        let cwd = std::fs::canonicalize(std::env::current_dir().unwrap()).unwrap();
        assert_eq!(
            absolute_path(Path::new("no-such-file.nrrd")),
            cwd.join("no-such-file.nrrd")
        );
    }

    #[test]
    fn raw_layouts_are_guessed_from_the_sidecar_else_the_file_size() {
        // 40³ two-byte voxels: not a u8 cube (128000 is not a cube), an i16 one.
        let fits = raw_shapes_for_size(40 * 40 * 40 * 2);
        assert_eq!(fits[0], ([40; 3], volume_core::VoxelType::I16));
        // 256 × 256 × 108 i16 (no cube of any type).
        let fits = raw_shapes_for_size(256 * 256 * 108 * 2);
        assert!(
            fits.contains(&([256, 256, 108], volume_core::VoxelType::I16)),
            "{fits:?}"
        );
        // Every fit fills the size exactly.
        for (d, t) in &fits {
            assert_eq!(
                (d[0] * d[1] * d[2] * t.size_bytes()) as u64,
                256 * 256 * 108 * 2
            );
        }
        assert!(raw_shapes_for_size(1_000_003).is_empty());

        let dir = tempfile::tempdir().unwrap();
        let raw = dir.path().join("v.raw");
        std::fs::write(&raw, vec![0u8; 40 * 40 * 40 * 2]).unwrap();
        let (layout, note) = guess_raw_layout(&raw);
        assert_eq!((layout.dims, layout.voxel_type.as_str()), ([40; 3], "i16"));
        assert!(note.contains("file size (128000 bytes)"), "{note}");
        std::fs::write(
            dir.path().join("v.json"),
            r#"{"dims": [20, 40, 80], "type": "u16", "endian": "big", "spacing": [1, 2, 3]}"#,
        )
        .unwrap();
        let (layout, note) = guess_raw_layout(&raw);
        assert_eq!(layout.dims, [20, 40, 80]);
        assert_eq!(
            (layout.voxel_type.as_str(), layout.little_endian),
            ("u16", false)
        );
        assert_eq!(layout.spacing, [1.0, 2.0, 3.0]);
        assert!(note.contains("v.json"), "{note}");
    }

    #[test]
    fn an_analyze_or_nifti_pair_opens_once() {
        let dir = tempfile::tempdir().unwrap();
        let pair = touch(dir.path(), &["t1.img", "t1.hdr"]);
        assert_eq!(group_files(&pair), FileGroup::Single(pair[1].clone()));
        let gz = touch(dir.path(), &["b.hdr.gz", "b.img.gz"]);
        assert_eq!(group_files(&gz), FileGroup::Single(gz[0].clone()));
        // Two pairs of a numbered series: the headers form the series.
        let series = touch(
            dir.path(),
            &["s_01.hdr", "s_01.img", "s_02.hdr", "s_02.img"],
        );
        assert!(matches!(
            group_files(&series),
            FileGroup::Series { steps: 2, .. }
        ));
    }

    #[test]
    fn numbered_files_form_a_series_and_others_a_list() {
        let dir = tempfile::tempdir().unwrap();
        let steps = touch(dir.path(), &["run_009.vtu", "run_010.vtu", "run_011.vtu"]);
        assert_eq!(
            group_files(&steps),
            FileGroup::Series {
                pattern: dir.path().join("run_*.vtu"),
                steps: 3
            }
        );
        assert_eq!(
            group_files(&steps[..1]),
            FileGroup::Single(steps[0].clone())
        );
        // A subset of the numbered files: the pattern would match more.
        assert!(matches!(
            group_files(&steps[..2]),
            FileGroup::List { reason, .. } if reason.contains("other files")
        ));
        let mixed = touch(dir.path(), &["a.nrrd", "b.vtu"]);
        assert!(matches!(
            group_files(&mixed),
            FileGroup::List { reason, .. } if reason.contains("kinds")
        ));
        let named = touch(dir.path(), &["head.nrrd", "knee.nrrd"]);
        assert!(matches!(
            group_files(&named),
            FileGroup::List { reason, .. } if reason.contains("number")
        ));
    }

    #[test]
    fn raw_extensions_need_the_dialog_unless_a_sidecar_exists() {
        let dir = tempfile::tempdir().unwrap();
        let raw = dir.path().join("ct.raw");
        assert!(needs_raw_dialog(&raw));
        std::fs::write(dir.path().join("ct.json"), "{}").unwrap();
        assert!(!needs_raw_dialog(&raw));
        assert!(!needs_raw_dialog(Path::new("a.nrrd")));
        assert!(needs_raw_dialog(Path::new("x/VOL.RAW")));
        // `NAME.raw.json`, which the reader also takes (the dialog used to open for it).
        let other = dir.path().join("mr.raw");
        assert!(needs_raw_dialog(&other));
        std::fs::write(dir.path().join("mr.raw.json"), "{}").unwrap();
        assert!(!needs_raw_dialog(&other));
    }

    #[test]
    fn sessions_are_told_from_sidecars_by_a_bounded_read() {
        let dir = tempfile::tempdir().unwrap();
        let session = dir.path().join("s.json");
        std::fs::write(&session, r#"{"version": 1, "files": ["a.nrrd"]}"#).unwrap();
        assert!(is_session_file(&session));
        let sidecar = dir.path().join("ct.json");
        std::fs::write(&sidecar, r#"{"dims": [4, 4, 4], "voxel_type": "u8"}"#).unwrap();
        assert!(!is_session_file(&sidecar));
        // Longer than the probe: judged by the keys in the prefix.
        let padding = " ".repeat(SESSION_PROBE_BYTES as usize);
        let long = dir.path().join("long.json");
        std::fs::write(
            &long,
            format!(r#"{{"version": 1, "camera": {{}}, "pad": "{padding}"}}"#),
        )
        .unwrap();
        assert!(is_session_file(&long));
        assert!(!is_session_file(&dir.path().join("missing.json")));
        assert!(!is_session_file(Path::new("a.nrrd")));
    }
}
