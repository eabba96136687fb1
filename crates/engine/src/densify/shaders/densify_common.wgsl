// Shared by the densification kernels: one densification's rules (`DensifyRules` in gpu.rs)
// and the per-Gaussian flag layout.

struct Rules {
    count: u32,
    children: u32,
    max_new: u32,
    seed: u32,
    gradient: f32,
    log_dense_limit: f32,
    min_opacity_logit: f32,
    screen_radius: f32,
    log_world_scale: f32,
    log_shrink: f32,
    new_count: u32,
    opacity_ceiling: f32,
}

// flags[i]: bits 0-1 the growth (none, clone, split), bit 2 set for a pruning candidate.
const GROWTH_NONE: u32 = 0u;
const GROWTH_CLONE: u32 = 1u;
const GROWTH_SPLIT: u32 = 2u;
const GROWTH_MASK: u32 = 3u;
const PRUNE_BIT: u32 = 4u;

fn flat_index(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.x + gid.y * groups.x * 256u;
}

// Gaussians one becomes if kept: itself, itself and a clone, or `children` split children.
fn growth_outputs(growth: u32, children: u32) -> u32 {
    if growth == GROWTH_CLONE {
        return 2u;
    }
    if growth == GROWTH_SPLIT {
        return children;
    }
    return 1u;
}
