//! Feature-aligned texturing's `[parameterize]`: the input mesh refined by edge splitting
//! until its vertices are about a texel apart (Xu et al. 2009, §5.1 optimizes per-vertex
//! colours, so the vertex spacing is the texture's resolution). The refiner is
//! [`texsyn_core::geom::edge_refine`].

use crate::geom::Mesh;
use crate::geom::edge_refine::{Refined, refine_edges};
use serde::{Deserialize, Serialize};
use texsyn_core::algorithm::Failure;
use texsyn_core::check::{ParamError, check_range};

pub use texsyn_core::geom::edge_refine::NODE;

/// `[parameterize]`: how fine the mesh is made for synthesis.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RefineParams {
    /// Exemplar texels per object unit: sets the texture's size on the mesh. Default:
    /// `"auto"` (read as 0 and resolved by the method: the exemplar's width spans a quarter
    /// of the mesh's bounding-box diagonal).
    #[serde(deserialize_with = "crate::parameterize::texels_or_auto")]
    pub scale: f32,
    /// Longest edge after refinement, in exemplar texels, 0.25..=8. Default: 1 (a vertex per
    /// texel, what §5's per-vertex optimization needs to show the texture's detail).
    pub edge: f32,
    /// Most vertices the refined mesh may have, 1000..=20,000,000. Default: 1,000,000.
    pub max_vertices: u32,
}

impl Default for RefineParams {
    fn default() -> Self {
        RefineParams {
            scale: 0.0,
            edge: 1.0,
            max_vertices: 1_000_000,
        }
    }
}

impl RefineParams {
    /// The ranges of `edge` and `max_vertices` (the scale is checked where it is required).
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("parameterize.edge", self.edge, 0.25, 8.0)?;
        check_range(
            "parameterize.max_vertices",
            self.max_vertices,
            1000,
            20_000_000,
        )
    }
}

/// The parameterize node: the refined mesh, each edge at most `edge / scale` long.
pub fn node(mesh: &Mesh, p: &RefineParams) -> Result<Refined, Failure> {
    let r = refine_edges(mesh, p.edge / p.scale, p.max_vertices as usize).map_err(|e| {
        Failure::input(format!(
            "parameterize: {e}; lower parameterize.scale or raise parameterize.edge or \
             parameterize.max_vertices"
        ))
    })?;
    let (from, to) = (mesh.vertex_count(), r.mesh.vertex_count());
    tracing::info!("parameterize: {from} → {to} vertices");
    Ok(r)
}
