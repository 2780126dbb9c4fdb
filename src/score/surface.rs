//! Scoring the methods that colour vertices, graph matching (Bangay & Morkel) and
//! feature-aligned texturing (Xu et al.), by resampling their colours into the exemplar's
//! frame along the field each synthesis itself reads the surface with.
//!
//! Graph matching makes one colour per vertex of the finest √2-subdivision level (the paper
//! leaves texture maps to other work, §3.5; texsyn bakes one from the copied addresses). Its
//! synthesis reads the surface through one texture-space step per edge
//! (`Level::step` in stages/synthesize/graph_matching.rs): the edge projected onto the
//! vertex's (right, −up) frame of the sweep field, kept at its length, times `scale` texels
//! per unit. That step, in the centre's frame carried outward with the surface
//! ([`TransportedFrame`]) and summed outward from 64 seeded vertices over the finest level's
//! triangulated edges, unfolds discs of the surface into exemplar texels
//! ([`super::charts::unfolded_discs`]); their triangles are filled by interpolating the
//! vertex colours, and, for a second item, with what the baked atlas holds
//! ([`finest_lookup`]); the discs are scored against the exemplar. So the picture is the
//! texture as the method lays it out, at one texel per exemplar texel.
//!
//! Feature-aligned texturing's texture optimization (§5) reads a vertex's neighbourhood in
//! the frame (u = the field on the tangent plane, n × u), turned by the texture's principal
//! angle onto exemplar pixel axes, at `parameterize.scale` texels per unit; a disc is
//! unfolded in its centre's frame, carried outward with the surface ([`TransportedFrame`]),
//! as a patch is read in its sample's one frame. Its `textured_atlas.png` is not used: it
//! lays each input triangle with its longest edge horizontal, so its patches are rotated
//! against the exemplar's. Whether the texture's lines follow the field is measured on the
//! surface itself ([`super::alignment::surface_alignment`]), not on the discs.
//!
//! Each atlas item also reports its `floor`: the exemplar laid out verbatim in the same discs
//! and read as the atlas reads ([`DiscFloor`]), what a flawless copy read this way scores.
//!
//! Limits: colours between vertices are interpolated, so where edges are longer than a
//! texel the discs are smoother than the synthesis meant (the gradient ratio falls with the
//! edge length); near a singularity of the field, and where a disc wider than a thin part (a
//! leg a few texels round) wraps around it, the unfolding tears, folds or overlaps itself,
//! and those texels are left out of the mask ([`super::charts::unfolded_discs_with`]): a
//! small shape scores fewer patches, from its flatter places.

use super::charts::{EdgeOffsets, unfolded_discs_with};
use super::{Item, Run, ScoreFailure};
use crate::artifact::feature_aligned::OrientedField;
use crate::geom::Mesh;
use crate::geom::edge_refine::Refined;
use crate::geom::poly_mesh::PolyMesh;
use crate::image::Image;
use crate::pipeline::Handle;
use crate::stages::analyse_exemplar::texture_feature_lines::TextureFeatures;
use crate::stages::field::feature_field::carry_field;
use crate::stages::field::sweep_field::SweepField;
use crate::stages::parameterize::sqrt2_subdivision::{Sqrt2Hierarchy, area_spread};
use crate::stages::reconstruct::feature_aligned_export::{ExemplarLookup, ExemplarSampling};
use crate::stages::reconstruct::finest_level_bake::finest_lookup;
use crate::stages::synthesize::graph_matching::{GraphMatching, texture_frame};
use crate::stages::synthesize::texture_optimization::SurfaceSynthesis;
use glam::{Vec2, Vec3};
use std::collections::HashMap;
use texsyn_core::math::PureMath;

/// The nodes of a graph-matching run that its score reads.
#[derive(Clone, Copy)]
pub struct GraphMatchingNodes {
    pub mesh: Handle<Mesh>,
    pub parameterize: Handle<Sqrt2Hierarchy>,
    pub field: Handle<SweepField>,
    pub synthesize: Handle<GraphMatching>,
    pub exemplar: Handle<Image>,
    /// `parameterize.scale`: exemplar texels per object unit.
    pub scale: f32,
    /// The atlas the run bakes, so the score sees what it holds; `None`: no atlas
    /// (`reconstruct.atlas_size = 0`).
    pub atlas: Option<BakedAtlas>,
}

/// Graph matching's baked atlas as the run asks for it.
#[derive(Clone, Copy)]
pub struct BakedAtlas {
    /// `reconstruct.atlas_size`: the export falls back to vertex colours when the input
    /// mesh's triangles do not fit it, and then there is no baked texture to score.
    pub size: u32,
    /// `reconstruct.lookup`.
    pub sampling: ExemplarSampling,
}

impl super::Planned for GraphMatchingNodes {
    fn score(
        &self,
        run: &Run<'_>,
        not_scored: &mut Vec<String>,
    ) -> Result<Vec<Item>, ScoreFailure> {
        graph_matching(run, self, not_scored)
    }
}

/// Graph matching at `nodes.scale` texels per unit: the finest level's vertex colours and,
/// when the run bakes an atlas, the texture that atlas holds (the exemplar read inside each
/// copied patch, each corner's patch continued and blended across seams), through the same
/// discs.
/// When the atlas cannot be built (the export wrote vertex colours instead), the reason goes
/// to `not_scored`.
pub fn graph_matching(
    run: &Run,
    nodes: &GraphMatchingNodes,
    not_scored: &mut Vec<String>,
) -> Result<Vec<Item>, ScoreFailure> {
    let scale = nodes.scale;
    let h = run.view(nodes.parameterize)?;
    let field = run.view(nodes.field)?;
    let out = run.view(nodes.synthesize)?;
    let ex = run.view(nodes.exemplar)?;
    let level = h.level(h.levels() - 1);
    let normals = level.vertex_normals();
    let mesh = level.to_triangles();
    let n = mesh.positions.len();
    if out.colours.len() != n || field.orientation.len() < n {
        return Err(ScoreFailure::new(
            "internal error: colours, field and hierarchy disagree on the vertex count",
        ));
    }
    // The synthesis's frame per vertex: "up" is the field projected on the tangent plane,
    // and an edge maps to (right, −up) texels at its own length; a disc carries its centre's.
    let axes: Vec<(Vec3, Vec3)> = (normals.iter().zip(&field.orientation[..n]))
        .map(|(&nrm, &o)| {
            let (up, right) = texture_frame(nrm, o);
            (right, -up)
        })
        .collect();
    let unfolding = &TransportedFrame {
        positions: &mesh.positions,
        normals: &normals,
        axes: &axes,
        scale,
        turn: (1.0, 0.0),
    };
    let mut item = Item::new(
        format!("the finest level's vertex colours, {DISCS_NOTE}"),
        "inputs.exemplar",
    );
    item.extra.insert(
        "texels_per_edge".into(),
        serde_json::json!(mesh.mean_edge_length() * scale),
    );
    // §3.2.2, Fig. 6: the face areas' spread before and after adaptive pre-subdivision (the
    // hierarchy's coarsest level), so a sweep over parameterize.area_factor tabulates it.
    let input_mesh = run.view(nodes.mesh)?;
    let input = PolyMesh::from_mesh(&input_mesh);
    let coarse = h.level(0);
    item.extra.insert(
        "area_spread_input".into(),
        serde_json::json!(area_spread(&input)),
    );
    item.extra.insert(
        "area_spread".into(),
        serde_json::json!(area_spread(&coarse)),
    );
    item.extra.insert(
        "coarse_faces".into(),
        serde_json::json!(coarse.face_count()),
    );
    let atlas = nodes
        .atlas
        .filter(|a| match atlas_written(&input_mesh, a.size) {
            Ok(()) => true,
            Err(why) => {
                not_scored.push(format!(
                    "the baked atlas: {why}; the run wrote vertex colours instead"
                ));
                false
            }
        });
    let baked = atlas.map(|a| {
        let sampling = a.sampling;
        let mut baked = Item::new(
            format!("the baked atlas (the exemplar read inside each copied patch), {DISCS_NOTE}"),
            "inputs.exemplar",
        );
        baked.extra = item.extra.clone();
        (baked, sampling)
    });
    score_vertex_colours(run, &mut item, &mesh, &out.colours, unfolding, ex)?;
    let mut items = vec![item];
    if let Some((mut baked, sampling)) = baked {
        if out.sources.len() != n {
            return Err(ScoreFailure::new(
                "internal error: sources and hierarchy disagree on the vertex count",
            ));
        }
        // The synthesis's own frames, as the atlas reads them (a frame fitted to the
        // addresses needs one-patch triangles around its vertex, which graph matching's
        // small patches often leave none of).
        let lookup = finest_lookup(
            &mesh,
            &normals,
            &field.orientation[..n],
            scale,
            &out.sources,
            ex,
            sampling,
        );
        baked.extra.insert(
            "looked_up_share".into(),
            serde_json::json!(lookup.looked_up_share()),
        );
        let colours = &out.colours;
        let shade = |f: usize, b: Vec3| {
            let vertex = |v: u32| Vec3::from(colours[v as usize]);
            let c = lookup.texture_colour(f, mesh.triangles[f], b.to_array(), vertex);
            [c.x, c.y, c.z, 1.0]
        };
        score_surface(
            run,
            &mut baked,
            &mesh,
            shade,
            unfolding,
            ex,
            Some(&mut DiscFloor::new(sampling)),
        )?;
        items.push(baked);
    }
    Ok(items)
}

/// The nodes of a feature-aligned run that its score reads: `synthesize` holds the aligned
/// result and, when the run compares, the unaligned one's node besides.
#[derive(Clone)]
pub struct FeatureAlignedNodes {
    pub parameterize: Handle<Refined>,
    pub field: Handle<OrientedField>,
    pub analyse_exemplar: Handle<TextureFeatures>,
    pub exemplar: Handle<Image>,
    /// Each synthesis scored, with what it is.
    pub synthesize: Vec<(Handle<SurfaceSynthesis>, &'static str)>,
    /// `parameterize.scale`: exemplar texels per object unit.
    pub scale: f32,
    /// `reconstruct.lookup`: how the atlas reads the exemplar, so the score sees what it holds.
    pub lookup: ExemplarSampling,
    /// The input mesh and `reconstruct.atlas_size`: without an atlas (size 0, or triangles
    /// the atlas cannot hold) the run writes the refined mesh's vertex colours, and those are
    /// what is scored.
    pub mesh: Handle<Mesh>,
    pub atlas_size: u32,
}

impl super::Planned for FeatureAlignedNodes {
    fn score(
        &self,
        run: &Run<'_>,
        not_scored: &mut Vec<String>,
    ) -> Result<Vec<Item>, ScoreFailure> {
        feature_aligned(run, self, not_scored)
    }
}

/// Feature-aligned texturing (Xu et al.): the refined mesh's texture as textured.glb's atlas
/// holds it (the exemplar looked up inside each copied patch), unfolded with the
/// frame texture optimization matches in (§5: `u` the field projected on the tangent plane,
/// `v = n × u`, turned by the texture's principal angle onto exemplar pixel axes, 1 /
/// `parameterize.scale` object units per texel), for the aligned result and, with `compare`,
/// the unaligned one.
///
/// The field's vectors are carried from the input mesh onto the refined one, as synthesis
/// carried them.
///
/// Without an atlas the refined mesh's vertex colours are scored, interpolated across its
/// triangles, as textured.glb's `COLOR_0` shows them; why goes to `not_scored`.
pub fn feature_aligned(
    run: &Run,
    nodes: &FeatureAlignedNodes,
    not_scored: &mut Vec<String>,
) -> Result<Vec<Item>, ScoreFailure> {
    let scale = nodes.scale;
    let baked = atlas_written(&run.view(nodes.mesh)?, nodes.atlas_size);
    if let Err(why) = &baked {
        not_scored.push(format!(
            "the atlas: {why}; the run wrote the refined mesh's vertex colours, scored instead"
        ));
    }
    let baked = baked.is_ok();
    let refined = run.view(nodes.parameterize)?;
    let field = run.view(nodes.field)?;
    let tf = run.view(nodes.analyse_exemplar)?;
    let ex = run.view(nodes.exemplar)?;
    let vectors = carry_field(&refined, &field.field.vectors);
    let vectors = vectors.map_err(|e| ScoreFailure::new(e.to_string()))?;
    let mesh = &refined.mesh;
    let normals: Vec<Vec3> = mesh.vertex_normals().to_vec();
    let axes = optimization_axes(&normals, &vectors);
    let (cos, sin) = (tf.principal_angle.cos_pure(), tf.principal_angle.sin_pure());
    let unfolding = TransportedFrame {
        positions: &mesh.positions,
        normals: &normals,
        axes: &axes,
        scale,
        turn: (cos, sin),
    };
    let mut items = Vec::new();
    let mut floor = DiscFloor::new(nodes.lookup);
    for &(node, what) in &nodes.synthesize {
        let out = run.view(node)?;
        if out.colours.len() != mesh.positions.len() {
            return Err(ScoreFailure::new(
                "internal error: colours and refined mesh disagree on the vertex count",
            ));
        }
        // What textured.glb's atlas holds: the exemplar looked up inside each patch, each
        // corner's patch continued and blended across seams.
        let lookup = ExemplarLookup::new(&refined.mesh, &out.source, ex, nodes.lookup)
            .with_fitted_frames(&refined.mesh);
        let colours = &out.colours;
        let shade = |f: usize, b: Vec3| {
            let vertex = |v: u32| Vec3::from(colours[v as usize]);
            let c = if baked {
                lookup.texture_colour(f, mesh.triangles[f], b.to_array(), vertex)
            } else {
                let t = mesh.triangles[f];
                (0..3).map(|k| b[k] * vertex(t[k])).sum()
            };
            [c.x, c.y, c.z, 1.0]
        };
        let holds = if baked {
            "as the atlas holds it"
        } else {
            "as the vertex colours hold it"
        };
        let mut item = Item::new(format!("{what} {holds}, {DISCS_NOTE}"), "inputs.exemplar");
        // Where the principal line should run: along the field (texture optimization lays the
        // exemplar's `principal_angle` along it), measured on the surface; the exemplar's own
        // measure at its principal angle is the floor.
        let luma: Vec<f32> = colours
            .iter()
            .map(|c| 0.299 * c[0] + 0.587 * c[1] + 0.114 * c[2])
            .collect();
        let radius = super::alignment::WINDOW as f32 / 2.0 / scale;
        let on_surface = super::alignment::surface_alignment(mesh, &luma, &vectors, radius);
        let exemplar = super::alignment::alignment(ex, None, tf.principal_angle);
        item.extra
            .insert("alignment_deg".into(), degrees_or_null(on_surface));
        item.extra
            .insert("exemplar_alignment_deg".into(), degrees_or_null(exemplar));
        let floor = baked.then_some(&mut floor);
        score_surface(run, &mut item, mesh, shade, &unfolding, ex, floor)?;
        items.push(item);
    }
    Ok(items)
}

/// Whether an export writes an atlas of `size` for `input`, as both exports decide it: not at
/// size 0, nor when the input's triangles do not fit (the export then writes vertex colours).
/// The error says why, naming the key.
fn atlas_written(input: &Mesh, size: u32) -> Result<(), String> {
    match size {
        0 => Err("reconstruct.atlas_size = 0".into()),
        size => crate::render::build_atlas(input, size)
            .map(drop)
            .map_err(|e| format!("reconstruct.atlas_size: {e}")),
    }
}

const DISCS_NOTE: &str = "discs unfolded along the field";

/// Per vertex, texture optimization's texel axes before the principal angle's turn: `u`, the
/// field on the tangent plane, and `n × u` (= −right of [`frames`]).
fn optimization_axes(normals: &[Vec3], field: &[Vec3]) -> Vec<(Vec3, Vec3)> {
    (frames(normals, field).into_iter())
        .map(|(u, right)| (u, -right))
        .collect()
}

/// Per vertex, (up, right): the field projected on the tangent plane (any tangent where it
/// vanishes) and `up × n`.
fn frames(normals: &[Vec3], field: &[Vec3]) -> Vec<(Vec3, Vec3)> {
    normals
        .iter()
        .zip(field)
        .map(|(&nrm, &o)| {
            let nrm = nrm.try_normalize().unwrap_or(Vec3::Z);
            let t = (o - o.dot(nrm) * nrm)
                .try_normalize()
                .unwrap_or_else(|| nrm.any_orthonormal_vector());
            (t, t.cross(nrm))
        })
        .collect()
}

/// Discs unfolded in one frame: the centre's synthesis frame (feature-aligned: `u` the field
/// on the tangent plane and `n × u`, turned by the principal angle onto exemplar pixel axes,
/// as texture optimization reads a patch; graph matching: the vertex's (right, −up)),
/// carried outward along the walk by the rotation between neighbouring normals (a discrete
/// exponential map), each edge at its own length times `scale`. Where the field turns inside
/// a disc, the texture turns with it in the disc, as it does on the surface. Stepping every
/// edge in its own vertex's field frame instead does not close around loops where the field
/// turns (a few degrees per texel on the elephant's fields): neighbours reached along
/// different paths land far apart and the disc shows a scramble of shards, stretched
/// triangles at every angle, that the surface does not.
struct TransportedFrame<'a> {
    positions: &'a [Vec3],
    normals: &'a [Vec3],
    /// Per vertex, the tangent directions the disc's texel x and y axes take there; only the
    /// centre's are read, the rest of the disc carries them.
    axes: &'a [(Vec3, Vec3)],
    scale: f32,
    /// cos, sin of the principal angle.
    turn: (f32, f32),
}

impl TransportedFrame<'_> {
    /// The texel length of the edge from `from` to `to`, which every step keeps.
    fn length(&self, from: usize, to: usize) -> f32 {
        self.positions[from].distance(self.positions[to]) * self.scale
    }

    /// The step for [`super::charts::unfolded_discs_with`]: `(centre, from, to)` to texels.
    fn step(&self) -> impl FnMut(usize, usize, usize) -> Vec2 + '_ {
        // The centre's axes, carried to every vertex the current disc reached.
        let mut carried: HashMap<usize, (Vec3, Vec3)> = HashMap::new();
        let mut disc = usize::MAX;
        move |centre, from, to| {
            if centre != disc {
                disc = centre;
                carried.clear();
                carried.insert(centre, self.axes[centre]);
            }
            let (u, v) = carried[&from];
            let turn = glam::Quat::from_rotation_arc(
                unit_or_z(self.normals[from]),
                unit_or_z(self.normals[to]),
            );
            carried.insert(to, (turn * u, turn * v));
            let d = self.positions[to] - self.positions[from];
            let o = Vec2::new(d.dot(u), d.dot(v));
            let (cos, sin) = self.turn;
            let o = Vec2::new(o.x * cos - o.y * sin, o.x * sin + o.y * cos);
            at_length(o, d.length() * self.scale)
        }
    }
}

fn unit_or_z(n: Vec3) -> Vec3 {
    n.try_normalize().unwrap_or(Vec3::Z)
}

/// An alignment median in degrees to one decimal, or null when no window counted.
fn degrees_or_null(a: Option<super::alignment::Alignment>) -> serde_json::Value {
    a.map(|a| serde_json::json!((a.median_degrees * 10.0).round() / 10.0))
        .unwrap_or(serde_json::Value::Null)
}

/// `o` scaled to `len` (zero stays zero).
fn at_length(o: Vec2, len: f32) -> Vec2 {
    let l = o.length();
    if l > 0.0 { o * (len / l) } else { Vec2::ZERO }
}

/// Unfolds discs of `mesh` in `unfolding`, fills their triangles with the vertex `colours`
/// interpolated, and scores them into `item`.
fn score_vertex_colours(
    run: &Run,
    item: &mut Item,
    mesh: &crate::geom::Mesh,
    colours: &[[f32; 3]],
    unfolding: &TransportedFrame,
    ex: crate::image::ImageView,
) -> Result<(), ScoreFailure> {
    let shade = |f: usize, b: Vec3| {
        let t = mesh.triangles[f];
        let mut c = [0.0f32, 0.0, 0.0, 1.0];
        for (k, w) in b.to_array().into_iter().enumerate() {
            for ch in 0..3 {
                c[ch] += w * colours[t[k] as usize][ch];
            }
        }
        c
    };
    score_surface(run, item, mesh, shade, unfolding, ex, None)
}

/// Unfolds discs of `mesh` in `unfolding`, fills their triangles with `shade(triangle,
/// barycentrics)` and scores them into `item`; with `floor`, also the floor of the atlas's
/// read ([`DiscFloor`]).
fn score_surface(
    run: &Run,
    item: &mut Item,
    mesh: &crate::geom::Mesh,
    shade: impl Fn(usize, Vec3) -> [f32; 4] + Sync,
    unfolding: &TransportedFrame,
    ex: crate::image::ImageView,
    floor: Option<&mut DiscFloor>,
) -> Result<(), ScoreFailure> {
    let adjacency = mesh.adjacency();
    let neighbors = &adjacency.neighbors;
    let edges = EdgeOffsets {
        adj_offsets: &adjacency.offsets,
        neighbors,
        edge_offsets: &[],
    };
    let to = |j: usize| neighbors[j] as usize;
    let mut step = unfolding.step();
    let step = |centre, from, j| step(centre, from, to(j));
    let length = |from, j| unfolding.length(from, to(j));
    let charts = unfolded_discs_with(
        &mesh.triangles,
        &edges,
        run.params.seed,
        step,
        length,
        shade,
    );
    item.extra
        .insert("discs".into(), serde_json::json!(charts.discs));
    item.extra.insert(
        "cut_share".into(),
        serde_json::json!(super::round3(charts.cut_share)),
    );
    if let Some(floor) = floor {
        floor.add_to(run, item, &charts, ex)?;
    }
    run.score_into(item, charts.image.view(), Some(&charts.mask), ex)
}

/// The discs' floor (ratio and gradient ratio): the exemplar laid out verbatim in every
/// disc, one seeded place per disc, and read with `read` between texels as the atlas reads
/// its addresses ([`super::charts::verbatim_discs`]), scored over the same mask. It is what
/// the read alone costs a flawless layout: a ratio of 0 for nearest reads, and for bicubic
/// and bilinear reads the blur of reading a noisy exemplar up to half a texel off, which the
/// ratio counts as a distance (brick: 0.43 and 0.48). Not a lower bound: a blurrier texture,
/// or a layout that happens to sit on whole texels, can score a lower ratio.
///
/// Items scored on the same discs (a feature-aligned run's aligned and unaligned results:
/// one mesh, one unfolding, one seed, so one mask) share it: it is scored once.
struct DiscFloor {
    read: ExemplarSampling,
    /// What the first item got: its `floor` extra (`None`: not computed) and its note.
    found: Option<(Option<serde_json::Value>, String)>,
}

impl DiscFloor {
    fn new(read: ExemplarSampling) -> DiscFloor {
        DiscFloor { read, found: None }
    }

    /// Puts the floor of `charts` into `item` (`extra.floor` and a note), scoring it the
    /// first time.
    fn add_to(
        &mut self,
        run: &Run,
        item: &mut Item,
        charts: &super::charts::Charts,
        ex: crate::image::ImageView,
    ) -> Result<(), ScoreFailure> {
        if self.found.is_none() {
            self.found = Some(self.score(run, &item.output, charts, ex)?);
        }
        let (floor, note) = self.found.clone().expect("scored above");
        if let Some(floor) = floor {
            item.extra.insert("floor".into(), floor);
        }
        item.notes.push(note);
        Ok(())
    }

    fn score(
        &self,
        run: &Run,
        output: &str,
        charts: &super::charts::Charts,
        ex: crate::image::ImageView,
    ) -> Result<(Option<serde_json::Value>, String), ScoreFailure> {
        let (size, seed, read) = ((ex.width, ex.height), run.params.seed, self.read);
        let Some(floor) = super::charts::verbatim_discs(charts, size, seed, |at| read.read(ex, at))
        else {
            let side = super::charts::VERBATIM_SIDE;
            let why = format!("floor not computed: a disc needs {side}×{side} exemplar texels");
            return Ok((None, why));
        };
        // Named after the item, so TEXSYN_SCORE_DUMP writes it beside the item's picture.
        let mut scored = Item::new(format!("floor of {output}"), "inputs.exemplar");
        run.score_into(&mut scored, floor.view(), Some(&charts.mask), ex)?;
        let Some(f) = scored.score else {
            return Ok((
                None,
                format!("floor not scored: {}", scored.notes.join("; ")),
            ));
        };
        let floor = serde_json::json!({
            "ratio": super::round3(f.ratio),
            "gradient_ratio": super::round3(f.gradient_ratio),
        });
        let note = "floor: the ratio and gradient ratio of the exemplar laid out verbatim in \
                    the same discs and read as the atlas reads it (reconstruct.lookup): what \
                    the read between texels costs a flawless layout. Not a lower bound: a \
                    blurrier texture can score a lower ratio";
        Ok((Some(floor), note.into()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_disc_in_one_transported_frame_is_the_plane_itself_however_the_field_turns() {
        // A flat 11×11 sheet whose field turns 0.3 rad per unit along x: unfolded from vertex
        // 0 (field along x there) at 2 texels per unit, every vertex must land at twice its
        // offset from the centre, whichever path reaches it. Stepping each edge in its own
        // vertex's field frame puts vertex 2 (reached through vertex 1, turned 0.3 rad) off.
        let mesh = crate::geom::primitives::grid(11, 1.0);
        let normals = mesh.vertex_normals().to_vec();
        let field: Vec<Vec3> = (mesh.positions.iter())
            .map(|p| Vec3::new((0.3 * p.x).cos_pure(), (0.3 * p.x).sin_pure(), 0.0))
            .collect();
        let axes = optimization_axes(&normals, &field);
        let unfolding = TransportedFrame {
            positions: &mesh.positions,
            normals: &normals,
            axes: &axes,
            scale: 2.0,
            turn: (1.0, 0.0),
        };
        for path in [[0usize, 1, 2, 13, 24], [0, 11, 22, 23, 24]] {
            let mut step = unfolding.step();
            let mut at = Vec2::ZERO;
            for w in path.windows(2) {
                at += step(0, w[0], w[1]);
            }
            let want = (mesh.positions[24] - mesh.positions[0]).truncate() * 2.0;
            assert!(at.distance(want) < 1e-4, "{path:?}: {at} against {want}");
        }
        // On a cylinder (radius 1, 24 vertices around) the frame turns with the tangent
        // planes: a walk around the ring unrolls into a straight line at the edges' length,
        // past the quarter turn where the edges point back against the centre's plane.
        let around = 24usize;
        let positions: Vec<Vec3> = (0..2 * around)
            .map(|k| {
                let a = (k % around) as f32 / around as f32 * std::f32::consts::TAU;
                Vec3::new(a.cos_pure(), a.sin_pure(), (k / around) as f32)
            })
            .collect();
        let normals: Vec<Vec3> = (positions.iter())
            .map(|p| Vec3::new(p.x, p.y, 0.0))
            .collect();
        let axis = vec![Vec3::Z; positions.len()];
        let ring_axes = optimization_axes(&normals, &axis);
        let cylinder = TransportedFrame {
            positions: &positions,
            normals: &normals,
            axes: &ring_axes,
            scale: 1.0,
            turn: (1.0, 0.0),
        };
        let mut step = cylinder.step();
        let edge = positions[0].distance(positions[1]);
        let mut at = Vec2::ZERO;
        for k in 0..around - 1 {
            let o = step(0, k, k + 1);
            at += o;
            let want = (k + 1) as f32 * edge;
            assert!(o.x.abs() < 1e-4, "step {k}: {o} leaves the ring's line");
            assert!(
                (at.length() - want).abs() < 1e-3,
                "after {} steps: {at}, {want} along",
                k + 1
            );
        }
        // Up the axis from there: along the other disc axis, as at the centre.
        let up = step(0, around - 1, 2 * around - 1);
        assert!((up - Vec2::new(1.0, 0.0)).length() < 1e-4, "{up}");
        // A turned principal angle turns the whole disc.
        let quarter = TransportedFrame {
            turn: (0.0, 1.0),
            ..unfolding
        };
        let o = quarter.step()(0, 0, 1);
        assert!(o.distance(Vec2::new(0.0, 2.0)) < 1e-5, "{o}");
    }
}
