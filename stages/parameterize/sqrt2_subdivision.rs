//! The √2-subdivision mesh hierarchy of Bangay & Morkel, "Graph Matching with Subdivision
//! Surfaces for Texture Synthesis on Surfaces" (AFRIGRAPH 2006), §3.2, built on the √2 split
//! of Li, Ma & Bao, "√2 subdivision for quadrilateral meshes", The Visual Computer 20 (2004).
//!
//! §3.2.1: one √2 step puts a point at the centre of every face and replaces every edge by the
//! quad joining its two ends and the points of its two faces, so a mesh of any polygons becomes
//! quads (triangles where an edge has one face), the face count becomes the edge count (about
//! double) and every old vertex keeps its id. §3.2.2: faces whose area exceeds f times the mean
//! are refined alone ("adaptive subdivision"), with triangles closing the seam between the
//! refined region and the rest (Fig. 5), round after round, to even out the vertex density
//! (§4: 16 rounds take the monarch from 722.9 % to 38.3 % standard deviation of face area).
//! The hierarchy is that evened-out mesh followed by full √2 steps until one edge spans about
//! one texel of the texture (the §3.3.2 scale ratio `r_scale`, texels per object unit).
//!
//! Where this departs from the papers, and why:
//! - Face points are plain centroids and old vertices stay where they are unless `smooth` is
//!   asked for: texture is sampled at vertices (§3.2.1), so attributes computed on one level
//!   carry over to the next unchanged, and the synthesis interpolates new vertices from their
//!   parents exactly. The surface stays the input's piecewise-flat surface.
//! - `smooth = true` is NOT Li, Ma & Bao's smoothing: their vertex and face masks (valence-
//!   dependent weights derived from 4-8 subdivision) could not be checked against the paper,
//!   so this implements a documented stand-in: each old vertex whose faces are all refined and
//!   which is on no boundary or seam moves halfway towards the mean of its new neighbouring
//!   face points, `v ← v/2 + mean(fp)/2`. On a regular quad grid that mean is the bilinear
//!   B-spline mask (1/4 centre, 1/8 edge neighbours, 1/16 diagonal ones), so the relaxation
//!   rounds corners without shrinking flat regions. Pre-subdivision never smooths.
//! - Li et al. keep neighbouring faces within one level of each other at a seam; like Bangay &
//!   Morkel ("we relax the requirement", §3.2.2) the seam triangles here allow any difference.
//! - An edge shared by three or more faces (not a manifold) or by one face twice is left in
//!   place and each refined face gets a triangle on it, so such an input keeps its topology
//!   rather than making the step fail; an edge two faces use in the same direction (an
//!   inconsistently oriented input) still becomes one quad, oriented like its first face.
//! - Pre-subdivision (§3.2.2) stops early by default: after a round that lowers the area
//!   spread by less than `adaptive_min_gain` (10 %) of itself, and once edges span a texel.
//!   The paper runs a fixed number of rounds (16 for the monarch), but each round refines a
//!   share of all faces, since the mean area it thresholds against falls: 16 rounds took the
//!   cow from 2,904 to 114,535 vertices with the spread at 37 % after 6, which leaves no
//!   coarse level to start from. `adaptive_min_gain = 0` runs the paper's fixed rounds.

use crate::check::{ParamError, check_range};
use crate::geom::Mesh;
use crate::geom::poly_mesh::PolyMesh;
use crate::graph::Csr;
use glam::Vec3;
use serde::{Deserialize, Serialize};
use texsyn_core::algorithm::Failure;

/// The `sqrt2_hierarchy` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("sqrt2_hierarchy", 2);

/// How far `smooth` moves an old vertex towards the mean of its new face points.
const RELAXATION: f32 = 0.5;

/// The edges of a polygon mesh, each with the corners (face sides) that use it. Corner `c` of
/// face `f` is the directed edge `face_vertices[c] → face_vertices[next(c)]`.
struct Edges {
    /// The face each corner belongs to.
    face_of: Vec<u32>,
    /// The edge each corner is a side of.
    edge_of: Vec<u32>,
    /// Corners of edge `e`: `corners[start[e]..start[e + 1]]`, ascending, so the first is the
    /// edge's first appearance in face order.
    start: Vec<u32>,
    corners: Vec<u32>,
}

impl Edges {
    fn build(mesh: &PolyMesh) -> Edges {
        let corner_count = mesh.face_vertices.len();
        let mut face_of = vec![0u32; corner_count];
        for f in 0..mesh.face_count() {
            face_of[mesh.face_start[f] as usize..mesh.face_start[f + 1] as usize].fill(f as u32);
        }
        let ends = |c: usize| {
            (
                mesh.face_vertices[c],
                mesh.face_vertices[next(mesh, &face_of, c)],
            )
        };
        // Bucket the corners by their edge's lower vertex (a counting sort, so linear), then
        // order each short bucket by the upper vertex; the sort is stable, so corners of one
        // edge stay in ascending order.
        let n = mesh.vertex_count();
        let Csr {
            offsets: bucket_start,
            items: mut corners,
        } = Csr::<u32>::from_pairs(
            n,
            (0..corner_count).map(|c| {
                let (a, b) = ends(c);
                (a.min(b) as usize, c as u32)
            }),
        );
        let mut edge_of = vec![0u32; corner_count];
        let mut start = vec![0u32];
        for v in 0..n {
            let bucket = &mut corners[bucket_start[v] as usize..bucket_start[v + 1] as usize];
            let upper = |c: &u32| {
                let (a, b) = ends(*c as usize);
                a.max(b)
            };
            bucket.sort_by_key(upper);
            for i in 0..bucket.len() {
                if i > 0 && upper(&bucket[i]) != upper(&bucket[i - 1]) {
                    start.push(bucket_start[v] + i as u32);
                }
                edge_of[bucket[i] as usize] = start.len() as u32 - 1;
            }
            if !bucket.is_empty() {
                start.push(bucket_start[v + 1]);
            }
        }
        Edges {
            face_of,
            edge_of,
            start,
            corners,
        }
    }

    fn count(&self) -> usize {
        self.start.len() - 1
    }

    fn uses(&self, e: usize) -> &[u32] {
        &self.corners[self.start[e] as usize..self.start[e + 1] as usize]
    }

    /// Whether the edge becomes a quad: exactly two corners, of two different faces, both
    /// refined. Every other edge stays, with a triangle on it for each refined face.
    fn paired(&self, e: usize, selected: &dyn Fn(usize) -> bool) -> bool {
        let u = self.uses(e);
        let (f, g) = (
            self.face_of[u[0] as usize],
            self.face_of[u[u.len() - 1] as usize],
        );
        u.len() == 2 && f != g && selected(f as usize) && selected(g as usize)
    }
}

/// The corner after corner `c` in its face.
fn next(mesh: &PolyMesh, face_of: &[u32], c: usize) -> usize {
    let f = face_of[c] as usize;
    if c + 1 == mesh.face_start[f + 1] as usize {
        mesh.face_start[f] as usize
    } else {
        c + 1
    }
}

/// One √2 step on the faces `selected` marks (all faces when `None`). Faces must not repeat a
/// vertex.
///
/// Returns the refined mesh and, per new vertex, the index in `mesh` of the face whose
/// centroid it is. Old vertices keep their ids (and, unless `smooth`, their positions bit for
/// bit); the face points follow them as ids `V..V + F_selected`, in face order. Output faces:
/// the unselected faces unchanged, in input order, then for each edge in order of its first
/// appearance in face order, either the quad `[a, fp_G, b, fp_F]` (an edge `a → b` of face
/// F whose other face G is refined too: the orientation of F is kept) or, for each refined
/// face F on it, the triangle `[a, b, fp_F]` (a boundary edge, the seam with unrefined faces,
/// or a non-manifold edge). The result is conforming, and consistently oriented and manifold
/// wherever the input is.
pub fn sqrt2_step(
    mesh: &PolyMesh,
    selected: Option<&[bool]>,
    smooth: bool,
) -> (PolyMesh, Vec<u32>) {
    if let Some(s) = selected {
        assert_eq!(s.len(), mesh.face_count(), "one selection flag per face");
    }
    let is_selected = |f: usize| selected.is_none_or(|s| s[f]);
    let edges = Edges::build(mesh);
    let old_count = mesh.vertex_count();

    let mut face_point = vec![u32::MAX; mesh.face_count()];
    let mut parents = Vec::new();
    for f in 0..mesh.face_count() {
        if is_selected(f) {
            face_point[f] = (old_count + parents.len()) as u32;
            parents.push(f as u32);
        }
    }
    let mut positions = Vec::with_capacity(old_count + parents.len());
    positions.extend_from_slice(&mesh.positions);
    positions.extend(parents.iter().map(|&f| mesh.face_centroid(f as usize)));

    let mut faces = PolyMesh {
        positions: Vec::new(),
        face_start: vec![0],
        face_vertices: Vec::with_capacity(4 * edges.count()),
    };
    let mut push = |vertices: &[u32]| {
        faces.face_vertices.extend_from_slice(vertices);
        faces.face_start.push(faces.face_vertices.len() as u32);
    };
    for f in (0..mesh.face_count()).filter(|&f| !is_selected(f)) {
        push(mesh.face(f));
    }
    let mut emitted = vec![false; edges.count()];
    for c in 0..mesh.face_vertices.len() {
        let e = edges.edge_of[c] as usize;
        if std::mem::replace(&mut emitted[e], true) {
            continue;
        }
        let uses = edges.uses(e);
        let ends = |u: u32| {
            let u = u as usize;
            let fp = face_point[edges.face_of[u] as usize];
            let b = mesh.face_vertices[next(mesh, &edges.face_of, u)];
            (mesh.face_vertices[u], b, fp)
        };
        if edges.paired(e, &is_selected) {
            let (a, b, fp_f) = ends(uses[0]);
            let (_, _, fp_g) = ends(uses[1]);
            push(&[a, fp_g, b, fp_f]);
        } else {
            for &u in uses {
                if is_selected(edges.face_of[u as usize] as usize) {
                    let (a, b, fp) = ends(u);
                    push(&[a, b, fp]);
                }
            }
        }
    }

    if smooth {
        relax_old_vertices(mesh, &edges, &is_selected, &face_point, &mut positions);
    }
    faces.positions = positions;
    (faces, parents)
}

/// The `smooth` stand-in (see the module doc): moves each old vertex that has only refined
/// faces and only quad-making edges halfway to the mean of its faces' points. Vertices on a
/// boundary, a seam or a non-manifold edge stay, so outlines and seams do not shrink.
fn relax_old_vertices(
    mesh: &PolyMesh,
    edges: &Edges,
    is_selected: &dyn Fn(usize) -> bool,
    face_point: &[u32],
    positions: &mut [Vec3],
) {
    let old_count = mesh.vertex_count();
    let mut movable = vec![true; old_count];
    let mut sum = vec![Vec3::ZERO; old_count];
    let mut count = vec![0u32; old_count];
    for f in 0..mesh.face_count() {
        for &v in mesh.face(f) {
            if is_selected(f) {
                sum[v as usize] += positions[face_point[f] as usize];
                count[v as usize] += 1;
            } else {
                movable[v as usize] = false;
            }
        }
    }
    for e in 0..edges.count() {
        if !edges.paired(e, is_selected) {
            let c = edges.uses(e)[0] as usize;
            movable[mesh.face_vertices[c] as usize] = false;
            movable[mesh.face_vertices[next(mesh, &edges.face_of, c)] as usize] = false;
        }
    }
    for v in 0..old_count {
        if movable[v] && count[v] > 0 {
            let mean = sum[v] / count[v] as f32;
            positions[v] = positions[v].lerp(mean, RELAXATION);
        }
    }
}

/// Standard deviation of the face areas over their mean (population deviation, as a fraction:
/// 7.229 is the paper's 722.9 %); 0 for a mesh without faces or area.
pub fn area_spread(mesh: &PolyMesh) -> f32 {
    let areas: Vec<f64> = (0..mesh.face_count())
        .map(|f| mesh.face_area(f) as f64)
        .collect();
    if areas.is_empty() {
        return 0.0;
    }
    let mean = areas.iter().sum::<f64>() / areas.len() as f64;
    if mean <= 0.0 {
        return 0.0;
    }
    let variance = areas.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / areas.len() as f64;
    (variance.sqrt() / mean) as f32
}

/// §3.2.2: up to `rounds` rounds of √2 steps on just the faces whose area exceeds `factor`
/// times the mean face area, stopping early when no face does (with `factor` ≥ 1 some face
/// is always left out; `factor` = 0 refines every face of non-zero area).
///
/// Returns the mesh, the parents of every new vertex (entry `i` is vertex `V + i` of the
/// result, `V` the input's vertex count: the ids of the corners of the face it is the centroid
/// of, ids of the result since old ids never change), and the area spread before the first
/// round and after each round done.
pub fn adaptive_presubdivision(
    mesh: &PolyMesh,
    factor: f32,
    rounds: u32,
) -> (PolyMesh, Vec<Vec<u32>>, Vec<f32>) {
    let mut current = mesh.clone();
    let mut parents = Vec::new();
    let mut spread = vec![area_spread(mesh)];
    for _ in 0..rounds {
        let areas: Vec<f64> = (0..current.face_count())
            .map(|f| current.face_area(f) as f64)
            .collect();
        let threshold = factor as f64 * areas.iter().sum::<f64>() / areas.len().max(1) as f64;
        let selected: Vec<bool> = areas.iter().map(|&a| a > threshold).collect();
        if !selected.contains(&true) {
            break;
        }
        let (next, parent_faces) = sqrt2_step(&current, Some(&selected), false);
        parents.extend(
            parent_faces
                .iter()
                .map(|&f| current.face(f as usize).to_vec()),
        );
        current = next;
        spread.push(area_spread(&current));
    }
    (current, parents, spread)
}

/// Parameters of [`build_hierarchy`] (the graph-matching method's `[parameterize]` section).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SubdivisionParams {
    /// Level-0 exemplar texels per object unit (the paper's r_scale, §3.3.2): the hierarchy is
    /// refined until an edge spans about one texel. Default: `"auto"` (read as 0 and resolved
    /// by the method: the exemplar's width spans a quarter of the mesh's bounding-box
    /// diagonal).
    #[serde(deserialize_with = "crate::parameterize::texels_or_auto")]
    pub scale: f32,
    /// The threshold factor f of §3.2.2: faces with area > f × mean are refined. 0 turns
    /// adaptive pre-subdivision off; otherwise 1 to 100. Default: 1.5 (the paper's choice for
    /// most objects).
    pub area_factor: f32,
    /// Most rounds of adaptive pre-subdivision (fewer when no face is over the threshold, a
    /// round no longer lowers the area spread by `adaptive_min_gain`, or edges already span a
    /// texel). Range 0 to 64. Default: 8.
    pub adaptive_rounds: u32,
    /// The early stop of pre-subdivision: a round is kept only if it lowers the area spread by
    /// at least this share of it, and no round refines edges that already span a texel. 0
    /// turns both off, for the paper's fixed `adaptive_rounds` rounds (fewer only when no face
    /// is over the threshold). Range 0 to 1. Default: 0.1. Left out of the node's key at the
    /// default.
    #[serde(skip_serializing_if = "is_default_min_gain")]
    pub adaptive_min_gain: f32,
    /// Move old vertices at each full step (a relaxation, not Li et al.'s masks: see the module
    /// doc). Default: false, which keeps every vertex where it was created.
    pub smooth: bool,
    /// Most vertices the finest level may have, a memory budget: about 100 bytes per vertex
    /// over all levels. Range 1 to 250 000 000 (all levels' corners must fit u32 offsets).
    /// Default: 4 000 000.
    pub max_vertices: u64,
}

impl Default for SubdivisionParams {
    fn default() -> Self {
        SubdivisionParams {
            scale: 0.0,
            area_factor: 1.5,
            adaptive_rounds: 8,
            adaptive_min_gain: DEFAULT_MIN_SPREAD_GAIN,
            smooth: false,
            max_vertices: 4_000_000,
        }
    }
}

/// The default of `adaptive_min_gain`: a pre-subdivision round is kept only if it lowers the
/// area spread by at least this share.
const DEFAULT_MIN_SPREAD_GAIN: f32 = 0.1;

fn is_default_min_gain(g: &f32) -> bool {
    *g == DEFAULT_MIN_SPREAD_GAIN
}

/// Upper bound of `max_vertices`: the finest level has about as many faces as vertices, four
/// corners each, and all levels together about twice that, so 8 corners per vertex stay well
/// inside the u32 offsets.
const MAX_VERTICES_LIMIT: u64 = 250_000_000;

impl SubdivisionParams {
    /// Checks every field's range; the message names the key, the range and the value.
    pub fn validate(&self) -> Result<(), ParamError> {
        if self.area_factor != 0.0 && !(1.0..=100.0).contains(&self.area_factor) {
            return Err(ParamError::invalid(
                "parameterize.area_factor",
                format!(
                    "must be 0 (no adaptive pre-subdivision) or in 1..=100, got {}",
                    self.area_factor
                ),
            ));
        }
        if !(self.scale.is_finite() && self.scale >= 0.0) {
            return Err(ParamError::invalid(
                "parameterize.scale",
                format!("must be a positive number, got {}", self.scale),
            ));
        }
        check_range("parameterize.adaptive_rounds", self.adaptive_rounds, 0, 64)?;
        check_range(
            "parameterize.adaptive_min_gain",
            self.adaptive_min_gain,
            0.0,
            1.0,
        )?;
        check_range(
            "parameterize.max_vertices",
            self.max_vertices,
            1,
            MAX_VERTICES_LIMIT,
        )
    }
}

/// Why [`build_hierarchy`] could not build a hierarchy.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SubdivisionError {
    #[error(transparent)]
    Params(#[from] ParamError),
    #[error(
        "parameterize.scale must be a positive finite number of texels per object unit, got \
         {scale}"
    )]
    Scale { scale: f32 },
    #[error("inputs.mesh has no faces: the √2 hierarchy needs a surface")]
    NoFaces,
    #[error("inputs.mesh: vertex {vertex} has a non-finite position {position}")]
    NonFinite { vertex: usize, position: Vec3 },
    #[error("inputs.mesh: triangle {face} {problem}")]
    BadTriangle { face: usize, problem: String },
    #[error(
        "parameterize.scale = {scale} would make about {vertices} vertices at the finest level \
         (budget {max_vertices}, parameterize.max_vertices); scale ≤ {scale_that_fits} fits"
    )]
    TooFine {
        scale: f32,
        vertices: u64,
        max_vertices: u64,
        scale_that_fits: f32,
    },
    #[error(
        "the coarsest level (the mesh after any adaptive pre-subdivision) already has \
         {vertices} vertices, over the budget of {max_vertices} (parameterize.max_vertices); \
         raise the budget, or lower parameterize.adaptive_rounds"
    )]
    TooLarge { vertices: u64, max_vertices: u64 },
}

/// The levels of a √2 hierarchy, sharing one vertex array: level `l` is made of the vertices
/// `0..level_vertices[l]` (every level is a prefix of the next, §3.2.1) and the faces
/// `level_face_start[l]..level_face_start[l + 1]` of the concatenated face list.
///
/// Vertices `0..input_vertices` are the input mesh's, with its ids; every later vertex was
/// made as the centroid of a face, whose corners `parents(v)` lists (pre-subdivision and full
/// steps alike), so per-vertex data on one level extends to the next by averaging over
/// parents in id order. With `smooth`, `positions` holds each vertex where the finest level
/// has it (old vertices move at each step), so coarse levels are samples of the finest surface
/// and a new vertex is no longer exactly at its parents' centroid.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Sqrt2Hierarchy {
    pub positions: Vec<Vec3>,
    pub level_vertices: Vec<u32>,
    /// Per level, its first face; one more entry than levels.
    pub level_face_start: Vec<u32>,
    /// Faces of all levels, coarsest first, in compressed-row form.
    pub face_start: Vec<u32>,
    pub face_vertices: Vec<u32>,
    /// Per vertex (all of them), the corners of the face whose centroid made it; empty for the
    /// input's vertices.
    pub parent_start: Vec<u32>,
    pub parent_vertices: Vec<u32>,
    /// How many vertices the input mesh had (its unreferenced vertices included).
    pub input_vertices: u32,
}

impl Sqrt2Hierarchy {
    pub fn levels(&self) -> usize {
        self.level_vertices.len()
    }

    /// Level `l` as a mesh of its own (positions truncated to its vertices).
    pub fn level(&self, l: usize) -> PolyMesh {
        let (first, end) = (
            self.level_face_start[l] as usize,
            self.level_face_start[l + 1] as usize,
        );
        let base = self.face_start[first];
        PolyMesh {
            positions: self.positions[..self.level_vertices[l] as usize].to_vec(),
            face_start: self.face_start[first..=end]
                .iter()
                .map(|s| s - base)
                .collect(),
            face_vertices: self.face_vertices[base as usize..self.face_start[end] as usize]
                .to_vec(),
        }
    }

    pub fn parents(&self, v: usize) -> &[u32] {
        &self.parent_vertices[self.parent_start[v] as usize..self.parent_start[v + 1] as usize]
    }

    fn push_level(&mut self, mesh: &PolyMesh) {
        let base = self.face_vertices.len() as u32;
        self.face_vertices.extend_from_slice(&mesh.face_vertices);
        self.face_start
            .extend(mesh.face_start[1..].iter().map(|s| s + base));
        self.level_vertices.push(mesh.vertex_count() as u32);
        self.level_face_start.push(self.face_start.len() as u32 - 1);
    }

    fn push_parents(&mut self, corners: &[u32]) {
        self.parent_vertices.extend_from_slice(corners);
        self.parent_start.push(self.parent_vertices.len() as u32);
    }
}

/// Builds the hierarchy for a texture at `scale` texels per object unit: level 0 is the input
/// after adaptive pre-subdivision (`p.area_factor`, `p.adaptive_rounds`, stopped early by
/// `p.adaptive_min_gain`; never smoothed),
/// then full √2 steps follow while `scale × mean edge length > 1`, so the finest level is the
/// first whose edges span at most about one texel. A mesh already that fine is one level.
///
/// The budget is checked before each full step, where the next level's size is known exactly
/// (V' = V + F), and after each pre-subdivision round. If the next full step would exceed
/// `p.max_vertices`, the error estimates the finest level's size (exact vertex counts and next
/// edge length, then edges assumed √2 shorter per step) and gives the largest scale at which
/// the finest level that fits is the last one needed: 1 / (its mean edge length). That needs
/// the levels up to the budget built, so an error costs as much time as the largest hierarchy
/// the budget allows; an estimate made up front could only guess which level a scale stops
/// at, and a suggested scale that then did not fit would be worse than the wait.
pub fn build_hierarchy(
    mesh: &Mesh,
    scale: f32,
    p: &SubdivisionParams,
) -> Result<Sqrt2Hierarchy, SubdivisionError> {
    check_inputs(mesh, scale, p)?;
    hierarchy_of(PolyMesh::from_mesh(mesh), scale, p)
}

/// [`build_hierarchy`] from a polygon mesh as it is: the quadrilaterals of earlier √2 steps
/// stay quadrilaterals (valence-4 vertices, as the paper's meshes have after subdivision,
/// §3.2.1), where a triangle mesh's vertices have about six neighbours.
pub fn build_hierarchy_from_polygons(
    mesh: PolyMesh,
    scale: f32,
    p: &SubdivisionParams,
) -> Result<Sqrt2Hierarchy, SubdivisionError> {
    check_inputs(&mesh.to_triangles(), scale, p)?;
    hierarchy_of(mesh, scale, p)
}

/// The parameters, the scale and the mesh (as triangles), before anything is built.
fn check_inputs(mesh: &Mesh, scale: f32, p: &SubdivisionParams) -> Result<(), SubdivisionError> {
    p.validate()?;
    if !(scale.is_finite() && scale > 0.0) {
        return Err(SubdivisionError::Scale { scale });
    }
    check_mesh(mesh)
}

fn hierarchy_of(
    input: PolyMesh,
    scale: f32,
    p: &SubdivisionParams,
) -> Result<Sqrt2Hierarchy, SubdivisionError> {
    let mut h = Sqrt2Hierarchy {
        level_face_start: vec![0],
        face_start: vec![0],
        parent_start: vec![0; input.vertex_count() + 1],
        input_vertices: input.vertex_count() as u32,
        ..Default::default()
    };
    let too_large = |m: &PolyMesh| SubdivisionError::TooLarge {
        vertices: m.vertex_count() as u64,
        max_vertices: p.max_vertices,
    };
    let mut current = input;
    if current.vertex_count() as u64 > p.max_vertices {
        return Err(too_large(&current));
    }
    // One round at a time, the same as `adaptive_presubdivision(.., rounds)` (each round
    // thresholds its own mesh), so that the budget is checked before a further round can
    // grow the mesh: a round refines a constant share of the faces, so many rounds on a large
    // mesh could take any amount of memory.
    if p.area_factor > 0.0 {
        let early_stop = p.adaptive_min_gain > 0.0;
        for _ in 0..p.adaptive_rounds {
            // Pre-subdivision evens out the vertex distribution; once a round stops doing
            // that (the spread bottoms out at 30–40 %, §3.2.2), further rounds only refine
            // everything, as the mean area falls with each round. Nor is it refined past the
            // texture's resolution: the levels do that.
            if early_stop && spans_at_most_one_texel(scale, current.mean_edge_length()) {
                break;
            }
            let (refined, parents, spread) = adaptive_presubdivision(&current, p.area_factor, 1);
            if parents.is_empty()
                || (early_stop && spread[1] > (1.0 - p.adaptive_min_gain) * spread[0])
            {
                break;
            }
            tracing::debug!(
                "adaptive pre-subdivision round: area spread {:.1} % -> {:.1} %, {} vertices",
                100.0 * spread[0],
                100.0 * spread[1],
                refined.vertex_count()
            );
            if refined.vertex_count() as u64 > p.max_vertices {
                return Err(too_large(&refined));
            }
            for corners in &parents {
                h.push_parents(corners);
            }
            current = refined;
        }
    }
    loop {
        h.push_level(&current);
        let edge = current.mean_edge_length();
        if spans_at_most_one_texel(scale, edge) {
            break;
        }
        let next_vertices = (current.vertex_count() + current.face_count()) as u64;
        if next_vertices > p.max_vertices {
            return Err(SubdivisionError::TooFine {
                scale,
                vertices: estimate_finest_vertices(&current, scale),
                max_vertices: p.max_vertices,
                scale_that_fits: largest_scale_stopping_at(edge),
            });
        }
        let (next, parent_faces) = sqrt2_step(&current, None, p.smooth);
        for &f in &parent_faces {
            h.push_parents(current.face(f as usize));
        }
        current = next;
    }
    h.positions = current.positions;
    Ok(h)
}

/// The stopping rule, in f64 so that [`largest_scale_stopping_at`] can invert it exactly.
fn spans_at_most_one_texel(scale: f32, edge: f32) -> bool {
    scale as f64 * edge as f64 <= 1.0
}

/// The largest f32 scale for which a level of mean edge length `edge` is the finest.
fn largest_scale_stopping_at(edge: f32) -> f32 {
    if edge <= 0.0 {
        return f32::MAX;
    }
    let mut s = (1.0 / edge as f64) as f32;
    while !spans_at_most_one_texel(s, edge) {
        s = s.next_down();
    }
    while s < f32::MAX && spans_at_most_one_texel(s.next_up(), edge) {
        s = s.next_up();
    }
    s
}

/// The finest level's vertex count if full steps went on from `mesh` until `scale × edge ≤ 1`.
/// The counts are exact ([`Counts`]) and so is the next level's mean edge length; only later
/// edge lengths are a guess: √2 shorter per step, as on a regular quad grid. (The first step
/// from triangles shrinks edges faster, by about 0.45, which is why it is computed.)
fn estimate_finest_vertices(mesh: &PolyMesh, scale: f32) -> u64 {
    let edges = Edges::build(mesh);
    let mut counts = Counts::of(mesh, &edges);
    let mut length = mean_edge_after_full_step(mesh, &edges);
    // A few hundred steps take any f32 scale down to a texel; f64 counts do not overflow.
    loop {
        counts = counts.after_full_step();
        if scale as f64 * length <= 1.0 || counts.vertices >= u64::MAX as f64 {
            return counts.vertices as u64;
        }
        length /= std::f64::consts::SQRT_2;
    }
}

/// The mean edge length a full step would give, without making it: the new edges join each
/// corner to its face's centroid, and the edges that do not become quads stay.
fn mean_edge_after_full_step(mesh: &PolyMesh, edges: &Edges) -> f64 {
    let all = |_: usize| true;
    let (mut sum, mut count) = (0.0f64, 0usize);
    for f in 0..mesh.face_count() {
        let centre = mesh.face_centroid(f);
        for &v in mesh.face(f) {
            sum += centre.distance(mesh.positions[v as usize]) as f64;
            count += 1;
        }
    }
    for e in (0..edges.count()).filter(|&e| !edges.paired(e, &all)) {
        let c = edges.uses(e)[0] as usize;
        let (a, b) = (
            mesh.face_vertices[c],
            mesh.face_vertices[next(mesh, &edges.face_of, c)],
        );
        sum += mesh.positions[a as usize].distance(mesh.positions[b as usize]) as f64;
        count += 1;
    }
    sum / count.max(1) as f64
}

/// What a full √2 step does to a mesh's size, without making the step.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Counts {
    vertices: f64,
    faces: f64,
    /// Edges that become quads (two uses by two faces).
    paired_edges: f64,
    /// Uses of all other edges (boundary edges once, non-manifold ones three times or more).
    other_uses: f64,
}

impl Counts {
    fn of(mesh: &PolyMesh, edges: &Edges) -> Counts {
        let all = |_: usize| true;
        let paired = (0..edges.count())
            .filter(|&e| edges.paired(e, &all))
            .count();
        Counts {
            vertices: mesh.vertex_count() as f64,
            faces: mesh.face_count() as f64,
            paired_edges: paired as f64,
            other_uses: (mesh.face_vertices.len() - 2 * paired) as f64,
        }
    }

    /// A face point per face (V' = V + F); a quad per paired edge and a triangle per use of
    /// any other edge (F' = P + N); one new edge per corner, from the corner to its face
    /// point, and each is used by the two faces made from the corner's two sides, so paired
    /// (P' = 2P + N, the corner count); the other edges stay with as many uses (N' = N).
    fn after_full_step(self) -> Counts {
        Counts {
            vertices: self.vertices + self.faces,
            faces: self.paired_edges + self.other_uses,
            paired_edges: 2.0 * self.paired_edges + self.other_uses,
            other_uses: self.other_uses,
        }
    }
}

/// The caller's mesh problems that would otherwise be panics or NaNs deep in the subdivision.
fn check_mesh(mesh: &Mesh) -> Result<(), SubdivisionError> {
    if mesh.triangles.is_empty() {
        return Err(SubdivisionError::NoFaces);
    }
    if let Some((vertex, &position)) = mesh
        .positions
        .iter()
        .enumerate()
        .find(|(_, p)| !p.is_finite())
    {
        return Err(SubdivisionError::NonFinite { vertex, position });
    }
    let n = mesh.positions.len();
    for (face, t) in mesh.triangles.iter().enumerate() {
        let problem = if let Some(v) = t.iter().find(|&&v| v as usize >= n) {
            format!("uses vertex {v}, but the mesh has {n} vertices")
        } else if t[0] == t[1] || t[1] == t[2] || t[2] == t[0] {
            format!("repeats a vertex ({}, {}, {})", t[0], t[1], t[2])
        } else {
            continue;
        };
        return Err(SubdivisionError::BadTriangle { face, problem });
    }
    Ok(())
}

/// The parameterize node: the √2 hierarchy of the input mesh at `p.scale`. `method` names
/// the method in the mesh-health warning.
pub fn node(mesh: &Mesh, p: &SubdivisionParams, method: &str) -> Result<Sqrt2Hierarchy, Failure> {
    texsyn_core::geom::mesh_check::warn_if_unhealthy(mesh, method);
    let h = build_hierarchy(mesh, p.scale, p).map_err(Failure::input)?;
    tracing::info!(
        "parameterize: {} levels, {} → {} vertices",
        h.levels(),
        h.level_vertices[0],
        h.level_vertices.last().copied().unwrap_or(0)
    );
    Ok(h)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::poly_mesh::Adjacency;
    use crate::geom::primitives::{cube, grid, octahedron, quad_grid, torus};

    /// The octahedron with its top pulled up to z = 30: four large faces over four small ones.
    fn tall_octahedron() -> Mesh {
        let mut m = octahedron();
        m.positions[4] = Vec3::new(0.0, 0.0, 30.0);
        m
    }

    fn edge_count(m: &PolyMesh) -> usize {
        m.vertex_neighbours().neighbours.len() / 2
    }

    fn bits(p: &[Vec3]) -> Vec<[u32; 3]> {
        p.iter().map(|v| v.to_array().map(f32::to_bits)).collect()
    }

    fn mean_of(m: &[Vec3], ids: &[u32]) -> Vec3 {
        ids.iter().fold(Vec3::ZERO, |s, &v| s + m[v as usize]) / ids.len() as f32
    }

    fn degree(adj: &Adjacency, v: usize) -> usize {
        adj.of(v).len()
    }

    #[test]
    fn full_step_on_closed_meshes_makes_quads_and_keeps_the_genus() {
        for (mesh, euler) in [(octahedron(), 2), (cube(), 2), (torus(8, 6, 0.5), 0)] {
            let p = PolyMesh::from_mesh(&mesh);
            let (q, parents) = sqrt2_step(&p, None, false);
            assert_eq!(q.vertex_count(), p.vertex_count() + p.face_count());
            assert_eq!(q.face_count(), edge_count(&p), "one face per old edge");
            assert!((0..q.face_count()).all(|f| q.face(f).len() == 4));
            assert_eq!(bits(&q.positions[..p.vertex_count()]), bits(&p.positions));
            assert!(q.is_consistently_oriented());
            assert_eq!(p.euler_characteristic(), euler);
            assert_eq!(q.euler_characteristic(), euler);
            assert_eq!(q.boundary_edge_count(), 0);
            assert_eq!(parents, (0..p.face_count() as u32).collect::<Vec<_>>());
            // Face points at their face's centroid; an old vertex is joined to the points of
            // its faces only (as many as its old valence), a face point to its face's corners.
            let (old_adj, adj) = (p.vertex_neighbours(), q.vertex_neighbours());
            for (i, &f) in parents.iter().enumerate() {
                let v = p.vertex_count() + i;
                assert_eq!(q.positions[v], p.face_centroid(f as usize));
                let mut corners = p.face(f as usize).to_vec();
                corners.sort();
                assert_eq!(adj.of(v), &corners[..]);
            }
            for v in 0..p.vertex_count() {
                assert_eq!(degree(&adj, v), degree(&old_adj, v));
                assert!(adj.of(v).iter().all(|&w| w as usize >= p.vertex_count()));
            }
            // Outward normals stay outward: the orientation follows the input's.
            let centre = mesh.bounds().0.midpoint(mesh.bounds().1);
            if euler == 2 {
                for f in 0..q.face_count() {
                    let c = q.face_centroid(f);
                    assert!(q.face_normal_unnormalized(f).dot(c - centre) > 0.0);
                }
            }
        }
    }

    #[test]
    fn each_edge_becomes_a_quad_oriented_like_its_first_face_or_a_boundary_triangle() {
        // Two triangles sharing the edge 1-2: 1 → 2 in face 0, 2 → 1 in face 1.
        let p = PolyMesh::from_faces(
            vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::ONE],
            &[vec![0, 1, 2], vec![2, 1, 3]],
        );
        let (q, parents) = sqrt2_step(&p, None, false);
        assert_eq!(parents, vec![0, 1]);
        let faces: Vec<&[u32]> = (0..q.face_count()).map(|f| q.face(f)).collect();
        // Face points 4 (face 0) and 5 (face 1); edges in order of first appearance.
        let want: [&[u32]; 5] = [
            &[0, 1, 4],
            &[1, 5, 2, 4],
            &[2, 0, 4],
            &[1, 3, 5],
            &[3, 2, 5],
        ];
        assert_eq!(faces, want);
        assert!(q.is_consistently_oriented());
    }

    #[test]
    fn boundary_edges_of_an_open_grid_become_triangles_and_stay_boundary() {
        let mut p = PolyMesh::from_mesh(&grid(5, 1.0));
        let boundary = p.boundary_edge_count();
        assert_eq!(boundary, 16);
        for _ in 0..3 {
            let (q, _) = sqrt2_step(&p, None, false);
            let triangles = (0..q.face_count())
                .filter(|&f| q.face(f).len() == 3)
                .count();
            assert_eq!(triangles, boundary, "one triangle per boundary edge");
            assert_eq!(q.face_count(), edge_count(&p));
            assert_eq!(q.boundary_edge_count(), boundary);
            assert_eq!(q.euler_characteristic(), 1);
            assert!(q.is_consistently_oriented());
            // The boundary edges are the old ones: each triangle's first side is one.
            for f in (0..q.face_count()).filter(|&f| q.face(f).len() == 3) {
                let t = q.face(f);
                assert!(t[0] < p.vertex_count() as u32 && t[1] < p.vertex_count() as u32);
                assert!(t[2] >= p.vertex_count() as u32);
            }
            p = q;
        }
    }

    #[test]
    fn two_steps_on_a_quad_grid_give_a_grid_of_half_the_spacing_with_ordinary_vertices() {
        let p = quad_grid(6);
        let (q, _) = sqrt2_step(&p, None, false);
        let (r, _) = sqrt2_step(&q, None, false);
        let adj = r.vertex_neighbours();
        // Away from the border the vertices are the grid of spacing 1/2 and all ordinary.
        let inner: Vec<usize> = (0..r.vertex_count())
            .filter(|&v| {
                let p = r.positions[v];
                (1.0..=5.0).contains(&p.x) && (1.0..=5.0).contains(&p.y)
            })
            .collect();
        assert_eq!(inner.len(), 9 * 9);
        for &v in &inner {
            assert_eq!(degree(&adj, v), 4, "vertex {v} at {}", r.positions[v]);
            let p = r.positions[v] * 2.0;
            assert_eq!(p, p.round());
            for &w in adj.of(v) {
                assert_eq!(r.positions[v].distance(r.positions[w as usize]), 0.5);
            }
        }
        // After one step the face points and the interior old vertices are ordinary too.
        let adj = q.vertex_neighbours();
        for v in 0..q.vertex_count() {
            let p = q.positions[v];
            if p.x > 0.0 && p.x < 6.0 && p.y > 0.0 && p.y < 6.0 {
                assert_eq!(degree(&adj, v), 4);
            }
        }
    }

    #[test]
    fn refining_a_region_closes_the_seam_with_triangles() {
        // Fig. 5: the centre 2×2 cells of a 6×6 grid.
        let p = quad_grid(6);
        let selected: Vec<bool> = (0..36)
            .map(|c| (2..4).contains(&(c % 6)) && (2..4).contains(&(c / 6)))
            .collect();
        let (q, parents) = sqrt2_step(&p, Some(&selected), false);
        assert_eq!(parents, vec![14, 15, 20, 21]);
        assert_eq!(q.vertex_count(), 49 + 4);
        // The 32 other cells first, unchanged and in order; then 4 quads on the block's inner
        // edges and 8 triangles on its outline.
        let kept: Vec<usize> = (0..36).filter(|&c| !selected[c]).collect();
        for (i, &c) in kept.iter().enumerate() {
            assert_eq!(q.face(i), p.face(c));
        }
        let sizes: Vec<usize> = (32..q.face_count()).map(|f| q.face(f).len()).collect();
        assert_eq!(sizes.iter().filter(|&&n| n == 4).count(), 4);
        assert_eq!(sizes.iter().filter(|&&n| n == 3).count(), 8);
        assert_eq!(q.face_count(), 44);
        // Conforming: the seam edges are shared by a kept cell and a triangle, nothing is
        // left open, and the orientation holds.
        assert!(q.is_consistently_oriented());
        assert_eq!(q.boundary_edge_count(), p.boundary_edge_count());
        assert_eq!(q.euler_characteristic(), 1);
        assert!((total_area(&q) - 36.0).abs() < 1e-4);
        assert_eq!(bits(&q.positions[..49]), bits(&p.positions));
    }

    #[test]
    fn smoothing_relaxes_interior_old_vertices_only() {
        // A 4×4 quad grid with its centre vertex (12) lifted.
        let mut p = quad_grid(4);
        p.positions[12].z = 1.0;
        let (plain, _) = sqrt2_step(&p, None, false);
        let (smooth, parents) = sqrt2_step(&p, None, true);
        assert_eq!(plain.face_vertices, smooth.face_vertices);
        // Each of the centre's four faces has it as one corner of four: face point z = 1/4;
        // halfway from 1 to 1/4 is 5/8.
        assert_eq!(smooth.positions[12], Vec3::new(2.0, 2.0, 0.625));
        // A flat interior vertex stays (the mask reproduces planes) up to the lifted bump's
        // reach: vertex 6 at (1, 1) has one face touching the centre, z = 1/16 after.
        assert_eq!(smooth.positions[6], Vec3::new(1.0, 1.0, 1.0 / 32.0));
        // Face points are the unsmoothed centroids; boundary vertices stay.
        for (i, &f) in parents.iter().enumerate() {
            assert_eq!(smooth.positions[25 + i], p.face_centroid(f as usize));
        }
        for v in [0, 1, 2, 3, 4, 5, 9, 10, 14, 15, 19, 20, 21, 22, 23, 24] {
            assert_eq!(smooth.positions[v], p.positions[v]);
        }
        assert_eq!(bits(&plain.positions[..25]), bits(&p.positions));
        // With a region selected, vertices on the seam stay too.
        let selected: Vec<bool> = (0..16)
            .map(|f| f == 5 || f == 6 || f == 9 || f == 10)
            .collect();
        let (part, _) = sqrt2_step(&p, Some(&selected), true);
        assert_eq!(part.positions[12], Vec3::new(2.0, 2.0, 0.625));
        assert_eq!(part.positions[6], p.positions[6]);
    }

    #[test]
    fn area_spread_is_the_relative_standard_deviation() {
        let p = PolyMesh::from_faces(
            vec![
                Vec3::ZERO,
                Vec3::X,
                Vec3::Y,
                Vec3::new(3.0, 0.0, 0.0),
                Vec3::new(0.0, 2.0, 0.0),
            ],
            // Areas 1/2 and 3/2: mean 1, deviation 1/2.
            &[vec![0, 1, 2], vec![0, 3, 2]],
        );
        assert!((area_spread(&p) - 0.5).abs() < 1e-6);
        assert_eq!(area_spread(&quad_grid(3)), 0.0);
        assert_eq!(area_spread(&PolyMesh::default()), 0.0);
    }

    /// Checks what adaptive pre-subdivision must keep: a conforming, consistently oriented
    /// mesh with the input's topology and boundary, and new vertices at their parents' mean.
    fn check_presubdivision(input: &PolyMesh, out: &PolyMesh, parents: &[Vec<u32>]) {
        assert!(out.is_consistently_oriented());
        assert_eq!(out.euler_characteristic(), input.euler_characteristic());
        assert_eq!(out.boundary_edge_count(), input.boundary_edge_count());
        assert_eq!(out.vertex_count(), input.vertex_count() + parents.len());
        assert_eq!(
            bits(&out.positions[..input.vertex_count()]),
            bits(&input.positions)
        );
        for (i, corners) in parents.iter().enumerate() {
            let v = input.vertex_count() + i;
            assert!(
                corners.iter().all(|&c| (c as usize) < v),
                "parents come first"
            );
            assert_eq!(out.positions[v], mean_of(&out.positions, corners));
        }
    }

    fn total_area(m: &PolyMesh) -> f64 {
        (0..m.face_count()).map(|f| m.face_area(f) as f64).sum()
    }

    #[test]
    fn adaptive_presubdivision_evens_out_a_closed_mesh() {
        let input = PolyMesh::from_mesh(&tall_octahedron());
        let (out, parents, spread) = adaptive_presubdivision(&input, 1.5, 16);
        check_presubdivision(&input, &out, &parents);
        assert_eq!(out.boundary_edge_count(), 0);
        assert_eq!(spread[0], area_spread(&input));
        assert_eq!(*spread.last().unwrap(), area_spread(&out));
        assert!(spread.len() > 3, "several rounds: {spread:?}");
        // It bottoms out near 40 % as in the paper (§3.2.2), not always at the last round.
        assert!(spread.last().unwrap() < &(0.6 * spread[0]), "{spread:?}");
        assert!(spread.iter().any(|&s| s < 0.5 * spread[0]), "{spread:?}");
        // Round one refines exactly the four tall faces.
        let first: Vec<&[u32]> = parents[..4].iter().map(|p| &p[..]).collect();
        assert_eq!(first, (0..4).map(|f| input.face(f)).collect::<Vec<_>>());
        assert!(!parents[4..].iter().any(|p| p == input.face(4)));
    }

    #[test]
    fn adaptive_presubdivision_evens_out_a_stretched_open_grid() {
        // x ↦ x³: cells grow from 1/81 to 61/81 of a unit wide along x.
        let mut m = grid(10, 1.0);
        for p in &mut m.positions {
            p.x = p.x.powi(3) / 81.0;
        }
        let input = PolyMesh::from_mesh(&m);
        let (out, parents, spread) = adaptive_presubdivision(&input, 1.5, 16);
        check_presubdivision(&input, &out, &parents);
        // Flat, so the new faces tile the old ones exactly.
        assert!((total_area(&out) - total_area(&input)).abs() < 1e-5 * total_area(&input));
        assert!(spread[0] > 0.8, "spread {spread:?}");
        assert!(
            spread.last().unwrap() < &(0.6 * spread[0]),
            "spread {spread:?}"
        );
        // No round is asked for when nothing is over the threshold.
        let even = quad_grid(4);
        let (same, none, spread) = adaptive_presubdivision(&even, 1.5, 16);
        assert_eq!(same, even);
        assert!(none.is_empty());
        assert_eq!(spread, vec![0.0]);
    }

    #[test]
    fn size_counts_predict_full_steps_exactly() {
        // A fin: three triangles on the edge 0-1 (not a manifold), plus closed and open meshes.
        let fin = PolyMesh::from_faces(
            vec![Vec3::ZERO, Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z],
            &[vec![0, 1, 2], vec![1, 0, 3], vec![0, 1, 4]],
        );
        for mesh in [
            fin,
            PolyMesh::from_mesh(&torus(5, 4, 0.5)),
            PolyMesh::from_mesh(&grid(4, 1.0)),
            quad_grid(3),
        ] {
            let mut counts = Counts::of(&mesh, &Edges::build(&mesh));
            let mut m = mesh;
            for _ in 0..4 {
                let predicted = mean_edge_after_full_step(&m, &Edges::build(&m));
                m = sqrt2_step(&m, None, false).0;
                counts = counts.after_full_step();
                assert_eq!(counts, Counts::of(&m, &Edges::build(&m)));
                assert!((predicted - m.mean_edge_length() as f64).abs() < 1e-6 * predicted);
                assert_eq!(counts.vertices, m.vertex_count() as f64);
                assert_eq!(counts.faces, m.face_count() as f64);
            }
        }
    }

    fn no_presubdivision() -> SubdivisionParams {
        SubdivisionParams {
            area_factor: 0.0,
            ..Default::default()
        }
    }

    /// Checks the hierarchy's invariants and returns each level's mean edge length.
    fn check_hierarchy(h: &Sqrt2Hierarchy, input: &Mesh, scale: f32) -> Vec<f32> {
        let levels = h.levels();
        assert_eq!(h.level_face_start.len(), levels + 1);
        assert_eq!(h.parent_start.len(), h.positions.len() + 1);
        assert_eq!(
            *h.level_vertices.last().unwrap() as usize,
            h.positions.len()
        );
        assert!(h.level_vertices.windows(2).all(|w| w[0] < w[1]));
        let input_poly = PolyMesh::from_mesh(input);
        let mut edges = Vec::new();
        for l in 0..levels {
            let m = h.level(l);
            assert_eq!(m.positions, h.positions[..h.level_vertices[l] as usize]);
            assert!(m.is_consistently_oriented(), "level {l}");
            assert_eq!(m.euler_characteristic(), input_poly.euler_characteristic());
            assert_eq!(m.boundary_edge_count(), input_poly.boundary_edge_count());
            if l > 0 {
                let prev = h.level(l - 1);
                assert_eq!(m.vertex_count(), prev.vertex_count() + prev.face_count());
                assert_eq!(
                    m,
                    sqrt2_step(&prev, None, false).0,
                    "level {l} is a full step"
                );
            }
            edges.push(m.mean_edge_length());
        }
        assert_eq!(h.input_vertices as usize, input.positions.len());
        for v in 0..h.positions.len() {
            if v < input.positions.len() {
                assert!(h.parents(v).is_empty());
                assert_eq!(h.positions[v], input.positions[v]);
            } else {
                let parents = h.parents(v);
                assert!(parents.len() >= 3 && parents.iter().all(|&p| (p as usize) < v));
                assert_eq!(h.positions[v], mean_of(&h.positions, parents), "vertex {v}");
            }
        }
        let last = edges.len() - 1;
        assert!(
            scale * edges[last] <= 1.0,
            "finest level spans at most a texel"
        );
        if last > 0 {
            assert!(scale * edges[last - 1] > 1.0, "the level before spans more");
        }
        edges
    }

    #[test]
    fn hierarchy_refines_until_an_edge_spans_a_texel() {
        let mesh = octahedron();
        let h = build_hierarchy(&mesh, 10.0, &no_presubdivision()).unwrap();
        let edges = check_hierarchy(&h, &mesh, 10.0);
        assert!(h.levels() >= 6, "{} levels", h.levels());
        assert_eq!(h.level(0), PolyMesh::from_mesh(&mesh));
        // Edges shrink by about √2 per step.
        for w in edges[1..].windows(2) {
            assert!((0.6..0.8).contains(&(w[1] / w[0])), "{edges:?}");
        }
    }

    #[test]
    fn hierarchy_starts_from_the_presubdivided_mesh() {
        let mesh = tall_octahedron();
        let p = SubdivisionParams::default();
        let h = build_hierarchy(&mesh, 6.0, &p).unwrap();
        check_hierarchy(&h, &mesh, 6.0);
        // The rounds kept are those that lowered the spread by at least adaptive_min_gain.
        let (_, _, spread) = adaptive_presubdivision(&PolyMesh::from_mesh(&mesh), 1.5, 8);
        let gain = p.adaptive_min_gain;
        let kept = (1..spread.len())
            .take_while(|&i| spread[i] <= (1.0 - gain) * spread[i - 1])
            .count();
        assert!(kept >= 1 && kept < spread.len() - 1, "{spread:?}");
        let (pre, parents, _) =
            adaptive_presubdivision(&PolyMesh::from_mesh(&mesh), 1.5, kept as u32);
        assert_eq!(h.level(0), pre);
        assert!(h.level_vertices[0] > 6);
        for (i, corners) in parents.iter().enumerate() {
            assert_eq!(h.parents(6 + i), &corners[..]);
        }
    }

    #[test]
    fn without_the_early_stop_pre_subdivision_runs_the_paper_s_fixed_rounds() {
        let mesh = tall_octahedron();
        let input = PolyMesh::from_mesh(&mesh);
        let rounds = 8;
        let (all, _, spread) = adaptive_presubdivision(&input, 1.5, rounds);
        // Four rounds find a face over the threshold, and the second evens the areas out by
        // under 10 %: the default stops after the first.
        assert_eq!(spread.len(), 5, "{spread:?}");
        assert!(spread[2] > 0.9 * spread[1], "{spread:?}");
        let default = build_hierarchy(&mesh, 6.0, &SubdivisionParams::default()).unwrap();
        assert!(default.level(0).vertex_count() < all.vertex_count());
        let fixed = SubdivisionParams {
            adaptive_min_gain: 0.0,
            adaptive_rounds: rounds,
            ..Default::default()
        };
        // At 6 texels per unit the early stop would also end the rounds once edges span a
        // texel; the fixed rounds go on.
        let h = build_hierarchy(&mesh, 6.0, &fixed).unwrap();
        assert_eq!(h.level(0), all);
        // A gain of 1 keeps no round (none removes the whole spread).
        let none = SubdivisionParams {
            adaptive_min_gain: 1.0,
            ..Default::default()
        };
        let h = build_hierarchy(&mesh, 6.0, &none).unwrap();
        assert_eq!(h.level(0), input);
        let bad = SubdivisionParams {
            adaptive_min_gain: 1.5,
            ..Default::default()
        };
        let e = build_hierarchy(&mesh, 6.0, &bad).unwrap_err();
        assert!(
            e.to_string().contains("parameterize.adaptive_min_gain"),
            "{e}"
        );
    }

    #[test]
    fn a_mesh_finer_than_the_texture_is_one_level() {
        // The octahedron's edges are √2 long: at 0.5 texels per unit each spans 0.7 texels.
        let mesh = octahedron();
        let h = build_hierarchy(&mesh, 0.5, &SubdivisionParams::default()).unwrap();
        assert_eq!(h.levels(), 1);
        assert_eq!(h.level(0), PolyMesh::from_mesh(&mesh));
        assert!(h.parent_vertices.is_empty());
        check_hierarchy(&h, &mesh, 0.5);
    }

    #[test]
    fn too_fine_a_scale_reports_the_largest_scale_that_fits() {
        let mesh = torus(6, 4, 0.5);
        let p = SubdivisionParams {
            max_vertices: 3000,
            ..no_presubdivision()
        };
        let err = build_hierarchy(&mesh, 1000.0, &p).unwrap_err();
        let SubdivisionError::TooFine {
            vertices,
            scale_that_fits,
            ..
        } = err.clone()
        else {
            panic!("expected TooFine, got {err}");
        };
        let message = err.to_string();
        assert!(
            message.starts_with("parameterize.scale = 1000 would make about "),
            "{message}"
        );
        assert!(
            message.contains("(budget 3000, parameterize.max_vertices); scale ≤ "),
            "{message}"
        );
        assert!(vertices > 3000);
        // At that scale the hierarchy is built within the budget, and it ends at the last
        // level the budget allows: one more step would exceed it.
        let h = build_hierarchy(&mesh, scale_that_fits, &p).unwrap();
        check_hierarchy(&h, &mesh, scale_that_fits);
        let finest = h.level(h.levels() - 1);
        assert!(finest.vertex_count() as u64 <= 3000);
        assert!((finest.vertex_count() + finest.face_count()) as u64 > 3000);
        assert!(vertices >= (finest.vertex_count() + finest.face_count()) as u64);
        // The next scale up does not fit.
        let above = build_hierarchy(&mesh, scale_that_fits.next_up(), &p);
        assert!(
            matches!(above, Err(SubdivisionError::TooFine { .. })),
            "{above:?}"
        );
        // The vertex count is a fair estimate of the finest level without a budget.
        let scale = 24.0;
        let Err(SubdivisionError::TooFine { vertices, .. }) = build_hierarchy(&mesh, scale, &p)
        else {
            panic!("expected TooFine");
        };
        let unbounded = SubdivisionParams {
            max_vertices: MAX_VERTICES_LIMIT,
            ..p.clone()
        };
        let big = build_hierarchy(&mesh, scale, &unbounded).unwrap();
        let actual = *big.level_vertices.last().unwrap() as f64;
        assert!(actual > 3000.0);
        assert!(
            (0.5..2.0).contains(&(vertices as f64 / actual)),
            "{vertices} vs {actual}"
        );
    }

    #[test]
    fn budget_below_the_presubdivided_mesh_is_reported() {
        let p = SubdivisionParams {
            max_vertices: 8,
            ..Default::default()
        };
        let err = build_hierarchy(&tall_octahedron(), 1.0, &p).unwrap_err();
        assert!(
            matches!(
                err,
                SubdivisionError::TooLarge {
                    max_vertices: 8,
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("parameterize.max_vertices"));
    }

    #[test]
    fn smooth_hierarchy_has_the_same_topology_and_moved_vertices() {
        let mesh = torus(6, 4, 0.5);
        let plain = build_hierarchy(&mesh, 8.0, &no_presubdivision()).unwrap();
        let p = SubdivisionParams {
            smooth: true,
            ..no_presubdivision()
        };
        let smooth = build_hierarchy(&mesh, 8.0, &p).unwrap();
        // Smoothing changes edge lengths, so possibly where the levels stop, not the levels.
        let common = plain.levels().min(smooth.levels());
        assert!(common >= 3);
        for l in 0..common {
            let (a, b) = (plain.level(l), smooth.level(l));
            assert!(a.face_start == b.face_start && a.face_vertices == b.face_vertices);
        }
        let parents = plain.parent_start[*plain.level_vertices.get(common - 1).unwrap() as usize];
        assert!(
            plain.parent_vertices[..parents as usize] == smooth.parent_vertices[..parents as usize]
        );
        let moved = (0..mesh.positions.len())
            .filter(|&v| smooth.positions[v] != plain.positions[v])
            .count();
        assert_eq!(
            moved,
            mesh.positions.len(),
            "a closed mesh has no fixed vertex"
        );
    }

    #[test]
    fn building_twice_gives_identical_hierarchies() {
        for smooth in [false, true] {
            let p = SubdivisionParams {
                smooth,
                ..Default::default()
            };
            let a = build_hierarchy(&tall_octahedron(), 12.0, &p).unwrap();
            let b = build_hierarchy(&tall_octahedron(), 12.0, &p).unwrap();
            assert!(a.levels() > 3);
            assert_eq!(a, b);
        }
    }

    #[test]
    fn bad_inputs_are_errors_that_name_their_key() {
        let p = SubdivisionParams::default();
        let empty = Mesh::new(vec![Vec3::ZERO; 3], vec![]);
        assert_eq!(
            build_hierarchy(&empty, 1.0, &p),
            Err(SubdivisionError::NoFaces)
        );
        let mut nan = octahedron();
        nan.positions[3].y = f32::NAN;
        let err = build_hierarchy(&nan, 1.0, &p).unwrap_err();
        assert!(
            matches!(err, SubdivisionError::NonFinite { vertex: 3, .. }),
            "{err}"
        );
        assert!(err.to_string().starts_with("inputs.mesh: vertex 3"));
        for scale in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            let err = build_hierarchy(&octahedron(), scale, &p).unwrap_err();
            assert!(
                err.to_string().starts_with("parameterize.scale must be"),
                "{err}"
            );
        }
        let bad = Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 3]]);
        let err = build_hierarchy(&bad, 1.0, &p).unwrap_err();
        assert_eq!(
            err.to_string(),
            "inputs.mesh: triangle 0 uses vertex 3, but the mesh has 3 vertices"
        );
        let repeated = Mesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            vec![[0, 1, 2], [1, 1, 2]],
        );
        let err = build_hierarchy(&repeated, 1.0, &p).unwrap_err();
        assert!(
            matches!(err, SubdivisionError::BadTriangle { face: 1, .. }),
            "{err}"
        );

        let with = |f: fn(&mut SubdivisionParams)| {
            let mut p = SubdivisionParams::default();
            f(&mut p);
            p.validate()
        };
        assert!(with(|_| {}).is_ok());
        assert!(with(|p| p.area_factor = 0.0).is_ok());
        assert!(with(|p| p.area_factor = 100.0).is_ok());
        assert!(with(|p| p.adaptive_rounds = 0).is_ok());
        let err = with(|p| p.area_factor = 0.5).unwrap_err();
        assert_eq!(
            err.to_string(),
            "parameterize.area_factor must be 0 (no adaptive pre-subdivision) or in 1..=100, got 0.5"
        );
        assert!(with(|p| p.area_factor = f32::NAN).is_err());
        assert!(with(|p| p.area_factor = -1.0).is_err());
        assert_eq!(
            with(|p| p.adaptive_rounds = 65).unwrap_err().to_string(),
            "parameterize.adaptive_rounds must be in 0..=64, got 65"
        );
        assert_eq!(
            with(|p| p.max_vertices = 0).unwrap_err().key(),
            "parameterize.max_vertices"
        );
        let invalid = SubdivisionParams {
            adaptive_rounds: 100,
            ..Default::default()
        };
        let err = build_hierarchy(&octahedron(), 1.0, &invalid).unwrap_err();
        assert!(matches!(err, SubdivisionError::Params(_)));
    }

    #[test]
    fn params_read_from_toml_with_defaults_and_reject_unknown_keys() {
        let p: SubdivisionParams = toml::from_str("area_factor = 2.0\nsmooth = true").unwrap();
        assert_eq!(
            p,
            SubdivisionParams {
                area_factor: 2.0,
                smooth: true,
                ..Default::default()
            }
        );
        let d = SubdivisionParams::default();
        assert_eq!(
            (d.area_factor, d.adaptive_rounds, d.smooth, d.max_vertices),
            (1.5, 8, false, 4_000_000)
        );
        assert!(toml::from_str::<SubdivisionParams>("area_factr = 2.0").is_err());
    }
}
