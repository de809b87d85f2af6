//! The time axis of a 4D NRRD (or 4D MetaImage, read by the same data plan) as a
//! [`StepLoader`]: attached data, one data file, or a `LIST`/pattern of data files. Raw data in one file is mapped once and each step is a
//! zero-copy view into it; step 0 is loaded up front so its errors are reported typed.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use volume_core::RectilinearVolume;
use volume_core::series::StepLoader;

use super::{DataPlan, VolumeLayout};
use crate::FirstStep;
use crate::error::FormatError;

/// The dataset a planned file holds: the volume when `layout` has one step, else the lazily
/// loaded time series of its steps (`format` names it in the series' description).
pub(crate) fn dataset(
    path: &Path,
    plan: DataPlan,
    layout: VolumeLayout,
    step_bytes: u64,
    format: &'static str,
) -> Result<crate::Dataset, FormatError> {
    if layout.steps == 1 {
        let data = plan.load(0, step_bytes)?;
        let volume = RectilinearVolume::new(layout.grid, data)
            .map_err(|e| FormatError::geometry(path, e))?;
        return Ok(crate::Dataset::Volume(volume));
    }
    let loader = NrrdSteps::new(path, Arc::new(plan), layout, step_bytes, format)?;
    let series = volume_core::series::TimeSeries::open(Arc::new(loader)).map_err(|e| {
        FormatError::Series {
            path: path.to_path_buf(),
            reason: e.to_string(),
        }
    })?;
    Ok(crate::Dataset::Series(series))
}

/// The steps of a 4D NRRD or MetaImage.
pub struct NrrdSteps {
    path: PathBuf,
    /// The format, for [`StepLoader::describe`].
    format: &'static str,
    plan: Arc<DataPlan>,
    layout: VolumeLayout,
    step_bytes: u64,
    first: FirstStep,
}

impl NrrdSteps {
    /// Prepares the loader and loads step 0 (so that its errors are reported typed).
    pub(crate) fn new(
        path: &Path,
        plan: Arc<DataPlan>,
        layout: VolumeLayout,
        step_bytes: u64,
        format: &'static str,
    ) -> Result<Self, FormatError> {
        let first = load(path, &plan, &layout, step_bytes, 0)?;
        Ok(Self {
            path: path.to_path_buf(),
            format,
            plan,
            layout,
            step_bytes,
            first: FirstStep::new(first),
        })
    }

    fn load(&self, step: usize) -> Result<RectilinearVolume, FormatError> {
        load(&self.path, &self.plan, &self.layout, self.step_bytes, step)
    }
}

impl StepLoader for NrrdSteps {
    fn step_count(&self) -> usize {
        self.layout.steps
    }

    fn load_step(&self, step: usize) -> Result<RectilinearVolume, String> {
        if step == 0
            && let Some(v) = self.first.take()
        {
            return Ok(v);
        }
        self.load(step).map_err(|e| e.to_string())
    }

    fn time_value(&self, step: usize) -> Option<f64> {
        self.layout.time.map(|(t0, dt)| t0 + step as f64 * dt)
    }

    fn describe(&self) -> String {
        format!(
            "{} time steps of 4D {} {} ({} data file(s))",
            self.layout.steps,
            self.format,
            self.path.display(),
            self.plan.file_count()
        )
    }
}

/// Step `step` of the 4D data: a view into the mapped data where it is raw in one file.
fn load(
    path: &Path,
    plan: &DataPlan,
    layout: &VolumeLayout,
    step_bytes: u64,
    step: usize,
) -> Result<RectilinearVolume, FormatError> {
    let data = plan.load(step as u64 * step_bytes, step_bytes)?;
    RectilinearVolume::new(layout.grid.clone(), data).map_err(|e| FormatError::geometry(path, e))
}
