//! The built variant set: its metadata, the owned flat arrays ([`TexelVariants`]) and the
//! borrowed view over them ([`TexelVariantsRef`]) that checks every length and index, with the
//! per-variant, per-level and per-template-set accessors synthesis reads.

use super::params::{TexelVariantParams, VariantsError};
use super::resample::{orientation_cos_sin, resampling};
use super::templates::{Template, feature_dim};
use crate::image::knn::{KdNode, KdTreeRef};
use serde::{Deserialize, Serialize};

/// Size of one level of a variant pyramid.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LevelMeta {
    pub width: u32,
    pub height: u32,
    /// Offset into the `texels` array, in f32 values.
    pub texel_offset: u64,
}

/// One feature set (a template at one level of one variant): where its arrays lie.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SetMeta {
    /// Raw feature length and PCA components kept.
    pub dim_in: u32,
    pub dims: u32,
    /// Candidate texels; their level-texel indices are `centres[centre_offset..][..count]`
    /// and the tree's ids `tree_ids[centre_offset..][..count]`.
    pub count: u32,
    pub centre_offset: u64,
    /// Offsets of the PCA mean (`dim_in` values) and basis (`dims × dim_in`).
    pub mean_offset: u64,
    pub basis_offset: u64,
    /// Offset of the tree points (`count × dims` values).
    pub point_offset: u64,
    pub node_offset: u64,
    pub node_count: u64,
}

/// The small, serializable part of [`TexelVariants`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VariantsMeta {
    pub params: TexelVariantParams,
    pub channels: u32,
    /// Size of the sample the variants were made from.
    pub sample_width: u32,
    pub sample_height: u32,
    /// Per channel, the factor applied before features are compared.
    pub channel_weights: Vec<f32>,
    /// Per (variant, level), variant-major: `levels[v * levels + l]`. Variant `v` has scale
    /// `v / orientations` and orientation `v % orientations`.
    pub levels: Vec<LevelMeta>,
    /// Per (variant, level, template), `sets[(v * levels + l) * 2 + t]`, `t` 0 for the causal
    /// and 1 for the full template. Empty unless `per_texel`.
    pub sets: Vec<SetMeta>,
    /// Whether the per-texel search structures (PCA bases, kd-trees) were built.
    pub per_texel: bool,
    /// Whether the k-coherent sets were searched (else every entry is none).
    pub coherent: bool,
    /// Per level of the sample pyramid ([`TexelVariantParams::kset_levels`]), its size and
    /// where its k-coherent sets (`coherent_k` texel indices per texel) start in `kset`.
    pub ksets: Vec<LevelMeta>,
}

/// The variant set, owned: flat arrays described by [`VariantsMeta`].
#[derive(Clone, Debug, PartialEq)]
pub struct TexelVariants {
    pub meta: VariantsMeta,
    pub texels: Vec<f32>,
    pub centres: Vec<u32>,
    pub pca_mean: Vec<f32>,
    pub pca_basis: Vec<f32>,
    pub tree_points: Vec<f32>,
    pub tree_ids: Vec<u32>,
    pub tree_nodes: Vec<KdNode>,
    /// The k-coherent sets, see [`VariantsMeta::ksets`]; `u32::MAX` pads a set of a level with
    /// too few texels.
    pub kset: Vec<u32>,
}

/// Names of the arrays of [`TexelVariants::arrays`], in order.
pub const ARRAY_NAMES: [&str; 8] = [
    "texels",
    "centres",
    "pca_mean",
    "pca_basis",
    "tree_points",
    "tree_ids",
    "tree_nodes",
    "kset",
];

/// One level of the sample pyramid's k-coherent sets, borrowed.
#[derive(Clone, Copy, Debug)]
pub struct KsetRef<'a> {
    pub width: u32,
    pub height: u32,
    /// `k` texel indices (`y * width + x`) per texel, row-major; `u32::MAX` for none.
    pub entries: &'a [u32],
}

/// The affine map from a variant level's texel coordinates to the sample's level-0 texel
/// coordinates (`x0 = a · q + b`), and back.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleMap {
    pub a: [[f64; 2]; 2],
    pub b: [f64; 2],
    pub inv: [[f64; 2]; 2],
}

impl SampleMap {
    #[inline]
    pub fn to_sample(&self, q: [f64; 2]) -> [f64; 2] {
        let a = &self.a;
        [
            a[0][0] * q[0] + a[0][1] * q[1] + self.b[0],
            a[1][0] * q[0] + a[1][1] * q[1] + self.b[1],
        ]
    }

    #[inline]
    pub fn from_sample(&self, x: [f64; 2]) -> [f64; 2] {
        let (u, v) = (x[0] - self.b[0], x[1] - self.b[1]);
        let m = &self.inv;
        [m[0][0] * u + m[0][1] * v, m[1][0] * u + m[1][1] * v]
    }
}

/// One level of one variant, borrowed: `width × height` texels of `channels` values.
#[derive(Clone, Copy, Debug)]
pub struct LevelRef<'a> {
    pub width: u32,
    pub height: u32,
    pub texels: &'a [f32],
}

/// One feature set, borrowed.
#[derive(Clone, Copy, Debug)]
pub struct SetRef<'a> {
    pub dim_in: usize,
    pub dims: usize,
    /// Level-texel index (`y * width + x`) of each candidate.
    pub centres: &'a [u32],
    pub mean: &'a [f32],
    pub basis: &'a [f32],
    /// Over the PCA-reduced features; ids index `centres`.
    pub tree: KdTreeRef<'a>,
}

impl SetRef<'_> {
    /// PCA coordinates of a raw feature vector (as [`Pca::project`]).
    ///
    /// [`Pca::project`]: crate::image::pca::Pca::project
    #[inline]
    pub fn project(&self, v: &[f32], out: &mut [f32]) {
        debug_assert_eq!(v.len(), self.dim_in);
        for (o, b) in out.iter_mut().zip(self.basis.chunks_exact(self.dim_in)) {
            let mut acc = 0.0f32;
            for ((&x, &m), &e) in v.iter().zip(self.mean).zip(b) {
                acc += (x - m) * e;
            }
            *o = acc;
        }
    }
}

/// The variant set, borrowed (from a [`TexelVariants`] or a mapped artifact) and checked.
#[derive(Clone, Debug)]
pub struct TexelVariantsRef<'a> {
    pub meta: VariantsMeta,
    pub(super) levels: Vec<LevelRef<'a>>,
    pub(super) sets: Vec<SetRef<'a>>,
    pub(super) ksets: Vec<KsetRef<'a>>,
}

impl<'a> TexelVariantsRef<'a> {
    pub fn params(&self) -> &TexelVariantParams {
        &self.meta.params
    }

    pub fn channels(&self) -> usize {
        self.meta.channels as usize
    }

    /// Pyramid levels of every variant.
    pub fn levels(&self) -> usize {
        self.meta.params.levels as usize
    }

    pub fn variant_count(&self) -> usize {
        self.meta.params.variant_count()
    }

    /// Variant index of scale `scale` (0 = most enlarged) and orientation `orientation`.
    #[inline]
    pub fn variant(&self, scale: usize, orientation: usize) -> usize {
        scale * self.meta.params.orientations as usize + orientation
    }

    #[inline]
    pub fn level(&self, variant: usize, level: usize) -> LevelRef<'a> {
        self.levels[variant * self.levels() + level]
    }

    /// The per-texel feature set; `None` when the set was built without them
    /// (`meta.per_texel` false).
    #[inline]
    pub fn try_set(&self, variant: usize, level: usize, kind: Template) -> Option<&SetRef<'a>> {
        let t = match kind {
            Template::Causal => 0,
            Template::Full => 1,
        };
        self.sets.get((variant * self.levels() + level) * 2 + t)
    }

    /// As [`Self::try_set`]; panics without per-texel structures.
    #[inline]
    pub fn set(&self, variant: usize, level: usize, kind: Template) -> &SetRef<'a> {
        self.try_set(variant, level, kind)
            .expect("texel variants built without per-texel search structures")
    }

    /// The k-coherent sets of sample pyramid level `level`.
    #[inline]
    pub fn kset(&self, level: usize) -> &KsetRef<'a> {
        &self.ksets[level]
    }

    /// `k` of the k-coherent sets.
    pub fn coherent_k(&self) -> usize {
        self.meta.params.coherent_k as usize
    }

    /// Sample pyramid level matching level `level` of `variant` (see
    /// [`TexelVariantParams::kset_levels`]).
    pub fn kset_level_of(&self, variant: usize, level: usize) -> usize {
        let p = &self.meta.params;
        let s = variant / p.orientations as usize;
        (level + s)
            .saturating_sub(p.middle_scale())
            .min(p.kset_levels() - 1)
    }

    /// The map between level `level` of `variant` and the sample's level 0 (see
    /// [`resample_variant`]: the variant's level-0 texel `p` shows the source level's point
    /// `c + R(−θ) (p − h) / m`).
    ///
    /// [`resample_variant`]: super::resample_variant
    pub fn sample_map(&self, variant: usize, level: usize) -> SampleMap {
        let p = &self.meta.params;
        let (s, k) = (
            variant / p.orientations as usize,
            (variant % p.orientations as usize) as u32,
        );
        let rs = resampling(self.meta.sample_width, self.meta.sample_height, p, s, k);
        let (mut w, mut h) = (self.meta.sample_width, self.meta.sample_height);
        for _ in 0..rs.source_level {
            w = w.div_ceil(2);
            h = h.div_ceil(2);
        }
        let (cos, sin) = orientation_cos_sin(k, p.orientations);
        let f = (1u64 << rs.source_level) as f64;
        let g = (1u64 << level) as f64 / rs.magnification;
        let half = (rs.side as f64 - 1.0) / 2.0;
        let (cx, cy) = ((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
        // x0 = f (c + R(−θ) (g q − h (1, 1)) / 1) with R(−θ) = [[cos, sin], [−sin, cos]] and
        // g folding the level's spacing and the magnification.
        let a = [[f * g * cos, f * g * sin], [-f * g * sin, f * g * cos]];
        let hm = half / rs.magnification;
        let b = [
            f * (cx - (cos * hm + sin * hm)),
            f * (cy - (-sin * hm + cos * hm)),
        ];
        let ig = 1.0 / (f * g);
        let inv = [[ig * cos, -ig * sin], [ig * sin, ig * cos]];
        SampleMap { a, b, inv }
    }

    /// Views arrays exported by [`TexelVariants::arrays`]. `get` returns an array's bytes by
    /// name (`None` if absent); they must be aligned for their element type (artifact arrays
    /// are). Every size, offset and index is checked against the metadata, so damaged input is
    /// an error, never a panic or an out-of-bounds read during synthesis.
    pub fn from_arrays(
        meta: VariantsMeta,
        get: impl Fn(&str) -> Option<&'a [u8]>,
    ) -> Result<TexelVariantsRef<'a>, VariantsError> {
        use VariantsError as E;
        fn arr<'b, T: bytemuck::Pod>(
            get: &impl Fn(&str) -> Option<&'b [u8]>,
            name: &str,
        ) -> Result<&'b [T], VariantsError> {
            let raw = get(name).ok_or_else(|| E::NoArray { name: name.into() })?;
            bytemuck::try_cast_slice(raw).map_err(|e| E::Misaligned {
                name: name.into(),
                bytes: raw.len(),
                size: std::mem::size_of::<T>(),
                cause: e,
            })
        }
        fn sub<'b, T>(
            a: &'b [T],
            off: u64,
            len: u64,
            what: &str,
        ) -> Result<&'b [T], VariantsError> {
            let end = off.checked_add(len);
            match end {
                Some(e) if e <= a.len() as u64 => Ok(&a[off as usize..e as usize]),
                _ => Err(E::OutsideArray {
                    what: what.into(),
                    len,
                    off,
                    array_len: a.len(),
                }),
            }
        }
        meta.params.validate()?;
        let c = meta.channels;
        if c != 3 && c != 6 {
            return Err(E::MetaChannels { channels: c });
        }
        if meta.channel_weights.len() != c as usize
            || meta.channel_weights.iter().any(|w| !w.is_finite())
        {
            return Err(E::ChannelWeights);
        }
        let nv = meta.params.variant_count();
        let nl = meta.params.levels as usize;
        let want_sets = if meta.per_texel { nv * nl * 2 } else { 0 };
        if meta.levels.len() != nv * nl || meta.sets.len() != want_sets {
            return Err(E::MetaCounts {
                levels: meta.levels.len(),
                sets: meta.sets.len(),
                want_levels: nv * nl,
                want_sets,
            });
        }
        if meta.ksets.len() != meta.params.kset_levels() {
            return Err(E::Layout {
                what: "the k-coherent set levels".into(),
            });
        }
        let texels: &[f32] = arr(&get, "texels")?;
        let centres: &[u32] = arr(&get, "centres")?;
        let pca_mean: &[f32] = arr(&get, "pca_mean")?;
        let pca_basis: &[f32] = arr(&get, "pca_basis")?;
        let tree_points: &[f32] = arr(&get, "tree_points")?;
        let tree_ids: &[u32] = arr(&get, "tree_ids")?;
        let tree_nodes: &[KdNode] = arr(&get, "tree_nodes")?;
        let kset: &[u32] = arr(&get, "kset")?;
        // The layout is the canonical one (arrays concatenated in order, nothing between or
        // after), so a metadata entry that disagrees with its neighbours is caught.
        let layout_err = |what: &str| E::Layout { what: what.into() };
        let mut next_texel = 0u64;
        let mut levels = Vec::with_capacity(meta.levels.len());
        for (i, lm) in meta.levels.iter().enumerate() {
            let n = lm.width as u64 * lm.height as u64 * c as u64;
            if lm.texel_offset != next_texel {
                return Err(layout_err(&format!("level {i}")));
            }
            next_texel += n;
            let t = sub(texels, lm.texel_offset, n, &format!("level {i}"))?;
            levels.push(LevelRef {
                width: lm.width,
                height: lm.height,
                texels: t,
            });
        }
        if next_texel != texels.len() as u64 {
            return Err(layout_err("the end of the texels"));
        }
        let mut next = [0u64; 5]; // centres/ids, mean, basis, points, nodes
        let mut sets = Vec::with_capacity(meta.sets.len());
        for (i, sm) in meta.sets.iter().enumerate() {
            let vl = i / 2;
            let kind = if i % 2 == 0 {
                Template::Causal
            } else {
                Template::Full
            };
            let side = match kind {
                Template::Causal => meta.params.template,
                Template::Full => meta.params.boundary_template,
            };
            let with_coarse = vl % nl + 1 < nl;
            let want = feature_dim(kind, side, with_coarse, c);
            let what = format!("feature set {i}");
            if sm.dim_in as usize != want || sm.dims == 0 || sm.dims > sm.dim_in || sm.count == 0 {
                return Err(E::SetDims {
                    what,
                    dim_in: sm.dim_in,
                    dims: sm.dims,
                    count: sm.count,
                    want,
                });
            }
            let offsets = [
                sm.centre_offset,
                sm.mean_offset,
                sm.basis_offset,
                sm.point_offset,
                sm.node_offset,
            ];
            if offsets != next {
                return Err(layout_err(&what));
            }
            next[0] += sm.count as u64;
            next[1] += sm.dim_in as u64;
            next[2] += sm.dims as u64 * sm.dim_in as u64;
            next[3] += sm.count as u64 * sm.dims as u64;
            next[4] += sm.node_count;
            let lv = levels[vl];
            let cs = sub(centres, sm.centre_offset, sm.count as u64, &what)?;
            let texel_count = lv.width * lv.height;
            if cs.iter().any(|&x| x >= texel_count) {
                return Err(E::CandidateOutside { what });
            }
            let ids = sub(tree_ids, sm.centre_offset, sm.count as u64, &what)?;
            let points = sub(
                tree_points,
                sm.point_offset,
                sm.count as u64 * sm.dims as u64,
                &what,
            )?;
            let nodes = sub(tree_nodes, sm.node_offset, sm.node_count, &what)?;
            let tree = KdTreeRef::from_parts(sm.dims as usize, points, ids, nodes, sm.count)
                .map_err(|e| E::Tree {
                    what: what.clone(),
                    cause: e,
                })?;
            sets.push(SetRef {
                dim_in: sm.dim_in as usize,
                dims: sm.dims as usize,
                centres: cs,
                mean: sub(pca_mean, sm.mean_offset, sm.dim_in as u64, &what)?,
                basis: sub(
                    pca_basis,
                    sm.basis_offset,
                    sm.dims as u64 * sm.dim_in as u64,
                    &what,
                )?,
                tree,
            });
        }
        let lens = [
            centres.len(),
            pca_mean.len(),
            pca_basis.len(),
            tree_points.len(),
            tree_nodes.len(),
        ];
        if next.iter().zip(lens).any(|(&a, b)| a != b as u64) || tree_ids.len() != centres.len() {
            return Err(layout_err("the end of the feature arrays"));
        }
        let k = meta.params.coherent_k as u64;
        let mut next_k = 0u64;
        let mut ksets = Vec::with_capacity(meta.ksets.len());
        for (i, km) in meta.ksets.iter().enumerate() {
            let count = km.width as u64 * km.height as u64;
            let what = format!("k-coherent sets of sample level {i}");
            if km.texel_offset != next_k {
                return Err(layout_err(&what));
            }
            next_k += count * k;
            let entries = sub(kset, km.texel_offset, count * k, &what)?;
            if entries.iter().any(|&e| e != u32::MAX && e as u64 >= count) {
                return Err(E::CandidateOutside { what });
            }
            ksets.push(KsetRef {
                width: km.width,
                height: km.height,
                entries,
            });
        }
        if next_k != kset.len() as u64 {
            return Err(layout_err("the end of the k-coherent sets"));
        }
        Ok(TexelVariantsRef {
            meta,
            levels,
            sets,
            ksets,
        })
    }
}

impl TexelVariants {
    /// The flat arrays, named as in [`ARRAY_NAMES`], as little-endian bytes.
    pub fn arrays(&self) -> Vec<(&'static str, &[u8])> {
        vec![
            ("texels", bytemuck::cast_slice(&self.texels)),
            ("centres", bytemuck::cast_slice(&self.centres)),
            ("pca_mean", bytemuck::cast_slice(&self.pca_mean)),
            ("pca_basis", bytemuck::cast_slice(&self.pca_basis)),
            ("tree_points", bytemuck::cast_slice(&self.tree_points)),
            ("tree_ids", bytemuck::cast_slice(&self.tree_ids)),
            ("tree_nodes", bytemuck::cast_slice(&self.tree_nodes)),
            ("kset", bytemuck::cast_slice(&self.kset)),
        ]
    }

    /// A checked borrowed view.
    pub fn as_ref(&self) -> TexelVariantsRef<'_> {
        let arrays = self.arrays();
        TexelVariantsRef::from_arrays(self.meta.clone(), |name| {
            arrays.iter().find(|(n, _)| *n == name).map(|(_, b)| *b)
        })
        .expect("freshly built texel variants are consistent")
    }
}
