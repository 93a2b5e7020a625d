//! The scene model: SoA meshes, materials (Wand & Straßer §3), point and elliptical area
//! lights, the camera of DESIGN.md, and hierarchical instancing.
//!
//! Instancing: a [`Group`] holds [`Instance`]s, each referring to a mesh or to another group
//! with an affine transform and an optional material override. The hierarchy is kept as
//! written; for the intersectors it is resolved into a list of *leaf instances* (mesh +
//! composed transform), never into copied triangles. Debian's Embree 3.13.5 is built with one
//! instance level, so both back-ends use this two-level (TLAS over leaf instances, BLAS per
//! unique mesh) form; memory stays O(unique triangles + instances).

pub mod builtin;
pub mod camera;
pub mod load;
pub mod lodscenes;
pub mod mesh;
pub mod tomlscene;

pub use camera::Camera;
pub use mesh::Mesh;

use crate::error::{Error, Result};
use glam::{Affine3A, Vec3};
use serde::{Deserialize, Serialize};

/// Surface material, with the properties of Wand & Straßer §3: colour, Phong parameters,
/// reflectivity, transparency, index of refraction and roughness.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Material {
    pub name: String,
    /// Diffuse albedo (linear RGB).
    pub color: Vec3,
    /// Diffuse weight.
    pub kd: f32,
    /// Specular (Phong highlight) weight.
    pub ks: f32,
    /// Phong exponent.
    pub shininess: f32,
    /// Mirror reflectivity in \[0, 1\].
    pub reflect: f32,
    /// Transparency (refracted fraction) in \[0, 1\].
    pub transmit: f32,
    /// Index of refraction of the inside.
    pub ior: f32,
    /// Surface roughness: the half-angle (radians) of the cone of glossy reflection.
    pub roughness: f32,
}

impl Default for Material {
    fn default() -> Self {
        Material {
            name: "default".into(),
            color: Vec3::splat(0.7),
            kd: 1.0,
            ks: 0.0,
            shininess: 32.0,
            reflect: 0.0,
            transmit: 0.0,
            ior: 1.5,
            roughness: 0.0,
        }
    }
}

impl Material {
    pub fn diffuse(name: &str, color: Vec3) -> Self {
        Material { name: name.into(), color, ..Default::default() }
    }
    pub fn validate(&self) -> Result<()> {
        let big = [self.color.max_element(), self.kd, self.ks, self.shininess].into_iter().fold(0.0f32, f32::max);
        if big > MAX_SHADING_VALUE {
            return Err(Error::Scene(format!(
                "material '{}': a colour, kd, ks or shininess of {big:e} is beyond {MAX_SHADING_VALUE:e} (the shaded radiance would overflow)",
                self.name
            )));
        }
        let ok = self.color.is_finite()
            && self.color.min_element() >= 0.0
            && [self.kd, self.ks, self.shininess, self.reflect, self.transmit, self.roughness].iter().all(|v| v.is_finite() && *v >= 0.0)
            && self.ior.is_finite()
            && self.ior > 0.0
            && self.reflect <= 1.0
            && self.transmit <= 1.0;
        if !ok {
            return Err(Error::Scene(format!("material '{}' has out-of-range values", self.name)));
        }
        // Total internal reflection hands the transmitted share to the mirror ray, so a sum
        // above one would make a surface brighter than what it reflects.
        if self.reflect + self.transmit > 1.0 {
            return Err(Error::Scene(format!(
                "material '{}': reflect {} + transmit {} exceeds 1 (the surface would create light)",
                self.name, self.reflect, self.transmit
            )));
        }
        Ok(())
    }
}

/// Light sources. Intensities are radiant intensity (W/sr, per RGB channel); irradiance at
/// distance d is `intensity · cosθ / d²`. An elliptical light is a disc of isotropic
/// point emitters with that total intensity, spread uniformly over the ellipse
/// `centre + a·cos φ·r + b·sin φ·r` (r ≤ 1); the Whitted tracer uses its centre.
#[derive(Clone, Debug, PartialEq)]
pub enum Light {
    Point { pos: Vec3, intensity: Vec3 },
    Ellipse { center: Vec3, axis_a: Vec3, axis_b: Vec3, intensity: Vec3 },
}

impl Light {
    pub fn center(&self) -> Vec3 {
        match self {
            Light::Point { pos, .. } => *pos,
            Light::Ellipse { center, .. } => *center,
        }
    }
    pub fn intensity(&self) -> Vec3 {
        match self {
            Light::Point { intensity, .. } | Light::Ellipse { intensity, .. } => *intensity,
        }
    }
    /// A point on the light for the 2D sample (u, v) (uniform over the ellipse's area).
    pub fn sample(&self, u: f32, v: f32) -> Vec3 {
        match self {
            Light::Point { pos, .. } => *pos,
            Light::Ellipse { center, axis_a, axis_b, .. } => {
                let (x, y) = crate::core::rng::concentric_disk(u, v);
                *center + *axis_a * x + *axis_b * y
            }
        }
    }
}

/// What an instance refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target {
    Mesh(u32),
    Group(u32),
}

#[derive(Clone, Debug)]
pub struct Instance {
    pub target: Target,
    pub xform: Affine3A,
    /// Replaces the materials of everything below this instance.
    pub material: Option<u32>,
}

#[derive(Clone, Debug, Default)]
pub struct Group {
    pub name: String,
    pub children: Vec<Instance>,
}

/// An instance of a unique mesh with its composed transform, as the intersectors see it.
#[derive(Clone, Debug)]
pub struct LeafInstance {
    pub mesh: u32,
    pub xform: Affine3A,
    pub inv: Affine3A,
    /// Inverse-transpose of the linear part, for normals.
    pub normal_mat: glam::Mat3A,
    pub material: Option<u32>,
}

/// Upper limit of the instances (leaves and groups) a scene's hierarchy may resolve to: each
/// leaf costs a few hundred bytes in every tracer, and a file of nested groups that each hold
/// two of the level below asks for 2^depth of them (40 levels filled 10 GB before this
/// limit). `complex` resolves to about 5,000.
pub const MAX_INSTANCE_VISITS: u64 = 1 << 22;

/// Upper limit of a scene's recursion depth (`--max-depth`, bench `depth=`, a scene file's
/// `max_depth`). A glass object splits every ray in two at each depth, and the conventional
/// tracers have no importance cut-off (the baseline as the papers describe it), so their ray
/// tree grows about 1.6× per level on the built-in glass scenes: at 64 a thumbnail of
/// `cabinet` did not finish in a minute, at 16 it takes 0.03 s.
pub const MAX_DEPTH: u32 = 16;

/// Deepest nesting of instance groups (a deeper chain is refused, not recursed into).
pub const MAX_NESTING: u32 = 64;

/// Largest coordinate a scene or camera may have. Embree rejects rays whose origin lies
/// beyond ±1.8e18 (an assertion that aborts the process), and at such magnitudes f32 has
/// no precision left for hit offsets anyway.
pub const MAX_COORD: f32 = 1e15;

/// Largest coordinate a ray origin may reach in an instance's own space (Embree aborts beyond
/// ±1.8e18; see [`Scene::check_ray_reach`]).
pub const MAX_LOCAL_COORD: f32 = 1e18;

/// Upper limit of a material's colour, kd, ks and shininess: with [`MAX_INTENSITY`] the
/// shaded radiance stays far inside f32 (a colour of 1e38 lit by 1e38 wrote +inf pixels).
pub const MAX_SHADING_VALUE: f32 = 1e6;

/// Upper limit of a light's intensity and of the background and ambient colours.
pub const MAX_INTENSITY: f32 = 1e15;

#[derive(Clone, Debug)]
pub struct Scene {
    pub name: String,
    pub meshes: Vec<Mesh>,
    pub groups: Vec<Group>,
    /// The root group.
    pub root: u32,
    pub materials: Vec<Material>,
    pub lights: Vec<Light>,
    pub camera: Camera,
    pub background: Vec3,
    /// Constant ambient term added to every diffuse surface (× albedo).
    pub ambient: Vec3,
    /// Maximum recursion depth for reflection and refraction (at most [`MAX_DEPTH`]).
    pub max_depth: u32,
    /// Lights are tested for visibility (shadow rays and cones); off (`render --no-shadows`,
    /// a diagnostic) every light counts as visible.
    pub shadows: bool,
}

impl Scene {
    pub fn empty(name: &str) -> Self {
        Scene {
            name: name.into(),
            meshes: vec![],
            groups: vec![Group { name: "root".into(), children: vec![] }],
            root: 0,
            materials: vec![Material::default()],
            lights: vec![],
            camera: Camera::default(),
            background: Vec3::new(0.05, 0.05, 0.08),
            ambient: Vec3::splat(0.03),
            max_depth: 5,
            shadows: true,
        }
    }
    pub fn add_material(&mut self, m: Material) -> u32 {
        self.materials.push(m);
        (self.materials.len() - 1) as u32
    }
    pub fn add_mesh(&mut self, m: Mesh) -> u32 {
        self.meshes.push(m);
        (self.meshes.len() - 1) as u32
    }
    pub fn add_group(&mut self, g: Group) -> u32 {
        self.groups.push(g);
        (self.groups.len() - 1) as u32
    }
    /// Adds an instance to the root group.
    pub fn instance(&mut self, target: Target, xform: Affine3A, material: Option<u32>) {
        let root = self.root as usize;
        self.groups[root].children.push(Instance { target, xform, material });
    }
    pub fn add_to_group(&mut self, group: u32, target: Target, xform: Affine3A, material: Option<u32>) {
        self.groups[group as usize].children.push(Instance { target, xform, material });
    }

    /// Resolves the instance hierarchy into leaf instances (mesh + composed transform).
    /// Fails on cycles (depth > 64), dangling references, and hierarchies that resolve to
    /// more than [`MAX_INSTANCE_VISITS`] instances.
    pub fn leaf_instances(&self) -> Result<Vec<LeafInstance>> {
        let mut out = Vec::new();
        let mut budget = MAX_INSTANCE_VISITS;
        self.collect(self.root, Affine3A::IDENTITY, None, 0, &mut out, &mut budget)?;
        Ok(out)
    }

    fn collect(&self, g: u32, xf: Affine3A, mat: Option<u32>, depth: u32, out: &mut Vec<LeafInstance>, budget: &mut u64) -> Result<()> {
        if depth > MAX_NESTING {
            return Err(Error::Scene(format!("instance hierarchy nests deeper than {MAX_NESTING} levels")));
        }
        let group = self.groups.get(g as usize).ok_or_else(|| Error::Scene(format!("group {g} does not exist")))?;
        for inst in &group.children {
            if *budget == 0 {
                return Err(Error::Scene(format!(
                    "the instance hierarchy resolves to more than {MAX_INSTANCE_VISITS} instances (nested groups multiply)"
                )));
            }
            *budget -= 1;
            let x = xf * inst.xform;
            let m = mat.or(inst.material);
            match inst.target {
                Target::Mesh(id) => {
                    let mesh = self.meshes.get(id as usize).ok_or_else(|| Error::Scene(format!("mesh {id} does not exist")))?;
                    if mesh.tris.is_empty() {
                        continue;
                    }
                    let det = x.matrix3.determinant();
                    if !det.is_finite() || det.abs() < 1e-30 {
                        return Err(Error::Scene(format!(
                            "instance of '{}' has a singular or overflowing transform (determinant {det:e})",
                            mesh.name
                        )));
                    }
                    out.push(LeafInstance {
                        mesh: id,
                        xform: x,
                        inv: x.inverse(),
                        normal_mat: x.matrix3.inverse().transpose(),
                        material: m,
                    });
                }
                Target::Group(id) => self.collect(id, x, m, depth + 1, out, budget)?,
            }
        }
        Ok(())
    }

    /// Triangles after instancing (what the renderer sees) and unique triangles (what memory holds).
    pub fn triangle_counts(&self) -> Result<(u64, u64)> {
        let leaves = self.leaf_instances()?;
        let inst: u64 = leaves.iter().map(|l| self.meshes[l.mesh as usize].tri_count() as u64).sum();
        let uniq: u64 = self.meshes.iter().map(|m| m.tri_count() as u64).sum();
        Ok((inst, uniq))
    }

    /// World-space bounds of all instanced geometry.
    pub fn bounds(&self) -> Result<(Vec3, Vec3)> {
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        let mut cache: Vec<Option<(Vec3, Vec3)>> = vec![None; self.meshes.len()];
        for l in self.leaf_instances()? {
            let (a, b) = *cache[l.mesh as usize].get_or_insert_with(|| self.meshes[l.mesh as usize].bounds());
            for i in 0..8 {
                let c =
                    Vec3::new(if i & 1 == 0 { a.x } else { b.x }, if i & 2 == 0 { a.y } else { b.y }, if i & 4 == 0 { a.z } else { b.z });
                let w = l.xform.transform_point3(c);
                lo = lo.min(w);
                hi = hi.max(w);
            }
        }
        Ok((lo, hi))
    }

    /// Errors when an instance is smaller than 1e-4 × |p| at its position (the relative part
    /// of the hit-point offset until stop 77, 25× `SURFACE_EPS_REL` now): such an instance has lost its shape to
    /// f32 rounding (a unit cube translated to 1e8 collapses to a point, f32's spacing there
    /// is 8) or shadows itself wrongly; before stop 57 it rendered as nothing with exit 0.
    /// The bare-mesh loader applies a stricter bound of its own (ten offsets).
    fn check_instance_scales(&self) -> Result<()> {
        let mut cache: Vec<Option<(Vec3, Vec3)>> = vec![None; self.meshes.len()];
        for l in self.leaf_instances()? {
            let mesh = &self.meshes[l.mesh as usize];
            if mesh.tri_count() == 0 {
                continue;
            }
            let (a, b) = *cache[l.mesh as usize].get_or_insert_with(|| mesh.bounds());
            let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
            for i in 0..8 {
                let c = Vec3::select(glam::BVec3::new(i & 1 != 0, i & 2 != 0, i & 4 != 0), b, a);
                let w = l.xform.transform_point3(c);
                (lo, hi) = (lo.min(w), hi.max(w));
            }
            let far = lo.abs().max(hi.abs()).max_element();
            let size = (hi - lo).length();
            // The relative part only: a whole scene at a tiny scale near the origin is the
            // intersectors' business (`verify` checks them at 1e-6), the absolute part of the
            // offset its renderers' (the bare-mesh loader refuses such a mesh).
            if !(size >= 1e-4 * far) {
                return Err(Error::Scene(format!(
                    "an instance of mesh '{}' spans only {size:.3e} units at coordinates up to {far:.3e}: smaller than the ray offsets that far out (1e-4 × its largest coordinate); move it nearer the origin or scale it up",
                    mesh.name
                )));
            }
        }
        Ok(())
    }

    /// Errors when a ray could reach an instance with an origin beyond ±[`MAX_LOCAL_COORD`] in
    /// the instance's own coordinates. Rays start at the camera (its eye, ± the lens) or at a
    /// hit point inside the scene's bounds; Embree moves every ray that enters an instance's
    /// bounds into the instance's space and aborts the process (an assertion) when the origin
    /// lies beyond ±1.8e18 there. Each coordinate is bounded by the row sums of the inverse
    /// transform, so the check is conservative. A very uneven scale (`[1e-11, 1e11, 1]`:
    /// determinant 1, each axis above the 1e-12 floor) or an eye far from a small instance
    /// crossed it (the C++ assertion, exit 134, before this check).
    pub fn check_ray_reach(&self) -> Result<()> {
        let leaves = self.leaf_instances()?;
        if leaves.is_empty() {
            return Ok(());
        }
        let (lo, hi) = self.bounds()?;
        let cam = self.camera.eye.abs().max_element() as f64 + self.camera.aperture.max(0.0) as f64;
        let reach = (lo.abs().max(hi.abs()).max_element() as f64).max(cam);
        for l in &leaves {
            let (m, t) = (l.inv.matrix3, l.inv.translation);
            let local = (0..3)
                .map(|i| {
                    let row = m.row(i);
                    (row.x.abs() as f64 + row.y.abs() as f64 + row.z.abs() as f64) * reach + (t[i].abs() as f64)
                })
                .fold(0.0f64, f64::max);
            if !(local <= MAX_LOCAL_COORD as f64) {
                return Err(Error::Scene(format!(
                    "an instance of mesh '{}' would see rays from up to {reach:.3e} (the camera and the scene's extent) at {local:.3e} in its own coordinates, beyond ±{MAX_LOCAL_COORD:e}: its scale is too small (or too uneven) for that distance; scale it up, or bring the camera nearer",
                    self.meshes[l.mesh as usize].name
                )));
            }
        }
        Ok(())
    }

    /// Checks the scene is renderable: has geometry, materials in range, finite values.
    pub fn validate(&mut self) -> Result<()> {
        for m in &self.materials {
            m.validate()?;
        }
        let nmat = self.materials.len() as u32;
        for mesh in &mut self.meshes {
            if let Some(bad) = mesh.mat.iter().find(|&&m| m >= nmat) {
                return Err(Error::Scene(format!("mesh '{}' uses material {bad}, but there are only {nmat}", mesh.name)));
            }
            let nv = mesh.vertex_count() as u32;
            if mesh.tris.iter().any(|t| t.iter().any(|&i| i >= nv)) {
                return Err(Error::Scene(format!("mesh '{}' has a face index out of range", mesh.name)));
            }
            if !mesh.has_normals() {
                mesh.compute_normals();
            }
        }
        let (inst, _) = self.triangle_counts()?;
        if inst == 0 {
            return Err(Error::Scene(format!("scene '{}' has no triangles", self.name)));
        }
        let (lo, hi) = self.bounds()?;
        let ext = lo.abs().max(hi.abs()).max_element();
        if ext.is_nan() || ext > MAX_COORD {
            return Err(Error::Scene(format!(
                "scene '{}' reaches coordinate {ext:.3e}, beyond ±{MAX_COORD:e}: scale the model down",
                self.name
            )));
        }
        self.check_instance_scales()?;
        self.camera.validate()?;
        self.check_ray_reach()?;
        for (what, c) in [("background", self.background), ("ambient", self.ambient)] {
            if !c.is_finite() || c.abs().max_element() > MAX_INTENSITY {
                return Err(Error::Scene(format!("{what} {c} is not finite or beyond {MAX_INTENSITY:e}")));
            }
        }
        // Counted from 1, as the TOML scene's `[[lights]]` entries are named.
        for (i, l) in (1..).zip(self.lights.iter()) {
            if !l.center().is_finite() || !l.intensity().is_finite() {
                return Err(Error::Scene(format!("light {i} has non-finite values")));
            }
            if l.intensity().abs().max_element() > MAX_INTENSITY {
                return Err(Error::Scene(format!(
                    "light {i}: intensity {:e} is beyond {MAX_INTENSITY:e} (the shaded radiance would overflow)",
                    l.intensity().abs().max_element()
                )));
            }
            if let Light::Ellipse { axis_a, axis_b, .. } = l {
                // Shadow cones aim at the ellipse's Gaussian (§4.2): zero or parallel axes
                // give it no area, and the distributed sampler a zero-area light.
                if !axis_a.is_finite() || !axis_b.is_finite() {
                    return Err(Error::Scene(format!("light {i} has non-finite axes")));
                }
                // In f64: the f32 cross product of axes ~1e20 long overflows.
                let (a, b) = (axis_a.as_dvec3(), axis_b.as_dvec3());
                if !(a.cross(b).length() > 1e-6 * a.length() * b.length()) {
                    return Err(Error::Scene(format!(
                        "light {i}: an elliptical light needs two non-zero, non-parallel axes (a point light has none)"
                    )));
                }
            }
        }
        Ok(())
    }

    /// The scene's materials, lights, camera and settings with no meshes and an empty root.
    pub fn clone_without_geometry(&self) -> Scene {
        Scene {
            name: self.name.clone(),
            meshes: Vec::new(),
            groups: vec![Group { name: "root".into(), children: Vec::new() }],
            root: 0,
            materials: self.materials.clone(),
            lights: self.lights.clone(),
            camera: self.camera.clone(),
            background: self.background,
            ambient: self.ambient,
            max_depth: self.max_depth,
            shadows: self.shadows,
        }
    }

    /// Memory held by the unique meshes (bytes).
    pub fn mesh_bytes(&self) -> usize {
        self.meshes.iter().map(|m| m.memory_bytes()).sum()
    }
}
