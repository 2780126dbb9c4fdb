//! Orientation field for jump-map texturing: at each vertex a unit tangent vector that says
//! where "up" in texture space points (Zelinka & Garland, "Interactive Texture Synthesis on
//! Surfaces Using Jump Maps", §3 and Fig. 2).
//!
//! The user gives anchors (a direction at a point), sinks (the field flows into them) and
//! sources (it flows out of them); these are relaxed over the mesh:
//!
//! - Sinks and sources: a harmonic potential φ (cotan Laplacian) equal to 1 at sinks and 0 at
//!   sources; the field is φ's tangential gradient. A harmonic φ has no interior extrema, so
//!   the only singularities are the ones the user placed, as §3 asks ("giving the user a
//!   greater degree of control over where these singularities occur"). A lone sink gets an
//!   implicit source at the vertex farthest from it, and vice versa.
//! - Anchors alone: the anchor vectors are interpolated harmonically as 3D vectors and
//!   projected into each tangent plane. One anchor gives its direction everywhere.
//! - Anchors with sinks/sources: the angle between each anchor and the potential's flow is
//!   interpolated harmonically and the flow is turned by it, so the anchors steer the field
//!   without moving its singularities.
//! - Nothing given (the default): a source and a sink at the two extremities of the shape
//!   along its longest axis (or `axis`), the setup of the paper's Fig. 2.
//! - Isotropic: the orientation carries no meaning. The paper suggests "assigning a random
//!   orientation field"; we depart from that: per-edge offsets average the endpoints'
//!   frames (§4.2.2), and random neighbouring frames would cancel in that average and tear
//!   the texture at every edge. Instead the projection of a fixed axis is used, smooth and
//!   free, with no solve.
//!
//! Where the result vanishes (at singularities), a neighbour's direction is used.

use crate::geom::Mesh;
use crate::geom::laplacian::{cotan_weights, harmonic_interpolate};
use glam::{DVec3, Vec3};
use serde::{Deserialize, Serialize};
use texsyn_core::algorithm::Failure;
use texsyn_core::math::PureMath;

/// The `orientation_field` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("orientation_field", 3);

/// A place on the mesh: a position (snapped to the nearest vertex) or a vertex index.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Point {
    /// A position in object space; the nearest vertex is used.
    #[serde(default)]
    pub at: Option<[f32; 3]>,
    /// A vertex index (0-based, in the file's vertex order).
    #[serde(default)]
    pub vertex: Option<u32>,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Anchor {
    #[serde(default)]
    pub at: Option<[f32; 3]>,
    #[serde(default)]
    pub vertex: Option<u32>,
    /// The "up" direction of the texture there (projected into the tangent plane).
    pub direction: [f32; 3],
}

/// `[field]` in a config.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FieldParams {
    /// The texture has no preferred direction: skip the relaxation. Default: false.
    pub isotropic: bool,
    /// Directions at points. Default: none.
    pub anchors: Vec<Anchor>,
    /// Points the field flows into. Default: none.
    pub sinks: Vec<Point>,
    /// Points the field flows out of. Default: none.
    pub sources: Vec<Point>,
    /// The axis along which the default field flows (source at its low end, sink at its
    /// high end), and the axis projected by the isotropic field. Default: the longest side
    /// of the bounding box.
    pub axis: Option<[f32; 3]>,
    /// 1, 2 or 4: the texture looks the same turned by a half (2) or a quarter (4) turn, so
    /// the field is relaxed only up to that turn ([`super::symmetric_field`]): anchors, or
    /// with none a soft `guide`. Default: 1. Left out of the node's key at 1.
    #[serde(skip_serializing_if = "is_one")]
    pub symmetry: u32,
    /// What a symmetric field without anchors follows: "flow" (the default field, symmetry
    /// 1's, taken up to the symmetry) or "axis" (`axis` projected on the surface). Default:
    /// flow. Left out of the node's key at its default.
    #[serde(skip_serializing_if = "SymmetricGuide::is_flow")]
    pub guide: SymmetricGuide,
}

/// See [`FieldParams::guide`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SymmetricGuide {
    /// The default flow: along tubes and round handles, where it already runs smoothly.
    #[default]
    Flow,
    /// The projected axis: straight courses across a shape the flow bends through.
    Axis,
}

impl SymmetricGuide {
    fn is_flow(&self) -> bool {
        *self == SymmetricGuide::Flow
    }
}

fn is_one(x: &u32) -> bool {
    *x == 1
}

impl Default for FieldParams {
    fn default() -> Self {
        FieldParams {
            isotropic: false,
            anchors: Vec::new(),
            sinks: Vec::new(),
            sources: Vec::new(),
            axis: None,
            symmetry: 1,
            guide: SymmetricGuide::Flow,
        }
    }
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FieldError {
    #[error("field.{what}[{index}]: give exactly one of `at` or `vertex`")]
    PointSpec { what: &'static str, index: usize },
    #[error(
        "field.{what}[{index}]: vertex {vertex} is out of range (the mesh has {count} vertices)"
    )]
    VertexRange {
        what: &'static str,
        index: usize,
        vertex: u32,
        count: usize,
    },
    #[error("field.{what}[{index}]: vertex {vertex} belongs to no triangle")]
    Unreferenced {
        what: &'static str,
        index: usize,
        vertex: u32,
    },
    #[error("field.{what}[{index}]: {message}")]
    Value {
        what: &'static str,
        index: usize,
        message: String,
    },
    /// The message stands alone: the pipeline prefixes the node's name ("field: ").
    #[error("{0}")]
    Other(String),
}

impl FieldParams {
    /// Checks what can be checked without the mesh.
    pub fn validate(&self) -> Result<(), FieldError> {
        let finite = |v: &[f32; 3]| v.iter().all(|x| x.is_finite());
        for (i, a) in self.anchors.iter().enumerate() {
            if !finite(&a.direction) || Vec3::from(a.direction).length() < 1e-12 {
                return Err(FieldError::Value {
                    what: "anchors",
                    index: i,
                    message: "direction must be a finite, non-zero vector".into(),
                });
            }
        }
        if let Some(axis) = &self.axis
            && (!finite(axis) || Vec3::from(*axis).length() < 1e-12)
        {
            return Err(FieldError::Other(
                "axis must be a finite, non-zero vector".into(),
            ));
        }
        if ![1, 2, 4].contains(&self.symmetry) {
            return Err(FieldError::Other(format!(
                "symmetry = {} is not one of 1, 2 or 4",
                self.symmetry
            )));
        }
        if self.guide != SymmetricGuide::Flow && (self.symmetry == 1 || !self.anchors.is_empty()) {
            return Err(FieldError::Other(
                "guide = \"axis\" guides a symmetric field without anchors (symmetry 2 or 4, no anchors): remove guide, or set symmetry and remove the anchors".into(),
            ));
        }
        if self.symmetry > 1 && self.isotropic {
            return Err(FieldError::Other(
                "isotropic = true has no direction to take up to a symmetry: remove symmetry or set isotropic = false".into(),
            ));
        }
        if self.symmetry > 1 && !(self.sinks.is_empty() && self.sources.is_empty()) {
            return Err(FieldError::Other(format!(
                "symmetry = {} relaxes anchors (or follows its guide) up to a 1/{} turn; sinks and sources make a flow, a field of symmetry 1: remove them or set symmetry = 1",
                self.symmetry, self.symmetry
            )));
        }
        if self.isotropic
            && !(self.anchors.is_empty() && self.sinks.is_empty() && self.sources.is_empty())
        {
            return Err(FieldError::Other(
                "isotropic = true ignores anchors, sinks and sources: remove them or set isotropic = false".into(),
            ));
        }
        Ok(())
    }
}

/// Computes the orientation field: a unit tangent vector per vertex (zero for vertices that
/// belong to no triangle).
pub fn orientation_field(mesh: &Mesh, params: &FieldParams) -> Result<Vec<Vec3>, FieldError> {
    params.validate()?;
    let (lo, hi) = mesh.bounds();
    let size = (hi - lo).length();
    if !(size.is_finite() && size > 0.0) {
        return Err(FieldError::Other(format!(
            "the mesh is degenerate: its vertices span {size} (all coincide, or coordinates are not finite)"
        )));
    }
    let n = mesh.vertex_count();
    let normals = mesh.vertex_normals();
    let mut referenced = vec![false; n];
    for t in &mesh.triangles {
        for &v in t {
            referenced[v as usize] = true;
        }
    }
    let axis = match params.axis {
        Some(a) => Vec3::from(a).normalize(),
        None => longest_axis(mesh),
    };
    let resolve =
        |what: &'static str, index: usize, at: &Option<[f32; 3]>, vertex: &Option<u32>| {
            resolve_point(mesh, &referenced, what, index, at, vertex)
        };

    let mut field: Vec<Vec3>;
    if params.isotropic {
        field = (0..n).map(|v| tangent(axis, normals[v])).collect();
    } else if params.symmetry > 1 {
        let mut anchors = Vec::new();
        for (i, a) in params.anchors.iter().enumerate() {
            let v = resolve("anchors", i, &a.at, &a.vertex)?;
            let d = tangent(Vec3::from(a.direction), normals[v as usize]);
            if d == Vec3::ZERO {
                return Err(FieldError::Value {
                    what: "anchors",
                    index: i,
                    message: format!(
                        "direction {:?} is along the surface normal at vertex {v}",
                        a.direction
                    ),
                });
            }
            anchors.push((v, d));
        }
        // Without anchors the guide is the default flow (symmetry 1's field), taken up to the
        // symmetry: it already runs along tubes and round handles, where a straight axis
        // projected on the surface turns across them.
        let guide = match params.guide {
            _ if !anchors.is_empty() => Vec::new(),
            SymmetricGuide::Flow => {
                let (lo, hi) = extremes_along(mesh, &referenced, axis);
                if lo == hi {
                    return Err(FieldError::Other(format!(
                        "the mesh does not extend along field.axis (one vertex, {lo}, is both ends of it): give another axis, or guide = \"axis\""
                    )));
                }
                // Pieces the flow does not reach (no source or sink on them) take a
                // neighbour's direction or the projected axis, as symmetry 1's field does.
                let f = flow(mesh, &cotan_weights(mesh), &[lo], &[hi])?;
                fill_from_neighbours(mesh, &referenced, f, axis)
            }
            SymmetricGuide::Axis => normals.iter().map(|&nv| axis - axis.dot(nv) * nv).collect(),
        };
        field = super::symmetric_field::symmetric_field(mesh, params.symmetry, &anchors, &guide)
            .map_err(|e| FieldError::Other(e.to_string()))?;
    } else {
        let mut sinks = Vec::new();
        for (i, p) in params.sinks.iter().enumerate() {
            sinks.push(resolve("sinks", i, &p.at, &p.vertex)?);
        }
        let mut sources = Vec::new();
        for (i, p) in params.sources.iter().enumerate() {
            sources.push(resolve("sources", i, &p.at, &p.vertex)?);
        }
        let mut anchors = Vec::new();
        for (i, a) in params.anchors.iter().enumerate() {
            anchors.push((
                resolve("anchors", i, &a.at, &a.vertex)?,
                Vec3::from(a.direction),
            ));
        }
        let weights = cotan_weights(mesh);
        let solve_err = |e: crate::linalg::SolveError| FieldError::Other(e.to_string());
        if sinks.is_empty() && sources.is_empty() && anchors.is_empty() {
            let (lo, hi) = extremes_along(mesh, &referenced, axis);
            sources.push(lo);
            sinks.push(hi);
        }
        if !sinks.is_empty() || !sources.is_empty() {
            if sinks.is_empty() {
                sinks.push(farthest_from(mesh, &referenced, &sources));
            }
            if sources.is_empty() {
                sources.push(farthest_from(mesh, &referenced, &sinks));
            }
            if let Some(v) = sinks.iter().find(|v| sources.contains(v)) {
                return Err(FieldError::Other(format!(
                    "vertex {v} is both a sink and a source"
                )));
            }
            field = flow(mesh, &weights, &sources, &sinks)?;
            if !anchors.is_empty() {
                // Turn the flow by a harmonically interpolated angle. Angles are measured
                // in each vertex's own (flow, normal × flow) frame.
                let fill = fill_from_neighbours(mesh, &referenced, field.clone(), axis);
                let fixed: Vec<(u32, Vec<f64>)> = anchors
                    .iter()
                    .map(|&(v, d)| {
                        let (b, nv) = (fill[v as usize], normals[v as usize]);
                        let d = tangent(d, nv);
                        let angle = (nv.cross(b).dot(d) as f64).atan2_pure(b.dot(d) as f64);
                        (v, vec![angle])
                    })
                    .collect();
                let theta = harmonic_interpolate(mesh, &weights, &fixed, 1).map_err(solve_err)?;
                field = (0..n)
                    .map(|v| {
                        let (b, nv) = (fill[v], normals[v]);
                        let (s, c) = (theta[v] as f32).sin_cos_pure();
                        c * b + s * nv.cross(b)
                    })
                    .collect();
            }
        } else {
            let fixed: Vec<(u32, Vec<f64>)> = anchors
                .iter()
                .map(|&(v, d)| {
                    let d = d.normalize().as_dvec3();
                    (v, vec![d.x, d.y, d.z])
                })
                .collect();
            let x = harmonic_interpolate(mesh, &weights, &fixed, 3).map_err(solve_err)?;
            field = (0..n)
                .map(|v| {
                    let d = Vec3::new(x[3 * v] as f32, x[3 * v + 1] as f32, x[3 * v + 2] as f32);
                    tangent(d, normals[v])
                })
                .collect();
        }
    }
    let mut field = fill_from_neighbours(mesh, &referenced, field, axis);
    for (v, f) in field.iter_mut().enumerate() {
        if !referenced[v] {
            *f = Vec3::ZERO;
        }
    }
    Ok(field)
}

/// The flow out of `sources` into `sinks` (§3): the gradient of the harmonic function that is
/// 0 at the sources and 1 at the sinks, as unit tangents (zero where it vanishes).
fn flow(
    mesh: &Mesh,
    weights: &[(u32, u32, f64)],
    sources: &[u32],
    sinks: &[u32],
) -> Result<Vec<Vec3>, FieldError> {
    let mut fixed: Vec<(u32, Vec<f64>)> = sources.iter().map(|&v| (v, vec![0.0])).collect();
    fixed.extend(sinks.iter().map(|&v| (v, vec![1.0])));
    let phi = harmonic_interpolate(mesh, weights, &fixed, 1)
        .map_err(|e| FieldError::Other(e.to_string()))?;
    Ok(vertex_gradients(mesh, &phi)
        .iter()
        .zip(mesh.vertex_normals())
        .map(|(g, &nv)| tangent(g.as_vec3(), nv))
        .collect())
}

/// The unit projection of `d` into the plane with normal `n`, or zero if it vanishes.
/// `d` projected into the tangent plane of normal `n` and normalized; zero when `d` is
/// (almost) along `n`.
pub(crate) fn tangent(d: Vec3, n: Vec3) -> Vec3 {
    let t = d - d.dot(n) * n;
    if t.length_squared() > 1e-12 * d.length_squared().max(1e-30) {
        t.normalize()
    } else {
        Vec3::ZERO
    }
}

fn longest_axis(mesh: &Mesh) -> Vec3 {
    let (lo, hi) = mesh.bounds();
    let e = hi - lo;
    if e.x >= e.y && e.x >= e.z {
        Vec3::X
    } else if e.y >= e.z {
        Vec3::Y
    } else {
        Vec3::Z
    }
}

/// The vertex a config entry names: `at` (the nearest referenced vertex) or `vertex` (checked
/// to exist and to belong to a triangle). `what[index]` names the entry in errors.
pub fn resolve_point(
    mesh: &Mesh,
    referenced: &[bool],
    what: &'static str,
    index: usize,
    at: &Option<[f32; 3]>,
    vertex: &Option<u32>,
) -> Result<u32, FieldError> {
    match (at, vertex) {
        (Some(p), None) => {
            if !p.iter().all(|x| x.is_finite()) {
                return Err(FieldError::Value {
                    what,
                    index,
                    message: "`at` must be finite".into(),
                });
            }
            let p = Vec3::from(*p);
            let mut best = (f32::INFINITY, u32::MAX);
            for (v, q) in mesh.positions.iter().enumerate() {
                if referenced[v] {
                    let d = q.distance_squared(p);
                    if d < best.0 {
                        best = (d, v as u32);
                    }
                }
            }
            Ok(best.1)
        }
        (None, Some(v)) => {
            if *v as usize >= mesh.vertex_count() {
                Err(FieldError::VertexRange {
                    what,
                    index,
                    vertex: *v,
                    count: mesh.vertex_count(),
                })
            } else if !referenced[*v as usize] {
                Err(FieldError::Unreferenced {
                    what,
                    index,
                    vertex: *v,
                })
            } else {
                Ok(*v)
            }
        }
        _ => Err(FieldError::PointSpec { what, index }),
    }
}

fn extremes_along(mesh: &Mesh, referenced: &[bool], axis: Vec3) -> (u32, u32) {
    let mut lo = (f32::INFINITY, 0u32);
    let mut hi = (f32::NEG_INFINITY, 0u32);
    for (v, p) in mesh.positions.iter().enumerate() {
        if referenced[v] {
            let s = p.dot(axis);
            if s < lo.0 {
                lo = (s, v as u32);
            }
            if s > hi.0 {
                hi = (s, v as u32);
            }
        }
    }
    (lo.1, hi.1)
}

pub(crate) fn farthest_from(mesh: &Mesh, referenced: &[bool], from: &[u32]) -> u32 {
    let mut best = (f32::NEG_INFINITY, 0u32);
    for (v, p) in mesh.positions.iter().enumerate() {
        if referenced[v] {
            let d = from
                .iter()
                .map(|&f| p.distance_squared(mesh.positions[f as usize]))
                .fold(f32::INFINITY, f32::min);
            if d > best.0 {
                best = (d, v as u32);
            }
        }
    }
    best.1
}

/// Area-weighted average of the per-face gradients of a piecewise-linear function.
fn vertex_gradients(mesh: &Mesh, phi: &[f64]) -> Vec<DVec3> {
    let mut g = vec![DVec3::ZERO; mesh.vertex_count()];
    for t in &mesh.triangles {
        let p = t.map(|v| mesh.positions[v as usize].as_dvec3());
        let n2 = (p[1] - p[0]).cross(p[2] - p[0]); // |n2| = 2·area
        let a2 = n2.length_squared();
        if a2 < 1e-300 {
            continue;
        }
        // ∇φ = Σ φ_i (n × e_i) / (2A), e_i the edge opposite corner i, counter-clockwise.
        let mut grad = DVec3::ZERO;
        for k in 0..3 {
            let e = p[(k + 2) % 3] - p[(k + 1) % 3];
            grad += phi[t[k] as usize] * n2.cross(e);
        }
        grad /= a2; // (n2/|n2|) × e / |n2| summed: one division by |n2|² covers both.
        let weight = a2.sqrt();
        for &v in t {
            g[v as usize] += weight * grad;
        }
    }
    g
}

/// Replaces zero vectors by a neighbour's direction (projected into the local tangent
/// plane), spreading breadth-first from vertices that have one. Components with no valid
/// vector at all use the projected axis, and failing that any tangent.
fn fill_from_neighbours(
    mesh: &Mesh,
    referenced: &[bool],
    mut field: Vec<Vec3>,
    axis: Vec3,
) -> Vec<Vec3> {
    let adj = mesh.adjacency();
    let normals = mesh.vertex_normals();
    let n = field.len();
    let mut queue: std::collections::VecDeque<u32> = (0..n as u32)
        .filter(|&v| field[v as usize] != Vec3::ZERO)
        .collect();
    let fill = |queue: &mut std::collections::VecDeque<u32>, field: &mut Vec<Vec3>| {
        while let Some(v) = queue.pop_front() {
            for &w in adj.neighbors(v as usize) {
                let w = w as usize;
                if field[w] == Vec3::ZERO && referenced[w] {
                    let mut t = tangent(field[v as usize], normals[w]);
                    if t == Vec3::ZERO {
                        t = any_tangent(normals[w]);
                    }
                    field[w] = t;
                    queue.push_back(w as u32);
                }
            }
        }
    };
    fill(&mut queue, &mut field);
    for v in 0..n {
        if referenced[v] && field[v] == Vec3::ZERO {
            let mut t = tangent(axis, normals[v]);
            if t == Vec3::ZERO {
                t = any_tangent(normals[v]);
            }
            field[v] = t;
            queue.push_back(v as u32);
            fill(&mut queue, &mut field);
        }
    }
    field
}

fn any_tangent(n: Vec3) -> Vec3 {
    if n == Vec3::ZERO {
        return Vec3::X;
    }
    n.any_orthonormal_vector()
}

/// The field node (§3): the "up" direction at every vertex of the imported mesh. `method`
/// names the method in the mesh-health warning.
pub fn node(mesh: &Mesh, params: &FieldParams, method: &str) -> Result<Vec<Vec3>, Failure> {
    texsyn_core::geom::mesh_check::warn_if_unhealthy(mesh, method);
    let field = orientation_field(mesh, params).map_err(Failure::input)?;
    // The measures cost a pass over every edge: only when someone reads them (`run -v`).
    if !tracing::enabled!(tracing::Level::INFO) {
        return Ok(field);
    }
    let m = super::symmetric_field::measure(mesh, &field, params.symmetry);
    tracing::info!(
        "field (symmetry {}): mean turn between neighbours {:.2}°, energy {:.3e}, {} singular triangles, total |index| {}",
        m.symmetry,
        m.mean_turn_deg,
        m.energy,
        m.singular_triangles,
        m.index_abs_total
    );
    if params.symmetry > 1 {
        // What the rest of the pipeline sees: one vector per vertex, combed.
        let c = super::symmetric_field::measure(mesh, &field, 1);
        tracing::info!(
            "field as combed (one vector per vertex): mean turn between neighbours {:.2}°",
            c.mean_turn_deg
        );
    }
    Ok(field)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sphere(rings: u32, segments: u32) -> Mesh {
        let mut p = vec![Vec3::Y];
        for r in 1..rings {
            let th = std::f32::consts::PI * r as f32 / rings as f32;
            for s in 0..segments {
                let ph = 2.0 * std::f32::consts::PI * s as f32 / segments as f32;
                p.push(Vec3::new(
                    th.sin_pure() * ph.cos_pure(),
                    th.cos_pure(),
                    th.sin_pure() * ph.sin_pure(),
                ));
            }
        }
        p.push(-Vec3::Y);
        let last = p.len() as u32 - 1;
        let idx = |r: u32, s: u32| 1 + (r - 1) * segments + s % segments;
        let mut t = Vec::new();
        for s in 0..segments {
            t.push([0, idx(1, s + 1), idx(1, s)]);
            t.push([last, idx(rings - 1, s), idx(rings - 1, s + 1)]);
        }
        for r in 1..rings - 1 {
            for s in 0..segments {
                t.push([idx(r, s), idx(r, s + 1), idx(r + 1, s + 1)]);
                t.push([idx(r, s), idx(r + 1, s + 1), idx(r + 1, s)]);
            }
        }
        Mesh::new(p, t)
    }

    fn check_unit_tangent(mesh: &Mesh, f: &[Vec3]) {
        for (v, (d, n)) in f.iter().zip(mesh.vertex_normals()).enumerate() {
            assert!(
                (d.length() - 1.0).abs() < 1e-4,
                "vertex {v}: |d| = {}",
                d.length()
            );
            assert!(d.dot(*n).abs() < 1e-4, "vertex {v} not tangent");
        }
    }

    #[test]
    fn sink_and_source_make_the_field_flow_from_one_to_the_other() {
        let m = sphere(16, 24);
        let params = FieldParams {
            sinks: vec![Point {
                at: Some([0.0, 1.0, 0.0]),
                vertex: None,
            }],
            sources: vec![Point {
                at: Some([0.0, -1.0, 0.0]),
                vertex: None,
            }],
            ..Default::default()
        };
        let f = orientation_field(&m, &params).unwrap();
        check_unit_tangent(&m, &f);
        // Away from the poles the flow climbs towards +y, the sink.
        for (v, p) in m.positions.iter().enumerate() {
            if p.y.abs() < 0.8 {
                assert!(
                    f[v].y > 0.9 * (1.0 - p.y * p.y).sqrt(),
                    "vertex {v} at {p}: {}",
                    f[v]
                );
            }
        }
    }

    #[test]
    fn a_single_anchor_orients_the_whole_mesh() {
        let m = sphere(12, 16);
        let params = FieldParams {
            anchors: vec![Anchor {
                at: Some([1.0, 0.0, 0.0]),
                vertex: None,
                direction: [0.0, 0.0, 1.0],
            }],
            ..Default::default()
        };
        let f = orientation_field(&m, &params).unwrap();
        check_unit_tangent(&m, &f);
        // Everywhere the field is the projection of +z.
        for (v, n) in m.vertex_normals().iter().enumerate() {
            let expect = tangent(Vec3::Z, *n);
            if expect != Vec3::ZERO && n.z.abs() < 0.9 {
                assert!(f[v].dot(expect) > 0.99, "vertex {v}");
            }
        }
    }

    #[test]
    fn anchors_turn_the_flow_without_moving_its_singularities() {
        let m = sphere(16, 24);
        let base = FieldParams {
            sinks: vec![Point {
                vertex: Some(0),
                at: None,
            }],
            sources: vec![Point {
                vertex: Some(m.vertex_count() as u32 - 1),
                at: None,
            }],
            ..Default::default()
        };
        let f0 = orientation_field(&m, &base).unwrap();
        // An anchor at the equator asking for a quarter turn from the flow.
        let v = m
            .positions
            .iter()
            .position(|p| p.y.abs() < 0.1 && p.x > 0.9)
            .unwrap();
        let n = m.vertex_normals()[v];
        let turned = n.cross(f0[v]);
        let params = FieldParams {
            anchors: vec![Anchor {
                vertex: Some(v as u32),
                at: None,
                direction: turned.into(),
            }],
            ..base
        };
        let f1 = orientation_field(&m, &params).unwrap();
        check_unit_tangent(&m, &f1);
        assert!(f1[v].dot(turned) > 0.999);
        // With a single anchor, the angle is the same everywhere: a quarter turn.
        for w in 0..m.vertex_count() {
            let nw = m.vertex_normals()[w];
            if m.positions[w].y.abs() < 0.9 {
                assert!(f1[w].dot(nw.cross(f0[w])) > 0.99, "vertex {w}");
            }
        }
    }

    #[test]
    fn default_and_isotropic_fields_are_unit_tangents() {
        let m = sphere(10, 12);
        for p in [
            FieldParams::default(),
            FieldParams {
                isotropic: true,
                ..Default::default()
            },
        ] {
            let f = orientation_field(&m, &p).unwrap();
            check_unit_tangent(&m, &f);
        }
    }

    #[test]
    fn bad_points_are_named() {
        let m = sphere(6, 8);
        let p = FieldParams {
            sinks: vec![Point {
                vertex: Some(9999),
                at: None,
            }],
            ..Default::default()
        };
        let e = orientation_field(&m, &p).unwrap_err().to_string();
        assert!(e.contains("field.sinks[0]") && e.contains("9999"), "{e}");
        let p = FieldParams {
            sources: vec![Point {
                vertex: Some(1),
                at: Some([0.0; 3]),
            }],
            ..Default::default()
        };
        let e = orientation_field(&m, &p).unwrap_err().to_string();
        assert!(
            e.contains("field.sources[0]") && e.contains("exactly one"),
            "{e}"
        );
        let p = FieldParams {
            anchors: vec![Anchor {
                vertex: Some(1),
                at: None,
                direction: [0.0; 3],
            }],
            ..Default::default()
        };
        assert!(
            orientation_field(&m, &p)
                .unwrap_err()
                .to_string()
                .contains("field.anchors[0]")
        );
    }

    /// A half-torus arc: a tube of radius 0.5 around the semicircle of radius 3 from
    /// (−3, 0, 0) over (0, 3, 0) to (3, 0, 0); ring `r` at arc angle ψ = π r / (rings − 1).
    fn arc_tube(rings: u32, segments: u32) -> Mesh {
        let mut p = Vec::new();
        for r in 0..rings {
            let psi = std::f32::consts::PI * r as f32 / (rings - 1) as f32;
            let out = Vec3::new(-psi.cos_pure(), psi.sin_pure(), 0.0);
            for s in 0..segments {
                let phi = 2.0 * std::f32::consts::PI * s as f32 / segments as f32;
                p.push(3.0 * out + 0.5 * (phi.cos_pure() * out + phi.sin_pure() * Vec3::Z));
            }
        }
        let idx = |r: u32, s: u32| r * segments + s % segments;
        let mut t = Vec::new();
        for r in 0..rings - 1 {
            for s in 0..segments {
                t.push([idx(r, s), idx(r + 1, s), idx(r + 1, s + 1)]);
                t.push([idx(r, s), idx(r + 1, s + 1), idx(r, s + 1)]);
            }
        }
        Mesh::new(p, t)
    }

    /// Without anchors a four-fold field follows the default flow up to a quarter turn: along
    /// the arc, not along the x axis projected on it (which crosses the arc at 45° halfway up
    /// each side).
    #[test]
    fn a_four_fold_field_without_anchors_runs_along_the_tube_as_the_flow_does() {
        let (rings, segments) = (61, 24);
        let m = arc_tube(rings, segments);
        // The least cosine between the field and the arc, up to a quarter turn.
        let worst = |guide: SymmetricGuide| {
            let params = FieldParams {
                symmetry: 4,
                guide,
                ..Default::default()
            };
            let f = orientation_field(&m, &params).unwrap();
            check_unit_tangent(&m, &f);
            let mut worst: f32 = 1.0;
            for r in 0..rings {
                let psi = std::f32::consts::PI * r as f32 / (rings - 1) as f32;
                if !(0.15..=0.85).contains(&(psi / std::f32::consts::PI)) {
                    continue;
                }
                let along = Vec3::new(psi.sin_pure(), psi.cos_pure(), 0.0);
                for s in 0..segments {
                    let v = (r * segments + s) as usize;
                    let across = m.vertex_normals()[v].cross(along);
                    worst = worst.min(f[v].dot(along).abs().max(f[v].dot(across).abs()));
                }
            }
            worst
        };
        let flow = worst(SymmetricGuide::Flow);
        assert!(flow > 0.95, "guided by the flow: {flow}");
        // The axis guide pulls the field towards x, off the arc on its slopes.
        let axis = worst(SymmetricGuide::Axis);
        assert!(axis < 0.9, "guided by the axis: {axis}");
        // The axis guide means nothing without symmetry, and is refused there.
        let p = FieldParams {
            guide: SymmetricGuide::Axis,
            ..Default::default()
        };
        let e = orientation_field(&m, &p).unwrap_err().to_string();
        assert!(e.contains("guide"), "{e}");
    }

    /// The default field on a mesh big enough for the iterative solver (AMG-preconditioned
    /// conjugate gradients): source and sink at the ends of the longest axis (x), so the
    /// field must run along the arc from its −x end to its +x end. Projecting the x axis (the
    /// fallback where a potential is flat) differs from that on the tube's top and bottom.
    #[test]
    fn the_default_field_on_a_big_mesh_flows_along_the_arc_from_source_to_sink() {
        let (rings, segments) = (600, 180);
        let m = arc_tube(rings, segments);
        assert!(
            m.vertex_count() >= crate::linalg::IterativeParams::default().min_unknowns,
            "the mesh must take the iterative path"
        );
        let f = orientation_field(&m, &FieldParams::default()).unwrap();
        check_unit_tangent(&m, &f);
        let mut checked = 0;
        for r in 0..rings {
            let psi = std::f32::consts::PI * r as f32 / (rings - 1) as f32;
            if !(0.25..=0.75).contains(&(psi / std::f32::consts::PI)) {
                continue;
            }
            let along = Vec3::new(psi.sin_pure(), psi.cos_pure(), 0.0);
            for s in 0..segments {
                let v = (r * segments + s) as usize;
                assert!(
                    f[v].dot(along) > 0.95,
                    "ring {r} segment {s}: field {:?}, arc direction {along:?}",
                    f[v]
                );
                checked += 1;
            }
        }
        assert!(checked > 40_000);
    }
}
