//! Method `geometry_images`: geometric texture synthesis and transfer via geometry images
//! (Lai, Hu, Gu & Martin 2005).
//!
//! ```text
//! inputs.mesh ── import.mesh ── parameterize (cut, square, geometry image) ──┬── field ──┐
//!                                                                            ├───────────┴─ synthesize ─ reconstruct ─ files
//! inputs.sample ─ import.sample ─ extract (texels) ─ analyse_exemplar (8 × 3 variants) ─┘
//! ```
//!
//! The sample is a mesh (a region of it is cut out and its relief extracted, §4.1) or an
//! image read as a height field (§5; a colour photograph by its luma). Texel values are
//! stored in units of the sample's texel spacing, so a relief keeps its proportions when it
//! moves to a mesh of another size (see `stages::reconstruct::displacement`).
//!
//! The geometry image's cut-nodes sit on the grid of the coarsest synthesis level (§4.2.2), so
//! the parameterization's `coarse_levels` is `analyse_exemplar.levels`, not a setting of its
//! own.

use super::{Method, MethodError, Planned, import};
use crate::artifact::Bundle;
use crate::check::ParamError;
use crate::config::{Config, check_range};
use crate::geom::Mesh;
use crate::geom::geometry_image::TexelImage;
use crate::image::Image;
use crate::pipeline::{Dag, Handle, NodeError, NodeSpec, Stage};
use crate::score::geometry::GeometryImageNodes;
use crate::score::{Item, Run, ScoreFailure};
use crate::stages::analyse_exemplar::texel_variants::{
    TexelVariantParams, build_texel_variants_with, check_sample_size,
};
use crate::stages::extract::height_field::{height_field_image, is_image_path};
use crate::stages::extract::{ExtractMethod, ExtractParams, extract_mesh_texture};
use crate::stages::field::param_field::{ParamFieldParams, param_field};
use crate::stages::parameterize::geometry_image::{GeometryImageParams, build_geometry_image};
use crate::stages::reconstruct::relief_export::{ReliefExportParams, export_relief};
use crate::stages::synthesize::geometry_texture::{
    GeometrySynthParams, Search, synthesize_geometry_texture,
};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GeometryImagesConfig {
    pub method: String,
    pub inputs: Inputs,
    #[serde(default)]
    pub parameterize: ParameterizeSection,
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
    /// Where the texture comes from: a mesh (a region of it is used, see `[extract]`) or an
    /// image read as a height field, a colour one by its luma (.png, .jpg, .exr).
    pub sample: PathBuf,
}

/// `[parameterize]`: the choices of [`GeometryImageParams`] (see there) except
/// `coarse_levels`, which is `analyse_exemplar.levels`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ParameterizeSection {
    pub size: u32,
    pub extremity_cuts: u32,
    pub stretch_cuts: u32,
    pub stretch_iterations: u32,
}

impl Default for ParameterizeSection {
    fn default() -> Self {
        let d = GeometryImageParams::default();
        ParameterizeSection {
            size: d.size,
            extremity_cuts: d.extremity_cuts,
            stretch_cuts: d.stretch_cuts,
            stretch_iterations: d.stretch_iterations,
        }
    }
}

impl ParameterizeSection {
    /// The parameterize node's parameters, with cut-nodes on the grid of synthesis level
    /// `levels − 1`.
    fn params(&self, levels: u32) -> GeometryImageParams {
        GeometryImageParams {
            size: self.size,
            extremity_cuts: self.extremity_cuts,
            stretch_cuts: self.stretch_cuts,
            stretch_iterations: self.stretch_iterations,
            coarse_levels: levels,
        }
    }
}

/// The analysis node's parameters: `[analyse_exemplar]`, and whether synthesis searches per
/// texel (`synthesize.search = "per_texel"`), which alone needs the per-texel search
/// structures (nearly all of the variant set's size and build time).
#[derive(Serialize)]
struct VariantsNodeParams {
    variants: TexelVariantParams,
    per_texel: bool,
}

/// The key of an image sample's extraction: its height scale alone (the other `[extract]`
/// keys are for mesh samples).
#[derive(Serialize)]
struct HeightFieldImageParams {
    height_scale: f32,
    /// Left out when false: configs that do not set it keep their keys.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    strict_grey: bool,
}

/// Parses the config and checks every value, and the values that must agree with each other,
/// naming the keys.
fn checked(config: &Config) -> Result<GeometryImagesConfig, MethodError> {
    if let Some(toml::Value::Table(t)) = config.table.get("parameterize")
        && t.contains_key("coarse_levels")
    {
        return Err(config
            .invalid(
                "parameterize.coarse_levels",
                "is no longer a setting: the cut-nodes sit on the grid of the coarsest synthesis \
                 level (§4.2.2), so it follows analyse_exemplar.levels; remove it and set \
                 analyse_exemplar.levels instead",
            )
            .into());
    }
    let c: GeometryImagesConfig = config.parse()?;
    let check = |key: &str, r: Result<(), ParamError>| config.check(key, r);
    check("analyse_exemplar", c.analyse_exemplar.validate())?;
    check("parameterize", c.parameterize.params(1).validate())?;
    // Both are valid on their own now: what is left to fail is the levels against the size.
    let levels = c.analyse_exemplar.levels;
    if c.parameterize.params(levels).validate().is_err() {
        return Err(config
            .invalid(
                "analyse_exemplar.levels",
                &format!(
                    "{levels} levels need parameterize.size >= {} (2^levels + 1, so that the \
                     coarsest synthesis grid, where the cut-nodes sit (§4.2.2), has 3 samples \
                     per side), got size {}",
                    (1u32 << levels) + 1,
                    c.parameterize.size
                ),
            )
            .into());
    }
    check("extract", c.extract.validate())?;
    check("field", c.field.validate())?;
    check("synthesize", c.synthesize.validate())?;
    check("reconstruct", c.reconstruct.displacement().validate())?;
    let preview = c.reconstruct.preview_size;
    check(
        "reconstruct.preview_size",
        check_range("reconstruct.preview_size", preview, 16, 4096),
    )?;
    if is_image_path(&c.inputs.sample) {
        if c.extract.method != ExtractMethod::HeightField {
            return Err(config
                .invalid(
                    "extract.method",
                    "an image sample is read as a height field: set method = \"height_field\" (or give a mesh sample)",
                )
                .into());
        }
    } else {
        // A mesh sample gives extract.size² texels: check them against the variants now.
        let size = c.extract.size;
        check_sample_size(size, size, &c.analyse_exemplar).map_err(|e| {
            config.invalid(
                "extract.size",
                &format!(
                    "{e} (extract.size = {size}: raise it, or lower analyse_exemplar.scales, \
                     .levels, .template or .boundary_template)"
                ),
            )
        })?;
        let per_texel = c.synthesize.search == Search::PerTexel;
        super::check_variant_memory(config, size, &c.analyse_exemplar, per_texel)?;
    }
    Ok(c)
}

/// The `geometry_images` method.
pub struct GeometryImages;

impl Method for GeometryImages {
    fn name(&self) -> &'static str {
        "geometry_images"
    }

    fn plan(&self, config: &Config) -> Result<(Dag, Box<dyn Planned>), MethodError> {
        let (dag, planned) = build(config)?;
        Ok((dag, Box::new(planned)))
    }
}

/// What the geometry-image score reads: its nodes, the synthesis parameters and the field's
/// density offset.
struct GeometryImagesScore {
    nodes: GeometryImageNodes,
    synthesize: GeometrySynthParams,
    density_offset: f32,
}

impl Planned for GeometryImagesScore {
    fn score(&self, run: &Run<'_>, _: &mut Vec<String>) -> Result<Vec<Item>, ScoreFailure> {
        crate::score::geometry::geometry_images(
            run,
            &self.nodes,
            &self.synthesize,
            self.density_offset,
        )
    }
}

fn build(config: &Config) -> Result<(Dag, GeometryImagesScore), MethodError> {
    let c = checked(config)?;
    let mut dag = Dag::default();
    let mesh = import::<Mesh>(
        &mut dag,
        "import.mesh",
        &config.resolve(&c.inputs.mesh),
        "inputs.mesh",
    )?;
    let gi = dag.node(
        NodeSpec::of(
            Stage::Parameterize,
            crate::stages::parameterize::geometry_image::NODE,
        ),
        c.parameterize.params(c.analyse_exemplar.levels),
        mesh,
        |ctx, p, mesh| {
            let build = build_geometry_image(&mesh, p, &|f| ctx.progress.set(f))
                .map_err(NodeError::input)?;
            Ok(build.image)
        },
    );

    let sample_path = config.resolve(&c.inputs.sample);
    let texels = if is_image_path(&sample_path) {
        image_sample(&mut dag, &sample_path, &c)?
    } else {
        let sample = import::<Mesh>(&mut dag, "import.sample", &sample_path, "inputs.sample")?;
        dag.node(
            NodeSpec::of(Stage::Extract, crate::stages::extract::MESH_TEXTURE_NODE),
            c.extract.clone(),
            sample,
            |ctx, p, mesh| {
                let e = extract_mesh_texture(&mesh, p, &|f| ctx.progress.set(f))
                    .map_err(NodeError::input)?;
                Ok(e.texels_in_spacing_units())
            },
        )
    };

    let variants = dag.node(
        NodeSpec::of(
            Stage::AnalyseExemplar,
            crate::stages::analyse_exemplar::texel_variants::NODE,
        ),
        VariantsNodeParams {
            variants: c.analyse_exemplar.clone(),
            per_texel: c.synthesize.search == Search::PerTexel,
        },
        texels,
        |ctx, p, sample| {
            build_texel_variants_with(&sample, &p.variants, p.per_texel, &|f| ctx.progress.set(f))
                .map_err(NodeError::input)
        },
    );
    let field = dag.node(
        NodeSpec::of(Stage::Field, crate::stages::field::param_field::NODE),
        c.field.clone(),
        gi,
        |_, p, gi| param_field(&gi, p).map_err(NodeError::input),
    );
    let synthesized = dag.node(
        NodeSpec::of(
            Stage::Synthesize,
            crate::stages::synthesize::geometry_texture::NODE,
        ),
        c.synthesize.clone(),
        (gi, field, variants),
        |ctx, p, (gi, field, variants)| {
            if field.dir.len() != gi.positions.len() {
                return Err(NodeError::internal(
                    "field and geometry image disagree on the sample count",
                ));
            }
            synthesize_geometry_texture(&gi, &field, &variants, p, &|f| ctx.progress.set(f))
                .map_err(NodeError::input)
        },
    );
    let reconstruct = dag.node(
        NodeSpec::of(
            Stage::Reconstruct,
            crate::stages::reconstruct::relief_export::NODE,
        ),
        c.reconstruct.clone(),
        (gi, synthesized, texels),
        |ctx, p, (gi, texels, sample)| {
            let files = export_relief(&gi, &texels, &sample, p, &|f| ctx.progress.set(f))
                .map_err(NodeError::input)?;
            Ok(Bundle::from(files))
        },
    );
    let score = GeometryImagesScore {
        nodes: GeometryImageNodes {
            parameterize: gi,
            analyse_exemplar: variants,
            field,
            synthesize: synthesized,
            reconstruct,
        },
        synthesize: c.synthesize.clone(),
        density_offset: c.field.density_offset,
    };
    Ok((dag, score))
}

/// An image sample read as a height field (§5; a colour image by its luma, with a warning,
/// unless `extract.strict_grey`). Its size is only known once it is
/// read, so it is checked against the variants here, where the error can name the sample.
fn image_sample(
    dag: &mut Dag,
    path: &Path,
    c: &GeometryImagesConfig,
) -> Result<Handle<TexelImage>, MethodError> {
    let img = import::<Image>(dag, "import.sample", path, "inputs.sample")?;
    let (path, variants) = (path.to_owned(), c.analyse_exemplar.clone());
    let params = HeightFieldImageParams {
        height_scale: c.extract.height_scale,
        strict_grey: c.extract.strict_grey,
    };
    Ok(dag.node(
        NodeSpec::of(Stage::Extract, crate::stages::extract::height_field::NODE),
        params,
        img,
        move |_, p, img| {
            // Image heights are in units of the texel spacing (one pixel).
            let h = height_field_image(&path, img, p.height_scale, 1, p.strict_grey)
                .map_err(NodeError::input)?;
            if let Some(w) = &h.warning {
                tracing::warn!("{w}");
            }
            let t = h.texels;
            check_sample_size(t.width, t.height, &variants)
                .map_err(|e| NodeError::input(format!("the sample: {e}")))?;
            Ok(t)
        },
    ))
}
