//! Artifact formats of the feature-aligned method: the shape's feature curves, the exemplar's
//! feature lines and distance map, the oriented field, the refined mesh and the synthesized
//! vertex colours.
//!
//! All are read as owned copies (none is large next to the work done on it). Readers check
//! every index against the arrays of the same artifact, so a damaged artifact is an error
//! here; indices into another artifact (shape curves into the mesh, the refined mesh against
//! the input) are checked by the node that joins them, as an internal error.

use super::format::inconsistent;
use super::{AlignedBytes, Artifact, ArtifactError, ArtifactWriter, Format, Kind};
use crate::geom::Mesh;
use crate::geom::edge_refine::Refined;
use crate::stages::analyse_exemplar::texture_feature_lines::TextureFeatures;
use crate::stages::extract::crease_lines::Polyline;
use crate::stages::extract::shape_features::{CurveKind, FeatureSource, ShapeFeatures};
use crate::stages::field::feature_field::FeatureField;
use crate::stages::synthesize::texture_optimization::{SurfaceSynthesis, SynthesisStats};
use glam::Vec3;
use serde::{Deserialize, Serialize};

/// Curves as CSR: `start[i]..start[i+1]` indexes `vertices`; all vertices below `bound`.
fn curves_ok(start: &[u32], vertices: &[u32], bound: Option<usize>) -> bool {
    start.first() == Some(&0)
        && start.windows(2).all(|w| w[0] < w[1])
        && start.last().map(|&s| s as usize) == Some(vertices.len())
        && bound.is_none_or(|b| vertices.iter().all(|&v| (v as usize) < b))
}

fn to_csr(curves: &[&Polyline]) -> (Vec<u32>, Vec<u32>, Vec<u8>) {
    let mut start = vec![0u32];
    let mut vertices = Vec::new();
    let mut closed = Vec::new();
    for c in curves {
        vertices.extend_from_slice(&c.vertices);
        start.push(vertices.len() as u32);
        closed.push(c.closed as u8);
    }
    (start, vertices, closed)
}

fn from_csr(start: &[u32], vertices: &[u32], closed: &[u8]) -> Vec<Polyline> {
    (0..closed.len())
        .map(|i| Polyline {
            vertices: vertices[start[i] as usize..start[i + 1] as usize].to_vec(),
            closed: closed[i] != 0,
        })
        .collect()
}

/// An optional array of 0/1 flags: all false when absent (written only when one is set).
fn optional_flags(a: &Artifact, name: &str, len: usize) -> Result<Vec<bool>, ArtifactError> {
    if !a.array_names().contains(&name) {
        return Ok(vec![false; len]);
    }
    let flags: &[u8] = a.array(name)?;
    if flags.iter().any(|&f| f > 1) {
        return Err(inconsistent(format!("{name} flags are not 0 or 1")));
    }
    Ok(flags.iter().map(|&f| f == 1).collect())
}

/// Metadata: the source; arrays `start`, `vertices`, `closed`, `kinds`, and `fixed` (one
/// byte per curve) only when some curve is fixed, so that curves without the flag keep the
/// bytes (and hashes) they had before the flag existed.
impl Format for ShapeFeatures {
    const KIND: Kind = Kind::ShapeFeatures;
    type View<'a> = ShapeFeatures;
    fn write(&self) -> AlignedBytes {
        let (start, vertices, closed) = to_csr(&self.curves.iter().collect::<Vec<_>>());
        let kinds: Vec<u8> = self.kinds.iter().map(|&k| k as u8).collect();
        let fixed: Vec<u8> = self.fixed.iter().map(|&f| f as u8).collect();
        let w = ArtifactWriter::new(Self::KIND, &self.source)
            .array("start", &start)
            .array("vertices", &vertices)
            .array("closed", &closed)
            .array("kinds", &kinds);
        if self.fixed.contains(&true) {
            w.array("fixed", &fixed).finish()
        } else {
            w.finish()
        }
    }
    fn decode(a: &Artifact) -> Result<ShapeFeatures, ArtifactError> {
        let source: FeatureSource = a.meta()?;
        let start: &[u32] = a.array("start")?;
        let vertices: &[u32] = a.array("vertices")?;
        let closed: &[u8] = a.array("closed")?;
        let kinds: &[u8] = a.array("kinds")?;
        let kinds: Option<Vec<CurveKind>> =
            kinds.iter().map(|&k| CurveKind::from_code(k)).collect();
        let fixed = optional_flags(a, "fixed", closed.len())?;
        match kinds {
            Some(kinds)
                if curves_ok(start, vertices, None)
                    && closed.len() + 1 == start.len()
                    && kinds.len() == closed.len()
                    && fixed.len() == closed.len() =>
            {
                Ok(ShapeFeatures {
                    curves: from_csr(start, vertices, closed),
                    kinds,
                    fixed,
                    source,
                })
            }
            _ => Err(inconsistent("shape feature curves are inconsistent")),
        }
    }
}

#[derive(Serialize, Deserialize)]
struct TextureFeatureMeta {
    width: u32,
    height: u32,
    principal: u32,
    principal_angle: f32,
}

/// Metadata [`TextureFeatureMeta`]; arrays `line_start`, `points`, `distance`.
impl Format for TextureFeatures {
    const KIND: Kind = Kind::TextureFeatures;
    type View<'a> = TextureFeatures;
    fn write(&self) -> AlignedBytes {
        let mut start = vec![0u32];
        let mut points: Vec<[f32; 2]> = Vec::new();
        for l in &self.lines {
            points.extend_from_slice(l);
            start.push(points.len() as u32);
        }
        let meta = TextureFeatureMeta {
            width: self.width,
            height: self.height,
            principal: self.principal,
            principal_angle: self.principal_angle,
        };
        ArtifactWriter::new(Self::KIND, &meta)
            .array("line_start", &start)
            .array("points", &points)
            .array("distance", &self.distance)
            .finish()
    }
    fn decode(a: &Artifact) -> Result<TextureFeatures, ArtifactError> {
        let m: TextureFeatureMeta = a.meta()?;
        let start: &[u32] = a.array("line_start")?;
        let points: &[[f32; 2]] = a.array("points")?;
        let distance: &[f32] = a.array("distance")?;
        let lines = start.len().saturating_sub(1);
        let ok = start.first() == Some(&0)
            && start.windows(2).all(|w| w[0] <= w[1])
            && start.last().map(|&s| s as usize) == Some(points.len())
            && (m.principal as usize) < lines
            && m.principal_angle.is_finite()
            && distance.len() == m.width as usize * m.height as usize
            && distance.iter().all(|d| d.is_finite() && *d >= 0.0)
            && points.iter().flatten().all(|x| x.is_finite());
        if !ok {
            return Err(inconsistent("texture feature lines are inconsistent"));
        }
        Ok(TextureFeatures {
            width: m.width,
            height: m.height,
            lines: (0..lines)
                .map(|i| points[start[i] as usize..start[i + 1] as usize].to_vec())
                .collect(),
            principal: m.principal,
            principal_angle: m.principal_angle,
            distance: distance.to_vec(),
        })
    }
}

pub use crate::stages::field::feature_field::OrientedField;

#[derive(Serialize, Deserialize)]
struct FieldMeta {
    singularities: u32,
    arbitrary_singularities: u32,
}

/// Metadata [`FieldMeta`]; arrays `vectors`, `start`, `vertices`, `closed`, `signs`.
impl Format for OrientedField {
    const KIND: Kind = Kind::FeatureField;
    type View<'a> = OrientedField;
    fn write(&self) -> AlignedBytes {
        let f = &self.field;
        let (start, vertices, closed) =
            to_csr(&f.curves.iter().map(|(c, _)| c).collect::<Vec<_>>());
        let signs: Vec<i8> = f.curves.iter().map(|(_, s)| *s).collect();
        let meta = FieldMeta {
            singularities: f.singularities,
            arbitrary_singularities: self.arbitrary_singularities,
        };
        let fixed: Vec<u8> = f.fixed.iter().map(|&x| x as u8).collect();
        let w = ArtifactWriter::new(Self::KIND, &meta)
            .array("vectors", &f.vectors)
            .array("start", &start)
            .array("vertices", &vertices)
            .array("closed", &closed)
            .array("signs", &signs);
        // Only when some curve is fixed: fields without fixed curves keep their bytes.
        if f.fixed.contains(&true) {
            w.array("fixed", &fixed).finish()
        } else {
            w.finish()
        }
    }
    fn decode(a: &Artifact) -> Result<OrientedField, ArtifactError> {
        let m: FieldMeta = a.meta()?;
        let vectors: &[Vec3] = a.array("vectors")?;
        let start: &[u32] = a.array("start")?;
        let vertices: &[u32] = a.array("vertices")?;
        let closed: &[u8] = a.array("closed")?;
        let signs: &[i8] = a.array("signs")?;
        let fixed = optional_flags(a, "fixed", signs.len())?;
        let ok = curves_ok(start, vertices, Some(vectors.len()))
            && closed.len() + 1 == start.len()
            && signs.len() == closed.len()
            && fixed.len() == signs.len()
            && signs.iter().all(|s| matches!(s, 1 | -1))
            && vectors.iter().all(|v| v.is_finite());
        if !ok {
            return Err(inconsistent("feature field arrays are inconsistent"));
        }
        let curves = from_csr(start, vertices, closed)
            .into_iter()
            .zip(signs.iter().copied())
            .collect();
        Ok(OrientedField {
            field: FeatureField {
                vectors: vectors.to_vec(),
                curves,
                fixed,
                singularities: m.singularities,
                zero_vectors: 0,
            },
            arbitrary_singularities: m.arbitrary_singularities,
        })
    }
}

/// Metadata: the input's vertex count; arrays `positions`, `triangles`, `parents`,
/// `face_origin`.
impl Format for Refined {
    const KIND: Kind = Kind::RefinedMesh;
    type View<'a> = Refined;
    fn write(&self) -> AlignedBytes {
        ArtifactWriter::new(Self::KIND, &self.input_vertices)
            .array("positions", &self.mesh.positions)
            .array("triangles", &self.mesh.triangles)
            .array("parents", &self.parents)
            .array("face_origin", &self.face_origin)
            .finish()
    }
    fn decode(a: &Artifact) -> Result<Refined, ArtifactError> {
        let input_vertices: u32 = a.meta()?;
        let positions: &[Vec3] = a.array("positions")?;
        let triangles: &[[u32; 3]] = a.array("triangles")?;
        let parents: &[[u32; 2]] = a.array("parents")?;
        let face_origin: &[u32] = a.array("face_origin")?;
        let n = positions.len();
        // Origins index the input mesh's triangles: checked against it where they are used.
        let ok = input_vertices as usize + parents.len() == n
            && face_origin.len() == triangles.len()
            && triangles.iter().flatten().all(|&v| (v as usize) < n)
            && parents
                .iter()
                .enumerate()
                .all(|(i, p)| p.iter().all(|&v| v < input_vertices + i as u32))
            && positions.iter().all(|p| p.is_finite());
        if !ok {
            return Err(inconsistent("refined mesh arrays are inconsistent"));
        }
        Ok(Refined {
            mesh: Mesh::new(positions.to_vec(), triangles.to_vec()),
            input_vertices,
            parents: parents.to_vec(),
            face_origin: face_origin.to_vec(),
        })
    }
}

/// Metadata [`SynthesisStats`]; arrays `colours`, `source`.
impl Format for SurfaceSynthesis {
    const KIND: Kind = Kind::SurfaceColours;
    type View<'a> = SurfaceSynthesis;
    fn write(&self) -> AlignedBytes {
        ArtifactWriter::new(Self::KIND, &self.stats)
            .array("colours", &self.colours)
            .array("source", &self.source)
            .finish()
    }
    fn decode(a: &Artifact) -> Result<SurfaceSynthesis, ArtifactError> {
        let stats: SynthesisStats = a.meta()?;
        let colours: &[[f32; 3]] = a.array("colours")?;
        let source: &[[f32; 2]] = a.array("source")?;
        if colours.len() != source.len() || colours.iter().flatten().any(|c| !c.is_finite()) {
            return Err(inconsistent("surface colour arrays are inconsistent"));
        }
        Ok(SurfaceSynthesis {
            colours: colours.to_vec(),
            source: source.to_vec(),
            stats,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn features(fixed: Vec<bool>) -> ShapeFeatures {
        ShapeFeatures {
            curves: vec![
                Polyline {
                    vertices: vec![0, 1, 2],
                    closed: false,
                },
                Polyline {
                    vertices: vec![3, 4, 5],
                    closed: true,
                },
            ],
            kinds: vec![CurveKind::User; 2],
            fixed,
            source: FeatureSource::Curves,
        }
    }

    #[test]
    fn shape_features_keep_their_fixed_flags_and_write_them_only_when_set() {
        let some = features(vec![false, true]);
        let a = Artifact::from_bytes(some.write()).unwrap();
        assert!(a.array_names().contains(&"fixed"));
        assert_eq!(ShapeFeatures::decode(&a).unwrap(), some);

        let none = features(vec![false, false]);
        let a = Artifact::from_bytes(none.write()).unwrap();
        assert!(!a.array_names().contains(&"fixed"));
        assert_eq!(ShapeFeatures::decode(&a).unwrap(), none);
    }
}
