//! Triangle meshes and the quantities derived from them.
//!
//! Positions are `Vec<Vec3>`, triangles `Vec<[u32; 3]>` (DESIGN.md, Conventions). Derived
//! quantities (adjacency, vertex → faces, vertex → edges, normals) are computed on first
//! request and kept with the mesh, as geometry-central does, so an algorithm asks for what it
//! needs and pays for it once.

pub mod chains;
pub mod cut_graph;
pub mod edge_refine;
pub mod geometry_image;
pub mod half_edge;
pub mod io;
pub mod laplacian;
pub mod mean_value;
pub mod mesh_check;
pub mod poly_mesh;
pub mod primitives;
pub mod subdivide;
pub mod surface_distance;

use crate::graph::Csr;
use glam::{BVec3, Vec3};
use std::sync::OnceLock;

/// A triangle mesh. Vertices not referenced by any triangle are allowed and ignored by the
/// algorithms (they keep the file's vertex numbering stable, so config entries that name a
/// vertex by index mean what the user sees in their modelling tool).
#[derive(Debug, Default)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
    /// Optional per-vertex RGBA colours in [0, 1] (COFF, PLY with colour properties).
    pub colors: Option<Vec<[f32; 4]>>,
    adjacency: OnceLock<VertexAdjacency>,
    vertex_faces: OnceLock<Csr<u32>>,
    edges: OnceLock<MeshEdges>,
    vertex_normals: OnceLock<Vec<Vec3>>,
}

impl Clone for Mesh {
    fn clone(&self) -> Self {
        Mesh::with_colors(
            self.positions.clone(),
            self.triangles.clone(),
            self.colors.clone(),
        )
    }
}

impl Mesh {
    pub fn new(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Self {
        Self::with_colors(positions, triangles, None)
    }

    pub fn with_colors(
        positions: Vec<Vec3>,
        triangles: Vec<[u32; 3]>,
        colors: Option<Vec<[f32; 4]>>,
    ) -> Self {
        Mesh {
            positions,
            triangles,
            colors,
            adjacency: OnceLock::new(),
            vertex_faces: OnceLock::new(),
            edges: OnceLock::new(),
            vertex_normals: OnceLock::new(),
        }
    }

    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    pub fn face_count(&self) -> usize {
        self.triangles.len()
    }

    /// Axis-aligned bounding box (min, max) of the referenced vertices.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for t in &self.triangles {
            for &v in t {
                let p = self.positions[v as usize];
                lo = lo.min(p);
                hi = hi.max(p);
            }
        }
        (lo, hi)
    }

    pub fn face_normal_unnormalized(&self, f: usize) -> Vec3 {
        let [a, b, c] = self.triangles[f];
        let (a, b, c) = (
            self.positions[a as usize],
            self.positions[b as usize],
            self.positions[c as usize],
        );
        (b - a).cross(c - a)
    }

    /// Area-weighted vertex normals, unit length (zero for unreferenced vertices).
    pub fn vertex_normals(&self) -> &[Vec3] {
        self.vertex_normals.get_or_init(|| {
            let mut n = vec![Vec3::ZERO; self.positions.len()];
            for (f, t) in self.triangles.iter().enumerate() {
                let fn_ = self.face_normal_unnormalized(f);
                for &v in t {
                    n[v as usize] += fn_;
                }
            }
            for x in &mut n {
                *x = x.normalize_or_zero();
            }
            n
        })
    }

    /// Vertices on the mesh's boundary (on an edge that only one triangle uses), ascending.
    /// Edges are matched by sorting, not hashing, so the result never depends on an order.
    pub fn boundary_vertices(&self) -> Vec<u32> {
        let mut edges: Vec<(u32, u32)> = Vec::with_capacity(self.triangles.len() * 3);
        for t in &self.triangles {
            for e in 0..3 {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                if a != b {
                    edges.push((a.min(b), a.max(b)));
                }
            }
        }
        edges.sort_unstable();
        let mut on = vec![false; self.positions.len()];
        let mut i = 0;
        while i < edges.len() {
            let mut j = i + 1;
            while j < edges.len() && edges[j] == edges[i] {
                j += 1;
            }
            if j - i == 1 {
                on[edges[i].0 as usize] = true;
                on[edges[i].1 as usize] = true;
            }
            i = j;
        }
        (0..self.positions.len() as u32)
            .filter(|&v| on[v as usize])
            .collect()
    }

    /// Vertex-to-vertex adjacency (one-ring), built on first use.
    pub fn adjacency(&self) -> &VertexAdjacency {
        self.adjacency
            .get_or_init(|| VertexAdjacency::build(self.positions.len(), &self.triangles))
    }

    /// Vertex → triangles: row `v` lists the triangles with a corner at `v`, ascending, a
    /// triangle once per such corner (twice when it names `v` twice). Built on first use.
    pub fn vertex_faces(&self) -> &Csr<u32> {
        self.vertex_faces.get_or_init(|| {
            Csr::from_pairs(
                self.positions.len(),
                self.triangles
                    .iter()
                    .enumerate()
                    .flat_map(|(f, t)| t.iter().map(move |&v| (v as usize, f as u32))),
            )
        })
    }

    /// The undirected edges and vertex → edges, numbered from [`Self::adjacency`]; built on
    /// first use.
    pub fn edges(&self) -> &MeshEdges {
        self.edges
            .get_or_init(|| MeshEdges::build(self.adjacency()))
    }

    /// Mean edge length over all triangle edges.
    pub fn mean_edge_length(&self) -> f32 {
        let mut sum = 0.0f64;
        let mut n = 0usize;
        for t in &self.triangles {
            for k in 0..3 {
                let a = self.positions[t[k] as usize];
                let b = self.positions[t[(k + 1) % 3] as usize];
                sum += (a - b).length() as f64;
                n += 1;
            }
        }
        if n == 0 { 0.0 } else { (sum / n as f64) as f32 }
    }
}

/// The eight corners of the axis-aligned box `[lo, hi]`: corner `k` takes its x from `hi`
/// when bit 0 of `k` is set (else from `lo`), its y by bit 1 and its z by bit 2.
pub fn box_corners(lo: Vec3, hi: Vec3) -> [Vec3; 8] {
    std::array::from_fn(|k| Vec3::select(BVec3::new(k & 1 != 0, k & 2 != 0, k & 4 != 0), hi, lo))
}

/// One-ring adjacency in compressed-row form: the neighbours of vertex `v` are
/// `neighbors[offsets[v]..offsets[v + 1]]`, sorted ascending, without duplicates.
#[derive(Debug, Clone)]
pub struct VertexAdjacency {
    pub offsets: Vec<u32>,
    pub neighbors: Vec<u32>,
}

impl VertexAdjacency {
    pub fn build(vertex_count: usize, triangles: &[[u32; 3]]) -> Self {
        use rayon::prelude::*;
        // Bucket every corner's two other corners under it (a counting sort by vertex),
        // then sort and deduplicate each vertex's short list: linear work plus tiny sorts,
        // instead of one sort of all directed edges.
        let sides = triangles.iter().flat_map(|t| {
            (0..3).flat_map(move |k| {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                (a != b)
                    .then_some([(a as usize, b), (b as usize, a)])
                    .into_iter()
                    .flatten()
            })
        });
        let Csr {
            offsets: counts,
            items: mut raw,
        } = Csr::<u32>::from_pairs(vertex_count, sides);
        let mut lists: Vec<&mut [u32]> = Vec::with_capacity(vertex_count);
        let mut rest = raw.as_mut_slice();
        for v in 0..vertex_count {
            let (head, tail) = rest.split_at_mut((counts[v + 1] - counts[v]) as usize);
            lists.push(head);
            rest = tail;
        }
        let degrees: Vec<u32> = lists
            .par_iter_mut()
            .map(|l| {
                l.sort_unstable();
                let mut n = 0;
                for i in 0..l.len() {
                    if i == 0 || l[i] != l[i - 1] {
                        l[n] = l[i];
                        n += 1;
                    }
                }
                n as u32
            })
            .collect();
        let mut offsets = vec![0u32; vertex_count + 1];
        for v in 0..vertex_count {
            offsets[v + 1] = offsets[v] + degrees[v];
        }
        let mut neighbors = vec![0u32; offsets[vertex_count] as usize];
        for v in 0..vertex_count {
            let src = counts[v] as usize;
            let len = degrees[v] as usize;
            neighbors[offsets[v] as usize..offsets[v] as usize + len]
                .copy_from_slice(&raw[src..src + len]);
        }
        VertexAdjacency { offsets, neighbors }
    }

    pub fn neighbors(&self, v: usize) -> &[u32] {
        &self.neighbors[self.offsets[v] as usize..self.offsets[v + 1] as usize]
    }

    pub fn degree(&self, v: usize) -> usize {
        (self.offsets[v + 1] - self.offsets[v]) as usize
    }

    /// Index into the half-edge arrays of the directed edge `a -> b`, if it exists.
    pub fn half_edge(&self, a: usize, b: u32) -> Option<usize> {
        let start = self.offsets[a] as usize;
        self.neighbors(a).binary_search(&b).ok().map(|i| start + i)
    }

    pub fn vertex_count(&self) -> usize {
        self.offsets.len() - 1
    }
}

/// The undirected edges of a mesh (pairs of distinct vertices that share a triangle side):
/// edge `e` joins `ends[e] = [a, b]`, `a < b`, numbered by ascending `(a, b)`. Row `v` of
/// `vertex_edges` is aligned with the vertex's one-ring: `vertex_edges.row(v)[i]` is the edge
/// to `adjacency.neighbors(v)[i]` (the rows share the adjacency's offsets).
#[derive(Debug, Clone)]
pub struct MeshEdges {
    pub ends: Vec<[u32; 2]>,
    pub vertex_edges: Csr<u32>,
}

impl MeshEdges {
    pub fn build(adj: &VertexAdjacency) -> Self {
        let mut ids = vec![0u32; adj.neighbors.len()];
        let mut ends = Vec::with_capacity(adj.neighbors.len() / 2);
        for v in 0..adj.vertex_count() {
            let start = adj.offsets[v] as usize;
            for (i, &w) in adj.neighbors(v).iter().enumerate() {
                ids[start + i] = if w as usize > v {
                    ends.push([v as u32, w]);
                    (ends.len() - 1) as u32
                } else {
                    // Numbered at w, which comes first.
                    ids[adj
                        .half_edge(w as usize, v as u32)
                        .expect("adjacency is symmetric")]
                };
            }
        }
        MeshEdges {
            ends,
            vertex_edges: Csr {
                offsets: adj.offsets.clone(),
                items: ids,
            },
        }
    }

    pub fn count(&self) -> usize {
        self.ends.len()
    }

    /// The edges at `v`, in the order of its neighbours.
    pub fn of_vertex(&self, v: usize) -> &[u32] {
        self.vertex_edges.row(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boundary_vertices_are_those_on_edges_of_one_triangle() {
        // A fan of four triangles around vertex 0: its rim is the boundary, the centre not;
        // vertex 5 is in no triangle.
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::Y, -Vec3::X, -Vec3::Y, Vec3::ONE];
        let fan = Mesh::new(p, vec![[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1]]);
        assert_eq!(fan.boundary_vertices(), vec![1, 2, 3, 4]);
        // Closed: none.
        assert!(
            crate::geom::primitives::octahedron()
                .boundary_vertices()
                .is_empty()
        );
        // The fan with one triangle missing opens the centre too.
        let open = Mesh::new(fan.positions.clone(), fan.triangles[..3].to_vec());
        assert_eq!(open.boundary_vertices(), vec![0, 1, 2, 3, 4]);
    }

    #[test]
    fn adjacency_of_two_triangles_is_symmetric_and_sorted() {
        let m = Mesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::ONE],
            vec![[0, 1, 2], [2, 1, 3]],
        );
        let adj = m.adjacency();
        assert_eq!(adj.neighbors(0), &[1, 2]);
        assert_eq!(adj.neighbors(1), &[0, 2, 3]);
        assert_eq!(adj.neighbors(3), &[1, 2]);
        for v in 0..4 {
            for &n in adj.neighbors(v) {
                assert!(adj.neighbors(n as usize).contains(&(v as u32)));
            }
        }
        assert_eq!(adj.half_edge(1, 3), Some(adj.offsets[1] as usize + 2));
        assert_eq!(adj.half_edge(0, 3), None);
    }

    #[test]
    fn box_corners_follow_the_bits_of_their_index() {
        let (lo, hi) = (Vec3::new(-1.0, 2.0, 3.0), Vec3::new(4.0, 5.0, 6.0));
        let c = box_corners(lo, hi);
        assert_eq!(c[0], lo);
        assert_eq!(c[7], hi);
        assert_eq!(c[1], Vec3::new(4.0, 2.0, 3.0));
        assert_eq!(c[2], Vec3::new(-1.0, 5.0, 3.0));
        assert_eq!(c[4], Vec3::new(-1.0, 2.0, 6.0));
        assert_eq!(c[6], Vec3::new(-1.0, 5.0, 6.0));
    }

    proptest::proptest! {
        #[test]
        fn vertex_faces_and_edges_match_lists_built_one_triangle_at_a_time(
            tris in proptest::collection::vec((0u32..12, 0u32..12, 0u32..12), 0..40)
        ) {
            let tris: Vec<[u32; 3]> = tris.into_iter().map(|(a, b, c)| [a, b, c]).collect();
            let m = Mesh::new(vec![Vec3::ZERO; 12], tris.clone());
            let mut faces = vec![Vec::new(); 12];
            let mut sides = std::collections::BTreeSet::new();
            for (f, t) in tris.iter().enumerate() {
                for k in 0..3 {
                    faces[t[k] as usize].push(f as u32);
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    if a != b {
                        sides.insert([a.min(b), a.max(b)]);
                    }
                }
            }
            let ends: Vec<[u32; 2]> = sides.into_iter().collect();
            let e = m.edges();
            proptest::prop_assert_eq!(&e.ends, &ends);
            proptest::prop_assert_eq!(e.count(), ends.len());
            let adj = m.adjacency();
            for v in 0..12 {
                proptest::prop_assert_eq!(m.vertex_faces().row(v), faces[v].as_slice());
                proptest::prop_assert_eq!(e.of_vertex(v).len(), adj.degree(v));
                for (&w, &id) in adj.neighbors(v).iter().zip(e.of_vertex(v)) {
                    let (a, b) = (v as u32, w);
                    proptest::prop_assert_eq!(e.ends[id as usize], [a.min(b), a.max(b)]);
                }
            }
        }

        #[test]
        fn adjacency_matches_the_set_of_triangle_edges(
            tris in proptest::collection::vec((0u32..12, 0u32..12, 0u32..12), 0..40)
        ) {
            let tris: Vec<[u32; 3]> = tris.into_iter().map(|(a, b, c)| [a, b, c]).collect();
            let adj = VertexAdjacency::build(12, &tris);
            let mut want = vec![std::collections::BTreeSet::new(); 12];
            for t in &tris {
                for k in 0..3 {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    if a != b {
                        want[a as usize].insert(b);
                        want[b as usize].insert(a);
                    }
                }
            }
            for v in 0..12 {
                let got: Vec<u32> = adj.neighbors(v).to_vec();
                let expect: Vec<u32> = want[v].iter().copied().collect();
                proptest::prop_assert_eq!(got, expect);
            }
        }
    }
}
