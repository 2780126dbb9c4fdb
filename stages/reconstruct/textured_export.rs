//! Exports of a mesh textured from an exemplar: what a user opens.
//!
//! - `textured.obj` + `textured.mtl` + the exemplar (`texture.<ext>`) and aligned maps
//!   (`<name>.<ext>`): one set of corner coordinates into the exemplar itself, so no new
//!   texture memory is needed (the paper's point), at the price of visible patch seams in
//!   ordinary viewers that cannot blend three coordinate sets.
//! - `textured.glb` and `baked.obj` + `baked.mtl`: the blended result baked into a chart atlas
//!   ([`crate::render::chart_atlas`]) of one or more pages (`baked_<map>.png`, or
//!   `baked_<map>_<page>.png` when there are several), one glTF primitive and one OBJ
//!   `usemtl` per page, with the normal map re-expressed in the frames a viewer decodes it
//!   with (the .glb's per-vertex normals and tangents, interpolated at each texel; see
//!   [`NormalRebase`]) and the roughness map in glTF's metallic-roughness slot, so Blender and
//!   three.js show what texsyn renders.
//! - `preview.png`: three views drawn with the blending shader by texsyn's rasterizer.
//!
//! Surfaces are exported in the order given; the first is the base colour.

use crate::check::{ParamError, check_range};
use crate::export::glb::{GlbMaterial, GlbMesh, GlbPrimitive, write_glb};
use crate::export::obj::{MtlMaps, write_mtl, write_obj, write_obj_materials};
use crate::geom::Mesh;
use crate::image::texel_to_uv;
use crate::render::chart_atlas::{ChartAtlas, ChartAtlasError, bake_page, build_chart_atlas};
use crate::render::shader::SurfaceShader;
use crate::render::up_axis::UpAxis;
use crate::render::views::{ViewOptions, render_views_of_each};
use glam::{Vec2, Vec3, Vec4};
use serde::{Deserialize, Serialize};

/// Range of `reconstruct.texel_density`.
pub const TEXEL_DENSITY_RANGE: (f32, f32) = (0.25, 16.0);

/// `[reconstruct]` parameters of textured-mesh exports.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExportParams {
    /// Largest side of a baked atlas page, 64..=8192: a texture that does not fit one page is
    /// spread over several. Default: 8192.
    pub atlas_size: u32,
    /// Atlas texels per exemplar texel (at `parameterize.scale`), 0.25..=16: 1 keeps the
    /// exemplar's own detail; more gives the blend's sub-texel detail room, less gives smaller
    /// files. Default: 1.
    pub texel_density: f32,
    /// Side of each of the three preview views, 16..=4096. Default: 512.
    pub preview_size: u32,
    /// The mesh's up direction in the previews, or `"auto"` (the default): guessed from the
    /// mesh, the side it stands on most steadily ([`crate::render::up_axis`]). Left out of the
    /// node's key when `"auto"`.
    #[serde(skip_serializing_if = "UpAxis::is_auto")]
    pub up: UpAxis,
    /// Texels over which the walk's patches cross-fade at their seams, 0..=64
    /// ([`crate::reconstruct::wide_blend`]); 0 (the default) is §4.4's blend over each single
    /// triangle. Left out of the node's key at 0.
    #[serde(skip_serializing_if = "is_zero")]
    pub blend_radius: f32,
}

fn is_zero(x: &f32) -> bool {
    *x == 0.0
}

impl Default for ExportParams {
    fn default() -> Self {
        ExportParams {
            atlas_size: 8192,
            texel_density: 1.0,
            preview_size: 512,
            up: UpAxis::default(),
            blend_radius: 0.0,
        }
    }
}

impl ExportParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("reconstruct.atlas_size", self.atlas_size, 64, 8192)?;
        let (lo, hi) = TEXEL_DENSITY_RANGE;
        check_range("reconstruct.texel_density", self.texel_density, lo, hi)?;
        check_range("reconstruct.preview_size", self.preview_size, 16, 4096)?;
        let max_radius = crate::reconstruct::wide_blend::MAX_RADIUS;
        check_range(
            "reconstruct.blend_radius",
            self.blend_radius,
            0.0,
            max_radius,
        )?;
        self.up
            .check()
            .map_err(|m| ParamError::invalid("reconstruct.up", m))?;
        Ok(())
    }
}

/// One textured surface property: a name (`basecolor`, `normal`, `roughness`, `height`, …),
/// the original file (copied beside the OBJ) and a shader that evaluates it on the surface.
pub struct ExportSurface<'a, S: SurfaceShader> {
    pub name: String,
    pub extension: String,
    pub file: &'a [u8],
    pub shader: S,
}

/// Moved to [`crate::export::encode_png`] (it is not specific to textured meshes); kept
/// here so the methods that import it from this module compile unchanged.
pub use crate::export::encode_png;

fn file_name(surface: &str, ext: &str) -> String {
    if surface == "basecolor" {
        format!("texture.{ext}")
    } else {
        format!("{surface}.{ext}")
    }
}

/// The file of page `page` of `pages` of a baked surface.
fn baked_name(surface: &str, page: usize, pages: usize) -> String {
    if pages == 1 {
        format!("baked_{surface}.png")
    } else {
        format!("baked_{surface}_{page}.png")
    }
}

/// Peak memory of baking one surface, in bytes per page texel. Measured with
/// `configs/demo.toml` (one surface): 416 MB above the run's 53 MB for one 5704×4980 page
/// (`texel_density = 16`), 15 bytes per texel.
pub const BAKE_BYTES_PER_TEXEL: u64 = 16;

/// Refuses, before the bake, pages whose estimated memory ([`BAKE_BYTES_PER_TEXEL`] per texel
/// and surface) is over the budget (`--max-memory`), naming a `texel_density` that fits: the
/// pages' sizes follow the surface's area, so they are known only once its charts are laid
/// out.
fn check_bake_memory(pages: &[[u32; 2]], surfaces: usize, density: f32) -> Result<(), ExportError> {
    let texels: u128 = pages.iter().map(|[w, h]| *w as u128 * *h as u128).sum();
    let per = (BAKE_BYTES_PER_TEXEL * surfaces.max(1) as u64) as u128;
    // In hundredths, so the value named has two decimals; the pages' area goes with its square.
    let at = ((density as f64 * 100.0).round() as u64).max(1);
    let estimate = |v: u64| {
        let v = v as u128;
        (per * texels * v * v / (at as u128 * at as u128)).min(u64::MAX as u128) as u64
    };
    texsyn_core::memory::check_budget("reconstruct.texel_density", at, estimate, |v| {
        format!("{:.2}", v as f64 / 100.0)
    })
    .map_err(|e| ExportError::Atlas(e.to_string()))
}

/// Why the export files could not be built.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// A face does not fit a page at this density.
    #[error("{0}")]
    Atlas(String),
}

impl ExportError {
    fn of_atlas(e: ChartAtlasError, p: &ExportParams) -> Self {
        let Some(shrink) = e.shrink_to_fit() else {
            return ExportError::Atlas(format!("reconstruct: {e}"));
        };
        let fits = p.texel_density as f64 * shrink;
        let advice = if fits >= TEXEL_DENSITY_RANGE.0 as f64 {
            // Two decimals, rounded down, so that the value named does fit.
            let v = ((fits * 100.0).floor() / 100.0).max(TEXEL_DENSITY_RANGE.0 as f64);
            format!("use reconstruct.texel_density ≤ {v:.2}")
        } else if p.atlas_size < 8192 {
            "raise reconstruct.atlas_size (at most 8192) or lower parameterize.scale".into()
        } else {
            "lower parameterize.scale: the triangles are too large for any page".into()
        };
        ExportError::Atlas(format!(
            "reconstruct.texel_density = {}: {e} of reconstruct.atlas_size = {}; {advice}",
            p.texel_density, p.atlas_size
        ))
    }
}

/// A glTF of `mesh` textured by a baked atlas of one region per triangle
/// ([`crate::render::build_atlas`]; corners are unshared), the atlas `png` as base colour.
pub fn per_triangle_atlas_glb(
    name: &str,
    mesh: &Mesh,
    atlas: &crate::render::Atlas,
    png: &[u8],
) -> Vec<u8> {
    let mut scene = GlbMesh {
        name: name.into(),
        material: GlbMaterial {
            double_sided: true,
            base_color_png: Some(png.to_vec()),
            ..Default::default()
        },
        ..Default::default()
    };
    let normals = mesh.vertex_normals();
    for t in &mesh.triangles {
        for &v in t {
            scene.positions.push(mesh.positions[v as usize]);
            scene.normals.push(normals[v as usize]);
            scene.indices.push(scene.indices.len() as u32);
        }
    }
    scene.texcoords = vec![atlas.corner_uv.iter().flatten().copied().collect()];
    write_glb(&scene)
}

/// Estimated peak memory, in bytes, of a baked atlas of `side` texels per side: about 9
/// bytes per texel (the float image, its 8-bit copy and the PNG) and the mesh besides
/// (measured: 152 MB at 4096², 547 MB at 8192² for the demo).
pub fn atlas_memory_estimate(side: u64) -> u64 {
    9 * side * side + (48 << 20)
}

/// Builds every export file, and `preview.png` plus one image per `extra_views` (name, shader)
/// rendered from the same rasterization. `single_set` holds one corner-coordinate set per face in texel
/// addresses of an exemplar of size `exemplar` (for the OBJ); `layout` per face corner
/// positions in exemplar texels where faces that share an edge continuously share its two
/// points (the chart atlas keeps those faces together), scaled by `texel_density` here.
#[allow(clippy::too_many_arguments)] // the export's inputs, each used once, passed as they are
pub fn export_textured_mesh<S: SurfaceShader>(
    mesh: &Mesh,
    single_set: &[[Vec2; 3]],
    layout: &[[Vec2; 3]],
    exemplar: (u32, u32),
    surfaces: &[ExportSurface<S>],
    extra_views: &[(&str, &dyn SurfaceShader)],
    p: &ExportParams,
    progress: &dyn Fn(f32),
) -> Result<Vec<(String, Vec<u8>)>, ExportError> {
    // The views need nothing from the atlas: rendered beside it, their serial parts overlap
    // the export's.
    let mut views = Vec::new();
    let files = rayon::in_place_scope(|scope| {
        scope.spawn(|_| {
            let opts = ViewOptions {
                size: p.preview_size,
                up: p
                    .up
                    .resolve(&mesh.positions, &mesh.triangles, "reconstruct"),
                ..Default::default()
            };
            let shaders: Vec<(&str, &dyn SurfaceShader)> = surfaces
                .first()
                .map(|base| ("preview.png", &base.shader as &dyn SurfaceShader))
                .into_iter()
                .chain(extra_views.iter().copied())
                .collect();
            let images = render_views_of_each(
                mesh,
                &shaders.iter().map(|&(_, s)| s).collect::<Vec<_>>(),
                &opts,
            );
            views = shaders
                .iter()
                .zip(images)
                .map(|(&(name, _), img)| (name.to_string(), encode_png(&img, false)))
                .collect();
        });
        export_files(mesh, single_set, layout, exemplar, surfaces, p, progress)
    });
    let mut files = files?;
    files.extend(views);
    progress(1.0);
    Ok(files)
}

/// Every export file but the rendered views.
fn export_files<S: SurfaceShader>(
    mesh: &Mesh,
    single_set: &[[Vec2; 3]],
    layout: &[[Vec2; 3]],
    exemplar: (u32, u32),
    surfaces: &[ExportSurface<S>],
    p: &ExportParams,
    progress: &dyn Fn(f32),
) -> Result<Vec<(String, Vec<u8>)>, ExportError> {
    let mut files: Vec<(String, Vec<u8>)> = Vec::new();
    let clock = std::time::Instant::now();
    let lap = |what: &str| {
        tracing::debug!(
            "reconstruct: {what} at {:.3} s",
            clock.elapsed().as_secs_f64()
        )
    };
    let (w, h) = exemplar;
    let uv: Vec<[Vec2; 3]> = single_set
        .iter()
        .map(|t| t.map(|a| texel_to_uv(a, w, h)))
        .collect();
    let find = |n: &str| surfaces.iter().find(|s| s.name == n);
    let mut maps = MtlMaps {
        diffuse: surfaces.first().map(|s| file_name(&s.name, &s.extension)),
        ..Default::default()
    };
    maps.normal = find("normal").map(|s| file_name(&s.name, &s.extension));
    maps.roughness = find("roughness").map(|s| file_name(&s.name, &s.extension));
    maps.height = find("height").map(|s| file_name(&s.name, &s.extension));
    // The OBJ's text and the atlas are independent: made side by side.
    let density = p.texel_density;
    let (obj, atlas) = rayon::join(
        || write_obj(mesh, Some(&uv), Some("textured.mtl"), "texsyn").into_bytes(),
        || {
            let scaled: Vec<[Vec2; 3]> = layout.iter().map(|t| t.map(|q| q * density)).collect();
            build_chart_atlas(mesh, &scaled, p.atlas_size)
        },
    );
    files.push(("textured.obj".into(), obj));
    files.push((
        "textured.mtl".into(),
        write_mtl("texsyn", &maps).into_bytes(),
    ));
    for s in surfaces {
        files.push((file_name(&s.name, &s.extension), s.file.to_vec()));
    }
    let atlas = atlas.map_err(|e| ExportError::of_atlas(e, p))?;
    check_bake_memory(&atlas.pages, surfaces.len(), density)?;
    let pages = atlas.pages.len();
    tracing::info!(
        "reconstruct: {} charts on {pages} page(s) ({}) at {density} atlas texels per exemplar texel",
        atlas.charts,
        atlas
            .pages
            .iter()
            .map(|[w, h]| format!("{w}×{h}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    progress(0.15);
    lap("textured.obj and chart atlas");
    let frames = TangentFrames::new(mesh, single_set, &atlas.corner_uv);
    let mut materials: Vec<GlbMaterial> = Vec::with_capacity(pages);
    let mut baked_mtl = String::new();
    let names: Vec<String> = (0..pages)
        .map(|page| format!("texsyn_page{page}"))
        .collect();
    // `baked.obj` needs only the atlas's coordinates: its text is made beside the bake (whose
    // PNG encoding is sequential), not after it.
    let mut baked_obj = Vec::new();
    // Tangents only for a normal map, which is never the first surface (the base colour).
    let normal_map = surfaces.iter().skip(1).any(|s| s.name == "normal");
    // A normal map is baked against the .glb's own interpolated vertex frames (what a viewer
    // decodes it with), so those come first; without one the .glb's arrays are built beside
    // the bake.
    let first = normal_map.then(|| glb_mesh(mesh, &atlas, &frames, true));
    let mut beside = None;
    rayon::in_place_scope(|scope| {
        // Its materials are attached after the bake.
        if first.is_none() {
            scope.spawn(|_| beside = Some(glb_mesh(mesh, &atlas, &frames, false)));
        }
        scope.spawn(|_| {
            // OBJ texture coordinates have v up.
            let obj_uv: Vec<[Vec2; 3]> = atlas
                .corner_uv
                .iter()
                .map(|t| t.map(|q| Vec2::new(q.x, 1.0 - q.y)))
                .collect();
            baked_obj = write_obj_materials(
                mesh,
                Some(&obj_uv),
                Some("baked.mtl"),
                &names,
                Some(&atlas.face_page),
            )
            .into_bytes();
        });
        for page in 0..pages {
            let rebased = find("normal")
                .zip(first.as_ref())
                .map(|(s, (glb, corner_vertex))| NormalRebase {
                    inner: &s.shader,
                    exemplar: &frames.exemplar,
                    target: VertexFrames {
                        corner_vertex,
                        normals: &glb.normals,
                        tangents: &glb.tangents,
                    },
                });
            let shaders: Vec<&dyn SurfaceShader> = surfaces
                .iter()
                .map(|s| match (&rebased, s.name.as_str()) {
                    (Some(r), "normal") => r as &dyn SurfaceShader,
                    _ => &s.shader as &dyn SurfaceShader,
                })
                .collect();
            let baked = bake_page(&atlas, page, mesh, &shaders);
            let mut material = GlbMaterial {
                name: names[page].clone(),
                double_sided: true,
                ..Default::default()
            };
            let mut page_maps = MtlMaps::default();
            for (k, (s, img)) in surfaces.iter().zip(baked).enumerate() {
                let png = encode_png(&img, false);
                let name = baked_name(&s.name, page, pages);
                match s.name.as_str() {
                    _ if k == 0 => {
                        material.base_color_png = Some(png.clone());
                        page_maps.diffuse = Some(name.clone());
                    }
                    "normal" => {
                        material.normal_png = Some(png.clone());
                        page_maps.normal = Some(name.clone());
                    }
                    "roughness" => {
                        // glTF reads roughness from green and metalness from blue.
                        let mut mr = img;
                        for px in mr.pixels_mut() {
                            px.0 = [0, px.0[0], 0, 255];
                        }
                        material.metallic_roughness_png = Some(encode_png(&mr, false));
                        page_maps.roughness = Some(name.clone());
                    }
                    "height" => page_maps.height = Some(name.clone()),
                    _ => {}
                }
                files.push((name, png));
            }
            baked_mtl.push_str(&write_mtl(&material.name, &page_maps));
            materials.push(material);
            progress(0.15 + 0.55 * (page + 1) as f32 / pages as f32);
            lap("page baked and encoded");
        }
    });
    lap("baked.obj");
    // A .glb holds at most 4 GiB (32-bit lengths): refuse rather than write a broken file.
    let textures: usize = materials
        .iter()
        .flat_map(|m| [&m.base_color_png, &m.normal_png, &m.metallic_roughness_png])
        .map(|png| png.as_ref().map_or(0, |b| b.len()))
        .sum();
    let arrays = mesh.triangles.len() * 3 * (12 + 12 + 16 + 8 + 4);
    if (textures + arrays) as u64 > u32::MAX as u64 - (64 << 20) {
        return Err(ExportError::Atlas(format!(
            "reconstruct.texel_density = {}: the .glb would hold {:.1} GiB of textures and arrays, \
             more than a .glb can (4 GiB); use a lower reconstruct.texel_density",
            p.texel_density,
            (textures + arrays) as f64 / (1u64 << 30) as f64
        )));
    }
    files.push(("baked.obj".into(), baked_obj));
    files.push(("baked.mtl".into(), baked_mtl.into_bytes()));
    let (mut glb, _) = first.or(beside).unwrap_or_default();
    files.push(("textured.glb".into(), {
        attach_materials(&mut glb, materials);
        write_glb(&glb)
    }));
    progress(0.95);
    lap("textured.glb");
    Ok(files)
}

/// Per face: the exemplar's tangent frame (texel x right, texel y *up*, as tangent-space
/// normal maps are drawn) and the atlas's (glTF: u right, image up = −v), both unit and
/// orthogonal to the face normal.
struct TangentFrames {
    exemplar: Vec<(Vec3, Vec3, Vec3)>,
    atlas: Vec<(Vec3, Vec3)>,
}

/// The directions on a triangle along which the two coordinates of a 2D map increase.
fn gradient_frame(p: [Vec3; 3], t: [Vec2; 3]) -> Option<(Vec3, Vec3)> {
    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
    let (d1, d2) = (t[1] - t[0], t[2] - t[0]);
    let det = d1.x * d2.y - d2.x * d1.y;
    if det.abs() < 1e-20 {
        return None;
    }
    let tx = (e1 * d2.y - e2 * d1.y) / det;
    let ty = (e2 * d1.x - e1 * d2.x) / det;
    Some((tx, ty))
}

impl TangentFrames {
    fn new(mesh: &Mesh, set: &[[Vec2; 3]], atlas_uv: &[[Vec2; 3]]) -> Self {
        use rayon::prelude::*;
        let (exemplar, atlas) = mesh
            .triangles
            .par_iter()
            .enumerate()
            .map(|(f, t)| {
                let p = t.map(|v| mesh.positions[v as usize]);
                let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
                let ortho = |a: Vec3, b: Vec3| -> (Vec3, Vec3) {
                    let a = (a - a.dot(n) * n).normalize_or_zero();
                    let b = (b - b.dot(n) * n - (b.dot(a)) * a).normalize_or_zero();
                    (a, b)
                };
                // Texel y points down the image; normal maps' +Y points up it.
                let (ex, ey) = gradient_frame(p, set[f])
                    .map(|(x, y)| ortho(x, -y))
                    .unwrap_or((Vec3::ZERO, Vec3::ZERO));
                let atlas = gradient_frame(p, atlas_uv[f])
                    .map(|(x, y)| ortho(x, -y))
                    .unwrap_or((Vec3::ZERO, Vec3::ZERO));
                ((ex, ey, n), atlas)
            })
            .unzip();
        TangentFrames { exemplar, atlas }
    }
}

/// The .glb's per-vertex shading frames, looked up through each face corner's vertex.
struct VertexFrames<'a> {
    corner_vertex: &'a [u32],
    normals: &'a [Vec3],
    /// glTF tangents: `xyz` and the bitangent's sign `w` (bitangent = w · normal × tangent).
    tangents: &'a [Vec4],
}

impl VertexFrames<'_> {
    /// The orthonormal frame (tangent, bitangent, normal) interpolated at `bary` of `face`, as
    /// a viewer decodes a tangent-space normal map with: the corners' normals and tangents
    /// interpolated and normalized, the tangent made orthogonal to the normal, the bitangent
    /// from the corners' sign. `None` where the frame degenerates.
    fn at(&self, face: usize, bary: Vec3) -> Option<(Vec3, Vec3, Vec3)> {
        let corner = |k: usize| Some(*self.corner_vertex.get(3 * face + k)? as usize);
        let (mut n, mut t, mut w) = (Vec3::ZERO, Vec3::ZERO, 0.0f32);
        for k in 0..3 {
            let v = corner(k)?;
            n += bary[k] * *self.normals.get(v)?;
            let tw = *self.tangents.get(v)?;
            t += bary[k] * tw.truncate();
            w += bary[k] * tw.w;
        }
        let n = n.try_normalize()?;
        let t = (t - t.dot(n) * n).try_normalize()?;
        let b = if w < 0.0 { -1.0 } else { 1.0 } * n.cross(t);
        Some((t, b, n))
    }
}

/// Re-expresses a tangent-space normal map sampled in the exemplar's frame in the frame the
/// .glb's vertices give each texel. The exemplar's normal perturbs the *interpolated* normal
/// (a flat map leaves the smooth shading as it is), and the result is written in that same
/// interpolated frame, so a viewer decoding the page with the .glb's normals and tangents gets
/// back the intended normal, inside charts and across their borders alike.
struct NormalRebase<'a, S: SurfaceShader> {
    inner: &'a S,
    /// Per face: the exemplar's texel x, texel y (up) and the face normal.
    exemplar: &'a [(Vec3, Vec3, Vec3)],
    target: VertexFrames<'a>,
}

impl<S: SurfaceShader> SurfaceShader for NormalRebase<'_, S> {
    fn albedo(&self, face: usize, bary: Vec3) -> Vec3 {
        let c = self.inner.albedo(face, bary);
        let Some(&(ex, ey, _)) = self.exemplar.get(face) else {
            return c;
        };
        let Some((tx, ty, n)) = self.target.at(face, bary) else {
            return c;
        };
        // The exemplar's axes in the plane of the interpolated normal.
        let Some(ex) = (ex - ex.dot(n) * n).try_normalize() else {
            return c;
        };
        let Some(ey) = (ey - ey.dot(n) * n - ey.dot(ex) * ex).try_normalize() else {
            return c;
        };
        let t = c * 2.0 - Vec3::ONE;
        let world = t.x * ex + t.y * ey + t.z * n;
        let local = Vec3::new(world.dot(tx), world.dot(ty), world.dot(n)).normalize_or_zero();
        (local + Vec3::ONE) * 0.5
    }
}

/// The .glb's mesh: one vertex per (mesh vertex, atlas coordinates) pair, so vertices are
/// shared inside charts and split along their borders; the tangent of a vertex is the mean of
/// its faces' atlas frames (smooth inside a chart, as normal-mapped meshes expect); one
/// primitive per page.
///
/// Also returns each face corner's vertex (`3 · face + corner`).
fn glb_mesh(
    mesh: &Mesh,
    atlas: &ChartAtlas,
    frames: &TangentFrames,
    want_tangents: bool,
) -> (GlbMesh, Vec<u32>) {
    let normals = mesh.vertex_normals();
    let faces = mesh.triangles.len();
    // Corners sorted by (vertex, uv bits): equal keys share one glTF vertex.
    let mut corners: Vec<(u32, u32, u32, u32)> = (0..faces * 3)
        .map(|c| {
            let (f, k) = (c / 3, c % 3);
            let uv = atlas.corner_uv[f][k];
            (
                mesh.triangles[f][k],
                uv.x.to_bits(),
                uv.y.to_bits(),
                c as u32,
            )
        })
        .collect();
    {
        use rayon::prelude::*;
        corners.par_sort_unstable();
    }
    let mut corner_vertex = vec![0u32; faces * 3];
    // Sized exactly: a million-triangle mesh's arrays are tens of MB each, and regrowing them
    // copies into fresh memory.
    let key = |c: &(u32, u32, u32, u32)| (c.0, c.1, c.2);
    let vertices = corners.len().min(1)
        + corners
            .windows(2)
            .filter(|w| key(&w[0]) != key(&w[1]))
            .count();
    let mut positions = Vec::with_capacity(vertices);
    let mut vnormals = Vec::with_capacity(vertices);
    let mut tangent_sum: Vec<Vec3> = Vec::with_capacity(vertices);
    let mut handedness: Vec<f32> = Vec::with_capacity(vertices);
    let mut uv = Vec::with_capacity(vertices);
    let mut i = 0;
    while i < corners.len() {
        let (v, ux, uy, _) = corners[i];
        let id = positions.len() as u32;
        let vu = v as usize;
        let n_face = frames.exemplar[corners[i].3 as usize / 3].2;
        let n = if normals[vu] != Vec3::ZERO {
            normals[vu]
        } else {
            n_face
        };
        positions.push(mesh.positions[vu]);
        vnormals.push(n);
        uv.push(Vec2::new(f32::from_bits(ux), f32::from_bits(uy)));
        let mut tsum = Vec3::ZERO;
        let mut wsum = 0.0f32;
        while i < corners.len() && (corners[i].0, corners[i].1, corners[i].2) == (v, ux, uy) {
            let c = corners[i].3 as usize;
            corner_vertex[c] = id;
            let (ax, ay) = frames.atlas[c / 3];
            let tan = (ax - ax.dot(n) * n).normalize_or_zero();
            tsum += tan;
            // glTF: bitangent = cross(normal, tangent.xyz) * w.
            wsum += if n.cross(tan).dot(ay) < 0.0 {
                -1.0
            } else {
                1.0
            };
            i += 1;
        }
        tangent_sum.push(tsum);
        handedness.push(if wsum < 0.0 { -1.0 } else { 1.0 });
    }
    // Tangents only matter to a normal map (the validator flags unused ones).
    let tangents = if want_tangents {
        tangent_sum
            .iter()
            .zip(&handedness)
            .map(|(t, &w)| {
                let t = t.normalize_or_zero();
                if t == Vec3::ZERO {
                    Vec4::new(1.0, 0.0, 0.0, 1.0)
                } else {
                    t.extend(w)
                }
            })
            .collect()
    } else {
        Vec::new()
    };
    let mut on_page = vec![0usize; atlas.pages.len().max(1)];
    for &page in &atlas.face_page[..faces] {
        on_page[page as usize] += 3;
    }
    let mut per_page: Vec<Vec<u32>> = on_page.iter().map(|&n| Vec::with_capacity(n)).collect();
    for f in 0..faces {
        let page = atlas.face_page[f] as usize;
        per_page[page].extend_from_slice(&corner_vertex[3 * f..3 * f + 3]);
    }
    let mut pages = per_page.into_iter();
    let indices = pages.next().unwrap_or_default();
    let glb = GlbMesh {
        name: "texsyn".into(),
        positions,
        normals: vnormals,
        tangents,
        texcoords: vec![uv],
        colors: None,
        extra: Vec::new(),
        indices,
        material: GlbMaterial::default(),
        more_primitives: pages
            .map(|indices| GlbPrimitive {
                indices,
                material: GlbMaterial::default(),
            })
            .collect(),
    };
    (glb, corner_vertex)
}

/// Gives the .glb's primitives (one per page, in page order) their baked materials.
fn attach_materials(glb: &mut GlbMesh, materials: Vec<GlbMaterial>) {
    let mut materials = materials.into_iter();
    glb.material = materials.next().unwrap_or_default();
    for (primitive, material) in glb.more_primitives.iter_mut().zip(materials) {
        primitive.material = material;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::shader::ConstantShader;
    use texsyn_core::math::PureMath;

    /// One triangle in the xy plane (normal +z).
    fn triangle() -> Mesh {
        Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]])
    }

    /// The exemplar frame of `triangle()` used below: texel x along world +x, texel y (down)
    /// along world −y, so the normal map's +Y (up the image) is world +y.
    fn exemplar_set() -> Vec<[Vec2; 3]> {
        vec![[
            Vec2::new(0.0, 10.0),
            Vec2::new(10.0, 10.0),
            Vec2::new(0.0, 0.0),
        ]]
    }

    fn rebase(frames: &TangentFrames, target: VertexFrames<'_>, tilt: Vec3, bary: Vec3) -> Vec3 {
        let inner = ConstantShader((tilt + Vec3::ONE) * 0.5);
        NormalRebase {
            inner: &inner,
            exemplar: &frames.exemplar,
            target,
        }
        .albedo(0, bary)
            * 2.0
            - Vec3::ONE
    }

    #[test]
    fn normal_maps_are_turned_from_the_exemplar_frame_into_the_glb_frame() {
        let mesh = triangle();
        // Atlas: u along world +y, v (down the image) along world +x: image up is world -x.
        let atlas_uv = vec![[
            Vec2::new(0.0, 0.0),
            Vec2::new(0.0, 0.5),
            Vec2::new(0.5, 0.0),
        ]];
        let frames = TangentFrames::new(&mesh, &exemplar_set(), &atlas_uv);
        // The .glb's frames of a flat triangle: normal +z, tangent (u) world +y; image up
        // (bitangent) is world -x = +z × +y, so w = +1.
        let (normals, tangents) = (vec![Vec3::Z; 3], vec![Vec4::new(0.0, 1.0, 0.0, 1.0); 3]);
        let target = || VertexFrames {
            corner_vertex: &[0, 1, 2],
            normals: &normals,
            tangents: &tangents,
        };
        // A normal tilted towards exemplar +X, i.e. world +x.
        let local = rebase(
            &frames,
            target(),
            Vec3::new(0.6, 0.0, 0.8),
            Vec3::splat(1.0 / 3.0),
        );
        // World +x is atlas -Y (image up is world -x) and has no atlas X component.
        assert!(
            (local - Vec3::new(0.0, -0.6, 0.8)).length() < 1e-5,
            "{local}"
        );
    }

    #[test]
    fn a_viewer_decoding_the_page_with_the_glb_frames_gets_the_intended_normal() {
        // Smooth shading: the three vertex normals lean apart (a patch of a sphere), and the
        // tangents turn with them, so no texel's frame is the face's own. Both handednesses
        // (w = −1: a mirrored chart).
        let mesh = triangle();
        let frames = TangentFrames::new(&mesh, &exemplar_set(), &exemplar_set());
        let normals = vec![
            Vec3::new(-0.3, -0.3, 1.0).normalize(),
            Vec3::new(0.4, -0.1, 1.0).normalize(),
            Vec3::new(-0.1, 0.4, 1.0).normalize(),
        ];
        for w in [1.0f32, -1.0] {
            let tangents: Vec<Vec4> = normals
                .iter()
                .zip([0.0f32, 0.3, -0.3])
                .map(|(n, turn)| {
                    let t = Vec3::new(turn.cos_pure(), turn.sin_pure(), 0.0);
                    (t - t.dot(*n) * *n).normalize().extend(w)
                })
                .collect();
            let target = || VertexFrames {
                corner_vertex: &[0, 1, 2],
                normals: &normals,
                tangents: &tangents,
            };
            let tilt = Vec3::new(0.48, -0.36, 0.8);
            for bary in [
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(0.0, 1.0, 0.0),
                Vec3::new(0.2, 0.3, 0.5),
                Vec3::splat(1.0 / 3.0),
            ] {
                let local = rebase(&frames, target(), tilt, bary);
                // What was meant: the exemplar's tilt around the interpolated normal, along
                // the exemplar's axes (world +x, +y) laid into that normal's plane.
                let n = (0..3)
                    .map(|k| bary[k] * normals[k])
                    .sum::<Vec3>()
                    .normalize();
                let ex = (Vec3::X - Vec3::X.dot(n) * n).normalize();
                let ey = (Vec3::Y - Vec3::Y.dot(n) * n - Vec3::Y.dot(ex) * ex).normalize();
                let meant = (tilt.x * ex + tilt.y * ey + tilt.z * n).normalize();
                // Decoded in the frame the bake used: exactly what was meant.
                let (t, b, n2) = target().at(0, bary).unwrap();
                let exact = local.x * t + local.y * b + local.z * n2;
                assert!(
                    (exact - meant).length() < 1e-5,
                    "w {w} at {bary}: {exact} vs {meant}"
                );
                // Decoded as the glTF sample viewer does, from the vertex arrays alone: the
                // corners' tangent, bitangent (w · n × t) and normal interpolated and
                // normalized, not made orthogonal again. The same to second order.
                let lerp = |f: &dyn Fn(usize) -> Vec3| {
                    (0..3).map(|k| bary[k] * f(k)).sum::<Vec3>().normalize()
                };
                let vt = lerp(&|k| tangents[k].truncate());
                let vb = lerp(&|k| w * normals[k].cross(tangents[k].truncate()));
                let vn = lerp(&|k| normals[k]);
                let shown = (local.x * vt + local.y * vb + local.z * vn).normalize();
                assert!(
                    (shown - meant).length() < 0.02,
                    "w {w} at {bary}: shown {shown}, meant {meant}"
                );
                // A flat map keeps the smooth shading.
                let flat = rebase(&frames, target(), Vec3::Z, bary);
                assert!((flat - Vec3::Z).length() < 1e-5, "at {bary}: {flat}");
            }
        }
    }

    #[test]
    fn params_out_of_range_are_named() {
        // The defaults with one field changed: the error names it, its range and its value.
        let error = |change: fn(&mut ExportParams)| {
            let mut p = ExportParams::default();
            change(&mut p);
            p.validate().unwrap_err().to_string()
        };
        assert_eq!(
            error(|p| p.atlas_size = 10),
            "reconstruct.atlas_size must be in 64..=8192, got 10"
        );
        assert_eq!(
            error(|p| p.up = UpAxis::Given([0.0; 3])),
            "reconstruct.up must be a finite non-zero vector or \"auto\", got [0.0, 0.0, 0.0]"
        );
    }
}
