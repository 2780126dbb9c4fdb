//! Matching one texel (§4.2–§4.3): its variant choice, the gathering of its template across
//! cuts, the candidates (k-coherent, shifted by the surface metric, or the kd-tree's nearest)
//! and the copy of the winner into the level.

use super::grid::quarter_turn;
use super::level::{
    Ctx, Level, MAX_CHANNELS, STREAM_BLOCK, STREAM_FALLBACK, STREAM_ORIENT, STREAM_SCALE, Scratch,
    Src, choice_index, pack_src,
};
use super::params::Search;
use crate::analyse_exemplar::texel_variants::{Template, coarse_window};
use crate::random::{counter_hash, counter_unit};
use glam::Vec2;

/// The texels of a `w × h` variant level (with a `cw × ch` coarser level, if any) whose whole
/// template lies inside, as inclusive ranges `[x_lo, x_hi, y_lo, y_hi]` (as the analysis'
/// candidates).
pub(super) fn valid_range(
    kind: Template,
    side: u32,
    w: u32,
    h: u32,
    coarse: Option<(u32, u32)>,
) -> [i64; 4] {
    let r = (side / 2) as i64;
    let (w, h) = (w as i64, h as i64);
    let mut b = [
        r,
        w - 1 - r,
        r,
        match kind {
            Template::Causal => h - 1,
            Template::Full => h - 1 - r,
        },
    ];
    if let Some((cw, ch)) = coarse {
        let rc = (coarse_window(side) / 2) as i64;
        b[0] = b[0].max(2 * rc);
        b[1] = b[1].min(2 * (cw as i64 - 1 - rc) + 1);
        b[2] = b[2].max(2 * rc);
        b[3] = b[3].min(2 * (ch as i64 - 1 - rc) + 1);
    }
    b
}

/// The value at grid offset `g` (fractional, `x` = columns) from `(i, j)`, interpolated
/// bilinearly between the four grid points around it, each read by `at(i, j)`.
#[inline]
pub(super) fn bilinear(
    g: Vec2,
    i: i64,
    j: i64,
    at: &impl Fn(i64, i64) -> [f32; MAX_CHANNELS],
) -> [f32; MAX_CHANNELS] {
    let (x0, y0) = (g.x.floor(), g.y.floor());
    let (fx, fy) = (g.x - x0, g.y - y0);
    let (bi, bj) = (i + y0 as i64, j + x0 as i64);
    let mut out = [0.0f32; MAX_CHANNELS];
    for (di, dj, w) in [
        (0, 0, (1.0 - fx) * (1.0 - fy)),
        (0, 1, fx * (1.0 - fy)),
        (1, 0, (1.0 - fx) * fy),
        (1, 1, fx * fy),
    ] {
        if w > 0.0 {
            let px = at(bi + di, bj + dj);
            for (o, p) in out.iter_mut().zip(px) {
                *o += w * p;
            }
        }
    }
    out
}

impl Ctx<'_, '_> {
    /// Variant for texel `t` of `level` in `pass` (§4.3).
    #[inline]
    pub(super) fn choose(&self, lv: &Level, level: usize, pass: u32, t: usize) -> usize {
        // Orientation: one random number per texel. Scale: one per cell of a jittered grid of
        // spacing `block` (each texel takes the cell whose jittered centre is nearest), so
        // neighbouring texels mostly match at the same scale.
        let n = lv.grid.n as i64;
        let b = self.block.max(1) as i64;
        let (i, j) = (t as i64 / n, t as i64 % n);
        let (ci, cj) = (i.div_euclid(b), j.div_euclid(b));
        let cells = n / b + 3;
        let mut best = (i64::MAX, 0u64);
        for di in -1..=1 {
            for dj in -1..=1 {
                let (gi, gj) = (ci + di, cj + dj);
                let cell = ((gi + 1) * cells + gj + 1) as u64;
                let h = counter_hash(
                    self.seed,
                    STREAM_BLOCK,
                    choice_index(level, pass, cell as usize),
                );
                let pi = gi * b + (h % b as u64) as i64;
                let pj = gj * b + ((h >> 32) % b as u64) as i64;
                let d = (pi - i).pow(2) + (pj - j).pow(2);
                if d < best.0 {
                    best = (d, cell);
                }
            }
        }
        let key = choice_index(level, pass, best.1 as usize);
        let f = lv.orient[t];
        let k0 = f.floor();
        let u = counter_unit(self.seed, STREAM_ORIENT, choice_index(level, pass, t));
        let k = (if u < 1.0 - (f - k0) {
            k0 as usize
        } else {
            k0 as usize + 1
        }) % self.orientations;
        let s = lv.scale[t];
        let s0 = s.floor();
        let u = counter_unit(self.seed, STREAM_SCALE, key);
        let sc = if u < 1.0 - (s - s0) {
            s0 as usize
        } else {
            (s0 as usize + 1).min(self.scales - 1)
        };
        self.variants.variant(sc, k)
    }

    /// The raw feature vector of texel `(i, j)` of `levels[l]` (taps `taps`, and `ctaps` one
    /// level coarser if there is one), as the variants' features are built, into `raw`.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn gather(
        &self,
        levels: &[Level],
        l: usize,
        taps: &[(i32, i32)],
        ctaps: &[(i32, i32)],
        i: i64,
        j: i64,
        outside_from_init: bool,
        raw: &mut Vec<f32>,
    ) {
        let c = self.channels;
        raw.clear();
        let read = |data: &[f32], k: usize, r: u8| {
            let mut px = [0.0f32; MAX_CHANNELS];
            px[..c].copy_from_slice(&data[k * c..(k + 1) * c]);
            if r != 0 {
                quarter_turn(r, &mut px);
            }
            px
        };
        let push = |px: [f32; MAX_CHANNELS], raw: &mut Vec<f32>| {
            for ch in 0..c {
                raw.push(px[ch] * self.weights[ch]);
            }
        };
        let lv = &levels[l];
        let t = lv.grid.idx(i, j);
        let metric = lv.metric.get(t);
        // The value at grid point (ti, tj) of the level being synthesized.
        let at = |ti: i64, tj: i64| {
            let (k, r, outside) = lv.grid.locate(ti, tj);
            let src = if outside_from_init && self.reads_init(i, j, ti, tj, outside) {
                &lv.init
            } else {
                &lv.data
            };
            read(src, k, r)
        };
        for &tap in taps {
            match metric {
                // With the surface metric a tap falls between grid points: bilinear, or the
                // nearest grid point.
                Some(m) if self.nearest_taps => {
                    let (dx, dy) = m.to_grid(tap);
                    push(at(i + dy as i64, j + dx as i64), raw)
                }
                Some(m) => push(bilinear(m.to_grid_f(tap), i, j, &at), raw),
                None => push(at(i + tap.1 as i64, j + tap.0 as i64), raw),
            }
        }
        if let Some(cl) = levels.get(l + 1) {
            // The coarser level is finished: read it as it is, across cuts too.
            let (ci, cj) = (i >> 1, j >> 1);
            let start = raw.len();
            let at = |ti: i64, tj: i64| {
                let (k, r, _) = cl.grid.locate(ti, tj);
                read(&cl.data, k, r)
            };
            for &tap in ctaps {
                match metric {
                    Some(m) if self.nearest_taps => {
                        let (dx, dy) = m.to_grid(tap);
                        push(at(ci + dy as i64, cj + dx as i64), raw)
                    }
                    Some(m) => push(bilinear(m.to_grid_f(tap), ci, cj, &at), raw),
                    None => push(at(ci + tap.1 as i64, cj + tap.0 as i64), raw),
                }
            }
            for v in &mut raw[start..] {
                *v *= self.coarse_weight;
            }
        }
    }

    /// The synthesized value of texel `(i, j)` of `levels[l]` with template `kind`, written to
    /// `out` (in the texel's grid axes); returns where it was copied from ([`pack_src`]).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn synthesize_texel(
        &self,
        levels: &[Level],
        l: usize,
        pass: u32,
        kind: Template,
        taps: &[(i32, i32)],
        ctaps: &[(i32, i32)],
        i: i64,
        j: i64,
        scratch: &mut Scratch,
        out: &mut [f32],
    ) -> Src {
        let c = self.channels;
        let lv = &levels[l];
        let t = lv.grid.idx(i, j);
        let v = self.choose(lv, l, pass, t);
        // The scanline pass reads outside taps from the level's starting values, so no texel
        // depends on one synthesized later (and the wavefront order stays exact); boundary
        // resynthesis reads the current values across the cuts.
        let from_init = kind == Template::Causal;
        self.gather(levels, l, taps, ctaps, i, j, from_init, &mut scratch.raw);
        let level_img = self.variants.level(v, l);
        let (k, frac) = match self.search {
            Search::PerTexel => {
                let set = self.variants.set(v, l, kind);
                debug_assert_eq!(scratch.raw.len(), set.dim_in);
                scratch.reduced.resize(set.dims, 0.0);
                set.project(&scratch.raw, &mut scratch.reduced);
                let (id, _) = set
                    .tree
                    .nearest1_approx(&scratch.reduced, self.eps, &mut scratch.search)
                    .expect("feature sets are never empty");
                (set.centres[id as usize] as usize, [0.0; 2])
            }
            Search::KCoherence => {
                self.coherent_match(levels, l, pass, kind, taps, ctaps, i, j, v, scratch)
            }
        };
        out[..c].copy_from_slice(&level_img.texels[k * c..(k + 1) * c]);
        if self.subtexel && frac != [0.0; 2] {
            // The value at the continuous source position, bilinear between the four texels
            // around it (clamped inside the level).
            let (w, h) = (level_img.width as i64, level_img.height as i64);
            let (x, y) = (
                (k as i64 % w) as f32 + frac[0],
                (k as i64 / w) as f32 + frac[1],
            );
            let (x0, y0) = (x.floor(), y.floor());
            let (fx, fy) = (x - x0, y - y0);
            let mut acc = [0.0f32; MAX_CHANNELS];
            for (dx, dy, wt) in [
                (0, 0, (1.0 - fx) * (1.0 - fy)),
                (1, 0, fx * (1.0 - fy)),
                (0, 1, (1.0 - fx) * fy),
                (1, 1, fx * fy),
            ] {
                let xi = (x0 as i64 + dx).clamp(0, w - 1);
                let yi = (y0 as i64 + dy).clamp(0, h - 1);
                let q = (yi * w + xi) as usize * c;
                for ch in 0..c {
                    acc[ch] += wt * level_img.texels[q + ch];
                }
            }
            out[..c].copy_from_slice(&acc[..c]);
        }
        Src {
            packed: pack_src(v, k),
            frac,
        }
    }

    /// Rounds a point of level `l` of variant `v` to a texel index inside `range`.
    #[inline]
    pub(super) fn texel_in(range: &[i64; 4], w: u32, q: [f64; 2]) -> Option<u32> {
        let (x, y) = ((q[0] + 0.5).floor() as i64, (q[1] + 0.5).floor() as i64);
        (x >= range[0] && x <= range[1] && y >= range[2] && y <= range[3])
            .then(|| (y * w as i64 + x) as u32)
    }

    /// The k-coherence match of texel `(i, j)` of `levels[l]` in variant `v` (see the module
    /// docs): the candidate of least template distance to the gathered `scratch.raw`, as a
    /// texel index of the variant's level.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn coherent_match(
        &self,
        levels: &[Level],
        l: usize,
        pass: u32,
        kind: Template,
        taps: &[(i32, i32)],
        ctaps: &[(i32, i32)],
        i: i64,
        j: i64,
        v: usize,
        scratch: &mut Scratch,
    ) -> (usize, [f32; 2]) {
        let vars = self.variants;
        let nl = vars.levels();
        let lv = &levels[l];
        let img = vars.level(v, l);
        let coarser = (l + 1 < nl).then(|| vars.level(v, l + 1));
        let side = match kind {
            Template::Causal => vars.params().template,
            Template::Full => vars.params().boundary_template,
        };
        let range = valid_range(
            kind,
            side,
            img.width,
            img.height,
            coarser.map(|cl| (cl.width, cl.height)),
        );
        let nlv = nl;
        let map_v = &self.maps[v * nlv + l];
        let kl = vars.kset_level_of(v, l);
        let ks = vars.kset(kl);
        let kscale = (1u64 << kl) as f64;
        let kk = vars.coherent_k();
        // Hertzmann et al.'s level scaling of κ: coarser levels jump more freely, so the
        // coarse layout keeps the sample's statistics rather than the first texels' copies.
        let jump_factor = (1.0 + self.coherence / (1u32 << l) as f32).powi(2);
        let cands = &mut scratch.candidates;
        cands.clear();
        let keep_frac = !lv.metric.is_empty();
        // The texel itself (its prediction from the coarser level, or its value before this
        // pass) and each synthesized neighbour inside the square: their source, shifted back by
        // the neighbour's offset.
        let own = std::iter::once((0i32, 0i32));
        let t = lv.grid.idx(i, j);
        for tap in own.chain(taps.iter().copied()) {
            let (dx, dy) = lv.tap_offset(t, tap);
            // Across a cut whose sides share their axes (a quarter turn of 0) the shift holds
            // too; across a turning cut it would need the turned variant, so those taps bring
            // none. Outside taps of the scanline pass are read from the starting values (see
            // `gather`), and so are their sources.
            let (ti, tj) = (i + dy as i64, j + dx as i64);
            let (k, r, outside) = lv.grid.locate(ti, tj);
            if r != 0 {
                continue;
            }
            let src = if kind == Template::Causal && self.reads_init(i, j, ti, tj, outside) {
                lv.init_src[k]
            } else {
                lv.src[k]
            };
            let (sv, sk) = (
                (src.packed >> 32) as usize,
                (src.packed & 0xFFFF_FFFF) as u32,
            );
            let sw = vars.level(sv, l).width;
            let shift = lv.sample_shift(t, (dx, dy));
            let q = [
                (sk % sw) as f64 + src.frac[0] as f64 - shift[0],
                (sk / sw) as f64 + src.frac[1] as f64 - shift[1],
            ];
            let q = if sv == v {
                q
            } else {
                // Another variant: the same point of the sample, in this variant's texels.
                map_v.from_sample(self.maps[sv * nlv + l].to_sample(q))
            };
            if let Some(id) = Self::texel_in(&range, img.width, q) {
                // The remainder is kept with the surface metric only: without it every shift
                // is whole texels within a variant, and the paper's rounding across variants
                // stays as it was.
                let frac = if keep_frac {
                    [q[0] - (q[0] + 0.5).floor(), q[1] - (q[1] + 0.5).floor()].map(|f| f as f32)
                } else {
                    [0.0; 2]
                };
                cands.push(((id as u64) << 1, frac));
            }
            // Its k-coherent set, through the sample level matching this variant's level.
            let x0 = map_v.to_sample(q);
            let (kx, ky) = (
                ((x0[0] / kscale + 0.5).floor() as i64).clamp(0, ks.width as i64 - 1),
                ((x0[1] / kscale + 0.5).floor() as i64).clamp(0, ks.height as i64 - 1),
            );
            let at = (ky * ks.width as i64 + kx) as usize * kk;
            for &e in &ks.entries[at..at + kk] {
                if e == u32::MAX {
                    continue;
                }
                let ex = [
                    (e % ks.width) as f64 * kscale,
                    (e / ks.width) as f64 * kscale,
                ];
                if let Some(id) = Self::texel_in(&range, img.width, map_v.from_sample(ex)) {
                    cands.push((((id as u64) << 1) | 1, [0.0; 2]));
                }
            }
        }
        // By texel, a shifted candidate before a k-coherent one of the same texel, which then
        // goes.
        cands.sort_unstable_by(|a, b| {
            a.0.cmp(&b.0)
                .then(a.1[0].total_cmp(&b.1[0]))
                .then(a.1[1].total_cmp(&b.1[1]))
        });
        cands.dedup_by(|b, a| a.0 >> 1 == b.0 >> 1);
        if cands.is_empty() && !(l + 1 == nl && kind == Template::Causal) {
            // Nothing coherent lies inside the variant: a random texel whose template does.
            let h = counter_hash(
                self.seed,
                STREAM_FALLBACK,
                choice_index(l, pass, lv.grid.idx(i, j)),
            );
            let nx = (range[1] - range[0] + 1) as u64;
            let ny = (range[3] - range[2] + 1) as u64;
            let x = range[0] + (h % nx) as i64;
            let y = range[2] + ((h >> 32) % ny) as i64;
            return ((y * img.width as i64 + x) as usize, [0.0; 2]);
        }
        let c = self.channels;
        let query = &scratch.raw;
        let w = img.width as i64;
        // Squared template distance of the texel at (x, y), or a value ≥ `bound` once the
        // partial sum reaches it.
        let dist = |x: i64, y: i64, bound: f32| -> f32 {
            let mut d = 0.0f32;
            let mut o = 0;
            for &(dx, dy) in taps {
                let k = ((y + dy as i64) * w + x + dx as i64) as usize * c;
                for ch in 0..c {
                    let e = img.texels[k + ch] * self.weights[ch] - query[o + ch];
                    d += e * e;
                }
                o += c;
                if d >= bound {
                    return d;
                }
            }
            if let Some(cl) = coarser {
                let (cx, cy) = (x / 2, y / 2);
                for &(dx, dy) in ctaps {
                    let k = ((cy + dy as i64) * cl.width as i64 + cx + dx as i64) as usize * c;
                    for ch in 0..c {
                        let e = cl.texels[k + ch] * self.weights[ch] * self.coarse_weight
                            - query[o + ch];
                        d += e * e;
                    }
                    o += c;
                }
            }
            d
        };
        if l + 1 == nl && kind == Template::Causal {
            // The coarsest level's scanline pass lays out the whole texture, and coherent
            // candidates there only propagate the random start: every texel of the variant is
            // a candidate (the coarsest levels are small).
            let mut best = (f32::INFINITY, 0i64);
            for y in range[2]..=range[3] {
                for x in range[0]..=range[1] {
                    let d = dist(x, y, best.0);
                    if d < best.0 {
                        best = (d, y * w + x);
                    }
                }
            }
            return (best.1 as usize, [0.0; 2]);
        }
        let mut best = (f32::INFINITY, (cands[0].0 >> 1) as u32, cands[0].1);
        for &(cand, frac) in cands.iter() {
            // Jumps to a k-coherent texel must be (1 + coherence) times better than a shifted
            // candidate (Hertzmann et al. 2001's κ), as squared distances.
            let scale = if cand & 1 == 1 { jump_factor } else { 1.0 };
            let cand = (cand >> 1) as u32;
            let (x, y) = ((cand % img.width) as i64, (cand / img.width) as i64);
            let d = dist(x, y, best.0 / scale) * scale;
            if d < best.0 {
                best = (d, cand, frac);
            }
        }
        (best.1 as usize, best.2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analyse_exemplar::texel_variants::{coarse_taps, template_taps};
    use crate::geom::geometry_image::TexelImage;
    use crate::synthesize::geometry_texture::grid::LevelGrid;

    #[test]
    fn destination_features_equal_the_sample_features_where_the_images_agree() {
        use crate::analyse_exemplar::texel_variants::{TexelVariantParams, build_texel_variants};
        // A 33×33 sample is itself a valid 2-level destination: the pyramids coincide, so each
        // candidate's gathered feature must be found at distance 0, at itself.
        let n = 33usize;
        let mut sample = TexelImage::new(n as u32, n as u32, 3);
        for (k, v) in sample.data.iter_mut().enumerate() {
            *v = counter_unit(3, 0, k as u64);
        }
        for template in [3u32, 5, 7] {
            let vp = TexelVariantParams {
                orientations: 1,
                scales: 1,
                levels: 2,
                template,
                boundary_template: template,
                ..Default::default()
            };
            let owned = build_texel_variants(&sample, &vp, &|_| {}).unwrap();
            let vr = owned.as_ref();
            let levels: Vec<Level> = (0..2)
                .map(|l| {
                    let lev = vr.level(0, l);
                    let m = lev.width as usize;
                    Level {
                        grid: LevelGrid::build(m, (0..(m * m) as u32).collect(), 2),
                        data: lev.texels.to_vec(),
                        init: lev.texels.to_vec(),
                        orient: vec![0.0; m * m],
                        scale: vec![0.0; m * m],
                        src: vec![Src::default(); m * m],
                        init_src: vec![Src::default(); m * m],
                        metric: Vec::new(),
                    }
                })
                .collect();
            let ctx = Ctx {
                variants: &vr,
                channels: 3,
                weights: &vr.meta.channel_weights,
                coarse_weight: vr.params().coarse_weight,
                seed: 0,
                eps: 0.0,
                orientations: 1,
                scales: 1,
                block: 5,
                search: Search::PerTexel,
                coherence: 0.0,
                nearest_taps: false,
                subtexel: false,
                wave: (template / 2) as i64 + 1,
                maps: vec![vr.sample_map(0, 0), vr.sample_map(0, 1)],
            };
            for kind in [Template::Causal, Template::Full] {
                let taps = template_taps(kind, template);
                let ctaps = coarse_taps(template);
                for l in 0..2 {
                    let set = vr.set(0, l, kind);
                    let m = levels[l].grid.n;
                    let mut raw = Vec::new();
                    let mut red = vec![0.0; set.dims];
                    let mut scratch = Vec::new();
                    for (id, &centre) in set.centres.iter().enumerate() {
                        let (i, j) = ((centre as usize / m) as i64, (centre as usize % m) as i64);
                        ctx.gather(&levels, l, &taps, &ctaps, i, j, true, &mut raw);
                        set.project(&raw, &mut red);
                        let (got, d) = set.tree.nearest1_approx(&red, 0.0, &mut scratch).unwrap();
                        assert_eq!(d, 0.0, "template {template} {kind:?} level {l} ({i}, {j})");
                        assert_eq!(got as usize, id);
                    }
                }
            }
        }
    }
}
