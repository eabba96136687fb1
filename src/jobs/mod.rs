//! jobs: see DESIGN.md.
