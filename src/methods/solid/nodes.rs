//! The `solid` method's per-exemplar-set nodes: an analysis and a synthesis for the core and
//! for each region.

use crate::artifact::solid::SolidSamples;
use crate::config::Config;
use crate::image::Image;
use crate::methods::{Imports, MethodError};
use crate::pipeline::Stage::{AnalyseExemplar, Synthesize};
use crate::pipeline::shard;
use crate::pipeline::{Dag, Handle, Keyed, NodeError, NodeSpec, WithTail};
use crate::stages::analyse_exemplar::candidate_triples::{
    self as triples, ExemplarSpec, SolidAnalysis,
};
use crate::stages::field::quaternion_field::RotationField;
use crate::stages::parameterize::volume_embedding as volume;
use crate::stages::parameterize::volume_embedding::RequestedVoxels as Request;
use crate::stages::synthesize::solid::solid_synthesis::{self as synthesis, Brick, SolidError};

/// The candidate-triple analysis of one exemplar set: `[exemplar, xy, yz, zx]` of the config
/// table `key`, each plane's image (and drawn mask) falling back to the shared one. A drawn
/// mask turns the feature channel on with its default settings when the config does not.
pub(super) fn add_analysis(
    dag: &mut Dag,
    config: &Config,
    images: &mut Imports<Image>,
    (name, key): (&str, &str),
    [shared, xy, yz, zx]: [&Option<ExemplarSpec>; 4],
    mut params: triples::CandidateParams,
) -> Result<Handle<SolidAnalysis>, MethodError> {
    // Each plane's image and drawn mask (each imported once per file) and whether they are
    // transposed.
    let planes = [("xy", xy), ("yz", yz), ("zx", zx)].map(|(plane, spec)| {
        let (spec, role) = match (spec, shared) {
            (Some(s), _) => (s, format!("{key}.{plane}")),
            (None, Some(s)) => (s, format!("{key}.exemplar")),
            (None, None) => {
                let m = "missing: give `exemplar` for all planes or one per plane";
                return Err(config.invalid(&format!("{key}.{plane}"), m).into());
            }
        };
        let image = images.get(dag, &config.resolve(spec.path()), &role)?;
        let mask = spec.mask().map(|m| {
            let (path, role) = (config.resolve(m), format!("{role}.mask"));
            let name = format!("{} ({role})", path.display());
            Ok::<_, MethodError>((images.get(dag, &path, &role)?, name))
        });
        Ok::<_, MethodError>((image, mask.transpose()?, spec.transpose()))
    });
    let [xy, yz, zx] = planes;
    let [(xy, mxy, tx), (yz, myz, ty), (zx, mzx, tz)] = [xy?, yz?, zx?];
    let named = [mxy, myz, mzx];
    let masks = named.clone().map(|m| m.map(|(h, _)| h));
    let names = named.map(|m| m.map(|(_, n)| n));
    if masks.iter().any(Option::is_some) && params.feature_mask.is_none() {
        params.feature_mask = Some(Default::default());
    }
    let key = triples::AnalysisKey {
        analysis: params,
        transpose: [tx, ty, tz],
    };
    let spec = NodeSpec::of(AnalyseExemplar, triples::NODE).named(name);
    Ok(dag.node(
        spec,
        key,
        ([xy, yz, zx], masks),
        move |ctx, key, (planes, masks)| {
            for ((plane, mask), name) in planes.iter().zip(&masks).zip(&names) {
                let (Some(m), Some(name)) = (mask, name) else {
                    continue;
                };
                if (m.width, m.height) != (plane.width, plane.height) {
                    return Err(NodeError::input(format!(
                        "{name}: the drawn mask is {}×{}, its exemplar {}×{}: a mask must \
                         match its image texel for texel",
                        m.width, m.height, plane.width, plane.height
                    )));
                }
                if !m.pixels.iter().any(|c| (c[0] + c[1] + c[2]) / 3.0 >= 0.5) {
                    return Err(NodeError::input(format!(
                        "{name}: the drawn mask has no feature texel (none at or above half \
                         intensity): draw the curves in white on black"
                    )));
                }
            }
            Ok(triples::node(planes, masks, key, &|f| ctx.progress.set(f))?)
        },
    ))
}

/// The synthesis of one exemplar set's solid at the requested voxels that `region` owns
/// (`None`: all of them), its bricks cached as the node's pieces.
pub(super) fn add_synthesis(
    dag: &mut Dag,
    name: String,
    analysis: Handle<SolidAnalysis>,
    (field, request): (Handle<RotationField>, Handle<Request>),
    params: WithTail<synthesis::SolidParams, u8>,
) -> Handle<SolidSamples> {
    let spec = NodeSpec::of(Synthesize, crate::stages::synthesize::solid::NODE).named(name);
    dag.node(
        spec.pieces("solid brick", &params.0),
        params,
        (Keyed(analysis), Keyed(field), request),
        |ctx, WithTail(p, region), (analysis, field, req)| {
            let synth = synthesis::SolidSynthesis::new(analysis, &field, req.volume, p.clone());
            let synth = synth.map_err(NodeError::input)?;
            let voxels = volume::region_voxels(req.voxels, req.regions, *region)
                .ok_or_else(|| NodeError::internal("a region's synthesis without voxel regions"))?;
            let bricks = ctx.pieces::<(u32, [i32; 3]), Brick>(synth.pyramid())?;
            if let Some(mode) = ctx.shard() {
                let assign = |all: &[[i32; 3]]| shard::assign(all, mode.shard);
                let share =
                    synthesis::synthesize_share(&synth, &voxels, &bricks, &assign, mode.plan_only);
                return Err(ctx.shard_done(&share?));
            }
            let run = synth.synthesize_voxels(&voxels, &bricks);
            let run = run.map_err(|e| NodeError::classify(e, SolidError::is_internal));
            Ok(SolidSamples::new(voxels, run?.0))
        },
    )
}
