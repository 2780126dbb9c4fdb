//! Half-edge connectivity of a triangle mesh, with the checks that the cut-and-parameterize
//! algorithms need: every edge has one or two triangles, neighbouring triangles are
//! consistently oriented, and every vertex's triangles form a single fan (a disk or a
//! half-disk around it). Also the boundary loops, the connected components and their Euler
//! characteristic and genus.
//!
//! Numbering: the half-edge `3f + k` runs from corner `k` to corner `k + 1` of triangle `f`
//! (so half-edge `3f + k` also names the corner `k` of `f`). Each edge with one triangle gets
//! a *boundary* half-edge (no face), numbered from `3F` on, so that every half-edge has a
//! twin. Boundary half-edges are linked into cycles by `next` / `prev` that run opposite to
//! the triangles (the interior is on their right). Vertices referenced by no triangle are
//! ignored: they have no half-edge and belong to no component.

use super::Mesh;
use crate::graph::Csr;

/// "No element": the face of a boundary half-edge, the half-edge of an unused vertex.
pub const NONE: u32 = u32::MAX;

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TopologyError {
    #[error("the mesh has no triangles")]
    Empty,
    #[error("triangle {face} refers to vertex {vertex}, but the mesh has only {count} vertices")]
    VertexOutOfRange {
        face: u32,
        vertex: u32,
        count: usize,
    },
    #[error("triangle {face} is degenerate: it uses vertex {vertex} more than once")]
    DegenerateFace { face: u32, vertex: u32 },
    #[error(
        "non-manifold edge between vertices {a} and {b}: it is shared by {} triangles \
         ({faces:?}), at most two are allowed",
        faces.len()
    )]
    NonManifoldEdge { a: u32, b: u32, faces: Vec<u32> },
    #[error(
        "triangles {f1} and {f2} are oriented inconsistently: both run along their shared \
         edge from vertex {a} to vertex {b} (one should run {b} to {a})"
    )]
    InconsistentOrientation { a: u32, b: u32, f1: u32, f2: u32 },
    #[error(
        "non-manifold vertex {vertex}: its triangles form {fans} separate fans (a surface \
         vertex has exactly one)"
    )]
    NonManifoldVertex { vertex: u32, fans: usize },
}

/// One connected component (triangles connected through shared edges).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Component {
    pub faces: usize,
    pub edges: usize,
    pub vertices: usize,
    pub boundary_loops: usize,
    /// V − E + F.
    pub euler_characteristic: i64,
    /// (2 − boundary loops − χ) / 2.
    pub genus: i64,
}

/// Half-edge connectivity (see the module doc for the numbering).
#[derive(Debug, Clone)]
pub struct HalfEdgeMesh {
    vertex_count: usize,
    face_count: usize,
    dest: Vec<u32>,
    twin: Vec<u32>,
    next: Vec<u32>,
    prev: Vec<u32>,
    edge: Vec<u32>,
    /// Per edge, its half-edge with the smaller index (always one with a face).
    edge_he: Vec<u32>,
    /// Per vertex, one outgoing half-edge: the boundary one for a boundary vertex, the
    /// smallest otherwise; `NONE` for an unused vertex.
    vertex_he: Vec<u32>,
    /// Boundary loops as face half-edges (interior on the left) in order:
    /// `dest(loop[k]) == origin(loop[k + 1])`.
    loops: Vec<Vec<u32>>,
    face_component: Vec<u32>,
    components: Vec<Component>,
}

impl HalfEdgeMesh {
    /// Builds the connectivity, or names the first problem found: vertex indices out of range,
    /// degenerate triangles, then non-manifold edges, then inconsistent orientation (in order
    /// of the edge's vertex pair), then non-manifold vertices (in vertex order).
    pub fn new(mesh: &Mesh) -> Result<Self, TopologyError> {
        let nv = mesh.vertex_count();
        let nf = mesh.face_count();
        if nf == 0 {
            return Err(TopologyError::Empty);
        }
        for (f, t) in mesh.triangles.iter().enumerate() {
            for k in 0..3 {
                if t[k] as usize >= nv {
                    return Err(TopologyError::VertexOutOfRange {
                        face: f as u32,
                        vertex: t[k],
                        count: nv,
                    });
                }
                if t[k] == t[(k + 1) % 3] {
                    return Err(TopologyError::DegenerateFace {
                        face: f as u32,
                        vertex: t[k],
                    });
                }
            }
        }
        let nh_faces = 3 * nf;
        let mut dest = Vec::with_capacity(nh_faces + nh_faces / 8);
        let mut next = Vec::with_capacity(dest.capacity());
        let mut prev = Vec::with_capacity(dest.capacity());
        for t in &mesh.triangles {
            let base = dest.len() as u32;
            for k in 0..3 {
                dest.push(t[(k + 1) % 3]);
                next.push(base + (k as u32 + 1) % 3);
                prev.push(base + (k as u32 + 2) % 3);
            }
        }
        let origin_of = |h: usize| mesh.triangles[h / 3][h % 3];
        // Group half-edges by their undirected edge: sort (min, max, half-edge).
        let mut keys: Vec<(u32, u32, u32)> = (0..nh_faces)
            .map(|h| {
                let (a, b) = (origin_of(h), dest[h]);
                (a.min(b), a.max(b), h as u32)
            })
            .collect();
        keys.sort_unstable();
        let groups: Vec<&[(u32, u32, u32)]> =
            keys.chunk_by(|x, y| x.0 == y.0 && x.1 == y.1).collect();
        for g in &groups {
            if g.len() > 2 {
                return Err(TopologyError::NonManifoldEdge {
                    a: g[0].0,
                    b: g[0].1,
                    faces: g.iter().map(|x| x.2 / 3).collect(),
                });
            }
        }
        for g in &groups {
            if g.len() == 2 && origin_of(g[0].2 as usize) == origin_of(g[1].2 as usize) {
                let h = g[0].2 as usize;
                return Err(TopologyError::InconsistentOrientation {
                    a: origin_of(h),
                    b: dest[h],
                    f1: g[0].2 / 3,
                    f2: g[1].2 / 3,
                });
            }
        }
        let mut twin = vec![NONE; nh_faces];
        let mut edge = vec![NONE; nh_faces];
        let mut edge_he = Vec::with_capacity(groups.len());
        for (e, g) in groups.iter().enumerate() {
            let h0 = g[0].2;
            edge_he.push(h0);
            edge[h0 as usize] = e as u32;
            if g.len() == 2 {
                let h1 = g[1].2;
                edge[h1 as usize] = e as u32;
                twin[h0 as usize] = h1;
                twin[h1 as usize] = h0;
            } else {
                // A boundary half-edge running the other way.
                let b = dest.len() as u32;
                dest.push(origin_of(h0 as usize));
                twin[h0 as usize] = b;
                twin.push(h0);
                edge.push(e as u32);
                next.push(NONE);
                prev.push(NONE);
            }
        }
        let nh = dest.len();
        let origin = |h: usize| dest[twin[h] as usize];
        // Outgoing boundary half-edges per vertex (at most one for a manifold vertex).
        let mut boundary_out = vec![NONE; nv];
        let mut boundary_out_count = vec![0u32; nv];
        for b in nh_faces..nh {
            let v = origin(b) as usize;
            boundary_out[v] = b as u32;
            boundary_out_count[v] += 1;
        }
        // Fans: walk every vertex's corners. Corners per vertex in a compressed list.
        let corners =
            Csr::<u32>::from_pairs(nv, (0..nh_faces).map(|h| (origin_of(h) as usize, h as u32)));
        let mut visited = vec![false; nh_faces];
        let mut vertex_he = vec![NONE; nv];
        for v in 0..nv {
            let mine = corners.row(v);
            if mine.is_empty() {
                continue;
            }
            let mut fans = 0usize;
            for &h0 in mine {
                if visited[h0 as usize] {
                    continue;
                }
                fans += 1;
                // Rotate clockwise (towards the previous face) to the start of this fan.
                let mut start = h0;
                loop {
                    let back = next[twin[start as usize] as usize];
                    // twin(h) is the incoming half-edge of the face on the other side of h.
                    if twin[start as usize] as usize >= nh_faces || back == h0 {
                        break;
                    }
                    start = back;
                }
                // Rotate counter-clockwise from the start, marking the fan's corners.
                let mut h = start;
                loop {
                    visited[h as usize] = true;
                    let t = twin[prev[h as usize] as usize];
                    if t as usize >= nh_faces || t == start {
                        break;
                    }
                    h = t;
                }
            }
            if fans > 1 || boundary_out_count[v] > 1 {
                return Err(TopologyError::NonManifoldVertex {
                    vertex: v as u32,
                    fans: fans.max(boundary_out_count[v] as usize),
                });
            }
            vertex_he[v] = if boundary_out[v] != NONE {
                boundary_out[v]
            } else {
                mine[0]
            };
        }
        // Boundary cycles: the boundary half-edge b: x → y is followed by the one leaving y.
        for b in nh_faces..nh {
            let y = dest[b] as usize;
            let nb = boundary_out[y];
            next[b] = nb;
            prev[nb as usize] = b as u32;
        }
        // Loops as face half-edges in order (interior on the left): the reverse of the
        // boundary cycles.
        let mut loops = Vec::new();
        let mut seen = vec![false; nh - nh_faces];
        for b0 in nh_faces..nh {
            if seen[b0 - nh_faces] {
                continue;
            }
            let mut lp = Vec::new();
            let mut b = b0;
            loop {
                seen[b - nh_faces] = true;
                lp.push(twin[b]);
                b = prev[b] as usize;
                if b == b0 {
                    break;
                }
            }
            loops.push(lp);
        }
        // Components by flood fill over faces.
        let mut face_component = vec![NONE; nf];
        let mut components = Vec::new();
        let mut stack = Vec::new();
        for f0 in 0..nf {
            if face_component[f0] != NONE {
                continue;
            }
            let c = components.len() as u32;
            face_component[f0] = c;
            stack.push(f0);
            while let Some(f) = stack.pop() {
                for k in 0..3 {
                    let t = twin[3 * f + k] as usize;
                    if t < nh_faces && face_component[t / 3] == NONE {
                        face_component[t / 3] = c;
                        stack.push(t / 3);
                    }
                }
            }
            components.push(Component {
                faces: 0,
                edges: 0,
                vertices: 0,
                boundary_loops: 0,
                euler_characteristic: 0,
                genus: 0,
            });
        }
        for f in 0..nf {
            components[face_component[f] as usize].faces += 1;
        }
        for &h in &edge_he {
            components[face_component[h as usize / 3] as usize].edges += 1;
        }
        for v in 0..nv {
            if let Some(&h) = corners.row(v).first() {
                let h = h as usize;
                components[face_component[h / 3] as usize].vertices += 1;
            }
        }
        for lp in &loops {
            components[face_component[lp[0] as usize / 3] as usize].boundary_loops += 1;
        }
        for c in &mut components {
            c.euler_characteristic = c.vertices as i64 - c.edges as i64 + c.faces as i64;
            c.genus = (2 - c.boundary_loops as i64 - c.euler_characteristic) / 2;
        }
        Ok(HalfEdgeMesh {
            vertex_count: nv,
            face_count: nf,
            dest,
            twin,
            next,
            prev,
            edge,
            edge_he,
            vertex_he,
            loops,
            face_component,
            components,
        })
    }

    /// Vertices of the input mesh (including unused ones).
    pub fn vertex_count(&self) -> usize {
        self.vertex_count
    }

    pub fn face_count(&self) -> usize {
        self.face_count
    }

    pub fn edge_count(&self) -> usize {
        self.edge_he.len()
    }

    /// All half-edges, boundary ones included.
    pub fn half_edge_count(&self) -> usize {
        self.dest.len()
    }

    #[inline]
    pub fn dest(&self, h: u32) -> u32 {
        self.dest[h as usize]
    }

    #[inline]
    pub fn origin(&self, h: u32) -> u32 {
        self.dest[self.twin[h as usize] as usize]
    }

    #[inline]
    pub fn twin(&self, h: u32) -> u32 {
        self.twin[h as usize]
    }

    #[inline]
    pub fn next(&self, h: u32) -> u32 {
        self.next[h as usize]
    }

    #[inline]
    pub fn prev(&self, h: u32) -> u32 {
        self.prev[h as usize]
    }

    /// The undirected edge of `h`.
    #[inline]
    pub fn edge(&self, h: u32) -> u32 {
        self.edge[h as usize]
    }

    /// The face of `h`, `NONE` for a boundary half-edge.
    #[inline]
    pub fn face(&self, h: u32) -> u32 {
        if (h as usize) < 3 * self.face_count {
            h / 3
        } else {
            NONE
        }
    }

    #[inline]
    pub fn is_boundary_half_edge(&self, h: u32) -> bool {
        h as usize >= 3 * self.face_count
    }

    /// A half-edge of edge `e` that has a face.
    #[inline]
    pub fn edge_half_edge(&self, e: u32) -> u32 {
        self.edge_he[e as usize]
    }

    /// The two vertices of edge `e`.
    pub fn edge_vertices(&self, e: u32) -> (u32, u32) {
        let h = self.edge_he[e as usize];
        (self.origin(h), self.dest(h))
    }

    pub fn is_boundary_edge(&self, e: u32) -> bool {
        self.is_boundary_half_edge(self.twin(self.edge_he[e as usize]))
    }

    /// Whether `v` is used by some triangle.
    pub fn is_used(&self, v: u32) -> bool {
        self.vertex_he[v as usize] != NONE
    }

    pub fn is_boundary_vertex(&self, v: u32) -> bool {
        let h = self.vertex_he[v as usize];
        h != NONE && self.is_boundary_half_edge(h)
    }

    /// The outgoing half-edges of `v` counter-clockwise (for counter-clockwise triangles),
    /// starting with the boundary half-edge if `v` is on the boundary. Empty for unused
    /// vertices. Consecutive half-edges `h`, `h'` enclose the corner of `face(h)`.
    pub fn outgoing(&self, v: u32) -> Outgoing<'_> {
        let start = self.vertex_he[v as usize];
        Outgoing {
            mesh: self,
            start,
            current: start,
        }
    }

    /// Boundary loops as face half-edges with the interior on the left, in order
    /// (`dest(loop[k]) == origin(loop[k + 1])`).
    pub fn boundary_loops(&self) -> &[Vec<u32>] {
        &self.loops
    }

    pub fn components(&self) -> &[Component] {
        &self.components
    }

    /// The component of face `f`.
    pub fn face_component(&self, f: u32) -> u32 {
        self.face_component[f as usize]
    }

    /// V − E + F over the whole mesh (used vertices only).
    pub fn euler_characteristic(&self) -> i64 {
        self.components.iter().map(|c| c.euler_characteristic).sum()
    }
}

/// Iterator of [`HalfEdgeMesh::outgoing`].
pub struct Outgoing<'a> {
    mesh: &'a HalfEdgeMesh,
    start: u32,
    current: u32,
}

impl Iterator for Outgoing<'_> {
    type Item = u32;

    fn next(&mut self) -> Option<u32> {
        if self.current == NONE {
            return None;
        }
        let h = self.current;
        // The next outgoing half-edge counter-clockwise: the twin of the half-edge that
        // enters v in h's face (or, on a boundary half-edge, the one before it in its cycle).
        let n = self.mesh.twin(self.mesh.prev(h));
        self.current = if n == self.start { NONE } else { n };
        Some(h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::primitives::octahedron;
    use crate::math::PureMath;
    use glam::Vec3;

    fn torus(n: u32, m: u32) -> Mesh {
        crate::geom::primitives::torus(n, m, 0.7)
    }

    #[test]
    fn octahedron_is_a_closed_sphere() {
        let he = HalfEdgeMesh::new(&octahedron()).unwrap();
        assert_eq!(he.edge_count(), 12);
        assert_eq!(he.half_edge_count(), 24);
        assert!(he.boundary_loops().is_empty());
        assert_eq!(he.components().len(), 1);
        let c = he.components()[0];
        assert_eq!((c.vertices, c.edges, c.faces), (6, 12, 8));
        assert_eq!((c.euler_characteristic, c.genus), (2, 0));
        for h in 0..24 {
            assert_eq!(he.twin(he.twin(h)), h);
            assert_eq!(he.origin(he.twin(h)), he.dest(h));
            assert_eq!(he.next(he.prev(h)), h);
        }
        // Vertex 4 (the top) sees its four neighbours in counter-clockwise order.
        let ring: Vec<u32> = he.outgoing(4).map(|h| he.dest(h)).collect();
        assert_eq!(ring.len(), 4);
        let i = ring.iter().position(|&v| v == 0).unwrap();
        let rot: Vec<u32> = (0..4).map(|k| ring[(i + k) % 4]).collect();
        assert_eq!(rot, vec![0, 1, 2, 3]);
    }

    #[test]
    fn torus_has_genus_one_and_an_open_strip_has_two_loops() {
        let he = HalfEdgeMesh::new(&torus(8, 5)).unwrap();
        assert_eq!(he.components()[0].genus, 1);
        assert_eq!(he.components()[0].euler_characteristic, 0);
        // Drop one ring of quads: an annulus (open cylinder), genus 0 with two loops.
        let m = torus(8, 5);
        let tris: Vec<[u32; 3]> = m.triangles[10..].to_vec();
        let he = HalfEdgeMesh::new(&Mesh::new(m.positions.clone(), tris)).unwrap();
        let c = he.components()[0];
        assert_eq!(
            (c.boundary_loops, c.genus, c.euler_characteristic),
            (2, 0, 0)
        );
        for lp in he.boundary_loops() {
            assert_eq!(lp.len(), 5);
            for k in 0..lp.len() {
                let (h, h2) = (lp[k], lp[(k + 1) % lp.len()]);
                assert!(he.is_boundary_half_edge(he.twin(h)));
                assert_eq!(he.dest(h), he.origin(h2));
            }
        }
        // The boundary vertex's ring starts with its boundary half-edge.
        let v = he.origin(he.boundary_loops()[0][0]);
        let first = he.outgoing(v).next().unwrap();
        assert!(he.is_boundary_half_edge(first));
        assert_eq!(he.outgoing(v).count(), 4);
    }

    #[test]
    fn unused_vertices_are_ignored_and_components_counted() {
        let mut m = octahedron();
        m.positions.push(Vec3::splat(9.0)); // unused vertex 6
        let base = m.positions.len() as u32;
        m.positions.extend([
            Vec3::new(5.0, 0.0, 0.0),
            Vec3::new(6.0, 0.0, 0.0),
            Vec3::new(5.0, 1.0, 0.0),
        ]);
        m.triangles.push([base, base + 1, base + 2]);
        let m = Mesh::new(m.positions.clone(), m.triangles.clone());
        let he = HalfEdgeMesh::new(&m).unwrap();
        assert!(!he.is_used(6));
        assert_eq!(he.outgoing(6).count(), 0);
        assert_eq!(he.components().len(), 2);
        let c = he.components()[1];
        assert_eq!(
            (c.vertices, c.edges, c.faces, c.boundary_loops),
            (3, 3, 1, 1)
        );
        assert_eq!((c.euler_characteristic, c.genus), (1, 0));
        assert_eq!(he.euler_characteristic(), 3);
    }

    #[test]
    fn three_triangles_on_one_edge_name_the_edge() {
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z];
        let t = vec![[0, 1, 2], [1, 0, 3], [0, 1, 4]];
        let err = HalfEdgeMesh::new(&Mesh::new(p, t)).unwrap_err();
        assert_eq!(
            err,
            TopologyError::NonManifoldEdge {
                a: 0,
                b: 1,
                faces: vec![0, 1, 2]
            }
        );
        assert!(err.to_string().contains("vertices 0 and 1"), "{err}");
    }

    #[test]
    fn a_flipped_neighbour_is_named() {
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::Y, -Vec3::Y];
        let t = vec![[0, 1, 2], [0, 1, 3]];
        let err = HalfEdgeMesh::new(&Mesh::new(p, t)).unwrap_err();
        assert_eq!(
            err,
            TopologyError::InconsistentOrientation {
                a: 0,
                b: 1,
                f1: 0,
                f2: 1
            }
        );
    }

    #[test]
    fn two_fans_at_one_vertex_are_named() {
        // Two triangles touching only at vertex 0 (a bow tie).
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::Y, -Vec3::X, -Vec3::Y];
        let t = vec![[0, 1, 2], [0, 3, 4]];
        let err = HalfEdgeMesh::new(&Mesh::new(p, t)).unwrap_err();
        assert_eq!(err, TopologyError::NonManifoldVertex { vertex: 0, fans: 2 });
        // Two closed cones sharing their apex: each fan is a full disk.
        let mut p = vec![Vec3::ZERO];
        let mut t = Vec::new();
        for (s, z) in [(1u32, 1.0f32), (4, -1.0)] {
            for k in 0..3 {
                let a = k as f32 * 2.1;
                p.push(Vec3::new(a.cos_pure(), a.sin_pure(), z));
            }
            t.push([0, s, s + 1]);
            t.push([0, s + 1, s + 2]);
            t.push([0, s + 2, s]);
            t.push([s, s + 2, s + 1]);
        }
        let err = HalfEdgeMesh::new(&Mesh::new(p, t)).unwrap_err();
        assert_eq!(err, TopologyError::NonManifoldVertex { vertex: 0, fans: 2 });
    }

    #[test]
    fn out_of_range_and_degenerate_faces_are_named() {
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::Y];
        let err = HalfEdgeMesh::new(&Mesh::new(p.clone(), vec![[0, 1, 7]])).unwrap_err();
        assert_eq!(
            err,
            TopologyError::VertexOutOfRange {
                face: 0,
                vertex: 7,
                count: 3
            }
        );
        let err = HalfEdgeMesh::new(&Mesh::new(p.clone(), vec![[0, 1, 2], [1, 1, 2]])).unwrap_err();
        assert_eq!(err, TopologyError::DegenerateFace { face: 1, vertex: 1 });
        assert_eq!(
            HalfEdgeMesh::new(&Mesh::new(p, vec![])).unwrap_err(),
            TopologyError::Empty
        );
    }
}
