//! eval: see DESIGN.md.
