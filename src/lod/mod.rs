//! Papaioannou et al., *Exploiting Multiresolution Models to Accelerate Ray Tracing*: LOD chains,
//! the distortion buffer, per-ray LOD selection and the two-pass tracer.
