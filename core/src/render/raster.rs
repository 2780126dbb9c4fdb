//! Scan conversion of one screen-space triangle.
//!
//! Vertices are snapped to a 1/256-pixel grid and the edge functions are evaluated exactly in
//! 64-bit integers, so two triangles sharing an edge compute exactly opposite edge values there.
//! A pixel is covered when its centre `(x + 0.5, y + 0.5)` is strictly inside the triangle, or
//! on an edge the triangle owns under a top-left style rule (of the two triangles sharing an
//! edge, exactly one owns it). Hence a closed fan of triangles covers every pixel of its
//! interior exactly once: no cracks, no double blending.

use glam::{Vec2, Vec3};
use std::ops::Range;

const SUBPIXEL_BITS: u32 = 8;
const SUB: i64 = 1 << SUBPIXEL_BITS;
const HALF: i64 = SUB / 2;

/// Screen coordinates (pixels) beyond this magnitude are rejected, which keeps the fixed-point
/// edge functions well inside `i64`.
pub const GUARD_BAND: f32 = (1 << 20) as f32;

#[inline]
fn snap(p: Vec2) -> (i64, i64) {
    (
        (p.x as f64 * SUB as f64).round() as i64,
        (p.y as f64 * SUB as f64).round() as i64,
    )
}

/// Edge function of the directed edge `p -> q` at `r` (twice the signed area of p, q, r).
#[inline]
fn edge(p: (i64, i64), q: (i64, i64), r: (i64, i64)) -> i64 {
    (q.0 - p.0) * (r.1 - p.1) - (q.1 - p.1) * (r.0 - p.0)
}

/// Whether the triangle owns pixel centres lying exactly on its directed edge `p -> q`: a fixed
/// half of all directions, so the two triangles on either side of an edge (which traverse it in
/// opposite directions) never both own it, and never both miss it.
#[inline]
fn owns(p: (i64, i64), q: (i64, i64)) -> bool {
    let (dx, dy) = (q.0 - p.0, q.1 - p.1);
    dy > 0 || (dy == 0 && dx < 0)
}

#[inline]
fn div_floor(a: i64, b: i64) -> i64 {
    a.div_euclid(b)
}

#[inline]
fn div_ceil(a: i64, b: i64) -> i64 {
    -(-a).div_euclid(b)
}

/// Calls `f(x, y, lambda)` for every pixel `x in 0..width`, `y in rows` whose centre is covered
/// by the triangle `xy` (pixel units, x right, y down), in row-major order. `lambda` holds the
/// screen-space (affine) barycentric coordinates of the pixel centre, ordered like `xy`.
/// Either winding works; triangles whose snapped area is zero, or with a coordinate outside
/// [`GUARD_BAND`] (or not finite), cover nothing.
pub fn raster_triangle(
    xy: [Vec2; 3],
    width: u32,
    rows: Range<u32>,
    mut f: impl FnMut(u32, u32, Vec3),
) {
    if !xy
        .iter()
        .all(|p| p.x.abs() <= GUARD_BAND && p.y.abs() <= GUARD_BAND)
    {
        return;
    }
    let v = xy.map(snap);
    let area = edge(v[0], v[1], v[2]);
    if area == 0 || width == 0 || rows.is_empty() {
        return;
    }
    // Orient counter-clockwise in the edge-function sense (area > 0); remember where each
    // corner went so lambda comes out in the caller's order.
    let order = if area > 0 { [0, 1, 2] } else { [0, 2, 1] };
    let [a, b, c] = order.map(|i| v[i]);
    let area = area.abs();
    let inv_area = 1.0 / area as f64;

    let min_x = a.0.min(b.0).min(c.0);
    let max_x = a.0.max(b.0).max(c.0);
    let min_y = a.1.min(b.1).min(c.1);
    let max_y = a.1.max(b.1).max(c.1);
    // Pixel x has its centre at x * SUB + HALF.
    let x0 = div_ceil(min_x - HALF, SUB).max(0);
    let x1 = div_floor(max_x - HALF, SUB).min(width as i64 - 1);
    let y0 = div_ceil(min_y - HALF, SUB).max(rows.start as i64);
    let y1 = div_floor(max_y - HALF, SUB).min(rows.end as i64 - 1);
    if x0 > x1 || y0 > y1 {
        return;
    }
    // Edges opposite each corner: lambda_a ~ E(b, c), lambda_b ~ E(c, a), lambda_c ~ E(a, b).
    let edges = [(b, c), (c, a), (a, b)];
    let bias = edges.map(|(p, q)| if owns(p, q) { 0 } else { -1 });
    // Per-pixel increments of each edge function along x.
    let step = edges.map(|(p, q)| -(q.1 - p.1) * SUB);
    for y in y0..=y1 {
        let py = y * SUB + HALF;
        let start = (x0 * SUB + HALF, py);
        let mut e = edges.map(|(p, q)| edge(p, q, start));
        for x in x0..=x1 {
            if e[0] + bias[0] >= 0 && e[1] + bias[1] >= 0 && e[2] + bias[2] >= 0 {
                let l = [
                    (e[0] as f64 * inv_area) as f32,
                    (e[1] as f64 * inv_area) as f32,
                    (e[2] as f64 * inv_area) as f32,
                ];
                let mut out = [0.0f32; 3];
                for k in 0..3 {
                    out[order[k]] = l[k];
                }
                f(x as u32, y as u32, Vec3::from_array(out));
            }
            for k in 0..3 {
                e[k] += step[k];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::PureMath;

    /// A small deterministic generator for test inputs (splitmix64).
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            z ^ (z >> 31)
        }
        fn f(&mut self, lo: f32, hi: f32) -> f32 {
            lo + (hi - lo) * ((self.next() >> 40) as f32 / (1u64 << 24) as f32)
        }
    }

    fn coverage(tri: [Vec2; 3], w: u32, h: u32) -> Vec<u8> {
        let mut hits = vec![0u8; (w * h) as usize];
        raster_triangle(tri, w, 0..h, |x, y, _| hits[(y * w + x) as usize] += 1);
        hits
    }

    /// Signed distance-like inside test in f64: returns the minimum over the three edges of the
    /// signed distance of `p` to the edge line, positive inside (either winding).
    fn inside_margin(tri: [Vec2; 3], p: (f64, f64)) -> f64 {
        let t = tri.map(|v| (v.x as f64, v.y as f64));
        let area = (t[1].0 - t[0].0) * (t[2].1 - t[0].1) - (t[1].1 - t[0].1) * (t[2].0 - t[0].0);
        let s = area.signum();
        let mut m = f64::INFINITY;
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let len = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
            let e = (b.0 - a.0) * (p.1 - a.1) - (b.1 - a.1) * (p.0 - a.0);
            m = m.min(s * e / len);
        }
        m
    }

    #[test]
    fn covers_exactly_the_pixels_whose_centres_are_inside() {
        let mut rng = Rng(7);
        let (w, h) = (40u32, 30u32);
        let mut checked_in = 0;
        for _ in 0..300 {
            // Some vertices off-screen to exercise clipping of the pixel range.
            let tri = [(); 3].map(|_| Vec2::new(rng.f(-10.0, 50.0), rng.f(-10.0, 40.0)));
            let hits = coverage(tri, w, h);
            for y in 0..h {
                for x in 0..w {
                    let m = inside_margin(tri, (x as f64 + 0.5, y as f64 + 0.5));
                    let hit = hits[(y * w + x) as usize];
                    assert!(hit <= 1);
                    // Vertex snapping moves edges by at most ~1/256 px: only judge pixels
                    // clearly on one side.
                    if m > 0.01 {
                        assert_eq!(hit, 1, "{tri:?} misses ({x}, {y}), margin {m}");
                        checked_in += 1;
                    } else if m < -0.01 {
                        assert_eq!(hit, 0, "{tri:?} covers ({x}, {y}), margin {m}");
                    }
                }
            }
        }
        assert!(checked_in > 5000);
    }

    #[test]
    fn barycentrics_reproduce_the_pixel_centre() {
        let tri = [
            Vec2::new(2.0, 3.5),
            Vec2::new(30.25, 9.0),
            Vec2::new(11.0, 27.75),
        ];
        let mut n = 0;
        for t in [tri, [tri[0], tri[2], tri[1]]] {
            raster_triangle(t, 32, 0..32, |x, y, l| {
                let p = t[0] * l.x + t[1] * l.y + t[2] * l.z;
                assert!((p - Vec2::new(x as f32 + 0.5, y as f32 + 0.5)).length() < 1e-3);
                assert!((l.x + l.y + l.z - 1.0).abs() < 1e-5);
                assert!(l.min_element() >= 0.0);
                n += 1;
            });
        }
        assert!(n > 400);
    }

    #[test]
    fn a_fan_with_shared_edges_and_vertices_covers_each_interior_pixel_once() {
        // A polygon fanned around a centre that sits exactly on a pixel centre, with vertices
        // and edges through pixel centres: the hard cases for a fill rule.
        let c = Vec2::new(16.5, 16.5);
        let mut ring = vec![];
        for k in 0..12 {
            let a = k as f32 * std::f32::consts::TAU / 12.0;
            ring.push(c + Vec2::new(a.cos_pure(), a.sin_pure()) * 13.0);
        }
        ring.push(Vec2::new(16.5, 2.5)); // extra vertex on a pixel centre
        ring.sort_by(|p, q| {
            let (ap, aq) = ((p - c).to_angle(), (q - c).to_angle());
            ap.partial_cmp(&aq).unwrap()
        });
        let mut hits = vec![0u8; 34 * 34];
        for k in 0..ring.len() {
            // Alternate windings: the rule must not depend on them.
            let tri = if k % 2 == 0 {
                [c, ring[k], ring[(k + 1) % ring.len()]]
            } else {
                [ring[(k + 1) % ring.len()], ring[k], c]
            };
            raster_triangle(tri, 34, 0..34, |x, y, _| hits[(y * 34 + x) as usize] += 1);
        }
        // Horizontal shared edges too: a square split into two triangles, then a grid of them.
        let mut grid = vec![0u8; 20 * 20];
        for gy in 0..4 {
            for gx in 0..4 {
                let o = Vec2::new(gx as f32 * 4.5, gy as f32 * 4.5);
                let (p00, p10, p01, p11) = (
                    o,
                    o + Vec2::new(4.5, 0.0),
                    o + Vec2::new(0.0, 4.5),
                    o + Vec2::new(4.5, 4.5),
                );
                for tri in [[p00, p10, p11], [p00, p11, p01]] {
                    raster_triangle(tri, 20, 0..20, |x, y, _| grid[(y * 20 + x) as usize] += 1);
                }
            }
        }
        for y in 0..34 {
            for x in 0..34 {
                let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                let h = hits[(y * 34 + x) as usize];
                assert!(h <= 1, "pixel ({x}, {y}) covered {h} times");
                // Inside the polygon (clearly): covered exactly once.
                if (p - c).length() < 12.0 {
                    assert_eq!(h, 1, "hole at ({x}, {y})");
                }
            }
        }
        for y in 0..20 {
            for x in 0..20 {
                let g = grid[(y * 20 + x) as usize];
                let inside = (x as f32 + 0.5) < 18.0 && (y as f32 + 0.5) < 18.0;
                assert_eq!(g, inside as u8, "grid pixel ({x}, {y})");
            }
        }
    }

    #[test]
    fn rows_restrict_the_output_and_degenerate_triangles_cover_nothing() {
        let tri = [
            Vec2::new(0.0, 0.0),
            Vec2::new(10.0, 0.0),
            Vec2::new(0.0, 10.0),
        ];
        let mut rows = vec![];
        raster_triangle(tri, 10, 3..5, |_, y, _| rows.push(y));
        assert!(!rows.is_empty() && rows.iter().all(|&y| (3..5).contains(&y)));
        let line = [
            Vec2::new(0.0, 0.0),
            Vec2::new(5.0, 5.0),
            Vec2::new(10.0, 10.0),
        ];
        raster_triangle(line, 10, 0..10, |_, _, _| panic!("degenerate"));
        let nan = [
            Vec2::new(f32::NAN, 0.0),
            Vec2::new(5.0, 5.0),
            Vec2::new(10.0, 0.0),
        ];
        raster_triangle(nan, 10, 0..10, |_, _, _| panic!("NaN"));
    }
}
