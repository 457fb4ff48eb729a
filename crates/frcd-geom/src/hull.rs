//! Robust 3D convex hull.
