//! Two-dimensional float arrays from `.npy` files (Nerfies `points.npy`, LLFF
//! `poses_bounds.npy`), as numpy writes them: float32 or float64, either byte order, C or
//! Fortran order.

use std::fs;
use std::io;
use std::path::Path;

use super::SceneError;

/// A row-major matrix of `rows` x `columns` values.
#[derive(Debug, Clone, PartialEq)]
pub struct NpyMatrix {
    pub rows: usize,
    pub columns: usize,
    pub values: Vec<f64>,
}

impl NpyMatrix {
    pub fn row(&self, index: usize) -> &[f64] {
        &self.values[index * self.columns..(index + 1) * self.columns]
    }
}

/// Reads `file_name` under `root` as a 2-D float matrix with `expected_columns` columns;
/// errors name the file and say what was found.
pub fn read_float_matrix(
    root: &Path,
    file_name: &str,
    expected_columns: usize,
) -> Result<NpyMatrix, SceneError> {
    let parse_error = |message: String| SceneError::Parse {
        file: file_name.to_string(),
        message,
    };
    let bytes = fs::read(root.join(file_name)).map_err(|source| match source.kind() {
        io::ErrorKind::NotFound => parse_error("missing".to_string()),
        _ => SceneError::Io {
            file: file_name.to_string(),
            source,
        },
    })?;
    check_header(&bytes).map_err(parse_error)?;
    let npy = npyz::NpyFile::new(&bytes[..])
        .map_err(|error| parse_error(format!("not a .npy array: {error}")))?;
    let shape = npy.shape().to_vec();
    let [rows, columns] = shape[..] else {
        return Err(parse_error(format!(
            "expected a 2-D array of shape (N, {expected_columns}), found shape {shape:?}"
        )));
    };
    if columns != expected_columns as u64 {
        return Err(parse_error(format!(
            "expected shape (N, {expected_columns}), found ({rows}, {columns})"
        )));
    }
    let (rows, columns) = (rows as usize, columns as usize);
    let fortran_order = npy.order() == npyz::Order::Fortran;
    let stored = read_floats(npy).map_err(parse_error)?;
    if stored.len() != rows * columns {
        return Err(parse_error(format!(
            "holds {} values but its shape says {rows} x {columns}",
            stored.len()
        )));
    }
    let values = if fortran_order {
        // Column-major on disk: value (row, column) sits at column * rows + row.
        (0..rows * columns)
            .map(|index| stored[(index % columns) * rows + index / columns])
            .collect()
    } else {
        stored
    };
    if values.iter().any(|value| !value.is_finite()) {
        return Err(parse_error("holds a non-finite value".to_string()));
    }
    Ok(NpyMatrix {
        rows,
        columns,
        values,
    })
}

/// The most brackets a header may nest: `{'shape': (2, 3)}` needs 2. Deeper headers describe
/// structured dtypes, which are refused anyway.
const MAX_HEADER_NESTING: usize = 2;

/// Checks what `npyz` would otherwise trust (both found by fuzzing): a header length past the
/// end of the file, for which it allocates a buffer first (up to 4 GiB from the u32 of a
/// version 2 or 3 header), and deeply nested brackets, on which its Python-literal parser
/// backtracks for minutes.
fn check_header(bytes: &[u8]) -> Result<(), String> {
    const MAGIC: &[u8] = b"\x93NUMPY";
    let (Some(magic), Some(&major)) = (bytes.get(..MAGIC.len()), bytes.get(6)) else {
        return Err("not a .npy array: too short".to_string());
    };
    if magic != MAGIC {
        return Err("not a .npy array: no \\x93NUMPY signature".to_string());
    }
    let (header_length, preamble) = match major {
        1 => (
            bytes
                .get(8..10)
                .map(|b| u64::from(u16::from_le_bytes([b[0], b[1]]))),
            10,
        ),
        _ => (
            bytes
                .get(8..12)
                .map(|b| u64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))),
            12,
        ),
    };
    let Some(header_length) = header_length else {
        return Err("not a .npy array: too short".to_string());
    };
    if preamble + header_length > bytes.len() as u64 {
        return Err(format!(
            "header says it is {header_length} bytes long but the file has {} bytes",
            bytes.len()
        ));
    }
    let header = &bytes[preamble as usize..(preamble + header_length) as usize];
    if nesting_depth(header) > MAX_HEADER_NESTING {
        return Err(format!(
            "header nests brackets more than {MAX_HEADER_NESTING} deep (only plain float32 or \
             float64 arrays are read)"
        ));
    }
    Ok(())
}

/// The deepest bracket nesting in `header`, quotes ignored (a bracket in a string only makes
/// a valid header look deeper, and valid float headers have no such strings).
fn nesting_depth(header: &[u8]) -> usize {
    let mut depth = 0usize;
    let mut deepest = 0;
    for byte in header {
        match byte {
            b'{' | b'[' | b'(' => {
                depth += 1;
                deepest = deepest.max(depth);
            }
            b'}' | b']' | b')' => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    deepest
}

/// The array's values widened to f64; only float32 and float64 arrays are accepted.
fn read_floats(npy: npyz::NpyFile<&[u8]>) -> Result<Vec<f64>, String> {
    let dtype = npy.dtype().descr();
    let npy = match npy.try_data::<f64>() {
        Ok(reader) => return reader.collect::<io::Result<Vec<f64>>>().map_err(truncated),
        Err(npy) => npy,
    };
    match npy.try_data::<f32>() {
        Ok(reader) => reader
            .map(|value| value.map(f64::from))
            .collect::<io::Result<Vec<f64>>>()
            .map_err(truncated),
        Err(_) => Err(format!(
            "expected float32 or float64 values, found dtype {dtype}"
        )),
    }
}

fn truncated(error: io::Error) -> String {
    format!("array data cannot be read: {error}")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A numpy file written by hand: big-endian float64 in Fortran (column-major) order.
    fn fortran_npy(values_column_major: &[f64]) -> Vec<u8> {
        let mut header = "{'descr': '>f8', 'fortran_order': True, 'shape': (2, 3), }".to_string();
        while !(10 + header.len() + 1).is_multiple_of(64) {
            header.push(' ');
        }
        header.push('\n');
        let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
        bytes.extend((header.len() as u16).to_le_bytes());
        bytes.extend(header.as_bytes());
        for value in values_column_major {
            bytes.extend(value.to_be_bytes());
        }
        bytes
    }

    #[test]
    fn fortran_order_and_big_endian_come_out_row_major() {
        let dir = tempfile::tempdir().unwrap();
        // Rows [1, 2, 3] and [4, 5, 6], stored column by column.
        let bytes = fortran_npy(&[1.0, 4.0, 2.0, 5.0, 3.0, 6.0]);
        std::fs::write(dir.path().join("m.npy"), bytes).unwrap();
        let matrix = read_float_matrix(dir.path(), "m.npy", 3).unwrap();
        assert_eq!((matrix.rows, matrix.columns), (2, 3));
        assert_eq!(matrix.row(0), [1.0, 2.0, 3.0]);
        assert_eq!(matrix.row(1), [4.0, 5.0, 6.0]);
    }

    #[test]
    fn wrong_shapes_and_types_are_parse_errors() {
        let dir = tempfile::tempdir().unwrap();
        let error = read_float_matrix(dir.path(), "m.npy", 3).unwrap_err();
        assert!(error.to_string().contains("missing"), "{error}");
        let bytes = fortran_npy(&[0.0; 6]);
        std::fs::write(dir.path().join("m.npy"), bytes).unwrap();
        let error = read_float_matrix(dir.path(), "m.npy", 17).unwrap_err();
        assert!(matches!(error, SceneError::Parse { .. }), "{error}");
        assert!(error.to_string().contains("(2, 3)"), "{error}");
        let mut integers = Vec::new();
        {
            use npyz::WriterBuilder;
            let mut writer = npyz::WriteOptions::<i32>::new()
                .default_dtype()
                .shape(&[1, 3])
                .writer(&mut integers)
                .begin_nd()
                .unwrap();
            writer.extend([1, 2, 3]).unwrap();
            writer.finish().unwrap();
        }
        std::fs::write(dir.path().join("m.npy"), integers).unwrap();
        let error = read_float_matrix(dir.path(), "m.npy", 3).unwrap_err();
        assert!(error.to_string().contains("float32 or float64"), "{error}");
    }

    /// Fuzzing found a version 3 header claiming 1.6 GB, which npyz allocated before reading.
    #[test]
    fn header_length_past_the_end_is_refused_before_allocating() {
        let dir = tempfile::tempdir().unwrap();
        let mut bytes = b"\x93NUMPY\x03\x00".to_vec();
        bytes.extend(0x6464_7b27_u32.to_le_bytes());
        bytes.extend(b"{'descr': '<f8'}");
        std::fs::write(dir.path().join("m.npy"), bytes).unwrap();
        let error = read_float_matrix(dir.path(), "m.npy", 3).unwrap_err();
        assert!(error.to_string().contains("header says"), "{error}");
    }

    /// Fuzzing found 60 nested braces in a header keep npyz's literal parser busy for minutes.
    #[test]
    fn deeply_nested_headers_are_refused_before_parsing() {
        let dir = tempfile::tempdir().unwrap();
        let header = format!("{{'descr': {}'<f8'}}", "{".repeat(60));
        let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
        bytes.extend((header.len() as u16).to_le_bytes());
        bytes.extend(header.as_bytes());
        std::fs::write(dir.path().join("m.npy"), bytes).unwrap();
        let started = std::time::Instant::now();
        let error = read_float_matrix(dir.path(), "m.npy", 3).unwrap_err();
        assert!(error.to_string().contains("nests"), "{error}");
        assert!(started.elapsed() < std::time::Duration::from_secs(1));
    }
}
