//! The shape's feature lines for feature-aligned texturing (Xu et al., "Feature-Aligned Shape
//! Texturing", §1, §4 and §6: the salient curves the texture's features are laid along).
//!
//! The paper takes them from Yoshizawa et al.'s crest-line detector (§6). texsyn offers three
//! sources, chosen by `extract.features`:
//!
//! - `crest`: ridges and valleys of an organic shape ([`super::crest_lines`]);
//! - `crease`: sharp creases of a CAD part by the dihedral angle ([`super::crease_lines`]);
//! - `curves`: polylines the user gives in the config (`extract.curves`) or in a file
//!   (`extract.curves_file`: a TOML file with the same `curves = [...]`, or an OBJ of `l`
//!   elements such as the `lines.obj` a run exports, edited in a modelling tool), snapped
//!   to vertex paths of the mesh ([`super::vertex_paths`]);
//! - `auto` (the default): user curves when there are any; otherwise the dihedral test: a mesh
//!   whose creases are long (median at least [`AUTO_MEDIAN_CREASE`] of the bounding-box
//!   diagonal) and add up to at least [`AUTO_TOTAL_CREASE`] diagonals is a CAD part and gets
//!   its creases, any other gets crest lines. The choice is reported.

use super::crease_lines::{CreaseParams, Polyline, crease_lines, polyline_length};
use super::crest_lines::{CrestParams, crest_polylines};
use super::vertex_paths::{SnapError, snap_to_vertex_path};
use crate::check::{ParamError, check_range};
use crate::geom::Mesh;
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use texsyn_core::algorithm::Failure;

/// The `shape_features` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("shape_features", 3);

/// `auto` picks `crease` when the median crease is at least this long (a fraction of the
/// bounding-box diagonal). Measured on the shared meshes at the default 30°: fandisk's 34
/// creases have a median of 0.29; the organic meshes have many short ones where coarse
/// triangles meet at sharp angles (median: man 0.029, elephant 0.036, cow 0.034, dragon
/// 0.029, cactus 0.041), which crest lines describe better. A total length alone does not
/// separate them: the elephant's 263 short creases add up to 11.7 diagonals, more than
/// fandisk's 9.2.
pub const AUTO_MEDIAN_CREASE: f32 = 0.1;
/// And the creases must add up to at least this many diagonals.
pub const AUTO_TOTAL_CREASE: f32 = 0.5;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FeatureSource {
    Auto,
    Crest,
    Crease,
    Curves,
}

/// What kind of line a curve is (for the exported lines and the preview's colours).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[repr(u8)]
pub enum CurveKind {
    Ridge = 0,
    Valley = 1,
    Crease = 2,
    User = 3,
}

impl CurveKind {
    pub fn from_code(c: u8) -> Option<CurveKind> {
        [
            CurveKind::Ridge,
            CurveKind::Valley,
            CurveKind::Crease,
            CurveKind::User,
        ]
        .get(c as usize)
        .copied()
    }
}

/// A user-drawn curve: points in the mesh's object space.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UserCurve {
    pub points: Vec<[f32; 3]>,
    /// Whether the last point joins the first. Default: false.
    #[serde(default)]
    pub closed: bool,
    /// Keep this curve's direction as drawn (first point to last) instead of letting §4.1's
    /// greedy orientation choose it; the other curves are then oriented around it. For what
    /// the paper says the greedy step cannot decide (symmetric spokes), and for an edited
    /// `lines.obj` given back (there: the lines of a group named `fixed`). Default: false.
    #[serde(default, skip_serializing_if = "is_false")]
    pub fixed: bool,
}

fn is_false(b: &bool) -> bool {
    !*b
}

/// `extract.*` of a `feature_aligned` config.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ShapeFeatureParams {
    /// "auto", "crest", "crease" or "curves". Default: "auto" (see the module doc).
    pub features: FeatureSource,
    /// Crest-line detection (`features = "crest"`).
    pub crest: CrestParams,
    /// Crease detection (`features = "crease"`, and the `auto` test).
    pub crease: CreaseParams,
    /// User curves (`features = "curves"`, or `auto` when given).
    pub curves: Vec<UserCurve>,
    /// A file of more user curves: `.toml` (`curves = [...]` as above) or `.obj` (`l`
    /// elements). Relative to the config.
    pub curves_file: Option<PathBuf>,
    /// How far a user curve's point may be from the nearest mesh vertex, as a fraction of
    /// the bounding box's diagonal, 0..=1. Default: 0.05.
    pub snap_distance: f32,
}

impl Default for ShapeFeatureParams {
    fn default() -> Self {
        ShapeFeatureParams {
            features: FeatureSource::Auto,
            crest: CrestParams::default(),
            crease: CreaseParams::default(),
            curves: Vec::new(),
            curves_file: None,
            snap_distance: 0.05,
        }
    }
}

impl ShapeFeatureParams {
    pub fn validate(&self) -> Result<(), ParamError> {
        self.crest.validate()?;
        self.crease.validate()?;
        check_range("extract.snap_distance", self.snap_distance, 0.0, 1.0)?;
        for (i, c) in self.curves.iter().enumerate() {
            if c.points.len() < 2 {
                return Err(ParamError::invalid(
                    format!("extract.curves[{i}].points"),
                    format!("needs at least 2 points, got {}", c.points.len()),
                ));
            }
            if let Some(j) = c
                .points
                .iter()
                .position(|p| p.iter().any(|x| !x.is_finite()))
            {
                return Err(ParamError::invalid(
                    format!("extract.curves[{i}].points[{j}]"),
                    "must be finite numbers",
                ));
            }
        }
        if self.features == FeatureSource::Curves
            && self.curves.is_empty()
            && self.curves_file.is_none()
        {
            return Err(ParamError::invalid(
                "extract.features",
                "is \"curves\" but neither extract.curves nor extract.curves_file gives any",
            ));
        }
        Ok(())
    }
}

/// The shape's feature curves, as vertex paths of the mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct ShapeFeatures {
    pub curves: Vec<Polyline>,
    pub kinds: Vec<CurveKind>,
    /// Per curve: its direction is the user's (`UserCurve::fixed`), not the field's to choose.
    pub fixed: Vec<bool>,
    /// The source used (never `Auto`).
    pub source: FeatureSource,
}

#[derive(Debug, thiserror::Error)]
pub enum ShapeFeatureError {
    #[error(
        "no feature lines found on the mesh by {detector} detection: lower {hint}, or give \
         curves (extract.features = \"curves\" with extract.curves or extract.curves_file)"
    )]
    NoneFound {
        detector: &'static str,
        hint: &'static str,
    },
    #[error("{key}: {source}")]
    Snap {
        key: String,
        #[source]
        source: SnapError,
    },
    #[error("extract.curves_file: {0}")]
    File(String),
}

/// The OBJ group name that marks a curves file's lines as fixed (`g fixed`, or one name of
/// several: `g user fixed`).
pub const FIXED_GROUP: &str = "fixed";

/// A curves file's curves: TOML `curves = [{ points = [...] }]` or OBJ `v` + `l` lines.
pub fn read_curves_file(name: &str, bytes: &[u8]) -> Result<Vec<UserCurve>, ShapeFeatureError> {
    let text = std::str::from_utf8(bytes)
        .map_err(|_| ShapeFeatureError::File(format!("{name} is not UTF-8 text")))?;
    if name.to_ascii_lowercase().ends_with(".obj") {
        return read_obj_lines(name, text);
    }
    #[derive(Deserialize)]
    #[serde(deny_unknown_fields)]
    struct File {
        curves: Vec<UserCurve>,
    }
    let f: File = toml::from_str(text)
        .map_err(|e| ShapeFeatureError::File(format!("{name}: {}", e.to_string().trim_end())))?;
    for (i, c) in f.curves.iter().enumerate() {
        let bad = |what: &str| ShapeFeatureError::File(format!("{name}, curve {i}: {what}"));
        if c.points.len() < 2 {
            return Err(bad(&format!(
                "needs at least 2 points, got {}",
                c.points.len()
            )));
        }
        if c.points.iter().flatten().any(|x| !x.is_finite()) {
            return Err(bad("points must be finite numbers"));
        }
    }
    Ok(f.curves)
}

fn read_obj_lines(name: &str, text: &str) -> Result<Vec<UserCurve>, ShapeFeatureError> {
    let mut v: Vec<[f32; 3]> = Vec::new();
    let mut curves = Vec::new();
    // Lines under a `g` statement naming the group `fixed` keep their direction.
    let mut fixed = false;
    for (ln, line) in text.lines().enumerate() {
        let bad = |what: &str| ShapeFeatureError::File(format!("{name}, line {}: {what}", ln + 1));
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let xyz: Vec<f32> = it
                    .take(3)
                    .map(|s| s.parse::<f32>())
                    .collect::<Result<_, _>>()
                    .map_err(|_| bad("a vertex needs three numbers"))?;
                if xyz.len() != 3 || xyz.iter().any(|x| !x.is_finite()) {
                    return Err(bad("a vertex needs three finite numbers"));
                }
                v.push([xyz[0], xyz[1], xyz[2]]);
            }
            Some("g") => fixed = it.any(|name| name == FIXED_GROUP),
            Some("l") => {
                let mut ids = Vec::new();
                for s in it {
                    // `l` entries may be `v/vt`; only the vertex matters.
                    let i: i64 = s
                        .split('/')
                        .next()
                        .and_then(|x| x.parse().ok())
                        .ok_or_else(|| bad(&format!("{s:?} is not a vertex index")))?;
                    let idx = if i < 0 { v.len() as i64 + i } else { i - 1 };
                    if idx < 0 || idx as usize >= v.len() {
                        return Err(bad(&format!(
                            "vertex {i} does not exist ({} vertices so far)",
                            v.len()
                        )));
                    }
                    ids.push(idx as usize);
                }
                if ids.len() < 2 {
                    return Err(bad("a line needs at least 2 vertices"));
                }
                let closed = ids.len() > 2 && ids.first() == ids.last();
                if closed {
                    ids.pop();
                }
                curves.push(UserCurve {
                    points: ids.iter().map(|&i| v[i]).collect(),
                    closed,
                    fixed,
                });
            }
            _ => {}
        }
    }
    if curves.is_empty() {
        return Err(ShapeFeatureError::File(format!(
            "{name} has no `l` (polyline) elements"
        )));
    }
    Ok(curves)
}

fn diagonal(mesh: &Mesh) -> f32 {
    let (lo, hi) = mesh.bounds();
    (hi - lo).length().max(f32::MIN_POSITIVE)
}

/// The feature curves of `mesh` (see the module doc). `file_curves` are a curves file's,
/// already read; they come after the config's.
pub fn shape_features(
    mesh: &Mesh,
    p: &ShapeFeatureParams,
    file_curves: &[UserCurve],
) -> Result<ShapeFeatures, ShapeFeatureError> {
    let user = p.curves.len() + file_curves.len();
    let source = match p.features {
        FeatureSource::Auto if user > 0 => FeatureSource::Curves,
        FeatureSource::Auto => {
            let creases = crease_lines(mesh, &p.crease);
            let mut lengths: Vec<f32> = creases
                .iter()
                .map(|l| polyline_length(mesh, l) / diagonal(mesh))
                .collect();
            lengths.sort_by(f32::total_cmp);
            let total: f32 = lengths.iter().sum();
            let median = lengths.get(lengths.len() / 2).copied().unwrap_or(0.0);
            if median >= AUTO_MEDIAN_CREASE && total >= AUTO_TOTAL_CREASE {
                FeatureSource::Crease
            } else {
                FeatureSource::Crest
            }
        }
        s => s,
    };
    let (curves, kinds, fixed) = match source {
        FeatureSource::Crease => {
            let c = crease_lines(mesh, &p.crease);
            if c.is_empty() {
                return Err(ShapeFeatureError::NoneFound {
                    detector: "crease",
                    hint: "extract.crease.angle or extract.crease.min_length",
                });
            }
            let (k, fixed) = (vec![CurveKind::Crease; c.len()], vec![false; c.len()]);
            (c, k, fixed)
        }
        FeatureSource::Crest => {
            let c = crest_polylines(mesh, &p.crest);
            if c.is_empty() {
                return Err(ShapeFeatureError::NoneFound {
                    detector: "crest-line",
                    hint: "extract.crest.threshold or extract.crest.min_length",
                });
            }
            let kinds = c
                .iter()
                .map(|(_, ridge)| {
                    if *ridge {
                        CurveKind::Ridge
                    } else {
                        CurveKind::Valley
                    }
                })
                .collect();
            let fixed = vec![false; c.len()];
            (c.into_iter().map(|(l, _)| l).collect(), kinds, fixed)
        }
        FeatureSource::Curves | FeatureSource::Auto => {
            let max = p.snap_distance * diagonal(mesh);
            let mut out = Vec::with_capacity(user);
            let mut fixed = Vec::with_capacity(user);
            let all = p.curves.iter().chain(file_curves);
            for (i, c) in all.enumerate() {
                let key = if i < p.curves.len() {
                    format!("extract.curves[{i}]")
                } else {
                    format!("extract.curves_file, curve {}", i - p.curves.len())
                };
                let points: Vec<Vec3> = c.points.iter().map(|&q| Vec3::from(q)).collect();
                let line = snap_to_vertex_path(mesh, &points, c.closed, Some(max))
                    .map_err(|source| ShapeFeatureError::Snap { key, source })?;
                // All points on one vertex: nothing to align to.
                if line.vertices.len() >= 2 {
                    out.push(line);
                    fixed.push(c.fixed);
                }
            }
            if out.is_empty() {
                return Err(ShapeFeatureError::NoneFound {
                    detector: "user",
                    hint: "nothing (no curves were given)",
                });
            }
            let k = vec![CurveKind::User; out.len()];
            (out, k, fixed)
        }
    };
    Ok(ShapeFeatures {
        curves,
        kinds,
        fixed,
        source,
    })
}

/// What the shape-feature node reads besides its inputs. The curves file's path is not a
/// parameter (its bytes are the input), but its format is: the same bytes read as OBJ or TOML
/// mean different curves.
#[derive(Debug, Clone, Serialize)]
pub struct ShapeFeatureKey {
    pub features: ShapeFeatureParams,
    pub curves_format: Option<String>,
}

impl ShapeFeatureKey {
    pub fn new(p: &ShapeFeatureParams) -> Self {
        let format = p.curves_file.as_deref().map(|f| {
            let e = f
                .extension()
                .map(|e| e.to_string_lossy().to_ascii_lowercase());
            e.unwrap_or_default()
        });
        ShapeFeatureKey {
            features: ShapeFeatureParams {
                curves_file: None,
                ..p.clone()
            },
            curves_format: format,
        }
    }
}

/// The extract node: the shape's feature curves, with those of a curves file (`file`: its
/// path, for errors, and its bytes). `method` names the method in the mesh-health warning.
pub fn node(
    mesh: &Mesh,
    key: &ShapeFeatureKey,
    file: Option<(&std::path::Path, &[u8])>,
    method: &str,
) -> Result<ShapeFeatures, Failure> {
    texsyn_core::geom::mesh_check::warn_if_unhealthy(mesh, method);
    let more = match file {
        Some((path, bytes)) => {
            read_curves_file(&path.display().to_string(), bytes).map_err(Failure::input)?
        }
        None => Vec::new(),
    };
    let s = shape_features(mesh, &key.features, &more).map_err(Failure::input)?;
    tracing::info!(
        "extract: {} feature curves ({:?})",
        s.curves.len(),
        s.source
    );
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::primitives;

    #[test]
    fn auto_picks_creases_on_a_box_and_user_curves_when_given() {
        let cube = primitives::cube();
        let refined = crate::geom::subdivide::subdivide(&crate::geom::subdivide::subdivide(&cube));
        let f = shape_features(&refined, &ShapeFeatureParams::default(), &[]).unwrap();
        assert_eq!(f.source, FeatureSource::Crease);
        assert!(!f.curves.is_empty());
        assert!(f.kinds.iter().all(|&k| k == CurveKind::Crease));

        let p = ShapeFeatureParams {
            curves: vec![UserCurve {
                points: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]],
                closed: false,
                fixed: false,
            }],
            ..Default::default()
        };
        let f = shape_features(&refined, &p, &[]).unwrap();
        assert_eq!(f.source, FeatureSource::Curves);
        assert_eq!(f.curves.len(), 1);
        let l = &f.curves[0];
        let pos = |v: u32| refined.positions[v as usize];
        assert_eq!(pos(l.vertices[0]), Vec3::ZERO);
        assert_eq!(pos(*l.vertices.last().unwrap()), Vec3::X);
    }

    #[test]
    fn auto_picks_creases_on_fandisk_and_crest_lines_on_the_elephant() {
        let read = |name: &str| {
            let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../configs/assets")
                .join(name);
            crate::geom::io::read_mesh(&p).unwrap()
        };
        let p = ShapeFeatureParams::default();
        let fandisk = shape_features(&read("fandisk.off"), &p, &[]).unwrap();
        assert_eq!(fandisk.source, FeatureSource::Crease);
        // The elephant's coarse triangles make hundreds of short creases (11.7 diagonals in
        // all): a total-length rule would call it a CAD part.
        let elephant = shape_features(&read("elephant.off"), &p, &[]).unwrap();
        assert_eq!(elephant.source, FeatureSource::Crest);
    }

    #[test]
    fn a_fixed_group_in_an_obj_and_a_fixed_key_in_toml_mark_curves_fixed() {
        let obj =
            "v 0 0 0\nv 1 0 0\nv 1 1 0\ng user\nl 1 2\ng user fixed\nl 2 3\ng valley\nl 3 1\n";
        let read = read_curves_file("lines.obj", obj.as_bytes()).unwrap();
        let fixed: Vec<bool> = read.iter().map(|c| c.fixed).collect();
        assert_eq!(fixed, [false, true, false]);
        let toml = "curves = [{ points = [[0, 0, 0], [1, 0, 0]] }, \
                    { points = [[1, 0, 0], [1, 1, 0]], fixed = true }]";
        let read = read_curves_file("c.toml", toml.as_bytes()).unwrap();
        assert_eq!(
            read.iter().map(|c| c.fixed).collect::<Vec<_>>(),
            [false, true]
        );

        // The flag reaches the snapped curves, one per curve kept.
        let grid = primitives::grid(5, 0.25);
        let p = ShapeFeatureParams {
            features: FeatureSource::Curves,
            ..Default::default()
        };
        let f = shape_features(&grid, &p, &read).unwrap();
        assert_eq!(f.fixed, [false, true]);
        // A flag left at its default is not part of the node's key (existing keys stay).
        let key = |c: &UserCurve| serde_json::to_string(c).unwrap();
        assert!(!key(&read[0]).contains("fixed") && key(&read[1]).contains("fixed"));
    }

    #[test]
    fn a_curve_off_the_mesh_names_its_key() {
        let grid = primitives::grid(5, 0.25);
        let p = ShapeFeatureParams {
            features: FeatureSource::Curves,
            curves: vec![
                UserCurve {
                    points: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]],
                    closed: false,
                    fixed: false,
                },
                UserCurve {
                    points: vec![[0.0, 0.5, 0.0], [0.5, 0.5, 3.0]],
                    closed: false,
                    fixed: false,
                },
            ],
            ..Default::default()
        };
        let e = shape_features(&grid, &p, &[]).unwrap_err().to_string();
        assert!(e.starts_with("extract.curves[1]"), "{e}");
    }

    #[test]
    fn a_flat_sheet_has_no_creases_and_the_error_says_what_to_lower() {
        let grid = primitives::grid(6, 0.2);
        let p = ShapeFeatureParams {
            features: FeatureSource::Crease,
            ..Default::default()
        };
        let e = shape_features(&grid, &p, &[]).unwrap_err().to_string();
        assert!(e.contains("extract.crease.angle"), "{e}");
    }

    #[test]
    fn obj_and_toml_curve_files_read_the_same_curves() {
        let obj = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nl 1 2 3\nl 3 -3\n";
        let a = read_curves_file("lines.obj", obj).unwrap();
        let toml =
            b"curves = [{ points = [[0,0,0],[1,0,0],[1,1,0]] }, { points = [[1,1,0],[0,0,0]] }]";
        let b = read_curves_file("lines.toml", toml).unwrap();
        let short = read_curves_file("c.toml", b"curves = [{ points = [[0,0,0]] }]");
        assert!(
            short
                .unwrap_err()
                .to_string()
                .contains("curve 0: needs at least 2 points")
        );
        assert_eq!(a, b);
        let e = read_curves_file("x.obj", b"v 0 0 0\nl 1 5\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 2") && e.contains("vertex 5"), "{e}");
        assert!(read_curves_file("x.obj", b"v 0 0 0\n").is_err());
    }
}
