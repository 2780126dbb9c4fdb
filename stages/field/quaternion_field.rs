//! The 3D rotation field of sketch-guided solid texturing (Zhang, Du, Lai, Ni & Hu, "Sketch
//! guided solid texturing", §3, eq. 1–2).
//!
//! A coarse regular grid spans the volume (its shortest side has 20–30 cells, as §6 says is
//! enough). Sketch curves are 3D polylines, processed in the order drawn. For each curve, the
//! field so far gives at each curve point a frame q̄; of its six directions ±x, ±y, ±z the
//! one best aligned with the curve (or the one the curve's label names) is turned onto the
//! curve's tangent by the smallest rotation, giving the curve's local frames q, with the sign
//! of each quaternion chosen nearest to q̄ (and, on the first curve, continuous along it from
//! w ≥ 0 at its first point). The field is then the least-squares solution of eq. (2):
//! ‖LQ‖² + Σ w²‖q(v) − q̄(v)‖² over all curve voxels so far, L the grid Laplacian with weights
//! 1/degree (eq. 1), w = 100: one sparse Cholesky factorization with four right-hand sides
//! (the quaternion components). Quaternions are normalized; where the result vanishes a
//! neighbour's is used. Look-ups interpolate trilinearly and normalize.
//!
//! Departure: one label per curve applies to the whole curve (the paper propagates a label
//! given at one point along the curve, which is the same thing). An unlabelled curve picks the
//! direction with the smallest alignment error summed along the curve, so a curve maps one
//! field axis, not a patchwork.
//!
//! The optional scale field (§3, last paragraph) interpolates user scalings at sparse points
//! harmonically on the same grid.
//!
//! A solid's field ([`solid_rotation_field`]) lives on a grid over the volume's box
//! ([`SolidBox`]), so it depends on the volume's margin as well as on the sketch.

use crate::check::{ParamError, check_range};
use crate::geom::Mesh;
use crate::linalg::{SolveError, SpdSolver};
use crate::parameterize::volume_embedding::SolidBox;
use glam::{DQuat, DVec3, Quat, Vec3};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;
use texsyn_core::algorithm::Failure;

/// The `quaternion_field` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("quaternion_field", 2);

/// `[field]` of the solid method: the sketch.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct SketchParams {
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

impl SketchParams {
    /// Checks the cell count, the curves and the scales (a curves file's curves are checked
    /// when it is read).
    pub fn validate(&self) -> Result<(), FieldError> {
        check_range("field.cells", self.cells(), 4, 128)?;
        validate_curves(&self.curves, &self.scales)
    }

    pub fn cells(&self) -> u32 {
        self.cells.unwrap_or(24)
    }

    /// What the field of a solid whose volume has `margin` depends on (besides the mesh and a
    /// curves file's curves).
    pub fn solid_field(&self, margin: f32) -> SolidFieldParams {
        SolidFieldParams {
            curves: self.curves.clone(),
            scales: self.scales.clone(),
            cells: self.cells(),
            margin,
        }
    }
}

/// A file of more sketch curves (`field.curves_file`, beside the config): `curves = [...]`.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CurvesFile {
    pub curves: Vec<Curve>,
}

/// Why a curves file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum CurvesFileError {
    #[error("not UTF-8 text")]
    NotText,
    #[error("{}", .0.to_string().trim_end())]
    Toml(#[from] toml::de::Error),
    #[error("{source} (curve numbers count from {offset} after the config's)")]
    Curve { source: FieldError, offset: usize },
}

impl CurvesFile {
    /// The file's curves, checked. `offset` curves (the config's own) come before them, which
    /// an error's curve number does not count.
    pub fn read(bytes: &[u8], offset: usize) -> Result<Vec<Curve>, CurvesFileError> {
        let text = std::str::from_utf8(bytes).map_err(|_| CurvesFileError::NotText)?;
        let file: CurvesFile = toml::from_str(text)?;
        validate_curves(&file.curves, &[])
            .map_err(|source| CurvesFileError::Curve { source, offset })?;
        Ok(file.curves)
    }
}

/// What a solid's rotation field depends on besides the mesh: the sketch's curves and scales,
/// the grid's cell count, and the margin of the volume's box, which the grid covers.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SolidFieldParams {
    pub curves: Vec<Curve>,
    pub scales: Vec<ScalePoint>,
    pub cells: u32,
    /// `parameterize.margin`.
    pub margin: f32,
}

/// §3 for a solid: the field on a grid over the volume's box around `mesh` with `p.cells`
/// cells on its shortest side, from `p.curves` and then `more` (a curves file's).
/// Reports the fraction done to `progress` (see [`rotation_field_with`]).
pub fn solid_rotation_field(
    mesh: &Mesh,
    p: &SolidFieldParams,
    more: Vec<Curve>,
    progress: &(dyn Fn(f32) + Sync),
) -> Result<RotationField, FieldError> {
    let mut curves = p.curves.clone();
    curves.extend(more);
    let (lo, hi) = SolidBox::around(mesh, p.margin).corners();
    let grid = FieldGrid::covering(lo, hi, p.cells);
    rotation_field_with(grid, &curves, &p.scales, progress)
}

/// Which local axis a curve follows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    fn unit(self) -> DVec3 {
        match self {
            Axis::X => DVec3::X,
            Axis::Y => DVec3::Y,
            Axis::Z => DVec3::Z,
        }
    }
}

/// A sketch curve: a 3D polyline in object space, optionally labelled with the local axis it
/// follows.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Curve {
    pub points: Vec<[f32; 3]>,
    #[serde(default)]
    pub axis: Option<Axis>,
}

/// A user scaling at a point (the optional scale field).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScalePoint {
    pub at: [f32; 3],
    pub scale: f32,
}

/// The regular grid the field lives on: `dims` nodes from `origin` with `spacing`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FieldGrid {
    pub origin: [f32; 3],
    pub spacing: f32,
    pub dims: [u32; 3],
}

impl FieldGrid {
    /// A grid over the box `lo..hi` whose shortest side has `cells` cells.
    pub fn covering(lo: Vec3, hi: Vec3, cells: u32) -> FieldGrid {
        let ext = (hi - lo).max(Vec3::splat(1e-6));
        let spacing = ext.min_element() / cells.max(1) as f32;
        let dims = (ext / spacing).ceil().as_uvec3() + glam::UVec3::ONE;
        FieldGrid {
            origin: lo.into(),
            spacing,
            dims: dims.into(),
        }
    }

    pub fn len(&self) -> usize {
        self.dims.iter().map(|&d| d as usize).product()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn index(&self, i: u32, j: u32, k: u32) -> usize {
        ((k as usize * self.dims[1] as usize) + j as usize) * self.dims[0] as usize + i as usize
    }

    /// Continuous grid coordinates of a point, clamped into the grid.
    fn coords(&self, p: Vec3) -> DVec3 {
        let g = (p - Vec3::from(self.origin)) / self.spacing;
        let hi = Vec3::new(
            (self.dims[0] - 1) as f32,
            (self.dims[1] - 1) as f32,
            (self.dims[2] - 1) as f32,
        );
        g.clamp(Vec3::ZERO, hi).as_dvec3()
    }

    fn nearest(&self, p: Vec3) -> usize {
        let g = self.coords(p).round();
        self.index(g.x as u32, g.y as u32, g.z as u32)
    }

    /// The 8 corner nodes around a point and their trilinear weights.
    fn corners(&self, p: Vec3) -> [(usize, f64); 8] {
        let g = self.coords(p);
        let base = g.floor();
        let f = g - base;
        let mut out = [(0usize, 0.0f64); 8];
        for c in 0..8 {
            let (dx, dy, dz) = (c & 1, (c >> 1) & 1, (c >> 2) & 1);
            let i = (base.x as u32 + dx).min(self.dims[0] - 1);
            let j = (base.y as u32 + dy).min(self.dims[1] - 1);
            let k = (base.z as u32 + dz).min(self.dims[2] - 1);
            let w = (if dx == 1 { f.x } else { 1.0 - f.x })
                * (if dy == 1 { f.y } else { 1.0 - f.y })
                * (if dz == 1 { f.z } else { 1.0 - f.z });
            out[c as usize] = (self.index(i, j, k), w);
        }
        out
    }

    fn neighbours(&self, n: usize) -> impl Iterator<Item = usize> + '_ {
        let d = self.dims.map(|x| x as usize);
        let (i, j, k) = (n % d[0], (n / d[0]) % d[1], n / (d[0] * d[1]));
        [
            (-1i64, 0i64, 0i64),
            (1, 0, 0),
            (0, -1, 0),
            (0, 1, 0),
            (0, 0, -1),
            (0, 0, 1),
        ]
        .into_iter()
        .filter_map(move |(a, b, c)| {
            let (x, y, z) = (i as i64 + a, j as i64 + b, k as i64 + c);
            (x >= 0 && y >= 0 && z >= 0 && x < d[0] as i64 && y < d[1] as i64 && z < d[2] as i64)
                .then(|| (z as usize * d[1] + y as usize) * d[0] + x as usize)
        })
    }
}

/// A rotation field on a grid: the local frame at each node as a unit quaternion (rotating
/// the exemplars' x, y, z axes into object space), and an optional scale per node.
#[derive(Clone, Debug, PartialEq)]
pub struct RotationField {
    pub grid: FieldGrid,
    pub rotations: Vec<Quat>,
    pub scales: Vec<f32>,
}

impl RotationField {
    /// The trivial field: identity everywhere, scale 1.
    pub fn trivial(grid: FieldGrid) -> Self {
        RotationField {
            grid,
            rotations: vec![Quat::IDENTITY; grid.len()],
            scales: vec![1.0; grid.len()],
        }
    }

    /// Trilinear look-up followed by normalization. Neighbouring quaternions are brought to
    /// one hemisphere first (q and −q are the same rotation).
    pub fn rotation_at(&self, p: Vec3) -> Quat {
        let c = self.grid.corners(p);
        let q0 = self.rotations[c[0].0].as_dquat();
        let mut acc = DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0);
        for (n, w) in c {
            let mut q = self.rotations[n].as_dquat();
            if q.dot(q0) < 0.0 {
                q = -q;
            }
            acc += q * w;
        }
        if acc.length_squared() > 1e-24 {
            acc.normalize().as_quat()
        } else {
            self.rotations[c[0].0]
        }
    }

    pub fn scale_at(&self, p: Vec3) -> f32 {
        self.grid
            .corners(p)
            .iter()
            .map(|&(n, w)| self.scales[n] as f64 * w)
            .sum::<f64>() as f32
    }
}

#[derive(Debug, thiserror::Error, PartialEq)]
pub enum FieldError {
    #[error(transparent)]
    Param(#[from] ParamError),
    #[error("field.curves[{curve}]: a curve needs at least two points, this one has {points}")]
    TooFewPoints { curve: usize, points: usize },
    #[error("field.curves[{curve}]: point {point} is not finite")]
    NotFinite { curve: usize, point: usize },
    #[error("field.curves[{curve}]: all its points coincide, so it has no direction")]
    NoDirection { curve: usize },
    #[error("field.scales[{index}]: scale must be a finite number in 0.1..=10, got {scale}")]
    Scale { index: usize, scale: f32 },
    #[error("field: {0}")]
    Solve(#[from] SolveError),
}

impl FieldError {
    /// The config key the error is about.
    pub fn key(&self) -> &str {
        match self {
            FieldError::Param(e) => e.key(),
            _ => "field",
        }
    }
}

/// Weight of the curve constraints in eq. (2); §3 uses 100 for every example.
pub const CONSTRAINT_WEIGHT: f64 = 100.0;

pub fn validate_curves(curves: &[Curve], scales: &[ScalePoint]) -> Result<(), FieldError> {
    for (c, curve) in curves.iter().enumerate() {
        if curve.points.len() < 2 {
            return Err(FieldError::TooFewPoints {
                curve: c,
                points: curve.points.len(),
            });
        }
        if let Some(p) = curve
            .points
            .iter()
            .position(|p| !Vec3::from(*p).is_finite())
        {
            return Err(FieldError::NotFinite { curve: c, point: p });
        }
        let first = Vec3::from(curve.points[0]);
        if curve.points.iter().all(|p| Vec3::from(*p) == first) {
            return Err(FieldError::NoDirection { curve: c });
        }
    }
    for (i, s) in scales.iter().enumerate() {
        if !(s.scale.is_finite() && (0.1..=10.0).contains(&s.scale) && Vec3::from(s.at).is_finite())
        {
            return Err(FieldError::Scale {
                index: i,
                scale: s.scale,
            });
        }
    }
    Ok(())
}

/// Points along a polyline no farther apart than `step`, each with its unit tangent.
fn resample(points: &[[f32; 3]], step: f32) -> Vec<(Vec3, DVec3)> {
    let mut out = Vec::new();
    for w in points.windows(2) {
        let (a, b) = (Vec3::from(w[0]), Vec3::from(w[1]));
        let len = a.distance(b);
        if len <= 0.0 {
            continue;
        }
        let t = (b - a).as_dvec3() / len as f64;
        let n = (len / step).ceil().max(1.0) as usize;
        for s in 0..n {
            out.push((a + (b - a) * (s as f32 / n as f32), t));
        }
    }
    if let (Some(last), Some(&(_, t))) = (points.last(), out.last()) {
        out.push((Vec3::from(*last), t));
    }
    out
}

/// The smallest rotation taking unit vector `from` onto unit vector `to`.
fn rotation_between(from: DVec3, to: DVec3) -> DQuat {
    DQuat::from_rotation_arc(from, to)
}

/// Computes the field from the curves, in order, and the scale points.
pub fn rotation_field(
    grid: FieldGrid,
    curves: &[Curve],
    scales: &[ScalePoint],
) -> Result<RotationField, FieldError> {
    rotation_field_with(grid, curves, scales, &|_| {})
}

/// [`rotation_field`], reporting the fraction done to `progress`: one solve per curve, and
/// one for the scales (each about the same cost: one factorization of the grid's system).
pub fn rotation_field_with(
    grid: FieldGrid,
    curves: &[Curve],
    scales: &[ScalePoint],
    progress: &(dyn Fn(f32) + Sync),
) -> Result<RotationField, FieldError> {
    validate_curves(curves, scales)?;
    let solves = (curves.len() + usize::from(!scales.is_empty())).max(1) as f32;
    let mut field = RotationField::trivial(grid);
    if !curves.is_empty() {
        let laplacian = SmoothnessSystem::new(&grid);
        // Constraint targets per node (the latest curve through a node wins).
        let mut targets: Vec<Option<DQuat>> = vec![None; grid.len()];
        for (c, curve) in curves.iter().enumerate() {
            let samples = resample(&curve.points, 0.5 * grid.spacing);
            if samples.is_empty() {
                return Err(FieldError::NoDirection { curve: c });
            }
            let current: Vec<DQuat> = samples
                .iter()
                .map(|(p, _)| field.rotation_at(*p).as_dquat())
                .collect();
            // Which of ±x, ±y, ±z follows the curve: the label, or the best aligned overall.
            let axis = match curve.axis {
                Some(a) => a,
                None => [Axis::X, Axis::Y, Axis::Z]
                    .into_iter()
                    .max_by(|a, b| {
                        let score = |ax: Axis| -> f64 {
                            samples
                                .iter()
                                .zip(&current)
                                .map(|((_, t), q)| (*q * ax.unit()).dot(*t).abs())
                                .sum()
                        };
                        score(*a).total_cmp(&score(*b))
                    })
                    .expect("three axes"),
            };
            let mut previous: Option<DQuat> = None;
            for (s, ((p, t), qbar)) in samples.iter().zip(&current).enumerate() {
                let dir = *qbar * axis.unit();
                let signed = if dir.dot(*t) >= 0.0 { dir } else { -dir };
                let mut q = (rotation_between(signed, *t) * *qbar).normalize();
                // Sign: nearest to the field so far; on the first curve, continuous along it
                // starting from w ≥ 0.
                let reference = if c == 0 {
                    previous.unwrap_or(if q.w >= 0.0 { q } else { -q })
                } else {
                    *qbar
                };
                if (q - reference).length_squared() > (-q - reference).length_squared() {
                    q = -q;
                }
                if c == 0 && s == 0 && q.w < 0.0 {
                    q = -q;
                }
                previous = Some(q);
                targets[grid.nearest(*p)] = Some(q);
            }
            let solved = laplacian.solve(&targets).map_err(FieldError::Solve)?;
            field.rotations = normalize_or_neighbour(&grid, solved);
            progress((c + 1) as f32 / solves);
        }
    }
    if !scales.is_empty() {
        let system = SmoothnessSystem::new(&grid);
        let mut targets: Vec<Option<f64>> = vec![None; grid.len()];
        for s in scales {
            targets[grid.nearest(Vec3::from(s.at))] = Some(s.scale as f64);
        }
        field.scales = system
            .solve_scalar(&targets)
            .map_err(FieldError::Solve)?
            .into_iter()
            .map(|x| x as f32)
            .collect();
    }
    progress(1.0);
    Ok(field)
}

/// ‖LQ‖² with L = I − D⁻¹A on the grid's 6-neighbourhood, as a sparse LᵀL.
struct SmoothnessSystem {
    n: usize,
    /// Lower-triangle entries of LᵀL (row ≥ col).
    ltl: Vec<(usize, usize, f64)>,
}

impl SmoothnessSystem {
    fn new(grid: &FieldGrid) -> Self {
        let n = grid.len();
        let mut entries: Vec<(usize, usize, f64)> = Vec::with_capacity(n * 28);
        let mut row: Vec<(usize, f64)> = Vec::with_capacity(7);
        for r in 0..n {
            row.clear();
            row.push((r, 1.0));
            let nb: Vec<usize> = grid.neighbours(r).collect();
            let w = 1.0 / nb.len() as f64;
            row.extend(nb.iter().map(|&m| (m, -w)));
            for &(a, va) in &row {
                for &(b, vb) in &row {
                    if a >= b {
                        entries.push((a, b, va * vb));
                    }
                }
            }
        }
        // Sum duplicates in a fixed order (sorted), so the sums are deterministic.
        entries.sort_by_key(|e| (e.0, e.1));
        let mut ltl: Vec<(usize, usize, f64)> = Vec::with_capacity(n * 13);
        for (a, b, v) in entries {
            match ltl.last_mut() {
                Some(last) if last.0 == a && last.1 == b => last.2 += v,
                _ => ltl.push((a, b, v)),
            }
        }
        SmoothnessSystem { n, ltl }
    }

    fn with_constraints(&self, fixed: impl Fn(usize) -> bool) -> Vec<(usize, usize, f64)> {
        let w2 = CONSTRAINT_WEIGHT * CONSTRAINT_WEIGHT;
        let mut t = self.ltl.clone();
        for v in 0..self.n {
            if fixed(v) {
                t.push((v, v, w2));
            }
        }
        t
    }

    fn solve(&self, targets: &[Option<DQuat>]) -> Result<Vec<DQuat>, SolveError> {
        let w2 = CONSTRAINT_WEIGHT * CONSTRAINT_WEIGHT;
        let solver = SpdSolver::new(self.n, &self.with_constraints(|v| targets[v].is_some()))?;
        let mut rhs = vec![0.0; 4 * self.n];
        for (v, t) in targets.iter().enumerate() {
            if let Some(q) = t {
                for (c, x) in [q.x, q.y, q.z, q.w].into_iter().enumerate() {
                    rhs[c * self.n + v] = w2 * x;
                }
            }
        }
        solver.solve(&mut rhs, 4);
        Ok((0..self.n)
            .map(|v| {
                DQuat::from_xyzw(
                    rhs[v],
                    rhs[self.n + v],
                    rhs[2 * self.n + v],
                    rhs[3 * self.n + v],
                )
            })
            .collect())
    }

    fn solve_scalar(&self, targets: &[Option<f64>]) -> Result<Vec<f64>, SolveError> {
        let w2 = CONSTRAINT_WEIGHT * CONSTRAINT_WEIGHT;
        let solver = SpdSolver::new(self.n, &self.with_constraints(|v| targets[v].is_some()))?;
        let mut rhs: Vec<f64> = targets.iter().map(|t| t.map_or(0.0, |x| w2 * x)).collect();
        solver.solve(&mut rhs, 1);
        Ok(rhs)
    }
}

/// Unit quaternions; where the solution vanishes (a singularity), a neighbour's value.
fn normalize_or_neighbour(grid: &FieldGrid, q: Vec<DQuat>) -> Vec<Quat> {
    let mut out: Vec<Option<Quat>> = q
        .iter()
        .map(|q| (q.length_squared() > 1e-20).then(|| q.normalize().as_quat()))
        .collect();
    let mut queue: std::collections::VecDeque<usize> =
        (0..out.len()).filter(|&v| out[v].is_some()).collect();
    while let Some(v) = queue.pop_front() {
        let val = out[v];
        for m in grid.neighbours(v) {
            if out[m].is_none() {
                out[m] = val;
                queue.push_back(m);
            }
        }
    }
    out.into_iter()
        .map(|q| q.unwrap_or(Quat::IDENTITY))
        .collect()
}

/// The field node for a solid: [`solid_rotation_field`] from the config's curves, then those
/// of a curves file (`file`: its path, for errors, and its bytes), checked on reading.
pub fn node(
    mesh: &Mesh,
    p: &SolidFieldParams,
    file: Option<(&std::path::Path, &[u8])>,
    progress: &(dyn Fn(f32) + Sync),
) -> Result<RotationField, Failure> {
    let more = match file {
        None => Vec::new(),
        Some((path, bytes)) => CurvesFile::read(bytes, p.curves.len())
            .map_err(|e| Failure::input(format!("{}: {e}", path.display())))?,
    };
    solid_rotation_field(mesh, p, more, progress).map_err(Failure::input)
}

#[cfg(test)]
mod tests {
    use super::*;
    use texsyn_core::math::PureMath;

    fn grid() -> FieldGrid {
        FieldGrid::covering(Vec3::ZERO, Vec3::new(2.0, 1.0, 1.0), 10)
    }

    fn angle_between_axes(q: Quat, axis: Vec3, dir: Vec3) -> f32 {
        (q * axis)
            .normalize()
            .dot(dir.normalize())
            .abs()
            .clamp(0.0, 1.0)
            .acos_pure()
            .to_degrees()
    }

    #[test]
    fn no_curves_give_the_trivial_field() {
        let f = rotation_field(grid(), &[], &[]).unwrap();
        assert!(f.rotations.iter().all(|&q| q == Quat::IDENTITY));
        assert_eq!(f.rotation_at(Vec3::new(0.3, 0.2, 0.9)), Quat::IDENTITY);
    }

    #[test]
    fn a_curve_turns_its_nearest_axis_onto_its_tangent_and_the_field_stays_unit() {
        // A diagonal curve in the xy plane: x (the closest axis) should follow it.
        let dir = Vec3::new(1.0, 0.6, 0.0).normalize();
        let c = Curve {
            points: vec![
                [0.2, 0.2, 0.5],
                (Vec3::new(0.2, 0.2, 0.5) + dir * 1.5).into(),
            ],
            axis: None,
        };
        let f = rotation_field(grid(), std::slice::from_ref(&c), &[]).unwrap();
        for q in &f.rotations {
            assert!((q.length() - 1.0).abs() < 1e-5);
        }
        for (p, _) in resample(&c.points, 0.05) {
            let a = angle_between_axes(f.rotation_at(p), Vec3::X, dir);
            assert!(a < 3.0, "at {p}: {a}°");
        }
    }

    #[test]
    fn a_label_picks_the_axis_and_later_curves_refine_the_field() {
        let up = Curve {
            points: vec![[0.5, 0.1, 0.5], [0.5, 0.9, 0.5]],
            axis: Some(Axis::Z),
        };
        let f = rotation_field(grid(), std::slice::from_ref(&up), &[]).unwrap();
        for (p, _) in resample(&up.points, 0.05) {
            assert!(angle_between_axes(f.rotation_at(p), Vec3::Z, Vec3::Y) < 3.0);
        }
        // A second curve far away along x, labelled x: both constraints hold.
        let along = Curve {
            points: vec![[1.5, 0.5, 0.2], [1.5, 0.5, 0.8]],
            axis: Some(Axis::X),
        };
        let f2 = rotation_field(grid(), &[up.clone(), along.clone()], &[]).unwrap();
        for (p, _) in resample(&along.points, 0.05) {
            assert!(angle_between_axes(f2.rotation_at(p), Vec3::X, Vec3::Z) < 3.0);
        }
        for (p, _) in resample(&up.points, 0.05) {
            assert!(angle_between_axes(f2.rotation_at(p), Vec3::Z, Vec3::Y) < 5.0);
        }
    }

    #[test]
    fn the_scale_field_interpolates_between_points() {
        let s = [
            ScalePoint {
                at: [0.0, 0.5, 0.5],
                scale: 1.0,
            },
            ScalePoint {
                at: [2.0, 0.5, 0.5],
                scale: 2.0,
            },
        ];
        let f = rotation_field(grid(), &[], &s).unwrap();
        let mid = f.scale_at(Vec3::new(1.0, 0.5, 0.5));
        assert!(mid > 1.2 && mid < 1.8, "{mid}");
        assert!((f.scale_at(Vec3::new(0.0, 0.5, 0.5)) - 1.0).abs() < 0.02);
    }

    #[test]
    fn bad_curves_are_named() {
        let e = rotation_field(
            grid(),
            &[Curve {
                points: vec![[0.0; 3]],
                axis: None,
            }],
            &[],
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "field.curves[0]: a curve needs at least two points, this one has 1"
        );
        let e = rotation_field(
            grid(),
            &[Curve {
                points: vec![[0.1; 3], [0.1; 3]],
                axis: None,
            }],
            &[],
        )
        .unwrap_err();
        assert!(e.to_string().contains("coincide"));
        let e = rotation_field(
            grid(),
            &[],
            &[ScalePoint {
                at: [0.0; 3],
                scale: 0.0,
            }],
        )
        .unwrap_err();
        assert!(e.to_string().contains("field.scales[0]"));
    }
}
