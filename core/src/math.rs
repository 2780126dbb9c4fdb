//! Transcendental functions from one pure-Rust implementation (the `libm` crate, a port of
//! musl's), so a hashed result does not depend on the platform's C library: `f32::sin` and
//! friends call the system libm, whose last bits differ between glibc versions, musl, macOS and
//! Windows, and every artifact (previews and atlases included) is hashed.
//!
//! `clippy.toml` disallows the standard methods (`cargo clippy -- -D clippy::disallowed_methods`
//! in `.ci/run`); call these instead: `x.sin()` becomes `x.sin_pure()`. `sqrt` and `mul_add`
//! are exact by IEEE 754 and stay as they are.

/// The pure-Rust transcendental functions, as methods on `f32` and `f64`.
pub trait PureMath: Sized + Copy {
    fn exp_pure(self) -> Self;
    fn exp2_pure(self) -> Self;
    fn exp_m1_pure(self) -> Self;
    fn ln_pure(self) -> Self;
    fn ln_1p_pure(self) -> Self;
    fn log2_pure(self) -> Self;
    fn log10_pure(self) -> Self;
    fn powf_pure(self, e: Self) -> Self;
    fn sin_pure(self) -> Self;
    fn cos_pure(self) -> Self;
    fn tan_pure(self) -> Self;
    fn sin_cos_pure(self) -> (Self, Self);
    fn asin_pure(self) -> Self;
    fn acos_pure(self) -> Self;
    fn atan_pure(self) -> Self;
    fn atan2_pure(self, x: Self) -> Self;
    fn sinh_pure(self) -> Self;
    fn cosh_pure(self) -> Self;
    fn tanh_pure(self) -> Self;
    fn cbrt_pure(self) -> Self;
    fn hypot_pure(self, other: Self) -> Self;
}

macro_rules! pure_math {
    ($t:ty, $exp:ident, $exp2:ident, $expm1:ident, $ln:ident, $ln1p:ident, $log2:ident,
     $log10:ident, $pow:ident, $sin:ident, $cos:ident, $tan:ident, $sincos:ident, $asin:ident,
     $acos:ident, $atan:ident, $atan2:ident, $sinh:ident, $cosh:ident, $tanh:ident,
     $cbrt:ident, $hypot:ident) => {
        impl PureMath for $t {
            fn exp_pure(self) -> Self {
                libm::$exp(self)
            }
            fn exp2_pure(self) -> Self {
                libm::$exp2(self)
            }
            fn exp_m1_pure(self) -> Self {
                libm::$expm1(self)
            }
            fn ln_pure(self) -> Self {
                libm::$ln(self)
            }
            fn ln_1p_pure(self) -> Self {
                libm::$ln1p(self)
            }
            fn log2_pure(self) -> Self {
                libm::$log2(self)
            }
            fn log10_pure(self) -> Self {
                libm::$log10(self)
            }
            fn powf_pure(self, e: Self) -> Self {
                libm::$pow(self, e)
            }
            fn sin_pure(self) -> Self {
                libm::$sin(self)
            }
            fn cos_pure(self) -> Self {
                libm::$cos(self)
            }
            fn tan_pure(self) -> Self {
                libm::$tan(self)
            }
            fn sin_cos_pure(self) -> (Self, Self) {
                libm::$sincos(self)
            }
            fn asin_pure(self) -> Self {
                libm::$asin(self)
            }
            fn acos_pure(self) -> Self {
                libm::$acos(self)
            }
            fn atan_pure(self) -> Self {
                libm::$atan(self)
            }
            fn atan2_pure(self, x: Self) -> Self {
                libm::$atan2(self, x)
            }
            fn sinh_pure(self) -> Self {
                libm::$sinh(self)
            }
            fn cosh_pure(self) -> Self {
                libm::$cosh(self)
            }
            fn tanh_pure(self) -> Self {
                libm::$tanh(self)
            }
            fn cbrt_pure(self) -> Self {
                libm::$cbrt(self)
            }
            fn hypot_pure(self, other: Self) -> Self {
                libm::$hypot(self, other)
            }
        }
    };
}

pure_math!(
    f32, expf, exp2f, expm1f, logf, log1pf, log2f, log10f, powf, sinf, cosf, tanf, sincosf, asinf,
    acosf, atanf, atan2f, sinhf, coshf, tanhf, cbrtf, hypotf
);
pure_math!(
    f64, exp, exp2, expm1, log, log1p, log2, log10, pow, sin, cos, tan, sincos, asin, acos, atan,
    atan2, sinh, cosh, tanh, cbrt, hypot
);

#[cfg(test)]
mod tests {
    use super::PureMath;

    /// The pure functions agree with the platform's to within a couple of ulps (a wrong
    /// mapping, say sin for cos or the f64 function truncated for f32, is far off).
    #[test]
    #[allow(clippy::disallowed_methods)]
    fn pure_functions_agree_with_the_platform_to_a_few_ulps() {
        let close32 = |a: f32, b: f32| (a - b).abs() <= 4.0 * f32::EPSILON * b.abs().max(1e-30);
        let close64 = |a: f64, b: f64| (a - b).abs() <= 4.0 * f64::EPSILON * b.abs().max(1e-300);
        for i in 1..200 {
            let x = i as f32 * 0.0173 - 1.6;
            let p = x.abs() + 0.1;
            assert!(close32(x.exp_pure(), x.exp()), "exp {x}");
            assert!(close32(x.exp2_pure(), x.exp2()), "exp2 {x}");
            assert!(
                close32(p.ln_pure(), p.ln()) || (p.ln()).abs() < 1e-6,
                "ln {p}"
            );
            assert!(
                close32(p.log2_pure(), p.log2()) || p.log2().abs() < 1e-6,
                "log2 {p}"
            );
            assert!(close32(p.powf_pure(1.7), p.powf(1.7)), "powf {p}");
            assert!(close32(x.sin_pure(), x.sin()), "sin {x}");
            assert!(close32(x.cos_pure(), x.cos()), "cos {x}");
            assert!(close32(x.atan2_pure(0.3), x.atan2(0.3)), "atan2 {x}");
            let (s, c) = x.sin_cos_pure();
            assert!(close32(s, x.sin()) && close32(c, x.cos()), "sin_cos {x}");
            let u = x / 2.0; // inside [-1, 1]
            assert!(close32(u.acos_pure(), u.acos()), "acos {u}");
            assert!(
                close32(u.asin_pure(), u.asin()) || u.asin().abs() < 1e-6,
                "asin {u}"
            );
            assert!(
                close32(x.tanh_pure(), x.tanh()) || x.tanh().abs() < 1e-6,
                "tanh {x}"
            );
            let d = x as f64 * 1.37;
            assert!(close64(d.exp_pure(), d.exp()), "exp64 {d}");
            assert!(close64(d.sin_pure(), d.sin()), "sin64 {d}");
            assert!(close64(d.cos_pure(), d.cos()), "cos64 {d}");
            assert!(close64(d.atan2_pure(-0.4), d.atan2(-0.4)), "atan2_64 {d}");
            assert!(close64(d.hypot_pure(2.0), d.hypot(2.0)), "hypot {d}");
        }
    }
}
