//! Texture optimization on a surface with the feature-to-feature constraint: Xu et al.,
//! "Feature-Aligned Shape Texturing" (2009), §5.1–5.2, built on the texture optimization of
//! Kwatra, Essa, Bobick & Kwatra, "Texture optimization for example-based synthesis"
//! (SIGGRAPH 2005) in its surface form (Kwatra et al. 2007, "Texture fluids", which runs it on
//! the points of a surface).
//!
//! The energy (§5.1, eq. 3) is `E = Σ_{p ∈ X†} λ_p ω_p |x_p − z_p|²` over a subset X† of the
//! vertices: `x_p` are the colours of the vertices around sample `p` (its "grid patch",
//! expressed at the vertices as in texture fluids), `z_p` the exemplar patch that matches them
//! best, `ω_p = |x_p − z_p|^(r−2)` Kwatra's robust weight (r = `robust_exponent`, 0.8), so that
//! each sample contributes `λ_p |x_p − z_p|^r`. The minimization alternates
//!
//! - a nearest-neighbour search (Kwatra's "E-step"): the sample's patch, resampled onto a
//!   regular `w × w` grid in its tangent frame, is matched against every exemplar patch of the
//!   same grid laid along `exemplar_angle` (PCA-reduced vectors in a kd-tree, the few nearest
//!   re-ranked by the full distance);
//! - a least-squares solve ("M-step"): the energy is a sum of squares per vertex once ω is
//!   fixed, so every vertex's colour is the `λ_p ω_p`-weighted mean of what the patches that
//!   cover it say it should be: `E(z_p + R·(s_qp, t_qp))`, the exemplar bilinearly looked up at
//!   the vertex's exact offset `(s, t)` in the sample's frame, rotated onto the exemplar.
//!
//! Sample `p`'s patch is unfolded in its frame (`u_p` the field projected into `p`'s tangent
//! plane, `v_p = n_p × u_p`) by a breadth-first walk over edges from `p` that stay within a
//! Euclidean distance `(w/2)·√2` texels of `p` (so the walk follows the surface and does not
//! jump across thin gaps): each edge steps a vertex's offset `(s, t)` by its own length over
//! `texel_size`, in its direction in the frame carried to the edge's first end, and the frame
//! turns with the normal along the edge (a discrete exponential map; `patches.rs` says why
//! not a projection onto `p`'s plane). The patch holds the vertices with `|s|, |t| ≤ w/2`.
//!
//! The samples X† (§5.1, after Chen et al. 2009) are picked greedily in a priority order: a
//! vertex becomes a sample unless an earlier sample lies within `r·w` texels of it (r =
//! `sample_spacing`). With feature curves, the order is vertices on the curves first, then by
//! increasing curve distance while within `w/2` of a curve, then the rest in random order; so
//! the curves are sampled every `r·w` first, then their surroundings, as the paper describes.
//!
//! §5.2's constraint: a sample at curve distance `d(p) < w/2` texels may only match exemplar
//! patches whose centre lies at a distance from the texture's feature lines within
//! `feature_tolerance` texels of `d(p)` — the kd-tree's filtered query. If no exemplar patch
//! passes, the sample searches unconstrained and is counted in `unconstrained_fallbacks`.
//!
//! Choices where the papers leave values open, and departures:
//! - **λ_p (eq. 4)**: the paper's `1/(d + 10⁻⁶)` gives samples on a curve a million times the
//!   weight of a sample one unit away, so along a curve nothing but the on-curve samples
//!   contributes, and the weight's size depends on the model's units. Here `d` is in texels and
//!   `λ_p = 1 / clamp(d, min_curve_distance, w/2)`: the same 1/d law in the band where the
//!   constraint acts, capped at `1/min_curve_distance` (default 1 texel: an on-curve sample
//!   weighs as much as one a texel away and w/2 times one outside the band; 0.25 gave a 4%
//!   worse nearest-patch score in the benchmark), and constant outside the band,
//!   where the paper's 1/d would only tilt weights between neighbouring samples for no purpose.
//!   `min_curve_distance = 1e-6` is the paper's literal law inside the band. Without features,
//!   λ = 1 (§5.1).
//! - **ω_p** floors `|x_p − z_p|` at 10⁻⁴ (a perfect match would otherwise weigh infinitely);
//!   `|x_p − z_p|²` is the sum of squared RGB differences over the patch's vertices, and the
//!   reported `final_energy` is `Σ λ_p |x_p − z_p|^r` after the last least-squares step.
//! - **Grid patch at the vertices**: the patch's vertices are splatted bilinearly onto the
//!   matching grid (each cell: the tent-weighted mean of the vertices within one cell of it),
//!   and the exemplar patches are sampled with the same tent (bilinear at the finest level, a
//!   tent `2^l` texels wide at coarse levels, so a one-texel line is seen wherever it lies, not
//!   only on every other texel). On a texel-aligned grid with the field along an axis this is
//!   exactly the vertex colours. A cell no vertex reaches (mesh boundary, a back-facing fold, a
//!   mesh coarser than a texel) is left out of the distance: the tree query fills it with the
//!   current match's values, the re-ranking skips it and considers 16 instead of 4 tree
//!   candidates. Vertices whose normal faces away from the sample's (`n_q · n_p ≤ 0`) are not in
//!   its patch.
//! - **Exemplar borders**: exemplars are not assumed tileable, so candidate centres are the
//!   pixel centres whose whole rotated patch (the square `|s|,|t| ≤ w/2`, rotated by
//!   `exemplar_angle`) lies inside the exemplar; lookups never wrap. Odd `w` puts the grid
//!   cells on pixel centres when the angle is a multiple of 90°, so matching compares exact
//!   pixels; other angles interpolate bilinearly.
//! - **Search**: PCA to `components` dimensions, fitted to 256 evenly spread candidates through
//!   their Gram matrix with a block power iteration (`crate::image::pca::Pca::fit`'s Jacobi
//!   solver is cubic in the dimension `w²·3`, up to 12 288: 0.9 s per level at w = 15), then an
//!   approximate kd-tree query (Arya–Mount, `search_eps`) for the 4 nearest (16 with the
//!   occurrence penalty, which needs alternatives to choose from), re-ranked by the
//!   full `w²·3`-dimensional distance together with the current match (so, with
//!   `coherence = 0`, a sample's match never gets worse by its own measure and the iteration
//!   can settle; the coherent candidates below are compared at a discount, so a match may be
//!   traded for a coherent one up to `1/(1 − coherence)` times farther).
//! - **Multi-resolution** (Kwatra 2005 §4 runs coarse to fine; Xu et al. §6 ask for it for
//!   speed): `levels` runs of the whole optimization, the coarsest first; level `l` below the
//!   finest uses patches `2^l·w` texels wide whose grid has a `2^l`-texel step (the same `w×w`
//!   vector size; tent-filtered on both sides, see above), with samples `r·2^l·w` apart. The
//!   coarse level lays out the large structures (a line's course over 2w texels), the fine level
//!   repairs the detail: with one level the striped test's nearest-patch ratio is 3.4–5.3, with
//!   two 1.3–2.8. A coarse level is skipped when its candidate centres would cover less than
//!   half of either exemplar side (too few to choose from); the finest must fit
//!   (`ExemplarTooSmall`). The M-step always looks up the sharp exemplar at the vertices' exact
//!   offsets. A level starts each sample's match (which fills its empty grid cells) at the
//!   exemplar position its vertex got at the previous level; the first level starts from random
//!   positions.
//! - **Occurrence penalty** (not in Xu et al. nor Kwatra et al.; Kopf et al. 2007, "Solid
//!   texture synthesis from 2D exemplars", §3.3): plain texture optimization settles on the
//!   exemplar's most common content. On brick it drops every mortar line: each 15-texel window
//!   inside a brick matches itself perfectly, so an all-brick result has a low energy (seen on
//!   fandisk and on a flat sheet; `the_occurrence_penalty_keeps_rare_features` measures it).
//!   Exemplar positions are counted in 8×8-texel blocks over the current matches; a candidate
//!   in a block used more than its fair share (its candidates × samples / candidates) gets
//!   `penalty = 1 + histogram · (use/fair − 1)`. It multiplies the candidate's distance in the
//!   search (Kopf re-weights only the solve; in the search it also steers new matches away
//!   from over-used content, which the solve's weights alone did not do in the tests) and
//!   divides the sample's ω in the colour solve, as Kopf does. `histogram = 0` is plain texture
//!   optimization.
//! - **k-coherence candidates** (not in Xu et al.; Ashikhmin 2001, "Synthesizing natural
//!   textures", and Han et al. 2006, §4, build their candidate sets from them): the
//!   kd-tree proposes patches by appearance alone, so neighbouring samples match unrelated
//!   exemplar places that look alike under the blurred least-squares colours, and the
//!   final pass's copies meet at seams every few texels (on fandisk, without them, stones
//!   come out in fragments with their mortar broken). Each sample also considers, for up to
//!   24 vertices spread through its patch, the exemplar patch that continues the address the
//!   vertex holds at the current iteration (its address minus its rotated offset), at
//!   `1 − coherence` times its distance. Han et al. search only such candidates; here they
//!   compete with the tree's, favoured, so a sample whose surroundings copy nothing that
//!   fits can still leave them. The sample's own match is usually among them (its own
//!   vertex copies it), so it is favoured too: the tree's best must be `1/(1 − coherence)`
//!   times nearer to displace a coherent match. Leaving the current match out of the
//!   favoured set measured the same (fandisk 0.776 / 0.767 / 0.695, the cow's curves 0.742 /
//!   0.895 / 0.700, against 0.774 / 0.779 / 0.704 and 0.736 / 0.886 / 0.697), so the gain is
//!   not hysteresis alone. Measured on fandisk (ratio / coverage / gradient ratio, bicubic
//!   atlas): without 0.782 / 0.722 / 0.675; candidates at their plain distance (factor 1)
//!   0.779 / 0.731 / 0.674; `coherence` 0.6: 0.774 / 0.779 / 0.704; 0.8: 0.780 / 0.764 /
//!   0.719. With 0.6 the preview shows whole stones with their mortar along the creases.
//! - **Final discrete pass** (`solver = "discrete"`, the default; Xu et al. §5 end with the
//!   least-squares colours): Kwatra's M-step makes each vertex the weighted mean of the ~16
//!   lookups that cover it. On a surface the overlapping patches' grids differ by sub-texel
//!   shifts and rotations, so the mean is a blur even where they agree on content: kept to the
//!   end, the average kept 17–18 % of the exemplar's gradient energy on fandisk (brick), a
//!   cactus (bark) and a mushroom (parquet). After the finest level's iterations each vertex
//!   instead copies the lookup of its heaviest covering patch, the one of largest `λ_p ω_p`
//!   (the sample whose exemplar patch matches best, weighted toward the curves): a real
//!   exemplar texel, with the address it came from, so the export can look the exemplar up
//!   between vertices ([`SurfaceSynthesis::source`]). The layout stays the least-squares
//!   one, whose overlapping patches agree, so the pass adds few seams. Measured (gradient
//!   ratio / nearest-patch ratio along the surface): fandisk 0.17 → 0.42 / 0.68 → 0.77,
//!   cactus 0.18 → 0.40 / 0.74 → 0.83, mushroom 0.18 → 0.37 / 0.61 → 0.62. Two other discrete
//!   solves were tried. The discrete minimizer of the quadratic energy with ω fixed (Han et
//!   al. 2006, "Fast example-based surface texture synthesis via discrete optimization", §4:
//!   the covering lookup nearest the weighted mean) kept the blur (gradient 0.19 on the
//!   cactus): the value nearest a blurred mean is itself smooth. Copying the heaviest patch in
//!   every iteration was sharper still (0.46 / 0.54 / 0.41) but quilted the layout with seams:
//!   the striped sheet's nearest-patch ratio rose from 1.3–2.8 to 3.0–4.4 (both without
//!   coherence candidates).
//!   `solver = "average"` keeps Kwatra's continuous solve to the end.
//! - **Iteration**: E then M, `iterations` times per level, stopping early when no sample's match
//!   changed. Initially every vertex takes the colour its nearest sample's random patch gives
//!   it (pieces of exemplar pasted side by side), not the mean of the random patches: the
//!   mean is a grey blur from which the first search finds no structure to lock on to.
//! - Vertices no patch covers (on a plane only with `sample_spacing > 0.5`, whose spacing
//!   exceeds the patch half-width; across creases from about 0.4, since samples are spaced by
//!   straight distance and patches by unfolded distance, which is longer) take the colour and
//!   source of the nearest covered vertex in edge
//!   hops, and are counted. Vertices used by no triangle get the exemplar's mean colour and the
//!   source `[-1, -1]`.
//! - The field is projected into each vertex's tangent plane; where it vanishes there, an
//!   arbitrary tangent direction is used.
//!
//! [`curve_distance`] gives the per-vertex geodesic distance the constraint needs: Dijkstra
//! whose updates also cross triangles (fast marching's planar-front update from the two
//! finished corners of a triangle), exact from a straight curve on a flat mesh, where edge
//! Dijkstra follows the edges' zigzag; see its doc for the measured error.

mod candidates;
mod geodesic;
mod node;
mod params;
mod patches;
mod pca;
mod run;
mod search;

pub use geodesic::curve_distance;
pub use node::{SynthesisKey, check_patch_fits, node};
pub use params::{
    FeatureConstraint, Solver, SurfaceSynthesis, SurfaceSynthesisInput, SynthesisError,
    SynthesisStats, TextureOptimizationParams, memory_estimate,
};
pub use run::texture_optimization;

/// The `texture_optimization` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("texture_optimization", 4);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::Mesh;
    use crate::geom::primitives::grid;
    use crate::image::Image;
    use crate::image::patch_score::{ScoreParams, patch_score};
    use crate::random::counter_hash;
    use crate::random::counter_unit;
    use crate::testing::assert_validation;
    use glam::Vec3;
    use texsyn_core::math::PureMath;

    fn no_progress(_: f32) {}

    /// Horizontal stripes (colour changes along y only) of random widths 3..=7 and random
    /// colours, with a little pixel noise so that no two patches are identical.
    fn striped(size: u32, seed: u64) -> Image {
        let mut rows = Vec::new();
        let mut k = 0u64;
        while rows.len() < size as usize {
            let width = 3 + (counter_hash(seed, 10, k) % 5) as usize;
            let c = [
                0.15 + 0.7 * counter_unit(seed, 11, k),
                0.15 + 0.7 * counter_unit(seed, 12, k),
                0.15 + 0.7 * counter_unit(seed, 13, k),
            ];
            rows.extend(std::iter::repeat_n(c, width));
            k += 1;
        }
        Image::from_fn(size, size, |x, y| {
            let c = rows[y as usize];
            let i = (y * size + x) as u64;
            let nz = |s| 0.03 * (counter_unit(seed, s, i) - 0.5);
            [c[0] + nz(20), c[1] + nz(21), c[2] + nz(22), 1.0]
        })
    }

    fn constant_field(n: usize, dir: Vec3) -> Vec<Vec3> {
        vec![dir; n]
    }

    /// The grid's vertex colours as an image (vertex (x, y) is pixel (x, y)).
    fn as_image(colours: &[[f32; 3]], side: usize) -> Image {
        Image::from_fn(side as u32, side as u32, |x, y| {
            let c = colours[y as usize * side + x as usize];
            [c[0], c[1], c[2], 1.0]
        })
    }

    fn preview(name: &str, img: &Image) {
        if std::env::var_os("TOPT_PREVIEW").is_some() {
            let scale = 4;
            let big = image::imageops::resize(
                &img.to_rgba8(),
                img.width * scale,
                img.height * scale,
                image::imageops::FilterType::Nearest,
            );
            big.save(format!("/tmp/topt-{name}.png")).unwrap();
        }
    }

    /// Mean absolute colour difference between neighbours along x and along y.
    fn directional_differences(c: &[[f32; 3]], side: usize) -> (f64, f64) {
        let (mut dx, mut dy) = (0.0f64, 0.0f64);
        let mut count = 0usize;
        for y in 0..side - 1 {
            for x in 0..side - 1 {
                let a = c[y * side + x];
                let b = c[y * side + x + 1];
                let d = c[(y + 1) * side + x];
                for k in 0..3 {
                    dx += (a[k] - b[k]).abs() as f64;
                    dy += (a[k] - d[k]).abs() as f64;
                }
                count += 1;
            }
        }
        (dx / count as f64, dy / count as f64)
    }

    fn synth(
        mesh: &Mesh,
        field: &[Vec3],
        ex: &Image,
        features: Option<FeatureConstraint>,
        p: &TextureOptimizationParams,
    ) -> SurfaceSynthesis {
        let input = SurfaceSynthesisInput {
            mesh,
            field,
            exemplar: ex,
            texel_size: 1.0,
            exemplar_angle: 0.0,
            features,
        };
        texture_optimization(&input, p, &no_progress).unwrap()
    }

    #[test]
    fn parameters_are_validated() {
        assert_validation!(TextureOptimizationParams {
            patch: 3 => "synthesize.patch must be in 4..=64, got 3",
            sample_spacing: 0.0 => "synthesize.sample_spacing must be in 0.05..=1, got 0",
            robust_exponent: 3.0 => "synthesize.robust_exponent must be in 0.1..=2, got 3",
            iterations: 0 => "synthesize.iterations must be in 1..=100, got 0",
            feature_tolerance: -1.0 => "synthesize.feature_tolerance must be in 0..=64, got -1",
            levels: 4 => "synthesize.levels must be in 1..=3, got 4",
            components: 2 => "synthesize.components must be in 4..=64, got 2",
            search_eps: f32::NAN => "synthesize.search_eps must be in 0..=10, got NaN",
            min_curve_distance: 0.0 => "synthesize.min_curve_distance must be in 0.000001..=64, got 0",
            histogram: -1.0 => "synthesize.histogram must be in 0..=10, got -1",
            coherence: 1.0 => "synthesize.coherence must be in 0..=0.95, got 1",
        });
    }

    #[test]
    fn stripes_follow_the_field_and_look_like_the_exemplar() {
        let side = 64;
        let mesh = grid(side, 1.0);
        let ex = striped(64, 3);
        // Plain texture optimization (no occurrence penalty): the scores below were measured
        // for it; the penalty is tested on its own below.
        let p = TextureOptimizationParams {
            histogram: 0.0,
            ..Default::default()
        };
        let out = synth(&mesh, &constant_field(side * side, Vec3::X), &ex, None, &p);
        let img = as_image(&out.colours, side);
        preview("stripes-x", &img);
        let (along, across) = directional_differences(&out.colours, side);
        assert!(
            along < 0.3 * across,
            "stripes do not run along u = x: along {along:.4}, across {across:.4}"
        );
        // Nearest-patch score: this exemplar's unique stripe colours make its self baseline
        // tiny (a crop's patches recur elsewhere along their stripe), so one seam between two
        // stripe layouts already doubles the ratio; measured 1.27, 1.96, 2.76 for seeds 0..3 with
        // `coherence = 0` (the asserts hold at the default too),
        // while a single level, plain least squares (r = 2) or a too large patch give 3.4–8.
        let mut ratios = Vec::new();
        for seed in 0..3 {
            let o = if seed == 0 {
                out.clone()
            } else {
                let p = TextureOptimizationParams { seed, ..p.clone() };
                synth(&mesh, &constant_field(side * side, Vec3::X), &ex, None, &p)
            };
            let score = patch_score(
                as_image(&o.colours, side).view(),
                ex.view(),
                &ScoreParams {
                    patch: 7,
                    ..Default::default()
                },
            )
            .unwrap();
            ratios.push(score.ratio);
        }
        let mean_ratio = ratios.iter().sum::<f64>() / 3.0;
        assert!(mean_ratio < 2.5, "patch score ratios {ratios:?}");
        assert_eq!(out.stats.uncovered_vertices, 0);
        assert!(out.stats.samples > 0 && out.stats.samples < (side * side / 8) as u32);

        // The field turned by 90° turns the stripes.
        let out = synth(&mesh, &constant_field(side * side, Vec3::Y), &ex, None, &p);
        preview("stripes-y", &as_image(&out.colours, side));
        let (along_x, along_y) = directional_differences(&out.colours, side);
        assert!(
            along_y < 0.3 * along_x,
            "stripes do not run along u = y: along y {along_y:.4}, along x {along_x:.4}"
        );
    }

    /// Mean squared RGB difference across the mesh's edges, per squared edge length.
    fn detail(mesh: &Mesh, colours: &[[f32; 3]]) -> f64 {
        let (mut sum, mut count) = (0.0f64, 0usize);
        for t in &mesh.triangles {
            for k in 0..3 {
                let (a, b) = (t[k] as usize, t[(k + 1) % 3] as usize);
                let len = mesh.positions[a].distance(mesh.positions[b]) as f64;
                let d: f32 = (0..3)
                    .map(|c| (colours[a][c] - colours[b][c]).powi(2))
                    .sum();
                sum += d as f64 / len.max(1e-6).powi(2);
                count += 1;
            }
        }
        sum / count.max(1) as f64
    }

    #[test]
    fn the_discrete_pass_copies_exemplar_texels_and_keeps_the_detail_the_average_blurs() {
        // A square 48 texels wide refined as feature-aligned refines a mesh (edges split
        // until at most a texel long: irregular vertices 0.5–1 texel apart), the field at 30°
        // to its sides. Overlapping patches sample the exemplar at different sub-texel
        // offsets, so their mean blurs the mortar lines.
        let corners = [[0.0, 0.0], [48.0, 0.0], [48.0, 48.0], [0.0, 48.0]];
        let square = Mesh::new(
            corners.iter().map(|&[x, y]| Vec3::new(x, y, 0.0)).collect(),
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let mesh = crate::geom::edge_refine::refine_edges(&square, 1.0, 100_000)
            .unwrap()
            .mesh;
        let ex = bricks(96);
        let (c, s) = (30f32.to_radians().cos_pure(), 30f32.to_radians().sin_pure());
        let field = constant_field(mesh.vertex_count(), Vec3::new(c, s, 0.0));
        let run = |solver| {
            let p = TextureOptimizationParams {
                solver,
                iterations: 4,
                ..Default::default()
            };
            synth(&mesh, &field, &ex, None, &p)
        };
        let (average, discrete) = (run(Solver::Average), run(Solver::Discrete));
        let (a, d) = (
            detail(&mesh, &average.colours),
            detail(&mesh, &discrete.colours),
        );
        // Measured 1.36× here with `coherence = 0` (on curved meshes with photographed
        // exemplars, 2.1–2.5×).
        assert!(
            d > 1.2 * a,
            "edge differences: discrete {d:.5}, average {a:.5}"
        );
        // Every vertex holds the exemplar's own colour at the address it reports.
        for (q, (col, src)) in discrete.colours.iter().zip(&discrete.source).enumerate() {
            let want = ex.view().sample(glam::Vec2::from(*src));
            let err = (0..3).map(|k| (col[k] - want[k]).abs()).fold(0.0, f32::max);
            assert!(
                err < 1e-5,
                "vertex {q}: {col:?} is not the exemplar at {src:?}"
            );
        }
    }

    /// A synthetic brick wall: light bricks 24×12 texels with a little noise, dark mortar rows
    /// and joints two texels wide (joints offset by half a brick every row).
    fn bricks(size: u32) -> Image {
        let mut img = Image::new(size, size);
        for y in 0..size {
            for x in 0..size {
                let row = y / 12;
                let xs = x + if row % 2 == 1 { 12 } else { 0 };
                let mortar = y % 12 < 2 || xs % 24 < 2;
                let n = crate::random::counter_unit(5, 0, (y * size + x) as u64) * 0.1;
                let v = if mortar { 0.1 + n * 0.5 } else { 0.7 + n };
                img.pixels[(y * size + x) as usize] = [v, v * 0.8, v * 0.6, 1.0];
            }
        }
        img
    }

    #[test]
    fn the_occurrence_penalty_keeps_rare_features() {
        // Mortar covers about a quarter of the wall. Plain texture optimization may settle on
        // brick interior (every 15-texel window of a brick is a perfect match for itself), and
        // the mortar fraction of the result drops; the penalty keeps it near the exemplar's.
        let side = 96;
        let mesh = grid(side, 1.0);
        let ex = bricks(96);
        let dark = |c: &[[f32; 3]]| c.iter().filter(|c| c[0] < 0.4).count() as f64 / c.len() as f64;
        let ex_rgb: Vec<[f32; 3]> = ex.pixels.iter().map(|p| [p[0], p[1], p[2]]).collect();
        let target = dark(&ex_rgb);
        let error = |histogram: f32| {
            (0..3)
                .map(|seed| {
                    let p = TextureOptimizationParams {
                        histogram,
                        seed,
                        ..Default::default()
                    };
                    let out = synth(&mesh, &constant_field(side * side, Vec3::X), &ex, None, &p);
                    preview(
                        &format!("bricks-h{histogram}-{seed}"),
                        &as_image(&out.colours, side),
                    );
                    (dark(&out.colours) - target).abs()
                })
                .sum::<f64>()
                / 3.0
        };
        let (plain, penalized) = (error(0.0), error(1.0));
        assert!(
            penalized < plain,
            "mortar fraction off by {penalized:.3} with the penalty, {plain:.3} without (exemplar {target:.3})"
        );
    }

    /// A textured background with three dark horizontal lines one texel thick, and each
    /// texel's distance to the nearest line.
    fn lined(size: u32) -> (Image, Vec<f32>) {
        let lines = [12i64, 30, 47];
        let dist = |y: u32| {
            lines
                .iter()
                .map(|&l| (y as i64 - l).abs() as f32)
                .fold(f32::INFINITY, f32::min)
        };
        let img = Image::from_fn(size, size, |x, y| {
            if dist(y) == 0.0 {
                [0.08, 0.06, 0.05, 1.0]
            } else {
                let i = (y * size + x) as u64;
                let blob = 0.5
                    + 0.15
                        * ((x as f32 * 0.45).sin_pure()
                            * (y as f32 * 0.3 + x as f32 * 0.1).cos_pure())
                    + 0.06 * (counter_unit(5, 1, i) - 0.5);
                [blob + 0.2, blob + 0.1, blob * 0.6, 1.0]
            }
        });
        let td = (0..size * size).map(|i| dist(i / size)).collect();
        (img, td)
    }

    #[test]
    fn the_constraint_puts_texture_lines_on_the_shape_curve() {
        let side = 64;
        let mesh = grid(side, 1.0);
        let curve: Vec<u32> = (0..side as u32).map(|x| 32 * side as u32 + x).collect();
        let d = curve_distance(&mesh, &curve);
        let (ex, td) = lined(64);
        let field = constant_field(side * side, Vec3::X);
        let p = TextureOptimizationParams::default();
        let free = synth(&mesh, &field, &ex, None, &p);
        let constrained = synth(
            &mesh,
            &field,
            &ex,
            Some(FeatureConstraint {
                curve_distance: &d,
                texture_distance: &td,
            }),
            &p,
        );
        preview("lines-free", &as_image(&free.colours, side));
        preview("lines-constrained", &as_image(&constrained.colours, side));
        assert!(constrained.stats.constrained_samples > 0);
        assert_eq!(constrained.stats.unconstrained_fallbacks, 0);
        let d_at = |s: [f32; 2]| {
            let x = (s[0].round() as usize).min(63);
            let y = (s[1].round() as usize).min(63);
            td[y * 64 + x]
        };
        let band = p.patch as f32 * 0.5;
        let mismatch = |out: &SurfaceSynthesis| {
            let (mut sum, mut count) = (0.0f64, 0usize);
            for v in 0..side * side {
                if d[v] < band {
                    sum += (d_at(out.source[v]) - d[v]).abs() as f64;
                    count += 1;
                }
            }
            sum / count as f64
        };
        let (m_free, m_con) = (mismatch(&free), mismatch(&constrained));
        assert!(
            m_con <= 0.5 * m_free,
            "mean |D(source) − d| with the constraint {m_con:.3}, without {m_free:.3}"
        );
        // The acceptance measure: from each curve vertex, the distance to the nearest vertex
        // whose colour comes from a texture line.
        let line_distance = |out: &SurfaceSynthesis| {
            let on_line: Vec<Vec3> = (0..side * side)
                .filter(|&v| d_at(out.source[v]) < 0.5)
                .map(|v| mesh.positions[v])
                .collect();
            let total: f32 = curve
                .iter()
                .map(|&c| {
                    let pc = mesh.positions[c as usize];
                    on_line
                        .iter()
                        .map(|q| q.distance(pc))
                        .fold(f32::INFINITY, f32::min)
                })
                .sum();
            total / curve.len() as f32
        };
        let (l_free, l_con) = (line_distance(&free), line_distance(&constrained));
        eprintln!("mismatch {m_free:.3} -> {m_con:.3}, line distance {l_free:.3} -> {l_con:.3}");
        assert!(
            l_con <= 0.5 * l_free,
            "curve to nearest texture line: {l_con:.3} with the constraint, {l_free:.3} without"
        );
        // On the curve itself the texture's line lies there, visibly dark.
        let on_curve = |out: &SurfaceSynthesis| {
            let (mut dsum, mut lum) = (0.0f64, 0.0f64);
            for &v in &curve {
                dsum += d_at(out.source[v as usize]) as f64;
                let c = out.colours[v as usize];
                lum += ((c[0] + c[1] + c[2]) / 3.0) as f64;
            }
            (dsum / curve.len() as f64, lum / curve.len() as f64)
        };
        let (dist_con, lum_con) = on_curve(&constrained);
        assert!(
            dist_con < 1.0,
            "on-curve vertices come from {dist_con:.2} texels off a line"
        );
        assert!(lum_con < 0.2, "the curve's row is not dark: {lum_con:.3}");
    }

    /// Rows of blocks of random widths 6..=13 and random colours, 4 to 8 texels tall, with
    /// one-texel dark joints: structure along both axes, like a wall's stones.
    fn blocks(size: u32, seed: u64) -> Image {
        let s = size as usize;
        let mut id = vec![(0u64, false); s * s];
        let (mut y, mut row) = (0usize, 0u64);
        while y < s {
            let h = 4 + (counter_hash(seed, 30, row) % 5) as usize;
            let (mut x, mut k) = ((counter_hash(seed, 31, row) % 7) as usize, 0u64);
            let mut start = 0;
            while start < s {
                let end = x.min(s);
                for yy in y..(y + h).min(s) {
                    for xx in start..end {
                        let joint = yy == y || xx == start;
                        id[yy * s + xx] = (row * 1000 + k, joint);
                    }
                }
                start = end;
                x = end + 6 + (counter_hash(seed, 32, row * 1000 + k) % 8) as usize;
                k += 1;
            }
            y += h;
            row += 1;
        }
        Image::from_fn(size, size, |x, y| {
            let (b, joint) = id[(y * size + x) as usize];
            let i = (y * size + x) as u64;
            let nz = |c| 0.05 * (counter_unit(seed, c, i) - 0.5);
            if joint {
                return [0.1 + nz(40), 0.1 + nz(41), 0.1 + nz(42), 1.0];
            }
            let c = |c| 0.35 + 0.5 * counter_unit(seed, c, b);
            [c(33) + nz(40), c(34) + nz(41), c(35) + nz(42), 1.0]
        })
    }

    /// The k-coherence candidates make neighbouring vertices copy neighbouring exemplar
    /// texels more often: on a flat grid of one-texel edges under a field that turns (as on
    /// a surface, patches meet at other angles and sub-texel shifts), the share of grid
    /// edges whose two vertices' addresses lie one texel apart, as inside one copied patch,
    /// rises with `coherence`; an edge whose addresses jump is a seam between two pieces.
    #[test]
    fn coherence_candidates_make_neighbours_copy_neighbouring_texels() {
        let side = 48;
        let mesh = grid(side, 1.0);
        let ex = blocks(64, 5);
        let field: Vec<Vec3> = mesh
            .positions
            .iter()
            .map(|q| Vec3::new(1.0, 0.03 * q.x, 0.0))
            .collect();
        let coherent_share = |coherence| {
            let p = TextureOptimizationParams {
                coherence,
                ..Default::default()
            };
            let out = synth(&mesh, &field, &ex, None, &p);
            let (mut coherent, mut edges) = (0usize, 0usize);
            for y in 0..side - 1 {
                for x in 0..side - 1 {
                    let a = out.source[y * side + x];
                    for b in [out.source[y * side + x + 1], out.source[(y + 1) * side + x]] {
                        edges += 1;
                        let jump = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
                        if (jump - 1.0).abs() < 0.25 {
                            coherent += 1;
                        }
                    }
                }
            }
            coherent as f64 / edges as f64
        };
        let (plain, pulled) = (coherent_share(0.0), coherent_share(0.6));
        // Measured 0.862 and 0.886. The flat sheet is the easy case (whole-texel steps, no
        // curves): on fandisk the same pull is what keeps stones whole with their mortar.
        // With the exemplar turned 0.3 rad both measure 0.863 (the candidates win 1,197
        // searches there, but the seams land as often): the rotation of a proposal is checked
        // by `search::tests` instead.
        assert!(
            pulled > plain + 0.01,
            "plain {plain:.3}, coherence 0.6 {pulled:.3}"
        );
    }

    #[test]
    fn more_iterations_lower_the_energy() {
        let side = 48;
        let mesh = grid(side, 1.0);
        let ex = striped(48, 9);
        let field = constant_field(side * side, Vec3::X);
        let run = |iterations| {
            let p = TextureOptimizationParams {
                iterations,
                levels: 1,
                ..Default::default()
            };
            synth(&mesh, &field, &ex, None, &p).stats
        };
        let (one, many) = (run(1), run(10));
        assert_eq!(one.iterations_run, 1);
        assert!(many.iterations_run > 1);
        assert!(
            many.final_energy < one.final_energy,
            "energy after {} iterations {} is not below that after one, {}",
            many.iterations_run,
            many.final_energy,
            one.final_energy
        );
    }

    #[test]
    fn results_do_not_depend_on_the_thread_count() {
        let side = 40;
        let mesh = grid(side, 1.0);
        let curve: Vec<u32> = (0..side as u32).map(|x| 20 * side as u32 + x).collect();
        let d = curve_distance(&mesh, &curve);
        let (ex, td) = lined(64);
        // A field that turns, so that offsets are not whole texels.
        let field: Vec<Vec3> = mesh
            .positions
            .iter()
            .map(|q| Vec3::new(1.0, 0.02 * q.x, 0.0))
            .collect();
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let input = SurfaceSynthesisInput {
                    mesh: &mesh,
                    field: &field,
                    exemplar: &ex,
                    texel_size: 1.0,
                    exemplar_angle: 0.3,
                    features: Some(FeatureConstraint {
                        curve_distance: &d,
                        texture_distance: &td,
                    }),
                };
                let p = TextureOptimizationParams {
                    patch: 9,
                    ..Default::default()
                };
                texture_optimization(&input, &p, &no_progress).unwrap()
            })
        };
        let (a, b) = (run(1), run(2));
        let bits = |o: &SurfaceSynthesis| {
            let c: Vec<u32> = o.colours.iter().flatten().map(|x| x.to_bits()).collect();
            let s: Vec<u32> = o.source.iter().flatten().map(|x| x.to_bits()).collect();
            (c, s)
        };
        assert_eq!(bits(&a), bits(&b));
        assert_eq!(a.stats, b.stats);
    }

    #[test]
    fn bad_input_is_an_error_naming_what_to_change() {
        let mesh = grid(8, 1.0);
        let field = constant_field(64, Vec3::X);
        let ex = striped(48, 1);
        let input = |field: &'static [Vec3]| SurfaceSynthesisInput {
            mesh: &mesh,
            field,
            exemplar: &ex,
            texel_size: 1.0,
            exemplar_angle: 0.0,
            features: None,
        };
        let field: &'static [Vec3] = field.leak();
        let big = TextureOptimizationParams {
            patch: 64,
            ..Default::default()
        };
        let e = texture_optimization(&input(field), &big, &no_progress).unwrap_err();
        assert!(matches!(e, SynthesisError::ExemplarTooSmall { .. }), "{e}");
        assert!(e.to_string().contains("synthesize.patch"), "{e}");
        // A patch that fits unrotated does not fit at 45°.
        let fits = TextureOptimizationParams {
            patch: 40,
            ..Default::default()
        };
        assert!(texture_optimization(&input(field), &fits, &no_progress).is_ok());
        let mut turned = input(field);
        turned.exemplar_angle = std::f32::consts::FRAC_PI_4;
        assert!(matches!(
            texture_optimization(&turned, &fits, &no_progress),
            Err(SynthesisError::ExemplarTooSmall { .. })
        ));
        let e = texture_optimization(&input(&field[1..]), &fits, &no_progress).unwrap_err();
        assert!(matches!(e, SynthesisError::InputMismatch(_)), "{e}");
        let d = vec![0.0f32; 63];
        let td = vec![0.0f32; 48 * 48];
        let mut wrong = input(field);
        wrong.features = Some(FeatureConstraint {
            curve_distance: &d,
            texture_distance: &td,
        });
        assert!(matches!(
            texture_optimization(&wrong, &fits, &no_progress),
            Err(SynthesisError::InputMismatch(_))
        ));
        let mut zero = input(field);
        zero.texel_size = 0.0;
        assert!(matches!(
            texture_optimization(&zero, &fits, &no_progress),
            Err(SynthesisError::InputMismatch(_))
        ));
        let bad = TextureOptimizationParams {
            iterations: 0,
            ..Default::default()
        };
        assert!(matches!(
            texture_optimization(&input(field), &bad, &no_progress),
            Err(SynthesisError::Params(_))
        ));
    }

    /// Prints quality measures for a few settings (a tuning aid, not a check).
    #[test]
    #[ignore]
    fn explore_settings() {
        let side = 64;
        let mesh = grid(side, 1.0);
        let ex = striped(64, 3);
        let field = constant_field(side * side, Vec3::X);
        let base = TextureOptimizationParams::default();
        let variants = [
            ("default", base.clone()),
            (
                "it6",
                TextureOptimizationParams {
                    iterations: 6,
                    ..base.clone()
                },
            ),
            (
                "it20",
                TextureOptimizationParams {
                    iterations: 20,
                    ..base.clone()
                },
            ),
            (
                "levels1it30",
                TextureOptimizationParams {
                    levels: 1,
                    iterations: 30,
                    ..base.clone()
                },
            ),
            (
                "levels3",
                TextureOptimizationParams {
                    levels: 3,
                    ..base.clone()
                },
            ),
            (
                "r2",
                TextureOptimizationParams {
                    robust_exponent: 2.0,
                    ..base.clone()
                },
            ),
            (
                "w9",
                TextureOptimizationParams {
                    patch: 9,
                    ..base.clone()
                },
            ),
            (
                "w21",
                TextureOptimizationParams {
                    patch: 21,
                    ..base.clone()
                },
            ),
            (
                "s0.15",
                TextureOptimizationParams {
                    sample_spacing: 0.15,
                    ..base.clone()
                },
            ),
        ];
        for (name, p) in variants {
            for seed in 0..3 {
                let p = TextureOptimizationParams { seed, ..p.clone() };
                let t = std::time::Instant::now();
                let out = synth(&mesh, &field, &ex, None, &p);
                let img = as_image(&out.colours, side);
                let score = patch_score(
                    img.view(),
                    ex.view(),
                    &ScoreParams {
                        patch: 7,
                        ..Default::default()
                    },
                )
                .unwrap();
                let (along, across) = directional_differences(&out.colours, side);
                eprintln!(
                    "{name:10} ratio {:.3} grad {:.3} along/across {:.3} its {} energy {:.1} {:?}",
                    score.ratio,
                    score.gradient_ratio,
                    along / across,
                    out.stats.iterations_run,
                    out.stats.final_energy,
                    t.elapsed()
                );
                preview(&format!("explore-{name}-{seed}"), &img);
            }
        }
    }

    /// Time for a ~100k-vertex grid with a 128² exemplar at the defaults (run with
    /// `--release -- --ignored timing --nocapture`; reads ../shared/data when it is there).
    #[test]
    #[ignore]
    fn timing_100k_vertices() {
        let side = 317;
        let mesh = grid(side, 1.0);
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../shared/data/exemplars/crinklepaper.png");
        let ex = match std::fs::read(&path) {
            Ok(bytes) => crate::image::decode_image(&path, &bytes).unwrap(),
            Err(_) => striped(128, 1),
        };
        let field = constant_field(side * side, Vec3::X);
        let p = TextureOptimizationParams::default();
        let t = std::time::Instant::now();
        let out = synth(&mesh, &field, &ex, None, &p);
        eprintln!(
            "{} vertices, {}×{} exemplar, unconstrained: {:?}, {:?}",
            side * side,
            ex.width,
            ex.height,
            t.elapsed(),
            out.stats
        );
        preview("crinkle-100k", &as_image(&out.colours, side));
        let (lex, td) = lined(128);
        let curve: Vec<u32> = (0..side as u32).map(|x| 158 * side as u32 + x).collect();
        let t = std::time::Instant::now();
        let d = curve_distance(&mesh, &curve);
        let td_time = t.elapsed();
        let t = std::time::Instant::now();
        let out = synth(
            &mesh,
            &field,
            &lex,
            Some(FeatureConstraint {
                curve_distance: &d,
                texture_distance: &td,
            }),
            &p,
        );
        eprintln!(
            "constrained: curve distance {td_time:?}, synthesis {:?}, {:?}",
            t.elapsed(),
            out.stats
        );
        preview("lines-100k", &as_image(&out.colours, side));
    }
}
