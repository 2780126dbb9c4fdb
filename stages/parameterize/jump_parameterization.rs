//! The jump-map parameterization of a surface (Zelinka & Garland, "Interactive Texture
//! Synthesis on Surfaces Using Jump Maps"): the texture scale (§3), the region-growing visit
//! order (§4.1), the per-edge texture offsets (§4.2.2) and the per-vertex validity boxes
//! (§4.2.4), together as the walk and the blend read them.
//!
//! Not in the paper: `scale = "auto"` picks a scale at which the exemplar spans a quarter of
//! the mesh's bounding-box diagonal, lowered until every vertex neighbourhood fits in half of
//! the exemplar; and `rotation` turns the exemplar against the field, because exemplars such
//! as wood1 have their grain across the image.

use crate::check::{ParamError, check_range};
use crate::geom::Mesh;
use crate::parameterize::edge_offsets::{
    OffsetBox, edge_offsets, largest_fitting_scale, validity_boxes,
};
use crate::parameterize::region_growing::region_growing_order;
use crate::parameterize::scale_keys::{ScaleKey, edge_factor, vertex_factors};
use glam::Vec2;
use serde::{Deserialize, Serialize};
use texsyn_core::algorithm::Failure;
use texsyn_core::math::PureMath;

/// The `jump_offsets` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("jump_offsets", 1);

/// `[parameterize]`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ParameterizeParams {
    /// Texture scale in exemplar texels per object-space unit (§3), or "auto". Default: "auto", so
    /// that the exemplar's width spans a quarter of the mesh's bounding-box diagonal (or less
    /// if the mesh's triangles would not fit).
    pub scale: Scale,
    /// The vertex where region growing starts (§4.1). Default: 0.
    pub seed_vertex: u32,
    /// Turns the exemplar against the field, in degrees counter-clockwise, -360..=360: the
    /// field says where the exemplar's "up" goes, and 90 makes an exemplar's horizontal
    /// features (wood grain, stripes) follow the field instead of crossing it. Default: 0.
    pub rotation: f32,
    /// §1: "the mesh must be refined until each triangle fits". With a scale in texels, split
    /// every edge that spans more than an eighth of the exemplar's shorter side (the core's
    /// edge refiner), so each vertex neighbourhood fits in a quarter of it, and texture the
    /// refined mesh; shorter edges are left alone. Default: false (a scale whose triangles do
    /// not fit is refused, naming the largest that fits). Left out of the node's key when off.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub refine: bool,
    /// A scale that varies over the surface ([`crate::parameterize::scale_keys`]): factors of
    /// `scale` at given places, relaxed in between. Default: none (one scale). Left out of the
    /// node's key when empty.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub scale_keys: Vec<ScaleKey>,
}

/// The `jump_refine` node's algorithm and version ([`refine_to_fit`]; part of its key; bump on
/// any change of output).
pub const REFINE_NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("jump_refine", 1);

/// Most vertices `refine` may make.
pub const REFINE_MAX_VERTICES: usize = 5_000_000;

/// Edges after `refine`, in exemplar texels, as a share of the exemplar's shorter side.
const REFINE_EDGE_SHARE: f32 = 0.125;

/// The `parameterize.refine` step: `mesh` with every edge at most an eighth of the exemplar's
/// shorter side (`width × height`) at `scale` texels per unit; the mesh itself when its edges
/// already are.
pub fn refine_to_fit(
    mesh: &Mesh,
    scale: f32,
    (width, height): (u32, u32),
) -> Result<Mesh, Failure> {
    let max_edge = REFINE_EDGE_SHARE * width.min(height) as f32 / scale;
    let r = crate::geom::edge_refine::refine_edges(mesh, max_edge, REFINE_MAX_VERTICES).map_err(
        |e| {
            Failure::input(format!(
                "parameterize.refine: {e}; lower parameterize.scale (now {scale}) or use a larger exemplar"
            ))
        },
    )?;
    tracing::info!(
        "parameterize: refined so that triangles fit the exemplar: {} → {} vertices",
        mesh.vertex_count(),
        r.mesh.vertex_count()
    );
    Ok(r.mesh)
}

/// `parameterize.scale`: a number of texels per object unit, or "auto".
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum Scale {
    Texels(f32),
    Auto(AutoWord),
}

/// The word `"auto"`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum AutoWord {
    Auto,
}

impl Default for Scale {
    fn default() -> Self {
        Scale::Auto(AutoWord::Auto)
    }
}

impl ParameterizeParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        if let Scale::Texels(s) = self.scale
            && !(s.is_finite() && s > 0.0)
        {
            return Err(ParamError::invalid(
                "parameterize.scale",
                format!("must be a positive number of texels per unit, got {s}"),
            ));
        }
        if !(self.rotation.is_finite() && (-360.0..=360.0).contains(&self.rotation)) {
            return Err(ParamError::invalid(
                "parameterize.rotation",
                format!("must be in -360..=360 degrees, got {}", self.rotation),
            ));
        }
        crate::parameterize::scale_keys::validate(&self.scale_keys)
    }
}

/// Why a parameterization cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum ParameterizeError {
    #[error(transparent)]
    Param(#[from] ParamError),
    #[error("the exemplar ({width}×{height}) is too small to texture a surface")]
    ExemplarTooSmall { width: u32, height: u32 },
    #[error(
        "parameterize.scale = {scale} texels per unit is too large for this mesh and a {width}×{height} exemplar: \
         some triangles do not fit in the exemplar (§1 of the paper). They fit at scale ≤ {fit_s}; \
         for good results use at most {half}, or set parameterize.refine = true to split them",
        fit_s = crate::check::Significant(*fit as f64),
        half = crate::check::Significant(0.5 * *fit as f64)
    )]
    ScaleTooLarge {
        scale: f32,
        width: u32,
        height: u32,
        fit: f32,
    },
    #[error("the field has {field} directions for {vertices} vertices (a bug in texsyn)")]
    FieldLength { field: usize, vertices: usize },
}

impl ParameterizeError {
    /// Whether texsyn is at fault (stored artifacts that disagree), not the user's input.
    pub fn is_internal(&self) -> bool {
        matches!(self, ParameterizeError::FieldLength { .. })
    }
}

/// The parameterization as it is computed; [`ParamParts`] is how the walk and the blend read
/// it (borrowed from this or from a stored artifact).
pub struct JumpParameterization {
    pub meta: ParamMeta,
    pub order: Vec<u32>,
    pub seeds: Vec<u32>,
    pub adj_offsets: Vec<u32>,
    pub neighbors: Vec<u32>,
    pub edge_offsets: Vec<Vec2>,
    pub boxes: Vec<OffsetBox>,
}

/// Metadata of a jump-map parameterization (stored with it by the artifact format).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ParamMeta {
    pub vertices: u64,
    /// Texels per object-space unit actually used.
    pub scale: f32,
    /// The exemplar size the boxes were checked against.
    pub exemplar: (u32, u32),
    /// Connected components (= seeds of the order).
    pub components: u32,
}

/// What the jump-map walk (`synthesize::jump_walk`) reads of a parameterization: the mesh's
/// connectivity, the edge offsets, the validity boxes and the visiting order.
#[derive(Clone, Copy)]
pub struct WalkInput<'a> {
    /// One-ring in compressed-row form (as [`crate::geom::VertexAdjacency`]).
    pub adj_offsets: &'a [u32],
    pub neighbors: &'a [u32],
    /// Texture-space offset of each half-edge `v → neighbors[h]`.
    pub edge_offsets: &'a [Vec2],
    pub boxes: &'a [OffsetBox],
    pub order: &'a [u32],
}

/// A parameterization as the walk and the blend read it: the order, the edge offsets in
/// compressed adjacency form and the validity boxes (views into an artifact, or owned arrays).
pub struct ParamParts<'a> {
    pub meta: ParamMeta,
    pub order: &'a [u32],
    pub seeds: &'a [u32],
    pub adj_offsets: &'a [u32],
    pub neighbors: &'a [u32],
    pub edge_offsets: &'a [Vec2],
    pub boxes: &'a [OffsetBox],
}

impl ParamParts<'_> {
    pub fn walk_input(&self) -> WalkInput<'_> {
        WalkInput {
            adj_offsets: self.adj_offsets,
            neighbors: self.neighbors,
            edge_offsets: self.edge_offsets,
            boxes: self.boxes,
            order: self.order,
        }
    }

    /// Offset of the half-edge a → b, if the edge exists.
    pub fn offset(&self, a: u32, b: u32) -> Option<Vec2> {
        let start = self.adj_offsets[a as usize] as usize;
        let end = self.adj_offsets[a as usize + 1] as usize;
        self.neighbors[start..end]
            .binary_search(&b)
            .ok()
            .map(|k| self.edge_offsets[start + k])
    }
}

pub fn jump_parameterization(
    mesh: &Mesh,
    up: &[glam::Vec3],
    (w, h): (u32, u32),
    p: &ParameterizeParams,
) -> Result<JumpParameterization, ParameterizeError> {
    if up.len() != mesh.vertex_count() {
        return Err(ParameterizeError::FieldLength {
            field: up.len(),
            vertices: mesh.vertex_count(),
        });
    }
    let n = mesh.vertex_count();
    check_range(
        "parameterize.seed_vertex",
        p.seed_vertex as usize,
        0,
        n.saturating_sub(1),
    )?;
    if w < 2 || h < 2 {
        return Err(ParameterizeError::ExemplarTooSmall {
            width: w,
            height: h,
        });
    }
    let adj = mesh.adjacency();
    let mut scale = match p.scale {
        Scale::Texels(s) => s,
        Scale::Auto(_) => crate::parameterize::automatic_scale(mesh, w),
    };
    let factors = vertex_factors(mesh, &p.scale_keys)?;
    let offsets_at = |scale: f32| {
        let mut o = edge_offsets(mesh, adj, up, scale);
        if !p.scale_keys.is_empty() {
            for v in 0..n {
                let (a, b) = (adj.offsets[v] as usize, adj.offsets[v + 1] as usize);
                for (d, &w) in o[a..b].iter_mut().zip(&adj.neighbors[a..b]) {
                    *d *= edge_factor(factors[v], factors[w as usize]);
                }
            }
        }
        if p.rotation != 0.0 {
            // Texel y points down, so a counter-clockwise turn on screen is clockwise in
            // (x, y). Negation commutes with the rotation exactly, keeping offsets antisymmetric.
            let (s, c) = (-p.rotation.to_radians()).sin_cos_pure();
            for d in &mut o {
                *d = glam::Vec2::new(c * d.x - s * d.y, s * d.x + c * d.y);
            }
        }
        o
    };
    let mut offsets = offsets_at(scale);
    let mut boxes = validity_boxes(adj, &offsets);
    let fit = largest_fitting_scale(&boxes, scale, w, h);
    if let Scale::Texels(_) = p.scale {
        if fit < scale {
            return Err(ParameterizeError::ScaleTooLarge {
                scale,
                width: w,
                height: h,
                fit,
            });
        }
        if fit < 2.0 * scale {
            tracing::warn!(
                "parameterize: at scale {scale} some vertex neighbourhoods span more than half the exemplar, \
                 leaving few valid addresses; scale ≤ {:.4} gives the walk more room",
                0.5 * fit
            );
        }
    } else if fit < 2.0 * scale {
        scale = 0.5 * fit;
        tracing::info!(
            "parameterize: automatic scale lowered to {scale} so that triangles fit the exemplar"
        );
        offsets = offsets_at(scale);
        boxes = validity_boxes(adj, &offsets);
    }
    let seed = if (p.seed_vertex as usize) < n {
        p.seed_vertex
    } else {
        0
    };
    let order = region_growing_order(adj, seed);
    Ok(JumpParameterization {
        meta: ParamMeta {
            vertices: n as u64,
            scale,
            exemplar: (w, h),
            components: order.seeds.len() as u32,
        },
        order: order.order,
        seeds: order.seeds,
        adj_offsets: adj.offsets.clone(),
        neighbors: adj.neighbors.clone(),
        edge_offsets: offsets,
        boxes,
    })
}

/// The parameterize node (§4.1): the walk's order, edge offsets and validity boxes. It reads
/// the exemplar only for its size.
pub fn node(
    mesh: &Mesh,
    up: &[glam::Vec3],
    exemplar: crate::image::ImageView,
    p: &ParameterizeParams,
) -> Result<JumpParameterization, Failure> {
    jump_parameterization(mesh, up, (exemplar.width, exemplar.height), p)
        .map_err(|e| Failure::classify(e, ParameterizeError::is_internal))
}
