//! Papaioannou et al., *Exploiting Multiresolution Models to Accelerate Ray Tracing*: LOD chains,
//! the distortion buffer, per-ray LOD selection and the two-pass tracer.

pub mod chain;
pub mod trace;

use crate::error::Result;
use chain::ChainParams;
use trace::LodParams;

/// The command-line options of `--method lod`, each a paper parameter with its default.
#[derive(clap::Args, Debug, Clone)]
pub struct LodArgs {
    /// Levels per mesh including the original (paper: up to 8).
    #[arg(long, default_value_t = 8)]
    pub lod_levels: u32,
    /// Distortion factor f of LOD⁽¹⁾ = LOD⁽⁰⁾·(1 − d)^f (paper: 10–24).
    #[arg(long, default_value_t = 16.0)]
    pub lod_f: f32,
    /// Degradation rate a_LOD of the deeper levels (paper: 0.4–0.6).
    #[arg(long, default_value_t = 0.5)]
    pub lod_a: f32,
    /// thres_LOD: deeper rays degrade only when their level-1 disparity exceeds it (the paper
    /// gives no value; 0.01 ≈ neighbouring rays 1.8° apart on both axes).
    #[arg(long, default_value_t = 0.01)]
    pub lod_threshold: f32,
    /// Disable selective tracing (§4).
    #[arg(long)]
    pub no_selective: bool,
    /// Ray level from which selective tracing drops the weaker child (paper: 2).
    #[arg(long, default_value_t = 2)]
    pub lod_selective_level: u32,
    /// Strength ratio above which selective tracing drops the weaker child (paper: 200 % = 2).
    #[arg(long, default_value_t = 2.0)]
    pub lod_selective_ratio: f32,
    /// When selective tracing applies: the ray's model is coarser than L₀ (`model`), or its
    /// LOD value is below 1 (`value`, the literal reading of §4, used until stop 50).
    #[arg(long, value_enum, default_value = "model")]
    pub lod_selective_on: trace::SelectiveOn,
    /// Distance criterion: objects farther than this get LOD = distance₀/distance as their
    /// highest model (off by default).
    #[arg(long)]
    pub lod_distance: Option<f32>,
    /// Force every ray to this LOD (1.0 renders what `--method whitted` renders).
    #[arg(long)]
    pub lod_force: Option<f32>,
    /// Measure disparity net of the incident rays' divergence (a flat mirror gives 0).
    #[arg(long)]
    pub lod_net_disparity: bool,
    /// What lowers the level-1 LOD: the paper's neighbour disparity, or the spread a ray
    /// cone gains from the surface curvature (beyond the paper).
    #[arg(long, value_enum, default_value = "disparity")]
    pub lod_selector: trace::Selector,
}

impl Default for LodArgs {
    fn default() -> Self {
        let p = LodParams::default();
        LodArgs {
            lod_levels: 8,
            lod_f: p.f,
            lod_a: p.a_lod,
            lod_threshold: p.thres,
            no_selective: !p.selective,
            lod_selective_level: p.selective_level,
            lod_selective_ratio: p.selective_ratio,
            lod_selective_on: p.selective_on,
            lod_distance: None,
            lod_force: None,
            lod_net_disparity: p.net_disparity,
            lod_selector: p.selector,
        }
    }
}

impl LodArgs {
    /// The options set away from their defaults, by their command-line names (`render`
    /// refuses them for the other methods, which would ignore them).
    pub fn changed(&self) -> Vec<&'static str> {
        let d = Self::default();
        let mut v = Vec::new();
        macro_rules! diff {
            ($($f:ident => $n:literal),* $(,)?) => { $( if self.$f != d.$f { v.push($n) } )* };
        }
        diff!(
            lod_levels => "--lod-levels", lod_f => "--lod-f", lod_a => "--lod-a", lod_threshold => "--lod-threshold",
            no_selective => "--no-selective", lod_selective_level => "--lod-selective-level",
            lod_selective_ratio => "--lod-selective-ratio", lod_selective_on => "--lod-selective-on", lod_distance => "--lod-distance", lod_force => "--lod-force",
            lod_net_disparity => "--lod-net-disparity", lod_selector => "--lod-selector",
        );
        v
    }

    pub fn params(&self) -> Result<(ChainParams, LodParams)> {
        let p = LodParams {
            f: self.lod_f,
            a_lod: self.lod_a,
            thres: self.lod_threshold,
            selective: !self.no_selective,
            selective_level: self.lod_selective_level,
            selective_ratio: self.lod_selective_ratio,
            selective_on: self.lod_selective_on,
            force: self.lod_force,
            net_disparity: self.lod_net_disparity,
            selector: self.lod_selector,
        };
        p.validate()?;
        let c = ChainParams { levels: self.lod_levels, distance: self.lod_distance };
        c.validate()?;
        Ok((c, p))
    }
}

/// A pass-1 map as a greyscale image: `disparity-r`/`disparity-t` show 20·d (white at
/// d ≥ 0.05), `lod-r`/`lod-t` show 1 − LOD⁽¹⁾ (white = coarsest), so darker is more detail
/// in every map.
pub fn maps_image(m: &trace::LodMaps, kind: &str) -> image::RgbImage {
    let v: Vec<f32> = match kind {
        "disparity-r" => m.d_r.iter().map(|d| 20.0 * d).collect(),
        "disparity-t" => m.d_t.iter().map(|d| 20.0 * d).collect(),
        "lod-r" => m.lod_r.iter().map(|l| 1.0 - l).collect(),
        _ => m.lod_t.iter().map(|l| 1.0 - l).collect(),
    };
    image::RgbImage::from_fn(m.width, m.height, |x, y| {
        let g = (v[(y * m.width + x) as usize].clamp(0.0, 1.0) * 255.0).round() as u8;
        image::Rgb([g, g, g])
    })
}
