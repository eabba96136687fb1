//! Typed configuration: TOML file, then SEGSPLAT_* environment, then flags.
