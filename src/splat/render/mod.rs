//! GPU renderer (forward and backward).
