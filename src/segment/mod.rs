//! segment: see DESIGN.md.
