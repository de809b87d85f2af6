//! Time-varying meshes: a ParaView `.pvd` collection or numbered files (thesis seed 004
//! §8.5). A [`MeshSeries`] is a list of `(time, path)` loaded lazily, one step at a time.
//!
//! All steps must share the first step's topology (point count and, after splitting, the same
//! tetrahedra); positions and scalars may change per step. [`MeshSeries::load_step_data`]
//! checks that and returns only what changed, so a renderer can refit instead of rebuild.
//!
//! `.pvd`: `<VTKFile type="Collection"><Collection><DataSet timestep="t" part="0"
//! file="step.vtu"/>...`; `file` is relative to the `.pvd`'s folder; steps are sorted by
//! time (stable); for several parts per time step only part 0 is used.

use std::path::{Path, PathBuf};

use quick_xml::events::Event;
use volume_core::tet::{PointField, TetMesh};

use super::{LoadedMesh, MeshError, read_file};

/// One time step of a series.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshStep {
    pub time: f64,
    pub path: PathBuf,
}

/// A time series of meshes sharing one topology, loaded lazily.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshSeries {
    /// The `.pvd` or the first numbered file (for messages).
    pub source: PathBuf,
    pub steps: Vec<MeshStep>,
}

/// Steps load lazily; no output may replace them meanwhile ([`crate::input::note_input`]).
fn note_steps(steps: &[MeshStep]) {
    for s in steps {
        crate::input::note_input(&s.path);
    }
}

/// What one step adds to the reference mesh (the first step).
#[derive(Debug, Clone, PartialEq)]
pub struct StepData {
    pub time: f64,
    /// New positions if any point moved, else `None` (only scalars change: refit value ranges).
    pub positions: Option<Vec<[f32; 3]>>,
    /// The step's scalar fields.
    pub fields: Vec<PointField>,
}

impl MeshSeries {
    pub fn len(&self) -> usize {
        self.steps.len()
    }

    pub fn is_empty(&self) -> bool {
        self.steps.is_empty()
    }

    /// A series of the given files, time = step index.
    pub fn from_files(paths: Vec<PathBuf>) -> Self {
        let source = paths.first().cloned().unwrap_or_default();
        let steps: Vec<MeshStep> = paths
            .into_iter()
            .enumerate()
            .map(|(i, path)| MeshStep {
                time: i as f64,
                path,
            })
            .collect();
        note_steps(&steps);
        Self { source, steps }
    }

    /// The numbered siblings of `example` (`step_007.vtu` finds every `step_<digits>.vtu` in
    /// its folder), sorted by number; time = the number.
    pub fn numbered(example: &Path) -> Result<Self, MeshError> {
        let name = example
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default();
        let (stem, ext) = match name.rfind('.') {
            Some(i) => (&name[..i], &name[i..]),
            None => (name, ""),
        };
        let digits_at = stem.trim_end_matches(|c: char| c.is_ascii_digit()).len();
        if digits_at == stem.len() {
            return Err(MeshError::UnknownFormat {
                path: example.to_path_buf(),
                reason: "not a numbered file: no digits before the extension".to_owned(),
            });
        }
        let prefix = &stem[..digits_at];
        let dir = example
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let mut found: Vec<(u64, PathBuf)> = Vec::new();
        for entry in std::fs::read_dir(dir).map_err(|e| MeshError::io(dir, e))? {
            let entry = entry.map_err(|e| MeshError::io(dir, e))?;
            let file = entry.file_name();
            let Some(f) = file.to_str() else { continue };
            let Some(mid) = f.strip_prefix(prefix).and_then(|r| r.strip_suffix(ext)) else {
                continue;
            };
            if !mid.is_empty()
                && mid.bytes().all(|b| b.is_ascii_digit())
                && let Ok(k) = mid.parse::<u64>()
            {
                found.push((k, entry.path()));
            }
        }
        found.sort();
        let steps: Vec<MeshStep> = found
            .into_iter()
            .map(|(k, path)| MeshStep {
                time: k as f64,
                path,
            })
            .collect();
        note_steps(&steps);
        Ok(Self {
            source: example.to_path_buf(),
            steps,
        })
    }

    /// Loads step `i` as a whole mesh.
    pub fn load_step(&self, i: usize) -> Result<LoadedMesh, MeshError> {
        let step = self.steps.get(i).ok_or_else(|| MeshError::Topology {
            path: self.source.clone(),
            step: i,
            reason: format!("no such step (the series has {})", self.steps.len()),
        })?;
        // A step that is itself a `.pvd` is read inside this series' collection, so that a
        // collection leading back to this one is reported as a cycle.
        let mut chain = Vec::new();
        if super::MeshFormat::from_path(&self.source) == Some(super::MeshFormat::Pvd) {
            chain.push(super::file_key(&self.source));
        }
        super::read_raw_within(&step.path, &mut chain)?.into_tet_mesh(&step.path)
    }

    /// Loads step `i` and checks it against `reference` (usually step 0): same point count
    /// and the same tetrahedra. Returns the positions only if some point moved.
    pub fn load_step_data(&self, i: usize, reference: &TetMesh) -> Result<StepData, MeshError> {
        let m = self.load_step(i)?.mesh;
        let path = self.steps[i].path.clone();
        if m.points.len() != reference.points.len() {
            return Err(MeshError::Topology {
                path,
                step: i,
                reason: format!(
                    "{} points, the first step has {}",
                    m.points.len(),
                    reference.points.len()
                ),
            });
        }
        if m.tets != reference.tets {
            let first = m
                .tets
                .iter()
                .zip(&reference.tets)
                .position(|(a, b)| a != b)
                .unwrap_or(m.tets.len().min(reference.tets.len()));
            return Err(MeshError::Topology {
                path,
                step: i,
                reason: format!(
                    "cells differ from the first step ({} vs {} tets, first difference at tet {first})",
                    m.tets.len(),
                    reference.tets.len()
                ),
            });
        }
        let positions = (m.points != reference.points).then_some(m.points);
        Ok(StepData {
            time: self.steps[i].time,
            positions,
            fields: m.fields,
        })
    }
}

/// Reads a ParaView `.pvd` collection (the steps are not loaded yet).
pub fn read_pvd(path: &Path) -> Result<MeshSeries, MeshError> {
    let data = read_file(path)?;
    parse_pvd(path, &data)
}

/// Parses the bytes of the `.pvd` collection at `path` (steps are named relative to its
/// directory; nothing is read).
pub fn parse_pvd(path: &Path, data: &[u8]) -> Result<MeshSeries, MeshError> {
    let dir = path.parent().unwrap_or(Path::new(""));
    let perr = |pos: usize, reason: String| MeshError::Parse {
        path: path.to_path_buf(),
        line: super::text::newlines(&data[..pos.min(data.len())]) + 1,
        offset: pos as u64,
        reason,
    };
    let mut reader = quick_xml::Reader::from_reader(data);
    let mut steps: Vec<MeshStep> = Vec::new();
    let mut saw_collection = false;
    loop {
        let pos = reader.buffer_position() as usize;
        match reader.read_event() {
            Err(e) => {
                return Err(perr(
                    reader.error_position() as usize,
                    format!("XML error: {e}"),
                ));
            }
            Ok(Event::Eof) => break,
            Ok(Event::Start(e) | Event::Empty(e)) => {
                let name = e.local_name();
                if name.as_ref() == b"VTKFile" {
                    let ty = e
                        .try_get_attribute("type")
                        .ok()
                        .flatten()
                        .map(|a| String::from_utf8_lossy(&a.value).into_owned());
                    if ty.as_deref() != Some("Collection") {
                        return Err(perr(
                            pos,
                            format!("VTKFile type {ty:?} is not \"Collection\""),
                        ));
                    }
                    saw_collection = true;
                } else if name.as_ref() == b"DataSet" {
                    let get = |k: &str| {
                        e.try_get_attribute(k).ok().flatten().map(|a| {
                            a.normalized_value(quick_xml::XmlVersion::Implicit1_0)
                                .map_or_else(
                                    |_| String::from_utf8_lossy(&a.value).into_owned(),
                                    std::borrow::Cow::into_owned,
                                )
                        })
                    };
                    let file = get("file")
                        .ok_or_else(|| perr(pos, "DataSet without a file attribute".into()))?;
                    let time = match get("timestep") {
                        Some(t) => t
                            .trim()
                            .parse::<f64>()
                            .ok()
                            .filter(|t| t.is_finite())
                            .ok_or_else(|| {
                                perr(pos, format!("timestep {t:?} is not a finite number"))
                            })?,
                        None => steps.len() as f64,
                    };
                    let part = get("part")
                        .and_then(|p| p.trim().parse::<i64>().ok())
                        .unwrap_or(0);
                    if part != 0 {
                        continue;
                    }
                    steps.push(MeshStep {
                        time,
                        path: dir.join(file),
                    });
                }
            }
            Ok(_) => {}
        }
    }
    if !saw_collection {
        return Err(perr(0, "no <VTKFile type=\"Collection\"> element".into()));
    }
    if steps.is_empty() {
        return Err(perr(0, "the collection lists no data sets".into()));
    }
    steps.sort_by(|a, b| a.time.total_cmp(&b.time));
    note_steps(&steps);
    Ok(MeshSeries {
        source: path.to_path_buf(),
        steps,
    })
}
