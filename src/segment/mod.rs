//! segment: mask generators (SAM-family automatic masks, classical fallback, user-provided),
//! tracking, de-duplication and merging. See DESIGN.md.

pub mod prompt;
