//! Exemplar analysis for solid synthesis: Gaussian stacks, PCA-reduced neighbourhoods,
//! candidate triples and candidate slabs (Zhang, Du, Lai, Ni & Hu, "Sketch guided solid
//! texturing", §2 and §4; candidate triples after Dong, Lefebvre, Tong & Drettakis 2008, "Lazy
//! solid texture synthesis"; Gaussian stacks after Lefebvre & Hoppe 2005).
//!
//! # Planes, axes and triples
//!
//! Three exemplars `I_xy`, `I_yz`, `I_zx` (plane 0, 1, 2; one image may serve several) show
//! the solid in the local frame's planes. Plane `P`'s image x runs along local axis `P` and its
//! image y along local axis `P + 1 (mod 3)`, so `I_xy` is (x, y), `I_yz` (y, z), `I_zx` (z, x),
//! exactly as eq. (4) adds a 3D offset to a triple: `T + d = (T_xy + (d_x, d_y),
//! T_yz + (d_y, d_z), T_zx + (d_z, d_x))` ([`Triple::offset`]). Coordinates are whole pixels and
//! wrap around (exemplars are treated as toroidal, as in Lefebvre & Hoppe; a non-tileable
//! exemplar then has a seam that neighbourhood matching simply avoids).
//!
//! Local axis `A` is shared by two planes: it is the image-x line ("H line") of plane `A` and
//! the image-y line ("V line") of plane `A + 2`. Its *crossbar* is the pair of N-pixel lines
//! through a triple's coordinates along that axis; a triple is consistent when the three
//! crossbars agree (Dong et al. 2008). The crossbar error of a triple is
//! `Σ_A w_A w_{A+2} Σ_i ‖E_A(T_A + h(i, 0)) − E_{A+2}(T_{A+2} + h(0, i))‖²`, `i = −N_h..N_h`,
//! with the plane weights `w` of §6.1 (a plane of weight 0 is not matched at all: the paper's
//! remedy for incompatible exemplars).
//!
//! # Levels
//!
//! Levels are numbered as in the synthesis pyramid, `l = 1..=L`, level 1 coarsest; arrays are
//! indexed by `li = l − 1`. Level `l` samples the exemplar with spacing `h = 2^(L−l)` pixels
//! from the Gaussian stack level of that spacing: no downsampling, the stack level for
//! `h = 2^s` is the exemplar convolved `s` times with the binomial `[1 4 6 4 1]/16`, the
//! `j`-th time dilated by `2^j` (à trous), with wrap-around, which equals the Gaussian pyramid
//! evaluated at every pixel offset (Lefebvre & Hoppe 2005, §3.1). Neighbourhoods are `N × N`
//! pixels spaced `h` apart (`N` = `neighbourhood_coarsest` at level 1, `neighbourhood` above,
//! the paper's 7 and 9), RGB, reduced per level and image by PCA to `components` (about 20,
//! §4.3) dimensions: these are the vectors correction compares.
//!
//! With `feature_mask` set (§4: "for exemplar image textures with high regularity (e.g.
//! bricks), a further feature component is introduced"), everything that matches — the
//! neighbourhood vectors and their PCA, crossbar lines and errors, slab seeds, and the
//! synthesized voxels' neighbourhoods — reads the exemplars in appearance space (colour plus a
//! feature channel, PCA-reduced to 3 dimensions; `feature_mask.rs`), stacked like the colours
//! and stored as the `appearance` array; the `stack` array keeps the colours, which are what
//! is output.
//!
//! # Candidate triples
//!
//! For every pixel `p` of every plane `P`, at every level, the `candidates` best triples with
//! `T_P = p`: crossbar lines (3N values) are reduced by a PCA common to all images of the
//! level (`crossbar_components` dimensions), the `search` best `T_{P+2}` are found with a
//! kd-tree (approximate by `search_eps`) among V lines matching p's H line, the `search` best
//! `T_{P+1}` among H lines matching p's V line, and all `search²` combinations are ranked by
//! their exact crossbar error (all three crossbars, full lines). Near-duplicates (a kept
//! triple within one pixel on every coordinate of a plane of positive weight) are skipped so the
//! few candidates differ.
//!
//! # Candidate slabs
//!
//! The paper initializes from "candidate slabs" of Dong et al. without defining them. Here a
//! slab is the `W × H × D` block of triples (at the coarsest level, `D` = `slab_thickness`
//! voxels) whose voxel `(x, y, z)` holds `S(x, y) + h·(0, 0, z − ⌊D/2⌋)` (eq. 4): the `I_xy`
//! exemplar, each pixel carried along local z by its triple. The stored *slab seed* `S(p)` of
//! xy pixel `p` is the one of p's candidate triples whose carried column stays most consistent,
//! i.e. with the least crossbar error summed over the `D` layers (the best triple at the slab's
//! middle layer alone would ignore how fast its yz and zx lines drift apart). The synthesis
//! tiles space with slabs stacked along z, each shifted in xy by a counter-based random offset
//! (see `stages/synthesize/solid/solid_synthesis/`).
//!
//! # Choosing exemplars
//!
//! One image for all three planes suits textures without a direction (marble, granite). A
//! layered material cannot show the same stripes in all three planes: a solid layered across
//! x shows the stripes in xy, the transposed stripes in zx and no stripes in yz, so give the
//! image for xy, its transpose for zx and weight 0 to yz (tests/it/solid_synthesis.rs does this
//! with wood2).
//!
//! # Departures
//!
//! - Distances are squared L2 (the paper uses L1 on RGB): matching runs in PCA space, where
//!   only L2 distances are preserved.
//! - Dong et al. search the crossbars of full-resolution neighbourhoods; here the per-axis
//!   search runs on PCA-reduced lines and only the final ranking uses full lines.
//!
//! # Storage
//!
//! [`SolidAnalysis`] is flat `Pod` arrays plus [`AnalysisMeta`] (serde); [`SolidAnalysis::arrays`]
//! gives the named byte slices to store, and [`SolidAnalysisRef::from_arrays`] views stored
//! arrays in place (zero copy), checking every length against the metadata.

use super::feature_mask::{FeatureMaskParams, appearance};
use crate::image::knn::KdTree;
use crate::image::pca::{Pca, PcaParams};
use crate::image::{Image, ImageView};
use bytemuck::{Pod, Zeroable};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use texsyn_core::algorithm::Failure;

/// The `candidate_triples` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("candidate_triples", 1);

/// Plane names, by plane index.
pub const PLANE_NAMES: [&str; 3] = ["xy", "yz", "zx"];

/// Largest exemplar side (coordinates are stored as u16).
pub const MAX_EXEMPLAR_SIDE: u32 = 32768;

/// A coordinate triple: one pixel in each of `I_xy`, `I_yz`, `I_zx` (`c[plane] = [x, y]`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord, Pod, Zeroable)]
pub struct Triple {
    pub c: [[u16; 2]; 3],
}

/// `x mod n` in `0..n`; one period either side without a division (the common case).
#[inline(always)]
pub fn wrap(x: i32, n: u32) -> u16 {
    let n = n as i32;
    if (0..n).contains(&x) {
        x as u16
    } else if (-n..0).contains(&x) {
        (x + n) as u16
    } else if (n..2 * n).contains(&x) {
        (x - n) as u16
    } else {
        x.rem_euclid(n) as u16
    }
}

impl Triple {
    pub fn new(xy: [u16; 2], yz: [u16; 2], zx: [u16; 2]) -> Triple {
        Triple { c: [xy, yz, zx] }
    }

    /// Eq. (4): `T + d` for a whole-pixel offset `d = (d_x, d_y, d_z)` in the local frame,
    /// wrapped into a `width × height` exemplar.
    #[inline(always)]
    pub fn offset(&self, d: [i32; 3], width: u32, height: u32) -> Triple {
        let mut out = *self;
        for p in 0..3 {
            out.c[p] = [
                wrap(self.c[p][0] as i32 + d[p], width),
                wrap(self.c[p][1] as i32 + d[(p + 1) % 3], height),
            ];
        }
        out
    }
}

/// Analysis parameters. Every field has a default (`#[serde(default)]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CandidateParams {
    /// Pyramid levels L (exemplar spacings 1, 2, …, 2^(L−1)). 1..=8. Default: 4.
    pub levels: u32,
    /// Neighbourhood side N at the coarsest level, odd, 3..=15. Default: 7 (§6).
    pub neighbourhood_coarsest: u32,
    /// Neighbourhood side N at the other levels, odd, 3..=15. Default: 9 (§6).
    pub neighbourhood: u32,
    /// Candidate triples kept per pixel and level (k), 1..=32. Default: 4.
    pub candidates: u32,
    /// Matches per crossbar searched before combining, 1..=32; `search²` must be at least
    /// `candidates`. Default: 8.
    pub search: u32,
    /// PCA dimensions of a plane's neighbourhood vectors (§4.3: "about 20"), 1..=64.
    /// Default: 20.
    pub components: u32,
    /// PCA dimensions of crossbar lines for the kd-tree search, 1..=32. Default: 10.
    pub crossbar_components: u32,
    /// Approximate kd-tree search factor (0 = exact), 0..=10. Default: 1.
    pub search_eps: f32,
    /// Weights of the xy, yz and zx planes in matching and colour, each ≥ 0, at least two
    /// positive (§6.1: a small or zero weight for an incompatible plane). Default: [1, 1, 1].
    pub plane_weights: [f32; 3],
    /// Thickness D of a candidate slab, in coarsest-level voxels, 1..=64. Default: 4.
    pub slab_thickness: u32,
    /// Feature masks for regular exemplars (§4, §6, Fig. 16): given, matching runs on the
    /// exemplars in appearance space, colour plus a feature channel (`feature_mask.rs`).
    /// Default: none (off). Left out of the serialized parameters when off, so keys of
    /// analyses without it do not change.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub feature_mask: Option<FeatureMaskParams>,
}

impl Default for CandidateParams {
    fn default() -> Self {
        CandidateParams {
            levels: 4,
            neighbourhood_coarsest: 7,
            neighbourhood: 9,
            candidates: 4,
            search: 8,
            components: 20,
            crossbar_components: 10,
            search_eps: 1.0,
            plane_weights: [1.0; 3],
            slab_thickness: 4,
            feature_mask: None,
        }
    }
}

/// Why an analysis could not be made or read.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum AnalysisError {
    #[error(
        "solid exemplars must have the same size: xy is {}×{}, yz is {}×{}, zx is {}×{}",
        xy.0, xy.1, yz.0, yz.1, zx.0, zx.1
    )]
    SizeMismatch {
        xy: (u32, u32),
        yz: (u32, u32),
        zx: (u32, u32),
    },
    #[error(
        "solid exemplars are {width}×{height}; with {levels} levels each side must be {min}..={MAX_EXEMPLAR_SIDE} pixels"
    )]
    Size {
        width: u32,
        height: u32,
        levels: u32,
        min: u32,
    },
    #[error("analyse_exemplar.{name} = {value}: {expected}")]
    Param {
        name: &'static str,
        value: String,
        expected: &'static str,
    },
    #[error("solid analysis arrays: {0}")]
    Corrupt(String),
    #[error("analyse_exemplar.feature_mask: {0}")]
    Features(String),
}

fn param<T: std::fmt::Debug>(
    name: &'static str,
    value: T,
    ok: bool,
    expected: &'static str,
) -> Result<(), AnalysisError> {
    if ok {
        Ok(())
    } else {
        Err(AnalysisError::Param {
            name,
            value: format!("{value:?}"),
            expected,
        })
    }
}

impl CandidateParams {
    pub fn validate(&self) -> Result<(), AnalysisError> {
        param(
            "levels",
            self.levels,
            (1..=8).contains(&self.levels),
            "expected 1..=8",
        )?;
        for (name, n) in [
            ("neighbourhood_coarsest", self.neighbourhood_coarsest),
            ("neighbourhood", self.neighbourhood),
        ] {
            param(
                name,
                n,
                (3..=15).contains(&n) && n % 2 == 1,
                "expected an odd number in 3..=15",
            )?;
        }
        param(
            "candidates",
            self.candidates,
            (1..=32).contains(&self.candidates),
            "expected 1..=32",
        )?;
        param(
            "search",
            self.search,
            (1..=32).contains(&self.search) && self.search * self.search >= self.candidates,
            "expected 1..=32 with search² ≥ candidates",
        )?;
        param(
            "components",
            self.components,
            (1..=64).contains(&self.components),
            "expected 1..=64",
        )?;
        param(
            "crossbar_components",
            self.crossbar_components,
            (1..=32).contains(&self.crossbar_components),
            "expected 1..=32",
        )?;
        param(
            "search_eps",
            self.search_eps,
            self.search_eps.is_finite() && (0.0..=10.0).contains(&self.search_eps),
            "expected 0..=10",
        )?;
        let w = self.plane_weights;
        param(
            "plane_weights",
            w,
            w.iter().all(|x| x.is_finite() && *x >= 0.0 && *x <= 1e6)
                && w.iter().filter(|x| **x > 0.0).count() >= 2,
            "expected finite weights ≥ 0, at least two of them positive",
        )?;
        param(
            "slab_thickness",
            self.slab_thickness,
            (1..=64).contains(&self.slab_thickness),
            "expected 1..=64",
        )?;
        if let Some((name, value, expected)) = self.feature_mask.as_ref().and_then(|f| f.invalid())
        {
            return Err(AnalysisError::Param {
                name,
                value: format!("{value:?}"),
                expected,
            });
        }
        Ok(())
    }

    /// N at array level `li` (0 = coarsest).
    pub fn n(&self, li: usize) -> usize {
        if li == 0 {
            self.neighbourhood_coarsest as usize
        } else {
            self.neighbourhood as usize
        }
    }
}

/// The small metadata of an analysis; with the arrays it is the whole artifact.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AnalysisMeta {
    /// Stored without `feature_mask` (see [`stored_params`]); whether the analysis has one is
    /// whether it has an `appearance` array.
    #[serde(with = "stored_params")]
    pub params: CandidateParams,
    pub width: u32,
    pub height: u32,
    /// Number of distinct exemplar images.
    pub images: u32,
    /// Which distinct image each plane uses.
    pub plane_image: [u32; 3],
    /// Neighbourhood vector length `3N²` per level (coarsest first).
    pub dims: Vec<u32>,
    /// PCA components kept per level (the same for every image).
    pub components: Vec<u32>,
}

/// The analysis' parameters as its artifact stores them: the fields from before feature masks,
/// in their order, so analyses without a mask keep their bytes (bincode is not
/// self-describing: a new field, even an absent `Option`, would change them). Read back,
/// `feature_mask` is `None`.
mod stored_params {
    use super::CandidateParams;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    #[derive(Serialize, Deserialize)]
    struct Stored {
        levels: u32,
        neighbourhood_coarsest: u32,
        neighbourhood: u32,
        candidates: u32,
        search: u32,
        components: u32,
        crossbar_components: u32,
        search_eps: f32,
        plane_weights: [f32; 3],
        slab_thickness: u32,
    }

    pub fn serialize<S: Serializer>(p: &CandidateParams, s: S) -> Result<S::Ok, S::Error> {
        Stored {
            levels: p.levels,
            neighbourhood_coarsest: p.neighbourhood_coarsest,
            neighbourhood: p.neighbourhood,
            candidates: p.candidates,
            search: p.search,
            components: p.components,
            crossbar_components: p.crossbar_components,
            search_eps: p.search_eps,
            plane_weights: p.plane_weights,
            slab_thickness: p.slab_thickness,
        }
        .serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<CandidateParams, D::Error> {
        let t = Stored::deserialize(d)?;
        Ok(CandidateParams {
            levels: t.levels,
            neighbourhood_coarsest: t.neighbourhood_coarsest,
            neighbourhood: t.neighbourhood,
            candidates: t.candidates,
            search: t.search,
            components: t.components,
            crossbar_components: t.crossbar_components,
            search_eps: t.search_eps,
            plane_weights: t.plane_weights,
            slab_thickness: t.slab_thickness,
            feature_mask: None,
        })
    }
}

/// Array offsets derived from the metadata.
#[derive(Clone, Debug)]
struct Layout {
    pixels: usize,
    images: usize,
    levels: usize,
    k: usize,
    dims: Vec<usize>,
    comps: Vec<usize>,
    /// Start of (level, image) in `pca_mean`, `pca_basis`, `features`.
    mean_at: Vec<usize>,
    basis_at: Vec<usize>,
    feat_at: Vec<usize>,
    means: usize,
    bases: usize,
    feats: usize,
}

impl AnalysisMeta {
    fn layout(&self) -> Result<Layout, AnalysisError> {
        let bad = |m: &str| Err(AnalysisError::Corrupt(m.to_owned()));
        if let Err(e) = self.params.validate() {
            return Err(AnalysisError::Corrupt(format!("metadata parameters: {e}")));
        }
        let levels = self.params.levels as usize;
        if self.dims.len() != levels || self.components.len() != levels {
            return bad("metadata lists do not match the level count");
        }
        if self.images == 0 || self.images > 3 || self.plane_image.iter().any(|&i| i >= self.images)
        {
            return bad("metadata plane images are out of range");
        }
        if self.width == 0
            || self.height == 0
            || self.width > MAX_EXEMPLAR_SIDE
            || self.height > MAX_EXEMPLAR_SIDE
        {
            return bad("metadata exemplar size is out of range");
        }
        let images = self.images as usize;
        let pixels = self.width as usize * self.height as usize;
        let dims: Vec<usize> = self.dims.iter().map(|&d| d as usize).collect();
        let comps: Vec<usize> = self.components.iter().map(|&d| d as usize).collect();
        for li in 0..levels {
            let n = self.params.n(li);
            if dims[li] != 3 * n * n || comps[li] == 0 || comps[li] > dims[li] {
                return bad("metadata dimensions disagree with the parameters");
            }
        }
        let (mut mean_at, mut basis_at, mut feat_at) = (vec![], vec![], vec![]);
        let (mut means, mut bases, mut feats) = (0, 0, 0);
        for li in 0..levels {
            for _ in 0..images {
                mean_at.push(means);
                basis_at.push(bases);
                feat_at.push(feats);
                means += dims[li];
                bases += dims[li] * comps[li];
                feats += pixels * comps[li];
            }
        }
        Ok(Layout {
            pixels,
            images,
            levels,
            k: self.params.candidates as usize,
            dims,
            comps,
            mean_at,
            basis_at,
            feat_at,
            means,
            bases,
            feats,
        })
    }
}

/// The analysis, owned: flat arrays (see the module docs for their layout).
#[derive(Clone, Debug, PartialEq)]
pub struct SolidAnalysis {
    pub meta: AnalysisMeta,
    /// Gaussian stacks, RGB, `[level][image][y][x]`.
    pub stack: Vec<[f32; 3]>,
    /// PCA means, `[level][image][dim]`.
    pub pca_mean: Vec<f32>,
    /// PCA bases, `[level][image][component][dim]`.
    pub pca_basis: Vec<f32>,
    /// Exemplar neighbourhoods in PCA space, `[level][image][pixel][component]`.
    pub features: Vec<f32>,
    /// Candidate triples, `[level][plane][pixel][k]`, best first.
    pub candidates: Vec<Triple>,
    /// Their crossbar errors, same layout.
    pub candidate_errors: Vec<f32>,
    /// Slab seeds of the coarsest level, `[pixel of I_xy]`.
    pub slabs: Vec<Triple>,
    /// With a feature mask: the exemplars in appearance space (`feature_mask.rs`), stacked
    /// like `stack`; what matching compares. Empty without one (matching compares `stack`).
    pub appearance: Vec<[f32; 3]>,
}

/// Names of the arrays in the order [`SolidAnalysis::arrays`] gives them.
pub const ARRAY_NAMES: [&str; 7] = [
    "stack",
    "pca_mean",
    "pca_basis",
    "features",
    "candidates",
    "candidate_errors",
    "slabs",
];

impl SolidAnalysis {
    /// The named arrays as bytes, to store next to `meta`.
    pub fn arrays(&self) -> Vec<(String, &[u8])> {
        let mut out: Vec<(String, &[u8])> = vec![
            ("stack".into(), bytemuck::cast_slice(&self.stack)),
            ("pca_mean".into(), bytemuck::cast_slice(&self.pca_mean)),
            ("pca_basis".into(), bytemuck::cast_slice(&self.pca_basis)),
            ("features".into(), bytemuck::cast_slice(&self.features)),
            ("candidates".into(), bytemuck::cast_slice(&self.candidates)),
            (
                "candidate_errors".into(),
                bytemuck::cast_slice(&self.candidate_errors),
            ),
            ("slabs".into(), bytemuck::cast_slice(&self.slabs)),
        ];
        // Only with a feature mask, so analyses without one store what they always did.
        if !self.appearance.is_empty() {
            out.push(("appearance".into(), bytemuck::cast_slice(&self.appearance)));
        }
        out
    }

    /// A borrowed view (what synthesis reads).
    pub fn as_ref(&self) -> SolidAnalysisRef<'_> {
        let layout = self
            .meta
            .layout()
            .expect("an analysis we built is consistent");
        SolidAnalysisRef {
            meta: self.meta.clone(),
            layout,
            stack: &self.stack,
            pca_mean: &self.pca_mean,
            pca_basis: &self.pca_basis,
            features: &self.features,
            candidates: &self.candidates,
            candidate_errors: &self.candidate_errors,
            slabs: &self.slabs,
            appearance: &self.appearance,
        }
    }
}

/// A borrowed analysis: arrays viewed in place, e.g. in a memory-mapped artifact.
#[derive(Clone, Debug)]
pub struct SolidAnalysisRef<'a> {
    pub meta: AnalysisMeta,
    layout: Layout,
    pub stack: &'a [[f32; 3]],
    pub pca_mean: &'a [f32],
    pub pca_basis: &'a [f32],
    pub features: &'a [f32],
    pub candidates: &'a [Triple],
    pub candidate_errors: &'a [f32],
    pub slabs: &'a [Triple],
    /// See [`SolidAnalysis::appearance`].
    pub appearance: &'a [[f32; 3]],
}

fn view<'a, T: Pod>(
    name: &str,
    arrays: &[(String, &'a [u8])],
    want: usize,
) -> Result<&'a [T], AnalysisError> {
    let raw = arrays
        .iter()
        .find(|(n, _)| n == name)
        .map(|(_, b)| *b)
        .ok_or_else(|| AnalysisError::Corrupt(format!("no array named {name:?}")))?;
    let typed: &[T] = bytemuck::try_cast_slice(raw).map_err(|e| {
        AnalysisError::Corrupt(format!("array {name:?} cannot be viewed in place: {e}"))
    })?;
    if typed.len() != want {
        return Err(AnalysisError::Corrupt(format!(
            "array {name:?} has {} elements, the metadata implies {want}",
            typed.len()
        )));
    }
    Ok(typed)
}

impl<'a> SolidAnalysisRef<'a> {
    /// Views stored arrays (named as [`SolidAnalysis::arrays`] names them) in place. Every
    /// length is checked against `meta` and every stored coordinate against the exemplar
    /// size, so a damaged artifact is an error here, never an out-of-bounds index later.
    pub fn from_arrays(
        meta: AnalysisMeta,
        arrays: &[(String, &'a [u8])],
    ) -> Result<Self, AnalysisError> {
        let lay = meta.layout()?;
        let planes_k = lay.levels * 3 * lay.pixels * lay.k;
        let r = SolidAnalysisRef {
            stack: view("stack", arrays, lay.levels * lay.images * lay.pixels)?,
            pca_mean: view("pca_mean", arrays, lay.means)?,
            pca_basis: view("pca_basis", arrays, lay.bases)?,
            features: view("features", arrays, lay.feats)?,
            candidates: view("candidates", arrays, planes_k)?,
            candidate_errors: view("candidate_errors", arrays, planes_k)?,
            slabs: view("slabs", arrays, lay.pixels)?,
            // Present exactly when the analysis had a feature mask.
            appearance: if arrays.iter().any(|(n, _)| n == "appearance") {
                view("appearance", arrays, lay.levels * lay.images * lay.pixels)?
            } else {
                &[]
            },
            layout: lay,
            meta,
        };
        let (w, h) = (r.meta.width as u16, r.meta.height as u16);
        let inside = |t: &Triple| t.c.iter().all(|c| c[0] < w && c[1] < h);
        if !r.candidates.iter().all(inside) || !r.slabs.iter().all(inside) {
            return Err(AnalysisError::Corrupt(
                "a stored triple lies outside the exemplar".into(),
            ));
        }
        let finite = |x: &f32| x.is_finite();
        if !r.pca_basis.iter().all(finite)
            || !r.pca_mean.iter().all(finite)
            || !r.features.iter().all(finite)
            || !r.stack.iter().flatten().all(finite)
            || !r.appearance.iter().flatten().all(finite)
        {
            return Err(AnalysisError::Corrupt(
                "a stored value is not finite".into(),
            ));
        }
        Ok(r)
    }

    pub fn levels(&self) -> u32 {
        self.meta.params.levels
    }
    pub fn width(&self) -> u32 {
        self.meta.width
    }
    pub fn height(&self) -> u32 {
        self.meta.height
    }
    /// Exemplar spacing `h = 2^(L−l)` of array level `li = l − 1`.
    pub fn spacing(&self, li: usize) -> i32 {
        1 << (self.layout.levels - 1 - li)
    }
    /// Neighbourhood side N of array level `li`.
    pub fn n(&self, li: usize) -> usize {
        self.meta.params.n(li)
    }
    pub fn components(&self, li: usize) -> usize {
        self.layout.comps[li]
    }
    pub fn dim(&self, li: usize) -> usize {
        self.layout.dims[li]
    }
    pub fn image_of(&self, plane: usize) -> usize {
        self.meta.plane_image[plane] as usize
    }
    pub fn weights(&self) -> [f32; 3] {
        self.meta.params.plane_weights
    }
    pub fn k(&self) -> usize {
        self.layout.k
    }

    /// Stack level of array level `li` for image `img`.
    pub fn stack_level(&self, li: usize, img: usize) -> &'a [[f32; 3]] {
        let p = self.layout.pixels;
        let start = (li * self.layout.images + img) * p;
        &self.stack[start..start + p]
    }

    #[inline]
    fn pixel_index(&self, px: [u16; 2]) -> usize {
        px[1] as usize * self.meta.width as usize + px[0] as usize
    }

    /// Stack colour of image `img` at level `li` and pixel `px`.
    #[inline]
    pub fn texel(&self, li: usize, img: usize, px: [u16; 2]) -> [f32; 3] {
        self.stack[(li * self.layout.images + img) * self.layout.pixels + self.pixel_index(px)]
    }

    /// Colour of a triple at level `li`: the plane-weighted mean of its three exemplar pixels
    /// (with the default weights, the plain average).
    #[inline]
    pub fn colour(&self, li: usize, t: &Triple) -> [f32; 3] {
        let w = self.meta.params.plane_weights;
        let mut acc = [0.0f32; 3];
        let mut total = 0.0f32;
        for p in 0..3 {
            if w[p] > 0.0 {
                let c = self.texel(li, self.image_of(p), t.c[p]);
                for ch in 0..3 {
                    acc[ch] += w[p] * c[ch];
                }
                total += w[p];
            }
        }
        acc.map(|x| x / total)
    }

    /// What matching compares of a triple at level `li`: [`Self::colour`], or with a feature
    /// mask the same plane-weighted mean of the triple's three appearance texels.
    #[inline]
    pub fn match_colour(&self, li: usize, t: &Triple) -> [f32; 3] {
        if self.appearance.is_empty() {
            return self.colour(li, t);
        }
        let w = self.meta.params.plane_weights;
        let mut acc = [0.0f32; 3];
        let mut total = 0.0f32;
        for p in 0..3 {
            if w[p] > 0.0 {
                let c = self.appearance[(li * self.layout.images + self.image_of(p))
                    * self.layout.pixels
                    + self.pixel_index(t.c[p])];
                for ch in 0..3 {
                    acc[ch] += w[p] * c[ch];
                }
                total += w[p];
            }
        }
        acc.map(|x| x / total)
    }

    /// What matching compares of pixel `px` of image `img` at level `li`: its colour, or with
    /// a feature mask its appearance texel (the per-plane counterpart of [`Self::match_colour`]).
    #[inline]
    pub fn match_texel(&self, li: usize, img: usize, px: [u16; 2]) -> [f32; 3] {
        let i = (li * self.layout.images + img) * self.layout.pixels + self.pixel_index(px);
        if self.appearance.is_empty() {
            self.stack[i]
        } else {
            self.appearance[i]
        }
    }

    /// The level of the stack that matching reads (appearance with a feature mask, else
    /// colour) of image `img` at array level `li`.
    pub fn match_level(&self, li: usize, img: usize) -> &'a [[f32; 3]] {
        if self.appearance.is_empty() {
            return self.stack_level(li, img);
        }
        let p = self.layout.pixels;
        let start = (li * self.layout.images + img) * p;
        &self.appearance[start..start + p]
    }

    /// PCA mean and basis (`components × dim`, row-major) of image `img` at level `li`.
    pub fn pca(&self, li: usize, img: usize) -> (&'a [f32], &'a [f32]) {
        let i = li * self.layout.images + img;
        let (d, c) = (self.layout.dims[li], self.layout.comps[li]);
        (
            &self.pca_mean[self.layout.mean_at[i]..self.layout.mean_at[i] + d],
            &self.pca_basis[self.layout.basis_at[i]..self.layout.basis_at[i] + d * c],
        )
    }

    /// The PCA-space neighbourhood of image `img` at level `li` around pixel `px`.
    #[inline]
    pub fn feature(&self, li: usize, img: usize, px: [u16; 2]) -> &'a [f32] {
        let i = li * self.layout.images + img;
        let c = self.layout.comps[li];
        let start = self.layout.feat_at[i] + self.pixel_index(px) * c;
        &self.features[start..start + c]
    }

    /// Candidate triples of pixel `px` of plane `plane` at level `li`, best first.
    #[inline]
    pub fn candidates(&self, li: usize, plane: usize, px: [u16; 2]) -> &'a [Triple] {
        let k = self.layout.k;
        let start = ((li * 3 + plane) * self.layout.pixels + self.pixel_index(px)) * k;
        &self.candidates[start..start + k]
    }

    /// Crossbar errors of [`Self::candidates`].
    pub fn candidate_errors(&self, li: usize, plane: usize, px: [u16; 2]) -> &'a [f32] {
        let k = self.layout.k;
        let start = ((li * 3 + plane) * self.layout.pixels + self.pixel_index(px)) * k;
        &self.candidate_errors[start..start + k]
    }

    /// Slab seed of xy pixel `px` (coarsest level).
    #[inline]
    pub fn slab(&self, px: [u16; 2]) -> Triple {
        self.slabs[self.pixel_index(px)]
    }

    /// Crossbar error of a triple at level `li` (see the module docs), from the stack.
    pub fn crossbar_error(&self, li: usize, t: &Triple) -> f32 {
        let st: [&[[f32; 3]]; 3] = std::array::from_fn(|p| self.match_level(li, self.image_of(p)));
        crossbar_error_in(
            &st,
            self.meta.width,
            self.meta.height,
            self.spacing(li),
            self.n(li) as i32 / 2,
            self.meta.params.plane_weights,
            t,
        )
    }
}

fn crossbar_error_in(
    st: &[&[[f32; 3]]; 3],
    w: u32,
    h: u32,
    spacing: i32,
    nh: i32,
    weights: [f32; 3],
    t: &Triple,
) -> f32 {
    let at = |img: &[[f32; 3]], x: i32, y: i32| {
        img[wrap(y, h) as usize * w as usize + wrap(x, w) as usize]
    };
    let mut total = 0.0f32;
    for a in 0..3 {
        let b = (a + 2) % 3;
        let wa = weights[a] * weights[b];
        if wa == 0.0 {
            continue;
        }
        let (ta, tb) = (t.c[a], t.c[b]);
        let mut e = 0.0f32;
        for i in -nh..=nh {
            let ca = at(st[a], ta[0] as i32 + spacing * i, ta[1] as i32);
            let cb = at(st[b], tb[0] as i32, tb[1] as i32 + spacing * i);
            for ch in 0..3 {
                let d = ca[ch] - cb[ch];
                e += d * d;
            }
        }
        total += wa * e;
    }
    total
}

/// One Gaussian stack level from the previous one: binomial [1 4 6 4 1]/16 with taps `step`
/// apart, separable, wrapping around.
fn blur_dilated(src: &[[f32; 3]], w: usize, h: usize, step: usize) -> Vec<[f32; 3]> {
    // Tap `t` (0..5) around `i` on an axis of length `n`: `t - 2` steps away, wrapped.
    let tap = |i: usize, t: usize, n: usize| {
        (i as i64 + (t as i64 - 2) * step as i64).rem_euclid(n as i64) as usize
    };
    let rows = binomial_pass(src, w, h, |x, y, t| y * w + tap(x, t, w));
    binomial_pass(&rows, w, h, |x, y, t| tap(y, t, h) * w + x)
}

/// One pass of [`blur_dilated`]: output pixel `(x, y)` is the [1 4 6 4 1]/16 sum of
/// `src[index(x, y, t)]` over the taps `t` in 0..5.
fn binomial_pass(
    src: &[[f32; 3]],
    w: usize,
    h: usize,
    index: impl Fn(usize, usize, usize) -> usize + Sync,
) -> Vec<[f32; 3]> {
    const K: [f32; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];
    let mut out = vec![[0.0f32; 3]; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            let mut acc = [0.0f32; 3];
            for (t, &k) in K.iter().enumerate() {
                let p = src[index(x, y, t)];
                for c in 0..3 {
                    acc[c] += k * p[c];
                }
            }
            *o = acc;
        }
    });
    out
}

/// The Gaussian stack of an image, finest (h = 1) first, `levels` levels.
pub fn gaussian_stack(img: ImageView, levels: usize) -> Vec<Vec<[f32; 3]>> {
    let (w, h) = (img.width as usize, img.height as usize);
    let mut out = vec![
        img.pixels
            .iter()
            .map(|p| [p[0], p[1], p[2]])
            .collect::<Vec<_>>(),
    ];
    for s in 1..levels {
        let next = blur_dilated(out.last().expect("one level"), w, h, 1 << (s - 1));
        out.push(next);
    }
    out
}

/// The `N × N` neighbourhood vectors (RGB, row-major, spacing `h`) of every pixel.
fn neighbourhood_vectors(level: &[[f32; 3]], w: u32, hgt: u32, n: usize, h: i32) -> Vec<f32> {
    let dim = 3 * n * n;
    let nh = (n / 2) as i32;
    let mut out = vec![0.0f32; w as usize * hgt as usize * dim];
    out.par_chunks_mut(dim).enumerate().for_each(|(i, v)| {
        let (x, y) = ((i % w as usize) as i32, (i / w as usize) as i32);
        let mut o = 0;
        for j in -nh..=nh {
            let yy = wrap(y + h * j, hgt) as usize * w as usize;
            for ii in -nh..=nh {
                let c = level[yy + wrap(x + h * ii, w) as usize];
                v[o..o + 3].copy_from_slice(&c);
                o += 3;
            }
        }
    });
    out
}

/// H lines (along image x) or V lines (along image y), 3N values each, of every pixel.
fn crossbar_lines(
    level: &[[f32; 3]],
    w: u32,
    hgt: u32,
    n: usize,
    h: i32,
    vertical: bool,
) -> Vec<f32> {
    let dim = 3 * n;
    let nh = (n / 2) as i32;
    let mut out = vec![0.0f32; w as usize * hgt as usize * dim];
    out.par_chunks_mut(dim).enumerate().for_each(|(i, v)| {
        let (x, y) = ((i % w as usize) as i32, (i / w as usize) as i32);
        for (o, ii) in (-nh..=nh).enumerate() {
            let (xx, yy) = if vertical {
                (x, y + h * ii)
            } else {
                (x + h * ii, y)
            };
            let c = level[wrap(yy, hgt) as usize * w as usize + wrap(xx, w) as usize];
            v[3 * o..3 * o + 3].copy_from_slice(&c);
        }
    });
    out
}

#[inline]
fn sq(a: &[f32], b: &[f32]) -> f32 {
    let mut s = 0.0f32;
    for (x, y) in a.iter().zip(b) {
        let d = x - y;
        s += d * d;
    }
    s
}

/// Toroidal distance ≤ 1 on both coordinates.
fn near(a: [u16; 2], b: [u16; 2], w: u32, h: u32) -> bool {
    let d = |x: u16, y: u16, n: u32| {
        let d = (x as i32 - y as i32).rem_euclid(n as i32);
        d.min(n as i32 - d)
    };
    d(a[0], b[0], w) <= 1 && d(a[1], b[1], h) <= 1
}

/// [`analyse`] with the images of the planes marked in `transpose` transposed first, so that
/// one image can show the same layers in two planes whose axes run the other way round.
pub fn analyse_transposed(
    planes: [ImageView; 3],
    masks: [Option<ImageView>; 3],
    transpose: [bool; 3],
    params: &CandidateParams,
) -> Result<SolidAnalysis, AnalysisError> {
    analyse_transposed_with(planes, masks, transpose, params, &|_| {})
}

/// [`analyse_transposed`], reporting the fraction done to `progress` (see
/// [`analyse_masked_with`]).
pub fn analyse_transposed_with(
    planes: [ImageView; 3],
    masks: [Option<ImageView>; 3],
    transpose: [bool; 3],
    params: &CandidateParams,
    progress: &(dyn Fn(f32) + Sync),
) -> Result<SolidAnalysis, AnalysisError> {
    let turned: [Option<Image>; 3] =
        std::array::from_fn(|k| transpose[k].then(|| planes[k].transposed()));
    let views = std::array::from_fn(|k| turned[k].as_ref().map_or(planes[k], Image::view));
    let turned_masks: [Option<Image>; 3] =
        std::array::from_fn(|k| masks[k].filter(|_| transpose[k]).map(|m| m.transposed()));
    let mask_views =
        std::array::from_fn(|k| turned_masks[k].as_ref().map(Image::view).or(masks[k]));
    analyse_masked_with(views, mask_views, params, progress)
}

/// Analyses the exemplars of the xy, yz and zx planes (pass the same image several times to
/// share it; identical images are analysed once). See the module docs.
pub fn analyse(
    planes: [ImageView; 3],
    params: &CandidateParams,
) -> Result<SolidAnalysis, AnalysisError> {
    analyse_masked(planes, [None; 3], params)
}

/// [`analyse`] with drawn feature masks: plane `P`'s mask, when given, holds the feature curves
/// of `P`'s exemplar (its size; `feature_mask.rs`), in place of the detected ones. A mask needs
/// `params.feature_mask`, which sets the channel's weight and radius.
pub fn analyse_masked(
    planes: [ImageView; 3],
    masks: [Option<ImageView>; 3],
    params: &CandidateParams,
) -> Result<SolidAnalysis, AnalysisError> {
    analyse_masked_with(planes, masks, params, &|_| {})
}

/// [`analyse_masked`], reporting the fraction done to `progress`: one step per pyramid level
/// (the finest, with the most texels, last), weighted by the level's neighbourhood size.
pub fn analyse_masked_with(
    planes: [ImageView; 3],
    masks: [Option<ImageView>; 3],
    params: &CandidateParams,
    progress: &(dyn Fn(f32) + Sync),
) -> Result<SolidAnalysis, AnalysisError> {
    params.validate()?;
    if masks.iter().any(Option::is_some) && params.feature_mask.is_none() {
        return Err(AnalysisError::Features(
            "a drawn mask is given but the feature channel is off".into(),
        ));
    }
    for (k, m) in masks.iter().enumerate() {
        if let Some(m) = m
            && (m.width, m.height) != (planes[k].width, planes[k].height)
        {
            return Err(AnalysisError::Features(format!(
                "the {} plane's drawn mask is {}×{}, its exemplar {}×{}: a mask must match its \
                 image texel for texel",
                ["xy", "yz", "zx"][k],
                m.width,
                m.height,
                planes[k].width,
                planes[k].height
            )));
        }
    }
    let sizes = planes.map(|p| (p.width, p.height));
    if sizes[1] != sizes[0] || sizes[2] != sizes[0] {
        return Err(AnalysisError::SizeMismatch {
            xy: sizes[0],
            yz: sizes[1],
            zx: sizes[2],
        });
    }
    let (w, hgt) = sizes[0];
    let levels = params.levels as usize;
    let min_side = (1u32 << (levels - 1)).max(8);
    if w < min_side || hgt < min_side || w > MAX_EXEMPLAR_SIDE || hgt > MAX_EXEMPLAR_SIDE {
        return Err(AnalysisError::Size {
            width: w,
            height: hgt,
            levels: params.levels,
            min: min_side,
        });
    }
    if let Some(bad) = planes
        .iter()
        .flat_map(|p| p.pixels.iter())
        .position(|p| p.iter().any(|c| !c.is_finite()))
    {
        return Err(AnalysisError::Param {
            name: "exemplar",
            value: format!("pixel {bad}"),
            expected: "finite colours",
        });
    }
    // Distinct images (an image with another drawn mask is another image).
    let mut images: Vec<ImageView> = Vec::new();
    let mut image_masks: Vec<Option<ImageView>> = Vec::new();
    let mut plane_image = [0u32; 3];
    let same_mask = |a: Option<ImageView>, b: Option<ImageView>| match (a, b) {
        (None, None) => true,
        (Some(a), Some(b)) => a.pixels == b.pixels,
        _ => false,
    };
    for (p, img) in planes.iter().enumerate() {
        let found = (0..images.len())
            .position(|o| images[o].pixels == img.pixels && same_mask(image_masks[o], masks[p]));
        plane_image[p] = match found {
            Some(i) => i as u32,
            None => {
                images.push(*img);
                image_masks.push(masks[p]);
                (images.len() - 1) as u32
            }
        };
    }
    let ni = images.len();
    let pixels = w as usize * hgt as usize;
    let stacks: Vec<Vec<Vec<[f32; 3]>>> = images
        .iter()
        .map(|img| gaussian_stack(*img, levels))
        .collect();
    // With a feature mask, matching reads the images in appearance space: their own stacks
    // (the projection is linear, so this is the appearance of the colour stack).
    let appearance_stacks: Option<Vec<Vec<Vec<[f32; 3]>>>> = match &params.feature_mask {
        None => None,
        Some(f) => Some(
            images
                .iter()
                .zip(&image_masks)
                .map(|(img, mask)| {
                    let a = appearance(*img, *mask, f).map_err(AnalysisError::Features)?;
                    Ok(gaussian_stack(a.image.view(), levels))
                })
                .collect::<Result<_, AnalysisError>>()?,
        ),
    };
    let matched = appearance_stacks.as_ref().unwrap_or(&stacks);
    // Array level li uses the stack level of spacing 2^(L−1−li); matching reads `matched`.
    let colour_img = |li: usize, img: usize| -> &[[f32; 3]] { &stacks[img][levels - 1 - li] };
    let level_img = |li: usize, img: usize| -> &[[f32; 3]] { &matched[img][levels - 1 - li] };

    let k = params.candidates as usize;
    let mut stack = Vec::with_capacity(levels * ni * pixels);
    let mut appearance_arr = Vec::new();
    let (mut pca_mean, mut pca_basis, mut features) = (vec![], vec![], vec![]);
    let mut candidates = Vec::with_capacity(levels * 3 * pixels * k);
    let mut candidate_errors = Vec::with_capacity(levels * 3 * pixels * k);
    let (mut dims, mut comps) = (vec![], vec![]);
    let weights = params.plane_weights;

    for li in 0..levels {
        let n = params.n(li);
        let h = 1i32 << (levels - 1 - li);
        let dim = 3 * n * n;
        let c = (params.components as usize).min(dim);
        dims.push(dim as u32);
        comps.push(c as u32);
        for img in 0..ni {
            stack.extend_from_slice(colour_img(li, img));
            if appearance_stacks.is_some() {
                appearance_arr.extend_from_slice(level_img(li, img));
            }
            let vecs = neighbourhood_vectors(level_img(li, img), w, hgt, n, h);
            let pca = Pca::fit(
                &vecs,
                dim,
                &PcaParams {
                    components: c as u32,
                    ..Default::default()
                },
            );
            pca_mean.extend_from_slice(&pca.mean);
            pca_basis.extend_from_slice(&pca.basis);
            features.extend(pca.project_all(&vecs));
        }

        // Crossbar lines, a common PCA, and kd-trees of projected H and V lines per image.
        let ldim = 3 * n;
        let hl: Vec<Vec<f32>> = (0..ni)
            .map(|i| crossbar_lines(level_img(li, i), w, hgt, n, h, false))
            .collect();
        let vl: Vec<Vec<f32>> = (0..ni)
            .map(|i| crossbar_lines(level_img(li, i), w, hgt, n, h, true))
            .collect();
        let all: Vec<f32> = hl.iter().chain(vl.iter()).flatten().copied().collect();
        let cb = Pca::fit(
            &all,
            ldim,
            &PcaParams {
                components: params.crossbar_components.min(ldim as u32),
                ..Default::default()
            },
        );
        drop(all);
        let hp: Vec<Vec<f32>> = hl.iter().map(|v| cb.project_all(v)).collect();
        let vp: Vec<Vec<f32>> = vl.iter().map(|v| cb.project_all(v)).collect();
        let cd = cb.components();
        let trees: Vec<(KdTree, KdTree)> = (0..ni)
            .into_par_iter()
            .map(|i| (KdTree::build(&hp[i], cd), KdTree::build(&vp[i], cd)))
            .collect();

        for plane in 0..3 {
            let (pa, pb) = ((plane + 1) % 3, (plane + 2) % 3);
            let (ip, ia, ib) = (
                plane_image[plane] as usize,
                plane_image[pa] as usize,
                plane_image[pb] as usize,
            );
            // Crossbar weights: axis `plane` (H of plane, V of pb), axis pa (H of pa, V of
            // plane), axis pb (H of pb, V of pa).
            let (w0, w1, w2) = (
                weights[plane] * weights[pb],
                weights[pa] * weights[plane],
                weights[pb] * weights[pa],
            );
            let search = params.search as usize;
            let per_pixel: Vec<(Vec<Triple>, Vec<f32>)> = (0..pixels)
                .into_par_iter()
                .map(|pix| {
                    fn part(v: &[f32], i: usize, d: usize) -> &[f32] {
                        &v[i * d..(i + 1) * d]
                    }
                    let line = |v, i| part(v, i, ldim);
                    let pline = |v, i| part(v, i, cd);
                    let bs = trees[ib].1.as_ref().nearest_approx(
                        pline(&hp[ip], pix),
                        search,
                        params.search_eps,
                        |_| true,
                    );
                    let as_ = trees[ia].0.as_ref().nearest_approx(
                        pline(&vp[ip], pix),
                        search,
                        params.search_eps,
                        |_| true,
                    );
                    let mut combos: Vec<(f32, u32, u32)> = Vec::with_capacity(as_.len() * bs.len());
                    for &(a, _) in &as_ {
                        for &(b, _) in &bs {
                            let (a, b) = (a as usize, b as usize);
                            let e = w0 * sq(line(&hl[ip], pix), line(&vl[ib], b))
                                + w1 * sq(line(&hl[ia], a), line(&vl[ip], pix))
                                + w2 * sq(line(&hl[ib], b), line(&vl[ia], a));
                            combos.push((e, a as u32, b as u32));
                        }
                    }
                    combos.sort_by(|x, y| {
                        x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)).then(x.2.cmp(&y.2))
                    });
                    let px = |i: u32| [(i % w) as u16, (i / w) as u16];
                    let mut kept: Vec<Triple> = Vec::with_capacity(k);
                    let mut errs: Vec<f32> = Vec::with_capacity(k);
                    for &(e, a, b) in &combos {
                        let mut t = Triple::default();
                        t.c[plane] = px(pix as u32);
                        t.c[pa] = px(a);
                        t.c[pb] = px(b);
                        // Planes of weight 0 are not matched: differences there do not count.
                        if kept.iter().any(|o| {
                            (0..3).all(|q| weights[q] == 0.0 || near(o.c[q], t.c[q], w, hgt))
                        }) {
                            continue;
                        }
                        kept.push(t);
                        errs.push(e);
                        if kept.len() == k {
                            break;
                        }
                    }
                    // Too few distinct combinations (tiny exemplars): fill with the best ones.
                    let mut i = 0;
                    while kept.len() < k {
                        let (e, a, b) = combos[i % combos.len()];
                        let mut t = Triple::default();
                        t.c[plane] = px(pix as u32);
                        t.c[pa] = px(a);
                        t.c[pb] = px(b);
                        kept.push(t);
                        errs.push(e);
                        i += 1;
                    }
                    (kept, errs)
                })
                .collect();
            for (t, e) in per_pixel {
                candidates.extend(t);
                candidate_errors.extend(e);
            }
        }
        let weight = |l: usize| (params.n(l) * params.n(l)) as f32;
        let done: f32 = (0..=li).map(weight).sum();
        progress(done / (0..levels).map(weight).sum::<f32>());
    }

    // Slab seeds at the coarsest level: the candidate whose column carried along z keeps the
    // least crossbar error over the slab's thickness.
    let d = params.slab_thickness as i32;
    let h0 = 1i32 << (levels - 1);
    let nh0 = (params.n(0) / 2) as i32;
    let st0: [&[[f32; 3]]; 3] = std::array::from_fn(|p| level_img(0, plane_image[p] as usize));
    let slabs: Vec<Triple> = (0..pixels)
        .into_par_iter()
        .map(|pix| {
            let cands = &candidates[pix * k..(pix + 1) * k];
            let mut best = (f32::INFINITY, cands[0]);
            for c in cands {
                let e: f32 = (0..d)
                    .map(|z| {
                        let t = c.offset([0, 0, h0 * (z - d / 2)], w, hgt);
                        crossbar_error_in(&st0, w, hgt, h0, nh0, weights, &t)
                    })
                    .sum();
                if e < best.0 {
                    best = (e, *c);
                }
            }
            best.1
        })
        .collect();

    Ok(SolidAnalysis {
        meta: AnalysisMeta {
            params: params.clone(),
            width: w,
            height: hgt,
            images: ni as u32,
            plane_image,
            dims,
            components: comps,
        },
        stack,
        pca_mean,
        pca_basis,
        features,
        candidates,
        candidate_errors,
        slabs,
        appearance: appearance_arr,
    })
}

/// An exemplar image of a plane as a config names it, optionally transposed (so one image
/// can show the same layers in two planes whose axes run the other way round).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum ExemplarSpec {
    Path(std::path::PathBuf),
    Spec {
        path: std::path::PathBuf,
        #[serde(default)]
        transpose: bool,
        /// A drawn feature mask for this image (its size, transposed with it; texels at or
        /// above half intensity on the feature curves): turns the feature channel on
        /// (`analyse_exemplar.feature_mask`'s settings, or their defaults) in place of the
        /// detected curves.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        mask: Option<std::path::PathBuf>,
    },
}

impl ExemplarSpec {
    /// The image's path, as the config gives it.
    pub fn path(&self) -> &std::path::Path {
        match self {
            ExemplarSpec::Path(path) | ExemplarSpec::Spec { path, .. } => path,
        }
    }

    /// The drawn feature mask's path, as the config gives it.
    pub fn mask(&self) -> Option<&std::path::Path> {
        match self {
            ExemplarSpec::Spec { mask, .. } => mask.as_deref(),
            ExemplarSpec::Path(_) => None,
        }
    }

    /// Whether the image is read transposed.
    pub fn transpose(&self) -> bool {
        matches!(
            self,
            ExemplarSpec::Spec {
                transpose: true,
                ..
            }
        )
    }
}

/// The analysis node's key: its parameters and which planes' images are transposed (the
/// drawn masks are inputs of the node, so their contents are in its key too).
#[derive(Debug, Clone, Serialize)]
pub struct AnalysisKey {
    pub analysis: CandidateParams,
    pub transpose: [bool; 3],
}

/// The analyse-exemplar node: [`analyse_transposed`] of the three planes' images and drawn
/// masks.
pub fn node(
    planes: [ImageView; 3],
    masks: [Option<ImageView>; 3],
    key: &AnalysisKey,
    progress: &(dyn Fn(f32) + Sync),
) -> Result<SolidAnalysis, Failure> {
    analyse_transposed_with(planes, masks, key.transpose, &key.analysis, progress)
        .map_err(Failure::input)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::Image;

    fn stripes(w: u32, h: u32) -> Image {
        Image::from_fn(w, h, |x, y| {
            let v = if (x / 3) % 2 == 0 { 0.9 } else { 0.1 };
            [v, 0.5 * v + 0.2 * (y % 5) as f32 / 5.0, 0.3, 1.0]
        })
    }

    #[test]
    fn triple_offset_follows_eq_4_and_wraps() {
        let t = Triple::new([1, 2], [3, 4], [5, 6]);
        let u = t.offset([10, 20, 30], 16, 16);
        assert_eq!(u, Triple::new([11, 6], [7, 2], [3, 0]));
        let back = u.offset([-10, -20, -30], 16, 16);
        assert_eq!(back, t);
    }

    #[test]
    fn stack_level_equals_pyramid_sampling() {
        // The à-trous stack at h = 2 sampled at even pixels equals blur-then-downsample.
        let img = stripes(16, 16);
        let st = gaussian_stack(img.view(), 2);
        let b = blur_dilated(&st[0], 16, 16, 1);
        assert_eq!(b, st[1]);
        // Constant images stay constant.
        let mut c = Image::new(8, 8);
        c.pixels
            .iter_mut()
            .for_each(|p| *p = [0.25, 0.5, 0.75, 1.0]);
        for l in gaussian_stack(c.view(), 3) {
            for p in l {
                for (a, b) in p.iter().zip([0.25, 0.5, 0.75]) {
                    assert!((a - b).abs() < 1e-6);
                }
            }
        }
    }

    #[test]
    fn candidates_have_their_pixel_and_sorted_errors() {
        let img = stripes(24, 24);
        let params = CandidateParams {
            levels: 2,
            neighbourhood_coarsest: 5,
            neighbourhood: 5,
            ..Default::default()
        };
        let a = analyse([img.view(); 3], &params).unwrap();
        assert_eq!(a.meta.images, 1);
        let r = a.as_ref();
        for li in 0..2 {
            for plane in 0..3 {
                for px in [[0u16, 0], [5, 7], [23, 23]] {
                    let c = r.candidates(li, plane, px);
                    let e = r.candidate_errors(li, plane, px);
                    assert!(c.iter().all(|t| t.c[plane] == px));
                    assert!(e.windows(2).all(|w| w[0] <= w[1]));
                    // Stored errors are the crossbar errors.
                    for (t, e) in c.iter().zip(e) {
                        let direct = r.crossbar_error(li, t);
                        assert!((direct - e).abs() <= 1e-4 * (1.0 + e), "{direct} vs {e}");
                    }
                }
            }
        }
    }
}
