//! Artifact formats of the geometry-image method: geometry images, texel images, the
//! parameter-domain field and the texel variants.
//!
//! Geometry images, texel images and fields are viewed as owned copies (the stages take
//! `&GeometryImage`, `&TexelImage` and `&ParamField`, as [`crate::geom::Mesh`] is read); the
//! variants, by far the largest, are viewed in place. `format_pair!` does not fit these: their
//! owned types are the stages' and the core's (an owned/borrowed pair would need a borrowed
//! twin of each there), and three store metadata that is not one of their fields.

use super::{AlignedBytes, Artifact, ArtifactError, ArtifactWriter, Format, Kind};
use crate::geom::geometry_image::{GeometryImage, TexelImage};
use crate::stages::analyse_exemplar::appearance_space::{
    AppearanceMeta, AppearanceSpace, AppearanceSpaceRef,
};
use crate::stages::analyse_exemplar::texel_variants::{TexelVariants, TexelVariantsRef};
use crate::stages::field::param_field::ParamField;
use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

fn bad(msg: impl std::fmt::Display) -> ArtifactError {
    ArtifactError::Meta(msg.to_string())
}

/// Metadata: the side `n`; arrays `positions`, `normals`, `mate_rep`.
impl Format for GeometryImage {
    const KIND: Kind = Kind::GeometryImage;
    /// Copied: synthesis and reconstruction want owned grids.
    type View<'a> = GeometryImage;
    fn write(&self) -> AlignedBytes {
        ArtifactWriter::new(Kind::GeometryImage, &self.n)
            .array("positions", &self.positions)
            .array("normals", &self.normals)
            .array("mate_rep", &self.mate_rep)
            .finish()
    }
    fn decode(a: &Artifact) -> Result<GeometryImage, ArtifactError> {
        let n: u32 = a.meta()?;
        let count = n as usize * n as usize;
        let positions: &[Vec3] = a.array("positions")?;
        let normals: &[Vec3] = a.array("normals")?;
        let mate_rep: &[u32] = a.array("mate_rep")?;
        if positions.len() != count || normals.len() != count || mate_rep.len() != count {
            return Err(bad("geometry image arrays disagree with its size"));
        }
        if mate_rep
            .iter()
            .enumerate()
            .any(|(k, &r)| r as usize > k || mate_rep[r as usize] != r)
        {
            return Err(bad("geometry image mate table is inconsistent"));
        }
        Ok(GeometryImage {
            n,
            positions: positions.to_vec(),
            normals: normals.to_vec(),
            mate_rep: mate_rep.to_vec(),
        })
    }
}

/// Metadata of a texel image: its size and channels (3 geometric, or 6 with colour).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
struct TexelMeta {
    width: u32,
    height: u32,
    channels: u32,
}

/// Metadata [`TexelMeta`]; array `data`.
impl Format for TexelImage {
    const KIND: Kind = Kind::TexelImage;
    /// Copied, like the geometry image.
    type View<'a> = TexelImage;
    fn write(&self) -> AlignedBytes {
        ArtifactWriter::new(
            Kind::TexelImage,
            &TexelMeta {
                width: self.width,
                height: self.height,
                channels: self.channels,
            },
        )
        .array("data", &self.data)
        .finish()
    }
    fn decode(a: &Artifact) -> Result<TexelImage, ArtifactError> {
        let m: TexelMeta = a.meta()?;
        let data: &[f32] = a.array("data")?;
        if data.len() != m.width as usize * m.height as usize * m.channels as usize
            || !(m.channels == 3 || m.channels == 6)
        {
            return Err(bad("texel image size disagrees with its metadata"));
        }
        Ok(TexelImage {
            width: m.width,
            height: m.height,
            channels: m.channels,
            data: data.to_vec(),
        })
    }
}

/// Metadata: the sample count; arrays `dir`, `rel_scale`.
impl Format for ParamField {
    const KIND: Kind = Kind::ParamField;
    /// Copied, like the geometry image it belongs to.
    type View<'a> = ParamField;
    fn write(&self) -> AlignedBytes {
        ArtifactWriter::new(Kind::ParamField, &(self.dir.len() as u64))
            .array("dir", &self.dir)
            .array("rel_scale", &self.rel_scale)
            .finish()
    }
    fn decode(a: &Artifact) -> Result<ParamField, ArtifactError> {
        let n: u64 = a.meta()?;
        let dir: &[Vec2] = a.array("dir")?;
        let rel_scale: &[f32] = a.array("rel_scale")?;
        if dir.len() as u64 != n || rel_scale.len() as u64 != n {
            return Err(bad("field arrays disagree with its metadata"));
        }
        Ok(ParamField {
            dir: dir.to_vec(),
            rel_scale: rel_scale.to_vec(),
        })
    }
}

/// Metadata the variants' `VariantsMeta`; the arrays of [`TexelVariants::arrays`], in its
/// order, viewed in place and checked by [`TexelVariantsRef::from_arrays`].
impl Format for TexelVariants {
    const KIND: Kind = Kind::TexelVariants;
    type View<'a> = TexelVariantsRef<'a>;
    fn write(&self) -> AlignedBytes {
        ArtifactWriter::new(Kind::TexelVariants, &self.meta)
            .arrays_bytes(self.arrays())
            .finish()
    }
    fn decode(a: &Artifact) -> Result<TexelVariantsRef<'_>, ArtifactError> {
        TexelVariantsRef::from_arrays(a.meta()?, |name| a.raw_array(name).ok()).map_err(bad)
    }
}

/// Metadata [`AppearanceMeta`]; arrays `stack`, `neighbourhoods`, `candidates`, viewed in
/// place and checked by [`AppearanceSpaceRef::new`].
impl Format for AppearanceSpace {
    const KIND: Kind = Kind::AppearanceSpace;
    type View<'a> = AppearanceSpaceRef<'a>;
    fn write(&self) -> AlignedBytes {
        ArtifactWriter::new(Kind::AppearanceSpace, &self.meta)
            .array("stack", &self.stack)
            .array("neighbourhoods", &self.neighbourhoods)
            .array("candidates", &self.candidates)
            .finish()
    }
    fn decode(a: &Artifact) -> Result<AppearanceSpaceRef<'_>, ArtifactError> {
        let meta: AppearanceMeta = a.meta()?;
        AppearanceSpaceRef::new(
            meta,
            a.array("stack")?,
            a.array("neighbourhoods")?,
            a.array("candidates")?,
        )
        .map_err(bad)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stages::analyse_exemplar::texel_variants::{
        Template, TexelVariantParams, VariantsMeta, build_texel_variants, build_texel_variants_with,
    };
    use texsyn_core::math::PureMath;

    fn stripes(n: u32, period: f32) -> TexelImage {
        let mut t = TexelImage::new(n, n, 3);
        for y in 0..n {
            for x in 0..n {
                let p = t.texel_mut(x, y);
                p[0] = 1.0;
                p[1] = 0.25;
                p[2] = (std::f32::consts::TAU * x as f32 / period).sin_pure();
            }
        }
        t
    }

    fn round_trip<F: Format>(value: &F) -> Artifact {
        Artifact::from_bytes(value.write()).unwrap()
    }

    #[test]
    fn grids_and_fields_round_trip_and_damage_is_an_error() {
        let gi = GeometryImage {
            n: 2,
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::ONE],
            normals: vec![Vec3::Z; 4],
            mate_rep: vec![0, 1, 0, 3],
        };
        assert_eq!(GeometryImage::view(&round_trip(&gi)).unwrap(), gi);
        let bad_mates = GeometryImage {
            mate_rep: vec![0, 1, 3, 3],
            ..gi.clone()
        };
        assert!(GeometryImage::view(&round_trip(&bad_mates)).is_err());
        let short = GeometryImage { n: 3, ..gi.clone() };
        assert!(GeometryImage::view(&round_trip(&short)).is_err());
        // Another kind is refused before decoding.
        assert!(TexelImage::view(&round_trip(&gi)).is_err());

        let t = stripes(5, 3.0);
        assert_eq!(TexelImage::view(&round_trip(&t)).unwrap(), t);
        let four = TexelImage {
            channels: 4,
            data: vec![0.0; 4 * 25],
            ..t
        };
        assert!(TexelImage::view(&round_trip(&four)).is_err());

        let f = ParamField {
            dir: vec![Vec2::Y, Vec2::X],
            rel_scale: vec![1.0, 2.0],
        };
        assert_eq!(ParamField::view(&round_trip(&f)).unwrap(), f);
        let uneven = ParamField {
            rel_scale: vec![1.0],
            ..f
        };
        assert!(ParamField::view(&round_trip(&uneven)).is_err());
    }

    /// The variant set read back from its artifact equals the owned set (levels, template
    /// sets, trees), and a missing array, a short array or inconsistent metadata is an error.
    #[test]
    fn variants_round_trip_in_place_and_damage_is_an_error() {
        let p = TexelVariantParams {
            orientations: 2,
            ..Default::default()
        };
        let v = build_texel_variants(&stripes(40, 7.0), &p, &|_| {}).unwrap();
        let art = round_trip(&v);
        let r = TexelVariants::view(&art).unwrap();
        let owned = v.as_ref();
        assert_eq!(r.meta, v.meta);
        for var in 0..r.variant_count() {
            for l in 0..r.levels() {
                assert_eq!(r.level(var, l).texels, owned.level(var, l).texels);
                for kind in [Template::Causal, Template::Full] {
                    let (a, b) = (r.set(var, l, kind), owned.set(var, l, kind));
                    assert_eq!(a.centres, b.centres);
                    assert_eq!(a.basis, b.basis);
                    let q = vec![0.1f32; a.dims];
                    let mut s = Vec::new();
                    assert_eq!(
                        a.tree.nearest1_approx(&q, 0.0, &mut s),
                        b.tree.nearest1_approx(&q, 0.0, &mut s)
                    );
                }
            }
        }
        let meta: VariantsMeta = art.meta().unwrap();
        assert!(
            TexelVariantsRef::from_arrays(meta.clone(), |n| {
                (n != "centres").then(|| art.raw_array(n).ok()).flatten()
            })
            .is_err()
        );
        assert!(
            TexelVariantsRef::from_arrays(meta.clone(), |n| {
                let a = art.raw_array(n).ok()?;
                Some(if n == "tree_points" {
                    &a[..a.len() - 4]
                } else {
                    a
                })
            })
            .is_err()
        );
        let mut bad = meta.clone();
        bad.sets[3].dims += 1;
        assert!(TexelVariantsRef::from_arrays(bad, |n| art.raw_array(n).ok()).is_err());
        let mut bad = meta;
        bad.levels.pop();
        assert!(TexelVariantsRef::from_arrays(bad, |n| art.raw_array(n).ok()).is_err());
        // Without the per-texel structures: the k-coherent sets come back, and a short one is
        // an error.
        let lean = build_texel_variants_with(&stripes(40, 7.0), &p, false, true, &|_| {}).unwrap();
        let art = round_trip(&lean);
        let r = TexelVariants::view(&art).unwrap();
        assert!(r.try_set(0, 0, Template::Causal).is_none());
        for l in 0..p.kset_levels() {
            assert_eq!(r.kset(l).entries, lean.as_ref().kset(l).entries);
        }
        let meta: VariantsMeta = art.meta().unwrap();
        assert!(
            TexelVariantsRef::from_arrays(meta, |n| {
                let a = art.raw_array(n).ok()?;
                Some(if n == "kset" { &a[..a.len() - 4] } else { a })
            })
            .is_err()
        );
        // Damage found through the format is an artifact error, not a panic.
        let mut fewer = v.clone();
        fewer.meta.levels.pop();
        assert!(TexelVariants::view(&round_trip(&fewer)).is_err());
    }
}
