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
//! analysis node, the sample's appearance space, which synthesize reads too; the variants then
//! leave out the sample's k-coherent sets, which only the template synthesizer reads.
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
use crate::stages::analyse_exemplar::appearance_space;
use crate::stages::analyse_exemplar::texel_variants::{
    self as variants, VariantsKey, check_sample_size,
};
use crate::stages::extract::height_field::{self, HeightFieldKey, is_image_path};
use crate::stages::extract::{self};
use crate::stages::field::param_field::{self};
use crate::stages::parameterize::geometry_image::{self};
use crate::stages::reconstruct::relief_export::{self};
use crate::stages::synthesize::geometry_texture::{Search, SynthAlgorithm};
use crate::stages::synthesize::surface_metric::{
    MAX_STRETCH, share_at_max_stretch, surface_metrics,
};
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
            |ctx, p, mesh| {
                let gi = geometry_image::node(&mesh, p, &|f| ctx.progress.set(f))?;
                let share = share_at_max_stretch(&surface_metrics(&gi));
                if let Some(warning) = stretch_warning(share, p) {
                    tracing::warn!("{warning}");
                }
                Ok(gi)
            },
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
            per_texel: counts_candidates(&c) && c.synthesize.search == Search::PerTexel,
            coherent: counts_candidates(&c) && c.synthesize.search == Search::KCoherence,
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

/// Above this share of texels at the stretch cap, parameterizing warns. The shipped configs
/// stay under it (relief_cow 0.09, dragon_elephant 0.04, dragon_knot 0.14); man.off with
/// relief_cow's settings has 0.46, and a brick wall grown over it shows no brick, where with
/// `stretch_iterations = 2` (0.02) the mortar lines close into bricks.
const STRETCH_WARNING_SHARE: f64 = 0.25;

/// What to tell a user whose geometry image is stretched to the cap of the surface metric on
/// more than [`STRETCH_WARNING_SHARE`] of its texels (`share`), or `None`.
fn stretch_warning(share: f64, p: &geometry_image::GeometryImageParams) -> Option<String> {
    if share <= STRETCH_WARNING_SHARE {
        return None;
    }
    let advice = if p.stretch_iterations > 0 {
        format!(
            "try fewer parameterize.stretch_iterations (now {}; 2 took a human figure from 46 % \
             to 2 %): fewer iterations stretch less but even out the surface area per texel \
             less, so thin parts such as legs get fewer texels",
            p.stretch_iterations
        )
    } else {
        format!(
            "parameterize.stretch_iterations is already 0; more parameterize.stretch_cuts (now \
             {}) can lower the share somewhat",
            p.stretch_cuts
        )
    };
    Some(format!(
        "the geometry image samples the surface unevenly: on {:.0} % of its texels a grid step \
         one way covers at least {} times the surface length of a step the other way (the cap of \
         the surface metric, λ = {MAX_STRETCH}), which synthesis does not undo, so a sample's fine \
         lines fall between texels there; {advice}",
        100.0 * share,
        MAX_STRETCH * MAX_STRETCH
    ))
}

/// Whether synthesis reads the variants' candidate structures: the template synthesizer does
/// (its k-coherent sets, or its per-texel search structures with `search = "per_texel"`), the
/// appearance synthesizer reads neither.
pub(super) fn counts_candidates(c: &GeometryImagesConfig) -> bool {
    c.synthesize.algorithm == SynthAlgorithm::Template
}

/// Whether a `w × h` sample suits the chosen synthesizer: the template synthesizer needs
/// candidates at every level of every variant ([`check_sample_size`]), the appearance
/// synthesizer only its appearance space's sides, so it takes much smaller samples.
pub(super) fn sample_fits(w: u32, h: u32, c: &GeometryImagesConfig) -> Result<(), String> {
    if counts_candidates(c) {
        check_sample_size(w, h, &c.analyse_exemplar).map_err(|e| e.to_string())
    } else {
        appearance_space::check_sides(w, h)
    }
}

/// An image sample read as a height field (§5), checked against the synthesizer once read.
fn image_sample(
    dag: &mut Dag,
    path: &Path,
    c: &GeometryImagesConfig,
) -> Result<Handle<TexelImage>, MethodError> {
    let img = import::<Image>(dag, "import.sample", path, "inputs.sample")?;
    let (path, c2) = (path.to_owned(), c.clone());
    let key = HeightFieldKey {
        height_scale: c.extract.height_scale,
        strict_grey: c.extract.strict_grey,
        template_variants: counts_candidates(c).then(|| c.analyse_exemplar.clone()),
    };
    Ok(dag.node(
        NodeSpec::of(Stage::Extract, height_field::NODE),
        key,
        img,
        move |_, key, img| {
            let fits = |w, h| sample_fits(w, h, &c2);
            Ok(height_field::node(&path, img, key, fits)?)
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_geometry_image_stretched_to_the_cap_is_warned_about_with_a_setting_to_change() {
        let p = geometry_image::GeometryImageParams::default();
        assert_eq!(stretch_warning(0.2, &p), None);
        let w = stretch_warning(0.46, &p).expect("a warning");
        assert!(
            w.contains("46 %") && w.contains("stretch_iterations (now 8;"),
            "{w}"
        );
        let none = geometry_image::GeometryImageParams {
            stretch_iterations: 0,
            ..p
        };
        let w = stretch_warning(0.46, &none).expect("a warning");
        assert!(w.contains("stretch_cuts"), "{w}");
    }
}
