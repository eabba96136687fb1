//! language: see DESIGN.md.
