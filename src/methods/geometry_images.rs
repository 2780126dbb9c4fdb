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
//! own ([`GeometryImageParams::with_levels`]).

use super::{Method, MethodError, Planned, import, input};
use crate::artifact::Bundle;
use crate::config::{Config, check_range};
use crate::geom::Mesh;
use crate::geom::geometry_image::TexelImage;
use crate::image::Image;
use crate::pipeline::{Dag, Handle, NodeSpec, Stage};
use crate::score::geometry::GeometryImageNodes;
use crate::score::{Item, Run, ScoreFailure};
use crate::stages::analyse_exemplar::texel_variants::{
    self as variants, TexelVariantParams, VariantsKey, check_sample_size,
};
use crate::stages::extract::height_field::{self, HeightFieldKey, is_image_path};
use crate::stages::extract::{self, ExtractMethod, ExtractParams};
use crate::stages::field::param_field::{self, ParamFieldParams};
use crate::stages::parameterize::geometry_image::{self, GeometryImageParams};
use crate::stages::reconstruct::relief_export::{self, ReliefExportParams};
use crate::stages::synthesize::geometry_texture::{self, GeometrySynthParams, Search};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

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
    /// Where the texture comes from: a mesh (a region of it is used, see `[extract]`) or an
    /// image read as a height field, a colour one by its luma (.png, .jpg, .exr).
    pub sample: PathBuf,
}

/// Parses the config and checks every value, and the values that must agree with each other,
/// naming the keys; returns it with the parameterize node's parameters.
fn checked(config: &Config) -> Result<(GeometryImagesConfig, GeometryImageParams), MethodError> {
    let c: GeometryImagesConfig = config.parse()?;
    config.check("analyse_exemplar", c.analyse_exemplar.validate())?;
    config.check("parameterize", c.parameterize.with_levels(1).map(drop))?;
    let levels = c.analyse_exemplar.levels;
    let gp = c
        .parameterize
        .with_levels(levels)
        .map_err(|e| config.param(e))?;
    config.check("extract", c.extract.validate())?;
    config.check("field", c.field.validate())?;
    config.check("synthesize", c.synthesize.validate())?;
    config.check("reconstruct", c.reconstruct.displacement().validate())?;
    let preview = c.reconstruct.preview_size;
    let range = check_range("reconstruct.preview_size", preview, 16, 4096);
    config.check("reconstruct.preview_size", range)?;
    if is_image_path(&c.inputs.sample) {
        if c.extract.method != ExtractMethod::HeightField {
            let m = "an image sample is read as a height field: set method = \"height_field\" (or give a mesh sample)";
            return Err(config.invalid("extract.method", m).into());
        }
    } else {
        // A mesh sample gives extract.size² texels: check them against the variants now.
        let size = c.extract.size;
        check_sample_size(size, size, &c.analyse_exemplar).map_err(|e| {
            let m = format!(
                "{e} (extract.size = {size}: raise it, or lower analyse_exemplar.scales, \
                 .levels, .template or .boundary_template)"
            );
            config.invalid("extract.size", &m)
        })?;
        let per_texel = c.synthesize.search == Search::PerTexel;
        super::check_variant_memory(config, size, &c.analyse_exemplar, per_texel)?;
    }
    Ok((c, gp))
}

/// The `geometry_images` method.
pub struct GeometryImages;

/// What the geometry-image score reads: its nodes, the synthesis parameters and the field's
/// density offset.
struct GeometryImagesScore {
    nodes: GeometryImageNodes,
    synthesize: GeometrySynthParams,
    density_offset: f32,
}

impl Planned for GeometryImagesScore {
    fn score(&self, run: &Run<'_>, _: &mut Vec<String>) -> Result<Vec<Item>, ScoreFailure> {
        let (nodes, offset) = (&self.nodes, self.density_offset);
        crate::score::geometry::geometry_images(run, nodes, &self.synthesize, offset)
    }
}

impl Method for GeometryImages {
    fn name(&self) -> &'static str {
        "geometry_images"
    }

    fn plan(&self, config: &Config) -> Result<(Dag, Box<dyn Planned>), MethodError> {
        let (c, gp) = checked(config)?;
        let mut dag = Dag::default();
        let mesh = input::<Mesh>(&mut dag, config, "mesh", &c.inputs.mesh)?;
        let gi = dag.node(
            NodeSpec::of(Stage::Parameterize, geometry_image::NODE),
            gp,
            mesh,
            |ctx, p, mesh| Ok(geometry_image::node(&mesh, p, &|f| ctx.progress.set(f))?),
        );
        let sample_path = config.resolve(&c.inputs.sample);
        let texels = if is_image_path(&sample_path) {
            image_sample(&mut dag, &sample_path, &c)?
        } else {
            let sample = input::<Mesh>(&mut dag, config, "sample", &c.inputs.sample)?;
            dag.node(
                NodeSpec::of(Stage::Extract, extract::MESH_TEXTURE_NODE),
                c.extract.clone(),
                sample,
                |ctx, p, mesh| {
                    Ok(extract::mesh_texture_node(&mesh, p, &|f| {
                        ctx.progress.set(f)
                    })?)
                },
            )
        };
        let key = VariantsKey {
            variants: c.analyse_exemplar.clone(),
            per_texel: c.synthesize.search == Search::PerTexel,
        };
        let variants = dag.node(
            NodeSpec::of(Stage::AnalyseExemplar, variants::NODE),
            key,
            texels,
            |ctx, key, sample| Ok(variants::node(&sample, key, &|f| ctx.progress.set(f))?),
        );
        let field = dag.node(
            NodeSpec::of(Stage::Field, param_field::NODE),
            c.field.clone(),
            gi,
            |_, p, gi| Ok(param_field::node(&gi, p)?),
        );
        let synthesize = dag.node(
            NodeSpec::of(Stage::Synthesize, geometry_texture::NODE),
            c.synthesize.clone(),
            (gi, field, variants),
            |ctx, p, (gi, field, v)| {
                Ok(geometry_texture::node(&gi, &field, &v, p, &|f| {
                    ctx.progress.set(f)
                })?)
            },
        );
        let reconstruct = dag.node(
            NodeSpec::of(Stage::Reconstruct, relief_export::NODE),
            c.reconstruct.clone(),
            (gi, synthesize, texels),
            |ctx, p, (gi, texels, sample)| {
                let progress = |f| ctx.progress.set(f);
                Ok(Bundle::from(relief_export::node(
                    &gi, &texels, &sample, p, &progress,
                )?))
            },
        );
        let nodes = GeometryImageNodes {
            parameterize: gi,
            analyse_exemplar: variants,
            field,
            synthesize,
            reconstruct,
        };
        let (synthesize, density_offset) = (c.synthesize.clone(), c.field.density_offset);
        let score = GeometryImagesScore {
            nodes,
            synthesize,
            density_offset,
        };
        Ok((dag, Box::new(score)))
    }
}

/// An image sample read as a height field (§5), checked against the variants once read.
fn image_sample(
    dag: &mut Dag,
    path: &Path,
    c: &GeometryImagesConfig,
) -> Result<Handle<TexelImage>, MethodError> {
    let img = import::<Image>(dag, "import.sample", path, "inputs.sample")?;
    let (path, variants) = (path.to_owned(), c.analyse_exemplar.clone());
    let key = HeightFieldKey {
        height_scale: c.extract.height_scale,
        strict_grey: c.extract.strict_grey,
    };
    Ok(dag.node(
        NodeSpec::of(Stage::Extract, height_field::NODE),
        key,
        img,
        move |_, key, img| {
            let fits = |w, h| check_sample_size(w, h, &variants).map_err(|e| e.to_string());
            Ok(height_field::node(&path, img, key, fits)?)
        },
    ))
}
