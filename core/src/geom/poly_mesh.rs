//! Polygon meshes with faces of any size, in compressed-row form.
//!
//! √2 subdivision (Bangay & Morkel 2006, §3.2.1) turns every mesh into quadrilaterals, with
//! triangles where the refinement meets a boundary or an unrefined region, so the hierarchy
//! cannot live in the triangle-only [`Mesh`]. Faces are stored as one flat list of vertex ids
//! (`face_vertices`) cut up by `face_start`, which keeps a million-face level to two arrays.
//!
//! Edges are the sides of the faces; a quad's diagonals are not edges. Derived quantities are
//! computed on request and not cached: a `PolyMesh` is a value that the subdivision builds and
//! hands on, and keeping it plain lets it derive `PartialEq` and `Default`.

use super::Mesh;
use crate::graph::Csr;
use glam::{DVec3, Vec3};

/// A polygon mesh: face `f` is `face_vertices[face_start[f]..face_start[f + 1]]`, its corners
/// in counter-clockwise order seen from outside. Vertices no face uses are allowed (they keep a
/// file's vertex numbering) and ignored by every derived quantity.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PolyMesh {
    pub positions: Vec<Vec3>,
    /// One more entry than there are faces; starts at 0.
    pub face_start: Vec<u32>,
    pub face_vertices: Vec<u32>,
}

/// Vertex-to-vertex adjacency in compressed-row form: the neighbours of `v` are
/// `neighbours[start[v]..start[v + 1]]`, sorted ascending, without duplicates.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Adjacency {
    pub start: Vec<u32>,
    pub neighbours: Vec<u32>,
}

impl Adjacency {
    pub fn of(&self, v: usize) -> &[u32] {
        &self.neighbours[self.start[v] as usize..self.start[v + 1] as usize]
    }
}

impl PolyMesh {
    /// The triangle mesh as a polygon mesh. Every vertex is kept, referenced or not, so vertex
    /// ids stay the file's ids.
    pub fn from_mesh(m: &Mesh) -> PolyMesh {
        PolyMesh {
            positions: m.positions.clone(),
            face_start: (0..=m.triangles.len() as u32).map(|f| 3 * f).collect(),
            face_vertices: m.triangles.iter().flatten().copied().collect(),
        }
    }

    pub fn from_faces(positions: Vec<Vec3>, faces: &[Vec<u32>]) -> PolyMesh {
        let mut face_start = Vec::with_capacity(faces.len() + 1);
        face_start.push(0);
        let mut face_vertices = Vec::new();
        for f in faces {
            face_vertices.extend_from_slice(f);
            face_start.push(face_vertices.len() as u32);
        }
        PolyMesh {
            positions,
            face_start,
            face_vertices,
        }
    }

    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    pub fn face_count(&self) -> usize {
        self.face_start.len().saturating_sub(1)
    }

    pub fn face(&self, f: usize) -> &[u32] {
        &self.face_vertices[self.face_start[f] as usize..self.face_start[f + 1] as usize]
    }

    /// Newell's normal of a face: twice its vector area. For a planar polygon its length is
    /// twice the area; for a skew quad (√2 subdivision makes many) it is the area of its
    /// projection on the best-fitting plane, the usual meaning of a skew polygon's area.
    /// Corners are taken relative to the first, so a face far from the origin loses no precision.
    pub fn face_normal_unnormalized(&self, f: usize) -> Vec3 {
        let face = self.face(f);
        let origin = self.positions[face[0] as usize].as_dvec3();
        let mut n = DVec3::ZERO;
        for k in 1..face.len().saturating_sub(1) {
            let b = self.positions[face[k] as usize].as_dvec3() - origin;
            let c = self.positions[face[k + 1] as usize].as_dvec3() - origin;
            n += b.cross(c);
        }
        n.as_vec3()
    }

    /// Polygon area: half the length of the Newell normal.
    pub fn face_area(&self, f: usize) -> f32 {
        0.5 * self.face_normal_unnormalized(f).length()
    }

    /// Mean of the face's corners (the √2 face point), summed in corner order in f32 so that
    /// callers who recompute it get the same bits.
    pub fn face_centroid(&self, f: usize) -> Vec3 {
        let face = self.face(f);
        let sum = face
            .iter()
            .fold(Vec3::ZERO, |s, &v| s + self.positions[v as usize]);
        sum / face.len() as f32
    }

    /// The faces as triangles with the same vertex ids: a quad is split along its shorter
    /// diagonal (the flatter split, and the one that keeps slivers out of the diamond-shaped
    /// quads √2 subdivision makes), larger faces are fanned from their first corner.
    /// Orientation is kept.
    pub fn to_triangles(&self) -> Mesh {
        let mut triangles = Vec::with_capacity(self.face_vertices.len());
        for f in 0..self.face_count() {
            let face = self.face(f);
            if face.len() == 4 {
                let p = |k: usize| self.positions[face[k] as usize];
                let [a, b, c, d] = [face[0], face[1], face[2], face[3]];
                if p(0).distance_squared(p(2)) <= p(1).distance_squared(p(3)) {
                    triangles.push([a, b, c]);
                    triangles.push([a, c, d]);
                } else {
                    triangles.push([b, c, d]);
                    triangles.push([b, d, a]);
                }
            } else {
                for k in 1..face.len().saturating_sub(1) {
                    triangles.push([face[0], face[k], face[k + 1]]);
                }
            }
        }
        Mesh::new(self.positions.clone(), triangles)
    }

    /// The directed edges (corner to next corner) of every face, in face order.
    fn directed_edges(&self) -> impl Iterator<Item = (u32, u32)> + Clone + '_ {
        (0..self.face_count()).flat_map(move |f| {
            let face = self.face(f);
            (0..face.len()).map(move |k| (face[k], face[(k + 1) % face.len()]))
        })
    }

    /// Vertices joined by a face side (not by a quad's diagonal).
    pub fn vertex_neighbours(&self) -> Adjacency {
        // Counting sort by vertex, then a short sort and dedup per vertex: linear work.
        let n = self.positions.len();
        let sides = self.directed_edges().flat_map(|(a, b)| {
            (a != b)
                .then_some([(a as usize, b), (b as usize, a)])
                .into_iter()
                .flatten()
        });
        let mut raw = Csr::<u32>::from_pairs(n, sides);
        let mut out = Adjacency {
            start: vec![0; n + 1],
            neighbours: Vec::with_capacity(raw.items.len() / 2),
        };
        for v in 0..n {
            let list = raw.row_mut(v);
            list.sort_unstable();
            let mut last = None;
            for &w in list.iter() {
                if last != Some(w) {
                    out.neighbours.push(w);
                    last = Some(w);
                }
            }
            out.start[v + 1] = out.neighbours.len() as u32;
        }
        out
    }

    /// Unit vertex normals: the sum of the adjacent faces' Newell normals (so weighted by
    /// area), normalized; zero for vertices no face uses.
    pub fn vertex_normals(&self) -> Vec<Vec3> {
        let mut n = vec![Vec3::ZERO; self.positions.len()];
        for f in 0..self.face_count() {
            let fn_ = self.face_normal_unnormalized(f);
            for &v in self.face(f) {
                n[v as usize] += fn_;
            }
        }
        n.iter().map(|x| x.normalize_or_zero()).collect()
    }

    /// Per vertex, the mean length of the distinct edges at it (0 for unreferenced vertices).
    pub fn mean_edge_lengths(&self) -> Vec<f32> {
        let adj = self.vertex_neighbours();
        (0..self.positions.len())
            .map(|v| {
                let nb = adj.of(v);
                if nb.is_empty() {
                    return 0.0;
                }
                let p = self.positions[v];
                let sum: f64 = nb
                    .iter()
                    .map(|&w| p.distance(self.positions[w as usize]) as f64)
                    .sum();
                (sum / nb.len() as f64) as f32
            })
            .collect()
    }

    /// Mean length over all distinct edges (each counted once, however many faces use it).
    pub fn mean_edge_length(&self) -> f32 {
        let adj = self.vertex_neighbours();
        let (mut sum, mut count) = (0.0f64, 0usize);
        for v in 0..self.positions.len() {
            for &w in adj.of(v).iter().filter(|&&w| w as usize > v) {
                sum += self.positions[v].distance(self.positions[w as usize]) as f64;
                count += 1;
            }
        }
        if count == 0 {
            0.0
        } else {
            (sum / count as f64) as f32
        }
    }

    /// The undirected edges as `(min, max)` keys with how many face sides use each, sorted.
    fn edge_uses(&self) -> Vec<(u64, u32)> {
        let mut keys: Vec<u64> = self
            .directed_edges()
            .map(|(a, b)| undirected_key(a, b))
            .collect();
        keys.sort_unstable();
        let mut out: Vec<(u64, u32)> = Vec::new();
        for k in keys {
            match out.last_mut() {
                Some((last, n)) if *last == k => *n += 1,
                _ => out.push((k, 1)),
            }
        }
        out
    }

    /// V − E + F with V counting only the vertices some face uses: 2 − 2g − b for a connected
    /// orientable surface of genus g with b boundary loops.
    pub fn euler_characteristic(&self) -> i64 {
        let mut used = vec![false; self.positions.len()];
        for &v in &self.face_vertices {
            used[v as usize] = true;
        }
        let v = used.iter().filter(|&&u| u).count() as i64;
        v - self.edge_uses().len() as i64 + self.face_count() as i64
    }

    /// Edges used by exactly one face.
    pub fn boundary_edge_count(&self) -> usize {
        self.edge_uses().iter().filter(|&&(_, n)| n == 1).count()
    }

    /// Whether no directed edge occurs twice and every edge two faces share is used once in
    /// each direction (so an edge three faces share fails too).
    pub fn is_consistently_oriented(&self) -> bool {
        let mut directed: Vec<u64> = self
            .directed_edges()
            .map(|(a, b)| ((a as u64) << 32) | b as u64)
            .collect();
        directed.sort_unstable();
        // With only two directions, an edge used twice without a repeated direction is used
        // once each way, and an edge used three times must repeat one.
        directed.windows(2).all(|w| w[0] != w[1])
    }
}

fn undirected_key(a: u32, b: u32) -> u64 {
    ((a.min(b) as u64) << 32) | a.max(b) as u64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::primitives::{cube, grid, octahedron, quad_grid, torus};

    #[test]
    fn from_mesh_keeps_every_vertex_and_the_triangles() {
        let mut m = octahedron();
        m.positions.push(Vec3::splat(9.0)); // unreferenced, id 6
        let p = PolyMesh::from_mesh(&m);
        assert_eq!(p.vertex_count(), 7);
        assert_eq!(p.face_count(), 8);
        for f in 0..8 {
            assert_eq!(p.face(f), &m.triangles[f]);
        }
        assert_eq!(p.face_start.len(), 9);
        assert_eq!(p.face_start[0], 0);
        // The unreferenced vertex counts for nothing.
        assert_eq!(p.euler_characteristic(), 2);
        assert_eq!(p.vertex_normals()[6], Vec3::ZERO);
        assert_eq!(p.mean_edge_lengths()[6], 0.0);
        assert!(p.vertex_neighbours().of(6).is_empty());
    }

    #[test]
    fn area_and_centroid_of_a_quad_a_triangle_and_a_pentagon() {
        let p = PolyMesh::from_faces(
            vec![
                Vec3::new(10.0, 10.0, 5.0),
                Vec3::new(12.0, 10.0, 5.0),
                Vec3::new(12.0, 13.0, 5.0),
                Vec3::new(10.0, 13.0, 5.0),
                Vec3::new(11.0, 14.0, 5.0),
            ],
            &[vec![0, 1, 2, 3], vec![3, 2, 4], vec![0, 1, 2, 4, 3]],
        );
        assert!((p.face_area(0) - 6.0).abs() < 1e-6);
        assert!((p.face_area(1) - 1.0).abs() < 1e-6);
        assert!((p.face_area(2) - 7.0).abs() < 1e-6);
        assert_eq!(p.face_centroid(0), Vec3::new(11.0, 11.5, 5.0));
        assert_eq!(p.face_normal_unnormalized(0), Vec3::new(0.0, 0.0, 12.0));
        // A skew quad's area is that of its projection along the Newell normal.
        let skew = PolyMesh::from_faces(
            vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 1.0),
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::new(0.0, 1.0, 1.0),
            ],
            &[vec![0, 1, 2, 3]],
        );
        assert!((skew.face_area(0) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn quads_are_split_along_the_shorter_diagonal() {
        // 0-2 is long (a kite stretched along x), 1-3 short.
        let p = PolyMesh::from_faces(
            vec![
                Vec3::new(-3.0, 0.0, 0.0),
                Vec3::new(0.0, -1.0, 0.0),
                Vec3::new(3.0, 0.0, 0.0),
                Vec3::new(0.0, 1.0, 0.0),
            ],
            &[vec![0, 1, 2, 3]],
        );
        let t = p.to_triangles();
        assert_eq!(t.triangles, vec![[1, 2, 3], [1, 3, 0]]);
        let mut q = p.clone();
        q.positions[0].x = -0.5;
        q.positions[2].x = 0.5;
        assert_eq!(q.to_triangles().triangles, vec![[0, 1, 2], [0, 2, 3]]);
        // Orientation is kept: both triangles face +z like the quad.
        for f in 0..2 {
            assert!(t.face_normal_unnormalized(f).z > 0.0);
        }
        // A pentagon is fanned from its first corner.
        let pent = PolyMesh::from_faces(vec![Vec3::ZERO; 5], &[vec![4, 3, 2, 1, 0]]);
        assert_eq!(
            pent.to_triangles().triangles,
            vec![[4, 3, 2], [4, 2, 1], [4, 1, 0]]
        );
    }

    #[test]
    fn neighbours_are_face_sides_not_quad_diagonals() {
        let g = quad_grid(2); // 3×3 vertices, centre 4
        let adj = g.vertex_neighbours();
        assert_eq!(adj.of(4), &[1, 3, 5, 7]);
        assert_eq!(adj.of(0), &[1, 3]);
        assert_eq!(adj.of(2), &[1, 5]);
        assert_eq!(adj.start.len(), 10);
        // The triangulated grid has the diagonals as edges.
        let t = PolyMesh::from_mesh(&grid(3, 1.0));
        assert_eq!(t.vertex_neighbours().of(4), &[0, 1, 3, 5, 7, 8]);
    }

    #[test]
    fn edge_lengths_count_each_edge_once() {
        let g = quad_grid(2);
        assert_eq!(g.mean_edge_length(), 1.0);
        assert_eq!(g.mean_edge_lengths(), vec![1.0; 9]);
        // Unit right triangle: edges 1, 1, √2.
        let t = PolyMesh::from_faces(vec![Vec3::ZERO, Vec3::X, Vec3::Y], &[vec![0, 1, 2]]);
        let want = (2.0 + 2f32.sqrt()) / 3.0;
        assert!((t.mean_edge_length() - want).abs() < 1e-6);
        let per = t.mean_edge_lengths();
        assert_eq!(per[0], 1.0);
        assert!((per[1] - (1.0 + 2f32.sqrt()) / 2.0).abs() < 1e-6);
    }

    #[test]
    fn normals_point_outwards_on_closed_meshes() {
        for m in [cube(), octahedron()] {
            let p = PolyMesh::from_mesh(&m);
            let (lo, hi) = m.bounds();
            let centre = (lo + hi) / 2.0;
            for (v, n) in p.vertex_normals().iter().enumerate() {
                assert!((n.length() - 1.0).abs() < 1e-5);
                assert!(n.dot(p.positions[v] - centre) > 0.0);
            }
        }
    }

    #[test]
    fn topology_counts_of_closed_open_and_broken_meshes() {
        let cube = PolyMesh::from_mesh(&cube());
        assert_eq!(cube.euler_characteristic(), 2);
        assert_eq!(cube.boundary_edge_count(), 0);
        assert!(cube.is_consistently_oriented());
        let torus = PolyMesh::from_mesh(&torus(8, 6, 0.5));
        assert_eq!(torus.euler_characteristic(), 0);
        assert_eq!(torus.boundary_edge_count(), 0);
        assert!(torus.is_consistently_oriented());
        // An n×n quad grid: 4n boundary edges, a disk.
        let g = quad_grid(3);
        assert_eq!(g.boundary_edge_count(), 12);
        assert_eq!(g.euler_characteristic(), 1);
        assert!(g.is_consistently_oriented());
        // One flipped triangle breaks the orientation but not the counts.
        let mut flipped = cube.clone();
        flipped.face_vertices.swap(0, 1);
        assert!(!flipped.is_consistently_oriented());
        assert_eq!(flipped.boundary_edge_count(), 0);
        // A third face on an edge (a fin): not a manifold, so not consistently oriented either.
        let fin = PolyMesh::from_faces(
            vec![Vec3::ZERO, Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z],
            &[vec![0, 1, 2], vec![1, 0, 3], vec![0, 1, 4]],
        );
        assert!(!fin.is_consistently_oriented());
    }
}
