//! Volumes, rotation fields and exemplar transforms for solid synthesis. Shared by
//! tests/solid_synthesis.rs and the `solid_*` examples.
#![allow(dead_code)] // each user takes a different part

use glam::{Quat, Vec3};
use texsyn::image::Image;
use texsyn::stages::field::quaternion_field::{FieldGrid, RotationField};
use texsyn::stages::parameterize::volume_embedding::Volume;

/// The image mirrored about its diagonal (width and height swapped).
pub fn transpose(img: &Image) -> Image {
    let mut out = Image::new(img.height, img.width);
    for y in 0..img.height {
        for x in 0..img.width {
            out.pixels[(x * img.height + y) as usize] = img.pixels[(y * img.width + x) as usize];
        }
    }
    out
}

/// The identity rotation over a grid of spacing 8 covering `volume`.
pub fn trivial_field(volume: &Volume) -> RotationField {
    let hi = Vec3::from(volume.origin)
        + Vec3::new(
            volume.dims[0] as f32,
            volume.dims[1] as f32,
            volume.dims[2] as f32,
        ) * volume.voxel;
    RotationField::trivial(FieldGrid::covering(volume.origin.into(), hi, 8))
}

/// The rotation `q` everywhere over the grid of [`trivial_field`].
pub fn rotated_field(volume: &Volume, q: Quat) -> RotationField {
    let mut f = trivial_field(volume);
    f.rotations.iter_mut().for_each(|r| *r = q);
    f
}

/// An n³ volume of unit voxels at the origin.
pub fn cube(n: u32) -> Volume {
    Volume {
        origin: [0.0; 3],
        voxel: 1.0,
        dims: [n; 3],
    }
}

/// An n³ [`cube`] and the identity rotation over it ([`trivial_field`]).
pub fn trivial_cube(n: u32) -> (Volume, RotationField) {
    let volume = cube(n);
    let field = trivial_field(&volume);
    (volume, field)
}

/// Tree rings: over a grid of `cells` cells covering `volume`, the rotation about z by the
/// polar angle about the volume's central z axis, so the local x axis points away from the
/// axis (a layered exemplar across x comes out as rings). The nodes on the axis, where the
/// angle is undefined, take 0: a singularity, as in the paper's Fig. 10.
pub fn rings_field(volume: &Volume, cells: u32) -> RotationField {
    let ext = Vec3::new(
        volume.dims[0] as f32,
        volume.dims[1] as f32,
        volume.dims[2] as f32,
    ) * volume.voxel;
    let lo = Vec3::from(volume.origin);
    let mut f = RotationField::trivial(FieldGrid::covering(lo, lo + ext, cells));
    let centre = lo + 0.5 * ext;
    let g = f.grid;
    for k in 0..g.dims[2] {
        for j in 0..g.dims[1] {
            for i in 0..g.dims[0] {
                let p = Vec3::from(g.origin) + Vec3::new(i as f32, j as f32, k as f32) * g.spacing;
                let d = p - centre;
                let n = ((k * g.dims[1] + j) * g.dims[0] + i) as usize;
                if d.x.abs() + d.y.abs() > 1e-6 {
                    let r = (d.x * d.x + d.y * d.y).sqrt();
                    let (c, s) = (d.x / r, d.y / r);
                    // Rotation about z taking x to (c, s): half-angle formulas, no libm.
                    let (hc, hs) = (((1.0 + c) / 2.0).sqrt(), ((1.0 - c) / 2.0).sqrt());
                    let hs = if s < 0.0 { -hs } else { hs };
                    f.rotations[n] = Quat::from_xyzw(0.0, 0.0, hs, hc);
                }
            }
        }
    }
    f
}

/// `field` with every node tilted by its own pseudo-random rotation of up to `amplitude`
/// radians about x and about y (counter-based, so reproducible): a field with jumps from node
/// to node, as a hastily sketched or noisy one has.
pub fn jittered(field: &RotationField, amplitude: f32, seed: u64) -> RotationField {
    let mut f = field.clone();
    for (n, q) in f.rotations.iter_mut().enumerate() {
        let u = |s: u64| texsyn::random::counter_unit(seed, s, n as u64) * 2.0 - 1.0;
        let tilt =
            Quat::from_rotation_x(amplitude * u(1)) * Quat::from_rotation_y(amplitude * u(2));
        *q = (*q * tilt).normalize();
    }
    f
}
