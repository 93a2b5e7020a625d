//! The film: linear RGB radiance per pixel plus the depth and normal AOVs, and its outputs.
//! Files are written to a temporary name beside the target and renamed, so a failed run
//! never leaves a half-written image.

pub mod io;
pub mod metrics;

use glam::Vec3;

#[derive(Clone, Debug)]
pub struct Film {
    pub width: u32,
    pub height: u32,
    /// Linear radiance, row-major, row 0 at the top.
    pub color: Vec<Vec3>,
    /// Distance along the unit primary direction to the first hit (`+inf` for a miss).
    pub depth: Vec<f32>,
    /// World-space shading normal at the first hit (zero for a miss).
    pub normal: Vec<Vec3>,
}

impl Film {
    pub fn new(width: u32, height: u32) -> Self {
        let n = (width as usize) * (height as usize);
        Film { width, height, color: vec![Vec3::ZERO; n], depth: vec![f32::INFINITY; n], normal: vec![Vec3::ZERO; n] }
    }
    #[inline]
    pub fn index(&self, i: u32, j: u32) -> usize {
        j as usize * self.width as usize + i as usize
    }
}

/// Linear → sRGB transfer, clamped to \[0, 1\].
#[inline]
pub fn linear_to_srgb(x: f32) -> f32 {
    let x = if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// sRGB → linear.
#[inline]
pub fn srgb_to_linear(x: f32) -> f32 {
    if x <= 0.040_45 {
        x / 12.92
    } else {
        ((x + 0.055) / 1.055).powf(2.4)
    }
}
