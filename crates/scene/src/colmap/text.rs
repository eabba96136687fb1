//! COLMAP's text model files (`cameras.txt`, `images.txt`, `points3D.txt`).

use std::fmt::Write as _;
use std::fs;
use std::io;
use std::path::Path;
use std::str::FromStr;

use super::camera_models::CameraModel;
use super::model::{
    ColmapCamera, ColmapImage, ColmapKeypoint, ColmapModel, ColmapPoint, ColmapTrackElement,
};
use crate::SceneError;

/// Reads the three files from `dir`; errors name the file (as `display_dir/<file>`) and line.
pub fn read_model(dir: &Path, display_dir: &str) -> Result<ColmapModel, SceneError> {
    let mut model = ColmapModel::default();
    let cameras = ModelText::read(dir, display_dir, "cameras.txt")?;
    for (line_number, line) in cameras.content_lines() {
        let camera = cameras.camera(line_number, line)?;
        model.cameras.insert(camera.id, camera);
    }
    let images = ModelText::read(dir, display_dir, "images.txt")?;
    model.images = images.images()?;
    let points = ModelText::read(dir, display_dir, "points3D.txt")?;
    for (line_number, line) in points.content_lines() {
        model.points.push(points.point(line_number, line)?);
    }
    Ok(model)
}

struct ModelText {
    file: String,
    text: String,
}

impl ModelText {
    fn read(dir: &Path, display_dir: &str, name: &str) -> Result<Self, SceneError> {
        let file = format!("{display_dir}/{name}");
        let bytes = fs::read(dir.join(name)).map_err(|source| match source.kind() {
            io::ErrorKind::NotFound => SceneError::Parse {
                file: file.clone(),
                message: "missing (a COLMAP model needs cameras, images and points3D)".to_string(),
            },
            _ => SceneError::Io {
                file: file.clone(),
                source,
            },
        })?;
        let text = String::from_utf8(bytes).map_err(|_| SceneError::Parse {
            file: file.clone(),
            message: "not UTF-8 text".to_string(),
        })?;
        Ok(Self { file, text })
    }

    fn error(&self, line_number: usize, message: impl std::fmt::Display) -> SceneError {
        SceneError::Parse {
            file: self.file.clone(),
            message: format!("line {line_number}: {message}"),
        }
    }

    /// Non-empty, non-comment lines with their 1-based numbers.
    fn content_lines(&self) -> impl Iterator<Item = (usize, &str)> {
        self.text
            .lines()
            .enumerate()
            .map(|(index, line)| (index + 1, line.trim()))
            .filter(|(_, line)| !line.is_empty() && !line.starts_with('#'))
    }

    fn parse<T: FromStr>(
        &self,
        line_number: usize,
        what: &str,
        token: Option<&str>,
    ) -> Result<T, SceneError> {
        let token = token.ok_or_else(|| self.error(line_number, format!("missing {what}")))?;
        token
            .parse()
            .map_err(|_| self.error(line_number, format!("{what} {token:?} is not a number")))
    }

    fn camera(&self, line_number: usize, line: &str) -> Result<ColmapCamera, SceneError> {
        let mut tokens = line.split_whitespace();
        let id = self.parse(line_number, "camera id", tokens.next())?;
        let model_name = tokens
            .next()
            .ok_or_else(|| self.error(line_number, "missing camera model"))?;
        let model = CameraModel::from_name(model_name).ok_or_else(|| {
            self.error(line_number, format!("unknown camera model {model_name:?}"))
        })?;
        let width = self.parse(line_number, "width", tokens.next())?;
        let height = self.parse(line_number, "height", tokens.next())?;
        let params = tokens
            .map(|token| self.parse(line_number, "camera parameter", Some(token)))
            .collect::<Result<Vec<f64>, _>>()?;
        if params.len() != model.param_count() {
            return Err(self.error(
                line_number,
                format!(
                    "{model_name} takes {} parameters, found {}",
                    model.param_count(),
                    params.len()
                ),
            ));
        }
        Ok(ColmapCamera {
            id,
            model,
            width,
            height,
            params,
        })
    }

    /// Images take two lines each; the keypoint line may be empty, so blank lines only count as
    /// separators before a header line.
    fn images(&self) -> Result<Vec<ColmapImage>, SceneError> {
        let mut images = Vec::new();
        let mut lines = self
            .text
            .lines()
            .enumerate()
            .map(|(index, line)| (index + 1, line.trim()))
            .filter(|(_, line)| !line.starts_with('#'));
        while let Some((line_number, header)) = lines.next() {
            if header.is_empty() {
                continue;
            }
            let mut image = self.image_header(line_number, header)?;
            if let Some((keypoint_line_number, keypoints)) = lines.next() {
                image.points2d = self.keypoints(keypoint_line_number, keypoints)?;
            }
            images.push(image);
        }
        Ok(images)
    }

    fn image_header(&self, line_number: usize, line: &str) -> Result<ColmapImage, SceneError> {
        let mut tokens = line
            .splitn(10, char::is_whitespace)
            .filter(|token| !token.is_empty());
        let id = self.parse(line_number, "image id", tokens.next())?;
        let mut qvec = [0.0; 4];
        for value in &mut qvec {
            *value = self.parse(line_number, "rotation", tokens.next())?;
        }
        let mut tvec = [0.0; 3];
        for value in &mut tvec {
            *value = self.parse(line_number, "translation", tokens.next())?;
        }
        let camera_id = self.parse(line_number, "camera id", tokens.next())?;
        let name = tokens
            .next()
            .map(str::trim)
            .filter(|name| !name.is_empty())
            .ok_or_else(|| self.error(line_number, "missing image name"))?;
        Ok(ColmapImage {
            id,
            qvec,
            tvec,
            camera_id,
            name: name.to_string(),
            points2d: Vec::new(),
        })
    }

    fn keypoints(&self, line_number: usize, line: &str) -> Result<Vec<ColmapKeypoint>, SceneError> {
        let tokens: Vec<&str> = line.split_whitespace().collect();
        if !tokens.len().is_multiple_of(3) {
            return Err(self.error(line_number, "keypoints must be X Y POINT3D_ID triples"));
        }
        tokens
            .chunks_exact(3)
            .map(|triple| {
                Ok(ColmapKeypoint {
                    xy: [
                        self.parse(line_number, "keypoint x", Some(triple[0]))?,
                        self.parse(line_number, "keypoint y", Some(triple[1]))?,
                    ],
                    point3d_id: self.parse(line_number, "point3D id", Some(triple[2]))?,
                })
            })
            .collect()
    }

    fn point(&self, line_number: usize, line: &str) -> Result<ColmapPoint, SceneError> {
        let tokens: Vec<&str> = line.split_whitespace().collect();
        if tokens.len() < 8 || !(tokens.len() - 8).is_multiple_of(2) {
            return Err(self.error(
                line_number,
                "expected POINT3D_ID X Y Z R G B ERROR then IMAGE_ID POINT2D_IDX pairs",
            ));
        }
        let id = self.parse(line_number, "point id", Some(tokens[0]))?;
        let xyz = [
            self.parse(line_number, "x", Some(tokens[1]))?,
            self.parse(line_number, "y", Some(tokens[2]))?,
            self.parse(line_number, "z", Some(tokens[3]))?,
        ];
        let rgb = [
            self.parse(line_number, "red", Some(tokens[4]))?,
            self.parse(line_number, "green", Some(tokens[5]))?,
            self.parse(line_number, "blue", Some(tokens[6]))?,
        ];
        let error = self.parse(line_number, "error", Some(tokens[7]))?;
        let track = tokens[8..]
            .chunks_exact(2)
            .map(|pair| {
                Ok(ColmapTrackElement {
                    image_id: self.parse(line_number, "track image id", Some(pair[0]))?,
                    point2d_index: self.parse(line_number, "track point2D index", Some(pair[1]))?,
                })
            })
            .collect::<Result<Vec<_>, SceneError>>()?;
        Ok(ColmapPoint {
            id,
            xyz,
            rgb,
            error,
            track,
        })
    }
}

/// Writes the three files into `dir` in COLMAP's text layout; floats are written in Rust's
/// shortest round-trip form, so reading them back gives the same values bit for bit.
pub fn write_model(dir: &Path, model: &ColmapModel) -> io::Result<()> {
    let mut cameras = String::from("# CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n");
    for camera in model.cameras.values() {
        let _ = write!(
            cameras,
            "{} {} {} {}",
            camera.id,
            camera.model.name(),
            camera.width,
            camera.height
        );
        for param in &camera.params {
            let _ = write!(cameras, " {param}");
        }
        cameras.push('\n');
    }
    fs::write(dir.join("cameras.txt"), cameras)?;

    let mut images = String::from(
        "# IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n# POINTS2D[] as (X, Y, POINT3D_ID)\n",
    );
    for image in &model.images {
        let [qw, qx, qy, qz] = image.qvec;
        let [tx, ty, tz] = image.tvec;
        let _ = writeln!(
            images,
            "{} {qw} {qx} {qy} {qz} {tx} {ty} {tz} {} {}",
            image.id, image.camera_id, image.name
        );
        let keypoints: Vec<String> = image
            .points2d
            .iter()
            .map(|keypoint| {
                format!(
                    "{} {} {}",
                    keypoint.xy[0], keypoint.xy[1], keypoint.point3d_id
                )
            })
            .collect();
        images.push_str(&keypoints.join(" "));
        images.push('\n');
    }
    fs::write(dir.join("images.txt"), images)?;

    let mut points =
        String::from("# POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n");
    for point in &model.points {
        let [x, y, z] = point.xyz;
        let [r, g, b] = point.rgb;
        let _ = write!(
            points,
            "{} {x} {y} {z} {r} {g} {b} {}",
            point.id, point.error
        );
        for element in &point.track {
            let _ = write!(points, " {} {}", element.image_id, element.point2d_index);
        }
        points.push('\n');
    }
    fs::write(dir.join("points3D.txt"), points)
}
