//! The per-render uniform block (`RenderUniforms` in `shaders/project_common.wgsl`).

use bytemuck::{Pod, Zeroable};

use crate::splat::{ObjectFilter, RenderCamera, RenderSettings};

/// Must match `RenderUniforms` in `shaders/project_common.wgsl` (160 bytes, std140-compatible).
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
            sh_degree: settings.sh_degree.min(crate::splat::model::MAX_SH_DEGREE),
            gaussian_count,
            filter_level,
            filter_id,
            filter_enabled,
            intersection_capacity,
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn uniform_block_is_160_bytes() {
        assert_eq!(std::mem::size_of::<super::RenderUniforms>(), 160);
    }
}
