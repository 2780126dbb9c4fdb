//! Geometry images (Lai et al. 2005 §3, Gu et al. 2002): cutting to a disk, the map to the
//! square and the samples, on real meshes closed (genus 0, 1, 3) and open.

use crate::common;
use common::geometry_image::{holed_knot, load_mesh as load};
use glam::{DVec2, DVec3, Vec3};
use texsyn::geom::Mesh;
use texsyn::geom::half_edge::{HalfEdgeMesh, TopologyError};
use texsyn::geom::mesh_check::{MeshHealth, mesh_health};
use texsyn::geom::primitives;
use texsyn::stages::parameterize::geometry_image::{
    GeometryImageBuild, GeometryImageError, GeometryImageParams, STRETCH_CUT_AREA_BOUND,
    build_geometry_image,
};
use texsyn::stages::reconstruct::displacement::grid_mesh;

/// The corpus: (path, genus, closed). The last entry is derived from the knot (see
/// `holed_knot` in tests/common/geometry_image.rs).
const CORPUS: [(&str, u32, bool); 5] = [
    ("configs/assets/cow.obj", 0, true),
    ("tests/data/meshes/knot.off", 1, true),
    ("tests/data/meshes/elephant.off", 3, true),
    ("tests/data/meshes/mushroom.off", 0, false),
    ("knot with two holes", 1, false),
];

fn params65() -> GeometryImageParams {
    GeometryImageParams {
        size: 65,
        ..Default::default()
    }
}

fn build(mesh: &Mesh, p: &GeometryImageParams) -> GeometryImageBuild {
    build_geometry_image(mesh, p, &|_| {}).unwrap()
}

/// All corpus builds at size 65, computed once.
fn corpus() -> &'static Vec<(String, Mesh, GeometryImageBuild)> {
    static C: std::sync::OnceLock<Vec<(String, Mesh, GeometryImageBuild)>> =
        std::sync::OnceLock::new();
    C.get_or_init(|| {
        CORPUS
            .iter()
            .map(|(path, _, _)| {
                let m = if path.ends_with("two holes") {
                    holed_knot()
                } else {
                    load(path)
                };
                let b = build(&m, &params65());
                (path.to_string(), m, b)
            })
            .collect()
    })
}

#[test]
fn cut_meshes_are_disks_and_the_inputs_have_their_known_genus() {
    for ((path, genus, closed), (_, mesh, b)) in CORPUS.iter().zip(corpus()) {
        let he = HalfEdgeMesh::new(mesh).unwrap();
        assert_eq!(he.components().len(), 1, "{path}");
        assert_eq!(he.components()[0].genus, *genus as i64, "{path}");
        assert_eq!(he.boundary_loops().is_empty(), *closed, "{path}");
        if path.ends_with("two holes") {
            assert_eq!(he.boundary_loops().len(), 2);
            assert_eq!(b.boundary_loops, 2);
        }
        assert_eq!(b.genus, *genus, "{path}");
        let dhe = HalfEdgeMesh::new(&b.disk).unwrap();
        assert_eq!(dhe.components().len(), 1, "{path}");
        assert_eq!(dhe.euler_characteristic(), 1, "{path}");
        assert_eq!(dhe.boundary_loops().len(), 1, "{path}");
        // Every input triangle is still there, as a copy or split into pieces.
        assert!(b.disk.face_count() >= mesh.face_count(), "{path}");
        // A closed mesh must be cut; an open one is cut only if it is not already a disk.
        if *closed {
            assert!(!b.cut_edges.is_empty(), "{path}");
        }
        for &[a, c] in &b.cut_edges {
            assert!(
                mesh.adjacency().half_edge(a as usize, c).is_some(),
                "{path}"
            );
        }
    }
}

fn signed_area(uv: &[glam::Vec2], t: [u32; 3]) -> f64 {
    let p = t.map(|v| uv[v as usize].as_dvec2());
    0.5 * (p[1] - p[0]).perp_dot(p[2] - p[0])
}

#[test]
fn the_map_fills_the_square_without_flips() {
    for (path, _, b) in corpus() {
        let n1 = (b.image.n - 1) as f32;
        let mut total = 0.0;
        for (f, &t) in b.disk.triangles.iter().enumerate() {
            let a = signed_area(&b.disk_uv, t);
            assert!(a > 0.0, "{path}: triangle {f} has area {a}");
            total += a;
        }
        // Positive triangles inside the square that add up to its area tile it (a
        // bijection onto the square).
        assert!(
            ((total - (n1 * n1) as f64) / (n1 * n1) as f64).abs() < 1e-4,
            "{path}: {total}"
        );
        for (v, q) in b.disk_uv.iter().enumerate() {
            assert!(
                q.x >= 0.0 && q.y >= 0.0 && q.x <= n1 && q.y <= n1,
                "{path}: vertex {v} at {q}"
            );
        }
        // Disk boundary vertices lie on the square's border, interior ones strictly inside.
        let dhe = HalfEdgeMesh::new(&b.disk).unwrap();
        for v in 0..b.disk.vertex_count() as u32 {
            let q = b.disk_uv[v as usize];
            let on_border = q.x == 0.0 || q.y == 0.0 || q.x == n1 || q.y == n1;
            assert_eq!(
                on_border,
                dhe.is_boundary_vertex(v),
                "{path}: vertex {v} at {q}"
            );
        }
    }
}

#[test]
fn cut_nodes_land_on_the_coarse_grid_of_the_perimeter() {
    for (path, _, b) in corpus() {
        let spacing = 1 << (params65().coarse_levels - 1);
        for (v, &o) in b.original_vertex.iter().enumerate() {
            if o != u32::MAX && b.cut_nodes.binary_search(&o).is_ok() {
                let q = b.disk_uv[v];
                for c in [q.x, q.y] {
                    assert_eq!(c.fract(), 0.0, "{path}: node {o} at {q}");
                    assert_eq!(c as u32 % spacing, 0, "{path}: node {o} at {q}");
                }
            }
        }
    }
}

#[test]
fn mated_samples_are_bit_identical_and_closed_borders_are_mated_except_cut_tips() {
    for ((_, _, closed), (path, _, b)) in CORPUS.iter().zip(corpus()) {
        let gi = &b.image;
        let n = gi.n;
        let groups = gi.mate_groups();
        assert!(!groups.is_empty() || !closed, "{path}");
        for g in &groups {
            let r = g[0] as usize;
            for &k in g {
                let k = k as usize;
                assert_eq!(gi.mate_rep[k] as usize, r);
                assert_eq!(
                    gi.positions[k].to_array().map(f32::to_bits),
                    gi.positions[r].to_array().map(f32::to_bits)
                );
                assert_eq!(
                    gi.normals[k].to_array().map(f32::to_bits),
                    gi.normals[r].to_array().map(f32::to_bits)
                );
                let (i, j) = (k as u32 / n, k as u32 % n);
                assert!(gi.is_boundary(i, j), "{path}: interior sample {k} is mated");
            }
        }
        let mut in_group = vec![false; (n * n) as usize];
        for g in &groups {
            for &k in g {
                in_group[k as usize] = true;
            }
        }
        // Unmated border samples. On a closed mesh the only ones allowed are the tips of
        // cut paths (cut-graph vertices of degree 1): a single wedge, the same point as no
        // other sample.
        let mut cut_degree = std::collections::HashMap::new();
        for &[a, c] in &b.cut_edges {
            *cut_degree.entry(a).or_insert(0) += 1;
            *cut_degree.entry(c).or_insert(0) += 1;
        }
        let mut unmated = 0;
        for i in 0..n {
            for j in 0..n {
                if gi.is_boundary(i, j) && !in_group[gi.index(i, j)] {
                    unmated += 1;
                    if *closed {
                        let at = glam::Vec2::new(j as f32, i as f32);
                        let v = b.disk_uv.iter().position(|&q| q == at);
                        let o = v.map(|v| b.original_vertex[v]);
                        assert!(
                            o.is_some_and(|o| cut_degree.get(&o) == Some(&1)),
                            "{path}: unmated border sample ({i}, {j}) is not a cut tip"
                        );
                    }
                }
            }
        }
        if !*closed {
            assert!(unmated > 0, "{path}: the mesh's own boundary has no mates");
        }
    }
}

/// Distance from p to triangle abc.
fn point_triangle_distance(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> f64 {
    let n = (b - a).cross(c - a);
    let nn = n.length_squared();
    if nn > 0.0 {
        let d = (p - a).dot(n) / nn;
        let q = p - n * d;
        let inside = [(a, b), (b, c), (c, a)]
            .iter()
            .all(|&(u, v)| (v - u).cross(q - u).dot(n) >= 0.0);
        if inside {
            return (p - q).length();
        }
    }
    [(a, b), (b, c), (c, a)]
        .iter()
        .map(|&(u, v)| {
            let e = v - u;
            let t = if e.length_squared() > 0.0 {
                ((p - u).dot(e) / e.length_squared()).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (p - (u + e * t)).length()
        })
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn samples_lie_on_the_input_surface() {
    for (path, mesh, b) in corpus() {
        let (lo, hi) = mesh.bounds();
        let tol = 1e-4 * (hi - lo).length() as f64;
        let tris: Vec<[DVec3; 3]> = mesh
            .triangles
            .iter()
            .map(|t| t.map(|v| mesh.positions[v as usize].as_dvec3()))
            .collect();
        for (k, p) in b.image.positions.iter().enumerate() {
            let p = p.as_dvec3();
            let d = tris
                .iter()
                .map(|t| point_triangle_distance(p, t[0], t[1], t[2]))
                .fold(f64::INFINITY, f64::min);
            assert!(
                d < tol,
                "{path}: sample {k} is {d} off the surface (tolerance {tol})"
            );
            assert!(
                (b.image.normals[k].length() - 1.0).abs() < 1e-3,
                "{path}: sample {k}"
            );
        }
    }
}

#[test]
fn border_samples_agree_with_the_disk_parameterization() {
    // The border samples come from arc length along the cut's 3D polylines; the disk's
    // boundary edges in the plane must carry the same points.
    for (path, mesh, b) in corpus() {
        let (lo, hi) = mesh.bounds();
        let tol = 1e-5 * (hi - lo).length();
        let n = b.image.n;
        let dhe = HalfEdgeMesh::new(&b.disk).unwrap();
        let lp = &dhe.boundary_loops()[0];
        let mut worst = 0.0f32;
        for i in 0..n {
            for j in 0..n {
                if !b.image.is_boundary(i, j) {
                    continue;
                }
                let x = DVec2::new(j as f64, i as f64);
                // The boundary edge of the disk through x.
                let mut found = None;
                for &h in lp {
                    let (a, c) = (dhe.origin(h), dhe.dest(h));
                    let (qa, qc) = (
                        b.disk_uv[a as usize].as_dvec2(),
                        b.disk_uv[c as usize].as_dvec2(),
                    );
                    let e = qc - qa;
                    let t = (x - qa).dot(e) / e.length_squared();
                    if (0.0..=1.0).contains(&t) && (qa + e * t - x).length() < 1e-3 {
                        let pa = b.disk.positions[a as usize].as_dvec3();
                        let pc = b.disk.positions[c as usize].as_dvec3();
                        found = Some(pa.lerp(pc, t));
                        break;
                    }
                }
                let p =
                    found.unwrap_or_else(|| panic!("{path}: no boundary edge through ({i}, {j})"));
                let d = (p.as_vec3() - b.image.positions[b.image.index(i, j)]).length();
                worst = worst.max(d);
            }
        }
        assert!(worst < tol, "{path}: {worst} (tolerance {tol})");
    }
}

#[test]
fn the_grid_has_no_spikes() {
    // Neighbouring samples are neighbours on the surface: at the paper's size 257 no
    // 4-neighbour pair is farther apart than a small fraction of the model (a spike or a
    // sample interpolated in the wrong triangle would be), and the largest gap is within a
    // small multiple of the median.
    for (path, mesh, _) in corpus() {
        let b = build(mesh, &GeometryImageParams::default());
        let gi = &b.image;
        let n = gi.n as usize;
        let (lo, hi) = mesh.bounds();
        let diag = (hi - lo).length();
        let mut d = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let p = gi.positions[i * n + j];
                if j + 1 < n {
                    d.push((p - gi.positions[i * n + j + 1]).length());
                }
                if i + 1 < n {
                    d.push((p - gi.positions[(i + 1) * n + j]).length());
                }
            }
        }
        d.sort_by(|a, b| a.total_cmp(b));
        let (median, max) = (d[d.len() / 2], d[d.len() - 1]);
        assert!(max < 0.1 * diag, "{path}: gap {max} vs diagonal {diag}");
        assert!(max < 30.0 * median, "{path}: gap {max} vs median {median}");
    }
}

#[test]
fn the_knot_cut_is_short() {
    let (_, mesh, b) = &corpus()[1];
    let total: f64 = {
        let adj = mesh.adjacency();
        (0..mesh.vertex_count())
            .flat_map(|v| adj.neighbors(v).iter().map(move |&w| (v, w as usize)))
            .filter(|&(v, w)| v < w)
            .map(|(v, w)| (mesh.positions[v] - mesh.positions[w]).length() as f64)
            .sum()
    };
    assert!(
        (b.cut_length as f64) < total / 10.0,
        "{} vs {}",
        b.cut_length,
        total
    );
    // Recompute the cut length from the reported edges.
    let l: f64 = b
        .cut_edges
        .iter()
        .map(|&[a, c]| (mesh.positions[a as usize] - mesh.positions[c as usize]).length() as f64)
        .sum();
    assert!((l - b.cut_length as f64).abs() < 1e-3 * l);
}

#[test]
fn a_non_manifold_edge_is_an_error_naming_it() {
    let mut m = load("tests/data/meshes/knot.off");
    let [a, c, _] = m.triangles[0];
    m.positions.push(Vec3::splat(100.0));
    let extra = m.positions.len() as u32 - 1;
    m.triangles.push([a, c, extra]);
    let m = Mesh::new(m.positions.clone(), m.triangles.clone());
    let err = build_geometry_image(&m, &params65(), &|_| {}).unwrap_err();
    match &err {
        GeometryImageError::Topology(TopologyError::NonManifoldEdge { a: x, b: y, faces }) => {
            assert_eq!((*x, *y), (a.min(c), a.max(c)));
            assert_eq!(faces.len(), 3);
        }
        other => panic!("{other:?}"),
    }
    let msg = err.to_string();
    assert!(
        msg.contains(&format!("vertices {} and {}", a.min(c), a.max(c))),
        "{msg}"
    );
}

#[test]
fn vertices_in_no_triangle_are_ignored() {
    // An unused vertex first and one last, far away: the result is the knot's, renumbered.
    let k = load("tests/data/meshes/knot.off");
    let mut p = vec![Vec3::splat(1e6)];
    p.extend_from_slice(&k.positions);
    p.push(Vec3::splat(-1e6));
    let t = k.triangles.iter().map(|x| x.map(|v| v + 1)).collect();
    let b = build(&Mesh::new(p, t), &params65());
    let plain = &corpus()[1].2;
    assert!(b.image.positions == plain.image.positions);
    assert!(
        b.original_vertex
            .iter()
            .all(|&v| v != 0 && v != k.vertex_count() as u32 + 1)
    );
}

#[test]
fn several_components_are_an_error_naming_the_count() {
    let k = load("tests/data/meshes/knot.off");
    let mut p = k.positions.clone();
    let mut t = k.triangles.clone();
    let off = p.len() as u32;
    p.extend(k.positions.iter().map(|x| *x + Vec3::splat(1000.0)));
    t.extend(k.triangles.iter().map(|x| x.map(|v| v + off)));
    let err = build_geometry_image(&Mesh::new(p, t), &params65(), &|_| {}).unwrap_err();
    assert!(err.to_string().contains("2 connected components"), "{err}");
}

#[test]
fn a_too_small_size_names_one_that_works() {
    let m = load("tests/data/meshes/elephant.off");
    let p = GeometryImageParams {
        size: 9,
        extremity_cuts: 6,
        ..Default::default()
    };
    let err = build_geometry_image(&m, &p, &|_| {}).unwrap_err();
    let GeometryImageError::PerimeterTooShort { suggested, .. } = err else {
        panic!("{err:?}");
    };
    assert!(
        err.to_string()
            .contains(&format!("size {suggested} would work"))
    );
    let ok = GeometryImageParams {
        size: suggested,
        ..p
    };
    build_geometry_image(&m, &ok, &|_| {}).unwrap();
    // And the next smaller size really is too small.
    let smaller = GeometryImageParams {
        size: (suggested - 1) / 2 + 1,
        ..ok
    };
    assert!(matches!(
        build_geometry_image(&m, &smaller, &|_| {}),
        Err(GeometryImageError::PerimeterTooShort { .. })
    ));
}

#[test]
fn extremity_cuts_lower_the_stretch_of_the_cow() {
    let (_, cow, plain) = &corpus()[0];
    let p = GeometryImageParams {
        extremity_cuts: 6,
        ..params65()
    };
    let b = build(cow, &p);
    assert!(b.cut_length > plain.cut_length);
    assert!(
        b.stretch < plain.stretch,
        "{} vs {}",
        b.stretch,
        plain.stretch
    );
    // Stretch reduction lowered the stretch of the mean value map.
    assert!(plain.stretch < plain.initial_stretch);
    assert_eq!(plain.flipped_triangles, 0);
}

#[test]
fn stretch_cuts_make_the_cow_map_less_anisotropic_within_the_area_bound() {
    let cow = &corpus()[0].1;
    let at = |stretch_cuts| {
        build(
            cow,
            &GeometryImageParams {
                size: 129,
                stretch_cuts,
                ..Default::default()
            },
        )
    };
    let (uncut, cut) = (at(0), at(8));
    assert!(uncut.stretch_cuts.is_empty());
    assert!(!cut.stretch_cuts.is_empty());
    // Every kept cut runs to its vertex: each is a vertex of the cut.
    for v in &cut.stretch_cuts {
        assert!(
            cut.cut_edges.iter().any(|e| e.contains(v)),
            "stretch cut to {v} is not in the cut"
        );
    }
    assert!(cut.cut_length > uncut.cut_length);
    eprintln!(
        "anisotropy {} -> {}, L² stretch {} -> {}, {} cuts kept",
        uncut.anisotropy,
        cut.anisotropy,
        uncut.stretch,
        cut.stretch,
        cut.stretch_cuts.len()
    );
    // The shape distortion falls by a good part (7.3 → 4.8 here, 4.2 at 257), the area distortion
    // stays within the bound, and nothing flips.
    assert!(
        cut.anisotropy < 0.8 * uncut.anisotropy,
        "{} vs {}",
        cut.anisotropy,
        uncut.anisotropy
    );
    assert!(cut.stretch <= STRETCH_CUT_AREA_BOUND * uncut.stretch);
    assert_eq!(cut.flipped_triangles, 0);
}

#[test]
fn the_image_is_byte_identical_for_one_and_two_threads() {
    let m = load("tests/data/meshes/elephant.off");
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                build(
                    &m,
                    &GeometryImageParams {
                        stretch_cuts: 4,
                        ..params65()
                    },
                )
            })
    };
    let (a, b) = (run(1), run(2));
    // The stretch-driven cuts run (and are kept) here, and choose alike.
    assert!(!a.stretch_cuts.is_empty());
    assert_eq!(a.stretch_cuts, b.stretch_cuts);
    let bytes = |x: &GeometryImageBuild| {
        let gi = &x.image;
        let mut v: Vec<u8> = bytemuck::cast_slice(&gi.positions).to_vec();
        v.extend_from_slice(bytemuck::cast_slice(&gi.normals));
        v.extend_from_slice(bytemuck::cast_slice(&gi.mate_rep));
        v.extend_from_slice(bytemuck::cast_slice(&x.disk_uv));
        v
    };
    assert!(bytes(&a) == bytes(&b));
}

/// The output mesh of a geometry image (its grid triangulated, mates merged, as the relief is
/// written): (mesh health, genus or `None` when not a manifold surface, output vertices,
/// mate groups).
fn grid_mesh_report(b: &GeometryImageBuild) -> (MeshHealth, Option<i64>, usize, usize) {
    let (m, samples) = grid_mesh(&b.image, &b.image.positions);
    let h = mesh_health(&m);
    let genus = HalfEdgeMesh::new(&m)
        .ok()
        .filter(|he| he.components().len() == 1)
        .map(|he| he.components()[0].genus);
    // Every output vertex is its own mate group's representative.
    for &s in &samples {
        assert_eq!(b.image.mate_rep[s as usize], s);
    }
    let groups = (0..b.image.mate_rep.len())
        .filter(|&k| b.image.mate_rep[k] as usize == k)
        .count();
    (h, genus, m.vertex_count(), groups)
}

#[test]
fn a_closed_input_gives_a_closed_manifold_of_its_genus_without_stray_vertices() {
    // Genus 0 (the cow, whose cut is a path: the square's border folds back at both of its
    // tips), 1 and 3, then the smallest closed meshes; every sample is used (no tip or
    // corner sample is left out).
    let mut cases: Vec<(String, Mesh, i64, GeometryImageBuild)> = CORPUS
        .iter()
        .zip(corpus())
        .filter(|((_, _, closed), _)| *closed)
        .map(|((path, genus, _), (_, m, b))| {
            (path.to_string(), m.clone(), *genus as i64, b.clone())
        })
        .collect();
    let small = [
        ("tetrahedron", primitives::tetrahedron(), 0),
        ("octahedron", primitives::octahedron(), 0),
        ("icosphere", primitives::icosphere(2), 0),
        ("seven-vertex torus", primitives::seven_vertex_torus(), 1),
    ];
    for (name, m, genus) in small {
        for size in [9, 17, 65] {
            let p = GeometryImageParams {
                size,
                coarse_levels: 2,
                ..Default::default()
            };
            let b = build_geometry_image(&m, &p, &|_| {})
                .unwrap_or_else(|e| panic!("{name} at size {size}: {e}"));
            cases.push((format!("{name} at size {size}"), m.clone(), genus, b));
        }
    }
    // Tips anywhere on the border: the cow with extremity cuts.
    let cow = &corpus()[0].1;
    let p = GeometryImageParams {
        extremity_cuts: 3,
        ..params65()
    };
    cases.push((
        "cow with 3 extremity cuts".into(),
        cow.clone(),
        0,
        build(cow, &p),
    ));
    for (name, _, genus, b) in &cases {
        let (h, g, vertices, groups) = grid_mesh_report(b);
        assert!(
            h.is_closed_manifold(),
            "{name}: the output has {}",
            h.summary()
        );
        assert_eq!(g, Some(*genus), "{name}: genus");
        assert_eq!(vertices, groups, "{name}: samples left out");
    }
}

#[test]
fn an_open_input_gives_a_manifold_open_only_along_its_own_boundary() {
    for ((path, genus, closed), (_, mesh, b)) in CORPUS.iter().zip(corpus()) {
        if *closed {
            continue;
        }
        let (h, g, vertices, groups) = grid_mesh_report(b);
        assert!(h.is_clean(), "{path}: {}", h.summary());
        assert!(h.boundary_edges > 0, "{path}");
        assert_eq!(g, Some(*genus as i64), "{path}: genus");
        assert_eq!(vertices, groups, "{path}: samples left out");
        let (m, _) = grid_mesh(&b.image, &b.image.positions);
        let loops = HalfEdgeMesh::new(&m).unwrap().boundary_loops().len();
        let input_loops = HalfEdgeMesh::new(mesh).unwrap().boundary_loops().len();
        assert_eq!(loops, input_loops, "{path}: boundary loops");
    }
}

#[test]
fn a_mesh_without_area_is_an_error_saying_so() {
    let mut m = primitives::tetrahedron();
    for p in &mut m.positions {
        *p = Vec3::splat(0.5);
    }
    let err = build_geometry_image(&m, &params65(), &|_| {}).unwrap_err();
    assert!(
        matches!(err, GeometryImageError::NoArea { triangles: 4 }),
        "{err:?}"
    );
    assert!(err.to_string().contains("no area"), "{err}");
    // On one line: no area either.
    for (k, p) in m.positions.iter_mut().enumerate() {
        *p = Vec3::new(k as f32, 0.0, 0.0);
    }
    let err = build_geometry_image(&m, &params65(), &|_| {}).unwrap_err();
    assert!(matches!(err, GeometryImageError::NoArea { .. }), "{err:?}");
}
