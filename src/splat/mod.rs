//! splat: see DESIGN.md.

pub mod adam;
pub mod loss;
