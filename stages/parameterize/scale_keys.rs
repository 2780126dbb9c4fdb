//! A texture scale that varies over the surface: `parameterize.scale_keys`.
//!
//! Beyond Zelinka & Garland: their §3 fixes one scale for the whole mesh, and their Fig. 7
//! shows several uniform scales on one mesh without remeshing, which is what makes a varying
//! one possible at all: the walk only reads per-edge offsets (§4.2.2), so an offset may be
//! scaled edge by edge. Each key multiplies `parameterize.scale` on a small disc around its
//! vertex (5 % of the bounding-box diagonal unless given); in between, the logarithm of the
//! factor is interpolated by inverse squared distance along the surface from each disc
//! (Shepard), so halfway between two keys the scale is their geometric mean.
//!
//! Not relaxed harmonically, as the field's anchors are (§3): a harmonic function weighs each
//! key by its capacity, not its distance. On the demo cow, keys of 0.4 at the thin tail and
//! 2.5 at the bulky nose gave 1.85 on the middle of the back (and a key pinned on one vertex
//! is a spike: 0.4 at the tail's tip gave 0.77 a few edges away), where a user asking for
//! "large at the tail, small at the head" means a change along the body. An edge takes the geometric mean of its ends' factors, which is the same seen from
//! either end, so every offset stays the negation of its reverse.

use crate::check::ParamError;
use crate::field::orientation_field::{FieldError, resolve_point};
use crate::geom::Mesh;
use serde::{Deserialize, Serialize};
use texsyn_core::math::PureMath;

/// One key: a place (`at`, snapped to the nearest vertex, or `vertex`) and the factor that
/// multiplies `parameterize.scale` there.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScaleKey {
    #[serde(default)]
    pub at: Option<[f32; 3]>,
    #[serde(default)]
    pub vertex: Option<u32>,
    /// Exemplar texels per unit there, as a multiple of `parameterize.scale`: above 1 the
    /// texture looks smaller, below 1 larger.
    pub factor: f32,
    /// The key holds on every vertex within this distance (object units, along the surface) of
    /// its vertex.
    /// Default: 5 % of the mesh's bounding-box diagonal. Left out of the key when not given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius: Option<f32>,
}

/// A key's default radius, as a share of the bounding-box diagonal.
pub const DEFAULT_RADIUS_SHARE: f32 = 0.05;

/// The range a key's factor may take: beyond it one part of the mesh would hold the
/// exemplar's features at a size over 400 times another's.
pub const FACTOR_RANGE: (f32, f32) = (0.05, 20.0);

/// Checks what can be checked without the mesh: each factor's range.
pub fn validate(keys: &[ScaleKey]) -> Result<(), ParamError> {
    for (i, k) in keys.iter().enumerate() {
        let (lo, hi) = FACTOR_RANGE;
        if !(k.factor >= lo && k.factor <= hi) {
            return Err(ParamError::invalid(
                format!("parameterize.scale_keys[{i}]"),
                format!("factor = {} is outside {lo}..={hi}", k.factor),
            ));
        }
        if let Some(r) = k.radius
            && !(r.is_finite() && r >= 0.0)
        {
            return Err(ParamError::invalid(
                format!("parameterize.scale_keys[{i}]"),
                format!("radius = {r} must be a distance, 0 or more"),
            ));
        }
    }
    Ok(())
}

/// Largest factor of the keys (1 without keys): `refine` splits edges for it.
pub fn largest_factor(keys: &[ScaleKey]) -> f32 {
    keys.iter().map(|k| k.factor).fold(1.0, f32::max)
}

/// The factor of every vertex: each key's factor on the vertices within its radius (along the
/// surface), interpolated in the log in between (1 everywhere without keys). Keys whose discs
/// overlap must agree.
pub fn vertex_factors(mesh: &Mesh, keys: &[ScaleKey]) -> Result<Vec<f32>, ParamError> {
    let n = mesh.vertex_count();
    if keys.is_empty() {
        return Ok(vec![1.0; n]);
    }
    validate(keys)?;
    let mut referenced = vec![false; n];
    for t in &mesh.triangles {
        for &v in t {
            referenced[v as usize] = true;
        }
    }
    let (lo, hi) = mesh.bounds();
    let diagonal = (hi - lo).length();
    let adj = mesh.adjacency();
    // Per key: its log factor, its radius and the surface distance of every vertex to it.
    let mut resolved: Vec<(f64, f32, Vec<f32>)> = Vec::with_capacity(keys.len());
    for (i, k) in keys.iter().enumerate() {
        let key = || format!("parameterize.scale_keys[{i}]");
        let v = resolve_point(mesh, &referenced, "scale_keys", i, &k.at, &k.vertex)
            .map_err(|e| ParamError::invalid(key(), point_message(e)))?;
        let log = (k.factor as f64).ln_pure();
        let radius = k.radius.unwrap_or(DEFAULT_RADIUS_SHARE * diagonal);
        let distance = surface_distance(mesh, adj, v);
        for (j, (other, other_radius, other_distance)) in resolved.iter().enumerate() {
            let overlap =
                (0..n).find(|&u| distance[u] <= radius && other_distance[u] <= *other_radius);
            if let Some(u) = overlap
                && (other - log).abs() > 1e-9
            {
                return Err(ParamError::invalid(
                    key(),
                    format!(
                        "it overlaps scale_keys[{j}] (vertex {u} is within both radii) with \
                         another factor: move them apart or give smaller radii"
                    ),
                ));
            }
        }
        resolved.push((log, radius, distance));
    }
    Ok((0..n)
        .map(|u| {
            // Inside a key's disc: its factor. Elsewhere: the keys' logs weighted by the inverse
            // square of the distance from each disc (Shepard), so that halfway between two
            // keys the factor is their geometric mean.
            if let Some((log, _, _)) = resolved.iter().find(|(_, r, d)| d[u] <= *r) {
                return log.exp_pure() as f32;
            }
            let (mut sum, mut weights) = (0.0f64, 0.0f64);
            for (log, r, d) in &resolved {
                if d[u].is_finite() {
                    let w = 1.0 / ((d[u] - r) as f64).powi(2);
                    sum += w * log;
                    weights += w;
                }
            }
            // A part of the mesh no key reaches keeps the base scale.
            if weights > 0.0 {
                (sum / weights).exp_pure() as f32
            } else {
                1.0
            }
        })
        .collect())
}

/// The length of the shortest path along edges from `from` to every vertex (infinite where
/// none leads).
fn surface_distance(mesh: &Mesh, adj: &texsyn_core::geom::VertexAdjacency, from: u32) -> Vec<f32> {
    use std::cmp::Reverse;
    let mut d = vec![f32::INFINITY; mesh.vertex_count()];
    let mut heap = std::collections::BinaryHeap::new();
    d[from as usize] = 0.0;
    heap.push(Reverse((0u32, from)));
    // Distances are non-negative floats, whose bits order as the numbers do.
    while let Some(Reverse((bits, v))) = heap.pop() {
        let dv = f32::from_bits(bits);
        if dv > d[v as usize] {
            continue;
        }
        let (a, b) = (
            adj.offsets[v as usize] as usize,
            adj.offsets[v as usize + 1] as usize,
        );
        for &u in &adj.neighbors[a..b] {
            let du = dv + mesh.positions[v as usize].distance(mesh.positions[u as usize]);
            if du < d[u as usize] {
                d[u as usize] = du;
                heap.push(Reverse((du.to_bits(), u)));
            }
        }
    }
    d
}

/// The message of a point that cannot be resolved, without the field's key (the caller names
/// its own).
fn point_message(e: FieldError) -> String {
    match e {
        FieldError::PointSpec { .. } => "give exactly one of `at` or `vertex`".into(),
        FieldError::VertexRange { vertex, count, .. } => {
            format!("vertex {vertex} is out of range (the mesh has {count} vertices)")
        }
        FieldError::Unreferenced { vertex, .. } => {
            format!("vertex {vertex} belongs to no triangle")
        }
        FieldError::Value { message, .. } | FieldError::Other(message) => message,
    }
}

/// The factor of the edge between vertices with factors `a` and `b`: their geometric mean,
/// symmetric in the two.
#[inline]
pub fn edge_factor(a: f32, b: f32) -> f32 {
    (a * b).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use texsyn_core::geom::primitives::grid;

    #[test]
    fn halfway_between_two_keys_the_scale_is_their_geometric_mean() {
        // Keys 4 and 1/4 on opposite corners of a grid, on single vertices (radius 0): along
        // the diagonal of edges between them the distances are exact, so at the middle both
        // weigh the same (factor 1) and at the quarter point the weights are 1/2² and 1/6²,
        // giving 4^((1/4 − 1/36) / (1/4 + 1/36)) = 4^0.8.
        let m = grid(9, 0.125);
        let key = |vertex: u32, factor: f32| ScaleKey {
            vertex: Some(vertex),
            factor,
            radius: Some(0.0),
            ..Default::default()
        };
        let f = vertex_factors(&m, &[key(0, 4.0), key(80, 0.25)]).unwrap();
        let diagonal = |k: usize| f[k * 9 + k];
        assert!((diagonal(0) - 4.0).abs() < 1e-5 && (diagonal(8) - 0.25).abs() < 1e-5);
        assert!((diagonal(4) - 1.0).abs() < 1e-4, "{}", diagonal(4));
        assert!(
            (diagonal(2) - 4f32.powf_pure(0.8)).abs() < 1e-3,
            "{}",
            diagonal(2)
        );
        assert!((1..9).all(|k| diagonal(k) < diagonal(k - 1)));
        assert_eq!(largest_factor(&[key(0, 4.0), key(80, 0.25)]), 4.0);
        // A radius holds the factor on a disc around the key.
        let wide = [
            ScaleKey {
                radius: Some(0.2),
                ..key(0, 4.0)
            },
            key(80, 0.25),
        ];
        let f = vertex_factors(&m, &wide).unwrap();
        assert_eq!((f[1], f[9], f[10]), (4.0, 4.0, 4.0));
        assert!(f[2 * 9 + 2] < 4.0);
    }

    #[test]
    fn one_key_scales_the_whole_mesh_and_none_leaves_it() {
        let m = grid(5, 1.0);
        let one = [ScaleKey {
            at: Some([2.0, 2.0, 0.0]),
            factor: 3.0,
            ..Default::default()
        }];
        assert!(
            vertex_factors(&m, &one)
                .unwrap()
                .iter()
                .all(|&f| (f - 3.0).abs() < 1e-4)
        );
        assert!(vertex_factors(&m, &[]).unwrap().iter().all(|&f| f == 1.0));
    }

    #[test]
    fn bad_keys_are_named() {
        let m = grid(3, 1.0);
        let cases: [(ScaleKey, &str); 4] = [
            (
                ScaleKey {
                    vertex: Some(99),
                    factor: 2.0,
                    ..Default::default()
                },
                "vertex 99 is out of range",
            ),
            (
                ScaleKey {
                    vertex: Some(1),
                    at: Some([0.0; 3]),
                    factor: 2.0,
                    ..Default::default()
                },
                "exactly one of",
            ),
            (
                ScaleKey {
                    vertex: Some(1),
                    factor: 0.0,
                    ..Default::default()
                },
                "factor = 0 is outside",
            ),
            (
                ScaleKey {
                    vertex: Some(1),
                    factor: f32::NAN,
                    ..Default::default()
                },
                "factor = NaN",
            ),
        ];
        for (k, words) in cases {
            let keys = [
                ScaleKey {
                    vertex: Some(0),
                    factor: 1.0,
                    ..Default::default()
                },
                k,
            ];
            let e = vertex_factors(&m, &keys).unwrap_err().to_string();
            assert!(
                e.contains("parameterize.scale_keys[1]") && e.contains(words),
                "{e}"
            );
        }
        let clash = [
            ScaleKey {
                vertex: Some(4),
                factor: 1.0,
                ..Default::default()
            },
            ScaleKey {
                at: Some([1.0, 1.0, 0.0]),
                factor: 2.0,
                ..Default::default()
            },
        ];
        let e = vertex_factors(&m, &clash).unwrap_err().to_string();
        assert!(e.contains("scale_keys[1]") && e.contains("vertex 4"), "{e}");
    }
}
