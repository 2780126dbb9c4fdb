//! Embedding a mesh in a voxel volume and turning a user's request into the voxels it needs
//! (Zhang et al., "Sketch guided solid texturing", §6: "the object embedded in a volume whose
//! edges are longer than those of the bounding box … about 20–30% longer … discretized to
//! about 800–1024 in its longest dimension").
//!
//! Requests: the surface shell (every voxel a triangle passes through, to colour the mesh),
//! a cross-section plane (a grid of sample points on the plane, one voxel apart, clipped to
//! the volume; a cut of the object keeps the samples inside the mesh), or a box. With exemplar
//! sets by depth under the surface (§6, Fig. 15: bark near the surface, wood inside), each
//! requested voxel is also given the region its depth falls in ([`request_voxels`]).
//!
//! [`SolidBox`] is the one place the volume's box is derived from the mesh and the margin:
//! the voxel grid here and the rotation field's grid (`field::quaternion_field`) both cover it.

use crate::check::{ParamError, check_range};
use crate::geom::Mesh;
use glam::{IVec3, Vec3};
use serde::{Deserialize, Serialize};
use texsyn_core::algorithm::Failure;

/// The `volume_request` node's algorithm and version (part of its key; bump on any change of output).
pub const NODE: texsyn_core::algorithm::Algorithm =
    texsyn_core::algorithm::Algorithm::new("volume_request", 5);

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

impl RequestParams {
    /// Checks `resolution` and `margin` (the request's plane or box is checked against the
    /// volume by [`request_voxels`], once the volume is known).
    pub fn validate(&self) -> Result<(), ParamError> {
        check_range("parameterize.resolution", self.resolution, 8, 4096)?;
        check_range("parameterize.margin", self.margin, 0.0, 4.0)
    }
}

/// Why a volume or a request's voxels could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum VolumeError {
    #[error("the mesh has no triangles to embed")]
    EmptyMesh,
    #[error("the plane needs a finite point and a non-zero normal")]
    DegeneratePlane,
    #[error("the plane through {point} with normal {normal} misses the volume ({lo} to {hi})")]
    PlaneMisses {
        point: Vec3,
        normal: Vec3,
        lo: Vec3,
        hi: Vec3,
    },
    #[error("the box {min} to {max} misses the volume ({lo} to {hi})")]
    BoxMisses {
        min: Vec3,
        max: Vec3,
        lo: Vec3,
        hi: Vec3,
    },
    /// The request's plane or box does not fit the volume.
    #[error("parameterize.request: {0}")]
    Request(Box<VolumeError>),
}

/// A regular voxel grid: voxel (i, j, k) has its centre at origin + (i + ½, j + ½, k + ½)·voxel.
/// The solid's finest level; synthesis builds its pyramid over it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Volume {
    /// Object-space corner of voxel (0, 0, 0).
    pub origin: [f32; 3],
    /// Side of a voxel, in object units.
    pub voxel: f32,
    /// Voxels along x, y, z.
    pub dims: [u32; 3],
}

impl Volume {
    pub fn centre(&self, v: IVec3) -> Vec3 {
        Vec3::from(self.origin) + (v.as_vec3() + Vec3::splat(0.5)) * self.voxel
    }

    /// The voxel containing a point (possibly outside the volume).
    pub fn voxel_of(&self, p: Vec3) -> IVec3 {
        ((p - Vec3::from(self.origin)) / self.voxel)
            .floor()
            .as_ivec3()
    }

    pub fn contains(&self, v: IVec3) -> bool {
        v.x >= 0
            && v.y >= 0
            && v.z >= 0
            && (v.x as u32) < self.dims[0]
            && (v.y as u32) < self.dims[1]
            && (v.z as u32) < self.dims[2]
    }

    pub fn min(&self) -> Vec3 {
        Vec3::from(self.origin)
    }

    pub fn max(&self) -> Vec3 {
        self.min() + glam::UVec3::from(self.dims).as_vec3() * self.voxel
    }
}

/// The box a solid lives in: the mesh's bounding box grown by `margin`, a fraction of each
/// side (0.25 by default; §6: "about 20–30% longer"). Derived here only: the voxel grid
/// ([`SolidBox::voxels`]) and the rotation field's grid ([`SolidBox::corners`]) both come
/// from it, so they cannot disagree on the margin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolidBox {
    /// The mesh's bounding box.
    lo: Vec3,
    hi: Vec3,
    margin: f32,
}

impl SolidBox {
    pub fn around(mesh: &Mesh, margin: f32) -> SolidBox {
        let (lo, hi) = mesh.bounds();
        SolidBox { lo, hi, margin }
    }

    /// The grown box's corners (what the rotation field's grid covers).
    pub fn corners(&self) -> (Vec3, Vec3) {
        let grow = (self.hi - self.lo) * self.margin * 0.5;
        (self.lo - grow, self.hi + grow)
    }

    /// The grown box cut into `longest` voxels along its longest side: whole voxels, centred
    /// on the box, so the grid reaches up to one voxel beyond it on the other sides.
    pub fn voxels(&self, longest: u32) -> Volume {
        let size = (self.hi - self.lo).max(Vec3::splat(1e-6));
        let grown = size * (1.0 + self.margin);
        let voxel = grown.max_element() / longest.max(1) as f32;
        let dims = (grown / voxel).ceil().as_uvec3().max(glam::UVec3::ONE);
        let centre = (self.lo + self.hi) * 0.5;
        let origin = centre - dims.as_vec3() * voxel * 0.5;
        Volume {
            origin: origin.into(),
            voxel,
            dims: dims.into(),
        }
    }
}

/// A volume around the mesh: [`SolidBox::voxels`] with `longest` voxels along its longest
/// side (`parameterize.resolution`, checked by [`RequestParams::validate`]).
pub fn embed(mesh: &Mesh, longest: u32, margin: f32) -> Result<Volume, VolumeError> {
    if mesh.triangles.is_empty() {
        return Err(VolumeError::EmptyMesh);
    }
    Ok(SolidBox::around(mesh, margin).voxels(longest))
}

/// The voxels a request needs, in the volume around the mesh: what the parameterize stage
/// gives synthesis and reconstruction.
#[derive(Clone, Debug, PartialEq)]
pub struct RequestedVoxels {
    pub volume: Volume,
    /// Sorted (z, then y, then x), without duplicates.
    pub voxels: Vec<IVec3>,
    /// A section request's sample grid.
    pub section: Option<Section>,
    /// With regions by depth: each voxel's region, the index of the first region depth it
    /// lies above, or the number of depths for the core below them all.
    pub regions: Option<Vec<u8>>,
}

/// Checks the depths of the regions by depth under the surface (`[[regions]]`): at most 16,
/// each greater than 0, increasing.
pub fn validate_region_depths(depths: &[f32]) -> Result<(), ParamError> {
    if depths.len() > 16 {
        let m = format!("has {} regions: at most 16", depths.len());
        return Err(ParamError::invalid("regions", m));
    }
    for (k, &d) in depths.iter().enumerate() {
        let key = format!("regions[{k}].depth");
        if !(d.is_finite() && d > 0.0) {
            return Err(ParamError::invalid(
                key,
                format!(
                    "is {d}: expected a depth under the surface greater than 0, in the mesh's units"
                ),
            ));
        }
        if let Some(&prev) = depths[..k].last().filter(|&&prev| d <= prev) {
            return Err(ParamError::invalid(
                key,
                format!(
                    "is {d} but the region before reaches {prev}: list regions from the surface \
                     inwards, depths increasing"
                ),
            ));
        }
    }
    Ok(())
}

/// The voxels of `p.request` in the volume `p.resolution` and `p.margin` give around the mesh.
/// With `region_depths` (increasing, in mesh units), each voxel also gets its region
/// ([`RequestedVoxels::regions`]) by its depth under the surface ([`voxel_depths`]).
pub fn request_voxels(
    mesh: &Mesh,
    p: &RequestParams,
    region_depths: &[f32],
) -> Result<RequestedVoxels, VolumeError> {
    let vol = embed(mesh, p.resolution, p.margin)?;
    // Sections and regions both need inside/outside: one flood fill for both.
    let outside_cell = std::cell::OnceCell::new();
    let outside = || {
        outside_cell
            .get_or_init(|| outside_voxels(mesh, &vol))
            .as_slice()
    };
    let in_request = |e| VolumeError::Request(Box::new(e));
    let (voxels, section) = match &p.request {
        Request::Surface => (surface_voxels(mesh, &vol), None),
        Request::Section { point, normal } => {
            let s =
                self::section(&vol, Vec3::from(*point), Vec3::from(*normal)).map_err(in_request)?;
            // A cut of the object: the plane's samples inside the mesh.
            (section_voxels_inside(&vol, &s, outside()), Some(s))
        }
        Request::Box { min, max } => (
            box_voxels(&vol, Vec3::from(*min), Vec3::from(*max)).map_err(in_request)?,
            None,
        ),
    };
    let regions = (!region_depths.is_empty()).then(|| {
        voxel_depths(mesh, &vol, &voxels, outside())
            .into_iter()
            .map(|d| {
                region_depths
                    .iter()
                    .position(|&r| d < r)
                    .unwrap_or(region_depths.len()) as u8
            })
            .collect()
    });
    Ok(RequestedVoxels {
        volume: vol,
        voxels,
        section,
        regions,
    })
}

/// The requested voxels that `region` owns (`None`: all of them), as coordinates; `None` when
/// a region is asked of a request made without regions.
pub fn region_voxels(
    voxels: &[IVec3],
    regions: Option<&[u8]>,
    region: Option<u8>,
) -> Option<Vec<[i32; 3]>> {
    match (region, regions) {
        (None, _) => Some(voxels.iter().map(|v| v.to_array()).collect()),
        (Some(k), Some(owner)) => Some(
            voxels
                .iter()
                .zip(owner)
                .filter(|(_, o)| **o == k)
                .map(|(v, _)| v.to_array())
                .collect(),
        ),
        (Some(_), None) => None,
    }
}

/// Every voxel a triangle passes through (sampled at a third of a voxel, which cannot skip a
/// voxel the triangle crosses by more than that), sorted and without duplicates.
pub fn surface_voxels(mesh: &Mesh, vol: &Volume) -> Vec<IVec3> {
    let mut out = Vec::new();
    surface_samples(mesh, vol, |vx| out.push(vx));
    sort_dedup(&mut out);
    out
}

/// Calls `f` with the voxel of every point of a triangle grid a third of a voxel apart on each
/// triangle (points inside the volume or on its faces; a voxel may come many times).
fn surface_samples(mesh: &Mesh, vol: &Volume, mut f: impl FnMut(IVec3)) {
    let step = vol.voxel / 3.0;
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
        let n = ((b - a).length().max((c - a).length()).max((c - b).length()) / step)
            .ceil()
            .max(1.0) as u32;
        for i in 0..=n {
            for j in 0..=n - i {
                let (u, v) = (i as f32 / n as f32, j as f32 / n as f32);
                let p = a + (b - a) * u + (c - a) * v;
                // A point on the volume's far faces (margin 0) belongs to the last voxel.
                if p.cmpge(vol.min()).all() && p.cmple(vol.max()).all() {
                    let last = IVec3::from(vol.dims.map(|d| d as i32)) - 1;
                    f(vol.voxel_of(p).clamp(IVec3::ZERO, last));
                }
            }
        }
    }
}

fn sort_dedup(v: &mut Vec<IVec3>) {
    v.sort_by_key(|p| (p.z, p.y, p.x));
    v.dedup();
}

/// A cross-section: sample points `origin + i·u + j·v` for i < width, j < height, one voxel
/// apart, covering the part of the plane inside the volume.
#[derive(Clone, Debug, PartialEq)]
pub struct Section {
    pub origin: Vec3,
    pub u: Vec3,
    pub v: Vec3,
    pub width: u32,
    pub height: u32,
}

impl Section {
    pub fn point(&self, i: u32, j: u32) -> Vec3 {
        self.origin + self.u * i as f32 + self.v * j as f32
    }
}

/// The section of the volume by the plane with `normal` through the centre of the voxel
/// holding `point` (moved along the normal by at most half a voxel on an axis-aligned plane,
/// under a voxel on any), sampled one voxel apart
/// starting half a voxel in from the volume's box. So on a plane along a grid axis every
/// sample is a voxel's centre, one per voxel: a plane or a sample on a voxel face would take
/// the voxel on one side or the other by rounding, from sample to sample, duplicating and
/// skipping columns or mixing two layers. Errors when the plane misses the volume.
pub fn section(vol: &Volume, point: Vec3, normal: Vec3) -> Result<Section, VolumeError> {
    if !point.is_finite() || !normal.is_finite() || normal.length() < 1e-12 {
        return Err(VolumeError::DegeneratePlane);
    }
    let n = normal.normalize();
    let point = point + n * (vol.centre(vol.voxel_of(point)) - point).dot(n);
    // In-plane axes: the world axis least aligned with n, orthogonalized.
    let helper = [Vec3::X, Vec3::Y, Vec3::Z]
        .into_iter()
        .min_by(|a, b| a.dot(n).abs().total_cmp(&b.dot(n).abs()))
        .unwrap();
    let u = (helper - helper.dot(n) * n).normalize();
    let v = n.cross(u);
    // Clip: project the volume's corners onto the plane's axes; the plane misses the volume
    // when all corners lie on one side.
    let (lo, hi) = (vol.min(), vol.max());
    let corners: Vec<Vec3> = (0..8)
        .map(|c| {
            Vec3::new(
                if c & 1 == 0 { lo.x } else { hi.x },
                if c & 2 == 0 { lo.y } else { hi.y },
                if c & 4 == 0 { lo.z } else { hi.z },
            )
        })
        .collect();
    let sides: Vec<f32> = corners.iter().map(|c| (*c - point).dot(n)).collect();
    if sides.iter().all(|&s| s > 0.0) || sides.iter().all(|&s| s < 0.0) {
        return Err(VolumeError::PlaneMisses {
            point,
            normal: n,
            lo,
            hi,
        });
    }
    let (mut umin, mut umax, mut vmin, mut vmax) = (
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::INFINITY,
        f32::NEG_INFINITY,
    );
    for c in &corners {
        let d = *c - point;
        umin = umin.min(d.dot(u));
        umax = umax.max(d.dot(u));
        vmin = vmin.min(d.dot(v));
        vmax = vmax.max(d.dot(v));
    }
    // Whole voxels across (a hair under a whole number is that number, not one more).
    let across = |extent: f32| ((extent / vol.voxel - 1e-3).ceil() as u32).max(1);
    let (width, height) = (across(umax - umin), across(vmax - vmin));
    let half = 0.5 * vol.voxel;
    Ok(Section {
        origin: point + u * (umin + half) + v * (vmin + half),
        u: u * vol.voxel,
        v: v * vol.voxel,
        width,
        height,
    })
}

/// The voxels the section's samples fall in (inside the volume), sorted, no duplicates.
pub fn section_voxels(vol: &Volume, s: &Section) -> Vec<IVec3> {
    let mut out = Vec::new();
    for j in 0..s.height {
        for i in 0..s.width {
            let vx = vol.voxel_of(s.point(i, j));
            if vol.contains(vx) {
                out.push(vx);
            }
        }
    }
    sort_dedup(&mut out);
    out
}

/// The voxels of a box (clipped to the volume). Errors when the box misses it.
pub fn box_voxels(vol: &Volume, min: Vec3, max: Vec3) -> Result<Vec<IVec3>, VolumeError> {
    let a = vol.voxel_of(min.min(max)).max(IVec3::ZERO);
    let b = vol
        .voxel_of(min.max(max))
        .min(glam::UVec3::from(vol.dims).as_ivec3() - IVec3::ONE);
    if a.cmpgt(b).any() {
        return Err(VolumeError::BoxMisses {
            min,
            max,
            lo: vol.min(),
            hi: vol.max(),
        });
    }
    let mut out = Vec::new();
    for z in a.z..=b.z {
        for y in a.y..=b.y {
            for x in a.x..=b.x {
                out.push(IVec3::new(x, y, z));
            }
        }
    }
    Ok(out)
}

/// Which voxels lie outside the mesh: a 6-connected flood fill over the voxels the surface
/// does not pass through (the shell grown by one voxel, so a corner the surface sampling
/// clipped cannot let the fill leak in). The fill runs only in the mesh's bounding box grown
/// by two voxels (everything beyond it is outside), starting from that box's border. Voxel
/// (x, y, z) is at index x + dims.x·(y + dims.y·z). A mesh with holes has no inside:
/// everything is outside then.
pub fn outside_voxels(mesh: &Mesh, vol: &Volume) -> Vec<bool> {
    let [nx, ny, nz] = vol.dims.map(|d| d as i32);
    let mut outside = vec![true; (nx * ny * nz) as usize];
    if mesh.positions.is_empty() {
        return outside;
    }
    let (lo, hi) = mesh.bounds();
    let dims = IVec3::new(nx, ny, nz);
    let blo = (vol.voxel_of(lo) - 2).clamp(IVec3::ZERO, dims - 1);
    let bhi = (vol.voxel_of(hi) + 2).clamp(IVec3::ZERO, dims - 1);
    let n = bhi - blo + 1;
    let local = |v: IVec3| {
        let q = v - blo;
        (q.x + n.x * (q.y + n.y * q.z)) as usize
    };
    let in_box = |v: IVec3| v.cmpge(blo).all() && v.cmple(bhi).all();
    // The shell, then grown by one voxel (a 3×3×3 dilation, one axis at a time).
    let mut wall = vec![false; (n.x * n.y * n.z) as usize];
    surface_samples(mesh, vol, |v| wall[local(v)] = true);
    for axis in 0..3 {
        let step = IVec3::from(std::array::from_fn(|k| (k == axis) as i32));
        let before = wall.clone();
        for (i, w) in wall.iter_mut().enumerate() {
            if *w {
                continue;
            }
            let q = IVec3::new(
                i as i32 % n.x,
                (i as i32 / n.x) % n.y,
                i as i32 / (n.x * n.y),
            ) + blo;
            *w = [q - step, q + step]
                .into_iter()
                .any(|p| in_box(p) && before[local(p)]);
        }
    }
    // Fill from the box's border; what the fill does not reach is inside.
    let mut reached = vec![false; wall.len()];
    let mut stack: Vec<IVec3> = Vec::new();
    for z in blo.z..=bhi.z {
        for y in blo.y..=bhi.y {
            for x in blo.x..=bhi.x {
                let v = IVec3::new(x, y, z);
                let on_border = v.cmpeq(blo).any() || v.cmpeq(bhi).any();
                if on_border && !wall[local(v)] && !reached[local(v)] {
                    reached[local(v)] = true;
                    stack.push(v);
                }
            }
        }
    }
    while let Some(v) = stack.pop() {
        for d in [
            IVec3::X,
            -IVec3::X,
            IVec3::Y,
            -IVec3::Y,
            IVec3::Z,
            -IVec3::Z,
        ] {
            let w = v + d;
            if in_box(w) && !wall[local(w)] && !reached[local(w)] {
                reached[local(w)] = true;
                stack.push(w);
            }
        }
    }
    for z in blo.z..=bhi.z {
        for y in blo.y..=bhi.y {
            for x in blo.x..=bhi.x {
                let v = IVec3::new(x, y, z);
                outside[(x + nx * (y + ny * z)) as usize] = reached[local(v)];
            }
        }
    }
    outside
}

/// The voxels of a section that are inside the mesh (or on its surface); `outside` is
/// [`outside_voxels`] of the mesh.
pub fn section_voxels_inside(vol: &Volume, s: &Section, outside: &[bool]) -> Vec<IVec3> {
    let [nx, ny, _] = vol.dims.map(|d| d as i32);
    section_voxels(vol, s)
        .into_iter()
        .filter(|v| !outside[(v.x + nx * (v.y + ny * v.z)) as usize])
        .collect()
}

/// How deep below the surface each voxel's centre lies: its distance to the nearest point of
/// the surface when inside the mesh (or in the shell the surface passes through), 0 when
/// outside (`outside` is [`outside_voxels`] of the mesh). Chooses an exemplar set by depth
/// (§7, Fig. 15: bark near the surface, wood inside).
pub fn voxel_depths(mesh: &Mesh, vol: &Volume, voxels: &[IVec3], outside: &[bool]) -> Vec<f32> {
    use rayon::prelude::*;
    let [nx, ny, _] = vol.dims.map(|d| d as i32);
    let distance = crate::geom::surface_distance::SurfaceDistance::new(mesh);
    voxels
        .par_iter()
        .map(|v| {
            let in_grid = vol.contains(*v);
            if in_grid && outside[(v.x + nx * (v.y + ny * v.z)) as usize] {
                0.0
            } else {
                distance.distance(vol.centre(*v))
            }
        })
        .collect()
}

/// The parameterize node: [`request_voxels`], with the region depths when the config has
/// `[[regions]]`.
pub fn node(
    mesh: &Mesh,
    p: &RequestParams,
    region_depths: Option<&[f32]>,
) -> Result<RequestedVoxels, Failure> {
    request_voxels(mesh, p, region_depths.unwrap_or_default()).map_err(Failure::input)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 1 × 1 × 2 box: its longest side is z.
    fn cube() -> Mesh {
        crate::geom::primitives::cuboid(Vec3::new(1.0, 1.0, 2.0))
    }

    /// The unit cube [0, 1]³ and its volume with a margin of 1, `longest` voxels a side.
    fn unit_cube(longest: u32) -> (Mesh, Volume) {
        let m = crate::geom::primitives::cube();
        let v = embed(&m, longest, 1.0).unwrap();
        (m, v)
    }

    #[test]
    fn the_volume_is_a_quarter_larger_and_its_longest_side_has_the_resolution() {
        let v = embed(&cube(), 40, 0.25).unwrap();
        assert_eq!(v.dims[2], 40);
        assert!((v.voxel - 2.5 / 40.0).abs() < 1e-6);
        assert!(
            v.min().cmple(Vec3::new(-0.1, -0.1, -0.2)).all()
                && v.max().cmpge(Vec3::new(1.1, 1.1, 2.2)).all()
        );
    }

    #[test]
    fn the_surface_shell_is_the_voxels_next_to_the_surface() {
        let m = cube();
        let v = embed(&m, 40, 0.25).unwrap();
        let shell = surface_voxels(&m, &v);
        assert!(!shell.is_empty());
        for vx in &shell {
            // Distance from the voxel centre to the cube's surface is at most a voxel diagonal.
            let c = v.centre(*vx);
            let inside = c.clamp(Vec3::ZERO, Vec3::new(1.0, 1.0, 2.0));
            let d_out = c.distance(inside);
            let d_in = [c.x, 1.0 - c.x, c.y, 1.0 - c.y, c.z, 2.0 - c.z]
                .into_iter()
                .fold(f32::INFINITY, f32::min);
            let d = if d_out > 0.0 { d_out } else { d_in };
            assert!(d <= v.voxel * 0.87 + 1e-5, "{vx}: {d}");
        }
        // A face of 1 × 2 units at 16 voxels per unit needs at least 16 × 32 voxels.
        let n = 1.0 / v.voxel;
        assert!(shell.len() as f32 >= 2.0 * (n * 2.0 * n) + 2.0 * (n * n));
    }

    #[test]
    fn sections_cover_the_plane_inside_and_a_missing_plane_is_an_error() {
        let v = embed(&cube(), 20, 0.25).unwrap();
        let s = section(&v, Vec3::new(0.5, 0.5, 1.0), Vec3::Z).unwrap();
        let voxels = section_voxels(&v, &s);
        // A z-slice: every voxel of that layer.
        assert_eq!(voxels.len(), (v.dims[0] * v.dims[1]) as usize);
        assert!(voxels.iter().all(|x| x.z == voxels[0].z));
        // Planes along each axis, through a voxel's inside and through a face between two
        // layers: one sample per voxel of one layer, each voxel once.
        for normal in [Vec3::X, Vec3::Y, -Vec3::Z] {
            let face = Vec3::from(v.origin) + Vec3::splat(7.0 * v.voxel);
            for point in [Vec3::new(0.43, 0.57, 0.61), face] {
                let s = section(&v, point, normal).unwrap();
                let mut seen = std::collections::HashSet::new();
                for j in 0..s.height {
                    for i in 0..s.width {
                        let x = v.voxel_of(s.point(i, j));
                        assert!(seen.insert(x), "{normal} {point}: {x} sampled twice");
                    }
                }
                let a = normal.abs().max_position();
                let layer: u32 = (0..3).filter(|&k| k != a).map(|k| v.dims[k]).product();
                assert_eq!(seen.len() as u32, layer, "{normal} {point}");
                assert!(seen.iter().all(|x| x[a] == seen.iter().next().unwrap()[a]));
                assert!(seen.iter().all(|x| v.contains(*x)), "{normal} {point}");
            }
        }
        let e = section(&v, Vec3::new(0.0, 0.0, 50.0), Vec3::Z).unwrap_err();
        assert!(e.to_string().contains("misses the volume"), "{e}");
        assert!(box_voxels(&v, Vec3::splat(10.0), Vec3::splat(11.0)).is_err());
        assert_eq!(
            box_voxels(&v, Vec3::ZERO, Vec3::splat(0.2)).unwrap().len(),
            {
                let a = v.voxel_of(Vec3::ZERO);
                let b = v.voxel_of(Vec3::splat(0.2));
                ((b - a + IVec3::ONE).x * (b - a + IVec3::ONE).y * (b - a + IVec3::ONE).z) as usize
            }
        );
    }

    #[test]
    fn a_cube_s_inside_is_found_and_its_outside_is_not() {
        let (m, v) = unit_cube(32);
        let s = section(&v, Vec3::splat(0.5), Vec3::Z).unwrap();
        let inside = section_voxels_inside(&v, &s, &outside_voxels(&m, &v));
        let all = section_voxels(&v, &s);
        assert!(inside.len() < all.len());
        for vx in &inside {
            let c = v.centre(*vx);
            assert!(
                c.x > -2.0 * v.voxel
                    && c.x < 1.0 + 2.0 * v.voxel
                    && c.y > -2.0 * v.voxel
                    && c.y < 1.0 + 2.0 * v.voxel
            );
        }
        // The unit square at 16 voxels per unit: at least its 16 × 16 voxels.
        assert!(inside.len() as f32 >= (1.0 / v.voxel).powi(2) * 0.9);
    }

    /// Against the box's own inside test: voxels more than 2 voxels inside are inside, more
    /// than 2 voxels outside (along some axis: the shell is grown by a voxel in every
    /// direction) are outside, with and without a margin (at 0 the box touches the volume's
    /// border).
    #[test]
    fn the_fill_agrees_with_a_box_s_inside_away_from_its_faces() {
        let size = Vec3::new(1.0, 0.7, 0.4);
        let m = crate::geom::primitives::cuboid(size);
        for (res, margin) in [(24, 0.0), (31, 0.25), (40, 1.0)] {
            let v = embed(&m, res, margin).unwrap();
            let outside = outside_voxels(&m, &v);
            let [nx, ny, nz] = v.dims.map(|d| d as i32);
            let (mut inside_seen, mut outside_seen) = (0, 0);
            for z in 0..nz {
                for y in 0..ny {
                    for x in 0..nx {
                        let c = v.centre(IVec3::new(x, y, z));
                        let depth = c.min(size - c).min_element();
                        let o = outside[(x + nx * (y + ny * z)) as usize];
                        if depth > 2.0 * v.voxel {
                            assert!(!o, "res {res} margin {margin}: {c} is inside");
                            inside_seen += 1;
                        } else if (c - c.clamp(Vec3::ZERO, size)).abs().max_element()
                            > 2.0 * v.voxel
                        {
                            assert!(o, "res {res} margin {margin}: {c} is outside");
                            outside_seen += 1;
                        }
                    }
                }
            }
            assert!(inside_seen > 0 && (margin == 0.0 || outside_seen > 0));
        }
    }

    #[test]
    fn depth_grows_towards_a_cube_s_centre_and_is_zero_outside() {
        let (m, v) = unit_cube(40);
        let centre = v.voxel_of(Vec3::splat(0.5));
        let near_face = v.voxel_of(Vec3::new(0.5, 0.5, 0.1));
        let outside = v.voxel_of(Vec3::new(0.5, 0.5, -0.3));
        let d = voxel_depths(
            &m,
            &v,
            &[centre, near_face, outside],
            &outside_voxels(&m, &v),
        );
        let c = v.centre(centre);
        let expect = c.min_element().min((Vec3::ONE - c).min_element());
        assert!((d[0] - expect).abs() < 1e-4, "{} vs {expect}", d[0]);
        assert!((d[1] - v.centre(near_face).z).abs() < 1e-4);
        assert_eq!(d[2], 0.0);
    }
}
