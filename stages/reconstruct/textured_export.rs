//! Exports of a mesh textured from an exemplar: what a user opens.
//!
//! - `textured.obj` + `textured.mtl` + the exemplar (`texture.<ext>`) and aligned maps
//!   (`<name>.<ext>`): one set of corner coordinates into the exemplar itself, so no new
//!   texture memory is needed (the paper's point), at the price of visible patch seams in
//!   ordinary viewers that cannot blend three coordinate sets.
//! - `textured.glb`: the blended result baked into a per-triangle atlas (`baked_<map>.png`),
//!   with the normal map re-expressed in the atlas's tangent frames and the roughness map in
//!   glTF's metallic-roughness slot, so Blender and three.js show what texsyn renders.
//! - `preview.png`: three views drawn with the blending shader by texsyn's rasterizer.
//!
//! Surfaces are exported in the order given; the first is the base colour.

use crate::check::{ParamError, check_range};
use crate::export::glb::{GlbMaterial, GlbMesh, write_glb};
use crate::export::obj::{MtlMaps, write_mtl, write_obj};
use crate::geom::Mesh;
use crate::image::texel_to_uv;
use crate::render::atlas::{Atlas, AtlasError, bake, build_atlas};
use crate::render::shader::SurfaceShader;
use crate::render::views::{ViewOptions, render_views};
use glam::{Vec2, Vec3, Vec4};
use serde::{Deserialize, Serialize};

/// `[reconstruct]` parameters of textured-mesh exports.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExportParams {
    /// Side of the baked atlas textures in the .glb, 64..=8192. Default: 2048.
    pub atlas_size: u32,
    /// Side of each of the three preview views, 16..=4096. Default: 512.
    pub preview_size: u32,
    /// The mesh's up direction, for the preview. Default: [0, 1, 0].
    pub up: [f32; 3],
}

impl Default for ExportParams {
    fn default() -> Self {
        ExportParams {
            atlas_size: 2048,
            preview_size: 512,
            up: [0.0, 1.0, 0.0],
        }
    }
}

impl ExportParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("reconstruct.atlas_size", self.atlas_size, 64, 8192)?;
        check_range("reconstruct.preview_size", self.preview_size, 16, 4096)?;
        let up = Vec3::from(self.up);
        if !up.is_finite() || up.length() < 1e-12 {
            return Err(ParamError::invalid(
                "reconstruct.up",
                format!("must be a finite non-zero vector, got {:?}", self.up),
            ));
        }
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

/// Why the export files could not be built.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The mesh does not fit an atlas of `reconstruct.atlas_size`.
    #[error("reconstruct.atlas_size: {0}")]
    Atlas(#[from] AtlasError),
}

/// Builds every export file. `single_set` holds one corner-coordinate set per face in texel
/// addresses of an exemplar of size `exemplar` (for the OBJ).
pub fn export_textured_mesh<S: SurfaceShader>(
    mesh: &Mesh,
    single_set: &[[Vec2; 3]],
    exemplar: (u32, u32),
    surfaces: &[ExportSurface<S>],
    p: &ExportParams,
    progress: &dyn Fn(f32),
) -> Result<Vec<(String, Vec<u8>)>, ExportError> {
    let mut files: Vec<(String, Vec<u8>)> = Vec::new();
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
    files.push((
        "textured.obj".into(),
        write_obj(mesh, Some(&uv), Some("textured.mtl"), "texsyn").into_bytes(),
    ));
    files.push((
        "textured.mtl".into(),
        write_mtl("texsyn", &maps).into_bytes(),
    ));
    for s in surfaces {
        files.push((file_name(&s.name, &s.extension), s.file.to_vec()));
    }
    progress(0.05);

    let atlas = build_atlas(mesh, p.atlas_size)?;
    let frames = TangentFrames::new(mesh, single_set, &atlas);
    let mut material = GlbMaterial {
        double_sided: true,
        ..Default::default()
    };
    for (k, s) in surfaces.iter().enumerate() {
        let baked = if s.name == "normal" {
            bake(
                &atlas,
                mesh,
                &NormalRebase {
                    inner: &s.shader,
                    frames: &frames,
                },
            )
        } else {
            bake(&atlas, mesh, &s.shader)
        };
        let png = encode_png(&baked, false);
        match s.name.as_str() {
            _ if k == 0 => material.base_color_png = Some(png.clone()),
            "normal" => material.normal_png = Some(png.clone()),
            "roughness" => {
                // glTF reads roughness from green and metalness from blue.
                let mut mr = baked.clone();
                for px in mr.pixels_mut() {
                    px.0 = [0, px.0[0], 0, 255];
                }
                material.metallic_roughness_png = Some(encode_png(&mr, false));
            }
            _ => {}
        }
        files.push((format!("baked_{}.png", s.name), png));
        progress(0.1 + 0.6 * (k + 1) as f32 / surfaces.len() as f32);
    }
    files.push((
        "textured.glb".into(),
        write_glb(&glb_mesh(mesh, &atlas, &frames, material)),
    ));
    progress(0.75);

    if let Some(base) = surfaces.first() {
        let opts = ViewOptions {
            size: p.preview_size,
            up: Vec3::from(p.up),
            ..Default::default()
        };
        let preview = render_views(mesh, &base.shader, &opts);
        files.push(("preview.png".into(), encode_png(&preview, false)));
    }
    progress(1.0);
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
    fn new(mesh: &Mesh, set: &[[Vec2; 3]], atlas: &Atlas) -> Self {
        let mut exemplar = Vec::with_capacity(mesh.triangles.len());
        let mut at = Vec::with_capacity(mesh.triangles.len());
        for (f, t) in mesh.triangles.iter().enumerate() {
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
            exemplar.push((ex, ey, n));
            let (ax, ay) = gradient_frame(p, atlas.corner_uv[f])
                .map(|(x, y)| ortho(x, -y))
                .unwrap_or((Vec3::ZERO, Vec3::ZERO));
            at.push((ax, ay));
        }
        TangentFrames {
            exemplar,
            atlas: at,
        }
    }
}

/// Re-expresses a tangent-space normal map sampled in the exemplar's frame in the atlas's.
struct NormalRebase<'a, S: SurfaceShader> {
    inner: &'a S,
    frames: &'a TangentFrames,
}

impl<S: SurfaceShader> SurfaceShader for NormalRebase<'_, S> {
    fn albedo(&self, face: usize, bary: Vec3) -> Vec3 {
        let c = self.inner.albedo(face, bary);
        let (ex, ey, n) = self.frames.exemplar[face];
        let (ax, ay) = self.frames.atlas[face];
        if ex == Vec3::ZERO || ax == Vec3::ZERO {
            return c;
        }
        let t = c * 2.0 - Vec3::ONE;
        let world = t.x * ex + t.y * ey + t.z * n;
        let local = Vec3::new(world.dot(ax), world.dot(ay), world.dot(n)).normalize_or_zero();
        (local + Vec3::ONE) * 0.5
    }
}

fn glb_mesh(mesh: &Mesh, atlas: &Atlas, frames: &TangentFrames, material: GlbMaterial) -> GlbMesh {
    let normals = mesh.vertex_normals();
    let corners = mesh.triangles.len() * 3;
    let mut positions = Vec::with_capacity(corners);
    let mut vnormals = Vec::with_capacity(corners);
    // Tangents only matter to a normal map (the validator flags unused ones).
    let want_tangents = material.normal_png.is_some();
    let mut tangents = Vec::with_capacity(if want_tangents { corners } else { 0 });
    let mut uv = Vec::with_capacity(corners);
    for (f, t) in mesh.triangles.iter().enumerate() {
        let (ax, ay) = frames.atlas[f];
        let n_face = frames.exemplar[f].2;
        for c in 0..3 {
            let v = t[c] as usize;
            positions.push(mesh.positions[v]);
            let n = if normals[v] != Vec3::ZERO {
                normals[v]
            } else {
                n_face
            };
            vnormals.push(n);
            // glTF: bitangent = cross(normal, tangent.xyz) * w.
            let tan = (ax - ax.dot(n) * n).normalize_or_zero();
            let w = if n.cross(tan).dot(ay) < 0.0 {
                -1.0
            } else {
                1.0
            };
            tangents.push(if tan == Vec3::ZERO {
                Vec4::new(1.0, 0.0, 0.0, 1.0)
            } else {
                tan.extend(w)
            });
            uv.push(atlas.corner_uv[f][c]);
        }
    }
    GlbMesh {
        name: "texsyn".into(),
        positions,
        normals: vnormals,
        tangents,
        texcoords: vec![uv],
        colors: None,
        extra: Vec::new(),
        indices: (0..corners as u32).collect(),
        material,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::shader::ConstantShader;

    /// One triangle in the xy plane (normal +z).
    fn triangle() -> Mesh {
        Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]])
    }

    #[test]
    fn normal_maps_are_turned_from_the_exemplar_frame_into_the_atlas_frame() {
        let mesh = triangle();
        // Exemplar: texel x along world +x, texel y (down) along world -y, so the normal
        // map's +Y (up the image) is world +y.
        let set = vec![[
            Vec2::new(0.0, 10.0),
            Vec2::new(10.0, 10.0),
            Vec2::new(0.0, 0.0),
        ]];
        // Atlas: u along world +y, v (down the image) along world +x: image up is world -x.
        let atlas = Atlas {
            size: 64,
            corner_uv: vec![[
                Vec2::new(0.0, 0.0),
                Vec2::new(0.0, 0.5),
                Vec2::new(0.5, 0.0),
            ]],
        };
        let frames = TangentFrames::new(&mesh, &set, &atlas);
        // A normal tilted towards exemplar +X, i.e. world +x.
        let tilt = Vec3::new(0.6, 0.0, 0.8);
        let inner = ConstantShader((tilt + Vec3::ONE) * 0.5);
        let rebased = NormalRebase {
            inner: &inner,
            frames: &frames,
        }
        .albedo(0, Vec3::splat(1.0 / 3.0));
        let local = rebased * 2.0 - Vec3::ONE;
        // World +x is atlas -Y (image up is world -x) and has no atlas X component.
        assert!(
            (local - Vec3::new(0.0, -0.6, 0.8)).length() < 1e-5,
            "{local}"
        );
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
            error(|p| p.up = [0.0; 3]),
            "reconstruct.up must be a finite non-zero vector, got [0.0, 0.0, 0.0]"
        );
    }
}
