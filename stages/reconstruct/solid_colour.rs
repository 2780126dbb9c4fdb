//! What a user sees of a solid texture (Zhang, Du, Lai, Ni & Hu, "Sketch guided solid
//! texturing", §2, Fig. 3c–d: the solid "on the bounding surface … or in the interior on
//! demand"; §6: surfaces, new cuts, and regions with their own exemplars, Fig. 15).
//!
//! A synthesized voxel holds a finest-level triple: three texels, one per plane of its local
//! frame; with regions, every set's triples at the voxels it owns ([`VoxelTriples`]). What a
//! surface or cut shows of a voxel is [`SolidColourRule`]'s choice: by default the texels of
//! the planes that face the viewing surface, weighted by how squarely they face it (a cut
//! along a plane of the frame shows that plane's exemplar); or the plane-weighted mean of the
//! three texels (§4.3's voxel colour). From those colours [`export_solid`] writes, by request:
//!
//! - the surface: the mesh refined until its edges are about `edge_voxels` voxels long, with a
//!   colour per vertex (`solid_surface.ply`), the original mesh with a baked texture
//!   (`solid_surface.glb`, `baked_surface.png`; when the per-triangle atlas cannot hold the
//!   mesh, the .glb is the refined surface with its vertex colours and there is no bake) and
//!   a preview of the coloured surface;
//! - a section: the cut as an image, one pixel per sample of the plane (`section.png`);
//! - a box: the voxels as raw RGB with a JSON header, the same voxels as a multi-part
//!   OpenEXR (one part per z-slice, `volume.exr`) that image tools open directly, and its
//!   middle z-slice as a PNG.
//!
//! Departures: the paper renders the solid texture per pixel; here a surface point takes the
//! colour of the voxel it lies in (or of the nearest synthesized voxel around it, for points
//! the surface sampling left at a voxel's edge), so the refined surface and the bake show the
//! voxels themselves. And the paper's voxel colour is the mean of its three texels, which
//! averages three unrelated exemplar texels wherever the triple is not consistent across its
//! planes: on marble1 a z-cut kept 14 % of the exemplar's gradient energy and showed no vein,
//! where the facing rule (with `synthesize.neighbourhood_colour = "plane"`) keeps it all
//! (BENCHMARKS.md). A box has no surface to face: its voxels take the mean under either rule.

use crate::analyse_exemplar::candidate_triples::{SolidAnalysisRef, Triple};
use crate::check::{ParamError, check_range};
use crate::field::quaternion_field::RotationField;
use crate::geom::Mesh;
use crate::parameterize::volume_embedding::{Request, Section, Volume};
use crate::reconstruct::textured_export::encode_png;
use crate::render::up_axis::UpAxis;
use crate::render::{AtlasError, MAX_ATLAS_SIZE};
use glam::{IVec3, Mat3, Vec3};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use texsyn_core::algorithm::Failure;

/// The `solid_colour` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("solid_colour", 4);

/// `[reconstruct]` of the solid method.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct SolidExportParams {
    /// Side of each preview view, 16..=4096. Default: 512.
    pub preview_size: u32,
    /// The mesh's up direction in the previews, or `"auto"` (the default): guessed from the
    /// mesh, the side it stands on most steadily ([`crate::render::up_axis`]). Left out of the
    /// node's key when `"auto"`.
    #[serde(skip_serializing_if = "UpAxis::is_auto")]
    pub up: UpAxis,
    /// Side of the baked texture in the .glb, 64..=8192. Default: 2048.
    pub atlas_size: u32,
    /// The surface is refined until its edges are at most this many voxels long (so every
    /// voxel's colour shows), 0.5..=16. Default: 1.5.
    pub edge_voxels: f32,
    /// Cap on the refined surface's triangles. Default: 2 000 000.
    pub max_faces: u32,
    /// What a surface or cut shows of a voxel's three texels. Default: `facing`.
    pub colour: SolidColourRule,
}

/// How a voxel's three texels (one per plane of its local frame) make the colour a surface or
/// cut shows there.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SolidColourRule {
    /// The texels of the planes facing the surface, weighted by the plane weights times
    /// `|n · normal of the plane|⁸` (the power keeps the blend to a narrow band around the
    /// diagonals, where two planes face the surface equally): a cut along a plane of the frame
    /// shows that plane's texel alone. A cut along a plane of weight 0 (x for the wood layers'
    /// `[1, 0, 1]`) shows the other two planes blended by how nearly they face it. Boxes,
    /// having no surface, take the mean.
    Facing,
    /// The plane-weighted mean of the three texels (§4.3's voxel colour) everywhere.
    Mean,
}

impl Default for SolidExportParams {
    fn default() -> Self {
        SolidExportParams {
            preview_size: 512,
            up: UpAxis::default(),
            atlas_size: 2048,
            edge_voxels: 1.5,
            max_faces: 2_000_000,
            colour: SolidColourRule::Facing,
        }
    }
}

impl SolidExportParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("reconstruct.preview_size", self.preview_size, 16, 4096)?;
        self.up
            .check()
            .map_err(|m| ParamError::invalid("reconstruct.up", m))?;
        check_range(
            "reconstruct.atlas_size",
            self.atlas_size,
            64,
            MAX_ATLAS_SIZE,
        )?;
        check_range("reconstruct.edge_voxels", self.edge_voxels, 0.5, 16.0)
    }
}

/// Why a solid could not be exported.
#[derive(Debug, thiserror::Error)]
pub enum SolidExportError {
    #[error("reconstruct.atlas_size: {0}")]
    Atlas(#[from] AtlasError),
    #[error("volume.exr: {0}")]
    Exr(#[from] crate::export::exr::ExrError),
}

/// The finest-level triples of the synthesized voxels, from one exemplar set or several (the
/// regions, each at the voxels it owns), with what turns a triple into a colour: each set's
/// analysis, the field's frames and the colour rule.
pub struct VoxelTriples<'a> {
    /// Voxel → (index of its set in `sets`, triple).
    triples: HashMap<IVec3, (u8, Triple)>,
    sets: Vec<SolidAnalysisRef<'a>>,
    field: &'a RotationField,
    volume: &'a Volume,
    rule: SolidColourRule,
}

impl<'a> VoxelTriples<'a> {
    pub fn new(field: &'a RotationField, volume: &'a Volume, rule: SolidColourRule) -> Self {
        VoxelTriples {
            triples: HashMap::new(),
            sets: Vec::new(),
            field,
            volume,
            rule,
        }
    }

    /// Adds one exemplar set's finest-level `triples` at `voxels` (at most 256 sets).
    pub fn add(&mut self, voxels: &[[i32; 3]], triples: &[Triple], analysis: SolidAnalysisRef<'a>) {
        let set = self.sets.len() as u8;
        self.sets.push(analysis);
        self.triples.extend(
            voxels
                .iter()
                .zip(triples)
                .map(|(v, t)| (IVec3::from(*v), (set, *t))),
        );
    }

    pub fn contains(&self, v: IVec3) -> bool {
        self.triples.contains_key(&v)
    }

    /// The colour voxel `v` shows on a surface of unit normal `normal` (`None`: no surface,
    /// the mean), if it was synthesized.
    pub fn colour(&self, v: IVec3, normal: Option<Vec3>) -> Option<[f32; 3]> {
        let &(set, t) = self.triples.get(&v)?;
        let a = &self.sets[set as usize];
        let finest = a.levels() as usize - 1;
        let normal = match (self.rule, normal) {
            (SolidColourRule::Facing, Some(n)) => n,
            _ => return Some(a.colour(finest, &t)),
        };
        let frame = Mat3::from_quat(self.field.rotation_at(self.volume.centre(v)));
        let w = facing_weights(frame, a.weights(), normal);
        let total: f32 = w.iter().sum();
        if total <= f32::MIN_POSITIVE {
            // No weighted plane faces the surface at all (its normal lies in the one plane of
            // weight 0, to the last bit).
            return Some(a.colour(finest, &t));
        }
        let mut acc = [0.0f32; 3];
        for p in 0..3 {
            if w[p] > 0.0 {
                let c = a.texel(finest, a.image_of(p), t.c[p]);
                for ch in 0..3 {
                    acc[ch] += w[p] * c[ch];
                }
            }
        }
        Some(acc.map(|x| x / total))
    }
}

/// [`SolidColourRule::Facing`]'s weight of each plane `p` of `frame` (spanned by its columns
/// `p` and `p + 1`, so facing along column `p + 2`) for a surface of unit normal `n`:
/// `plane_weights[p] · |n · frame column (p + 2)|⁸`.
fn facing_weights(frame: Mat3, plane_weights: [f32; 3], n: Vec3) -> [f32; 3] {
    std::array::from_fn(|p| {
        let c = n.dot(frame.col((p + 2) % 3)).abs();
        let c2 = c * c;
        let c4 = c2 * c2;
        plane_weights[p] * c4 * c4
    })
}

/// What to export: the kind of request, with what each kind needs.
pub enum SolidOutput<'a> {
    /// A surface request: the mesh whose surface was requested.
    Surface(&'a Mesh),
    /// A section request: the section's sample grid.
    Section(&'a Section),
    /// A box request: the box's voxels.
    Box(&'a [IVec3]),
}

impl<'a> SolidOutput<'a> {
    /// What `request` asks for; `None` for a section request without its grid.
    pub fn of(
        request: &Request,
        mesh: &'a Mesh,
        section: Option<&'a Section>,
        voxels: &'a [IVec3],
    ) -> Option<SolidOutput<'a>> {
        Some(match request {
            Request::Surface => SolidOutput::Surface(mesh),
            Request::Section { .. } => SolidOutput::Section(section?),
            Request::Box { .. } => SolidOutput::Box(voxels),
        })
    }
}

/// The files of a request's output (names and bytes). `progress` receives fractions of the
/// work done.
pub fn export_solid(
    output: SolidOutput,
    vol: &Volume,
    colours: &VoxelTriples,
    p: &SolidExportParams,
    progress: &dyn Fn(f32),
) -> Result<Vec<(String, Vec<u8>)>, SolidExportError> {
    Ok(match output {
        SolidOutput::Surface(mesh) => export_surface(mesh, vol, colours, p, progress)?,
        SolidOutput::Section(s) => vec![("section.png".into(), section_png(vol, s, colours))],
        SolidOutput::Box(voxels) => export_box(voxels, vol, colours)?,
    })
}

/// The colour shown at `p` on a surface of unit normal `n`: that of the voxel containing
/// `p`, or of the nearest requested voxel around it.
fn colour_at(vol: &Volume, colours: &VoxelTriples, p: Vec3, n: Vec3) -> Option<[f32; 3]> {
    let v = vol.voxel_of(p);
    if colours.contains(v) {
        return colours.colour(v, Some(n));
    }
    let mut best: Option<(f32, IVec3)> = None;
    for dz in -1..=1 {
        for dy in -1..=1 {
            for dx in -1..=1 {
                let w = v + IVec3::new(dx, dy, dz);
                if colours.contains(w) {
                    let d = vol.centre(w).distance_squared(p);
                    if best.is_none_or(|b| d < b.0) {
                        best = Some((d, w));
                    }
                }
            }
        }
    }
    colours.colour(best?.1, Some(n))
}

/// The surface coloured by [`colour_at`], for baking.
struct SolidShader<'a> {
    mesh: &'a Mesh,
    /// The mesh's vertex normals, interpolated across each face.
    normals: &'a [Vec3],
    vol: &'a Volume,
    colours: &'a VoxelTriples<'a>,
}

impl crate::render::SurfaceShader for SolidShader<'_> {
    fn albedo(&self, face: usize, bary: Vec3) -> Vec3 {
        let t = self.mesh.triangles[face];
        let p = self.mesh.positions[t[0] as usize] * bary.x
            + self.mesh.positions[t[1] as usize] * bary.y
            + self.mesh.positions[t[2] as usize] * bary.z;
        let n = (self.normals[t[0] as usize] * bary.x
            + self.normals[t[1] as usize] * bary.y
            + self.normals[t[2] as usize] * bary.z)
            .normalize_or_zero();
        colour_at(self.vol, self.colours, p, n)
            .map(Vec3::from)
            .unwrap_or(Vec3::splat(0.5))
    }
}

fn export_surface(
    mesh: &Mesh,
    vol: &Volume,
    colours: &VoxelTriples,
    p: &SolidExportParams,
    progress: &dyn Fn(f32),
) -> Result<Vec<(String, Vec<u8>)>, SolidExportError> {
    let refined = crate::geom::subdivide::refine_to_edge_length(
        mesh,
        p.edge_voxels * vol.voxel,
        p.max_faces as usize,
    );
    let refined_normals = refined.vertex_normals();
    let vertex_colours: Vec<[f32; 4]> = refined
        .positions
        .iter()
        .zip(refined_normals)
        .map(|(q, n)| {
            let c = colour_at(vol, colours, *q, *n).unwrap_or([0.5; 3]);
            [c[0], c[1], c[2], 1.0]
        })
        .collect();
    let coloured = Mesh::with_colors(
        refined.positions.clone(),
        refined.triangles.clone(),
        Some(vertex_colours),
    );
    progress(0.3);
    let mut files = vec![(
        "solid_surface.ply".to_string(),
        crate::geom::io::write_ply(&coloured, coloured.colors.as_deref()),
    )];
    let shader = SolidShader {
        mesh,
        normals: mesh.vertex_normals(),
        vol,
        colours,
    };
    // The per-triangle atlas has room for a limited number of triangles: past it, the .glb
    // carries the refined surface's vertex colours (as the PLY does) rather than the run
    // failing after its synthesis.
    let atlas = match crate::render::build_atlas(mesh, p.atlas_size) {
        Ok(atlas) => Some(atlas),
        Err(e) => {
            tracing::warn!(
                "reconstruct.atlas_size: {e}; solid_surface.glb carries the refined surface's \
                 vertex colours (COLOR_0) instead of a baked texture, and baked_surface.png is \
                 not written"
            );
            None
        }
    };
    let mut glb = crate::export::GlbMesh {
        name: "solid".into(),
        material: crate::export::GlbMaterial {
            double_sided: true,
            ..Default::default()
        },
        ..Default::default()
    };
    match atlas {
        Some(atlas) => {
            let baked = crate::render::bake(&atlas, mesh, &shader);
            progress(0.7);
            let png = encode_png(&baked, false);
            glb.material.base_color_png = Some(png.clone());
            let normals = mesh.vertex_normals();
            for t in &mesh.triangles {
                for c in 0..3 {
                    glb.positions.push(mesh.positions[t[c] as usize]);
                    glb.normals.push(normals[t[c] as usize]);
                    glb.indices.push(glb.indices.len() as u32);
                }
            }
            glb.texcoords = vec![atlas.corner_uv.iter().flatten().copied().collect()];
            files.push(("solid_surface.glb".into(), crate::export::write_glb(&glb)));
            files.push(("baked_surface.png".into(), png));
        }
        None => {
            progress(0.7);
            let colours = coloured.colors.as_deref().unwrap_or_default();
            let glb = crate::export::GlbMesh::vertex_coloured("solid", &coloured, colours);
            files.push(("solid_surface.glb".into(), crate::export::write_glb(&glb)));
        }
    }
    let opts = crate::render::ViewOptions {
        size: p.preview_size,
        up: p
            .up
            .resolve(&coloured.positions, &coloured.triangles, "reconstruct"),
        ..Default::default()
    };
    let preview = crate::render::render_views(
        &coloured,
        &crate::render::VertexColorShader::from_mesh(&coloured).expect("coloured"),
        &opts,
    );
    files.push(("preview.png".into(), encode_png(&preview, false)));
    progress(1.0);
    Ok(files)
}

/// The section as an image: one pixel per sample, rows from the top; samples outside the
/// object a light grey.
fn section_png(vol: &Volume, s: &Section, colours: &VoxelTriples) -> Vec<u8> {
    let mut img =
        image::RgbaImage::from_pixel(s.width, s.height, image::Rgba([235, 236, 240, 255]));
    let normal = s.u.cross(s.v).normalize_or_zero();
    for j in 0..s.height {
        for i in 0..s.width {
            let p = s.point(i, j);
            if let Some(c) = colours.colour(vol.voxel_of(p), Some(normal)) {
                // Image rows go down; the section's v axis up.
                let px = img.get_pixel_mut(i, s.height - 1 - j);
                px.0 = [to8(c[0]), to8(c[1]), to8(c[2]), 255];
            }
        }
    }
    encode_png(&img, false)
}

fn to8(x: f32) -> u8 {
    (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// A box as raw RGB bytes (x fastest, then y, then z) with a JSON header, the same bytes as a
/// multi-part EXR (part `zNNNN` = slice z, half floats `byte / 255`), and its middle z-slice
/// as a PNG for a quick look.
fn export_box(
    voxels: &[IVec3],
    vol: &Volume,
    colours: &VoxelTriples,
) -> Result<Vec<(String, Vec<u8>)>, SolidExportError> {
    let lo = voxels
        .iter()
        .copied()
        .reduce(IVec3::min)
        .unwrap_or(IVec3::ZERO);
    let hi = voxels
        .iter()
        .copied()
        .reduce(IVec3::max)
        .unwrap_or(IVec3::ZERO);
    let d = hi - lo + IVec3::ONE;
    let mut raw = vec![0u8; (d.x * d.y * d.z * 3) as usize];
    for z in 0..d.z {
        for y in 0..d.y {
            for x in 0..d.x {
                let c = colours
                    .colour(lo + IVec3::new(x, y, z), None)
                    .unwrap_or([0.0; 3]);
                let i = (((z * d.y + y) * d.x + x) * 3) as usize;
                raw[i..i + 3].copy_from_slice(&[to8(c[0]), to8(c[1]), to8(c[2])]);
            }
        }
    }
    let origin = vol.centre(lo) - Vec3::splat(0.5 * vol.voxel);
    let header = serde_json::json!({
        "format": "raw RGB, 8 bits per channel, x fastest, then y, then z",
        "file": "volume.raw",
        "exr": "volume.exr: one part per z-slice (z0000 = z 0), channels R, G, B as half floats byte / 255, row 0 = y 0",
        "dims": [d.x, d.y, d.z],
        "origin": [origin.x, origin.y, origin.z],
        "voxel": vol.voxel,
    });
    let mut slice = image::RgbaImage::new(d.x as u32, d.y as u32);
    let z = d.z / 2;
    for y in 0..d.y {
        for x in 0..d.x {
            let i = (((z * d.y + y) * d.x + x) * 3) as usize;
            slice.put_pixel(
                x as u32,
                (d.y - 1 - y) as u32,
                image::Rgba([raw[i], raw[i + 1], raw[i + 2], 255]),
            );
        }
    }
    let exr = crate::export::exr::write_exr_volume([d.x as u32, d.y as u32, d.z as u32], &raw)?;
    Ok(vec![
        ("volume.raw".into(), raw),
        (
            "volume.json".into(),
            serde_json::to_vec_pretty(&header).expect("json of plain values"),
        ),
        ("volume.exr".into(), exr),
        ("volume_middle_slice.png".into(), encode_png(&slice, false)),
    ])
}

/// The reconstruct node's key: the export settings and the kind of request it renders.
#[derive(Debug, Clone, Serialize)]
pub struct SolidColourKey {
    pub export: SolidExportParams,
    pub request: Request,
}

/// What the reconstruct node reads of the request (the volume, the voxels and a section's
/// grid) and of the field (the voxels' frames).
pub struct RequestView<'a> {
    pub volume: &'a Volume,
    pub voxels: &'a [IVec3],
    pub section: Option<&'a Section>,
    pub field: &'a RotationField,
}

/// The reconstruct node: the colours of every exemplar set's synthesized voxels (`sets`: the
/// voxels, their triples and the set's analysis), exported as the request asks.
pub fn node<'a>(
    key: &SolidColourKey,
    mesh: &Mesh,
    request: RequestView,
    sets: impl IntoIterator<Item = (&'a [[i32; 3]], &'a [Triple], SolidAnalysisRef<'a>)>,
    progress: &dyn Fn(f32),
) -> Result<Vec<(String, Vec<u8>)>, Failure> {
    let mut colours = VoxelTriples::new(request.field, request.volume, key.export.colour);
    for (voxels, triples, analysis) in sets {
        colours.add(voxels, triples, analysis);
    }
    let output = SolidOutput::of(&key.request, mesh, request.section, request.voxels)
        .ok_or_else(|| Failure::internal("section request without its grid"))?;
    export_solid(output, request.volume, &colours, &key.export, progress).map_err(Failure::input)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Quat;

    #[test]
    fn the_plane_a_cut_runs_along_takes_all_the_weight() {
        let w = [1.0, 1.0, 1.0];
        // Plane p is spanned by frame columns p and p + 1: xy faces z, yz faces x, zx faces y.
        assert_eq!(facing_weights(Mat3::IDENTITY, w, Vec3::Z), [1.0, 0.0, 0.0]);
        assert_eq!(facing_weights(Mat3::IDENTITY, w, -Vec3::X), [0.0, 1.0, 0.0]);
        assert_eq!(facing_weights(Mat3::IDENTITY, w, Vec3::Y), [0.0, 0.0, 1.0]);
        // In a frame turned a quarter about x, its y column is world z: a z-cut runs along
        // the frame's zx plane.
        let turned = Mat3::from_quat(Quat::from_rotation_x(std::f32::consts::FRAC_PI_2));
        let t = facing_weights(turned, w, Vec3::Z);
        assert!(t[2] > 0.999 && t[0] < 1e-6 && t[1] < 1e-6, "{t:?}");
    }

    #[test]
    fn diagonals_blend_their_planes_equally_and_a_weightless_plane_never_shows() {
        let d = Vec3::new(1.0, 0.0, 1.0).normalize();
        let e = facing_weights(Mat3::IDENTITY, [1.0; 3], d);
        assert!(
            (e[0] - e[1]).abs() < 1e-6 && e[0] > 0.0 && e[2] == 0.0,
            "{e:?}"
        );
        // Off the diagonal by 20°, the nearer plane dominates (the power keeps blends narrow).
        // 65° from x: tan 65° ≈ 2.1445.
        let n = Vec3::new(1.0, 0.0, 2.1445).normalize();
        let f = facing_weights(Mat3::IDENTITY, [1.0; 3], n);
        assert!(f[0] > 10.0 * f[1], "{f:?}");
        let g = facing_weights(Mat3::IDENTITY, [1.0, 0.0, 1.0], Vec3::X);
        assert_eq!(g, [0.0, 0.0, 0.0]);
        // Near x (10° off it), the weighted planes still blend by how nearly they face the
        // surface, the one nearer winning (no fall back to the mean there).
        let near = Vec3::new(1.0, 0.1, 0.05).normalize();
        let h = facing_weights(Mat3::IDENTITY, [1.0, 0.0, 1.0], near);
        assert!(
            h[0] + h[2] > f32::MIN_POSITIVE && h[2] > 200.0 * h[0],
            "{h:?}"
        );
    }
}
