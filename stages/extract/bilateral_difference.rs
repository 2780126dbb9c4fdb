//! Smoothing and differencing (Lai et al., "Geometric Texture Synthesis and Transfer via
//! Geometry Images", §4.1.1, eq. 1–5).
//!
//! The sample patch's geometry image is smoothed by a bilateral filter (eq. 1–4): each
//! sample's smoothed position p̄ is the average of the grid's positions weighted by nearness in
//! the grid (α, σ1 in grid units) and nearness in space (β, σ2 in object units). Normals of the
//! smoothed grid and the eq. 5 frames ([`local_frames`]) give each sample a frame, and the
//! texel is p − p̄ in it: (dx, dy, dn).
//!
//! Departures from the paper, and why:
//! - eq. 3 as printed divides the *unsquared* distance by 2σ2²; here β = exp(−‖p − p0‖² / 2σ2²),
//!   the Gaussian of Tomasi & Manduchi that the paper cites, so σ2 is a length in object units.
//! - eq. 4 sums over the whole grid; the window is the disc of radius 3σ1 (α < 0.012 beyond).
//! - Near the grid's edges the window is completed by point reflection (p(−i) = 2p(0) − p(i)),
//!   so the smoothing of a flat or linearly varying patch is exact up to the edge instead of
//!   pulling edge samples inward, which would show as false texture along the image's border.
//! - n̄ is the cross product of the smoothed grid's central differences (one-sided at the
//!   edges), which is the area-weighted normal of the grid's 1-ring; the normals are turned,
//!   all together, to agree with the geometry image's own normals.
//! - Mates (samples that are the same surface point, across cuts) take their representative's
//!   smoothed position, so that they get the same texel.

use super::{ExtractError, ParamError, check_positive, check_range};
use crate::geom::geometry_image::{Frame, GeometryImage, TexelImage, local_frames};
use glam::{DVec3, Vec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicU32, Ordering};
use texsyn_core::math::PureMath;

/// The bilateral filter's widths.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BilateralParams {
    /// σ1 of eq. 2 in grid units, 0.5..=N. Default: N / 12 (at least 0.5).
    pub sigma_grid: Option<f32>,
    /// σ2 of eq. 3 in object units, > 0. Default: 0.1 × the patch's size (the square root of
    /// the geometry image's surface area).
    pub sigma_space: Option<f32>,
}

impl BilateralParams {
    /// Checks the fields that are set; the error names the field, its range and the value.
    pub fn validate(&self) -> Result<(), ParamError> {
        if let Some(s) = self.sigma_grid {
            check_range("sigma_grid", s, 0.5, 1024.0)?;
        }
        if let Some(s) = self.sigma_space {
            check_positive("sigma_space", s)?;
        }
        Ok(())
    }
}

/// The result of [`bilateral_difference`].
#[derive(Clone, Debug, PartialEq)]
pub struct BilateralExtraction {
    /// N×N texels (dx, dy, dn[, r, g, b]), laid out like the geometry image.
    pub texels: TexelImage,
    /// The smoothed positions p̄ (the base surface).
    pub smoothed: Vec<Vec3>,
    /// The frame of each sample, in which `texels` are expressed: p = p̄ + dx x̂ + dy ŷ + dn n̂.
    pub frames: Vec<Frame>,
    /// The σ1 and σ2 used.
    pub sigma_grid: f32,
    pub sigma_space: f32,
}

/// §4.1.1 on the sample patch's geometry image. `colors`, when the sample has vertex colours,
/// gives an RGB colour per geometry-image sample (row-major like the positions); the texels
/// then have 6 channels. Rows are processed in parallel; the result does not depend on the
/// thread count. `progress` receives fractions of the work done.
pub fn bilateral_difference(
    gi: &GeometryImage,
    colors: Option<&[[f32; 3]]>,
    params: &BilateralParams,
    progress: &(dyn Fn(f32) + Sync),
) -> Result<BilateralExtraction, ExtractError> {
    params.validate()?;
    let n = gi.n as usize;
    let count = n * n;
    if n < 2 {
        return Err(ExtractError::GeometryImage(format!(
            "it is {n}×{n}; at least 2×2 samples are needed"
        )));
    }
    for (name, len) in [
        ("positions", gi.positions.len()),
        ("normals", gi.normals.len()),
        ("mate_rep", gi.mate_rep.len()),
    ] {
        if len != count {
            return Err(ExtractError::GeometryImage(format!(
                "it has {len} {name} for {n}×{n} samples"
            )));
        }
    }
    if let Some(c) = colors
        && c.len() != count
    {
        return Err(ExtractError::GeometryImage(format!(
            "{} colours were given for {n}×{n} samples",
            c.len()
        )));
    }
    if let Some(k) = gi.positions.iter().position(|p| !p.is_finite()) {
        return Err(ExtractError::GeometryImage(format!(
            "sample (row {}, column {}) has a non-finite position",
            k / n,
            k % n
        )));
    }
    if let Some(k) = gi.mate_rep.iter().position(|&r| r as usize >= count) {
        return Err(ExtractError::GeometryImage(format!(
            "sample {k} names mate {} outside the image",
            gi.mate_rep[k]
        )));
    }

    let sigma_grid = params.sigma_grid.unwrap_or((n as f32 / 12.0).max(0.5));
    let sigma_space = match params.sigma_space {
        Some(s) => s,
        None => {
            let d = 0.1 * grid_area(n, &gi.positions).sqrt() as f32;
            if d > 0.0 {
                d
            } else {
                return Err(ExtractError::GeometryImage(
                    "its samples span no area".into(),
                ));
            }
        }
    };

    // The grid extended by r samples on every side by point reflection.
    let r = ((3.0 * sigma_grid).ceil() as usize).clamp(1, n - 1);
    let m = n + 2 * r;
    let reflect = |i: isize, len: usize| -> (usize, usize, bool) {
        // (edge sample, mirrored sample, whether reflected)
        if i < 0 {
            (0, (-i) as usize, true)
        } else if i >= len as isize {
            (len - 1, 2 * (len - 1) - i as usize, true)
        } else {
            (i as usize, i as usize, false)
        }
    };
    let mut rows_ext = vec![DVec3::ZERO; n * m];
    for i in 0..n {
        for jj in 0..m {
            let (e, k, refl) = reflect(jj as isize - r as isize, n);
            let edge = gi.positions[i * n + e].as_dvec3();
            rows_ext[i * m + jj] = if refl {
                2.0 * edge - gi.positions[i * n + k].as_dvec3()
            } else {
                edge
            };
        }
    }
    let mut ext = vec![DVec3::ZERO; m * m];
    for ii in 0..m {
        let (e, k, refl) = reflect(ii as isize - r as isize, n);
        for jj in 0..m {
            ext[ii * m + jj] = if refl {
                2.0 * rows_ext[e * m + jj] - rows_ext[k * m + jj]
            } else {
                rows_ext[e * m + jj]
            };
        }
    }

    let w = 2 * r + 1;
    let alpha: Vec<f64> = (0..w * w)
        .map(|k| {
            let (di, dj) = (k / w, k % w);
            let d2 = (di as f64 - r as f64).powi(2) + (dj as f64 - r as f64).powi(2);
            (-d2 / (2.0 * sigma_grid as f64 * sigma_grid as f64)).exp_pure()
        })
        .collect();
    // The window is the disc of radius r: per window row, the columns within it.
    let spans: Vec<(usize, usize)> = (0..w)
        .map(|di| {
            let dy = di as f64 - r as f64;
            let half = ((r * r) as f64 - dy * dy).max(0.0).sqrt().floor() as usize;
            (r - half, r + half + 1)
        })
        .collect();
    let inv_two_s2 = 1.0 / (2.0 * sigma_space as f64 * sigma_space as f64);
    let done = AtomicU32::new(0);
    let mut smoothed = vec![Vec3::ZERO; count];
    smoothed.par_chunks_mut(n).enumerate().for_each(|(i, out)| {
        for (j, o) in out.iter_mut().enumerate() {
            let p0 = gi.positions[i * n + j].as_dvec3();
            let mut sum = DVec3::ZERO;
            let mut weight = 0.0f64;
            // Window rows i-r..=i+r are ext rows i..=i+2r.
            for (di, &(c0, c1)) in spans.iter().enumerate() {
                let row = &ext[(i + di) * m + j + c0..(i + di) * m + j + c1];
                let arow = &alpha[di * w + c0..di * w + c1];
                for (&p, &a) in row.iter().zip(arow) {
                    let d = p - p0;
                    let wt = a * (-d.length_squared() * inv_two_s2).exp_pure();
                    sum += wt * d;
                    weight += wt;
                }
            }
            *o = (p0 + sum / weight).as_vec3();
        }
        let d = done.fetch_add(1, Ordering::Relaxed) + 1;
        progress(0.9 * d as f32 / n as f32);
    });
    for k in 0..count {
        let rep = gi.mate_rep[k] as usize;
        if rep != k {
            smoothed[k] = smoothed[rep];
        }
    }

    // Normals of the smoothed grid: ∂p̄/∂j × ∂p̄/∂i (the grid's u and v).
    let at = |i: usize, j: usize| smoothed[i * n + j];
    let diff = |a: usize, b: usize, get: &dyn Fn(usize) -> Vec3| -> Vec3 {
        if a == 0 {
            get(1) - get(0)
        } else if a == b - 1 {
            get(b - 1) - get(b - 2)
        } else {
            get(a + 1) - get(a - 1)
        }
    };
    let mut normals: Vec<Vec3> = (0..count)
        .map(|k| {
            let (i, j) = (k / n, k % n);
            let du = diff(j, n, &|jj| at(i, jj));
            let dv = diff(i, n, &|ii| at(ii, j));
            du.cross(dv).normalize_or_zero()
        })
        .collect();
    let agreement: f64 = normals
        .iter()
        .zip(&gi.normals)
        .map(|(a, b)| a.dot(*b) as f64)
        .sum();
    if agreement < 0.0 {
        for v in &mut normals {
            *v = -*v;
        }
    }
    let frames = local_frames(gi.n, &smoothed, &normals, &gi.mate_rep);

    let channels = if colors.is_some() { 6 } else { 3 };
    let mut texels = TexelImage::new(gi.n, gi.n, channels);
    for (k, t) in texels.data.chunks_mut(channels as usize).enumerate() {
        let d = gi.positions[k] - smoothed[k];
        let f = &frames[k];
        t[0] = d.dot(f.x);
        t[1] = d.dot(f.y);
        t[2] = d.dot(f.n);
        if let Some(c) = colors {
            t[3..6].copy_from_slice(&c[k]);
        }
    }
    progress(1.0);
    Ok(BilateralExtraction {
        texels,
        smoothed,
        frames,
        sigma_grid,
        sigma_space,
    })
}

/// The area of an n×n grid of positions triangulated along one diagonal per quad, summed
/// in row order.
fn grid_area(n: usize, p: &[Vec3]) -> f64 {
    let mut area = 0.0f64;
    for i in 0..n - 1 {
        for j in 0..n - 1 {
            let (a, b, c, d) = (
                p[i * n + j].as_dvec3(),
                p[i * n + j + 1].as_dvec3(),
                p[(i + 1) * n + j + 1].as_dvec3(),
                p[(i + 1) * n + j].as_dvec3(),
            );
            area += 0.5 * ((b - a).cross(c - a).length() + (c - a).cross(d - a).length());
        }
    }
    area
}

/// The colour of each geometry-image sample, for a sample with vertex colours (§4.1.4): the
/// geometry image's disk (the patch cut open, with `disk_uv` in grid units, u = column,
/// v = row, and `original_vertex` naming each disk vertex's patch vertex or `u32::MAX` for a
/// vertex inserted on an edge) is searched for the triangle under each sample and its
/// corners' colours are interpolated. Inserted vertices take the colour interpolated along
/// the edge they split (found among their neighbours as the pair they lie between).
pub fn geometry_image_colors(
    n: u32,
    disk: &crate::geom::Mesh,
    disk_uv: &[glam::Vec2],
    original_vertex: &[u32],
    patch_colors: &[[f32; 4]],
) -> Vec<[f32; 3]> {
    let nv = disk.positions.len();
    let mut color: Vec<Option<[f32; 3]>> = (0..nv)
        .map(|v| {
            let o = original_vertex.get(v).copied().unwrap_or(u32::MAX);
            patch_colors.get(o as usize).map(|c| [c[0], c[1], c[2]])
        })
        .collect();
    let adj = disk.adjacency();
    loop {
        let mut progressed = false;
        for v in 0..nv {
            if color[v].is_some() {
                continue;
            }
            let p = disk.positions[v];
            let nb: Vec<u32> = adj
                .neighbors(v)
                .iter()
                .copied()
                .filter(|&w| color[w as usize].is_some())
                .collect();
            // The pair of coloured neighbours p lies most nearly between.
            let mut best: Option<(f32, [f32; 3])> = None;
            for (x, &a) in nb.iter().enumerate() {
                for &b in &nb[x + 1..] {
                    let (pa, pb) = (disk.positions[a as usize], disk.positions[b as usize]);
                    let ab = (pb - pa).length();
                    if ab <= 0.0 {
                        continue;
                    }
                    let slack = (p - pa).length() + (p - pb).length() - ab;
                    if best.is_none_or(|bb| slack < bb.0) {
                        let t = ((p - pa).dot(pb - pa) / (ab * ab)).clamp(0.0, 1.0);
                        let (ca, cb) = (color[a as usize].unwrap(), color[b as usize].unwrap());
                        best = Some((slack, std::array::from_fn(|k| ca[k] + (cb[k] - ca[k]) * t)));
                    }
                }
            }
            if let Some((_, c)) = best {
                color[v] = Some(c);
                progressed = true;
            } else if nb.len() == 1 {
                color[v] = color[nb[0] as usize];
                progressed = true;
            }
        }
        if !progressed {
            break;
        }
    }
    let color: Vec<[f32; 3]> = color.into_iter().map(|c| c.unwrap_or([1.0; 3])).collect();
    let locator = super::square_domain::Locator::new(disk_uv, &disk.triangles);
    (0..n * n)
        .into_par_iter()
        .map(|k| {
            let q = glam::Vec2::new((k % n) as f32, (k / n) as f32);
            match locator.nearest(q) {
                Some((f, w)) => {
                    let t = disk.triangles[f as usize];
                    std::array::from_fn(|c| {
                        color[t[0] as usize][c] * w[0]
                            + color[t[1] as usize][c] * w[1]
                            + color[t[2] as usize][c] * w[2]
                    })
                }
                None => [1.0; 3],
            }
        })
        .collect()
}
