//! splat: see DESIGN.md.

pub mod loss;
