//! # data-samples
//!
//! Deterministic synthetic datasets for tests, benchmarks and demos, and the small committed
//! samples under `data-samples/samples/` (see the README there).
//!
//! - [`marschner_lobb`]: the Marschner–Lobb signal (thesis seed 004 §7.5, Figures 7.5/7.6).
//! - [`analytic`]: a sphere distance field, a torus and nested offset spheres, with their
//!   analytic isosurfaces ([`analytic::Sphere`] has a ray intersection for test truth).
//! - [`phantom`]: a CT-like head in Hounsfield units, `i16`, anisotropic spacing.
//! - [`blobs`]: moving and merging Gaussian blobs, a 20-step time series (lazy or eager).
//! - [`tets`]: tetrahedral meshes of a ball, a shell and a torus (a structured grid split
//!   into tets) with analytic point fields and a moving Gaussian series.
//! - [`sparse_blobs`]: a 2048×2048×1100 `u8` volume of analytic blobs as a sparse file
//!   (more than 2³² voxels, for the out-of-core test).
//! - [`hostile`]: a corpus of several hundred malformed, hostile and edge-case files over
//!   every reader, with what each must give (a clean error, or a render).
//! - [`sampling`]: the parallel field sampler and the [`ValueMap`] that stores a field's
//!   natural values in any voxel type.
//!
//! [`Generator`] names them all for the command line (`isoscope generate NAME`).

use volume_core::{RectilinearVolume, VolumeError, VoxelType};

pub mod analytic;
pub mod blobs;
pub mod hostile;
pub mod marschner_lobb;
pub mod phantom;
pub mod sampling;
pub mod sparse_blobs;
pub mod tets;

pub use sampling::ValueMap;

/// Why a dataset could not be generated.
#[derive(Debug, thiserror::Error)]
pub enum GenerateError {
    #[error("every axis needs at least 2 samples, got {}x{}x{}", dims[0], dims[1], dims[2])]
    DimsTooSmall { dims: [usize; 3] },
    #[error("a time series needs at least 1 step")]
    NoSteps,
    #[error("step {step} is out of range: the series has {steps} steps")]
    StepOutOfRange { step: usize, steps: usize },
    #[error("cannot allocate {bytes} bytes for the voxels")]
    OutOfMemory { bytes: usize },
    #[error(transparent)]
    Volume(#[from] VolumeError),
    /// A generated tetrahedral mesh failed validation ([`tets`]).
    #[error(transparent)]
    Mesh(#[from] volume_core::tet::TetError),
}

/// The named generators of `isoscope generate`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Generator {
    MarschnerLobb,
    Sphere,
    Torus,
    NestedSpheres,
    Phantom,
    Blobs,
}

impl Generator {
    pub const ALL: [Generator; 6] = [
        Generator::MarschnerLobb,
        Generator::Sphere,
        Generator::Torus,
        Generator::NestedSpheres,
        Generator::Phantom,
        Generator::Blobs,
    ];

    /// The command-line name.
    pub const fn name(self) -> &'static str {
        match self {
            Generator::MarschnerLobb => "marschner-lobb",
            Generator::Sphere => "sphere",
            Generator::Torus => "torus",
            Generator::NestedSpheres => "nested-spheres",
            Generator::Phantom => "phantom",
            Generator::Blobs => "blobs",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|g| g.name() == name)
    }

    /// One line for `--help` and error messages.
    pub const fn description(self) -> &'static str {
        match self {
            Generator::MarschnerLobb => {
                "Marschner-Lobb signal on [-1,1]^3 (fM = 6, alpha = 0.25), iso 0.5"
            }
            Generator::Sphere => {
                "distance from (0.1,-0.05,0.03) on [-1,1]^3: isovalue r is a sphere of radius r"
            }
            Generator::Torus => {
                "distance to a circle of radius 0.55 on [-1,1]^3: isovalue r is a torus"
            }
            Generator::NestedSpheres => {
                "nested offset spheres on [-1,1]^3: every isovalue s is a sphere of radius s"
            }
            Generator::Phantom => {
                "CT-like head phantom in Hounsfield units, anisotropic spacing (mm)"
            }
            Generator::Blobs => "time series: four Gaussian blobs moving and merging, iso 0.5",
        }
    }

    /// Dims when no size is given.
    pub const fn default_dims(self) -> [usize; 3] {
        match self {
            Generator::MarschnerLobb => [41, 41, 41],
            Generator::Phantom => phantom::DEFAULT_DIMS,
            Generator::Sphere | Generator::Torus | Generator::NestedSpheres | Generator::Blobs => {
                [64, 64, 64]
            }
        }
    }

    /// Dims for a single size `n` (`--size n`): `n³`, except the phantom, which keeps its
    /// aspect (`n × n × round(n · 110/256)`).
    pub fn dims_for_size(self, n: usize) -> [usize; 3] {
        match self {
            Generator::Phantom => phantom::dims_for_size(n),
            _ => [n; 3],
        }
    }

    /// Voxel type when none is given.
    pub const fn default_voxel_type(self) -> VoxelType {
        match self {
            Generator::Phantom => VoxelType::I16,
            _ => VoxelType::F32,
        }
    }

    pub const fn is_series(self) -> bool {
        matches!(self, Generator::Blobs)
    }

    /// Steps when none are given (1 for single volumes).
    pub const fn default_steps(self) -> usize {
        if self.is_series() {
            blobs::DEFAULT_STEPS
        } else {
            1
        }
    }

    /// How the generator's natural values are stored in `voxel_type`.
    pub fn value_map(self, voxel_type: VoxelType) -> ValueMap {
        let range = |(lo, hi): (f64, f64)| ValueMap::range_to_type(lo, hi, voxel_type);
        match self {
            Generator::MarschnerLobb => marschner_lobb::value_map(voxel_type),
            Generator::Sphere => range(analytic::SPHERE_RANGE),
            Generator::Torus => range(analytic::TORUS_RANGE),
            Generator::NestedSpheres => range(analytic::NESTED_RANGE),
            Generator::Phantom => phantom::value_map(voxel_type),
            Generator::Blobs => blobs::value_map(voxel_type),
        }
    }

    /// Suggested isovalues in natural units (map with [`Generator::value_map`] to store units).
    pub fn suggested_isovalues(self) -> &'static [f64] {
        match self {
            Generator::MarschnerLobb => &[marschner_lobb::ISOVALUE],
            Generator::Sphere => &[analytic::SPHERE_SUGGESTED_RADIUS],
            Generator::Torus => &[analytic::TORUS_SUGGESTED_MINOR_RADIUS],
            Generator::NestedSpheres => &analytic::NESTED_SUGGESTED_LEVELS,
            // Skin and bone.
            Generator::Phantom => &[-300.0, 500.0],
            Generator::Blobs => &[blobs::ISOVALUE],
        }
    }

    /// Generates the volume (step 0 of the default series for `blobs`).
    pub fn generate(
        self,
        dims: [usize; 3],
        voxel_type: VoxelType,
    ) -> Result<RectilinearVolume, GenerateError> {
        self.generate_step(dims, voxel_type, 0, self.default_steps(), &|| {})
    }

    /// Generates step `step` of `steps` (single volumes: `step` 0 of 1 step), calling
    /// `on_slice` after each z-slice.
    pub fn generate_step(
        self,
        dims: [usize; 3],
        voxel_type: VoxelType,
        step: usize,
        steps: usize,
        on_slice: &(dyn Fn() + Sync),
    ) -> Result<RectilinearVolume, GenerateError> {
        if !self.is_series() && (steps != 1 || step != 0) {
            return Err(GenerateError::StepOutOfRange { step, steps: 1 });
        }
        match self {
            Generator::MarschnerLobb => {
                marschner_lobb::generate_with_progress(dims, voxel_type, on_slice)
            }
            Generator::Sphere => analytic::sphere(dims, voxel_type, on_slice),
            Generator::Torus => analytic::torus(dims, voxel_type, on_slice),
            Generator::NestedSpheres => analytic::nested_spheres(dims, voxel_type, on_slice),
            Generator::Phantom => phantom::generate(dims, voxel_type, on_slice),
            Generator::Blobs => blobs::Blobs::new(dims, voxel_type, steps)?.step(step, on_slice),
        }
    }
}

impl std::fmt::Display for Generator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for g in Generator::ALL {
            assert_eq!(Generator::from_name(g.name()), Some(g));
        }
        assert_eq!(Generator::from_name("spheres"), None);
    }

    #[test]
    fn every_generator_honours_dims_and_type_and_rejects_tiny_sizes() {
        for g in Generator::ALL {
            for t in [VoxelType::U8, VoxelType::I16, VoxelType::F64] {
                let v = g.generate([5, 4, 3], t).unwrap();
                assert_eq!(v.dims(), [5, 4, 3], "{g}");
                assert_eq!(v.data.voxel_type(), t, "{g}");
            }
            assert!(matches!(
                g.generate([1, 4, 3], VoxelType::F32),
                Err(GenerateError::DimsTooSmall { .. })
            ));
        }
        assert!(
            Generator::Sphere
                .generate_step([4; 3], VoxelType::F32, 1, 2, &|| {})
                .is_err()
        );
    }

    #[test]
    fn progress_is_reported_once_per_slice() {
        let n = std::sync::atomic::AtomicUsize::new(0);
        let tick = || {
            n.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        };
        Generator::Torus
            .generate_step([6, 5, 7], VoxelType::F32, 0, 1, &tick)
            .unwrap();
        assert_eq!(n.load(std::sync::atomic::Ordering::Relaxed), 7);
    }

    #[test]
    fn integer_outputs_are_the_float_field_through_the_value_map() {
        for g in Generator::ALL {
            let f = g.generate([6, 6, 6], VoxelType::F64).unwrap();
            for t in [VoxelType::U8, VoxelType::U16, VoxelType::I16] {
                let q = g.generate([6, 6, 6], t).unwrap();
                let m = g.value_map(t);
                for (i, j, k) in [(0, 0, 0), (3, 2, 1), (5, 5, 5)] {
                    let want = m.to_stored(f.value_f64(i, j, k)).round();
                    assert_eq!(q.value_f64(i, j, k), want, "{g} {t}");
                }
            }
        }
    }
}
