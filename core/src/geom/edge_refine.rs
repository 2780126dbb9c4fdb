//! Refinement by edge splitting: every edge longer than a bound is split at its midpoint, and
//! each triangle is re-triangulated by how many of its edges were split (one: two triangles,
//! two: three, three: four), round after round until no edge is too long.
//!
//! Used where a per-vertex method needs vertices about one texel apart (feature-aligned
//! texturing, Xu et al. 2009 §5.1 optimizes vertex colours). Uniform midpoint subdivision
//! ([`super::subdivide`]) is driven by the longest edge of the whole mesh and quadruples every
//! triangle each round; a CAD mesh such as fandisk mixes long thin triangles with small ones,
//! so uniform subdivision spends most of its budget where the mesh is already fine. Splitting
//! only long edges keeps the result conforming (no T-junctions: a split edge is split in both
//! of its triangles) and refines only where needed.
//!
//! Every new vertex records its two parents (the ends of the edge it split), so per-vertex
//! data (a vector field) can be carried over, and [`Refined::refine_path`] maps a vertex path
//! of the input mesh (a feature curve) onto the refined mesh.

use super::Mesh;
use glam::Vec3;
use std::collections::BTreeMap;

/// The `edge_refinement` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: crate::algorithm::Algorithm =
    crate::algorithm::Algorithm::new("edge_refinement", 2);

/// The refined mesh and where its new vertices came from.
#[derive(Debug, Clone)]
pub struct Refined {
    pub mesh: Mesh,
    /// The input mesh's vertex count: vertices below it are the input's, with their ids.
    pub input_vertices: u32,
    /// For every vertex from `input_vertices` on, in order: the ends of the edge it splits.
    pub parents: Vec<[u32; 2]>,
    /// For every refined triangle: the input triangle it lies in (so a point of the input
    /// mesh can be found on the refined one, e.g. to bake refined colours into an atlas of the
    /// input mesh).
    pub face_origin: Vec<u32>,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RefineError {
    #[error(
        "refining to edges of at most {max_edge} would need more than {max_vertices} vertices \
         (the {round}th round of splits alone adds {adding} to {have})"
    )]
    TooManyVertices {
        max_edge: f32,
        max_vertices: usize,
        round: u32,
        have: usize,
        adding: usize,
    },
    #[error("refining did not converge in {0} rounds (degenerate triangles?)")]
    NoConvergence(u32),
}

const MAX_ROUNDS: u32 = 64;

/// Splits edges longer than `max_edge` until none is, with at most `max_vertices` vertices.
pub fn refine_edges(
    mesh: &Mesh,
    max_edge: f32,
    max_vertices: usize,
) -> Result<Refined, RefineError> {
    let mut positions = mesh.positions.clone();
    let mut triangles = mesh.triangles.clone();
    let mut origin: Vec<u32> = (0..triangles.len() as u32).collect();
    let mut parents: Vec<[u32; 2]> = Vec::new();
    let limit2 = max_edge * max_edge;
    for round in 1..=MAX_ROUNDS {
        let mut long: Vec<(u32, u32)> = Vec::new();
        for t in &triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let (a, b) = (a.min(b), a.max(b));
                if positions[a as usize].distance_squared(positions[b as usize]) > limit2 {
                    long.push((a, b));
                }
            }
        }
        long.sort_unstable();
        long.dedup();
        if long.is_empty() {
            return Ok(Refined {
                mesh: Mesh::new(positions, triangles),
                input_vertices: mesh.positions.len() as u32,
                parents,
                face_origin: origin,
            });
        }
        if positions.len() + long.len() > max_vertices {
            return Err(RefineError::TooManyVertices {
                max_edge,
                max_vertices,
                round,
                have: positions.len(),
                adding: long.len(),
            });
        }
        let mut mid: BTreeMap<(u32, u32), u32> = BTreeMap::new();
        for &(a, b) in &long {
            mid.insert((a, b), positions.len() as u32);
            positions.push((positions[a as usize] + positions[b as usize]) * 0.5);
            parents.push([a, b]);
        }
        let split = |a: u32, b: u32| mid.get(&(a.min(b), a.max(b))).copied();
        let mut next = Vec::with_capacity(triangles.len() * 2);
        let mut next_origin = Vec::with_capacity(triangles.len() * 2);
        for (t, &o) in triangles.iter().zip(&origin) {
            let before = next.len();
            let m: [Option<u32>; 3] = std::array::from_fn(|k| split(t[k], t[(k + 1) % 3]));
            match m.iter().filter(|x| x.is_some()).count() {
                0 => next.push(*t),
                1 => {
                    // Rotate so the split edge is (t[r], t[r+1]).
                    let r = (0..3).find(|&k| m[k].is_some()).expect("one split");
                    let (a, b, c) = (t[r], t[(r + 1) % 3], t[(r + 2) % 3]);
                    let ab = m[r].expect("split");
                    next.push([a, ab, c]);
                    next.push([ab, b, c]);
                }
                2 => {
                    // Rotate so the unsplit edge is (t[r+2], t[r]): splits on (a,b) and (b,c).
                    let r = ((0..3).find(|&k| m[k].is_none()).expect("one unsplit") + 1) % 3;
                    let (a, b, c) = (t[r], t[(r + 1) % 3], t[(r + 2) % 3]);
                    let (ab, bc) = (m[r].expect("split"), m[(r + 1) % 3].expect("split"));
                    next.push([ab, b, bc]);
                    // The quad (a, ab, bc, c) along its shorter diagonal: fewer thin triangles.
                    let p = |v: u32| positions[v as usize];
                    if p(a).distance_squared(p(bc)) <= p(ab).distance_squared(p(c)) {
                        next.push([a, ab, bc]);
                        next.push([a, bc, c]);
                    } else {
                        next.push([a, ab, c]);
                        next.push([ab, bc, c]);
                    }
                }
                _ => {
                    let (ab, bc, ca) = (m[0].unwrap(), m[1].unwrap(), m[2].unwrap());
                    next.push([t[0], ab, ca]);
                    next.push([t[1], bc, ab]);
                    next.push([t[2], ca, bc]);
                    next.push([ab, bc, ca]);
                }
            }
            next_origin.resize(next.len(), o);
            debug_assert!(next.len() > before);
        }
        triangles = next;
        origin = next_origin;
    }
    Err(RefineError::NoConvergence(MAX_ROUNDS))
}

impl Refined {
    /// Per-vertex values carried to the new vertices: each is `blend` of its parents' values
    /// (parents always come before their children, so one pass in order suffices).
    pub fn carry<T: Copy>(&self, input: &[T], blend: impl Fn(T, T) -> T) -> Vec<T> {
        let mut out = input.to_vec();
        for &[a, b] in &self.parents {
            let v = blend(out[a as usize], out[b as usize]);
            out.push(v);
        }
        out
    }

    /// A vertex path of the input mesh (consecutive vertices share an edge) as a path of the
    /// refined mesh: every split edge on the way is replaced by its halves.
    pub fn refine_path(&self, path: &[u32], closed: bool) -> Vec<u32> {
        self.refine_path_with(&self.midpoints(), path, closed)
    }

    /// Several paths: the midpoint map is built once.
    pub fn refine_paths<'p>(
        &self,
        paths: impl IntoIterator<Item = (&'p [u32], bool)>,
    ) -> Vec<Vec<u32>> {
        let mid = self.midpoints();
        paths
            .into_iter()
            .map(|(p, closed)| self.refine_path_with(&mid, p, closed))
            .collect()
    }

    fn midpoints(&self) -> BTreeMap<(u32, u32), u32> {
        self.parents
            .iter()
            .enumerate()
            .map(|(i, &[a, b])| ((a.min(b), a.max(b)), self.input_vertices + i as u32))
            .collect()
    }

    fn refine_path_with(
        &self,
        mid: &BTreeMap<(u32, u32), u32>,
        path: &[u32],
        closed: bool,
    ) -> Vec<u32> {
        let mut out = Vec::with_capacity(path.len() * 2);
        let n = path.len();
        let edges = if closed { n } else { n.saturating_sub(1) };
        if let Some(&first) = path.first() {
            out.push(first);
        }
        for i in 0..edges {
            let (a, b) = (path[i], path[(i + 1) % n]);
            // Iterative in-order expansion of (a, b) down to unsplit edges.
            let mut stack = vec![(a, b)];
            while let Some((x, y)) = stack.pop() {
                match mid.get(&(x.min(y), x.max(y))) {
                    Some(&m) => {
                        stack.push((m, y));
                        stack.push((x, m));
                    }
                    None => out.push(y),
                }
            }
        }
        if closed && out.len() > 1 {
            // The loop came back to its first vertex: a closed path does not repeat it.
            out.pop();
        }
        out
    }
}

/// The longest edge of the mesh.
pub fn longest_edge(positions: &[Vec3], triangles: &[[u32; 3]]) -> f32 {
    let mut m = 0f32;
    for t in triangles {
        for k in 0..3 {
            let d = positions[t[k] as usize].distance(positions[t[(k + 1) % 3] as usize]);
            m = m.max(d);
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::primitives;

    fn area(m: &Mesh) -> f32 {
        (0..m.face_count())
            .map(|f| m.face_normal_unnormalized(f).length() * 0.5)
            .sum()
    }

    /// Every undirected edge is used by at most two triangles, and the boundary (edges used
    /// once) has the input's length: splitting introduced no T-junction or crack.
    fn boundary_length(m: &Mesh) -> f32 {
        let mut count: BTreeMap<(u32, u32), u32> = BTreeMap::new();
        for t in &m.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *count.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        assert!(
            count.values().all(|&c| c <= 2),
            "an edge has three triangles"
        );
        count
            .iter()
            .filter(|(_, c)| **c == 1)
            .map(|(&(a, b), _)| m.positions[a as usize].distance(m.positions[b as usize]))
            .sum()
    }

    #[test]
    fn long_edges_are_split_until_none_is_too_long_without_cracks() {
        // A long thin triangle next to a small one: a mesh like fandisk's.
        let m = Mesh::new(
            vec![
                Vec3::ZERO,
                Vec3::new(10.0, 0.0, 0.0),
                Vec3::new(0.0, 0.5, 0.0),
                Vec3::new(0.0, -0.5, 0.0),
            ],
            vec![[0, 1, 2], [0, 3, 1]],
        );
        let r = refine_edges(&m, 0.4, 100_000).unwrap();
        assert!(longest_edge(&r.mesh.positions, &r.mesh.triangles) <= 0.4);
        assert!((area(&r.mesh) - area(&m)).abs() < 1e-4);
        assert!((boundary_length(&r.mesh) - boundary_length(&m)).abs() < 1e-3);
        // Both input triangles face +z: every refined triangle keeps that orientation.
        for f in 0..r.mesh.face_count() {
            assert!(
                r.mesh.face_normal_unnormalized(f).z > 0.0,
                "triangle {f} flipped"
            );
        }
        // Origins: every refined triangle lies in the plane of its input triangle.
        assert_eq!(r.face_origin.len(), r.mesh.face_count());
        for (f, &o) in r.face_origin.iter().enumerate() {
            let n = m.face_normal_unnormalized(o as usize).normalize();
            let p0 = m.positions[m.triangles[o as usize][0] as usize];
            for &v in &r.mesh.triangles[f] {
                assert!((r.mesh.positions[v as usize] - p0).dot(n).abs() < 1e-6);
            }
            // The centroid is inside the origin (both input triangles are in z = 0).
            let c = r.mesh.triangles[f]
                .iter()
                .map(|&v| r.mesh.positions[v as usize])
                .sum::<Vec3>()
                / 3.0;
            let t = m.triangles[o as usize].map(|v| m.positions[v as usize]);
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                assert!(
                    (b - a).cross(c - a).z >= -1e-6,
                    "triangle {f} is outside its origin {o}"
                );
            }
        }
        // Parents: every new vertex is the midpoint of its parents.
        for (i, &[a, b]) in r.parents.iter().enumerate() {
            let v = r.input_vertices as usize + i;
            let (pa, pb) = (r.mesh.positions[a as usize], r.mesh.positions[b as usize]);
            assert!(r.mesh.positions[v].distance((pa + pb) * 0.5) < 1e-6);
            assert!((a as usize) < v && (b as usize) < v);
        }
    }

    #[test]
    fn a_mesh_already_fine_enough_is_unchanged_and_the_budget_is_an_error() {
        let m = primitives::grid(5, 0.1);
        let r = refine_edges(&m, 1.0, 100).unwrap();
        assert_eq!(r.mesh.triangles, m.triangles);
        assert!(r.parents.is_empty());
        let e = refine_edges(&m, 0.001, 1000).unwrap_err();
        assert!(matches!(e, RefineError::TooManyVertices { .. }), "{e}");
    }

    #[test]
    fn paths_follow_their_split_edges_and_values_carry_over() {
        let m = primitives::grid(3, 1.0);
        let r = refine_edges(&m, 0.3, 100_000).unwrap();
        // The bottom row 0-1-2, as a path, becomes a chain of short edges along y = 0.
        let path = r.refine_path(&[0, 1, 2], false);
        assert_eq!(path.first(), Some(&0));
        assert_eq!(path.last(), Some(&2));
        assert!(path.len() >= 9, "{path:?}");
        let adj = r.mesh.adjacency();
        for w in path.windows(2) {
            assert!(
                adj.neighbors(w[0] as usize).contains(&w[1]),
                "{w:?} is not an edge"
            );
            assert!(r.mesh.positions[w[1] as usize].y.abs() < 1e-6);
        }
        // A closed path around the boundary does not repeat its first vertex.
        let closed = r.refine_path(&[0, 1, 2, 5, 8, 7, 6, 3], true);
        assert_ne!(closed.first(), closed.last());
        assert!(
            adj.neighbors(closed[0] as usize)
                .contains(closed.last().unwrap())
        );
        // Carried values: x coordinates carried by averaging equal the positions' x.
        let xs: Vec<f32> = m.positions.iter().map(|p| p.x).collect();
        let carried = r.carry(&xs, |a, b| 0.5 * (a + b));
        for (v, p) in r.mesh.positions.iter().enumerate() {
            assert!((carried[v] - p.x).abs() < 1e-5);
        }
    }
}
