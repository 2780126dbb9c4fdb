//! The optimization loop (§5.1–5.2): per level, alternating the nearest-patch search with the
//! least-squares colour solve, the constraint's curve weight, the energy, and the final paste
//! of each vertex's nearest exemplar texel.

use super::candidates::{Candidates, Level, Rgb, Rot, build_candidates, margin};
use super::params::{
    Solver, SurfaceSynthesis, SurfaceSynthesisInput, SynthesisError, SynthesisStats,
    TextureOptimizationParams,
};
use super::patches::{
    Frames, Patches, SampleInfo, choose_samples, gather_patches, split_by, sq, tangent_frames,
};
use super::search::{occurrence_penalty, search};
use crate::random::counter_hash;
use rayon::prelude::*;
use std::collections::VecDeque;
use texsyn_core::math::PureMath;

const STREAM_ORDER: u64 = 1;
const STREAM_INIT: u64 = 2;
/// Floor of `|x_p − z_p|` in Kwatra's weight.
const MIN_PATCH_DISTANCE: f32 = 1e-4;

/// λ_p of a sample at curve distance `d` texels (see the module doc). `d` not below `band`
/// (NaN and ∞ included) is outside the constraint's reach.
pub(super) fn curve_weight(d: f32, band: f32, floor: f32) -> f32 {
    let d = if d < band { d.max(floor) } else { band };
    1.0 / d
}

/// Synthesizes a texture on `input.mesh`; see the module doc. `progress` gets the fraction
/// done after every iteration.
pub fn texture_optimization(
    input: &SurfaceSynthesisInput,
    p: &TextureOptimizationParams,
    progress: &(dyn Fn(f32) + Sync),
) -> Result<SurfaceSynthesis, SynthesisError> {
    p.validate()?;
    let mesh = input.mesh;
    let n = mesh.vertex_count();
    let ex = input.exemplar;
    let (ew, eh) = (ex.width as usize, ex.height as usize);
    if input.field.len() != n {
        return Err(SynthesisError::InputMismatch(format!(
            "the field has {} vectors for {n} vertices",
            input.field.len()
        )));
    }
    if ex.pixels.len() != ew * eh {
        return Err(SynthesisError::InputMismatch(format!(
            "the exemplar is {ew}×{eh} but has {} pixels",
            ex.pixels.len()
        )));
    }
    if !(input.texel_size.is_finite() && input.texel_size > 0.0) {
        return Err(SynthesisError::InputMismatch(format!(
            "texel_size must be a positive number of object units, got {}",
            input.texel_size
        )));
    }
    if !input.exemplar_angle.is_finite() {
        return Err(SynthesisError::InputMismatch(format!(
            "exemplar_angle must be finite, got {}",
            input.exemplar_angle
        )));
    }
    if let Some(f) = &input.features {
        if f.curve_distance.len() != n {
            return Err(SynthesisError::InputMismatch(format!(
                "curve_distance has {} values for {n} vertices",
                f.curve_distance.len()
            )));
        }
        if f.texture_distance.len() != ew * eh {
            return Err(SynthesisError::InputMismatch(format!(
                "texture_distance has {} values for the {ew}×{eh} exemplar",
                f.texture_distance.len()
            )));
        }
    }
    let rot = Rot {
        c: input.exemplar_angle.cos_pure(),
        s: input.exemplar_angle.sin_pure(),
    };
    let w = p.patch as usize;
    let finest = Level { w, step: 1.0 };
    let m = margin(finest, rot);
    if ew.min(eh) < 2 * m + 1 {
        return Err(SynthesisError::ExemplarTooSmall {
            patch: p.patch,
            width: ex.width,
            height: ex.height,
            needed: (2 * m + 1) as u32,
            angle_degrees: input.exemplar_angle.to_degrees(),
        });
    }
    let rgb = Rgb {
        w: ew,
        h: eh,
        px: ex.pixels.iter().map(|c| [c[0], c[1], c[2]]).collect(),
    };
    let mut mean = [0.0f64; 3];
    for c in &rgb.px {
        for k in 0..3 {
            mean[k] += c[k] as f64;
        }
    }
    let mean = mean.map(|x| (x / rgb.px.len().max(1) as f64) as f32);

    let mut referenced = vec![false; n];
    for t in &mesh.triangles {
        for &v in t {
            referenced[v as usize] = true;
        }
    }
    let mut colours = vec![mean; n];
    let mut source = vec![[-1.0f32; 2]; n];
    let mut stats = SynthesisStats::default();
    if !referenced.iter().any(|&r| r) {
        progress(1.0);
        return Ok(SurfaceSynthesis {
            colours,
            source,
            stats,
        });
    }

    let (normals, us, vs) = tangent_frames(mesh, input.field);
    let frames = Frames {
        normals: &normals,
        u: &us,
        v: &vs,
    };
    let h = input.texel_size;
    let curve_texels: Option<Vec<f32>> = input
        .features
        .as_ref()
        .map(|f| f.curve_distance.iter().map(|&d| d / h).collect());

    let levels: Vec<Level> = (0..p.levels)
        .rev()
        .map(|l| Level {
            w,
            step: (1u32 << l) as f32,
        })
        .collect();
    let total_iterations = (levels.len() as u32 * p.iterations) as f32;
    let mut done_iterations = 0u32;
    let mut first = true;
    for (li, &level) in levels.iter().enumerate() {
        let t0 = std::time::Instant::now();
        let Some(cands) = build_candidates(
            &rgb,
            input.features.as_ref().map(|f| f.texture_distance),
            level,
            rot,
            p.components as usize,
        ) else {
            // A coarse level that does not fit: the finest one is checked above.
            done_iterations += p.iterations;
            continue;
        };
        stats.levels_run += 1;
        let band = level.extent() * 0.5;

        // X†.
        let mut order: Vec<(u8, f32, u64, u32)> = (0..n as u32)
            .map(|v| {
                let hash = counter_hash(p.seed, STREAM_ORDER, v as u64);
                match &curve_texels {
                    Some(d) if d[v as usize] < band => (0, d[v as usize], hash, v),
                    _ => (1, 0.0, hash, v),
                }
            })
            .collect();
        order.sort_by(|a, b| {
            a.0.cmp(&b.0)
                .then(a.1.total_cmp(&b.1))
                .then(a.2.cmp(&b.2))
                .then(a.3.cmp(&b.3))
        });
        let order: Vec<u32> = order.into_iter().map(|x| x.3).collect();
        let t1 = std::time::Instant::now();
        let samples = choose_samples(
            mesh,
            &order,
            p.sample_spacing * level.extent() * h,
            &referenced,
        );
        let patches = gather_patches(mesh, &frames, &samples, level, h);
        let t2 = std::time::Instant::now();
        let ns = samples.len();

        let mut info = SampleInfo {
            lambda: vec![1.0; ns],
            constraint: vec![None; ns],
        };
        let (mut constrained, mut fallbacks) = (0u32, 0u32);
        if let Some(d) = &curve_texels {
            for (i, &s) in samples.iter().enumerate() {
                let ds = d[s as usize];
                info.lambda[i] = curve_weight(ds, band, p.min_curve_distance);
                if ds < band {
                    constrained += 1;
                    if cands.any_within(ds, p.feature_tolerance) {
                        info.constraint[i] = Some(ds);
                    } else {
                        fallbacks += 1;
                    }
                }
            }
        }
        stats.samples = ns as u32;
        stats.constrained_samples = constrained;
        stats.unconstrained_fallbacks = fallbacks;

        // Initial matches: random at the first level, else where each sample's vertex came
        // from at the previous level.
        let mut z: Vec<u32> = samples
            .iter()
            .enumerate()
            .map(|(i, &s)| {
                if first {
                    (counter_hash(p.seed, STREAM_INIT, i as u64) % cands.len() as u64) as u32
                } else {
                    cands.nearest_to(source[s as usize])
                }
            })
            .collect();
        let mut lookups = vec![[0.0f32; 3]; patches.vertex.len()];
        refresh_lookups(&mut lookups, &patches, &z, &cands, &rgb, rot);
        if first {
            paste_nearest(
                &patches,
                &lookups,
                &cands,
                &z,
                rot,
                &mut colours,
                &mut source,
            );
            first = false;
        }
        for it in 0..p.iterations {
            let penalty = occurrence_penalty(&z, &cands, p.histogram);
            let new_z = search(
                &patches, &info, &colours, &z, &cands, level, p, &penalty, &source, rot,
            );
            let changed = new_z != z;
            if it > 0 && !changed {
                break;
            }
            z = new_z;
            refresh_lookups(&mut lookups, &patches, &z, &cands, &rgb, rot);
            let omega = robust_weights(&patches, &colours, &lookups, &z, &cands, p);
            solve_colours(
                &patches,
                &info,
                &omega,
                &lookups,
                &cands,
                &z,
                rot,
                Solver::Average,
                &mut colours,
                &mut source,
            );
            stats.final_energy =
                total_energy(&patches, &info, &colours, &lookups, p.robust_exponent);
            stats.iterations_run += 1;
            done_iterations += 1;
            progress((done_iterations as f32 / total_iterations).min(1.0));
        }
        if p.solver == Solver::Discrete && li + 1 == levels.len() {
            // The final discrete pass: each vertex copies its best-matching covering patch.
            let omega = robust_weights(&patches, &colours, &lookups, &z, &cands, p);
            let (c, s) = (&mut colours, &mut source);
            solve_colours(
                &patches, &info, &omega, &lookups, &cands, &z, rot, p.solver, c, s,
            );
        }
        tracing::debug!(
            "texture optimization level {li}: {} candidates in {:?}, {ns} samples and patches in \
             {:?}, iterations in {:?}",
            cands.len(),
            t1 - t0,
            t2 - t1,
            t2.elapsed()
        );
        done_iterations = (li as u32 + 1) * p.iterations;
        progress((done_iterations as f32 / total_iterations).min(1.0));
    }

    // Vertices no patch covered: from the nearest covered vertex, in edge hops.
    let mut covered: Vec<bool> = source.iter().map(|s| s[0] > -0.5).collect();
    let mut queue: VecDeque<usize> = (0..n).filter(|&v| covered[v]).collect();
    let adj = mesh.adjacency();
    while let Some(a) = queue.pop_front() {
        for &b in adj.neighbors(a) {
            let b = b as usize;
            if !covered[b] && referenced[b] {
                covered[b] = true;
                colours[b] = colours[a];
                source[b] = source[a];
                stats.uncovered_vertices += 1;
                queue.push_back(b);
            }
        }
    }
    progress(1.0);
    Ok(SurfaceSynthesis {
        colours,
        source,
        stats,
    })
}

/// The exemplar colour each patch entry's vertex is asked to take under its sample's match.
pub(super) fn refresh_lookups(
    lookups: &mut [[f32; 3]],
    patches: &Patches,
    z: &[u32],
    cands: &Candidates,
    rgb: &Rgb,
    rot: Rot,
) {
    split_by(lookups, &patches.start)
        .into_par_iter()
        .enumerate()
        .for_each(|(i, out)| {
            let c = cands.centre(z[i]);
            let base = patches.start[i];
            for (k, o) in out.iter_mut().enumerate() {
                *o = rgb.sample(c + rot.apply(patches.offset[base + k]));
            }
        });
}

/// Kwatra's `ω_p = |x_p − z_p|^(r−2)` per sample, divided by the occurrence penalty of its
/// match: Kopf et al. §3.3, samples matched to over-used exemplar content count less.
fn robust_weights(
    patches: &Patches,
    colours: &[[f32; 3]],
    lookups: &[[f32; 3]],
    z: &[u32],
    cands: &Candidates,
    p: &TextureOptimizationParams,
) -> Vec<f32> {
    let penalty = occurrence_penalty(z, cands, p.histogram);
    patch_errors(patches, colours, lookups)
        .iter()
        .zip(z)
        .map(|(&e, &zi)| {
            (e.sqrt() as f32)
                .max(MIN_PATCH_DISTANCE)
                .powf_pure(p.robust_exponent - 2.0)
                / penalty[zi as usize]
        })
        .collect()
}

/// `|x_p − z_p|²` per sample: squared RGB differences summed over the patch's vertices.
pub(super) fn patch_errors(
    patches: &Patches,
    colours: &[[f32; 3]],
    lookups: &[[f32; 3]],
) -> Vec<f64> {
    (0..patches.start.len() - 1)
        .into_par_iter()
        .map(|i| {
            let mut s = 0.0f64;
            for e in patches.start[i]..patches.start[i + 1] {
                s += sq(colours[patches.vertex[e] as usize], lookups[e]) as f64;
            }
            s
        })
        .collect()
}

pub(super) fn total_energy(
    patches: &Patches,
    info: &SampleInfo,
    colours: &[[f32; 3]],
    lookups: &[[f32; 3]],
    r: f32,
) -> f64 {
    let errors = patch_errors(patches, colours, lookups);
    errors
        .iter()
        .zip(&info.lambda)
        .map(|(&e, &l)| l as f64 * e.powf_pure(r as f64 * 0.5))
        .sum()
}

/// The colour step: each covered vertex takes the lookup and source of its heaviest covering
/// patch, the one of largest `λω` (`Solver::Discrete`), or the `λω`-weighted mean of its
/// patches' lookups and the heaviest one's source (`Solver::Average`).
#[allow(clippy::too_many_arguments)]
pub(super) fn solve_colours(
    patches: &Patches,
    info: &SampleInfo,
    omega: &[f32],
    lookups: &[[f32; 3]],
    cands: &Candidates,
    z: &[u32],
    rot: Rot,
    solver: Solver,
    colours: &mut [[f32; 3]],
    source: &mut [[f32; 2]],
) {
    colours
        .par_iter_mut()
        .zip(source.par_iter_mut())
        .enumerate()
        .for_each(|(q, (col, src))| {
            let list = patches.by_vertex.row(q);
            if list.is_empty() {
                return;
            }
            let mut acc = [0.0f32; 3];
            let mut wsum = 0.0f32;
            let mut best = (f32::NEG_INFINITY, 0usize);
            for &e in list {
                let e = e as usize;
                let s = patches.entry_sample[e] as usize;
                let wgt = info.lambda[s] * omega[s];
                for k in 0..3 {
                    acc[k] += wgt * lookups[e][k];
                }
                wsum += wgt;
                if wgt > best.0 {
                    best = (wgt, e);
                }
            }
            if solver == Solver::Average && wsum > 0.0 && wsum.is_finite() {
                *col = acc.map(|a| a / wsum);
            } else {
                *col = lookups[best.1];
            }
            let e = best.1;
            let s = patches.entry_sample[e] as usize;
            let at = cands.centre(z[s]) + rot.apply(patches.offset[e]);
            *src = [at.x, at.y];
        });
}

/// Initial colours: every vertex takes the colour its nearest covering sample's (random) patch
/// gives it, so the first search sees sharp pieces of exemplar, not their blurred mean.
pub(super) fn paste_nearest(
    patches: &Patches,
    lookups: &[[f32; 3]],
    cands: &Candidates,
    z: &[u32],
    rot: Rot,
    colours: &mut [[f32; 3]],
    source: &mut [[f32; 2]],
) {
    colours
        .par_iter_mut()
        .zip(source.par_iter_mut())
        .enumerate()
        .for_each(|(q, (col, src))| {
            let list = patches.by_vertex.row(q);
            let nearest = list.iter().map(|&e| e as usize).min_by(|&a, &b| {
                let (oa, ob) = (patches.offset[a], patches.offset[b]);
                (oa[0] * oa[0] + oa[1] * oa[1]).total_cmp(&(ob[0] * ob[0] + ob[1] * ob[1]))
            });
            if let Some(e) = nearest {
                *col = lookups[e];
                let s = patches.entry_sample[e] as usize;
                let at = cands.centre(z[s]) + rot.apply(patches.offset[e]);
                *src = [at.x, at.y];
            }
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn curve_weight_is_one_over_distance_in_the_band_capped_and_flat_outside() {
        let (band, floor) = (7.5, 0.25);
        assert_eq!(curve_weight(2.0, band, floor), 0.5);
        assert_eq!(curve_weight(0.0, band, floor), 4.0);
        assert_eq!(curve_weight(0.1, band, floor), 4.0);
        // Continuous at the band's edge, constant beyond, NaN and ∞ are far.
        assert!((curve_weight(7.4999, band, floor) - 1.0 / 7.5).abs() < 1e-5);
        assert_eq!(curve_weight(7.5, band, floor), 1.0 / 7.5);
        assert_eq!(curve_weight(100.0, band, floor), 1.0 / 7.5);
        assert_eq!(curve_weight(f32::INFINITY, band, floor), 1.0 / 7.5);
        assert_eq!(curve_weight(f32::NAN, band, floor), 1.0 / 7.5);
        // The paper's literal law with the floor at ε₀.
        assert_eq!(curve_weight(0.0, band, 1e-6), 1e6);
    }
}
