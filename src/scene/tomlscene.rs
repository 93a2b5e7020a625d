//! TOML scene files: materials, meshes (files or built-in generators), instance groups,
//! root instances, lights, camera. See `scenes/example.toml` for a complete example.
//!
//! ```toml
//! name = "example"            # optional; default: the file's stem
//! background = [0.5, 0.6, 0.8] # a colour is [r, g, b] or one number (grey); default dark blue
//! ambient = 0.05              # constant ambient term (× albedo); default 0.03
//! max_depth = 5               # reflection/refraction recursion limit (0..=16); default 5
//!
//! [camera]                    # optional; without it the scene is framed automatically
//! eye = [0, 2, 8]             # required in [camera]
//! look = [0, 0.5, 0]          # required in [camera]
//! up = [0, 1, 0]              # default +y
//! fovy = 45                   # vertical field of view, degrees; default 45
//! aperture = 0                # lens radius (0 = pinhole); default 0
//! focal_dist = 8              # default: |look - eye|
//!
//! [materials.chrome]          # Wand & Straßer §3 properties; every field optional,
//! color = [0.8, 0.8, 0.85]    # defaults as `Material::default()`:
//! kd = 0.3                    # color 0.7, kd 1, ks 0, shininess 32, reflect 0,
//! ks = 0.8                    # transmit 0, ior 1.5, roughness 0.
//! shininess = 80              # A material named "default" replaces the grey material
//! reflect = 0.6               # that meshes without a `material` use.
//! transmit = 0.0
//! ior = 1.5
//! roughness = 0.0             # glossy cone half-angle, radians
//!
//! [meshes.cow]
//! file = "../assets/cow.off"  # .off or .obj (with its MTL materials), relative to this file
//! material = "chrome"         # optional: material of all its triangles
//! normalize = true            # optional (any mesh): fit into a unit box, base on y = 0
//!
//! [meshes.board]
//! generator = "checkerboard"  # sphere | icosphere | cube | quad | checkerboard | plant
//! n = 16                      # checkerboard: cells per side (default 8)
//! size = 16.0                 # checkerboard: side length, centred at the origin (default 8)
//! material = "white"          # checkerboard: first colour
//! material_b = "black"        # checkerboard: second colour; plant: leaves
//! # sphere: stacks (default 32), slices (default 64), radius 1 at the origin
//! # icosphere: level (default 3), radius 1
//! # cube: [-1,1]^3; quad: [0,1]^2 in the xz-plane, normal +y
//! # plant: kind = "shrub" | "herb" | "fern" (default shrub), seed (default 0)
//!
//! [[groups.herd.instances]]   # a group: a list of instances
//! target = "cow"              # a mesh or a group name (meshes and groups share one namespace)
//! translate = [2, 0, 0]       # transform = translate · rotate · scale (scale applied first)
//! rotate = [0, 45, 0]         # degrees: Euler [x, y, z] (x applied first, then y, then z),
//!                             # or { axis = [0, 1, 0], angle = 45 }
//! scale = 2.0                 # one number or [x, y, z] (non-zero)
//! material = "gold"           # optional override for everything below this instance
//!                             # (an outer override wins over inner ones)
//!
//! [[instances]]               # the root group's instances, same fields
//! target = "herd"
//!
//! [[lights]]
//! type = "point"
//! pos = [5, 10, 5]
//! intensity = 200             # radiant intensity, W/sr: one number or [r, g, b]
//!
//! [[lights]]
//! type = "ellipse"            # a disc of emitters: center + a·x + b·y, x² + y² ≤ 1
//! center = [-4, 8, 5]
//! axis_a = [0.8, 0, 0]
//! axis_b = [0, 0, 0.8]
//! intensity = [90, 85, 80]
//! ```
//!
//! Unknown fields are errors everywhere (`deny_unknown_fields`), as are unknown material, mesh
//! and group names, name clashes between meshes and groups, cycles among groups, non-finite or
//! out-of-range numbers and unreadable mesh files. Every error is an [`Error::Parse`] naming
//! this file (and the line and column, for syntax errors), in one line.
//!
//! Choice: maps are read as sorted maps, so material and mesh indices follow name order, not
//! file order; nothing depends on that order except the index numbers in `--stats`.

use super::{builtin, Camera, Group, Instance, Light, Material, Scene, Target};
use crate::error::{Error, Result};
use glam::{Affine3A, Quat, Vec3};
use serde::Deserialize;
use std::collections::{BTreeMap, HashMap, HashSet};
use std::path::{Path, PathBuf};

/// What makes two instances of a group exact copies: the target, the transform's bits and
/// the material override.
fn instance_key(target: Target, xform: &Affine3A, material: Option<u32>) -> (bool, u32, [u32; 12], Option<u32>) {
    let (group, id) = match target {
        Target::Mesh(m) => (false, m),
        Target::Group(g) => (true, g),
    };
    (group, id, xform.to_cols_array().map(f32::to_bits), material)
}

// ---------------------------------------------------------------- the file's schema

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct FileDef {
    name: Option<String>,
    background: Option<Vec3Def>,
    ambient: Option<Vec3Def>,
    max_depth: Option<u32>,
    camera: Option<CameraDef>,
    #[serde(default)]
    materials: BTreeMap<String, MaterialDef>,
    #[serde(default)]
    meshes: BTreeMap<String, MeshDef>,
    #[serde(default)]
    groups: BTreeMap<String, GroupDef>,
    #[serde(default)]
    instances: Vec<InstanceDef>,
    #[serde(default)]
    lights: Vec<LightDef>,
}

/// A vector given as `[x, y, z]` or as one number (all three components).
#[derive(Deserialize, Debug, Clone, Copy)]
#[serde(untagged, expecting = "a number or an array of three numbers")]
enum Vec3Def {
    One(f32),
    Three([f32; 3]),
}

impl Vec3Def {
    fn get(self) -> Vec3 {
        match self {
            Vec3Def::One(v) => Vec3::splat(v),
            Vec3Def::Three(v) => Vec3::from(v),
        }
    }
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct CameraDef {
    eye: [f32; 3],
    look: [f32; 3],
    up: Option<[f32; 3]>,
    fovy: Option<f32>,
    aperture: Option<f32>,
    focal_dist: Option<f32>,
}

#[derive(Deserialize, Debug, Default)]
#[serde(deny_unknown_fields)]
struct MaterialDef {
    color: Option<Vec3Def>,
    kd: Option<f32>,
    ks: Option<f32>,
    shininess: Option<f32>,
    reflect: Option<f32>,
    transmit: Option<f32>,
    ior: Option<f32>,
    roughness: Option<f32>,
}

#[derive(Deserialize, Debug, Default)]
#[serde(deny_unknown_fields)]
struct MeshDef {
    file: Option<String>,
    generator: Option<String>,
    material: Option<String>,
    material_b: Option<String>,
    normalize: Option<bool>,
    n: Option<u32>,
    size: Option<f32>,
    stacks: Option<u32>,
    slices: Option<u32>,
    level: Option<u32>,
    kind: Option<String>,
    seed: Option<u32>,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct GroupDef {
    instances: Vec<InstanceDef>,
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct InstanceDef {
    target: String,
    translate: Option<[f32; 3]>,
    rotate: Option<RotateDef>,
    scale: Option<Vec3Def>,
    material: Option<String>,
}

#[derive(Deserialize, Debug)]
#[serde(untagged, expecting = "rotate: Euler angles [x, y, z] in degrees, or { axis = [x, y, z], angle = degrees }")]
enum RotateDef {
    Euler([f32; 3]),
    AxisAngle(AxisAngleDef),
}

#[derive(Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct AxisAngleDef {
    axis: [f32; 3],
    angle: f32,
}

#[derive(Deserialize, Debug)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
enum LightDef {
    Point { pos: [f32; 3], intensity: Vec3Def },
    Ellipse { center: [f32; 3], axis_a: [f32; 3], axis_b: [f32; 3], intensity: Vec3Def },
}

// ---------------------------------------------------------------- loading

/// Memory a TOML scene takes while parsed, per byte of its text (the text, toml's document
/// and the scene's definitions): a 22 MB file of 300k instances peaked at 834 MB for the
/// whole render (`/usr/bin/time -f %M`, stop 82), most of it the parse.
const TOML_BYTES_PER_BYTE: u64 = 32;

/// Loads a TOML scene file (format in the module header). Mesh files are resolved relative
/// to the TOML file's folder. The scene is validated; every error names `path`.
pub fn load(path: &Path) -> Result<Scene> {
    crate::error::check_input_read(path, TOML_BYTES_PER_BYTE)?;
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    from_str(&text, path)
}

/// The mesh files a TOML scene names (resolved like [`load`]), so that no output of a run
/// overwrites one; empty when the file cannot be read or parsed (loading reports that).
pub fn referenced_files(path: &Path) -> Vec<std::path::PathBuf> {
    if crate::error::check_input_read(path, TOML_BYTES_PER_BYTE).is_err() {
        return Vec::new();
    }
    let Ok(text) = std::fs::read_to_string(path) else { return Vec::new() };
    let Ok(def) = toml::from_str::<FileDef>(&text) else { return Vec::new() };
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    def.meshes.values().filter_map(|m| m.file.as_ref().map(|f| dir.join(f))).collect()
}

/// Parses TOML scene text as if read from `path` (for messages and relative mesh paths).
pub fn from_str(text: &str, path: &Path) -> Result<Scene> {
    let def: FileDef = toml::from_str(text).map_err(|e| Error::parse(path, syntax_message(text, &e)))?;
    let mut b = Builder { path, dir: path.parent().map(Path::to_path_buf).unwrap_or_default() };
    let mut scene = b.build(def)?;
    scene.validate().map_err(|e| b.err(e.to_string()))?;
    Ok(scene)
}

/// One line: "line L, column C: message" (toml's own rendering spans several lines).
fn syntax_message(text: &str, e: &toml::de::Error) -> String {
    let msg = e.message().split_whitespace().collect::<Vec<_>>().join(" ");
    match e.span() {
        Some(sp) => {
            let start = sp.start.min(text.len());
            let before = &text[..start];
            let line = before.matches('\n').count() + 1;
            let col = before.rsplit('\n').next().map(|l| l.chars().count()).unwrap_or(0) + 1;
            format!("line {line}, column {col}: {msg}")
        }
        None => msg,
    }
}

struct Builder<'a> {
    path: &'a Path,
    dir: PathBuf,
}

/// Lists names for "unknown name" messages (at most 12).
fn list(names: impl Iterator<Item = String>) -> String {
    let v: Vec<String> = names.collect();
    if v.is_empty() {
        return "none defined".into();
    }
    let mut s = v.iter().take(12).cloned().collect::<Vec<_>>().join(", ");
    if v.len() > 12 {
        s += &format!(", ... ({} in all)", v.len());
    }
    s
}

impl Builder<'_> {
    fn err(&self, msg: impl Into<String>) -> Error {
        Error::parse(self.path, msg.into())
    }
    fn finite(&self, v: f32, what: &str) -> Result<f32> {
        if v.is_finite() {
            Ok(v)
        } else {
            Err(self.err(format!("{what} must be a finite number, not {v}")))
        }
    }
    fn vec3(&self, v: [f32; 3], what: &str) -> Result<Vec3> {
        if v.iter().all(|x| x.is_finite()) {
            Ok(Vec3::from(v))
        } else {
            Err(self.err(format!("{what} must be three finite numbers, not {v:?}")))
        }
    }
    fn vec3d(&self, v: Vec3Def, what: &str) -> Result<Vec3> {
        let v = v.get();
        self.vec3(v.to_array(), what)
    }
    fn colour(&self, v: Vec3Def, what: &str) -> Result<Vec3> {
        let c = self.vec3d(v, what)?;
        if c.min_element() < 0.0 {
            return Err(self.err(format!("{what} must not be negative, not {c}")));
        }
        Ok(c)
    }

    fn build(&mut self, def: FileDef) -> Result<Scene> {
        let name = def.name.clone().unwrap_or_else(|| super::load::stem_name(self.path, "scene"));
        // `bench` and `demo` name their files after the scene: "../x" wrote outside `--out`,
        // a newline split the summary line (stop 46's sweep).
        if name.is_empty() || name == "." || name == ".." || name.chars().any(|c| c == '/' || c == '\\' || c.is_control()) {
            return Err(self.err(format!("name {name:?} must be a plain file name (no '/', '\\', control characters, '.' or '..')")));
        }
        let mut s = Scene::empty(&name);
        if let Some(v) = def.background {
            s.background = self.colour(v, "background")?;
        }
        if let Some(v) = def.ambient {
            s.ambient = self.colour(v, "ambient")?;
        }
        if let Some(d) = def.max_depth {
            if d > super::MAX_DEPTH {
                return Err(self.err(format!("max_depth {d} is out of range (0..={})", super::MAX_DEPTH)));
            }
            s.max_depth = d;
        }

        // Materials by name; "default" replaces material 0.
        let mut mats: HashMap<String, u32> = HashMap::new();
        mats.insert("default".into(), 0);
        for (mname, md) in &def.materials {
            let m = self.material(mname, md)?;
            let id = if mname == "default" {
                s.materials[0] = m;
                0
            } else {
                s.add_material(m)
            };
            mats.insert(mname.clone(), id);
        }
        let mat_of = |b: &Self, name: &str, whose: &str| -> Result<u32> {
            mats.get(name)
                .copied()
                .ok_or_else(|| b.err(format!("{whose}: unknown material '{name}' (materials: {})", list(def.materials.keys().cloned()))))
        };

        // Meshes.
        let mut targets: HashMap<String, Target> = HashMap::new();
        for (mname, md) in &def.meshes {
            let whose = format!("mesh '{mname}'");
            let mat = md.material.as_deref().map(|n| mat_of(self, n, &whose)).transpose()?;
            let mat_b = md.material_b.as_deref().map(|n| mat_of(self, n, &whose)).transpose()?;
            let mut mesh = self.mesh(mname, md, mat, mat_b, &mut s)?;
            mesh.name = mname.clone();
            if md.normalize == Some(true) {
                builtin::normalize_mesh(&mut mesh);
            }
            let id = s.add_mesh(mesh);
            targets.insert(mname.clone(), Target::Mesh(id));
        }

        // Groups: allocate first (groups may refer to groups defined later), then fill.
        let mut group_ids = Vec::new();
        for gname in def.groups.keys() {
            if targets.contains_key(gname) {
                return Err(self.err(format!("the name '{gname}' is both a mesh and a group")));
            }
            let id = s.add_group(Group { name: gname.clone(), children: vec![] });
            targets.insert(gname.clone(), Target::Group(id));
            group_ids.push(id);
        }
        let known = |b: &Self, name: &str, whose: &str| -> Result<Target> {
            targets.get(name).copied().ok_or_else(|| {
                b.err(format!(
                    "{whose}: unknown target '{name}' (meshes: {}; groups: {})",
                    list(def.meshes.keys().cloned()),
                    list(def.groups.keys().cloned())
                ))
            })
        };
        // Exact copies of an instance within one group (same target, transform and material)
        // add nothing to the image, only time: 10,000 copies of a quad took the cone tracers'
        // build 30 s and their render about a second per 50 pixels. Dropped with a warning,
        // as a mesh's copies of a triangle are.
        let mut copies = 0usize;
        for ((gname, gd), &gid) in def.groups.iter().zip(&group_ids) {
            let mut seen = HashSet::new();
            for (k, inst) in gd.instances.iter().enumerate() {
                let whose = format!("group '{gname}', instance {}", k + 1);
                let target = known(self, &inst.target, &whose)?;
                let material = inst.material.as_deref().map(|n| mat_of(self, n, &whose)).transpose()?;
                let xform = self.transform(inst, &whose)?;
                if !seen.insert(instance_key(target, &xform, material)) {
                    copies += 1;
                    continue;
                }
                s.groups[gid as usize].children.push(Instance { target, xform, material });
            }
        }
        self.check_cycles(&s, &group_ids)?;
        let mut seen = HashSet::new();
        for (k, inst) in def.instances.iter().enumerate() {
            let whose = format!("instance {}", k + 1);
            let target = known(self, &inst.target, &whose)?;
            let material = inst.material.as_deref().map(|n| mat_of(self, n, &whose)).transpose()?;
            let xform = self.transform(inst, &whose)?;
            if !seen.insert(instance_key(target, &xform, material)) {
                copies += 1;
                continue;
            }
            s.instance(target, xform, material);
        }
        if copies > 0 {
            crate::error::warn(format!(
                "{}: skipped {copies} exact cop{} of an instance (the same target, transform and material as another in its group)",
                self.path.display(),
                if copies == 1 { "y" } else { "ies" }
            ));
        }
        if def.instances.is_empty() {
            return Err(self.err("no [[instances]]: the root group is empty, nothing would be rendered"));
        }

        for (k, l) in def.lights.iter().enumerate() {
            let whose = format!("light {}", k + 1);
            let light = match *l {
                LightDef::Point { pos, intensity } => Light::Point {
                    pos: self.vec3(pos, &format!("{whose}: pos"))?,
                    intensity: self.colour(intensity, &format!("{whose}: intensity"))?,
                },
                LightDef::Ellipse { center, axis_a, axis_b, intensity } => Light::Ellipse {
                    center: self.vec3(center, &format!("{whose}: center"))?,
                    axis_a: self.vec3(axis_a, &format!("{whose}: axis_a"))?,
                    axis_b: self.vec3(axis_b, &format!("{whose}: axis_b"))?,
                    intensity: self.colour(intensity, &format!("{whose}: intensity"))?,
                },
            };
            s.lights.push(light);
        }

        s.camera = match &def.camera {
            Some(c) => {
                let eye = self.vec3(c.eye, "camera: eye")?;
                let look = self.vec3(c.look, "camera: look")?;
                let cam = Camera {
                    eye,
                    look,
                    up: c.up.map(|u| self.vec3(u, "camera: up")).transpose()?.unwrap_or(Vec3::Y),
                    fovy: c.fovy.map(|v| self.finite(v, "camera: fovy")).transpose()?.unwrap_or(45.0),
                    aperture: c.aperture.map(|v| self.finite(v, "camera: aperture")).transpose()?.unwrap_or(0.0),
                    focal_dist: c.focal_dist.map(|v| self.finite(v, "camera: focal_dist")).transpose()?.unwrap_or((look - eye).length()),
                };
                // Camera::validate's message already starts with "camera:".
                cam.validate().map_err(|e| self.err(e.to_string().trim_start_matches("invalid option: ").to_string()))?;
                cam
            }
            None => {
                let (lo, hi) = s.bounds().map_err(|e| self.err(e.to_string()))?;
                if !lo.is_finite() || !hi.is_finite() {
                    return Err(self.err("no [camera] and the scene's bounds are empty or not finite"));
                }
                super::load::frame_bounds(lo, hi, 45.0)
            }
        };
        Ok(s)
    }

    fn material(&self, name: &str, d: &MaterialDef) -> Result<Material> {
        let base = Material::default();
        let whose = |f: &str| format!("material '{name}': {f}");
        let unit = |v: Option<f32>, dflt: f32, f: &str, max: f32| -> Result<f32> {
            let Some(v) = v else { return Ok(dflt) };
            if !(v.is_finite() && v >= 0.0 && v <= max) {
                let range = if max.is_finite() { format!("0..={max}") } else { "≥ 0".into() };
                return Err(self.err(format!("{} = {v} is out of range ({range})", whose(f))));
            }
            Ok(v)
        };
        if d.ior.is_some_and(|v| !(v > 0.0)) {
            return Err(self.err(format!("{} must be positive", whose("ior"))));
        }
        let m = Material {
            name: name.to_string(),
            color: d.color.map(|c| self.colour(c, &whose("color"))).transpose()?.unwrap_or(base.color),
            kd: unit(d.kd, base.kd, "kd", f32::INFINITY)?,
            ks: unit(d.ks, base.ks, "ks", f32::INFINITY)?,
            shininess: unit(d.shininess, base.shininess, "shininess", f32::INFINITY)?,
            reflect: unit(d.reflect, base.reflect, "reflect", 1.0)?,
            transmit: unit(d.transmit, base.transmit, "transmit", 1.0)?,
            ior: unit(d.ior, base.ior, "ior", f32::INFINITY)?,
            roughness: unit(d.roughness, base.roughness, "roughness", f32::INFINITY)?,
        };
        Ok(m)
    }

    fn mesh(&self, name: &str, d: &MeshDef, mat: Option<u32>, mat_b: Option<u32>, s: &mut Scene) -> Result<super::Mesh> {
        let whose = format!("mesh '{name}'");
        let gen = d.generator.as_deref();
        // Which parameters each source accepts (besides material and normalize).
        let given: Vec<&str> = [
            ("material_b", d.material_b.is_some()),
            ("n", d.n.is_some()),
            ("size", d.size.is_some()),
            ("stacks", d.stacks.is_some()),
            ("slices", d.slices.is_some()),
            ("level", d.level.is_some()),
            ("kind", d.kind.is_some()),
            ("seed", d.seed.is_some()),
        ]
        .iter()
        .filter(|(_, g)| *g)
        .map(|(f, _)| *f)
        .collect();
        let allowed: &[&str] = match gen {
            None => &[],
            Some("sphere") => &["stacks", "slices"],
            Some("icosphere") => &["level"],
            Some("cube") | Some("quad") => &[],
            Some("checkerboard") => &["n", "size", "material_b"],
            Some("plant") => &["kind", "seed", "material_b"],
            Some(g) => {
                return Err(self.err(format!("{whose}: unknown generator '{g}' (sphere, icosphere, cube, quad, checkerboard, plant)")))
            }
        };
        if let Some(f) = given.iter().find(|f| !allowed.contains(f)) {
            let src = gen.map(|g| format!("generator '{g}'")).unwrap_or_else(|| "a mesh file".into());
            return Err(self.err(format!("{whose}: '{f}' does not apply to {src}")));
        }
        let m = mat.unwrap_or(0);
        let range = |v: Option<u32>, dflt: u32, lo: u32, hi: u32, f: &str| -> Result<u32> {
            let v = v.unwrap_or(dflt);
            if !(lo..=hi).contains(&v) {
                return Err(self.err(format!("{whose}: {f} = {v} is out of range ({lo}..={hi})")));
            }
            Ok(v)
        };
        match (&d.file, gen) {
            (Some(_), Some(_)) => Err(self.err(format!("{whose}: give either 'file' or 'generator', not both"))),
            (None, None) => Err(self.err(format!("{whose}: needs 'file' or 'generator'"))),
            (Some(f), None) => {
                let p = self.dir.join(f);
                let wrap = |e: Error| self.err(format!("{whose}: {e}"));
                let is_obj = p.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj"));
                if is_obj && mat.is_none() {
                    // OBJ with MTL: its materials are appended after the scene's.
                    let base = s.materials.len() as u32;
                    let (mesh, mtls) = super::load::load_obj_with_materials(&p, base).map_err(wrap)?;
                    for mut mm in mtls {
                        mm.name = format!("{name}/{}", mm.name);
                        s.add_material(mm);
                    }
                    Ok(mesh)
                } else {
                    super::load::load_mesh(&p, m).map_err(wrap)
                }
            }
            (None, Some(g)) => Ok(match g {
                "sphere" => builtin::uv_sphere(range(d.stacks, 32, 2, 2048, "stacks")?, range(d.slices, 64, 3, 4096, "slices")?, m),
                "icosphere" => builtin::icosphere(range(d.level, 3, 0, 7, "level")?, m),
                "cube" => builtin::cube_mesh(m),
                "quad" => builtin::unit_quad(m),
                "checkerboard" => {
                    let size = self.finite(d.size.unwrap_or(8.0), &format!("{whose}: size"))?;
                    if size <= 0.0 {
                        return Err(self.err(format!("{whose}: size must be positive, not {size}")));
                    }
                    builtin::checkerboard(range(d.n, 8, 1, 2048, "n")?, size, m, mat_b.unwrap_or(m))
                }
                "plant" => {
                    let seed = d.seed.unwrap_or(0);
                    let p = match d.kind.as_deref().unwrap_or("shrub") {
                        "shrub" => builtin::PlantParams::shrub(seed),
                        "herb" => builtin::PlantParams::herb(seed),
                        "fern" => builtin::PlantParams::fern(seed),
                        k => return Err(self.err(format!("{whose}: unknown plant kind '{k}' (shrub, herb, fern)"))),
                    };
                    builtin::plant(&p, m, mat_b.unwrap_or(m))
                }
                _ => unreachable!("generator names are checked above"),
            }),
        }
    }

    /// translate · rotate · scale.
    fn transform(&self, d: &InstanceDef, whose: &str) -> Result<Affine3A> {
        let t = d.translate.map(|v| self.vec3(v, &format!("{whose}: translate"))).transpose()?.unwrap_or(Vec3::ZERO);
        let r = match &d.rotate {
            None => Quat::IDENTITY,
            Some(RotateDef::Euler(e)) => {
                let e = self.vec3(*e, &format!("{whose}: rotate"))?;
                Quat::from_rotation_z(e.z.to_radians()) * Quat::from_rotation_y(e.y.to_radians()) * Quat::from_rotation_x(e.x.to_radians())
            }
            Some(RotateDef::AxisAngle(a)) => {
                let axis = self.vec3(a.axis, &format!("{whose}: rotate axis"))?;
                let angle = self.finite(a.angle, &format!("{whose}: rotate angle"))?;
                // Scaled to its largest component first: [1e30, 1e30, 1e30] is a fine axis
                // whose length overflows f32.
                let big = axis.abs().max_element();
                let n = if big > 0.0 { (axis / big).normalize_or_zero() } else { Vec3::ZERO };
                if n == Vec3::ZERO {
                    return Err(self.err(format!("{whose}: rotate axis must not be zero")));
                }
                Quat::from_axis_angle(n, angle.to_radians())
            }
        };
        let sc = d.scale.map(|v| self.vec3d(v, &format!("{whose}: scale"))).transpose()?.unwrap_or(Vec3::ONE);
        if sc.abs().min_element() < 1e-12 {
            return Err(self.err(format!("{whose}: scale must be at least 1e-12 in every axis, not [{:e}, {:e}, {:e}]", sc.x, sc.y, sc.z)));
        }
        Ok(Affine3A::from_scale_rotation_translation(sc, r, t))
    }

    /// Depth-first search over group → group references; reports the first cycle found.
    fn check_cycles(&self, s: &Scene, groups: &[u32]) -> Result<()> {
        // 0 = unseen, 1 = on the stack, 2 = done.
        let mut state = vec![0u8; s.groups.len()];
        fn visit(s: &Scene, g: u32, state: &mut [u8], stack: &mut Vec<u32>) -> Option<Vec<u32>> {
            match state[g as usize] {
                2 => return None,
                1 => {
                    let from = stack.iter().position(|&x| x == g).unwrap_or(0);
                    let mut cyc = stack[from..].to_vec();
                    cyc.push(g);
                    return Some(cyc);
                }
                _ => {}
            }
            // Deeper than the hierarchy may nest (`Scene::collect`): an empty "cycle" says so,
            // before a chain of 100,000 groups overflows this recursion's stack.
            if stack.len() > super::MAX_NESTING as usize {
                return Some(Vec::new());
            }
            state[g as usize] = 1;
            stack.push(g);
            for inst in &s.groups[g as usize].children {
                if let Target::Group(c) = inst.target {
                    if let Some(cyc) = visit(s, c, state, stack) {
                        return Some(cyc);
                    }
                }
            }
            stack.pop();
            state[g as usize] = 2;
            None
        }
        for &g in groups {
            let mut stack = Vec::new();
            if let Some(cyc) = visit(s, g, &mut state, &mut stack) {
                if cyc.is_empty() {
                    return Err(self.err(format!("groups nest deeper than {} levels", super::MAX_NESTING)));
                }
                let names: Vec<&str> = cyc.iter().map(|&i| s.groups[i as usize].name.as_str()).collect();
                return Err(self.err(format!("groups refer to each other in a cycle: {}", names.join(" -> "))));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Scene> {
        from_str(text, Path::new("/tmp/t.toml"))
    }

    const MIN: &str = r#"
[meshes.ball]
generator = "icosphere"
level = 1
[[instances]]
target = "ball"
"#;

    #[test]
    fn minimal_scene_loads_and_frames_itself() {
        let s = parse(MIN).unwrap();
        assert_eq!(s.triangle_counts().unwrap(), (80, 80));
        assert_eq!(s.name, "t");
        s.camera.validate().unwrap();
    }

    #[test]
    fn transforms_compose_translate_rotate_scale() {
        let s = parse(
            r#"
[meshes.q]
generator = "quad"
[[instances]]
target = "q"
translate = [1, 2, 3]
rotate = { axis = [0, 1, 0], angle = 90 }
scale = [2, 1, 1]
[[instances]]
target = "q"
rotate = [90, 0, 0]
"#,
        )
        .unwrap();
        let root = &s.groups[s.root as usize];
        let p = root.children[0].xform.transform_point3(Vec3::X);
        assert!((p - Vec3::new(1.0, 2.0, 1.0)).length() < 1e-5, "{p}");
        let p = root.children[1].xform.transform_point3(Vec3::Y);
        assert!((p - Vec3::Z).length() < 1e-5, "{p}");
    }

    #[test]
    fn numbers_accept_integers_and_scalars() {
        let s = parse(&format!("background = 1\nambient = [0, 0, 1]\n{MIN}")).unwrap();
        assert_eq!(s.background, Vec3::ONE);
        assert_eq!(s.ambient, Vec3::Z);
    }

    #[test]
    fn errors_are_one_line_and_name_the_file() {
        let cases = [
            ("colour = 1\n", "unknown field"),
            ("[materials.m]\nkd = nan\n", "kd"),
            ("[materials.m]\nreflect = 2\n", "reflect"),
            ("[meshes.a]\ngenerator = \"teapot\"\n", "teapot"),
            ("[meshes.a]\ngenerator = \"cube\"\nlevel = 2\n", "level"),
            ("[meshes.a]\nfile = \"nope.off\"\n[[instances]]\ntarget = \"a\"\n", "nope.off"),
            ("[meshes.a]\ngenerator = \"cube\"\nmaterial = \"gold\"\n", "gold"),
            ("[meshes.a]\ngenerator = \"cube\"\n[[instances]]\ntarget = \"b\"\n", "unknown target 'b'"),
            ("[meshes.a]\ngenerator = \"cube\"\n[[instances]]\ntarget = \"a\"\nscale = 0\n", "scale"),
            ("[meshes.a]\ngenerator = \"cube\"\n[[groups.x.instances]]\ntarget = \"y\"\n[[groups.y.instances]]\ntarget = \"x\"\n[[instances]]\ntarget = \"x\"\n", "cycle"),
            ("[meshes.a]\ngenerator = \"cube\"\n[[groups.a.instances]]\ntarget = \"a\"\n", "both a mesh and a group"),
            ("[meshes.a]\ngenerator = \"cube\"\n", "no [[instances]]"),
            ("[meshes.a]\ngenerator = \"cube\"\n[[instances]]\ntarget = \"a\"\n[[lights]]\ntype = \"spot\"\n", "spot"),
            ("[meshes.a]\ngenerator = \"cube\"\n[[instances]]\ntarget = \"a\"\n[[lights]]\ntype = \"point\"\npos = [0, 1, 0]\nintensity = 1\ncolor = 1\n", "color"),
            ("[meshes.a]\ngenerator = \"cube\"\n[[instances]]\ntarget = \"a\"\n[camera]\neye = [0, 0, 0]\nlook = [0, 0, 0]\n", "camera"),
            ("[meshes.a]\ngenerator = \"cube\"\n[[instances]]\ntarget = \"a\"\nrotate = [1, 2]\n", "rotate"),
            ("max_depth = 1000\n", "max_depth"),
            ("[materials.m]\nior = 0\n", "ior must be positive"),
            ("[materials.m]\nior = -1.5\n", "ior must be positive"),
            ("[meshes.a]\ngenerator = \"cube\"\n[[instances]]\ntarget = \"a\"\nscale = [1e-30, 1, 1]\n", "[1e-30, 1e0, 1e0]"),
            ("[meshes.a\n", "line 1"),
            // A unit cube at 1e8 collapses to a point in f32 (rendered empty, exit 0, before stop 57).
            ("[meshes.a]\ngenerator = \"cube\"\n[[instances]]\ntarget = \"a\"\ntranslate = [1e8, 0, 0]\n", "smaller than the ray offsets"),
        ];
        for (text, needle) in cases {
            let e = parse(text).expect_err(text).to_string();
            assert!(e.starts_with("/tmp/t.toml: "), "{text:?}: {e}");
            assert!(e.contains(needle), "{text:?}: '{e}' lacks '{needle}'");
            assert!(!e.contains('\n'), "{text:?}: multi-line message: {e}");
            assert!(matches!(parse(text), Err(Error::Parse { .. })), "{text:?}");
        }
    }

    #[test]
    fn outer_material_override_and_default_material() {
        let s = parse(
            r#"
[materials.default]
color = 0.2
[materials.red]
color = [1, 0, 0]
[meshes.c]
generator = "cube"
[[groups.g.instances]]
target = "c"
material = "red"
[[instances]]
target = "g"
"#,
        )
        .unwrap();
        assert_eq!(s.materials[0].color, Vec3::splat(0.2));
        let leaves = s.leaf_instances().unwrap();
        assert_eq!(s.materials[leaves[0].material.unwrap() as usize].name, "red");
    }
}
