//! The pinhole camera of DESIGN.md (a contract: the Embree checks depend on it), plus a thin
//! lens (aperture radius, focal distance) for depth of field.

use crate::error::{Error, Result};
use glam::Vec3;

#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    pub eye: Vec3,
    pub look: Vec3,
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub fovy: f32,
    /// Lens radius (0 = pinhole).
    pub aperture: f32,
    /// Distance along the view direction to the plane in focus.
    pub focal_dist: f32,
}

impl Default for Camera {
    fn default() -> Self {
        Camera { eye: Vec3::new(0.0, 0.0, 5.0), look: Vec3::ZERO, up: Vec3::Y, fovy: 45.0, aperture: 0.0, focal_dist: 5.0 }
    }
}

/// The camera resolved for one image size: basis and scale factors.
#[derive(Clone, Copy, Debug)]
pub struct CameraFrame {
    pub eye: Vec3,
    pub f: Vec3,
    pub r: Vec3,
    pub u: Vec3,
    pub s: f32,
    pub aspect: f32,
    pub width: u32,
    pub height: u32,
    pub aperture: f32,
    pub focal_dist: f32,
}

impl Camera {
    pub fn validate(&self) -> Result<()> {
        let f = self.look - self.eye;
        if self.eye.is_finite() && self.look.is_finite() {
            // The automatic framing of a scene at the ±MAX_COORD limit puts the eye a few
            // extents away: the camera gets 100× the room (still far inside Embree's ±1.8e18).
            let far = self.eye.abs().max(self.look.abs()).max_element();
            let lim = 100.0 * super::MAX_COORD;
            if far > lim {
                return Err(Error::Usage(format!("camera: eye or look at coordinate {far:.3e}, beyond ±{lim:e}")));
            }
        }
        let why = if !(self.eye.is_finite() && self.look.is_finite() && self.up.is_finite()) {
            Some("eye, look and up must be finite")
        } else if !(f.length_squared() > 0.0) {
            Some("eye and look must differ")
        } else if !(f.cross(self.up).length_squared() > 1e-20) {
            Some("up must not be zero or parallel to the view")
        } else if !(self.fovy.is_finite() && self.fovy > 0.0 && self.fovy < 180.0) {
            Some("fovy must lie in (0, 180) degrees")
        } else if !(self.aperture.is_finite() && self.aperture >= 0.0) {
            Some("aperture must be finite and ≥ 0")
        } else if !(self.focal_dist.is_finite() && self.focal_dist > 0.0) {
            Some("focal distance must be finite and > 0")
        } else {
            None
        };
        if let Some(why) = why {
            return Err(Error::Usage(format!("camera: {why}")));
        }
        // A lens wider than 100 focal distances opens the defocus cone past 89.4°: every
        // pixel is the whole scene averaged, and lens samples 1e30 away crossed Embree's
        // ±1.8e18 ray-origin limit (stop 57's review: 1e30 was accepted).
        let (far, lim) = (self.eye.abs().max_element(), 100.0 * super::MAX_COORD);
        if self.aperture > 100.0 * self.focal_dist || far + self.aperture > lim {
            return Err(Error::Usage(format!(
                "camera: aperture {:e} is too wide (at most 100 × the focal distance {:e}, and eye ± aperture within ±{lim:e})",
                self.aperture, self.focal_dist
            )));
        }
        Ok(())
    }

    pub fn frame(&self, width: u32, height: u32) -> CameraFrame {
        let f = (self.look - self.eye).normalize();
        let r = f.cross(self.up).normalize();
        let u = r.cross(f);
        CameraFrame {
            eye: self.eye,
            f,
            r,
            u,
            s: (self.fovy.to_radians() * 0.5).tan(),
            aspect: width as f32 / height as f32,
            width,
            height,
            aperture: self.aperture,
            focal_dist: self.focal_dist,
        }
    }
}

impl CameraFrame {
    /// Unit direction through image position (px, py) in pixels (pixel centre of (i, j) is
    /// (i+0.5, j+0.5)); row 0 at the top.
    #[inline]
    pub fn dir_at(&self, px: f32, py: f32) -> Vec3 {
        let x = (2.0 * px / self.width as f32 - 1.0) * self.aspect * self.s;
        let y = (1.0 - 2.0 * py / self.height as f32) * self.s;
        (self.f + x * self.r + y * self.u).normalize()
    }
    /// The DESIGN.md primary ray through the centre of pixel (i, j).
    #[inline]
    pub fn pixel_center_dir(&self, i: u32, j: u32) -> Vec3 {
        self.dir_at(i as f32 + 0.5, j as f32 + 0.5)
    }
    /// [`pixel_center_dir`](Self::pixel_center_dir) of eight pixels (`i[k]`, `j[k]`) in one
    /// f32x8 pass, bit for bit (the same IEEE operations in the same order as glam's). A
    /// packet tracer's tile of rays takes three divisions and a square root per ray, whose
    /// latency the scalar loop mostly waited on.
    pub fn pixel_center_dirs_x8(&self, i: [u32; 8], j: [u32; 8]) -> [Vec3; 8] {
        use wide::f32x8;
        let half = f32x8::splat(0.5);
        let px = f32x8::from(i.map(|v| v as f32)) + half;
        let py = f32x8::from(j.map(|v| v as f32)) + half;
        let two = f32x8::splat(2.0);
        let x = (two * px / f32x8::splat(self.width as f32) - f32x8::ONE) * self.aspect * self.s;
        let y = (f32x8::ONE - two * py / f32x8::splat(self.height as f32)) * self.s;
        let v = [0, 1, 2].map(|a| f32x8::splat(self.f[a]) + x * self.r[a] + y * self.u[a]);
        let rcp = f32x8::ONE / (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let [dx, dy, dz] = v.map(|c| (c * rcp).to_array());
        std::array::from_fn(|k| Vec3::new(dx[k], dy[k], dz[k]))
    }
    /// A thin-lens ray: `dir` is the pinhole direction, (lu, lv) a lens sample in [0,1)².
    /// Returns (origin, unit direction). The focal plane is at distance `focal_dist` along f.
    pub fn lens_ray(&self, dir: Vec3, lu: f32, lv: f32) -> (Vec3, Vec3) {
        if self.aperture <= 0.0 {
            return (self.eye, dir);
        }
        let t_focus = self.focal_dist / dir.dot(self.f);
        let p_focus = self.eye + dir * t_focus;
        let (dx, dy) = crate::core::rng::concentric_disk(lu, lv);
        let o = self.eye + self.r * (dx * self.aperture) + self.u * (dy * self.aperture);
        (o, (p_focus - o).normalize())
    }
}

#[cfg(test)]
mod tests {
    /// The eight-pixel form is the scalar one bit for bit, at odd sizes and over a frame.
    #[test]
    fn pixel_center_dirs_x8_is_the_scalar_one() {
        for (w, h) in [(512u32, 384u32), (37, 1), (1, 53), (1920, 1080)] {
            let cam = Camera { eye: Vec3::new(0.3, 1.7, -4.0), look: Vec3::new(0.1, 0.5, 0.2), ..Camera::default() };
            let fr = cam.frame(w, h);
            for y in (0..h).step_by(7) {
                for x0 in (0..w).step_by(11) {
                    let (i, j) =
                        (std::array::from_fn(|k| (x0 + k as u32 % 4).min(w - 1)), std::array::from_fn(|k| (y + k as u32 / 4).min(h - 1)));
                    let got = fr.pixel_center_dirs_x8(i, j);
                    for k in 0..8 {
                        let want = fr.pixel_center_dir(i[k], j[k]);
                        assert_eq!(
                            got[k].to_array().map(f32::to_bits),
                            want.to_array().map(f32::to_bits),
                            "{w}x{h} pixel ({}, {})",
                            i[k],
                            j[k]
                        );
                    }
                }
            }
        }
    }

    use super::*;
    #[test]
    fn invalid_cameras_name_what_is_wrong() {
        let d = Camera::default();
        assert!(d.validate().is_ok());
        let msg = |c: Camera| c.validate().unwrap_err().to_string();
        assert!(msg(Camera { eye: Vec3::NAN, ..d }).contains("finite"));
        assert!(msg(Camera { look: d.eye, ..d }).contains("eye and look must differ"));
        assert!(msg(Camera { up: Vec3::Z, ..d }).contains("parallel"));
        assert!(msg(Camera { fovy: 0.0, ..d }).contains("fovy"));
        assert!(msg(Camera { aperture: -1.0, ..d }).contains("aperture"));
        assert!(msg(Camera { aperture: 1e30, ..d }).contains("aperture 1e30 is too wide"));
        assert!(msg(Camera { aperture: 600.0, focal_dist: 5.0, ..d }).contains("too wide"));
        assert!(Camera { aperture: 400.0, focal_dist: 5.0, ..d }.validate().is_ok());
        assert!(msg(Camera { focal_dist: 0.0, ..d }).contains("focal distance"));
        assert!(msg(Camera { eye: Vec3::splat(1e30), ..d }).contains("beyond"));
    }
    #[test]
    fn centre_pixel_looks_forward() {
        let c = Camera { eye: Vec3::ZERO, look: Vec3::new(0.0, 0.0, -1.0), up: Vec3::Y, fovy: 90.0, ..Default::default() };
        let fr = c.frame(3, 3);
        assert!((fr.pixel_center_dir(1, 1) - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-6);
        // Row 0 is the top: its y is positive.
        assert!(fr.pixel_center_dir(1, 0).y > 0.0);
        // Column 0 is the left: x negative.
        assert!(fr.pixel_center_dir(0, 1).x < 0.0);
        // fovy 90: top edge at y = tan(45°) = 1 (at pixel edge 0).
        let d = fr.dir_at(1.5, 0.0);
        assert!((d.y / -d.z - 1.0).abs() < 1e-5);
    }
    #[test]
    fn lens_rays_converge_on_focal_plane() {
        let c = Camera { eye: Vec3::ZERO, look: Vec3::new(0.0, 0.0, -1.0), up: Vec3::Y, fovy: 60.0, aperture: 0.2, focal_dist: 4.0 };
        let fr = c.frame(32, 32);
        let d = fr.pixel_center_dir(5, 20);
        let target = d * (4.0 / d.dot(fr.f));
        for (u, v) in [(0.1, 0.9), (0.5, 0.5), (0.8, 0.3)] {
            let (o, dd) = fr.lens_ray(d, u, v);
            let t = (target - o).dot(dd);
            assert!((o + dd * t - target).length() < 1e-4);
        }
    }
}
