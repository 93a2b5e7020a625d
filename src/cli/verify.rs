//! `lodtrace verify SCENE [--accel bvh] [--rays N]`: cross-check an intersector against
//! Embree in robust mode (see [`crate::baseline::verify`] for the ray sets and tolerances).
use crate::baseline::accel::AccelKind;
use crate::error::{Error, Result};
use std::path::PathBuf;

#[derive(clap::Args, Debug, Clone)]
pub struct VerifyArgs {
    /// Built-in scene name, or an .obj, .off or .toml file.
    pub scene: String,
    /// The back-end to check (`embree` checks Embree's fast mode against its robust mode).
    #[arg(long, value_enum, default_value = "bvh")]
    pub accel: AccelKind,
    /// Random and aimed rays (plus 64×64 camera rays and a few invalid rays).
    #[arg(long, default_value_t = 100_000)]
    pub rays: usize,
    /// Seed of the ray sets (the same seed, scene and --rays give the same rays).
    #[arg(long, default_value_t = 1)]
    pub seed: u32,
    /// Also write the report as JSON (`none`: not written).
    #[arg(long)]
    pub json: Option<PathBuf>,
}

/// Returns the exit code: 0 agreement, 1 disagreement beyond tolerance.
#[cfg(feature = "embree")]
pub fn run(a: &VerifyArgs) -> Result<i32> {
    // The rays and both intersectors' hits are held at once (about 170 bytes a ray, peak
    // RSS `/usr/bin/time -f %M`): 1e7 rays take 1.7 GB.
    if a.rays == 0 || a.rays > 10_000_000 {
        return Err(Error::Usage(format!("--rays {} is out of range (1..=10000000)", a.rays)));
    }
    // A failed allocation aborts without an error line (`--rays 10000000` under `ulimit -v
    // 1200000`).
    crate::error::check_memory(a.rays as u64 * 170, &format!("--rays {}", a.rays)).map_err(Error::Usage)?;
    if let Some(p) = &a.json {
        if super::render::is_stdout(p) {
            return Err(Error::Usage("--json -: verify prints its table on standard output; give --json a file name".into()));
        }
        super::render::check_json_path(p, "--json")?;
        crate::film::io::check_outputs_apart_from_scene(&a.scene, &[p])?;
    }
    let scene = crate::scene::load::load_scene(&a.scene)?;
    let t0 = std::time::Instant::now();
    let rep = crate::baseline::verify::verify_scene(&scene, a.accel, a.rays, a.seed)?;
    crate::error::print_stdout(&format!(
        "{}({} rays in {:.2} s)\n",
        crate::baseline::verify::format_report(&rep),
        rep.total_rays(),
        t0.elapsed().as_secs_f64()
    ))?;
    if let Some(p) = &a.json {
        // The report plus what reproduces and judges it.
        let mut v = serde_json::to_value(&rep).map_err(|e| Error::Usage(e.to_string()))?;
        if let Some(o) = v.as_object_mut() {
            o.insert("rays".into(), a.rays.into());
            o.insert("seed".into(), a.seed.into());
            o.insert("mismatches_total".into(), rep.mismatches().into());
            o.insert("pass".into(), (rep.mismatches() == 0).into());
        }
        let text = serde_json::to_string_pretty(&v).map_err(|e| Error::Usage(e.to_string()))? + "\n";
        crate::film::io::write_atomic(p, |tmp| std::fs::write(tmp, &text).map_err(|e| Error::io(p, e)))?;
    }
    Ok(if rep.mismatches() == 0 { 0 } else { 1 })
}

#[cfg(not(feature = "embree"))]
pub fn run(_a: &VerifyArgs) -> Result<i32> {
    Err(Error::Usage("verify needs Embree (cargo feature 'embree' is off)".into()))
}
