//! Principal component analysis of f32 vectors, reproducible to the bit.
//!
//! The mean and covariance are accumulated in f64 over fixed-size chunks of [`CHUNK`] vectors,
//! and the chunk sums are added in index order, so the result does not depend on the number of
//! threads. The eigendecomposition is a plain cyclic Jacobi iteration in f64 (no runtime SIMD
//! dispatch, so also the same on every x86-64 machine); the covariance matrices here are small
//! (a few hundred rows at most).

use rayon::prelude::*;

/// Vectors per chunk of the mean and covariance reductions.
pub const CHUNK: usize = 2048;

/// How many components to keep. Default: automatic (the fewest explaining 95% of the
/// variance, but at least 4 and at most 16).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PcaParams {
    /// Components kept; 0 = automatic, see `variance`, `min_auto` and `max_auto`.
    /// Always capped at the input dimension. Default: 0.
    pub components: u32,
    /// Automatic choice: fraction of the total variance to explain, in (0, 1]. Default: 0.95.
    pub variance: f64,
    /// Automatic choice: at least this many components. Default: 4.
    pub min_auto: u32,
    /// Automatic choice: at most this many components. Default: 16.
    pub max_auto: u32,
}

impl Default for PcaParams {
    fn default() -> Self {
        PcaParams {
            components: 0,
            variance: 0.95,
            min_auto: 4,
            max_auto: 16,
        }
    }
}

/// A fitted PCA basis.
#[derive(Clone, Debug, PartialEq)]
pub struct Pca {
    /// Input dimension.
    pub dim: usize,
    /// Mean of the input vectors.
    pub mean: Vec<f32>,
    /// Kept components, one row of length `dim` each, by decreasing variance. Orthonormal.
    pub basis: Vec<f32>,
    /// All eigenvalues of the covariance (variances along the components), decreasing.
    pub eigenvalues: Vec<f64>,
}

impl Pca {
    /// Fits a basis to `data`, `data.len() / dim` vectors of length `dim` stored one after the
    /// other. With no vectors the mean is zero and the basis the first coordinate axes.
    pub fn fit(data: &[f32], dim: usize, params: &PcaParams) -> Pca {
        assert!(
            dim > 0 && data.len().is_multiple_of(dim),
            "data is not a whole number of vectors"
        );
        let n = data.len() / dim;
        let chunk_len = CHUNK * dim;

        // Mean.
        let partial: Vec<Vec<f64>> = data
            .par_chunks(chunk_len)
            .map(|c| {
                let mut s = vec![0.0f64; dim];
                for v in c.chunks_exact(dim) {
                    for (a, &x) in s.iter_mut().zip(v) {
                        *a += x as f64;
                    }
                }
                s
            })
            .collect();
        let mut mean64 = vec![0.0f64; dim];
        for s in &partial {
            for (m, &x) in mean64.iter_mut().zip(s) {
                *m += x;
            }
        }
        if n > 0 {
            for m in &mut mean64 {
                *m /= n as f64;
            }
        }

        // Covariance, upper triangle packed row by row.
        let tri = dim * (dim + 1) / 2;
        let partial: Vec<Vec<f64>> = data
            .par_chunks(chunk_len)
            .map(|c| {
                let mut s = vec![0.0f64; tri];
                let mut centred = vec![0.0f64; dim];
                for v in c.chunks_exact(dim) {
                    for ((d, &x), &m) in centred.iter_mut().zip(v).zip(&mean64) {
                        *d = x as f64 - m;
                    }
                    let mut off = 0;
                    for i in 0..dim {
                        let ci = centred[i];
                        let row = &mut s[off..off + dim - i];
                        for (r, &cj) in row.iter_mut().zip(&centred[i..]) {
                            *r += ci * cj;
                        }
                        off += dim - i;
                    }
                }
                s
            })
            .collect();
        let mut cov_tri = vec![0.0f64; tri];
        for s in &partial {
            for (a, &x) in cov_tri.iter_mut().zip(s) {
                *a += x;
            }
        }
        let denom = (n.max(2) - 1) as f64;
        let mut cov = vec![0.0f64; dim * dim];
        let mut off = 0;
        for i in 0..dim {
            for j in i..dim {
                let v = cov_tri[off + j - i] / denom;
                cov[i * dim + j] = v;
                cov[j * dim + i] = v;
            }
            off += dim - i;
        }

        let (values, vectors) = symmetric_eigen(&cov, dim);
        let k = choose_components(&values, params).min(dim);
        let mut basis = Vec::with_capacity(k * dim);
        for c in 0..k {
            basis.extend(vectors[c * dim..(c + 1) * dim].iter().map(|&x| x as f32));
        }
        Pca {
            dim,
            mean: mean64.iter().map(|&m| m as f32).collect(),
            basis,
            eigenvalues: values,
        }
    }

    /// Number of kept components.
    pub fn components(&self) -> usize {
        self.basis.len() / self.dim
    }

    /// Fraction of the total variance the kept components explain (1 if there is none).
    pub fn explained_variance(&self) -> f64 {
        let total: f64 = self.eigenvalues.iter().map(|v| v.max(0.0)).sum();
        if total <= 0.0 {
            return 1.0;
        }
        let kept: f64 = self.eigenvalues[..self.components()]
            .iter()
            .map(|v| v.max(0.0))
            .sum();
        kept / total
    }

    /// Coordinates of `v` (length `dim`) in the kept basis, written to `out`
    /// (length [`Self::components`]).
    pub fn project(&self, v: &[f32], out: &mut [f32]) {
        debug_assert_eq!(v.len(), self.dim);
        for (o, b) in out.iter_mut().zip(self.basis.chunks_exact(self.dim)) {
            let mut acc = 0.0f32;
            for ((&x, &m), &e) in v.iter().zip(&self.mean).zip(b) {
                acc += (x - m) * e;
            }
            *o = acc;
        }
    }

    /// Projects every vector of `data` (as in [`Self::fit`]); parallel, thread-count independent.
    pub fn project_all(&self, data: &[f32]) -> Vec<f32> {
        let k = self.components();
        let n = data.len() / self.dim;
        let mut out = vec![0.0f32; n * k];
        if k == 0 {
            return out;
        }
        out.par_chunks_mut(k)
            .zip(data.par_chunks(self.dim))
            .for_each(|(o, v)| self.project(v, o));
        out
    }
}

/// Number of components for `params` given the eigenvalues in decreasing order.
pub fn choose_components(eigenvalues: &[f64], params: &PcaParams) -> usize {
    let n = eigenvalues.len();
    if params.components > 0 {
        return (params.components as usize).min(n);
    }
    let total: f64 = eigenvalues.iter().map(|v| v.max(0.0)).sum();
    let mut k = n;
    if total > 0.0 {
        let mut acc = 0.0;
        for (i, v) in eigenvalues.iter().enumerate() {
            acc += v.max(0.0);
            if acc >= params.variance * total {
                k = i + 1;
                break;
            }
        }
    }
    k.clamp(
        params.min_auto as usize,
        params.max_auto.max(params.min_auto) as usize,
    )
    .min(n)
}

/// Eigen-decomposition of the symmetric `n × n` matrix `a` (row-major) by cyclic Jacobi
/// rotations. Returns eigenvalues in decreasing order (ties: original order) and the matching
/// unit eigenvectors as rows, each with its largest-magnitude entry made positive.
pub fn symmetric_eigen(a: &[f64], n: usize) -> (Vec<f64>, Vec<f64>) {
    assert_eq!(a.len(), n * n);
    let mut a = a.to_vec();
    // v holds eigenvectors as rows (v = Vᵀ), so rotations touch contiguous rows.
    let mut v = vec![0.0f64; n * n];
    for i in 0..n {
        v[i * n + i] = 1.0;
    }
    let norm: f64 = a.iter().map(|x| x * x).sum::<f64>().sqrt();
    if norm > 0.0 {
        for _sweep in 0..100 {
            let mut off = 0.0;
            for p in 0..n {
                for q in p + 1..n {
                    off += a[p * n + q] * a[p * n + q];
                }
            }
            if off.sqrt() <= 1e-15 * norm {
                break;
            }
            for p in 0..n {
                for q in p + 1..n {
                    let apq = a[p * n + q];
                    if apq.abs() <= 1e-300 {
                        continue;
                    }
                    let app = a[p * n + p];
                    let aqq = a[q * n + q];
                    let theta = (aqq - app) / (2.0 * apq);
                    let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                    let t = if theta == 0.0 { 1.0 } else { t };
                    let c = 1.0 / (t * t + 1.0).sqrt();
                    let s = t * c;
                    // A ← Jᵀ A J on rows/columns p and q.
                    for k in 0..n {
                        let akp = a[k * n + p];
                        let akq = a[k * n + q];
                        a[k * n + p] = c * akp - s * akq;
                        a[k * n + q] = s * akp + c * akq;
                    }
                    for k in 0..n {
                        let apk = a[p * n + k];
                        let aqk = a[q * n + k];
                        a[p * n + k] = c * apk - s * aqk;
                        a[q * n + k] = s * apk + c * aqk;
                    }
                    a[p * n + q] = 0.0;
                    a[q * n + p] = 0.0;
                    let (vp, vq) = {
                        let (lo, hi) = v.split_at_mut(q * n);
                        (&mut lo[p * n..p * n + n], &mut hi[..n])
                    };
                    for (x, y) in vp.iter_mut().zip(vq.iter_mut()) {
                        let (xp, xq) = (*x, *y);
                        *x = c * xp - s * xq;
                        *y = s * xp + c * xq;
                    }
                }
            }
        }
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&i, &j| a[j * n + j].total_cmp(&a[i * n + i]).then(i.cmp(&j)));
    let values = order.iter().map(|&i| a[i * n + i]).collect();
    let mut vectors = Vec::with_capacity(n * n);
    for &i in &order {
        let row = &v[i * n..(i + 1) * n];
        let mut big = 0;
        for (k, x) in row.iter().enumerate() {
            if x.abs() > row[big].abs() {
                big = k;
            }
        }
        let sign = if row[big] < 0.0 { -1.0 } else { 1.0 };
        vectors.extend(row.iter().map(|x| x * sign));
    }
    (values, vectors)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::PureMath;

    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
        fn normal(&mut self) -> f64 {
            let u = self.next().max(1e-12);
            let v = self.next();
            (-2.0 * u.ln_pure()).sqrt() * (std::f64::consts::TAU * v).cos_pure()
        }
    }

    /// `n` vectors in `dim` dimensions spanning a random rank-`sd.len()` subspace with standard
    /// deviations `sd` along its orthonormal axes, plus an offset.
    fn low_rank(n: usize, dim: usize, sd: &[f64], seed: u64) -> (Vec<f32>, Vec<Vec<f64>>) {
        let mut rng = Rng(seed);
        let mut axes: Vec<Vec<f64>> = Vec::new();
        while axes.len() < sd.len() {
            let mut v: Vec<f64> = (0..dim).map(|_| rng.normal()).collect();
            for a in &axes {
                let d: f64 = v.iter().zip(a).map(|(x, y)| x * y).sum();
                for (x, y) in v.iter_mut().zip(a) {
                    *x -= d * y;
                }
            }
            let l: f64 = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            axes.push(v.iter().map(|x| x / l).collect());
        }
        let offset: Vec<f64> = (0..dim).map(|i| i as f64 * 0.1).collect();
        let mut data = Vec::with_capacity(n * dim);
        for _ in 0..n {
            let coef: Vec<f64> = sd.iter().map(|s| s * rng.normal()).collect();
            for i in 0..dim {
                let mut x = offset[i];
                for (c, a) in coef.iter().zip(&axes) {
                    x += c * a[i];
                }
                data.push(x as f32);
            }
        }
        (data, axes)
    }

    fn variance_of(data: &[f32], dim: usize) -> Vec<f64> {
        let n = data.len() / dim;
        let mut mean = vec![0.0; dim];
        for v in data.chunks(dim) {
            for (m, &x) in mean.iter_mut().zip(v) {
                *m += x as f64 / n as f64;
            }
        }
        let mut var = vec![0.0; dim];
        for v in data.chunks(dim) {
            for ((s, &x), m) in var.iter_mut().zip(v).zip(&mean) {
                *s += (x as f64 - m).powi(2) / (n - 1) as f64;
            }
        }
        var
    }

    #[test]
    fn jacobi_diagonalizes() {
        let n = 7;
        let mut rng = Rng(99);
        let mut a = vec![0.0; n * n];
        for i in 0..n {
            for j in i..n {
                let x = rng.next() - 0.5;
                a[i * n + j] = x;
                a[j * n + i] = x;
            }
        }
        let (vals, vecs) = symmetric_eigen(&a, n);
        for k in 0..n {
            let e = &vecs[k * n..(k + 1) * n];
            for i in 0..n {
                let av: f64 = (0..n).map(|j| a[i * n + j] * e[j]).sum();
                assert!((av - vals[k] * e[i]).abs() < 1e-12, "A v != λ v");
            }
            if k > 0 {
                assert!(vals[k] <= vals[k - 1]);
            }
        }
    }

    #[test]
    fn low_rank_data_variance_is_reproduced_and_basis_orthonormal() {
        let dim = 30;
        let sd = [3.0, 2.0, 1.0];
        let (data, axes) = low_rank(5000, dim, &sd, 7);
        let pca = Pca::fit(
            &data,
            dim,
            &PcaParams {
                components: 3,
                ..Default::default()
            },
        );
        assert_eq!(pca.components(), 3);
        // Orthonormal basis.
        for i in 0..3 {
            for j in 0..3 {
                let d: f32 = (0..dim)
                    .map(|t| pca.basis[i * dim + t] * pca.basis[j * dim + t])
                    .sum();
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((d - want).abs() < 1e-5, "basis dot {i} {j} = {d}");
            }
        }
        // The basis spans the generating subspace.
        for i in 0..3 {
            let b = &pca.basis[i * dim..(i + 1) * dim];
            let in_span: f64 = axes
                .iter()
                .map(|a| {
                    a.iter()
                        .zip(b)
                        .map(|(x, &y)| x * y as f64)
                        .sum::<f64>()
                        .powi(2)
                })
                .sum();
            assert!(
                (in_span - 1.0).abs() < 1e-4,
                "component {i} leaves the subspace"
            );
        }
        // Projected data keeps all the variance, component by component.
        let proj = pca.project_all(&data);
        let total_in: f64 = variance_of(&data, dim).iter().sum();
        let var_out = variance_of(&proj, 3);
        let total_out: f64 = var_out.iter().sum();
        assert!(
            (total_out - total_in).abs() < 1e-3 * total_in,
            "{total_out} vs {total_in}"
        );
        for k in 0..3 {
            assert!((var_out[k] - pca.eigenvalues[k]).abs() < 1e-3 * pca.eigenvalues[k]);
            // Sample variance along each axis is close to the generating one.
            assert!((var_out[k].sqrt() - sd[k]).abs() < 0.1 * sd[k]);
        }
        assert!(pca.eigenvalues[3].abs() < 1e-6 * pca.eigenvalues[0]);
        assert!(pca.explained_variance() > 0.999999);
    }

    #[test]
    fn automatic_component_count() {
        let p = PcaParams::default();
        // 95% needs 3 here, in [4, 16] -> 4.
        assert_eq!(
            choose_components(&[10.0, 5.0, 4.0, 0.5, 0.1, 0.0, 0.0], &p),
            4
        );
        // Flat spectrum of 40: 95% needs 38 -> capped at 16.
        assert_eq!(choose_components(&[1.0; 40], &p), 16);
        // 95% of a 20-flat spectrum needs 19 > 16, but of 10 -> 10.
        assert_eq!(choose_components(&[1.0; 10], &p), 10);
        // Never more than the dimension.
        assert_eq!(choose_components(&[1.0, 0.0], &p), 2);
        let fixed = PcaParams { components: 3, ..p };
        assert_eq!(choose_components(&[1.0; 10], &fixed), 3);
    }

    #[test]
    fn fit_is_identical_for_any_thread_count() {
        let dim = 12;
        let (data, _) = low_rank(3 * CHUNK + 17, dim, &[2.0, 1.0, 0.5, 0.25, 0.1], 3);
        let fit = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| Pca::fit(&data, dim, &PcaParams::default()))
        };
        let a = fit(1);
        let b = fit(2);
        let c = fit(3);
        assert_eq!(a, b);
        assert_eq!(a, c);
    }
}
