//! Writing output files without losing data: one mechanism for every writer, command and
//! viewer save.
//!
//! [`OutputFile::create`] checks the target before anything is written:
//! - it must not be one of the files an input reads ([`crate::input::input_matching`]: data
//!   files, detached and `LIST` files, sidecars, series and `.pvd` steps, mesh partners,
//!   `.isot`), compared by device and inode (hard and symbolic links) and by resolved path;
//! - an existing file is replaced only with [`Replace::Allow`] (the CLI's `--force`, or a save
//!   dialog that asked), and it must be a regular file: `/dev/full` or a directory is refused,
//!   never renamed over;
//! - a symbolic link is written through (its target is replaced), as `cp` does.
//!
//! The bytes go to a temporary file in the target's folder (so the final rename stays on one
//! file system), created with mode 0666 minus the umask like any new file. [`OutputFile::commit`]
//! syncs it, checks its length against the bytes written, and renames it over the target
//! (without replacing a file that appeared meanwhile, unless allowed), then syncs the folder.
//! Any failure — a full disk, a file-size limit, a write error the encoder only sees at its
//! final flush — is returned as an error and leaves no partial output: the temporary file is
//! removed when the [`OutputFile`] is dropped uncommitted.

use std::fs::File;
use std::io::{self, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use crate::FormatError;
use crate::input::{input_matching, resolved_path};

/// Whether an existing output may be replaced.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Replace {
    /// An existing file is an error ([`FormatError::OutputExists`]).
    #[default]
    Refuse,
    /// An existing regular file is replaced (atomically, when the new one is complete).
    Allow,
}

impl Replace {
    /// `Allow` when `force` is set (the CLI's `--force`).
    pub fn from_force(force: bool) -> Self {
        if force {
            Replace::Allow
        } else {
            Replace::Refuse
        }
    }
}

/// Checks that `path` may be written under `replace` (see the module docs), and returns the
/// path to write: `path` itself, or the target of a symbolic link.
pub fn check_output(path: &Path, replace: Replace) -> Result<PathBuf, FormatError> {
    let bad = |reason: &str| FormatError::BadOutput {
        path: path.to_path_buf(),
        reason: reason.to_owned(),
    };
    if path.file_name().is_none() {
        return Err(bad("is not a file name"));
    }
    let target = match std::fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_symlink() => match std::fs::canonicalize(path) {
            Ok(t) => t,
            Err(_) => return Err(bad("is a symbolic link to a missing file or folder")),
        },
        _ => path.to_path_buf(),
    };
    if let Some(input) = input_matching(&target) {
        return Err(FormatError::OutputIsInput {
            path: path.to_path_buf(),
            input,
        });
    }
    match std::fs::metadata(&target) {
        Ok(meta) => {
            if !meta.is_file() {
                let kind =
                    crate::input::special_kind(meta.file_type()).unwrap_or("not a regular file");
                return Err(bad(&format!("is {kind}; outputs must be regular files")));
            }
            if replace == Replace::Refuse {
                return Err(FormatError::OutputExists {
                    path: path.to_path_buf(),
                });
            }
        }
        Err(e) if e.kind() == io::ErrorKind::NotFound => {}
        Err(e) => return Err(FormatError::io(path, e)),
    }
    Ok(target)
}

/// Checks that no two of `paths` name the same file (e.g. `-o` and `--depth-out`).
pub fn check_distinct(paths: &[&Path]) -> Result<(), FormatError> {
    let resolved: Vec<PathBuf> = paths.iter().map(|p| resolved_path(p)).collect();
    for (i, a) in resolved.iter().enumerate() {
        if let Some(j) = resolved[..i].iter().position(|b| b == a) {
            return Err(FormatError::BadOutput {
                path: paths[i].to_path_buf(),
                reason: format!(
                    "is also the output {}; give each output its own file",
                    paths[j].display()
                ),
            });
        }
    }
    Ok(())
}

/// An output being written: a temporary file, renamed over the target by [`Self::commit`].
/// Implements [`Write`] and [`Seek`] (unbuffered: wrap it in a `BufWriter` for small writes).
#[derive(Debug)]
pub struct OutputFile {
    /// As the caller named it (for messages).
    path: PathBuf,
    /// Where it goes (the target of a symbolic link).
    target: PathBuf,
    replace: Replace,
    tmp: tempfile::NamedTempFile,
    /// The highest offset written (the file's expected length).
    end: u64,
    pos: u64,
}

impl OutputFile {
    /// Checks the target ([`check_output`]) and creates the temporary file beside it.
    pub fn create(path: &Path, replace: Replace) -> Result<Self, FormatError> {
        let target = check_output(path, replace)?;
        let dir = match target.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        let name = target
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let prefix = format!(".{name}.");
        let mut builder = tempfile::Builder::new();
        builder.prefix(&prefix).suffix(".tmp");
        // tempfile's default is 0600; a finished output gets the mode of any new file (0666
        // minus the umask, applied by the kernel at creation).
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt as _;
            builder.permissions(std::fs::Permissions::from_mode(0o666));
        }
        let tmp = builder
            .tempfile_in(dir)
            .map_err(|e| FormatError::io(path, e))?;
        Ok(Self {
            path: path.to_path_buf(),
            target,
            replace,
            tmp,
            end: 0,
            pos: 0,
        })
    }

    /// The path as given to [`Self::create`].
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The temporary file (e.g. to set its length).
    pub fn file(&self) -> &File {
        self.tmp.as_file()
    }

    /// Syncs, checks and renames the file into place (see the module docs).
    pub fn commit(self) -> Result<(), FormatError> {
        let io = |e: io::Error| FormatError::io(&self.path, e);
        let file = self.tmp.as_file();
        file.sync_all().map_err(io)?;
        let len = file.metadata().map_err(io)?.len();
        if len < self.end {
            return Err(FormatError::io(
                &self.path,
                io::Error::other(format!(
                    "holds {len} bytes after writing {} (the write was cut short)",
                    self.end
                )),
            ));
        }
        // An input opened since `create` (the viewer loads in the background) still counts.
        if let Some(input) = input_matching(&self.target) {
            return Err(FormatError::OutputIsInput {
                path: self.path.clone(),
                input,
            });
        }
        let persisted = match self.replace {
            Replace::Allow => self.tmp.persist(&self.target),
            Replace::Refuse => self.tmp.persist_noclobber(&self.target),
        };
        if let Err(e) = persisted {
            return Err(if e.error.kind() == io::ErrorKind::AlreadyExists {
                FormatError::OutputExists { path: self.path }
            } else {
                FormatError::io(&self.path, e.error)
            });
        }
        sync_folder(&self.target).map_err(|e| FormatError::io(&self.path, e))
    }
}

/// Makes the rename durable (Unix: fsync the folder).
fn sync_folder(target: &Path) -> io::Result<()> {
    #[cfg(unix)]
    {
        let dir = match target.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        File::open(dir)?.sync_all()
    }
    #[cfg(not(unix))]
    {
        let _ = target;
        Ok(())
    }
}

impl Write for OutputFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.tmp.as_file().write(buf)?;
        self.pos += n as u64;
        self.end = self.end.max(self.pos);
        Ok(n)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.tmp.as_file().flush()
    }
}

impl Seek for OutputFile {
    fn seek(&mut self, to: SeekFrom) -> io::Result<u64> {
        self.pos = self.tmp.as_file().seek(to)?;
        Ok(self.pos)
    }
}

/// Writes `bytes` to `path` as one output ([`OutputFile`]).
pub fn write_output(path: &Path, bytes: &[u8], replace: Replace) -> Result<(), FormatError> {
    let mut out = OutputFile::create(path, replace)?;
    out.write_all(bytes).map_err(|e| FormatError::io(path, e))?;
    out.commit()
}

/// Streams an output through `write` into a buffered [`OutputFile`], then commits it; an
/// error from `write` or from the final flush leaves no file.
pub fn write_output_with<E>(
    path: &Path,
    replace: Replace,
    write: impl FnOnce(&mut io::BufWriter<&mut OutputFile>) -> Result<(), E>,
) -> Result<(), E>
where
    E: From<FormatError>,
{
    let mut out = OutputFile::create(path, replace)?;
    {
        let mut w = io::BufWriter::with_capacity(1 << 20, &mut out);
        write(&mut w)?;
        w.flush().map_err(|e| FormatError::io(path, e))?;
    }
    out.commit().map_err(E::from)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn leftovers(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.to_ascii_lowercase().ends_with(".tmp"))
            .collect()
    }

    #[test]
    fn new_output_is_written_with_the_mode_of_any_new_file() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("a.bin");
        write_output(&out, b"hello", Replace::Refuse).unwrap();
        assert_eq!(std::fs::read(&out).unwrap(), b"hello");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt as _;
            let reference = dir.path().join("reference");
            File::create(&reference).unwrap();
            let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
            assert_eq!(mode(&out), mode(&reference));
        }
        assert!(leftovers(dir.path()).is_empty());
    }

    #[test]
    fn existing_output_is_replaced_only_when_allowed() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("a.txt");
        std::fs::write(&out, b"old").unwrap();
        let e = write_output(&out, b"new", Replace::Refuse).unwrap_err();
        assert!(matches!(e, FormatError::OutputExists { .. }), "{e}");
        assert!(e.to_string().contains("--force"), "{e}");
        assert_eq!(std::fs::read(&out).unwrap(), b"old");
        write_output(&out, b"new", Replace::Allow).unwrap();
        assert_eq!(std::fs::read(&out).unwrap(), b"new");
    }

    #[test]
    fn an_input_is_never_an_output_by_path_or_by_link() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.dat");
        std::fs::write(&input, b"data").unwrap();
        crate::input::read_regular(&input).unwrap();
        let e = write_output(&input, b"x", Replace::Allow).unwrap_err();
        match &e {
            FormatError::OutputIsInput { path, input: named } => {
                assert_eq!(path, &input);
                assert_eq!(named, &std::fs::canonicalize(&input).unwrap());
            }
            other => panic!("{other}"),
        }
        #[cfg(unix)]
        {
            let hard = dir.path().join("hard.dat");
            std::fs::hard_link(&input, &hard).unwrap();
            let e = write_output(&hard, b"x", Replace::Allow).unwrap_err();
            assert!(matches!(e, FormatError::OutputIsInput { .. }), "{e}");
            let soft = dir.path().join("soft.dat");
            std::os::unix::fs::symlink(&input, &soft).unwrap();
            let e = write_output(&soft, b"x", Replace::Allow).unwrap_err();
            assert!(matches!(e, FormatError::OutputIsInput { .. }), "{e}");
        }
        assert_eq!(std::fs::read(&input).unwrap(), b"data");
    }

    #[test]
    fn a_noted_input_counts_before_it_is_read() {
        let dir = tempfile::tempdir().unwrap();
        let later = dir.path().join("step_001.nrrd");
        std::fs::write(&later, b"later").unwrap();
        crate::input::note_input(&later);
        let e = write_output(&later, b"x", Replace::Allow).unwrap_err();
        assert!(matches!(e, FormatError::OutputIsInput { .. }), "{e}");
    }

    #[test]
    fn a_removed_input_whose_name_is_reused_is_not_an_input() {
        // The identity must still hold under the recorded path: an inode freed and reused
        // by an unrelated file does not make that file an input.
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("gone.dat");
        std::fs::write(&input, b"data").unwrap();
        crate::input::read_regular(&input).unwrap();
        std::fs::remove_file(&input).unwrap();
        let other = dir.path().join("other.dat");
        std::fs::write(&other, b"other").unwrap();
        write_output(&other, b"x", Replace::Allow).unwrap();
        assert_eq!(std::fs::read(&other).unwrap(), b"x");
    }

    #[cfg(unix)]
    #[test]
    fn special_files_and_folders_are_not_outputs() {
        for special in ["/dev/full", "/dev/null"] {
            let e = write_output(Path::new(special), b"x", Replace::Allow).unwrap_err();
            assert!(
                matches!(e, FormatError::BadOutput { .. }) && e.to_string().contains("device"),
                "{e}"
            );
        }
        let dir = tempfile::tempdir().unwrap();
        let e = write_output(dir.path(), b"x", Replace::Allow).unwrap_err();
        assert!(e.to_string().contains("directory"), "{e}");
    }

    #[test]
    fn a_failed_write_leaves_no_file() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("partial.bin");
        let r: Result<(), FormatError> = write_output_with(&out, Replace::Refuse, |w| {
            w.write_all(&[7u8; 4096])
                .map_err(|e| FormatError::io(&out, e))?;
            Err(FormatError::io(&out, io::Error::other("disk full")))
        });
        assert!(r.is_err());
        assert!(!out.exists());
        assert!(leftovers(dir.path()).is_empty());
        // A missing folder is an error naming the output.
        let e = write_output(&dir.path().join("no/such/x.bin"), b"x", Replace::Refuse).unwrap_err();
        assert!(e.to_string().contains("x.bin"), "{e}");
    }

    #[test]
    fn two_outputs_may_not_be_one_file() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a.png");
        let b = dir.path().join("./a.png");
        let e = check_distinct(&[&a, &dir.path().join("d.npy"), &b]).unwrap_err();
        assert!(e.to_string().contains("is also the output"), "{e}");
        check_distinct(&[&a, &dir.path().join("d.npy")]).unwrap();
    }
}
