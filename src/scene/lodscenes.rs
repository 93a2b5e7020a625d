//! The built-in scenes of Papaioannou et al. (§5) and their geometry generators.
//!
//! - `chessboard` (Fig. 4): a wooden chessboard whose light squares are glass tiles with
//!   bumpy refractive tops, with glass and wooden pawns (lathe surfaces), on a finely carved
//!   base plate that shows through the glass. Finely tessellated throughout so intersection
//!   cost matters (1.66 M instanced triangles, 0.29 M unique).
//! - `cabinet` (Fig. 6): a wooden cabinet with a flat mirror on its back wall reflecting
//!   wine glasses and vases on its shelf.
//! - `reflector` (Fig. 5): detailed models (armadillo, bunny, cow from `tools/setup`) seen
//!   in curved reflectors (a chrome sphere, a chrome cylinder section, a polished torus-like
//!   lathe ring).
//!
//! The paper gives only the pictures; sizes, materials and layout are ours. Everything is
//! real geometry; pieces are instanced (one unique pawn, one unique tile, ...).

use super::builtin::cube_mesh;
use super::{Camera, Light, Material, Mesh, Scene, Target};
use crate::error::Result;
use glam::{Affine3A, Quat, Vec3};

/// A surface of revolution about +y: `profile` is (radius, height) from bottom to top,
/// revolved in `segments` steps. A zero radius at either end closes the surface with one
/// pole vertex. Smooth vertex normals.
pub fn lathe(name: &str, profile: &[(f32, f32)], segments: u32, mat: u32) -> Mesh {
    let mut m = Mesh::new(name);
    let seg = segments.max(3);
    // Ring index of each profile point (u32::MAX for a pole: one vertex).
    let mut rings: Vec<u32> = Vec::with_capacity(profile.len());
    for &(r, y) in profile {
        if r <= 0.0 {
            rings.push(m.push_vertex(Vec3::new(0.0, y, 0.0)) | 0x8000_0000);
        } else {
            let base = m.vertex_count() as u32;
            for s in 0..seg {
                let a = std::f32::consts::TAU * s as f32 / seg as f32;
                m.push_vertex(Vec3::new(r * a.cos(), y, -r * a.sin()));
            }
            rings.push(base);
        }
    }
    let v = |ring: u32, s: u32| if ring & 0x8000_0000 != 0 { ring & 0x7fff_ffff } else { ring + s % seg };
    for k in 0..profile.len().saturating_sub(1) {
        let (a, b) = (rings[k], rings[k + 1]);
        let (pa, pb) = (a & 0x8000_0000 != 0, b & 0x8000_0000 != 0);
        for s in 0..seg {
            // Counter-clockwise seen from outside for a profile going up.
            if !pa && !pb {
                m.push_tri(v(a, s), v(a, s + 1), v(b, s + 1), mat);
                m.push_tri(v(a, s), v(b, s + 1), v(b, s), mat);
            } else if pa && !pb {
                m.push_tri(v(a, 0), v(b, s + 1), v(b, s), mat);
            } else if !pa && pb {
                m.push_tri(v(a, s), v(a, s + 1), v(b, 0), mat);
            }
        }
    }
    m.compute_normals();
    m
}

/// Samples a piecewise-linear profile of key points at `n` points by arc length, rounding
/// corners with two passes of Chaikin smoothing first.
pub fn smooth_profile(keys: &[(f32, f32)], n: usize) -> Vec<(f32, f32)> {
    let mut p: Vec<(f32, f32)> = keys.to_vec();
    for _ in 0..2 {
        let mut q = vec![p[0]];
        for w in p.windows(2) {
            let (a, b) = (w[0], w[1]);
            q.push((0.75 * a.0 + 0.25 * b.0, 0.75 * a.1 + 0.25 * b.1));
            q.push((0.25 * a.0 + 0.75 * b.0, 0.25 * a.1 + 0.75 * b.1));
        }
        q.push(*p.last().expect("non-empty"));
        p = q;
    }
    let len: Vec<f32> = std::iter::once(0.0)
        .chain(p.windows(2).scan(0.0, |acc, w| {
            *acc += ((w[1].0 - w[0].0).powi(2) + (w[1].1 - w[0].1).powi(2)).sqrt();
            Some(*acc)
        }))
        .collect();
    let total = *len.last().expect("non-empty");
    let mut out = Vec::with_capacity(n);
    let mut k = 0;
    for i in 0..n {
        let s = total * i as f32 / (n - 1) as f32;
        while k + 2 < len.len() && len[k + 1] < s {
            k += 1;
        }
        let t = ((s - len[k]) / (len[k + 1] - len[k]).max(1e-9)).clamp(0.0, 1.0);
        let (a, b) = (p[k], p[k + 1]);
        let r = a.0 + (b.0 - a.0) * t;
        out.push((if i == 0 || i == n - 1 { r.max(0.0) } else { r.max(1e-3) }, a.1 + (b.1 - a.1) * t));
    }
    // Keep the poles exact.
    out[0] = (keys[0].0, keys[0].1);
    let l = keys[keys.len() - 1];
    out[n - 1] = (l.0, l.1);
    out
}

/// A chess pawn, height 1, base radius 0.42: `rings` profile samples × `segments`.
pub fn pawn(rings: usize, segments: u32, mat: u32) -> Mesh {
    let keys = [
        (0.0, 0.0),
        (0.42, 0.0),
        (0.42, 0.07),
        (0.36, 0.12),
        (0.33, 0.16),
        (0.26, 0.2),
        (0.2, 0.3),
        (0.15, 0.45),
        (0.13, 0.56),
        (0.22, 0.6),
        (0.22, 0.63),
        (0.12, 0.67),
        (0.15, 0.72),
        (0.19, 0.78),
        (0.2, 0.85),
        (0.18, 0.92),
        (0.11, 0.98),
        (0.0, 1.0),
    ];
    lathe("pawn", &smooth_profile(&keys, rings), segments, mat)
}

/// A closed wine glass (solid of revolution with a thin bowl wall), height 1.
pub fn wine_glass(rings: usize, segments: u32, mat: u32) -> Mesh {
    let keys = [
        (0.0, 0.0),
        (0.3, 0.0),
        (0.3, 0.02),
        (0.06, 0.04),
        (0.035, 0.1),
        (0.035, 0.38),
        (0.09, 0.45),
        (0.22, 0.55),
        (0.27, 0.7),
        (0.26, 0.88),
        (0.25, 1.0),
        (0.235, 1.0),
        (0.245, 0.88),
        (0.25, 0.7),
        (0.2, 0.56),
        (0.0, 0.48),
    ];
    lathe("wine glass", &smooth_profile(&keys, rings), segments, mat)
}

/// A vase, height 1.
pub fn vase(rings: usize, segments: u32, mat: u32) -> Mesh {
    let keys = [(0.0, 0.0), (0.2, 0.0), (0.3, 0.12), (0.34, 0.35), (0.25, 0.6), (0.13, 0.75), (0.12, 0.88), (0.17, 1.0), (0.0, 0.97)];
    lathe("vase", &smooth_profile(&keys, rings), segments, mat)
}

/// A unit-square glass tile, `thick` high, whose top is an n×n grid displaced by a sum of
/// bumps of amplitude `amp` (closed: bumpy top, flat sides and bottom with their own
/// vertices so the top's smooth normals stay its own).
pub fn bumpy_tile(n: u32, thick: f32, amp: f32, mat: u32) -> Mesh {
    let mut m = Mesh::new("bumpy tile");
    let bump = |x: f32, z: f32| {
        let tau = std::f32::consts::TAU;
        // Zero at the border so neighbouring tiles meet; ripples of several frequencies.
        let edge = (std::f32::consts::PI * x).sin() * (std::f32::consts::PI * z).sin();
        thick
            + amp
                * edge
                * (0.6 * (tau * 2.0 * x).sin() * (tau * 2.0 * z).cos() + 0.4 * (tau * 5.0 * x + 1.3).sin() * (tau * 3.0 * z + 0.7).sin())
    };
    let id = |i: u32, j: u32| i * (n + 1) + j;
    for i in 0..=n {
        for j in 0..=n {
            let (x, z) = (i as f32 / n as f32, j as f32 / n as f32);
            m.push_vertex(Vec3::new(x, bump(x, z), z));
        }
    }
    for i in 0..n {
        for j in 0..n {
            m.push_tri(id(i, j), id(i, j + 1), id(i + 1, j + 1), mat);
            m.push_tri(id(i, j), id(i + 1, j + 1), id(i + 1, j), mat);
        }
    }
    m.compute_normals();
    // Sides: the top border down to y = 0, then the bottom.
    let mut side = Mesh::new("sides");
    let border: Vec<Vec3> = (0..n)
        .map(|k| (k, 0))
        .chain((0..n).map(|k| (n, k)))
        .chain((0..n).map(|k| (n - k, n)))
        .chain((0..n).map(|k| (0, n - k)))
        .map(|(i, j)| {
            let (x, z) = (i as f32 / n as f32, j as f32 / n as f32);
            Vec3::new(x, bump(x, z), z)
        })
        .collect();
    let nb = border.len() as u32;
    for p in &border {
        side.push_vertex(*p);
        side.push_vertex(Vec3::new(p.x, 0.0, p.z));
    }
    for k in 0..nb {
        let (a, b) = (2 * k, 2 * ((k + 1) % nb));
        side.push_tri(a, b + 1, a + 1, mat);
        side.push_tri(a, b, b + 1, mat);
    }
    let c = side.vertex_count() as u32;
    for (x, z) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
        side.push_vertex(Vec3::new(x, 0.0, z));
    }
    side.push_tri(c, c + 1, c + 2, mat);
    side.push_tri(c, c + 2, c + 3, mat);
    // Flat normals for the sides and bottom (face normals, one vertex set per side).
    side.compute_normals();
    m.append(&side, &Affine3A::IDENTITY);
    m
}

/// A carved base plate over \[0, w\]×\[0, d\]: an n×m grid with a relief of engraved rings and
/// stripes (depth `depth`), materials alternating in stripes. Top surface only.
pub fn carved_plate(w: f32, d: f32, nx: u32, nz: u32, depth: f32, mat_a: u32, mat_b: u32) -> Mesh {
    let mut m = Mesh::new("carved plate");
    let h = |x: f32, z: f32| {
        let r = ((x - w * 0.5).powi(2) + (z - d * 0.5).powi(2)).sqrt();
        -depth * (0.5 + 0.5 * (r * 9.0).sin()) * (0.5 + 0.5 * (x * 7.0 + z * 3.0).cos())
    };
    let id = |i: u32, j: u32| i * (nz + 1) + j;
    for i in 0..=nx {
        for j in 0..=nz {
            let (x, z) = (w * i as f32 / nx as f32, d * j as f32 / nz as f32);
            m.push_vertex(Vec3::new(x, h(x, z), z));
        }
    }
    for i in 0..nx {
        for j in 0..nz {
            let x = w * (i as f32 + 0.5) / nx as f32;
            let mat = if ((x * 4.0).floor() as i32) % 2 == 0 { mat_a } else { mat_b };
            m.push_tri(id(i, j), id(i, j + 1), id(i + 1, j + 1), mat);
            m.push_tri(id(i, j), id(i + 1, j + 1), id(i + 1, j), mat);
        }
    }
    m.compute_normals();
    m
}

fn glass(name: &str, tint: Vec3) -> Material {
    Material { name: name.into(), color: tint, kd: 0.02, ks: 0.7, shininess: 90.0, reflect: 0.1, transmit: 0.85, ior: 1.5, roughness: 0.0 }
}

fn box_at(lo: Vec3, hi: Vec3) -> Affine3A {
    // cube_mesh spans [-1,1]³.
    Affine3A::from_scale_rotation_translation((hi - lo) * 0.5, Quat::IDENTITY, (hi + lo) * 0.5)
}

/// Papaioannou et al. Fig. 4: the chessboard (see the module header).
pub fn chessboard() -> Scene {
    let mut s = Scene::empty("chessboard");
    s.materials[0] =
        Material { name: "dark wood".into(), color: Vec3::new(0.35, 0.18, 0.07), kd: 0.9, ks: 0.25, shininess: 30.0, ..Default::default() };
    let tile_glass = s.add_material(glass("tile glass", Vec3::new(0.92, 0.97, 1.0)));
    let pawn_glass = s.add_material(glass("pawn glass", Vec3::new(1.0, 0.97, 0.9)));
    let pawn_wood = s.add_material(Material {
        name: "varnished wood".into(),
        color: Vec3::new(0.6, 0.36, 0.16),
        kd: 0.85,
        ks: 0.5,
        shininess: 60.0,
        reflect: 0.12,
        ..Default::default()
    });
    let cream = s.add_material(Material::diffuse("cream inlay", Vec3::new(0.9, 0.85, 0.7)));
    let red = s.add_material(Material::diffuse("red inlay", Vec3::new(0.6, 0.08, 0.06)));
    let table = s.add_material(Material::diffuse("table", Vec3::new(0.3, 0.32, 0.35)));

    // Base plate under the glass squares (seen through them), the wooden squares, frame.
    let plate = s.add_mesh(carved_plate(8.0, 8.0, 320, 320, 0.05, cream, red));
    s.instance(Target::Mesh(plate), Affine3A::from_translation(Vec3::new(0.0, 0.0, 0.0)), None);
    let cube = s.add_mesh(cube_mesh(0));
    let tile = s.add_mesh(bumpy_tile(48, 0.25, 0.06, tile_glass));
    for i in 0..8 {
        for j in 0..8 {
            let (x, z) = (i as f32, j as f32);
            if (i + j) % 2 == 0 {
                // Glass square, rotated by a multiple of 90° so the bumps differ.
                let rot = Affine3A::from_translation(Vec3::new(0.5, 0.0, 0.5))
                    * Affine3A::from_rotation_y(std::f32::consts::FRAC_PI_2 * ((i * 3 + j) % 4) as f32)
                    * Affine3A::from_translation(Vec3::new(-0.5, 0.0, -0.5));
                s.instance(Target::Mesh(tile), Affine3A::from_translation(Vec3::new(x, 0.02, z)) * rot, None);
            } else {
                s.instance(Target::Mesh(cube), box_at(Vec3::new(x, 0.0, z), Vec3::new(x + 1.0, 0.27, z + 1.0)), None);
            }
        }
    }
    // Frame around the board and the table it stands on.
    for (lo, hi) in [
        (Vec3::new(-0.5, -0.1, -0.5), Vec3::new(8.5, 0.3, 0.0)),
        (Vec3::new(-0.5, -0.1, 8.0), Vec3::new(8.5, 0.3, 8.5)),
        (Vec3::new(-0.5, -0.1, 0.0), Vec3::new(0.0, 0.3, 8.0)),
        (Vec3::new(8.0, -0.1, 0.0), Vec3::new(8.5, 0.3, 8.0)),
        (Vec3::new(-0.5, -0.3, -0.5), Vec3::new(8.5, -0.06, 8.5)),
    ] {
        s.instance(Target::Mesh(cube), box_at(lo, hi), None);
    }
    s.instance(Target::Mesh(cube), box_at(Vec3::new(-20.0, -1.3, -20.0), Vec3::new(28.0, -0.3, 28.0)), Some(table));
    // Pawns: glass on row 1, wood on row 6, and a few advanced ones.
    let pawn = s.add_mesh(pawn(160, 256, 0));
    let place = |i: f32, j: f32, scale: f32| {
        Affine3A::from_scale_rotation_translation(Vec3::splat(scale), Quat::IDENTITY, Vec3::new(i + 0.5, 0.27, j + 0.5))
    };
    for i in 0..8 {
        let adv = if i == 3 || i == 4 { 2.0 } else { 0.0 };
        s.instance(Target::Mesh(pawn), place(i as f32, 1.0 + adv, 0.9), Some(pawn_glass));
        s.instance(Target::Mesh(pawn), place(i as f32, 6.0 - adv * 0.5, 0.9), Some(pawn_wood));
    }
    s.camera =
        Camera { eye: Vec3::new(4.0, 6.2, 12.0), look: Vec3::new(4.0, 0.2, 3.6), up: Vec3::Y, fovy: 45.0, aperture: 0.0, focal_dist: 10.0 };
    s.lights.push(Light::Point { pos: Vec3::new(-3.0, 9.0, 9.0), intensity: Vec3::splat(120.0) });
    s.lights.push(Light::Point { pos: Vec3::new(12.0, 6.0, -2.0), intensity: Vec3::splat(40.0) });
    s.background = Vec3::new(0.55, 0.6, 0.7);
    s.ambient = Vec3::splat(0.08);
    s.max_depth = 6;
    s
}

/// Papaioannou et al. Fig. 6: a cabinet with a flat mirror on its back wall reflecting the
/// glasses and vases in front of it.
pub fn cabinet() -> Scene {
    let mut s = Scene::empty("cabinet");
    s.materials[0] = Material {
        name: "cabinet wood".into(),
        color: Vec3::new(0.45, 0.25, 0.1),
        kd: 0.9,
        ks: 0.2,
        shininess: 20.0,
        ..Default::default()
    };
    let mirror = s.add_material(Material {
        name: "mirror".into(),
        color: Vec3::splat(0.9),
        kd: 0.03,
        ks: 0.3,
        shininess: 200.0,
        reflect: 0.9,
        ..Default::default()
    });
    let g = s.add_material(glass("glass", Vec3::new(0.95, 1.0, 0.97)));
    let porcelain = s.add_material(Material {
        name: "porcelain".into(),
        color: Vec3::new(0.85, 0.82, 0.75),
        kd: 0.8,
        ks: 0.6,
        shininess: 80.0,
        reflect: 0.08,
        ..Default::default()
    });
    let blue = s.add_material(Material {
        name: "blue glaze".into(),
        color: Vec3::new(0.1, 0.2, 0.6),
        kd: 0.8,
        ks: 0.7,
        shininess: 90.0,
        reflect: 0.1,
        ..Default::default()
    });
    let wall = s.add_material(Material::diffuse("wall", Vec3::new(0.7, 0.68, 0.62)));
    let cube = s.add_mesh(cube_mesh(0));
    // Cabinet: inside x ∈ [0,6], y ∈ [0,4], z ∈ [0,2.5] (open at z = 2.5), walls 0.15 thick.
    for (lo, hi) in [
        (Vec3::new(-0.15, -0.15, -0.15), Vec3::new(6.15, 0.0, 2.5)),   // bottom
        (Vec3::new(-0.15, 4.0, -0.15), Vec3::new(6.15, 4.15, 2.5)),    // top
        (Vec3::new(-0.15, 0.0, -0.15), Vec3::new(0.0, 4.0, 2.5)),      // left
        (Vec3::new(6.0, 0.0, -0.15), Vec3::new(6.15, 4.0, 2.5)),       // right
        (Vec3::new(-0.15, -0.15, -0.3), Vec3::new(6.15, 4.15, -0.15)), // back
        (Vec3::new(0.0, 1.9, 0.0), Vec3::new(6.0, 2.0, 2.5)),          // shelf
    ] {
        s.instance(Target::Mesh(cube), box_at(lo, hi), None);
    }
    // The mirror on the back wall (a thin box, flat front at z = 0).
    s.instance(Target::Mesh(cube), box_at(Vec3::new(0.0, 0.0, -0.15), Vec3::new(6.0, 4.0, 0.0)), Some(mirror));
    // Room behind the camera and around: walls the mirror shows.
    s.instance(Target::Mesh(cube), box_at(Vec3::new(-10.0, -0.6, -1.0), Vec3::new(16.0, -0.15, 20.0)), Some(wall));
    let glass_mesh = s.add_mesh(wine_glass(160, 192, 0));
    let vase_mesh = s.add_mesh(vase(120, 192, 0));
    let at =
        |x: f32, y: f32, z: f32, sc: f32| Affine3A::from_scale_rotation_translation(Vec3::splat(sc), Quat::IDENTITY, Vec3::new(x, y, z));
    for (k, x) in [0.8f32, 1.9, 3.1, 4.3, 5.3].iter().enumerate() {
        s.instance(Target::Mesh(glass_mesh), at(*x, 0.0, 0.9 + 0.35 * (k % 2) as f32, 1.3), Some(g));
    }
    for (k, x) in [1.0f32, 2.6, 4.0, 5.2].iter().enumerate() {
        s.instance(Target::Mesh(vase_mesh), at(*x, 2.0, 0.8 + 0.4 * (k % 2) as f32, 1.2), Some(if k % 2 == 0 { porcelain } else { blue }));
    }
    for (k, x) in [1.7f32, 3.4, 4.7].iter().enumerate() {
        s.instance(Target::Mesh(glass_mesh), at(*x, 2.0, 1.6 - 0.3 * (k % 2) as f32, 1.0), Some(g));
    }
    s.camera =
        Camera { eye: Vec3::new(3.6, 2.6, 9.0), look: Vec3::new(3.0, 1.9, 0.8), up: Vec3::Y, fovy: 42.0, aperture: 0.0, focal_dist: 8.0 };
    s.lights.push(Light::Point { pos: Vec3::new(3.0, 3.7, 2.3), intensity: Vec3::splat(14.0) });
    s.lights.push(Light::Point { pos: Vec3::new(-2.0, 6.0, 10.0), intensity: Vec3::splat(90.0) });
    s.background = Vec3::new(0.2, 0.2, 0.22);
    s.ambient = Vec3::splat(0.06);
    s.max_depth = 6;
    s
}

/// Papaioannou et al. Fig. 5: detailed models seen in curved reflectors. Needs
/// `assets/armadillo.off`, `bunny00.off` and `cow.off` (`tools/setup`).
pub fn reflector() -> Result<Scene> {
    let mut s = Scene::empty("reflector");
    s.materials[0] = Material::diffuse("floor light", Vec3::new(0.8, 0.78, 0.72));
    let dark = s.add_material(Material::diffuse("floor dark", Vec3::new(0.12, 0.12, 0.15)));
    let chrome = s.add_material(Material {
        name: "chrome".into(),
        color: Vec3::splat(0.9),
        kd: 0.05,
        ks: 0.8,
        shininess: 150.0,
        reflect: 0.85,
        ..Default::default()
    });
    let clay = s.add_material(Material {
        name: "clay".into(),
        color: Vec3::new(0.75, 0.55, 0.4),
        kd: 0.9,
        ks: 0.3,
        shininess: 30.0,
        ..Default::default()
    });
    let jade = s.add_material(Material {
        name: "jade".into(),
        color: Vec3::new(0.3, 0.65, 0.45),
        kd: 0.9,
        ks: 0.5,
        shininess: 60.0,
        ..Default::default()
    });
    let board = s.add_mesh(super::builtin::checkerboard(24, 24.0, 0, dark));
    s.instance(Target::Mesh(board), Affine3A::IDENTITY, None);
    let arma = s.add_mesh(super::builtin::asset_mesh("reflector", "armadillo.off", 0)?);
    let bunny = s.add_mesh(super::builtin::asset_mesh("reflector", "bunny00.off", 0)?);
    let cow = s.add_mesh(super::builtin::asset_mesh("reflector", "cow.off", 0)?);
    let put = |sc: f32, rot: f32, t: Vec3| Affine3A::from_scale_rotation_translation(Vec3::splat(sc), Quat::from_rotation_y(rot), t);
    s.instance(Target::Mesh(arma), put(2.2, 3.4, Vec3::new(-2.6, 0.0, 2.6)), Some(clay));
    s.instance(Target::Mesh(bunny), put(2.0, 0.6, Vec3::new(2.8, 0.0, 2.8)), Some(jade));
    s.instance(Target::Mesh(cow), put(2.4, -0.8, Vec3::new(0.3, 0.0, 4.6)), Some(clay));
    s.instance(Target::Mesh(bunny), put(1.4, 2.5, Vec3::new(-0.6, 0.0, 1.4)), Some(clay));
    // The reflectors: a chrome sphere, a convex cylinder section (lathe), a ring.
    let sphere = s.add_mesh(super::builtin::uv_sphere(96, 192, 0));
    s.instance(Target::Mesh(sphere), put(1.6, 0.0, Vec3::new(-0.3, 1.6, -2.2)), Some(chrome));
    let drum = s.add_mesh(lathe("drum", &[(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)], 256, 0));
    s.instance(
        Target::Mesh(drum),
        Affine3A::from_scale_rotation_translation(Vec3::new(1.3, 3.2, 1.3), Quat::IDENTITY, Vec3::new(4.2, 0.0, -1.2)),
        Some(chrome),
    );
    let ring_profile: Vec<(f32, f32)> = (0..=64)
        .map(|k| {
            let a = std::f32::consts::TAU * k as f32 / 64.0;
            (1.0 + 0.28 * a.cos(), 0.28 * a.sin())
        })
        .collect();
    let ring = s.add_mesh(lathe("ring", &ring_profile, 192, 0));
    s.instance(
        Target::Mesh(ring),
        Affine3A::from_scale_rotation_translation(Vec3::splat(1.2), Quat::from_rotation_x(1.2), Vec3::new(-4.4, 1.5, -1.0)),
        Some(chrome),
    );
    s.camera =
        Camera { eye: Vec3::new(0.5, 4.0, 11.0), look: Vec3::new(0.0, 1.2, 0.0), up: Vec3::Y, fovy: 50.0, aperture: 0.0, focal_dist: 11.0 };
    s.lights.push(Light::Point { pos: Vec3::new(-4.0, 9.0, 8.0), intensity: Vec3::splat(150.0) });
    s.lights.push(Light::Point { pos: Vec3::new(6.0, 5.0, 6.0), intensity: Vec3::splat(50.0) });
    s.background = Vec3::new(0.5, 0.55, 0.65);
    s.ambient = Vec3::splat(0.07);
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn closed(m: &Mesh) -> bool {
        // Every edge used twice (opposite directions) → closed, consistently oriented.
        let mut e = std::collections::HashMap::new();
        for t in &m.tris {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *e.entry((a, b)).or_insert(0i32) += 1;
            }
        }
        e.iter().all(|(&(a, b), &n)| n == 1 && e.get(&(b, a)) == Some(&1))
    }

    #[test]
    fn lathe_solids_are_closed_and_outward() {
        for m in [pawn(40, 32, 0), wine_glass(40, 32, 0), vase(30, 24, 0)] {
            assert!(closed(&m), "{} not closed", m.name);
            // Outward: normals point away from the axis at mid-height on average.
            let mut s = 0.0;
            for i in 0..m.vertex_count() as u32 {
                let p = m.pos(i);
                s += m.normal(i).dot(Vec3::new(p.x, 0.0, p.z));
            }
            assert!(s > 0.0, "{} inside out", m.name);
            assert!(signed_volume(&m) > 0.0, "{} negative volume", m.name);
        }
    }

    fn signed_volume(m: &Mesh) -> f32 {
        (0..m.tris.len())
            .map(|t| {
                let [a, b, c] = m.tri_verts(t);
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    #[test]
    fn bumpy_tile_is_closed_with_a_bumpy_top() {
        let m = bumpy_tile(12, 0.25, 0.06, 0);
        // Outward orientation: positive volume close to the slab's (bumps average out).
        let v = signed_volume(&m);
        assert!((v - 0.25).abs() < 0.02, "volume {v}");
        let (lo, hi) = m.bounds();
        assert!(lo.y.abs() < 1e-6 && hi.y > 0.25);
        assert_eq!(m.tris.len(), 12 * 12 * 2 + 4 * 12 * 2 + 2);
    }
}
