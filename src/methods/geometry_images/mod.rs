//! Method `geometry_images`: geometric texture synthesis and transfer via geometry images
//! (Lai, Hu, Gu & Martin 2005).
//!
//! ```text
//! inputs.mesh ── import.mesh ── parameterize (cut, square, geometry image) ──┬── field ──┐
//!                                                                            ├───────────┴─ synthesize ─ reconstruct ─ files
//! inputs.sample ─ import.sample ─ extract (texels) ─ analyse_exemplar (8 × 3 variants) ─┘
//! ```
//!
//! With `synthesize.algorithm = "appearance"` (the default) the variants feed a second
//! analysis node, the sample's appearance space, which synthesize reads too.
//!
//! The sample is a mesh (a region of it is cut out and its relief extracted, §4.1) or an
//! image read as a height field (§5; a colour photograph by its luma). Texel values are
//! stored in units of the sample's texel spacing, so a relief keeps its proportions when it
//! moves to a mesh of another size (see `stages::reconstruct::displacement`).
//!
//! The geometry image's cut-nodes sit on the grid of the coarsest synthesis level (§4.2.2), so
//! the parameterization's `coarse_levels` is `analyse_exemplar.levels`, not a setting of its
//! own ([`GeometryImageParams::with_levels`]).

mod config;
mod synthesis;

pub use config::{GeometryImagesConfig, Inputs};

use super::{Method, MethodError, Planned, import, input};
use crate::artifact::Bundle;
use crate::config::Config;
use crate::geom::Mesh;
use crate::geom::geometry_image::TexelImage;
use crate::image::Image;
use crate::pipeline::{Dag, Handle, NodeSpec, Stage};
use crate::score::geometry::GeometryImageNodes;
use crate::stages::analyse_exemplar::texel_variants::{
    self as variants, VariantsKey, check_sample_size,
};
use crate::stages::extract::height_field::{self, HeightFieldKey, is_image_path};
use crate::stages::extract::{self};
use crate::stages::field::param_field::{self};
use crate::stages::parameterize::geometry_image::{self};
use crate::stages::reconstruct::relief_export::{self};
use crate::stages::synthesize::geometry_texture::Search;
use std::path::Path;

/// The `geometry_images` method.
pub struct GeometryImages;

impl Method for GeometryImages {
    fn name(&self) -> &'static str {
        "geometry_images"
    }

    fn plan(&self, config: &Config) -> Result<(Dag, Box<dyn Planned>), MethodError> {
        let (c, gp) = config::checked(config)?;
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
        let synthesize = synthesis::node(&mut dag, &c.synthesize, gi, field, variants);
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
            synthesize_params: c.synthesize.clone(),
            density_offset: c.field.density_offset,
        };
        Ok((dag, Box::new(nodes)))
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
