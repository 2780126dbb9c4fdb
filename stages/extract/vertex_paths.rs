//! Curves in space snapped onto a mesh as vertex paths: the common curve type of
//! feature-aligned texturing (Xu et al., "Feature-Aligned Shape Texturing", §4.1: "each
//! [curve] represented as a sequence of vertices connected by edges") made from curves that
//! are not vertex paths yet: crest lines, whose points lie inside mesh edges
//! ([`super::crest_lines`]), and curves a user types into a config as 3D points.
//!
//! Each point goes to its nearest mesh vertex (a k-d tree over the vertices that triangles
//! use; ties go to the lower vertex id); consecutive distinct vertices are joined by the
//! shortest edge path between them (Dijkstra over edge lengths, stopped as soon as the target
//! is settled, ties broken by vertex id so the path does not depend on anything but the
//! mesh); consecutive repeats collapse. The paper does not say how its crest lines became
//! vertex sequences; nearest vertex plus shortest path is the simplest snapping that keeps
//! the path within about one edge of the curve wherever the curve's points are at most an
//! edge or so apart.

use super::crease_lines::Polyline;
use crate::geom::Mesh;
use crate::graph::Dijkstra;
use crate::image::knn::KdTree;
use glam::Vec3;

/// Why a curve could not be snapped onto a mesh.
#[derive(Debug, thiserror::Error)]
pub enum SnapError {
    /// A point farther than `max_distance` from every vertex.
    #[error(
        "curve point {point} at {position} is {distance} from the mesh's nearest vertex \
         ({nearest}), more than the allowed snapping distance: the curve is not on this mesh \
         (check the curve's coordinates are in the mesh's object units, or raise the snapping \
         distance)"
    )]
    OffMesh {
        point: usize,
        position: Vec3,
        nearest: u32,
        distance: f32,
    },
    /// Consecutive points whose nearest vertices lie in different connected components.
    #[error(
        "curve points {} and {point} snap to vertices in different connected pieces of the \
         mesh, so no edge path joins them (split the curve where it jumps between pieces)",
        point.saturating_sub(1)
    )]
    Disconnected { point: usize },
    /// A point with a NaN or infinite coordinate.
    #[error("curve point {point} has a non-finite coordinate ({position})")]
    NonFinite { point: usize, position: Vec3 },
    /// A mesh without triangles has no vertices to snap to.
    #[error("the mesh has no triangles, so there is nothing to snap curve points to")]
    EmptyMesh,
}

/// Each point goes to its nearest vertex; consecutive distinct vertices are joined by the
/// shortest edge path (Dijkstra over edge lengths, ties broken by vertex id so it is
/// deterministic); repeated vertices collapse. `max_distance` in object units (None: no
/// check). For a closed polyline the last point joins the first.
///
/// A closed curve whose path has fewer than three distinct vertices comes back open (a loop
/// needs three). No points give an empty polyline.
pub fn snap_to_vertex_path(
    mesh: &Mesh,
    points: &[Vec3],
    closed: bool,
    max_distance: Option<f32>,
) -> Result<Polyline, SnapError> {
    if points.is_empty() {
        return Ok(Polyline {
            vertices: Vec::new(),
            closed: false,
        });
    }
    let mut s = Snapper::new(mesh)?;
    s.snap(points, closed, max_distance)
}

/// Nearest-vertex lookups and local shortest paths on one mesh, reused across many curves
/// (crest lines are snapped by the hundred): the tree is built once and Dijkstra's arrays
/// are reset only where a search touched them.
pub(crate) struct Snapper<'a> {
    mesh: &'a Mesh,
    tree: KdTree,
    /// Tree index -> vertex id (the tree holds only vertices that triangles use).
    ids: Vec<u32>,
    /// Shortest-path search, predecessors by vertex.
    search: Dijkstra,
    scratch: Vec<f32>,
}

impl<'a> Snapper<'a> {
    pub(crate) fn new(mesh: &'a Mesh) -> Result<Self, SnapError> {
        let n = mesh.positions.len();
        let mut used = vec![false; n];
        for t in &mesh.triangles {
            for &v in t {
                used[v as usize] = true;
            }
        }
        let ids: Vec<u32> = (0..n as u32).filter(|&v| used[v as usize]).collect();
        if ids.is_empty() {
            return Err(SnapError::EmptyMesh);
        }
        let coords: Vec<f32> = ids
            .iter()
            .flat_map(|&v| mesh.positions[v as usize].to_array())
            .collect();
        Ok(Snapper {
            mesh,
            tree: KdTree::build(&coords, 3),
            ids,
            search: Dijkstra::new(n, u32::MAX),
            scratch: Vec::new(),
        })
    }

    /// The nearest used vertex to `p` and its distance.
    fn nearest(&mut self, p: Vec3) -> (u32, f32) {
        let (i, d2) = self
            .tree
            .as_ref()
            .nearest1_approx(&p.to_array(), 0.0, &mut self.scratch)
            .expect("the tree is not empty");
        (self.ids[i as usize], d2.sqrt())
    }

    pub(crate) fn snap(
        &mut self,
        points: &[Vec3],
        closed: bool,
        max_distance: Option<f32>,
    ) -> Result<Polyline, SnapError> {
        let mut stops = Vec::with_capacity(points.len());
        for (i, &p) in points.iter().enumerate() {
            if !p.is_finite() {
                return Err(SnapError::NonFinite {
                    point: i,
                    position: p,
                });
            }
            let (v, d) = self.nearest(p);
            if let Some(max) = max_distance
                && d > max
            {
                return Err(SnapError::OffMesh {
                    point: i,
                    position: p,
                    nearest: v,
                    distance: d,
                });
            }
            stops.push(v);
        }
        let mut path = vec![stops[0]];
        for i in 1..stops.len() {
            let (from, to) = (*path.last().expect("non-empty"), stops[i]);
            if from != to {
                let leg = self
                    .shortest_path(from, to)
                    .ok_or(SnapError::Disconnected { point: i })?;
                path.extend_from_slice(&leg[1..]);
            }
        }
        if closed && path.len() > 1 {
            let (from, to) = (*path.last().expect("non-empty"), path[0]);
            if from != to {
                let leg = self
                    .shortest_path(from, to)
                    .ok_or(SnapError::Disconnected { point: 0 })?;
                path.extend_from_slice(&leg[1..]);
            }
            // The loop does not repeat its first vertex.
            path.pop();
        }
        let closed = closed && path.len() >= 3;
        Ok(Polyline {
            vertices: path,
            closed,
        })
    }

    /// The shortest edge path from `a` to `b` (both ends included), or None when `b` is not
    /// reachable. Stops when `b` is settled, so a short hop costs a few rings, not the mesh.
    fn shortest_path(&mut self, a: u32, b: u32) -> Option<Vec<u32>> {
        let adj = self.mesh.adjacency();
        let pos = &self.mesh.positions;
        let search = &mut self.search;
        search.reset();
        search.add_source(a);
        let found = search.run(&[b], |search, v, d| {
            let pv = pos[v as usize];
            for &w in adj.neighbors(v as usize) {
                // Equal distances keep the lower predecessor id: the path is a function of
                // the mesh alone.
                search.relax_lowest_pred(w, d + pv.distance(pos[w as usize]) as f64, v);
            }
        });
        found.then(|| search.path(a, b))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::primitives::grid;

    fn shares_edge(m: &Mesh, a: u32, b: u32) -> bool {
        m.adjacency().neighbors(a as usize).contains(&b)
    }

    fn assert_connected(m: &Mesh, l: &Polyline) {
        for w in l.vertices.windows(2) {
            assert!(shares_edge(m, w[0], w[1]), "{w:?} is not an edge");
        }
        if l.closed {
            let (f, last) = (l.vertices[0], *l.vertices.last().unwrap());
            assert!(shares_edge(m, last, f), "closing {last}-{f} is not an edge");
        }
    }

    fn nearest_brute(m: &Mesh, p: Vec3) -> u32 {
        (0..m.positions.len() as u32)
            .min_by(|&a, &b| {
                m.positions[a as usize]
                    .distance(p)
                    .total_cmp(&m.positions[b as usize].distance(p))
                    .then(a.cmp(&b))
            })
            .unwrap()
    }

    #[test]
    fn a_sparse_curve_becomes_a_connected_path_through_the_nearest_vertices() {
        let m = grid(20, 0.1);
        // Points far apart (several edges), slightly off the vertices and off the plane.
        let pts = [
            Vec3::new(0.02, 0.03, 0.01),
            Vec3::new(0.71, 0.18, -0.02),
            Vec3::new(1.22, 1.49, 0.0),
            Vec3::new(0.33, 1.81, 0.03),
        ];
        let l = snap_to_vertex_path(&m, &pts, false, Some(0.1)).unwrap();
        assert!(!l.closed);
        assert_connected(&m, &l);
        let mut at = 0;
        for &p in &pts {
            let v = nearest_brute(&m, p);
            let k = l.vertices[at..]
                .iter()
                .position(|&x| x == v)
                .unwrap_or_else(|| panic!("{v} (nearest to {p}) not on the path in order"));
            at += k;
        }
        assert_eq!(l.vertices[0], nearest_brute(&m, pts[0]));
        assert_eq!(*l.vertices.last().unwrap(), nearest_brute(&m, pts[3]));
        // Shortest: the first leg, from (0,0) to (7,2) in grid steps, whose diagonals run
        // (+1, +1), is 5 straight steps and 2 diagonal ones: 8 vertices.
        let leg = l
            .vertices
            .iter()
            .position(|&v| v == nearest_brute(&m, pts[1]))
            .unwrap();
        assert_eq!(leg + 1, 8, "{:?}", &l.vertices[..=leg]);
        // No vertex twice in a row.
        assert!(l.vertices.windows(2).all(|w| w[0] != w[1]));
    }

    #[test]
    fn a_closed_curve_joins_its_last_point_to_its_first() {
        let m = grid(20, 0.1);
        let pts = [
            Vec3::new(0.5, 0.5, 0.0),
            Vec3::new(1.3, 0.5, 0.0),
            Vec3::new(1.3, 1.3, 0.0),
            Vec3::new(0.5, 1.3, 0.0),
        ];
        let l = snap_to_vertex_path(&m, &pts, true, None).unwrap();
        assert!(l.closed);
        assert_connected(&m, &l);
        assert_ne!(l.vertices[0], *l.vertices.last().unwrap());
        let mut sorted = l.vertices.clone();
        sorted.sort();
        sorted.dedup();
        assert_eq!(sorted.len(), l.vertices.len(), "a vertex repeats: {l:?}");
        // The square's perimeter is 4 × 8 edges.
        assert_eq!(l.vertices.len(), 32);
        let open = snap_to_vertex_path(&m, &pts, false, None).unwrap();
        assert!(!open.closed);
        assert_eq!(open.vertices.len(), 25);
        // Repeated points collapse, and a "loop" of one vertex is no loop.
        let one = snap_to_vertex_path(&m, &[pts[0], pts[0] + 0.01], true, None).unwrap();
        assert_eq!(one.vertices.len(), 1);
        assert!(!one.closed);
    }

    #[test]
    fn off_mesh_points_and_separate_pieces_are_errors() {
        let m = grid(10, 0.1);
        let pts = [Vec3::new(0.1, 0.1, 0.0), Vec3::new(0.4, 0.4, 0.5)];
        match snap_to_vertex_path(&m, &pts, false, Some(0.2)) {
            Err(SnapError::OffMesh {
                point,
                nearest,
                distance,
                ..
            }) => {
                assert_eq!(point, 1);
                assert_eq!(nearest, 44);
                assert!((distance - 0.5).abs() < 1e-5);
            }
            other => panic!("{other:?}"),
        }
        assert!(snap_to_vertex_path(&m, &pts, false, Some(0.6)).is_ok());
        assert!(snap_to_vertex_path(&m, &pts, false, None).is_ok());
        // Two grids side by side, not joined.
        let mut pos = m.positions.clone();
        let mut tris = m.triangles.clone();
        let n = pos.len() as u32;
        pos.extend(m.positions.iter().map(|p| *p + Vec3::new(2.0, 0.0, 0.0)));
        tris.extend(m.triangles.iter().map(|t| t.map(|v| v + n)));
        let two = Mesh::new(pos, tris);
        let pts = [
            Vec3::new(0.1, 0.1, 0.0),
            Vec3::new(0.8, 0.1, 0.0),
            Vec3::new(2.5, 0.1, 0.0),
        ];
        match snap_to_vertex_path(&two, &pts, false, None) {
            Err(SnapError::Disconnected { point }) => assert_eq!(point, 2),
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            snap_to_vertex_path(&m, &[Vec3::NAN], false, None),
            Err(SnapError::NonFinite { point: 0, .. })
        ));
        assert!(matches!(
            snap_to_vertex_path(&Mesh::default(), &[Vec3::ZERO], false, None),
            Err(SnapError::EmptyMesh)
        ));
    }

    #[test]
    fn unused_vertices_are_never_snapped_to() {
        let mut m = grid(5, 0.1);
        m.positions.push(Vec3::new(0.2, 0.2, 0.01));
        let m = Mesh::new(m.positions.clone(), m.triangles.clone());
        let l = snap_to_vertex_path(&m, &[Vec3::new(0.2, 0.2, 0.01)], false, None).unwrap();
        assert_eq!(l.vertices, vec![12]);
    }
}
