//! `texsyn render`: renders three views of a mesh, textured through its OBJ texture
//! coordinates, into one PNG.

use super::{Globals, write_atomic};
use anyhow::{Context, Result, bail};
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
    /// Up axis: x, y, z, -x, -y, -z, or auto (guessed from the mesh: the side it stands on
    /// most steadily; the axis used is printed).
    #[arg(long, default_value = "auto")]
    up: String,
}

/// `texsyn render`.
pub fn render(args: &RenderArgs, g: &Globals) -> Result<i32> {
    let up = if args.up == "auto" {
        let bytes = std::fs::read(&args.mesh)
            .with_context(|| format!("reading {}", args.mesh.display()))?;
        let mesh = texsyn::geom::io::read_mesh_bytes(&args.mesh, &bytes)?;
        let up = texsyn::render::up_axis::guess_up(&mesh.positions, &mesh.triangles);
        if !g.quiet {
            println!(
                "up: {} (guessed from the mesh; --up chooses)",
                texsyn::render::up_axis::axis_name(up)
            );
        }
        up
    } else {
        parse_axis(&args.up)?
    };
    let opts = texsyn::render::views::ViewOptions {
        size: args.size,
        up,
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
        other => bail!("--up {other:?}: expected x, y, z, -x, -y, -z or auto"),
    })
}
