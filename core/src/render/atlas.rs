//! A texture atlas with one region per triangle, and baking a [`SurfaceShader`] into it.
//!
//! Layout: every triangle keeps its true shape (no distortion) at one common scale (texels per
//! world unit), so texel density is uniform over the surface. Each triangle is laid with its
//! longest edge horizontal; triangles sorted by height fill shelves (rows) left to right,
//! alternating between "base down" and "base up" (and mirrored) so that neighbours nest into
//! each other's slanted sides, like a triangle strip. A new triangle slides left until its
//! region (the triangle grown by [`ATLAS_GUTTER`] texels in every direction, i.e. its
//! Minkowski sum with a square) would touch another's; the exact contact position comes from
//! the separating-axis theorem. The scale is the largest (found by bisection) at which all
//! shelves fit in the square.
//!
//! Baking writes every texel whose centre lies in a triangle's region, with the shader's colour
//! at the barycentrics of the texel centre (clamped to the nearest point of the triangle for
//! gutter texels), then dilates a few passes into the unused texels, and finally fills what is
//! left with the mean colour, so bilinear and mip-mapped sampling never picks up a background
//! colour. Regions are disjoint, so no texel is written twice and the result does not depend on
//! the order (or thread) in which triangles are processed.

use super::shader::SurfaceShader;
use crate::geom::Mesh;
use glam::{DVec2, DVec3, Vec2, Vec3};
use rayon::prelude::*;

/// Width, in texels, of the gutter around every triangle of an atlas: the region of a triangle
/// is every point within this L∞ distance of it, and regions of different triangles are
/// disjoint (so triangles are at least twice this far apart).
pub const ATLAS_GUTTER: f32 = 2.0;

/// Packing margin per side: the gutter plus a little slack for f32 rounding of the stored uvs.
const MARGIN: f64 = ATLAS_GUTTER as f64 + 0.05;
/// How many of the latest triangles of a shelf are checked exactly when placing a new one (the
/// older ones are treated as a wall).
const RECENT: usize = 3;
/// Dilation passes into unused texels after baking.
const DILATE_PASSES: usize = 4;
/// Rows per parallel band when baking.
const BAND: u32 = 32;

/// Texture coordinates for baking: each triangle owns a region of the texture.
#[derive(Debug, Clone, PartialEq)]
pub struct Atlas {
    /// Side of the (square) texture in texels.
    pub size: u32,
    /// Corner texture coordinates per face, glTF convention (u right, v down, [0, 1]).
    pub corner_uv: Vec<[Vec2; 3]>,
}

/// The largest atlas side any `reconstruct.atlas_size` accepts.
pub const MAX_ATLAS_SIZE: u32 = 8192;

/// The atlas cannot be built.
#[derive(Debug, thiserror::Error)]
pub enum AtlasError {
    #[error(
        "a {size}×{size} texture atlas cannot hold {faces} triangles with {gutter}-texel \
         gutters; use a size of at least {suggested}"
    )]
    TooSmall {
        size: u32,
        faces: usize,
        gutter: f32,
        suggested: u32,
    },
    /// Not even the largest accepted side would do: no `atlas_size` to suggest.
    #[error(
        "a {size}×{size} texture atlas cannot hold {faces} triangles with {gutter}-texel \
         gutters, and neither can the largest ({largest}×{largest}): this per-triangle atlas \
         needs a mesh with fewer triangles"
    )]
    TooManyTriangles {
        size: u32,
        faces: usize,
        gutter: f32,
        largest: u32,
    },
}

impl AtlasError {
    /// The error for a `size` too small for `faces` triangles, which fit (bare, with their
    /// gutters) a side of `fits`: twice that, for room, up to the largest size a config may
    /// name; no size when even the largest cannot hold them.
    fn for_size(size: u32, faces: usize, fits: u32) -> AtlasError {
        if fits > MAX_ATLAS_SIZE {
            AtlasError::TooManyTriangles {
                size,
                faces,
                gutter: ATLAS_GUTTER,
                largest: MAX_ATLAS_SIZE,
            }
        } else {
            AtlasError::TooSmall {
                size,
                faces,
                gutter: ATLAS_GUTTER,
                suggested: fits.saturating_mul(2).min(MAX_ATLAS_SIZE),
            }
        }
    }
}

/// A triangle laid flat: longest edge from corner `corners[0]` to `corners[1]` along x, length
/// `len`; apex `corners[2]` at (`a`, `h`) with `0 <= a <= len`, `h >= 0`.
#[derive(Debug, Clone, Copy)]
struct Shape {
    corners: [usize; 3],
    len: f64,
    a: f64,
    h: f64,
}

fn shape(mesh: &Mesh, f: usize) -> Shape {
    let degenerate = Shape {
        corners: [0, 1, 2],
        len: 0.0,
        a: 0.0,
        h: 0.0,
    };
    let t = mesh.triangles[f];
    let Some(p) = t
        .iter()
        .map(|&v| mesh.positions.get(v as usize).map(|p| p.as_dvec3()))
        .collect::<Option<Vec<DVec3>>>()
    else {
        return degenerate;
    };
    if !p.iter().all(|q| q.is_finite()) {
        return degenerate;
    }
    let mut k = 0;
    let mut len2 = -1.0;
    for e in 0..3 {
        let l = (p[(e + 1) % 3] - p[e]).length_squared();
        if l > len2 {
            len2 = l;
            k = e;
        }
    }
    let len = len2.sqrt();
    if len.is_nan() || len <= 0.0 || !len.is_finite() {
        return degenerate;
    }
    let (a, b, c) = (p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
    let along = (c - a).dot(b - a) / len;
    let h = (b - a).cross(c - a).length() / len;
    Shape {
        corners: [k, (k + 1) % 3, (k + 2) % 3],
        len,
        a: along.clamp(0.0, len),
        h: if h.is_finite() { h } else { 0.0 },
    }
}

/// Corners (in `Shape::corners` order) of a shape scaled by `s` in a shelf of height
/// `shelf_h` whose top is at y = 0, at x offset 0: base on the shelf's bottom (`up`) or top, optionally mirrored.
fn local(sh: &Shape, s: f64, shelf_h: f64, up: bool, mirror: bool) -> [DVec2; 3] {
    let (xa, xb, xc) = if mirror {
        (s * sh.len, 0.0, s * (sh.len - sh.a))
    } else {
        (0.0, s * sh.len, s * sh.a)
    };
    let (yb, yc) = if up {
        (shelf_h - MARGIN, shelf_h - MARGIN - s * sh.h)
    } else {
        (MARGIN, MARGIN + s * sh.h)
    };
    [DVec2::new(xa, yb), DVec2::new(xb, yb), DVec2::new(xc, yc)]
}

fn min_x(t: &[DVec2; 3]) -> f64 {
    t[0].x.min(t[1].x).min(t[2].x)
}

fn max_x(t: &[DVec2; 3]) -> f64 {
    t[0].x.max(t[1].x).max(t[2].x)
}

/// Separating axes for a triangle pair: x, y and the unit normals of both triangles' edges,
/// each oriented with a non-negative x component. Returns the axes and how many there are.
fn axes(p: &[DVec2; 3], q: &[DVec2; 3]) -> ([DVec2; 8], usize) {
    let mut out = [DVec2::ZERO; 8];
    out[0] = DVec2::X;
    out[1] = DVec2::Y;
    let mut n_out = 2;
    for t in [p, q] {
        for k in 0..3 {
            let e = t[(k + 1) % 3] - t[k];
            let n = DVec2::new(-e.y, e.x);
            let l = n.length();
            if l > 1e-12 {
                let n = n / l;
                out[n_out] = if n.x < 0.0 { -n } else { n };
                n_out += 1;
            }
        }
    }
    (out, n_out)
}

fn project(t: &[DVec2; 3], n: DVec2) -> (f64, f64) {
    let d = t.map(|p| p.dot(n));
    (d[0].min(d[1]).min(d[2]), d[0].max(d[1]).max(d[2]))
}

/// The smallest `dx >= lo` at which `q` shifted right by `dx`, grown by `MARGIN`, does not meet
/// `p` grown by `MARGIN` (i.e. `q + dx` does not meet `p` grown by `2 MARGIN`).
fn min_separation(p: &[DVec2; 3], q: &[DVec2; 3], lo: f64) -> f64 {
    const TOL: f64 = 1e-9;
    // Per axis: normal, p's grown interval, q's interval (at dx = 0).
    let (normals, count) = axes(p, q);
    let mut ax = [(DVec2::ZERO, 0.0, 0.0, 0.0, 0.0); 8];
    for (slot, &n) in ax.iter_mut().zip(&normals[..count]) {
        let r = 2.0 * MARGIN * (n.x.abs() + n.y.abs());
        let (pmin, pmax) = project(p, n);
        let (qmin, qmax) = project(q, n);
        *slot = (n, pmin - r, pmax + r, qmin, qmax);
    }
    let ax = &ax[..count];
    let separated = |dx: f64| {
        ax.iter().any(|&(n, pmin, pmax, qmin, qmax)| {
            qmax + dx * n.x <= pmin + TOL || qmin + dx * n.x >= pmax - TOL
        })
    };
    if separated(lo) {
        return lo;
    }
    // Otherwise the answer is where q leaves p's shadow along some axis: try those positions
    // in increasing order.
    let mut candidates = [f64::INFINITY; 8];
    for (c, &(n, _, pmax, qmin, _)) in candidates.iter_mut().zip(ax) {
        if n.x > 1e-9 {
            let d = (pmax - qmin) / n.x;
            if d > lo {
                *c = d;
            }
        }
    }
    candidates.sort_by(f64::total_cmp);
    for d in candidates.into_iter().take_while(|d| d.is_finite()) {
        if separated(d) {
            return d;
        }
    }
    // Unreachable in exact arithmetic (the x axis always separates eventually); stay safe.
    max_x(p) + 2.0 * MARGIN - min_x(q) + 1e-6
}

/// Lays out all triangles at scale `s` (texels per world unit) in a `size`² square, or `None`
/// if they do not fit. Positions are in texel units, per face, in `Shape::corners` order.
fn pack(shapes: &[Shape], order: &[usize], s: f64, size: f64) -> Option<Vec<[DVec2; 3]>> {
    let mut out = vec![[DVec2::ZERO; 3]; shapes.len()];
    let mut y0 = 0.0;
    let mut shelf_h: Option<f64> = None;
    let mut recent: Vec<[DVec2; 3]> = Vec::with_capacity(RECENT + 1);
    let mut wall = f64::NEG_INFINITY;
    for &f in order {
        let sh = &shapes[f];
        loop {
            let h = match shelf_h {
                Some(h) => h,
                None => {
                    let h = s * sh.h + 2.0 * MARGIN;
                    if y0 + h > size {
                        return None;
                    }
                    recent.clear();
                    wall = f64::NEG_INFINITY;
                    shelf_h = Some(h);
                    h
                }
            };
            let mut best: Option<(f64, f64, [DVec2; 3])> = None;
            for (up, mirror) in [(true, false), (false, true), (true, true), (false, false)] {
                let q = local(sh, s, h, up, mirror).map(|p| p + DVec2::new(0.0, y0));
                let qmin = min_x(&q);
                let mut dx = (MARGIN - qmin).max(wall - qmin);
                let mut settled = false;
                for _ in 0..64 {
                    let mut moved = false;
                    for p in &recent {
                        let d = min_separation(p, &q, dx);
                        if d > dx {
                            dx = d;
                            moved = true;
                        }
                    }
                    if !moved {
                        settled = true;
                        break;
                    }
                }
                if !settled {
                    for p in &recent {
                        dx = dx.max(max_x(p) + 2.0 * MARGIN - qmin);
                    }
                }
                let right = dx + max_x(&q);
                if best.is_none_or(|b| right < b.0) {
                    best = Some((right, dx, q));
                }
            }
            let (right, dx, q) = best.expect("four variants tried");
            if right + MARGIN <= size {
                let placed = q.map(|p| p + DVec2::new(dx, 0.0));
                out[f] = placed;
                recent.push(placed);
                if recent.len() > RECENT {
                    let old = recent.remove(0);
                    wall = wall.max(max_x(&old) + 2.0 * MARGIN);
                }
                break;
            }
            if recent.is_empty() {
                return None; // does not fit even alone in an empty shelf
            }
            y0 += h;
            shelf_h = None;
        }
    }
    Some(out)
}

/// Builds an atlas of `size`² texels for `mesh`: every triangle gets its own region (the
/// triangle plus a gutter of [`ATLAS_GUTTER`] texels around it, disjoint from all other
/// regions and inside the texture), triangles keep their shape, and the scale is as large as
/// fits. Deterministic. Fails when even points with their gutters do not fit.
pub fn build_atlas(mesh: &Mesh, size: u32) -> Result<Atlas, AtlasError> {
    let faces = mesh.triangles.len();
    let shapes: Vec<Shape> = (0..faces).into_par_iter().map(|f| shape(mesh, f)).collect();
    let mut order: Vec<usize> = (0..faces).collect();
    order.sort_by(|&i, &j| {
        shapes[j]
            .h
            .total_cmp(&shapes[i].h)
            .then(shapes[j].len.total_cmp(&shapes[i].len))
            .then(i.cmp(&j))
    });
    let side = size as f64;
    let too_small = || {
        let mut suggested = size.max(16).next_power_of_two();
        while suggested < 1 << 16 && pack(&shapes, &order, 0.0, suggested as f64).is_none() {
            suggested *= 2;
        }
        AtlasError::for_size(size, faces, suggested)
    };
    let mut best = pack(&shapes, &order, 0.0, side).ok_or_else(too_small)?;
    let max_len = shapes.iter().map(|s| s.len).fold(0.0, f64::max);
    let max_h = shapes.iter().map(|s| s.h).fold(0.0, f64::max);
    if max_len > 0.0 {
        let room = side - 2.0 * MARGIN;
        let mut hi = room / max_len;
        if max_h > 0.0 {
            hi = hi.min(room / max_h);
        }
        match pack(&shapes, &order, hi, side) {
            Some(p) => best = p,
            None => {
                // Bisection to 0.1 % of the scale (0.05 % of the texel count).
                let mut lo = 0.0;
                for _ in 0..40 {
                    if hi - lo <= 1e-3 * hi {
                        break;
                    }
                    let mid = 0.5 * (lo + hi);
                    match pack(&shapes, &order, mid, side) {
                        Some(p) => {
                            lo = mid;
                            best = p;
                        }
                        None => hi = mid,
                    }
                }
            }
        }
    }
    let corner_uv = best
        .iter()
        .zip(&shapes)
        .map(|(placed, sh)| {
            let mut uv = [Vec2::ZERO; 3];
            for k in 0..3 {
                uv[sh.corners[k]] = (placed[k] / side).as_vec2();
            }
            uv
        })
        .collect();
    Ok(Atlas { size, corner_uv })
}

/// Whether the closed square of half-side `g` centred at `c` meets the closed triangle `t`.
fn square_meets_triangle(c: DVec2, g: f64, t: &[DVec2; 3]) -> bool {
    let sep = |n: DVec2| {
        let r = g * (n.x.abs() + n.y.abs());
        let (lo, hi) = project(t, n);
        let cc = c.dot(n);
        cc + r < lo || cc - r > hi
    };
    if sep(DVec2::X) || sep(DVec2::Y) {
        return false;
    }
    for k in 0..3 {
        let e = t[(k + 1) % 3] - t[k];
        let n = DVec2::new(-e.y, e.x);
        if n != DVec2::ZERO && sep(n) {
            return false;
        }
    }
    true
}

/// Barycentric coordinates of the point of triangle `t` nearest to `c` (of `c` itself when it
/// is inside).
pub(crate) fn nearest_barycentric(c: DVec2, t: &[DVec2; 3]) -> Vec3 {
    let (v0, v1, v2) = (t[1] - t[0], t[2] - t[0], c - t[0]);
    let d = v0.perp_dot(v1);
    if d != 0.0 {
        let b1 = v2.perp_dot(v1) / d;
        let b2 = v0.perp_dot(v2) / d;
        let b0 = 1.0 - b1 - b2;
        if b0 >= 0.0 && b1 >= 0.0 && b2 >= 0.0 {
            return DVec3::new(b0, b1, b2).as_vec3();
        }
    }
    let mut best = (f64::INFINITY, DVec3::X);
    for k in 0..3 {
        let (a, b) = (t[k], t[(k + 1) % 3]);
        let e = b - a;
        let l2 = e.length_squared();
        let s = if l2 > 0.0 {
            ((c - a).dot(e) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let dist = (a + e * s - c).length_squared();
        if dist < best.0 {
            let mut w = [0.0; 3];
            w[k] = 1.0 - s;
            w[(k + 1) % 3] = s;
            best = (dist, DVec3::from_array(w));
        }
    }
    best.1.as_vec3()
}

/// Bakes `shader` into the atlas: an image `atlas.size`² (opaque, sRGB-encoded like the shader's
/// colours) to be sampled with `atlas.corner_uv`. Faces beyond `atlas.corner_uv` or
/// `mesh.triangles` are ignored. Deterministic for any thread count.
pub fn bake(atlas: &Atlas, mesh: &Mesh, shader: &dyn SurfaceShader) -> image::RgbaImage {
    let n = atlas.size;
    if n == 0 {
        return image::RgbaImage::new(0, 0);
    }
    let g = ATLAS_GUTTER as f64;
    let side = n as f64;
    let faces = atlas.corner_uv.len().min(mesh.triangles.len());
    let bands = n.div_ceil(BAND) as usize;
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); bands];
    let tris: Vec<[DVec2; 3]> = atlas.corner_uv[..faces]
        .iter()
        .map(|c| c.map(|uv| uv.as_dvec2() * side))
        .collect();
    // Texel rows j whose centre j + 0.5 can be within g of the triangle.
    let row_range = |t: &[DVec2; 3]| {
        let lo = t[0].y.min(t[1].y).min(t[2].y) - g - 0.5;
        let hi = t[0].y.max(t[1].y).max(t[2].y) + g - 0.5;
        (lo.ceil().max(0.0), hi.floor().min(side - 1.0))
    };
    for (f, t) in tris.iter().enumerate() {
        if !t.iter().all(|p| p.is_finite()) {
            continue;
        }
        let (j0, j1) = row_range(t);
        if j0 > j1 {
            continue;
        }
        let (b0, b1) = (j0 as u32 / BAND, j1 as u32 / BAND);
        for bin in &mut bins[b0 as usize..=b1 as usize] {
            bin.push(f as u32);
        }
    }

    // 8-bit RGB + "written" flag in alpha (255 = written), 4 bytes per texel.
    let mut px = vec![[0u8; 4]; (n as usize) * (n as usize)];
    px.par_chunks_mut((n * BAND) as usize)
        .enumerate()
        .for_each(|(band, rows)| {
            let y0 = band as u32 * BAND;
            let y1 = y0 + (rows.len() as u32 / n);
            for &f in &bins[band] {
                let t = &tris[f as usize];
                let (j0, j1) = row_range(t);
                let lo_x = t[0].x.min(t[1].x).min(t[2].x) - g - 0.5;
                let hi_x = t[0].x.max(t[1].x).max(t[2].x) + g - 0.5;
                let (i0, i1) = (lo_x.ceil().max(0.0), hi_x.floor().min(side - 1.0));
                if i0 > i1 {
                    continue;
                }
                let (i0, i1) = (i0 as u32, i1 as u32);
                for j in (j0 as u32).max(y0)..=(j1 as u32).min(y1 - 1) {
                    for i in i0..=i1 {
                        let c = DVec2::new(i as f64 + 0.5, j as f64 + 0.5);
                        let slot = &mut rows[((j - y0) * n + i) as usize];
                        if slot[3] != 0 || !square_meets_triangle(c, g, t) {
                            continue;
                        }
                        let col = shader.albedo(f as usize, nearest_barycentric(c, t));
                        *slot = [quantize(col.x), quantize(col.y), quantize(col.z), 255];
                    }
                }
            }
        });

    finish_bake(px, n, n)
}

/// The image of a bake: written texels (alpha != 0) as they are, dilated a few rings into the
/// unwritten ones, and whatever is left the mean colour (integer sums: exact, order-free), so
/// bilinear and mip-mapped sampling never pick up a background colour.
pub(crate) fn finish_bake(mut px: Vec<[u8; 4]>, w: u32, h: u32) -> image::RgbaImage {
    dilate_rect(&mut px, w as usize, h as usize);
    let mut sum = [0u64; 3];
    let mut count = 0u64;
    for p in &px {
        if p[3] != 0 {
            for k in 0..3 {
                sum[k] += p[k] as u64;
            }
            count += 1;
        }
    }
    let mean = if count > 0 {
        sum.map(|s| ((s + count / 2) / count) as u8)
    } else {
        [128; 3]
    };
    let mut out = image::RgbaImage::new(w, h);
    out.par_chunks_mut(4).zip(px.par_iter()).for_each(|(o, p)| {
        let c = if p[3] != 0 { [p[0], p[1], p[2]] } else { mean };
        o.copy_from_slice(&[c[0], c[1], c[2], 255]);
    });
    out
}

/// An sRGB-encoded colour component to 8 bits (clamped, NaN as 0).
pub(crate) fn quantize(c: f32) -> u8 {
    let c = if c.is_nan() { 0.0 } else { c.clamp(0.0, 1.0) };
    (c * 255.0 + 0.5) as u8
}

/// Grows the written texels (alpha != 0) into unwritten ones, `DILATE_PASSES` rings: each new
/// texel gets the mean (rounded) of its written 8-neighbours from the previous pass.
/// The image is `w`×`h`.
pub(crate) fn dilate_rect(px: &mut [[u8; 4]], w: usize, h: usize) {
    let n = w;
    for _ in 0..DILATE_PASSES {
        let prev = px.to_vec();
        px.par_chunks_mut(n).enumerate().for_each(|(y, row)| {
            for (x, out) in row.iter_mut().enumerate() {
                if out[3] != 0 {
                    continue;
                }
                let mut sum = [0u32; 3];
                let mut k = 0;
                for dy in -1i64..=1 {
                    for dx in -1i64..=1 {
                        let (xx, yy) = (x as i64 + dx, y as i64 + dy);
                        if (dx, dy) == (0, 0)
                            || xx < 0
                            || yy < 0
                            || xx >= w as i64
                            || yy >= h as i64
                        {
                            continue;
                        }
                        let q = prev[yy as usize * n + xx as usize];
                        if q[3] != 0 {
                            for (s, v) in sum.iter_mut().zip(q) {
                                *s += v as u32;
                            }
                            k += 1;
                        }
                    }
                }
                if k > 0 {
                    let avg = |s: u32| ((s + k / 2) / k) as u8;
                    *out = [avg(sum[0]), avg(sum[1]), avg(sum[2]), 255];
                }
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_error_suggests_a_size_past_the_largest() {
        // Fitting at 2048 suggests 4096; fitting only at 8192 suggests 8192 (not 16384).
        let within = AtlasError::for_size(1024, 1000, 2048).to_string();
        assert!(within.contains("at least 4096"), "{within}");
        let last = AtlasError::for_size(2048, 1_000_000, MAX_ATLAS_SIZE).to_string();
        assert!(last.contains("at least 8192"), "{last}");
        let past = AtlasError::for_size(2048, 5_000_000, 2 * MAX_ATLAS_SIZE).to_string();
        assert!(!past.contains("16384"), "{past}");
        assert!(
            past.contains("8192×8192") && past.contains("fewer triangles"),
            "{past}"
        );
        // A real mesh too big for a small atlas gets a size it may use.
        let mesh = crate::geom::primitives::torus(40, 40, 0.5);
        let e = build_atlas(&mesh, 64).unwrap_err();
        let AtlasError::TooSmall { suggested, .. } = e else {
            panic!("{e}")
        };
        assert!(suggested <= MAX_ATLAS_SIZE && build_atlas(&mesh, suggested).is_ok());
    }
    use crate::image::Image;
    use crate::render::views::tests::{assert_rgb_near, uv_sphere};

    /// A deterministic "random" colour per face (a simple integer hash, not from the code under
    /// test).
    struct FaceColors;
    impl SurfaceShader for FaceColors {
        fn albedo(&self, face: usize, _bary: Vec3) -> Vec3 {
            let h = (face as u32).wrapping_mul(2_654_435_761) ^ 0x5bd1_e995;
            Vec3::new(
                (h & 0xff) as f32 / 255.0,
                ((h >> 8) & 0xff) as f32 / 255.0,
                ((h >> 16) & 0xff) as f32 / 255.0,
            )
        }
    }

    /// The colour is the barycentric coordinate itself: smooth inside each face.
    struct BaryColors;
    impl SurfaceShader for BaryColors {
        fn albedo(&self, _face: usize, bary: Vec3) -> Vec3 {
            bary
        }
    }

    use crate::geom::primitives::cube;

    /// Meshes of very different triangle shapes and sizes, including slivers and a degenerate.
    fn corpus() -> Vec<Mesh> {
        let (sphere, _) = uv_sphere(12, 24);
        let mut mixed = cube();
        let base = mixed.positions.len() as u32;
        mixed.positions.extend([
            Vec3::new(5.0, 0.0, 0.0),
            Vec3::new(9.0, 0.0, 0.0),
            Vec3::new(5.0, 0.01, 0.0),
            Vec3::new(5.0, 0.0, 0.0),
            Vec3::new(0.001, 0.0, 0.0),
        ]);
        mixed.triangles.push([base, base + 1, base + 2]); // sliver
        mixed.triangles.push([base, base + 3, base]); // degenerate (a point)
        mixed.triangles.push([0, base + 4, 1]); // collinear
        mixed.triangles.push([0, 3, 6]); // big
        vec![
            Mesh::new(sphere.positions.clone(), sphere.triangles.clone()),
            cube(),
            mixed,
        ]
    }

    /// Convex hull (counter-clockwise in x-right/y-down terms irrelevant) of points.
    fn hull(mut pts: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
        pts.sort_by(|a, b| a.partial_cmp(b).unwrap());
        pts.dedup();
        if pts.len() < 3 {
            return pts;
        }
        let cross = |o: (f64, f64), a: (f64, f64), b: (f64, f64)| {
            (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
        };
        let mut lower: Vec<(f64, f64)> = vec![];
        for &p in &pts {
            while lower.len() >= 2
                && cross(lower[lower.len() - 2], lower[lower.len() - 1], p) <= 0.0
            {
                lower.pop();
            }
            lower.push(p);
        }
        let mut upper: Vec<(f64, f64)> = vec![];
        for &p in pts.iter().rev() {
            while upper.len() >= 2
                && cross(upper[upper.len() - 2], upper[upper.len() - 1], p) <= 0.0
            {
                upper.pop();
            }
            upper.push(p);
        }
        lower.pop();
        upper.pop();
        lower.extend(upper);
        lower
    }

    /// Whether `p` is inside or on the convex polygon `h` (ccw, from `hull`).
    fn in_hull(h: &[(f64, f64)], p: (f64, f64)) -> bool {
        if h.len() < 3 {
            return h
                .iter()
                .any(|q| (q.0 - p.0).abs() < 1e-12 && (q.1 - p.1).abs() < 1e-12);
        }
        (0..h.len()).all(|k| {
            let (a, b) = (h[k], h[(k + 1) % h.len()]);
            (b.0 - a.0) * (p.1 - a.1) - (b.1 - a.1) * (p.0 - a.0) >= -1e-9
        })
    }

    #[test]
    fn regions_with_gutters_are_disjoint_and_inside_the_texture() {
        for (m, mesh) in corpus().iter().enumerate() {
            for size in [256u32, 512] {
                let atlas = build_atlas(mesh, size).unwrap();
                assert_eq!(atlas.corner_uv.len(), mesh.face_count());
                let n = size as f64;
                let g = ATLAS_GUTTER as f64;
                // Region = triangle ⊕ square of half-side g = hull of corners ± g.
                let regions: Vec<Vec<(f64, f64)>> = atlas
                    .corner_uv
                    .iter()
                    .map(|c| {
                        let mut pts = vec![];
                        for uv in c {
                            assert!((0.0..=1.0).contains(&uv.x) && (0.0..=1.0).contains(&uv.y));
                            for (sx, sy) in [(-g, -g), (g, -g), (-g, g), (g, g)] {
                                let p = (uv.x as f64 * n + sx, uv.y as f64 * n + sy);
                                assert!(p.0 >= 0.0 && p.1 >= 0.0 && p.0 <= n && p.1 <= n, "{p:?}");
                                pts.push(p);
                            }
                        }
                        hull(pts)
                    })
                    .collect();
                // Every half-texel grid point belongs to at most one region.
                let mut owner = vec![u32::MAX; (2 * size * 2 * size) as usize];
                let mut used = 0usize;
                for (f, h) in regions.iter().enumerate() {
                    let (x0, x1) = h
                        .iter()
                        .fold((f64::MAX, f64::MIN), |a, p| (a.0.min(p.0), a.1.max(p.0)));
                    let (y0, y1) = h
                        .iter()
                        .fold((f64::MAX, f64::MIN), |a, p| (a.0.min(p.1), a.1.max(p.1)));
                    for j in ((y0 * 2.0).floor() as u32)..((y1 * 2.0).ceil() as u32).min(2 * size) {
                        for i in
                            ((x0 * 2.0).floor() as u32)..((x1 * 2.0).ceil() as u32).min(2 * size)
                        {
                            let p = (i as f64 * 0.5 + 0.25, j as f64 * 0.5 + 0.25);
                            if in_hull(h, p) {
                                let o = &mut owner[(j * 2 * size + i) as usize];
                                if *o != u32::MAX {
                                    let uv = |f: usize| atlas.corner_uv[f].map(|c| c * size as f32);
                                    panic!(
                                        "mesh {m}, size {size}: faces {o} and {f} overlap at {p:?}: {:?} {:?}",
                                        uv(*o as usize),
                                        uv(f)
                                    );
                                }
                                *o = f as u32;
                                used += 1;
                            }
                        }
                    }
                }
                // The packing should use a decent share of the texture.
                let share = used as f64 / owner.len() as f64;
                if m < 2 {
                    assert!(
                        share > 0.4,
                        "mesh {m}, size {size}: regions cover only {share}"
                    );
                }
                eprintln!("mesh {m}, size {size}: regions cover {share:.3} of the texture");
            }
        }
    }

    #[test]
    fn too_small_an_atlas_is_an_error_not_a_panic() {
        let (sphere, _) = uv_sphere(40, 80);
        let e = build_atlas(&sphere, 32).unwrap_err();
        assert!(e.to_string().contains("use a size of at least"), "{e}");
    }

    fn baked_image(img: &image::RgbaImage) -> Image {
        Image {
            width: img.width(),
            height: img.height(),
            pixels: img
                .pixels()
                .map(|p| p.0.map(|c| c as f32 / 255.0))
                .collect(),
        }
    }

    #[test]
    fn baked_atlas_at_each_centroid_has_that_faces_colour() {
        for mesh in corpus() {
            let atlas = build_atlas(&mesh, 512).unwrap();
            let baked = bake(&atlas, &mesh, &FaceColors);
            let img = baked_image(&baked);
            for (f, c) in atlas.corner_uv.iter().enumerate() {
                let uv = (c[0] + c[1] + c[2]) / 3.0;
                // glTF uv (v down) to texel address.
                let p = Vec2::new(uv.x * 512.0 - 0.5, uv.y * 512.0 - 0.5);
                let got = img.view().sample(p);
                let want = FaceColors.albedo(f, Vec3::splat(1.0 / 3.0));
                for k in 0..3 {
                    assert!(
                        (got[k] - want[k]).abs() < 0.6 / 255.0,
                        "face {f}: {got:?} vs {want}"
                    );
                }
            }
        }
    }

    #[test]
    fn baked_texels_inside_a_face_hold_the_shader_colour_at_their_centre() {
        let mesh = cube();
        let atlas = build_atlas(&mesh, 128).unwrap();
        let baked = bake(&atlas, &mesh, &BaryColors);
        let mut checked = 0;
        for (f, c) in atlas.corner_uv.iter().enumerate() {
            let t = c.map(|uv| uv.as_dvec2() * 128.0);
            for j in 0..128u32 {
                for i in 0..128u32 {
                    let p = DVec2::new(i as f64 + 0.5, j as f64 + 0.5);
                    // Barycentrics by areas (independent of the baker's formula).
                    let area = |a: DVec2, b: DVec2, c: DVec2| (b - a).perp_dot(c - a);
                    let total = area(t[0], t[1], t[2]);
                    let b = [
                        area(p, t[1], t[2]) / total,
                        area(t[0], p, t[2]) / total,
                        area(t[0], t[1], p) / total,
                    ];
                    if b.iter().all(|&x| x > 0.0) {
                        assert_rgb_near(
                            baked.get_pixel(i, j).0,
                            b.map(|x| (x * 255.0).round() as i32),
                            format_args!("face {f} texel ({i}, {j})"),
                        );
                        checked += 1;
                    }
                }
            }
        }
        assert!(checked > 128 * 128 / 4);
        // The whole image is opaque: gutters and the rest are filled.
        assert!(baked.pixels().all(|p| p.0[3] == 255));
    }

    #[test]
    fn gutter_texels_hold_the_nearest_edge_colour_and_dilation_fills_beyond() {
        // A single triangle: texels just outside an edge get that edge's colour (clamped
        // barycentrics), so bilinear sampling on the edge sees no background.
        let mesh = Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]);
        let atlas = build_atlas(&mesh, 64).unwrap();
        let baked = bake(&atlas, &mesh, &BaryColors);
        let img = baked_image(&baked);
        let c = atlas.corner_uv[0];
        for k in 0..3 {
            let (a, b) = (c[k], c[(k + 1) % 3]);
            for s in [0.2f32, 0.5, 0.8] {
                let uv = a + (b - a) * s;
                let got = img
                    .view()
                    .sample(Vec2::new(uv.x * 64.0 - 0.5, uv.y * 64.0 - 0.5));
                let mut want = [0.0f32; 3];
                want[k] = 1.0 - s;
                want[(k + 1) % 3] = s;
                for q in 0..3 {
                    assert!(
                        (got[q] - want[q]).abs() < 0.03,
                        "edge {k} at {s}: {got:?} vs {want:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn bake_is_identical_for_one_and_two_threads() {
        let (mesh, _) = uv_sphere(12, 24);
        let atlas = build_atlas(&mesh, 256).unwrap();
        let run = |n: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap()
                .install(|| {
                    (
                        build_atlas(&mesh, 256).unwrap(),
                        bake(&atlas, &mesh, &BaryColors),
                    )
                })
        };
        let (a1, i1) = run(1);
        let (a2, i2) = run(2);
        assert_eq!(a1, a2);
        assert_eq!(a1, atlas);
        assert!(i1.as_raw() == i2.as_raw());
    }
}
