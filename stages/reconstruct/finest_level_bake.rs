//! Graph matching's texture on the user's own mesh. Bangay & Morkel ("Graph Matching with
//! Subdivision Surfaces for Texture Synthesis on Surfaces", §3) colour the vertices of the
//! finest √2 level and leave "conversion to a texture map" to other work (§3.5); a user wants
//! the mesh they gave textured. Here the finest level's texture is baked into an atlas of the
//! input mesh's triangles ([`crate::render::build_atlas`], one region per triangle).
//!
//! A point of an input triangle is found on the nearest point of the finest level's surface
//! (its quads split into triangles). With `smooth = false` (the default) the finest level lies
//! on the input's own piecewise-flat surface, so the nearest point is the point itself; with
//! smoothing it is the point's projection onto the smoothed surface. Every vertex there read
//! its colour at an exemplar address (the match plus its offset in the region, §3.3.1), so
//! inside a finest triangle whose corners copied one patch the atlas reads the exemplar at
//! the address interpolated across it ([`super::patch_lookup`]): the exemplar's own detail
//! at the atlas's density, not the vertex spacing's. Across a seam between patches (where a
//! graph cut (§3.4) or a later match left neighbours from different places) each corner's
//! patch is continued to the point through its frame and the reads are blended; a corner
//! without an address (a colour only interpolated from a coarser level) leaves the nearest
//! corner's colour, and without addresses at all the corners' colours are interpolated.
//!
//! The nearest triangle is found through a uniform grid of cells about two finest edges wide,
//! searched ring by ring until the block searched holds the nearest point found: a point on
//! the finest surface ends in its own cell.

use super::patch_lookup::{ExemplarLookup, ExemplarSampling, PatchFrames};
use crate::geom::Mesh;
use crate::graph::Csr;
use crate::render::shader::SurfaceShader;
use glam::{IVec3, Vec3};
use texsyn_core::math::PureMath;

/// Where graph matching's finest level (`finest`, triangulated, with the hierarchy's vertex
/// `normals`) copied its colours: `sources` read in `exemplar`, each patch continued across
/// seams through the texture frame its vertex was matched in (the `field`, `scale` texels
/// per unit). The atlas and the score both read the texture through this.
pub fn finest_lookup<'a>(
    finest: &'a Mesh,
    normals: &[Vec3],
    field: &[Vec3],
    scale: f32,
    sources: &'a [[f32; 2]],
    exemplar: crate::image::ImageView<'a>,
    sampling: ExemplarSampling,
) -> ExemplarLookup<'a> {
    let axes = crate::synthesize::graph_matching::texture_axes(normals, field, scale);
    let frames = PatchFrames {
        positions: &finest.positions,
        axes,
    };
    ExemplarLookup::new(finest, sources, exemplar, sampling).with_frames(frames)
}

/// The finest level's texture seen from the input mesh, for baking.
pub struct FinestColours<'a> {
    input: &'a Mesh,
    finest: &'a Mesh,
    colours: &'a [[f32; 3]],
    lookup: Option<ExemplarLookup<'a>>,
    grid: TriangleGrid,
}

impl<'a> FinestColours<'a> {
    /// `finest`: the finest level triangulated; `colours`: one per vertex of it; `lookup`:
    /// the exemplar addresses they were read at (`None`: colours interpolated).
    pub fn new(
        input: &'a Mesh,
        finest: &'a Mesh,
        colours: &'a [[f32; 3]],
        lookup: Option<ExemplarLookup<'a>>,
    ) -> Self {
        FinestColours {
            input,
            finest,
            colours,
            lookup,
            grid: TriangleGrid::new(finest),
        }
    }
}

impl SurfaceShader for FinestColours<'_> {
    fn albedo(&self, face: usize, bary: Vec3) -> Vec3 {
        let Some(t) = self.input.triangles.get(face) else {
            return Vec3::splat(0.5);
        };
        let [a, b, c] = t.map(|v| self.input.positions[v as usize]);
        let p = a * bary.x + b * bary.y + c * bary.z;
        let Some((t, l)) = self.grid.nearest(self.finest, p) else {
            return Vec3::splat(0.5);
        };
        let tri = self.finest.triangles[t as usize];
        if let Some(lookup) = self.lookup.as_ref().filter(|l| l.is_active()) {
            let vertex = |v: u32| Vec3::from(self.colours[v as usize]);
            return lookup.texture_colour(t as usize, tri, l, vertex);
        }
        (0..3)
            .map(|k| Vec3::from(self.colours[tri[k] as usize]) * l[k])
            .sum()
    }
}

/// Triangles by the grid cells their bounding boxes touch.
struct TriangleGrid {
    origin: Vec3,
    cell: f32,
    dims: IVec3,
    cells: Csr<u32>,
}

impl TriangleGrid {
    fn new(mesh: &Mesh) -> Self {
        let (lo, hi) = mesh.bounds();
        let tris = mesh.triangles.len().max(1);
        let mean_edge: f32 = mesh
            .triangles
            .iter()
            .map(|t| mesh.positions[t[0] as usize].distance(mesh.positions[t[1] as usize]))
            .sum::<f32>()
            / tris as f32;
        let extent = (hi - lo).max(Vec3::splat(1e-12));
        // About two edges per cell, but never more cells than four per triangle.
        let mut cell = (2.0 * mean_edge).max(extent.max_element() * 1e-6);
        let count = |cell: f32| (extent / cell).ceil().max(Vec3::ONE);
        let cells = count(cell);
        let total = cells.x as f64 * cells.y as f64 * cells.z as f64;
        let most = 4.0 * tris as f64;
        if total > most {
            cell *= (total / most).cbrt_pure() as f32;
        }
        let dims = count(cell).as_ivec3();
        let mut grid = TriangleGrid {
            origin: lo,
            cell,
            dims,
            cells: Csr::from_pairs(0, std::iter::empty::<(usize, u32)>()),
        };
        let index = |c: IVec3| ((c.z * dims.y + c.y) * dims.x + c.x) as usize;
        let spans: Vec<(IVec3, IVec3)> = mesh
            .triangles
            .iter()
            .map(|t| {
                let p = t.map(|v| mesh.positions[v as usize]);
                let (a, b) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
                (grid.cell_of(a), grid.cell_of(b))
            })
            .collect();
        let pairs = spans.iter().enumerate().flat_map(|(t, &(a, b))| {
            (a.z..=b.z).flat_map(move |z| {
                (a.y..=b.y).flat_map(move |y| {
                    (a.x..=b.x).map(move |x| (index(IVec3::new(x, y, z)), t as u32))
                })
            })
        });
        let rows = (dims.x * dims.y * dims.z) as usize;
        grid.cells = Csr::from_pairs(rows, pairs);
        grid
    }

    fn cell_of(&self, p: Vec3) -> IVec3 {
        ((p - self.origin) / self.cell)
            .floor()
            .as_ivec3()
            .clamp(IVec3::ZERO, self.dims - IVec3::ONE)
    }

    /// The triangle nearest `p` and the barycentrics of its point nearest `p` (the first
    /// triangle of equals, so the result does not depend on the search order).
    fn nearest(&self, mesh: &Mesh, p: Vec3) -> Option<(u32, [f32; 3])> {
        let centre = self.cell_of(p);
        let mut best: Option<(f32, u32, [f32; 3])> = None;
        let reach = self.dims.max_element();
        for ring in 0..=reach {
            // Every triangle not yet seen lies outside the block of cells searched so far
            // (rings below `ring`), so at least as far from `p` as that block's boundary. A
            // point on the surface (distance 0) stops after its own cell.
            if let Some((d, _, _)) = best {
                let lo = self.origin + (centre - IVec3::splat(ring - 1)).as_vec3() * self.cell;
                let hi = self.origin + (centre + IVec3::splat(ring)).as_vec3() * self.cell;
                let gap = (p - lo).min(hi - p).min_element().max(0.0);
                if d <= gap * gap {
                    break;
                }
            }
            for z in -ring..=ring {
                for y in -ring..=ring {
                    for x in -ring..=ring {
                        if x.abs().max(y.abs()).max(z.abs()) != ring {
                            continue;
                        }
                        let c = centre + IVec3::new(x, y, z);
                        if c.cmplt(IVec3::ZERO).any() || c.cmpge(self.dims).any() {
                            continue;
                        }
                        let row = ((c.z * self.dims.y + c.y) * self.dims.x + c.x) as usize;
                        for &t in self.cells.row(row) {
                            let tri =
                                mesh.triangles[t as usize].map(|v| mesh.positions[v as usize]);
                            let l = closest_point_barycentrics(p, tri);
                            let q = tri[0] * l[0] + tri[1] * l[1] + tri[2] * l[2];
                            let d = q.distance_squared(p);
                            let better = match best {
                                None => true,
                                Some((bd, bt, _)) => d < bd || (d == bd && t < bt),
                            };
                            if better {
                                best = Some((d, t, l));
                            }
                        }
                    }
                }
            }
        }
        best.map(|(_, t, l)| (t, l))
    }
}

/// Barycentrics of the point of triangle `[a, b, c]` nearest `p` (Ericson, "Real-Time
/// Collision Detection", §5.1.5: the Voronoi region of a corner, an edge or the face).
pub fn closest_point_barycentrics(p: Vec3, [a, b, c]: [Vec3; 3]) -> [f32; 3] {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return [0.0, 1.0, 0.0];
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return [1.0 - v, v, 0.0];
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return [0.0, 0.0, 1.0];
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return [1.0 - w, 0.0, w];
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return [0.0, 1.0 - w, w];
    }
    let denom = va + vb + vc;
    if denom.abs() < f32::MIN_POSITIVE {
        return [1.0, 0.0, 0.0];
    }
    let (v, w) = (vb / denom, vc / denom);
    [1.0 - v - w, v, w]
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::geom::primitives;

    #[test]
    fn the_closest_point_is_the_projection_inside_and_the_nearest_corner_or_edge_outside() {
        let t = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let l = closest_point_barycentrics(Vec3::new(0.25, 0.25, 3.0), t);
        assert!(
            (l[1] - 0.25).abs() < 1e-6 && (l[2] - 0.25).abs() < 1e-6,
            "{l:?}"
        );
        assert_eq!(
            closest_point_barycentrics(Vec3::new(-1.0, -1.0, 0.0), t),
            [1.0, 0.0, 0.0]
        );
        assert_eq!(
            closest_point_barycentrics(Vec3::new(2.0, -0.5, 0.0), t),
            [0.0, 1.0, 0.0]
        );
        let e = closest_point_barycentrics(Vec3::new(0.5, -2.0, 0.0), t);
        assert!((e[0] - 0.5).abs() < 1e-6 && (e[1] - 0.5).abs() < 1e-6 && e[2] == 0.0);
        let h = closest_point_barycentrics(Vec3::new(1.0, 1.0, 0.0), t);
        assert!((h[1] - 0.5).abs() < 1e-6 && (h[2] - 0.5).abs() < 1e-6 && h[0].abs() < 1e-6);
    }

    #[test]
    fn the_grid_finds_the_same_triangle_as_a_search_of_all() {
        let mesh = primitives::torus(40, 24, 0.3);
        let grid = TriangleGrid::new(&mesh);
        for i in 0..300u64 {
            let u = |s| crate::random::counter_unit(7, s, i) * 3.0 - 1.5;
            let p = Vec3::new(u(0), u(1), u(2) * 0.5);
            let (t, _) = grid.nearest(&mesh, p).unwrap();
            let dist = |t: usize| {
                let tri = mesh.triangles[t].map(|v| mesh.positions[v as usize]);
                let l = closest_point_barycentrics(p, tri);
                (tri[0] * l[0] + tri[1] * l[1] + tri[2] * l[2]).distance(p)
            };
            let all = (0..mesh.triangles.len())
                .map(dist)
                .fold(f32::INFINITY, f32::min);
            assert!(
                dist(t as usize) <= all + 1e-6,
                "point {p}: {} > {all}",
                dist(t as usize)
            );
        }
    }

    #[test]
    fn a_point_of_the_input_takes_the_colour_the_finer_mesh_has_there() {
        // The finer mesh is the input refined on its own surface, coloured linearly in
        // position: the shader must give that colour at any point of the input.
        let input = primitives::grid(4, 1.0);
        let refined = crate::geom::edge_refine::refine_edges(&input, 0.2, 100_000).unwrap();
        let colour = |p: Vec3| [p.x / 3.0, p.y / 3.0, 0.5];
        let colours: Vec<[f32; 3]> = refined.mesh.positions.iter().map(|&p| colour(p)).collect();
        let shader = FinestColours::new(&input, &refined.mesh, &colours, None);
        for (f, bary, p) in seeded_points(&input, 5, 200) {
            let got = shader.albedo(f, bary);
            let want = Vec3::from(colour(p));
            assert!(
                (got - want).abs().max_element() < 1e-4,
                "at {p}: {got} instead of {want}"
            );
        }
    }

    #[test]
    fn inside_copied_patches_a_point_reads_the_exemplar_at_its_own_address() {
        // The finer mesh copied one patch laid at 8 texels per unit: every point of the input
        // must read the exemplar (red, green = address / 64) at 8 × its position + (4, 4),
        // however far it lies from a vertex of the finer mesh.
        let input = primitives::grid(4, 1.0);
        let refined = crate::geom::edge_refine::refine_edges(&input, 0.5, 100_000).unwrap();
        let address = |p: Vec3| glam::Vec2::new(4.0 + 8.0 * p.x, 4.0 + 8.0 * p.y);
        let sources: Vec<[f32; 2]> = (refined.mesh.positions.iter())
            .map(|&p| address(p).to_array())
            .collect();
        let colours = vec![[0.0f32; 3]; sources.len()];
        let ramp = crate::image::Image::from_fn(64, 64, |x, y| {
            [x as f32 / 64.0, y as f32 / 64.0, 0.5, 1.0]
        });
        let frames = PatchFrames {
            positions: &refined.mesh.positions,
            axes: vec![[Vec3::X * 8.0, Vec3::Y * 8.0]; sources.len()],
        };
        let lookup = ExemplarLookup::new(
            &refined.mesh,
            &sources,
            ramp.view(),
            ExemplarSampling::Bilinear,
        )
        .with_frames(frames);
        assert_eq!(lookup.looked_up_share(), 1.0);
        let shader = FinestColours::new(&input, &refined.mesh, &colours, Some(lookup));
        for (f, bary, p) in seeded_points(&input, 6, 200) {
            let a = address(p);
            let want = Vec3::new(a.x / 64.0, a.y / 64.0, 0.5);
            let got = shader.albedo(f, bary);
            assert!(
                (got - want).abs().max_element() < 1e-4,
                "at {p}: {got} instead of {want}"
            );
        }
    }

    /// `n` seeded points of `mesh`, spread over its triangles in turn: (triangle,
    /// barycentrics, position).
    pub(crate) fn seeded_points(mesh: &Mesh, seed: u64, n: u64) -> Vec<(usize, Vec3, Vec3)> {
        (0..n)
            .map(|i| {
                let (u, v) = (
                    crate::random::counter_unit(seed, 0, i),
                    crate::random::counter_unit(seed, 1, i),
                );
                let (u, v) = if u + v > 1.0 {
                    (1.0 - u, 1.0 - v)
                } else {
                    (u, v)
                };
                let f = i as usize % mesh.triangles.len();
                let bary = Vec3::new(1.0 - u - v, u, v);
                let t = mesh.triangles[f].map(|k| mesh.positions[k as usize]);
                (f, bary, t[0] * bary.x + t[1] * bary.y + t[2] * bary.z)
            })
            .collect()
    }
}
