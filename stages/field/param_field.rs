//! The orientation and scaling field of geometric texture synthesis, over a geometry image
//! (Lai et al., "Geometric Texture Synthesis and Transfer via Geometry Images", §4.3).
//!
//! - Orientation: the user gives key tangent vectors at chosen points; they are diffused over
//!   the surface and each result is mapped into the parameter domain by solving
//!   x·X_u + y·X_v = v (least squares), then normalized. The paper diffuses by explicit
//!   iterations, coarse to fine; we solve the same diffusion's steady state directly: a sparse
//!   harmonic problem over the grid samples with the paper's weights (reciprocal edge length)
//!   and the key vectors as fixed values, one Cholesky factorization for three right-hand
//!   sides. Mated samples share one unknown, which is the paper's "average the vectors for
//!   corresponding vertices on each iterative update" taken to convergence, so both sides of a
//!   cut see the same 3D direction (each in its own grid frame). Without key vectors the
//!   texture follows the parameterization (direction (0, 1) everywhere: no rotation).
//! - Scaling: S(v₀), the mean distance to the 4-connected neighbours, and R = S / S̄ with S̄
//!   the median over the image (the paper says mean; see [`reference_spacing`]). The global density offset of §5 (Fig. 8) multiplies R by
//!   2^offset: positive offsets pick smaller sample variants, so the texture gets denser.

use crate::check::{ParamError, check_range};
use crate::geom::geometry_image::GeometryImage;
use crate::linalg::{SolveError, SpdSolver};
use glam::{DVec3, Vec2, Vec3};
use serde::{Deserialize, Serialize};
use texsyn_core::algorithm::Failure;
use texsyn_core::math::PureMath;

/// The `param_field` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("param_field", 3);

/// A key tangent vector: a direction at the surface point nearest to `at`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeyVector {
    pub at: [f32; 3],
    pub direction: [f32; 3],
}

/// `[field]` of the geometry-image method.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ParamFieldParams {
    /// Key tangent vectors: the texture's "up" at those points. Default: none (the texture
    /// follows the parameterization).
    pub keys: Vec<KeyVector>,
    /// Global density offset in octaves, -3..=3: +1 makes the texture twice as dense. Default: 0.
    pub density_offset: f32,
}

impl ParamFieldParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        for (k, key) in self.keys.iter().enumerate() {
            let d = Vec3::from(key.direction);
            if !Vec3::from(key.at).is_finite() || !d.is_finite() || d.length() < 1e-12 {
                return Err(ParamError::invalid(
                    "`at`",
                    "must be finite and `direction` finite and non-zero",
                )
                .within(&format!("field.keys[{k}]")));
            }
        }
        check_range("field.density_offset", self.density_offset, -3.0, 3.0)
    }
}

/// Why the field could not be computed.
#[derive(Debug, thiserror::Error)]
pub enum ParamFieldError {
    #[error(transparent)]
    Params(#[from] ParamError),
    #[error("field.keys[{index}]: direction is normal to the surface at {at:?}")]
    NormalKey { index: usize, at: [f32; 3] },
    #[error(transparent)]
    Solve(#[from] SolveError),
}

/// The per-sample controls of synthesis (§4.3), one entry per geometry-image sample
/// (`i * n + j`).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct ParamField {
    /// Desired texture "up" direction in grid coordinates (`x` = column `j`, `y` = row `i`),
    /// unit length. The sample's up is its own `+y` axis (its rows, the direction of `dy`), so
    /// `(0, 1)` everywhere reproduces the sample unrotated. A zero vector counts as `(0, 1)`.
    pub dir: Vec<Vec2>,
    /// Relative scaling `R(v0)` (§4.3, including any global density offset), > 0. `R = 1` uses
    /// the sample's own size, `R = 2` (grid points twice as far apart on the surface as on
    /// average) the sample scaled down by 2, `R = 0.5` scaled up by 2.
    pub rel_scale: Vec<f32>,
}

pub fn param_field(
    gi: &GeometryImage,
    p: &ParamFieldParams,
) -> Result<ParamField, ParamFieldError> {
    p.validate()?;
    let n = gi.n as usize;
    let count = n * n;
    let dir = if p.keys.is_empty() {
        vec![Vec2::Y; count]
    } else {
        let vectors = diffuse_keys(gi, &p.keys)?;
        (0..count)
            .map(|k| to_parameter_domain(gi, k, vectors[k]).unwrap_or(Vec2::Y))
            .collect()
    };
    let spacing = local_spacing(gi);
    let mean = spacing.iter().map(|&s| s as f64).sum::<f64>() / count as f64;
    let factor = 2f64.powf_pure(p.density_offset as f64);
    let rel_scale = spacing
        .iter()
        .map(|&s| {
            if mean > 0.0 {
                (s as f64 / mean * factor) as f32
            } else {
                1.0
            }
        })
        .collect();
    Ok(ParamField { dir, rel_scale })
}

/// S̄: the median of S(v₀) over the samples. The paper takes the mean; a geometry image's
/// spacing varies a lot (protrusions are sampled sparsely), and the few sparse samples pull the
/// mean up until R < 1 over most of the surface, which makes the texture coarse everywhere. The
/// median puts R = 1 where most of the surface is.
pub fn reference_spacing(spacing: &[f32]) -> f32 {
    let mut s: Vec<f32> = spacing
        .iter()
        .copied()
        .filter(|v| *v > 0.0 && v.is_finite())
        .collect();
    if s.is_empty() {
        return 0.0;
    }
    s.sort_by(|a, b| a.total_cmp(b));
    s[s.len() / 2]
}

/// S(v₀): mean distance to the existing 4-connected grid neighbours.
pub fn local_spacing(gi: &GeometryImage) -> Vec<f32> {
    let n = gi.n as i64;
    (0..n * n)
        .map(|k| {
            let (i, j) = (k / n, k % n);
            let p = gi.positions[k as usize];
            let mut sum = 0.0f32;
            let mut c = 0;
            for (di, dj) in [(0, 1), (0, -1), (1, 0), (-1, 0)] {
                let (a, b) = (i + di, j + dj);
                if a >= 0 && b >= 0 && a < n && b < n {
                    sum += p.distance(gi.positions[(a * n + b) as usize]);
                    c += 1;
                }
            }
            if c > 0 { sum / c as f32 } else { 0.0 }
        })
        .collect()
}

/// Harmonic interpolation of the key vectors over the grid (mates merged), projected into
/// each sample's tangent plane.
fn diffuse_keys(gi: &GeometryImage, keys: &[KeyVector]) -> Result<Vec<Vec3>, ParamFieldError> {
    let n = gi.n as usize;
    let count = n * n;
    // Unknowns: one per mate group.
    let mut unknown = vec![u32::MAX; count];
    let mut reps = Vec::new();
    for k in 0..count {
        let r = gi.mate_rep[k] as usize;
        if r == k {
            unknown[k] = reps.len() as u32;
            reps.push(k);
        }
    }
    for k in 0..count {
        unknown[k] = unknown[gi.mate_rep[k] as usize];
    }
    // Fixed values: the key vectors at their nearest samples, projected into the tangent plane.
    let mut fixed: Vec<Option<DVec3>> = vec![None; reps.len()];
    for (idx, key) in keys.iter().enumerate() {
        let at = Vec3::from(key.at);
        let k = (0..count)
            .min_by(|&a, &b| {
                gi.positions[a]
                    .distance_squared(at)
                    .total_cmp(&gi.positions[b].distance_squared(at))
            })
            .expect("a geometry image has samples");
        let nrm = gi.normals[k];
        let d = Vec3::from(key.direction);
        let t = d - d.dot(nrm) * nrm;
        if t.length() < 1e-6 * d.length() {
            return Err(ParamFieldError::NormalKey {
                index: idx,
                at: key.at,
            });
        }
        fixed[unknown[k] as usize] = Some(t.normalize().as_dvec3());
    }
    // Free unknowns get consecutive indices in the reduced system.
    let mut free = vec![u32::MAX; reps.len()];
    let mut nfree = 0usize;
    for u in 0..reps.len() {
        if fixed[u].is_none() {
            free[u] = nfree as u32;
            nfree += 1;
        }
    }
    let mut diag = vec![0.0f64; nfree];
    let mut triplets = Vec::new();
    let mut rhs = vec![0.0f64; 3 * nfree];
    let mut add_edge = |a: usize, b: usize| {
        let (ua, ub) = (unknown[a] as usize, unknown[b] as usize);
        let len = gi.positions[a].distance(gi.positions[b]) as f64;
        if ua == ub || len <= 0.0 {
            return;
        }
        let w = 1.0 / len;
        for (x, y) in [(ua, ub), (ub, ua)] {
            if free[x] == u32::MAX {
                continue;
            }
            let fx = free[x] as usize;
            diag[fx] += w;
            match fixed[y] {
                Some(v) => {
                    rhs[fx] += w * v.x;
                    rhs[nfree + fx] += w * v.y;
                    rhs[2 * nfree + fx] += w * v.z;
                }
                None => {
                    if x > y {
                        triplets.push((fx, free[y] as usize, -w));
                    }
                }
            }
        }
    };
    for i in 0..n {
        for j in 0..n {
            let k = i * n + j;
            if j + 1 < n {
                add_edge(k, k + 1);
            }
            if i + 1 < n {
                add_edge(k, k + n);
            }
        }
    }
    let eps = 1e-9 * diag.iter().sum::<f64>() / nfree.max(1) as f64;
    for (u, d) in diag.iter().enumerate() {
        triplets.push((u, u, d + eps.max(1e-300)));
    }
    if nfree > 0 {
        SpdSolver::new(nfree, &triplets)?.solve(&mut rhs, 3);
    }
    Ok((0..count)
        .map(|k| {
            let u = unknown[k] as usize;
            let v = match fixed[u] {
                Some(v) => v,
                None => {
                    let f = free[u] as usize;
                    DVec3::new(rhs[f], rhs[nfree + f], rhs[2 * nfree + f])
                }
            }
            .as_vec3();
            let nrm = gi.normals[k];
            (v - v.dot(nrm) * nrm).normalize_or_zero()
        })
        .collect())
}

/// Solves x·X_u + y·X_v = v in the least-squares sense with grid derivatives at sample k
/// (central differences, one-sided at the border) and normalizes (x, y).
fn to_parameter_domain(gi: &GeometryImage, k: usize, v: Vec3) -> Option<Vec2> {
    if v == Vec3::ZERO {
        return None;
    }
    let n = gi.n as usize;
    let (i, j) = (k / n, k % n);
    let p = |i: usize, j: usize| gi.positions[i * n + j];
    let d = |a: Vec3, b: Vec3, steps: f32| (b - a) / steps;
    let xu = match j {
        0 => d(p(i, 0), p(i, 1), 1.0),
        _ if j == n - 1 => d(p(i, n - 2), p(i, n - 1), 1.0),
        _ => d(p(i, j - 1), p(i, j + 1), 2.0),
    };
    let xv = match i {
        0 => d(p(0, j), p(1, j), 1.0),
        _ if i == n - 1 => d(p(n - 2, j), p(n - 1, j), 1.0),
        _ => d(p(i - 1, j), p(i + 1, j), 2.0),
    };
    // Normal equations of [X_u X_v] (x, y)ᵀ = v.
    let (a, b, c) = (xu.dot(xu) as f64, xu.dot(xv) as f64, xv.dot(xv) as f64);
    let (r1, r2) = (xu.dot(v) as f64, xv.dot(v) as f64);
    let det = a * c - b * b;
    if det.abs() < 1e-30 {
        return None;
    }
    let x = (c * r1 - b * r2) / det;
    let y = (a * r2 - b * r1) / det;
    let out = Vec2::new(x as f32, y as f32);
    (out.length() > 0.0).then(|| out.normalize())
}

/// The field node: the direction field over the geometry image.
pub fn node(gi: &GeometryImage, p: &ParamFieldParams) -> Result<ParamField, Failure> {
    param_field(gi, p).map_err(Failure::input)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat n×n geometry image with x along columns and y along rows, spacing `h`.
    fn plane(n: u32, h: f32) -> GeometryImage {
        let mut positions = Vec::new();
        for i in 0..n {
            for j in 0..n {
                positions.push(Vec3::new(j as f32 * h, i as f32 * h, 0.0));
            }
        }
        let count = (n * n) as usize;
        GeometryImage {
            n,
            positions,
            normals: vec![Vec3::Z; count],
            mate_rep: (0..count as u32).collect(),
        }
    }

    #[test]
    fn a_single_key_vector_orients_the_whole_plane_in_grid_coordinates() {
        let gi = plane(9, 0.5);
        // World +x is the column direction: grid (1, 0).
        let p = ParamFieldParams {
            keys: vec![KeyVector {
                at: [1.0, 1.0, 0.0],
                direction: [1.0, 0.0, 0.3],
            }],
            density_offset: 0.0,
        };
        let f = param_field(&gi, &p).unwrap();
        for d in &f.dir {
            assert!((*d - Vec2::X).length() < 1e-5, "{d}");
        }
        // On a uniform plane R = 1 everywhere but at the border (one-sided neighbours are
        // the same distance, so also 1).
        assert!(f.rel_scale.iter().all(|&r| (r - 1.0).abs() < 1e-5));
    }

    #[test]
    fn the_parameter_direction_undoes_a_stretched_parameterization() {
        // Rows twice as far apart as columns: a 45° world direction is (1, 0.5) in grid
        // steps, normalized.
        let mut gi = plane(9, 1.0);
        for p in &mut gi.positions {
            p.y *= 2.0;
        }
        let p = ParamFieldParams {
            keys: vec![KeyVector {
                at: [0.0; 3],
                direction: [1.0, 1.0, 0.0],
            }],
            density_offset: 0.0,
        };
        let f = param_field(&gi, &p).unwrap();
        let want = Vec2::new(1.0, 0.5).normalize();
        assert!((f.dir[40] - want).length() < 1e-5, "{}", f.dir[40]);
    }

    #[test]
    fn two_keys_blend_smoothly_and_mates_share_a_direction() {
        let mut gi = plane(17, 0.25);
        // Mate the left and right columns (a cylinder-like cut), positions made identical.
        let n = 17usize;
        for i in 0..n {
            let (l, r) = (i * n, i * n + n - 1);
            gi.positions[r] = gi.positions[l];
            gi.mate_rep[r] = l as u32;
        }
        let p = ParamFieldParams {
            keys: vec![
                KeyVector {
                    at: [1.0, 0.0, 0.0],
                    direction: [1.0, 0.0, 0.0],
                },
                KeyVector {
                    at: [1.0, 4.0, 0.0],
                    direction: [0.0, 1.0, 0.0],
                },
            ],
            density_offset: 1.0,
        };
        let f = param_field(&gi, &p).unwrap();
        // Turning monotonically from +x at the bottom to +y at the top, along column 4.
        let angle = |i: usize| f.dir[i * n + 4].y.atan2_pure(f.dir[i * n + 4].x);
        for i in 1..n {
            assert!(angle(i) >= angle(i - 1) - 1e-4, "row {i}");
        }
        assert!(angle(0) < 0.2 && angle(n - 1) > 1.3);
        assert!(
            f.rel_scale.iter().all(|&r| r > 1.0),
            "density offset +1 doubles R"
        );
    }

    #[test]
    fn keys_normal_to_the_surface_are_rejected_by_name() {
        let gi = plane(5, 1.0);
        let p = ParamFieldParams {
            keys: vec![KeyVector {
                at: [0.0; 3],
                direction: [0.0, 0.0, 1.0],
            }],
            density_offset: 0.0,
        };
        let e = param_field(&gi, &p).unwrap_err().to_string();
        assert!(e.starts_with("field.keys[0]: direction is normal"), "{e}");
        let mut p = p;
        p.keys[0].direction = [0.0; 3];
        assert_eq!(
            param_field(&gi, &p).unwrap_err().to_string(),
            "field.keys[0]: `at` must be finite and `direction` finite and non-zero"
        );
    }
}
