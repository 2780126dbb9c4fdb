//! sRGB transfer functions written with basic IEEE arithmetic only (no libm `powf`), so that
//! preview and baked images are byte-identical on every platform (DESIGN.md, Determinism).
//! Accuracy is about 1e-9 relative, far below one 8-bit step.

/// log2(x) for finite x > 0.
fn log2_f64(x: f64) -> f64 {
    let bits = x.to_bits();
    let mut e = ((bits >> 52) & 0x7ff) as i64 - 1023;
    let mut m = f64::from_bits((bits & 0x000f_ffff_ffff_ffff) | 0x3ff0_0000_0000_0000);
    if e == -1023 {
        // Subnormal: renormalize.
        let y = x * (1u64 << 54) as f64;
        return log2_f64(y) - 54.0;
    }
    // Bring m into [sqrt(1/2), sqrt(2)) so that the series converges fast.
    if m > std::f64::consts::SQRT_2 {
        m *= 0.5;
        e += 1;
    }
    let t = (m - 1.0) / (m + 1.0);
    let t2 = t * t;
    // ln(m) = 2 (t + t^3/3 + t^5/5 + ...), |t| <= 0.1716.
    let mut term = t;
    let mut sum = t;
    for k in 1..8 {
        term *= t2;
        sum += term / (2 * k + 1) as f64;
    }
    e as f64 + 2.0 * sum * std::f64::consts::LOG2_E
}

/// 2^y for moderate y (|y| < 1000).
fn exp2_f64(y: f64) -> f64 {
    let n = y.floor();
    let f = (y - n) * std::f64::consts::LN_2; // in [0, ln 2)
    let mut term = 1.0;
    let mut sum = 1.0;
    for k in 1..16 {
        term *= f / k as f64;
        sum += term;
    }
    let n = n as i64;
    sum * f64::from_bits(((n + 1023) as u64) << 52)
}

/// x^y for x >= 0 (0 for x <= 0).
pub fn pow(x: f64, y: f64) -> f64 {
    if x <= 0.0 || x.is_nan() {
        return 0.0;
    }
    exp2_f64((y * log2_f64(x)).clamp(-1000.0, 1000.0))
}

/// sRGB-encoded value in [0, 1] to linear light, exactly (input clamped to [0, 1]).
pub fn to_linear_exact(c: f32) -> f32 {
    let c = if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) } as f64;
    if c <= 0.04045 {
        (c / 12.92) as f32
    } else {
        pow((c + 0.055) / 1.055, 2.4) as f32
    }
}

/// Linear light to sRGB encoding in [0, 1], exactly (input clamped to [0, 1]).
pub fn from_linear_exact(l: f32) -> f32 {
    let l = if l.is_nan() { 0.0 } else { l.clamp(0.0, 1.0) } as f64;
    if l <= 0.0031308 {
        (l * 12.92) as f32
    } else {
        (1.055 * pow(l, 1.0 / 2.4) - 0.055) as f32
    }
}

/// Table resolution of the fast conversions.
const LUT: usize = 4096;

struct Tables {
    to_linear: Vec<f32>,
    from_linear: Vec<f32>,
}

fn tables() -> &'static Tables {
    static T: std::sync::OnceLock<Tables> = std::sync::OnceLock::new();
    T.get_or_init(|| Tables {
        to_linear: (0..=LUT)
            .map(|i| to_linear_exact(i as f32 / LUT as f32))
            .collect(),
        from_linear: (0..=LUT)
            .map(|i| from_linear_exact(i as f32 / LUT as f32))
            .collect(),
    })
}

#[inline]
fn lerp_table(t: &[f32], x: f32) -> f32 {
    let x = if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) } * LUT as f32;
    let i = (x as usize).min(LUT - 1);
    let f = x - i as f32;
    t[i] + (t[i + 1] - t[i]) * f
}

/// sRGB-encoded value in [0, 1] to linear light (input clamped to [0, 1]); a table with linear
/// interpolation, within 1e-7 of the exact curve.
#[inline]
pub fn to_linear(c: f32) -> f32 {
    lerp_table(&tables().to_linear, c)
}

/// Linear light to sRGB encoding in [0, 1] (input clamped to [0, 1]); a table with linear
/// interpolation, within 2e-5 of the exact curve.
#[inline]
pub fn from_linear(l: f32) -> f32 {
    // Below the first table step the curve is linear.
    if l < 0.0031308 {
        return from_linear_exact(l);
    }
    lerp_table(&tables().from_linear, l)
}

/// Linear light to an 8-bit sRGB value, rounded to nearest.
#[inline]
pub fn to_u8(l: f32) -> u8 {
    (from_linear(l) * 255.0 + 0.5) as u8
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::PureMath;

    #[test]
    fn pow_matches_std_closely() {
        for i in 1..2000 {
            let x = i as f64 / 1999.0;
            for y in [2.4, 1.0 / 2.4, 0.5, 3.0] {
                let a = pow(x, y);
                let b = x.powf_pure(y);
                assert!((a - b).abs() <= 1e-12 + 1e-10 * b, "{x}^{y}: {a} vs {b}");
            }
        }
        assert!((pow(1e-310, 0.5) - 1e-155).abs() < 1e-165);
    }

    #[test]
    fn tables_follow_the_exact_curves() {
        for i in 0..=100_000 {
            let x = i as f32 / 100_000.0;
            assert!((to_linear(x) - to_linear_exact(x)).abs() < 2e-7, "{x}");
            assert!((from_linear(x) - from_linear_exact(x)).abs() < 2e-5, "{x}");
        }
    }

    #[test]
    fn srgb_round_trips_every_8_bit_value() {
        for v in 0..=255u8 {
            let l = to_linear(v as f32 / 255.0);
            assert_eq!(to_u8(l), v);
        }
        // Known anchor values of the sRGB curve.
        assert!((to_linear(0.5) - 0.214_041).abs() < 1e-5);
        assert_eq!(to_linear(0.0), 0.0);
        assert!((to_linear(1.0) - 1.0).abs() < 1e-6);
    }
}
