//! Sharp creases of a mesh as polylines: the shape features of CAD parts (fandisk) for
//! feature-aligned texturing (Xu et al., "Feature-Aligned Shape Texturing", §1 and §6 take
//! feature lines as given; texsyn finds them: crest lines for organic meshes,
//! dihedral-angle creases for CAD meshes).
//!
//! An edge is a crease when the angle between the normals of its two triangles is at least
//! `angle` degrees. Crease edges are joined into polylines that run from an end or a junction
//! (a vertex where the number of crease edges is not two) to the next one; what is left are
//! closed loops. Polylines shorter than `min_length` (a fraction of the bounding box's
//! diagonal) are dropped: short creases are noise for texture alignment. Boundary edges and
//! edges of more than two triangles are never creases (they have no dihedral angle).
//!
//! Not wired into a method yet: the feature-aligned method will read it. Crest
//! lines of smooth shapes (Yoshizawa, Belyaev & Seidel 2005) are still to be written.

use crate::check::{ParamError, check_range};
use crate::geom::Mesh;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use texsyn_core::math::PureMath;

/// Parameters of [`crease_lines`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CreaseParams {
    /// Smallest dihedral angle of a crease, in degrees, 1..=179. Default: 30.
    pub angle: f32,
    /// Shortest polyline kept, as a fraction of the bounding box's diagonal, 0..=1.
    /// Default: 0.02.
    pub min_length: f32,
}

impl Default for CreaseParams {
    fn default() -> Self {
        CreaseParams {
            angle: 30.0,
            min_length: 0.02,
        }
    }
}

impl CreaseParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("extract.angle", self.angle, 1.0, 179.0)?;
        check_range("extract.min_length", self.min_length, 0.0, 1.0)
    }
}

/// A polyline through mesh vertices; a closed one does not repeat its first vertex.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Polyline {
    pub vertices: Vec<u32>,
    pub closed: bool,
}

/// The creases of `mesh` (see the module doc), in a deterministic order: open polylines by
/// their first edge in vertex order, then loops.
pub fn crease_lines(mesh: &Mesh, p: &CreaseParams) -> Vec<Polyline> {
    let cos_limit = p.angle.to_radians().cos_pure();
    // Undirected edge -> the faces using it.
    let mut faces: BTreeMap<(u32, u32), Vec<usize>> = BTreeMap::new();
    for (f, t) in mesh.triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            faces.entry((a.min(b), a.max(b))).or_default().push(f);
        }
    }
    let normal = |f: usize| mesh.face_normal_unnormalized(f).normalize_or_zero();
    let mut crease: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    for (&(a, b), fs) in &faces {
        if fs.len() != 2 || a == b {
            continue;
        }
        let (n0, n1) = (normal(fs[0]), normal(fs[1]));
        if n0 == glam::Vec3::ZERO || n1 == glam::Vec3::ZERO {
            continue;
        }
        if n0.dot(n1) <= cos_limit {
            crease.entry(a).or_default().push(b);
            crease.entry(b).or_default().push(a);
        }
    }
    // Open polylines from every end or junction, then the loops that are left.
    let mut lines: Vec<Polyline> = crate::geom::chains::trace_chains(&crease)
        .into_iter()
        .map(|(vertices, closed)| Polyline { vertices, closed })
        .collect();
    let (lo, hi) = mesh.bounds();
    let min = p.min_length * (hi - lo).length();
    lines.retain(|l| polyline_length(mesh, l) >= min);
    lines
}

/// Length of a polyline in object units (closing segment included for loops).
pub fn polyline_length(mesh: &Mesh, l: &Polyline) -> f32 {
    let p = |v: u32| mesh.positions[v as usize];
    let mut len: f32 = l
        .vertices
        .windows(2)
        .map(|w| p(w[0]).distance(p(w[1])))
        .sum();
    if l.closed && l.vertices.len() > 2 {
        len += p(l.vertices[0]).distance(p(*l.vertices.last().expect("non-empty")));
    }
    len
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::primitives::{cube, grid};

    #[test]
    fn a_cube_has_twelve_creases_from_corner_to_corner() {
        let m = cube();
        let lines = crease_lines(&m, &CreaseParams::default());
        assert_eq!(lines.len(), 12, "{lines:?}");
        for l in &lines {
            assert!(!l.closed);
            assert!((polyline_length(&m, l) - 1.0).abs() < 1e-5);
        }
        // The faces' diagonals are flat: no crease at 30°, and none at all at 91°.
        let none = crease_lines(
            &m,
            &CreaseParams {
                angle: 91.0,
                ..Default::default()
            },
        );
        assert!(none.is_empty());
    }

    /// A 1×1 grid folded along x = 0.5 by `fold` degrees.
    fn folded(fold: f32) -> Mesh {
        let mut m = grid(11, 0.1);
        let a = fold.to_radians();
        for p in &mut m.positions {
            if p.x > 0.5 {
                let d = p.x - 0.5;
                p.x = 0.5 + d * a.cos_pure();
                p.z = d * a.sin_pure();
            }
        }
        Mesh::new(m.positions.clone(), m.triangles.clone())
    }

    #[test]
    fn a_fold_gives_one_polyline_along_it_when_sharp_enough() {
        let m = folded(60.0);
        let lines = crease_lines(&m, &CreaseParams::default());
        assert_eq!(lines.len(), 1, "{lines:?}");
        let l = &lines[0];
        assert!(!l.closed);
        assert_eq!(l.vertices.len(), 11);
        assert!(
            l.vertices
                .iter()
                .all(|&v| (m.positions[v as usize].x - 0.5).abs() < 1e-6)
        );
        assert!((polyline_length(&m, l) - 1.0).abs() < 1e-5);
        // A gentle fold is not a crease at 30°.
        assert!(crease_lines(&folded(20.0), &CreaseParams::default()).is_empty());
    }

    #[test]
    fn a_closed_crease_is_a_loop_and_short_ones_are_dropped() {
        let m = cube();
        let lines = crease_lines(
            &m,
            &CreaseParams {
                min_length: 0.9,
                ..Default::default()
            },
        );
        assert!(
            lines.is_empty(),
            "edges of length 1 are shorter than 0.9 × the diagonal (1.56)"
        );
        // A loop: a cylindrical band bulging outward along its middle ring, whose 16 vertices
        // each have two crease edges.
        let n = 16u32;
        let mut pos = Vec::new();
        for ring in 0..3 {
            for i in 0..n {
                let a = i as f32 / n as f32 * std::f32::consts::TAU;
                let r = if ring == 1 { 1.5 } else { 1.0 };
                pos.push(glam::Vec3::new(
                    r * a.cos_pure(),
                    ring as f32,
                    r * a.sin_pure(),
                ));
            }
        }
        let mut tris = Vec::new();
        for ring in 0..2 {
            for i in 0..n {
                let (a, b) = (ring * n + i, ring * n + (i + 1) % n);
                let (c, d) = (a + n, b + n);
                tris.push([a, c, b]);
                tris.push([b, c, d]);
            }
        }
        let band = Mesh::new(pos, tris);
        let lines = crease_lines(&band, &CreaseParams::default());
        assert_eq!(lines.len(), 1, "{lines:?}");
        assert!(lines[0].closed);
        assert_eq!(lines[0].vertices.len(), n as usize);
        assert!(lines[0].vertices.iter().all(|&v| (n..2 * n).contains(&v)));
    }
}

#[cfg(test)]
mod fandisk {
    use super::*;

    /// What the creases of fandisk.off are, when ../shared/data is there (not for CI).
    #[test]
    #[ignore]
    fn fandisk_creases() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../shared/data/meshes/fandisk.off");
        let m = crate::geom::io::read_mesh(&path).unwrap();
        let lines = crease_lines(&m, &CreaseParams::default());
        let total: f32 = lines.iter().map(|l| polyline_length(&m, l)).sum();
        let closed = lines.iter().filter(|l| l.closed).count();
        eprintln!(
            "fandisk: {} creases ({closed} closed), total length {total}",
            lines.len()
        );
        assert!(!lines.is_empty());
    }
}
