//! The child-ordering step of every kd-tree traversal, written once: the single-ray and
//! packet traversals of this module and the out-of-core one ([`crate::ooc`]) all decide with
//! it which children of a node to enter, nearest first.
//!
//! Robustness (seed 000 §5, Havran; seed 004 §7.2): a ray parallel to the split plane
//! enters the child on its origin's side, and *both* children when the origin lies in the
//! plane, each over the whole interval, since the surface on a shared face may belong to
//! either cell. Otherwise the split distance `t_split` decides: beyond the interval only
//! the near child, before it only the far one, else both (near over `[t_near, t_split]`,
//! far over `[t_split, t_far]`).

/// Which children of a node are entered; `T` is a ray's `t` (`f32`) or a packet's lanes.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Visit<T> {
    /// Only the near child, over the whole interval.
    Near,
    /// Only the far child, over the whole interval.
    Far,
    /// The near child over `[t_near, near_t_far]` now, the far child over
    /// `[far_t_near, t_far]` later.
    Both { near_t_far: T, far_t_near: T },
}

/// One node step: which child is the near one, and which children are entered.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Step<T> {
    pub near_is_left: bool,
    pub visit: Visit<T>,
}

/// The single-ray step at a node splitting at `split` along an axis where the ray has
/// `origin`, `dir` and `inv_dir` (traversal units), over `[t_near, t_far]` (module docs).
#[inline(always)]
pub(crate) fn ray_step(
    origin: f32,
    dir: f32,
    inv_dir: f32,
    split: f32,
    t_near: f32,
    t_far: f32,
) -> Step<f32> {
    if dir == 0.0 {
        let (near_is_left, visit) = if origin < split {
            (true, Visit::Near)
        } else if origin > split {
            (false, Visit::Near)
        } else {
            // In the split plane: both sides, each over the whole interval.
            (
                true,
                Visit::Both {
                    near_t_far: t_far,
                    far_t_near: t_near,
                },
            )
        };
        return Step {
            near_is_left,
            visit,
        };
    }
    let t_split = (split - origin) * inv_dir;
    let visit = if t_split > t_far {
        Visit::Near
    } else if t_split < t_near {
        Visit::Far
    } else {
        Visit::Both {
            near_t_far: t_split,
            far_t_near: t_split,
        }
    };
    Step {
        near_is_left: dir > 0.0,
        visit,
    }
}

/// Applies `step` to the children `left` and `right` (entered only if live): returns the
/// child to descend into (`None`: pop the stack) and, when both are entered and the far
/// child is live, the far child with its interval `(far, far_t_near, t_far)` for the caller
/// to push; `t_far` is then narrowed to the near child's interval. The push is returned,
/// not made through a closure: a pushing closure of 16-ray lanes was not inlined, and its
/// copies of the lanes through memory stalled store forwarding (6 % of the MNI frame).
#[inline(always)]
pub(crate) fn take_step<N: Copy, T: Copy>(
    step: Step<T>,
    left: N,
    right: N,
    left_live: bool,
    right_live: bool,
    t_far: &mut T,
) -> (Option<N>, Option<(N, T, T)>) {
    let (near, far, near_live, far_live) = if step.near_is_left {
        (left, right, left_live, right_live)
    } else {
        (right, left, right_live, left_live)
    };
    match step.visit {
        Visit::Near => (near_live.then_some(near), None),
        Visit::Far => (far_live.then_some(far), None),
        Visit::Both {
            near_t_far,
            far_t_near,
        } => {
            let push = far_live.then_some((far, far_t_near, *t_far));
            if !near_live {
                return (None, push);
            }
            *t_far = near_t_far;
            (Some(near), push)
        }
    }
}
