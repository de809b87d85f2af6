//! Time series: a sequence of volumes with the same dims and voxel type, loaded lazily.
//!
//! A [`StepLoader`] (implemented in `formats` for numbered files, NRRD lists and 4D NRRD)
//! loads one step on demand; [`TimeSeries`] checks every loaded step against the first and
//! keeps a small cache so that stepping back and forth does not reload.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

use crate::error::VolumeError;
use crate::volume::RectilinearVolume;

/// Loads the steps of a time series on demand.
pub trait StepLoader: Send + Sync {
    fn step_count(&self) -> usize;
    /// Loads step `step` (< `step_count()`). The error text names the file and the problem.
    fn load_step(&self, step: usize) -> Result<RectilinearVolume, String>;
    /// The time value of `step` if the source records one (otherwise the step index is used).
    fn time_value(&self, step: usize) -> Option<f64> {
        let _ = step;
        None
    }
    /// A short description of where the steps come from (for `info`).
    fn describe(&self) -> String;
}

/// A lazily loaded time series with a small LRU cache of steps.
pub struct TimeSeries {
    loader: Arc<dyn StepLoader>,
    first: RectilinearVolume,
    cache: Mutex<VecDeque<(usize, RectilinearVolume)>>,
    cache_capacity: usize,
}

impl TimeSeries {
    /// Opens the series by loading its first step (which fixes dims and type).
    pub fn open(loader: Arc<dyn StepLoader>) -> Result<Self, VolumeError> {
        if loader.step_count() == 0 {
            return Err(VolumeError::BadStep {
                step: 0,
                reason: "the series has no steps".into(),
            });
        }
        let first = loader
            .load_step(0)
            .map_err(|reason| VolumeError::StepLoad { step: 0, reason })?;
        Ok(Self {
            loader,
            first,
            cache: Mutex::new(VecDeque::new()),
            cache_capacity: 4,
        })
    }

    pub fn step_count(&self) -> usize {
        self.loader.step_count()
    }

    pub fn time_value(&self, step: usize) -> f64 {
        self.loader.time_value(step).unwrap_or(step as f64)
    }

    pub fn first(&self) -> &RectilinearVolume {
        &self.first
    }

    pub fn loader(&self) -> &Arc<dyn StepLoader> {
        &self.loader
    }

    /// Loads (or returns the cached) step, checking it matches the first step's dims and type.
    pub fn step(&self, step: usize) -> Result<RectilinearVolume, VolumeError> {
        if step >= self.step_count() {
            return Err(VolumeError::BadStep {
                step,
                reason: format!("only {} steps", self.step_count()),
            });
        }
        if step == 0 {
            return Ok(self.first.clone());
        }
        if let Some(v) = self
            .lock_cache()
            .iter()
            .find(|(s, _)| *s == step)
            .map(|(_, v)| v.clone())
        {
            return Ok(v);
        }
        let vol = self
            .loader
            .load_step(step)
            .map_err(|reason| VolumeError::StepLoad { step, reason })?;
        if vol.dims() != self.first.dims() || vol.data.voxel_type() != self.first.data.voxel_type()
        {
            return Err(VolumeError::BadStep {
                step,
                reason: format!(
                    "{:?} {} differs from step 0: {:?} {}",
                    vol.dims(),
                    vol.data.voxel_type(),
                    self.first.dims(),
                    self.first.data.voxel_type()
                ),
            });
        }
        let mut cache = self.lock_cache();
        if cache.len() >= self.cache_capacity {
            cache.pop_front();
        }
        cache.push_back((step, vol.clone()));
        Ok(vol)
    }

    fn lock_cache(&self) -> std::sync::MutexGuard<'_, VecDeque<(usize, RectilinearVolume)>> {
        // A poisoned cache only means another thread panicked mid-insert; the data is still valid.
        self.cache
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::Grid;
    use std::sync::atomic::{AtomicUsize, Ordering};

    struct Counting {
        loads: AtomicUsize,
        bad_step: usize,
    }

    impl StepLoader for Counting {
        fn step_count(&self) -> usize {
            5
        }
        fn load_step(&self, step: usize) -> Result<RectilinearVolume, String> {
            self.loads.fetch_add(1, Ordering::SeqCst);
            let dims = if step == self.bad_step {
                [3, 2, 2]
            } else {
                [2, 2, 2]
            };
            let n = dims.iter().product();
            let g = Grid::uniform(dims, [0.0; 3], [1.0; 3]).map_err(|e| e.to_string())?;
            RectilinearVolume::new(g, vec![step as u8; n].into()).map_err(|e| e.to_string())
        }
        fn describe(&self) -> String {
            "test".into()
        }
    }

    #[test]
    fn steps_load_lazily_cache_and_are_checked() {
        let loader = Arc::new(Counting {
            loads: AtomicUsize::new(0),
            bad_step: 3,
        });
        let ts = TimeSeries::open(loader.clone()).unwrap();
        assert_eq!(loader.loads.load(Ordering::SeqCst), 1);
        assert_eq!(ts.step(2).unwrap().value_f64(1, 1, 1), 2.0);
        assert_eq!(ts.step(2).unwrap().value_f64(0, 0, 0), 2.0);
        assert_eq!(loader.loads.load(Ordering::SeqCst), 2);
        assert!(matches!(
            ts.step(3),
            Err(VolumeError::BadStep { step: 3, .. })
        ));
        assert!(matches!(
            ts.step(9),
            Err(VolumeError::BadStep { step: 9, .. })
        ));
        assert_eq!(ts.time_value(4), 4.0);
    }
}
