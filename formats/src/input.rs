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

use std::fs::{File, FileType};
use std::io::{self, Read};
use std::path::Path;

/// What a non-regular file is, for messages (`None` for a regular file).
fn special_kind(t: FileType) -> Option<&'static str> {
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
pub fn check_regular(path: &Path) -> io::Result<()> {
    check(std::fs::metadata(path)?.file_type())
}

/// Opens `path` for reading if it is a regular file (see the module docs).
pub fn open_regular(path: &Path) -> io::Result<File> {
    check_regular(path)?;
    let file = File::open(path)?;
    check(file.metadata()?.file_type())?;
    Ok(file)
}

/// Reads the whole of a regular file.
pub fn read_regular(path: &Path) -> io::Result<Vec<u8>> {
    let mut file = open_regular(path)?;
    // The length is a hint only (the file may change); `read_to_end` grows as bytes arrive.
    let hint = file.metadata().as_ref().map_or(0, std::fs::Metadata::len);
    let mut out = Vec::with_capacity(usize::try_from(hint).unwrap_or(0));
    file.read_to_end(&mut out)?;
    Ok(out)
}

/// Reads a regular file as UTF-8 text.
pub fn read_regular_to_string(path: &Path) -> io::Result<String> {
    String::from_utf8(read_regular(path)?)
        .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e.utf8_error()))
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
