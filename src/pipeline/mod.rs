//! pipeline: see DESIGN.md.
