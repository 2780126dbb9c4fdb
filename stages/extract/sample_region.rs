//! The sample patch (Lai et al., "Geometric Texture Synthesis and Transfer via Geometry
//! Images", §3: "in practice, it is most likely that we will wish to use a small portion or
//! patch of the model's surface containing the desired geometric texture").
//!
//! The paper cuts patches by hand; here a sphere or a box names the region, the patch is the
//! triangles with all three corners inside it, and only its largest edge-connected piece (by
//! area) is kept, so that the sample is one patch that can be cut to a disk or projected onto
//! one plane.

use super::ExtractError;
use crate::check::ParamError;
use crate::geom::Mesh;
use glam::Vec3;
use serde::{Deserialize, Serialize};

/// A region of space selecting part of a sample model, in the model's coordinates.
///
/// ```toml
/// region = { shape = "sphere", center = [0.1, 0.4, 0.0], radius = 0.05 }
/// region = { shape = "box", min = [0, 0, 0], max = [1, 0.5, 1] }
/// ```
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "shape", rename_all = "snake_case", deny_unknown_fields)]
pub enum Region {
    /// Points at distance ≤ `radius` (> 0) from `center`.
    Sphere { center: [f32; 3], radius: f32 },
    /// Points with `min ≤ p ≤ max` in every coordinate (`min ≤ max`).
    Box { min: [f32; 3], max: [f32; 3] },
}

impl Region {
    /// Checks the shape; the error names the field and what was wrong.
    pub fn validate(&self) -> Result<(), ParamError> {
        let finite = |name: &str, v: [f32; 3]| {
            if v.iter().all(|c| c.is_finite()) {
                Ok(())
            } else {
                Err(ParamError::invalid(
                    name,
                    format!("must be 3 finite numbers, got {v:?}"),
                ))
            }
        };
        match self {
            Region::Sphere { center, radius } => {
                finite("center", *center)?;
                super::check_positive("radius", *radius)
            }
            Region::Box { min, max } => {
                finite("min", *min)?;
                finite("max", *max)?;
                for k in 0..3 {
                    if min[k] > max[k] {
                        return Err(ParamError::invalid(
                            "min",
                            format!(
                                "must not exceed max in any coordinate, got min {min:?}, max {max:?}"
                            ),
                        ));
                    }
                }
                Ok(())
            }
        }
    }

    /// Whether `p` lies inside (boundary included).
    pub fn contains(&self, p: Vec3) -> bool {
        match self {
            Region::Sphere { center, radius } => {
                (p - Vec3::from_array(*center)).length_squared() <= radius * radius
            }
            Region::Box { min, max } => {
                p.cmpge(Vec3::from_array(*min)).all() && p.cmple(Vec3::from_array(*max)).all()
            }
        }
    }
}

impl std::fmt::Display for Region {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Region::Sphere { center, radius } => write!(
                f,
                "sphere at ({}, {}, {}) of radius {radius}",
                center[0], center[1], center[2]
            ),
            Region::Box { min, max } => write!(
                f,
                "box from ({}, {}, {}) to ({}, {}, {})",
                min[0], min[1], min[2], max[0], max[1], max[2]
            ),
        }
    }
}

/// The sample patch: the triangles of `mesh` whose three vertices lie inside `region` (all
/// triangles when `region` is `None`), reduced to their largest edge-connected piece by area
/// (ties: the piece holding the lowest-numbered triangle), with the vertices renumbered
/// compactly in their original order and colours kept. Triangles that repeat a vertex are
/// dropped.
pub fn select_region(mesh: &Mesh, region: Option<&Region>) -> Result<Mesh, ExtractError> {
    if let Some(r) = region {
        r.validate().map_err(|e| e.within("region"))?;
    }
    if mesh.triangles.is_empty() {
        return Err(ExtractError::EmptyMesh);
    }
    super::check_finite(mesh)?;
    let inside: Vec<bool> = match region {
        Some(r) => mesh.positions.iter().map(|&p| r.contains(p)).collect(),
        None => vec![true; mesh.positions.len()],
    };
    let kept: Vec<u32> = (0..mesh.triangles.len() as u32)
        .filter(|&f| {
            let t = mesh.triangles[f as usize];
            t[0] != t[1] && t[1] != t[2] && t[0] != t[2] && t.iter().all(|&v| inside[v as usize])
        })
        .collect();
    if kept.is_empty() {
        let Some(r) = region else {
            return Err(ExtractError::EmptyMesh);
        };
        let (lo, hi) = mesh.bounds();
        return Err(ExtractError::EmptyRegion {
            region: r.to_string(),
            bounds: format!(
                "({}, {}, {}) to ({}, {}, {})",
                lo.x, lo.y, lo.z, hi.x, hi.y, hi.z
            ),
        });
    }

    // Edge-connected pieces: union the triangles that share an edge (found by sorting the
    // edges, so the result does not depend on hashing).
    let mut parent: Vec<u32> = (0..kept.len() as u32).collect();
    fn find(parent: &mut [u32], mut x: u32) -> u32 {
        while parent[x as usize] != x {
            let p = parent[x as usize];
            parent[x as usize] = parent[p as usize];
            x = p;
        }
        x
    }
    let mut edges: Vec<(u32, u32, u32)> = Vec::with_capacity(kept.len() * 3);
    for (k, &f) in kept.iter().enumerate() {
        let t = mesh.triangles[f as usize];
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            edges.push((a.min(b), a.max(b), k as u32));
        }
    }
    edges.sort_unstable();
    for w in edges.windows(2) {
        if w[0].0 == w[1].0 && w[0].1 == w[1].1 {
            let (a, b) = (find(&mut parent, w[0].2), find(&mut parent, w[1].2));
            if a != b {
                // The smaller root wins, so a root is its piece's lowest-numbered triangle.
                let (lo, hi) = (a.min(b), a.max(b));
                parent[hi as usize] = lo;
            }
        }
    }
    let mut area = vec![0.0f64; kept.len()];
    let roots: Vec<u32> = (0..kept.len() as u32)
        .map(|k| find(&mut parent, k))
        .collect();
    for (k, &f) in kept.iter().enumerate() {
        area[roots[k] as usize] += 0.5 * mesh.face_normal_unnormalized(f as usize).length() as f64;
    }
    let mut best = 0usize;
    for k in 0..kept.len() {
        if roots[k] as usize == k && area[k] > area[best] {
            best = k;
        }
    }

    let mut used = vec![false; mesh.positions.len()];
    for (k, &f) in kept.iter().enumerate() {
        if roots[k] as usize == best {
            for &v in &mesh.triangles[f as usize] {
                used[v as usize] = true;
            }
        }
    }
    let mut new_index = vec![u32::MAX; mesh.positions.len()];
    let mut positions = Vec::new();
    let mut colors = mesh.colors.as_ref().map(|_| Vec::new());
    for v in (0..mesh.positions.len()).filter(|&v| used[v]) {
        new_index[v] = positions.len() as u32;
        positions.push(mesh.positions[v]);
        if let (Some(out), Some(c)) = (colors.as_mut(), mesh.colors.as_ref()) {
            out.push(c.get(v).copied().unwrap_or([1.0; 4]));
        }
    }
    let triangles: Vec<[u32; 3]> = kept
        .iter()
        .enumerate()
        .filter(|&(k, _)| roots[k] as usize == best)
        .map(|(_, &f)| mesh.triangles[f as usize].map(|v| new_index[v as usize]))
        .collect();
    Ok(Mesh::with_colors(positions, triangles, colors))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regions_parse_from_toml_and_reject_unknown_keys() {
        #[derive(Deserialize)]
        struct W {
            region: Region,
        }
        let w: W =
            toml::from_str("region = { shape = \"sphere\", center = [1, 2, 3], radius = 0.5 }")
                .unwrap();
        assert_eq!(
            w.region,
            Region::Sphere {
                center: [1.0, 2.0, 3.0],
                radius: 0.5
            }
        );
        let w: W =
            toml::from_str("[region]\nshape = \"box\"\nmin = [0, 0, 0]\nmax = [1, 1, 1]").unwrap();
        assert!(matches!(w.region, Region::Box { .. }));
        assert!(
            toml::from_str::<W>(
                "region = { shape = \"sphere\", center = [1, 2, 3], radius = 0.5, r = 1 }"
            )
            .is_err()
        );
        assert!(toml::from_str::<W>("region = { shape = \"cone\" }").is_err());
    }

    #[test]
    fn validation_names_the_field() {
        let e = Region::Sphere {
            center: [0.0; 3],
            radius: -1.0,
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert_eq!(e, "radius must be a finite number > 0, got -1");
        let e = Region::Box {
            min: [0.0, 2.0, 0.0],
            max: [1.0, 1.0, 1.0],
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert!(e.starts_with("min must not exceed max"), "{e}");
        let e = Region::Sphere {
            center: [f32::NAN, 0.0, 0.0],
            radius: 1.0,
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert!(e.contains("center"), "{e}");
    }
}
