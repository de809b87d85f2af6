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
    use crate::math::rng::Rng;

    /// A random `f32` `±(1 + m/2²³)·2^e`, `e` in `[−6, 5]`: a multiple of `2⁻²⁹` below `2⁶`,
    /// so sums of up to 64 of them (and their `f32` partial sums) are exact in `f64`.
    fn summand(rng: &mut Rng) -> f32 {
        let m = 1.0 + rng.below(1 << 23) as f32 / (1u32 << 23) as f32;
        let e = rng.below(12) as i32 - 6;
        let sign = if rng.chance(0.5) { -1.0 } else { 1.0 };
        sign * m * 2f32.powi(e)
    }

    /// `(|fl(Σx) − Σx|, Σ|x|)` for the left-to-right `f32` sum, both exact (see [`summand`]).
    fn sum_error(xs: &[f32]) -> (f64, f64) {
        let fl = xs.iter().fold(0.0f32, |s, &x| s + x);
        let exact: f64 = xs.iter().map(|&x| f64::from(x)).sum();
        let abs: f64 = xs.iter().map(|&x| f64::from(x).abs()).sum();
        ((f64::from(fl) - exact).abs(), abs)
    }

    /// `|fl(Πx) − Πx| / |Πx|` for the left-to-right `f32` product of `xs` (each in
    /// `[2⁻⁴, 2⁴)`, at most 5), from the exact integer product of the 24-bit significands.
    fn product_rel_error(xs: &[f32]) -> f64 {
        // x = sig · 2^exp with sig a 24-bit integer.
        let split = |x: f32| {
            let b = x.to_bits();
            let exp = ((b >> 23) & 0xff) as i32 - 127 - 23;
            (u128::from(b & 0x7f_ffff | 0x80_0000), exp)
        };
        let (mut sig, mut exp) = (1u128, 0i32);
        for &x in xs {
            let (s, e) = split(x);
            sig *= s;
            exp += e;
        }
        let (fl_sig, fl_exp) = split(xs.iter().product());
        // fl = fl_sig · 2^(fl_exp − exp) in units of 2^exp; the shift is ≥ 0 for ≥ 1 factor.
        let fl = fl_sig << (fl_exp - exp);
        fl.abs_diff(sig) as f64 / sig as f64
    }

    /// Recursive summation of `n` terms: `|fl − exact| ≤ gamma(n − 1)·Σ|x|` (Higham Eq. 4.4;
    /// pbrt-v4 §6.8.1), on seeded random inputs, with the exact sum from `f64`.
    #[test]
    fn gamma_bounds_random_sums_against_exact_sums() {
        let mut rng = Rng::new(0x5eed_5a11);
        for n in 2..=64usize {
            let bound = f64::from(gamma_f32(n as u32 - 1));
            for trial in 0..2_000 {
                let xs: Vec<f32> = (0..n).map(|_| summand(&mut rng)).collect();
                let (err, abs) = sum_error(&xs);
                assert!(
                    err <= bound * abs,
                    "n {n} trial {trial}: {xs:?} err {err} > {bound}·{abs}"
                );
            }
        }
    }

    /// The sum bound is tight: a sum whose every addition rounds up by almost half an ulp
    /// exceeds `gamma(n − 2)·Σ|x|`, so a `gamma` one rounding too small fails the test above
    /// on such inputs (and here).
    #[test]
    fn sum_error_reaches_beyond_one_rounding_fewer() {
        for n in 3..=64usize {
            // 1 plus terms just above half an ulp of 1: each addition rounds up.
            let mut xs = vec![1.0f32];
            xs.extend(std::iter::repeat_n(
                2f32.powi(-24) * (1.0 + 2f32.powi(-10)),
                n - 1,
            ));
            let (err, abs) = sum_error(&xs);
            assert!(err <= f64::from(gamma_f32(n as u32 - 1)) * abs, "n {n}");
            assert!(
                err > f64::from(gamma_f32(n as u32 - 2)) * abs,
                "n {n}: err {err}"
            );
        }
    }

    /// A chain of `n` factors: `|fl − exact| ≤ gamma(n − 1)·|exact|`, exact in integers; one
    /// rounding comes within 2 % of `gamma(1)`, so a `gamma(1)` 2 % too small would fail.
    #[test]
    fn gamma_bounds_random_products_against_exact_products() {
        let mut rng = Rng::new(0x9a_44a0);
        let mut worst_single = 0.0f64;
        for n in 2..=5usize {
            let bound = f64::from(gamma_f32(n as u32 - 1));
            for trial in 0..50_000 {
                let xs: Vec<f32> = (0..n)
                    .map(|_| {
                        let m = 1.0 + rng.below(1 << 23) as f32 / (1u32 << 23) as f32;
                        m * 2f32.powi(rng.below(8) as i32 - 4)
                    })
                    .collect();
                let rel = product_rel_error(&xs);
                assert!(
                    rel <= bound,
                    "n {n} trial {trial}: {xs:?} rel {rel} > {bound}"
                );
                if n == 2 {
                    worst_single = worst_single.max(rel);
                }
            }
        }
        let g1 = f64::from(gamma_f32(1));
        assert!(
            worst_single > 0.98 * g1,
            "worst single rounding {worst_single} vs {g1}"
        );
    }

    #[test]
    fn gamma_and_ulp_steps_are_ordered() {
        assert!(gamma_f32(3) > 3.0 * UNIT_ROUNDOFF_F32);
        assert!(gamma_f64(1) > 0.0 && gamma_f64(1) < 1e-15);
        assert!(next_up(1.0) > 1.0 && next_down(1.0) < 1.0);
    }
}
