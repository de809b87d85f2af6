//! Opening input files: regular files only.
//!
//! Every reader in this crate opens its files (main files, detached NRRD data files and
//! `LIST`/pattern entries, raw sidecars, series steps, TetGen partners, `.pvd` steps, `.isot`)
//! through [`open_regular`] or [`read_regular`]. They check, after following symbolic links,
//! that the path is a regular file *before* opening it: opening a FIFO for reading blocks until
//! a writer appears (a hang), and a device such as `/dev/zero` never ends (reading it exhausts
//! memory). A directory, FIFO, socket or device is an [`std::io::Error`] of kind
//! `InvalidInput` whose message says what the path is ("is a FIFO, not a regular file"); the
//! callers wrap it with the path, so the error names the file.
//!
//! The kind is checked again on the opened handle, so a path swapped for a special file between
//! the check and the open is still refused before anything is read (a FIFO swapped in at that
//! instant can still block the open itself: std has no portable non-blocking open).
//!
//! ## The input log
//! Every file opened or checked here is also recorded in a process-wide log (its path, and on
//! Unix its device and inode), and readers that list files to read later (series steps, `.pvd`
//! steps, detached NRRD data files) record those with [`note_input`] when they are opened. The
//! output writer ([`crate::output`]) refuses any output that is one of these files
//! ([`input_matching`]): same device and inode (a hard link, a symbolic link), or the same path
//! after resolution. The log is process-wide rather than passed along because inputs are read
//! on worker threads and lazily (a time step long after the open), and because one log that
//! every reader feeds through these functions cannot miss a reader added later. It only
//! grows (unless emptied by [`forget_inputs`], between unrelated inputs of a process that writes
//! nothing); an entry whose file has since been removed or replaced no longer matches.

use std::collections::HashSet;
use std::fs::{File, FileType, Metadata};
use std::io::{self, Read};
use std::path::{Path, PathBuf};
use std::sync::{LazyLock, Mutex, MutexGuard};

/// One input file: the path as resolved when it was read, and its identity.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct InputFile {
    path: PathBuf,
    id: Option<(u64, u64)>,
}

/// The log: the entries in the order they were recorded, and the same entries hashed, so that
/// recording one is not a scan of the log (a MetaImage or NRRD pattern may name a million data
/// files, each noted in turn: a scan per file took hours).
#[derive(Default)]
struct InputLog {
    order: Vec<InputFile>,
    seen: HashSet<InputFile>,
}

static INPUTS: LazyLock<Mutex<InputLog>> = LazyLock::new(Mutex::default);

fn input_log() -> MutexGuard<'static, InputLog> {
    INPUTS
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Device and inode (Unix); `None` elsewhere, where only paths are compared.
// `None` only off Unix.
#[cfg_attr(unix, allow(clippy::unnecessary_wraps))]
fn file_id(meta: &Metadata) -> Option<(u64, u64)> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt as _;
        Some((meta.dev(), meta.ino()))
    }
    #[cfg(not(unix))]
    {
        let _ = meta;
        None
    }
}

/// `path` made absolute with symbolic links resolved, as far as it exists (a missing file
/// keeps its name under its resolved folder).
pub fn resolved_path(path: &Path) -> PathBuf {
    if let Ok(p) = std::fs::canonicalize(path) {
        return p;
    }
    match (path.parent(), path.file_name()) {
        (Some(dir), Some(name)) => {
            let dir = if dir.as_os_str().is_empty() {
                Path::new(".")
            } else {
                dir
            };
            std::fs::canonicalize(dir).map_or_else(|_| path.to_path_buf(), |d| d.join(name))
        }
        _ => path.to_path_buf(),
    }
}

fn record(path: &Path, meta: Option<&Metadata>) {
    let entry = InputFile {
        path: resolved_path(path),
        id: meta.and_then(file_id),
    };
    let mut log = input_log();
    if log.seen.insert(entry.clone()) {
        log.order.push(entry);
    }
}

/// A file named inside the header at `header_path` (a detached data file): absolute names as
/// they are, relative ones beside the header.
pub(crate) fn beside(header_path: &Path, name: &str) -> PathBuf {
    let p = Path::new(name);
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        header_path.parent().unwrap_or(Path::new("")).join(p)
    }
}

/// Records `path` as an input that will be read later (a time step, a detached data file), so
/// that no output replaces it in the meantime.
pub fn note_input(path: &Path) {
    record(path, std::fs::metadata(path).ok().as_ref());
}

/// Empties the input log. For a process that reads unrelated inputs one after another and
/// writes no output in between, where each input starts as a fresh process would: the fuzz
/// targets, whose scratch files are removed and written again for every execution (a new inode
/// each time, so the log would otherwise gain entries on every execution).
pub fn forget_inputs() {
    let mut log = input_log();
    log.order.clear();
    log.seen.clear();
}

/// The recorded input that `output` would overwrite, if any: the same device and inode as an
/// input that still exists under its recorded path (so a removed input whose inode was reused
/// does not match), or the same resolved path.
pub fn input_matching(output: &Path) -> Option<PathBuf> {
    let out_path = resolved_path(output);
    let out_id = std::fs::metadata(output).ok().as_ref().and_then(file_id);
    let log = input_log();
    log.order
        .iter()
        .find(|input| {
            if input.path == out_path {
                return true;
            }
            match (out_id, input.id) {
                (Some(o), Some(i)) if o == i => {
                    std::fs::metadata(&input.path)
                        .ok()
                        .as_ref()
                        .and_then(file_id)
                        == Some(i)
                }
                _ => false,
            }
        })
        .map(|input| input.path.clone())
}

/// What a non-regular file is, for messages (`None` for a regular file).
pub(crate) fn special_kind(t: FileType) -> Option<&'static str> {
    if t.is_file() {
        return None;
    }
    if t.is_dir() {
        return Some("a directory");
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if t.is_fifo() {
            return Some("a FIFO (named pipe)");
        }
        if t.is_char_device() {
            return Some("a character device");
        }
        if t.is_block_device() {
            return Some("a block device");
        }
        if t.is_socket() {
            return Some("a socket");
        }
    }
    Some("not a file")
}

fn check(t: FileType) -> io::Result<()> {
    match special_kind(t) {
        None => Ok(()),
        Some(kind) => Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("is {kind}, not a regular file"),
        )),
    }
}

/// Checks that `path` (after following symbolic links) is a regular file, without opening it.
/// The file is recorded in the input log.
pub fn check_regular(path: &Path) -> io::Result<()> {
    let meta = std::fs::metadata(path)?;
    check(meta.file_type())?;
    record(path, Some(&meta));
    Ok(())
}

/// Opens `path` for reading if it is a regular file (see the module docs).
/// The file is recorded in the input log.
pub fn open_regular(path: &Path) -> io::Result<File> {
    check(std::fs::metadata(path)?.file_type())?;
    let file = File::open(path)?;
    let meta = file.metadata()?;
    check(meta.file_type())?;
    record(path, Some(&meta));
    Ok(file)
}

/// Reads the whole of a regular file.
pub fn read_regular(path: &Path) -> io::Result<Vec<u8>> {
    let mut file = open_regular(path)?;
    // The length is a hint only (the file may change); `read_to_end` grows as bytes arrive.
    let hint = file.metadata().as_ref().map_or(0, Metadata::len);
    let mut out = Vec::with_capacity(usize::try_from(hint).unwrap_or(0));
    file.read_to_end(&mut out)?;
    Ok(out)
}

/// Reads a regular file as UTF-8 text.
pub fn read_regular_to_string(path: &Path) -> io::Result<String> {
    String::from_utf8(read_regular(path)?)
        .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e.utf8_error()))
}

/// Opens a settings file (a viewer session) for reading if it is a regular file, without
/// recording it in the input log (see [`read_settings_to_string`]).
pub fn open_settings(path: &Path) -> io::Result<File> {
    check(std::fs::metadata(path)?.file_type())?;
    let file = File::open(path)?;
    check(file.metadata()?.file_type())?;
    Ok(file)
}

/// Reads a small settings file (a viewer session) as UTF-8 text: regular files only, at most
/// `max_bytes`, and *not* recorded in the input log, because saving a session over the
/// session it was loaded from is what "Save" means (the file is read whole and closed).
pub fn read_settings_to_string(path: &Path, max_bytes: u64) -> io::Result<String> {
    let file = open_settings(path)?;
    let mut out = Vec::new();
    file.take(max_bytes.saturating_add(1))
        .read_to_end(&mut out)?;
    if out.len() as u64 > max_bytes {
        return Err(io::Error::new(
            io::ErrorKind::InvalidData,
            format!("is larger than {max_bytes} bytes, too large for a settings file"),
        ));
    }
    String::from_utf8(out).map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e.utf8_error()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regular_files_open_and_others_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let f = dir.path().join("a.bin");
        std::fs::write(&f, b"abc").unwrap();
        assert_eq!(read_regular(&f).unwrap(), b"abc");
        let e = open_regular(dir.path()).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidInput);
        assert_eq!(e.to_string(), "is a directory, not a regular file");
        #[cfg(unix)]
        {
            let e = read_regular(Path::new("/dev/null")).unwrap_err();
            assert!(e.to_string().contains("character device"), "{e}");
        }
        assert_eq!(
            open_regular(&dir.path().join("missing"))
                .unwrap_err()
                .kind(),
            io::ErrorKind::NotFound
        );
    }
}
