//! Scoring the geometry-image method (Lai, Hu, Gu & Martin): the synthesized relief image
//! against the sample's, and the output mesh's soundness.
//!
//! **Relief.** The synthesize node's texels hold `(dx, dy, dn)` (and colour); the height `dn`
//! is scored as a grey image against the `dn` of the sample variant the synthesis copies from
//! at the field's reference scale: the analysis's middle scale, orientation 0 (the sample
//! unrotated), finest level. Both go through one mapping, the reference's `dn` range onto
//! [0, 1] (values outside clamp), so distances are fractions of the sample's relief depth.
//! The synthesized image covers the geometry image's square, whose texels are spread over
//! the surface at the field's scale: with `field.density_offset` ≠ 0 the texture is
//! synthesized from other scales and the ratio compares unlike sizes (reported with it).
//!
//! **Mesh.** `relief.obj` as written: boundary edges (one triangle), non-manifold edges (more
//! than two), unreferenced vertices, and flipped faces: triangles whose normal points against
//! the normal of the same three vertices on the undisplaced geometry-image mesh (`grid_mesh`
//! of the input's geometry image, which numbers its vertices the same way), i.e. relative to
//! the input surface.

use super::relief_frame::{LayoutCopy, floor_along_maps, score_along_maps};
use super::{Item, Run, ScoreFailure};
use crate::artifact::Bundle;
use crate::geom::Mesh;
use crate::geom::geometry_image::{GeometryImage, TexelImage};
use crate::image::Image;
use crate::pipeline::Handle;
use crate::stages::analyse_exemplar::texel_variants::{TexelVariants, TexelVariantsRef};
use crate::stages::field::param_field::ParamField;
use crate::stages::reconstruct::displacement::grid_mesh;
use crate::stages::synthesize::geometry_texture::{
    GeometrySynthParams, TexelControls, sample_frame_maps, texel_controls,
};
use crate::stages::synthesize::surface_metric::{
    MAX_STRETCH, share_at_max_stretch, surface_metrics,
};
use std::collections::HashMap;
use std::path::Path;
use texsyn_core::math::PureMath;

/// The texel channel holding the height (`dn`).
const HEIGHT: usize = 2;

/// The nodes of a geometry-image run that its score reads.
#[derive(Clone)]
pub struct GeometryImageNodes {
    pub parameterize: Handle<GeometryImage>,
    pub analyse_exemplar: Handle<TexelVariants>,
    pub field: Handle<ParamField>,
    pub synthesize: Handle<TexelImage>,
    pub reconstruct: Handle<Bundle>,
    /// The run's `[synthesize]`.
    pub synthesize_params: GeometrySynthParams,
    /// The run's `field.density_offset`.
    pub density_offset: f32,
}

impl super::Planned for GeometryImageNodes {
    fn score(&self, run: &Run<'_>, _: &mut Vec<String>) -> Result<Vec<Item>, ScoreFailure> {
        geometry_images(run, self)
    }
}

/// Scores the relief and the mesh.
pub fn geometry_images(run: &Run, nodes: &GeometryImageNodes) -> Result<Vec<Item>, ScoreFailure> {
    let (synth, density_offset) = (&nodes.synthesize_params, nodes.density_offset);
    let texels = run.view(nodes.synthesize)?;
    let variants = run.view(nodes.analyse_exemplar)?;
    let v = variants.variant(variants.params().middle_scale(), 0);
    let reference = variants.level(v, 0);
    let ref_channels = variants.channels();
    let ref_h: Vec<f32> = reference
        .texels
        .chunks_exact(ref_channels)
        .map(|t| t[HEIGHT])
        .collect();
    let (lo, hi) = ref_h
        .iter()
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &h| {
            (lo.min(h), hi.max(h))
        });
    let span = if hi > lo { hi - lo } else { 1.0 };
    let grey = |w: u32, h: u32, values: &[f32]| {
        Image::from_fn(w, h, |x, y| {
            let g = (values[(y * w + x) as usize] - lo) / span;
            [g, g, g, 1.0]
        })
    };
    let reference_img = grey(reference.width, reference.height, &ref_h);
    let out_h: Vec<f32> = texels
        .data
        .chunks_exact(texels.channels as usize)
        .map(|t| t[HEIGHT])
        .collect();
    let out_img = grey(texels.width, texels.height, &out_h);
    let mut item = Item::new(
        "the synthesized relief (dn, as grey)",
        "the sample's relief at the reference scale, unrotated",
    );
    run.score_into(&mut item, out_img.view(), None, reference_img.view())?;
    // The grid row and the mesh checks do not depend on the surface row: if that one cannot
    // be made (whatever the reason), they still stand, with a note saying why it is missing.
    let frame = surface_item(
        run,
        nodes,
        synth,
        &variants,
        &out_img,
        &grey,
        density_offset,
    )
    .map_err(|e| {
        item.notes.push(format!(
            "the relief along the surface could not be scored: {e}"
        ))
    })
    .ok();
    item.extra
        .insert("density_offset".into(), serde_json::json!(density_offset));
    if density_offset != 0.0 {
        item.notes.push(format!(
            "field.density_offset = {density_offset}: the texture is synthesized {:.2}× denser than the \
             reference, so the ratio compares unlike scales (it is meaningful at 0)",
            2f32.powf_pure(density_offset)
        ));
    }

    let gi = run.view(nodes.parameterize)?;
    let bytes = run.file(nodes.reconstruct, "relief.obj")?;
    let relief = crate::geom::io::read_mesh_bytes(Path::new("relief.obj"), &bytes)
        .map_err(|e| ScoreFailure::new(format!("reading relief.obj: {e}")))?;
    let (base, _) = grid_mesh(&gi, &gi.positions);
    tracing::debug!(
        "score: relief {} vertices {} triangles, undisplaced {} vertices {} triangles",
        relief.positions.len(),
        relief.triangles.len(),
        base.positions.len(),
        base.triangles.len()
    );
    let checks = mesh_checks(&relief, Some(&base));
    item.extra.insert(
        "mesh".into(),
        serde_json::to_value(&checks).expect("plain numbers"),
    );
    Ok(std::iter::once(item).chain(frame).collect())
}

/// The relief read in the sample's frame along the surface ([`super::relief_frame`]): each
/// patch through the map synthesis laid the texture out with at its centre (metric, scale
/// and orientation), against the sample unrotated, at the scale of the variants the synthesis
/// used most (the median scale index over the samples, rounded: at density offset 0 the
/// sample's own size; denser textures copy from downsampled variants, whose detail the grid
/// can hold, so they are compared with those).
fn surface_item(
    run: &Run,
    nodes: &GeometryImageNodes,
    synth: &GeometrySynthParams,
    variants: &TexelVariantsRef<'_>,
    out_img: &Image,
    grey: &dyn Fn(u32, u32, &[f32]) -> Image,
    offset: f32,
) -> Result<Item, ScoreFailure> {
    let gi = run.view(nodes.parameterize)?;
    let field = run.view(nodes.field)?;
    if field.dir.len() != gi.positions.len() || gi.positions.len() != out_img.pixels.len() {
        return Err(ScoreFailure::new(
            "the field, geometry image and synthesized relief disagree on the sample count",
        ));
    }
    let controls = texel_controls(&gi, &field, variants.params(), synth);
    let mut by_scale = controls.scale.clone();
    by_scale.sort_unstable_by(f32::total_cmp);
    let median = by_scale.get(by_scale.len() / 2).copied().unwrap_or(0.0);
    let s_ref = ((median + 0.5).floor() as usize).min(variants.params().scales as usize - 1);
    let v_ref = variants.variant(s_ref, 0);
    // The maps go to the sample's texels; the reference's are `size` of them.
    let size = variants.sample_map(v_ref, 0).a[0][0] as f32;
    let maps: Vec<[f32; 4]> = sample_frame_maps(&controls, variants)
        .into_iter()
        .map(|m| m.map(|v| v / size))
        .collect();
    let level = variants.level(v_ref, 0);
    let heights: Vec<f32> = level
        .texels
        .chunks_exact(variants.channels())
        .map(|t| t[HEIGHT])
        .collect();
    let reference_img = grey(level.width, level.height, &heights);
    let mut item = Item::new(
        "the synthesized relief read along the surface, in the sample's frame",
        format!(
            "the sample's relief unrotated, at the synthesis's median scale: variant scale {s_ref} \
             ({}×{} texels, {size} sample texels each)",
            level.width, level.height
        ),
    );
    item.extra
        .insert("reference_scale".into(), serde_json::json!(s_ref));
    if let Some(dir) = std::env::var_os("TEXSYN_SCORE_DUMP") {
        let win = super::relief_frame::windows_along_maps(out_img.view(), &maps, 64, 6);
        let png = crate::stages::reconstruct::textured_export::encode_png(&win.to_rgba8(), false);
        let path = Path::new(&dir).join("score_relief_along_the_surface.png");
        if let Err(e) = std::fs::write(&path, png) {
            tracing::warn!("TEXSYN_SCORE_DUMP: writing {}: {e}", path.display());
        }
    }
    match score_along_maps(out_img.view(), &maps, reference_img.view(), &run.params) {
        Ok(f) => {
            item.score = Some(f.score);
            item.extra.insert(
                "skipped_patches".into(),
                serde_json::json!(f.skipped as f64 / (f.skipped + f.readable) as f64),
            );
            let grid = (out_img.width, out_img.height);
            floor_item(
                &mut item,
                synth,
                &controls,
                variants,
                size,
                grid,
                &maps,
                &reference_img,
                run,
            );
        }
        Err(e) => item.notes.push(format!("not scored: {e}")),
    }
    // How unevenly the geometry image samples the surface, which the surface metric has to
    // undo (and which no per-texel scale can).
    let metrics = surface_metrics(&gi);
    let mut stretch: Vec<f32> = metrics.iter().map(|m| m.stretch()).collect();
    stretch.sort_unstable_by(f32::total_cmp);
    if !stretch.is_empty() {
        let at = |q: f64| stretch[((stretch.len() - 1) as f64 * q).round() as usize] as f64;
        item.extra.insert(
            "stretch".into(),
            serde_json::json!({
                "median": super::round3(at(0.5)),
                "p90": super::round3(at(0.9)),
                "at_max": super::round3(share_at_max_stretch(&metrics)),
            }),
        );
        item.notes.push(format!(
            "stretch: λ of the geometry image's surface metric (a grid step along its long \
             direction spans λ² times the surface length of one across it; 1 = isotropic), \
             median, 90th percentile, and the fraction at its cap of {MAX_STRETCH}; on the \
             cow more `parameterize.stretch_iterations` even out the area per texel but raise \
             λ"
        ));
    }
    item.extra
        .insert("density_offset".into(), serde_json::json!(offset));
    item.notes.push(
        "each patch is read through the map the synthesis used at its centre (surface metric, \
         the field's scale and orientation), bilinearly; patches that leave the square are \
         skipped (skipped_patches: their fraction of the texels)"
            .into(),
    );
    Ok(item)
}

/// The surface row's `floor`: what a verbatim layout under the same maps scores, copied the
/// way synthesis copies (texels of the variant turned and scaled as the field says, or
/// bilinearly with `subtexel` and the surface metric).
#[allow(clippy::too_many_arguments)]
fn floor_item(
    item: &mut Item,
    synth: &GeometrySynthParams,
    controls: &TexelControls,
    variants: &TexelVariantsRef<'_>,
    size: f32,
    grid: (u32, u32),
    maps: &[[f32; 4]],
    reference_img: &Image,
    run: &Run,
) {
    let subtexel = synth.subtexel && synth.anisotropic;
    let copy = if subtexel {
        LayoutCopy::Bilinear
    } else {
        LayoutCopy::Nearest
    };
    // The variants' frames: the same maps without the surface metric.
    let turned_and_scaled = TexelControls {
        metric: Vec::new(),
        orient: controls.orient.clone(),
        scale: controls.scale.clone(),
    };
    let frames: Vec<[f32; 4]> = sample_frame_maps(&turned_and_scaled, variants)
        .into_iter()
        .map(|m| m.map(|v| v / size))
        .collect();
    match floor_along_maps(
        grid.0,
        grid.1,
        maps,
        &frames,
        reference_img.view(),
        copy,
        &run.params,
    ) {
        Ok(f) => {
            item.extra.insert(
                "floor".into(),
                serde_json::json!({
                    "ratio": super::round3(f.ratio),
                    "gradient_ratio": super::round3(f.gradient_ratio),
                    "patches": f.queries,
                }),
            );
            item.notes.push(format!(
                "floor: the ratio and gradient ratio of the sample laid out verbatim under each \
                 patch's map and read back the same way, copied as synthesis copies ({}): what \
                 reading through these maps costs a flawless layout, over `patches` of the \
                 row's patches (those whose layout fits in the sample). Not a lower bound: a \
                 blurrier result can score a lower ratio",
                if subtexel {
                    "bilinearly"
                } else {
                    "texel by texel from the turned and scaled variant"
                }
            ));
        }
        Err(e) => item.notes.push(format!("floor not computed: {e}")),
    }
}

/// Soundness of an output mesh.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct MeshChecks {
    pub triangles: usize,
    /// Edges with one triangle (0 for a closed mesh).
    pub boundary_edges: usize,
    /// Edges with more than two triangles.
    pub non_manifold_edges: usize,
    pub unreferenced_vertices: usize,
    /// Triangles whose normal points against the same three vertices' on the reference;
    /// `None` without a reference with the same vertices.
    pub flipped_faces: Option<usize>,
}

/// [`MeshChecks`] of `mesh`; flips against `reference` (the same vertices at other
/// positions: each triangle of `mesh` is compared with its three vertices there, so the two
/// may triangulate differently).
pub fn mesh_checks(mesh: &Mesh, reference: Option<&Mesh>) -> MeshChecks {
    let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
    let mut used = vec![false; mesh.positions.len()];
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
            used[t[k] as usize] = true;
        }
    }
    let normal = |m: &Mesh, t: &[u32; 3]| {
        let p = t.map(|i| m.positions[i as usize]);
        (p[1] - p[0]).cross(p[2] - p[0])
    };
    let flipped_faces = reference
        .filter(|r| r.positions.len() == mesh.positions.len())
        .map(|r| {
            mesh.triangles
                .iter()
                .filter(|t| normal(mesh, t).dot(normal(r, t)) < 0.0)
                .count()
        });
    MeshChecks {
        triangles: mesh.triangles.len(),
        boundary_edges: edges.values().filter(|&&c| c == 1).count(),
        non_manifold_edges: edges.values().filter(|&&c| c > 2).count(),
        unreferenced_vertices: used.iter().filter(|&&u| !u).count(),
        flipped_faces,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn a_tetrahedron_is_closed_and_an_open_flipped_one_is_not() {
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z, Vec3::ONE];
        let tris = vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]];
        let tet = Mesh::new(p.clone(), tris.clone());
        let c = mesh_checks(&tet, Some(&tet));
        assert_eq!(
            c,
            MeshChecks {
                triangles: 4,
                boundary_edges: 0,
                non_manifold_edges: 0,
                unreferenced_vertices: 1,
                flipped_faces: Some(0)
            }
        );
        // Vertex 3 pushed through the base flips the three faces around it.
        let mut q = p.clone();
        q[3] = Vec3::new(0.2, 0.2, -1.0);
        let dented = Mesh::new(q, tris.clone());
        assert_eq!(mesh_checks(&dented, Some(&tet)).flipped_faces, Some(3));
        // One face removed: three boundary edges; a fin on an edge: non-manifold.
        let open = Mesh::new(p.clone(), tris[..3].to_vec());
        assert_eq!(mesh_checks(&open, None).boundary_edges, 3);
        let mut fin = tris.clone();
        fin.push([0, 1, 4]);
        let c = mesh_checks(&Mesh::new(p, fin), None);
        assert_eq!((c.non_manifold_edges, c.flipped_faces), (1, None));
    }
}
