//! Synthesis quality and variant-analysis cost of a `geometry_images` config.
//!
//! Runs the config (with `field.density_offset = 0` and any further `--set` overrides) in a
//! cache directory and prints, for the synthesize node's output, the nearest-patch measures of
//! [`texsyn::image::patch_score`] (7×7 patches, at most 20,000 queries, seed 0): the synthesized
//! height channel (dn, level 0) scored as a grey image against the variant set's middle-scale,
//! orientation-0, finest-level height image, both mapped to [0, 1] by the same affine map (that
//! sample image's height range). It also prints the analyse_exemplar node's seconds and size
//! (its seconds are those of this run: 0 when the cache already held it).
//!
//! ```text
//! cargo run --release -p texsyn-bench --example gi_quality -- CONFIG CACHE_DIR [KEY=VALUE ...] [--png OUT.png]
//! ```

use std::path::PathBuf;
use texsyn::artifact::Format;
use texsyn::config::Config;
use texsyn::geom::geometry_image::TexelImage;
use texsyn::image::Image;
use texsyn::image::patch_score::{ScoreParams, patch_score};
use texsyn::pipeline::{ProgressMode, RunOptions};
use texsyn::stages::analyse_exemplar::texel_variants::TexelVariants;

fn grey(width: u32, height: u32, h: impl Fn(u32, u32) -> f32, lo: f32, hi: f32) -> Image {
    let mut img = Image::new(width, height);
    for y in 0..height {
        for x in 0..width {
            let v = (h(x, y) - lo) / (hi - lo).max(1e-12);
            img.pixels[(y * width + x) as usize] = [v, v, v, 1.0];
        }
    }
    img
}

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let config = PathBuf::from(args.next().expect("CONFIG"));
    let cache_dir = PathBuf::from(args.next().expect("CACHE_DIR"));
    let mut sets = vec!["field.density_offset=0".to_owned()];
    let mut png = None;
    while let Some(a) = args.next() {
        if a == "--png" {
            png = Some(PathBuf::from(args.next().expect("--png OUT")));
        } else {
            sets.push(a);
        }
    }
    let cfg = Config::load(&config, &sets)?;
    let plan = texsyn::methods::plan(&cfg)?;
    let cache = texsyn::cache::Cache::open(&cache_dir)?;
    let t = std::time::Instant::now();
    let result = texsyn::pipeline::run(
        &plan.dag,
        &cache,
        RunOptions {
            progress: ProgressMode::Hidden,
            verify_all: false,
            defer_export_checks: false,
        },
    )?;
    let wall = t.elapsed().as_secs_f64();
    let find = |stage: &str| {
        result
            .reports
            .iter()
            .position(|r| r.stage == stage)
            .unwrap_or_else(|| panic!("no {stage} node"))
    };
    let (ia, is) = (find("analyse_exemplar"), find("synthesize"));
    let variants = TexelVariants::view(&result.artifacts[ia])?;
    let synth = TexelImage::view(&result.artifacts[is])?;
    let p = variants.params();
    let c = variants.channels();
    let ex = variants.level(variants.variant(p.middle_scale(), 0), 0);
    let heights: Vec<f32> = ex.texels.iter().skip(2).step_by(c).copied().collect();
    let lo = heights.iter().copied().fold(f32::INFINITY, f32::min);
    let hi = heights.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    let exemplar = grey(
        ex.width,
        ex.height,
        |x, y| heights[(y * ex.width + x) as usize],
        lo,
        hi,
    );
    let out = grey(
        synth.width,
        synth.height,
        |x, y| synth.texel(x, y)[2],
        lo,
        hi,
    );
    let s = patch_score(out.view(), exemplar.view(), &ScoreParams::default())?;
    let ra = &result.reports[ia];
    let rs = &result.reports[is];
    println!(
        "{} {}: ratio {:.3} coverage {:.3} largest_offset {:.3} gradient_ratio {:.3} | \
         analyse {:?} {:.2} s {:.1} MB | synthesize {:?} {:.2} s | run {wall:.1} s",
        config.display(),
        sets[1..].join(" "),
        s.ratio,
        s.coverage,
        s.largest_offset,
        s.gradient_ratio,
        ra.status,
        ra.seconds,
        ra.bytes as f64 / 1e6,
        rs.status,
        rs.seconds,
    );
    if let Some(path) = png {
        let img = image::GrayImage::from_fn(synth.width, synth.height, |x, y| {
            let v = (synth.texel(x, y)[2] - lo) / (hi - lo).max(1e-12);
            image::Luma([(v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8])
        });
        img.save(&path)?;
    }
    Ok(())
}
