//! Artifact formats of the solid method: the candidate-triple analysis of an exemplar set, the
//! rotation field, the requested voxels, the synthesized samples, and the bricks that
//! synthesis caches as keyed pieces. Readers check lengths against the metadata and each
//! other, so a damaged artifact is an error, never an out-of-bounds index later.

use super::format::inconsistent;
use super::{AlignedBytes, Artifact, ArtifactError, ArtifactWriter, Format, Kind, ReadOwned};
use crate::stages::analyse_exemplar::candidate_triples::{SolidAnalysis, SolidAnalysisRef, Triple};
use crate::stages::field::quaternion_field::{FieldGrid, RotationField};
use crate::stages::parameterize::volume_embedding::{RequestedVoxels, Section, Volume};
use crate::stages::synthesize::solid::solid_synthesis::{Brick, BrickMeta};
use glam::{IVec3, Quat};
use serde::{Deserialize, Serialize};

/// The analysis: its metadata, then its arrays under the names
/// [`SolidAnalysis::arrays`] gives them, viewed in place.
impl Format for SolidAnalysis {
    const KIND: Kind = Kind::SolidAnalysis;
    type View<'a> = SolidAnalysisRef<'a>;
    fn write(&self) -> AlignedBytes {
        ArtifactWriter::new(Self::KIND, &self.meta)
            .arrays_bytes(self.arrays())
            .finish()
    }
    fn decode(a: &Artifact) -> Result<SolidAnalysisRef<'_>, ArtifactError> {
        let arrays: Vec<(String, &[u8])> = a
            .array_names()
            .into_iter()
            .map(|n| Ok((n.to_owned(), a.raw_array(n)?)))
            .collect::<Result<_, ArtifactError>>()?;
        SolidAnalysisRef::from_arrays(a.meta()?, &arrays).map_err(|e| inconsistent(e.to_string()))
    }
}

/// The field: its grid as metadata, a rotation and a scale per grid node. Read as an owned
/// copy (small: a coarse grid).
impl Format for RotationField {
    const KIND: Kind = Kind::RotationField;
    type View<'a> = RotationField;
    fn write(&self) -> AlignedBytes {
        ArtifactWriter::new(Self::KIND, &self.grid)
            .array("rotations", &self.rotations)
            .array("scales", &self.scales)
            .finish()
    }
    fn decode(a: &Artifact) -> Result<RotationField, ArtifactError> {
        let grid: FieldGrid = a.meta()?;
        let rotations: &[Quat] = a.array("rotations")?;
        let scales: &[f32] = a.array("scales")?;
        if rotations.len() != grid.len() || scales.len() != grid.len() {
            return Err(inconsistent("rotation field disagrees with its grid"));
        }
        Ok(RotationField {
            grid,
            rotations: rotations.to_vec(),
            scales: scales.to_vec(),
        })
    }
}

/// A section's sample grid as stored: origin, u, v, width, height.
type SectionGrid = ([f32; 3], [f32; 3], [f32; 3], u32, u32);

#[derive(Serialize, Deserialize)]
struct RequestMeta {
    volume: Volume,
    section: Option<SectionGrid>,
}

/// Requested voxels as a reader sees them.
pub struct RequestedVoxelsRef<'a> {
    pub volume: Volume,
    pub voxels: &'a [IVec3],
    pub section: Option<Section>,
    /// Each voxel's region, when the config has regions.
    pub regions: Option<&'a [u8]>,
}

/// The request: the volume and the section grid as metadata, the voxels, and their regions
/// (an array present only with regions).
impl Format for RequestedVoxels {
    const KIND: Kind = Kind::VoxelRequest;
    type View<'a> = RequestedVoxelsRef<'a>;
    fn write(&self) -> AlignedBytes {
        let meta = RequestMeta {
            volume: self.volume,
            section: self
                .section
                .as_ref()
                .map(|s| (s.origin.into(), s.u.into(), s.v.into(), s.width, s.height)),
        };
        let w = ArtifactWriter::new(Self::KIND, &meta).array("voxels", &self.voxels);
        match &self.regions {
            Some(r) => w.array("regions", r).finish(),
            None => w.finish(),
        }
    }
    fn decode(a: &Artifact) -> Result<RequestedVoxelsRef<'_>, ArtifactError> {
        let m: RequestMeta = a.meta()?;
        let voxels: &[IVec3] = a.array("voxels")?;
        let regions = if a.array_names().contains(&"regions") {
            let r: &[u8] = a.array("regions")?;
            if r.len() != voxels.len() {
                return Err(inconsistent("request: regions and voxels differ in length"));
            }
            Some(r)
        } else {
            None
        };
        Ok(RequestedVoxelsRef {
            volume: m.volume,
            voxels,
            section: m.section.map(|(o, u, v, width, height)| Section {
                origin: o.into(),
                u: u.into(),
                v: v.into(),
                width,
                height,
            }),
            regions,
        })
    }
}

/// What a synthesis node gives reconstruction: the finest-level triple of each voxel it was
/// asked for. How many bricks were reused depends on what the cache held, so it is logged and
/// counted in the run table, never stored: the artifact is the same whatever was cached.
pub struct SolidSamples {
    /// The number of voxels.
    pub count: u64,
    pub voxels: Vec<[i32; 3]>,
    pub triples: Vec<Triple>,
}

pub struct SolidSamplesRef<'a> {
    pub count: u64,
    pub voxels: &'a [[i32; 3]],
    pub triples: &'a [Triple],
}

impl SolidSamples {
    pub fn new(voxels: Vec<[i32; 3]>, triples: Vec<Triple>) -> SolidSamples {
        SolidSamples {
            count: voxels.len() as u64,
            voxels,
            triples,
        }
    }
}

crate::format_pair! {
    SolidSamples => SolidSamplesRef, kind: SolidSamples, meta: count,
    arrays: [voxels, triples],
    check: |s| s.voxels.len() as u64 == s.count && s.triples.len() == s.voxels.len(),
}

/// A brick: its level, coordinates and side as metadata, its triples (x fastest). Bricks are
/// keyed pieces of a synthesis node, read back as owned values.
impl Format for Brick {
    const KIND: Kind = Kind::SolidBrick;
    type View<'a> = Brick;
    fn write(&self) -> AlignedBytes {
        ArtifactWriter::new(Self::KIND, &self.meta())
            .array("triples", &self.triples)
            .finish()
    }
    fn decode(a: &Artifact) -> Result<Brick, ArtifactError> {
        Self::read(a)
    }
}

impl ReadOwned for Brick {
    fn read(a: &Artifact) -> Result<Brick, ArtifactError> {
        let meta: BrickMeta = a.meta()?;
        let triples = a.raw_array("triples")?;
        Brick::from_arrays(meta, &[("triples".to_string(), triples)])
            .map_err(|e| inconsistent(e.to_string()))
    }
}

/// A synthesis' bricks are its node's pieces, by (level, brick coordinates).
impl crate::stages::synthesize::solid::solid_synthesis::BrickStore
    for crate::pipeline::PieceStore<'_, (u32, [i32; 3]), Brick>
{
    fn get(&self, level: u32, brick: [i32; 3]) -> Option<std::sync::Arc<Brick>> {
        crate::pipeline::PieceStore::get(self, &(level, brick))
    }
    fn put(&self, level: u32, brick: [i32; 3], b: std::sync::Arc<Brick>) {
        crate::pipeline::PieceStore::put(self, &(level, brick), b)
    }
    /// The level's bricks are in the cache: only the copies in memory go.
    fn release(&self, level: u32) {
        self.forget(|(l, _)| *l == level)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bricks_and_requests_round_trip() {
        let b = Brick {
            level: 2,
            coord: [1, -2, 3],
            size: 2,
            triples: (0..8)
                .map(|i| Triple::new([i, 1], [2, i], [3, 4]))
                .collect(),
        };
        let a = Artifact::from_bytes(b.write()).unwrap();
        assert_eq!(Brick::read(&a).unwrap(), b);
        // The stage's own arrays read back as the same brick.
        assert_eq!(Brick::from_arrays(b.meta(), &b.arrays()).unwrap(), b);
        let short = ArtifactWriter::new(Kind::SolidBrick, &b.meta())
            .array("triples", &b.triples[..7])
            .finish();
        assert!(Brick::read(&Artifact::from_bytes(short).unwrap()).is_err());

        let r = RequestedVoxels {
            volume: Volume {
                origin: [0.5, -1.0, 2.0],
                voxel: 0.25,
                dims: [4, 5, 6],
            },
            voxels: vec![IVec3::new(1, 2, 3), IVec3::new(3, 2, 1)],
            section: Some(Section {
                origin: glam::Vec3::ONE,
                u: glam::Vec3::X,
                v: glam::Vec3::Y,
                width: 7,
                height: 8,
            }),
            regions: Some(vec![0, 1]),
        };
        let a = Artifact::from_bytes(r.write()).unwrap();
        let v = RequestedVoxels::view(&a).unwrap();
        assert_eq!(
            (v.volume, v.voxels, v.section.as_ref(), v.regions),
            (
                r.volume,
                &r.voxels[..],
                r.section.as_ref(),
                r.regions.as_deref()
            )
        );
    }
}
