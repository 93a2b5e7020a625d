//! Animation sequences (Adams et al. §5): the paper's four built-ins and a default motion for
//! any mesh, all deterministic (fixed-order simulation, hashed initial conditions), with a
//! recording format so benches replay identical frames.
//!
//! | name            | paper                         | here                                              |
//! |-----------------|-------------------------------|---------------------------------------------------|
//! | `armadillo-ball`| armadillo hit by a cannon ball| `assets/armadillo.off` (or `opts.armadillo`), soft, on a floor; a stiff heavy ball shot at its chest |
//! | `bend`          | goblin on the parallel bars   | a goblin built from round cones (`character`), in support on parallel bars, swinging with a 105° pike at the hips; a skeleton drives the soft body through its rest shape |
//! | `heads`         | three bouncing CSG heads      | three heads, each a sphere cut by two planes = three surfaces with clipping relations, bouncing on a floor and off each other |
//! | `elastic-balls` | 40 balls into a hollow cube   | 40 soft balls (one shared model, 40 instances) thrown into a hollow cube |
//! | `from_mesh`     | –                             | any mesh, normalised to height 1, dropped onto a floor, deforming on impact |
//!
//! Simulation nodes: for analytic solids a lattice inside the solid; for meshes the
//! centroids of a voxel clustering of the surfels (a shell — the MLS gradient uses a
//! pseudo-inverse for it, see `displace`). Counts are scaled by `SequenceOptions::detail`
//! (1.0 ≈ the paper's Table 1: armadillo 170k surfels / ~450 nodes, balls 6k / ~90 nodes).

use super::object::{ObjectParams, SurfelObject};
use super::sim::{Body, BodyParams, Collider, World};
use super::surfel::{disc_surfels, sample_mesh, sphere_surfels, surfels_from_mesh_vertices, SurfelModel, SurfelSoa};
use super::trace::DeformScene;
use super::DeformError;
use crate::core::rng::Sampler;
use crate::scene::{Camera, Mesh};
use glam::Vec3;
use std::path::PathBuf;
use std::sync::Arc;

/// Options of the built-in sequences.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SequenceOptions {
    /// Scales surfel and node counts (1.0 ≈ paper sizes; tests use ~0.02–0.1).
    pub detail: f32,
    /// Armadillo mesh for `armadillo-ball` (default: `armadillo.off` in
    /// [`assets_dir`](crate::scene::builtin::assets_dir), which honours `LODTRACE_ASSETS` as
    /// `lodtrace animate` does).
    pub armadillo: PathBuf,
    /// For meshes: `None` = one surfel per vertex when the mesh has at least the target count
    /// of vertices, else area samples; `Some(n)` = exactly n area samples (about).
    pub mesh_surfels: Option<usize>,
    /// Simulation nodes for a mesh (scaled by detail^(1/2), at least 24).
    pub mesh_nodes: usize,
    pub object: ObjectParams,
    pub seed: u32,
}

impl Default for SequenceOptions {
    fn default() -> Self {
        SequenceOptions {
            detail: 1.0,
            // Not a bare "assets/armadillo.off": that ignored LODTRACE_ASSETS, and run from a
            // folder without ./assets (a git worktree) `armadillo-ball` failed to load
            // (review, stop 80: test `simulation_energy_bounded`).
            armadillo: crate::scene::builtin::assets_dir().join("armadillo.off"),
            mesh_surfels: None,
            mesh_nodes: 450,
            object: ObjectParams::default(),
            seed: 0,
        }
    }
}

/// Node positions of every body in one frame.
pub type FrameNodes = Vec<Vec<Vec3>>;

/// Recorded frames (node positions per body), for replay.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Recording {
    pub name: String,
    pub dt: f32,
    pub frames: Vec<FrameNodes>,
}

/// A deforming scene and its simulation.
pub struct Sequence {
    pub name: String,
    /// Objects and instances for [`DeformTracer::new`](super::DeformTracer::new); body b of
    /// the world is instance b.
    pub scene: DeformScene,
    pub world: World,
    /// Frames advanced so far.
    pub frame: u32,
    /// Suggested length.
    pub frames: u32,
    /// Suggested camera.
    pub camera: Camera,
    /// The point light (`lodtrace animate` shading). It lies on the free side of every plane
    /// collider: the walls of a hollow box are seen through from outside (a cut-away), but
    /// they do shadow, so a light outside them would leave the inside unlit
    /// ([`Sequence::light_is_free`]).
    pub light: Vec3,
}

impl Sequence {
    /// Whether the light lies on the free side of every plane collider (strictly), so that
    /// no wall of the scene stands between it and the whole inside.
    pub fn light_is_free(&self) -> bool {
        self.world.colliders.iter().all(|c| match *c {
            Collider::Plane { n, d } => self.light.dot(n) > d,
            _ => true,
        })
    }

    pub const BUILTIN: [&'static str; 4] = ["armadillo-ball", "bend", "heads", "elastic-balls"];

    /// One of [`Sequence::BUILTIN`].
    pub fn builtin(name: &str, opts: &SequenceOptions) -> Result<Sequence, DeformError> {
        if !(opts.detail.is_finite() && opts.detail > 0.0 && opts.detail <= 10.0) {
            return Err(DeformError::Invalid(format!("detail {} out of range (0, 10]", opts.detail)));
        }
        match name {
            "armadillo-ball" => armadillo_ball(opts),
            "bend" => bend(opts),
            "heads" => heads(opts),
            "elastic-balls" => elastic_balls(opts),
            _ => Err(DeformError::UnknownSequence(name.to_string())),
        }
    }

    /// The default motion for any mesh: normalised to height 1 (flat meshes: longest side
    /// 2), dropped from 0.5 above a floor, soft, deforming on impact.
    pub fn from_mesh(mesh: &Mesh, opts: &SequenceOptions) -> Result<Sequence, DeformError> {
        let name = if mesh.name.is_empty() { "mesh" } else { &mesh.name };
        Ok(Self::dropped(name, mesh_object(mesh, opts, 1.0, Vec3::new(0.0, 0.5, 0.0))?))
    }

    /// A point file's surfels (§3: surfel models read from point files) dropped onto a
    /// floor like [`Sequence::from_mesh`]; the file's radii are kept (scaled with the model).
    pub fn from_points(model: SurfelModel, opts: &SequenceOptions) -> Result<Sequence, DeformError> {
        let name = model.collections.first().map(|c| c.name.clone()).unwrap_or_else(|| "points".into());
        let file = model.surfels.positions();
        let (lo, hi) = file.iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
        let (sc, shift) = placement(lo, hi, 1.0, Vec3::new(0.0, 0.5, 0.0));
        let obj = surfel_object(&name, model.surfels, opts, 1.0, Vec3::new(0.0, 0.5, 0.0)).map_err(|e| match e {
            // Distinct in the file (its own duplicates are refused when it is read), but one
            // f32 position once scaled and moved into the scene: say how close is too close.
            DeformError::DuplicatePoint { a, b } => {
                let at = file[a] * sc + shift;
                let ulp = at.abs().max_element();
                let ulp = f32::from_bits(ulp.to_bits() + 1) - ulp;
                DeformError::Invalid(format!(
                    "'{name}': surfels {a} and {b} are {:.3e} apart, closer than f32 can tell apart once the model is scaled to the sequence's size (about {:.1e} in the file's units there); merge them or drop one",
                    (file[a] - file[b]).length(),
                    ulp / sc
                ))
            }
            e => e,
        })?;
        Ok(Self::dropped(&name, obj))
    }

    fn dropped(name: &str, (obj, nodes, radius): (Arc<SurfelObject>, Vec<Vec3>, f32)) -> Sequence {
        let mut world = World::new(1.0 / 30.0, 4);
        world.colliders.push(Collider::Plane { n: Vec3::Y, d: 0.0 });
        let n = nodes.len();
        // Stiff enough that a mesh keeps its shape after the impact (0.15 with 16-node
        // clusters let a bunny slump into a pancake; measured by eye on assets/bunny00.off).
        world.bodies.push(Body::new(
            nodes,
            vec![1.0; n],
            radius,
            BodyParams { stiffness: 0.8, beta: 0.05, cluster_size: 64, ..Default::default() },
        ));
        Sequence {
            name: name.into(),
            scene: DeformScene { objects: vec![obj], instances: vec![0] },
            world,
            frame: 0,
            frames: 60,
            // Aimed at the middle of the drop (the model spans 0.5–1.5 above the floor at the
            // start, 0–1 at rest): aimed at 0.5, a cube's top front edge sat on the image's
            // top row in the first frames.
            camera: cam(Vec3::new(0.0, 1.15, 3.2), Vec3::new(0.0, 0.75, 0.0), 40.0),
            light: shoulder_light(Vec3::new(0.0, 1.15, 3.2), Vec3::new(0.0, 0.75, 0.0)),
        }
    }

    /// Node positions now.
    pub fn current(&self) -> FrameNodes {
        self.world.positions()
    }

    /// Advances one frame and returns the node positions.
    pub fn step(&mut self) -> FrameNodes {
        self.world.step_frame();
        self.frame += 1;
        self.current()
    }

    /// Records `frames` frames: the current state, then `frames − 1` steps.
    pub fn record(&mut self, frames: u32) -> Result<Recording, DeformError> {
        self.record_with(frames, || {})
    }

    /// [`Sequence::record`], calling `tick` after each frame (a progress bar: a long
    /// sequence simulates for minutes before its first frame is traced).
    pub fn record_with(&mut self, frames: u32, mut tick: impl FnMut()) -> Result<Recording, DeformError> {
        if frames == 0 {
            return Err(DeformError::ZeroFrames);
        }
        let mut v = vec![self.current()];
        tick();
        for _ in 1..frames {
            v.push(self.step());
            tick();
        }
        Ok(Recording { name: self.name.clone(), dt: self.world.dt, frames: v })
    }
}

/// A light above and a little behind the right shoulder of a camera at `eye` looking at `look`
/// (up +y).
fn shoulder_light(eye: Vec3, look: Vec3) -> Vec3 {
    let d = look - eye;
    let right = d.cross(Vec3::Y).normalize_or_zero();
    eye + d * 0.3 + Vec3::Y * d.length() * 0.8 + right * d.length() * 0.4
}

fn cam(eye: Vec3, look: Vec3, fovy: f32) -> Camera {
    Camera { eye, look, up: Vec3::Y, fovy, aperture: 0.0, focal_dist: (look - eye).length() }
}

/// Lattice points inside a solid (about `target` of them) and the lattice spacing.
fn lattice_nodes(inside: &dyn Fn(Vec3) -> bool, lo: Vec3, hi: Vec3, target: usize) -> (Vec<Vec3>, f32) {
    let ext = hi - lo;
    let mut s = (ext.x * ext.y * ext.z / target.max(1) as f32).cbrt();
    let mut best = (Vec::new(), s);
    for _ in 0..6 {
        let n = ((ext / s).ceil().as_ivec3()).max(glam::IVec3::ONE);
        let off = (ext - n.as_vec3() * s) * 0.5 + Vec3::splat(0.5 * s);
        let mut pts = Vec::new();
        for k in 0..n.z {
            for j in 0..n.y {
                for i in 0..n.x {
                    let p = lo + off + Vec3::new(i as f32, j as f32, k as f32) * s;
                    if inside(p) {
                        pts.push(p);
                    }
                }
            }
        }
        let c = pts.len();
        best = (pts, s);
        if c == 0 {
            s *= 0.5;
            continue;
        }
        let ratio = c as f32 / target as f32;
        if (0.8..1.25).contains(&ratio) {
            break;
        }
        s *= ratio.cbrt();
    }
    best
}

/// Voxel clustering of surface points into about `target` node positions (cell centroids),
/// with the cell size.
fn cluster_nodes(pts: &[Vec3], target: usize) -> (Vec<Vec3>, f32) {
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for p in pts {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let ext = (hi - lo).max(Vec3::splat(1e-6));
    let area_guess = 2.0 * (ext.x * ext.y + ext.y * ext.z + ext.z * ext.x);
    let mut s = (area_guess / target.max(1) as f32).sqrt();
    let mut best = (Vec::new(), s);
    for _ in 0..8 {
        let mut cells: std::collections::BTreeMap<(i32, i32, i32), (Vec3, u32)> = Default::default();
        for p in pts {
            let k = ((*p - lo) / s).floor().as_ivec3();
            let e = cells.entry((k.x, k.y, k.z)).or_insert((Vec3::ZERO, 0));
            e.0 += *p;
            e.1 += 1;
        }
        let nodes: Vec<Vec3> = cells.values().map(|(sum, c)| *sum / *c as f32).collect();
        let ratio = nodes.len() as f32 / target as f32;
        best = (nodes, s);
        if (0.85..1.18).contains(&ratio) {
            break;
        }
        s *= ratio.sqrt();
    }
    best
}

/// Mesh → surfel object normalised to `height`, bottom centre at `base`; returns the object,
/// its node positions (world = reference here) and the node collision radius.
fn mesh_object(mesh: &Mesh, opts: &SequenceOptions, height: f32, base: Vec3) -> Result<(Arc<SurfelObject>, Vec<Vec3>, f32), DeformError> {
    let target = ((170_000.0 * opts.detail) as usize).max(200);
    let s = match opts.mesh_surfels {
        Some(n) => sample_mesh(mesh, n, opts.seed)?,
        None => {
            let v = surfels_from_mesh_vertices(mesh)?;
            if v.len() * 5 >= target * 4 {
                v
            } else {
                sample_mesh(mesh, target, opts.seed)?
            }
        }
    };
    // Samples of one mesh coincide only when f32 cannot tell them apart: parts tiny against
    // the whole (two unit tetrahedra 1e6 apart). The file holds no duplicate to point at.
    surfel_object(&mesh.name, s, opts, height, base).map_err(|e| match e {
        DeformError::DuplicatePoint { .. } => DeformError::TooSmall(format!(
            "{}: parts of the mesh are tiny against the whole (surfels sampled from them fall on one f32 position once the model is scaled to the sequence's size)",
            mesh.name
        )),
        e => e,
    })
}

/// The scale and shift that place points of the box `lo`..`hi` in a sequence
/// (`p · sc + shift`): the larger of (height, half the longest side) becomes `height` (tall
/// objects get exactly this height, flat ones are not blown up), the bottom centre goes to
/// `base`.
fn placement(lo: Vec3, hi: Vec3, height: f32, base: Vec3) -> (f32, Vec3) {
    let ext = hi - lo;
    let sc = height / ext.y.max(0.5 * ext.max_element()).max(1e-20);
    (sc, base - Vec3::new(0.5 * (lo.x + hi.x), lo.y, 0.5 * (lo.z + hi.z)) * sc)
}

/// A model spanning `lo..hi` is large enough for f32 (at least 1e-6 × (1 + its largest
/// coordinate)). The model is rescaled later ([`placement`]), but its surfel radii and
/// neighbourhoods are measured in its own units, where squared distances of a 1e-30-sized
/// model underflow f32 (stop 46's sweep: NaN radius ratios and a garbage frame, exit 0).
pub(crate) fn check_extent(name: &str, lo: Vec3, hi: Vec3) -> Result<(), DeformError> {
    let far = lo.abs().max(hi.abs()).max_element();
    let size = (hi - lo).max_element();
    if !(size >= 1e-6 * (1.0 + far)) {
        return Err(DeformError::Invalid(format!(
            "'{name}' spans only {size:.3e} units at coordinates up to {far:.3e}: too small for f32 (at least 1e-6 × (1 + its largest coordinate)); scale it up"
        )));
    }
    Ok(())
}

/// A surfel set (sampled from a mesh or read from a point file) scaled to `height`, standing
/// on `base`, with simulation nodes clustered from its surfels.
fn surfel_object(
    name: &str,
    mut s: SurfelSoa,
    opts: &SequenceOptions,
    height: f32,
    base: Vec3,
) -> Result<(Arc<SurfelObject>, Vec<Vec3>, f32), DeformError> {
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for i in 0..s.len() {
        lo = lo.min(s.pos(i));
        hi = hi.max(s.pos(i));
    }
    check_extent(name, lo, hi)?;
    let (sc, shift) = placement(lo, hi, height, base);
    for i in 0..s.len() {
        let p = s.pos(i) * sc + shift;
        s.px[i] = p.x;
        s.py[i] = p.y;
        s.pz[i] = p.z;
        s.r[i] *= sc;
    }
    let n_nodes = ((opts.mesh_nodes as f32 * opts.detail.sqrt()) as usize).max(24);
    let (nodes, cell) = cluster_nodes(&s.positions(), n_nodes);
    let model = SurfelModel::single(name, s, [0.75, 0.72, 0.68]);
    let m = vec![1.0; nodes.len()];
    let obj = SurfelObject::build(model, nodes.clone(), m, &opts.object)?;
    Ok((obj, nodes, 0.5 * cell))
}

fn scaled(n: f32, detail: f32, min: usize) -> usize {
    ((n * detail) as usize).max(min)
}

fn ball_object(
    opts: &SequenceOptions,
    r: f32,
    surfels: usize,
    nodes: usize,
    color: [f32; 3],
) -> Result<(Arc<SurfelObject>, Vec<Vec3>, f32), DeformError> {
    let s = sphere_surfels(Vec3::ZERO, r, surfels);
    let (nd, sp) = lattice_nodes(&|p: Vec3| p.length() <= r * 0.92, Vec3::splat(-r), Vec3::splat(r), nodes);
    let obj = SurfelObject::build(SurfelModel::single("ball", s, color), nd.clone(), vec![1.0; nd.len()], &opts.object)?;
    Ok((obj, nd, 0.5 * sp + 0.08 * r))
}

fn armadillo_ball(opts: &SequenceOptions) -> Result<Sequence, DeformError> {
    let mesh = crate::scene::load::load_mesh(&opts.armadillo, 0)?;
    let (arm, arm_nodes, arm_r) = mesh_object(&mesh, opts, 1.6, Vec3::ZERO)?;
    let (ball, ball_nodes, ball_r) =
        ball_object(opts, 0.22, scaled(6000.0, opts.detail, 300), scaled(88.0, opts.detail.sqrt(), 20), [0.15, 0.15, 0.17])?;
    let mut world = World::new(1.0 / 30.0, 4);
    world.colliders.push(Collider::Plane { n: Vec3::Y, d: 0.0 });
    let na = arm_nodes.len();
    world.bodies.push(Body::new(
        arm_nodes,
        vec![1.0; na],
        arm_r,
        BodyParams { stiffness: 0.2, beta: 0.3, friction: 0.6, ..Default::default() },
    ));
    let start = Vec3::new(0.25, 1.1, 2.6);
    let bx: Vec<Vec3> = ball_nodes.iter().map(|p| *p + start).collect();
    let nb = bx.len();
    let mut b = Body::new(bx, vec![8.0; nb], ball_r, BodyParams { stiffness: 1.0, beta: 0.0, cluster_size: 0, ..Default::default() });
    // Aimed at the chest (x ≈ 0, y ≈ 1.0, z ≈ 0): flight time ~0.35 s.
    b.set_velocity(Vec3::new(-0.7, 1.2, -7.5));
    world.bodies.push(b);
    Ok(Sequence {
        name: "armadillo-ball".into(),
        scene: DeformScene { objects: vec![arm, ball], instances: vec![0, 1] },
        world,
        frame: 0,
        frames: 90,
        camera: cam(Vec3::new(2.6, 1.3, 3.0), Vec3::new(0.0, 0.8, 0.0), 40.0),
        light: shoulder_light(Vec3::new(2.6, 1.3, 3.0), Vec3::new(0.0, 0.8, 0.0)),
    })
}

/// `bend`: the goblin ([`super::character`]) in support on the parallel bars, swinging
/// about its shoulders with a pike of up to 105° at the hips in the front swing (the
/// "large bend"), one swing in 2 s. Paper sizes (Table 1): 100k surfels, 502 nodes.
fn bend(opts: &SequenceOptions) -> Result<Sequence, DeformError> {
    use super::character::{swing_skin, Bone, Goblin, HAND_X, HAND_Y};
    const BAR: f32 = 1.55;
    let g = Goblin::new();
    let place = Vec3::new(0.0, BAR - HAND_Y, 0.0);
    let mut surf = g.surfels(scaled(100_000.0, opts.detail, 400), opts.seed);
    for i in 0..surf.len() {
        surf.py[i] += place.y;
    }
    let (rest, sp) = g.nodes(scaled(500.0, opts.detail.sqrt(), 60));
    let nodes: Vec<Vec3> = rest.iter().map(|p| *p + place).collect();
    let obj =
        SurfelObject::build(SurfelModel::single("goblin", surf, [0.45, 0.6, 0.35]), nodes.clone(), vec![1.0; nodes.len()], &opts.object)?;
    let nn = nodes.len();
    let skin = swing_skin(&g, &rest, place, 2.0, 0.3);
    // The arms hold the body up on the rails: nodes mostly on an arm, shoulder to hand, follow
    // the skeleton exactly (the hands do not move; near the shoulder the torso blends in).
    let arms: Vec<u32> = (0..nn as u32)
        .filter(|&j| {
            let b = skin.bones[j as usize][0];
            b == Bone::ArmL as u16 || b == Bone::ArmR as u16
        })
        .collect();
    let mut body = Body::new(
        nodes,
        vec![1.0; nn],
        0.5 * sp,
        BodyParams { stiffness: 0.5, beta: 0.0, cluster_size: 12, damping: 0.01, ..Default::default() },
    );
    body.drive(skin);
    body.pin(&arms);
    let mut world = World::new(1.0 / 30.0, 4);
    world.bodies.push(body);
    world.colliders.push(Collider::Plane { n: Vec3::Y, d: 0.0 });
    // The parallel bars: two rails under the hands on four posts.
    for s in [-1.0f32, 1.0] {
        let x = HAND_X * s;
        world.colliders.push(Collider::Box { lo: Vec3::new(x - 0.025, BAR - 0.05, -1.1), hi: Vec3::new(x + 0.025, BAR, 1.1) });
        for z in [-0.9f32, 0.9] {
            world.colliders.push(Collider::Box { lo: Vec3::new(x - 0.02, 0.0, z - 0.02), hi: Vec3::new(x + 0.02, BAR - 0.05, z + 0.02) });
        }
    }
    let (eye, look) = (Vec3::new(2.5, 2.0, 1.1), Vec3::new(0.0, 1.45, 0.0));
    Ok(Sequence {
        name: "bend".into(),
        scene: DeformScene { objects: vec![obj], instances: vec![0] },
        world,
        frame: 0,
        frames: 90,
        camera: cam(eye, look, 45.0),
        light: shoulder_light(eye, look),
    })
}

/// A head of three surfaces: sphere (radius `r`) ∩ {y > −0.55 r} ∩ {z < 0.75 r}.
fn head_model(r: f32, n: usize) -> (SurfelModel, Box<dyn Fn(Vec3) -> bool + Sync>) {
    let mut m = SurfelModel::default();
    let sph = sphere_surfels(Vec3::ZERO, r, n);
    let spacing = (4.0 * std::f32::consts::PI / n as f32).sqrt() * r;
    m.add_collection("skull", &sph, [0.85, 0.7, 0.6]);
    m.add_collection("neck-cut", &disc_surfels(Vec3::new(0.0, -0.55 * r, 0.0), -Vec3::Y, 0.95 * r, spacing), [0.8, 0.3, 0.25]);
    m.add_collection("face-cut", &disc_surfels(Vec3::new(0.0, 0.0, 0.75 * r), Vec3::Z, 0.8 * r, spacing), [0.3, 0.4, 0.8]);
    m.clip = vec![(0, 1), (0, 2), (1, 2)];
    let inside = move |p: Vec3| p.length() <= r * 0.93 && p.y > -0.5 * r && p.z < 0.7 * r;
    (m, Box::new(inside))
}

fn heads(opts: &SequenceOptions) -> Result<Sequence, DeformError> {
    let r = 0.35;
    let (model, inside) = head_model(r, scaled(60_000.0, opts.detail, 400));
    let (nodes, sp) = lattice_nodes(&*inside, Vec3::splat(-r), Vec3::splat(r), scaled(250.0, opts.detail.sqrt(), 30));
    let obj = SurfelObject::build(model, nodes.clone(), vec![1.0; nodes.len()], &opts.object)?;
    let mut world = World::new(1.0 / 30.0, 4);
    world.colliders.extend(Collider::hollow_box(Vec3::new(-1.5, 0.0, -1.5), Vec3::new(1.5, 4.0, 1.5), false));
    let starts = [Vec3::new(-0.6, 1.0, 0.0), Vec3::new(0.1, 1.6, 0.2), Vec3::new(0.7, 2.3, -0.1)];
    let spins = [0.4f32, -0.9, 1.3];
    for (k, (st, sp_ang)) in starts.iter().zip(spins).enumerate() {
        let q = glam::Quat::from_rotation_y(sp_ang) * glam::Quat::from_rotation_x(0.3 * k as f32);
        let x: Vec<Vec3> = nodes.iter().map(|p| q * *p + *st).collect();
        let n = x.len();
        let mut b = Body::new(x, vec![1.0; n], 0.5 * sp, BodyParams { stiffness: 0.35, beta: 0.2, restitution: 0.6, ..Default::default() });
        b.set_velocity(Vec3::new(0.3 - 0.3 * k as f32, 0.0, 0.2));
        world.bodies.push(b);
    }
    Ok(Sequence {
        name: "heads".into(),
        scene: DeformScene { objects: vec![obj], instances: vec![0, 0, 0] },
        world,
        frame: 0,
        frames: 90,
        camera: cam(Vec3::new(0.0, 1.3, 3.6), Vec3::new(0.0, 0.6, 0.0), 45.0),
        // Above the open top of the box, towards the camera: inside the walls' x and z range, so
        // no wall lies between it and anything inside.
        light: Vec3::new(0.8, 5.5, 0.9),
    })
}

fn elastic_balls(opts: &SequenceOptions) -> Result<Sequence, DeformError> {
    let r = 0.22;
    let (obj, nodes, nr) = ball_object(opts, r, scaled(6000.0, opts.detail, 300), scaled(88.0, opts.detail.sqrt(), 20), [0.8, 0.25, 0.2])?;
    let mut world = World::new(1.0 / 30.0, 4);
    world.colliders.extend(Collider::hollow_box(Vec3::new(-1.2, 0.0, -1.2), Vec3::new(1.2, 3.0, 1.2), false));
    for k in 0..40u32 {
        let mut smp = Sampler::new(opts.seed, k, 7);
        let c = Vec3::new(-0.9 + 0.6 * (k % 4) as f32, 1.2 + 0.5 * (k / 16) as f32, -0.9 + 0.6 * ((k / 4) % 4) as f32)
            + Vec3::new(smp.next() - 0.5, smp.next() - 0.5, smp.next() - 0.5) * 0.06;
        let x: Vec<Vec3> = nodes.iter().map(|p| *p + c).collect();
        let n = x.len();
        let mut b = Body::new(x, vec![1.0; n], nr, BodyParams { stiffness: 0.3, beta: 0.2, restitution: 0.5, ..Default::default() });
        b.set_velocity(Vec3::new(smp.next() * 2.0 - 1.0, smp.next() * 1.5, smp.next() * 2.0 - 1.0) * 2.0);
        world.bodies.push(b);
    }
    Ok(Sequence {
        name: "elastic-balls".into(),
        scene: DeformScene { objects: vec![obj], instances: vec![0; 40] },
        world,
        frame: 0,
        frames: 90,
        camera: cam(Vec3::new(0.0, 3.2, 4.2), Vec3::new(0.0, 0.8, 0.0), 45.0),
        // Above the open top of the box, towards the camera (as for `heads`).
        light: Vec3::new(0.6, 4.6, 0.8),
    })
}

/// Heads of three surfaces as a stand-alone model (for tests and demos): the surfel model
/// and an inside test of the solid.
pub fn csg_head(radius: f32, sphere_surfels: usize) -> (SurfelModel, Box<dyn Fn(Vec3) -> bool + Sync>) {
    head_model(radius, sphere_surfels)
}

/// Lattice simulation nodes inside a solid (about `target`), and their spacing.
pub fn nodes_inside(inside: &dyn Fn(Vec3) -> bool, lo: Vec3, hi: Vec3, target: usize) -> (Vec<Vec3>, f32) {
    lattice_nodes(inside, lo, hi, target)
}
