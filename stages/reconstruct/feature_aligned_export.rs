//! What a user gets from feature-aligned texturing (Xu et al., "Feature-Aligned Shape
//! Texturing"), and what lets them check each step before trusting the result:
//!
//! - `textured.ply`: the refined mesh with a colour per vertex (what §5 optimizes);
//! - `textured.glb`: the input mesh with the refined mesh's colours baked into a texture atlas
//!   of the input's triangles (a base-colour texture), for tools that ignore vertex colours;
//!   with `atlas_size = 0`, or an input mesh with more triangles than the atlas holds, the
//!   refined mesh with vertex colours (`COLOR_0`) instead (the latter with a warning);
//! - `textured_atlas.png`: that atlas;
//! - `preview.png`: three views; with the unaligned comparison, `unaligned_preview.png` and
//!   `comparison.png` (aligned above, unaligned below: the paper's Fig. 7 pairs);
//! - `lines.obj`: the shape's feature curves as OBJ polylines (`l`), in groups `ridge`,
//!   `valley`, `crease`, `user`, oriented as the field follows them; it can be edited and given
//!   back as `extract.curves_file`, and lines moved into a group that also names `fixed`
//!   (`g user fixed`) keep their direction there (fixed curves are written so);
//! - `lines_preview.png`: the mesh with its curves drawn (red ridges and creases, blue
//!   valleys, green user curves);
//! - `field.png`: the vector field as a line-integral convolution (streaks along the field;
//!   singularities show as points where streaks swirl or end), with the curves drawn;
//! - `texture_features.png`: the exemplar with its feature lines (from the analysis stage).

use crate::check::{ParamError, check_range};
use crate::export::encode_png;
use crate::extract::shape_features::FIXED_GROUP;
use crate::geom::Mesh;
use crate::geom::edge_refine::Refined;
use crate::render::up_axis::UpAxis;
use crate::render::{VertexColorShader, ViewOptions, render_views};
use glam::Vec3;
use serde::{Deserialize, Serialize};

pub use super::patch_lookup::{ExemplarLookup, ExemplarSampling};

/// The `feature_aligned_export` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("feature_aligned_export", 7);

/// `[reconstruct]` of the feature-aligned method.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FeatureAlignedExportParams {
    /// Side of each preview view, 16..=4096. Default: 512.
    pub preview_size: u32,
    /// The mesh's up direction in the previews, or `"auto"` (the default): guessed from the
    /// mesh, the side it stands on most steadily ([`crate::render::up_axis`]). Left out of the
    /// node's key when `"auto"`.
    #[serde(skip_serializing_if = "UpAxis::is_auto")]
    pub up: UpAxis,
    /// Side of the baked atlas in `textured.glb`, 64..=8192; 0 writes vertex colours only.
    /// Default: 2048.
    pub atlas_size: u32,
    /// Length of the field picture's streaks, in vertex steps each way, 1..=200. Default: 12.
    pub streak_length: u32,
    /// How the atlas reads the exemplar at an interpolated address inside one patch
    /// ([`ExemplarLookup`]). Default: bicubic. Left out of the node's key at the default.
    #[serde(skip_serializing_if = "ExemplarSampling::is_bicubic")]
    pub lookup: ExemplarSampling,
}

impl Default for FeatureAlignedExportParams {
    fn default() -> Self {
        FeatureAlignedExportParams {
            preview_size: 512,
            up: UpAxis::default(),
            atlas_size: 2048,
            streak_length: 12,
            lookup: ExemplarSampling::Bicubic,
        }
    }
}

impl FeatureAlignedExportParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("reconstruct.preview_size", self.preview_size, 16, 4096)?;
        if self.atlas_size != 0 {
            check_range(
                "reconstruct.atlas_size",
                self.atlas_size,
                64,
                crate::render::MAX_ATLAS_SIZE,
            )?;
        }
        check_range("reconstruct.streak_length", self.streak_length, 1, 200)?;
        self.up
            .check()
            .map_err(|m| ParamError::invalid("reconstruct.up", m))?;
        Ok(())
    }
}

/// A feature curve to draw and export: a vertex path of the input mesh, its kind (0 ridge,
/// 1 valley, 2 crease, 3 user), its orientation (+1: along its vertex order) and whether the
/// user fixed that orientation.
pub struct DrawnCurve<'a> {
    pub vertices: &'a [u32],
    pub closed: bool,
    pub kind: u8,
    pub sign: i8,
    pub fixed: bool,
}

/// Everything the export draws on.
pub struct FeatureAlignedResult<'a> {
    pub input: &'a Mesh,
    pub refined: &'a Refined,
    /// Per refined vertex.
    pub colours: &'a [[f32; 3]],
    /// Per refined vertex: the exemplar address its colour came from (`[-1, -1]`: none).
    pub source: &'a [[f32; 2]],
    pub exemplar: &'a crate::image::Image,
    pub unaligned: Option<&'a [[f32; 3]]>,
    /// Per refined vertex, unit tangent (or zero).
    pub field: &'a [Vec3],
    pub curves: Vec<DrawnCurve<'a>>,
    pub texture_features_png: Vec<u8>,
    /// `report.json`: the run's numbers, written by the method.
    pub report: String,
}

const KIND_NAMES: [&str; 4] = ["ridge", "valley", "crease", "user"];
const KIND_COLOURS: [[f32; 3]; 4] = [
    [0.85, 0.1, 0.1],
    [0.1, 0.3, 0.9],
    [0.85, 0.1, 0.1],
    [0.1, 0.7, 0.2],
];

fn rgba(c: &[[f32; 3]]) -> Vec<[f32; 4]> {
    c.iter().map(|c| [c[0], c[1], c[2], 1.0]).collect()
}

/// The output files (see the module doc).
pub fn export_feature_aligned(
    r: &FeatureAlignedResult,
    p: &FeatureAlignedExportParams,
    progress: &dyn Fn(f32),
) -> Result<Vec<(String, Vec<u8>)>, crate::render::AtlasError> {
    let mesh = &r.refined.mesh;
    let opts = ViewOptions {
        size: p.preview_size,
        up: p
            .up
            .resolve(&mesh.positions, &mesh.triangles, "reconstruct"),
        ..Default::default()
    };
    let colours = rgba(r.colours);
    let mut files = vec![(
        "textured.ply".to_string(),
        crate::geom::io::write_ply(mesh, Some(&colours)),
    )];
    // Patches are laid in their sample's frame (§5.1), which the addresses themselves give.
    let lookup = ExemplarLookup::new(&r.refined.mesh, r.source, r.exemplar.view(), p.lookup)
        .with_fitted_frames(&r.refined.mesh);
    tracing::info!(
        "atlas: {:.1} % of the refined triangles lie in one exemplar patch and are looked up in the exemplar; across the rest each corner's patch is continued and blended",
        100.0 * lookup.looked_up_share()
    );
    let (glb, atlas_png) = glb(r.input, r.refined, &colours, lookup, p.atlas_size)?;
    files.push(("textured.glb".into(), glb));
    if let Some(png) = atlas_png {
        files.push(("textured_atlas.png".into(), png));
    }
    progress(0.3);
    let view =
        |c: &[[f32; 4]]| render_views(mesh, &VertexColorShader::new(&mesh.triangles, c), &opts);
    let preview = view(&colours);
    files.push(("preview.png".into(), encode_png(&preview, false)));
    if let Some(u) = r.unaligned {
        let unaligned = view(&rgba(u));
        files.push((
            "unaligned_preview.png".into(),
            encode_png(&unaligned, false),
        ));
        files.push((
            "comparison.png".into(),
            encode_png(&stack(&preview, &unaligned), false),
        ));
    }
    progress(0.6);
    // Curves on the refined mesh, for drawing.
    let paths = r
        .refined
        .refine_paths(r.curves.iter().map(|c| (c.vertices, c.closed)));
    let refined_curves: Vec<(Vec<u32>, u8)> = paths
        .into_iter()
        .zip(&r.curves)
        .map(|(p, c)| (p, c.kind))
        .collect();
    let grey = vec![[0.78, 0.78, 0.78, 1.0]; mesh.vertex_count()];
    files.push((
        "lines_preview.png".into(),
        encode_png(&view(&draw_curves(mesh, grey, &refined_curves)), false),
    ));
    let lic = streaks(mesh, r.field, p.streak_length as usize);
    files.push((
        "field.png".into(),
        encode_png(&view(&draw_curves(mesh, lic, &refined_curves)), false),
    ));
    files.push((
        "lines.obj".into(),
        lines_obj(r.input, &r.curves).into_bytes(),
    ));
    files.push((
        "texture_features.png".into(),
        r.texture_features_png.clone(),
    ));
    files.push(("report.json".into(), r.report.clone().into_bytes()));
    progress(1.0);
    Ok(files)
}

/// Two images one above the other.
fn stack(a: &image::RgbaImage, b: &image::RgbaImage) -> image::RgbaImage {
    let w = a.width().max(b.width());
    let mut out = image::RgbaImage::from_pixel(w, a.height() + b.height(), image::Rgba([255; 4]));
    image::imageops::replace(&mut out, a, 0, 0);
    image::imageops::replace(&mut out, b, 0, a.height() as i64);
    out
}

/// The curves' vertices and their one-ring painted in the curves' colours (a line one
/// vertex wide is thinner than a preview pixel on a texel-fine mesh).
fn draw_curves(
    mesh: &Mesh,
    mut colours: Vec<[f32; 4]>,
    curves: &[(Vec<u32>, u8)],
) -> Vec<[f32; 4]> {
    let adj = mesh.adjacency();
    for (path, kind) in curves {
        let c = KIND_COLOURS[(*kind as usize).min(3)];
        for &v in path {
            colours[v as usize] = [c[0], c[1], c[2], 1.0];
            for &w in adj.neighbors(v as usize) {
                colours[w as usize] = [c[0], c[1], c[2], 1.0];
            }
        }
    }
    colours
}

/// Line-integral convolution over the vertices: every vertex averages a fixed per-vertex
/// noise along the streamline through it, followed `steps` vertices each way by always moving
/// to the neighbour best aligned with the field (the field's sign is kept continuous along
/// the walk). Streaks along the field appear; where the field turns fast or vanishes, they
/// break up.
pub fn streaks(mesh: &Mesh, field: &[Vec3], steps: usize) -> Vec<[f32; 4]> {
    use rayon::prelude::*;
    let n = mesh.vertex_count();
    let adj = mesh.adjacency();
    let noise: Vec<f32> = (0..n as u64)
        .map(|v| crate::random::counter_unit(0x11c, 0, v))
        .collect();
    let walk = |start: usize, sign: f32, sum: &mut f32, count: &mut u32| {
        let mut cur = start;
        let mut dir = field[start] * sign;
        for _ in 0..steps {
            if dir.length_squared() < 1e-12 {
                break;
            }
            let pc = mesh.positions[cur];
            let mut best = (0.5f32, usize::MAX);
            for &w in adj.neighbors(cur) {
                let e = mesh.positions[w as usize] - pc;
                let len = e.length();
                if len > 0.0 {
                    let c = e.dot(dir) / (len * dir.length());
                    if c > best.0 {
                        best = (c, w as usize);
                    }
                }
            }
            if best.1 == usize::MAX {
                break;
            }
            let f = field[best.1];
            dir = if f.dot(dir) >= 0.0 { f } else { -f };
            cur = best.1;
            *sum += noise[cur];
            *count += 1;
        }
    };
    (0..n)
        .into_par_iter()
        .map(|v| {
            let (mut sum, mut count) = (noise[v], 1u32);
            walk(v, 1.0, &mut sum, &mut count);
            walk(v, -1.0, &mut sum, &mut count);
            // The mean of m uniform values has a spread of 0.29/√m: stretch it back so short
            // and long streaks show the same contrast.
            let g = 0.5 + (sum / count as f32 - 0.5) * (count as f32).sqrt() * 0.7;
            let g = g.clamp(0.05, 0.95);
            [g, g, g, 1.0]
        })
        .collect()
}

/// The curves as OBJ polylines on the input mesh's vertices, grouped by kind, each written in
/// the direction the field follows it; curves the user fixed in a group that also names
/// [`FIXED_GROUP`], so they stay fixed when the file is given back.
fn lines_obj(mesh: &Mesh, curves: &[DrawnCurve]) -> String {
    use std::fmt::Write;
    let mut s = String::from(
        "# Feature curves of a texsyn feature_aligned run, oriented as the field follows them.\n\
         # Edit and give back as extract.curves_file (with extract.features = \"curves\").\n",
    );
    let mut used: Vec<u32> = curves
        .iter()
        .flat_map(|c| c.vertices.iter().copied())
        .collect();
    used.sort_unstable();
    used.dedup();
    for &v in &used {
        let q = mesh.positions[v as usize];
        let _ = writeln!(s, "v {} {} {}", q.x, q.y, q.z);
    }
    let index = |v: u32| used.binary_search(&v).expect("listed") + 1;
    for (k, name) in KIND_NAMES.iter().enumerate() {
        for fixed in [false, true] {
            let mut group = curves
                .iter()
                .filter(|c| c.kind as usize == k && c.fixed == fixed)
                .peekable();
            if group.peek().is_none() {
                continue;
            }
            match fixed {
                false => writeln!(s, "g {name}"),
                true => writeln!(s, "g {name} {FIXED_GROUP}"),
            }
            .expect("writing to a String");
            for c in group {
                let mut ids: Vec<usize> = c.vertices.iter().map(|&v| index(v)).collect();
                if c.sign < 0 {
                    ids.reverse();
                }
                if c.closed && ids.len() > 2 {
                    ids.push(ids[0]);
                }
                s.push('l');
                for i in ids {
                    let _ = write!(s, " {i}");
                }
                s.push('\n');
            }
        }
    }
    s
}

/// `textured.glb`: the input mesh with the refined mesh's colours baked into an atlas of the
/// input's triangles (the refined mesh can have millions of triangles, too many for one region
/// each, while the input's few thousand get many texels each: fandisk's 12,946 at 2048² hold
/// about five atlas texels per exemplar texel at the shipped scale). Without an atlas
/// (`atlas_size = 0`, or an input mesh the atlas cannot hold): the refined mesh with
/// `COLOR_0`.
fn glb(
    input: &Mesh,
    refined: &Refined,
    colours: &[[f32; 4]],
    lookup: ExemplarLookup,
    atlas_size: u32,
) -> Result<(Vec<u8>, Option<Vec<u8>>), crate::render::AtlasError> {
    let atlas = match atlas_size {
        0 => None,
        size => match crate::render::build_atlas(input, size) {
            Ok(a) => Some(a),
            Err(e) => {
                tracing::warn!(
                    "reconstruct.atlas_size: {e}; textured.glb carries vertex colours (COLOR_0) of the refined mesh instead of a baked atlas"
                );
                None
            }
        },
    };
    let Some(atlas) = atlas else {
        let scene =
            crate::export::GlbMesh::vertex_coloured("feature_aligned", &refined.mesh, colours);
        return Ok((crate::export::write_glb(&scene), None));
    };
    let shader = RefinedColours::new(input, refined, colours, lookup);
    let png = encode_png(&crate::render::bake(&atlas, input, &shader), false);
    let glb =
        super::textured_export::per_triangle_atlas_glb("feature_aligned", input, &atlas, &png);
    Ok((glb, Some(png)))
}

/// The refined mesh's colours seen from the input mesh: a point of input triangle `f`, given by
/// its barycentrics, is looked up among the refined triangles that lie in `f`
/// (`Refined::face_origin`) through a grid over `f`'s barycentric domain. Inside a refined
/// triangle whose corners copied one exemplar patch it takes the exemplar at the interpolated
/// address ([`ExemplarLookup`]); elsewhere (a seam between patches) the colour of the nearest
/// corner, so a seam stays a sharp line and is not blended.
struct RefinedColours<'a> {
    refined: &'a Refined,
    colours: &'a [[f32; 4]],
    lookup: ExemplarLookup<'a>,
    /// Per input face: its first cell in `cell_start`, and the grid's side.
    face_cells: Vec<(u32, u32)>,
    cell_start: Vec<u32>,
    /// Refined triangle ids, by cell.
    items: Vec<u32>,
    /// Every refined triangle of each input face (CSR), for points whose cell is empty.
    face_start: Vec<u32>,
    face_items: Vec<u32>,
    /// Per refined triangle: its corners in its origin's barycentric (b1, b2) coordinates.
    uv: Vec<[glam::Vec2; 3]>,
}

impl<'a> RefinedColours<'a> {
    fn new(
        input: &Mesh,
        refined: &'a Refined,
        colours: &'a [[f32; 4]],
        lookup: ExemplarLookup<'a>,
    ) -> Self {
        use glam::Vec2;
        let m = &refined.mesh;
        let faces = input.triangles.len();
        let uv: Vec<[Vec2; 3]> = m
            .triangles
            .iter()
            .zip(&refined.face_origin)
            .map(|(t, &o)| {
                let [a, b, c] = input.triangles[o as usize].map(|v| input.positions[v as usize]);
                t.map(|v| barycentric_uv(a, b, c, m.positions[v as usize]))
            })
            .collect();
        let mut by_face: Vec<Vec<u32>> = vec![Vec::new(); faces];
        for (t, &o) in refined.face_origin.iter().enumerate() {
            by_face[o as usize].push(t as u32);
        }
        let mut face_cells = Vec::with_capacity(faces);
        let mut cell_start = vec![0u32];
        let mut items = Vec::new();
        for list in &by_face {
            // About one triangle per cell, whatever the refinement.
            let side = ((list.len() as f32).sqrt().ceil() as u32).clamp(1, 4096);
            face_cells.push((cell_start.len() as u32 - 1, side));
            let mut cells: Vec<Vec<u32>> = vec![Vec::new(); (side * side) as usize];
            let cell = |x: f32| ((x * side as f32).floor() as i64).clamp(0, side as i64 - 1) as u32;
            for &t in list {
                let c = uv[t as usize];
                let lo = c[0].min(c[1]).min(c[2]);
                let hi = c[0].max(c[1]).max(c[2]);
                for y in cell(lo.y)..=cell(hi.y) {
                    for x in cell(lo.x)..=cell(hi.x) {
                        cells[(y * side + x) as usize].push(t);
                    }
                }
            }
            for c in cells {
                items.extend(c);
                cell_start.push(items.len() as u32);
            }
        }
        let mut face_start = vec![0u32];
        let mut face_items = Vec::with_capacity(refined.face_origin.len());
        for list in by_face {
            face_items.extend(list);
            face_start.push(face_items.len() as u32);
        }
        RefinedColours {
            refined,
            colours,
            lookup,
            face_cells,
            cell_start,
            items,
            face_start,
            face_items,
            uv,
        }
    }
}

/// Barycentric (b1, b2) of `p` in triangle (a, b, c); (0, 0) for a degenerate triangle.
fn barycentric_uv(a: Vec3, b: Vec3, c: Vec3, p: Vec3) -> glam::Vec2 {
    let (e0, e1, e2) = ((b - a).as_dvec3(), (c - a).as_dvec3(), (p - a).as_dvec3());
    let (d00, d01, d11) = (e0.dot(e0), e0.dot(e1), e1.dot(e1));
    let (d20, d21) = (e2.dot(e0), e2.dot(e1));
    let den = d00 * d11 - d01 * d01;
    if den.abs() <= 1e-12 * d00 * d11 || den == 0.0 {
        return glam::Vec2::ZERO;
    }
    glam::Vec2::new(
        ((d11 * d20 - d01 * d21) / den) as f32,
        ((d00 * d21 - d01 * d20) / den) as f32,
    )
}

impl crate::render::SurfaceShader for RefinedColours<'_> {
    fn albedo(&self, face: usize, bary: Vec3) -> Vec3 {
        let Some(&(first, side)) = self.face_cells.get(face) else {
            return Vec3::splat(0.5);
        };
        let q = glam::Vec2::new(bary.y, bary.z);
        let cell = |x: f32| ((x * side as f32).floor() as i64).clamp(0, side as i64 - 1) as u32;
        let c = (first + cell(q.y) * side + cell(q.x)) as usize;
        let mut list = &self.items[self.cell_start[c] as usize..self.cell_start[c + 1] as usize];
        if list.is_empty() {
            list = &self.face_items
                [self.face_start[face] as usize..self.face_start[face + 1] as usize];
        }
        // The refined triangle holding q (its smallest barycentric is the largest; a point on
        // a shared edge or just outside, as gutter texels are, takes the nearest).
        let mut best: Option<(f32, u32, [f32; 3])> = None;
        for &t in list {
            let [a, b, cc] = self.uv[t as usize];
            let (v0, v1, v2) = (b - a, cc - a, q - a);
            let den = v0.perp_dot(v1);
            if den.abs() < 1e-20 {
                continue;
            }
            let l1 = v2.perp_dot(v1) / den;
            let l2 = v0.perp_dot(v2) / den;
            let l = [1.0 - l1 - l2, l1, l2];
            let score = l[0].min(l[1]).min(l[2]);
            if best.is_none_or(|(s, _, _)| score > s) {
                best = Some((score, t, l));
            }
        }
        let Some((_, t, l)) = best else {
            return Vec3::splat(0.5);
        };
        let l = l.map(|x| x.max(0.0));
        let sum = (l[0] + l[1] + l[2]).max(1e-12);
        let l = l.map(|x| x / sum);
        let tri = self.refined.mesh.triangles[t as usize];
        let vertex = |v: u32| {
            let c = self.colours[v as usize];
            Vec3::new(c[0], c[1], c[2])
        };
        self.lookup.texture_colour(t as usize, tri, l, vertex)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::primitives;

    #[test]
    fn streaks_run_along_the_field_not_across_it() {
        // On a grid with the field along x, a vertex's streak value is shared with its x
        // neighbours far more than with its y neighbours.
        let n = 60;
        let mesh = primitives::grid(n, 1.0);
        let field = vec![Vec3::X; mesh.vertex_count()];
        let g: Vec<f32> = streaks(&mesh, &field, 10).iter().map(|c| c[0]).collect();
        let (mut along, mut across) = (0.0f32, 0.0f32);
        for y in 15..45 {
            for x in 15..45 {
                let i = y * n + x;
                along += (g[i] - g[i + 1]).abs();
                across += (g[i] - g[i + n]).abs();
            }
        }
        assert!(along * 3.0 < across, "along {along}, across {across}");
    }

    /// A planar input mesh (z = 0.3 y), refined to edges of at most 0.07, and `shift(x)` texels
    /// added to the exemplar address of each refined vertex of the patch map `address`.
    fn two_triangles() -> (Mesh, Refined) {
        let input = Mesh::new(
            vec![
                Vec3::ZERO,
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(1.0, 1.0, 0.3),
                Vec3::new(0.0, 1.0, 0.3),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let refined = crate::geom::edge_refine::refine_edges(&input, 0.07, 100_000).unwrap();
        (input, refined)
    }

    /// One patch's similarity map of the plane z = 0.3 y: arc length along x and along the
    /// slope, at 14 texels per unit, 2 texels in from the exemplar's corner.
    fn address(p: Vec3) -> glam::Vec2 {
        glam::Vec2::new(p.x, p.y * (1.0f32 + 0.09).sqrt()) * 14.0 + 2.0
    }

    /// An exemplar whose red and green are its texel address / 64 (bilinear lookups of it give
    /// the address back) and whose blue is a one-texel checkerboard, detail that colours
    /// interpolated between vertices about a texel apart cannot hold.
    fn ramp() -> crate::image::Image {
        let mut pixels = Vec::new();
        for y in 0..64 {
            for x in 0..64 {
                let checker = ((x + y) % 2) as f32;
                pixels.push([x as f32 / 64.0, y as f32 / 64.0, checker, 1.0]);
            }
        }
        crate::image::Image {
            width: 64,
            height: 64,
            pixels,
        }
    }

    /// The exemplar's colour at each address: what a vertex that copied it holds.
    fn looked_up(source: &[[f32; 2]], exemplar: &crate::image::Image) -> Vec<[f32; 4]> {
        (source.iter())
            .map(|&s| exemplar.view().sample(s.into()))
            .collect()
    }

    /// The atlas shader's colours at 400 seeded points of the input mesh, with the point.
    fn shade_points(shader: &RefinedColours, input: &Mesh) -> Vec<(Vec3, Vec3)> {
        use crate::render::SurfaceShader;
        let points = super::super::finest_level_bake::tests::seeded_points(input, 3, 400);
        (points.into_iter())
            .map(|(f, bary, p)| (p, shader.albedo(f, bary)))
            .collect()
    }

    #[test]
    fn inside_one_patch_the_atlas_holds_the_exemplar_at_the_interpolated_address() {
        // Every refined vertex copied one patch: the shader must return the exemplar at the
        // point's own address, finer than the vertex spacing, at any point of the input mesh.
        let (input, refined) = two_triangles();
        let exemplar = ramp();
        let source: Vec<[f32; 2]> = refined
            .mesh
            .positions
            .iter()
            .map(|&p| address(p).into())
            .collect();
        let colours = looked_up(&source, &exemplar);
        let lookup = ExemplarLookup::new(
            &refined.mesh,
            &source,
            exemplar.view(),
            ExemplarSampling::Bilinear,
        );
        assert!(
            (0..refined.mesh.triangles.len()).all(|t| lookup.one_patch(t)),
            "every triangle lies in the one patch"
        );
        let shader = RefinedColours::new(&input, &refined, &colours, lookup);
        for (p, got) in shade_points(&shader, &input) {
            let want = Vec3::from_slice(&exemplar.view().sample(address(p))[..3]);
            assert!(
                (got - want).abs().max_element() < 1e-4,
                "at {p}: {got} instead of {want}"
            );
        }
    }

    #[test]
    fn nearest_lookups_copy_the_exemplar_s_own_texels() {
        // The checkerboard's blue is 0 or 1 at every texel: nearest reads keep it so at every
        // point, bilinear reads between texels average it to values in between.
        let (input, refined) = two_triangles();
        let exemplar = ramp();
        let source: Vec<[f32; 2]> = (refined.mesh.positions.iter())
            .map(|&p| address(p).into())
            .collect();
        let colours = looked_up(&source, &exemplar);
        let blues = |sampling| {
            let lookup = ExemplarLookup::new(&refined.mesh, &source, exemplar.view(), sampling);
            let shader = RefinedColours::new(&input, &refined, &colours, lookup);
            shade_points(&shader, &input)
                .into_iter()
                .map(|(p, c)| (address(p), c))
                .collect::<Vec<_>>()
        };
        for (at, c) in blues(ExemplarSampling::Nearest) {
            let texel = at.round();
            let want = ((texel.x + texel.y) as i64 % 2) as f32;
            assert!(
                (c.z - want).abs() < 1e-6,
                "at {at}: blue {} not {want}",
                c.z
            );
            assert!((c.x - texel.x / 64.0).abs() < 1e-6, "at {at}: {c}");
        }
        let between = blues(ExemplarSampling::Bilinear)
            .iter()
            .filter(|(_, c)| c.z > 0.1 && c.z < 0.9)
            .count();
        assert!(
            between > 100,
            "bilinear reads between texels blend: {between}"
        );
    }

    #[test]
    fn across_a_seam_the_atlas_blends_each_corner_s_patch_continued_to_the_point() {
        // Vertices right of x = 0.5 copied another patch, 20 texels further in the exemplar.
        // Across the seam a point reads each corner's patch continued to it (frames fitted to
        // the addresses) and blends them: both patches agree on the address's y, which must
        // come out exact, and x lies between the two patches' (0 and 20 texels off the left
        // one's). A corner's own colour, not continued, is up to a texel off in y.
        let (input, refined) = two_triangles();
        let exemplar = ramp();
        let shift = |p: Vec3| if p.x > 0.5 { 20.0 } else { 0.0 };
        let source: Vec<[f32; 2]> = (refined.mesh.positions.iter())
            .map(|&p| (address(p) + glam::Vec2::new(shift(p), 0.0)).into())
            .collect();
        let colours = looked_up(&source, &exemplar);
        let lookup = ExemplarLookup::new(
            &refined.mesh,
            &source,
            exemplar.view(),
            ExemplarSampling::Bilinear,
        )
        .with_fitted_frames(&refined.mesh);
        let seams = (0..refined.mesh.triangles.len())
            .filter(|&t| !lookup.one_patch(t))
            .count();
        assert!(
            seams > 0,
            "the triangles across x = 0.5 are not one patch's"
        );
        let shader = RefinedColours::new(&input, &refined, &colours, lookup);
        let mut blended = 0;
        for (p, got) in shade_points(&shader, &input) {
            let (x, y) = (got.x * 64.0 - address(p).x, got.y * 64.0 - address(p).y);
            assert!(y.abs() < 0.02, "at {p}: {y} texels off in y");
            assert!(
                (-0.02..=20.02).contains(&x),
                "at {p}: address {x} texels off the left patch's, outside the two patches'"
            );
            if (1.0..19.0).contains(&x) {
                blended += 1;
            }
        }
        assert!(blended > 0, "no point blends the two patches");
    }

    #[test]
    fn lines_obj_reverses_curves_the_field_runs_against_and_reads_back() {
        let mesh = primitives::grid(3, 1.0);
        let curves = [
            DrawnCurve {
                vertices: &[0, 1, 2],
                closed: false,
                kind: 2,
                sign: -1,
                fixed: false,
            },
            DrawnCurve {
                vertices: &[3, 4],
                closed: false,
                kind: 1,
                sign: 1,
                fixed: true,
            },
        ];
        let s = lines_obj(&mesh, &curves);
        let read = crate::extract::shape_features::read_curves_file("l.obj", s.as_bytes()).unwrap();
        assert_eq!(read.len(), 2);
        // Kinds are written in order ridge, valley, crease, user: the valley first, and it
        // stays fixed.
        assert_eq!(read[0].points, vec![[0.0, 1.0, 0.0], [1.0, 1.0, 0.0]]);
        assert_eq!((read[0].fixed, read[1].fixed), (true, false));
        assert_eq!(
            read[1].points,
            vec![[2.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
        );
    }
}
