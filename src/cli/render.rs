//! `texsyn render`: renders three views of a mesh, textured through its OBJ texture
//! coordinates, into one PNG.

use super::{Globals, write_atomic};
use anyhow::{Result, bail};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct RenderArgs {
    mesh: PathBuf,
    /// Texture image for the mesh's texture coordinates. Without it an OBJ's materials'
    /// `map_Kd` images (beside the OBJ) are used, one per material: every page of a baked
    /// atlas.
    #[arg(long)]
    texture: Option<PathBuf>,
    /// Output PNG.
    #[arg(short, long)]
    output: PathBuf,
    /// Side of each view in pixels.
    #[arg(long, default_value_t = 512)]
    size: u32,
    /// Up axis: x, y, z, -x, -y or -z.
    #[arg(long, default_value = "y")]
    up: String,
}

/// `texsyn render`.
pub fn render(args: &RenderArgs, g: &Globals) -> Result<i32> {
    let opts = texsyn::render::views::ViewOptions {
        size: args.size,
        up: parse_axis(&args.up)?,
        ..Default::default()
    };
    let img = texsyn::render::load::render_mesh_file(&args.mesh, args.texture.as_deref(), &opts)?;
    let png = texsyn::stages::reconstruct::textured_export::encode_png(&img, false);
    write_atomic(&args.output, &png)?;
    if !g.quiet {
        println!("wrote {}", args.output.display());
    }
    Ok(0)
}

/// `--up`'s axis.
fn parse_axis(s: &str) -> Result<glam::Vec3> {
    Ok(match s {
        "x" | "+x" => glam::Vec3::X,
        "y" | "+y" => glam::Vec3::Y,
        "z" | "+z" => glam::Vec3::Z,
        "-x" => -glam::Vec3::X,
        "-y" => -glam::Vec3::Y,
        "-z" => -glam::Vec3::Z,
        other => bail!("--up {other:?}: expected x, y, z, -x, -y or -z"),
    })
}
