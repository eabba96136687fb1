//! Gaussian scenes as PLY files in the layout of the original 3DGS code ("Inria layout"), which
//! common splat viewers open: `x y z nx ny nz f_dc_0..2 f_rest_0..44 opacity scale_0..2 rot_0..3`,
//! binary little endian. Reading accepts any property order, ASCII or binary, float or double,
//! and SH degree 0-3 (by the number of `f_rest_*` properties).
//!
//! Object ids are not PLY properties (viewers would show them as junk attributes); they go to a
//! sidecar, see [`crate::labels`].

use std::io::{BufReader, BufWriter, Read, Write};

use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    Addable, ElementDef, Encoding, Header, PropertyAccess, PropertyAccessResult, PropertyDef,
    PropertyType, ScalarType,
};
use ply_rs_bw::writer::Writer;

use crate::model::{GaussianModel, OBJECT_NONE, SH_COEFFICIENTS};

/// Opacity logits beyond this are clamped on import: +/-inf (seen in files written by some tools)
/// would poison gradients, and sigmoid(20) is already 1 - 2e-9.
pub const OPACITY_LOGIT_LIMIT: f32 = 20.0;

const REST_PER_CHANNEL: usize = SH_COEFFICIENTS - 1;
/// Slots: x y z, f_dc 0..3, f_rest 0..45, opacity, scale 0..3, rot 0..4.
const SLOT_COUNT: usize = 3 + 3 + 3 * REST_PER_CHANNEL + 1 + 3 + 4;
const SLOT_DC: usize = 3;
const SLOT_REST: usize = 6;
const SLOT_OPACITY: usize = SLOT_REST + 3 * REST_PER_CHANNEL;
const SLOT_SCALE: usize = SLOT_OPACITY + 1;
const SLOT_ROTATION: usize = SLOT_SCALE + 3;

#[derive(Debug, thiserror::Error)]
pub enum PlyError {
    #[error("PLY read failed: {0}")]
    Read(std::io::Error),
    #[error("PLY parse failed: {0}")]
    Parse(#[from] ply_rs_bw::parser::ParseError),
    #[error("PLY write failed: {0}")]
    Write(std::io::Error),
    #[error("PLY has no `vertex` element")]
    NoVertexElement,
    #[error("PLY vertex element lacks property `{0}`")]
    MissingProperty(String),
    #[error("PLY has {0} f_rest properties; expected 0, 9, 24 or 45 (SH degree 0-3)")]
    UnsupportedShRest(usize),
    #[error("Gaussian {index}: property `{property}` is not finite")]
    NotFinite { index: usize, property: String },
}

/// Result of an import, with what had to be repaired.
#[derive(Debug, Clone)]
pub struct PlyImport {
    pub model: GaussianModel,
    /// SH degree the file carried.
    pub sh_degree: u32,
    /// Gaussians whose opacity was +/-inf and was clamped to +/-[`OPACITY_LOGIT_LIMIT`].
    pub clamped_opacities: usize,
}

/// Property name -> slot in a row; `None` for properties we do not use (normals, colours).
fn slot_for(name: &str) -> Option<usize> {
    let indexed = |prefix: &str, limit: usize| -> Option<usize> {
        name.strip_prefix(prefix)
            .and_then(|digits| digits.parse::<usize>().ok())
            .filter(|&index| index < limit)
    };
    match name {
        "x" => Some(0),
        "y" => Some(1),
        "z" => Some(2),
        "opacity" => Some(SLOT_OPACITY),
        _ => indexed("f_dc_", 3)
            .map(|i| SLOT_DC + i)
            .or_else(|| indexed("f_rest_", 3 * REST_PER_CHANNEL).map(|i| SLOT_REST + i))
            .or_else(|| indexed("scale_", 3).map(|i| SLOT_SCALE + i))
            .or_else(|| indexed("rot_", 4).map(|i| SLOT_ROTATION + i)),
    }
}

fn slot_name(slot: usize) -> String {
    match slot {
        0 => "x".into(),
        1 => "y".into(),
        2 => "z".into(),
        s if s < SLOT_REST => format!("f_dc_{}", s - SLOT_DC),
        s if s < SLOT_OPACITY => format!("f_rest_{}", s - SLOT_REST),
        SLOT_OPACITY => "opacity".into(),
        s if s < SLOT_ROTATION => format!("scale_{}", s - SLOT_SCALE),
        s => format!("rot_{}", s - SLOT_ROTATION),
    }
}

/// One vertex row; `set` records which slots the file provided.
#[derive(Debug, Clone)]
struct GaussianRow {
    values: [f32; SLOT_COUNT],
    set: u64,
}

impl GaussianRow {
    fn store(&mut self, name: &str, value: f32) -> PropertyAccessResult {
        match slot_for(name) {
            Some(slot) => {
                self.values[slot] = value;
                self.set |= 1 << slot;
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::Ignored,
        }
    }
}

impl PropertyAccess for GaussianRow {
    fn new() -> Self {
        Self {
            values: [0.0; SLOT_COUNT],
            set: 0,
        }
    }

    fn set_float(&mut self, property_name: &str, value: f32) -> PropertyAccessResult {
        self.store(property_name, value)
    }

    fn set_double(&mut self, property_name: &str, value: f64) -> PropertyAccessResult {
        self.store(property_name, value as f32)
    }

    fn set_uchar(&mut self, _property_name: &str, _value: u8) -> PropertyAccessResult {
        PropertyAccessResult::Ignored
    }

    fn get_float(&self, property_name: &str) -> Option<f32> {
        match property_name {
            "nx" | "ny" | "nz" => Some(0.0),
            name => slot_for(name).map(|slot| self.values[slot]),
        }
    }
}

/// Reads a Gaussian PLY from any reader.
pub fn read_ply<R: Read>(source: R) -> Result<PlyImport, PlyError> {
    let parser = Parser::<GaussianRow>::new();
    let mut reader = Reader::new(BufReader::new(source));
    let header = parser.read_header(&mut reader)?;
    let mut vertices = None;
    for (name, element) in &header.elements {
        // Elements must be consumed in header order; anything after `vertex` is not needed.
        let rows = parser.read_payload_for_element(&mut reader, element, &header)?;
        if name == "vertex" {
            vertices = Some((rows, element));
            break;
        }
    }
    let (rows, element) = vertices.ok_or(PlyError::NoVertexElement)?;
    let rest_count = element
        .properties
        .keys()
        .filter(|name| name.starts_with("f_rest_"))
        .count();
    let sh_degree = match rest_count {
        0 => 0,
        9 => 1,
        24 => 2,
        45 => 3,
        other => return Err(PlyError::UnsupportedShRest(other)),
    };
    let rest_per_channel = rest_count / 3;
    let mut required: Vec<usize> = (0..SLOT_REST).collect();
    required.extend(SLOT_OPACITY..SLOT_COUNT);
    for channel in 0..3 {
        required.extend((0..rest_per_channel).map(|k| SLOT_REST + channel * rest_per_channel + k));
    }
    let required_mask = required.iter().fold(0u64, |mask, &slot| mask | 1 << slot);
    if let Some(first) = rows.first() {
        let missing = required_mask & !first.set;
        if missing != 0 {
            return Err(PlyError::MissingProperty(slot_name(
                missing.trailing_zeros() as usize,
            )));
        }
    }
    model_from_rows(&rows, rest_per_channel, sh_degree)
}

fn model_from_rows(
    rows: &[GaussianRow],
    rest_per_channel: usize,
    sh_degree: u32,
) -> Result<PlyImport, PlyError> {
    let mut model = GaussianModel::default();
    let mut clamped_opacities = 0;
    for (index, row) in rows.iter().enumerate() {
        let v = &row.values;
        let mut opacity = v[SLOT_OPACITY];
        if opacity.is_infinite() {
            opacity = opacity.clamp(-OPACITY_LOGIT_LIMIT, OPACITY_LOGIT_LIMIT);
            clamped_opacities += 1;
        }
        let finite_check =
            (0..SLOT_COUNT).find(|&slot| slot != SLOT_OPACITY && !v[slot].is_finite());
        if let Some(slot) = finite_check.or(opacity.is_nan().then_some(SLOT_OPACITY)) {
            return Err(PlyError::NotFinite {
                index,
                property: slot_name(slot),
            });
        }
        let mut sh = [[0.0f32; 3]; SH_COEFFICIENTS];
        sh[0] = [v[SLOT_DC], v[SLOT_DC + 1], v[SLOT_DC + 2]];
        for channel in 0..3 {
            for k in 0..rest_per_channel {
                sh[1 + k][channel] = v[SLOT_REST + channel * rest_per_channel + k];
            }
        }
        model.means.push([v[0], v[1], v[2]]);
        model.sh_coefficients.push(sh);
        model.opacity_logits.push(opacity);
        model
            .log_scales
            .push([v[SLOT_SCALE], v[SLOT_SCALE + 1], v[SLOT_SCALE + 2]]);
        model.rotations.push([
            v[SLOT_ROTATION],
            v[SLOT_ROTATION + 1],
            v[SLOT_ROTATION + 2],
            v[SLOT_ROTATION + 3],
        ]);
        model.object_ids.push([OBJECT_NONE; 3]);
    }
    if clamped_opacities > 0 {
        tracing::warn!(
            clamped_opacities,
            "PLY import: infinite opacities clamped to +/-{OPACITY_LOGIT_LIMIT}"
        );
    }
    Ok(PlyImport {
        model,
        sh_degree,
        clamped_opacities,
    })
}

/// Writes `model` in the Inria layout (SH degree 3, binary little endian).
pub fn write_ply<W: Write>(model: &GaussianModel, target: W) -> Result<(), PlyError> {
    let mut out = BufWriter::new(target);
    let mut element = ElementDef::new("vertex".to_string());
    let float = || PropertyType::Scalar(ScalarType::Float);
    let mut names: Vec<String> = ["x", "y", "z", "nx", "ny", "nz"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    names.extend((SLOT_DC..SLOT_COUNT).map(slot_name));
    for name in names {
        element.properties.add(PropertyDef::new(name, float()));
    }
    element.count = model.len();
    let mut header = Header::new();
    header.encoding = Encoding::BinaryLittleEndian;
    header.elements.add(element.clone());
    let writer = Writer::<GaussianRow>::new();
    writer
        .write_header(&mut out, &header)
        .map_err(PlyError::Write)?;
    // Rows are materialised in bounded chunks so a multi-million Gaussian export does not double
    // the model in memory.
    const CHUNK: usize = 65_536;
    let mut chunk = Vec::with_capacity(CHUNK.min(model.len()));
    for start in (0..model.len()).step_by(CHUNK) {
        chunk.clear();
        chunk.extend((start..(start + CHUNK).min(model.len())).map(|i| row_of(model, i)));
        writer
            .write_payload_of_element(&mut out, &chunk, &element, &header)
            .map_err(PlyError::Write)?;
    }
    out.flush().map_err(PlyError::Write)
}

fn row_of(model: &GaussianModel, index: usize) -> GaussianRow {
    let mut row = GaussianRow::new();
    let v = &mut row.values;
    v[..3].copy_from_slice(&model.means[index]);
    let sh = &model.sh_coefficients[index];
    v[SLOT_DC..SLOT_DC + 3].copy_from_slice(&sh[0]);
    for channel in 0..3 {
        for k in 0..REST_PER_CHANNEL {
            v[SLOT_REST + channel * REST_PER_CHANNEL + k] = sh[1 + k][channel];
        }
    }
    v[SLOT_OPACITY] = model.opacity_logits[index];
    v[SLOT_SCALE..SLOT_SCALE + 3].copy_from_slice(&model.log_scales[index]);
    v[SLOT_ROTATION..SLOT_ROTATION + 4].copy_from_slice(&model.rotations[index]);
    row.set = u64::MAX;
    row
}

/// Reads a PLY file from `path`.
pub fn read_ply_file(path: &std::path::Path) -> Result<PlyImport, PlyError> {
    let file = std::fs::File::open(path).map_err(PlyError::Read)?;
    read_ply(file)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_model() -> GaussianModel {
        let mut model = GaussianModel::default();
        for i in 0..5 {
            let f = i as f32;
            model.means.push([f, -f, 0.5 * f]);
            model.log_scales.push([-f, 0.1, 0.2]);
            model.rotations.push([1.0, 0.1 * f, 0.0, -0.2]);
            model.opacity_logits.push(f - 2.0);
            let mut sh = [[0.0; 3]; SH_COEFFICIENTS];
            for (k, coefficient) in sh.iter_mut().enumerate() {
                *coefficient = [k as f32, 100.0 + k as f32, 200.0 + k as f32 + f];
            }
            model.sh_coefficients.push(sh);
            model.object_ids.push([OBJECT_NONE; 3]);
        }
        model
    }

    #[test]
    fn round_trip_is_exact() {
        let model = sample_model();
        let mut bytes = Vec::new();
        write_ply(&model, &mut bytes).unwrap();
        let imported = read_ply(bytes.as_slice()).unwrap();
        assert_eq!(imported.sh_degree, 3);
        assert_eq!(imported.clamped_opacities, 0);
        assert_eq!(imported.model, model);
    }

    #[test]
    fn inria_rest_order_is_channel_major() {
        let model = sample_model();
        let mut bytes = Vec::new();
        write_ply(&model, &mut bytes).unwrap();
        let header_end = bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .unwrap()
            + 11;
        let header = std::str::from_utf8(&bytes[..header_end]).unwrap();
        let names: Vec<&str> = header
            .lines()
            .filter_map(|line| line.strip_prefix("property float "))
            .collect();
        assert_eq!(names.len(), 62);
        let first_row: Vec<f32> =
            bytemuck::pod_collect_to_vec(&bytes[header_end..header_end + 62 * 4]);
        let at = |name: &str| first_row[names.iter().position(|n| *n == name).unwrap()];
        // f_rest_{c*15 + k} is coefficient k+1 of channel c.
        assert_eq!(at("f_rest_0"), 1.0);
        assert_eq!(at("f_rest_15"), 101.0);
        assert_eq!(at("f_rest_44"), 215.0);
        assert_eq!(at("nx"), 0.0);
    }

    fn ascii_ply(properties: &[&str], rows: &[&str]) -> Vec<u8> {
        let mut text = format!("ply\nformat ascii 1.0\nelement vertex {}\n", rows.len());
        for property in properties {
            text.push_str(&format!("property float {property}\n"));
        }
        text.push_str("end_header\n");
        for row in rows {
            text.push_str(row);
            text.push('\n');
        }
        text.into_bytes()
    }

    const DEGREE0: [&str; 14] = [
        "opacity", "rot_3", "rot_2", "rot_1", "rot_0", "scale_2", "scale_1", "scale_0", "f_dc_2",
        "f_dc_1", "f_dc_0", "z", "y", "x",
    ];

    #[test]
    fn reads_any_property_order_and_degree_zero() {
        let bytes = ascii_ply(&DEGREE0, &["0.5 0 0 0 1 -3 -2 -1 0.3 0.2 0.1 9 8 7"]);
        let imported = read_ply(bytes.as_slice()).unwrap();
        assert_eq!(imported.sh_degree, 0);
        let model = imported.model;
        assert_eq!(model.means[0], [7.0, 8.0, 9.0]);
        assert_eq!(model.log_scales[0], [-1.0, -2.0, -3.0]);
        assert_eq!(model.rotations[0], [1.0, 0.0, 0.0, 0.0]);
        assert_eq!(model.sh_coefficients[0][0], [0.1, 0.2, 0.3]);
        assert_eq!(model.sh_coefficients[0][1], [0.0; 3]);
        assert_eq!(model.opacity_logits[0], 0.5);
    }

    /// Binary files are where non-finite values occur in practice (ASCII "inf" is not PLY).
    fn binary_ply(properties: &[&str], rows: &[Vec<f32>]) -> Vec<u8> {
        let mut bytes = format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex {}\n",
            rows.len()
        );
        for property in properties {
            bytes.push_str(&format!("property float {property}\n"));
        }
        bytes.push_str("end_header\n");
        let mut bytes = bytes.into_bytes();
        for row in rows {
            bytes.extend_from_slice(bytemuck::cast_slice(row));
        }
        bytes
    }

    #[test]
    fn infinite_opacity_is_clamped_and_nan_rejected() {
        let mut row = vec![0.0f32; 14];
        row[0] = f32::INFINITY;
        row[4] = 1.0;
        let imported = read_ply(binary_ply(&DEGREE0, &[row.clone()]).as_slice()).unwrap();
        assert_eq!(imported.clamped_opacities, 1);
        assert_eq!(imported.model.opacity_logits[0], OPACITY_LOGIT_LIMIT);

        row[0] = 0.0;
        row[11] = f32::NAN;
        match read_ply(binary_ply(&DEGREE0, &[row]).as_slice()) {
            Err(PlyError::NotFinite { index, property }) => {
                assert_eq!(index, 0);
                assert_eq!(property, "z");
            }
            other => panic!("expected NotFinite, got {other:?}"),
        }
    }

    #[test]
    fn missing_property_is_named() {
        let bytes = ascii_ply(&DEGREE0[1..], &["0 0 0 1 0 0 0 0 0 0 0 0 0"]);
        match read_ply(bytes.as_slice()) {
            Err(PlyError::MissingProperty(name)) => assert_eq!(name, "opacity"),
            other => panic!("expected MissingProperty, got {other:?}"),
        }
    }
}
