//! Time-varying tetrahedral meshes: the two schemes of thesis 004 §8.5.
//!
//! All steps share one topology (points and tets); each step has its own scalars and, if
//! points move, its own positions ([`TetStep`]). [`TetSteps`] switches between steps with
//! either scheme ([`StepScheme`]):
//! - [`StepScheme::PerStepBvh`] (§8.5.1): a [`TetScene`] (data + BVH) per step, built up
//!   front in parallel. Switching is free; memory grows with the step count.
//! - [`StepScheme::Refit`] (§8.5.2): one scene, refit on every switch: only the isoranges when
//!   the positions stay the same ([`TetScene::refit_scalars`]), the full 4D bounds when they
//!   change ([`TetScene::refit_positions`]).
//!
//! Readers that load steps lazily (formats' mesh series) can also drive a single
//! [`TetScene`]'s refits directly.

use rayon::prelude::*;

use super::bvh::BvhOptions;
use super::mesh::TetError;
use super::scene::TetScene;
use crate::render::Normals;

/// One step's data.
#[derive(Debug, Clone, PartialEq)]
pub struct TetStep {
    /// Point positions of this step, or `None` for the reference positions.
    pub positions: Option<Vec<[f32; 3]>>,
    /// The selected field's values at the points.
    pub values: Vec<f32>,
}

/// How [`TetSteps`] switches steps (module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum StepScheme {
    /// A prebuilt BVH per step: fast switching, more memory.
    PerStepBvh,
    /// One BVH refit per switch: little memory.
    #[default]
    Refit,
}

/// A time-varying tet mesh with a current step (module docs).
#[derive(Debug, Clone)]
pub struct TetSteps {
    scheme: StepScheme,
    reference: Vec<[f32; 3]>,
    steps: Vec<TetStep>,
    /// One scene per step (`PerStepBvh`) or the single refit scene (`Refit`).
    scenes: Vec<TetScene>,
    current: usize,
    /// The step whose positions the refit scene holds (`None`: the reference positions).
    positions_of: Option<usize>,
}

impl TetSteps {
    /// Validates every step against the topology and prepares the scheme; the current step
    /// is 0.
    pub fn new(
        points: &[[f32; 3]],
        tets: &[[u32; 4]],
        steps: Vec<TetStep>,
        scheme: StepScheme,
        options: BvhOptions,
    ) -> Result<Self, TetError> {
        let n = points.len();
        if steps.is_empty() {
            return Err(TetError::StepLength {
                what: "time steps",
                expected: 1,
                actual: 0,
            });
        }
        for s in &steps {
            if s.values.len() != n {
                return Err(TetError::StepLength {
                    what: "step scalar values",
                    expected: n,
                    actual: s.values.len(),
                });
            }
            if let Some(p) = &s.positions
                && p.len() != n
            {
                return Err(TetError::StepLength {
                    what: "step point positions",
                    expected: n,
                    actual: p.len(),
                });
            }
        }
        let scene_of = |s: &TetStep| {
            let pts = s.positions.as_deref().unwrap_or(points);
            TetScene::from_parts(pts, tets.to_vec(), &s.values, options)
        };
        let scenes = match scheme {
            StepScheme::PerStepBvh => steps
                .par_iter()
                .map(scene_of)
                .collect::<Result<Vec<_>, _>>()?,
            StepScheme::Refit => vec![scene_of(&steps[0])?],
        };
        let positions_of = steps[0].positions.as_ref().map(|_| 0);
        Ok(Self {
            scheme,
            reference: points.to_vec(),
            steps,
            scenes,
            current: 0,
            positions_of,
        })
    }

    pub fn scheme(&self) -> StepScheme {
        self.scheme
    }

    pub fn step_count(&self) -> usize {
        self.steps.len()
    }

    pub fn current_step(&self) -> usize {
        self.current
    }

    /// Makes `step` current (refitting under [`StepScheme::Refit`]).
    pub fn set_step(&mut self, step: usize) -> Result<(), TetError> {
        if step >= self.steps.len() {
            return Err(TetError::StepLength {
                what: "step index (out of range)",
                expected: self.steps.len(),
                actual: step,
            });
        }
        if self.scheme == StepScheme::Refit && step != self.current {
            let s = &self.steps[step];
            let want = s.positions.as_ref().map(|_| step);
            let scene = &mut self.scenes[0];
            if want != self.positions_of {
                scene.refit_positions(s.positions.as_deref().unwrap_or(&self.reference))?;
                self.positions_of = want;
            }
            scene.refit_scalars(&s.values)?;
        }
        self.current = step;
        Ok(())
    }

    /// The scene of the current step.
    pub fn scene(&self) -> &TetScene {
        match self.scheme {
            StepScheme::PerStepBvh => &self.scenes[self.current],
            StepScheme::Refit => &self.scenes[0],
        }
    }

    /// Sets the normal mode of every scene.
    pub fn set_normals(&mut self, normals: Normals) {
        for s in &mut self.scenes {
            s.set_normals(normals);
        }
    }

    /// Sets the packet size of every scene.
    pub fn set_packet_size(&mut self, rays: usize) {
        for s in &mut self.scenes {
            s.set_packet_size(rays);
        }
    }
}
