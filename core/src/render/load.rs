//! The `render` command's backend: load a mesh (and optionally a texture) and render the views.

use super::shader::{
    ConstantShader, CornerUvShader, MaterialUvShader, SurfaceShader, VertexColorShader,
};
use super::views::{ViewOptions, render_views};
use crate::geom::Mesh;
use crate::geom::io::MeshError;
use crate::image::{Image, ImageError, decode_image};
use glam::{Vec2, Vec3};
use std::path::{Path, PathBuf};

/// Albedo of meshes with neither texture nor vertex colours.
pub const NEUTRAL_GREY: Vec3 = Vec3::new(0.7, 0.7, 0.7);

/// What went wrong rendering a file. Every message names the file.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: cannot read OBJ: {message}")]
    Obj { path: PathBuf, message: String },
    #[error(transparent)]
    Mesh(#[from] MeshError),
    #[error(transparent)]
    Image(#[from] ImageError),
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    #[error("invalid render option {name}: {message}")]
    Option { name: &'static str, message: String },
}

/// A mesh as the `render` command sees it: geometry plus per-face corner uvs if the file has
/// them (OBJ convention), and what its materials say.
struct Loaded {
    mesh: Mesh,
    corner_uv: Option<Vec<[Vec2; 3]>>,
    materials: FaceMaterials,
}

/// Per face, the OBJ material's diffuse texture (`map_Kd`, an index into `textures`) and colour
/// (`Kd`); empty for other formats and for OBJs without a readable MTL.
#[derive(Default)]
struct FaceMaterials {
    texture: Vec<Option<u32>>,
    colour: Vec<Vec3>,
    /// The distinct `map_Kd` files, resolved against their MTL's folder.
    textures: Vec<PathBuf>,
}

fn obj_error(path: &Path, e: tobj::LoadError) -> RenderError {
    RenderError::Obj {
        path: path.to_owned(),
        message: e.to_string(),
    }
}

/// Reads an OBJ checked by the pipeline's reader, then with tobj, keeping its per-corner
/// texture coordinates, vertex colours and each
/// face's material (from the `mtllib` files, relative to the OBJ; their images relative to each
/// MTL). Groups and objects are merged
/// into one mesh. An MTL that cannot be read is a warning: the mesh renders without it.
fn load_obj(path: &Path) -> Result<Loaded, RenderError> {
    let bytes = crate::geom::io::read_regular_file(path).map_err(|source| RenderError::Io {
        path: path.to_owned(),
        source,
    })?;
    // The file must pass the reader `run` uses, with its errors (a face of two vertices, a
    // coordinate of a million digits, a bad index …): tobj is laxer, and is only asked for what
    // that reader does not keep (corner texture coordinates, colours, materials).
    crate::geom::io::read_mesh_bytes(path, &bytes)?;
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let dir = path.parent().unwrap_or(Path::new(""));
    let (models, materials) = tobj::load_obj_buf(&mut bytes.as_slice(), &opts, |mtl| {
        let mtl_path = dir.join(mtl);
        let bytes = crate::geom::io::read_regular_file(&mtl_path).map_err(|e| {
            tracing::warn!(
                "{}: {e}; its materials are left out of the render",
                mtl_path.display()
            );
            tobj::LoadError::OpenFileFailed
        })?;
        let (mut materials, names) =
            tobj::load_mtl_buf(&mut bytes.as_slice()).inspect_err(|e| {
                tracing::warn!(
                    "{}: cannot read MTL ({e}); its materials are left out of the render",
                    mtl_path.display()
                )
            })?;
        // An MTL names its images relative to itself (as Blender and three.js read them).
        let mtl_dir = mtl_path.parent().unwrap_or(Path::new(""));
        for m in &mut materials {
            if let Some(file) = &mut m.diffuse_texture {
                *file = mtl_dir.join(file.trim()).to_string_lossy().into_owned();
            }
        }
        Ok((materials, names))
    })
    .map_err(|e| obj_error(path, e))?;
    let materials = materials.unwrap_or_default();
    // Each material's texture slot (files named by several materials share one) and colour.
    let mut textures: Vec<PathBuf> = vec![];
    let material_texture: Vec<Option<u32>> = materials
        .iter()
        .map(|m| {
            let file = PathBuf::from(m.diffuse_texture.as_deref()?);
            let slot = textures.iter().position(|t| *t == file).unwrap_or_else(|| {
                textures.push(file);
                textures.len() - 1
            });
            Some(slot as u32)
        })
        .collect();
    let material_colour: Vec<Vec3> = materials
        .iter()
        .map(|m| m.diffuse.map_or(NEUTRAL_GREY, Vec3::from_array))
        .collect();
    let mut face_materials = FaceMaterials {
        textures,
        ..FaceMaterials::default()
    };
    let invalid = |message: String| RenderError::Invalid {
        path: path.to_owned(),
        message,
    };
    let mut positions = vec![];
    let mut colors: Vec<[f32; 4]> = vec![];
    let mut all_colored = true;
    let mut triangles = vec![];
    let mut corner_uv = vec![];
    let mut all_uv = true;
    for model in &models {
        let m = &model.mesh;
        let base = positions.len() as u32;
        let nv = m.positions.len() / 3;
        for p in m.positions.chunks_exact(3) {
            positions.push(Vec3::new(p[0], p[1], p[2]));
        }
        if m.vertex_color.len() == m.positions.len() {
            for c in m.vertex_color.chunks_exact(3) {
                colors.push([c[0], c[1], c[2], 1.0]);
            }
        } else {
            all_colored = false;
        }
        let has_uv = m.texcoord_indices.len() == m.indices.len() && !m.texcoords.is_empty();
        all_uv &= has_uv;
        let (texture, colour) = m.material_id.map_or((None, NEUTRAL_GREY), |k| {
            (
                material_texture.get(k).copied().flatten(),
                material_colour.get(k).copied().unwrap_or(NEUTRAL_GREY),
            )
        });
        let faces = m.indices.len() / 3;
        face_materials
            .texture
            .extend(std::iter::repeat_n(texture, faces));
        face_materials
            .colour
            .extend(std::iter::repeat_n(colour, faces));
        for (k, t) in m.indices.chunks_exact(3).enumerate() {
            if let Some(&bad) = t.iter().find(|&&v| v as usize >= nv) {
                return Err(invalid(format!(
                    "object '{}': face {} uses vertex {} of {}",
                    model.name,
                    k + 1,
                    bad + 1,
                    nv
                )));
            }
            triangles.push([t[0] + base, t[1] + base, t[2] + base]);
            if has_uv {
                let mut uv = [Vec2::ZERO; 3];
                for (c, corner) in uv.iter_mut().enumerate() {
                    let i = m.texcoord_indices[3 * k + c] as usize;
                    let Some(st) = m.texcoords.get(2 * i..2 * i + 2) else {
                        return Err(invalid(format!(
                            "object '{}': face {} uses texture coordinate {} of {}",
                            model.name,
                            k + 1,
                            i + 1,
                            m.texcoords.len() / 2
                        )));
                    };
                    *corner = Vec2::new(st[0], st[1]);
                }
                corner_uv.push(uv);
            }
        }
    }
    if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
        return Err(invalid(format!("vertex {} is not a finite point", i + 1)));
    }
    let colors = (all_colored && !colors.is_empty()).then_some(colors);
    let corner_uv = (all_uv && !triangles.is_empty()).then_some(corner_uv);
    Ok(Loaded {
        mesh: Mesh::with_colors(positions, triangles, colors),
        corner_uv,
        materials: face_materials,
    })
}

/// Loads `mesh_path` (OBJ via tobj, keeping its texture coordinates and materials; other
/// formats via [`crate::geom::io::read_mesh`]) and renders the three preview views. The surface
/// is the `texture` applied through the OBJ's uvs when both exist; else, for an OBJ with uvs
/// whose materials name `map_Kd` images (relative to their MTL), each face's own image, so a
/// baked atlas of several pages renders as written (faces without one take their material's
/// `Kd`); else the mesh's vertex colours; else a neutral grey. A texture given for a mesh
/// without uvs is ignored with a warning, and so is a material image that cannot be read.
pub fn render_mesh_file(
    mesh_path: &Path,
    texture: Option<&Path>,
    opts: &ViewOptions,
) -> Result<image::RgbaImage, RenderError> {
    if opts.size == 0 || opts.size > ViewOptions::MAX_SIZE {
        return Err(RenderError::Option {
            name: "size",
            message: format!(
                "{} is outside 1..={} pixels",
                opts.size,
                ViewOptions::MAX_SIZE
            ),
        });
    }
    if !opts.up.is_finite() || opts.up.length_squared() == 0.0 {
        return Err(RenderError::Option {
            name: "up",
            message: format!("{} is not a direction", opts.up),
        });
    }
    let is_obj = mesh_path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("obj"));
    let loaded = if is_obj {
        load_obj(mesh_path)?
    } else {
        Loaded {
            mesh: crate::geom::io::read_mesh(mesh_path)?,
            corner_uv: None,
            materials: FaceMaterials::default(),
        }
    };
    if loaded.mesh.triangles.is_empty() {
        return Err(RenderError::Invalid {
            path: mesh_path.to_owned(),
            message: "the mesh has no triangles".into(),
        });
    }
    let image = match texture {
        Some(p) => {
            let bytes =
                crate::geom::io::read_regular_file(p).map_err(|source| RenderError::Io {
                    path: p.to_owned(),
                    source,
                })?;
            Some(decode_image(p, &bytes)?)
        }
        None => None,
    };
    // Without an explicit texture, the materials' own images.
    let mut page_slot: Vec<Option<u32>> = vec![];
    let mut pages: Vec<Image> = vec![];
    if texture.is_none()
        && loaded.corner_uv.is_some()
        && loaded.materials.texture.iter().any(Option::is_some)
    {
        for file in &loaded.materials.textures {
            let read = crate::geom::io::read_regular_file(file)
                .map_err(|source| RenderError::Io {
                    path: file.clone(),
                    source,
                })
                .and_then(|bytes| Ok(decode_image(file, &bytes)?));
            match read {
                Ok(img) => {
                    page_slot.push(Some(pages.len() as u32));
                    pages.push(img);
                }
                Err(e) => {
                    tracing::warn!(
                        "{}: {e}; the faces of its material render without it",
                        mesh_path.display()
                    );
                    page_slot.push(None);
                }
            }
        }
    }
    let face_page: Vec<Option<u32>> = loaded
        .materials
        .texture
        .iter()
        .map(|t| t.and_then(|k| page_slot.get(k as usize).copied().flatten()))
        .collect();
    let mesh = &loaded.mesh;
    let material_shader;
    let uv_shader;
    let vc_shader;
    let grey = ConstantShader(NEUTRAL_GREY);
    let shader: &dyn SurfaceShader = match (&image, &loaded.corner_uv) {
        (Some(img), Some(uv)) => {
            uv_shader = CornerUvShader::new(uv, img.view());
            &uv_shader
        }
        // Even when no page could be read: the faces then show their materials' `Kd`.
        (None, Some(uv)) if loaded.materials.texture.iter().any(Option::is_some) => {
            material_shader = MaterialUvShader {
                corner_uv: uv,
                face_texture: &face_page,
                textures: pages.iter().map(Image::view).collect(),
                untextured: &loaded.materials.colour,
            };
            &material_shader
        }
        _ => {
            if image.is_some() {
                tracing::warn!(
                    "{}: no texture coordinates; rendering without the texture",
                    mesh_path.display()
                );
            }
            match VertexColorShader::from_mesh(mesh) {
                Some(s) => {
                    vc_shader = s;
                    &vc_shader
                }
                None => &grey,
            }
        }
    };
    Ok(render_views(mesh, shader, opts))
}
