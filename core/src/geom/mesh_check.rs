//! One check of a mesh's health for every method: what is odd about it, counted, so that a
//! method that cannot work with it refuses it (the geometry-image method needs one manifold
//! piece, see [`super::half_edge`]) and a method that can says what it found rather than
//! accepting it silently (jump maps and graph matching colour what they are given).

use super::Mesh;

/// What is odd about a mesh. All zero for a clean manifold mesh.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MeshHealth {
    /// Triangles with a repeated corner, or of zero area.
    pub degenerate_faces: usize,
    /// Triangles with the same three corners as an earlier one (in any order).
    pub duplicate_faces: usize,
    /// Edges used by more than two triangles.
    pub non_manifold_edges: usize,
    /// Vertices no triangle uses.
    pub unreferenced_vertices: usize,
    /// Edges used by exactly one triangle: 0 for a closed mesh. Not a defect (open meshes are
    /// fine for most methods), so [`MeshHealth::is_clean`] ignores it.
    pub boundary_edges: usize,
}

impl MeshHealth {
    /// No defect and no unreferenced vertex (the mesh may be open).
    pub fn is_clean(&self) -> bool {
        !self.has_defects() && self.unreferenced_vertices == 0
    }

    /// Clean and closed: every edge has exactly two triangles. (A vertex where two fans of
    /// triangles meet is not counted here; [`super::half_edge::HalfEdgeMesh::new`] refuses it.)
    pub fn is_closed_manifold(&self) -> bool {
        self.is_clean() && self.boundary_edges == 0
    }

    /// Whether anything beyond unreferenced vertices (which are allowed: they keep a file's
    /// vertex numbering) was found.
    pub fn has_defects(&self) -> bool {
        self.degenerate_faces + self.duplicate_faces + self.non_manifold_edges > 0
    }

    /// The warning a method that works on such a mesh gives (`None` when it has no defects).
    pub fn warning(&self, method: &str) -> Option<String> {
        self.has_defects().then(|| {
            format!(
                "inputs.mesh has {}: {method} textures it as it is, but expect flaws there (geometry_images would refuse it)",
                self.summary()
            )
        })
    }

    /// One line naming what was found, e.g. "2 degenerate triangles, 1 duplicate triangle".
    pub fn summary(&self) -> String {
        [
            (
                self.degenerate_faces,
                "degenerate triangle",
                "degenerate triangles",
            ),
            (
                self.duplicate_faces,
                "duplicate triangle",
                "duplicate triangles",
            ),
            (
                self.non_manifold_edges,
                "non-manifold edge",
                "non-manifold edges",
            ),
            (
                self.unreferenced_vertices,
                "unreferenced vertex",
                "unreferenced vertices",
            ),
            (self.boundary_edges, "boundary edge", "boundary edges"),
        ]
        .iter()
        .filter(|(n, _, _)| *n > 0)
        .map(|(n, one, many)| format!("{n} {}", if *n == 1 { one } else { many }))
        .collect::<Vec<_>>()
        .join(", ")
    }
}

/// Counts what is odd about `mesh` (see [`MeshHealth`]). Faces and edges are counted by
/// sorting their keys (in parallel; counts do not depend on the order) rather than hashing:
/// on a 1.4M-triangle mesh this is several times faster.
pub fn mesh_health(mesh: &Mesh) -> MeshHealth {
    use rayon::prelude::*;
    let mut h = MeshHealth::default();
    let mut used = vec![false; mesh.vertex_count()];
    let mut faces: Vec<[u32; 3]> = Vec::with_capacity(mesh.triangles.len());
    let mut edges: Vec<u64> = Vec::with_capacity(mesh.triangles.len() * 3);
    for (f, t) in mesh.triangles.iter().enumerate() {
        for &v in t {
            if let Some(u) = used.get_mut(v as usize) {
                *u = true;
            }
        }
        if t[0] == t[1]
            || t[1] == t[2]
            || t[0] == t[2]
            || mesh.face_normal_unnormalized(f) == glam::Vec3::ZERO
        {
            h.degenerate_faces += 1;
        }
        let mut key = *t;
        key.sort_unstable();
        faces.push(key);
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if a != b {
                edges.push(((a.min(b) as u64) << 32) | a.max(b) as u64);
            }
        }
    }
    faces.par_sort_unstable();
    h.duplicate_faces = faces.windows(2).filter(|w| w[0] == w[1]).count();
    edges.par_sort_unstable();
    for run in edges.chunk_by(|a, b| a == b) {
        match run.len() {
            1 => h.boundary_edges += 1,
            2 => {}
            _ => h.non_manifold_edges += 1,
        }
    }
    h.unreferenced_vertices = used.iter().filter(|&&u| !u).count();
    h
}

/// Logs the warning a method gives for a mesh with defects it textures as they are.
pub fn warn_if_unhealthy(mesh: &crate::geom::Mesh, method: &str) {
    if let Some(w) = mesh_health(mesh).warning(method) {
        tracing::warn!("{w}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn a_clean_mesh_is_clean_and_each_oddity_is_counted() {
        let closed = mesh_health(&crate::geom::primitives::octahedron());
        assert!(
            closed.is_clean() && closed.is_closed_manifold(),
            "{closed:?}"
        );
        let open = mesh_health(&crate::geom::primitives::grid(3, 1.0));
        assert!(open.is_clean() && !open.is_closed_manifold());
        assert_eq!(open.boundary_edges, 8, "a 3 × 3 grid has 8 border edges");
        let p = vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::Z,
            Vec3::ONE,
            Vec3::new(2.0, 0.0, 0.0),
        ];
        let m = Mesh::new(
            p,
            vec![
                [0, 1, 2],
                [2, 1, 0], // duplicate (other orientation)
                [0, 1, 3],
                [0, 1, 0], // repeated corner
                [0, 1, 5], // zero area: all on the x axis
            ],
        );
        let h = mesh_health(&m);
        assert_eq!(h.degenerate_faces, 2);
        assert_eq!(h.duplicate_faces, 1);
        assert_eq!(h.non_manifold_edges, 1, "edge 0-1 has five triangles");
        assert_eq!(h.unreferenced_vertices, 1, "vertex 4");
        // 1-3, 3-0, 1-5 and 5-0 have one triangle each.
        assert_eq!(h.boundary_edges, 4);
        assert_eq!(
            h.summary(),
            "2 degenerate triangles, 1 duplicate triangle, 1 non-manifold edge, 1 unreferenced vertex, 4 boundary edges"
        );
    }
}
