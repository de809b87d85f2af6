//! Closed intervals of `f32`.

/// A closed interval `[lo, hi]`; empty when `lo > hi`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Interval {
    pub lo: f32,
    pub hi: f32,
}

impl Interval {
    pub const EMPTY: Interval = Interval {
        lo: f32::INFINITY,
        hi: f32::NEG_INFINITY,
    };

    pub const fn new(lo: f32, hi: f32) -> Self {
        Self { lo, hi }
    }

    pub fn is_empty(&self) -> bool {
        self.lo
            .partial_cmp(&self.hi)
            .is_none_or(std::cmp::Ordering::is_gt)
    }

    pub fn contains(&self, x: f32) -> bool {
        self.lo <= x && x <= self.hi
    }

    pub fn intersect(&self, o: &Interval) -> Interval {
        Interval {
            lo: self.lo.max(o.lo),
            hi: self.hi.min(o.hi),
        }
    }

    pub fn union(&self, o: &Interval) -> Interval {
        Interval {
            lo: self.lo.min(o.lo),
            hi: self.hi.max(o.hi),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interval_set_operations() {
        let a = Interval::new(0.0, 2.0);
        let b = Interval::new(1.0, 3.0);
        assert_eq!(a.intersect(&b), Interval::new(1.0, 2.0));
        assert_eq!(a.union(&b), Interval::new(0.0, 3.0));
        assert!(Interval::new(3.0, 1.0).is_empty());
        assert!(Interval::EMPTY.is_empty());
        assert!(a.contains(2.0) && !a.contains(2.5));
        assert!(Interval::new(f32::NAN, 1.0).is_empty());
    }
}
