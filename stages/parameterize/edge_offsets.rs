//! Per-edge texture-space offsets (Zelinka & Garland, "Interactive Texture Synthesis on
//! Surfaces Using Jump Maps", §4.2.2, Fig. 4) and per-vertex validity boxes (§4.2.4).
//!
//! Each vertex has a tangent frame: its orientation vector u ("up" in texture space) and
//! v = u × n. An edge's frame averages its endpoints' u and keeps the part of their averaged
//! v perpendicular to that; the edge vector is projected into it and scaled by the user's
//! texels per object unit. The offset is computed from quantities symmetric in the two
//! endpoints, so the offset of j→i is exactly (bit for bit) minus that of i→j, and the corner
//! coordinates of §4.3 are consistent.
//!
//! Texel addresses have y pointing down (image rows), so "up" on the surface maps to −y.
//!
//! The validity box of a vertex encloses the offsets of all its edges (and the vertex itself):
//! an address is valid for the vertex when the box placed at it lies inside the exemplar.

use crate::geom::{Mesh, VertexAdjacency};
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// A vertex's validity box: offsets relative to its address.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct OffsetBox {
    pub min: Vec2,
    pub max: Vec2,
}

impl OffsetBox {
    /// The range of addresses `a` for which `a + box` lies in `[0, w-1] × [0, h-1]`, as
    /// (lowest, highest); empty when lowest > highest on an axis.
    #[inline]
    pub fn valid_range(&self, width: u32, height: u32) -> (Vec2, Vec2) {
        let hi = Vec2::new((width - 1) as f32, (height - 1) as f32);
        (-self.min, hi - self.max)
    }

    #[inline]
    pub fn admits(&self, a: Vec2, width: u32, height: u32) -> bool {
        let (lo, hi) = self.valid_range(width, height);
        a.x >= lo.x && a.y >= lo.y && a.x <= hi.x && a.y <= hi.y
    }

    pub fn size(&self) -> Vec2 {
        self.max - self.min
    }
}

/// Offsets per half-edge of `adj` (the edge `v → adj.neighbors(v)[k]` is at
/// `adj.offsets[v] + k`), in texels, for orientation field `up` and `scale` texels per unit.
pub fn edge_offsets(mesh: &Mesh, adj: &VertexAdjacency, up: &[Vec3], scale: f32) -> Vec<Vec2> {
    let normals = mesh.vertex_normals();
    let right: Vec<Vec3> = up.iter().zip(normals).map(|(u, n)| u.cross(*n)).collect();
    let mut out = vec![Vec2::ZERO; adj.neighbors.len()];
    out.par_chunks_mut(4096)
        .enumerate()
        .for_each(|(chunk, slots)| {
            let base = chunk * 4096;
            // Find the vertex owning the first half-edge of this chunk, then walk.
            let mut v = adj.offsets.partition_point(|&o| o as usize <= base) - 1;
            for (k, slot) in slots.iter_mut().enumerate() {
                let h = base + k;
                while adj.offsets[v + 1] as usize <= h {
                    v += 1;
                }
                let w = adj.neighbors[h] as usize;
                *slot = edge_offset(
                    mesh.positions[w] - mesh.positions[v],
                    up[v],
                    up[w],
                    right[v],
                    right[w],
                    scale,
                );
            }
        });
    out
}

#[inline]
fn edge_offset(e: Vec3, ui: Vec3, uj: Vec3, vi: Vec3, vj: Vec3, scale: f32) -> Vec2 {
    // Sums are commutative in IEEE arithmetic, so both directions see the same frame.
    let mut u = (ui + uj).normalize_or_zero();
    if u == Vec3::ZERO {
        // Opposite orientations have no average: take the lexicographically larger one, a
        // rule that is symmetric in the endpoints.
        u = if ui.to_array() > uj.to_array() {
            ui
        } else {
            uj
        };
    }
    let vbar = vi + vj;
    let mut v = (vbar - vbar.dot(u) * u).normalize_or_zero();
    if v == Vec3::ZERO {
        v = u.any_orthonormal_vector();
    }
    Vec2::new(e.dot(v), -e.dot(u)) * scale
}

/// The validity box of every vertex (vertices without edges get an empty box at 0).
pub fn validity_boxes(adj: &VertexAdjacency, offsets: &[Vec2]) -> Vec<OffsetBox> {
    (0..adj.vertex_count())
        .into_par_iter()
        .map(|v| {
            let mut b = OffsetBox {
                min: Vec2::ZERO,
                max: Vec2::ZERO,
            };
            for d in &offsets[adj.offsets[v] as usize..adj.offsets[v + 1] as usize] {
                b.min = b.min.min(*d);
                b.max = b.max.max(*d);
            }
            b
        })
        .collect()
}

/// The largest scale at which every vertex's box fits in a `width × height` exemplar, given
/// the boxes computed at `scale` (boxes scale linearly with the scale).
pub fn largest_fitting_scale(boxes: &[OffsetBox], scale: f32, width: u32, height: u32) -> f32 {
    let (w, h) = ((width - 1) as f32, (height - 1) as f32);
    boxes
        .iter()
        .map(|b| {
            let s = b.size();
            let fx = if s.x > 0.0 { w / s.x } else { f32::INFINITY };
            let fy = if s.y > 0.0 { h / s.y } else { f32::INFINITY };
            fx.min(fy)
        })
        .fold(f32::INFINITY, f32::min)
        * scale
}

#[cfg(test)]
mod tests {
    use super::*;
    use texsyn_core::math::PureMath;

    use crate::geom::primitives::grid;

    /// A flat `n`×`n` grid, `spacing` apart, with up along +y everywhere, and its edge
    /// offsets at `scale` texels per unit.
    fn flat_grid_offsets(n: usize, spacing: f32, scale: f32) -> (Mesh, Vec<Vec2>) {
        let m = grid(n, spacing);
        let up = vec![Vec3::Y; m.vertex_count()];
        let off = edge_offsets(&m, m.adjacency(), &up, scale);
        (m, off)
    }

    #[test]
    fn flat_grid_with_up_along_y_maps_to_texels_with_y_down() {
        let (m, off) = flat_grid_offsets(5, 0.1, 20.0);
        let adj = m.adjacency();
        // Normal is +z, up is +y, so right = y × z = +x: object x → texel x, object y → -texel y.
        let h = adj.half_edge(0, 1).unwrap();
        assert!((off[h] - Vec2::new(2.0, 0.0)).length() < 1e-5, "{}", off[h]);
        let h = adj.half_edge(0, 5).unwrap();
        assert!(
            (off[h] - Vec2::new(0.0, -2.0)).length() < 1e-5,
            "{}",
            off[h]
        );
    }

    #[test]
    fn opposite_half_edges_have_exactly_opposite_offsets() {
        let mut m = grid(6, 0.3);
        // Bend it and give it a swirling field so frames differ between endpoints.
        for p in &mut m.positions {
            p.z = (p.x * 3.0).sin_pure() * 0.2;
        }
        let m = Mesh::new(m.positions.clone(), m.triangles.clone());
        let n = m.vertex_normals().to_vec();
        let up: Vec<Vec3> = m
            .positions
            .iter()
            .zip(&n)
            .map(|(p, n)| {
                let d = Vec3::new(-p.y, p.x + 0.3, 0.1);
                (d - d.dot(*n) * *n).normalize()
            })
            .collect();
        let adj = m.adjacency();
        let off = edge_offsets(&m, adj, &up, 7.0);
        for v in 0..m.vertex_count() {
            for &w in adj.neighbors(v) {
                let a = off[adj.half_edge(v, w).unwrap()];
                let b = off[adj.half_edge(w as usize, v as u32).unwrap()];
                assert_eq!(a, -b, "edge {v}-{w}");
            }
        }
    }

    #[test]
    fn boxes_enclose_offsets_and_fit_check_scales_linearly() {
        let (m, off) = flat_grid_offsets(4, 1.0, 10.0);
        let boxes = validity_boxes(m.adjacency(), &off);
        // Interior vertex 5: neighbours at ±10 in x and y.
        assert_eq!(boxes[5].min, Vec2::new(-10.0, -10.0));
        assert_eq!(boxes[5].max, Vec2::new(10.0, 10.0));
        // A 21×21 exemplar fits a 20-texel box exactly, at scale 10.
        let s = largest_fitting_scale(&boxes, 10.0, 21, 21);
        assert!((s - 10.0).abs() < 1e-4, "{s}");
        assert!(boxes[5].admits(Vec2::new(10.0, 10.0), 21, 21));
        assert!(!boxes[5].admits(Vec2::new(9.5, 10.0), 21, 21));
    }
}
