//! Method `jump_maps`: texture coordinates on a mesh from a jump map of the exemplar
//! (Zelinka & Garland, "Interactive Texture Synthesis on Surfaces Using Jump Maps").
//!
//! ```text
//! inputs.exemplar ─ import.exemplar ─ analyse_exemplar (jump map) ───────────┐
//!                                  └──────────────┐                          │
//! inputs.mesh ── import.mesh ── field ── parameterize (order, offsets, boxes) ─ synthesize (walk)
//!                            └───────────────────────────────────────────────── reconstruct ─ files
//! ```
//!
//! `parameterize` reads the exemplar only for its size (to check that triangles fit and for
//! the automatic scale), so a new exemplar of the same size reruns it cheaply and, by early
//! cutoff, nothing downstream on its account.

mod config;

pub use config::{Inputs, JumpMapsConfig};

use super::{Method, MethodError, Planned, import, input};
use crate::artifact::Bundle;
use crate::artifact::jump_maps::{OrientationField, TexelAddresses};
use crate::config::Config;
use crate::geom::Mesh;
use crate::image::Image;
use crate::pipeline::{Dag, Handle, NodeSpec, Stage};
use crate::score::charts::JumpMapNodes;
use crate::stages::analyse_exemplar::jump_map::{self, JumpMap, JumpMapParams};
use crate::stages::field::orientation_field::{self};
use crate::stages::parameterize::jump_parameterization::{self, Scale};
use crate::stages::reconstruct::jump_export::{self, JumpExportKey, MapFile};
use crate::stages::synthesize::jump_walk::{self};

/// The `jump_maps` method.
pub struct JumpMaps;

impl Method for JumpMaps {
    fn name(&self) -> &'static str {
        "jump_maps"
    }

    fn plan(&self, config: &Config) -> Result<(Dag, Box<dyn Planned>), MethodError> {
        let c = config::checked(config)?;
        let mut dag = Dag::default();
        let mesh = input::<Mesh>(&mut dag, config, "mesh", &c.inputs.mesh)?;
        let exemplar = input::<Image>(&mut dag, config, "exemplar", &c.inputs.exemplar)?;
        // `parameterize.refine`: everything downstream works on the refined mesh.
        let mesh = match (c.parameterize.refine, &c.parameterize.scale) {
            (false, _) => mesh,
            (true, Scale::Texels(scale)) => {
                // Split for the largest scale a key asks for.
                let largest = crate::stages::parameterize::scale_keys::largest_factor(
                    &c.parameterize.scale_keys,
                );
                let scale = if largest > 1.0 {
                    scale * largest
                } else {
                    *scale
                };
                let spec = NodeSpec::of(Stage::Parameterize, jump_parameterization::REFINE_NODE)
                    .named("parameterize.refine");
                dag.node(spec, scale, (mesh, exemplar), |_, scale, (mesh, e)| {
                    Ok(jump_parameterization::refine_to_fit(
                        &mesh,
                        *scale,
                        (e.width, e.height),
                    )?)
                })
            }
            (true, Scale::Auto(_)) => {
                let m = "needs a scale in texels: \"auto\" already lowers the scale until \
                         triangles fit";
                return Err(config.invalid("parameterize.refine", m).into());
            }
        };
        let jump_map = add_jump_map(&mut dag, exemplar, c.analyse_exemplar.clone());
        let field = dag.node(
            NodeSpec::of(Stage::Field, orientation_field::NODE),
            c.field.clone(),
            mesh,
            |_, p, mesh| {
                Ok(OrientationField(orientation_field::node(
                    &mesh,
                    p,
                    "jump_maps",
                )?))
            },
        );
        let parameterize = dag.node(
            NodeSpec::of(Stage::Parameterize, jump_parameterization::NODE),
            c.parameterize.clone(),
            (mesh, field, exemplar),
            |_, p, (mesh, up, e)| Ok(jump_parameterization::node(&mesh, up, e, p)?),
        );
        let synthesize = dag.node(
            NodeSpec::of(Stage::Synthesize, jump_walk::NODE),
            c.synthesize.clone(),
            (parameterize, jump_map),
            |ctx, p, (param, jm)| {
                let walk = jump_walk::node(&param, jm, p, &|f| ctx.progress.set(f))?;
                Ok(TexelAddresses::new(walk, (jm.width, jm.height)))
            },
        );
        // The exemplar is exported as `basecolor`, the first of the maps the export copies.
        let exemplar_path = config.resolve(&c.inputs.exemplar);
        let mut maps = vec![(exemplar, dag.file(&exemplar_path, "inputs.exemplar")?)];
        let mut key = JumpExportKey::new(&c.reconstruct, &exemplar_path);
        for (name, path) in &c.inputs.maps {
            let (path, role) = (config.resolve(path), format!("inputs.maps.{name}"));
            let img = import::<Image>(&mut dag, &format!("import.map.{name}"), &path, &role)?;
            maps.push((img, dag.file(&path, &role)?));
            key.add_map(name, &path);
        }
        dag.node(
            NodeSpec::of(Stage::Reconstruct, jump_export::NODE),
            key,
            (mesh, parameterize, synthesize, maps),
            |ctx, p, (mesh, param, walk, maps)| {
                let maps = maps
                    .into_iter()
                    .map(|(image, f)| MapFile::new(image, &f.path, &f.bytes));
                let files =
                    jump_export::node(p, &mesh, &param, walk.addresses, maps.collect(), &|f| {
                        ctx.progress.set(f)
                    })?;
                Ok(Bundle::from(files))
            },
        );
        let nodes = JumpMapNodes {
            mesh,
            parameterize,
            synthesize,
            exemplar,
            blend_radius: c.reconstruct.blend_radius,
        };
        Ok((dag, Box::new(nodes)))
    }
}

/// The jump map of an exemplar (analyse-exemplar, §2 of the 2002 paper); `synth2d` uses the
/// same node, so the two methods share the cached map.
pub(crate) fn add_jump_map(
    dag: &mut Dag,
    exemplar: Handle<Image>,
    params: JumpMapParams,
) -> Handle<JumpMap> {
    dag.node(
        NodeSpec::of(Stage::AnalyseExemplar, jump_map::NODE),
        params,
        exemplar,
        |ctx, p, img| Ok(jump_map::node(img, p, &|f| ctx.progress.set(f))?),
    )
}
