//! Wand & Straßer 2003, *Multi-Resolution Point-Sample Raytracing*: anisotropic ray cones
//! traced through a multi-resolution octree of prefiltered differential point samples, with a
//! one-pixel A-buffer per ray.
//!
//! - [`build`]: the point hierarchy (§3.1–3.2), [`quant`]: its quantisation (§3.2), and
//!   [`cache`]: its on-disk cache (built once per mesh, materials and parameters, then read back);
//! - [`cone`]: ray cones, footprints and their construction for every ray kind (§4.1–4.2);
//! - [`abuffer`]: fragments, merging and alpha compositing (§4.4);
//! - [`group`]: points over groups of instances (the instance tree's slots), the level of
//!   detail above the objects;
//! - [`trace`]: the intersection tests (§4.3, 4.5, 4.6), the traversal (§5.1–5.2) and shading;
//! - [`render`]: the image loop of `--method multires` and `--method cone`;
//! - [`octree_accel`]: `--accel octree`, the conventional tracer on the same octree (§6).
//!
//! Each paper parameter is a named option ([`MultiresArgs`]). Twelve default to a deviation
//! from the paper, each documented where it is set; `--paper` (`paper=1` in `bench`) gives the
//! paper's choice for all of them ([`MultiresArgs::PAPER`]).
pub mod abuffer;
pub mod build;
pub mod cache;
pub mod cone;
pub mod group;
pub mod mask;
pub mod mass;
pub mod octree_accel;
pub mod plane;
pub mod quant;
pub mod render;
pub mod trace;

use crate::error::Result;
use build::BuildParams;
use trace::{EigenMode, TraceParams};

/// Command-line options of the cone tracers (shared by `render`; `bench` specs use short keys).
#[derive(clap::Args, Debug, Clone)]
pub struct MultiresArgs {
    /// Quantisation grid per octree node: k³ voxels (point spacing = node side / k).
    /// (The paper gives no value; 4 measured fastest on `spheres`: 256² frame 2.7 s vs 7.3 s at
    /// k = 8 and 27 s at k = 16, because large triangles then sit in smaller nodes.)
    // Range checked by the parser too, so `--k -1` names 2..=64, not u32's range.
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u32).range(2..=64))]
    pub k: u32,
    /// Oversampling factor c of the point prefiltering (paper: typically 100).
    #[arg(long, default_value_t = 100.0)]
    pub oversampling: f32,
    /// A triangle with more than this many representative points in a node stays in that
    /// node and is intersected as a triangle; the others go down to its children (paper §3.1:
    /// "more than 3").
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub stay_reps: u32,
    /// Depth limit of the point octree: the triangles that reach it stay in their node.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=30))]
    pub max_tree_depth: u32,
    /// Surface area behind a point's weight: `area` (the samples' area in its voxel; the
    /// default, a deviation that reduces the paper's overestimated opacity of sparse
    /// geometry) or `voxel` (a whole voxel face, as the paper).
    #[arg(long, value_enum, default_value = "area", conflicts_with = "paper")]
    pub point_weights: build::PointWeights,
    /// Anisotropy limit: the minor footprint axis is at least this fraction of the major (paper: 1/4..1/16).
    #[arg(long, default_value_t = 0.125)]
    pub anisotropy_clamp: f32,
    /// Anisotropy limit of reflected and refracted cones and of their hits' shadow cones
    /// (default: `--anisotropy-clamp`, as the paper). Larger values trade blur in the
    /// reflections' narrow direction for speed: on `complex` 640×480, 1 with `--lod-scale 4`
    /// takes the frame from 3.6× the octree Whitted frame to 2.1× (stop 82; 3.0× and 1.8× at
    /// stop 28, before the review fixes to the images since; BENCHMARKS.md).
    #[arg(long)]
    pub secondary_clamp: Option<f32>,
    /// Level of detail: use a node's points when lod_scale × the footprint's minor semi-axis ≥
    /// point spacing (2, the default, is the paper's "spacing no larger than the minimum
    /// diameter", §5.1).
    #[arg(long, default_value_t = 2.0)]
    pub lod_scale: f32,
    /// Depth tolerance of a point sample for fragment merging, in point spacings.
    #[arg(long, default_value_t = 1.0)]
    pub depth_tolerance: f32,
    /// Eigen-decomposition once per octree box (paper §5.2) or exactly per point/vertex.
    #[arg(long, value_enum, default_value = "per-box")]
    pub eigen: EigenMode,
    /// Ray–triangle weight: the paper's exp(−(d−0.5)²) or the exact Gaussian edge coverage
    /// (default: on a black/white checkerboard, 96², RMSE against 256 spp 0.015 vs 0.070 with
    /// the paper's formula at cone scale 0.5; 0.046 vs 0.106 at cone scale 1). `mass`
    /// integrates the Gaussian over the whole triangle, right for leaf blades thinner than
    /// the footprint too (`complex` 640×480: mean FLIP 0.1062 vs 0.1229, but 2.5× the time,
    /// since see-through foliage no longer stops cones early).
    #[arg(long, value_enum, default_value = "coverage", conflicts_with = "paper")]
    pub tri_weight: trace::TriWeight,
    /// Ray–triangle weight of shadow cones (default: `--tri-weight`). `mass` gives a soft
    /// shadow the true coverage of a tessellated occluder, whose triangles are smaller than
    /// the shadow cone's footprint (`coverage` gives each up to half the footprint): `effects`
    /// 400×300 mean FLIP 0.181 → 0.145, `spheres` 512² 0.0219 → 0.0158, for 1.3–1.7× the
    /// time (README, stop 39).
    #[arg(long, value_enum)]
    pub shadow_tri_weight: Option<trace::TriWeight>,
    /// Let a fragment's alpha be the sum of all its weights and its normal the mean of all
    /// its pieces', as the paper, instead of the larger of the weights facing towards and away
    /// from the cone's origin and the normal of the closed surfaces' side that shows (the
    /// default, a deviation): a wide footprint that merges a solid's near and far sides into
    /// one fragment otherwise counts its coverage twice, the paper's overestimated soft
    /// shadows and silhouettes (§7), and shades it with a normal averaged from both sides.
    /// See `multires::abuffer::Frag::alpha`.
    #[arg(long)]
    pub no_facing: bool,
    /// Sum every piece whose depth interval overlaps a fragment into it, as the paper;
    /// default (a deviation): a fragment keeps the pieces of two meshes (an object and the
    /// floor it stands on) apart and composites them front to back by their mean depths, so a
    /// floor behind an object's base does not average into the object (the paper's §7
    /// "merges the floor and the base of the bunny into a single fragment"). See
    /// `multires::abuffer::Frag::parts`.
    #[arg(long)]
    pub merge_meshes: bool,
    /// Primary cone footprint in pixels (1 = the pixel's extent, the paper's wording). The
    /// default 0.5 is close to 0.41, where the Gaussian's variance equals a box pixel's.
    #[arg(long, default_value_t = 0.5, conflicts_with = "paper")]
    pub cone_scale: f32,
    /// Depth of field: the cone's footprint at the lens in lens radii (the paper does not say;
    /// 1 = the radius). The default 1/√2 gives the Gaussian the variance of the thin lens's
    /// uniform disk, which distributed ray tracing samples.
    #[arg(long, default_value_t = std::f32::consts::FRAC_1_SQRT_2, conflicts_with = "paper")]
    pub lens_scale: f32,
    /// Blurry reflection: the cone's added spread in units of tan(roughness) (§6; the paper
    /// does not say, 1 = tan(roughness)). The default 1/√2 gives the Gaussian the variance of
    /// the uniform cone of half-angle `roughness` that distributed ray tracing samples.
    #[arg(long, default_value_t = std::f32::consts::FRAC_1_SQRT_2, conflicts_with = "paper")]
    pub rough_scale: f32,
    /// Elliptical lights: the shadow cone's light Gaussian in units of the ellipse's axes
    /// (§4.2; 1 = the axes). The default 1/√2 gives it the variance of the uniform ellipse
    /// that distributed ray tracing samples.
    #[arg(long, default_value_t = std::f32::consts::FRAC_1_SQRT_2, conflicts_with = "paper")]
    pub light_scale: f32,
    /// Disable the mipmap blend one level down.
    #[arg(long)]
    pub no_mipmap: bool,
    /// Trace primary cones only (local shading, no shadow or secondary cones).
    #[arg(long)]
    pub primary_only: bool,
    /// Early ray termination: `paper` stops a cone once the alpha of all its fragments reaches
    /// one (§4.4); `final` waits until those fragments lie wholly before the traversal front.
    /// With `--method cone` on wide cones (shadow and secondary cones, depth of field) `final`
    /// can take minutes: without points nothing ends a cone's descent before the triangles
    /// it overlaps, all of them (`complex` 64×48: 160 s); `--time-budget` bounds it.
    #[arg(long, value_enum, default_value = "paper")]
    pub termination: trace::Termination,
    /// Shade every fragment by its single averaged normal, as the paper (default: aggregates
    /// of differently facing pieces, such as foliage, blend in the mean cosine of normals
    /// spread over the hemisphere, by their normal spread).
    #[arg(long)]
    pub no_normal_spread: bool,
    /// Visit every instance a cone overlaps, instead of stopping at a slot of the instance
    /// tree whose spacing the footprint covers and using that slot's points (the default; a
    /// completion of the paper for instanced scenes, see `multires::group`).
    #[arg(long)]
    pub no_group_points: bool,
    /// Start every fragment's shadow cones past its own footprint (projected on the plane of
    /// its mean normal), as for a surface; default: aggregates of differently facing pieces
    /// (foliage) skip their own thickness only, so the leaves within the footprint still
    /// shadow each other (a deviation from the paper).
    #[arg(long)]
    pub no_aggregate_shadow: bool,
    /// Give a triangle's fragment no more depth than the triangle's own vertices span, instead
    /// of its plane's span across the footprint (the paper's surface rule, the default):
    /// pieces smaller than the footprint at different depths (leaves, the two sides of a
    /// glass shell) then composite front to back instead of summing into one fragment. A
    /// deviation from the paper; `complex` 320×240: mean FLIP 0.1207 → 0.1189 for 27 % more
    /// time, with `--tri-weight mass` 0.0896 → 0.0854 for 32 % more.
    #[arg(long)]
    pub tight_depth: bool,
    /// Give triangle fragments coverage masks (64 sub-rays of the cone) and use them to
    /// correct the front-to-back compositing where pieces in successive fragments cover the
    /// same part of the footprint (leaves of one plant), which alpha alone counts twice. A
    /// deviation from the paper (Carpenter's A-buffer remedy); see `multires::mask`.
    #[arg(long)]
    pub coverage_masks: bool,
    /// Trace the shadow cones of a flat surface (a board) through the surface's own plane
    /// too, rejecting its pieces near the start one by one as the paper does; default: skip
    /// every instance on that plane when the light lies wholly on the lit side (a plane
    /// cannot shadow itself; a deviation, see `multires::plane`).
    #[arg(long)]
    pub no_plane_skip: bool,
    /// Stop rendering after this many seconds (the frame is reported as unfinished).
    #[arg(long)]
    pub time_budget: Option<f64>,
    /// The paper as written: every option that defaults to a deviation takes the paper's
    /// choice instead ([`MultiresArgs::PAPER`]: voxel point weights, the paper's triangle
    /// weight, a one-pixel primary cone, lens, roughness and light cones of the full radius,
    /// alpha and normal summed over a fragment, meshes merged, one normal per fragment, every
    /// instance visited, shadow cones past the whole footprint, self-shadowing planes
    /// traversed). Refused beside any of those options. Two things stay: the leaf-disc and
    /// weight-cut-off details the paper leaves open, and depth of field adds the squares of
    /// the lens and pixel cones where the paper takes their maximum (a maximum of two
    /// ellipses is no footprint of the form fp(t); `cone` module docs).
    #[arg(long)]
    pub paper: bool,
}

impl Default for MultiresArgs {
    fn default() -> Self {
        let b = BuildParams::default();
        let t = TraceParams::default();
        MultiresArgs {
            k: b.k,
            oversampling: b.c,
            stay_reps: b.stay_reps,
            max_tree_depth: b.max_depth,
            point_weights: b.weights,
            anisotropy_clamp: t.clamp,
            secondary_clamp: t.secondary_clamp,
            lod_scale: t.lod_scale,
            depth_tolerance: t.depth_tol,
            eigen: t.eigen,
            tri_weight: t.tri_weight,
            shadow_tri_weight: t.shadow_tri_weight,
            no_facing: !t.facing,
            merge_meshes: !t.split_meshes,
            cone_scale: t.cone_scale,
            lens_scale: t.lens_scale,
            rough_scale: t.rough_scale,
            light_scale: t.light_scale,
            no_mipmap: !t.mipmap,
            primary_only: t.primary_only,
            time_budget: t.time_budget,
            termination: t.termination,
            no_normal_spread: !t.normal_spread,
            no_group_points: !t.group_points,
            no_aggregate_shadow: !t.aggregate_shadow,
            tight_depth: t.tight_depth,
            coverage_masks: t.coverage_masks,
            no_plane_skip: !t.plane_skip,
            paper: false,
        }
    }
}

impl MultiresArgs {
    /// The options `--paper` sets, by their command-line names: each defaults to a
    /// deviation from the paper (its documentation says which and why).
    pub const PAPER: [&'static str; 12] = [
        "--point-weights",
        "--tri-weight",
        "--cone-scale",
        "--lens-scale",
        "--rough-scale",
        "--light-scale",
        "--no-facing",
        "--merge-meshes",
        "--no-normal-spread",
        "--no-group-points",
        "--no-aggregate-shadow",
        "--no-plane-skip",
    ];

    /// These options with `--paper` applied: the paper's choice for each of [`Self::PAPER`].
    /// An error if `--paper` comes with one of those options set.
    pub fn resolved(&self) -> Result<MultiresArgs> {
        if !self.paper {
            return Ok(self.clone());
        }
        let (b, t) = self.changed();
        if let Some(o) = b.iter().chain(&t).find(|o| Self::PAPER.contains(o)) {
            return Err(crate::error::Error::Usage(format!("--paper sets {o} to the paper's choice; give one or the other")));
        }
        Ok(MultiresArgs {
            point_weights: build::PointWeights::Voxel,
            tri_weight: trace::TriWeight::Paper,
            cone_scale: 1.0,
            lens_scale: 1.0,
            rough_scale: 1.0,
            light_scale: 1.0,
            no_facing: true,
            merge_meshes: true,
            no_normal_spread: true,
            no_group_points: true,
            no_aggregate_shadow: true,
            no_plane_skip: true,
            ..self.clone()
        })
    }

    /// The options set away from their defaults, by their command-line names: first those of
    /// the octree build (`--k`, `--oversampling`, `--stay-reps`, `--max-tree-depth`,
    /// `--point-weights`, which `--accel octree` uses too), then the cone tracers' own. `render` refuses them for a method that would
    /// ignore them.
    pub fn changed(&self) -> (Vec<&'static str>, Vec<&'static str>) {
        let d = Self::default();
        let mut build = Vec::new();
        let mut trace = Vec::new();
        macro_rules! diff {
            ($v:ident: $($f:ident => $n:literal),* $(,)?) => { $( if self.$f != d.$f { $v.push($n) } )* };
        }
        // NaN differs from every default, so an invalid value is reported here too.
        diff!(build: k => "--k", oversampling => "--oversampling", stay_reps => "--stay-reps", max_tree_depth => "--max-tree-depth",
            point_weights => "--point-weights");
        diff!(trace:
            anisotropy_clamp => "--anisotropy-clamp", secondary_clamp => "--secondary-clamp", lod_scale => "--lod-scale",
            depth_tolerance => "--depth-tolerance", eigen => "--eigen", tri_weight => "--tri-weight",
            shadow_tri_weight => "--shadow-tri-weight", no_facing => "--no-facing", merge_meshes => "--merge-meshes", cone_scale => "--cone-scale", lens_scale => "--lens-scale",
            rough_scale => "--rough-scale", light_scale => "--light-scale",
            no_mipmap => "--no-mipmap", primary_only => "--primary-only", termination => "--termination",
            no_normal_spread => "--no-normal-spread", no_group_points => "--no-group-points",
            no_aggregate_shadow => "--no-aggregate-shadow", tight_depth => "--tight-depth", coverage_masks => "--coverage-masks",
            no_plane_skip => "--no-plane-skip", time_budget => "--time-budget", paper => "--paper",
        );
        (build, trace)
    }

    /// The options of the cones that `--primary-only` does not trace: shadow cones
    /// ([`Self::SHADOW`]) and reflected and refracted cones.
    pub const AFTER_PRIMARY: [&'static str; 6] =
        ["--secondary-clamp", "--rough-scale", "--shadow-tri-weight", "--light-scale", "--no-aggregate-shadow", "--no-plane-skip"];
    /// The options of the shadow cones alone, which `render --no-shadows` does not trace.
    pub const SHADOW: [&'static str; 4] = ["--shadow-tri-weight", "--light-scale", "--no-aggregate-shadow", "--no-plane-skip"];

    pub fn params(&self, points: bool) -> Result<(BuildParams, TraceParams)> {
        // An option of cones that are not traced is refused, as another method's options
        // are: until stop 80 `--primary-only --secondary-clamp 1` rendered what
        // `--primary-only` did, without a word.
        if self.primary_only {
            if let Some(o) = self.changed().1.iter().find(|o| Self::AFTER_PRIMARY.contains(o)) {
                return Err(crate::error::Error::Usage(format!(
                    "{o} has no effect beside --primary-only (no shadow, reflected or refracted cones)"
                )));
            }
        }
        let r = self.resolved()?;
        let b = BuildParams {
            k: r.k,
            c: r.oversampling,
            stay_reps: r.stay_reps,
            max_depth: r.max_tree_depth,
            weights: r.point_weights,
            ..Default::default()
        };
        let t = TraceParams {
            clamp: r.anisotropy_clamp,
            secondary_clamp: r.secondary_clamp,
            lod_scale: r.lod_scale,
            depth_tol: r.depth_tolerance,
            eigen: r.eigen,
            tri_weight: r.tri_weight,
            shadow_tri_weight: r.shadow_tri_weight,
            facing: !r.no_facing,
            split_meshes: !r.merge_meshes,
            cone_scale: r.cone_scale,
            lens_scale: r.lens_scale,
            rough_scale: r.rough_scale,
            light_scale: r.light_scale,
            mipmap: !r.no_mipmap,
            primary_only: r.primary_only,
            time_budget: r.time_budget,
            termination: r.termination,
            normal_spread: !r.no_normal_spread,
            group_points: !r.no_group_points,
            aggregate_shadow: !r.no_aggregate_shadow,
            tight_depth: r.tight_depth,
            coverage_masks: r.coverage_masks,
            plane_skip: !r.no_plane_skip,
            points,
            ..Default::default()
        };
        b.validate()?;
        t.validate()?;
        Ok((b, t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `--paper` sets exactly the options of [`MultiresArgs::PAPER`], each to a value other
    /// than its default (each defaults to a deviation), changes nothing else, and refuses to
    /// be combined with any of them.
    #[test]
    fn paper_sets_every_deviation_and_refuses_a_clash() {
        let r = MultiresArgs { paper: true, ..Default::default() }.resolved().unwrap();
        let (b, t) = MultiresArgs { paper: false, ..r.clone() }.changed();
        let mut set: Vec<&str> = b.into_iter().chain(t).collect();
        set.sort();
        let mut want = MultiresArgs::PAPER.to_vec();
        want.sort();
        assert_eq!(set, want);
        let (bp, tp) = MultiresArgs { paper: true, ..Default::default() }.params(true).unwrap();
        assert_eq!(bp.weights, build::PointWeights::Voxel);
        assert_eq!(
            (tp.tri_weight, tp.cone_scale, tp.facing, tp.split_meshes, tp.plane_skip),
            (trace::TriWeight::Paper, 1.0, false, false, false)
        );
        // Without `--paper`, resolved() is the options themselves.
        let d = MultiresArgs::default();
        assert!(d.resolved().unwrap().changed() == (Vec::new(), Vec::new()));
        let clash = MultiresArgs { paper: true, cone_scale: 0.7, ..Default::default() };
        let e = clash.resolved().unwrap_err().to_string();
        assert!(e.contains("--cone-scale"), "{e}");
        // An option --paper does not set combines with it.
        let ok = MultiresArgs { paper: true, lod_scale: 3.0, ..Default::default() }.params(true).unwrap();
        assert_eq!(ok.1.lod_scale, 3.0);
    }

    /// Every build parameter of §3 is an option with the paper's default (stop 91: the
    /// "more than 3" representatives and the depth limit were fixed, and `validate` named
    /// options that did not exist): the defaults are [`BuildParams::default`], set values
    /// reach the build, and `changed` reports them as build options.
    #[test]
    fn build_parameters_are_options() {
        let d = MultiresArgs::default();
        assert_eq!(d.params(true).unwrap().0, BuildParams::default());
        let a = MultiresArgs { stay_reps: 7, max_tree_depth: 9, ..Default::default() };
        let b = a.params(true).unwrap().0;
        assert_eq!((b.stay_reps, b.max_depth), (7, 9));
        assert_eq!(a.changed().0, vec!["--stay-reps", "--max-tree-depth"]);
        use clap::Parser;
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            m: MultiresArgs,
        }
        let p = Cli::try_parse_from(["x"]).unwrap();
        assert_eq!((p.m.stay_reps, p.m.max_tree_depth), (3, 20));
        let p = Cli::try_parse_from(["x", "--stay-reps", "5", "--max-tree-depth", "12"]).unwrap();
        assert_eq!((p.m.stay_reps, p.m.max_tree_depth), (5, 12));
        for bad in [["--stay-reps", "0"], ["--stay-reps", "1001"], ["--max-tree-depth", "0"], ["--max-tree-depth", "31"]] {
            assert!(Cli::try_parse_from(["x", bad[0], bad[1]]).is_err(), "{bad:?}");
        }
    }
}
