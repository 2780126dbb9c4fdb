//! The cotangent Laplacian and harmonic interpolation with fixed values.
//!
//! Weights are the usual (cot α + cot β) / 2, clamped below at a small positive value: on
//! meshes with obtuse triangles the raw weights can be negative, which breaks the maximum
//! principle (an interpolated orientation could overshoot its anchors) and the positive
//! definiteness that the Cholesky solver needs.

use super::Mesh;
use crate::graph::{Csr, for_each_run};
use crate::linalg::{IterativeParams, SolveError, solve_spd};
use rayon::prelude::*;

/// Symmetric edge weights as (i, j, w) with i < j, summed over the triangles sharing the edge.
pub fn cotan_weights(mesh: &Mesh) -> Vec<(u32, u32, f64)> {
    // Per triangle in parallel, collected in triangle order: the same list as a loop.
    let w: Vec<(u32, u32, f64)> = mesh
        .triangles
        .par_iter()
        .flat_map_iter(|t| {
            (0..3).filter_map(move |k| {
                let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
                // The angle at c faces edge (a, b).
                let pa = mesh.positions[a as usize].as_dvec3();
                let pb = mesh.positions[b as usize].as_dvec3();
                let pc = mesh.positions[c as usize].as_dvec3();
                let (u, v) = (pa - pc, pb - pc);
                let cross = u.cross(v).length();
                let cot = if cross > 1e-300 {
                    u.dot(v) / cross
                } else {
                    0.0
                };
                let (i, j) = if a < b { (a, b) } else { (b, a) };
                (i != j).then_some((i, j, 0.5 * cot))
            })
        })
        .collect();
    // Order by (i, j) as a stable sort would, in linear time: bucket by i (a counting sort
    // keeps the push order), then sort each short bucket stably by j (buckets in parallel).
    let mut sorted: Csr<(u32, u32, f64), usize> =
        Csr::from_pairs(mesh.vertex_count(), w.iter().map(|&e| (e.0 as usize, e)));
    drop(w);
    for_each_run(&mut sorted.items, &sorted.offsets, |bucket| {
        bucket.sort_by_key(|x| x.1)
    });
    // Sum duplicates in sorted order: a fixed order, so the sums are deterministic.
    let mut out: Vec<(u32, u32, f64)> = Vec::with_capacity(sorted.items.len() / 2 + 1);
    for (i, j, x) in sorted.items {
        match out.last_mut() {
            Some(last) if last.0 == i && last.1 == j => last.2 += x,
            _ => out.push((i, j, x)),
        }
    }
    let mean = out.iter().map(|e| e.2.abs()).sum::<f64>() / out.len().max(1) as f64;
    let floor = 1e-3 * mean.max(1e-12);
    for e in &mut out {
        e.2 = e.2.max(floor);
    }
    out
}

/// Solves the Laplace equation on the mesh for `k` scalar channels with the given vertices
/// fixed to the given values (Dirichlet conditions). Vertices in a connected component with
/// no fixed vertex get 0 (a tiny regularization keeps the system positive definite there).
/// Returns `values[v * k + c]`. Big meshes are solved iteratively to a relative residual of
/// 1e-8 ([`IterativeParams::default`], [`crate::linalg::solve_spd`]).
pub fn harmonic_interpolate(
    mesh: &Mesh,
    weights: &[(u32, u32, f64)],
    fixed: &[(u32, Vec<f64>)],
    k: usize,
) -> Result<Vec<f64>, SolveError> {
    harmonic_interpolate_with(mesh, weights, fixed, k, &IterativeParams::default())
}

/// [`harmonic_interpolate`] with a choice of when and how tightly to solve iteratively.
pub fn harmonic_interpolate_with(
    mesh: &Mesh,
    weights: &[(u32, u32, f64)],
    fixed: &[(u32, Vec<f64>)],
    k: usize,
    params: &IterativeParams,
) -> Result<Vec<f64>, SolveError> {
    let n = mesh.vertex_count();
    let mut fixed_value: Vec<Option<&[f64]>> = vec![None; n];
    for (v, vals) in fixed {
        fixed_value[*v as usize] = Some(vals);
    }
    // Free vertices get consecutive unknown indices.
    let mut unknown = vec![u32::MAX; n];
    let mut count = 0usize;
    for v in 0..n {
        if fixed_value[v].is_none() {
            unknown[v] = count as u32;
            count += 1;
        }
    }
    let mut diag = vec![0.0f64; count];
    let mut triplets = Vec::with_capacity(weights.len() + count);
    let mut rhs = vec![0.0f64; count * k];
    for &(i, j, w) in weights {
        let (ui, uj) = (unknown[i as usize], unknown[j as usize]);
        if ui != u32::MAX {
            diag[ui as usize] += w;
        }
        if uj != u32::MAX {
            diag[uj as usize] += w;
        }
        match (ui != u32::MAX, uj != u32::MAX) {
            (true, true) => triplets.push((ui.max(uj) as usize, ui.min(uj) as usize, -w)),
            (true, false) => {
                let vals = fixed_value[j as usize].unwrap();
                for c in 0..k {
                    rhs[c * count + ui as usize] += w * vals[c];
                }
            }
            (false, true) => {
                let vals = fixed_value[i as usize].unwrap();
                for c in 0..k {
                    rhs[c * count + uj as usize] += w * vals[c];
                }
            }
            (false, false) => {}
        }
    }
    let mean_diag = diag.iter().sum::<f64>() / count.max(1) as f64;
    let eps = 1e-9 * mean_diag.max(1e-12);
    for (u, d) in diag.iter().enumerate() {
        triplets.push((u, u, d + eps));
    }
    let mut out = vec![0.0f64; n * k];
    if count > 0 {
        solve_spd(count, &triplets, &mut rhs, k, params)?;
    }
    for v in 0..n {
        for c in 0..k {
            out[v * k + c] = match fixed_value[v] {
                Some(vals) => vals[c],
                None => rhs[c * count + unknown[v] as usize],
            };
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn grid(n: usize) -> Mesh {
        crate::geom::primitives::grid(n, 1.0 / (n - 1) as f32)
    }

    #[test]
    fn linear_function_is_reproduced_from_its_boundary_values() {
        // A linear function is harmonic for the cotan Laplacian on a planar mesh.
        let n = 12;
        let m = grid(n);
        let f = |p: Vec3| 0.3 + 2.0 * p.x - 1.5 * p.y;
        let mut fixed = Vec::new();
        for (v, p) in m.positions.iter().enumerate() {
            if p.x == 0.0 || p.y == 0.0 || p.x == 1.0 || p.y == 1.0 {
                fixed.push((v as u32, vec![f(*p) as f64, -(f(*p) as f64)]));
            }
        }
        let w = cotan_weights(&m);
        let x = harmonic_interpolate(&m, &w, &fixed, 2).unwrap();
        for (v, p) in m.positions.iter().enumerate() {
            assert!((x[2 * v] - f(*p) as f64).abs() < 1e-5, "vertex {v}");
            assert!((x[2 * v + 1] + f(*p) as f64).abs() < 1e-5);
        }
    }

    #[test]
    fn interpolated_values_stay_within_the_fixed_range() {
        let m = grid(9);
        let w = cotan_weights(&m);
        let x = harmonic_interpolate(&m, &w, &[(0, vec![1.0]), (80, vec![-1.0])], 1).unwrap();
        assert!(x.iter().all(|&v| (-1.0 - 1e-9..=1.0 + 1e-9).contains(&v)));
        assert!(x[40].abs() < 1e-6, "centre should be midway: {}", x[40]);
    }
}
