//! COLMAP camera models: ids, names, parameter layouts, and the mapping of their parameters to
//! focal lengths, principal point and distortion.

use crate::Intrinsics;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum CameraModel {
    SimplePinhole,
    Pinhole,
    SimpleRadial,
    Radial,
    OpenCv,
    OpenCvFisheye,
    FullOpenCv,
    Fov,
    SimpleRadialFisheye,
    RadialFisheye,
    ThinPrismFisheye,
    RadTanThinPrismFisheye,
}

/// How a model's parameter list starts: one shared focal length or separate fx, fy.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FocalLayout {
    /// `f, cx, cy, extra...`
    Single,
    /// `fx, fy, cx, cy, extra...`
    Separate,
}

impl CameraModel {
    pub const ALL: [CameraModel; 12] = [
        CameraModel::SimplePinhole,
        CameraModel::Pinhole,
        CameraModel::SimpleRadial,
        CameraModel::Radial,
        CameraModel::OpenCv,
        CameraModel::OpenCvFisheye,
        CameraModel::FullOpenCv,
        CameraModel::Fov,
        CameraModel::SimpleRadialFisheye,
        CameraModel::RadialFisheye,
        CameraModel::ThinPrismFisheye,
        CameraModel::RadTanThinPrismFisheye,
    ];

    /// The numeric id COLMAP writes in `cameras.bin`.
    pub fn id(self) -> i32 {
        match self {
            CameraModel::SimplePinhole => 0,
            CameraModel::Pinhole => 1,
            CameraModel::SimpleRadial => 2,
            CameraModel::Radial => 3,
            CameraModel::OpenCv => 4,
            CameraModel::OpenCvFisheye => 5,
            CameraModel::FullOpenCv => 6,
            CameraModel::Fov => 7,
            CameraModel::SimpleRadialFisheye => 8,
            CameraModel::RadialFisheye => 9,
            CameraModel::ThinPrismFisheye => 10,
            CameraModel::RadTanThinPrismFisheye => 11,
        }
    }

    /// The name COLMAP writes in `cameras.txt`.
    pub fn name(self) -> &'static str {
        match self {
            CameraModel::SimplePinhole => "SIMPLE_PINHOLE",
            CameraModel::Pinhole => "PINHOLE",
            CameraModel::SimpleRadial => "SIMPLE_RADIAL",
            CameraModel::Radial => "RADIAL",
            CameraModel::OpenCv => "OPENCV",
            CameraModel::OpenCvFisheye => "OPENCV_FISHEYE",
            CameraModel::FullOpenCv => "FULL_OPENCV",
            CameraModel::Fov => "FOV",
            CameraModel::SimpleRadialFisheye => "SIMPLE_RADIAL_FISHEYE",
            CameraModel::RadialFisheye => "RADIAL_FISHEYE",
            CameraModel::ThinPrismFisheye => "THIN_PRISM_FISHEYE",
            CameraModel::RadTanThinPrismFisheye => "RAD_TAN_THIN_PRISM_FISHEYE",
        }
    }

    pub fn from_id(id: i32) -> Option<CameraModel> {
        CameraModel::ALL.into_iter().find(|model| model.id() == id)
    }

    pub fn from_name(name: &str) -> Option<CameraModel> {
        CameraModel::ALL
            .into_iter()
            .find(|model| model.name() == name)
    }

    /// Total parameter count, focal lengths and principal point included.
    pub fn param_count(self) -> usize {
        let distortion = match self {
            CameraModel::SimplePinhole | CameraModel::Pinhole => 0,
            CameraModel::SimpleRadial | CameraModel::SimpleRadialFisheye | CameraModel::Fov => 1,
            CameraModel::Radial | CameraModel::RadialFisheye => 2,
            CameraModel::OpenCv | CameraModel::OpenCvFisheye => 4,
            CameraModel::FullOpenCv | CameraModel::ThinPrismFisheye => 8,
            CameraModel::RadTanThinPrismFisheye => 12,
        };
        self.focal_and_center_count() + distortion
    }

    fn focal_layout(self) -> FocalLayout {
        match self {
            CameraModel::SimplePinhole
            | CameraModel::SimpleRadial
            | CameraModel::Radial
            | CameraModel::SimpleRadialFisheye
            | CameraModel::RadialFisheye => FocalLayout::Single,
            _ => FocalLayout::Separate,
        }
    }

    fn focal_and_center_count(self) -> usize {
        match self.focal_layout() {
            FocalLayout::Single => 3,
            FocalLayout::Separate => 4,
        }
    }

    /// Maps COLMAP's parameter list to [`Intrinsics`]; `params` must hold
    /// [`CameraModel::param_count`] values. Distortion keeps COLMAP's order for the model, e.g.
    /// OPENCV `k1, k2, p1, p2`, FOV `omega`.
    pub fn intrinsics(self, width: u32, height: u32, params: &[f64]) -> Option<Intrinsics> {
        if params.len() != self.param_count() {
            return None;
        }
        let (fx, fy, cx, cy) = match self.focal_layout() {
            FocalLayout::Single => (params[0], params[0], params[1], params[2]),
            FocalLayout::Separate => (params[0], params[1], params[2], params[3]),
        };
        Some(Intrinsics {
            width,
            height,
            fx,
            fy,
            cx,
            cy,
            model: self.name().to_string(),
            distortion: params[self.focal_and_center_count()..].to_vec(),
        })
    }

    /// The inverse of [`CameraModel::intrinsics`] (used by the writers): `fx` is used for
    /// single-focal models.
    pub fn params_from_intrinsics(self, intrinsics: &Intrinsics) -> Vec<f64> {
        let mut params = match self.focal_layout() {
            FocalLayout::Single => vec![intrinsics.fx, intrinsics.cx, intrinsics.cy],
            FocalLayout::Separate => {
                vec![intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy]
            }
        };
        params.extend_from_slice(&intrinsics.distortion);
        params.resize(self.param_count(), 0.0);
        params
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_and_names_round_trip() {
        for model in CameraModel::ALL {
            assert_eq!(CameraModel::from_id(model.id()), Some(model));
            assert_eq!(CameraModel::from_name(model.name()), Some(model));
        }
        assert_eq!(CameraModel::from_id(12), None);
        assert_eq!(CameraModel::from_name("PINHOLE_X"), None);
    }

    #[test]
    fn each_model_maps_its_parameters() {
        let expected: [(CameraModel, usize, [f64; 4], usize); 12] = [
            (CameraModel::SimplePinhole, 3, [1.0, 1.0, 2.0, 3.0], 0),
            (CameraModel::Pinhole, 4, [1.0, 2.0, 3.0, 4.0], 0),
            (CameraModel::SimpleRadial, 4, [1.0, 1.0, 2.0, 3.0], 1),
            (CameraModel::Radial, 5, [1.0, 1.0, 2.0, 3.0], 2),
            (CameraModel::OpenCv, 8, [1.0, 2.0, 3.0, 4.0], 4),
            (CameraModel::OpenCvFisheye, 8, [1.0, 2.0, 3.0, 4.0], 4),
            (CameraModel::FullOpenCv, 12, [1.0, 2.0, 3.0, 4.0], 8),
            (CameraModel::Fov, 5, [1.0, 2.0, 3.0, 4.0], 1),
            (CameraModel::SimpleRadialFisheye, 4, [1.0, 1.0, 2.0, 3.0], 1),
            (CameraModel::RadialFisheye, 5, [1.0, 1.0, 2.0, 3.0], 2),
            (CameraModel::ThinPrismFisheye, 12, [1.0, 2.0, 3.0, 4.0], 8),
            (
                CameraModel::RadTanThinPrismFisheye,
                16,
                [1.0, 2.0, 3.0, 4.0],
                12,
            ),
        ];
        for (model, count, [fx, fy, cx, cy], distortion_len) in expected {
            assert_eq!(model.param_count(), count, "{}", model.name());
            let params: Vec<f64> = (1..=count).map(|value| value as f64).collect();
            let intrinsics = model.intrinsics(640, 480, &params).unwrap();
            assert_eq!(
                (intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy),
                (fx, fy, cx, cy),
                "{}",
                model.name()
            );
            assert_eq!(intrinsics.distortion.len(), distortion_len);
            assert_eq!(
                intrinsics.distortion.last().copied(),
                if distortion_len > 0 {
                    Some(count as f64)
                } else {
                    None
                }
            );
            assert_eq!(intrinsics.model, model.name());
            assert!(model.intrinsics(640, 480, &params[1..]).is_none());
            assert_eq!(model.params_from_intrinsics(&intrinsics), params);
        }
    }
}
