//! Method `solid`: sketch-guided solid texturing, synthesized on demand (Zhang, Du, Lai, Ni &
//! Hu 2011).
//!
//! ```text
//! inputs.xy/yz/zx ─ import.* ─ analyse_exemplar (stacks, PCA, candidate triples and slabs) ─┐
//! inputs.mesh ─ import.mesh ─┬─ field (quaternion field from the sketch curves) ───────────┼─ synthesize ─ reconstruct ─ files
//!                            └─ parameterize (volume, requested voxels) ───────────────────┘
//! ```
//!
//! `synthesize` stores every pyramid level as bricks, one cache object each, keyed by what a
//! brick depends on (analysis, field, volume, synthesis parameters, its level and position) and
//! never by the request: a second request (another cross-section of the same solid) reuses
//! every brick the first one made and computes only the ones it lacks.

use super::{MethodError, import_image, import_mesh, to_json};
use crate::artifact::kinds::{read_mesh, view_image, write_bundle};
use crate::artifact::{Artifact, ArtifactWriter, ContentHash, Kind, canonical_bytes};
use crate::cache::{Cache, Lookup};
use crate::config::{Config, check_range};
use crate::image::Image;
use crate::pipeline::{Dag, InputRef, Node, NodeError, Stage};
use crate::stages::analyse_exemplar::candidate_triples::{
    AnalysisMeta, CandidateParams, SolidAnalysisRef, Triple, analyse,
};
use crate::stages::field::quaternion_field::{
    Curve, FieldGrid, RotationField, ScalePoint, rotation_field,
};
use crate::stages::parameterize::volume_embedding::{
    Section, Volume as Embedding, box_voxels, embed, outside_voxels, section,
    section_voxels_inside, surface_voxels, voxel_depths,
};
use crate::stages::reconstruct::textured_export::encode_png;
use crate::stages::synthesize::solid::solid_synthesis::{
    Brick, BrickMeta, BrickStore, SolidParams, SolidSynthesis, Volume, VoxelRequest,
};
use glam::{IVec3, Quat, Vec3};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

const ANALYSIS_VERSION: u32 = 1;
const FIELD_VERSION: u32 = 1;
const REQUEST_VERSION: u32 = 4;
const SYNTH_VERSION: u32 = 2;
const RECONSTRUCT_VERSION: u32 = 1;

/// A `solid` config.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SolidConfig {
    pub method: String,
    pub inputs: SolidInputs,
    #[serde(default)]
    pub analyse_exemplar: CandidateParams,
    #[serde(default)]
    pub field: SolidFieldParams,
    #[serde(default)]
    pub parameterize: RequestParams,
    #[serde(default)]
    pub synthesize: SolidParams,
    #[serde(default)]
    pub reconstruct: SolidExportParams,
    /// `[[regions]]`: other exemplar sets for shells under the surface (§7, Fig. 15), listed
    /// from the surface inwards; the voxels deeper than the last one take `[inputs]`'s.
    #[serde(default)]
    pub regions: Vec<SolidRegion>,
}

/// A shell under the surface synthesized from its own exemplars (§7, Fig. 15: tree bark near
/// the surface, wood inside). Each region is a separate solid, synthesized only at the voxels
/// it owns, in the same field.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SolidRegion {
    /// How deep under the surface the region reaches, in the mesh's units: it holds the
    /// voxels whose centres are less deep than this and at least as deep as the previous
    /// region's `depth`. Voxels outside the mesh count as depth 0. Depths must increase.
    pub depth: f32,
    /// One exemplar for all three planes, or one per plane, as in `[inputs]`.
    #[serde(default)]
    pub exemplar: Option<ExemplarSpec>,
    #[serde(default)]
    pub xy: Option<ExemplarSpec>,
    #[serde(default)]
    pub yz: Option<ExemplarSpec>,
    #[serde(default)]
    pub zx: Option<ExemplarSpec>,
    /// This region's plane weights (see `analyse_exemplar.plane_weights`). Default: those of
    /// `[analyse_exemplar]`.
    #[serde(default)]
    pub plane_weights: Option<[f32; 3]>,
}

/// An exemplar image, optionally transposed (so one image can show the same layers in two
/// planes whose axes run the other way round).
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum ExemplarSpec {
    Path(PathBuf),
    Spec {
        path: PathBuf,
        #[serde(default)]
        transpose: bool,
    },
}

impl ExemplarSpec {
    fn path(&self) -> &PathBuf {
        match self {
            ExemplarSpec::Path(p) | ExemplarSpec::Spec { path: p, .. } => p,
        }
    }
    fn transpose(&self) -> bool {
        matches!(
            self,
            ExemplarSpec::Spec {
                transpose: true,
                ..
            }
        )
    }
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SolidInputs {
    /// The shape the solid is embedded around and whose surface is coloured.
    pub mesh: PathBuf,
    /// One exemplar for all three planes, or …
    #[serde(default)]
    pub exemplar: Option<ExemplarSpec>,
    /// … one per plane (the local frame's xy, yz and zx planes; any may be omitted if
    /// `exemplar` is given). Different images must have the same size.
    #[serde(default)]
    pub xy: Option<ExemplarSpec>,
    #[serde(default)]
    pub yz: Option<ExemplarSpec>,
    #[serde(default)]
    pub zx: Option<ExemplarSpec>,
}

/// `[field]`: the sketch.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct SolidFieldParams {
    /// Sketch curves: `{ points = [[x, y, z], …], axis = "x" | "y" | "z" }` (axis optional),
    /// in drawing order. Default: none (the trivial field).
    pub curves: Vec<Curve>,
    /// A TOML file beside the config with more curves (`curves = [...]`), appended after
    /// `curves`. Default: none.
    pub curves_file: Option<PathBuf>,
    /// Cells on the shortest side of the field's grid, 4..=128. Default: 24 (§6: 20–30).
    pub cells: Option<u32>,
    /// User scalings at points (the optional scale field of §3). Default: none.
    pub scales: Vec<ScalePoint>,
}

/// What part of the solid to synthesize.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Request {
    /// The voxels the mesh's surface passes through (to colour the mesh).
    Surface,
    /// The plane through `point` with `normal`: the cut of the object (samples inside the
    /// mesh), as an image.
    Section { point: [f32; 3], normal: [f32; 3] },
    /// Every voxel of a box (a small full volume).
    Box { min: [f32; 3], max: [f32; 3] },
}

/// `[parameterize]`: the volume and the request.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RequestParams {
    /// Voxels along the volume's longest side, 8..=4096. Default: 256 (the paper uses
    /// 800–1024).
    pub resolution: u32,
    /// How much larger than the bounding box the volume is, 0..=4. Default: 0.25 (§6: 20–30%).
    pub margin: f32,
    /// Default: the surface.
    pub request: Request,
}

impl Default for RequestParams {
    fn default() -> Self {
        RequestParams {
            resolution: 256,
            margin: 0.25,
            request: Request::Surface,
        }
    }
}

/// `[reconstruct]`.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct SolidExportParams {
    /// Side of each preview view, 16..=4096. Default: 512.
    pub preview_size: u32,
    /// The mesh's up direction, for the preview. Default: [0, 1, 0].
    pub up: [f32; 3],
    /// Side of the baked texture in the .glb, 64..=8192. Default: 2048.
    pub atlas_size: u32,
    /// The surface is refined until its edges are at most this many voxels long (so every
    /// voxel's colour shows), 0.5..=16. Default: 1.5.
    pub edge_voxels: f32,
    /// Cap on the refined surface's triangles. Default: 2 000 000.
    pub max_faces: u32,
}

impl Default for SolidExportParams {
    fn default() -> Self {
        SolidExportParams {
            preview_size: 512,
            up: [0.0, 1.0, 0.0],
            atlas_size: 2048,
            edge_voxels: 1.5,
            max_faces: 2_000_000,
        }
    }
}

/// The curves file format.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CurvesFile {
    curves: Vec<Curve>,
}

pub fn build(config: &Config) -> Result<Dag, MethodError> {
    let c: SolidConfig = config.parse()?;
    let check = |key: &str, r: Result<(), String>| r.map_err(|m| config.invalid(key, &m));
    check(
        "analyse_exemplar",
        c.analyse_exemplar.validate().map_err(|e| e.to_string()),
    )?;
    let levels = c.analyse_exemplar.levels;
    if c.synthesize.levels.len() != levels as usize {
        return Err(config
            .invalid(
                "synthesize.levels",
                &format!(
                    "has {} entries but analyse_exemplar.levels is {levels}: give one [[synthesize.levels]] per pyramid level",
                    c.synthesize.levels.len()
                ),
            )
            .into());
    }
    check(
        "parameterize.resolution",
        check_range(
            "parameterize.resolution",
            c.parameterize.resolution,
            8,
            4096,
        ),
    )?;
    check(
        "parameterize.margin",
        check_range("parameterize.margin", c.parameterize.margin, 0.0, 4.0),
    )?;
    let e = &c.reconstruct;
    check(
        "reconstruct.preview_size",
        check_range("reconstruct.preview_size", e.preview_size, 16, 4096),
    )?;
    check(
        "reconstruct.atlas_size",
        check_range("reconstruct.atlas_size", e.atlas_size, 64, 8192),
    )?;
    check(
        "reconstruct.edge_voxels",
        check_range("reconstruct.edge_voxels", e.edge_voxels, 0.5, 16.0),
    )?;
    let cells = c.field.cells.unwrap_or(24);
    check("field.cells", check_range("field.cells", cells, 4, 128))?;
    check(
        "field",
        crate::stages::field::quaternion_field::validate_curves(&c.field.curves, &c.field.scales)
            .map_err(|e| e.to_string()),
    )?;

    let mut dag = Dag::default();
    let mesh = import_mesh(
        &mut dag,
        "import.mesh",
        &config.resolve(&c.inputs.mesh),
        "inputs.mesh",
    )?;

    // Exemplar sets: `[inputs]`'s for the core, then each region's.
    let mut imports: Vec<(PathBuf, InputRef)> = Vec::new();
    let core_planes = exemplar_set(
        config,
        "inputs",
        [&c.inputs.xy, &c.inputs.yz, &c.inputs.zx],
        &c.inputs.exemplar,
    )?;
    let analysis = add_analysis(
        &mut dag,
        config,
        &mut imports,
        "analyse_exemplar",
        &core_planes,
        c.analyse_exemplar.clone(),
    )?;
    if c.regions.len() > 16 {
        return Err(config
            .invalid(
                "regions",
                &format!("has {} regions: at most 16", c.regions.len()),
            )
            .into());
    }
    let mut region_analyses = Vec::new();
    let mut depths = Vec::new();
    for (k, r) in c.regions.iter().enumerate() {
        let key = format!("regions[{k}]");
        if !(r.depth.is_finite() && r.depth > 0.0) {
            return Err(config
                .invalid(
                    &format!("{key}.depth"),
                    &format!("is {}: expected a depth under the surface greater than 0, in the mesh's units", r.depth),
                )
                .into());
        }
        if let Some(&prev) = depths.last()
            && r.depth <= prev
        {
            return Err(config
                .invalid(
                    &format!("{key}.depth"),
                    &format!("is {} but the region before reaches {prev}: list regions from the surface inwards, depths increasing", r.depth),
                )
                .into());
        }
        depths.push(r.depth);
        let mut p = c.analyse_exemplar.clone();
        if let Some(w) = r.plane_weights {
            p.plane_weights = w;
            check(
                &format!("{key}.plane_weights"),
                p.validate().map_err(|e| e.to_string()),
            )?;
        }
        let planes = exemplar_set(config, &key, [&r.xy, &r.yz, &r.zx], &r.exemplar)?;
        region_analyses.push(add_analysis(
            &mut dag,
            config,
            &mut imports,
            &format!("analyse_exemplar.region{}", k + 1),
            &planes,
            p,
        )?);
    }

    // The field: curves from the config, then from the curves file.
    let mut field_inputs = vec![mesh];
    let curves_file = c.field.curves_file.as_ref().map(|f| config.resolve(f));
    if let Some(f) = &curves_file {
        field_inputs.push(dag.add_file(f, "field.curves_file")?);
    }
    let fp = c.field.clone();
    let margin = c.parameterize.margin;
    let field = dag.add(Node {
        name: "field".into(),
        stage: Stage::Field,
        algorithm: "quaternion_field",
        version: FIELD_VERSION,
        params: canonical_bytes(&(&fp.curves, &fp.scales, cells, margin)),
        params_json: to_json(&fp),
        inputs: field_inputs,
        exports: false,
        keyed: Vec::new(),
        pieces: None,
        compute: Box::new(move |ctx| {
            let mesh = read_mesh(ctx.artifact(0))?;
            let mut curves = fp.curves.clone();
            if curves_file.is_some() {
                let f = ctx.file(1);
                let text = std::str::from_utf8(&f.bytes).map_err(|_| {
                    NodeError::input(format!("{}: not UTF-8 text", f.path.display()))
                })?;
                let extra: CurvesFile = toml::from_str(text).map_err(|e| {
                    NodeError::input(format!(
                        "{}: {}",
                        f.path.display(),
                        e.to_string().trim_end()
                    ))
                })?;
                let offset = curves.len();
                crate::stages::field::quaternion_field::validate_curves(&extra.curves, &[])
                    .map_err(|e| {
                        NodeError::input(format!(
                            "{}: {e} (curve numbers count from {offset} after the config's)",
                            f.path.display()
                        ))
                    })?;
                curves.extend(extra.curves);
            }
            let (lo, hi) = mesh.bounds();
            let grow = (hi - lo) * margin * 0.5;
            let grid = FieldGrid::covering(lo - grow, hi + grow, cells);
            let f = rotation_field(grid, &curves, &fp.scales).map_err(NodeError::input)?;
            Ok(write_field(&f))
        }),
    });

    let rp = c.parameterize.clone();
    let region_depths = depths.clone();
    let request = dag.add(Node {
        name: "parameterize".into(),
        stage: Stage::Parameterize,
        algorithm: "volume_request",
        version: REQUEST_VERSION,
        params: if depths.is_empty() {
            canonical_bytes(&rp)
        } else {
            canonical_bytes(&(&rp, &depths))
        },
        params_json: to_json(&rp),
        inputs: vec![mesh],
        exports: false,
        keyed: Vec::new(),
        pieces: None,
        compute: Box::new(move |ctx| {
            let mesh = read_mesh(ctx.artifact(0))?;
            let vol = embed(&mesh, rp.resolution, rp.margin).map_err(NodeError::input)?;
            // Sections and regions both need inside/outside: one flood fill for both.
            let outside_cell = std::cell::OnceCell::new();
            let outside = || {
                outside_cell
                    .get_or_init(|| outside_voxels(&mesh, &vol))
                    .as_slice()
            };
            let (voxels, sec) = match &rp.request {
                Request::Surface => (surface_voxels(&mesh, &vol), None),
                Request::Section { point, normal } => {
                    let s = section(&vol, Vec3::from(*point), Vec3::from(*normal))
                        .map_err(|e| NodeError::input(format!("parameterize.request: {e}")))?;
                    // A cut of the object: the plane's samples inside the mesh.
                    (section_voxels_inside(&vol, &s, outside()), Some(s))
                }
                Request::Box { min, max } => (
                    box_voxels(&vol, Vec3::from(*min), Vec3::from(*max))
                        .map_err(|e| NodeError::input(format!("parameterize.request: {e}")))?,
                    None,
                ),
            };
            // Each voxel's region: the first whose depth it lies above, else the core (index
            // `depths.len()`).
            let regions = (!region_depths.is_empty()).then(|| {
                voxel_depths(&mesh, &vol, &voxels, outside())
                    .into_iter()
                    .map(|d| {
                        region_depths
                            .iter()
                            .position(|&r| d < r)
                            .unwrap_or(region_depths.len()) as u8
                    })
                    .collect::<Vec<u8>>()
            });
            Ok(write_request(
                &vol,
                &voxels,
                sec.as_ref(),
                regions.as_deref(),
            ))
        }),
    });

    let sp = c.synthesize.clone();
    let core_region = (!depths.is_empty()).then_some(depths.len() as u8);
    let samples = add_synthesis(
        &mut dag,
        "synthesize".into(),
        [analysis, field, request],
        sp.clone(),
        core_region,
    );
    let region_samples: Vec<(InputRef, InputRef)> = region_analyses
        .iter()
        .enumerate()
        .map(|(k, &a)| {
            let s = add_synthesis(
                &mut dag,
                format!("synthesize.region{}", k + 1),
                [a, field, request],
                sp.clone(),
                Some(k as u8),
            );
            (s, a)
        })
        .collect();

    let ep = c.reconstruct.clone();
    let request_kind = c.parameterize.request.clone();
    let regions = region_samples.len();
    dag.add(Node {
        name: "reconstruct".into(),
        stage: Stage::Reconstruct,
        algorithm: "solid_colour",
        version: RECONSTRUCT_VERSION,
        params: canonical_bytes(&(&ep, &request_kind)),
        params_json: to_json(&ep),
        inputs: {
            // The core's samples and analysis, the request and mesh, then each region's pair.
            let mut v = vec![samples, analysis, request, mesh];
            for (s, a) in &region_samples {
                v.extend([*s, *a]);
            }
            v
        },
        exports: true,
        keyed: Vec::new(),
        pieces: None,
        compute: Box::new(move |ctx| {
            let req = read_request(ctx.artifact(2))?;
            let mut colours: HashMap<IVec3, [f32; 3]> = HashMap::new();
            let pairs = std::iter::once((0, 1)).chain((0..regions).map(|k| (4 + 2 * k, 5 + 2 * k)));
            for (si, ai) in pairs {
                let s = ctx.artifact(si);
                s.expect_kind(Kind::SolidSamples)?;
                let voxels: &[[i32; 3]] = s.array("voxels")?;
                let triples: &[Triple] = s.array("triples")?;
                let analysis = view_analysis(ctx.artifact(ai))?;
                let finest = analysis.levels() as usize - 1;
                colours.extend(
                    voxels
                        .iter()
                        .zip(triples)
                        .map(|(v, t)| (IVec3::from(*v), analysis.colour(finest, t))),
                );
            }
            let files = match &request_kind {
                Request::Surface => {
                    let mesh = read_mesh(ctx.artifact(3))?;
                    export_surface(&mesh, &req.volume, &colours, &ep, &|f| ctx.progress.set(f))?
                }
                Request::Section { .. } => {
                    let sec = req
                        .section
                        .as_ref()
                        .ok_or_else(|| NodeError::internal("section request without its grid"))?;
                    vec![(
                        "section.png".into(),
                        section_png(&req.volume, sec, &colours),
                    )]
                }
                Request::Box { .. } => export_box(&req.voxels, &req.volume, &colours),
            };
            Ok(write_bundle(&files))
        }),
    });
    Ok(dag)
}

/// One exemplar set: each plane's image, falling back to the shared one, with the config key
/// it came from (`key` names the config table), for errors about the file.
fn exemplar_set(
    config: &Config,
    key: &str,
    planes: [&Option<ExemplarSpec>; 3],
    shared: &Option<ExemplarSpec>,
) -> Result<[(ExemplarSpec, String); 3], MethodError> {
    let mut specs = Vec::new();
    for (name, spec) in ["xy", "yz", "zx"].into_iter().zip(planes) {
        match (spec, shared) {
            (Some(s), _) => specs.push((s.clone(), format!("{key}.{name}"))),
            (None, Some(s)) => specs.push((s.clone(), format!("{key}.exemplar"))),
            (None, None) => {
                return Err(config
                    .invalid(
                        &format!("{key}.{name}"),
                        "missing: give `exemplar` for all planes or one per plane",
                    )
                    .into());
            }
        }
    }
    Ok(specs.try_into().expect("three planes"))
}

/// The candidate-triple analysis of one exemplar set, importing each image once however many
/// planes and sets use it.
fn add_analysis(
    dag: &mut Dag,
    config: &Config,
    imports: &mut Vec<(PathBuf, InputRef)>,
    name: &str,
    specs: &[(ExemplarSpec, String); 3],
    p: CandidateParams,
) -> Result<InputRef, MethodError> {
    let mut plane_inputs = Vec::new();
    for (spec, key) in specs {
        let path = config.resolve(spec.path());
        let input = match imports.iter().find(|(q, _)| *q == path) {
            Some((_, r)) => *r,
            None => {
                let node = match imports.len() {
                    0 => "import.exemplar".to_string(),
                    n => format!("import.exemplar.{n}"),
                };
                let r = import_image(dag, &node, &path, key)?;
                imports.push((path.clone(), r));
                r
            }
        };
        plane_inputs.push(input);
    }
    let transposes: [bool; 3] = [
        specs[0].0.transpose(),
        specs[1].0.transpose(),
        specs[2].0.transpose(),
    ];
    Ok(dag.add(Node {
        name: name.into(),
        stage: Stage::AnalyseExemplar,
        algorithm: "candidate_triples",
        version: ANALYSIS_VERSION,
        params: canonical_bytes(&(&p, transposes)),
        params_json: to_json(&p),
        inputs: plane_inputs,
        exports: false,
        keyed: Vec::new(),
        pieces: None,
        compute: Box::new(move |ctx| {
            let imgs: Vec<Image> = (0..3)
                .map(|k| {
                    let v = view_image(ctx.artifact(k))?;
                    Ok(if transposes[k] {
                        transpose(v.to_owned())
                    } else {
                        v.to_owned()
                    })
                })
                .collect::<Result<_, NodeError>>()?;
            let a = analyse([imgs[0].view(), imgs[1].view(), imgs[2].view()], &p)
                .map_err(NodeError::input)?;
            let mut w = ArtifactWriter::new(Kind::SolidAnalysis, &a.meta);
            for (name, bytes) in a.arrays() {
                w = w.array_bytes(&name, bytes.to_vec());
            }
            Ok(w.finish())
        }),
    }))
}

/// The synthesis of one exemplar set's solid at the requested voxels it owns (`region`: the
/// voxels of that region only, `None`: all of them).
fn add_synthesis(
    dag: &mut Dag,
    name: String,
    [analysis, field, request]: [InputRef; 3],
    sp: SolidParams,
    region: Option<u8>,
) -> InputRef {
    dag.add(Node {
        name,
        stage: Stage::Synthesize,
        algorithm: "solid_bricks",
        version: SYNTH_VERSION,
        // The region is part of the key: two regions with the same exemplar set have the same
        // inputs but own different voxels.
        params: match region {
            None => canonical_bytes(&sp),
            Some(k) => canonical_bytes(&(&sp, k)),
        },
        params_json: to_json(&sp),
        inputs: vec![analysis, field, request],
        exports: false,
        keyed: Vec::new(),
        pieces: None,
        compute: Box::new(move |ctx| {
            let analysis = view_analysis(ctx.artifact(0))?;
            let field = read_field(ctx.artifact(1))?;
            let req = read_request(ctx.artifact(2))?;
            let volume = Volume {
                origin: req.volume.origin,
                voxel_size: req.volume.voxel,
                dims: req.volume.dims,
                levels: sp.levels.len() as u32,
            };
            let synth = SolidSynthesis::new(analysis, &field, volume, sp.clone()).map_err(NodeError::input)?;
            let voxels: Vec<[i32; 3]> = match (region, &req.regions) {
                (Some(k), Some(owner)) => req
                    .voxels
                    .iter()
                    .zip(owner)
                    .filter(|(_, o)| **o == k)
                    .map(|(v, _)| v.to_array())
                    .collect(),
                (Some(_), None) => {
                    return Err(NodeError::internal("a region's synthesis without voxel regions"));
                }
                (None, _) => req.voxels.iter().map(|v| v.to_array()).collect(),
            };
            let request = VoxelRequest::from_voxels(&voxels);
            // Bricks are keyed by everything they depend on except the request.
            let mut h = blake3::Hasher::new();
            h.update(b"texsyn solid brick v1\0");
            h.update(&SYNTH_VERSION.to_le_bytes());
            h.update(&canonical_bytes(&sp));
            h.update(&ctx.input_hashes[0].0);
            h.update(&ctx.input_hashes[1].0);
            h.update(&canonical_bytes(&volume));
            let store = CacheBrickStore::new(ctx.cache, ContentHash(*h.finalize().as_bytes()));
            let report = synth.synthesize(&request, &store).map_err(NodeError::input)?;
            for l in &report.levels {
                tracing::info!(
                    "synthesize: level {}: {} bricks needed, {} computed, {} reused; {} voxels, {} corrections",
                    l.level,
                    l.bricks_needed,
                    l.bricks_computed,
                    l.bricks_reused,
                    l.voxels,
                    l.corrections
                );
            }
            let finest = volume.levels;
            let triples: Vec<Triple> = voxels
                .iter()
                .map(|v| synth.triple_at(&store, finest, *v).ok_or_else(|| NodeError::internal(format!("voxel {v:?} was not synthesized"))))
                .collect::<Result<_, _>>()?;
            // How many bricks were reused depends on what the cache held, so it is logged, never
            // stored: the artifact is the same whatever was cached.
            Ok(ArtifactWriter::new(Kind::SolidSamples, &(voxels.len() as u64))
                .array("voxels", &voxels)
                .array("triples", &triples)
                .finish())
        }),
    })
}

fn transpose(img: Image) -> Image {
    let mut out = Image::new(img.height, img.width);
    for y in 0..img.height {
        for x in 0..img.width {
            out.pixels[(x * img.height + y) as usize] = img.pixels[(y * img.width + x) as usize];
        }
    }
    out
}

fn view_analysis(a: &Artifact) -> Result<SolidAnalysisRef<'_>, NodeError> {
    a.expect_kind(Kind::SolidAnalysis)?;
    let meta: AnalysisMeta = a.meta()?;
    let arrays: Vec<(String, &[u8])> = a
        .array_names()
        .into_iter()
        .map(|n| Ok((n.to_owned(), a.raw_array(n)?)))
        .collect::<Result<_, crate::artifact::ArtifactError>>()?;
    SolidAnalysisRef::from_arrays(meta, &arrays)
        .map_err(|e| NodeError::internal(format!("cached solid analysis: {e}")))
}

fn write_field(f: &RotationField) -> Vec<u8> {
    ArtifactWriter::new(Kind::RotationField, &f.grid)
        .array("rotations", &f.rotations)
        .array("scales", &f.scales)
        .finish()
}

fn read_field(a: &Artifact) -> Result<RotationField, NodeError> {
    a.expect_kind(Kind::RotationField)?;
    let grid: FieldGrid = a.meta()?;
    let rotations: &[Quat] = a.array("rotations")?;
    let scales: &[f32] = a.array("scales")?;
    if rotations.len() != grid.len() || scales.len() != grid.len() {
        return Err(NodeError::internal(
            "cached rotation field disagrees with its grid",
        ));
    }
    Ok(RotationField {
        grid,
        rotations: rotations.to_vec(),
        scales: scales.to_vec(),
    })
}

/// A section's sample grid: origin, u, v, width, height.
type SectionGrid = ([f32; 3], [f32; 3], [f32; 3], u32, u32);

#[derive(Serialize, Deserialize)]
struct RequestMeta {
    volume: Embedding,
    section: Option<SectionGrid>,
}

struct RequestData {
    volume: Embedding,
    voxels: Vec<IVec3>,
    section: Option<Section>,
    /// Each voxel's region (`[[regions]]` index, or their count for the core), when the config
    /// has regions.
    regions: Option<Vec<u8>>,
}

fn write_request(
    vol: &Embedding,
    voxels: &[IVec3],
    sec: Option<&Section>,
    regions: Option<&[u8]>,
) -> Vec<u8> {
    let meta = RequestMeta {
        volume: *vol,
        section: sec.map(|s| (s.origin.into(), s.u.into(), s.v.into(), s.width, s.height)),
    };
    let v: Vec<[i32; 3]> = voxels.iter().map(|v| v.to_array()).collect();
    let w = ArtifactWriter::new(Kind::VoxelRequest, &meta).array("voxels", &v);
    match regions {
        Some(r) => w.array("regions", r).finish(),
        None => w.finish(),
    }
}

fn read_request(a: &Artifact) -> Result<RequestData, NodeError> {
    a.expect_kind(Kind::VoxelRequest)?;
    let m: RequestMeta = a.meta()?;
    let v: &[[i32; 3]] = a.array("voxels")?;
    let regions = if a.array_names().contains(&"regions") {
        let r: &[u8] = a.array("regions")?;
        if r.len() != v.len() {
            return Err(NodeError::internal(
                "cached request: regions and voxels differ in length",
            ));
        }
        Some(r.to_vec())
    } else {
        None
    };
    Ok(RequestData {
        regions,
        volume: m.volume,
        voxels: v.iter().map(|x| IVec3::from(*x)).collect(),
        section: m.section.map(|(o, u, v, width, height)| Section {
            origin: o.into(),
            u: u.into(),
            v: v.into(),
            width,
            height,
        }),
    })
}

type BrickMap = HashMap<(u32, [i32; 3]), Arc<Brick>>;

/// Bricks as cache objects, plus the ones made or read in this run in memory.
struct CacheBrickStore<'a> {
    cache: &'a Cache,
    prefix: ContentHash,
    memory: Mutex<BrickMap>,
}

impl<'a> CacheBrickStore<'a> {
    fn new(cache: &'a Cache, prefix: ContentHash) -> Self {
        CacheBrickStore {
            cache,
            prefix,
            memory: Mutex::new(HashMap::new()),
        }
    }

    fn key(&self, level: u32, brick: [i32; 3]) -> ContentHash {
        let mut h = blake3::Hasher::new();
        h.update(&self.prefix.0);
        h.update(&level.to_le_bytes());
        for c in brick {
            h.update(&c.to_le_bytes());
        }
        ContentHash(*h.finalize().as_bytes())
    }
}

impl BrickStore for CacheBrickStore<'_> {
    fn get(&self, level: u32, brick: [i32; 3]) -> Option<Arc<Brick>> {
        if let Some(b) = self
            .memory
            .lock()
            .expect("brick memory")
            .get(&(level, brick))
        {
            return Some(b.clone());
        }
        let key = self.key(level, brick);
        let Lookup::Hit(a) = self.cache.peek(&key) else {
            return None;
        };
        // A damaged brick is recomputed, like any damaged object.
        if a.verify().is_err() || a.expect_kind(Kind::SolidBrick).is_err() {
            self.cache.remove(&key);
            return None;
        }
        let meta: BrickMeta = a.meta().ok()?;
        let raw = a.raw_array("triples").ok()?;
        let b = Arc::new(Brick::from_arrays(meta, &[("triples".to_string(), raw)]).ok()?);
        self.memory
            .lock()
            .expect("brick memory")
            .insert((level, brick), b.clone());
        Some(b)
    }

    fn put(&self, level: u32, brick: [i32; 3], b: Arc<Brick>) {
        let mut w = ArtifactWriter::new(Kind::SolidBrick, &b.meta());
        for (name, bytes) in b.arrays() {
            w = w.array_bytes(&name, bytes.to_vec());
        }
        let bytes = w.finish();
        if let Err(e) = self.cache.put(&self.key(level, brick), &bytes) {
            tracing::warn!("could not store a brick in the cache: {e}");
        }
        self.memory
            .lock()
            .expect("brick memory")
            .insert((level, brick), b);
    }
}

/// The colour of the voxel containing `p`, or of the nearest requested voxel around it.
fn colour_at(vol: &Embedding, colours: &HashMap<IVec3, [f32; 3]>, p: Vec3) -> Option<[f32; 3]> {
    let v = vol.voxel_of(p);
    if let Some(c) = colours.get(&v) {
        return Some(*c);
    }
    let mut best: Option<(f32, [f32; 3])> = None;
    for dz in -1..=1 {
        for dy in -1..=1 {
            for dx in -1..=1 {
                let w = v + IVec3::new(dx, dy, dz);
                if let Some(c) = colours.get(&w) {
                    let d = vol.centre(w).distance_squared(p);
                    if best.is_none_or(|b| d < b.0) {
                        best = Some((d, *c));
                    }
                }
            }
        }
    }
    best.map(|b| b.1)
}

struct SolidShader<'a> {
    mesh: &'a crate::geom::Mesh,
    vol: &'a Embedding,
    colours: &'a HashMap<IVec3, [f32; 3]>,
}

impl crate::render::SurfaceShader for SolidShader<'_> {
    fn albedo(&self, face: usize, bary: Vec3) -> Vec3 {
        let t = self.mesh.triangles[face];
        let p = self.mesh.positions[t[0] as usize] * bary.x
            + self.mesh.positions[t[1] as usize] * bary.y
            + self.mesh.positions[t[2] as usize] * bary.z;
        colour_at(self.vol, self.colours, p)
            .map(Vec3::from)
            .unwrap_or(Vec3::splat(0.5))
    }
}

fn export_surface(
    mesh: &crate::geom::Mesh,
    vol: &Embedding,
    colours: &HashMap<IVec3, [f32; 3]>,
    p: &SolidExportParams,
    progress: &dyn Fn(f32),
) -> Result<Vec<(String, Vec<u8>)>, NodeError> {
    let refined = crate::geom::subdivide::refine_to_edge_length(
        mesh,
        p.edge_voxels * vol.voxel,
        p.max_faces as usize,
    );
    let vertex_colours: Vec<[f32; 4]> = refined
        .positions
        .iter()
        .map(|q| {
            let c = colour_at(vol, colours, *q).unwrap_or([0.5; 3]);
            [c[0], c[1], c[2], 1.0]
        })
        .collect();
    let coloured = crate::geom::Mesh::with_colors(
        refined.positions.clone(),
        refined.triangles.clone(),
        Some(vertex_colours),
    );
    progress(0.3);
    let mut files = vec![(
        "solid_surface.ply".to_string(),
        crate::geom::io::write_ply(&coloured, coloured.colors.as_deref()),
    )];
    let shader = SolidShader { mesh, vol, colours };
    let atlas = crate::render::build_atlas(mesh, p.atlas_size)
        .map_err(|e| NodeError::input(format!("reconstruct.atlas_size: {e}")))?;
    let baked = crate::render::bake(&atlas, mesh, &shader);
    progress(0.7);
    let png = encode_png(&baked, false);
    let normals = mesh.vertex_normals();
    let mut glb = crate::export::GlbMesh {
        name: "solid".into(),
        material: crate::export::GlbMaterial {
            base_color_png: Some(png.clone()),
            double_sided: true,
            ..Default::default()
        },
        ..Default::default()
    };
    for (f, t) in mesh.triangles.iter().enumerate() {
        for c in 0..3 {
            glb.positions.push(mesh.positions[t[c] as usize]);
            glb.normals.push(normals[t[c] as usize]);
            glb.indices.push(glb.indices.len() as u32);
        }
        let _ = f;
    }
    glb.texcoords = vec![atlas.corner_uv.iter().flatten().copied().collect()];
    files.push(("solid_surface.glb".into(), crate::export::write_glb(&glb)));
    files.push(("baked_surface.png".into(), png));
    let opts = crate::render::ViewOptions {
        size: p.preview_size,
        up: Vec3::from(p.up),
        ..Default::default()
    };
    let preview = crate::render::render_views(
        &coloured,
        &crate::render::VertexColorShader::from_mesh(&coloured).expect("coloured"),
        &opts,
    );
    files.push(("preview.png".into(), encode_png(&preview, false)));
    progress(1.0);
    Ok(files)
}

fn section_png(vol: &Embedding, s: &Section, colours: &HashMap<IVec3, [f32; 3]>) -> Vec<u8> {
    let mut img =
        image::RgbaImage::from_pixel(s.width, s.height, image::Rgba([235, 236, 240, 255]));
    for j in 0..s.height {
        for i in 0..s.width {
            let p = s.point(i, j);
            if let Some(c) = colours.get(&vol.voxel_of(p)) {
                // Image rows go down; the section's v axis up.
                let px = img.get_pixel_mut(i, s.height - 1 - j);
                px.0 = [to8(c[0]), to8(c[1]), to8(c[2]), 255];
            }
        }
    }
    encode_png(&img, false)
}

fn to8(x: f32) -> u8 {
    (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// A box as raw RGB bytes (x fastest, then y, then z) with a JSON header, and its middle
/// z-slice as a PNG for a quick look.
fn export_box(
    voxels: &[IVec3],
    vol: &Embedding,
    colours: &HashMap<IVec3, [f32; 3]>,
) -> Vec<(String, Vec<u8>)> {
    let lo = voxels
        .iter()
        .copied()
        .reduce(IVec3::min)
        .unwrap_or(IVec3::ZERO);
    let hi = voxels
        .iter()
        .copied()
        .reduce(IVec3::max)
        .unwrap_or(IVec3::ZERO);
    let d = hi - lo + IVec3::ONE;
    let mut raw = vec![0u8; (d.x * d.y * d.z * 3) as usize];
    for z in 0..d.z {
        for y in 0..d.y {
            for x in 0..d.x {
                let c = colours
                    .get(&(lo + IVec3::new(x, y, z)))
                    .copied()
                    .unwrap_or([0.0; 3]);
                let i = (((z * d.y + y) * d.x + x) * 3) as usize;
                raw[i..i + 3].copy_from_slice(&[to8(c[0]), to8(c[1]), to8(c[2])]);
            }
        }
    }
    let origin = vol.centre(lo) - Vec3::splat(0.5 * vol.voxel);
    let header = serde_json::json!({
        "format": "raw RGB, 8 bits per channel, x fastest, then y, then z",
        "file": "volume.raw",
        "dims": [d.x, d.y, d.z],
        "origin": [origin.x, origin.y, origin.z],
        "voxel": vol.voxel,
    });
    let mut slice = image::RgbaImage::new(d.x as u32, d.y as u32);
    let z = d.z / 2;
    for y in 0..d.y {
        for x in 0..d.x {
            let i = (((z * d.y + y) * d.x + x) * 3) as usize;
            slice.put_pixel(
                x as u32,
                (d.y - 1 - y) as u32,
                image::Rgba([raw[i], raw[i + 1], raw[i + 2], 255]),
            );
        }
    }
    vec![
        ("volume.raw".into(), raw),
        (
            "volume.json".into(),
            serde_json::to_vec_pretty(&header).expect("json of plain values"),
        ),
        ("volume_middle_slice.png".into(), encode_png(&slice, false)),
    ]
}
