//! Geometry images (Gu, Gortler & Hoppe 2002, as used by Lai et al., "Geometric Texture
//! Synthesis and Transfer via Geometry Images", §3): a surface cut to a disk, mapped to the
//! unit square and sampled on an N×N grid, and the texel images synthesized over them.
//!
//! Grid convention: sample (row i, column j) is at index `i * n + j`; column j runs along the
//! parameter u, row i along v. Boundary samples that are the same surface point (the two
//! sides of a cut, or several where cuts meet) are *mates*; they hold bit-identical positions
//! and normals, and `mate_rep` maps every sample to the smallest index of its mate group
//! (itself when it has no mate).

use glam::Vec3;

#[derive(Debug, Clone, PartialEq)]
pub struct GeometryImage {
    pub n: u32,
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    /// Per sample, the smallest sample index that is the same surface point.
    pub mate_rep: Vec<u32>,
}

impl GeometryImage {
    #[inline]
    pub fn index(&self, i: u32, j: u32) -> usize {
        (i * self.n + j) as usize
    }

    pub fn is_boundary(&self, i: u32, j: u32) -> bool {
        i == 0 || j == 0 || i == self.n - 1 || j == self.n - 1
    }

    /// The sample indices of each mate group with more than one member, smallest first.
    pub fn mate_groups(&self) -> Vec<Vec<u32>> {
        let mut groups: std::collections::BTreeMap<u32, Vec<u32>> = Default::default();
        for (k, &r) in self.mate_rep.iter().enumerate() {
            if r as usize != k {
                groups.entry(r).or_insert_with(|| vec![r]).push(k as u32);
            }
        }
        groups.into_values().collect()
    }
}

/// A grid of texels with `channels` values each: geometric texture (dx, dy, dn), optionally
/// followed by colour (r, g, b) (§4.1.4). Row-major like [`GeometryImage`].
#[derive(Debug, Clone, PartialEq)]
pub struct TexelImage {
    pub width: u32,
    pub height: u32,
    pub channels: u32,
    pub data: Vec<f32>,
}

impl TexelImage {
    pub fn new(width: u32, height: u32, channels: u32) -> Self {
        TexelImage {
            width,
            height,
            channels,
            data: vec![0.0; (width * height * channels) as usize],
        }
    }

    #[inline]
    pub fn texel(&self, x: u32, y: u32) -> &[f32] {
        let c = self.channels as usize;
        let i = (y as usize * self.width as usize + x as usize) * c;
        &self.data[i..i + c]
    }

    #[inline]
    pub fn texel_mut(&mut self, x: u32, y: u32) -> &mut [f32] {
        let c = self.channels as usize;
        let i = (y as usize * self.width as usize + x as usize) * c;
        &mut self.data[i..i + c]
    }
}

/// A local frame: x̂ and ŷ tangent, n̂ normal, orthonormal and right-handed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    pub x: Vec3,
    pub y: Vec3,
    pub n: Vec3,
}

/// The local frames of §4.1.1 (eq. 5) over a grid of positions: n̂ from the grid's
/// neighbouring samples, x̂ the central difference along j (one-sided at the first and last
/// column) made orthogonal to n̂, ŷ = n̂ × x̂. Frames of mates are copied from their group's
/// representative so that one texel value means one displacement on both sides of a cut
/// (§4.2.2 makes mated texels identical).
pub fn local_frames(n: u32, positions: &[Vec3], normals: &[Vec3], mate_rep: &[u32]) -> Vec<Frame> {
    let nn = n as usize;
    let at = |i: usize, j: usize| positions[i * nn + j];
    let mut frames: Vec<Frame> = (0..nn * nn)
        .map(|k| {
            let (i, j) = (k / nn, k % nn);
            let normal = normals[k].normalize_or_zero();
            let dx = if nn < 2 {
                Vec3::X
            } else if j == 0 {
                at(i, 1) - at(i, 0)
            } else if j == nn - 1 {
                at(i, nn - 1) - at(i, nn - 2)
            } else {
                (at(i, j + 1) - at(i, j - 1)) * 0.5
            };
            let mut x = (dx - dx.dot(normal) * normal).normalize_or_zero();
            if x == Vec3::ZERO {
                // Degenerate row (a collapsed boundary): any tangent keeps the frame valid.
                x = if normal == Vec3::ZERO {
                    Vec3::X
                } else {
                    normal.any_orthonormal_vector()
                };
            }
            let normal = if normal == Vec3::ZERO {
                x.any_orthonormal_vector()
            } else {
                normal
            };
            Frame {
                x,
                y: normal.cross(x),
                n: normal,
            }
        })
        .collect();
    for k in 0..frames.len() {
        let r = mate_rep[k] as usize;
        if r != k {
            frames[k] = frames[r];
        }
    }
    frames
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_of_a_tilted_plane_follow_the_grid_and_mates_share_the_representatives() {
        let n = 5u32;
        let mut positions = Vec::new();
        for i in 0..n {
            for j in 0..n {
                positions.push(Vec3::new(j as f32, 0.5 * j as f32, i as f32));
            }
        }
        let normal = Vec3::new(1.0, 0.5, 0.0).cross(Vec3::Z).normalize();
        let normals = vec![normal; 25];
        let mut mate_rep: Vec<u32> = (0..25).collect();
        mate_rep[24] = 4; // pretend the last corner mates the first row's end
        let f = local_frames(n, &positions, &normals, &mate_rep);
        let x = Vec3::new(1.0, 0.5, 0.0).normalize();
        for (k, fr) in f.iter().enumerate() {
            assert!((fr.x - x).length() < 1e-6, "sample {k}");
            assert!((fr.n - normal).length() < 1e-6);
            assert!((fr.y - normal.cross(x)).length() < 1e-6);
        }
        assert_eq!(f[24], f[4]);
    }

    #[test]
    fn mate_groups_collect_each_group_once() {
        let gi = GeometryImage {
            n: 2,
            positions: vec![Vec3::ZERO; 4],
            normals: vec![Vec3::Z; 4],
            mate_rep: vec![0, 0, 2, 0],
        };
        assert_eq!(gi.mate_groups(), vec![vec![0, 1, 3]]);
    }
}
