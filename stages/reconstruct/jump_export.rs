//! The jump-map method's reconstruction (Zelinka & Garland, §4.3–4.4): the blended surface
//! exported with the exemplar and every map aligned with it (normal, roughness, …), each
//! through the same corner sets, plus the paper's Fig. 3 (right): the surface textured with a
//! colour ramp instead of the exemplar, which shows where patches meet.

use crate::geom::Mesh;
use crate::image::{Image, ImageView};
use crate::parameterize::jump_parameterization::ParamParts;
use crate::reconstruct::jump_blend::{
    BlendShader, MissingEdge, corner_sets, one_patch, random_base_set,
};
use crate::reconstruct::textured_export::{
    ExportError, ExportParams, ExportSurface, export_textured_mesh,
};
use crate::reconstruct::wide_blend::{WideBlend, wide_blend};
use glam::Vec2;
use std::path::PathBuf;
use texsyn_core::algorithm::Failure;

/// The `jump_blend_export` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("jump_blend_export", 6);

/// An image textured onto the surface with the walk's coordinates: the exemplar itself or a
/// map aligned with it. Its original file is copied into the export as it is.
pub struct AlignedMap<'a> {
    /// `basecolor` for the exemplar; the config's name for a map.
    pub name: String,
    /// The file's format (its extension).
    pub format: String,
    pub image: ImageView<'a>,
    pub path: PathBuf,
    pub bytes: &'a [u8],
}

#[derive(Debug, thiserror::Error)]
pub enum JumpExportError {
    #[error(
        "{}: map {name:?} is {}×{}, but the exemplar is {}×{}: maps must be aligned with the exemplar",
        path.display(), size.0, size.1, exemplar.0, exemplar.1
    )]
    MapSize {
        path: PathBuf,
        name: String,
        size: (u32, u32),
        exemplar: (u32, u32),
    },
    #[error(transparent)]
    Export(#[from] ExportError),
    #[error("texel addresses and mesh disagree on the vertex count")]
    VertexCount,
    #[error(transparent)]
    MissingEdge(#[from] MissingEdge),
}

impl JumpExportError {
    /// Whether texsyn is at fault (stored artifacts that disagree), not the user's input.
    pub fn is_internal(&self) -> bool {
        matches!(
            self,
            JumpExportError::VertexCount | JumpExportError::MissingEdge(_)
        )
    }
}

/// The files of the jump-map export: textured OBJ/MTL/PNG, the baked .glb and its textures,
/// the preview, `patches.png` and (up to [`PATCH_MODEL_TRIANGLES`]) `patches.glb`.
pub fn export_jump_textured(
    mesh: &Mesh,
    param: &ParamParts,
    addresses: &[Vec2],
    exemplar: &AlignedMap,
    maps: &[AlignedMap],
    p: &ExportParams,
    progress: &dyn Fn(f32),
) -> Result<Vec<(String, Vec<u8>)>, JumpExportError> {
    if addresses.len() != mesh.vertex_count() || param.meta.vertices as usize != mesh.vertex_count()
    {
        return Err(JumpExportError::VertexCount);
    }
    let clock = std::time::Instant::now();
    let sets = corner_sets(&mesh.triangles, param, addresses)?;
    let single = random_base_set(&sets);
    tracing::debug!(
        "reconstruct: corner sets at {:.3} s",
        clock.elapsed().as_secs_f64()
    );
    let size = (exemplar.image.width, exemplar.image.height);
    let wide = wide_blend_of(mesh, param, addresses, p.blend_radius, size)?;
    tracing::debug!(
        "reconstruct: blend patches at {:.3} s",
        clock.elapsed().as_secs_f64()
    );
    let mut surfaces = Vec::new();
    for m in std::iter::once(exemplar).chain(maps) {
        let map_size = (m.image.width, m.image.height);
        if map_size != size {
            return Err(JumpExportError::MapSize {
                path: m.path.clone(),
                name: m.name.clone(),
                size: map_size,
                exemplar: size,
            });
        }
        surfaces.push(ExportSurface {
            name: m.name.clone(),
            extension: m.format.clone(),
            file: m.bytes,
            shader: BlendShader {
                sets: &sets,
                texture: m.image,
                wide: wide.as_ref(),
            },
        });
    }
    let layout = chart_layout(&mesh.triangles, param, addresses, &single);
    tracing::debug!(
        "reconstruct: chart layout at {:.3} s",
        clock.elapsed().as_secs_f64()
    );
    let ramp = colour_ramp(size.0, size.1);
    let patches = BlendShader {
        sets: &sets,
        texture: ramp.view(),
        wide: wide.as_ref(),
    };
    let mut files = export_textured_mesh(
        mesh,
        &single,
        &layout,
        size,
        &surfaces,
        &[("patches.png", &patches)],
        p,
        progress,
    )?;
    if mesh.triangles.len() <= PATCH_MODEL_TRIANGLES {
        files.push(("patches.glb".into(), patch_model(mesh, &single, &ramp)));
    } else {
        tracing::info!(
            "reconstruct: no patches.glb for {} triangles (it repeats every corner; at most {} \
             are written): patches.png shows the patches",
            mesh.triangles.len(),
            PATCH_MODEL_TRIANGLES
        );
    }
    Ok(files)
}

/// The blend over several triangles for `reconstruct.blend_radius` (none at 0: §4.4's own
/// blend), logged with how many triangles it touches.
pub fn wide_blend_of(
    mesh: &Mesh,
    param: &ParamParts,
    addresses: &[Vec2],
    radius: f32,
    exemplar: (u32, u32),
) -> Result<Option<WideBlend>, MissingEdge> {
    if radius <= 0.0 {
        return Ok(None);
    }
    let wide = wide_blend(&mesh.triangles, param, addresses, radius, exemplar)?;
    let faces = mesh.triangles.len();
    let blended = (0..faces).filter(|&f| wide.face(f).len() > 1).count();
    tracing::info!(
        "reconstruct: blending over {radius} texels: {blended} of {faces} triangles ({:.1} %) \
         mix several patches",
        100.0 * blended as f64 / faces.max(1) as f64
    );
    Ok(Some(wide))
}

/// Largest mesh whose patch view is written as a model (three vertices a triangle: 300k
/// triangles make about 40 MB).
pub const PATCH_MODEL_TRIANGLES: usize = 300_000;

/// The patch view as a model (`patches.glb`, the 3D counterpart of `patches.png` and of the
/// paper's Fig. 3): every triangle textured through its own exemplar coordinates (`single`,
/// the walk's one set per triangle, before the §4.4 blend) with the colour `ramp` in place of
/// the exemplar, so a patch shows as one smooth ramp and its border as a jump.
fn patch_model(mesh: &Mesh, single: &[[Vec2; 3]], ramp: &Image) -> Vec<u8> {
    let (w, h) = (ramp.width, ramp.height);
    let normals = mesh.vertex_normals();
    let mut glb = crate::export::GlbMesh {
        name: "patches".into(),
        ..Default::default()
    };
    let mut uvs = Vec::with_capacity(3 * mesh.triangles.len());
    for (t, corners) in mesh.triangles.iter().zip(single) {
        for (&v, &a) in t.iter().zip(corners) {
            glb.positions.push(mesh.positions[v as usize]);
            glb.normals.push(normals[v as usize]);
            let uv = crate::image::texel_to_uv(a, w, h);
            // glTF's v runs down the image.
            uvs.push(Vec2::new(uv.x, 1.0 - uv.y));
        }
    }
    glb.texcoords = vec![uvs];
    glb.indices = (0..glb.positions.len() as u32).collect();
    glb.material = crate::export::GlbMaterial {
        name: "patches".into(),
        base_color_png: Some(crate::export::encode_png(&ramp.to_rgba8(), false)),
        double_sided: true,
        ..Default::default()
    };
    crate::export::write_glb(&glb)
}

/// The chart layout of the atlas: a face inside a patch of the walk (every edge's address
/// difference agrees with its offset) is laid at its vertices' own addresses, so that the faces
/// of a patch share their corners and stay together in one chart; a face across a jump keeps
/// its single set's shape, alone or laid against a neighbouring chart.
pub fn chart_layout(
    triangles: &[[u32; 3]],
    param: &ParamParts,
    addresses: &[Vec2],
    single: &[[Vec2; 3]],
) -> Vec<[Vec2; 3]> {
    use rayon::prelude::*;
    triangles
        .par_iter()
        .zip(single)
        .map(|(t, own)| {
            let continuous = (0..3).all(|k| {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                param
                    .offset(a, b)
                    .is_some_and(|o| one_patch(o, addresses[a as usize], addresses[b as usize]))
            });
            if continuous {
                t.map(|v| addresses[v as usize])
            } else {
                *own
            }
        })
        .collect()
}

/// An image whose colour encodes the texel address (red along x, green along y, blue in a
/// checker of 8-texel cells), so a surface textured with it shows its patches.
fn colour_ramp(w: u32, h: u32) -> Image {
    let mut img = Image::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let checker = ((x / 8 + y / 8) % 2) as f32;
            img.pixels[(y * w + x) as usize] = [
                x as f32 / (w - 1).max(1) as f32,
                y as f32 / (h - 1).max(1) as f32,
                0.25 + 0.5 * checker,
                1.0,
            ];
        }
    }
    img
}

/// The export's own file names a map's name must not produce: a map `N` exports `N.EXT` and
/// `baked_N.png` (or `baked_N_K.png`, one per page), beside `texture.EXT` (the exemplar),
/// `baked_basecolor*.png`, `textured.*`, `baked.*`, `preview.png` and `patches.png`.
const RESERVED_MAP_NAMES: [&str; 6] = [
    "basecolor",
    "texture",
    "textured",
    "baked",
    "preview",
    "patches",
];

/// Why the map name `name` could export a file of the same name as another export file (a
/// reserved name, a `baked_` prefix, or `M_K` beside a map `M`, whose pages are
/// `baked_M_K.png`); `None` when every name it produces is its own.
fn map_name_clash<'a>(name: &str, all: impl Iterator<Item = &'a String>) -> Option<String> {
    if RESERVED_MAP_NAMES.contains(&name) {
        return Some(format!(
            "the name {name:?} is the export's own (reserved: {}); choose another",
            RESERVED_MAP_NAMES.join(", ")
        ));
    }
    if name.starts_with("baked_") {
        return Some("names starting with `baked_` are the baked pages'; choose another".into());
    }
    for other in all {
        if let Some(k) = name
            .strip_prefix(other.as_str())
            .and_then(|r| r.strip_prefix('_'))
            && !k.is_empty()
            && k.bytes().all(|b| b.is_ascii_digit())
        {
            return Some(format!(
                "map {other:?}'s baked pages are named baked_{other}_K.png, so {name:?} \
                 could export the same file name; choose another"
            ));
        }
    }
    None
}

/// A name an extra map may have: letters, digits, '_' and '-', and no file name it exports
/// is another export's (`all`: every map's name).
pub fn check_map_name<'a>(name: &str, all: impl Iterator<Item = &'a String>) -> Result<(), String> {
    let allowed = |ch: char| ch.is_ascii_alphanumeric() || ch == '_' || ch == '-';
    if name.is_empty() || !name.chars().all(allowed) {
        return Err("map names may use letters, digits, '_' and '-'".into());
    }
    map_name_clash(name, all).map_or(Ok(()), Err)
}

/// What the reconstruct node's key holds besides its inputs: the export parameters, each extra
/// map's name and file format, and the exemplar's format (the files are copied into the
/// export as they are).
#[derive(Debug, Clone, serde::Serialize)]
pub struct JumpExportKey {
    pub export: ExportParams,
    pub maps: Vec<(String, String)>,
    pub exemplar_format: String,
}

impl JumpExportKey {
    /// The key for an export with no extra maps yet, of an exemplar read from `exemplar`.
    pub fn new(export: &ExportParams, exemplar: &std::path::Path) -> Self {
        JumpExportKey {
            export: export.clone(),
            maps: Vec::new(),
            exemplar_format: file_format(exemplar),
        }
    }

    /// Adds the extra map `name`, read from `path`.
    pub fn add_map(&mut self, name: &str, path: &std::path::Path) {
        self.maps.push((name.to_owned(), file_format(path)));
    }
}

/// A map's file format for the export: its extension (lower case), or PNG for a file
/// without one.
fn file_format(path: &std::path::Path) -> String {
    let e = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    e.filter(|e| !e.is_empty()).unwrap_or_else(|| "png".into())
}

/// An image aligned with the exemplar and the file it was read from.
pub struct MapFile<'a> {
    pub image: ImageView<'a>,
    pub path: &'a std::path::Path,
    pub bytes: &'a [u8],
}

impl<'a> MapFile<'a> {
    pub fn new(image: ImageView<'a>, path: &'a std::path::Path, bytes: &'a [u8]) -> Self {
        MapFile { image, path, bytes }
    }
}

/// The reconstruct node: the textured mesh and its files. `files` are the exemplar, exported
/// as `basecolor`, then each extra map of the key, exported under its config name.
pub fn node(
    key: &JumpExportKey,
    mesh: &Mesh,
    param: &ParamParts,
    addresses: &[Vec2],
    mut files: Vec<MapFile>,
    progress: &dyn Fn(f32),
) -> Result<Vec<(String, Vec<u8>)>, Failure> {
    if files.len() != key.maps.len() + 1 {
        return Err(Failure::internal("the export's maps and its key disagree"));
    }
    let exemplar = files.remove(0);
    let maps = files;
    fn aligned<'a>((name, format): &(String, String), f: MapFile<'a>) -> AlignedMap<'a> {
        AlignedMap {
            name: name.clone(),
            format: format.clone(),
            image: f.image,
            path: f.path.to_owned(),
            bytes: f.bytes,
        }
    }
    let basecolor = ("basecolor".to_owned(), key.exemplar_format.clone());
    let maps: Vec<AlignedMap> = key
        .maps
        .iter()
        .zip(maps)
        .map(|(m, f)| aligned(m, f))
        .collect();
    let exemplar = aligned(&basecolor, exemplar);
    let files = export_jump_textured(
        mesh,
        param,
        addresses,
        &exemplar,
        &maps,
        &key.export,
        progress,
    )
    .map_err(|e| Failure::classify(e, JumpExportError::is_internal))?;
    // Map names are checked when the config is planned ([`check_map_name`]); a bundle with
    // two files of one name would still overwrite one with the other, so it is refused.
    let mut names: Vec<&str> = files.iter().map(|(n, _)| n.as_str()).collect();
    names.sort_unstable();
    if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
        return Err(Failure::input(format!(
            "two exported files would be named {:?}: rename the map in inputs.maps whose \
             file names collide",
            w[0]
        )));
    }
    Ok(files)
}
