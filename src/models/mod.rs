//! models: see DESIGN.md.
