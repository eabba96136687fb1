//! scene: see DESIGN.md.
