//! Point clouds shipped with a dataset as PLY (nerfstudio's `ply_file_path`, e.g.
//! `sparse_pc.ply`): vertex positions and optional colours, ASCII or binary.
//!
//! Only the first element may be `vertex` and its properties must be scalars; that is what
//! COLMAP, nerfstudio and Open3D write for point clouds. Gaussian-splat PLY files are a different
//! concern (`splat`).

use std::fs;
use std::io;
use std::path::Path;

use glam::Vec3;

use super::{SceneError, SparsePoints};

/// Counts in headers are untrusted: reserve at most this many elements up front.
const MAX_RESERVE: usize = 1 << 16;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Encoding {
    Ascii,
    BinaryLittleEndian,
    BinaryBigEndian,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ScalarType {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl ScalarType {
    fn parse(name: &str) -> Option<ScalarType> {
        Some(match name {
            "char" | "int8" => ScalarType::I8,
            "uchar" | "uint8" => ScalarType::U8,
            "short" | "int16" => ScalarType::I16,
            "ushort" | "uint16" => ScalarType::U16,
            "int" | "int32" => ScalarType::I32,
            "uint" | "uint32" => ScalarType::U32,
            "float" | "float32" => ScalarType::F32,
            "double" | "float64" => ScalarType::F64,
            _ => return None,
        })
    }

    fn byte_len(self) -> usize {
        match self {
            ScalarType::I8 | ScalarType::U8 => 1,
            ScalarType::I16 | ScalarType::U16 => 2,
            ScalarType::I32 | ScalarType::U32 | ScalarType::F32 => 4,
            ScalarType::F64 => 8,
        }
    }

    fn decode(self, bytes: &[u8], encoding: Encoding) -> f64 {
        macro_rules! number {
            ($type:ty) => {{
                let mut raw = [0u8; std::mem::size_of::<$type>()];
                raw.copy_from_slice(bytes);
                f64::from(match encoding {
                    Encoding::BinaryBigEndian => <$type>::from_be_bytes(raw),
                    _ => <$type>::from_le_bytes(raw),
                })
            }};
        }
        match self {
            ScalarType::I8 => number!(i8),
            ScalarType::U8 => number!(u8),
            ScalarType::I16 => number!(i16),
            ScalarType::U16 => number!(u16),
            ScalarType::I32 => number!(i32),
            ScalarType::U32 => number!(u32),
            ScalarType::F32 => number!(f32),
            ScalarType::F64 => number!(f64),
        }
    }
}

struct Header {
    encoding: Encoding,
    vertex_count: usize,
    properties: Vec<(String, ScalarType)>,
    /// Byte offset where the body starts.
    body_offset: usize,
}

/// Reads the vertex positions and colours (0..1; 8-bit colours are divided by 255) of the PLY
/// at `relative_path` under `root`. Points from a PLY have no tracks.
pub fn read_point_ply(root: &Path, relative_path: &Path) -> Result<SparsePoints, SceneError> {
    let file = relative_path.display().to_string();
    let bytes = fs::read(root.join(relative_path)).map_err(|source| match source.kind() {
        io::ErrorKind::NotFound => SceneError::Parse {
            file: file.clone(),
            message: "point cloud file is missing".to_string(),
        },
        _ => SceneError::Io {
            file: file.clone(),
            source,
        },
    })?;
    let parse_error = |message: String| SceneError::Parse {
        file: file.clone(),
        message,
    };
    let header = parse_header(&bytes).map_err(parse_error)?;
    let column = |name: &str| header.properties.iter().position(|(n, _)| n == name);
    let (Some(x), Some(y), Some(z)) = (column("x"), column("y"), column("z")) else {
        return Err(parse_error(
            "vertex needs x, y and z properties".to_string(),
        ));
    };
    let color_columns = match (column("red"), column("green"), column("blue")) {
        (Some(r), Some(g), Some(b)) => Some([r, g, b]),
        _ => None,
    };
    let rows = read_rows(&bytes[header.body_offset..], &header).map_err(parse_error)?;
    let mut points = SparsePoints {
        positions: Vec::with_capacity(rows.len()),
        colors: Vec::with_capacity(rows.len()),
        tracks: vec![Vec::new(); rows.len()],
    };
    for row in rows {
        points
            .positions
            .push(Vec3::new(row[x] as f32, row[y] as f32, row[z] as f32));
        let color = match color_columns {
            Some(columns) => columns.map(|column| {
                let value = row[column];
                match header.properties[column].1 {
                    ScalarType::U8 => value / 255.0,
                    ScalarType::U16 => value / 65535.0,
                    _ => value,
                }
            }),
            None => [0.5; 3],
        };
        points
            .colors
            .push(Vec3::from_array(color.map(|channel| channel as f32)));
    }
    Ok(points)
}

fn parse_header(bytes: &[u8]) -> Result<Header, String> {
    const END: &[u8] = b"end_header";
    const MAX_HEADER_LEN: usize = 64 * 1024;
    let searched = &bytes[..bytes.len().min(MAX_HEADER_LEN)];
    let end = searched
        .windows(END.len())
        .position(|window| window == END)
        .ok_or("no end_header line (not a PLY file?)")?;
    let mut body_offset = end + END.len();
    while body_offset < bytes.len() && bytes[body_offset] != b'\n' {
        body_offset += 1;
    }
    // Past the newline; a file ending right after `end_header` has an empty body (found by
    // fuzzing: the offset ran one past the end).
    body_offset = (body_offset + 1).min(bytes.len());
    let text = std::str::from_utf8(&bytes[..end]).map_err(|_| "header is not text")?;
    let mut lines = text.lines().map(str::trim);
    if lines.next() != Some("ply") {
        return Err("does not start with \"ply\"".to_string());
    }
    let mut encoding = None;
    let mut vertex_count = None;
    let mut properties = Vec::new();
    let mut in_vertex = false;
    for line in lines {
        let tokens: Vec<&str> = line.split_whitespace().collect();
        match tokens.as_slice() {
            ["format", kind, _version] => {
                encoding = Some(match *kind {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::BinaryLittleEndian,
                    "binary_big_endian" => Encoding::BinaryBigEndian,
                    other => return Err(format!("unknown format {other:?}")),
                });
            }
            ["element", name, count] => {
                if vertex_count.is_some() {
                    // Elements after the vertices (faces, edges) are not read.
                    in_vertex = false;
                    continue;
                }
                if *name != "vertex" {
                    return Err(format!("the first element must be vertex, found {name:?}"));
                }
                vertex_count = Some(
                    count
                        .parse::<usize>()
                        .map_err(|_| format!("vertex count {count:?} is not a number"))?,
                );
                in_vertex = true;
            }
            ["property", "list", ..] if in_vertex => {
                return Err("list properties on vertices are not supported".to_string());
            }
            ["property", kind, name] if in_vertex => {
                let scalar =
                    ScalarType::parse(kind).ok_or(format!("unknown property type {kind:?}"))?;
                properties.push((name.to_string(), scalar));
            }
            _ => {}
        }
    }
    Ok(Header {
        encoding: encoding.ok_or("no format line")?,
        vertex_count: vertex_count.ok_or("no vertex element")?,
        properties,
        body_offset,
    })
}

fn read_rows(body: &[u8], header: &Header) -> Result<Vec<Vec<f64>>, String> {
    let columns = header.properties.len();
    let count = header.vertex_count;
    let mut rows = Vec::with_capacity(count.min(MAX_RESERVE));
    if header.encoding == Encoding::Ascii {
        let text = std::str::from_utf8(body).map_err(|_| "ASCII body is not text")?;
        let mut lines = text.lines().filter(|line| !line.trim().is_empty());
        for index in 0..count {
            let line = lines
                .next()
                .ok_or(format!("file ends after {index} of {count} vertices"))?;
            let row = line
                .split_whitespace()
                .take(columns)
                .map(|token| token.parse::<f64>())
                .collect::<Result<Vec<f64>, _>>()
                .map_err(|_| format!("vertex {index}: not a number"))?;
            if row.len() != columns {
                return Err(format!("vertex {index}: expected {columns} values"));
            }
            rows.push(row);
        }
        return Ok(rows);
    }
    let row_len: usize = header
        .properties
        .iter()
        .map(|(_, scalar)| scalar.byte_len())
        .sum();
    let needed = row_len
        .checked_mul(count)
        .ok_or("vertex count is too large")?;
    if body.len() < needed {
        return Err(format!(
            "file ends early: {count} vertices need {needed} bytes, found {}",
            body.len()
        ));
    }
    for row_bytes in body[..needed].chunks_exact(row_len.max(1)).take(count) {
        let mut offset = 0;
        let row = header
            .properties
            .iter()
            .map(|(_, scalar)| {
                let value = scalar.decode(
                    &row_bytes[offset..offset + scalar.byte_len()],
                    header.encoding,
                );
                offset += scalar.byte_len();
                value
            })
            .collect();
        rows.push(row);
    }
    Ok(rows)
}

/// Writes `points` as a binary little-endian PLY with float positions and 8-bit colours, the
/// layout nerfstudio writes for `sparse_pc.ply`.
pub fn write_point_ply(path: &Path, points: &SparsePoints) -> io::Result<()> {
    let mut bytes = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
        points.positions.len()
    )
    .into_bytes();
    for (position, color) in points.positions.iter().zip(&points.colors) {
        for value in position.to_array() {
            bytes.extend_from_slice(&value.to_le_bytes());
        }
        for channel in color.to_array() {
            bytes.push((channel.clamp(0.0, 1.0) * 255.0).round() as u8);
        }
    }
    fs::write(path, bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ascii_and_binary_read_the_same_points() {
        let dir = tempfile::tempdir().unwrap();
        let ascii = "ply\nformat ascii 1.0\ncomment made by hand\nelement vertex 2\nproperty double x\nproperty double y\nproperty double z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n1 2 3 255 0 51\n-1 0.5 4 0 255 0\n";
        fs::write(dir.path().join("a.ply"), ascii).unwrap();
        let from_ascii = read_point_ply(dir.path(), Path::new("a.ply")).unwrap();
        write_point_ply(&dir.path().join("b.ply"), &from_ascii).unwrap();
        let from_binary = read_point_ply(dir.path(), Path::new("b.ply")).unwrap();
        assert_eq!(from_ascii, from_binary);
        assert_eq!(from_ascii.positions[1], Vec3::new(-1.0, 0.5, 4.0));
        assert_eq!(from_ascii.colors[0], Vec3::new(1.0, 0.0, 0.2));
        assert_eq!(from_ascii.tracks, vec![Vec::new(), Vec::new()]);
    }

    #[test]
    fn truncated_binary_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let points = SparsePoints {
            positions: vec![Vec3::ONE; 10],
            colors: vec![Vec3::ZERO; 10],
            tracks: vec![Vec::new(); 10],
        };
        let path = dir.path().join("p.ply");
        write_point_ply(&path, &points).unwrap();
        let bytes = fs::read(&path).unwrap();
        fs::write(&path, &bytes[..bytes.len() - 5]).unwrap();
        let error = read_point_ply(dir.path(), Path::new("p.ply")).unwrap_err();
        assert!(error.to_string().contains("p.ply"), "{error}");
        assert!(error.to_string().contains("ends early"), "{error}");
    }

    /// Fuzzing found a file ending right after `end_header` (no newline) panicked slicing the
    /// body one byte past the end.
    #[test]
    fn header_at_the_very_end_is_an_error_not_a_panic() {
        let dir = tempfile::tempdir().unwrap();
        let ply = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header";
        fs::write(dir.path().join("p.ply"), ply).unwrap();
        let error = read_point_ply(dir.path(), Path::new("p.ply")).unwrap_err();
        assert!(error.to_string().contains("ends after 0 of 1"), "{error}");
    }
}
