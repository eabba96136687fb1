//! Kernel variants forced by the user, for comparing them on one machine. Without a choice each
//! engine module picks the variant that suits the adapter's capabilities. The library never
//! reads these from the process environment: the CLI maps `SEGSPLAT_RASTER_KERNEL` /
//! `SEGSPLAT_GEMM_KERNEL` onto them, and the service reads them from
//! `workers.adapters.kernels`.

use std::str::FromStr;

use serde::{Deserialize, Serialize};

/// How the rasterize kernels lay pixels over invocations.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RasterLayout {
    /// One pixel per invocation.
    Pixels,
    /// A column of pixels per invocation, each subgroup walking its tile on its own (needs
    /// subgroups).
    Columns,
}

/// Which GEMM kernel the deformation field runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GemmLayout {
    /// Output tiles staged through workgroup memory.
    Tiled,
    /// An output block per invocation, no workgroup memory.
    Rows,
    /// Rows per invocation, the other operand shared by subgroup broadcasts (subgroups of 8).
    Broadcast,
}

/// Variants to force; `None` leaves each to the adapter.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct KernelChoices {
    pub raster: Option<RasterLayout>,
    pub gemm: Option<GemmLayout>,
}

/// A variant name that names no variant.
#[derive(Debug, Clone, thiserror::Error)]
#[error("{value:?} names no {what} kernel (expected one of {expected})")]
pub struct UnknownKernel {
    what: &'static str,
    value: String,
    expected: &'static str,
}

impl FromStr for RasterLayout {
    type Err = UnknownKernel;

    fn from_str(value: &str) -> Result<Self, Self::Err> {
        match value {
            "pixels" => Ok(Self::Pixels),
            "columns" => Ok(Self::Columns),
            _ => Err(UnknownKernel {
                what: "rasterize",
                value: value.to_string(),
                expected: "pixels, columns",
            }),
        }
    }
}

impl GemmLayout {
    /// The name `SEGSPLAT_GEMM_KERNEL`, `workers.adapters.kernels.gemm` and a job's metrics use:
    /// the one table both parsing and printing read.
    pub fn name(self) -> &'static str {
        match self {
            Self::Tiled => "tiled",
            Self::Rows => "rows",
            Self::Broadcast => "broadcast",
        }
    }
}

impl FromStr for GemmLayout {
    type Err = UnknownKernel;

    fn from_str(value: &str) -> Result<Self, Self::Err> {
        [Self::Tiled, Self::Rows, Self::Broadcast]
            .into_iter()
            .find(|layout| layout.name() == value)
            .ok_or_else(|| UnknownKernel {
                what: "GEMM",
                value: value.to_string(),
                expected: "tiled, rows, broadcast",
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_and_unknown_names_are_refused() {
        assert_eq!(
            "columns".parse::<RasterLayout>().ok(),
            Some(RasterLayout::Columns)
        );
        assert_eq!("rows".parse::<GemmLayout>().ok(), Some(GemmLayout::Rows));
        let error = "column"
            .parse::<RasterLayout>()
            .err()
            .map(|e| e.to_string());
        assert_eq!(
            error.as_deref(),
            Some("\"column\" names no rasterize kernel (expected one of pixels, columns)")
        );
        let choices: KernelChoices =
            toml::from_str("raster = \"pixels\"\ngemm = \"tiled\"").unwrap_or_default();
        assert_eq!(choices.raster, Some(RasterLayout::Pixels));
        assert_eq!(choices.gemm, Some(GemmLayout::Tiled));
    }
}
