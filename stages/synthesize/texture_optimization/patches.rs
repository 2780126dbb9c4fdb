//! The surface side: tangent frames from the field, the samples X† spread over the mesh, their
//! grid patches (which vertices each texel of a patch reads, with weights), and the samples'
//! per-level weights.

use super::candidates::Level;
use crate::geom::Mesh;
use crate::graph::Csr;
use glam::Vec3;
use rayon::prelude::*;
use std::collections::VecDeque;

/// Unit normals and tangent frames `(u, v = n × u)` per vertex.
pub(super) fn tangent_frames(mesh: &Mesh, field: &[Vec3]) -> (Vec<Vec3>, Vec<Vec3>, Vec<Vec3>) {
    let normals: Vec<Vec3> = mesh
        .vertex_normals()
        .iter()
        .map(|&n| if n == Vec3::ZERO { Vec3::Z } else { n })
        .collect();
    let mut us = Vec::with_capacity(normals.len());
    let mut vs = Vec::with_capacity(normals.len());
    for (&n, &f) in normals.iter().zip(field) {
        let t = f - n * n.dot(f);
        let u = if t.length_squared() > 1e-16 && t.is_finite() {
            t.normalize()
        } else {
            n.any_orthonormal_vector()
        };
        us.push(u);
        vs.push(n.cross(u));
    }
    (normals, us, vs)
}

/// Greedy X†: in `order`, a referenced vertex becomes a sample unless an earlier sample is
/// within `radius` (Euclidean, reached over edges through vertices within `radius`).
pub(super) fn choose_samples(
    mesh: &Mesh,
    order: &[u32],
    radius: f32,
    referenced: &[bool],
) -> Vec<u32> {
    let n = mesh.vertex_count();
    let adj = mesh.adjacency();
    let pos = &mesh.positions;
    let mut covered = vec![false; n];
    let mut stamp = vec![u32::MAX; n];
    let mut queue = VecDeque::new();
    let mut samples = Vec::new();
    let r2 = radius * radius;
    for &v in order {
        let v = v as usize;
        if !referenced[v] || covered[v] {
            continue;
        }
        let id = samples.len() as u32;
        samples.push(v as u32);
        queue.clear();
        queue.push_back(v);
        stamp[v] = id;
        covered[v] = true;
        while let Some(a) = queue.pop_front() {
            for &b in adj.neighbors(a) {
                let b = b as usize;
                if stamp[b] == id || pos[b].distance_squared(pos[v]) > r2 {
                    continue;
                }
                stamp[b] = id;
                covered[b] = true;
                queue.push_back(b);
            }
        }
    }
    samples
}

/// Every sample's patch: its vertices with their offsets in texels.
pub(super) struct Patches {
    /// Per sample, the range of its entries.
    pub(super) start: Vec<usize>,
    pub(super) vertex: Vec<u32>,
    pub(super) offset: Vec<[f32; 2]>,
    /// Per vertex, the indices of the entries covering it, in sample order.
    pub(super) by_vertex: Csr<u32, usize>,
    /// Sample of each entry.
    pub(super) entry_sample: Vec<u32>,
}

pub(super) struct Frames<'a> {
    pub(super) normals: &'a [Vec3],
    pub(super) u: &'a [Vec3],
    pub(super) v: &'a [Vec3],
}

/// A vertex's place in a patch: its offset from the sample in texels, and the sample's frame
/// carried to it.
#[derive(Clone, Copy)]
struct Carried {
    at: glam::Vec2,
    u: Vec3,
    v: Vec3,
}

/// Each sample's patch, unfolded from the sample outward over the edges (a discrete
/// exponential map, as `texsyn score` unfolds its discs): an edge steps the offset by its own
/// length, in the direction it has in the frame carried to its first end, and the frame turns
/// with the normal from one end to the other. A projection onto the sample's tangent plane
/// would shorten every offset across a crease by the cosine of the turn: over a 60–80° crease
/// (fandisk's) a column of the far face's vertices would read almost one exemplar texel, and
/// narrow faces between creases would show the exemplar streaked across them. On a plane both
/// agree. Each vertex keeps the offset of the first path that reaches it (breadth first, in
/// adjacency order), so where the surface is not developable (a corner where three creases
/// meet) the unfolding has a seam, placed deterministically.
pub(super) fn gather_patches(
    mesh: &Mesh,
    frames: &Frames,
    samples: &[u32],
    level: Level,
    texel_size: f32,
) -> Patches {
    let n = mesh.vertex_count();
    let adj = mesh.adjacency();
    let pos = &mesh.positions;
    let half = level.extent() * 0.5;
    let radius = half * std::f32::consts::SQRT_2 * texel_size * 1.001;
    let r2 = radius * radius;
    let unit = |x: Vec3| x.try_normalize().unwrap_or(Vec3::Z);
    let none = Carried {
        at: glam::Vec2::ZERO,
        u: Vec3::ZERO,
        v: Vec3::ZERO,
    };
    let per_sample: Vec<(Vec<u32>, Vec<[f32; 2]>)> = samples
        .par_iter()
        .map_init(
            || (vec![u32::MAX; n], vec![none; n], VecDeque::new()),
            |(stamp, carried, queue), &p| {
                let p = p as usize;
                let np = frames.normals[p];
                let mut verts = Vec::new();
                let mut offs = Vec::new();
                queue.clear();
                queue.push_back(p);
                // Samples are distinct vertices, so a sample's own index marks its visits.
                stamp[p] = p as u32;
                carried[p] = Carried {
                    at: glam::Vec2::ZERO,
                    u: frames.u[p],
                    v: frames.v[p],
                };
                while let Some(a) = queue.pop_front() {
                    let c = carried[a];
                    if c.at.x.abs() <= half && c.at.y.abs() <= half {
                        verts.push(a as u32);
                        offs.push(c.at.to_array());
                    }
                    for &b in adj.neighbors(a) {
                        let b = b as usize;
                        if stamp[b] == p as u32
                            || pos[b].distance_squared(pos[p]) > r2
                            || frames.normals[b].dot(np) <= 0.0
                        {
                            continue;
                        }
                        stamp[b] = p as u32;
                        let d = pos[b] - pos[a];
                        let dir = glam::Vec2::new(d.dot(c.u), d.dot(c.v));
                        let step = dir.normalize_or_zero() * (d.length() / texel_size);
                        let turn = glam::Quat::from_rotation_arc(
                            unit(frames.normals[a]),
                            unit(frames.normals[b]),
                        );
                        carried[b] = Carried {
                            at: c.at + step,
                            u: turn * c.u,
                            v: turn * c.v,
                        };
                        queue.push_back(b);
                    }
                }
                (verts, offs)
            },
        )
        .collect();
    let total: usize = per_sample.iter().map(|x| x.0.len()).sum();
    let mut start = Vec::with_capacity(samples.len() + 1);
    let mut vertex = Vec::with_capacity(total);
    let mut offset = Vec::with_capacity(total);
    let mut entry_sample = Vec::with_capacity(total);
    start.push(0);
    for (i, (v, o)) in per_sample.into_iter().enumerate() {
        entry_sample.extend(std::iter::repeat_n(i as u32, v.len()));
        vertex.extend(v);
        offset.extend(o);
        start.push(vertex.len());
    }
    let by_vertex = Csr::from_pairs(
        n,
        vertex
            .iter()
            .enumerate()
            .map(|(e, &q)| (q as usize, e as u32)),
    );
    Patches {
        start,
        vertex,
        offset,
        by_vertex,
        entry_sample,
    }
}

/// Splits `v` into consecutive mutable pieces at `start` (a CSR offset array).
pub(super) fn split_by<'a, T>(mut v: &'a mut [T], start: &[usize]) -> Vec<&'a mut [T]> {
    let mut out = Vec::with_capacity(start.len().saturating_sub(1));
    for w in start.windows(2) {
        let (a, b) = v.split_at_mut(w[1] - w[0]);
        out.push(a);
        v = b;
    }
    out
}

#[inline]
pub(super) fn sq(a: [f32; 3], b: [f32; 3]) -> f32 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
}

/// Per-level state of the samples.
pub(super) struct SampleInfo {
    /// λ_p.
    pub(super) lambda: Vec<f32>,
    /// Curve distance in texels of constrained samples that have candidates; None otherwise.
    pub(super) constraint: Vec<Option<f32>>,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sheet bent by 60° along the line x = 0: a patch of a sample on the flat half reaches
    /// over the crease with the far half unfolded, every vertex at the offset it has along the
    /// surface (half a texel per grid step). A projection onto the sample's plane would put
    /// the far vertices on the sample's row at 1 + 2·cos 60° = 2 texels instead of 3, and a
    /// frame not carried over the crease would turn the far half's rows (off the sample's row
    /// the step's direction depends on it).
    #[test]
    fn a_patch_over_a_crease_is_unfolded_not_projected() {
        use texsyn_core::math::PureMath;
        let (half, bend) = (10usize, 60f32.to_radians());
        let n = 2 * half + 1;
        let mut mesh = crate::geom::primitives::grid(n, 0.5);
        for p in &mut mesh.positions {
            let x = p.x - half as f32 * 0.5;
            *p = if x <= 0.0 {
                Vec3::new(x, p.y, 0.0)
            } else {
                Vec3::new(x * bend.cos_pure(), p.y, x * bend.sin_pure())
            };
        }
        let field = vec![Vec3::X; mesh.vertex_count()];
        let (normals, u, v) = tangent_frames(&mesh, &field);
        let frames = Frames {
            normals: &normals,
            u: &u,
            v: &v,
        };
        // Grid vertex (i, j) is at index j·n + i; x = 0 is column `half`.
        let (i0, j0) = (half - 2, half);
        let sample = j0 * n + i0;
        let level = Level { w: 9, step: 1.0 };
        let patches = gather_patches(&mesh, &frames, &[sample as u32], level, 1.0);
        let mut far = 0;
        for (&q, o) in patches.vertex.iter().zip(&patches.offset) {
            let (i, j) = (q as usize % n, q as usize / n);
            let want = [(i as f32 - i0 as f32) * 0.5, (j as f32 - j0 as f32) * 0.5];
            let err = ((o[0] - want[0]).powi(2) + (o[1] - want[1]).powi(2)).sqrt();
            assert!(
                err < 0.1,
                "vertex ({i}, {j}) at {o:?}, along the surface {want:?}"
            );
            far += (i > half + 2) as usize;
        }
        assert!(
            far >= 10,
            "the patch reaches {far} vertices past the crease"
        );
        let on_row = j0 * n + half + 4;
        assert!(patches.vertex.contains(&(on_row as u32)));
    }
}
