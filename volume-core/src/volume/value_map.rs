//! Stored voxel values to physical values: `physical = slope · stored + intercept`.
//!
//! Medical files store integers and a linear rescale to physical units (NIfTI
//! `scl_slope`/`scl_inter`, DICOM RescaleSlope/RescaleIntercept to Hounsfield units). The
//! voxels keep their stored type, so memory stays native; isovalues, value ranges and
//! histograms are given in physical units and mapped here, once per frame or query, never
//! per voxel in a hot loop.

/// A linear map from stored values to physical values. The default is the identity.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ValueMap {
    pub slope: f64,
    pub intercept: f64,
}

impl Default for ValueMap {
    fn default() -> Self {
        Self::IDENTITY
    }
}

/// Why a slope/intercept pair cannot be a [`ValueMap`].
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[error("value rescale slope {slope} and intercept {intercept}: {reason}")]
pub struct BadValueMap {
    pub slope: f64,
    pub intercept: f64,
    pub reason: &'static str,
}

impl ValueMap {
    pub const IDENTITY: ValueMap = ValueMap {
        slope: 1.0,
        intercept: 0.0,
    };

    /// A map with a finite, non-zero slope and a finite intercept. (Readers decide what a
    /// file's zero slope means first: in NIfTI it means "no scaling".)
    pub fn new(slope: f64, intercept: f64) -> Result<Self, BadValueMap> {
        let bad = |reason| BadValueMap {
            slope,
            intercept,
            reason,
        };
        if !slope.is_finite() || !intercept.is_finite() {
            return Err(bad("both must be finite"));
        }
        if slope == 0.0 {
            return Err(bad("the slope must not be zero"));
        }
        Ok(Self { slope, intercept })
    }

    pub fn is_identity(&self) -> bool {
        *self == Self::IDENTITY
    }

    /// The physical value of a stored one.
    #[inline]
    pub fn to_physical(&self, stored: f64) -> f64 {
        if self.is_identity() {
            return stored;
        }
        stored * self.slope + self.intercept
    }

    /// The stored value of a physical one (`f64`, before any rounding to the voxel type).
    #[inline]
    pub fn to_stored(&self, physical: f64) -> f64 {
        if self.is_identity() {
            return physical;
        }
        (physical - self.intercept) / self.slope
    }

    /// An isovalue in stored units as the intersectors take it (`f32`). The identity
    /// returns `iso` bit for bit; values beyond `f32` become ±inf, which no cell holds.
    #[inline]
    pub fn iso_to_stored(&self, iso: f32) -> f32 {
        if self.is_identity() {
            return iso;
        }
        self.to_stored(f64::from(iso)) as f32
    }

    /// A physical range `[lo, hi]` of stored values `[lo, hi]` (ordered; a negative slope
    /// swaps the ends).
    pub fn range_to_physical(&self, (lo, hi): (f64, f64)) -> (f64, f64) {
        let (a, b) = (self.to_physical(lo), self.to_physical(hi));
        (a.min(b), a.max(b))
    }

    /// The stored range of a physical range (ordered).
    pub fn range_to_stored(&self, (lo, hi): (f64, f64)) -> (f64, f64) {
        let (a, b) = (self.to_stored(lo), self.to_stored(hi));
        (a.min(b), a.max(b))
    }

    /// True when the slope is negative: stored order is the reverse of physical order.
    pub fn reverses(&self) -> bool {
        self.slope < 0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ct_rescale_round_trips_and_orders_ranges() {
        let m = ValueMap::new(1.0, -1024.0).unwrap();
        assert_eq!(m.to_physical(1024.0), 0.0);
        assert_eq!(m.to_stored(-1000.0), 24.0);
        assert_eq!(m.iso_to_stored(500.0), 1524.0);
        let n = ValueMap::new(-0.5, 10.0).unwrap();
        assert_eq!(n.range_to_physical((0.0, 4.0)), (8.0, 10.0));
        assert_eq!(n.range_to_stored((8.0, 10.0)), (0.0, 4.0));
        assert!(n.reverses() && !m.reverses());
        for x in [-3.25, 0.0, 7.5, 1e6] {
            assert!((n.to_stored(n.to_physical(x)) - x).abs() <= 1e-9 * x.abs().max(1.0));
        }
    }

    #[test]
    fn identity_is_bit_exact_and_bad_maps_are_refused() {
        let id = ValueMap::default();
        assert!(id.is_identity());
        for x in [0.1f32, -3.7e-20, 1e30, f32::MAX] {
            assert_eq!(id.iso_to_stored(x).to_bits(), x.to_bits());
        }
        assert!(ValueMap::new(0.0, 1.0).is_err());
        assert!(ValueMap::new(f64::NAN, 1.0).is_err());
        assert!(ValueMap::new(1.0, f64::INFINITY).is_err());
        let e = ValueMap::new(0.0, 3.0).unwrap_err().to_string();
        assert!(e.contains("slope 0") && e.contains("zero"), "{e}");
        // A tiny slope maps a large isovalue beyond f32: it becomes infinite (never hit).
        let tiny = ValueMap::new(1e-40, 0.0).unwrap();
        assert!(tiny.iso_to_stored(1.0).is_infinite());
    }
}
