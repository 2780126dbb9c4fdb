//! Feature-aligned texturing's `[parameterize]`: the input mesh refined by edge splitting
//! until its vertices are about a texel apart (Xu et al. 2009, §5.1 optimizes per-vertex
//! colours, so the vertex spacing is the texture's resolution). The refiner is
//! [`texsyn_core::geom::edge_refine`].

use crate::geom::Mesh;
use crate::geom::edge_refine::{RefineError, Refined, refine_edges};
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

/// Vertices per unit area that [`refine_edges`] makes, for edges of at most 1 unit: at
/// least [`FEWEST_PER_AREA`], since a triangle with edges ≤ 1 has area ≤ √3/4 and a closed
/// mesh has half as many vertices as triangles; usually at most [`MOST_PER_AREA`], since
/// halving stops once an edge is at most the limit, so edges end between half of it and all
/// of it (an equilateral mesh of edge ½ has 4.6). Measured on the shared meshes at 100–300
/// texels per unit: 2.6–5.0, and above 6 where splitting skinny faces makes skinnier ones.
const FEWEST_PER_AREA: f64 = 1.15;
const MOST_PER_AREA: f64 = 6.0;

/// A scale at most `scale` whose refinement fits `p.max_vertices`, close to the largest:
/// `scale` itself when the area estimate says it fits even at [`MOST_PER_AREA`]; otherwise
/// found by refining, starting from the largest scale that fits at [`FEWEST_PER_AREA`] and
/// lowering by the overshoot each refusal reports. `None` when even the input's vertices do
/// not fit. Cost: a few refinements up to the budget, only for a scale that may not fit.
pub fn largest_scale_within_budget(mesh: &Mesh, scale: f32, p: &RefineParams) -> Option<f32> {
    let area: f64 = (0..mesh.face_count())
        .map(|f| 0.5 * mesh.face_normal_unnormalized(f).length() as f64)
        .sum();
    let room = p.max_vertices as f64 - mesh.vertex_count() as f64;
    if room <= 0.0 {
        return None;
    }
    let texels2 = area / (p.edge as f64 * p.edge as f64);
    let fits_at = |per_area: f64| (room / (per_area * texels2)).sqrt() as f32;
    if scale <= fits_at(MOST_PER_AREA) {
        return Some(scale);
    }
    let mut s = scale.min(fits_at(FEWEST_PER_AREA));
    for _ in 0..64 {
        match refine_edges(mesh, p.edge / s, p.max_vertices as usize) {
            Err(RefineError::TooManyVertices { have, adding, .. }) => {
                // At least the refused count is needed; vertices grow with the scale².
                let over = p.max_vertices as f64 / (have + adding) as f64;
                s *= (0.95 * over.sqrt()).clamp(0.5, 0.9) as f32;
            }
            // Fits, or fails for a reason the node names in the same words.
            _ => return Some(s),
        }
    }
    Some(s)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::primitives::{cuboid, icosphere, torus};
    use glam::Vec3;

    /// On shapes with long thin faces (a slab), curved faces and coarse faces, a scale that
    /// does not fit is lowered to one whose refinement does, and not far below: its refinement
    /// holds at least a sixth of the budget.
    #[test]
    fn a_scale_over_the_budget_is_lowered_to_one_that_refines_within_it() {
        let p = RefineParams {
            scale: 0.0,
            edge: 1.0,
            max_vertices: 20_000,
        };
        for mesh in [
            cuboid(Vec3::new(4.0, 1.0, 0.1)),
            icosphere(1),
            torus(12, 8, 0.3),
        ] {
            let too_fine = 400.0;
            assert!(refine_edges(&mesh, p.edge / too_fine, 20_000).is_err());
            let scale = largest_scale_within_budget(&mesh, too_fine, &p).unwrap();
            assert!(scale < too_fine);
            let refined = refine_edges(&mesh, p.edge / scale, 20_000)
                .unwrap_or_else(|e| panic!("scale {scale}: {e}"));
            let n = refined.mesh.vertex_count();
            assert!(n >= 20_000 / 6, "scale {scale} gives only {n} vertices");
        }
    }

    /// A scale that fits is kept; a mesh with more vertices than the budget has no scale.
    #[test]
    fn a_scale_that_fits_is_kept_and_a_mesh_over_the_budget_has_none() {
        let mesh = icosphere(1);
        let p = RefineParams {
            max_vertices: 20_000,
            ..RefineParams::default()
        };
        assert_eq!(largest_scale_within_budget(&mesh, 5.0, &p), Some(5.0));
        let p = RefineParams {
            max_vertices: 10,
            ..p
        };
        assert_eq!(largest_scale_within_budget(&mesh, 5.0, &p), None);
    }
}
