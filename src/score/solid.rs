//! Scoring the solid method (Zhang, Du, Lai, Ni & Hu, "Sketch Guided Solid Texturing"):
//! planar sections of the synthesized solid against the exemplar of their plane.
//!
//! The solid matches each axis plane's slices to that plane's exemplar (§4), so a section
//! along an axis plane is comparable with it. What is scored is what the run's request makes:
//! a `section` request whose normal is an axis (`section.png`: normal z against `xy`, x
//! against `yz`, y against `zx`, falling back to `inputs.exemplar`), a `box` request's middle
//! z slice (`volume_middle_slice.png`, against `xy`). Pixels outside the synthesized voxels
//! (the section image's background colour) are masked out. A `surface` request makes no
//! planar image: `texsyn score` then synthesizes a section through the centre of the mesh's
//! bounding box, normal z, in the same cache ([`substitute_section`]; bricks the surface
//! already made are reused) and scores that; `run`'s `[score]` reports it as not scored.
//!
//! Limits: the section is in world axes; where the rotation field turns the solid away from
//! them (sketched curves), its slices are not along the exemplar planes and score farther
//! than the synthesis is; region exemplars (`[[regions]]`) are not told apart.

use super::{Item, Run, ScoreFailure};
use crate::artifact::Bundle;
use crate::geom::Mesh;
use crate::image::Image;
use crate::pipeline::Handle;
use crate::stages::analyse_exemplar::candidate_triples::ExemplarSpec;
use crate::stages::parameterize::volume_embedding::Request;
use std::path::Path;

/// `section.png`'s colour where no voxel was synthesized (solid_colour.rs).
const BACKGROUND: [u8; 3] = [235, 236, 240];

/// The nodes of a solid run that its score reads.
#[derive(Clone, Copy)]
pub struct SolidNodes {
    pub mesh: Handle<Mesh>,
    pub reconstruct: Handle<Bundle>,
}

/// What of a solid run's config its score reads.
#[derive(Clone, Debug)]
pub struct SolidSetup {
    pub request: Request,
    /// `inputs.xy`, `inputs.yz`, `inputs.zx`; `inputs.exemplar` stands in for a missing one.
    pub xy: Option<ExemplarSpec>,
    pub yz: Option<ExemplarSpec>,
    pub zx: Option<ExemplarSpec>,
    pub exemplar: Option<ExemplarSpec>,
    /// How many `[[regions]]` the config has.
    pub regions: usize,
    /// Whether the rotation field follows sketched curves.
    pub sketched: bool,
}

/// A solid run's score hook: its nodes and what of its config the score reads.
pub struct SolidScore {
    pub nodes: SolidNodes,
    pub setup: SolidSetup,
}

impl super::Planned for SolidScore {
    fn score(
        &self,
        run: &Run<'_>,
        not_scored: &mut Vec<String>,
    ) -> Result<Vec<Item>, ScoreFailure> {
        solid(run, &self.nodes, &self.setup, not_scored)
    }

    fn score_substitute(&self, result: &crate::pipeline::RunResult) -> Option<String> {
        substitute_section(result, &self.nodes, &self.setup.request)
    }
}

pub fn solid(
    run: &Run,
    nodes: &SolidNodes,
    c: &SolidSetup,
    not_scored: &mut Vec<String>,
) -> Result<Vec<Item>, ScoreFailure> {
    // How the written image lies against its exemplar (see `PlaneFrame`).
    let mut frame = PlaneFrame {
        flip_rows: true,
        transpose: false,
        flip_columns: false,
    };
    let (file, plane) = match c.request {
        Request::Surface => {
            not_scored.push(
                "solid surface request: the solid is synthesized only where the surface passes, \
                 so there is no planar image to compare; `texsyn score` on this config synthesizes \
                 a section through the mesh's centre (normal z) and scores that"
                    .into(),
            );
            return Ok(Vec::new());
        }
        Request::Section { normal, .. } => {
            let axis = (0..3)
                .find(|&a| (0..3).all(|b| b == a || normal[b].abs() <= 1e-6 * normal[a].abs()));
            let positive = axis.is_some_and(|a| normal[a] > 0.0);
            frame = PlaneFrame {
                flip_rows: axis != Some(1) && positive,
                transpose: axis == Some(1),
                flip_columns: axis == Some(1) && !positive,
            };
            match axis {
                Some(0) => ("section.png", "yz"),
                Some(1) => ("section.png", "zx"),
                Some(2) => ("section.png", "xy"),
                _ => {
                    not_scored.push(format!(
                        "solid section with normal {normal:?}: not along an exemplar plane (its \
                         normal is no axis)"
                    ));
                    return Ok(Vec::new());
                }
            }
        }
        Request::Box { .. } => ("volume_middle_slice.png", "xy"),
    };
    let spec = match plane {
        "xy" => c.xy.as_ref(),
        "yz" => c.yz.as_ref(),
        _ => c.zx.as_ref(),
    };
    let (spec, key) = match spec {
        Some(s) => (s, format!("inputs.{plane}")),
        None => match c.exemplar.as_ref() {
            Some(s) => (s, "inputs.exemplar".to_owned()),
            None => {
                not_scored.push(format!("solid {file}: no exemplar for the {plane} plane"));
                return Ok(Vec::new());
            }
        },
    };
    let exemplar = load_exemplar(run, spec, &key)?;
    let out = frame.apply(&run.image(nodes.reconstruct, file)?);
    let mask: Vec<bool> = out
        .pixels
        .iter()
        .map(|p| {
            let q = [p[0], p[1], p[2]].map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8);
            q != BACKGROUND
        })
        .collect();
    let mut item = Item::new(file, key);
    run.score_into(&mut item, out.view(), Some(&mask), exemplar.view())?;
    if c.regions > 0 {
        item.notes.push(format!(
            "the config has {} [[regions]] with exemplars of their own: their voxels in the \
             section are scored against the base exemplar too, and far from it",
            c.regions
        ));
    }
    if c.sketched {
        item.notes.push(
            "the rotation field follows sketched curves: where it turns the solid, this \
             world-axis section is not along the exemplar plane"
                .into(),
        );
    }
    Ok(vec![item])
}

/// How a section image lies against its plane's exemplar. The exemplar of plane `P` has image
/// x along local axis `P` and image y (rows down) along axis `P + 1` (candidate_triples.rs).
/// A section's image has x along its `u` axis and rows running down its `v` axis
/// (`volume_embedding::section`, `solid_colour.rs`): for a normal `+z`, `u = x` and `v = y`,
/// so rows run along `−y` and the image is the exemplar's upside down; `+x` likewise (`u = y`,
/// `v = z`); a negative normal turns `v` round, so no flip; a `±y` normal has `u = x` and
/// `v = ∓z` against the `zx` exemplar's (z, x): transposed, and mirrored for `−y`. A box's
/// middle z slice is written like a `+z` section.
#[derive(Clone, Copy, Debug, PartialEq)]
struct PlaneFrame {
    flip_rows: bool,
    transpose: bool,
    /// After the transpose.
    flip_columns: bool,
}

impl PlaneFrame {
    fn apply(&self, img: &Image) -> Image {
        let (w, h) = (img.width, img.height);
        let (ow, oh) = if self.transpose { (h, w) } else { (w, h) };
        let mut out = Image::new(ow, oh);
        for oy in 0..oh {
            for ox in 0..ow {
                // (ox, oy) in the exemplar's frame; (sx, sy) in the written image.
                let tx = if self.flip_columns { ow - 1 - ox } else { ox };
                let (sx, sy) = if self.transpose { (oy, tx) } else { (tx, oy) };
                let sy = if self.flip_rows { h - 1 - sy } else { sy };
                out.pixels[(oy * ow + ox) as usize] = img.pixels[(sy * w + sx) as usize];
            }
        }
        out
    }
}

/// For a solid run whose request is the surface: the `--set` that asks for a section
/// instead, through the centre of the mesh's bounding box with normal z (the `xy` exemplar's
/// plane), which cuts the mesh whatever its shape. `texsyn score` runs that (the bricks the
/// two requests share are reused from the cache) and scores its `section.png`. `None` for
/// other requests.
pub fn substitute_section(
    result: &crate::pipeline::RunResult,
    nodes: &SolidNodes,
    request: &Request,
) -> Option<String> {
    if *request != Request::Surface {
        return None;
    }
    let mesh =
        <Mesh as crate::artifact::Format>::view(&result.artifacts[nodes.mesh.index()]).ok()?;
    let (lo, hi) = mesh.bounds();
    let m = (lo + hi) * 0.5;
    Some(format!(
        "parameterize.request={{ kind = \"section\", point = [{}, {}, {}], normal = [0.0, 0.0, 1.0] }}",
        m.x, m.y, m.z
    ))
}

/// The exemplar image a spec names, transposed when it says so.
fn load_exemplar(run: &Run, spec: &ExemplarSpec, key: &str) -> Result<Image, ScoreFailure> {
    let transpose = spec.transpose();
    let path = run.config.resolve(spec.path());
    let bytes = std::fs::read(&path)
        .map_err(|e| ScoreFailure::new(format!("{} ({key}): {e}", path.display())))?;
    let img = crate::image::decode_image(Path::new(&path), &bytes)
        .map_err(|e| ScoreFailure::new(format!("{} ({key}): {e}", path.display())))?;
    Ok(if transpose {
        Image::from_fn(img.height, img.width, |x, y| img.view().get(y, x))
    } else {
        img
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: u32, h: u32) -> Image {
        let mut img = Image::new(w, h);
        for y in 0..h {
            for x in 0..w {
                img.pixels[(y * w + x) as usize] = [x as f32, y as f32, 0.0, 1.0];
            }
        }
        img
    }

    #[test]
    fn plane_frames_flip_and_transpose_as_documented() {
        let img = ramp(3, 2);
        let at = |i: &Image, x: u32, y: u32| {
            let p = i.pixels[(y * i.width + x) as usize];
            (p[0] as u32, p[1] as u32)
        };
        let f = |flip_rows, transpose, flip_columns| PlaneFrame {
            flip_rows,
            transpose,
            flip_columns,
        };
        let up = f(true, false, false).apply(&img);
        assert_eq!((up.width, up.height), (3, 2));
        assert_eq!(at(&up, 0, 0), (0, 1));
        assert_eq!(at(&up, 2, 1), (2, 0));
        let t = f(false, true, false).apply(&img);
        assert_eq!((t.width, t.height), (2, 3));
        assert_eq!(at(&t, 1, 2), (2, 1));
        let tm = f(false, true, true).apply(&img);
        assert_eq!(at(&tm, 0, 2), (2, 1));
        assert_eq!(at(&tm, 1, 0), (0, 0));
    }
}
