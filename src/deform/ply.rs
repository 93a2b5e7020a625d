//! Point files (PLY, via `ply-rs-bw`, the maintained fork of `ply-rs`) as surfel models
//! (Adams et al. §3: surfel models read from point files). The `vertex` element must have
//! `x y z nx ny nz`; a `radius` (or `r`) property is optional. Without it each surfel's radius is the distance to its 8th nearest
//! neighbour (so the discs overlap). NaN/inf coordinates, zero normals and duplicate points
//! are typed errors, never panics.

use super::knn::KdTree;
use super::surfel::{SurfelModel, SurfelSoa};
use super::DeformError;
use glam::Vec3;
use ply_rs_bw::parser::Parser;
use ply_rs_bw::ply::{DefaultElement, Property};
use std::path::Path;

fn scalar(p: &Property) -> Option<f32> {
    Some(match *p {
        Property::Char(v) => v as f32,
        Property::UChar(v) => v as f32,
        Property::Short(v) => v as f32,
        Property::UShort(v) => v as f32,
        Property::Int(v) => v as f32,
        Property::UInt(v) => v as f32,
        Property::Float(v) => v,
        Property::Double(v) => v as f32,
        _ => return None,
    })
}

/// `ply-rs-bw`'s parse message as one plain line: its chain of nested errors (" Error: …")
/// cut to the first, plus the innermost when it is short and says something new ("Expected
/// element of type 'Scalar(Float)', but found nothing."), never the parser's list of expected
/// tokens; whitespace collapsed (not [`crate::error::one_line`], which only escapes control
/// characters). A body cut short says so in words, whichever layer noticed.
fn plain_ply_message(msg: &str) -> String {
    let parts: Vec<&str> = msg.split("Error: ").map(str::trim).filter(|p| !p.is_empty()).collect();
    let Some(first) = parts.first() else { return String::new() };
    let mut out = first.to_string();
    if let Some(last) = parts.last().filter(|l| parts.len() > 1 && l.len() < 100 && !l.contains("expected one of") && !l.contains('{')) {
        out = format!("{} — {last}", out.trim_end_matches('.'));
    }
    let out = out.split_whitespace().collect::<Vec<_>>().join(" ");
    let eof = parts.iter().any(|p| p.contains("failed to fill whole buffer") || p.contains("UnexpectedEof"));
    if eof && !out.contains("end of file") {
        format!("{} (the file ends early)", out.trim_end_matches('.'))
    } else {
        out
    }
}

/// A PLY body must hold exactly what its header declares: ply-rs-bw reads the declared
/// counts and silently drops what follows (a wrong count, or two files run together). ASCII rows
/// are counted; a binary body whose properties are all fixed-size scalars must be exactly
/// as long as the counts say (with lists its length is not known before parsing). Counts
/// that are not whole numbers (`-1`, 10^20) are named as such.
fn body_matches_header(buf: &[u8]) -> Result<(), String> {
    // The header ends at the line that is `end_header`, not at the first `end_header` in the
    // text: a comment naming it ("comment written before the end_header line") cut the header
    // there, so a valid file was refused ("the header declares 0 rows, the file holds 109").
    let (mut start, mut split) = (0, None);
    while start < buf.len() {
        let nl = buf[start..].iter().position(|&b| b == b'\n').map(|n| start + n);
        let line = &buf[start..nl.unwrap_or(buf.len())];
        if line.trim_ascii() == b"end_header" {
            split = Some((start, nl.map_or(buf.len(), |n| n + 1)));
            break;
        }
        let Some(n) = nl else { break };
        start = n + 1;
    }
    let Some((end, body_start)) = split else { return Ok(()) };
    let head = String::from_utf8_lossy(&buf[..end]);
    let body = &buf[body_start..];
    // Per element: (bytes of one row, rows, properties).
    let (mut declared, mut elements, mut fixed) = (0u64, Vec::<(u64, u64, u64)>::new(), true);
    // Names seen: ply-rs-bw keeps one element of a name and one property of a name (a second
    // `element vertex` was dropped without a word, half the points; a second `property float
    // x` shifted the values it read, "zero normal").
    let (mut names, mut props) = (Vec::<String>::new(), Vec::<String>::new());
    for l in head.lines().map(str::trim) {
        let w: Vec<&str> = l.split_whitespace().collect();
        if let (Some(&"property"), Some(name)) = (w.first(), w.last()) {
            if w.len() >= 3 {
                if props.iter().any(|p| p == name) {
                    let element = names.last().map_or("", String::as_str);
                    return Err(format!("element '{element}': property '{name}' is declared twice in the header"));
                }
                props.push(name.to_string());
                if let Some(e) = elements.last_mut() {
                    e.2 += 1;
                }
            }
        }
        match w.as_slice() {
            ["element", name, count, ..] => {
                let c = count.parse::<u64>().map_err(|_| format!("element '{name}': bad count '{count}' in the header"))?;
                if names.iter().any(|n| n == name) {
                    return Err(format!("element '{name}' is declared twice in the header"));
                }
                names.push(name.to_string());
                props.clear();
                declared += c;
                elements.push((0, c, 0));
            }
            ["property", "list", ..] => fixed = false,
            ["property", ty, _] => {
                let size = match *ty {
                    "char" | "uchar" | "int8" | "uint8" => 1,
                    "short" | "ushort" | "int16" | "uint16" => 2,
                    "int" | "uint" | "float" | "int32" | "uint32" | "float32" => 4,
                    "double" | "float64" => 8,
                    _ => {
                        fixed = false;
                        0
                    }
                };
                if let Some(e) = elements.last_mut() {
                    e.0 += size;
                }
            }
            _ => {}
        }
    }
    if head.lines().any(|l| l.trim_start().starts_with("format ascii")) {
        let text = String::from_utf8_lossy(body);
        let rows = text.lines().filter(|l| !l.trim().is_empty()).count() as u64;
        if rows > declared {
            return Err(format!("the header declares {declared} rows, the file holds {rows}"));
        }
    } else if fixed {
        let want: u64 = elements.iter().map(|&(b, n, _)| b.saturating_mul(n)).fold(0u64, u64::saturating_add);
        if body.len() as u64 > want {
            return Err(format!("the header declares {declared} rows ({want} bytes), the body holds {} bytes", body.len()));
        }
    }
    // ply-rs-bw parses each row into an IndexMap of its properties: about 160 bytes per
    // property (a 64-byte entry, the index, the name's own allocation, the entries'
    // doubling) and 128 per row (stop 82: 1M rows of six floats peaked at 1.6 GB with the
    // surfel object built after). A header declaring more than the memory holds (10^7 rows
    // in a 240 MB file) aborted the parse on a failed allocation, exit 134.
    let parse: u64 = elements.iter().map(|&(_, n, p)| n.saturating_mul(128 + 160 * p)).fold(0u64, u64::saturating_add);
    crate::error::check_memory(parse, &format!("parsing the {declared} rows the header declares"))?;
    Ok(())
}

/// Reads a PLY point file (ASCII or binary) into a single-collection surfel model.
pub fn load_ply(path: &Path) -> Result<SurfelModel, DeformError> {
    let err = |msg: String| DeformError::Ply { path: path.to_path_buf(), msg };
    // The whole file is read before it is parsed.
    crate::error::check_input_read(path, 1).map_err(|e| err(e.to_string()))?;
    let f = std::fs::File::open(path).map_err(|e| err(e.to_string()))?;
    let mut r = std::io::BufReader::new(f);
    read_ply(&mut r, path)
}

/// As [`load_ply`], from any reader (`path` only names the source in errors).
pub fn read_ply<R: std::io::BufRead>(r: &mut R, path: &Path) -> Result<SurfelModel, DeformError> {
    let err = |msg: String| DeformError::Ply { path: path.to_path_buf(), msg };
    let mut buf = Vec::new();
    r.read_to_end(&mut buf).map_err(|e| err(e.to_string()))?;
    body_matches_header(&buf).map_err(err)?;
    let parser = Parser::<DefaultElement>::new();
    let ply = parser.read_ply(&mut buf.as_slice()).map_err(|e| err(format!("parse error: {}", plain_ply_message(&e.to_string()))))?;
    let verts = ply.payload.get("vertex").ok_or_else(|| err("no 'vertex' element".into()))?;
    let get = |e: &DefaultElement, k: &str, i: usize| -> Result<Option<f32>, DeformError> {
        match e.get(k) {
            None => Ok(None),
            Some(p) => scalar(p).map(Some).ok_or_else(|| err(format!("vertex {i}: property '{k}' is a list"))),
        }
    };
    let mut s = SurfelSoa::default();
    let mut has_r = true;
    for (i, e) in verts.iter().enumerate() {
        let mut v = [0f32; 6];
        for (k, name) in ["x", "y", "z", "nx", "ny", "nz"].iter().enumerate() {
            v[k] = get(e, name, i)?.ok_or_else(|| err(format!("vertex {i}: missing property '{name}'")))?;
        }
        let rad = match get(e, "radius", i)? {
            Some(x) => Some(x),
            None => get(e, "r", i)?,
        };
        has_r &= rad.is_some();
        // Without a radius the placeholder is the smallest positive one, which passes the
        // radius checks of `validate` at any model scale (1.0 was "wider than the whole
        // model" for models under a unit across); the k-NN radii below replace it.
        s.push(Vec3::new(v[0], v[1], v[2]), Vec3::new(v[3], v[4], v[5]), rad.unwrap_or(f32::MIN_POSITIVE));
    }
    if s.len() < 4 {
        return Err(DeformError::TooSmall(format!("{}: {} points (need at least 4)", path.display(), s.len())));
    }
    let name = crate::scene::load::stem_name(path, "points");
    if !has_r {
        // The placeholder becomes the model's size, which passes `validate`'s checks of radii
        // against the model (neither wider than it nor a millionth of it) at any scale.
        let (lo, hi) = s.positions().iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
        let diag = (hi - lo).length();
        if diag.is_finite() && diag > 0.0 {
            s.r.iter_mut().for_each(|r| *r = diag);
        }
    }
    // Validate positions and normals (and duplicates) before using them for radii.
    s.validate()?;
    if !has_r {
        // A model too small for f32 says so before its k-NN radii are measured: they were
        // held at 1e-12, and a sphere 3e-20 across was refused for a "radius 1e-12 wider than
        // the whole model", a radius the file never gave.
        let (lo, hi) = s.positions().iter().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
        super::sequences::check_extent(&name, lo, hi)?;
        let pts = s.positions();
        let kd = KdTree::new(&pts);
        let mut out = Vec::new();
        for i in 0..s.len() {
            kd.knn(pts[i], 8, Some(i as u32), &mut out);
            s.r[i] = out.last().map(|x| x.1.sqrt()).unwrap_or(1.0).max(1e-12);
        }
    }
    let mut m = SurfelModel::single(&name, s, [0.7, 0.7, 0.7]);
    m.validate()?;
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ply_text(rows: &[[f32; 6]]) -> String {
        let mut t = format!(
            "ply\nformat ascii 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nend_header\n",
            rows.len()
        );
        for r in rows {
            t += &format!("{} {} {} {} {} {}\n", r[0], r[1], r[2], r[3], r[4], r[5]);
        }
        t
    }

    fn rows() -> Vec<[f32; 6]> {
        (0..20).map(|i| [i as f32, (i * i) as f32 * 0.1, 0.0, 0.0, 0.0, 1.0]).collect()
    }

    #[test]
    fn reads_points() {
        let m = read_ply(&mut ply_text(&rows()).as_bytes(), Path::new("t.ply")).unwrap();
        assert_eq!(m.len(), 20);
        assert!(m.surfels.r.iter().all(|r| *r > 0.0));
    }

    /// Without radii, a model of any scale loads (stop 57: one under a unit across was
    /// refused, the placeholder radius 1 being "wider than the whole model"); its radii are
    /// the 8th-neighbour distances, in the model's units.
    #[test]
    fn small_models_without_radii_load() {
        for scale in [1e-3f32, 0.05, 1.0, 1e3] {
            let r: Vec<[f32; 6]> = rows().iter().map(|r| [r[0] * scale, r[1] * scale, r[2], r[3], r[4], r[5]]).collect();
            let m = read_ply(&mut ply_text(&r).as_bytes(), Path::new("t.ply")).unwrap_or_else(|e| panic!("scale {scale}: {e}"));
            let (lo, hi) = m.surfels.r.iter().fold((f32::MAX, 0f32), |(a, b), &x| (a.min(x), b.max(x)));
            assert!(lo >= 0.99 * scale && hi <= 40.0 * scale, "scale {scale}: radii {lo}..{hi}");
        }
    }

    #[test]
    fn bad_points_are_typed_errors() {
        let mut r = rows();
        r[4][1] = f32::NAN;
        let e = read_ply(&mut ply_text(&r).replace("NaN", "nan").as_bytes(), Path::new("t.ply"));
        assert!(matches!(e, Err(DeformError::BadSurfel { index: 4, .. }) | Err(DeformError::Ply { .. })), "{e:?}");
        let mut r = rows();
        r[5][3..6].copy_from_slice(&[0.0, 0.0, 0.0]);
        assert!(matches!(read_ply(&mut ply_text(&r).as_bytes(), Path::new("t.ply")), Err(DeformError::BadSurfel { index: 5, .. })));
        // One NaN component among finite ones (ply-rs refuses "nan" there; other sources reach
        // the check, where max_element would ignore it).
        let mut soa = SurfelSoa::default();
        soa.push(Vec3::ZERO, Vec3::Y, 1.0);
        soa.push(Vec3::X, Vec3::new(f32::NAN, 1.0, 0.0), 1.0);
        assert!(matches!(soa.validate_values(), Err(DeformError::BadSurfel { index: 1, .. })));
        let mut r = rows();
        r[9] = r[2];
        assert!(matches!(read_ply(&mut ply_text(&r).as_bytes(), Path::new("t.ply")), Err(DeformError::DuplicatePoint { .. })));
        assert!(matches!(read_ply(&mut "garbage".as_bytes(), Path::new("t.ply")), Err(DeformError::Ply { .. })));
        // The header declares 10 vertices, the body holds 20.
        let t = ply_text(&rows()).replace("element vertex 20", "element vertex 10");
        let e = read_ply(&mut t.as_bytes(), Path::new("t.ply"));
        assert!(matches!(e, Err(DeformError::Ply { .. })), "{:?}", e.map(|m| m.len()));
        assert!(load_ply(Path::new("/nonexistent/x.ply")).is_err());
        // Counts that are not whole numbers are named (stop 46: "declares 0 rows").
        for bad in ["-1", "99999999999999999999"] {
            let t = ply_text(&rows()).replace("element vertex 20", &format!("element vertex {bad}"));
            match read_ply(&mut t.as_bytes(), Path::new("t.ply")) {
                Err(DeformError::Ply { msg, .. }) => assert!(msg.contains("bad count"), "{msg}"),
                e => panic!("{bad}: {:?}", e.map(|m| m.len())),
            }
        }
        // Binary: exactly the declared bytes load; more are refused (they were dropped).
        let bin = |rows: &[[f32; 6]], declared: usize| {
            let mut b = format!(
                "ply\nformat binary_little_endian 1.0\nelement vertex {declared}\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nend_header\n"
            )
            .into_bytes();
            for r in rows {
                for v in r {
                    b.extend_from_slice(&v.to_le_bytes());
                }
            }
            b
        };
        assert_eq!(read_ply(&mut bin(&rows(), 20).as_slice(), Path::new("b.ply")).unwrap().len(), 20);
        match read_ply(&mut bin(&rows(), 10).as_slice(), Path::new("b.ply")) {
            Err(DeformError::Ply { msg, .. }) => assert!(msg.contains("body holds"), "{msg}"),
            e => panic!("{:?}", e.map(|m| m.len())),
        }
        // A normal whose length overflows f32 is still a direction.
        let mut r = rows();
        r[3][3..].copy_from_slice(&[1e30, 1e30, 0.0]);
        let m = read_ply(&mut ply_text(&r).as_bytes(), Path::new("t.ply")).unwrap();
        let n = m.surfels.normal(3);
        assert!((n - Vec3::new(1.0, 1.0, 0.0).normalize()).length() < 1e-6, "{n}");
    }

    /// A radius wider than the whole model (a unit mix-up) is refused; one within it loads.
    #[test]
    fn absurd_radius_is_refused() {
        let with_r = |r: f32| {
            let t = ply_text(&rows()).replace("property float nz\n", "property float nz\nproperty float radius\n");
            let mut lines: Vec<String> = t.lines().map(String::from).collect();
            let body = lines.iter().position(|l| l == "end_header").unwrap() + 1;
            for l in &mut lines[body..] {
                *l = format!("{l} {}", if l.starts_with("7 ") { r } else { 0.5 });
            }
            lines.join("\n") + "\n"
        };
        // The rows span 19 × 36.1 units.
        assert!(read_ply(&mut with_r(30.0).as_bytes(), Path::new("t.ply")).is_ok());
        match read_ply(&mut with_r(1e20).as_bytes(), Path::new("t.ply")) {
            Err(DeformError::BadSurfel { index: 7, msg }) => assert!(msg.contains("wider than the whole model"), "{msg}"),
            e => panic!("{:?}", e.map(|m| m.len())),
        }
    }

    /// The parser's chain of nested errors becomes one plain line: the first, the innermost
    /// when short, never a token list or a Debug dump; a body cut short says so in words
    /// when only the innermost io::Error knew it.
    #[test]
    fn ply_messages_are_one_plain_line() {
        assert_eq!(
            plain_ply_message(
                "Line 12: Couldn't read element line. String: '1 0 0 ' Error: Expected element of type 'Scalar(Float)', but found nothing."
            ),
            "Line 12: Couldn't read element line. String: '1 0 0 ' — Expected element of type 'Scalar(Float)', but found nothing."
        );
        assert_eq!(
            plain_ply_message("Line 2: Couldn't parse line. String: 'format foo 1.0 ' Error: ParseError { location: LineCol { line: 1 } }"),
            "Line 2: Couldn't parse line. String: 'format foo 1.0 '"
        );
        assert_eq!(
            plain_ply_message("Line 17: Couldn't read list element. Error: failed to fill whole buffer"),
            "Line 17: Couldn't read list element — failed to fill whole buffer (the file ends early)"
        );
        assert_eq!(plain_ply_message("Line 1:\n  Unexpected   end of file."), "Line 1: Unexpected end of file.");
    }

    /// A binary body that ends inside a list: one plain line that says the file ends early,
    /// no Debug dump of an io::Error ("Error { kind: UnexpectedEof, ... }", as ply-rs 0.1
    /// gave) and no chain of nested errors.
    #[test]
    fn a_short_binary_list_says_the_file_ends_early() {
        let mut b = b"ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nelement face 1\nproperty list uint int vertex_indices\nend_header\n".to_vec();
        for i in 0..4 {
            for v in [i as f32, (i * i) as f32, 1.0, 0.0, 0.0, 1.0] {
                b.extend_from_slice(&v.to_le_bytes());
            }
        }
        b.extend_from_slice(&3u32.to_le_bytes());
        b.extend_from_slice(&0i32.to_le_bytes());
        match read_ply(&mut b.as_slice(), Path::new("t.ply")) {
            Err(DeformError::Ply { msg, .. }) => {
                assert!(msg.contains("end of file") && !msg.contains('{') && !msg.contains("Error:"), "{msg}")
            }
            e => panic!("{:?}", e.map(|m| m.len())),
        }
    }
}
