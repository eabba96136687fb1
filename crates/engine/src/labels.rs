//! Per-Gaussian object ids beside a PLY: a NumPy `.npy` file of `uint32` with shape `(N, 3)` in
//! PLY vertex order, columns small / middle / large, `4294967295` (u32::MAX) meaning "no object".
//! NumPy users read it with `np.load(path)`; it stays aligned because it is written from the same
//! model in the same order as the PLY.

use std::io::{Read, Write};

use npyz::WriterBuilder;

#[derive(Debug, thiserror::Error)]
pub enum LabelsError {
    #[error("labels file I/O: {0}")]
    Io(#[from] std::io::Error),
    #[error("labels file has shape {found:?}; expected ({expected}, 3) uint32")]
    Shape { found: Vec<u64>, expected: usize },
}

/// Writes the ids as `uint32[N, 3]`.
pub fn write_labels<W: Write>(object_ids: &[[u32; 3]], target: W) -> Result<(), LabelsError> {
    let mut writer = npyz::WriteOptions::<u32>::new()
        .default_dtype()
        .shape(&[object_ids.len() as u64, 3])
        .writer(target)
        .begin_nd()?;
    writer.extend(object_ids.iter().flatten().copied())?;
    writer.finish()?;
    Ok(())
}

/// Reads ids written by [`write_labels`], checking they match `expected_count` Gaussians.
pub fn read_labels<R: Read>(
    source: R,
    expected_count: usize,
) -> Result<Vec<[u32; 3]>, LabelsError> {
    let file = npyz::NpyFile::new(source)?;
    let shape = file.shape().to_vec();
    if shape != [expected_count as u64, 3] {
        return Err(LabelsError::Shape {
            found: shape,
            expected: expected_count,
        });
    }
    let flat: Vec<u32> = file.into_vec()?;
    Ok(flat
        .chunks_exact(3)
        .map(|ids| [ids[0], ids[1], ids[2]])
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_shape_check() {
        let ids = vec![[0, 1, 2], [u32::MAX, 7, 300_000], [5, 5, u32::MAX]];
        let mut bytes = Vec::new();
        write_labels(&ids, &mut bytes).unwrap();
        assert!(bytes.starts_with(b"\x93NUMPY"));
        assert_eq!(read_labels(bytes.as_slice(), 3).unwrap(), ids);
        assert!(matches!(
            read_labels(bytes.as_slice(), 4),
            Err(LabelsError::Shape { .. })
        ));
    }
}
