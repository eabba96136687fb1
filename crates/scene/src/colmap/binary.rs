//! COLMAP's binary model files (`cameras.bin`, `images.bin`, `points3D.bin`), little endian.

use std::fs::File;
use std::io::{self, BufReader, BufWriter, Read, Write};
use std::path::Path;

use super::camera_models::CameraModel;
use super::model::{
    ColmapCamera, ColmapImage, ColmapKeypoint, ColmapModel, ColmapPoint, ColmapTrackElement,
};
use crate::SceneError;

/// Counts in headers are untrusted: reserve at most this many elements up front.
const MAX_RESERVE: usize = 1 << 16;

/// Reads the three files from `dir`; errors name the file (as `display_dir/<file>`).
pub fn read_model(dir: &Path, display_dir: &str) -> Result<ColmapModel, SceneError> {
    let mut model = ColmapModel::default();
    let mut reader = ModelReader::open(dir, display_dir, "cameras.bin")?;
    for _ in 0..reader.count()? {
        let camera = reader.camera()?;
        model.cameras.insert(camera.id, camera);
    }
    let mut reader = ModelReader::open(dir, display_dir, "images.bin")?;
    let image_count = reader.count()?;
    model.images.reserve(image_count.min(MAX_RESERVE));
    for _ in 0..image_count {
        model.images.push(reader.image()?);
    }
    let mut reader = ModelReader::open(dir, display_dir, "points3D.bin")?;
    let point_count = reader.count()?;
    model.points.reserve(point_count.min(MAX_RESERVE));
    for _ in 0..point_count {
        model.points.push(reader.point()?);
    }
    Ok(model)
}

struct ModelReader {
    file: String,
    reader: BufReader<File>,
}

impl ModelReader {
    fn open(dir: &Path, display_dir: &str, name: &str) -> Result<Self, SceneError> {
        let file = format!("{display_dir}/{name}");
        let handle = File::open(dir.join(name)).map_err(|source| match source.kind() {
            io::ErrorKind::NotFound => SceneError::Parse {
                file: file.clone(),
                message: "missing (a COLMAP model needs cameras, images and points3D)".to_string(),
            },
            _ => SceneError::Io {
                file: file.clone(),
                source,
            },
        })?;
        Ok(Self {
            file,
            reader: BufReader::new(handle),
        })
    }

    fn parse_error(&self, message: impl Into<String>) -> SceneError {
        SceneError::Parse {
            file: self.file.clone(),
            message: message.into(),
        }
    }

    fn bytes<const N: usize>(&mut self) -> Result<[u8; N], SceneError> {
        let mut buffer = [0u8; N];
        self.reader
            .read_exact(&mut buffer)
            .map_err(|source| match source.kind() {
                io::ErrorKind::UnexpectedEof => self.parse_error("file ends early (truncated)"),
                _ => SceneError::Io {
                    file: self.file.clone(),
                    source,
                },
            })?;
        Ok(buffer)
    }

    fn u64(&mut self) -> Result<u64, SceneError> {
        Ok(u64::from_le_bytes(self.bytes()?))
    }

    fn i64(&mut self) -> Result<i64, SceneError> {
        Ok(i64::from_le_bytes(self.bytes()?))
    }

    fn u32(&mut self) -> Result<u32, SceneError> {
        Ok(u32::from_le_bytes(self.bytes()?))
    }

    fn i32(&mut self) -> Result<i32, SceneError> {
        Ok(i32::from_le_bytes(self.bytes()?))
    }

    fn f64(&mut self) -> Result<f64, SceneError> {
        Ok(f64::from_le_bytes(self.bytes()?))
    }

    fn count(&mut self) -> Result<usize, SceneError> {
        let count = self.u64()?;
        usize::try_from(count).map_err(|_| self.parse_error(format!("count {count} is too large")))
    }

    fn camera(&mut self) -> Result<ColmapCamera, SceneError> {
        let id = self.u32()?;
        let model_id = self.i32()?;
        let model = CameraModel::from_id(model_id).ok_or_else(|| {
            self.parse_error(format!("camera {id}: unknown camera model id {model_id}"))
        })?;
        let width = self.u64()?;
        let height = self.u64()?;
        let params = (0..model.param_count())
            .map(|_| self.f64())
            .collect::<Result<Vec<_>, _>>()?;
        Ok(ColmapCamera {
            id,
            model,
            width,
            height,
            params,
        })
    }

    fn image(&mut self) -> Result<ColmapImage, SceneError> {
        let id = self.u32()?;
        let qvec = [self.f64()?, self.f64()?, self.f64()?, self.f64()?];
        let tvec = [self.f64()?, self.f64()?, self.f64()?];
        let camera_id = self.u32()?;
        let name = self.null_terminated_name(id)?;
        let keypoint_count = self.count()?;
        let mut points2d = Vec::with_capacity(keypoint_count.min(MAX_RESERVE));
        for _ in 0..keypoint_count {
            let xy = [self.f64()?, self.f64()?];
            let point3d_id = self.i64()?;
            points2d.push(ColmapKeypoint { xy, point3d_id });
        }
        Ok(ColmapImage {
            id,
            qvec,
            tvec,
            camera_id,
            name,
            points2d,
        })
    }

    fn null_terminated_name(&mut self, image_id: u32) -> Result<String, SceneError> {
        const MAX_NAME_LEN: usize = 4096;
        let mut name = Vec::new();
        loop {
            let [byte] = self.bytes::<1>()?;
            if byte == 0 {
                break;
            }
            if name.len() == MAX_NAME_LEN {
                return Err(self.parse_error(format!("image {image_id}: name is not terminated")));
            }
            name.push(byte);
        }
        String::from_utf8(name)
            .map_err(|_| self.parse_error(format!("image {image_id}: name is not UTF-8")))
    }

    fn point(&mut self) -> Result<ColmapPoint, SceneError> {
        let id = self.u64()?;
        let xyz = [self.f64()?, self.f64()?, self.f64()?];
        let rgb = self.bytes::<3>()?;
        let error = self.f64()?;
        let track_len = self.count()?;
        let mut track = Vec::with_capacity(track_len.min(MAX_RESERVE));
        for _ in 0..track_len {
            let image_id = self.u32()?;
            let point2d_index = self.u32()?;
            track.push(ColmapTrackElement {
                image_id,
                point2d_index,
            });
        }
        Ok(ColmapPoint {
            id,
            xyz,
            rgb,
            error,
            track,
        })
    }
}

/// Writes the three files into `dir` in COLMAP's binary layout.
pub fn write_model(dir: &Path, model: &ColmapModel) -> io::Result<()> {
    let mut out = BufWriter::new(File::create(dir.join("cameras.bin"))?);
    out.write_all(&(model.cameras.len() as u64).to_le_bytes())?;
    for camera in model.cameras.values() {
        out.write_all(&camera.id.to_le_bytes())?;
        out.write_all(&camera.model.id().to_le_bytes())?;
        out.write_all(&camera.width.to_le_bytes())?;
        out.write_all(&camera.height.to_le_bytes())?;
        write_f64s(&mut out, &camera.params)?;
    }
    out.into_inner()?.sync_all()?;

    let mut out = BufWriter::new(File::create(dir.join("images.bin"))?);
    out.write_all(&(model.images.len() as u64).to_le_bytes())?;
    for image in &model.images {
        out.write_all(&image.id.to_le_bytes())?;
        write_f64s(&mut out, &image.qvec)?;
        write_f64s(&mut out, &image.tvec)?;
        out.write_all(&image.camera_id.to_le_bytes())?;
        out.write_all(image.name.as_bytes())?;
        out.write_all(&[0])?;
        out.write_all(&(image.points2d.len() as u64).to_le_bytes())?;
        for keypoint in &image.points2d {
            write_f64s(&mut out, &keypoint.xy)?;
            out.write_all(&keypoint.point3d_id.to_le_bytes())?;
        }
    }
    out.into_inner()?.sync_all()?;

    let mut out = BufWriter::new(File::create(dir.join("points3D.bin"))?);
    out.write_all(&(model.points.len() as u64).to_le_bytes())?;
    for point in &model.points {
        out.write_all(&point.id.to_le_bytes())?;
        write_f64s(&mut out, &point.xyz)?;
        out.write_all(&point.rgb)?;
        out.write_all(&point.error.to_le_bytes())?;
        out.write_all(&(point.track.len() as u64).to_le_bytes())?;
        for element in &point.track {
            out.write_all(&element.image_id.to_le_bytes())?;
            out.write_all(&element.point2d_index.to_le_bytes())?;
        }
    }
    out.into_inner()?.sync_all()?;
    Ok(())
}

fn write_f64s(out: &mut impl Write, values: &[f64]) -> io::Result<()> {
    values
        .iter()
        .try_for_each(|value| out.write_all(&value.to_le_bytes()))
}
