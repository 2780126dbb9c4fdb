//! Exact distance from points to a triangle mesh's surface.
//!
//! Triangles are bucketed by their bounding boxes in a uniform grid of cells; a query visits
//! shells of cells around its own, nearest first, and stops once the next shell cannot hold
//! anything closer than what it found. The closest point on a triangle follows Ericson,
//! *Real-Time Collision Detection*, §5.1.5 (Voronoi regions of vertices, edges and face).
//!
//! Used by the solid method to choose an exemplar set by depth below the surface (Zhang et al.
//! 2011, Fig. 15); written by hand because it is small and needs no more than this.

use super::Mesh;
use crate::graph::Csr;
use glam::{IVec3, Vec3};

/// The closest point to `p` on triangle `abc`.
pub fn closest_point_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    // A degenerate triangle gives a non-finite denominator: fall back to its nearest vertex.
    if !denom.is_finite() {
        return [a, b, c]
            .into_iter()
            .min_by(|x, y| x.distance_squared(p).total_cmp(&y.distance_squared(p)))
            .expect("three vertices");
    }
    a + ab * (vb * denom) + ac * (vc * denom)
}

/// A mesh's triangles bucketed for distance queries.
pub struct SurfaceDistance<'a> {
    mesh: &'a Mesh,
    origin: Vec3,
    cell: f32,
    dims: IVec3,
    /// Per cell, the triangles whose bounding box overlaps it, ascending.
    buckets: Csr<u32>,
}

impl<'a> SurfaceDistance<'a> {
    /// Buckets `mesh`'s triangles (about two per cell on average).
    pub fn new(mesh: &'a Mesh) -> Self {
        let (lo, hi) = mesh.bounds();
        let extent = (hi - lo).max(Vec3::splat(1e-12));
        let n = mesh.triangles.len().max(1) as f32;
        // Cells about the size of the triangles: cube root of volume per triangle would
        // over-fill thin shapes, area per triangle matches a surface better.
        let area = 2.0 * (extent.x * extent.y + extent.y * extent.z + extent.z * extent.x);
        let cell = (area / n).sqrt().max(extent.max_element() / 128.0);
        let dims = ((extent / cell).ceil().as_ivec3()).max(IVec3::ONE);
        let cells = (dims.x * dims.y * dims.z) as usize;
        let range = |t: &[u32; 3]| {
            let p = t.map(|i| mesh.positions[i as usize]);
            let tlo = p[0].min(p[1]).min(p[2]);
            let thi = p[0].max(p[1]).max(p[2]);
            let c0 = ((tlo - lo) / cell)
                .floor()
                .as_ivec3()
                .clamp(IVec3::ZERO, dims - 1);
            let c1 = ((thi - lo) / cell)
                .floor()
                .as_ivec3()
                .clamp(IVec3::ZERO, dims - 1);
            (c0, c1)
        };
        let index = |c: IVec3| (c.x + dims.x * (c.y + dims.y * c.z)) as usize;
        // (cell, triangle) for every cell a triangle's box overlaps, triangles in order.
        let pairs = mesh.triangles.iter().enumerate().flat_map(|(ti, t)| {
            let (c0, c1) = range(t);
            (c0.z..=c1.z).flat_map(move |z| {
                (c0.y..=c1.y).flat_map(move |y| {
                    (c0.x..=c1.x).map(move |x| (index(IVec3::new(x, y, z)), ti as u32))
                })
            })
        });
        let buckets = Csr::from_pairs(cells, pairs);
        SurfaceDistance {
            mesh,
            origin: lo,
            cell,
            dims,
            buckets,
        }
    }

    /// The distance from `p` to the nearest point of the surface (infinite for a mesh without
    /// triangles).
    pub fn distance(&self, p: Vec3) -> f32 {
        if self.mesh.triangles.is_empty() {
            return f32::INFINITY;
        }
        // The query's cell, clamped into the grid; `outside` is how far p is from the grid's
        // box, which every shell's bound must add.
        let rel = (p - self.origin) / self.cell;
        let home = rel.floor().as_ivec3().clamp(IVec3::ZERO, self.dims - 1);
        let grid_hi = self.dims.as_vec3();
        let outside = (Vec3::ZERO - rel)
            .max(rel - grid_hi)
            .max(Vec3::ZERO)
            .length()
            * self.cell;
        let mut best = f32::INFINITY;
        let max_ring = self.dims.max_element();
        for ring in 0..=max_ring {
            // Every cell of this ring is at least (ring − 1) cells from p (p may sit anywhere in
            // its home cell), so once that exceeds the best, nothing closer remains.
            let bound = outside.max((ring as f32 - 1.0).max(0.0) * self.cell);
            if bound * bound > best {
                break;
            }
            self.visit_ring(home, ring, |ti| {
                let t = self.mesh.triangles[ti as usize];
                let [a, b, c] = t.map(|i| self.mesh.positions[i as usize]);
                let d = closest_point_on_triangle(p, a, b, c).distance_squared(p);
                if d < best {
                    best = d;
                }
            });
        }
        best.sqrt()
    }

    /// Calls `f` with every triangle of the cells at Chebyshev distance `ring` from `home`
    /// (a triangle spanning several cells may come more than once; distances don't mind).
    fn visit_ring(&self, home: IVec3, ring: i32, mut f: impl FnMut(u32)) {
        let lo = (home - IVec3::splat(ring)).max(IVec3::ZERO);
        let hi = (home + IVec3::splat(ring)).min(self.dims - 1);
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    let c = IVec3::new(x, y, z);
                    if (c - home).abs().max_element() != ring {
                        continue;
                    }
                    let k = (x + self.dims.x * (y + self.dims.y * z)) as usize;
                    for &ti in self.buckets.row(k) {
                        f(ti);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::PureMath;

    fn brute(mesh: &Mesh, p: Vec3) -> f32 {
        mesh.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
                closest_point_on_triangle(p, a, b, c).distance(p)
            })
            .fold(f32::INFINITY, f32::min)
    }

    /// A closed box [0,1]³ made of 2·6·n² triangles.
    fn cube(n: usize) -> Mesh {
        let mut p = Vec::new();
        let mut t = Vec::new();
        for axis in 0..3 {
            for side in [0.0f32, 1.0] {
                let base = p.len() as u32;
                for j in 0..=n {
                    for i in 0..=n {
                        let (u, v) = (i as f32 / n as f32, j as f32 / n as f32);
                        let mut q = [0.0; 3];
                        q[axis] = side;
                        q[(axis + 1) % 3] = u;
                        q[(axis + 2) % 3] = v;
                        p.push(Vec3::from(q));
                    }
                }
                let w = (n + 1) as u32;
                for j in 0..n as u32 {
                    for i in 0..n as u32 {
                        let k = base + j * w + i;
                        t.push([k, k + 1, k + w + 1]);
                        t.push([k, k + w + 1, k + w]);
                    }
                }
            }
        }
        Mesh::new(p, t)
    }

    #[test]
    fn closest_point_lies_in_each_voronoi_region() {
        let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::Y);
        // Above the face: the projection.
        let q = closest_point_on_triangle(Vec3::new(0.2, 0.3, 5.0), a, b, c);
        assert!(q.distance(Vec3::new(0.2, 0.3, 0.0)) < 1e-6);
        // Beyond a vertex.
        assert_eq!(
            closest_point_on_triangle(Vec3::new(-1.0, -1.0, 1.0), a, b, c),
            a
        );
        assert_eq!(
            closest_point_on_triangle(Vec3::new(3.0, -0.5, 0.0), a, b, c),
            b
        );
        // Beyond the hypotenuse: its midpoint.
        let q = closest_point_on_triangle(Vec3::new(1.0, 1.0, 0.0), a, b, c);
        assert!(q.distance(Vec3::new(0.5, 0.5, 0.0)) < 1e-6);
        // Degenerate triangle: no NaN.
        let q = closest_point_on_triangle(Vec3::new(0.3, 1.0, 0.0), a, b, b * 0.5);
        assert!(q.is_finite());
    }

    #[test]
    fn distance_inside_a_cube_is_the_distance_to_its_nearest_face() {
        let m = cube(6);
        let s = SurfaceDistance::new(&m);
        let mut state = 12345u64;
        let mut r = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        for _ in 0..500 {
            let p = Vec3::new(r(), r(), r());
            let expect = p.min_element().min((Vec3::ONE - p).min_element());
            let got = s.distance(p);
            assert!((got - expect).abs() < 1e-5, "{p}: {got} vs {expect}");
        }
    }

    #[test]
    fn distance_matches_brute_force_inside_and_far_outside() {
        let m = cube(5);
        let s = SurfaceDistance::new(&m);
        for k in 0..300 {
            let f = k as f32;
            let p = Vec3::new(
                (f * 0.731).sin_pure() * 3.0,
                (f * 1.173).cos_pure() * 3.0,
                (f * 0.377).sin_pure() * 0.5 + 0.5,
            );
            let (got, expect) = (s.distance(p), brute(&m, p));
            assert!((got - expect).abs() < 1e-5, "{p}: {got} vs {expect}");
        }
    }
}
