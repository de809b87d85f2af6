//! Time series of volume files: numbered files and globs.
//!
//! [`FileSeries`] is a [`StepLoader`] that loads one step on demand: one volume file per
//! step, from a printf pattern (`vol_%03d.nrrd`, the files that exist, in numeric order) or a
//! glob on the file name (`vol_*.nrrd`, natural order: `vol_2` before `vol_10`). The steps of
//! a 4D NRRD (or of a detached header with one data file per step) are
//! [`crate::nrrd::NrrdSteps`], next to the rest of NRRD.
//!
//! Step 0 is loaded when the series is opened, so a broken first file is reported with its
//! specific [`FormatError`]; later steps report theirs as text through the loader interface.

use std::cmp::Ordering;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use volume_core::RectilinearVolume;
use volume_core::series::{StepLoader, TimeSeries};

use crate::error::FormatError;
use crate::nrrd::header::format_printf;
use crate::{Dataset, FirstStep, OpenOptions};

/// One volume file per step.
pub struct FileSeries {
    pattern: PathBuf,
    files: Vec<PathBuf>,
    options: OpenOptions,
    first: FirstStep,
    /// Step 0's dims and voxel type: a later step that differs is refused naming both files.
    first_shape: ([usize; 3], volume_core::VoxelType),
}

impl FileSeries {
    /// The series of the files matching `pattern` (printf `%d` or glob `*`/`?` in the file
    /// name); step 0 is loaded now.
    pub fn open(pattern: &Path, options: &OpenOptions) -> Result<Self, FormatError> {
        let files = expand_pattern(pattern)?;
        // Later steps load lazily; no output may replace them meanwhile.
        for f in &files {
            crate::input::note_input(f);
        }
        let first = load_file(&files[0], options)?;
        Ok(Self {
            pattern: pattern.to_path_buf(),
            files,
            options: options.clone(),
            first_shape: (first.dims(), first.data.voxel_type()),
            first: FirstStep::new(first),
        })
    }

    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }
}

fn load_file(path: &Path, options: &OpenOptions) -> Result<RectilinearVolume, FormatError> {
    match crate::open_file(path, options)? {
        Dataset::Volume(v) => Ok(v),
        Dataset::Series(_) => Err(FormatError::Series {
            path: path.to_path_buf(),
            reason: "a step file is itself a time series".into(),
        }),
    }
}

impl StepLoader for FileSeries {
    fn step_count(&self) -> usize {
        self.files.len()
    }

    fn load_step(&self, step: usize) -> Result<RectilinearVolume, String> {
        if step == 0
            && let Some(v) = self.first.take()
        {
            return Ok(v);
        }
        let path = self
            .files
            .get(step)
            .ok_or_else(|| format!("step {step} out of range"))?;
        let v = load_file(path, &self.options).map_err(|e| e.to_string())?;
        let (dims, ty) = self.first_shape;
        if (v.dims(), v.data.voxel_type()) != (dims, ty) {
            return Err(format!(
                "{}: {:?} {} differs from step 0 ({}: {dims:?} {ty})",
                path.display(),
                v.dims(),
                v.data.voxel_type(),
                self.files[0].display()
            ));
        }
        Ok(v)
    }

    fn describe(&self) -> String {
        format!(
            "{} files matching {}",
            self.files.len(),
            self.pattern.display()
        )
    }
}

/// Opens a numbered-file series as a [`TimeSeries`].
pub fn open_file_series(pattern: &Path, options: &OpenOptions) -> Result<TimeSeries, FormatError> {
    let loader = FileSeries::open(pattern, options)?;
    TimeSeries::open(Arc::new(loader)).map_err(|e| FormatError::Series {
        path: pattern.to_path_buf(),
        reason: e.to_string(),
    })
}

/// True if the file name of `path` is a series pattern (`%d`-style or a glob).
pub fn is_pattern(path: &Path) -> bool {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    name.contains('*') || name.contains('?') || printf_parts(&name).is_some()
}

/// Splits `vol_%03d.nrrd` into (`vol_`, `%03d`, `.nrrd`) if it has one integer conversion.
fn printf_parts(name: &str) -> Option<(&str, &str, &str)> {
    let start = name.find('%')?;
    let rest = &name[start + 1..];
    let spec_len = rest.find(|c: char| !(c.is_ascii_digit() || c == '-' || c == '+'))?;
    let conv = rest[spec_len..].chars().next()?;
    if !matches!(conv, 'd' | 'i' | 'u') {
        return None;
    }
    let end = start + 1 + spec_len + 1;
    let suffix = &name[end..];
    if suffix.contains('%') {
        return None;
    }
    Some((&name[..start], &name[start..end], suffix))
}

/// The files a pattern names, in step order. Errors if none match.
pub fn expand_pattern(pattern: &Path) -> Result<Vec<PathBuf>, FormatError> {
    let err = |reason: String| FormatError::Series {
        path: pattern.to_path_buf(),
        reason,
    };
    let name = pattern
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| err("no file name".into()))?;
    let dir = match pattern.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if dir.to_string_lossy().contains(['*', '?']) {
        return Err(err("wildcards are only supported in the file name".into()));
    }
    let entries = std::fs::read_dir(&dir).map_err(|e| FormatError::io(&dir, e))?;
    let mut names = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| FormatError::io(&dir, e))?;
        if entry
            .file_type()
            .is_ok_and(|t| t.is_file() || t.is_symlink())
        {
            names.push(entry.file_name().to_string_lossy().into_owned());
        }
    }
    let mut matched: Vec<String> = if let Some((prefix, spec, suffix)) = printf_parts(&name) {
        let mut numbered: Vec<(i64, String)> = names
            .into_iter()
            .filter_map(|n| {
                let middle = n.strip_prefix(prefix)?.strip_suffix(suffix)?;
                let num: i64 = middle.trim_start().parse().ok()?;
                (format_printf(spec, num) == middle).then_some((num, n))
            })
            .collect();
        numbered.sort();
        numbered.into_iter().map(|(_, n)| n).collect()
    } else if name.contains(['*', '?']) {
        let mut m: Vec<String> = names.into_iter().filter(|n| glob_match(&name, n)).collect();
        m.sort_by(|a, b| natural_cmp(a, b));
        m
    } else {
        return Err(err("not a pattern (use %03d or *)".into()));
    };
    if matched.is_empty() {
        return Err(err(format!("no files match in {}", dir.display())));
    }
    Ok(matched.drain(..).map(|n| dir.join(n)).collect())
}

/// `*` matches any run, `?` one character.
fn glob_match(pattern: &str, name: &str) -> bool {
    let p: Vec<char> = pattern.chars().collect();
    let n: Vec<char> = name.chars().collect();
    let (mut pi, mut ni) = (0, 0);
    let (mut star, mut mark) = (None, 0);
    while ni < n.len() {
        if pi < p.len() && (p[pi] == '?' || p[pi] == n[ni]) {
            pi += 1;
            ni += 1;
        } else if pi < p.len() && p[pi] == '*' {
            star = Some(pi);
            mark = ni;
            pi += 1;
        } else if let Some(s) = star {
            pi = s + 1;
            mark += 1;
            ni = mark;
        } else {
            return false;
        }
    }
    while pi < p.len() && p[pi] == '*' {
        pi += 1;
    }
    pi == p.len()
}

/// Natural order: digit runs compare as numbers (`a2` < `a10`).
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (mut a, mut b) = (a.as_bytes(), b.as_bytes());
    loop {
        match (a.first(), b.first()) {
            (None, None) => return Ordering::Equal,
            (None, Some(_)) => return Ordering::Less,
            (Some(_), None) => return Ordering::Greater,
            (Some(x), Some(y)) if x.is_ascii_digit() && y.is_ascii_digit() => {
                let da = a.iter().take_while(|c| c.is_ascii_digit()).count();
                let db = b.iter().take_while(|c| c.is_ascii_digit()).count();
                let (na, nb) = (&a[..da], &b[..db]);
                let ta = trim_zeros(na);
                let tb = trim_zeros(nb);
                let ord = ta.len().cmp(&tb.len()).then(ta.cmp(tb)).then(da.cmp(&db));
                if ord != Ordering::Equal {
                    return ord;
                }
                a = &a[da..];
                b = &b[db..];
            }
            (Some(x), Some(y)) => {
                if x != y {
                    return x.cmp(y);
                }
                a = &a[1..];
                b = &b[1..];
            }
        }
    }
}

fn trim_zeros(d: &[u8]) -> &[u8] {
    let z = d.iter().take_while(|&&c| c == b'0').count();
    &d[z..]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::nrrd::{NrrdEncoding, write_nrrd};
    use volume_core::Grid;

    fn write_step(dir: &Path, name: &str, value: u8) {
        let g = Grid::uniform([2, 2, 2], [0.0; 3], [1.0; 3]).unwrap();
        let v = RectilinearVolume::new(g, vec![value; 8].into()).unwrap();
        write_nrrd(
            &dir.join(name),
            &v,
            NrrdEncoding::Raw,
            crate::output::Replace::Refuse,
        )
        .unwrap();
    }

    #[test]
    fn natural_order_and_glob_matching() {
        let mut v = vec!["v10", "v2", "v1", "v02", "a"];
        v.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(v, vec!["a", "v1", "v2", "v02", "v10"]);
        assert!(glob_match("vol_*.nrrd", "vol_12.nrrd"));
        assert!(glob_match("v?l*", "vol"));
        assert!(!glob_match("vol_*.nrrd", "vol_12.nhdr"));
        assert!(glob_match("*", ""));
    }

    #[test]
    fn printf_and_glob_series_load_lazily_in_order() {
        let dir = tempfile::tempdir().unwrap();
        for (i, n) in [(0, 0u8), (1, 10), (2, 20), (10, 100)] {
            write_step(dir.path(), &format!("vol_{i:03}.nrrd"), n);
        }
        write_step(dir.path(), "vol_7.nrrd", 77); // not %03d: excluded from the printf series
        let ts =
            open_file_series(&dir.path().join("vol_%03d.nrrd"), &OpenOptions::default()).unwrap();
        assert_eq!(ts.step_count(), 4);
        assert_eq!(ts.step(3).unwrap().value_f64(1, 1, 1), 100.0);
        assert_eq!(ts.first().value_f64(0, 0, 0), 0.0);
        let ts = open_file_series(&dir.path().join("vol_*.nrrd"), &OpenOptions::default()).unwrap();
        assert_eq!(ts.step_count(), 5);
        let values: Vec<f64> = (0..5)
            .map(|s| ts.step(s).unwrap().value_f64(0, 0, 0))
            .collect();
        assert_eq!(values, vec![0.0, 10.0, 20.0, 77.0, 100.0]);
        let e = open_file_series(&dir.path().join("none_*.nrrd"), &OpenOptions::default())
            .err()
            .unwrap();
        assert!(matches!(e, FormatError::Series { .. }), "{e}");
    }
}
