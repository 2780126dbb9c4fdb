//! Orientation by neighbour averaging and Turk's sweep field, built coarse to fine over a √2
//! hierarchy (Bangay & Morkel, "Graph Matching with Subdivision Surfaces for Texture Synthesis
//! on Surfaces", §3.1.1–3.1.2, after Turk 2001).
//!
//! - Orientation (§3.1.1): key vertices carry the user's directions and stay fixed; every pass
//!   sets each other vertex to the mean of its neighbours' vectors, projected to its tangent
//!   plane and normalized, "until every vertex has a defined value" and (our stopping rule, the
//!   paper gives none) no vector moves by more than `tolerance` in a pass, or after
//!   `max_passes`. Passes are Gauss–Seidel in vertex order (deterministic, and twice as fast to
//!   converge as Jacobi).
//! - Coarse to fine: "performed in a hierarchical manner starting with the coarse mesh … and
//!   diffusing them to the higher resolution meshes". A vertex new at a level starts from the
//!   mean of the vertices of the face it was made from; then the level is relaxed. Synthesis
//!   reads the finest level's vectors at every level (the old vertices barely move once their
//!   level has converged), so one vector per vertex is stored.
//! - No keys given: the paper always has some. Like the jump-map method, the default is the
//!   flow from a source to a sink at the two ends of the shape's longest axis (or `axis`),
//!   computed on level 0 ([`super::orientation_field`]), so a config runs on any mesh. Level 0
//!   is then not relaxed (that field is already smooth); finer levels are.
//! - Sinks and sources (beyond the paper, as the jump-map method has them): level 0's field is
//!   the flow of the harmonic potential between them ([`super::orientation_field`]), the keys
//!   turning it where they are; level 0 is then not relaxed, finer levels are, with the keys
//!   fixed. The singularities stay where the user put them, which averaging from keys alone
//!   cannot promise.
//! - Rotation: every finished vector is turned by `rotation` degrees about its vertex's normal
//!   (counter-clockwise seen from outside), turning the texture against the field; the sweep
//!   follows the turned vectors.
//! - Sweep (§3.1.1–3.1.2): a value increasing along the orientation, used to order the first
//!   level's visits. From a start vertex (the first key, or the default field's source) each
//!   vertex gets the mean over its neighbours `u` of `s(u) + (p − p_u)·ō`, `ō` the mean of the
//!   two orientations, first in breadth-first order, then relaxed (`SWEEP_PASSES`). Turk's
//!   sweep is a relaxation of the same relation. Only level 0 needs it (later levels are
//!   visited in random order, §3.1.2), so only level 0's values are stored.

use super::feature_field::rotate_about_normals;
use super::orientation_field::{
    Anchor, FieldError, FieldParams, Point, farthest_from, orientation_field, resolve_point,
    tangent,
};
use crate::check::{ParamError, check_range};
use crate::geom::Mesh;
use crate::geom::poly_mesh::PolyMesh;
use crate::parameterize::sqrt2_subdivision::Sqrt2Hierarchy;
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use texsyn_core::algorithm::Failure;

/// The `sweep_field` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("sweep_field", 2);

/// The `field_keys` node's algorithm and version (part of its key; bump on any change of output).
pub const KEYS_NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("field_keys", 1);

/// Relaxation passes of the sweep after its breadth-first initialization.
const SWEEP_PASSES: usize = 30;

/// `[field]` of the graph-matching method.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SweepFieldParams {
    /// Key orientation vectors (`at` or `vertex`, and `direction`), fixed while the rest is
    /// averaged. Default: none (the flow along the longest axis).
    pub keys: Vec<Anchor>,
    /// Points the field flows into (`at` or `vertex`). Default: none. Left out of the node's
    /// key when empty, as are `sources` and `rotation` at their defaults.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sinks: Vec<Point>,
    /// Points the field flows out of. Default: none.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sources: Vec<Point>,
    /// The axis of the default field (no keys). Default: the bounding box's longest side.
    pub axis: Option<[f32; 3]>,
    /// A level is converged when no vector moves farther than this in a pass,
    /// 1e-6..=0.5. Default: 1e-3.
    pub tolerance: f32,
    /// Cap on the averaging passes per level, 1..=100000. Default: 500.
    pub max_passes: u32,
    /// Degrees (-180..=180) every vector is turned about its normal: the texture turned
    /// against the field. Default: 0.
    #[serde(skip_serializing_if = "super::feature_field::is_zero")]
    pub rotation: f32,
}

impl Default for SweepFieldParams {
    fn default() -> Self {
        SweepFieldParams {
            keys: Vec::new(),
            axis: None,
            tolerance: 1e-3,
            max_passes: 500,
            sinks: Vec::new(),
            sources: Vec::new(),
            rotation: 0.0,
        }
    }
}

impl SweepFieldParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("field.tolerance", self.tolerance, 1e-6, 0.5)?;
        check_range("field.max_passes", self.max_passes, 1, 100_000)?;
        check_range("field.rotation", self.rotation, -180.0, 180.0)?;
        let usable =
            |v: &[f32; 3]| v.iter().all(|x| x.is_finite()) && Vec3::from(*v).length() > 1e-12;
        for (i, k) in self.keys.iter().enumerate() {
            if !usable(&k.direction) {
                return Err(ParamError::invalid(
                    format!("field.keys[{i}].direction"),
                    "must be a finite, non-zero vector",
                ));
            }
        }
        if let Some(axis) = &self.axis
            && !usable(axis)
        {
            return Err(ParamError::invalid(
                "field.axis",
                "must be a finite, non-zero vector",
            ));
        }
        Ok(())
    }
}

/// Key vectors resolved to vertices of the input mesh (whose ids level 0 keeps).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct FieldKeys {
    pub vertices: Vec<u32>,
    pub directions: Vec<Vec3>,
}

/// What the `field.keys` node reads of `[field]`: the keys, resolved into its artifact, and the
/// sinks and sources, only checked there (the field node resolves them on level 0, which keeps
/// the input's vertices). Without sinks and sources its canonical bytes are the keys' alone.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct KeyPoints {
    pub keys: Vec<Anchor>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sinks: Vec<Point>,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub sources: Vec<Point>,
}

impl SweepFieldParams {
    /// The part of `[field]` the `field.keys` node reads.
    pub fn key_points(&self) -> KeyPoints {
        KeyPoints {
            keys: self.keys.clone(),
            sinks: self.sinks.clone(),
            sources: self.sources.clone(),
        }
    }
}

/// Resolves the keys on the input mesh and checks the sinks and sources there; an error names
/// the entry (`field.keys[i]`, `field.sinks[i]`, `field.sources[i]`).
pub fn resolve_keys(mesh: &Mesh, p: &SweepFieldParams) -> Result<FieldKeys, FieldError> {
    let mut referenced = vec![false; mesh.vertex_count()];
    for t in &mesh.triangles {
        for &v in t {
            referenced[v as usize] = true;
        }
    }
    let mut sinks = Vec::new();
    for (i, q) in p.sinks.iter().enumerate() {
        sinks.push(resolve_point(
            mesh,
            &referenced,
            "sinks",
            i,
            &q.at,
            &q.vertex,
        )?);
    }
    for (i, q) in p.sources.iter().enumerate() {
        let v = resolve_point(mesh, &referenced, "sources", i, &q.at, &q.vertex)?;
        if sinks.contains(&v) {
            return Err(FieldError::Value {
                what: "sources",
                index: i,
                message: format!("vertex {v} is also a sink"),
            });
        }
    }
    let normals = mesh.vertex_normals();
    let mut keys = FieldKeys::default();
    for (i, k) in p.keys.iter().enumerate() {
        let v = resolve_point(mesh, &referenced, "keys", i, &k.at, &k.vertex)?;
        let d = Vec3::from(k.direction);
        if !(d.is_finite() && d.length() > 1e-12) || tangent(d, normals[v as usize]) == Vec3::ZERO {
            return Err(FieldError::Value {
                what: "keys",
                index: i,
                message: format!(
                    "direction {:?} does not run along the surface at vertex {v} (normal {:?})",
                    k.direction,
                    normals[v as usize].to_array()
                ),
            });
        }
        keys.vertices.push(v);
        keys.directions.push(d);
    }
    Ok(keys)
}

/// One orientation per vertex of the finest level; the sweep of level 0's vertices.
#[derive(Clone, Debug, PartialEq)]
pub struct SweepField {
    pub orientation: Vec<Vec3>,
    pub sweep: Vec<f32>,
    /// Averaging passes each level took.
    pub passes: Vec<u32>,
}

/// The field over `h`, from `keys` (see the module doc).
pub fn sweep_field(
    h: &Sqrt2Hierarchy,
    keys: &FieldKeys,
    p: &SweepFieldParams,
) -> Result<SweepField, FieldError> {
    let finest = *h.level_vertices.last().expect("a hierarchy has a level") as usize;
    let mut orientation = vec![Vec3::ZERO; finest];
    let mut defined = vec![false; finest];
    let mut fixed = vec![false; finest];
    let level0 = h.level(0);
    let mut passes = Vec::new();
    let start;
    let flow = !p.sinks.is_empty() || !p.sources.is_empty();
    if flow {
        // The potential's flow on level 0, turned by the keys (as jump maps' anchors).
        let tri = level0.to_triangles();
        let anchors = keys
            .vertices
            .iter()
            .zip(&keys.directions)
            .map(|(&v, d)| Anchor {
                at: None,
                vertex: Some(v),
                direction: d.to_array(),
            })
            .collect();
        let fp = FieldParams {
            anchors,
            sinks: p.sinks.clone(),
            sources: p.sources.clone(),
            axis: p.axis,
            ..Default::default()
        };
        let f = orientation_field(&tri, &fp)?;
        let normals = tri.vertex_normals();
        for (v, d) in f.iter().enumerate() {
            orientation[v] = *d;
            defined[v] = *d != Vec3::ZERO;
            // Level 0 holds the solve's field; finer levels only fill in between, so the
            // singularities stay at the vertices the user named.
            fixed[v] = true;
        }
        for (&v, &d) in keys.vertices.iter().zip(&keys.directions) {
            orientation[v as usize] = tangent(d, normals[v as usize]);
        }
        passes.push(0);
        let mut referenced = vec![false; tri.vertex_count()];
        for t in &tri.triangles {
            for &v in t {
                referenced[v as usize] = true;
            }
        }
        let resolve = |what, points: &[Point]| {
            (points.iter().enumerate())
                .map(|(i, q)| resolve_point(&tri, &referenced, what, i, &q.at, &q.vertex))
                .collect::<Result<Vec<u32>, _>>()
        };
        let mut sinks = resolve("sinks", &p.sinks)?;
        let mut sources = resolve("sources", &p.sources)?;
        // A lone sink flows from the vertex farthest from it, and vice versa, as the potential
        // places it.
        if sources.is_empty() {
            sources.push(farthest_from(&tri, &referenced, &sinks));
        }
        if sinks.is_empty() {
            sinks.push(farthest_from(&tri, &referenced, &sources));
        }
        // A sink's or source's own vector is a neighbour's (the flow vanishes there): it
        // must not be averaged into the vertices around it.
        for &v in sinks.iter().chain(&sources) {
            defined[v as usize] = false;
        }
        start = sources[0];
    } else if keys.vertices.is_empty() {
        let tri = level0.to_triangles();
        let fp = FieldParams {
            axis: p.axis,
            ..Default::default()
        };
        let f = orientation_field(&tri, &fp)?;
        for (v, d) in f.iter().enumerate() {
            orientation[v] = *d;
            defined[v] = *d != Vec3::ZERO;
        }
        passes.push(0);
        // The default field flows from the low end of its axis: start the sweep there.
        let axis = f
            .iter()
            .fold(Vec3::ZERO, |a, d| a + *d)
            .try_normalize()
            .unwrap_or(Vec3::X);
        start = (0..tri.vertex_count())
            .filter(|&v| defined[v])
            .min_by(|&a, &b| {
                tri.positions[a]
                    .dot(axis)
                    .total_cmp(&tri.positions[b].dot(axis))
                    .then(a.cmp(&b))
            })
            .unwrap_or(0) as u32;
    } else {
        let normals = level0.vertex_normals();
        for (&v, &d) in keys.vertices.iter().zip(&keys.directions) {
            // Keys were resolved on the input mesh, whose vertices level 0 keeps; a cached
            // key artifact that disagrees is texsyn's fault, not the user's.
            if v as usize >= normals.len() || !d.is_finite() {
                return Err(FieldError::Other(format!(
                    "internal: key vertex {v} is not a vertex of level 0"
                )));
            }
            let t = tangent(d, normals[v as usize]);
            if t == Vec3::ZERO {
                return Err(FieldError::Other(format!(
                    "the key direction at vertex {v} is along the surface normal there"
                )));
            }
            orientation[v as usize] = t;
            defined[v as usize] = true;
            fixed[v as usize] = true;
        }
        passes.push(relax(&level0, &mut orientation, &mut defined, &fixed, p));
        // A piece of the mesh that no key reaches gets the default field (the paper assumes
        // every piece has a key; without this its vertices would stay undefined).
        let adj0 = level0.vertex_neighbours();
        let missing = (0..level0.vertex_count()).any(|v| !defined[v] && !adj0.of(v).is_empty());
        if missing {
            let tri = level0.to_triangles();
            let fp = FieldParams {
                axis: p.axis,
                ..Default::default()
            };
            let f = orientation_field(&tri, &fp)?;
            let mut filled = 0usize;
            for v in 0..level0.vertex_count() {
                if !defined[v] && !adj0.of(v).is_empty() && f[v] != Vec3::ZERO {
                    orientation[v] = f[v];
                    defined[v] = true;
                    filled += 1;
                }
            }
            tracing::warn!(
                "field: {filled} vertices on pieces of the mesh without a key took the default field; add a key on each piece to orient it"
            );
        }
        start = keys.vertices[0];
    }
    for l in 1..h.levels() {
        let (lo, hi) = (
            h.level_vertices[l - 1] as usize,
            h.level_vertices[l] as usize,
        );
        for v in lo..hi {
            let sum: Vec3 = (h.parents(v).iter())
                .filter(|&&u| defined[u as usize])
                .map(|&u| orientation[u as usize])
                .sum();
            orientation[v] = sum.try_normalize().unwrap_or(Vec3::ZERO);
            defined[v] = orientation[v] != Vec3::ZERO;
        }
        let level = h.level(l);
        passes.push(relax(&level, &mut orientation, &mut defined, &fixed, p));
    }
    if p.rotation != 0.0 {
        let normals = h.level(h.levels() - 1).vertex_normals();
        rotate_about_normals(&mut orientation, &normals, p.rotation);
    }
    let sweep = sweep_values(&level0, &orientation, start);
    Ok(SweepField {
        orientation,
        sweep,
        passes,
    })
}

/// Gauss–Seidel averaging passes over one level; returns how many ran.
fn relax(
    mesh: &PolyMesh,
    orientation: &mut [Vec3],
    defined: &mut [bool],
    fixed: &[bool],
    p: &SweepFieldParams,
) -> u32 {
    let n = mesh.vertex_count();
    let adj = mesh.vertex_neighbours();
    let normals = mesh.vertex_normals();
    for pass in 1..=p.max_passes {
        let mut change = 0.0f32;
        let mut undefined = 0usize;
        for v in 0..n {
            if fixed[v] || adj.of(v).is_empty() {
                continue;
            }
            let sum: Vec3 = adj
                .of(v)
                .iter()
                .filter(|&&u| defined[u as usize])
                .map(|&u| orientation[u as usize])
                .sum();
            let t = tangent(sum, normals[v]);
            if t == Vec3::ZERO {
                // No defined neighbour yet, or they cancel (a singularity): keep what it has.
                undefined += usize::from(!defined[v]);
                continue;
            }
            change = change.max(if defined[v] {
                (t - orientation[v]).length()
            } else {
                2.0
            });
            orientation[v] = t;
            defined[v] = true;
        }
        if undefined == 0 && change <= p.tolerance {
            return pass;
        }
    }
    p.max_passes
}

/// Turk's sweep on one level: breadth-first initialization from `start` (and from the lowest
/// vertex of every other connected piece), then relaxation with the starts fixed.
fn sweep_values(mesh: &PolyMesh, orientation: &[Vec3], start: u32) -> Vec<f32> {
    let n = mesh.vertex_count();
    let adj = mesh.vertex_neighbours();
    let pos = &mesh.positions;
    let step = |u: usize, v: usize| {
        let o = (orientation[u] + orientation[v]).normalize_or_zero();
        (pos[v] - pos[u]).dot(o)
    };
    let mut s = vec![0.0f32; n];
    let mut seen = vec![false; n];
    let mut roots = Vec::new();
    let mut queue = VecDeque::new();
    let starts = std::iter::once(start as usize).chain(0..n);
    for r in starts {
        if seen[r] || adj.of(r).is_empty() {
            continue;
        }
        seen[r] = true;
        roots.push(r);
        queue.push_back(r);
        while let Some(v) = queue.pop_front() {
            for &u in adj.of(v) {
                let u = u as usize;
                if !seen[u] {
                    seen[u] = true;
                    // Every seen vertex already has its value (set when it was seen).
                    let (sum, cnt) = adj
                        .of(u)
                        .iter()
                        .map(|&w| w as usize)
                        .filter(|&w| seen[w] && w != u)
                        .fold((0.0, 0), |(a, c), w| (a + s[w] + step(w, u), c + 1));
                    s[u] = if cnt > 0 {
                        sum / cnt as f32
                    } else {
                        s[v] + step(v, u)
                    };
                    queue.push_back(u);
                }
            }
        }
    }
    let is_root: Vec<bool> = {
        let mut r = vec![false; n];
        for &v in &roots {
            r[v] = true;
        }
        r
    };
    for _ in 0..SWEEP_PASSES {
        for v in 0..n {
            if is_root[v] || adj.of(v).is_empty() {
                continue;
            }
            let nb = adj.of(v);
            s[v] = nb
                .iter()
                .map(|&u| s[u as usize] + step(u as usize, v))
                .sum::<f32>()
                / nb.len() as f32;
        }
    }
    s
}

/// The order in which level 0 is visited: by increasing sweep, ties by vertex id; vertices of
/// no face are left out.
pub fn sweep_order(mesh: &PolyMesh, sweep: &[f32]) -> Vec<u32> {
    let adj = mesh.vertex_neighbours();
    let mut order: Vec<u32> = (0..mesh.vertex_count() as u32)
        .filter(|&v| !adj.of(v as usize).is_empty())
        .collect();
    order.sort_by(|&a, &b| {
        sweep[a as usize]
            .total_cmp(&sweep[b as usize])
            .then(a.cmp(&b))
    });
    order
}

/// The `field.keys` node: the config's keys resolved on the input mesh, so a key on a vertex
/// that does not exist is reported before the subdivision runs.
pub fn keys_node(mesh: &Mesh, points: &KeyPoints) -> Result<FieldKeys, Failure> {
    let p = SweepFieldParams {
        keys: points.keys.clone(),
        sinks: points.sinks.clone(),
        sources: points.sources.clone(),
        ..Default::default()
    };
    resolve_keys(mesh, &p).map_err(Failure::input)
}

/// The field node: [`sweep_field`] on the hierarchy from the resolved keys.
pub fn node(
    h: &Sqrt2Hierarchy,
    keys: &FieldKeys,
    p: &SweepFieldParams,
) -> Result<SweepField, Failure> {
    if keys.vertices.iter().any(|&v| v >= h.level_vertices[0]) {
        return Err(Failure::internal(
            "a field key names a vertex level 0 lacks",
        ));
    }
    sweep_field(h, keys, p).map_err(Failure::input)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::primitives::grid;
    use crate::parameterize::sqrt2_subdivision::{SubdivisionParams, build_hierarchy};

    fn hierarchy(mesh: &Mesh, scale: f32) -> Sqrt2Hierarchy {
        build_hierarchy(mesh, scale, &SubdivisionParams::default()).unwrap()
    }

    #[test]
    fn one_key_on_a_plane_orients_every_vertex_of_every_level_its_way() {
        let mesh = grid(9, 0.125); // 1×1 in the xy plane
        let h = hierarchy(&mesh, 40.0);
        assert!(h.levels() > 2);
        let p = SweepFieldParams {
            keys: vec![Anchor {
                vertex: Some(40),
                at: None,
                direction: [1.0, 1.0, 0.0],
            }],
            ..Default::default()
        };
        let keys = resolve_keys(&mesh, &p).unwrap();
        let f = sweep_field(&h, &keys, &p).unwrap();
        let want = Vec3::new(1.0, 1.0, 0.0).normalize();
        for (v, o) in f.orientation.iter().enumerate() {
            assert!(o.distance(want) < 1e-3, "vertex {v}: {o}");
        }
        // The sweep increases along the field: the far corner (1, 1) is after the origin.
        let (lo, hi) = (0usize, 80usize);
        assert!(
            f.sweep[hi] > f.sweep[lo] + 1.0,
            "{:?}",
            (f.sweep[lo], f.sweep[hi])
        );
        let order = sweep_order(&h.level(0), &f.sweep);
        assert_eq!(order.len(), 81);
        assert_eq!(order[0], 0);
        assert_eq!(*order.last().unwrap(), 80);
    }

    #[test]
    fn two_opposing_keys_meet_smoothly_and_keys_stay_fixed() {
        let mesh = grid(11, 0.1);
        let h = hierarchy(&mesh, 5.0);
        let p = SweepFieldParams {
            keys: vec![
                Anchor {
                    vertex: Some(0),
                    at: None,
                    direction: [1.0, 0.0, 0.0],
                },
                Anchor {
                    vertex: None,
                    at: Some([1.0, 1.0, 0.0]),
                    direction: [0.0, 1.0, 0.0],
                },
            ],
            ..Default::default()
        };
        let keys = resolve_keys(&mesh, &p).unwrap();
        assert_eq!(keys.vertices, vec![0, 120]);
        let f = sweep_field(&h, &keys, &p).unwrap();
        assert_eq!(f.orientation[0], Vec3::X);
        assert_eq!(f.orientation[120], Vec3::Y);
        // In between, neighbours differ little (a smooth field: the turn of 90° is spread over
        // the square, steepest next to the point constraints) and every vector is a unit
        // tangent of the plane.
        let fine = h.level(h.levels() - 1);
        let adj = fine.vertex_neighbours();
        let (mut sum, mut count, mut max) = (0.0f32, 0usize, 0.0f32);
        for v in 0..fine.vertex_count() {
            let o = f.orientation[v];
            assert!((o.length() - 1.0).abs() < 1e-4 && o.z.abs() < 1e-5);
            for &u in adj.of(v) {
                let a = o.angle_between(f.orientation[u as usize]);
                sum += a;
                count += 1;
                max = max.max(a);
            }
        }
        assert!(
            max < 0.6 && sum / (count as f32) < 0.15,
            "{max} {}",
            sum / count as f32
        );
    }

    fn point(v: u32) -> Point {
        Point {
            at: None,
            vertex: Some(v),
        }
    }

    #[test]
    fn a_sink_and_sources_place_the_flow_and_its_singularities() {
        // A sink in the middle of the unit square, sources at its corners: the field flows
        // inwards around the sink on every level, which keys averaged outward cannot give
        // (their mean has no singularity where the user wants one).
        let mesh = grid(9, 0.125);
        let h = hierarchy(&mesh, 40.0);
        let p = SweepFieldParams {
            sinks: vec![point(40)],
            sources: vec![point(0), point(8), point(72), point(80)],
            ..Default::default()
        };
        let keys = resolve_keys(&mesh, &p).unwrap();
        let f = sweep_field(&h, &keys, &p).unwrap();
        let centre = Vec3::new(0.5, 0.5, 0.0);
        let mut checked = 0;
        for (v, o) in f.orientation.iter().enumerate() {
            let to_sink = centre - h.positions[v];
            if (0.08..0.2).contains(&to_sink.length()) {
                let a = o.angle_between(to_sink).to_degrees();
                assert!(
                    a < 25.0,
                    "vertex {v} at {}: {a}° off the sink",
                    h.positions[v]
                );
                checked += 1;
            }
        }
        assert!(checked > 50, "{checked}");
        // The sweep starts at the first source and rises towards the sink.
        assert!(
            f.sweep[40] > f.sweep[0] + 0.3,
            "{} {}",
            f.sweep[0],
            f.sweep[40]
        );
        // A lone sink flows from the vertex farthest from it (a corner) into it.
        let p = SweepFieldParams {
            sinks: vec![point(80)],
            ..Default::default()
        };
        let f = sweep_field(&h, &resolve_keys(&mesh, &p).unwrap(), &p).unwrap();
        let mid = f.orientation[40];
        assert!(
            mid.angle_between(Vec3::new(1.0, 1.0, 0.0)).to_degrees() < 10.0,
            "{mid}"
        );
    }

    #[test]
    fn keys_turn_the_flow_and_stay_fixed_on_every_level() {
        // Flow from the left edge's middle (0, 0.5) to the right edge's (1, 0.5); a key at the
        // centre turns it a quarter turn, one at (0.2, 0.5) keeps it: between them it turns
        // part way, and both keys hold on every level.
        let mesh = grid(11, 0.1);
        let h = hierarchy(&mesh, 20.0);
        let key = |v, d: [f32; 3]| Anchor {
            vertex: Some(v),
            at: None,
            direction: d,
        };
        let p = SweepFieldParams {
            sources: vec![point(55)],
            sinks: vec![point(65)],
            keys: vec![key(60, [0.0, 1.0, 0.0]), key(57, [1.0, 0.0, 0.0])],
            ..Default::default()
        };
        let keys = resolve_keys(&mesh, &p).unwrap();
        let f = sweep_field(&h, &keys, &p).unwrap();
        assert!(h.levels() > 2);
        assert_eq!(f.orientation[60], Vec3::Y);
        assert_eq!(f.orientation[57], Vec3::X);
        let between = f.orientation[59].angle_between(Vec3::X).to_degrees();
        assert!((20.0..80.0).contains(&between), "{between}");
        // Without the keys the flow runs along x there.
        let plain = SweepFieldParams {
            keys: vec![],
            ..p.clone()
        };
        let g = sweep_field(&h, &resolve_keys(&mesh, &plain).unwrap(), &plain).unwrap();
        assert!(g.orientation[59].angle_between(Vec3::X).to_degrees() < 5.0);
    }

    #[test]
    fn a_rotation_turns_every_vector_about_its_normal() {
        let mesh = grid(9, 0.125);
        let h = hierarchy(&mesh, 40.0);
        let key = Anchor {
            vertex: Some(40),
            at: None,
            direction: [1.0, 0.0, 0.0],
        };
        for (degrees, want) in [(90.0, Vec3::Y), (-90.0, -Vec3::Y), (180.0, -Vec3::X)] {
            let p = SweepFieldParams {
                keys: vec![key.clone()],
                rotation: degrees,
                ..Default::default()
            };
            let f = sweep_field(&h, &resolve_keys(&mesh, &p).unwrap(), &p).unwrap();
            for (v, o) in f.orientation.iter().enumerate() {
                assert!(o.distance(want) < 1e-3, "{degrees}°, vertex {v}: {o}");
            }
        }
        let p = SweepFieldParams {
            rotation: 200.0,
            ..Default::default()
        };
        assert!(
            p.validate()
                .unwrap_err()
                .to_string()
                .contains("field.rotation")
        );
    }

    #[test]
    fn bad_sinks_and_sources_are_named() {
        let mesh = grid(5, 0.25);
        let p = SweepFieldParams {
            sinks: vec![point(3)],
            sources: vec![point(1), point(3)],
            ..Default::default()
        };
        let e = resolve_keys(&mesh, &p).unwrap_err().to_string();
        assert!(
            e.contains("field.sources[1]") && e.contains("also a sink"),
            "{e}"
        );
        let p = SweepFieldParams {
            sinks: vec![Point::default()],
            ..Default::default()
        };
        let e = resolve_keys(&mesh, &p).unwrap_err().to_string();
        assert!(e.contains("field.sinks[0]"), "{e}");
    }

    #[test]
    fn no_keys_gives_the_default_flow_and_bad_keys_are_named() {
        let mesh = crate::geom::primitives::torus(24, 12, 0.3);
        let h = hierarchy(&mesh, 8.0);
        let f = sweep_field(&h, &FieldKeys::default(), &SweepFieldParams::default()).unwrap();
        assert!(
            f.orientation
                .iter()
                .all(|o| (o.length() - 1.0).abs() < 1e-3)
        );
        // The torus lies in the xy plane: the default flow runs along x (its longest side,
        // tied with y; x wins), so on the outer rim at ±y the field points along ±x, and the
        // sweep grows along x.
        let (mut along, mut n) = (0.0, 0);
        for (v, p) in h.positions.iter().enumerate() {
            if p.y.abs() > 2.2 {
                along += f.orientation[v].x.abs();
                n += 1;
            }
        }
        assert!(n > 0 && along / n as f32 > 0.9, "{}", along / n as f32);
        let level0 = h.level(0);
        let x = |u: usize| level0.positions[u].x;
        let lo = (0..level0.vertex_count())
            .min_by(|&a, &b| x(a).total_cmp(&x(b)))
            .unwrap();
        let hi = (0..level0.vertex_count())
            .max_by(|&a, &b| x(a).total_cmp(&x(b)))
            .unwrap();
        assert!(
            f.sweep[hi] > f.sweep[lo] + 2.0,
            "{} {}",
            f.sweep[lo],
            f.sweep[hi]
        );
        let p = SweepFieldParams {
            keys: vec![Anchor {
                vertex: Some(100_000),
                at: None,
                direction: [1.0, 0.0, 0.0],
            }],
            ..Default::default()
        };
        let e = resolve_keys(&mesh, &p).unwrap_err().to_string();
        assert!(e.contains("field.keys[0]") && e.contains("100000"), "{e}");
    }
}
