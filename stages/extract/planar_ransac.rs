//! Planar parameter domain sampling (Lai et al., "Geometric Texture Synthesis and Transfer
//! via Geometry Images", §4.1.2).
//!
//! A plane is fitted to the sample patch by RANSAC on area-uniform random surface samples
//! (not the vertices, which are "generally not evenly distributed"): planes through three
//! random samples, the one with the most samples within δ kept, and refitted by least squares
//! (PCA) to its inliers. The patch's boundary vertices are projected onto the plane, the
//! interior is placed by a convex-combination (mean-value) map with that boundary fixed, and an
//! N×N grid is sampled in the largest square of the parameter domain
//! ([`super::square_domain`]). Each texel is the difference between the patch point mapped to
//! the sample and the sample's point on the plane, in the frame (e1, e2, e1 × e2).
//!
//! Departures: the paper fits H_S to "a set S of a few points" by least squares; three points
//! define the plane exactly, so that is what is drawn. Planes are ranked by the truncated
//! quadratic cost Σ min(d², δ²) (MSAC, Torr & Zisserman 2000) rather than by the inlier count
//! I(S): with a δ generous enough to hold the texture's relief, counting prefers planes tilted
//! to catch the feet of the outliers while their inliers still fit within ±δ (a 3° error on a
//! flat sample with a 30% ridge); the cost prefers the plane its inliers are closest to. The
//! least-squares refit on the inliers (d ≤ δ) is the paper's. The square's orientation in the plane is
//! searched (see [`super::square_domain`]). The plane's normal is turned to agree with the
//! patch's face normals, so dn > 0 is outside the surface.

use super::square_domain::{Locator, Square, largest_rotated_square, rotate_into};
use super::{ExtractError, ParamError, check_range};
use crate::geom::Mesh;
use crate::geom::geometry_image::TexelImage;
use crate::geom::mean_value::convex_combination_map;
use crate::random::counter_hash;
use glam::{DVec3, Vec2, Vec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use texsyn_core::math::PureMath;

/// Random streams of this module (counter-based, see [`crate::random`]).
const STREAM_FACE: u64 = 0x5041_4e45_0001;
const STREAM_BARY: u64 = 0x5041_4e45_0002;
const STREAM_PICK: u64 = 0x5041_4e45_0003;

/// A plane with an orthonormal, right-handed frame: `e1 × e2 = normal`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub origin: Vec3,
    pub normal: Vec3,
    pub e1: Vec3,
    pub e2: Vec3,
}

impl Plane {
    /// `p` in the plane's frame: (along e1, along e2, height along the normal).
    #[inline]
    pub fn coords(&self, p: Vec3) -> Vec3 {
        let d = p - self.origin;
        Vec3::new(d.dot(self.e1), d.dot(self.e2), d.dot(self.normal))
    }

    /// The point of the plane at (x, y).
    #[inline]
    pub fn point(&self, q: Vec2) -> Vec3 {
        self.origin + q.x * self.e1 + q.y * self.e2
    }

    /// The same plane with (e1, e2) turned by `angle` radians about the normal, so that the
    /// new coordinates of a point are [`rotate_into`] of its old ones.
    pub fn rotated(&self, angle: f32) -> Plane {
        let (s, c) = angle.sin_cos_pure();
        let e1 = (c * self.e1 + s * self.e2).normalize();
        Plane {
            origin: self.origin,
            normal: self.normal,
            e1,
            e2: self.normal.cross(e1),
        }
    }
}

/// The plane fit's parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RansacParams {
    /// Planes tried, 1..=1000000. Default: 500.
    pub iterations: u32,
    /// Inlier distance δ in object units (> 0). Default: 0.01 × the patch's size (the square
    /// root of its area).
    pub inlier_distance: Option<f32>,
    /// Area-uniform random surface samples, 16..=1000000. Default: 4096.
    pub samples: u32,
    /// Seed of the samples and of the draws. Default: 1.
    pub seed: u64,
}

impl Default for RansacParams {
    fn default() -> Self {
        RansacParams {
            iterations: 500,
            inlier_distance: None,
            samples: 4096,
            seed: 1,
        }
    }
}

impl RansacParams {
    /// Checks every field; the error names the field, its range and the value.
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("ransac_iterations", self.iterations, 1, 1_000_000)?;
        check_range("surface_samples", self.samples, 16, 1_000_000)?;
        if let Some(d) = self.inlier_distance {
            super::check_positive("inlier_distance", d)?;
        }
        Ok(())
    }
}

/// The result of [`fit_plane_ransac`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneFit {
    /// Origin at the inliers' centroid, normal agreeing with the patch's face normals, e1 the
    /// world axis least aligned with the normal, projected into the plane.
    pub plane: Plane,
    /// How many of the surface samples were inliers of the best 3-sample plane.
    pub inliers: u32,
    pub samples: u32,
    /// The δ used (object units).
    pub inlier_distance: f32,
}

/// Fits a plane to the surface of `mesh` (§4.1.2): RANSAC over area-uniform random samples
/// with a least-squares (PCA) refit to the best plane's inliers. Deterministic for a seed.
pub fn fit_plane_ransac(mesh: &Mesh, params: &RansacParams) -> Result<PlaneFit, ExtractError> {
    params.validate()?;
    if mesh.triangles.is_empty() {
        return Err(ExtractError::EmptyMesh);
    }
    super::check_finite(mesh)?;
    let faces = mesh.triangles.len();
    let degenerate = |message: &str| ExtractError::DegeneratePatch {
        faces,
        message: message.to_owned(),
    };
    let (lo, hi) = mesh.bounds();
    let diagonal = (hi - lo).length();
    let size = surface_area(mesh).sqrt() as f32;
    let delta = params.inlier_distance.unwrap_or(0.01 * size);
    if !(delta > 0.0 && diagonal > 0.0) {
        return Err(degenerate("its triangles have zero total area"));
    }

    let points = surface_samples(mesh, params.samples, params.seed)
        .ok_or_else(|| degenerate("its triangles have zero total area"))?;
    let s = points.len() as u64;
    // Per plane: (inlier count, truncated quadratic cost).
    let scores: Vec<(u32, f64)> = (0..params.iterations)
        .into_par_iter()
        .map(|t| {
            let pick = |k: u64| {
                points[(counter_hash(params.seed, STREAM_PICK, 3 * t as u64 + k) % s) as usize]
            };
            let (a, b, c) = (pick(0), pick(1), pick(2));
            let n = (b - a).cross(c - a);
            let len = n.length();
            if len.is_nan() || len <= 1e-6 * diagonal * diagonal {
                return (0, f64::INFINITY);
            }
            let n = n / len;
            let (mut count, mut cost) = (0u32, 0.0f64);
            for &p in &points {
                let d = (p - a).dot(n).abs();
                if d <= delta {
                    count += 1;
                }
                cost += (d.min(delta) as f64).powi(2);
            }
            (count, cost)
        })
        .collect();
    // The least cost, the first of equals (a fixed order, whatever the thread count).
    let mut best = 0usize;
    for (t, sc) in scores.iter().enumerate() {
        if sc.1 < scores[best].1 {
            best = t;
        }
    }
    if scores[best].0 < 3 {
        return Err(degenerate(
            "no three random surface samples span a plane (is it a line?)",
        ));
    }
    let pick =
        |k: u64| points[(counter_hash(params.seed, STREAM_PICK, 3 * best as u64 + k) % s) as usize];
    let (a, b, c) = (pick(0), pick(1), pick(2));
    let n = (b - a).cross(c - a).normalize();
    let inliers: Vec<Vec3> = points
        .iter()
        .copied()
        .filter(|&p| (p - a).dot(n).abs() <= delta)
        .collect();
    let (centroid, normal) = pca_plane(&inliers).unwrap_or((a.as_dvec3(), n.as_dvec3()));

    // Outward: agree with the area-weighted face normals.
    let mut outward = DVec3::ZERO;
    for f in 0..faces {
        outward += mesh.face_normal_unnormalized(f).as_dvec3();
    }
    let mut normal = normal.as_vec3().normalize();
    if outward.dot(normal.as_dvec3()) < 0.0 {
        normal = -normal;
    }
    // e1: the world axis least aligned with the normal (the first on ties), in the plane.
    let abs = normal.abs();
    let axis = if abs.x <= abs.y && abs.x <= abs.z {
        Vec3::X
    } else if abs.y <= abs.z {
        Vec3::Y
    } else {
        Vec3::Z
    };
    let e1 = (axis - axis.dot(normal) * normal).normalize();
    Ok(PlaneFit {
        plane: Plane {
            origin: centroid.as_vec3(),
            normal,
            e1,
            e2: normal.cross(e1),
        },
        inliers: scores[best].0,
        samples: points.len() as u32,
        inlier_distance: delta,
    })
}

/// The total area of the mesh's triangles (summed in triangle order).
pub fn surface_area(mesh: &Mesh) -> f64 {
    (0..mesh.triangles.len())
        .map(|f| 0.5 * mesh.face_normal_unnormalized(f).as_dvec3().length())
        .sum()
}

/// `count` points uniformly distributed by area over the mesh's surface: sample k picks a
/// triangle with probability proportional to its area and a uniform point in it, from
/// counter-based random numbers of (seed, k). `None` when the total area is zero.
pub fn surface_samples(mesh: &Mesh, count: u32, seed: u64) -> Option<Vec<Vec3>> {
    let mut cumulative = Vec::with_capacity(mesh.triangles.len());
    let mut total = 0.0f64;
    for f in 0..mesh.triangles.len() {
        total += 0.5 * mesh.face_normal_unnormalized(f).as_dvec3().length();
        cumulative.push(total);
    }
    if !(total > 0.0 && total.is_finite()) {
        return None;
    }
    let unit =
        |stream: u64, k: u64| (counter_hash(seed, stream, k) >> 11) as f64 / (1u64 << 53) as f64;
    Some(
        (0..count as u64)
            .into_par_iter()
            .map(|k| {
                let target = unit(STREAM_FACE, k) * total;
                let f = cumulative
                    .partition_point(|&c| c <= target)
                    .min(cumulative.len() - 1);
                let [a, b, c] = mesh.triangles[f].map(|v| mesh.positions[v as usize].as_dvec3());
                let r1 = unit(STREAM_BARY, 2 * k).sqrt();
                let r2 = unit(STREAM_BARY, 2 * k + 1);
                (a * (1.0 - r1) + b * (r1 * (1.0 - r2)) + c * (r1 * r2)).as_vec3()
            })
            .collect(),
    )
}

/// Least-squares plane through points: (centroid, unit normal = the direction of least
/// variance). `None` for fewer than 3 points.
pub fn pca_plane(points: &[Vec3]) -> Option<(DVec3, DVec3)> {
    if points.len() < 3 {
        return None;
    }
    let mut c = DVec3::ZERO;
    for p in points {
        c += p.as_dvec3();
    }
    c /= points.len() as f64;
    let mut m = [[0.0f64; 3]; 3];
    for p in points {
        let d = p.as_dvec3() - c;
        let d = [d.x, d.y, d.z];
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += d[i] * d[j];
            }
        }
    }
    let (values, vectors) = symmetric_eigen3(m);
    let mut k = 0;
    for i in 1..3 {
        if values[i] < values[k] {
            k = i;
        }
    }
    let n = DVec3::new(vectors[0][k], vectors[1][k], vectors[2][k]).normalize();
    n.is_finite().then_some((c, n))
}

/// Eigen-decomposition of a symmetric 3×3 matrix by cyclic Jacobi rotations: (eigenvalues,
/// eigenvectors as the columns of the second matrix).
pub fn symmetric_eigen3(mut a: [[f64; 3]; 3]) -> ([f64; 3], [[f64; 3]; 3]) {
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let scale: f64 = a.iter().flatten().map(|x| x.abs()).sum::<f64>().max(1e-300);
    for _sweep in 0..64 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        if off <= 1e-15 * scale {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q].abs() <= 1e-300 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for row in a.iter_mut() {
                let (kp, kq) = (row[p], row[q]);
                row[p] = c * kp - s * kq;
                row[q] = s * kp + c * kq;
            }
            for k in 0..3 {
                let (pk, qk) = (a[p][k], a[q][k]);
                a[p][k] = c * pk - s * qk;
                a[q][k] = s * pk + c * qk;
            }
            for row in v.iter_mut() {
                let (kp, kq) = (row[p], row[q]);
                row[p] = c * kp - s * kq;
                row[q] = s * kp + c * kq;
            }
        }
    }
    ([a[0][0], a[1][1], a[2][2]], v)
}

/// A texture sampled on a square of a plane: the planar and height-field extractors' result.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanarExtraction {
    /// `size`×`size` texels (dx, dy, dn[, r, g, b]); column j runs along `plane.e1`, row i
    /// along `plane.e2`.
    pub texels: TexelImage,
    /// The fitted plane, its (e1, e2) turned to the square's orientation.
    pub plane: Plane,
    /// The sampled square in the plane's (e1, e2) coordinates.
    pub square: Square,
    /// Inliers of the RANSAC plane among the surface samples.
    pub inliers: u32,
}

impl PlanarExtraction {
    /// The point of the plane under texel (column `col`, row `row`).
    pub fn sample_point(&self, row: u32, col: u32) -> Vec3 {
        self.plane
            .point(self.square.sample(self.texels.width, row, col))
    }
}

/// A `size`×`size` texel image over `square` of the patch's parameter domain `uv`: at each
/// sample point `q`, `hit` picks the triangle and barycentric weights under it (a texel with
/// no triangle stays zero), `texel` writes the relief channels from the interpolated point,
/// and the patch's colours, when it has them, go to channels 3..6. Rows run in parallel.
pub(crate) fn sample_square(
    patch: &Mesh,
    uv: &[Vec2],
    square: &Square,
    size: u32,
    hit: impl Fn(&Locator, Vec2) -> Option<(u32, [f32; 3])> + Sync,
    texel: impl Fn(&mut [f32], Vec2, Vec3) + Sync,
) -> TexelImage {
    let locator = Locator::new(uv, &patch.triangles);
    let channels = super::channels_for(patch);
    let mut texels = TexelImage::new(size, size, channels);
    texels
        .data
        .par_chunks_mut((size * channels) as usize)
        .enumerate()
        .for_each(|(row, out)| {
            for col in 0..size {
                let q = square.sample(size, row as u32, col);
                let t = &mut out[(col * channels) as usize..((col + 1) * channels) as usize];
                let Some((f, w)) = hit(&locator, q) else {
                    continue;
                };
                let (p, c) = interpolate(patch, f, w);
                texel(t, q, p);
                if let Some(c) = c {
                    t[3..6].copy_from_slice(&c);
                }
            }
        });
    texels
}

/// The texel channels at a point of triangle `f` with barycentric coordinates `w`: the
/// interpolated position and, when the mesh has colours, its interpolated colour.
pub(crate) fn interpolate(mesh: &Mesh, f: u32, w: [f32; 3]) -> (Vec3, Option<[f32; 3]>) {
    let t = mesh.triangles[f as usize];
    let p = mesh.positions[t[0] as usize] * w[0]
        + mesh.positions[t[1] as usize] * w[1]
        + mesh.positions[t[2] as usize] * w[2];
    let c = mesh.colors.as_ref().map(|cs| {
        let get = |v: u32| cs.get(v as usize).copied().unwrap_or([1.0; 4]);
        let (a, b, c) = (get(t[0]), get(t[1]), get(t[2]));
        std::array::from_fn(|k| a[k] * w[0] + b[k] * w[1] + c[k] * w[2])
    });
    (p, c)
}

/// What the planar and height-field extractors start with: `size` checked (1..=8192 texels
/// a side), then the plane fitted to the patch ([`fit_plane_ransac`]).
pub(crate) fn fit_sampling_plane(
    patch: &Mesh,
    size: u32,
    params: &RansacParams,
) -> Result<PlaneFit, ExtractError> {
    check_range("size", size, 1, 8192)?;
    fit_plane_ransac(patch, params)
}

/// The largest square of the patch's parameter domain `uv` (coordinates in `plane`), with
/// `plane` and `uv` turned so that the square is axis-aligned in them. `no_square` is the
/// error's message when the domain holds none.
pub(crate) fn largest_square_on_plane(
    patch: &Mesh,
    plane: &Plane,
    uv: &[Vec2],
    no_square: &str,
) -> Result<(Plane, Vec<Vec2>, Square), ExtractError> {
    let (angle, square) =
        largest_rotated_square(uv, &patch.triangles, super::square_domain::RESOLUTION).ok_or_else(
            || ExtractError::DegeneratePatch {
                faces: patch.triangles.len(),
                message: no_square.into(),
            },
        )?;
    let uv = uv.iter().map(|&q| rotate_into(q, angle)).collect();
    Ok((plane.rotated(angle), uv, square))
}

/// §4.1.2 on a connected sample patch (e.g. from [`super::sample_region::select_region`]):
/// plane fit, boundary projection, convex-combination map, largest square, `size`×`size`
/// samples. `progress` receives fractions of the work done.
pub fn planar_extract(
    patch: &Mesh,
    size: u32,
    params: &RansacParams,
    progress: &(dyn Fn(f32) + Sync),
) -> Result<PlanarExtraction, ExtractError> {
    let fit = fit_sampling_plane(patch, size, params)?;
    progress(0.2);
    let faces = patch.triangles.len();
    let boundary = patch.boundary_vertices();
    if boundary.is_empty() {
        return Err(ExtractError::NoBoundary {
            faces,
            method: "planar",
        });
    }
    let fixed: Vec<(u32, Vec2)> = boundary
        .iter()
        .map(|&v| {
            let q = fit.plane.coords(patch.positions[v as usize]);
            (v, Vec2::new(q.x, q.y))
        })
        .collect();
    let uv = convex_combination_map(patch, &fixed).map_err(|e| ExtractError::Parameterize {
        faces,
        message: e.to_string(),
    })?;
    progress(0.6);
    let (plane, uv, square) = largest_square_on_plane(
        patch,
        &fit.plane,
        &uv,
        "its parameter domain holds no square (is the patch seen edge-on from its plane?)",
    )?;
    progress(0.8);
    let texels = sample_square(
        patch,
        &uv,
        &square,
        size,
        |locator, q| locator.nearest(q),
        |t, q, p| {
            let d = plane.coords(p);
            t[0] = d.x - q.x;
            t[1] = d.y - q.y;
            t[2] = d.z;
        },
    );
    progress(1.0);
    Ok(PlanarExtraction {
        texels,
        plane,
        square,
        inliers: fit.inliers,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jacobi_diagonalizes_a_symmetric_matrix() {
        let a = [[4.0, 1.0, 2.0], [1.0, 3.0, 0.5], [2.0, 0.5, 1.0]];
        let (vals, v) = symmetric_eigen3(a);
        for k in 0..3 {
            let x = [v[0][k], v[1][k], v[2][k]];
            for i in 0..3 {
                let ax: f64 = (0..3).map(|j| a[i][j] * x[j]).sum();
                assert!((ax - vals[k] * x[i]).abs() < 1e-10, "{vals:?}");
            }
        }
        let trace: f64 = vals.iter().sum();
        assert!((trace - 8.0).abs() < 1e-10);
    }

    #[test]
    fn surface_samples_cover_triangles_by_area() {
        // Two triangles, the second three times the area of the first.
        let m = Mesh::new(
            vec![
                Vec3::ZERO,
                Vec3::X,
                Vec3::Y,
                Vec3::new(2.0, 0.0, 0.0),
                Vec3::new(5.0, 0.0, 0.0),
                Vec3::new(2.0, 2.0, 0.0),
            ],
            vec![[0, 1, 2], [3, 4, 5]],
        );
        let pts = surface_samples(&m, 4000, 7).unwrap();
        let second = pts.iter().filter(|p| p.x >= 2.0).count() as f32 / 4000.0;
        // The first has area 0.5, the second 3.
        assert!((second - 3.0 / 3.5).abs() < 0.03, "{second}");
        assert!(pts.iter().all(|p| p.z == 0.0 && p.x >= 0.0 && p.y >= 0.0));
    }
}
