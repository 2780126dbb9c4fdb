//! Method `synth2d`: the image jump-map algorithm (Zelinka & Garland 2002, reviewed in §4.2.1
//! of the surfaces paper), which shows the jump map working on images before it is used on
//! surfaces. Shares the `analyse_exemplar` node (same algorithm, same key) with `jump_maps`.
//!
//! ```text
//! inputs.exemplar ─ import.exemplar ─ analyse_exemplar ─ synthesize (addresses) ─ reconstruct ─ files
//! ```

use super::jump_maps::add_jump_map;
use super::{Method, MethodError, Planned, import};
use crate::artifact::Bundle;
use crate::artifact::jump_maps::AddressImage;
use crate::check::{ParamError, check_range};
use crate::config::Config;
use crate::image::Image;
use crate::pipeline::{Dag, Handle, NodeSpec, Stage};
use crate::score::{Item, Run, ScoreFailure};
use crate::stages::analyse_exemplar::jump_map::JumpMapParams;
use crate::stages::reconstruct::blend2d::render_2d;
use crate::stages::reconstruct::textured_export::encode_png;
use crate::stages::synthesize::synth2d::{Synth2dParams, synthesize_2d};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

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

impl RenderSection {
    fn validate(&self) -> Result<(), ParamError> {
        check_range("reconstruct.blend_radius", self.blend_radius, 0, 8)
    }
}

impl SynthSection {
    /// The output size, then the walk's own parameters.
    fn validate(&self) -> Result<(), ParamError> {
        check_range("synthesize.width", self.width, 1, 16384)?;
        check_range("synthesize.height", self.height, 1, 16384)?;
        self.walk().validate()
    }

    /// The walk's own parameters (the rest say where and how much to synthesize).
    fn walk(&self) -> Synth2dParams {
        Synth2dParams {
            continuation: self.continuation,
            boundary_fraction: self.boundary_fraction,
            combine_neighbours: self.combine_neighbours,
        }
    }
}

/// The `synth2d` method.
pub struct Synth2d;

impl Method for Synth2d {
    fn name(&self) -> &'static str {
        "synth2d"
    }

    fn plan(&self, config: &Config) -> Result<(Dag, Box<dyn Planned>), MethodError> {
        let (dag, nodes) = build(config)?;
        Ok((dag, Box::new(nodes)))
    }
}

/// The nodes `synth2d`'s score reads.
struct Synth2dNodes {
    reconstruct: Handle<Bundle>,
    exemplar: Handle<Image>,
}

impl Planned for Synth2dNodes {
    fn score(&self, run: &Run<'_>, _: &mut Vec<String>) -> Result<Vec<Item>, ScoreFailure> {
        Ok(vec![crate::score::synth2d(
            run,
            self.reconstruct,
            self.exemplar,
        )?])
    }
}

fn build(config: &Config) -> Result<(Dag, Synth2dNodes), MethodError> {
    let c: Synth2dConfig = config.parse()?;
    config.check("analyse_exemplar", c.analyse_exemplar.validate())?;
    config.check("synthesize", c.synthesize.validate())?;
    config.check("reconstruct", c.reconstruct.validate())?;
    let (w, h) = (c.synthesize.width as u64, c.synthesize.height as u64);
    super::check_memory(
        config,
        "synthesize.width",
        w,
        |w| crate::stages::synthesize::synth2d::memory_estimate(w, h),
        |w| format!("{w} (with height {h})"),
    )?;
    let s = c.synthesize.clone();

    let mut dag = Dag::default();
    let exemplar = import::<Image>(
        &mut dag,
        "import.exemplar",
        &config.resolve(&c.inputs.exemplar),
        "inputs.exemplar",
    )?;
    let jump_map = add_jump_map(&mut dag, exemplar, c.analyse_exemplar.clone());
    let synth = dag.node(
        NodeSpec::of(Stage::Synthesize, crate::stages::synthesize::synth2d::NODE),
        s,
        jump_map,
        |_, s, jm| {
            Ok(AddressImage {
                size: (s.width, s.height),
                addresses: synthesize_2d(jm, s.width, s.height, &s.walk(), s.seed),
            })
        },
    );
    let reconstruct = dag.node(
        NodeSpec::of(
            Stage::Reconstruct,
            crate::stages::reconstruct::blend2d::NODE,
        ),
        c.reconstruct.clone(),
        (synth, exemplar),
        |_, r, (a, exemplar)| {
            let (w, h) = a.size;
            let addr = a.addresses;
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
            Ok(Bundle::from(vec![
                ("synthesized.png".into(), encode_png(&img.to_rgba8(), false)),
                (
                    "coordinates.png".into(),
                    encode_png(&coords.to_rgba8(), false),
                ),
            ]))
        },
    );
    Ok((
        dag,
        Synth2dNodes {
            reconstruct,
            exemplar,
        },
    ))
}
