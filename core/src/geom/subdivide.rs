//! Midpoint subdivision: every triangle into four, edge midpoints shared (positions only;
//! vertex colours are interpolated when present).

use super::Mesh;
use std::collections::HashMap;

pub fn subdivide(mesh: &Mesh) -> Mesh {
    let mut positions = mesh.positions.clone();
    let mut colors = mesh.colors.clone();
    let mut mid: HashMap<(u32, u32), u32> = HashMap::with_capacity(mesh.triangles.len() * 2);
    let mut triangles = Vec::with_capacity(mesh.triangles.len() * 4);
    for t in &mesh.triangles {
        let mut m = [0u32; 3];
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let key = (a.min(b), a.max(b));
            m[k] = *mid.entry(key).or_insert_with(|| {
                positions.push((positions[a as usize] + positions[b as usize]) * 0.5);
                if let Some(c) = &mut colors {
                    let (x, y) = (c[a as usize], c[b as usize]);
                    c.push(std::array::from_fn(|i| 0.5 * (x[i] + y[i])));
                }
                positions.len() as u32 - 1
            });
        }
        triangles.push([t[0], m[0], m[2]]);
        triangles.push([t[1], m[1], m[0]]);
        triangles.push([t[2], m[2], m[1]]);
        triangles.push([m[0], m[1], m[2]]);
    }
    Mesh::with_colors(positions, triangles, colors)
}

/// The longest edge of any triangle.
pub fn max_edge_length(mesh: &Mesh) -> f32 {
    mesh.triangles
        .iter()
        .flat_map(|t| (0..3).map(move |k| (t[k], t[(k + 1) % 3])))
        .map(|(a, b)| mesh.positions[a as usize].distance(mesh.positions[b as usize]))
        .fold(0.0, f32::max)
}

/// Subdivides until no edge is longer than `max_edge`, or until one more round would pass
/// `max_faces` triangles.
pub fn refine_to_edge_length(mesh: &Mesh, max_edge: f32, max_faces: usize) -> Mesh {
    let mut m = mesh.clone();
    while max_edge_length(&m) > max_edge && m.triangles.len() * 4 <= max_faces {
        m = subdivide(&m);
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn one_triangle_becomes_four_with_shared_midpoints_and_the_same_area() {
        let m = Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]);
        let s = subdivide(&m);
        assert_eq!((s.vertex_count(), s.face_count()), (6, 4));
        let area = |m: &Mesh| {
            (0..m.face_count())
                .map(|f| m.face_normal_unnormalized(f).length() * 0.5)
                .sum::<f32>()
        };
        assert!((area(&s) - area(&m)).abs() < 1e-6);
        let r = refine_to_edge_length(&m, 0.3, 1000);
        assert!(max_edge_length(&r) <= 0.3);
        let capped = refine_to_edge_length(&m, 0.001, 100);
        assert!(capped.face_count() <= 100);
    }
}
