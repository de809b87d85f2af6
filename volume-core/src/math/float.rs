//! Floating-point error bounds.
//!
//! `gamma(n) = n·ε / (1 − n·ε)` bounds the relative error of `n` chained roundings
//! (Higham; pbrt-v4 §6.8.1), with `ε` half the machine epsilon (the unit roundoff).

/// Unit roundoff for `f32`.
pub const UNIT_ROUNDOFF_F32: f32 = f32::EPSILON * 0.5;
/// Unit roundoff for `f64`.
pub const UNIT_ROUNDOFF_F64: f64 = f64::EPSILON * 0.5;

/// `gamma(n)` for `f32`.
#[inline]
pub const fn gamma_f32(n: u32) -> f32 {
    let ne = n as f32 * UNIT_ROUNDOFF_F32;
    ne / (1.0 - ne)
}

/// `gamma(n)` for `f64`.
#[inline]
pub const fn gamma_f64(n: u32) -> f64 {
    let ne = n as f64 * UNIT_ROUNDOFF_F64;
    ne / (1.0 - ne)
}

/// The next representable `f32` above `x` (identity for `+inf` and NaN).
#[inline]
pub fn next_up(x: f32) -> f32 {
    x.next_up()
}

/// The next representable `f32` below `x`.
#[inline]
pub fn next_down(x: f32) -> f32 {
    x.next_down()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gamma_bounds_repeated_rounding() {
        // Summing 1/3 three times in f32 stays within gamma(3) of the exact 1.
        let third = 1.0f32 / 3.0;
        let s = third + third + third;
        assert!((s - 1.0).abs() <= gamma_f32(3));
        assert!(gamma_f32(3) > 3.0 * UNIT_ROUNDOFF_F32);
        assert!(gamma_f64(1) > 0.0 && gamma_f64(1) < 1e-15);
        assert!(next_up(1.0) > 1.0 && next_down(1.0) < 1.0);
    }
}
