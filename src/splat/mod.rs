//! splat: see DESIGN.md.
