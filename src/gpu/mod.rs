//! gpu: see DESIGN.md.
