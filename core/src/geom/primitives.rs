//! Simple meshes for tests, examples and benchmarks.

use super::Mesh;
use crate::math::PureMath;
use glam::{Vec2, Vec3};

/// An n×n grid of vertices in the z = 0 plane, `spacing` apart, x along columns and y along
/// rows, each cell split into two counter-clockwise triangles (normal +z).
pub fn grid(n: usize, spacing: f32) -> Mesh {
    let mut p = Vec::with_capacity(n * n);
    for y in 0..n {
        for x in 0..n {
            p.push(Vec3::new(x as f32 * spacing, y as f32 * spacing, 0.0));
        }
    }
    let mut t = Vec::with_capacity(2 * n.saturating_sub(1).pow(2));
    for y in 0..n.saturating_sub(1) {
        for x in 0..n - 1 {
            let i = (y * n + x) as u32;
            let n = n as u32;
            t.push([i, i + 1, i + n + 1]);
            t.push([i, i + n + 1, i + n]);
        }
    }
    Mesh::new(p, t)
}

/// The closed unit cube [0, 1]³ as 12 outward-facing triangles.
pub fn cube() -> Mesh {
    cuboid(Vec3::ONE)
}

/// The closed box [0, size] as 12 outward-facing triangles.
pub fn cuboid(size: Vec3) -> Mesh {
    let p = (0..8)
        .map(|k: u32| {
            let corner = [[0, 0], [1, 0], [1, 1], [0, 1]][(k % 4) as usize];
            Vec3::new(corner[0] as f32, corner[1] as f32, (k / 4) as f32) * size
        })
        .collect();
    let t = vec![
        [0, 2, 1],
        [0, 3, 2],
        [4, 5, 6],
        [4, 6, 7],
        [0, 1, 5],
        [0, 5, 4],
        [2, 3, 7],
        [2, 7, 6],
        [1, 2, 6],
        [1, 6, 5],
        [3, 0, 4],
        [3, 4, 7],
    ];
    Mesh::new(p, t)
}

/// The closed octahedron with its corners on the unit axes (genus 0): vertices +x, +y, -x,
/// -y (the equator, 0 to 3), +z (4) and -z (5); the fan of four triangles round +z, then
/// the fan round -z, counter-clockwise seen from outside.
pub fn octahedron() -> Mesh {
    let p = vec![Vec3::X, Vec3::Y, -Vec3::X, -Vec3::Y, Vec3::Z, -Vec3::Z];
    let upper = (0..4).map(|i| [i, (i + 1) % 4, 4]);
    let lower = (0..4).map(|i| [(i + 1) % 4, i, 5]);
    Mesh::new(p, upper.chain(lower).collect())
}

/// The regular tetrahedron with corners (1, 1, 1), (1, −1, −1), (−1, 1, −1), (−1, −1, 1):
/// the smallest closed triangle mesh (4 vertices, 6 edges, 4 triangles), outward-facing.
pub fn tetrahedron() -> Mesh {
    let p = vec![
        Vec3::new(1.0, 1.0, 1.0),
        Vec3::new(1.0, -1.0, -1.0),
        Vec3::new(-1.0, 1.0, -1.0),
        Vec3::new(-1.0, -1.0, 1.0),
    ];
    Mesh::new(p, vec![[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]])
}

/// The octahedron split `levels` times into four (midpoints pushed out to the unit sphere):
/// a closed genus-0 mesh of 8·4^levels triangles.
pub fn icosphere(levels: u32) -> Mesh {
    let mut m = octahedron();
    for _ in 0..levels {
        m = super::subdivide::subdivide(&m);
        let p = m.positions.iter().map(|p| p.normalize()).collect();
        m = Mesh::new(p, m.triangles.clone());
    }
    m
}

/// The 7-vertex torus (Möbius 1861, Császár 1949): the smallest closed triangle mesh of
/// genus 1, every vertex joined to every other. Triangles {i, i+1, i+3} and {i, i+3, i+2}
/// (mod 7); vertex i sits on a torus at angles (2πi/7, 2π·3i/7), which gives every triangle
/// some area (the mesh intersects itself, which the topology does not mind).
pub fn seven_vertex_torus() -> Mesh {
    let p = (0..7)
        .map(|i| {
            let (a, b) = (
                std::f32::consts::TAU * i as f32 / 7.0,
                std::f32::consts::TAU * (3 * i % 7) as f32 / 7.0,
            );
            let r = 2.0 + b.cos_pure();
            Vec3::new(r * a.cos_pure(), r * a.sin_pure(), b.sin_pure())
        })
        .collect();
    let t = (0..7u32)
        .flat_map(|i| [[i, (i + 1) % 7, (i + 3) % 7], [i, (i + 3) % 7, (i + 2) % 7]])
        .collect();
    Mesh::new(p, t)
}

/// A quad in the XY plane, [-1, 1]², facing +Z, as two triangles, with the texture
/// coordinates of each triangle's corners in the OBJ convention: (0, 0) bottom left to
/// (1, 1) top right.
pub fn uv_quad() -> (Mesh, Vec<[Vec2; 3]>) {
    let pos = vec![
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(1.0, -1.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(-1.0, 1.0, 0.0),
    ];
    let uv = [
        Vec2::new(0.0, 0.0),
        Vec2::new(1.0, 0.0),
        Vec2::new(1.0, 1.0),
        Vec2::new(0.0, 1.0),
    ];
    let tris = vec![[0, 1, 2], [0, 2, 3]];
    let corner_uv = tris
        .iter()
        .map(|t: &[u32; 3]| t.map(|i| uv[i as usize]))
        .collect();
    (Mesh::new(pos, tris), corner_uv)
}

/// A torus of n × m quads (each split in two; genus 1), major radius 2 around the z axis,
/// tube radius `tube`.
pub fn torus(n: u32, m: u32, tube: f32) -> Mesh {
    let mut p = Vec::new();
    for i in 0..n {
        for j in 0..m {
            let (a, b) = (
                i as f32 / n as f32 * std::f32::consts::TAU,
                j as f32 / m as f32 * std::f32::consts::TAU,
            );
            let r = 2.0 + tube * b.cos_pure();
            p.push(Vec3::new(
                r * a.cos_pure(),
                r * a.sin_pure(),
                tube * b.sin_pure(),
            ));
        }
    }
    let id = |i: u32, j: u32| (i % n) * m + j % m;
    let mut t = Vec::new();
    for i in 0..n {
        for j in 0..m {
            t.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            t.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    Mesh::new(p, t)
}

/// An n×n grid of unit quads in the z = 0 plane, counter-clockwise seen from +z: vertex
/// (x, y) has id y(n + 1) + x, cell (x, y) is face yn + x.
pub fn quad_grid(n: u32) -> super::poly_mesh::PolyMesh {
    let w = n + 1;
    let positions = (0..w * w)
        .map(|i| Vec3::new((i % w) as f32, (i / w) as f32, 0.0))
        .collect();
    let faces: Vec<Vec<u32>> = (0..n * n)
        .map(|c| {
            let i = (c / n) * w + c % n;
            vec![i, i + 1, i + w + 1, i + w]
        })
        .collect();
    super::poly_mesh::PolyMesh::from_faces(positions, &faces)
}
