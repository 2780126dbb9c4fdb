//! Method `geometry_images`: geometric texture synthesis and transfer via geometry images
//! (Lai, Hu, Gu & Martin 2005).
//!
//! ```text
//! inputs.mesh ── import.mesh ── parameterize (cut, square, geometry image) ──┬── field ──┐
//!                                                                            ├───────────┴─ synthesize ─ reconstruct ─ files
//! inputs.sample ─ import.sample ─ extract (texels) ─ analyse_exemplar (8 × 3 variants) ─┘
//! ```
//!
//! The sample is a mesh (a region of it is cut out and its relief extracted, §4.1) or a
//! greyscale image read as a height field (§5). Texel values are stored in units of the
//! sample's texel spacing, so a relief keeps its proportions when it moves to a mesh of
//! another size (see `stages::reconstruct::displacement`).

use super::{MethodError, import_image, import_mesh, to_json};
use crate::artifact::canonical_bytes;
use crate::artifact::geometry_images::{
    read_geometry_image, read_param_field, read_texels, write_geometry_image, write_param_field,
    write_texels,
};
use crate::artifact::kinds::{read_mesh, view_image, write_bundle};
use crate::config::Config;
use crate::geom::geometry_image::{GeometryImage, TexelImage};
use crate::pipeline::{Dag, InputRef, Node, NodeError, Stage};
use crate::stages::analyse_exemplar::texel_variants::{
    TexelVariantParams, build_texel_variants, check_sample_size,
};
use crate::stages::extract::{ExtractMethod, ExtractParams, extract_mesh_texture};
use crate::stages::field::param_field::{ParamFieldParams, param_field};
use crate::stages::parameterize::geometry_image::{GeometryImageParams, build_geometry_image};
use crate::stages::reconstruct::displacement::{DisplacementParams, displace, grid_mesh};
use crate::stages::reconstruct::textured_export::encode_png;
use crate::stages::synthesize::geometry_texture::{
    GeometrySynthParams, synthesize_geometry_texture,
};
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

const GEOMETRY_IMAGE_VERSION: u32 = 1;
const EXTRACT_VERSION: u32 = 1;
const FIELD_VERSION: u32 = 2;
const RECONSTRUCT_VERSION: u32 = 5;
const VARIANTS_VERSION: u32 = 1;
const SYNTH_VERSION: u32 = 1;

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GeometryImagesConfig {
    pub method: String,
    pub inputs: Inputs,
    #[serde(default)]
    pub parameterize: GeometryImageParams,
    #[serde(default)]
    pub extract: ExtractParams,
    #[serde(default)]
    pub analyse_exemplar: TexelVariantParams,
    #[serde(default)]
    pub field: ParamFieldParams,
    #[serde(default)]
    pub synthesize: GeometrySynthParams,
    #[serde(default)]
    pub reconstruct: ReliefExportParams,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Inputs {
    /// The model that gets the texture (.obj, .off, .ply, .stl).
    pub mesh: PathBuf,
    /// Where the texture comes from: a mesh (a region of it is used, see `[extract]`) or a
    /// greyscale image read as a height field (.png, .jpg, .exr).
    pub sample: PathBuf,
}

/// `[reconstruct]`: the displacement (§4.4) and the preview.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReliefExportParams {
    /// Multiplies the relief, 0..=100. Default: 1.
    pub amplitude: f32,
    /// Increasing steps in which the texture is added (§4.4.1), 1..=100. Default: 10.
    pub steps: u32,
    /// A sample stops growing where a triangle's normal turns by more than this, degrees,
    /// 1..=180. Default: 150 (the paper's example).
    pub flip_angle: f32,
    /// Side of each preview view, 16..=4096. Default: 512.
    pub preview_size: u32,
    /// The mesh's up direction, for the preview. Default: [0, 1, 0].
    pub up: [f32; 3],
}

impl ReliefExportParams {
    fn displacement(&self) -> DisplacementParams {
        DisplacementParams {
            amplitude: self.amplitude,
            steps: self.steps,
            flip_angle: self.flip_angle,
        }
    }
}

impl Default for ReliefExportParams {
    fn default() -> Self {
        let d = DisplacementParams::default();
        ReliefExportParams {
            amplitude: d.amplitude,
            steps: d.steps,
            flip_angle: d.flip_angle,
            preview_size: 512,
            up: [0.0, 1.0, 0.0],
        }
    }
}

fn is_image(p: &Path) -> bool {
    matches!(
        p.extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase())
            .as_deref(),
        Some("png" | "jpg" | "jpeg" | "exr")
    )
}

/// Mean distance between grid-neighbouring base points: the sample's texel spacing.
fn texel_spacing(base: &[Vec3], width: usize, height: usize) -> f32 {
    let mut sum = 0.0f64;
    let mut n = 0u64;
    for y in 0..height {
        for x in 0..width {
            let p = base[y * width + x];
            if x + 1 < width {
                sum += p.distance(base[y * width + x + 1]) as f64;
                n += 1;
            }
            if y + 1 < height {
                sum += p.distance(base[(y + 1) * width + x]) as f64;
                n += 1;
            }
        }
    }
    if n == 0 { 1.0 } else { (sum / n as f64) as f32 }
}

/// Divides the geometric channels by the spacing (colour channels stay).
fn normalize(mut t: TexelImage, spacing: f32) -> TexelImage {
    let c = t.channels as usize;
    for texel in t.data.chunks_mut(c) {
        for v in &mut texel[..3] {
            *v /= spacing;
        }
    }
    t
}

pub fn build(config: &Config) -> Result<Dag, MethodError> {
    let c: GeometryImagesConfig = config.parse()?;
    let check = |key: &str, r: Result<(), crate::check::ParamError>| config.check(key, r);
    check("parameterize", c.parameterize.validate())?;
    check("extract", c.extract.validate())?;
    check("analyse_exemplar", c.analyse_exemplar.validate())?;
    check("field", c.field.validate())?;
    check("synthesize", c.synthesize.validate())?;
    check("reconstruct", c.reconstruct.displacement().validate())?;
    check(
        "reconstruct.preview_size",
        crate::config::check_range(
            "reconstruct.preview_size",
            c.reconstruct.preview_size,
            16,
            4096,
        ),
    )?;
    if c.parameterize.coarse_levels != c.analyse_exemplar.levels {
        return Err(config
            .invalid(
                "parameterize.coarse_levels",
                &format!(
                    "must equal analyse_exemplar.levels ({}): cut-nodes sit on the coarsest synthesis grid (§4.2.2), got {}",
                    c.analyse_exemplar.levels, c.parameterize.coarse_levels
                ),
            )
            .into());
    }
    let sample_path = config.resolve(&c.inputs.sample);
    let sample_is_image = is_image(&sample_path);
    if sample_is_image && c.extract.method != ExtractMethod::HeightField {
        return Err(config
            .invalid(
                "extract.method",
                "an image sample is read as a height field: set method = \"height_field\" (or give a mesh sample)",
            )
            .into());
    }

    let mut dag = Dag::default();
    let mesh = import_mesh(
        &mut dag,
        "import.mesh",
        &config.resolve(&c.inputs.mesh),
        "inputs.mesh",
    )?;

    let p = c.parameterize.clone();
    let gi = dag.add(Node {
        name: "parameterize".into(),
        stage: Stage::Parameterize,
        algorithm: "geometry_image",
        version: GEOMETRY_IMAGE_VERSION,
        params: canonical_bytes(&p),
        params_json: to_json(&p),
        inputs: vec![mesh],
        exports: false,
        keyed: Vec::new(),
        pieces: None,
        compute: Box::new(move |ctx| {
            let mesh = read_mesh(ctx.artifact(0))?;
            let build = build_geometry_image(&mesh, &p, &|f| ctx.progress.set(f))
                .map_err(NodeError::input)?;
            Ok(write_geometry_image(&build.image))
        }),
    });

    let vp = c.analyse_exemplar.clone();
    // The size check of the variants, run where the sample is made so the error names it.
    let check_size = move |w: u32, h: u32| {
        check_sample_size(w, h, &vp).map_err(|e| NodeError::input(format!("the sample: {e}")))
    };
    let check_image = check_size.clone();
    let p = c.extract.clone();
    let texels: InputRef = if sample_is_image {
        let img = import_image(&mut dag, "import.sample", &sample_path, "inputs.sample")?;
        let path = sample_path.clone();
        dag.add(Node {
            name: "extract".into(),
            stage: Stage::Extract,
            algorithm: "height_field_image",
            version: EXTRACT_VERSION,
            params: canonical_bytes(&p.height_scale),
            params_json: serde_json::json!({ "height_scale": p.height_scale }),
            inputs: vec![img],
            exports: false,
            keyed: Vec::new(),
            pieces: None,
            compute: Box::new(move |ctx| {
                let img = view_image(ctx.artifact(0))?;
                // Image heights are in units of the texel spacing (one pixel).
                let t = crate::stages::extract::height_field::height_field_image(
                    &path,
                    img,
                    p.height_scale,
                    1,
                )
                .map_err(NodeError::input)?;
                check_image(t.width, t.height)?;
                Ok(write_texels(&t))
            }),
        })
    } else {
        let sample = import_mesh(&mut dag, "import.sample", &sample_path, "inputs.sample")?;
        dag.add(Node {
            name: "extract".into(),
            stage: Stage::Extract,
            algorithm: "geometric_texture",
            version: EXTRACT_VERSION,
            params: canonical_bytes(&p),
            params_json: to_json(&p),
            inputs: vec![sample],
            exports: false,
            keyed: Vec::new(),
            pieces: None,
            compute: Box::new(move |ctx| {
                let mesh = read_mesh(ctx.artifact(0))?;
                let e = extract_mesh_texture(&mesh, &p, &|f| ctx.progress.set(f))
                    .map_err(NodeError::input)?;
                let (w, h) = (e.texels.width, e.texels.height);
                check_size(w, h)?;
                let spacing = texel_spacing(&e.base, w as usize, h as usize);
                Ok(write_texels(&normalize(e.texels, spacing.max(1e-30))))
            }),
        })
    };

    let variants = analyse_node(&mut dag, &c, texels);

    let p = c.field.clone();
    let field = dag.add(Node {
        name: "field".into(),
        stage: Stage::Field,
        algorithm: "param_field",
        version: FIELD_VERSION,
        params: canonical_bytes(&p),
        params_json: to_json(&p),
        inputs: vec![gi],
        exports: false,
        keyed: Vec::new(),
        pieces: None,
        compute: Box::new(move |ctx| {
            let gi = read_geometry_image(ctx.artifact(0))?;
            let f = param_field(&gi, &p).map_err(NodeError::input)?;
            Ok(write_param_field(&f))
        }),
    });

    let synthesized = synthesize_node(&mut dag, &c, gi, field, variants);

    let p = c.reconstruct.clone();
    dag.add(Node {
        name: "reconstruct".into(),
        stage: Stage::Reconstruct,
        algorithm: "displacement",
        version: RECONSTRUCT_VERSION,
        params: canonical_bytes(&p),
        params_json: to_json(&p),
        inputs: vec![gi, synthesized, texels],
        exports: true,
        keyed: Vec::new(),
        pieces: None,
        compute: Box::new(move |ctx| {
            let gi = read_geometry_image(ctx.artifact(0))?;
            let texels = read_texels(ctx.artifact(1))?;
            let sample = read_texels(ctx.artifact(2))?;
            let files = export_relief(&gi, &texels, &sample, &p, &|f| ctx.progress.set(f))
                .map_err(NodeError::input)?;
            Ok(write_bundle(&files))
        }),
    });
    Ok(dag)
}

/// The grey image of a texel image's dn channel, mapped from [-3σ, 3σ] around its mean.
fn dn_png(t: &TexelImage) -> Vec<u8> {
    let c = t.channels as usize;
    let dn: Vec<f32> = t.data.chunks(c).map(|x| x[2]).collect();
    let n = dn.len().max(1) as f64;
    let mean = dn.iter().map(|&v| v as f64).sum::<f64>() / n;
    let sd = (dn.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / n)
        .sqrt()
        .max(1e-12);
    let mut img = image::RgbaImage::new(t.width, t.height);
    for (px, v) in img.pixels_mut().zip(&dn) {
        let g = (((*v as f64 - mean) / (6.0 * sd) + 0.5).clamp(0.0, 1.0) * 255.0).round() as u8;
        px.0 = [g, g, g, 255];
    }
    encode_png(&img, false)
}

/// The output files: the displaced mesh (OBJ, PLY, .glb), the input's geometry image as EXR,
/// the sample's and the synthesized relief as grey images, and a preview.
fn export_relief(
    gi: &GeometryImage,
    texels: &TexelImage,
    sample: &TexelImage,
    p: &ReliefExportParams,
    progress: &dyn Fn(f32),
) -> Result<Vec<(String, Vec<u8>)>, String> {
    let n = gi.n as usize;
    let spacing = crate::stages::field::param_field::local_spacing(gi);
    let unit = crate::stages::field::param_field::reference_spacing(&spacing);
    let displaced = displace(gi, texels, unit, &p.displacement());
    if displaced.held_back > 0 {
        tracing::info!(
            "reconstruct: flip avoidance held {} of {} samples short of their full displacement",
            displaced.held_back,
            n * n
        );
    }
    progress(0.3);
    let (mesh, samples) = grid_mesh(gi, &displaced.positions);
    let colors: Option<Vec<[f32; 4]>> = (texels.channels == 6).then(|| {
        samples
            .iter()
            .map(|&s| {
                let t = texels.texel(s % gi.n, s / gi.n);
                [t[3], t[4], t[5], 1.0]
            })
            .collect()
    });
    let mesh = crate::geom::Mesh::with_colors(mesh.positions, mesh.triangles, colors);
    let mut files = vec![
        (
            "relief.obj".to_string(),
            crate::export::write_obj(&mesh, None, None, "relief").into_bytes(),
        ),
        (
            "relief.ply".to_string(),
            crate::geom::io::write_ply(&mesh, mesh.colors.as_deref()),
        ),
    ];
    files.push((
        "relief.glb".into(),
        crate::export::write_glb(&glb_of(&mesh)),
    ));
    progress(0.5);
    files.push((
        "geometry_image.exr".into(),
        crate::export::exr::write_exr_rgb(gi.n, gi.n, &gi.positions).map_err(|e| e.to_string())?,
    ));
    files.push((
        "geometry_image_normals.exr".into(),
        crate::export::exr::write_exr_rgb(gi.n, gi.n, &gi.normals).map_err(|e| e.to_string())?,
    ));
    files.push(("sample_relief.png".into(), dn_png(sample)));
    files.push(("synthesized_relief.png".into(), dn_png(texels)));
    progress(0.6);
    let opts = crate::render::ViewOptions {
        size: p.preview_size,
        up: Vec3::from(p.up),
        ..Default::default()
    };
    let preview = match crate::render::VertexColorShader::from_mesh(&mesh) {
        Some(s) => crate::render::render_views(&mesh, &s, &opts),
        None => crate::render::render_views(
            &mesh,
            &crate::render::ConstantShader(Vec3::splat(0.8)),
            &opts,
        ),
    };
    files.push(("preview.png".into(), encode_png(&preview, false)));
    // The synthesized relief painted on the undisplaced surface: shows how the texture lies
    // on the shape (orientation, scale, seams) without the shading of the displacement.
    let (flat, flat_samples) = grid_mesh(gi, &gi.positions);
    let dn: Vec<f32> = flat_samples
        .iter()
        .map(|&s| texels.texel(s % gi.n, s / gi.n)[2])
        .collect();
    let mean = dn.iter().sum::<f32>() / dn.len().max(1) as f32;
    let sd = (dn.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>() / dn.len().max(1) as f32)
        .sqrt()
        .max(1e-12);
    let grey: Vec<[f32; 4]> = dn
        .iter()
        .map(|v| {
            let g = ((v - mean) / (6.0 * sd) + 0.5).clamp(0.0, 1.0);
            [g, g, g, 1.0]
        })
        .collect();
    let shader = crate::render::VertexColorShader::new(&flat.triangles, &grey);
    let map = crate::render::render_views(
        &flat,
        &shader,
        &crate::render::ViewOptions { lit: false, ..opts },
    );
    files.push(("relief_map.png".into(), encode_png(&map, false)));
    progress(1.0);
    Ok(files)
}

/// A .glb of the displaced mesh: unwelded corners with face normals would facet the relief,
/// so vertices are shared and carry area-weighted normals; colours (sRGB in the texels)
/// become linear COLOR_0.
fn glb_of(mesh: &crate::geom::Mesh) -> crate::export::GlbMesh {
    crate::export::GlbMesh {
        name: "relief".into(),
        positions: mesh.positions.clone(),
        normals: mesh.vertex_normals().to_vec(),
        colors: mesh.colors.as_ref().map(|c| {
            c.iter()
                .map(|x| {
                    let l = |v: f32| crate::render::srgb::to_linear(v.clamp(0.0, 1.0));
                    [l(x[0]), l(x[1]), l(x[2]), x[3]]
                })
                .collect()
        }),
        indices: mesh.triangles.iter().flatten().copied().collect(),
        material: crate::export::GlbMaterial {
            double_sided: true,
            roughness: 0.6,
            ..Default::default()
        },
        ..Default::default()
    }
}

fn analyse_node(dag: &mut Dag, c: &GeometryImagesConfig, texels: InputRef) -> InputRef {
    let p = c.analyse_exemplar.clone();
    dag.add(Node {
        name: "analyse_exemplar".into(),
        stage: Stage::AnalyseExemplar,
        algorithm: "texel_variants",
        version: VARIANTS_VERSION,
        params: canonical_bytes(&p),
        params_json: to_json(&p),
        inputs: vec![texels],
        exports: false,
        keyed: Vec::new(),
        pieces: None,
        compute: Box::new(move |ctx| {
            let sample = read_texels(ctx.artifact(0))?;
            let v = build_texel_variants(&sample, &p, &|f| ctx.progress.set(f))
                .map_err(NodeError::input)?;
            Ok(write_variants(&v))
        }),
    })
}

fn synthesize_node(
    dag: &mut Dag,
    c: &GeometryImagesConfig,
    gi: InputRef,
    field: InputRef,
    variants: InputRef,
) -> InputRef {
    let p = c.synthesize.clone();
    dag.add(Node {
        name: "synthesize".into(),
        stage: Stage::Synthesize,
        algorithm: "geometry_texture",
        version: SYNTH_VERSION,
        params: canonical_bytes(&p),
        params_json: to_json(&p),
        inputs: vec![gi, field, variants],
        exports: false,
        keyed: Vec::new(),
        pieces: None,
        compute: Box::new(move |ctx| {
            let gi = read_geometry_image(ctx.artifact(0))?;
            let field = read_param_field(ctx.artifact(1))?;
            let a = ctx.artifact(2);
            let variants = view_variants(a)?;
            if field.dir.len() != gi.positions.len() {
                return Err(NodeError::internal(
                    "field and geometry image disagree on the sample count",
                ));
            }
            let t =
                synthesize_geometry_texture(&gi, &field, &variants, &p, &|f| ctx.progress.set(f))
                    .map_err(NodeError::input)?;
            Ok(write_texels(&t))
        }),
    })
}

fn write_variants(v: &crate::stages::analyse_exemplar::texel_variants::TexelVariants) -> Vec<u8> {
    let mut w = crate::artifact::ArtifactWriter::new(crate::artifact::Kind::TexelVariants, &v.meta);
    for (name, bytes) in v.arrays() {
        w = w.array_bytes(name, bytes.to_vec());
    }
    w.finish()
}

fn view_variants(
    a: &crate::artifact::Artifact,
) -> Result<crate::stages::analyse_exemplar::texel_variants::TexelVariantsRef<'_>, NodeError> {
    a.expect_kind(crate::artifact::Kind::TexelVariants)?;
    let meta = a.meta()?;
    crate::stages::analyse_exemplar::texel_variants::TexelVariantsRef::from_arrays(meta, |name| {
        a.raw_array(name).ok()
    })
    .map_err(|e| NodeError::internal(format!("cached texel variants: {e}")))
}
