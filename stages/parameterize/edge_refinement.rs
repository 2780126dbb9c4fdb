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
/// least this, since a triangle with edges ≤ 1 has area ≤ √3/4 and a closed mesh has half as
/// many vertices as triangles.
const FEWEST_PER_AREA: f64 = 1.15;

/// Vertices per unit area that [`refine_edges`] usually makes at most: measured on the shared
/// meshes at 100–300 texels per unit, 2.6–5.0, and above 6 where splitting skinny faces
/// makes skinnier ones. Area alone misjudges a needle or a squashed sheet (little area, long
/// edges), so the quick acceptance also counts the splits along the input's own edges.
const MOST_PER_AREA: f64 = 6.0;

/// A refinement estimated to need at most this share of the budget is accepted without
/// refining, so planning stays cheap for the common case (a scale far inside the budget).
const QUICK_SHARE: f64 = 0.5;

/// Refusals before giving up; each lowers the scale by at least a tenth.
const MAX_TRIES: usize = 64;

/// A scale at most `scale` whose refinement fits `p.max_vertices`, close to the largest.
/// `scale` itself when the estimate ([`MOST_PER_AREA`] of the area, plus the splits along
/// every input edge, each edge counted once per triangle) needs at most [`QUICK_SHARE`] of
/// the room; otherwise every answer is checked by refining: the first try is the largest
/// scale that can fit by the area bound [`FEWEST_PER_AREA`] (or, when the input alone fills
/// the budget, the largest at which no edge is split), and each refusal lowers it by the
/// overshoot it reports. `None` when no tried scale fits. Cost: nothing for a scale far
/// inside the budget; otherwise a refinement up to the budget per try, paid wherever the
/// scale is resolved (`run`, `plan`, `score`).
pub fn largest_scale_within_budget(mesh: &Mesh, scale: f32, p: &RefineParams) -> Option<f32> {
    let area: f64 = (0..mesh.face_count())
        .map(|f| 0.5 * mesh.face_normal_unnormalized(f).length() as f64)
        .sum();
    let room = (p.max_vertices as f64 - mesh.vertex_count() as f64).max(0.0);
    let texels2 = area / (p.edge as f64 * p.edge as f64);
    let by_area = (room / (FEWEST_PER_AREA * texels2)).sqrt() as f32;
    let edge_lengths = || {
        (mesh.triangles.iter())
            .flat_map(|t| (0..3).map(move |k| (t[k], t[(k + 1) % 3])))
            .map(|(a, b)| mesh.positions[a as usize].distance(mesh.positions[b as usize]))
    };
    let longest = edge_lengths().fold(0.0f32, f32::max);
    let limit = (p.edge / scale) as f64;
    let along_edges: f64 = edge_lengths()
        .map(|l| (l as f64 / limit).ceil().max(1.0) - 1.0)
        .sum();
    let estimate = MOST_PER_AREA * area / (limit * limit) + along_edges;
    if estimate.is_finite() && estimate <= QUICK_SHARE * room {
        return Some(scale);
    }
    // A hair below `edge / longest`, so that rounding in `edge / scale` splits nothing.
    let unsplit = if longest > 0.0 {
        p.edge / longest * (1.0 - 1e-5)
    } else {
        f32::INFINITY
    };
    // NaN (no area and no room) compares false in `max`, which keeps `unsplit`.
    let mut s = scale.min(by_area.max(unsplit));
    for _ in 0..MAX_TRIES {
        if !(s.is_finite() && s > 0.0) {
            return None;
        }
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
    None
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

    /// A scale that fits is kept. Meshes whose area says nothing of their refinement (a
    /// needle, a sheet squashed to almost no height; [`MOST_PER_AREA`] of their area alone says
    /// both fit the budget at the scales below) still get a scale that refines within the budget: the quick
    /// acceptance counts their edges' splits, and the search checks what it returns. A mesh that alone fills the budget
    /// gets the largest scale that splits none of its edges, which the node accepts.
    #[test]
    fn every_answer_refines_within_the_budget_even_where_the_area_misleads() {
        let p = RefineParams {
            max_vertices: 20_000,
            ..RefineParams::default()
        };
        assert_eq!(
            largest_scale_within_budget(&icosphere(1), 5.0, &p),
            Some(5.0)
        );
        let mut squashed = crate::geom::primitives::grid(40, 1.0);
        for v in &mut squashed.positions {
            v.y *= 1e-3;
        }
        let needle = cuboid(Vec3::new(100.0, 0.01, 0.01));
        for (mesh, scale, budget) in [(&squashed, 10.0, 20_000), (&needle, 5.0, 1000)] {
            let p = RefineParams {
                max_vertices: budget,
                ..p
            };
            assert!(refine_edges(mesh, p.edge / scale, budget as usize).is_err());
            let fitted = largest_scale_within_budget(mesh, scale, &p).unwrap();
            assert!(fitted < scale);
            refine_edges(mesh, p.edge / fitted, budget as usize)
                .unwrap_or_else(|e| panic!("scale {fitted}: {e}"));
        }
        let full = RefineParams {
            max_vertices: 10,
            ..p
        };
        let mesh = icosphere(1);
        let s = largest_scale_within_budget(&mesh, 5.0, &full).unwrap();
        let same = refine_edges(&mesh, full.edge / s, 10).unwrap();
        assert_eq!(same.mesh.vertex_count(), mesh.vertex_count());
        let finer = refine_edges(&mesh, full.edge / (1.01 * s), 10);
        assert!(
            finer.is_err(),
            "scale {s}: {:?}",
            finer.map(|r| r.mesh.vertex_count())
        );
    }
}
