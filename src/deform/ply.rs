//! Point files (PLY, via `ply-rs`) as surfel models (Adams et al. §3: surfel models read from
//! point files). The `vertex` element must have `x y z nx ny nz`; a `radius` (or `r`)
//! property is optional. Without it each surfel's radius is the distance to its 8th nearest
//! neighbour (so the discs overlap). NaN/inf coordinates, zero normals and duplicate points
//! are typed errors, never panics.

use super::knn::KdTree;
use super::surfel::{SurfelModel, SurfelSoa};
use super::DeformError;
use glam::Vec3;
use ply_rs::parser::Parser;
use ply_rs::ply::{DefaultElement, Property};
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

/// `ply-rs`'s multi-line parse message (line, offending text, nested `Custom { .. }`
/// error) as one line: whitespace collapsed, the nested debug dump dropped.
fn one_line(msg: &str) -> String {
    let head = msg.split("Error: Custom").next().unwrap_or(msg);
    let head = head.split("Error: ParseError").next().unwrap_or(head);
    // ply-rs spells it so.
    head.replace("Couln't", "Could not").split_whitespace().collect::<Vec<_>>().join(" ")
}

/// An ASCII PLY body must hold exactly the rows its header declares: ply-rs reads the
/// declared counts and silently drops what follows (a wrong count, or two files run
/// together). Binary files are left to the parser.
fn ascii_rows_match_header(buf: &[u8]) -> Result<(), String> {
    let text = String::from_utf8_lossy(buf);
    let Some((head, body)) = text.split_once("end_header") else { return Ok(()) };
    if !head.lines().any(|l| l.trim_start().starts_with("format ascii")) {
        return Ok(());
    }
    let declared: u64 = head
        .lines()
        .filter_map(|l| l.trim().strip_prefix("element "))
        .filter_map(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
        .sum();
    let rows = body.lines().filter(|l| !l.trim().is_empty()).count() as u64;
    if rows > declared {
        return Err(format!("the header declares {declared} rows, the file holds {rows}"));
    }
    Ok(())
}

/// Reads a PLY point file (ASCII or binary) into a single-collection surfel model.
pub fn load_ply(path: &Path) -> Result<SurfelModel, DeformError> {
    let err = |msg: String| DeformError::Ply { path: path.to_path_buf(), msg };
    crate::error::check_input_file(path).map_err(|e| err(e.to_string()))?;
    let f = std::fs::File::open(path).map_err(|e| err(e.to_string()))?;
    let mut r = std::io::BufReader::new(f);
    read_ply(&mut r, path)
}

/// As [`load_ply`], from any reader (`path` only names the source in errors).
pub fn read_ply<R: std::io::BufRead>(r: &mut R, path: &Path) -> Result<SurfelModel, DeformError> {
    let err = |msg: String| DeformError::Ply { path: path.to_path_buf(), msg };
    let mut buf = Vec::new();
    r.read_to_end(&mut buf).map_err(|e| err(e.to_string()))?;
    ascii_rows_match_header(&buf).map_err(err)?;
    let parser = Parser::<DefaultElement>::new();
    let ply = parser.read_ply(&mut buf.as_slice()).map_err(|e| err(format!("parse error: {}", one_line(&e.to_string()))))?;
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
        s.push(Vec3::new(v[0], v[1], v[2]), Vec3::new(v[3], v[4], v[5]), rad.unwrap_or(1.0));
    }
    if s.len() < 4 {
        return Err(DeformError::TooSmall(format!("{}: {} points (need at least 4)", path.display(), s.len())));
    }
    // Validate positions and normals (and duplicates) before using them for radii.
    s.validate()?;
    if !has_r {
        let pts = s.positions();
        let kd = KdTree::new(&pts);
        let mut out = Vec::new();
        for i in 0..s.len() {
            kd.knn(pts[i], 8, Some(i as u32), &mut out);
            s.r[i] = out.last().map(|x| x.1.sqrt()).unwrap_or(1.0).max(1e-12);
        }
    }
    let mut m = SurfelModel::single(
        &path.file_stem().map(|x| x.to_string_lossy().to_string()).unwrap_or_else(|| "points".into()),
        s,
        [0.7, 0.7, 0.7],
    );
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

    #[test]
    fn bad_points_are_typed_errors() {
        let mut r = rows();
        r[4][1] = f32::NAN;
        let e = read_ply(&mut ply_text(&r).replace("NaN", "nan").as_bytes(), Path::new("t.ply"));
        assert!(matches!(e, Err(DeformError::BadSurfel { index: 4, .. }) | Err(DeformError::Ply { .. })), "{e:?}");
        let mut r = rows();
        r[5][3..6].copy_from_slice(&[0.0, 0.0, 0.0]);
        assert!(matches!(read_ply(&mut ply_text(&r).as_bytes(), Path::new("t.ply")), Err(DeformError::BadSurfel { index: 5, .. })));
        let mut r = rows();
        r[9] = r[2];
        assert!(matches!(read_ply(&mut ply_text(&r).as_bytes(), Path::new("t.ply")), Err(DeformError::DuplicatePoint { .. })));
        assert!(matches!(read_ply(&mut "garbage".as_bytes(), Path::new("t.ply")), Err(DeformError::Ply { .. })));
        // The header declares 10 vertices, the body holds 20.
        let t = ply_text(&rows()).replace("element vertex 20", "element vertex 10");
        let e = read_ply(&mut t.as_bytes(), Path::new("t.ply"));
        assert!(matches!(e, Err(DeformError::Ply { .. })), "{:?}", e.map(|m| m.len()));
        assert!(load_ply(Path::new("/nonexistent/x.ply")).is_err());
    }
}
