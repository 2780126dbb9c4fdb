//! The PCA basis of the candidate patches: a block power iteration for the leading
//! eigenvectors of their covariance.

use crate::image::pca::{Pca, symmetric_eigen};
use crate::random::counter_hash;
use rayon::prelude::*;

/// Candidate patches the PCA basis is fitted to (evenly spread over the candidates).
const PCA_FIT_VECTORS: usize = 256;
/// Block power iterations of the PCA fit.
const POWER_ITERATIONS: usize = 30;

/// PCA of the rows of `data`, fitted to at most [`PCA_FIT_VECTORS`] evenly spread rows through
/// their Gram matrix `G = X Xᵀ`: the principal directions of that subset are `Xᵀu/√λ` for the
/// eigenpairs `(λ, u)` of `G`, and the leading ones come from a block power iteration with a
/// Rayleigh–Ritz step, so the cost is neither cubic in the dimension (`w²·3`, up to 12 288) nor
/// in the subset size. Everything is sequential or per-row, so the basis is the same for any
/// thread count.
pub(super) fn fit_pca(data: &[f32], dim: usize, components: usize) -> Pca {
    let n = data.len() / dim;
    let m = n.min(PCA_FIT_VECTORS);
    let rows: Vec<&[f32]> = (0..m)
        .map(|i| {
            let r = i * n / m;
            &data[r * dim..(r + 1) * dim]
        })
        .collect();
    let mut mean = vec![0.0f64; dim];
    for r in &rows {
        for (a, &x) in mean.iter_mut().zip(r.iter()) {
            *a += x as f64;
        }
    }
    for a in &mut mean {
        *a /= m.max(1) as f64;
    }
    let centred: Vec<Vec<f64>> = rows
        .iter()
        .map(|r| r.iter().zip(&mean).map(|(&x, &mu)| x as f64 - mu).collect())
        .collect();
    let gram: Vec<f64> = (0..m)
        .into_par_iter()
        .flat_map_iter(|i| {
            let ci = &centred[i];
            centred.iter().map(move |cj| dot(ci, cj))
        })
        .collect();
    let (values, vectors) = leading_eigen(&gram, m, components + 8);
    let top = values.first().copied().unwrap_or(0.0);
    let mut basis = Vec::new();
    for (c, &l) in values.iter().enumerate().take(components) {
        if !(l > top * 1e-9 && l > 0.0) {
            break;
        }
        let mut b = vec![0.0f64; dim];
        for (i, row) in centred.iter().enumerate() {
            let u = vectors[c * m + i];
            for (x, &y) in b.iter_mut().zip(row) {
                *x += u * y;
            }
        }
        let norm = b.iter().map(|x| x * x).sum::<f64>().sqrt();
        basis.extend(b.iter().map(|x| (x / norm) as f32));
    }
    if basis.is_empty() {
        // A flat exemplar: no direction separates anything, but the tree needs one.
        basis = vec![0.0; dim];
        basis[0] = 1.0;
    }
    Pca {
        dim,
        mean: mean.iter().map(|&x| x as f32).collect(),
        basis,
        eigenvalues: values.iter().map(|v| v / (m.max(2) - 1) as f64).collect(),
    }
}

/// Dot product in four interleaved partial sums (vectorizable, and a fixed order).
pub(super) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0f64; 4];
    let mut ca = a.chunks_exact(4);
    let mut cb = b.chunks_exact(4);
    for (x, y) in (&mut ca).zip(&mut cb) {
        for t in 0..4 {
            acc[t] += x[t] * y[t];
        }
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for (x, y) in ca.remainder().iter().zip(cb.remainder()) {
        s += x * y;
    }
    s
}

/// The `k` leading eigenpairs of the symmetric `n × n` matrix `a` (row-major), eigenvalues
/// decreasing, eigenvectors as rows: block power iteration on `k` vectors, then the
/// Rayleigh–Ritz projection solved by [`symmetric_eigen`].
pub(super) fn leading_eigen(a: &[f64], n: usize, k: usize) -> (Vec<f64>, Vec<f64>) {
    let k = k.min(n);
    if k == 0 {
        return (Vec::new(), Vec::new());
    }
    // Block as k rows of length n.
    let mut v: Vec<f64> = (0..k * n)
        .map(|i| counter_hash(0x9ca, 0, i as u64) as f64 / u64::MAX as f64 - 0.5)
        .collect();
    let multiply = |v: &[f64]| -> Vec<f64> {
        v.par_chunks(n)
            .flat_map_iter(|row| (0..n).map(move |i| dot(&a[i * n..(i + 1) * n], row)))
            .collect()
    };
    let orthonormalize = |v: &mut [f64]| {
        for r in 0..k {
            let (done, rest) = v.split_at_mut(r * n);
            let row = &mut rest[..n];
            for q in done.chunks_exact(n) {
                let d: f64 = q.iter().zip(row.iter()).map(|(x, y)| x * y).sum();
                for (x, y) in row.iter_mut().zip(q) {
                    *x -= d * y;
                }
            }
            let norm = row.iter().map(|x| x * x).sum::<f64>().sqrt();
            if norm > 1e-300 {
                row.iter_mut().for_each(|x| *x /= norm);
            } else {
                row.iter_mut().for_each(|x| *x = 0.0);
            }
        }
    };
    orthonormalize(&mut v);
    for _ in 0..POWER_ITERATIONS {
        v = multiply(&v);
        orthonormalize(&mut v);
    }
    let av = multiply(&v);
    let mut h = vec![0.0f64; k * k];
    for i in 0..k {
        for j in 0..k {
            h[i * k + j] = v[i * n..(i + 1) * n]
                .iter()
                .zip(&av[j * n..(j + 1) * n])
                .map(|(x, y)| x * y)
                .sum();
        }
    }
    // Symmetrize rounding.
    for i in 0..k {
        for j in i + 1..k {
            let s = 0.5 * (h[i * k + j] + h[j * k + i]);
            h[i * k + j] = s;
            h[j * k + i] = s;
        }
    }
    let (values, small) = symmetric_eigen(&h, k);
    let mut vectors = vec![0.0f64; k * n];
    for c in 0..k {
        for j in 0..k {
            let w = small[c * k + j];
            for (x, y) in vectors[c * n..(c + 1) * n]
                .iter_mut()
                .zip(&v[j * n..(j + 1) * n])
            {
                *x += w * y;
            }
        }
    }
    (values, vectors)
}
