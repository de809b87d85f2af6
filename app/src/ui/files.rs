//! Several files opened together (command line, drag and drop, the file dialog).
//!
//! As ParaView groups numbered files (`blob_000.nrrd`, `blob_001.nrrd`, ...) into one time
//! series, files of one kind in one folder whose names differ only in a number open as a
//! series: the viewer hands the series pattern (`blob_*.nrrd`) to
//! [`crate::scene::open_scene`], which loads steps lazily and checks that every step has the
//! first one's shape (dims and voxel type for grids, topology for meshes). Anything else
//! stays a list of files, shown one at a time.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

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

/// Groups `files` (see the module docs). Empty input gives an empty list.
pub fn group_files(files: &[PathBuf]) -> FileGroup {
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
    // The pattern must match exactly the given files (not more siblings).
    let given: BTreeSet<PathBuf> = files.iter().cloned().collect();
    match formats::series::expand_pattern(&pattern) {
        Ok(found) if found.iter().cloned().collect::<BTreeSet<_>>() == given => FileGroup::Series {
            pattern,
            steps: files.len(),
        },
        Ok(_) => list(&format!(
            "the folder holds other files matching {pre}*{post}; open that pattern to see them all"
        )),
        Err(e) => list(&e.to_string()),
    }
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
}
