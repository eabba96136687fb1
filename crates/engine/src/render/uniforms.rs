//! The per-render uniform block (`RenderUniforms` in `crates/engine/src/render/shaders/project_common.wgsl`).

use bytemuck::{Pod, Zeroable};

use crate::{ObjectFilter, RenderCamera, RenderSettings};

/// `RenderUniforms` of `crates/engine/src/render/shaders/project_common.wgsl` (176 bytes, std140-compatible); a test
/// parses the shader and checks every field's offset and the size.
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
pub struct RenderUniforms {
    pub camera_from_world: [[f32; 4]; 4],
    pub camera_position: [f32; 4],
    pub background: [f32; 4],
    pub focal: [f32; 2],
    pub principal: [f32; 2],
    pub image_size: [u32; 2],
    pub tile_grid: [u32; 2],
    pub near: f32,
    pub far: f32,
    pub sh_degree: u32,
    pub gaussian_count: u32,
    pub filter_level: u32,
    pub filter_id: u32,
    pub filter_enabled: u32,
    pub intersection_capacity: u32,
    /// [`RenderCamera::jacobian_limit`].
    pub jacobian_limit: [f32; 2],
    /// 1: the rasterize backward sums `|d loss / d mean2d|` (the densification statistic, fed by
    /// the full render's loss alone); 0 for object renders, which leave it to the full render.
    pub mean2d_abs: u32,
    /// 1: the rasterize forward marks which [`crate::OCCUPANCY_CELL`] squares hold a non-zero
    /// colour (object renders); 0 for the full render.
    pub mark_occupancy: u32,
}

impl RenderUniforms {
    pub fn new(
        camera: &RenderCamera,
        settings: &RenderSettings,
        gaussian_count: u32,
        intersection_capacity: u32,
    ) -> Self {
        let position = camera.position();
        let background = settings.background;
        let (filter_level, filter_id, filter_enabled) = match settings.filter {
            ObjectFilter::All => (0, 0, 0),
            ObjectFilter::Object { level, id } => (level.index() as u32, id, 1),
        };
        Self {
            camera_from_world: camera.camera_from_world.to_cols_array_2d(),
            camera_position: [position.x, position.y, position.z, 1.0],
            background: [background[0], background[1], background[2], 0.0],
            focal: [camera.fx, camera.fy],
            principal: [camera.cx, camera.cy],
            image_size: [camera.width, camera.height],
            tile_grid: camera.tile_grid(),
            near: camera.near,
            far: camera.far,
            sh_degree: settings.sh_degree.min(crate::model::MAX_SH_DEGREE),
            gaussian_count,
            filter_level,
            filter_id,
            filter_enabled,
            intersection_capacity,
            jacobian_limit: camera.jacobian_limit(),
            mean2d_abs: u32::from(matches!(settings.filter, ObjectFilter::All)),
            mark_occupancy: 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_block_is_176_bytes() {
        assert_eq!(std::mem::size_of::<RenderUniforms>(), 176);
    }

    /// Offsets and size of the struct `name` as WGSL lays it out in `source`.
    fn wgsl_layout(source: &str, name: &str) -> (Vec<(String, u32)>, u32) {
        let module = naga::front::wgsl::parse_str(source).unwrap_or_else(|e| panic!("{e}"));
        module
            .types
            .iter()
            .find_map(|(_, ty)| match &ty.inner {
                naga::TypeInner::Struct { members, span } if ty.name.as_deref() == Some(name) => {
                    let offsets = members
                        .iter()
                        .map(|m| (m.name.clone().unwrap_or_default(), m.offset))
                        .collect();
                    Some((offsets, *span))
                }
                _ => None,
            })
            .unwrap_or_else(|| panic!("no struct {name}"))
    }

    #[test]
    fn layout_matches_the_shader() {
        let source = include_str!("shaders/project_common.wgsl");
        let (offsets, size) = wgsl_layout(source, "RenderUniforms");
        let host = [
            (
                "camera_from_world",
                std::mem::offset_of!(RenderUniforms, camera_from_world),
            ),
            (
                "camera_position",
                std::mem::offset_of!(RenderUniforms, camera_position),
            ),
            (
                "background",
                std::mem::offset_of!(RenderUniforms, background),
            ),
            ("focal", std::mem::offset_of!(RenderUniforms, focal)),
            ("principal", std::mem::offset_of!(RenderUniforms, principal)),
            (
                "image_size",
                std::mem::offset_of!(RenderUniforms, image_size),
            ),
            ("tile_grid", std::mem::offset_of!(RenderUniforms, tile_grid)),
            ("near", std::mem::offset_of!(RenderUniforms, near)),
            ("far", std::mem::offset_of!(RenderUniforms, far)),
            ("sh_degree", std::mem::offset_of!(RenderUniforms, sh_degree)),
            (
                "gaussian_count",
                std::mem::offset_of!(RenderUniforms, gaussian_count),
            ),
            (
                "filter_level",
                std::mem::offset_of!(RenderUniforms, filter_level),
            ),
            ("filter_id", std::mem::offset_of!(RenderUniforms, filter_id)),
            (
                "filter_enabled",
                std::mem::offset_of!(RenderUniforms, filter_enabled),
            ),
            (
                "intersection_capacity",
                std::mem::offset_of!(RenderUniforms, intersection_capacity),
            ),
            (
                "jacobian_limit",
                std::mem::offset_of!(RenderUniforms, jacobian_limit),
            ),
            (
                "mean2d_abs",
                std::mem::offset_of!(RenderUniforms, mean2d_abs),
            ),
            (
                "mark_occupancy",
                std::mem::offset_of!(RenderUniforms, mark_occupancy),
            ),
        ];
        let host: Vec<(String, u32)> = host
            .iter()
            .map(|(name, offset)| (name.to_string(), *offset as u32))
            .collect();
        assert_eq!(offsets, host);
        assert_eq!(size as usize, std::mem::size_of::<RenderUniforms>());
    }
}
