//! The synthesize node of `geometry_images`, with the appearance space its default
//! synthesizer reads.

use crate::geom::geometry_image::{GeometryImage, TexelImage};
use crate::pipeline::{Dag, Handle, NodeSpec, Stage};
use crate::stages::analyse_exemplar::appearance_space;
use crate::stages::analyse_exemplar::texel_variants::TexelVariants;
use crate::stages::field::param_field::ParamField;
use crate::stages::synthesize::geometry_texture::{self, GeometrySynthParams, SynthAlgorithm};

/// Plans synthesis: the template synthesizer reads the variants; the appearance synthesizer
/// also the sample's appearance space, an analysis node of its own (cached apart from
/// synthesis, so a rerun with another seed or pass count does not redo it).
pub(super) fn node(
    dag: &mut Dag,
    p: &GeometrySynthParams,
    gi: Handle<GeometryImage>,
    field: Handle<ParamField>,
    variants: Handle<TexelVariants>,
) -> Handle<TexelImage> {
    let spec = NodeSpec::of(Stage::Synthesize, geometry_texture::NODE);
    match p.algorithm {
        SynthAlgorithm::Template => dag.node(
            spec,
            p.clone(),
            (gi, field, variants),
            |ctx, p, (gi, field, v)| {
                let progress = |f| ctx.progress.set(f);
                Ok(geometry_texture::node(&gi, &field, &v, None, p, &progress)?)
            },
        ),
        SynthAlgorithm::Appearance => {
            let space = dag.node(
                NodeSpec::of(Stage::AnalyseExemplar, appearance_space::NODE)
                    .named("analyse_exemplar.appearance"),
                p.appearance_k,
                variants,
                |_, k, v| Ok(appearance_space::node(&v, *k)?),
            );
            dag.node(
                spec,
                p.clone(),
                (gi, field, variants, space),
                |ctx, p, (gi, field, v, space)| {
                    let progress = |f| ctx.progress.set(f);
                    let space = Some(&space);
                    Ok(geometry_texture::node(
                        &gi, &field, &v, space, p, &progress,
                    )?)
                },
            )
        }
    }
}
