//! Helpers shared by the writers' unit tests: a sample volume with distinct voxels and the
//! volume a reader returns.

use volume_core::{Grid, RectilinearVolume};

use crate::{Dataset, FormatError};

/// An i16 volume on `grid` whose voxels all differ (negative ones included).
pub(crate) fn sample_volume(grid: Grid) -> RectilinearVolume {
    let n = grid.voxel_count();
    let data: Vec<i16> = (0..n).map(|i| (i as i16) * 37 - 500).collect();
    RectilinearVolume::new(grid, data.into()).unwrap()
}

/// The volume of a reader's result (panics on an error or a series).
pub(crate) fn volume_of(read: Result<Dataset, FormatError>) -> RectilinearVolume {
    match read.unwrap() {
        Dataset::Volume(v) => v,
        Dataset::Series(_) => panic!("volume expected"),
    }
}
