//! Loading scenes: built-in names, bare meshes (.obj with MTL via tobj, .off), and TOML
//! scene files. A bare mesh is framed automatically, lit by a default light, grey diffuse
//! unless its OBJ file names MTL materials.

use super::{Camera, Light, Material, Mesh, Scene, Target};
use crate::error::{Error, Result};
use glam::{Affine3A, Vec3};
use std::path::Path;

/// Resolves SCENE as DESIGN.md describes: a built-in name, or a file by extension.
pub fn load_scene(spec: &str) -> Result<Scene> {
    let p = Path::new(spec);
    let ext = p.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
    let mut scene = match ext.as_deref() {
        Some("obj") => {
            // Its MTL materials (if any) follow the default grey at index 0.
            let (mesh, mtls) = load_obj_with_materials(p, 1)?;
            let mut s = bare_mesh_scene(mesh)?;
            for m in mtls {
                s.add_material(m);
            }
            s
        }
        Some("off") => bare_mesh_scene(load_off(p, 0)?)?,
        Some("toml") => super::tomlscene::load(p)?,
        Some("ply") => {
            return Err(Error::parse(p, "point files (.ply) are surfel models: render them with `--method surfel` or `lodtrace animate`; the other methods take .obj, .off or .toml"))
        }
        _ => return super::builtin::get(spec).and_then(|mut s| s.validate().map(|_| s)),
    };
    // A file's scene names the file: "material 'm': ..." alone did not say which MTL or
    // TOML it came from (stop 61's sweep).
    scene.validate().map_err(|e| match e {
        Error::Scene(m) => Error::Scene(format!("{}: {m}", p.display())),
        e => e,
    })?;
    Ok(scene)
}

/// Loads a mesh file; every triangle gets material `mat`, whatever an OBJ's MTL says (for
/// those, [`load_obj_with_materials`]). Until stop 54 an OBJ's triangles got `mat` + their
/// MTL index, so a scene file's `material = "white"` on such an OBJ named materials the scene
/// does not have.
pub fn load_mesh(path: &Path, mat: u32) -> Result<Mesh> {
    let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
    match ext.as_deref() {
        Some("off") => load_off(path, mat),
        Some("obj") => load_obj(path, mat, mat).map(|(mut m, _)| {
            m.mat.iter_mut().for_each(|x| *x = mat);
            m
        }),
        _ => Err(Error::parse(path, "unsupported mesh format (expected .obj or .off)")),
    }
}

/// The name a scene, mesh or point set takes from its file: the file's stem, with control
/// characters (a newline in the file name) replaced by `_`, since the name heads table rows
/// and summary lines and names output files; `default` when the path has no stem.
pub fn stem_name(path: &Path, default: &str) -> String {
    path.file_stem()
        .map_or_else(|| default.to_string(), |s| s.to_string_lossy().chars().map(|c| if c.is_control() { '_' } else { c }).collect())
}

fn read_to_string(path: &Path) -> Result<String> {
    // The text, and the vertex and face arrays parsed from it (each smaller than its text).
    crate::error::check_input_read(path, 2)?;
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let text = String::from_utf8(bytes).map_err(|e| {
        let line = line_of(e.as_bytes(), e.utf8_error().valid_up_to());
        Error::parse(path, format!("line {line}: not text (a byte that is not UTF-8)"))
    })?;
    // Classic Mac line ends: the whole file would read as one line ("truncated: 0 of N").
    if text.contains('\r') && !text.contains('\n') {
        return Err(Error::parse(path, "lines end in CR only (classic Mac); convert them to LF or CR LF"));
    }
    Ok(text)
}

/// The line (from 1) that holds byte `at` of `bytes`.
fn line_of(bytes: &[u8], at: usize) -> usize {
    1 + bytes[..at].iter().filter(|&&c| c == b'\n').count()
}

/// Object File Format: a header `OFF` (or with the prefixes `C`, `N`, `ST`, `4`: colours,
/// normals, texture coordinates, homogeneous positions; `ST` first, the others in any order,
/// each at most once, so `4NOFF` and `N4OFF` alike; `nOFF`, of any dimension, is refused),
/// counts `nv nf ne`, one vertex per
/// line, then one face per line `n i0 i1 ...` (polygons are fan-triangulated). With `4` a
/// position is `x y z w`, the point (x/w, y/w, z/w); a `w` of 0 (a point at infinity) or not
/// finite is refused naming its line. With `N` the
/// three values after a vertex's position (its `x y z w` with `4`) are its normal (normalised;
/// used for shading like an OBJ file's); colours and texture coordinates after them, and a
/// face's colour after its indices, are skipped. Values past those the header declares on a vertex line
/// of a plain `OFF` (or `4OFF`, `NOFF`) are skipped with one warning. Comments (`#`) and
/// blank lines are ignored; a missing header is accepted.
pub fn load_off(path: &Path, mat: u32) -> Result<Mesh> {
    let text = read_to_string(path)?;
    // A UTF-8 byte-order mark (some Windows editors write one) is not part of the header.
    let mut lines = text
        .strip_prefix('\u{feff}')
        .unwrap_or(&text)
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.split('#').next().unwrap_or("").split_whitespace().collect::<Vec<_>>()))
        .filter(|(_, t)| !t.is_empty());
    let bad = |line: usize, m: String| Error::parse(path, format!("line {line}: {m}"));
    let (mut line, mut toks) = lines.next().ok_or_else(|| Error::parse(path, "empty file"))?;
    let (mut homogeneous, mut normals, mut extras) = (false, false, false);
    if let Some(kw) = toks.first().copied().filter(|t| t.ends_with("OFF")) {
        let prefix = kw.trim_end_matches("OFF");
        let flags = prefix.strip_prefix("ST").unwrap_or(prefix);
        let twice = flags.char_indices().any(|(i, c)| flags[..i].contains(c));
        if !flags.chars().all(|c| matches!(c, 'C' | 'N' | '4')) || twice {
            return Err(bad(line, format!("unsupported OFF header '{kw}' (OFF with the prefixes ST, C, N, 4, each at most once)")));
        }
        homogeneous = flags.contains('4');
        normals = flags.contains('N');
        // Colours (3 or 4 values, or a colour-map index) and texture coordinates vary in
        // length: what follows the position and normal is not checked then.
        extras = flags.contains('C') || prefix.starts_with("ST");
        toks.remove(0);
        if toks.is_empty() {
            (line, toks) = lines.next().ok_or_else(|| Error::parse(path, "truncated: expected the vertex and face counts"))?;
        }
    }
    let count = |s: Option<&&str>, what: &str| -> Result<usize> {
        let s = s.ok_or_else(|| bad(line, format!("missing {what}")))?;
        s.parse::<usize>().map_err(|_| bad(line, format!("bad {what} '{s}'")))
    };
    let (nv, nf) = (count(toks.first(), "vertex count")?, count(toks.get(1), "face count")?);
    if nv > 100_000_000 || nf > 200_000_000 {
        return Err(Error::parse(path, "absurd vertex or face count"));
    }
    let mut mesh = Mesh::new(stem_name(path, ""));
    let dims = if homogeneous { 4 } else { 3 };
    let want = dims + if normals { 3 } else { 0 };
    let mut extra_at = None;
    for k in 0..nv {
        let (line, t) = lines.next().ok_or_else(|| Error::parse(path, format!("truncated: {k} of {nv} vertices")))?;
        if t.len() < want {
            let of = if normals { " (position and normal)" } else { "" };
            return Err(bad(line, format!("vertex {k} has {} values, expected {want}{of}", t.len())));
        }
        if t.len() > want && !extras && extra_at.is_none() {
            extra_at = Some((line, t.len()));
        }
        let mut v = [0f32; 7];
        for (c, s) in v.iter_mut().zip(&t[..want]) {
            *c = s.parse::<f32>().map_err(|_| bad(line, format!("bad coordinate '{s}'")))?;
        }
        let p = Vec3::new(v[0], v[1], v[2]);
        if homogeneous && (v[3] == 0.0 || !v[3].is_finite()) {
            return Err(bad(line, format!("vertex {k} has w = {} (4OFF: the point is x/w, y/w, z/w; w must be finite and not 0)", t[3])));
        }
        mesh.push_vertex(if homogeneous { p / v[3] } else { p });
        if normals {
            // A zero or non-finite normal is left as read: `finish_mesh` then computes
            // every normal from the faces, with a warning.
            let n = Vec3::new(v[dims], v[dims + 1], v[dims + 2]);
            let n = if n.is_finite() { n.normalize_or_zero() } else { n };
            mesh.nx.push(n.x);
            mesh.ny.push(n.y);
            mesh.nz.push(n.z);
        }
    }
    if let Some((line, got)) = extra_at {
        crate::error::warn(format!(
            "{}: line {line}: a vertex has {got} values where the header declares {want}; the rest are ignored (a colour or normal needs the header C or N)",
            path.display()
        ));
    }
    for f in 0..nf {
        let (line, t) = lines.next().ok_or_else(|| Error::parse(path, format!("truncated: {f} of {nf} faces")))?;
        let n = t[0].parse::<usize>().map_err(|_| bad(line, format!("bad face size '{}'", t[0])))?;
        if !(3..=1000).contains(&n) {
            return Err(bad(line, format!("face {f} has {n} vertices (3 to 1000)")));
        }
        if t.len() < n + 1 {
            return Err(bad(line, format!("face {f} lists {} of its {n} vertices", t.len() - 1)));
        }
        let mut idx = Vec::with_capacity(n);
        for s in &t[1..=n] {
            let i = s.parse::<usize>().map_err(|_| bad(line, format!("bad face index '{s}'")))?;
            if i >= nv {
                return Err(bad(line, format!("face {f} index {i} out of range (vertices: {nv})")));
            }
            idx.push(i as u32);
        }
        for k in 1..n - 1 {
            mesh.push_tri(idx[0], idx[k], idx[k + 1], mat);
        }
    }
    // More than the header declares: a wrong count, most likely (faces lost without a word).
    if let Some((line, _)) = lines.next() {
        crate::error::warn(format!(
            "{}: line {line}: data after the {nf} faces the header declares is ignored (is the face count right?)",
            path.display()
        ));
    }
    finish_mesh(path, mesh)
}

/// An OBJ stream without its `l` (polyline) and `p` (point) elements, each replaced by an
/// empty line (line numbers stay): tobj 4 parses `l a b c` as the face `f a b c`.
struct SurfaceLines<R> {
    inner: R,
    line: Vec<u8>,
    at: usize,
    dropped: usize,
    /// The faces' texture-coordinate and normal references, checked here: tobj drops a
    /// reference to an element the file lacks without a word, and with it every normal of
    /// the mesh (the sweep of stop 65). `refs` = [vt, vn].
    refs: FaceRefs,
    /// The number of a line longer than [`MAX_OBJ_LINE`], where reading stopped.
    too_long: Option<usize>,
}

/// The longest OBJ line read (a face of 100,000 vertices takes about 1 MB). A file without
/// line ends (a sparse or binary file named .obj) was read into one line until the memory ran
/// out: the allocation failure aborted without an error line.
const MAX_OBJ_LINE: usize = 64 << 20;

/// Counts of `vt` and `vn` lines so far, the largest index the faces name of each (with its
/// line), the first face line naming a relative index before the file's start, and the
/// first face of fewer than 3 vertices (line, face number, vertices): tobj keeps `f 1 2` as
/// a line and `f 1` as a point, and both were dropped from the mesh without a word.
///
/// Also (stop 91: tobj names no line for these) the vertex references, a `v` line whose w
/// is 0 ("scaling (w) by zero") and a `usemtl` without a name ("material parse error").
#[derive(Default)]
struct FaceRefs {
    line_no: usize,
    /// Of [`REF_KIND`]: vertices, texture coordinates, normals.
    count: [i64; 3],
    max: [(i64, usize); 3],
    before_start: Option<(usize, &'static str, i64)>,
    faces: usize,
    short_face: Option<(usize, usize, usize)>,
    /// The first `v` line with w = 0 and the first `usemtl` without a name.
    zero_w: Option<usize>,
    bare_usemtl: Option<usize>,
}

const REF_KIND: [&str; 3] = ["vertex", "texture coordinate", "normal"];

impl FaceRefs {
    fn scan(&mut self, kw: &[u8]) {
        self.line_no += 1;
        let text = String::from_utf8_lossy(kw);
        let mut w = text.split_whitespace();
        match w.next() {
            Some("v") => {
                self.count[0] += 1;
                // x y z w (x y z r g b is a vertex colour). No allocation: a line per vertex.
                let (mut n, mut fourth) = (0, None);
                for x in w {
                    n += 1;
                    if n == 4 {
                        fourth = Some(x);
                    }
                }
                if n == 4 && fourth.is_some_and(|x| x.parse::<f32>() == Ok(0.0)) && self.zero_w.is_none() {
                    self.zero_w = Some(self.line_no);
                }
            }
            Some("vt") => self.count[1] += 1,
            Some("vn") => self.count[2] += 1,
            Some("usemtl") if w.next().is_none() && self.bare_usemtl.is_none() => self.bare_usemtl = Some(self.line_no),
            Some("f") => {
                let n = w.clone().count();
                if n < 3 && self.short_face.is_none() {
                    self.short_face = Some((self.line_no, self.faces, n));
                }
                self.faces += 1;
                for v in w {
                    for (k, part) in v.split('/').take(3).enumerate() {
                        let Ok(i) = part.parse::<i64>() else { continue };
                        if i < 0 && self.count[k] + i < 0 && self.before_start.is_none() {
                            self.before_start = Some((self.line_no, REF_KIND[k], i));
                        }
                        if i > self.max[k].0 {
                            self.max[k] = (i, self.line_no);
                        }
                    }
                }
            }
            _ => {}
        }
    }
    /// The first bad reference or short face (the one on the earliest line), as an error
    /// message.
    fn error(&self) -> Option<String> {
        let mut found: Vec<(usize, String)> = Vec::new();
        if let Some((line, kind, i)) = self.before_start {
            found.push((line, format!("line {line}: a face names {kind} {i}, before the file's first")));
        }
        // A face may name a vertex defined after it (tobj resolves indices at the end); so
        // only the largest index against the file's count.
        for (k, kind) in REF_KIND.iter().enumerate() {
            let ((i, line), n) = (self.max[k], self.count[k]);
            if i > n {
                let of = if k == 0 { "vertices" } else { "of them" };
                found.push((line, format!("line {line}: a face names {kind} {i}, but the file has {n} {of}")));
            }
        }
        if let Some(line) = self.zero_w {
            found.push((line, format!("line {line}: a vertex with w = 0 (a point at infinity)")));
        }
        if let Some(line) = self.bare_usemtl {
            found.push((line, format!("line {line}: usemtl names no material")));
        }
        if let Some((line, f, n)) = self.short_face {
            // As the OFF loader's "face 0 has 2 vertices (3 to 1000)".
            found.push((line, format!("line {line}: face {f} has {n} vert{} (at least 3)", if n == 1 { "ex" } else { "ices" })));
        }
        found.into_iter().min_by_key(|(line, _)| *line).map(|(_, m)| m)
    }
}

impl<R: std::io::BufRead> std::io::Read for SurfaceLines<R> {
    fn read(&mut self, out: &mut [u8]) -> std::io::Result<usize> {
        use std::io::BufRead;
        let n = {
            let b = self.fill_buf()?;
            let n = b.len().min(out.len());
            out[..n].copy_from_slice(&b[..n]);
            n
        };
        self.consume(n);
        Ok(n)
    }
}

impl<R: std::io::BufRead> std::io::BufRead for SurfaceLines<R> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        if self.at >= self.line.len() {
            self.line.clear();
            self.at = 0;
            let read = std::io::Read::take(&mut self.inner, MAX_OBJ_LINE as u64 + 1).read_until(b'\n', &mut self.line)?;
            if self.line.len() > MAX_OBJ_LINE {
                self.too_long = Some(self.refs.line_no + 1);
                self.line.clear();
                return Err(std::io::Error::new(std::io::ErrorKind::InvalidData, "line too long"));
            }
            if read > 0 {
                // A comment runs from `#` to the line's end, after a statement too (tobj
                // only skips lines that start with one: `f 1 2 3 # a` was "face parse
                // error" and `mtllib a.mtl # b` three library names; the sweep of stop 91).
                if let Some(h) = self.line.iter().position(|&c| c == b'#') {
                    let nl = self.line.last() == Some(&b'\n');
                    self.line.truncate(h);
                    while self.line.last().is_some_and(|c| *c == b' ' || *c == b'\t') {
                        self.line.pop();
                    }
                    if nl {
                        self.line.push(b'\n');
                    }
                }
                let first = self.line.iter().position(|c| !c.is_ascii_whitespace());
                let kw = first.map(|i| &self.line[i..]).unwrap_or(&[]);
                let is = |k: u8| kw.first() == Some(&k) && kw.get(1).is_some_and(|c| c.is_ascii_whitespace());
                self.refs.scan(kw);
                if is(b'l') || is(b'p') {
                    self.dropped += 1;
                    self.line.clear();
                    self.line.push(b'\n');
                }
            }
        }
        Ok(&self.line[self.at..])
    }
    fn consume(&mut self, n: usize) {
        self.at = (self.at + n).min(self.line.len());
    }
}

/// After tobj refused an OBJ file (its errors carry no position): the first line whose
/// numbers do not parse — a `v`/`vn`/`vt` line with fewer than 3/3/1 numbers or a bad one, or
/// an `f`/`l`/`p` line with an index that is not a non-zero whole number.
fn obj_bad_line(path: &Path) -> Option<usize> {
    let bytes = std::fs::read(path).ok()?;
    let text = match std::str::from_utf8(&bytes) {
        Ok(t) => t,
        // tobj's "read error": the first byte that is not UTF-8.
        Err(e) => return Some(line_of(&bytes, e.valid_up_to())),
    };
    for (i, l) in text.lines().enumerate() {
        let mut t = l.split('#').next().unwrap_or("").split_whitespace();
        let ok = match t.next() {
            Some(k @ ("v" | "vn" | "vt")) => {
                let nums: Vec<&str> = t.collect();
                nums.len() >= if k == "vt" { 1 } else { 3 } && nums.iter().all(|x| x.parse::<f32>().is_ok())
            }
            Some("f" | "l" | "p") => {
                let idx: Vec<&str> = t.collect();
                !idx.is_empty()
                    && idx
                        .iter()
                        .all(|v| v.split('/').enumerate().all(|(k, x)| (k > 0 && x.is_empty()) || x.parse::<i64>().is_ok_and(|n| n != 0)))
            }
            _ => true,
        };
        if !ok {
            return Some(i + 1);
        }
    }
    None
}

fn finish_mesh(path: &Path, mut mesh: Mesh) -> Result<Mesh> {
    if mesh.tris.is_empty() {
        return Err(Error::parse(path, "no faces"));
    }
    // Whether a triangle has an area in f64 that underflows f32's test (the squared length
    // of the edges' cross product, ~size⁴: 0 below about 1e-11 units). Looked for only in
    // small meshes, before the degenerate triangles are removed.
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for i in 0..mesh.vertex_count() as u32 {
        let p = mesh.pos(i);
        if p.is_finite() {
            (lo, hi) = (lo.min(p), hi.max(p));
        }
    }
    let size = (hi - lo).max_element(); // not the diagonal: its square underflows too
    let underflows = size > 0.0
        && size < 1e-9
        && (0..mesh.tri_count()).any(|t| {
            let [p0, p1, p2] = mesh.tri_verts(t).map(|p| p.as_dvec3());
            p0.is_finite() && p1.is_finite() && p2.is_finite() && (p1 - p0).cross(p2 - p0).length_squared() > 0.0
        });
    let bad = mesh.remove_degenerate();
    if mesh.tris.is_empty() {
        // Say how large the mesh is: a model a few 1e-20 across has distinct vertices but
        // triangle areas that underflow f32 (stop 57: "degenerate" alone read as a bad file).
        // Decided by the areas in f64, not by the size alone: a tetrahedron 1e-14 across
        // (areas ~1e-28, their squares 0 in f32) was "degenerate or non-finite" as the size
        // bound was 1e-15.
        let why = if underflows {
            format!("every triangle has zero area in f32: the mesh spans only {size:.3e} units; scale it up")
        } else {
            "every triangle is degenerate or non-finite".to_string()
        };
        return Err(Error::parse(path, why));
    }
    if bad > 0 {
        crate::error::warn(format!("{}: skipped {bad} degenerate or non-finite triangles", path.display()));
    }
    let dup = mesh.remove_duplicates();
    if dup > 0 {
        crate::error::warn(format!("{}: skipped {dup} duplicate triangles (same vertices, winding and material)", path.display()));
    }
    // Normals missing for some vertices (an OBJ mixing `f 1//1 …` with `f 2 4 3` gives those
    // zero normals, which shaded them black), zero or non-finite: all are computed from the
    // faces instead.
    let unit = |n: Vec3| n.is_finite() && n.length_squared() > 0.25;
    if !mesh.has_normals() || !(0..mesh.vertex_count() as u32).all(|i| unit(mesh.normal(i))) {
        if mesh.has_normals() {
            crate::error::warn(format!("{}: some vertex normals are missing or zero; computing all from the faces", path.display()));
        }
        mesh.compute_normals();
    }
    Ok(mesh)
}

/// An MTL file's text with every colour statement (`Ka`, `Kd`, `Ks`, `Ke`) made to hold
/// three values, as tobj 4.0.5 requires: it panics on fewer (an `unwrap` in its
/// `parse_float3`). One value is the MTL form for a grey (`Kd 0.5` is `Kd 0.5 0.5 0.5`) and is
/// expanded; none or two are a parse error (the caller warns and uses the default
/// material, as for any malformed MTL).
fn mtl_colours_complete(text: &[u8]) -> std::result::Result<Vec<u8>, tobj::LoadError> {
    let text = String::from_utf8_lossy(text);
    let mut out = String::with_capacity(text.len() + 64);
    for line in text.lines() {
        // Comments after a statement too, as in the OBJ file ([`SurfaceLines`]).
        let line = line.split('#').next().unwrap_or("");
        let mut w = line.split_whitespace();
        match w.next() {
            Some(k @ ("Ka" | "Kd" | "Ks" | "Ke")) => {
                let v: Vec<&str> = w.collect();
                match v.len() {
                    1 => out.push_str(&format!("{k} {0} {0} {0}", v[0])),
                    n if n >= 3 => out.push_str(line),
                    _ => return Err(tobj::LoadError::MaterialParseError),
                }
            }
            _ => out.push_str(line),
        }
        out.push('\n');
    }
    Ok(out.into_bytes())
}

/// An OBJ with its MTL materials, for a scene that appends them after its first `base`
/// materials: triangles take `base` + their MTL index; without an MTL, or without a material
/// of it (faces before any `usemtl`, or after one naming a material the MTL lacks), material
/// 0 (the scene's default).
pub fn load_obj_with_materials(path: &Path, base: u32) -> Result<(Mesh, Vec<Material>)> {
    let (mut mesh, mtls) = load_obj(path, base, 0)?;
    if mtls.is_empty() {
        mesh.mat.iter_mut().for_each(|x| *x = 0);
    }
    Ok((mesh, mtls))
}

/// OBJ via tobj (triangulated, single index). Returns the mesh and the MTL materials it uses;
/// triangle materials are `mat` + the MTL material index, or `default` for a triangle with no
/// MTL material. (Until stop 61 such a triangle took `mat` + 0, the MTL's first material.)
pub fn load_obj(path: &Path, mat: u32, default: u32) -> Result<(Mesh, Vec<Material>)> {
    crate::error::check_input_file(path)?;
    // Lines (`l`) and points (`p`) are no surface: tobj reads `l` like `f` (a polyline of 3
    // or more vertices became a filled polygon), so [`SurfaceLines`] drops them first.
    // `..Default::default()` covers the fields tobj's `merging` and `reordering` features add,
    // which another crate in the build may turn on.
    #[allow(clippy::needless_update)]
    let opts = tobj::LoadOptions { triangulate: true, single_index: true, ignore_lines: true, ignore_points: true, ..Default::default() };
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    // tobj's own `load_obj` opens an `mtllib` path as given: `/dev/zero` filled the memory and
    // a FIFO blocked forever. Only a regular file of sane size is read.
    let load_one = |full: &Path| -> tobj::MTLLoadResult {
        crate::error::check_input_file(full).map_err(|_| tobj::LoadError::OpenFileFailed)?;
        if std::fs::metadata(full).map_or(true, |m| m.len() > MAX_MTL_BYTES) {
            return Err(tobj::LoadError::ReadError);
        }
        let text = std::fs::read(full).map_err(|_| tobj::LoadError::ReadError)?;
        tobj::load_mtl_buf(&mut std::io::Cursor::new(mtl_colours_complete(&text)?))
    };
    // tobj passes the rest of an `mtllib` line as one name (a name may hold spaces), but the
    // format allows several libraries on one line (`mtllib a.mtl b.mtl`, once read as the
    // one missing file "a.mtl b.mtl"). A file of the whole name is read as one;
    // otherwise each name, in order, each through the guards above, a later definition of a
    // material name winning as across several `mtllib` lines.
    let load_mtl = |p: &Path| -> tobj::MTLLoadResult {
        let whole = dir.join(p);
        let names: Vec<&str> = p.to_str().map(|s| s.split_whitespace().collect()).unwrap_or_default();
        if whole.is_file() || names.len() < 2 {
            return load_one(&whole);
        }
        let (mut mats, mut map) = load_one(&dir.join(names[0]))?;
        for n in &names[1..] {
            let (more, more_map) = load_one(&dir.join(n))?;
            let offset = mats.len();
            mats.extend(more);
            for (k, i) in more_map {
                map.insert(k, i + offset);
            }
        }
        Ok((mats, map))
    };
    let mut reader = SurfaceLines {
        inner: std::io::BufReader::new(file),
        line: Vec::new(),
        at: 0,
        dropped: 0,
        refs: FaceRefs::default(),
        too_long: None,
    };
    let loaded = tobj::load_obj_buf(&mut reader, &opts, load_mtl);
    if let Some(line) = reader.too_long {
        return Err(Error::parse(path, format!("line {line} is longer than {} MB: not an OBJ text file", MAX_OBJ_LINE >> 20)));
    }
    // Before tobj's own error, which names no line ("face normal index out of bounds").
    if let Some(m) = reader.refs.error() {
        return Err(Error::parse(path, m));
    }
    let (models, mtls) = loaded.map_err(|e| match obj_bad_line(path) {
        // tobj's "read error" on a regular file: a line that is not UTF-8.
        Some(line) if matches!(e, tobj::LoadError::ReadError) => {
            Error::parse(path, format!("line {line}: not text (a byte that is not UTF-8)"))
        }
        Some(line) => Error::parse(path, format!("line {line}: {e}")),
        None => Error::parse(path, e.to_string()),
    })?;
    if reader.dropped > 0 {
        crate::error::warn(format!(
            "{}: skipped {} line or point element{} (`l`, `p`: no surface to trace)",
            path.display(),
            reader.dropped,
            if reader.dropped == 1 { "" } else { "s" }
        ));
    }
    let mtls = mtls.unwrap_or_else(|e| {
        // The geometry is still usable: grey diffuse, as for a file without materials.
        crate::error::warn(format!("{}: materials not loaded ({e}); using the default material", path.display()));
        Vec::new()
    });
    let mut mesh = Mesh::new(stem_name(path, ""));
    let mut normals_ok = true;
    let mut unmatched = 0usize;
    for m in &models {
        let mm = &m.mesh;
        if mm.positions.len() % 3 != 0 || mm.indices.len() % 3 != 0 {
            return Err(Error::parse(path, "malformed geometry"));
        }
        let base = mesh.vertex_count() as u32;
        let nv = (mm.positions.len() / 3) as u32;
        for v in mm.positions.chunks_exact(3) {
            mesh.push_vertex(Vec3::new(v[0], v[1], v[2]));
        }
        if mm.normals.len() == mm.positions.len() && normals_ok {
            for n in mm.normals.chunks_exact(3) {
                let n = Vec3::new(n[0], n[1], n[2]).normalize_or_zero();
                mesh.nx.push(n.x);
                mesh.ny.push(n.y);
                mesh.nz.push(n.z);
            }
        } else {
            normals_ok = false;
        }
        let tm = match mm.material_id {
            Some(i) => mat + i as u32,
            None => {
                unmatched += mm.indices.len() / 3;
                default
            }
        };
        for t in mm.indices.chunks_exact(3) {
            if t.iter().any(|&i| i >= nv) {
                return Err(Error::parse(path, format!("face index out of range (vertices: {nv})")));
            }
            mesh.push_tri(base + t[0], base + t[1], base + t[2], tm);
        }
    }
    if !normals_ok {
        mesh.nx.clear();
        mesh.ny.clear();
        mesh.nz.clear();
    }
    if unmatched > 0 && !mtls.is_empty() {
        crate::error::warn(format!(
            "{}: {unmatched} triangle{} name no material of the MTL file (faces before any `usemtl`, or a `usemtl` of a name it lacks); they take the default material",
            path.display(),
            if unmatched == 1 { "" } else { "s" }
        ));
    }
    let materials = mtls.iter().map(|m| material_from_mtl(path, m)).collect::<Result<Vec<_>>>()?;
    Ok((finish_mesh(path, mesh)?, materials))
}

/// A material library larger than this is not a material library.
const MAX_MTL_BYTES: u64 = 64 << 20;

/// An MTL material; values a renderer cannot use (NaN, infinite, negative colours, dissolve
/// outside [0, 1], Ns < 0, Ni ≤ 0) are errors, as in a TOML scene.
fn material_from_mtl(path: &Path, m: &tobj::Material) -> Result<Material> {
    let bad = |what: &str| Err(Error::parse(path, format!("material '{}' in its MTL file: {what}", m.name)));
    let fin = |v: &Option<[f32; 3]>| v.is_none_or(|c| c.iter().all(|x| x.is_finite() && *x >= 0.0));
    if !fin(&m.diffuse) || !fin(&m.specular) || !fin(&m.ambient) {
        return bad("Ka, Kd and Ks must be finite and ≥ 0");
    }
    if m.shininess.is_some_and(|v| !(v.is_finite() && v >= 0.0)) {
        return bad("Ns must be finite and ≥ 0");
    }
    if m.dissolve.is_some_and(|v| !(0.0..=1.0).contains(&v)) {
        return bad("d (dissolve) must lie in [0, 1]");
    }
    // `Tr` (transparency, 1 − d), which many exporters write instead of `d`; tobj keeps it
    // as an unknown parameter. `d` wins where both are given.
    let tr = match m.unknown_param.get("Tr") {
        Some(t) => match t.trim().parse::<f32>() {
            Ok(v) if (0.0..=1.0).contains(&v) => Some(v),
            _ => return bad(&format!("Tr (transparency) must be one number in [0, 1], not '{t}'")),
        },
        None => None,
    };
    if m.optical_density.is_some_and(|v| !(v.is_finite() && v > 0.0)) {
        return bad("Ni (index of refraction) must be finite and > 0");
    }
    let kd = m.diffuse.map(Vec3::from).unwrap_or(Vec3::splat(0.7));
    let ks = m.specular.map(|s| Vec3::from(s).max_element()).unwrap_or(0.0);
    let d = m.dissolve.or(tr.map(|t| 1.0 - t)).unwrap_or(1.0);
    Ok(Material {
        name: m.name.clone(),
        color: kd,
        kd: 1.0,
        ks: ks.min(1.0),
        shininess: m.shininess.unwrap_or(32.0).max(1.0),
        reflect: 0.0,
        transmit: 1.0 - d,
        ior: m.optical_density.unwrap_or(1.5).max(1.0),
        roughness: 0.0,
    })
}

/// A scene holding one mesh, grey diffuse (material 0; the caller appends an OBJ's MTL
/// materials), on no floor, framed so the whole mesh fits the
/// view, lit by a light above and behind the camera.
pub fn bare_mesh_scene(mesh: Mesh) -> Result<Scene> {
    let mut s = Scene::empty(&mesh.name);
    s.materials[0] = Material::diffuse("grey", Vec3::splat(0.7));
    let id = s.add_mesh(mesh);
    s.instance(Target::Mesh(id), Affine3A::IDENTITY, None);
    let (lo, hi) = s.bounds()?;
    if !lo.is_finite() || !hi.is_finite() {
        return Err(Error::Scene("mesh bounds are not finite".into()));
    }
    // Hit points are offset by 1e-4 × (1 + |p|) before secondary rays: a model of less than ten
    // such offsets shadows itself wrongly or not at all (stop 46's sweep: a cow scaled
    // by 1e-5 vanished, exit 0).
    let far = lo.abs().max(hi.abs()).max_element();
    let size = (hi - lo).length();
    if !(size >= 1e-3 * (1.0 + far)) {
        return Err(Error::Scene(format!(
            "mesh '{}' spans only {size:.3e} units at coordinates up to {far:.3e}: too small for the ray offsets (at least 1e-3 × (1 + its largest coordinate)); scale it up",
            s.name
        )));
    }
    s.camera = frame_bounds(lo, hi, 40.0);
    let r = (hi - lo).length().max(1e-6);
    let eye = s.camera.eye;
    let light_pos = eye
        + (s.camera.up * 0.5 * r)
        + (eye - s.camera.look).normalize() * 0.2 * r
        + s.camera.look.cross(Vec3::Y).normalize_or_zero() * 0.3 * r;
    let d2 = (light_pos - (lo + hi) * 0.5).length_squared();
    if d2 * 3.0 > crate::scene::MAX_INTENSITY {
        return Err(Error::Scene(format!(
            "mesh '{}' spans {size:.3e} units: its automatic light would need an intensity of {:.3e}, beyond {:e}; scale it down or light it in a scene file",
            s.name,
            d2 * 3.0,
            crate::scene::MAX_INTENSITY
        )));
    }
    s.lights.push(Light::Point { pos: light_pos, intensity: Vec3::splat(d2 * 3.0) });
    s.ambient = Vec3::splat(0.05);
    Ok(s)
}

/// A camera looking at the centre of the box from the front-right-above, far enough that the
/// bounding sphere fits the vertical field of view.
pub fn frame_bounds(lo: Vec3, hi: Vec3, fovy: f32) -> Camera {
    let c = (lo + hi) * 0.5;
    let r = ((hi - lo).length() * 0.5).max(1e-6);
    let dist = r / (fovy.to_radians() * 0.5).sin() * 1.05;
    let dir = Vec3::new(0.35, 0.3, 1.0).normalize();
    Camera { eye: c + dir * dist, look: c, up: Vec3::Y, fovy, aperture: 0.0, focal_dist: dist }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Stop 57: a zero `vn` passed the finiteness check and shaded its vertices black; faces
    /// without normal indices beside faces with them load with unit normals too.
    #[test]
    fn zero_or_missing_normals_are_computed() {
        let dir = std::env::temp_dir().join(format!("lodtrace-load-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("mixed.obj");
        std::fs::write(&p, "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\nf 2 4 3\n").unwrap();
        let zero = dir.join("zero.obj");
        std::fs::write(&zero, "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nvn 0 0 0\nf 1//1 2//2 3//1\n").unwrap();
        for p in [&p, &zero] {
            let (m, _) = load_obj(p, 0, 0).unwrap();
            for i in 0..m.vertex_count() as u32 {
                let n = m.normal(i);
                assert!((n.length() - 1.0).abs() < 1e-4, "{}: vertex {i}: normal {n}", p.display());
            }
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// An OFF file starting with a UTF-8 byte-order mark loads (it was refused as an
    /// "unsupported OFF header '\u{feff}OFF'", the mark invisible in the message).
    #[test]
    fn an_off_file_with_a_byte_order_mark_loads() {
        let dir = std::env::temp_dir().join(format!("lodtrace-load-bom-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("bom.off");
        std::fs::write(&p, "\u{feff}OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n").unwrap();
        let m = load_off(&p, 0).unwrap();
        assert_eq!(m.vertex_count(), 3);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A fresh scratch folder for one test of this module.
    fn scratch(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("lodtrace-load-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// `4OFF`: positions are homogeneous, (x/w, y/w, z/w), with the `N` prefix in either
    /// order; a `w` of 0 or not finite is refused naming its line (it was loaded as a point at
    /// infinity and the file then refused as "every triangle is degenerate or non-finite"); a
    /// prefix given twice is refused.
    #[test]
    fn homogeneous_off_vertices_are_divided_by_w() {
        let dir = scratch("4off");
        let p = dir.join("h.off");
        for head in ["4OFF", "4NOFF", "N4OFF"] {
            let n = if head.contains('N') { " 0 0 1" } else { "" };
            std::fs::write(&p, format!("{head}\n3 1 0\n0 0 0 2{n}\n4 0 0 2{n}\n0 4 0 -4{n}\n3 0 1 2\n")).unwrap();
            let m = load_off(&p, 0).unwrap();
            let v: Vec<Vec3> = (0..3).map(|i| m.pos(i)).collect();
            assert_eq!(v, [Vec3::ZERO, Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, -1.0, 0.0)], "{head}");
        }
        for w in ["0", "-0", "inf", "nan"] {
            std::fs::write(&p, format!("4OFF\n3 1 0\n0 0 0 1\n1 0 0 {w}\n0 1 0 1\n3 0 1 2\n")).unwrap();
            let e = load_off(&p, 0).unwrap_err().to_string();
            assert!(e.contains("line 4: vertex 1 has w = "), "w = {w}: {e}");
        }
        std::fs::write(&p, "44OFF\n3 1 0\n0 0 0 1\n1 0 0 1\n0 1 0 1\n3 0 1 2\n").unwrap();
        let e = load_off(&p, 0).unwrap_err().to_string();
        assert!(e.contains("unsupported OFF header '44OFF'"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// `mtllib a.mtl b.mtl`: each library is loaded (the line was read as one file name and
    /// no material loaded); a name that is one file with a space still loads as one.
    #[test]
    fn mtllib_with_several_files_loads_each() {
        let dir = scratch("mtllib");
        std::fs::write(dir.join("a.mtl"), "newmtl red\nKd 1 0 0\n").unwrap();
        std::fs::write(dir.join("b.mtl"), "newmtl green\nKd 0 1 0\n").unwrap();
        std::fs::write(dir.join("c d.mtl"), "newmtl blue\nKd 0 0 1\n").unwrap();
        let geo = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nusemtl red\nf 1 2 3\nusemtl green\nf 2 4 3\n";
        let p = dir.join("two.obj");
        std::fs::write(&p, format!("mtllib a.mtl b.mtl\n{geo}")).unwrap();
        let (m, mats) = load_obj(&p, 1, 0).unwrap();
        assert_eq!(mats.len(), 2);
        assert_eq!(m.mat, [1, 2], "each face its own library's material");
        assert_eq!((mats[0].name.as_str(), mats[0].color, mats[1].name.as_str(), mats[1].color), ("red", Vec3::X, "green", Vec3::Y));
        std::fs::write(&p, "mtllib c d.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl blue\nf 1 2 3\n").unwrap();
        let (_, mats) = load_obj(&p, 1, 0).unwrap();
        assert_eq!(mats.len(), 1);
        assert_eq!(mats[0].color, Vec3::Z);
        // Each file passes the input guards: `/dev/zero` is not read (the geometry loads,
        // without the line's materials, with a warning).
        std::fs::write(&p, format!("mtllib a.mtl /dev/zero\n{geo}")).unwrap();
        let (m, mats) = load_obj(&p, 1, 0).unwrap();
        assert!(mats.is_empty() && m.mat == [0, 0], "{:?}", m.mat);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A comment after a statement is a comment, in the OBJ and in its MTL (stop 91: `f 1 2
    /// 3 # a` was "face parse error", `v 0 0 0 # a` "color parse error", and `mtllib a.mtl
    /// # mats` three library names, so the materials were dropped).
    #[test]
    fn comments_after_statements_are_comments() {
        let dir = scratch("comments");
        std::fs::write(dir.join("a b.mtl"), "newmtl red # the red one\nKd 1 0 0 # pure\n").unwrap();
        let p = dir.join("c.obj");
        let obj = "mtllib a b.mtl # mats\nv 0 0 0 # a\nv 1 0 0\t#b\nv 0 1 0#c\nusemtl red # x\nf 1 2 3 # face\nf 1 3 2#back\n# done\n";
        std::fs::write(&p, obj).unwrap();
        let (m, mats) = load_obj(&p, 1, 0).unwrap();
        assert_eq!((m.tri_count(), m.mat.as_slice()), (2, &[1u32, 1][..]));
        assert_eq!((mats.len(), mats[0].name.as_str(), mats[0].color), (1, "red", Vec3::X));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// What tobj refuses without a position is told with its line: a face naming a vertex
    /// past the file's last or before its first, a vertex with w = 0, a `usemtl` with no
    /// name (stop 91).
    #[test]
    fn obj_errors_name_their_line() {
        let dir = scratch("errlines");
        let p = dir.join("e.obj");
        let head = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n";
        for (body, says) in [
            ("f 1 2 3\nf 1 2 5\n", "line 6: a face names vertex 5, but the file has 4 vertices"),
            ("f 1 2 3\nf -1 -2 -5\n", "line 6: a face names vertex -5, before the file's first"),
            ("v 1 0 0 0\nf 1 2 3\n", "line 5: a vertex with w = 0"),
            ("f 1 2 3\nusemtl\nf 2 4 3\n", "line 6: usemtl names no material"),
        ] {
            std::fs::write(&p, format!("{head}{body}")).unwrap();
            let e = load_obj(&p, 1, 0).unwrap_err().to_string();
            assert!(e.contains(says), "{body:?}: {e}");
        }
        // Vertex colours (x y z r g b) with r = 0 are no w.
        std::fs::write(&p, "v 0 0 0 0 0.5 1\nv 1 0 0 0 0 0\nv 0 1 0 0 1 1\nf 1 2 3\n").unwrap();
        assert!(load_obj(&p, 1, 0).is_ok());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A mesh too small for f32 triangle areas says so, not only "degenerate".
    #[test]
    fn a_microscopic_mesh_is_told_to_scale_up() {
        let dir = std::env::temp_dir().join(format!("lodtrace-load-tiny-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("tiny.obj");
        std::fs::write(&p, "v 0 0 0\nv 1e-25 0 0\nv 0 1e-25 0\nf 1 2 3\n").unwrap();
        let e = load_obj(&p, 0, 0).unwrap_err().to_string();
        assert!(e.contains("spans only 1.000e-25 units; scale it up"), "{e}");
        std::fs::write(&p, "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n").unwrap();
        let e = load_obj(&p, 0, 0).unwrap_err().to_string();
        assert!(e.contains("every triangle is degenerate"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
