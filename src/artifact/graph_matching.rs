//! Artifact formats of the graph-matching method: the √2 hierarchy, the resolved field keys,
//! the sweep field, the Gaussian stack and the synthesized vertex colours.
//!
//! All are read as owned copies: the stages index them with derived adjacency, and none is
//! large next to the work done on it. Readers check every index against the arrays it points
//! into, so a damaged artifact is an error here, never an out-of-bounds index later.

use super::format::inconsistent;
use super::{AlignedBytes, Artifact, ArtifactError, ArtifactWriter, Format, Kind};
use crate::stages::analyse_exemplar::gaussian_stack::{GaussianStack, StackMeta};
use crate::stages::field::sweep_field::{FieldKeys, SweepField};
use crate::stages::parameterize::sqrt2_subdivision::Sqrt2Hierarchy;
use crate::stages::synthesize::graph_matching::{GraphMatching, MatchStats};
use glam::Vec3;
use serde::{Deserialize, Serialize};

/// A CSR index (`start`, `items`) is well formed: starts at 0, never decreases, ends at the
/// item count, and every item is below `bound`.
fn csr_ok(start: &[u32], items: &[u32], bound: usize) -> bool {
    start.first() == Some(&0)
        && start.windows(2).all(|w| w[0] <= w[1])
        && *start.last().expect("non-empty") as usize == items.len()
        && items.iter().all(|&i| (i as usize) < bound)
}

#[derive(Serialize, Deserialize)]
struct HierarchyMeta {
    input_vertices: u32,
    level_vertices: Vec<u32>,
    level_face_start: Vec<u32>,
}

/// Metadata: per-level vertex counts and face offsets; arrays `positions`, `face_start`,
/// `face_vertices`, `parent_start`, `parent_vertices`.
impl Format for Sqrt2Hierarchy {
    const KIND: Kind = Kind::Sqrt2Hierarchy;
    type View<'a> = Sqrt2Hierarchy;
    fn write(&self) -> AlignedBytes {
        let meta = HierarchyMeta {
            input_vertices: self.input_vertices,
            level_vertices: self.level_vertices.clone(),
            level_face_start: self.level_face_start.clone(),
        };
        ArtifactWriter::new(Self::KIND, &meta)
            .array("positions", &self.positions)
            .array("face_start", &self.face_start)
            .array("face_vertices", &self.face_vertices)
            .array("parent_start", &self.parent_start)
            .array("parent_vertices", &self.parent_vertices)
            .finish()
    }
    fn decode(a: &Artifact) -> Result<Sqrt2Hierarchy, ArtifactError> {
        let m: HierarchyMeta = a.meta()?;
        let positions: &[Vec3] = a.array("positions")?;
        let face_start: &[u32] = a.array("face_start")?;
        let face_vertices: &[u32] = a.array("face_vertices")?;
        let parent_start: &[u32] = a.array("parent_start")?;
        let parent_vertices: &[u32] = a.array("parent_vertices")?;
        let n = positions.len();
        let faces = face_start.len().saturating_sub(1);
        let ok = !m.level_vertices.is_empty()
            && m.input_vertices <= m.level_vertices[0]
            && m.level_vertices.windows(2).all(|w| w[0] <= w[1])
            && m.level_vertices.last().map(|&v| v as usize) == Some(n)
            && m.level_face_start.len() == m.level_vertices.len() + 1
            && m.level_face_start.first() == Some(&0)
            && m.level_face_start.windows(2).all(|w| w[0] <= w[1])
            && m.level_face_start.last().map(|&f| f as usize) == Some(faces)
            && csr_ok(face_start, face_vertices, n)
            && parent_start.len() == n + 1
            && csr_ok(parent_start, parent_vertices, n)
            && positions.iter().all(|p| p.is_finite());
        if !ok {
            return Err(inconsistent("√2 hierarchy arrays are inconsistent"));
        }
        // A level's faces use only that level's vertices.
        for l in 0..m.level_vertices.len() {
            let (f0, f1) = (m.level_face_start[l], m.level_face_start[l + 1]);
            let (i0, i1) = (face_start[f0 as usize], face_start[f1 as usize]);
            if face_vertices[i0 as usize..i1 as usize]
                .iter()
                .any(|&v| v >= m.level_vertices[l])
            {
                return Err(inconsistent(
                    "√2 hierarchy: a face uses a finer level's vertex",
                ));
            }
        }
        Ok(Sqrt2Hierarchy {
            input_vertices: m.input_vertices,
            positions: positions.to_vec(),
            level_vertices: m.level_vertices,
            level_face_start: m.level_face_start,
            face_start: face_start.to_vec(),
            face_vertices: face_vertices.to_vec(),
            parent_start: parent_start.to_vec(),
            parent_vertices: parent_vertices.to_vec(),
        })
    }
}

/// Metadata: the key count; arrays `vertices`, `directions`.
impl Format for FieldKeys {
    const KIND: Kind = Kind::FieldKeys;
    type View<'a> = FieldKeys;
    fn write(&self) -> AlignedBytes {
        ArtifactWriter::new(Self::KIND, &(self.vertices.len() as u64))
            .array("vertices", &self.vertices)
            .array("directions", &self.directions)
            .finish()
    }
    fn decode(a: &Artifact) -> Result<FieldKeys, ArtifactError> {
        let n: u64 = a.meta()?;
        let vertices: &[u32] = a.array("vertices")?;
        let directions: &[Vec3] = a.array("directions")?;
        if vertices.len() as u64 != n
            || directions.len() as u64 != n
            || directions.iter().any(|d| !d.is_finite())
        {
            return Err(inconsistent("field keys arrays are inconsistent"));
        }
        Ok(FieldKeys {
            vertices: vertices.to_vec(),
            directions: directions.to_vec(),
        })
    }
}

/// Metadata: passes per level; arrays `orientation`, `sweep`.
impl Format for SweepField {
    const KIND: Kind = Kind::SweepField;
    type View<'a> = SweepField;
    fn write(&self) -> AlignedBytes {
        ArtifactWriter::new(Self::KIND, &self.passes)
            .array("orientation", &self.orientation)
            .array("sweep", &self.sweep)
            .finish()
    }
    fn decode(a: &Artifact) -> Result<SweepField, ArtifactError> {
        let passes: Vec<u32> = a.meta()?;
        let orientation: &[Vec3] = a.array("orientation")?;
        let sweep: &[f32] = a.array("sweep")?;
        if sweep.len() > orientation.len()
            || orientation.iter().any(|o| !o.is_finite())
            || sweep.iter().any(|s| !s.is_finite())
        {
            return Err(inconsistent("sweep field arrays are inconsistent"));
        }
        Ok(SweepField {
            orientation: orientation.to_vec(),
            sweep: sweep.to_vec(),
            passes,
        })
    }
}

/// Metadata [`StackMeta`]; array `texels`.
impl Format for GaussianStack {
    const KIND: Kind = Kind::GaussianStack;
    type View<'a> = GaussianStack;
    fn write(&self) -> AlignedBytes {
        ArtifactWriter::new(Self::KIND, &self.meta)
            .array("texels", &self.texels)
            .finish()
    }
    fn decode(a: &Artifact) -> Result<GaussianStack, ArtifactError> {
        let meta: StackMeta = a.meta()?;
        let texels: &[[f32; 3]] = a.array("texels")?;
        let stack = GaussianStack {
            meta,
            texels: texels.to_vec(),
        };
        if !stack.view().is_consistent() {
            return Err(inconsistent("Gaussian stack disagrees with its sizes"));
        }
        Ok(stack)
    }
}

/// Metadata [`MatchStats`]; arrays `colours`, `level_colours`, `sources`.
impl Format for GraphMatching {
    const KIND: Kind = Kind::VertexColours;
    type View<'a> = GraphMatching;
    fn write(&self) -> AlignedBytes {
        ArtifactWriter::new(Self::KIND, &self.stats)
            .array("colours", &self.colours)
            .array("level_colours", &self.level_colours)
            .array("sources", &self.sources)
            .finish()
    }
    fn decode(a: &Artifact) -> Result<GraphMatching, ArtifactError> {
        let stats: MatchStats = a.meta()?;
        let colours: &[[f32; 3]] = a.array("colours")?;
        let level_colours: &[[f32; 3]] = a.array("level_colours")?;
        let sources: &[[f32; 2]] = a.array("sources")?;
        if sources.len() != colours.len() || level_colours.len() < colours.len() {
            return Err(inconsistent("vertex colour arrays are inconsistent"));
        }
        Ok(GraphMatching {
            colours: colours.to_vec(),
            level_colours: level_colours.to_vec(),
            sources: sources.to_vec(),
            stats,
        })
    }
}
