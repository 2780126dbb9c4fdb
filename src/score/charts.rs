//! Scoring the jump-map method (Zelinka & Garland, §4.3–4.4): its blended surface in
//! texture space, and its coordinate seams.
//!
//! **Texture-space charts.** The baked atlas (`baked_basecolor.png`) lays each triangle with
//! its longest edge horizontal and at the atlas's own scale, so its patches are rotated and
//! rescaled against the exemplar's, and a nearest-patch distance would mostly measure that.
//! Instead each triangle is rasterized at one texel per exemplar texel in the frame of its
//! own coordinate set (the set the OBJ export uses, `random_base_set`), so that its texture
//! is upright and at the exemplar's scale, and coloured with the §4.4 blend of the three
//! corner sets (the `BlendShader` the bake uses). Triangles are packed on a canvas one texel
//! apart and only texels whose centre is inside a triangle are in the mask: a scored patch
//! lies wholly inside one triangle (`patch_score_masked`). Triangles smaller than a patch do
//! not count, so on a finely tessellated mesh few or no patches are scored (reported).
//!
//! **Seams.** Where two triangles that share an edge have different coordinates for its
//! ends (a coordinate seam), the OBJ shows the exemplar at two places side by side. The seam
//! score samples both sides' exemplar colour at 8 points along each seam edge (RMS over RGB)
//! and divides the mean by the same measure with the second side placed at a seeded random
//! position in the exemplar ("randomly placed triangles"): 0 means invisible seams, 1 seams as
//! visible as pasting unrelated pieces together.

use super::{Item, Run, ScoreFailure};
use crate::artifact::jump_maps::{JumpParameterization, TexelAddresses};
use crate::geom::Mesh;
use crate::image::{Image, ImageView};
use crate::random::counter_unit;
use crate::stages::reconstruct::jump_blend::{BlendShader, corner_sets, random_base_set};
use glam::{Vec2, Vec3};
use std::collections::HashMap;

/// Most texels of the charts' canvas; triangles past it are left out (reported).
const MAX_CANVAS_TEXELS: usize = 16 << 20;
/// Width of the charts' canvas.
const CANVAS_WIDTH: usize = 2048;
/// Samples along each seam edge.
const SEAM_SAMPLES: usize = 8;
const STREAM_SEAM_X: u64 = 0x5ea0_0001;
const STREAM_SEAM_Y: u64 = 0x5ea0_0002;

pub(crate) fn jump_maps(run: &Run) -> Result<Vec<Item>, ScoreFailure> {
    let mesh = run.view::<Mesh>("import.mesh")?;
    let param = run.view::<JumpParameterization>("parameterize")?;
    let walk = run.view::<TexelAddresses>("synthesize")?;
    let ex = run.view::<Image>("import.exemplar")?;
    let sets = corner_sets(&mesh.triangles, &param, walk.addresses)
        .map_err(|e| ScoreFailure::new(format!("internal error: {e}")))?;
    let single = random_base_set(&sets);
    let shader = BlendShader {
        sets: &sets,
        texture: ex,
    };
    let charts = texture_space_charts(&single, |f, b| shader.rgba(f, b));
    let mut item = Item::new(
        "the blended surface in texture space (each triangle upright at the exemplar's scale)",
        "inputs.exemplar",
    );
    item.extra.insert(
        "triangles_charted".into(),
        serde_json::json!(charts.charted),
    );
    if charts.charted < single.len() {
        item.notes.push(format!(
            "{} of {} triangles fit the {}-texel canvas",
            charts.charted,
            single.len(),
            MAX_CANVAS_TEXELS
        ));
    }
    run.score_into(
        &mut item,
        charts.image.view(),
        Some(&charts.mask),
        ex,
    )?;
    let seams = seam_score(&mesh.triangles, &single, ex, run.params.seed);
    item.extra.insert(
        "seams".into(),
        serde_json::to_value(&seams).expect("plain numbers"),
    );
    Ok(vec![item])
}

/// Triangles rasterized in their own texel coordinates and packed on one canvas.
pub struct Charts {
    pub image: Image,
    /// Texels whose centre lies in a triangle.
    pub mask: Vec<bool>,
    /// Triangles placed (the first ones, in order, that fit [`MAX_CANVAS_TEXELS`]).
    pub charted: usize,
}

/// Rasterizes every triangle `f` (corner coordinates `coords[f]`, in texels) at one canvas
/// texel per unit, coloured by `colour(f, barycentrics)`, packed in rows (shelves) one texel
/// apart, in face order.
pub fn texture_space_charts(
    coords: &[[Vec2; 3]],
    colour: impl Fn(usize, Vec3) -> [f32; 4] + Sync,
) -> Charts {
    // Shelf packing of the triangles' texel bounding boxes.
    let mut places: Vec<(usize, Vec2, usize, usize, usize, usize)> = Vec::new();
    let (mut x, mut y, mut row_h) = (0usize, 0usize, 0usize);
    for (f, c) in coords.iter().enumerate() {
        if c.iter().any(|p| !p.is_finite()) {
            continue;
        }
        let lo = c[0].min(c[1]).min(c[2]).floor();
        let hi = c[0].max(c[1]).max(c[2]).ceil();
        let (w, h) = ((hi.x - lo.x) as usize, (hi.y - lo.y) as usize);
        if w == 0 || h == 0 || w > CANVAS_WIDTH {
            continue;
        }
        if x + w > CANVAS_WIDTH {
            x = 0;
            y += row_h + 1;
            row_h = 0;
        }
        if (y + h) * CANVAS_WIDTH > MAX_CANVAS_TEXELS {
            break;
        }
        places.push((f, lo, x, y, w, h));
        x += w + 1;
        row_h = row_h.max(h);
    }
    let height = (y + row_h).max(1);
    let mut pixels = vec![[0.0f32; 4]; CANVAS_WIDTH * height];
    let mut mask = vec![false; CANVAS_WIDTH * height];
    for &(f, lo, x0, y0, w, h) in &places {
        let [a, b, c] = coords[f];
        let (e1, e2) = (b - a, c - a);
        let det = e1.perp_dot(e2);
        if det.abs() < 1e-12 {
            continue;
        }
        for j in 0..h {
            for i in 0..w {
                let p = lo + Vec2::new(i as f32 + 0.5, j as f32 + 0.5) - a;
                let u = p.perp_dot(e2) / det;
                let v = e1.perp_dot(p) / det;
                let bary = Vec3::new(1.0 - u - v, u, v);
                if bary.min_element() < 0.0 {
                    continue;
                }
                let k = (y0 + j) * CANVAS_WIDTH + x0 + i;
                pixels[k] = colour(f, bary);
                mask[k] = true;
            }
        }
    }
    Charts {
        image: Image {
            width: CANVAS_WIDTH as u32,
            height: height as u32,
            pixels,
        },
        mask,
        charted: places.len(),
    }
}

/// How visible coordinate seams are; see the module doc.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SeamScore {
    /// Seam edge colour difference over the random placement's (0 = invisible).
    pub ratio: f64,
    /// Mean RMS colour difference across seam edges.
    pub seam_rms: f64,
    /// The same with one side placed at random.
    pub random_rms: f64,
    /// Interior edges whose two triangles disagree on the coordinates of its ends.
    pub seam_edges: usize,
    pub interior_edges: usize,
}

/// The seam score of a mesh whose triangle `f` has corner texel coordinates `coords[f]` into
/// `ex`.
pub fn seam_score(triangles: &[[u32; 3]], coords: &[[Vec2; 3]], ex: ImageView, seed: u64) -> SeamScore {
    let mut first: HashMap<(u32, u32), (usize, usize)> = HashMap::new();
    let mut pairs = Vec::new();
    for (f, t) in triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let key = (a.min(b), a.max(b));
            match first.get(&key) {
                None => {
                    first.insert(key, (f, k));
                }
                Some(&(g, m)) => pairs.push(((f, k), (g, m))),
            }
        }
    }
    let corner = |f: usize, v: u32| -> Vec2 {
        let i = triangles[f].iter().position(|&x| x == v).expect("edge of the face");
        coords[f][i]
    };
    let (w, h) = (ex.width as f32, ex.height as f32);
    let (mut seam, mut random, mut seams) = (0.0f64, 0.0f64, 0usize);
    for &((f, k), (g, _)) in &pairs {
        let (a, b) = (triangles[f][k], triangles[f][(k + 1) % 3]);
        let (fa, fb) = (corner(f, a), corner(f, b));
        let (ga, gb) = (corner(g, a), corner(g, b));
        if fa.distance(ga) < 1e-3 && fb.distance(gb) < 1e-3 {
            continue;
        }
        // The random placement: g's side moved so its midpoint falls at a seeded point.
        let r = Vec2::new(
            counter_unit(seed, STREAM_SEAM_X, seams as u64) * w,
            counter_unit(seed, STREAM_SEAM_Y, seams as u64) * h,
        ) - (ga + gb) * 0.5;
        seams += 1;
        for s in 0..SEAM_SAMPLES {
            let t = (s as f32 + 0.5) / SEAM_SAMPLES as f32;
            let cf = bilinear(ex, fa.lerp(fb, t));
            let cg = bilinear(ex, ga.lerp(gb, t));
            let cr = bilinear(ex, ga.lerp(gb, t) + r);
            seam += rms(cf, cg);
            random += rms(cf, cr);
        }
    }
    let n = (seams * SEAM_SAMPLES).max(1) as f64;
    let (seam_rms, random_rms) = (seam / n, random / n);
    SeamScore {
        ratio: if random_rms > 0.0 {
            seam_rms / random_rms
        } else {
            0.0
        },
        seam_rms,
        random_rms,
        seam_edges: seams,
        interior_edges: pairs.len(),
    }
}

fn rms(a: [f32; 3], b: [f32; 3]) -> f64 {
    let s: f64 = (0..3).map(|c| ((a[c] - b[c]) as f64).powi(2)).sum();
    (s / 3.0).sqrt()
}

/// RGB at texel coordinates `p` (texel centres at half-integers), clamped to the border and
/// to [0, 1].
pub fn bilinear(img: ImageView, p: Vec2) -> [f32; 3] {
    let q = p - Vec2::splat(0.5);
    let (x0, y0) = (q.x.floor(), q.y.floor());
    let (fx, fy) = (q.x - x0, q.y - y0);
    let (x0, y0) = (x0 as i64, y0 as i64);
    let at = |x: i64, y: i64| img.get_clamped(x, y);
    let mut out = [0.0f32; 3];
    let (p00, p10, p01, p11) = (at(x0, y0), at(x0 + 1, y0), at(x0, y0 + 1), at(x0 + 1, y0 + 1));
    for c in 0..3 {
        let top = p00[c] + (p10[c] - p00[c]) * fx;
        let bottom = p01[c] + (p11[c] - p01[c]) * fx;
        out[c] = (top + (bottom - top) * fy).clamp(0.0, 1.0);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two triangles of a unit square in texel units, scaled by `s`.
    fn square(s: f32, second_offset: Vec2) -> (Vec<[u32; 3]>, Vec<[Vec2; 3]>) {
        let p = |x: f32, y: f32| Vec2::new(x, y) * s + Vec2::splat(4.0);
        (
            vec![[0, 1, 2], [0, 2, 3]],
            vec![
                [p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0)],
                [
                    p(0.0, 0.0) + second_offset,
                    p(1.0, 1.0) + second_offset,
                    p(0.0, 1.0) + second_offset,
                ],
            ],
        )
    }

    fn stripes() -> Image {
        Image::from_fn(64, 64, |x, y| {
            let v = ((x * 7 + y * 3) % 11) as f32 / 10.0;
            [v, 1.0 - v, (y % 5) as f32 / 4.0, 1.0]
        })
    }

    #[test]
    fn continuous_coordinates_have_no_seam_and_jumps_do() {
        let ex = stripes();
        let (tris, coords) = square(20.0, Vec2::ZERO);
        let s = seam_score(&tris, &coords, ex.view(), 0);
        assert_eq!((s.seam_edges, s.interior_edges), (0, 1), "{s:?}");
        let (tris, coords) = square(20.0, Vec2::new(13.0, 5.0));
        let s = seam_score(&tris, &coords, ex.view(), 0);
        assert_eq!(s.seam_edges, 1, "{s:?}");
        assert!(s.seam_rms > 0.05 && s.ratio > 0.3, "{s:?}");
    }

    #[test]
    fn charts_copy_each_triangle_upright_and_mask_only_its_inside() {
        let ex = stripes();
        let (_, coords) = square(30.0, Vec2::ZERO);
        let c = texture_space_charts(&coords, |f, b| {
            let p = coords[f][0] * b.x + coords[f][1] * b.y + coords[f][2] * b.z;
            let [r, g, bl] = bilinear(ex.view(), p);
            [r, g, bl, 1.0]
        });
        assert_eq!(c.charted, 2);
        let inside = c.mask.iter().filter(|&&m| m).count();
        // Two right triangles of legs 30: about 450 texels each.
        assert!((inside as f32 - 900.0).abs() < 60.0, "{inside}");
        // Each chart is the exemplar, upright: patches inside it are verbatim.
        let s = crate::image::patch_score::patch_score_masked(
            c.image.view(),
            Some(&c.mask),
            ex.view(),
            &crate::image::patch_score::ScoreParams {
                patch: 5,
                ..Default::default()
            },
        )
        .unwrap();
        assert!(s.mean_rms < 1e-3, "{s:?}");
    }
}
