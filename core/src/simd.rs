//! f32 kernels whose results are the same bits on every CPU: dot products with a fixed
//! order of partial sums, projections onto the rows of a basis, squared distances, and their
//! SSE, AVX2 and AVX-512 versions, each doing the portable version's products and sums in
//! the same order (Rust never fuses a multiply and an add), so a wider CPU only runs faster.
//!
//! The vector versions need CPU features: the tokens [`Avx2`] and [`Avx512`] exist only once
//! detection found them, so code that holds one may call the matching kernel (an `unsafe`
//! call, justified by the token), and [`Kernels`] lets generic code carry which ones it may
//! call. Each vector kernel has a bitwise test against the portable one (skipped, and saying
//! so, on a CPU without it).

/// Which projection kernels a caller may use. A value of a type whose `AVX2` is true
/// exists only once the CPU was found to have AVX2, so holding one is what makes the unsafe
/// calls sound: no safe caller can reach them on a CPU without it.
pub trait Kernels: Copy {
    const AVX2: bool;
}

/// The portable kernels, on any CPU.
#[derive(Clone, Copy)]
pub struct Portable;

impl Kernels for Portable {
    const AVX2: bool = false;
}

/// Proof that the CPU has AVX2: only [`Avx2::detect`] makes one.
#[derive(Clone, Copy)]
pub struct Avx2(());

impl Avx2 {
    pub fn detect() -> Option<Avx2> {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            return Some(Avx2(()));
        }
        None
    }
}

impl Kernels for Avx2 {
    const AVX2: bool = true;
}

/// Proof that the CPU has AVX-512F and AVX2: only [`Avx512::detect`] makes one.
#[derive(Clone, Copy, Debug)]
pub struct Avx512(());

impl Avx512 {
    pub fn detect() -> Option<Avx512> {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx2")
        {
            return Some(Avx512(()));
        }
        None
    }
}

/// A cache hint for the lines of `s`.
#[inline]
pub fn prefetch_slice(s: &[f32]) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let p = s.as_ptr() as *const i8;
        let bytes = std::mem::size_of_val(s);
        let mut off = 0;
        while off < bytes {
            // SAFETY: a prefetch is a hint that never faults; the address is inside `s`.
            unsafe { _mm_prefetch(p.add(off), _MM_HINT_T0) };
            off += 64;
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = s;
}

/// `out[k] = basis_k · x − mean_k` for the rows `basis_k` of a row-major basis: each row's dot
/// product is [`dot`]'s, term for term and in the same order (so the same value), but four
/// rows go through the vector at once, which keeps four independent sums in flight where
/// one row at a time waits on its own additions.
#[inline]
pub fn project(basis: &[f32], x: &[f32], mean: &[f32], out: &mut [f32]) {
    const L: usize = 8;
    let dim = x.len();
    let comps = out.len();
    let whole = dim / L * L;
    let mut k = 0;
    while k + 4 <= comps {
        let rows: [&[f32]; 4] = std::array::from_fn(|r| &basis[(k + r) * dim..(k + r + 1) * dim]);
        let mut acc = [[0.0f32; L]; 4];
        let mut c = 0;
        while c < whole {
            let xs = &x[c..c + L];
            for r in 0..4 {
                let row = &rows[r][c..c + L];
                for i in 0..L {
                    acc[r][i] += row[i] * xs[i];
                }
            }
            c += L;
        }
        for r in 0..4 {
            let mut tail = 0.0f32;
            for i in whole..dim {
                tail += rows[r][i] * x[i];
            }
            out[k + r] = reduce_lanes(acc[r]) + tail - mean[k + r];
        }
        k += 4;
    }
    while k < comps {
        out[k] = dot(&basis[k * dim..(k + 1) * dim], x) - mean[k];
        k += 1;
    }
}

/// [`project`] in AVX registers: lane `i` of row `k`'s register is `project`'s `acc[r][i]`,
/// added to in the same order (a product, then a sum, never fused), so every output is the
/// same bits as [`project`]'s.
///
/// # Safety
///
/// The CPU must have AVX2: hold an [`Avx2`] token (or run in code compiled for AVX2).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub fn project_avx2(basis: &[f32], x: &[f32], mean: &[f32], out: &mut [f32]) {
    use std::arch::x86_64::{
        _mm256_add_ps, _mm256_loadu_ps, _mm256_mul_ps, _mm256_setzero_ps, _mm256_storeu_ps,
    };
    const L: usize = 8;
    let dim = x.len();
    let comps = out.len();
    assert!(basis.len() >= comps * dim && mean.len() >= comps);
    let whole = dim / L * L;
    let mut k = 0;
    while k + 4 <= comps {
        let rows: [&[f32]; 4] = std::array::from_fn(|r| &basis[(k + r) * dim..(k + r + 1) * dim]);
        let mut acc = [_mm256_setzero_ps(); 4];
        // Raw loads: checked slices cost the loop five compares and branches per eight
        // columns, more than its four multiplies and adds.
        let row_at = rows.map(|r| r.as_ptr());
        let mut c = 0;
        while c < whole {
            // SAFETY: unaligned loads of 8 floats at `c`, where `c + 8 <= whole <= dim`, the
            // length of `x` and of every row.
            let xv = unsafe { _mm256_loadu_ps(x.as_ptr().add(c)) };
            for r in 0..4 {
                // SAFETY: as above.
                let rv = unsafe { _mm256_loadu_ps(row_at[r].add(c)) };
                acc[r] = _mm256_add_ps(acc[r], _mm256_mul_ps(rv, xv));
            }
            c += L;
        }
        for r in 0..4 {
            let mut lanes = [0.0f32; L];
            // SAFETY: an unaligned store of 8 floats to an array of 8.
            unsafe { _mm256_storeu_ps(lanes.as_mut_ptr(), acc[r]) };
            let mut tail = 0.0f32;
            for i in whole..dim {
                tail += rows[r][i] * x[i];
            }
            out[k + r] = reduce_lanes(lanes) + tail - mean[k + r];
        }
        k += 4;
    }
    while k < comps {
        out[k] = dot(&basis[k * dim..(k + 1) * dim], x) - mean[k];
        k += 1;
    }
}

/// The whole 8-column blocks of a row-major `comps × dim` basis, rows taken in pairs: for
/// pair `m` (rows `2m`, `2m + 1`; a last odd row is left out) and block `b`, sixteen floats at
/// `(m · ⌊dim/8⌋ + b) · 16`, row `2m`'s columns `8b..8b + 8` then row `2m + 1`'s: one
/// 512-bit load gives [`project_avx512`] both rows' block.
pub fn pair_rows(basis: &[f32], dim: usize) -> Vec<f32> {
    let comps = basis.len() / dim.max(1);
    let blocks = dim / 8;
    let mut out = Vec::with_capacity(comps / 2 * blocks * 16);
    for m in 0..comps / 2 {
        for b in 0..blocks {
            for r in [2 * m, 2 * m + 1] {
                out.extend_from_slice(&basis[r * dim + 8 * b..r * dim + 8 * b + 8]);
            }
        }
    }
    out
}

/// [`project`] with two rows in each AVX-512 register: the low eight lanes of pair `m`'s
/// register are row `2m`'s `acc` lanes of [`project`], the high eight row `2m + 1`'s, each
/// added to in the same order (a product, then a sum, never fused) from the same zero, and
/// reduced the same way with the same tail: every output is the same bits as [`project`]'s
/// (which groups rows in fours only to keep sums in flight; a row's value does not depend on
/// its group). Half the multiplies and adds of [`project_avx2`]. `paired` is
/// [`pair_rows`] of `basis`.
///
/// # Safety
///
/// The CPU must have AVX-512F and AVX2: hold an [`Avx512`] token.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2")]
pub fn project_avx512(basis: &[f32], paired: &[f32], x: &[f32], mean: &[f32], out: &mut [f32]) {
    use std::arch::x86_64::{
        _mm256_castps_pd, _mm256_loadu_ps, _mm512_add_ps, _mm512_broadcast_f64x4, _mm512_castpd_ps,
        _mm512_loadu_ps, _mm512_mul_ps, _mm512_setzero_ps, _mm512_storeu_ps,
    };
    const L: usize = 8;
    const GROUP: usize = 4;
    let dim = x.len();
    let comps = out.len();
    let blocks = dim / L;
    let whole = blocks * L;
    let pairs = comps / 2;
    assert!(basis.len() >= comps * dim && mean.len() >= comps);
    assert!(paired.len() >= pairs * blocks * 16);
    // Row `k`'s output from its eight lane sums.
    let finish = |k: usize, lanes: &[f32]| {
        let row = &basis[k * dim..(k + 1) * dim];
        let mut tail = 0.0f32;
        for i in whole..dim {
            tail += row[i] * x[i];
        }
        let acc: [f32; L] = lanes.try_into().expect("8 lanes");
        reduce_lanes(acc) + tail - mean[k]
    };
    let mut m = 0;
    while m < pairs {
        let group = GROUP.min(pairs - m);
        let mut acc = [_mm512_setzero_ps(); GROUP];
        let at = paired.as_ptr();
        for b in 0..blocks {
            // SAFETY: 8 floats of `x` at `8b + 8 <= whole <= dim`; 16 of `paired` at
            // `((m + r) · blocks + b) · 16`, inside its `pairs · blocks · 16` (asserted).
            let xv = unsafe {
                _mm512_castpd_ps(_mm512_broadcast_f64x4(_mm256_castps_pd(_mm256_loadu_ps(
                    x.as_ptr().add(b * L),
                ))))
            };
            for r in 0..group {
                // SAFETY: as above.
                let rv = unsafe { _mm512_loadu_ps(at.add(((m + r) * blocks + b) * 16)) };
                acc[r] = _mm512_add_ps(acc[r], _mm512_mul_ps(rv, xv));
            }
        }
        for r in 0..group {
            let mut lanes = [0.0f32; 16];
            // SAFETY: an unaligned store of 16 floats to an array of 16.
            unsafe { _mm512_storeu_ps(lanes.as_mut_ptr(), acc[r]) };
            let k = 2 * (m + r);
            out[k] = finish(k, &lanes[..L]);
            out[k + 1] = finish(k + 1, &lanes[L..]);
        }
        m += group;
    }
    if comps % 2 == 1 {
        let k = comps - 1;
        out[k] = dot(&basis[k * dim..(k + 1) * dim], x) - mean[k];
    }
}

/// [`lane_sum`]'s final reduction of eight lanes.
#[inline]
fn reduce_lanes(mut acc: [f32; 8]) -> f32 {
    let mut n = 4;
    for i in 0..n {
        acc[i] += acc[i + n];
    }
    while n > 1 {
        for i in 0..n / 2 {
            acc[i] = acc[2 * i] + acc[2 * i + 1];
        }
        n /= 2;
    }
    acc[0]
}

/// Dot product with eight partial sums (see `lane_sum`).
#[inline]
pub fn dot(a: &[f32], b: &[f32]) -> f32 {
    lane_sum::<8>(a, b, |x, y| x * y)
}

/// Squared Euclidean distance with four partial sums (see `lane_sum`).
#[inline(always)]
pub fn squared_distance(a: &[f32], b: &[f32]) -> f32 {
    #[cfg(target_arch = "x86_64")]
    if a.len() == b.len() {
        return squared_distance_sse(a, b);
    }
    squared_distance_portable(a, b)
}

#[inline(always)]
pub fn squared_distance_portable(a: &[f32], b: &[f32]) -> f32 {
    lane_sum::<4>(a, b, |x, y| {
        let t = x - y;
        t * t
    })
}

/// [`squared_distance_portable`] for equal lengths, its four partial sums in one SSE
/// register (x86-64's baseline): the same operations in the same order, so the same bits.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
#[allow(unused_unsafe)]
fn squared_distance_sse(a: &[f32], b: &[f32]) -> f32 {
    use std::arch::x86_64::{
        _mm_add_ps, _mm_loadu_ps, _mm_mul_ps, _mm_setzero_ps, _mm_storeu_ps, _mm_sub_ps,
    };
    let n = a.len().min(b.len());
    let whole = n / 4 * 4;
    // SAFETY: SSE is part of x86-64; every load and store is of 4 floats from an array of 4.
    let l = unsafe {
        let mut acc = _mm_setzero_ps();
        let mut c = 0;
        while c < whole {
            let x: &[f32; 4] = a[c..c + 4].try_into().expect("4 lanes");
            let y: &[f32; 4] = b[c..c + 4].try_into().expect("4 lanes");
            let d = _mm_sub_ps(_mm_loadu_ps(x.as_ptr()), _mm_loadu_ps(y.as_ptr()));
            acc = _mm_add_ps(acc, _mm_mul_ps(d, d));
            c += 4;
        }
        let mut l = [0.0f32; 4];
        _mm_storeu_ps(l.as_mut_ptr(), acc);
        l
    };
    let mut tail = 0.0f32;
    for i in whole..n {
        let t = a[i] - b[i];
        tail += t * t;
    }
    ((l[0] + l[2]) + (l[1] + l[3])) + tail
}

/// The sum of `term(a[i], b[i])` over `L` partial sums (so it vectorizes), added in a fixed
/// order: lane i with lane i + L/2, then neighbours pairwise (for 8 lanes
/// ((0+4) + (1+5)) + ((2+6) + (3+7))), then the terms past the last whole chunk.
#[inline]
fn lane_sum<const L: usize>(a: &[f32], b: &[f32], term: impl Fn(f32, f32) -> f32) -> f32 {
    let mut acc = [0.0f32; L];
    let (ca, cb) = (a.chunks_exact(L), b.chunks_exact(L));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for i in 0..L {
            acc[i] += term(x[i], y[i]);
        }
    }
    let mut tail = 0.0f32;
    for (x, y) in ra.iter().zip(rb) {
        tail += term(*x, *y);
    }
    let mut n = L / 2;
    for i in 0..n {
        acc[i] += acc[i + n];
    }
    while n > 1 {
        for i in 0..n / 2 {
            acc[i] = acc[2 * i] + acc[2 * i + 1];
        }
        n /= 2;
    }
    acc[0] + tail
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::random::{counter_hash, counter_unit};

    /// Deterministic floats in [-2, 2) with some exact zeros, negative zeros and repeats.
    fn floats(seed: u64, n: usize) -> Vec<f32> {
        (0..n as u64)
            .map(|i| match counter_hash(seed, 1, i) % 16 {
                0 => 0.0,
                1 => -0.0,
                2 => 1.5,
                _ => 4.0 * counter_unit(seed, 2, i) - 2.0,
            })
            .collect()
    }

    #[test]
    fn avx2_projection_is_bitwise_the_portable_one() {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // N = 7 and 9 neighbourhoods (147, 243 values), and lengths with other tails.
            for (seed, dim, comps) in [
                (1, 243, 20),
                (2, 147, 20),
                (3, 243, 7),
                (4, 8, 3),
                (5, 5, 4),
            ] {
                let basis = floats(seed, dim * comps);
                let x = floats(seed + 100, dim);
                let mean = floats(seed + 200, comps);
                let (mut a, mut b) = (vec![0.0f32; comps], vec![0.0f32; comps]);
                project(&basis, &x, &mean, &mut a);
                // SAFETY: the CPU has AVX2 (checked above).
                unsafe { project_avx2(&basis, &x, &mean, &mut b) };
                let bits = |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&a), bits(&b), "dim {dim}, comps {comps}");
                // And both are the rows' dot products (so the test compares real values).
                for k in 0..comps {
                    let d: f64 = (0..dim)
                        .map(|i| basis[k * dim + i] as f64 * x[i] as f64)
                        .sum::<f64>()
                        - mean[k] as f64;
                    assert!((a[k] as f64 - d).abs() < 1e-3, "row {k}: {} vs {d}", a[k]);
                }
            }
        }
    }

    #[test]
    fn avx512_projection_is_bitwise_the_portable_one() {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx512f")
            && std::arch::is_x86_feature_detected!("avx2")
        {
            // N = 7 and 9 neighbourhoods, an odd row count, fewer rows than a group, a
            // length under one block, tails of every size.
            for (seed, dim, comps) in [
                (1, 243, 20),
                (2, 147, 20),
                (3, 243, 7),
                (4, 8, 3),
                (5, 5, 4),
                (6, 250, 13),
                (7, 17, 1),
                (8, 64, 18),
            ] {
                let basis = floats(seed, dim * comps);
                let x = floats(seed + 100, dim);
                let mean = floats(seed + 200, comps);
                let paired = pair_rows(&basis, dim);
                let (mut a, mut b) = (vec![0.0f32; comps], vec![0.0f32; comps]);
                project(&basis, &x, &mean, &mut a);
                // SAFETY: the CPU has AVX-512F and AVX2 (checked above).
                unsafe { project_avx512(&basis, &paired, &x, &mean, &mut b) };
                let bits = |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&a), bits(&b), "dim {dim}, comps {comps}");
            }
        } else {
            // Not a pass: this CPU cannot run the path (CI's emulated CPUs check the others).
            eprintln!("avx512_projection_is_bitwise_the_portable_one: skipped, no AVX-512F");
        }
    }

    #[test]
    fn sse_distance_is_bitwise_the_portable_one() {
        for (seed, n) in [(1, 20), (2, 3), (3, 0), (4, 17), (5, 64)] {
            let (a, b) = (floats(seed, n), floats(seed + 50, n));
            let d = squared_distance(&a, &b);
            assert_eq!(
                d.to_bits(),
                squared_distance_portable(&a, &b).to_bits(),
                "n = {n}"
            );
            let exact: f64 = a
                .iter()
                .zip(&b)
                .map(|(x, y)| (*x as f64 - *y as f64).powi(2))
                .sum();
            assert!((d as f64 - exact).abs() <= 1e-4 * (1.0 + exact), "n = {n}");
        }
    }
}
