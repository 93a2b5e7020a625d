//! Built-in scenes (`lodtrace scenes`) and the procedural geometry they are made of.
//!
//! - `spheres`: Wand & Straßer Fig. 6, a reflective and a refractive sphere on a checkerboard
//!   made of geometry (about 7,400 triangles).
//! - `plane`, `cube`, `ico`: small test scenes (known-answer shading, watertightness).

use super::{Camera, Light, Material, Mesh, Scene, Target};
use crate::error::{Error, Result};
use glam::{Affine3A, Vec3};

pub struct BuiltinInfo {
    pub name: &'static str,
    pub about: &'static str,
}

pub const BUILTINS: &[BuiltinInfo] = &[
    BuiltinInfo { name: "spheres", about: "Wand & Strasser Fig. 6: reflective and refractive sphere on a geometric checkerboard (~7,400 triangles)" },
    BuiltinInfo { name: "plane", about: "test: a diffuse square lit by one point light (known-answer shading)" },
    BuiltinInfo { name: "cube", about: "test: a closed cube seen at an angle (watertightness)" },
    BuiltinInfo { name: "ico", about: "test: a subdivided icosphere (closed, 5,120 triangles)" },
];

pub fn get(name: &str) -> Result<Scene> {
    match name {
        "spheres" => Ok(spheres()),
        "plane" => Ok(plane()),
        "cube" => Ok(single("cube", cube_mesh(0))),
        "ico" => Ok(single("ico", icosphere(4, 0))),
        _ => Err(Error::UnknownScene(name.to_string())),
    }
}

// ---------------------------------------------------------------- geometry generators

/// UV sphere of radius 1 at the origin: `stacks` × `slices`, smooth normals, closed (poles
/// share one vertex).
pub fn uv_sphere(stacks: u32, slices: u32, mat: u32) -> Mesh {
    let mut m = Mesh::new("sphere");
    let top = m.push_vertex(Vec3::Y);
    for i in 1..stacks {
        let th = std::f32::consts::PI * i as f32 / stacks as f32;
        for j in 0..slices {
            let ph = std::f32::consts::TAU * j as f32 / slices as f32;
            m.push_vertex(Vec3::new(th.sin() * ph.cos(), th.cos(), -th.sin() * ph.sin()));
        }
    }
    let bot = m.push_vertex(-Vec3::Y);
    let ring = |i: u32, j: u32| 1 + (i - 1) * slices + (j % slices);
    for j in 0..slices {
        m.push_tri(top, ring(1, j), ring(1, j + 1), mat);
        m.push_tri(bot, ring(stacks - 1, j + 1), ring(stacks - 1, j), mat);
    }
    for i in 1..stacks - 1 {
        for j in 0..slices {
            let (a, b, c, d) = (ring(i, j), ring(i, j + 1), ring(i + 1, j), ring(i + 1, j + 1));
            m.push_tri(a, c, d, mat);
            m.push_tri(a, d, b, mat);
        }
    }
    let (nx, ny, nz) = (m.px.clone(), m.py.clone(), m.pz.clone());
    m.nx = nx;
    m.ny = ny;
    m.nz = nz;
    m
}

/// Icosphere of radius 1 (closed, `20·4^level` triangles), smooth normals.
pub fn icosphere(level: u32, mat: u32) -> Mesh {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut v: Vec<Vec3> = [
        (-1., t, 0.), (1., t, 0.), (-1., -t, 0.), (1., -t, 0.), (0., -1., t), (0., 1., t),
        (0., -1., -t), (0., 1., -t), (t, 0., -1.), (t, 0., 1.), (-t, 0., -1.), (-t, 0., 1.),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
        [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1],
    ];
    for _ in 0..level {
        let mut mid = std::collections::HashMap::new();
        let mut get = |a: u32, b: u32, v: &mut Vec<Vec3>| -> u32 {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                v.push(((v[a as usize] + v[b as usize]) * 0.5).normalize());
                (v.len() - 1) as u32
            })
        };
        let mut nf = Vec::with_capacity(f.len() * 4);
        for [a, b, c] in f {
            let ab = get(a, b, &mut v);
            let bc = get(b, c, &mut v);
            let ca = get(c, a, &mut v);
            nf.extend_from_slice(&[[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        f = nf;
    }
    let mut m = Mesh::new("icosphere");
    for p in &v {
        m.push_vertex(*p);
        m.nx.push(p.x);
        m.ny.push(p.y);
        m.nz.push(p.z);
    }
    for [a, b, c] in f {
        m.push_tri(a, b, c, mat);
    }
    m
}

/// Axis-aligned unit cube [-1,1]³, closed, flat normals (24 vertices, 12 triangles).
pub fn cube_mesh(mat: u32) -> Mesh {
    let mut m = Mesh::new("cube");
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let mut n = Vec3::ZERO;
            n[axis] = sign;
            let (u, v) = crate::core::onb(n);
            let base = m.vertex_count() as u32;
            for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                let p = n + u * a + v * b;
                // Snap to exact ±1 so faces share vertex positions exactly (watertight).
                m.push_vertex(p.round());
                m.nx.push(n.x);
                m.ny.push(n.y);
                m.nz.push(n.z);
            }
            // Orient counter-clockwise seen from outside.
            let p0 = m.pos(base);
            let p1 = m.pos(base + 1);
            let p2 = m.pos(base + 2);
            if (p1 - p0).cross(p2 - p0).dot(n) > 0.0 {
                m.push_tri(base, base + 1, base + 2, mat);
                m.push_tri(base, base + 2, base + 3, mat);
            } else {
                m.push_tri(base, base + 2, base + 1, mat);
                m.push_tri(base, base + 3, base + 2, mat);
            }
        }
    }
    m
}

/// A unit square [0,1]² in the xz-plane (y = 0), normal +y, two triangles.
pub fn unit_quad(mat: u32) -> Mesh {
    let mut m = Mesh::new("quad");
    for (x, z) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
        m.push_vertex(Vec3::new(x, 0.0, z));
        m.nx.push(0.0);
        m.ny.push(1.0);
        m.nz.push(0.0);
    }
    m.push_tri(0, 2, 1, mat);
    m.push_tri(0, 3, 2, mat);
    m
}

/// An n×n checkerboard of real geometry centred at the origin in the xz-plane, side `size`,
/// cells alternating `mat_a` / `mat_b`; each cell is its own two triangles.
pub fn checkerboard(n: u32, size: f32, mat_a: u32, mat_b: u32) -> Mesh {
    let mut m = Mesh::new("checkerboard");
    let cell = size / n as f32;
    let h = size * 0.5;
    for i in 0..=n {
        for j in 0..=n {
            m.push_vertex(Vec3::new(-h + i as f32 * cell, 0.0, -h + j as f32 * cell));
            m.nx.push(0.0);
            m.ny.push(1.0);
            m.nz.push(0.0);
        }
    }
    let id = |i: u32, j: u32| i * (n + 1) + j;
    for i in 0..n {
        for j in 0..n {
            let mat = if (i + j) % 2 == 0 { mat_a } else { mat_b };
            m.push_tri(id(i, j), id(i, j + 1), id(i + 1, j + 1), mat);
            m.push_tri(id(i, j), id(i + 1, j + 1), id(i + 1, j), mat);
        }
    }
    m
}

// ---------------------------------------------------------------- scenes

fn single(name: &str, mesh: Mesh) -> Scene {
    let mut s = Scene::empty(name);
    let id = s.add_mesh(mesh);
    s.instance(Target::Mesh(id), Affine3A::from_rotation_y(0.5) * Affine3A::from_rotation_x(0.3), None);
    s.camera = Camera { eye: Vec3::new(0.0, 0.5, 4.0), look: Vec3::ZERO, up: Vec3::Y, fovy: 45.0, aperture: 0.0, focal_dist: 4.0 };
    s.lights.push(Light::Point { pos: Vec3::new(3.0, 4.0, 5.0), intensity: Vec3::splat(40.0) });
    s
}

/// Known-answer scene: a white diffuse square [-1,1]² (y = 0) under a point light at height
/// 2 above the centre, intensity 10, no ambient; camera straight down from y = 3.
/// Radiance at the centre: (albedo/π)·I·cosθ/d² = (0.5/π)·10/4.
pub fn plane() -> Scene {
    let mut s = Scene::empty("plane");
    s.materials[0] = Material::diffuse("white", Vec3::splat(0.5));
    let id = s.add_mesh(unit_quad(0));
    s.instance(Target::Mesh(id), Affine3A::from_scale_rotation_translation(Vec3::new(2.0, 1.0, 2.0), glam::Quat::IDENTITY, Vec3::new(-1.0, 0.0, -1.0)), None);
    s.camera = Camera { eye: Vec3::new(0.0, 3.0, 0.0), look: Vec3::ZERO, up: Vec3::new(0.0, 0.0, -1.0), fovy: 30.0, aperture: 0.0, focal_dist: 3.0 };
    s.lights.push(Light::Point { pos: Vec3::new(0.0, 2.0, 0.0), intensity: Vec3::splat(10.0) });
    s.ambient = Vec3::ZERO;
    s.background = Vec3::ZERO;
    s
}

/// Wand & Straßer Fig. 6 (after Amanatides' cone-tracing scene): a red mirror-like sphere and
/// a glass sphere on a 16×16 checkerboard of real geometry.
pub fn spheres() -> Scene {
    let mut s = Scene::empty("spheres");
    s.materials[0] = Material::diffuse("white", Vec3::splat(0.8));
    let black = s.add_material(Material::diffuse("black", Vec3::splat(0.05)));
    let red = s.add_material(Material {
        name: "red mirror".into(),
        color: Vec3::new(0.7, 0.05, 0.05),
        kd: 0.6,
        ks: 0.6,
        shininess: 60.0,
        reflect: 0.45,
        ..Default::default()
    });
    let glass = s.add_material(Material {
        name: "glass".into(),
        color: Vec3::splat(1.0),
        kd: 0.05,
        ks: 0.8,
        shininess: 120.0,
        reflect: 0.08,
        transmit: 0.88,
        ior: 1.5,
        ..Default::default()
    });
    let board = s.add_mesh(checkerboard(16, 16.0, 0, black));
    s.instance(Target::Mesh(board), Affine3A::IDENTITY, None);
    let sphere = s.add_mesh(uv_sphere(43, 41, 0));
    s.instance(Target::Mesh(sphere), Affine3A::from_scale_rotation_translation(Vec3::splat(1.3), glam::Quat::IDENTITY, Vec3::new(-1.6, 1.3, -1.0)), Some(red));
    s.instance(Target::Mesh(sphere), Affine3A::from_scale_rotation_translation(Vec3::splat(1.1), glam::Quat::IDENTITY, Vec3::new(1.4, 1.1, 1.2)), Some(glass));
    s.camera = Camera { eye: Vec3::new(0.5, 3.2, 8.5), look: Vec3::new(0.0, 0.8, 0.0), up: Vec3::Y, fovy: 45.0, aperture: 0.0, focal_dist: 8.5 };
    s.lights.push(Light::Ellipse { center: Vec3::new(-4.0, 8.0, 5.0), axis_a: Vec3::new(0.8, 0.0, 0.0), axis_b: Vec3::new(0.0, 0.0, 0.8), intensity: Vec3::splat(90.0) });
    s.background = Vec3::new(0.45, 0.55, 0.75);
    s.ambient = Vec3::splat(0.08);
    s
}
