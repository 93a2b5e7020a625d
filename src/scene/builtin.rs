//! Built-in scenes (`lodtrace scenes`) and the procedural geometry they are made of.
//!
//! - `spheres`: Wand & Straßer Fig. 6, a reflective and a refractive sphere on a checkerboard
//!   made of geometry (about 7,400 triangles).
//! - `effects`: Wand & Straßer Fig. 8, special effects: soft shadows from an elliptical light,
//!   depth of field, and blurry reflections at three roughnesses (about 14,000 triangles).
//! - `complex`: Wand & Straßer §6 "High Complexity" (Fig. 7): specular cows, transparent
//!   bunnies and procedural plants on a large checkerboard of real geometry, hierarchically
//!   instanced to about 8.7 million triangles from about 110,000 unique ones (footnote 3 of the
//!   paper: 110,231). Needs `assets/bunny00.off` and `assets/cow.off` (`tools/setup`).
//! - `instanced`: a small test of nested instancing (rotations, non-uniform scales, material
//!   overrides at several levels), a few thousand triangles, for the intersector cross-checks.
//! - `plane`, `cube`, `ico`: small test scenes (known-answer shading, watertightness).
//!
//! Choices where the paper is silent (it gives only the triangle counts and the picture):
//! - The plants are our own recursive branching generator ([`plant`]): tapered prism stems
//!   that bend under a random wobble and a pull toward the light, children placed by the
//!   golden angle (phyllotaxis), many small folded 4-triangle leaf blades on the last levels.
//!   Three variants (shrub, tall herb, fern-like) make ~29k unique triangles, which with
//!   bunny (75,408), cow (5,804) and one 8×8-cell board patch (128) gives ~110k unique.
//! - The board is a 256×256-unit plane of 0.5-unit cells: one 8×8-cell patch, instanced as
//!   row → block → board, so far-away cells fall well below a pixel (the aliasing the paper
//!   is about), and all of it is geometry, as the paper insists.
//! - Instancing depth: plant → clump (6 plants) → field (4×4 clumps) → root; cow → herd →
//!   root; bunny → bunnies → root. The hierarchy is kept; only leaf instances are resolved.

use super::{Camera, Light, Material, Mesh, Scene, Target};
use crate::core::rng::Sampler;
use crate::error::{Error, Result};
use glam::{Affine3A, Quat, Vec3};
use std::path::{Path, PathBuf};

pub struct BuiltinInfo {
    pub name: &'static str,
    pub about: &'static str,
}

pub const BUILTINS: &[BuiltinInfo] = &[
    BuiltinInfo { name: "spheres", about: "Wand & Strasser Fig. 6: reflective and refractive sphere on a geometric checkerboard (~7,400 triangles)" },
    BuiltinInfo { name: "effects", about: "Wand & Strasser Fig. 8: soft shadows from an elliptical light, depth of field, blurry reflections at three roughnesses (~14,000 triangles)" },
    BuiltinInfo { name: "complex", about: "Wand & Strasser Fig. 7: specular cows, glass bunnies, procedural plants on a huge geometric checkerboard (~8.7M instanced / ~110k unique triangles; needs tools/setup)" },
    BuiltinInfo { name: "chessboard", about: "Papaioannou et al. Fig. 4: wooden chessboard with bumpy glass squares, glass and wooden lathe pawns, carved base plate (~1.66M instanced triangles)" },
    BuiltinInfo { name: "cabinet", about: "Papaioannou et al. Fig. 6: cabinet with a flat mirror on its back wall reflecting glasses and vases" },
    BuiltinInfo { name: "reflector", about: "Papaioannou et al. Fig. 5: armadillo, bunnies and cow seen in curved chrome reflectors (needs tools/setup)" },
    BuiltinInfo { name: "instanced", about: "test: nested instance groups with rotations, non-uniform scales and material overrides (~5,000 triangles)" },
    BuiltinInfo { name: "plane", about: "test: a diffuse square lit by one point light (known-answer shading)" },
    BuiltinInfo { name: "cube", about: "test: a closed cube seen at an angle (watertightness)" },
    BuiltinInfo { name: "ico", about: "test: a subdivided icosphere (closed, 5,120 triangles)" },
];

pub fn get(name: &str) -> Result<Scene> {
    match name {
        "spheres" => Ok(spheres()),
        "effects" => Ok(effects()),
        "complex" => complex(),
        "instanced" => Ok(instanced()),
        "chessboard" => Ok(super::lodscenes::chessboard()),
        "cabinet" => Ok(super::lodscenes::cabinet()),
        "reflector" => super::lodscenes::reflector(),
        "plane" => Ok(plane()),
        "cube" => Ok(single("cube", cube_mesh(0))),
        "ico" => Ok(single("ico", icosphere(4, 0))),
        // A deforming sequence asked of a triangle renderer: say where it is served.
        _ if crate::deform::Sequence::BUILTIN.contains(&name) => Err(Error::Scene(format!(
            "'{name}' is a deforming sequence (Adams et al.), not a triangle scene: render it with --method surfel, bench it with surfel specs (e.g. --methods surfel:update=naive,surfel:update=lazy-cache), or run lodtrace animate {name}"
        ))),
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
        (-1., t, 0.),
        (1., t, 0.),
        (-1., -t, 0.),
        (1., -t, 0.),
        (0., -1., t),
        (0., 1., t),
        (0., -1., -t),
        (0., 1., -t),
        (t, 0., -1.),
        (t, 0., 1.),
        (-t, 0., -1.),
        (-t, 0., 1.),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut f: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
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

/// A unit square \[0, 1\]² in the xz-plane (y = 0), normal +y, two triangles.
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

/// Fits a mesh into a unit box in place: uniform scale so the largest extent of its bounds is
/// 1, centred on x = z = 0, resting on y = 0 (the base of the bounds). Normals are unchanged
/// (the map is a uniform scale plus a translation). Returns the scale factor applied; an empty
/// or flat-to-a-point mesh is left as it is (factor 1).
pub fn normalize_mesh(mesh: &mut Mesh) -> f32 {
    let (lo, hi) = mesh.bounds();
    let ext = (hi - lo).max_element();
    if !lo.is_finite() || !hi.is_finite() || ext <= 0.0 {
        return 1.0;
    }
    let k = 1.0 / ext;
    let shift = Vec3::new(-(lo.x + hi.x) * 0.5, -lo.y, -(lo.z + hi.z) * 0.5);
    for i in 0..mesh.vertex_count() {
        mesh.px[i] = (mesh.px[i] + shift.x) * k;
        mesh.py[i] = (mesh.py[i] + shift.y) * k;
        mesh.pz[i] = (mesh.pz[i] + shift.z) * k;
    }
    k
}

/// Parameters of the recursive branching plant generator ([`plant`]). Lengths are in the
/// plant's own units (the trunk starts at the origin and grows along +y).
#[derive(Clone, Debug)]
pub struct PlantParams {
    /// Seed of the deterministic random stream.
    pub seed: u32,
    /// Branching levels below the trunk (level 0 = trunk).
    pub levels: u32,
    /// Children per branch, inclusive range (the last child continues the branch's axis).
    pub children: [u32; 2],
    /// Trunk length and base radius.
    pub length: f32,
    pub radius: f32,
    /// Child length and radius relative to the parent.
    pub length_ratio: f32,
    pub radius_ratio: f32,
    /// Mean angle (degrees) between a side branch and its parent.
    pub branch_angle: f32,
    /// Stem segments of the trunk (one fewer per level, at least 2) and prism sides (one fewer
    /// per level, at least 3).
    pub segments: u32,
    pub sides: u32,
    /// Leaves on each branch of the last level (a third as many on the level above).
    pub leaves: u32,
    pub leaf_length: f32,
    pub leaf_width: f32,
    /// Pull of each stem segment toward +y (light), and random bend per segment.
    pub tropism: f32,
    pub wobble: f32,
}

impl PlantParams {
    /// A bushy shrub: short trunk, wide branching, broad leaves (~9.5k triangles).
    pub fn shrub(seed: u32) -> Self {
        PlantParams {
            seed,
            levels: 3,
            children: [3, 5],
            length: 0.45,
            radius: 0.035,
            length_ratio: 0.72,
            radius_ratio: 0.6,
            branch_angle: 48.0,
            segments: 5,
            sides: 6,
            leaves: 40,
            leaf_length: 0.09,
            leaf_width: 0.04,
            tropism: 0.12,
            wobble: 0.18,
        }
    }
    /// A tall herb: a long main stem, narrow branching, slender leaves (~9.5k triangles).
    pub fn herb(seed: u32) -> Self {
        PlantParams {
            seed,
            levels: 4,
            children: [3, 4],
            length: 0.7,
            radius: 0.025,
            length_ratio: 0.62,
            radius_ratio: 0.62,
            branch_angle: 32.0,
            segments: 6,
            sides: 5,
            leaves: 14,
            leaf_length: 0.09,
            leaf_width: 0.03,
            tropism: 0.2,
            wobble: 0.12,
        }
    }
    /// A fern-like rosette: a short base with many arching fronds, each with many small
    /// leaflets (~9.5k triangles).
    pub fn fern(seed: u32) -> Self {
        PlantParams {
            seed,
            levels: 1,
            children: [24, 30],
            length: 0.12,
            radius: 0.03,
            length_ratio: 7.0,
            radius_ratio: 0.5,
            branch_angle: 38.0,
            segments: 4,
            sides: 5,
            leaves: 80,
            leaf_length: 0.06,
            leaf_width: 0.022,
            tropism: -0.33,
            wobble: 0.06,
        }
    }
}

/// A procedural plant: recursive branching (an L-system-like grammar evaluated directly:
/// `branch → stem [child]* leaf*`), stems as tapered open prisms with a pointed cap, leaves as
/// small folded blades of 4 triangles. Deterministic in `p.seed` (random numbers from
/// [`Sampler`]). Stems use `stem_mat`, leaves `leaf_mat`. Smooth normals are set.
pub fn plant(p: &PlantParams, stem_mat: u32, leaf_mat: u32) -> Mesh {
    let mut g = PlantGen { p, rng: Sampler::new(p.seed, 0x504c_414e, 0), m: Mesh::new("plant"), stem_mat, leaf_mat, azimuth: 0.0 };
    g.branch(Vec3::ZERO, Vec3::Y, p.length, p.radius, 0);
    g.m
}

struct PlantGen<'a> {
    p: &'a PlantParams,
    rng: Sampler,
    m: Mesh,
    stem_mat: u32,
    leaf_mat: u32,
    /// Running phyllotaxis angle (radians): children and leaves are spread by the golden angle.
    azimuth: f32,
}

const GOLDEN_ANGLE: f32 = 2.399_963; // radians, 137.5°
/// Lowest height (plant units) of stems and leaves above the ground plane y = 0.
const GROUND_CLEARANCE: f32 = 0.003;

impl PlantGen<'_> {
    fn rand(&mut self) -> f32 {
        self.rng.next()
    }
    fn rand_range(&mut self, a: f32, b: f32) -> f32 {
        a + (b - a) * self.rand()
    }
    /// Uniform direction on the unit sphere.
    fn rand_dir(&mut self) -> Vec3 {
        let z = 2.0 * self.rand() - 1.0;
        let phi = std::f32::consts::TAU * self.rand();
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(r * phi.cos(), z, r * phi.sin())
    }
    fn vertex(&mut self, p: Vec3, n: Vec3) -> u32 {
        self.m.nx.push(n.x);
        self.m.ny.push(n.y);
        self.m.nz.push(n.z);
        self.m.push_vertex(p)
    }
    /// The next phyllotaxis direction perpendicular to `axis`.
    fn next_out(&mut self, axis: Vec3) -> Vec3 {
        self.azimuth += GOLDEN_ANGLE + self.rand_range(-0.25, 0.25);
        let (u, v) = crate::core::onb(axis);
        u * self.azimuth.cos() + v * self.azimuth.sin()
    }

    fn branch(&mut self, start: Vec3, dir: Vec3, len: f32, r0: f32, level: u32) {
        let p = self.p;
        let segs = p.segments.saturating_sub(level).max(2) as usize;
        let sides = p.sides.saturating_sub(level).max(3);
        let r1 = r0 * p.radius_ratio.clamp(0.05, 1.0);
        // The stem's centre line: bent per segment by a random wobble and the tropism.
        let mut pts = Vec::with_capacity(segs + 1);
        pts.push(start);
        let mut d = dir.normalize();
        for s in 0..segs {
            let w = self.rand_dir();
            d = (d + w * p.wobble + Vec3::Y * p.tropism).normalize_or(d);
            // Stay above the ground (y = 0), tip cap included: level out instead of sinking.
            let r = r0 + (r1 - r0) * ((s + 1) as f32 / segs as f32);
            if d.y < 0.0 && pts[s].y + d.y * (len / segs as f32) < 2.0 * r + GROUND_CLEARANCE {
                d = Vec3::new(d.x, 0.0, d.z).normalize_or(Vec3::X);
            }
            pts.push(pts[s] + d * (len / segs as f32));
        }
        let tangent = |i: usize| -> Vec3 {
            let a = pts[i.saturating_sub(1)];
            let b = pts[(i + 1).min(segs)];
            (b - a).normalize_or(dir)
        };
        // Rings with a parallel-transported frame, so the prism does not twist.
        let base = self.m.vertex_count() as u32;
        let mut u = crate::core::onb(dir.normalize()).0;
        for (i, &c) in pts.iter().enumerate() {
            // The trunk's base ring lies flat on the ground.
            let t = if i == 0 && level == 0 { dir.normalize() } else { tangent(i) };
            u = (u - t * u.dot(t)).normalize_or(crate::core::onb(t).0);
            let v = t.cross(u);
            let r = r0 + (r1 - r0) * (i as f32 / segs as f32);
            for k in 0..sides {
                let a = std::f32::consts::TAU * k as f32 / sides as f32;
                let n = u * a.cos() + v * a.sin();
                self.vertex(c + n * r, n);
            }
        }
        for i in 0..segs as u32 {
            for k in 0..sides {
                let a = base + i * sides + k;
                let b = base + i * sides + (k + 1) % sides;
                let (c, e) = (a + sides, b + sides);
                self.m.push_tri(a, b, e, self.stem_mat);
                self.m.push_tri(a, e, c, self.stem_mat);
            }
        }
        let t_end = tangent(segs);
        let tip = self.vertex(pts[segs] + t_end * (r1 * 2.0), t_end);
        let last = base + segs as u32 * sides;
        for k in 0..sides {
            self.m.push_tri(last + k, last + (k + 1) % sides, tip, self.stem_mat);
        }
        // A point, direction and radius at fraction f of the stem.
        let along = |f: f32| -> (Vec3, Vec3, f32) {
            let x = f.clamp(0.0, 1.0) * segs as f32;
            let i = (x as usize).min(segs - 1);
            let fr = x - i as f32;
            (pts[i].lerp(pts[i + 1], fr), (pts[i + 1] - pts[i]).normalize_or(dir), r0 + (r1 - r0) * f)
        };
        if level < p.levels {
            let span = p.children[1].saturating_sub(p.children[0]) + 1;
            let n = p.children[0] + ((self.rand() * span as f32) as u32).min(span - 1);
            for k in 0..n {
                let apical = k + 1 == n;
                let f = if apical { 1.0 } else { 0.3 + 0.65 * (k as f32 + self.rand()) / n as f32 };
                let (pos, sd, r) = along(f);
                let out = self.next_out(sd);
                let ang = p.branch_angle.to_radians() * if apical { 0.25 } else { self.rand_range(0.75, 1.25) };
                let cdir = (sd * ang.cos() + out * ang.sin()).normalize();
                let clen = len * p.length_ratio * self.rand_range(0.8, 1.1) * if apical { 0.9 } else { 1.0 - 0.3 * f };
                self.branch(pos, cdir, clen, (r * 0.85).max(r1), level + 1);
            }
        }
        let nleaves = if level == p.levels {
            p.leaves
        } else if level + 1 == p.levels {
            p.leaves / 3
        } else {
            0
        };
        for k in 0..nleaves {
            let f = 0.2 + 0.8 * (k as f32 + self.rand()) / nleaves as f32;
            let (pos, sd, _) = along(f);
            self.leaf(pos, sd);
        }
    }

    /// One leaf blade at `base` on a stem of direction `sd`: a diamond folded along its midrib,
    /// drooping toward the tip; 5 vertices, 4 triangles.
    fn leaf(&mut self, base: Vec3, sd: Vec3) {
        let p = self.p;
        let out = self.next_out(sd);
        let tilt = self.rand_range(40.0, 75.0).to_radians();
        let mut ld = (sd * tilt.cos() + out * tilt.sin()).normalize();
        let l = p.leaf_length * self.rand_range(0.7, 1.3);
        let wd = p.leaf_width * self.rand_range(0.7, 1.3);
        // Keep the blade above the ground: it may sink by at most `room`, half of it by its
        // direction and half by the droop of its tip (the fold only lifts: n.y ≥ 0).
        let room = (base.y - GROUND_CLEARANCE).max(0.0);
        if ld.y * l < -0.5 * room {
            let y = (-0.5 * room / l).max(-1.0);
            let h = Vec3::new(ld.x, 0.0, ld.z).normalize_or(Vec3::X);
            ld = h * (1.0 - y * y).sqrt() + Vec3::Y * y;
        }
        let droop = (0.2 * l).min(room + ld.y.min(0.0) * l).max(0.0);
        let w = ld.cross(Vec3::Y).normalize_or(out.cross(ld).normalize_or(crate::core::onb(ld).0));
        let n = w.cross(ld).normalize();
        let fold = n * (0.2 * wd);
        let tip = base + ld * l - Vec3::Y * droop;
        let mid = base + ld * (0.5 * l);
        let left = base + ld * (0.35 * l) - w * (0.5 * wd) + fold;
        let right = base + ld * (0.35 * l) + w * (0.5 * wd) + fold;
        let nt = (tip - mid).cross(w).normalize_or(n);
        let nt = if nt.dot(n) < 0.0 { -nt } else { nt };
        let [b, m, lft, rgt, t] = [(base, n), (mid, n), (left, n), (right, n), (tip, nt)].map(|(q, nn)| self.vertex(q, nn));
        let mat = self.leaf_mat;
        self.m.push_tri(b, lft, m, mat);
        self.m.push_tri(b, m, rgt, mat);
        self.m.push_tri(lft, t, m, mat);
        self.m.push_tri(m, t, rgt, mat);
    }
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
    s.instance(
        Target::Mesh(id),
        Affine3A::from_scale_rotation_translation(Vec3::new(2.0, 1.0, 2.0), glam::Quat::IDENTITY, Vec3::new(-1.0, 0.0, -1.0)),
        None,
    );
    s.camera = Camera {
        eye: Vec3::new(0.0, 3.0, 0.0),
        look: Vec3::ZERO,
        up: Vec3::new(0.0, 0.0, -1.0),
        fovy: 30.0,
        aperture: 0.0,
        focal_dist: 3.0,
    };
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
    s.instance(
        Target::Mesh(sphere),
        Affine3A::from_scale_rotation_translation(Vec3::splat(1.3), glam::Quat::IDENTITY, Vec3::new(-1.6, 1.3, -1.0)),
        Some(red),
    );
    s.instance(
        Target::Mesh(sphere),
        Affine3A::from_scale_rotation_translation(Vec3::splat(1.1), glam::Quat::IDENTITY, Vec3::new(1.4, 1.1, 1.2)),
        Some(glass),
    );
    s.camera =
        Camera { eye: Vec3::new(0.5, 3.2, 8.5), look: Vec3::new(0.0, 0.8, 0.0), up: Vec3::Y, fovy: 45.0, aperture: 0.0, focal_dist: 8.5 };
    s.lights.push(Light::Ellipse {
        center: Vec3::new(-4.0, 8.0, 5.0),
        axis_a: Vec3::new(0.8, 0.0, 0.0),
        axis_b: Vec3::new(0.0, 0.0, 0.8),
        intensity: Vec3::splat(90.0),
    });
    s.background = Vec3::new(0.45, 0.55, 0.75);
    s.ambient = Vec3::splat(0.08);
    s
}

/// Wand & Straßer Fig. 8 ("Special Effects", 512×512): one scene for the three effects.
/// - Soft shadows (Fig. 8a/b): one elliptical area light (semi-axes 2.8 × 1.7) high at the
///   back left; the spheres' shadows fall toward the front right, with penumbrae about one
///   board cell wide. The dark cells are a mid grey (0.15) so the shadows read on both colours.
/// - Depth of field (Fig. 8c): a thin lens (`aperture` 0.22) focused on the middle sphere's
///   centre; a cube and an icosphere in the foreground and a row of pillars far behind blur.
/// - Blurry reflections (Fig. 8d): three mirror spheres, identical but for the roughness
///   (glossy cone half-angle) 0.03, 0.1 and 0.25 radians from left to right, side by side in
///   the focal plane. They reflect the checkerboard and a wall of one-unit coloured stripes
///   behind the camera (outside the view), so the blur shows on sharp coloured edges.
///
/// All geometry, no textures: 14,068 triangles (6,784 unique). The Whitted integrator shows
/// none of the effects (light centre, pinhole, perfect mirrors); the distributed one samples
/// them, the multiresolution tracer widens its cones for them.
pub fn effects() -> Scene {
    let mut s = Scene::empty("effects");
    s.materials[0] = Material::diffuse("white", Vec3::splat(0.8));
    let black = s.add_material(Material::diffuse("black", Vec3::splat(0.15)));
    let chrome = |name: &str, roughness: f32| Material {
        name: name.into(),
        color: Vec3::splat(0.85),
        kd: 0.12,
        ks: 0.5,
        shininess: 60.0,
        reflect: 0.8,
        roughness,
        ..Default::default()
    };
    let mirrors = [
        s.add_material(chrome("mirror 0.03", 0.03)),
        s.add_material(chrome("mirror 0.1", 0.1)),
        s.add_material(chrome("mirror 0.25", 0.25)),
    ];
    let plastic = |name: &str, color: Vec3| Material { name: name.into(), color, kd: 0.9, ks: 0.05, shininess: 40.0, ..Default::default() };
    let colors = [
        s.add_material(plastic("red", Vec3::new(0.8, 0.08, 0.06))),
        s.add_material(plastic("orange", Vec3::new(0.9, 0.45, 0.05))),
        s.add_material(plastic("yellow", Vec3::new(0.85, 0.75, 0.1))),
        s.add_material(plastic("green", Vec3::new(0.1, 0.6, 0.15))),
        s.add_material(plastic("blue", Vec3::new(0.1, 0.2, 0.85))),
        s.add_material(plastic("purple", Vec3::new(0.5, 0.1, 0.7))),
    ];
    let [red, orange, yellow, green, blue, purple] = colors;

    // The floor: 32×32 cells of one unit, reaching well behind the spheres.
    let board = s.add_mesh(checkerboard(32, 32.0, 0, black));
    s.instance(Target::Mesh(board), Affine3A::from_translation(Vec3::new(0.0, 0.0, -8.0)), None);

    // Three mirror spheres (radius 0.75) side by side in the focal plane.
    let sphere = s.add_mesh(uv_sphere(43, 41, 0));
    for (k, &m) in mirrors.iter().enumerate() {
        let x = 2.2 * (k as f32 - 1.0);
        s.instance(
            Target::Mesh(sphere),
            Affine3A::from_scale_rotation_translation(Vec3::splat(0.75), Quat::IDENTITY, Vec3::new(x, 0.75, 0.0)),
            Some(m),
        );
    }

    // Foreground (near, blurred): a red cube and a blue icosphere.
    let cube = s.add_mesh(cube_mesh(0));
    let ico = s.add_mesh(icosphere(3, 0));
    s.instance(Target::Mesh(cube), srt(Vec3::splat(0.3), 0.6, Vec3::new(-1.1, 0.3, 3.3)), Some(red));
    s.instance(
        Target::Mesh(ico),
        Affine3A::from_scale_rotation_translation(Vec3::splat(0.35), Quat::IDENTITY, Vec3::new(1.2, 0.35, 3.3)),
        Some(blue),
    );

    // Background (far, blurred): a row of coloured pillars.
    for (k, &m) in [green, yellow, purple, orange, red].iter().enumerate() {
        let x = -4.0 + 2.0 * k as f32;
        s.instance(Target::Mesh(cube), srt(Vec3::new(0.3, 1.1, 0.3), 0.4, Vec3::new(x, 1.1, -8.0 - 0.7 * (k % 2) as f32)), Some(m));
    }

    // Behind the camera (seen only in the mirrors): a wall of coloured stripes, sharp edges
    // for the glossy cones to blur.
    for k in 0..28 {
        let x = -13.5 + k as f32;
        s.instance(Target::Mesh(cube), srt(Vec3::new(0.5, 4.0, 0.1), 0.0, Vec3::new(x, 4.0, 11.5)), Some(colors[k % colors.len()]));
    }

    let eye = Vec3::new(0.0, 4.2, 8.2);
    let look = Vec3::new(0.0, 0.75, 0.0); // the middle sphere's centre
    s.camera = Camera { eye, look, up: Vec3::Y, fovy: 45.0, aperture: 0.22, focal_dist: (look - eye).length() };
    // High at the back left: the shadows fall toward the front right, long and soft.
    s.lights.push(Light::Ellipse {
        center: Vec3::new(-7.0, 9.0, -6.0),
        axis_a: Vec3::new(2.8, 0.0, 0.0),
        axis_b: Vec3::new(0.0, 0.0, 1.7),
        intensity: Vec3::splat(360.0),
    });
    s.background = Vec3::new(0.45, 0.55, 0.75);
    s.ambient = Vec3::splat(0.08);
    s
}

/// Where the real meshes live: `$LODTRACE_ASSETS`, else `./assets` when it exists, else the
/// crate's own `assets/` folder (where `tools/setup` puts them).
pub fn assets_dir() -> PathBuf {
    // Empty counts as unset (as `LODTRACE_CACHE`).
    if let Some(d) = std::env::var_os("LODTRACE_ASSETS").filter(|d| !d.is_empty()) {
        return PathBuf::from(d);
    }
    let local = Path::new("assets");
    if local.is_dir() {
        return local.to_path_buf();
    }
    Path::new(env!("CARGO_MANIFEST_DIR")).join("assets")
}

/// What a missing asset's error says to do (the built-in scenes and sequences alike).
pub(crate) const MISSING_ASSET_HINT: &str = "run tools/setup (or set LODTRACE_ASSETS to a folder holding it)";

/// Loads an asset mesh normalised by [`normalize_mesh`], or says to run tools/setup.
pub(crate) fn asset_mesh(scene: &str, file: &str, mat: u32) -> Result<Mesh> {
    let p = assets_dir().join(file);
    if !p.is_file() {
        return Err(Error::Scene(format!("scene '{scene}' needs the mesh {} (not found): {MISSING_ASSET_HINT}", p.display())));
    }
    let mut m = super::load::load_off(&p, mat)?;
    normalize_mesh(&mut m);
    Ok(m)
}

fn srt(scale: Vec3, rot_y: f32, t: Vec3) -> Affine3A {
    Affine3A::from_scale_rotation_translation(scale, Quat::from_rotation_y(rot_y), t)
}

/// Wand & Straßer §6 "High Complexity" (Fig. 7): specular cows, glass bunnies and procedural
/// plants on a large checkerboard, all geometry, hierarchically instanced (see the module
/// header for the layout). Fails with a clear message when the asset meshes are missing.
pub fn complex() -> Result<Scene> {
    let mut s = Scene::empty("complex");
    // Materials (Wand & Straßer §3: colour, Phong, reflectivity, transparency, ior, roughness).
    s.materials[0] = Material::diffuse("board white", Vec3::new(0.85, 0.85, 0.8));
    let dark = s.add_material(Material::diffuse("board dark", Vec3::new(0.06, 0.06, 0.08)));
    let chrome = s.add_material(Material {
        name: "cow chrome".into(),
        color: Vec3::new(0.75, 0.75, 0.8),
        kd: 0.25,
        ks: 0.8,
        shininess: 80.0,
        reflect: 0.6,
        ..Default::default()
    });
    let gold = s.add_material(Material {
        name: "cow gold".into(),
        color: Vec3::new(0.9, 0.62, 0.22),
        kd: 0.35,
        ks: 0.7,
        shininess: 60.0,
        reflect: 0.45,
        ..Default::default()
    });
    let glass = s.add_material(Material {
        name: "bunny glass".into(),
        color: Vec3::new(0.95, 0.97, 1.0),
        kd: 0.04,
        ks: 0.8,
        shininess: 150.0,
        reflect: 0.08,
        transmit: 0.88,
        ior: 1.5,
        ..Default::default()
    });
    let tinted = s.add_material(Material {
        name: "bunny tinted glass".into(),
        color: Vec3::new(0.7, 0.88, 1.0),
        kd: 0.05,
        ks: 0.8,
        shininess: 150.0,
        reflect: 0.1,
        transmit: 0.85,
        ior: 1.33,
        ..Default::default()
    });
    let stem = s.add_material(Material::diffuse("stem", Vec3::new(0.32, 0.22, 0.1)));
    let leaf = s.add_material(Material {
        name: "leaf".into(),
        color: Vec3::new(0.16, 0.45, 0.1),
        kd: 0.9,
        ks: 0.12,
        shininess: 20.0,
        ..Default::default()
    });
    let leaf2 = s.add_material(Material {
        name: "leaf yellow".into(),
        color: Vec3::new(0.45, 0.55, 0.1),
        kd: 0.9,
        ks: 0.1,
        shininess: 20.0,
        ..Default::default()
    });
    let leaf3 = s.add_material(Material {
        name: "leaf dark".into(),
        color: Vec3::new(0.05, 0.3, 0.12),
        kd: 0.9,
        ks: 0.15,
        shininess: 30.0,
        ..Default::default()
    });

    let bunny = s.add_mesh(asset_mesh("complex", "bunny00.off", glass)?);
    let cow = s.add_mesh(asset_mesh("complex", "cow.off", chrome)?);

    // The board: 8×8-cell patch (4×4 units) → row of 16 → block of 16 rows → 4×4 blocks.
    let patch = s.add_mesh(checkerboard(8, 4.0, 0, dark));
    let row = s.add_group(super::Group { name: "board row".into(), children: vec![] });
    for i in 0..16 {
        s.add_to_group(row, Target::Mesh(patch), Affine3A::from_translation(Vec3::new(2.0 + 4.0 * i as f32, 0.0, 0.0)), None);
    }
    let block = s.add_group(super::Group { name: "board block".into(), children: vec![] });
    for j in 0..16 {
        s.add_to_group(block, Target::Group(row), Affine3A::from_translation(Vec3::new(0.0, 0.0, 2.0 + 4.0 * j as f32)), None);
    }
    let board = s.add_group(super::Group { name: "board".into(), children: vec![] });
    for bi in 0..4 {
        for bj in 0..4 {
            s.add_to_group(
                board,
                Target::Group(block),
                Affine3A::from_translation(Vec3::new(-128.0 + 64.0 * bi as f32, 0.0, -128.0 + 64.0 * bj as f32)),
                None,
            );
        }
    }
    s.instance(Target::Group(board), Affine3A::IDENTITY, None);

    // Plants: three variants → clumps of 6 → fields of 4×4 clumps.
    let plants = [
        s.add_mesh(plant(&PlantParams::shrub(11), stem, leaf)),
        s.add_mesh(plant(&PlantParams::herb(23), stem, leaf2)),
        s.add_mesh(plant(&PlantParams::fern(37), stem, leaf3)),
    ];
    let mut rng = Sampler::new(2003, 0x636f_6d70, 0);
    let mut clumps = Vec::new();
    for c in 0..3u32 {
        let g = s.add_group(super::Group { name: format!("clump {c}"), children: vec![] });
        for k in 0..6u32 {
            let which = plants[((c + k) % 3) as usize];
            let a = std::f32::consts::TAU * (k as f32 + rng.next() * 0.6) / 6.0;
            let r = 0.35 + 0.6 * rng.next();
            let sc = 0.8 + 0.5 * rng.next();
            s.add_to_group(
                g,
                Target::Mesh(which),
                srt(Vec3::splat(sc), rng.next() * std::f32::consts::TAU, Vec3::new(r * a.cos(), 0.0, r * a.sin())),
                None,
            );
        }
        clumps.push(g);
    }
    let field = s.add_group(super::Group { name: "field".into(), children: vec![] });
    for i in 0..4 {
        for j in 0..4 {
            let c = clumps[(rng.next() * 3.0) as usize % 3];
            let t = Vec3::new(-4.5 + 3.0 * i as f32 + rng.next() - 0.5, 0.0, -4.5 + 3.0 * j as f32 + rng.next() - 0.5);
            s.add_to_group(field, Target::Group(c), srt(Vec3::splat(0.9 + 0.3 * rng.next()), rng.next() * std::f32::consts::TAU, t), None);
        }
    }
    for (x, z) in [(-9.0, -2.0), (9.5, -4.0), (-11.0, -16.0), (11.0, -18.0), (-3.0, -30.0), (12.0, -36.0), (-14.0, -44.0), (2.0, -58.0)] {
        s.instance(Target::Group(field), srt(Vec3::ONE, rng.next() * std::f32::consts::TAU, Vec3::new(x, 0.0, z)), None);
    }
    // A hedge of clumps far away across the view, where the plants shrink below a pixel.
    let hedge = s.add_group(super::Group { name: "hedge".into(), children: vec![] });
    for k in 0..7 {
        let c = clumps[k % 3];
        let t = Vec3::new(-18.0 + 6.0 * k as f32 + 2.0 * rng.next(), 0.0, rng.next() * 2.0);
        s.add_to_group(hedge, Target::Group(c), srt(Vec3::splat(1.3), rng.next() * std::f32::consts::TAU, t), None);
    }
    s.instance(Target::Group(hedge), Affine3A::from_translation(Vec3::new(-4.0, 0.0, -80.0)), None);

    // Cows: a herd of 5 (chrome and gold), instanced three times.
    let herd = s.add_group(super::Group { name: "herd".into(), children: vec![] });
    for (k, (x, z, a)) in
        [(0.0, 0.0, 0.3), (2.6, -1.5, -0.6), (-2.4, -2.2, 2.6), (0.8, -4.0, 1.2), (-1.0, 2.4, -2.0)].into_iter().enumerate()
    {
        s.add_to_group(herd, Target::Mesh(cow), srt(Vec3::splat(2.2), a, Vec3::new(x, 0.0, z)), (k % 2 == 1).then_some(gold));
    }
    for (x, z, a) in [(2.5, 2.0, 0.0), (-6.0, -24.0, 1.0), (18.0, -60.0, -0.7)] {
        s.instance(Target::Group(herd), srt(Vec3::ONE, a, Vec3::new(x, 0.0, z)), None);
    }

    // Bunnies: a group of 3 glass bunnies, instanced twice (the far one tinted).
    let bunnies = s.add_group(super::Group { name: "bunnies".into(), children: vec![] });
    for (x, z, a, sc) in [(0.0, 0.0, 1.3, 1.8), (2.8, -2.0, 0.6, 1.4), (-2.5, -1.2, 2.2, 1.2)] {
        s.add_to_group(bunnies, Target::Mesh(bunny), srt(Vec3::splat(sc), a, Vec3::new(x, 0.0, z)), None);
    }
    s.instance(Target::Group(bunnies), srt(Vec3::ONE, 0.0, Vec3::new(-3.0, 0.0, 6.0)), None);
    s.instance(Target::Group(bunnies), srt(Vec3::ONE, 2.0, Vec3::new(4.0, 0.0, -14.0)), Some(tinted));

    s.camera =
        Camera { eye: Vec3::new(0.5, 3.4, 13.5), look: Vec3::new(0.0, 0.3, 0.0), up: Vec3::Y, fovy: 50.0, aperture: 0.0, focal_dist: 13.9 };
    s.lights.push(Light::Ellipse {
        center: Vec3::new(-40.0, 70.0, 45.0),
        axis_a: Vec3::new(4.0, 0.0, 0.0),
        axis_b: Vec3::new(0.0, 0.0, 4.0),
        intensity: Vec3::new(30000.0, 28500.0, 26000.0),
    });
    s.lights.push(Light::Point { pos: Vec3::new(12.0, 10.0, 25.0), intensity: Vec3::new(120.0, 130.0, 150.0) });
    s.background = Vec3::new(0.55, 0.7, 0.95);
    s.ambient = Vec3::splat(0.12);
    Ok(s)
}

/// Test scene for nested instancing: pairs (cube + icosphere) → rings of 6 (alternate pairs
/// with a material override) → towers of 3 rings (the middle ring overridden again, which
/// wins: an outer override replaces inner ones) → three towers (one rotated about a tilted
/// axis, one non-uniformly scaled) on a checkerboard. About 5,000 triangles.
pub fn instanced() -> Scene {
    let mut s = Scene::empty("instanced");
    s.materials[0] = Material::diffuse("white", Vec3::splat(0.8));
    let dark = s.add_material(Material::diffuse("dark", Vec3::splat(0.1)));
    let red = s.add_material(Material {
        name: "red".into(),
        color: Vec3::new(0.8, 0.1, 0.1),
        kd: 0.8,
        ks: 0.4,
        shininess: 40.0,
        ..Default::default()
    });
    let blue = s.add_material(Material {
        name: "blue mirror".into(),
        color: Vec3::new(0.2, 0.3, 0.9),
        kd: 0.5,
        ks: 0.5,
        shininess: 60.0,
        reflect: 0.4,
        ..Default::default()
    });
    let glass = s.add_material(Material {
        name: "glass".into(),
        color: Vec3::ONE,
        kd: 0.05,
        ks: 0.7,
        shininess: 100.0,
        reflect: 0.1,
        transmit: 0.85,
        ior: 1.5,
        ..Default::default()
    });
    let board = s.add_mesh(checkerboard(8, 16.0, 0, dark));
    let cube = s.add_mesh(cube_mesh(0));
    let ico = s.add_mesh(icosphere(1, 0));
    let pair = s.add_group(super::Group { name: "pair".into(), children: vec![] });
    s.add_to_group(
        pair,
        Target::Mesh(cube),
        Affine3A::from_scale_rotation_translation(
            Vec3::splat(0.3),
            Quat::from_rotation_x(0.5) * Quat::from_rotation_z(0.3),
            Vec3::new(-0.45, 0.3, 0.0),
        ),
        None,
    );
    s.add_to_group(
        pair,
        Target::Mesh(ico),
        Affine3A::from_scale_rotation_translation(Vec3::new(0.35, 0.45, 0.35), Quat::IDENTITY, Vec3::new(0.45, 0.45, 0.0)),
        None,
    );
    let ring = s.add_group(super::Group { name: "ring".into(), children: vec![] });
    for k in 0..6 {
        let a = std::f32::consts::TAU * k as f32 / 6.0;
        let xf = Affine3A::from_rotation_y(a) * Affine3A::from_translation(Vec3::new(2.0, 0.0, 0.0));
        s.add_to_group(ring, Target::Group(pair), xf, (k % 2 == 1).then_some(red));
    }
    let tower = s.add_group(super::Group { name: "tower".into(), children: vec![] });
    for k in 0..3 {
        let xf = srt(Vec3::splat(1.0 - 0.25 * k as f32), 0.25 * k as f32, Vec3::new(0.0, 1.0 * k as f32, 0.0));
        s.add_to_group(tower, Target::Group(ring), xf, (k == 1).then_some(blue));
    }
    s.add_to_group(
        tower,
        Target::Mesh(ico),
        Affine3A::from_scale_rotation_translation(Vec3::splat(0.6), Quat::IDENTITY, Vec3::new(0.0, 0.6, 0.0)),
        Some(glass),
    );
    s.instance(Target::Mesh(board), Affine3A::IDENTITY, None);
    s.instance(Target::Group(tower), Affine3A::IDENTITY, None);
    s.instance(
        Target::Group(tower),
        Affine3A::from_translation(Vec3::new(-4.5, 1.2, -3.5))
            * Affine3A::from_axis_angle(Vec3::new(1.0, 1.0, 0.0).normalize(), 0.6)
            * Affine3A::from_scale(Vec3::splat(0.6)),
        None,
    );
    s.instance(
        Target::Group(tower),
        Affine3A::from_translation(Vec3::new(4.5, 0.0, -3.0)) * Affine3A::from_scale(Vec3::new(0.5, 1.4, 0.8)),
        Some(dark),
    );
    s.camera = Camera {
        eye: Vec3::new(0.0, 5.0, 11.0),
        look: Vec3::new(0.0, 1.0, -1.0),
        up: Vec3::Y,
        fovy: 45.0,
        aperture: 0.0,
        focal_dist: 11.0,
    };
    s.lights.push(Light::Point { pos: Vec3::new(5.0, 9.0, 6.0), intensity: Vec3::splat(120.0) });
    s.lights.push(Light::Ellipse {
        center: Vec3::new(-6.0, 8.0, 2.0),
        axis_a: Vec3::new(1.0, 0.0, 0.0),
        axis_b: Vec3::new(0.0, 0.0, 0.5),
        intensity: Vec3::splat(60.0),
    });
    s.background = Vec3::new(0.4, 0.5, 0.7);
    s.ambient = Vec3::splat(0.06);
    s
}
