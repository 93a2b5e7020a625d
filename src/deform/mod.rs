//! Adams et al. 2005, *Ray Tracing Dynamic Scenes with Point-Sampled Surfaces*: surfels,
//! deformation, lazily updated bounding-sphere hierarchy, MLS intersection, caching, clipping.
