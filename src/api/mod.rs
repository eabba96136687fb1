//! api: see DESIGN.md.
