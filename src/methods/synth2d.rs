//! Method `synth2d`: the image jump-map algorithm (Zelinka & Garland 2002, reviewed in §4.2.1
//! of the surfaces paper), which shows the jump map working on images before it is used on
//! surfaces. Shares the `analyse_exemplar` node (same algorithm, same key) with `jump_maps`.
//!
//! ```text
//! inputs.exemplar ─ import.exemplar ─ analyse_exemplar ─ synthesize (addresses) ─ reconstruct ─ files
//! ```

use super::jump_maps::add_jump_map;
use super::{Method, MethodError, Planned, input};
use crate::artifact::Bundle;
use crate::artifact::jump_maps::AddressImage;
use crate::config::Config;
use crate::image::Image;
use crate::pipeline::{Dag, NodeSpec, Stage};
use crate::score::Synth2dNodes;
use crate::stages::analyse_exemplar::jump_map::JumpMapParams;
use crate::stages::reconstruct::blend2d::{self, Blend2dParams};
use crate::stages::synthesize::synth2d::{self, Synth2dParams};
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
    pub synthesize: Synth2dParams,
    #[serde(default)]
    pub reconstruct: Blend2dParams,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Inputs {
    pub exemplar: PathBuf,
}

/// The `synth2d` method.
pub struct Synth2d;

impl Method for Synth2d {
    fn name(&self) -> &'static str {
        "synth2d"
    }

    fn plan(&self, config: &Config) -> Result<(Dag, Box<dyn Planned>), MethodError> {
        let c: Synth2dConfig = config.parse()?;
        config.check("analyse_exemplar", c.analyse_exemplar.validate())?;
        config.check("synthesize", c.synthesize.validate())?;
        config.check("reconstruct", c.reconstruct.validate())?;
        let (w, h) = (c.synthesize.width as u64, c.synthesize.height as u64);
        super::check_memory(
            config,
            "synthesize.width",
            w,
            |w| synth2d::memory_estimate(w, h),
            |w| format!("{w} (with height {h})"),
        )?;

        let mut dag = Dag::default();
        let exemplar = input::<Image>(&mut dag, config, "exemplar", &c.inputs.exemplar)?;
        let jump_map = add_jump_map(&mut dag, exemplar, c.analyse_exemplar.clone());
        let synthesize = dag.node(
            NodeSpec::of(Stage::Synthesize, synth2d::NODE),
            c.synthesize.clone(),
            jump_map,
            |_, p, jm| {
                let (size, addresses) = ((p.width, p.height), synth2d::node(jm, p));
                Ok(AddressImage { size, addresses })
            },
        );
        let reconstruct = dag.node(
            NodeSpec::of(Stage::Reconstruct, blend2d::NODE),
            c.reconstruct.clone(),
            (synthesize, exemplar),
            |_, p, (a, exemplar)| {
                Ok(Bundle::from(blend2d::node(
                    exemplar,
                    a.addresses,
                    a.size,
                    p,
                )))
            },
        );
        let nodes = Synth2dNodes {
            reconstruct,
            exemplar,
        };
        Ok((dag, Box::new(nodes)))
    }
}
