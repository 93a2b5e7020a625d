//! The displacement field (Adams et al. §3, Eq. 1–2) and the optimal rigid transformation
//! that is factored out of it every step (§4.1.3, Eq. 10).
//!
//! Per frame the simulation hands us the deformed node positions `x'_j`. From them:
//! 1. Eq. 10: centres of mass `x̄`, `x̄'`; `F = Σ m_j² (x_j − x̄)(x'_j − x̄')ᵀ`; SVD
//!    `F = U W Vᵀ`; `R = V Uᵀ` (a reflection is turned into the nearest rotation by flipping
//!    the axis of the smallest singular value). The transformed reference of a point is
//!    `x̂ = R x + t'` with `t' = x̄' − R x̄`.
//! 2. Relative node displacements `û_j = x'_j − x̂_j`.
//! 3. The displacement gradient at each node, by moving least squares over its `k_grad`
//!    nearest nodes (\[MKN*04\]): `∇û_j = (Σ_k w_jk (û_k − û_j) d̂_jkᵀ) M̂_j⁻¹`. Written against
//!    the *reference* offsets `d_jk = x_k − x_j` it becomes `K_j = ∇û_j R =
//!    (Σ_k w_jk (û_k − û_j) d_jkᵀ) M_j⁺`, so `M_j⁺` (pseudo-inverse: surface-sampled nodes
//!    make `M_j` near-singular across the surface) is precomputed once.
//!
//! Eq. 1 then reads `x'_i = R x_i + t' + Σ_j ω̄_ij (û_j + K_j d_ij)` with `d_ij = x_i − x_j`,
//! the first-order Taylor expansion of the displacement about node j as in \[MKN*04\]. (The
//! paper defines `d_{x,y} = y − x`, which read literally gives the opposite sign and is not
//! first-order accurate; the bounds of Eq. 9 only use ‖d‖ and are unaffected.) The tangent axes
//! deform with the same first-order map, `u'_i = (R + Σ_j ω̄_ij K_j) u_i` (§3, after
//! \[PKKG03\]); the deformed normal is `u' × v'`. `‖K_j‖_F = ‖∇û_j‖_F` (R is orthogonal): the
//! Frobenius norm the radius bound (Eq. 9) uses.
//!
//! With `factor_rigid = false` (ablation), R = I and t' = 0, i.e. displacements are measured
//! in the reference system as in Figure 2, left.

use super::knn::KdTree;
use super::DeformError;
use glam::{Mat3, Mat3A, Vec3, Vec3A, Vec4};
use wide::f32x8;

/// The radial spline of Eq. 2: `1 − 6r² + 8r³ − 3r⁴` for `r < 1`, else 0 (NaN too, as
/// the f32x8 kernels' `r < 1` mask gives). Evaluated as `(1 − r)³(1 + 3r)`, the same
/// polynomial: the expanded form cancels near r = 1 and went slightly negative there in f32
/// (−7e-7 at r = 0.998, where the weight is +3e-8; review finding, stop 77).
#[inline(always)]
pub fn spline_weight(r: f32) -> f32 {
    if r < 1.0 {
        let s = 1.0 - r;
        s * s * s * (1.0 + 3.0 * r)
    } else {
        0.0
    }
}

/// Simulation nodes of one object in its reference (undeformed) system, with the static
/// part of the MLS gradient.
#[derive(Clone, Debug)]
pub struct SimNodes {
    pub rest: Vec<Vec3>,
    pub mass: Vec<f32>,
    /// Gradient neighbourhood of node j: `nb[nb_off[j]..nb_off[j+1]]` with weights `nb_w`.
    nb_off: Vec<u32>,
    nb: Vec<u32>,
    nb_w: Vec<f32>,
    /// Pseudo-inverse of the weighted moment matrix `M_j = Σ w d dᵀ`.
    minv: Vec<Mat3>,
}

impl SimNodes {
    /// `k_grad` nearest nodes (support 1.25× the farthest) define each node's gradient.
    pub fn new(rest: Vec<Vec3>, mass: Vec<f32>, k_grad: usize) -> Result<Self, DeformError> {
        if rest.is_empty() || rest.len() != mass.len() {
            return Err(DeformError::Invalid(format!("{} simulation nodes with {} masses", rest.len(), mass.len())));
        }
        if rest.iter().any(|p| !p.is_finite()) || mass.iter().any(|m| !(m.is_finite() && *m > 0.0)) {
            return Err(DeformError::Invalid("non-finite simulation node or non-positive mass".into()));
        }
        let kd = KdTree::new(&rest);
        let mut nb_off = vec![0u32];
        let (mut nb, mut nb_w, mut minv) = (Vec::new(), Vec::new(), Vec::new());
        let mut out = Vec::new();
        for (j, &x) in rest.iter().enumerate() {
            kd.knn(x, k_grad.max(1), Some(j as u32), &mut out);
            let h = out.last().map(|o| o.1.sqrt() * 1.25).unwrap_or(1.0).max(1e-20);
            let mut m = nalgebra::Matrix3::<f64>::zeros();
            for &(k, d2) in &out {
                let w = spline_weight(d2.sqrt() / h);
                let d = (rest[k as usize] - x).as_dvec3();
                let dv = nalgebra::Vector3::new(d.x, d.y, d.z);
                m += dv * dv.transpose() * w as f64;
                nb.push(k);
                nb_w.push(w);
            }
            nb_off.push(nb.len() as u32);
            let mx = m.abs().max();
            let pinv = m.pseudo_inverse(1e-3 * mx.max(1e-300)).unwrap_or_else(|_| nalgebra::Matrix3::zeros());
            minv.push(Mat3::from_cols_array(&std::array::from_fn(|i| pinv[(i % 3, i / 3)] as f32)));
        }
        Ok(SimNodes { rest, mass, nb_off, nb, nb_w, minv })
    }
    pub fn len(&self) -> usize {
        self.rest.len()
    }
    pub fn is_empty(&self) -> bool {
        self.rest.is_empty()
    }
}

/// The deformation of one object in one frame (see module docs).
#[derive(Clone, Debug)]
pub struct DeformField {
    /// Optimal rotation R (Eq. 10).
    pub rot: Mat3,
    /// t' = x̄' − R x̄: `x̂ = rot·x + trans`.
    pub trans: Vec3,
    /// û_j, displacement relative to the transformed reference.
    pub u: Vec<Vec3>,
    /// K_j = ∇û_j R (applied to reference offsets).
    pub k: Vec<Mat3>,
    /// ‖K_j‖_F.
    pub kf: Vec<f32>,
    /// K_j and a_j = û_j − K_j x_j packed per node for Eq. 1 ([`deform_point`]).
    pub lin: Vec<NodeLin>,
}

/// One simulation node's linear field packed in one 64-byte line: `k` = K_j and `a_kf` =
/// (a_j, ‖K_j‖_F) with a_j = û_j − K_j x_j, so that Eq. 1's sum
/// Σ_j ω_j (û_j + K_j (x − x_j)) = Σ_j ω_j a_j + (Σ_j ω_j K_j) x: four 4-wide multiply-adds
/// per node instead of a matrix–vector product and two matrix sums.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(64))]
pub struct NodeLin {
    pub k: Mat3A,
    pub a_kf: Vec4,
}

const _: () = assert!(std::mem::size_of::<NodeLin>() == 64 && std::mem::align_of::<NodeLin>() >= std::mem::align_of::<f32x8>());

impl NodeLin {
    /// The line as two f32x8: [K_x | K_y], [K_z | a, ‖K‖_F] (each `Mat3A` column's fourth
    /// lane is padding, never read from the sums).
    #[inline(always)]
    fn as_x8(&self) -> &[f32x8; 2] {
        // SAFETY: NodeLin is repr(C), 64 bytes of f32 lanes (three Vec3A, each 16 bytes with
        // a padding lane, then a Vec4) and at least as aligned as f32x8 (asserted above), so
        // it is two valid, aligned f32x8. Every bit pattern is a valid f32.
        unsafe { &*(self as *const NodeLin as *const [f32x8; 2]) }
    }
}

fn pack_lin(rest: &[Vec3], u: &[Vec3], k: &[Mat3], kf: &[f32]) -> Vec<NodeLin> {
    (0..rest.len()).map(|j| NodeLin { k: Mat3A::from(k[j]), a_kf: (u[j] - k[j] * rest[j]).extend(kf[j]) }).collect()
}

impl DeformField {
    /// The undeformed state.
    pub fn identity(nodes: &SimNodes) -> Self {
        let n = nodes.len();
        DeformField {
            rot: Mat3::IDENTITY,
            trans: Vec3::ZERO,
            u: vec![Vec3::ZERO; n],
            k: vec![Mat3::ZERO; n],
            kf: vec![0.0; n],
            lin: vec![NodeLin::default(); n],
        }
    }

    pub fn compute(nodes: &SimNodes, deformed: &[Vec3], factor_rigid: bool) -> Result<Self, DeformError> {
        if deformed.len() != nodes.len() {
            return Err(DeformError::FrameMismatch(format!("{} node positions for {} simulation nodes", deformed.len(), nodes.len())));
        }
        if let Some(j) = deformed.iter().position(|p| !p.is_finite()) {
            return Err(DeformError::FrameMismatch(format!("node {j} position is not finite")));
        }
        let (rot, trans) = if factor_rigid { optimal_rigid(&nodes.rest, deformed, &nodes.mass) } else { (Mat3::IDENTITY, Vec3::ZERO) };
        let u: Vec<Vec3> = nodes.rest.iter().zip(deformed).map(|(x, xd)| *xd - (rot * *x + trans)).collect();
        let mut k = Vec::with_capacity(nodes.len());
        let mut kf = Vec::with_capacity(nodes.len());
        for j in 0..nodes.len() {
            let mut a = Mat3::ZERO;
            for e in nodes.nb_off[j] as usize..nodes.nb_off[j + 1] as usize {
                let kk = nodes.nb[e] as usize;
                let w = nodes.nb_w[e];
                let du = (u[kk] - u[j]) * w;
                let d = nodes.rest[kk] - nodes.rest[j];
                // Outer product du dᵀ (columns = du * d_c).
                a += Mat3::from_cols(du * d.x, du * d.y, du * d.z);
            }
            let kj = a * nodes.minv[j];
            let f = (kj.x_axis.length_squared() + kj.y_axis.length_squared() + kj.z_axis.length_squared()).sqrt();
            k.push(kj);
            kf.push(f);
        }
        let lin = pack_lin(&nodes.rest, &u, &k, &kf);
        Ok(DeformField { rot, trans, u, k, kf, lin })
    }
}

/// Eq. 10: the rigid transform (R, t') that best maps `rest` onto `deformed` with mass
/// weights: `x̂ = R x + t'`.
pub fn optimal_rigid(rest: &[Vec3], deformed: &[Vec3], mass: &[f32]) -> (Mat3, Vec3) {
    let msum: f64 = mass.iter().map(|m| *m as f64).sum();
    let mut xm = glam::DVec3::ZERO;
    let mut xmd = glam::DVec3::ZERO;
    for ((x, xd), m) in rest.iter().zip(deformed).zip(mass) {
        xm += x.as_dvec3() * (*m as f64 / msum);
        xmd += xd.as_dvec3() * (*m as f64 / msum);
    }
    let mut f = nalgebra::Matrix3::<f64>::zeros();
    for ((x, xd), m) in rest.iter().zip(deformed).zip(mass) {
        let a = x.as_dvec3() - xm;
        let b = xd.as_dvec3() - xmd;
        let m2 = (*m as f64) * (*m as f64);
        f += nalgebra::Vector3::new(a.x, a.y, a.z) * nalgebra::Vector3::new(b.x, b.y, b.z).transpose() * m2;
    }
    let r = rotation_from_svd(f);
    let rot = Mat3::from_cols_array(&std::array::from_fn(|i| r[(i % 3, i / 3)] as f32));
    let trans = (xmd - glam::DMat3::from_cols_array(&std::array::from_fn(|i| r[(i % 3, i / 3)])) * xm).as_vec3();
    (rot, trans)
}

/// R = V Uᵀ for F = U W Vᵀ, reflections removed.
pub fn rotation_from_svd(f: nalgebra::Matrix3<f64>) -> nalgebra::Matrix3<f64> {
    let svd = f.svd(true, true);
    let (u, vt) = match (svd.u, svd.v_t) {
        (Some(u), Some(vt)) => (u, vt),
        _ => return nalgebra::Matrix3::identity(),
    };
    let mut v = vt.transpose();
    let mut r = v * u.transpose();
    if r.determinant() < 0.0 {
        // Flip the axis of the smallest singular value.
        let (mut kmin, mut smin) = (0, f64::INFINITY);
        for i in 0..3 {
            if svd.singular_values[i] < smin {
                smin = svd.singular_values[i];
                kmin = i;
            }
        }
        for row in 0..3 {
            v[(row, kmin)] = -v[(row, kmin)];
        }
        r = v * u.transpose();
    }
    if r.iter().any(|x| !x.is_finite()) {
        return nalgebra::Matrix3::identity();
    }
    r
}

/// Per-surfel node weights of Eq. 1: `k` nodes per surfel (`idx[i*k..]`, normalised `w`).
#[derive(Clone, Debug)]
pub struct NodeWeights {
    pub k: usize,
    pub idx: Vec<u32>,
    pub w: Vec<f32>,
}

impl NodeWeights {
    /// The `k` nearest nodes of every point, support radius `h_i` = 1.25× the distance to
    /// the k-th, weights of Eq. 2 normalised to sum 1.
    pub fn new(points: &[Vec3], nodes: &SimNodes, k: usize) -> Self {
        use rayon::prelude::*;
        let k = k.clamp(1, nodes.len());
        let kd = KdTree::new(&nodes.rest);
        let per: Vec<(Vec<u32>, Vec<f32>)> = points
            .par_iter()
            .map_init(Vec::new, |out, p| {
                kd.knn(*p, k, None, out);
                let h = (out.last().unwrap().1.sqrt() * 1.25).max(1e-20);
                let mut w: Vec<f32> = out.iter().map(|o| spline_weight(o.1.sqrt() / h)).collect();
                let s: f32 = w.iter().sum();
                if s > 0.0 {
                    w.iter_mut().for_each(|x| *x /= s);
                } else {
                    w.iter_mut().for_each(|x| *x = 1.0 / k as f32);
                }
                (out.iter().map(|o| o.0).collect(), w)
            })
            .collect();
        let mut idx = Vec::with_capacity(points.len() * k);
        let mut w = Vec::with_capacity(points.len() * k);
        for (a, b) in per {
            idx.extend(a);
            w.extend(b);
        }
        NodeWeights { k, idx, w }
    }
}

/// A deformed surfel: centre, tangent axes, and the gradient stretch bound
/// `1 + Σ_j ω̄_ij ‖K_j‖_F` (≥ the largest singular value of the tangent map / ‖R‖).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeformedSurfel {
    pub p: Vec3,
    pub u: Vec3,
    pub v: Vec3,
    pub stretch: f32,
}

impl DeformedSurfel {
    /// Unit normal `u × v` (zero if the axes collapsed).
    #[inline]
    pub fn normal(&self) -> Vec3 {
        self.u.cross(self.v).normalize_or_zero()
    }
    /// Radius of the smallest ball around `p` holding the deformed ellipse: the largest
    /// singular value of `[u v]`.
    #[inline]
    pub fn extent(&self) -> f32 {
        let (a, b, c) = (self.u.length_squared(), self.u.dot(self.v), self.v.length_squared());
        let l = 0.5 * (a + c + ((a - c) * (a - c) + 4.0 * b * b).sqrt());
        l.max(0.0).sqrt()
    }
}

/// Eq. 1's weighted sums over a point's nodes: [Σω K_x | Σω K_y] and [Σω K_z | Σω a, Σω ‖K‖_F]
/// (fourth lanes of the K columns padding).
#[inline(always)]
fn eq1_sums(f: &DeformField, idx: &[u32], w: &[f32]) -> ([f32; 8], [f32; 8]) {
    // A node's 64-byte line is two f32x8 loads, [K_x | K_y] and [K_z | a, ‖K‖_F], and its
    // term two 8-wide multiply-adds; even and odd nodes go to separate sums, halving the
    // chain of dependent multiply-adds. Criterion `deform_point` (16 nodes per surfel), stop
    // 70: 21.3 ns per surfel with four 4-wide multiply-adds on four loads per node, 20.7 ns
    // with one 8-wide chain, 17.7 ns like this (four sums: 17.4 ns).
    let zero = f32x8::ZERO;
    let (mut s0, mut s1, mut t0, mut t1) = (zero, zero, zero, zero);
    let pairs = idx.len() / 2;
    for h in 0..pairs {
        let (a, b) = (f.lin[idx[2 * h] as usize].as_x8(), f.lin[idx[2 * h + 1] as usize].as_x8());
        let (wa, wb) = (f32x8::splat(w[2 * h]), f32x8::splat(w[2 * h + 1]));
        s0 = a[0].mul_add(wa, s0);
        s1 = a[1].mul_add(wa, s1);
        t0 = b[0].mul_add(wb, t0);
        t1 = b[1].mul_add(wb, t1);
    }
    if idx.len() % 2 == 1 {
        let (a, wa) = (f.lin[idx[2 * pairs] as usize].as_x8(), f32x8::splat(w[2 * pairs]));
        s0 = a[0].mul_add(wa, s0);
        s1 = a[1].mul_add(wa, s1);
    }
    ((s0 + t0).to_array(), (s1 + t1).to_array())
}

/// Eq. 1 for one point with reference position `x`, tangent axes (u, v) and node weights,
/// from the packed per-node fields ([`NodeLin`]).
#[inline]
pub fn deform_point(f: &DeformField, x: Vec3, axes: (Vec3, Vec3), idx: &[u32], w: &[f32]) -> DeformedSurfel {
    let (k01, k2a) = eq1_sums(f, idx, w);
    // `deform_point_ref`'s matrix products in 4-wide columns (glam's `Mat3A`): each lane
    // takes the same operations in the same order as its `Mat3` (scalar lanes), so the
    // results are bit for bit the same, in about a quarter of the instructions.
    let col = |a: &[f32; 8], i: usize| Vec3A::new(a[i], a[i + 1], a[i + 2]);
    let kw = Mat3A::from_cols(col(&k01, 0), col(&k01, 4), col(&k2a, 0));
    let rot = Mat3A::from(f.rot);
    let xa = Vec3A::from(x);
    let p = rot * xa + Vec3A::from(f.trans) + col(&k2a, 4) + kw * xa;
    let g = rot + kw;
    DeformedSurfel { p: p.into(), u: (g * Vec3A::from(axes.0)).into(), v: (g * Vec3A::from(axes.1)).into(), stretch: 1.0 + k2a[7] }
}

/// [`deform_point`] as written first, on glam's scalar-lane `Mat3` (the reference its tests
/// compare it with, bit for bit).
#[cfg(test)]
fn deform_point_ref(f: &DeformField, x: Vec3, axes: (Vec3, Vec3), idx: &[u32], w: &[f32]) -> DeformedSurfel {
    let (k01, k2a) = eq1_sums(f, idx, w);
    let kw = Mat3::from_cols(Vec3::new(k01[0], k01[1], k01[2]), Vec3::new(k01[4], k01[5], k01[6]), Vec3::new(k2a[0], k2a[1], k2a[2]));
    let akf = Vec4::new(k2a[4], k2a[5], k2a[6], k2a[7]);
    let p = f.rot * x + f.trans + akf.truncate() + kw * x;
    let g = f.rot + kw;
    DeformedSurfel { p, u: g * axes.0, v: g * axes.1, stretch: 1.0 + akf.w }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spline_weight_shape() {
        assert_eq!(spline_weight(0.0), 1.0);
        assert!(spline_weight(1.0).abs() < 1e-6 && spline_weight(1.5) == 0.0);
        let mut prev = 1.0;
        for i in 1..100 {
            let w = spline_weight(i as f32 / 100.0);
            assert!(w <= prev && w >= 0.0);
            prev = w;
        }
        // Near the support's edge, where the expanded polynomial cancels in f32 (it gave
        // 11,149 negative values of 200,000 in [0.98, 1)): never negative, and within f32 of
        // the exact value (1 − r)³(1 + 3r) taken in f64; NaN weighs nothing.
        for i in 0..200_000 {
            let r = 0.98 + 0.02 * i as f32 / 200_000.0;
            let w = spline_weight(r);
            let (rd, exact) = (r as f64, (1.0 - r as f64).powi(3) * (1.0 + 3.0 * r as f64));
            assert!(w >= 0.0 && (w as f64 - exact).abs() <= 1e-6 * exact + 1e-12, "r = {rd}: {w}, exact {exact}");
        }
        assert_eq!(spline_weight(f32::NAN), 0.0);
    }

    #[test]
    fn rigid_motion_is_factored_out_exactly() {
        let rest: Vec<Vec3> = (0..40).map(|i| Vec3::new((i % 4) as f32, ((i / 4) % 5) as f32 * 0.7, (i / 20) as f32 * 1.3)).collect();
        let nodes = SimNodes::new(rest.clone(), vec![1.0; 40], 8).unwrap();
        let q = glam::Quat::from_axis_angle(Vec3::new(1.0, 2.0, 0.5).normalize(), 2.5);
        let t = Vec3::new(3.0, -1.0, 7.0);
        let def: Vec<Vec3> = rest.iter().map(|x| q * *x + t).collect();
        let f = DeformField::compute(&nodes, &def, true).unwrap();
        assert!(f.u.iter().all(|u| u.length() < 1e-4), "{:?}", f.u[0]);
        assert!(f.kf.iter().all(|k| *k < 1e-4));
        // An affine stretch gives the exact gradient (nodes span 3D here).
        let a = Mat3::from_diagonal(Vec3::new(1.2, 0.9, 1.0));
        let def: Vec<Vec3> = rest.iter().map(|x| a * *x).collect();
        let f = DeformField::compute(&nodes, &def, false).unwrap();
        let ka = a - Mat3::IDENTITY;
        for j in 0..40 {
            assert!((f.k[j] - ka).abs_diff_eq(Mat3::ZERO, 1e-3), "{j}: {:?}", f.k[j]);
        }
        let w = NodeWeights::new(&[Vec3::new(1.1, 1.3, 0.4)], &nodes, 8);
        let x = Vec3::new(1.1, 1.3, 0.4);
        let s = deform_point(&f, x, (Vec3::X, Vec3::Y), &w.idx, &w.w);
        assert!((s.p - a * x).length() < 1e-3, "{} vs {}", s.p, a * x);
        assert!((s.u - a * Vec3::X).length() < 1e-3);
    }

    /// [`deform_point`]'s 4-wide matrix products give bit for bit its scalar-lane reference's
    /// results, on random motions, points and axes (degenerate axes included).
    #[test]
    fn deform_point_matches_its_reference_bit_for_bit() {
        use crate::core::rng::Sampler;
        let mut s = Sampler::new(9, 4, 1);
        let rest: Vec<Vec3> = (0..40).map(|_| Vec3::new(s.next(), s.next(), s.next()) * 3.0 - 1.0).collect();
        let nodes = SimNodes::new(rest.clone(), vec![1.0; 40], 8).unwrap();
        for trial in 0..6 {
            let q = glam::Quat::from_axis_angle(Vec3::new(s.next(), 1.0, s.next()).normalize(), 3.0 * s.next());
            let amp = 0.3 * trial as f32;
            let def: Vec<Vec3> = rest.iter().map(|x| q * *x + amp * Vec3::new((2.0 * x.y).sin(), x.x * x.z, x.y * x.y)).collect();
            let f = DeformField::compute(&nodes, &def, trial % 2 == 0).unwrap();
            let pts: Vec<Vec3> = (0..200).map(|_| Vec3::new(s.next(), s.next(), s.next()) * 3.0 - 1.0).collect();
            for k in [1, 5, 16] {
                let w = NodeWeights::new(&pts, &nodes, k);
                for (i, &x) in pts.iter().enumerate() {
                    let (idx, ws) = (&w.idx[i * k..i * k + k], &w.w[i * k..i * k + k]);
                    let u = Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5) * 0.02;
                    let v = if i % 7 == 0 { u } else { Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5) * 0.02 };
                    let (a, b) = (deform_point(&f, x, (u, v), idx, ws), deform_point_ref(&f, x, (u, v), idx, ws));
                    let bits = |d: &DeformedSurfel| [d.p, d.u, d.v].map(|v| v.to_array().map(f32::to_bits)).concat();
                    assert_eq!((bits(&a), a.stretch.to_bits()), (bits(&b), b.stretch.to_bits()), "trial {trial}, k {k}, point {i}");
                }
            }
        }
    }

    /// The packed form of Eq. 1 ([`NodeLin`]) equals the direct sum
    /// x̂ + Σ_j ω_j (û_j + K_j (x − x_j)), ∇ = R + Σ_j ω_j K_j, on a random non-rigid motion.
    #[test]
    fn packed_eq1_matches_direct_sum() {
        use crate::core::rng::Sampler;
        let mut s = Sampler::new(8, 1, 2);
        let rest: Vec<Vec3> = (0..60).map(|_| Vec3::new(s.next(), s.next(), s.next()) * 2.0).collect();
        let nodes = SimNodes::new(rest.clone(), vec![1.0; 60], 8).unwrap();
        let q = glam::Quat::from_axis_angle(Vec3::new(0.3, 1.0, 0.2).normalize(), 0.7);
        let def: Vec<Vec3> = rest.iter().map(|x| q * *x + Vec3::new(0.1 * (3.0 * x.y).sin(), 0.2 * x.x * x.z, 0.05 * x.y * x.y)).collect();
        let f = DeformField::compute(&nodes, &def, true).unwrap();
        let pts: Vec<Vec3> = (0..50).map(|_| Vec3::new(s.next(), s.next(), s.next()) * 2.0).collect();
        let w = NodeWeights::new(&pts, &nodes, 16);
        for (i, &x) in pts.iter().enumerate() {
            let (idx, ws) = (&w.idx[i * 16..i * 16 + 16], &w.w[i * 16..i * 16 + 16]);
            let (u, v) = (Vec3::new(0.01, 0.0, 0.002), Vec3::new(0.0, 0.012, -0.001));
            let got = deform_point(&f, x, (u, v), idx, ws);
            let (mut p, mut g, mut st) = (f.rot * x + f.trans, f.rot, 1.0f32);
            for (&j, &wj) in idx.iter().zip(ws) {
                let j = j as usize;
                p += (f.u[j] + f.k[j] * (x - rest[j])) * wj;
                g += f.k[j] * wj;
                st += wj * f.kf[j];
            }
            assert!((got.p - p).length() < 1e-5, "{i}: {} vs {p}", got.p);
            assert!((got.u - g * u).length() < 1e-6 && (got.v - g * v).length() < 1e-6);
            assert!((got.stretch - st).abs() < 1e-5);
        }
    }
}
