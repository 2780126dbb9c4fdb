//! Requests: sets of finest-level voxels (a box with a bit per voxel), from a box, a list or
//! a plane's cross-section.

use crate::parameterize::volume_embedding::Volume;
use glam::{IVec3, Vec3};

/// A set of finest-level voxels: a box with a bit per voxel.
#[derive(Clone, Debug, PartialEq)]
pub struct VoxelRequest {
    lo: IVec3,
    dims: IVec3,
    bits: Vec<u64>,
}

impl VoxelRequest {
    /// The voxels of `[lo, hi)` for which `f` holds.
    pub fn from_fn(lo: [i32; 3], hi: [i32; 3], f: impl Fn([i32; 3]) -> bool) -> VoxelRequest {
        let lo = IVec3::from(lo);
        let dims = (IVec3::from(hi) - lo).max(IVec3::ZERO);
        let n = dims.x as usize * dims.y as usize * dims.z as usize;
        let mut bits = vec![0u64; n.div_ceil(64)];
        let mut i = 0;
        for z in 0..dims.z {
            for y in 0..dims.y {
                for x in 0..dims.x {
                    let v = lo + IVec3::new(x, y, z);
                    if f(v.into()) {
                        bits[i / 64] |= 1 << (i % 64);
                    }
                    i += 1;
                }
            }
        }
        VoxelRequest { lo, dims, bits }
    }

    /// Every voxel of `[lo, hi)`.
    pub fn from_box(lo: [i32; 3], hi: [i32; 3]) -> VoxelRequest {
        VoxelRequest::from_fn(lo, hi, |_| true)
    }

    /// These voxels.
    pub fn from_voxels(voxels: &[[i32; 3]]) -> VoxelRequest {
        if voxels.is_empty() {
            return VoxelRequest::from_box([0; 3], [0; 3]);
        }
        let lo = voxels.iter().fold(IVec3::MAX, |a, &v| a.min(v.into()));
        let hi = voxels.iter().fold(IVec3::MIN, |a, &v| a.max(v.into())) + 1;
        let mut r = VoxelRequest::from_fn(lo.into(), hi.into(), |_| false);
        for &v in voxels {
            let i = r.index(v.into());
            r.bits[i / 64] |= 1 << (i % 64);
        }
        r
    }

    /// The finest voxels of `volume` that a plane (through `point`, with normal `normal`, in
    /// object space) passes through: a cross-section.
    pub fn plane(volume: &Volume, point: Vec3, normal: Vec3) -> VoxelRequest {
        let n = normal.normalize_or(Vec3::Z);
        let half = 0.5 * volume.voxel * (n.x.abs() + n.y.abs() + n.z.abs());
        let hi = [
            volume.dims[0] as i32,
            volume.dims[1] as i32,
            volume.dims[2] as i32,
        ];
        VoxelRequest::from_fn([0; 3], hi, |v| {
            let c = volume.centre(IVec3::from(v));
            (c - point).dot(n).abs() <= half
        })
    }

    #[inline]
    fn index(&self, v: IVec3) -> usize {
        let q = v - self.lo;
        ((q.z as usize * self.dims.y as usize) + q.y as usize) * self.dims.x as usize + q.x as usize
    }

    pub fn contains(&self, v: [i32; 3]) -> bool {
        let v = IVec3::from(v);
        let q = v - self.lo;
        if !(q.cmpge(IVec3::ZERO).all() && q.cmplt(self.dims).all()) {
            return false;
        }
        let i = self.index(v);
        self.bits[i / 64] >> (i % 64) & 1 == 1
    }

    /// Number of voxels.
    pub fn len(&self) -> usize {
        self.bits.iter().map(|b| b.count_ones() as usize).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The voxels, z-major then y then x.
    pub fn voxels(&self) -> impl Iterator<Item = [i32; 3]> + '_ {
        let (nx, ny) = (self.dims.x as usize, self.dims.y as usize);
        self.bits.iter().enumerate().flat_map(move |(wi, &word)| {
            let mut w = word;
            std::iter::from_fn(move || {
                if w == 0 {
                    return None;
                }
                let b = w.trailing_zeros() as usize;
                w &= w - 1;
                let i = wi * 64 + b;
                Some(
                    (self.lo
                        + IVec3::new(
                            (i % nx) as i32,
                            ((i / nx) % ny) as i32,
                            (i / (nx * ny)) as i32,
                        ))
                    .into(),
                )
            })
        })
    }
}
