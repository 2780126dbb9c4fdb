//! Planar domains for §4.1.2 and §4.1.3 (Lai et al., "Geometric Texture Synthesis and
//! Transfer via Geometry Images"): "the largest square in the parameter domain is detected,
//! and we then regularly sample the texture inside this square".
//!
//! The domain is a set of triangles in the plane (the parameterized patch, or the patch
//! projected onto its plane). Its coverage is rasterized on a fine lattice; a lattice cell
//! counts when its four corners are covered, and the largest square of such cells is found by
//! the classic dynamic programme. The paper does not say how the square is oriented: here it
//! is axis-aligned in a basis rotated by one of [`ANGLES`] angles over a quarter turn, the
//! angle with the largest square winning (ties, and gains under 1%, keep the smaller angle),
//! so that a square patch tilted against the world axes is not halved.
//!
//! [`Locator`] then finds the triangle under each sample with a uniform bucket grid.

use crate::graph::Csr;
use glam::Vec2;
use rayon::prelude::*;
use texsyn_core::math::PureMath;

/// How many square orientations are tried, evenly spaced over 90°.
pub const ANGLES: u32 = 18;
/// Lattice points along the longer side of the domain's bounding box.
pub const RESOLUTION: u32 = 512;

/// An axis-aligned square in a planar domain: lower corner and side length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Square {
    pub corner: Vec2,
    pub side: f32,
}

impl Square {
    /// The centre of cell (`row`, `col`) of an `n`×`n` grid over the square: columns along
    /// the first axis, rows along the second.
    #[inline]
    pub fn sample(&self, n: u32, row: u32, col: u32) -> Vec2 {
        let step = self.side / n as f32;
        self.corner + Vec2::new((col as f32 + 0.5) * step, (row as f32 + 0.5) * step)
    }
}

/// Rotates planar coordinates into the basis turned by `angle` (radians): the coordinates
/// of `p` along (cos a, sin a) and (−sin a, cos a).
#[inline]
pub fn rotate_into(p: Vec2, angle: f32) -> Vec2 {
    let (s, c) = angle.sin_cos_pure();
    Vec2::new(c * p.x + s * p.y, -s * p.x + c * p.y)
}

/// Twice the signed area of (a, b, c).
#[inline]
fn cross(a: Vec2, b: Vec2, c: Vec2) -> f32 {
    (b - a).perp_dot(c - a)
}

/// Barycentric coordinates of `p` in (a, b, c), either orientation; `None` when degenerate.
#[inline]
pub fn barycentric(p: Vec2, a: Vec2, b: Vec2, c: Vec2) -> Option<[f32; 3]> {
    let d = cross(a, b, c);
    let scale = (b - a).length_squared().max((c - a).length_squared());
    if d.abs() <= 1e-7 * scale || !d.is_finite() {
        return None;
    }
    let wa = cross(p, b, c) / d;
    let wb = cross(a, p, c) / d;
    Some([wa, wb, 1.0 - wa - wb])
}

/// Tolerance on barycentric coordinates for "inside".
const INSIDE_EPS: f32 = 1e-5;

/// The largest axis-aligned square whose coverage lattice cells are all covered by the
/// triangles, or `None` when no cell is covered.
pub fn largest_square(uv: &[Vec2], triangles: &[[u32; 3]], resolution: u32) -> Option<Square> {
    let (mut lo, mut hi) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
    for t in triangles {
        for &v in t {
            lo = lo.min(uv[v as usize]);
            hi = hi.max(uv[v as usize]);
        }
    }
    let extent = (hi - lo).max_element();
    if !(extent.is_finite() && extent > 0.0) {
        return None;
    }
    let cell = extent / resolution.max(1) as f32;
    let nx = ((hi.x - lo.x) / cell).ceil() as usize + 1;
    let ny = ((hi.y - lo.y) / cell).ceil() as usize + 1;
    let mut covered = vec![false; nx * ny];
    for t in triangles {
        let (a, b, c) = (uv[t[0] as usize], uv[t[1] as usize], uv[t[2] as usize]);
        let tlo = a.min(b).min(c);
        let thi = a.max(b).max(c);
        let x0 = (((tlo.x - lo.x) / cell).ceil().max(0.0)) as usize;
        let y0 = (((tlo.y - lo.y) / cell).ceil().max(0.0)) as usize;
        let x1 = (((thi.x - lo.x) / cell).floor() as usize).min(nx - 1);
        let y1 = (((thi.y - lo.y) / cell).floor() as usize).min(ny - 1);
        for y in y0..=y1 {
            for x in x0..=x1 {
                if covered[y * nx + x] {
                    continue;
                }
                let p = lo + Vec2::new(x as f32 * cell, y as f32 * cell);
                if let Some(w) = barycentric(p, a, b, c)
                    && w.iter().all(|&w| w >= -INSIDE_EPS)
                {
                    covered[y * nx + x] = true;
                }
            }
        }
    }
    // side[y][x]: the side, in cells, of the largest all-covered square whose upper corner
    // cell is (x, y).
    let (cx, cy) = (nx - 1, ny - 1);
    let mut side = vec![0u32; cx * cy];
    let mut best = (0u32, 0usize, 0usize);
    for y in 0..cy {
        for x in 0..cx {
            let cell_covered = covered[y * nx + x]
                && covered[y * nx + x + 1]
                && covered[(y + 1) * nx + x]
                && covered[(y + 1) * nx + x + 1];
            if !cell_covered {
                continue;
            }
            let s = if x == 0 || y == 0 {
                1
            } else {
                1 + side[(y - 1) * cx + x]
                    .min(side[y * cx + x - 1])
                    .min(side[(y - 1) * cx + x - 1])
            };
            side[y * cx + x] = s;
            if s > best.0 {
                best = (s, x, y);
            }
        }
    }
    let (s, x, y) = best;
    if s == 0 {
        return None;
    }
    let corner = lo + Vec2::new((x + 1 - s as usize) as f32, (y + 1 - s as usize) as f32) * cell;
    Some(Square {
        corner,
        side: s as f32 * cell,
    })
}

/// The largest square over [`ANGLES`] orientations: (angle in radians, square in the rotated
/// coordinates of [`rotate_into`]).
pub fn largest_rotated_square(
    uv: &[Vec2],
    triangles: &[[u32; 3]],
    resolution: u32,
) -> Option<(f32, Square)> {
    let found: Vec<Option<(f32, Square)>> = (0..ANGLES)
        .into_par_iter()
        .map(|k| {
            let angle = k as f32 * std::f32::consts::FRAC_PI_2 / ANGLES as f32;
            let rotated: Vec<Vec2> = if k == 0 {
                uv.to_vec()
            } else {
                uv.iter().map(|&p| rotate_into(p, angle)).collect()
            };
            largest_square(&rotated, triangles, resolution).map(|s| (angle, s))
        })
        .collect();
    let mut best: Option<(f32, Square)> = None;
    for f in found.into_iter().flatten() {
        match best {
            Some((_, b)) if f.1.side <= b.side * 1.01 => {}
            _ => best = Some(f),
        }
    }
    best
}

/// Finds the triangles under points of a planar triangulation with a uniform bucket grid.
pub struct Locator<'a> {
    uv: &'a [Vec2],
    triangles: &'a [[u32; 3]],
    lo: Vec2,
    cell: f32,
    gx: usize,
    gy: usize,
    /// Per bucket, the triangles whose bounding box overlaps it, ascending.
    buckets: Csr<u32>,
}

impl<'a> Locator<'a> {
    pub fn new(uv: &'a [Vec2], triangles: &'a [[u32; 3]]) -> Self {
        let (mut lo, mut hi) = (Vec2::splat(f32::INFINITY), Vec2::splat(f32::NEG_INFINITY));
        for t in triangles {
            for &v in t {
                lo = lo.min(uv[v as usize]);
                hi = hi.max(uv[v as usize]);
            }
        }
        if triangles.is_empty() {
            lo = Vec2::ZERO;
            hi = Vec2::ONE;
        }
        let size = (hi - lo).max(Vec2::splat(1e-20));
        // About one triangle per bucket.
        let count = (triangles.len().max(1) as f32).sqrt();
        let cell = (size.x * size.y / count / count)
            .sqrt()
            .max(size.max_element() / 4096.0);
        let gx = ((size.x / cell).floor() as usize + 1).clamp(1, 4096);
        let gy = ((size.y / cell).floor() as usize + 1).clamp(1, 4096);
        let range = |t: &[u32; 3]| {
            let (a, b, c) = (uv[t[0] as usize], uv[t[1] as usize], uv[t[2] as usize]);
            let tlo = ((a.min(b).min(c) - lo) / cell).floor();
            let thi = ((a.max(b).max(c) - lo) / cell).floor();
            (
                (tlo.x.max(0.0) as usize).min(gx - 1),
                (tlo.y.max(0.0) as usize).min(gy - 1),
                (thi.x.max(0.0) as usize).min(gx - 1),
                (thi.y.max(0.0) as usize).min(gy - 1),
            )
        };
        // (bucket, triangle) for every bucket a triangle's box overlaps, triangles in order.
        let pairs = triangles.iter().enumerate().flat_map(|(f, t)| {
            let (x0, y0, x1, y1) = range(t);
            (y0..=y1).flat_map(move |y| (x0..=x1).map(move |x| (y * gx + x, f as u32)))
        });
        let buckets = Csr::from_pairs(gx * gy, pairs);
        Locator {
            uv,
            triangles,
            lo,
            cell,
            gx,
            gy,
            buckets,
        }
    }

    fn bucket(&self, bx: usize, by: usize) -> &[u32] {
        self.buckets.row(by * self.gx + bx)
    }

    fn bary(&self, f: u32, p: Vec2) -> Option<[f32; 3]> {
        let t = self.triangles[f as usize];
        barycentric(
            p,
            self.uv[t[0] as usize],
            self.uv[t[1] as usize],
            self.uv[t[2] as usize],
        )
    }

    /// Every triangle containing `p`, ascending, with `p`'s barycentric coordinates.
    pub fn containing(&self, p: Vec2) -> impl Iterator<Item = (u32, [f32; 3])> + '_ {
        let q = ((p - self.lo) / self.cell).floor();
        let inside_grid = q.x >= 0.0 && q.y >= 0.0 && q.x < self.gx as f32 && q.y < self.gy as f32;
        let bucket: &[u32] = if inside_grid {
            self.bucket(q.x as usize, q.y as usize)
        } else {
            &[]
        };
        bucket.iter().filter_map(move |&f| {
            let w = self.bary(f, p)?;
            w.iter().all(|&w| w >= -INSIDE_EPS).then_some((f, w))
        })
    }

    /// The triangle nearest to `p` (inside it when one contains it) and the barycentric
    /// coordinates of the nearest point, clamped into the triangle. `None` only for an empty
    /// or fully degenerate triangulation.
    pub fn nearest(&self, p: Vec2) -> Option<(u32, [f32; 3])> {
        if let Some(hit) = self.containing(p).next() {
            return Some(hit);
        }
        let q = ((p - self.lo) / self.cell).floor();
        let cx = (q.x.max(0.0) as usize).min(self.gx - 1) as isize;
        let cy = (q.y.max(0.0) as usize).min(self.gy - 1) as isize;
        let mut best: Option<(f32, u32, [f32; 3])> = None;
        let max_ring = self.gx.max(self.gy) as isize;
        let mut found_at: Option<isize> = None;
        for ring in 0..=max_ring {
            if let Some(r) = found_at
                && ring > r + 1
            {
                break;
            }
            for by in (cy - ring)..=(cy + ring) {
                for bx in (cx - ring)..=(cx + ring) {
                    let on_ring = (by - cy).abs() == ring || (bx - cx).abs() == ring;
                    if !on_ring
                        || bx < 0
                        || by < 0
                        || bx >= self.gx as isize
                        || by >= self.gy as isize
                    {
                        continue;
                    }
                    for &f in self.bucket(bx as usize, by as usize) {
                        let t = self.triangles[f as usize];
                        let (a, b, c) = (
                            self.uv[t[0] as usize],
                            self.uv[t[1] as usize],
                            self.uv[t[2] as usize],
                        );
                        let Some((d, w)) = nearest_in_triangle(p, a, b, c) else {
                            continue;
                        };
                        let better = match best {
                            None => true,
                            Some((bd, bf, _)) => d < bd || (d == bd && f < bf),
                        };
                        if better {
                            best = Some((d, f, w));
                        }
                    }
                }
            }
            if best.is_some() && found_at.is_none() {
                found_at = Some(ring);
            }
        }
        best.map(|(_, f, w)| (f, w))
    }
}

/// Squared distance from `p` to triangle (a, b, c) and the barycentric coordinates of the
/// nearest point; `None` for a degenerate triangle.
fn nearest_in_triangle(p: Vec2, a: Vec2, b: Vec2, c: Vec2) -> Option<(f32, [f32; 3])> {
    let w = barycentric(p, a, b, c)?;
    if w.iter().all(|&w| w >= 0.0) {
        return Some((0.0, w));
    }
    let mut best = (f32::INFINITY, [0.0; 3]);
    let corners = [a, b, c];
    for e in 0..3 {
        let (i, j) = (e, (e + 1) % 3);
        let (s, t) = (corners[i], corners[j]);
        let d = t - s;
        let u = ((p - s).dot(d) / d.length_squared().max(1e-30)).clamp(0.0, 1.0);
        let dist = (s + d * u - p).length_squared();
        if dist < best.0 {
            let mut w = [0.0; 3];
            w[i] = 1.0 - u;
            w[j] = u;
            best = (dist, w);
        }
    }
    Some(best)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_square() -> (Vec<Vec2>, Vec<[u32; 3]>) {
        (
            vec![
                Vec2::new(0.0, 0.0),
                Vec2::new(2.0, 0.0),
                Vec2::new(2.0, 2.0),
                Vec2::new(0.0, 2.0),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    }

    #[test]
    fn the_largest_square_of_a_square_is_itself() {
        let (uv, t) = unit_square();
        let s = largest_square(&uv, &t, 256).unwrap();
        assert!((s.side - 2.0).abs() < 1e-4, "{s:?}");
        assert!(s.corner.length() < 1e-4);
    }

    #[test]
    fn the_largest_square_of_an_l_shape_avoids_the_notch() {
        // An L: [0,3]x[0,1] ∪ [0,1]x[0,3]; the largest square has side 1.
        let uv = vec![
            Vec2::new(0.0, 0.0),
            Vec2::new(3.0, 0.0),
            Vec2::new(3.0, 1.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(1.0, 3.0),
            Vec2::new(0.0, 3.0),
            Vec2::new(0.0, 1.0),
        ];
        let t = vec![[0, 1, 2], [0, 2, 3], [0, 3, 6], [6, 3, 4], [6, 4, 5]];
        let s = largest_square(&uv, &t, 300).unwrap();
        assert!((s.side - 1.0).abs() < 0.02, "{s:?}");
    }

    #[test]
    fn a_diamond_is_searched_at_45_degrees() {
        // A square of side 2 turned by 45°: axis-aligned squares inside it have side √2.
        let r = std::f32::consts::SQRT_2;
        let uv = vec![
            Vec2::new(0.0, -r),
            Vec2::new(r, 0.0),
            Vec2::new(0.0, r),
            Vec2::new(-r, 0.0),
        ];
        let t = vec![[0, 1, 2], [0, 2, 3]];
        let axis = largest_square(&uv, &t, 256).unwrap();
        assert!((axis.side - r).abs() < 0.03, "{axis:?}");
        let (angle, s) = largest_rotated_square(&uv, &t, 256).unwrap();
        assert!((angle - std::f32::consts::FRAC_PI_4).abs() < 1e-5);
        assert!((s.side - 2.0).abs() < 0.03, "{s:?}");
    }

    #[test]
    fn the_locator_finds_containing_and_nearest_triangles() {
        let (uv, t) = unit_square();
        let loc = Locator::new(&uv, &t);
        let hits: Vec<u32> = loc.containing(Vec2::new(1.5, 0.5)).map(|h| h.0).collect();
        assert_eq!(hits, vec![0]);
        let hits: Vec<u32> = loc.containing(Vec2::new(0.5, 1.5)).map(|h| h.0).collect();
        assert_eq!(hits, vec![1]);
        let (f, w) = loc.nearest(Vec2::new(3.0, 1.0)).unwrap();
        assert_eq!(f, 0);
        // The nearest point is (2, 1): halfway between corners 1 and 2.
        assert!(
            (w[1] - 0.5).abs() < 1e-5 && (w[2] - 0.5).abs() < 1e-5,
            "{w:?}"
        );
    }
}
