//! Method `synth2d`: the image jump-map algorithm (Zelinka & Garland 2002, reviewed in §4.2.1
//! of the surfaces paper), which shows the jump map working on images before it is used on
//! surfaces. Shares the `analyse_exemplar` node (same algorithm, same key) with `jump_maps`.
//!
//! ```text
//! inputs.exemplar ─ import.exemplar ─ analyse_exemplar ─ synthesize (addresses) ─ reconstruct ─ files
//! ```

use super::{MethodError, import_image, to_json};
use crate::artifact::jump_maps::{view_jump_map, write_jump_map};
use crate::artifact::kinds::{view_image, write_bundle};
use crate::artifact::{ArtifactWriter, Kind, canonical_bytes};
use crate::config::{Config, check_range};
use crate::image::Image;
use crate::pipeline::{Dag, Node, NodeError, Stage};
use crate::stages::analyse_exemplar::jump_map::{
    JumpMapParams, build_jump_map, check_exemplar_size,
};
use crate::stages::reconstruct::blend2d::render_2d;
use crate::stages::reconstruct::textured_export::encode_png;
use crate::stages::synthesize::synth2d::{Synth2dParams, synthesize_2d};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

const SYNTH_VERSION: u32 = 1;
const RENDER_VERSION: u32 = 1;
/// Must match `jump_maps`' so the two methods share the cached jump map.
const JUMP_MAP_VERSION: u32 = 1;

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Synth2dConfig {
    pub method: String,
    pub inputs: Inputs,
    #[serde(default)]
    pub analyse_exemplar: JumpMapParams,
    #[serde(default)]
    pub synthesize: SynthSection,
    #[serde(default)]
    pub reconstruct: RenderSection,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Inputs {
    pub exemplar: PathBuf,
}

/// `[synthesize]` of `synth2d`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct SynthSection {
    /// Output size in pixels, 1..=16384 each. Default: 256 × 256.
    pub width: u32,
    pub height: u32,
    /// Default: 1.
    pub seed: u64,
    /// Weight of "do not jump": about the mean run, in pixels, between jumps. Default: 300.
    pub continuation: f32,
    /// Boundary avoidance band, as a fraction of the exemplar. Default: 0.1.
    pub boundary_fraction: f32,
    /// Draw from all synthesized neighbours' suggestions at once (§4.2.5 applied to
    /// images) rather than from one random neighbour (the 2002 algorithm). Default: true.
    pub combine_neighbours: bool,
}

impl Default for SynthSection {
    fn default() -> Self {
        let d = Synth2dParams::default();
        SynthSection {
            width: 256,
            height: 256,
            seed: 1,
            continuation: d.continuation,
            boundary_fraction: d.boundary_fraction,
            combine_neighbours: d.combine_neighbours,
        }
    }
}

/// `[reconstruct]` of `synth2d`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RenderSection {
    /// Radius of the blend kernel, 0..=8 (0 copies pixels). Default: 1.
    pub blend_radius: u32,
}

impl Default for RenderSection {
    fn default() -> Self {
        RenderSection { blend_radius: 1 }
    }
}

pub fn build(config: &Config) -> Result<Dag, MethodError> {
    let c: Synth2dConfig = config.parse()?;
    let check = |key: &str, r: Result<(), crate::check::ParamError>| config.check(key, r);
    check("analyse_exemplar", c.analyse_exemplar.validate())?;
    let s = c.synthesize.clone();
    let sp = Synth2dParams {
        continuation: s.continuation,
        boundary_fraction: s.boundary_fraction,
        combine_neighbours: s.combine_neighbours,
    };
    check("synthesize", sp.validate())?;
    check(
        "synthesize.width",
        check_range("synthesize.width", s.width, 1, 16384),
    )?;
    check(
        "synthesize.height",
        check_range("synthesize.height", s.height, 1, 16384),
    )?;
    check(
        "reconstruct.blend_radius",
        check_range("reconstruct.blend_radius", c.reconstruct.blend_radius, 0, 8),
    )?;

    let mut dag = Dag::default();
    let exemplar = import_image(
        &mut dag,
        "import.exemplar",
        &config.resolve(&c.inputs.exemplar),
        "inputs.exemplar",
    )?;
    let p = c.analyse_exemplar.clone();
    let jump_map = dag.add(Node {
        name: "analyse_exemplar".into(),
        stage: Stage::AnalyseExemplar,
        algorithm: "jump_map",
        version: JUMP_MAP_VERSION,
        params: canonical_bytes(&p),
        params_json: to_json(&p),
        inputs: vec![exemplar],
        exports: false,
        compute: Box::new(move |ctx| {
            let img = view_image(ctx.artifact(0))?;
            check_exemplar_size(img.width, img.height).map_err(NodeError::input)?;
            Ok(write_jump_map(&build_jump_map(img, &p, &|f| {
                ctx.progress.set(f)
            })))
        }),
    });
    let synth = dag.add(Node {
        name: "synthesize".into(),
        stage: Stage::Synthesize,
        algorithm: "jump_walk_2d",
        version: SYNTH_VERSION,
        params: canonical_bytes(&s),
        params_json: to_json(&s),
        inputs: vec![jump_map],
        exports: false,
        compute: Box::new(move |ctx| {
            let jm = view_jump_map(ctx.artifact(0))?;
            let addr = synthesize_2d(jm, s.width, s.height, &sp, s.seed);
            Ok(
                ArtifactWriter::new(Kind::AddressImage, &(s.width, s.height))
                    .array("addresses", &addr)
                    .finish(),
            )
        }),
    });
    let r = c.reconstruct.clone();
    dag.add(Node {
        name: "reconstruct".into(),
        stage: Stage::Reconstruct,
        algorithm: "blend_2d",
        version: RENDER_VERSION,
        params: canonical_bytes(&r),
        params_json: to_json(&r),
        inputs: vec![synth, exemplar],
        exports: true,
        compute: Box::new(move |ctx| {
            let a = ctx.artifact(0);
            a.expect_kind(Kind::AddressImage)?;
            let (w, h): (u32, u32) = a.meta()?;
            let addr: &[[u16; 2]] = a.array("addresses")?;
            if addr.len() != w as usize * h as usize {
                return Err(NodeError::internal(
                    "address image size disagrees with metadata",
                ));
            }
            let exemplar = view_image(ctx.artifact(1))?;
            let img = render_2d(exemplar, addr, w, h, r.blend_radius);
            // The coordinate map (red = x, green = y, scaled to the exemplar) lets a user
            // apply the same synthesis to other maps of the material.
            let mut coords = Image::new(w, h);
            for (px, a) in coords.pixels.iter_mut().zip(addr) {
                *px = [
                    a[0] as f32 / (exemplar.width.max(2) - 1) as f32,
                    a[1] as f32 / (exemplar.height.max(2) - 1) as f32,
                    0.0,
                    1.0,
                ];
            }
            Ok(write_bundle(&[
                ("synthesized.png".into(), encode_png(&img.to_rgba8(), false)),
                (
                    "coordinates.png".into(),
                    encode_png(&coords.to_rgba8(), false),
                ),
            ]))
        }),
    });
    Ok(dag)
}
