//! A kernel's bind-group layout, read from its WGSL instead of left to wgpu's automatic layout,
//! so that uniform bindings can take dynamic offsets: a kernel's parameters then live in the
//! context's [`UniformRing`](crate::uniform_ring::UniformRing) and its bind group is the same
//! every step (see [`BindGroupCache`](crate::bind_cache::BindGroupCache)).
//!
//! Only the bindings the entry point uses are in the layout, as in wgpu's automatic layout:
//! several entry points share one source and callers pass only the buffers theirs reads.

use naga::valid::{Capabilities, GlobalUse, ValidationFlags, Validator};

/// What one `@group(0) @binding(i)` of the entry point is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BindingKind {
    /// `var<uniform>`: bound with a dynamic offset.
    Uniform,
    /// `var<storage, read>`.
    StorageRead,
    /// `var<storage, read_write>`.
    StorageReadWrite,
}

/// The entry point's bindings in binding order, or `None` when the source uses something this
/// reading does not cover (another group, textures, a parse failure): the kernel then keeps
/// wgpu's automatic layout and binds its uniforms without dynamic offsets.
pub fn reflect_bindings(source: &str, entry_point: &str) -> Option<Vec<(u32, BindingKind)>> {
    let module = naga::front::wgsl::parse_str(source).ok()?;
    let info = Validator::new(ValidationFlags::all(), Capabilities::all())
        .validate(&module)
        .ok()?;
    let entry_index = module
        .entry_points
        .iter()
        .position(|entry| entry.name == entry_point)?;
    let uses = info.get_entry_point(entry_index);
    let mut bindings = Vec::new();
    for (handle, global) in module.global_variables.iter() {
        let Some(binding) = &global.binding else {
            continue;
        };
        if uses[handle] == GlobalUse::empty() {
            continue;
        }
        if binding.group != 0 {
            return None;
        }
        let kind = match global.space {
            naga::AddressSpace::Uniform => BindingKind::Uniform,
            naga::AddressSpace::Storage { access } => {
                if access.contains(naga::StorageAccess::STORE) {
                    BindingKind::StorageReadWrite
                } else {
                    BindingKind::StorageRead
                }
            }
            _ => return None,
        };
        bindings.push((binding.binding, kind));
    }
    bindings.sort_by_key(|(binding, _)| *binding);
    Some(bindings)
}

/// The layout entries for `bindings`, uniforms with dynamic offsets.
pub fn layout_entries(bindings: &[(u32, BindingKind)]) -> Vec<wgpu::BindGroupLayoutEntry> {
    bindings
        .iter()
        .map(|&(binding, kind)| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: match kind {
                    BindingKind::Uniform => wgpu::BufferBindingType::Uniform,
                    BindingKind::StorageRead => {
                        wgpu::BufferBindingType::Storage { read_only: true }
                    }
                    BindingKind::StorageReadWrite => {
                        wgpu::BufferBindingType::Storage { read_only: false }
                    }
                },
                has_dynamic_offset: kind == BindingKind::Uniform,
                min_binding_size: None,
            },
            count: None,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const SOURCE: &str = "
struct Params { count: u32, scale: f32 }
@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> input: array<f32>;
@group(0) @binding(2) var<storage, read_write> output: array<f32>;
@group(0) @binding(3) var<storage, read_write> unused_here: array<u32>;

@compute @workgroup_size(64)
fn scale(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x < params.count { output[id.x] = input[id.x] * params.scale; }
}

@compute @workgroup_size(64)
fn clear(@builtin(global_invocation_id) id: vec3<u32>) {
    unused_here[id.x] = 0u;
}
";

    #[test]
    fn only_the_entry_points_own_bindings_are_in_its_layout() {
        assert_eq!(
            reflect_bindings(SOURCE, "scale"),
            Some(vec![
                (0, BindingKind::Uniform),
                (1, BindingKind::StorageRead),
                (2, BindingKind::StorageReadWrite),
            ])
        );
        assert_eq!(
            reflect_bindings(SOURCE, "clear"),
            Some(vec![(3, BindingKind::StorageReadWrite)])
        );
    }

    #[test]
    fn what_the_reading_does_not_cover_keeps_the_automatic_layout() {
        assert_eq!(reflect_bindings(SOURCE, "missing"), None);
        assert_eq!(reflect_bindings("fn broken(", "scale"), None);
        let other_group = SOURCE.replace("@group(0) @binding(1)", "@group(1) @binding(1)");
        assert_eq!(reflect_bindings(&other_group, "scale"), None);
    }
}
