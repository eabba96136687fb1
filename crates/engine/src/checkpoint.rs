//! Training checkpoints: enough state that a restarted job continues bit for bit — parameters,
//! optimiser moments, densification accumulators, step and RNG position — in one file.
//!
//! Layout: `SEGSPLAT-CKPT\0` magic, u32 version, u64 JSON header length, the JSON header (caller
//! metadata plus the name, offset and length of each binary section), the sections, and a SHA-256
//! of everything before it. Sections are raw little-endian bytes, so f32 state round-trips exactly.
//! A truncated or altered file fails the digest check instead of loading garbage.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;

use serde::{Deserialize, Serialize, de::DeserializeOwned};
use sha2::{Digest, Sha256};

const MAGIC: &[u8; 14] = b"SEGSPLAT-CKPT\0";
const VERSION: u32 = 1;

#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    #[error("checkpoint {path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("checkpoint is not a segsplat checkpoint or is version {0}, expected {VERSION}")]
    Format(String),
    #[error("checkpoint is truncated or corrupt (digest mismatch)")]
    Corrupt,
    #[error("checkpoint header: {0}")]
    Header(#[from] serde_json::Error),
    #[error("checkpoint lacks section `{0}`")]
    MissingSection(String),
}

#[derive(Serialize, Deserialize)]
struct Header<M> {
    meta: M,
    sections: BTreeMap<String, (u64, u64)>,
}

/// A checkpoint in memory: caller metadata plus named binary sections.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Checkpoint<M> {
    pub meta: M,
    pub sections: BTreeMap<String, Vec<u8>>,
}

impl<M: Serialize + DeserializeOwned> Checkpoint<M> {
    pub fn new(meta: M) -> Self {
        Self {
            meta,
            sections: BTreeMap::new(),
        }
    }

    /// Adds a section of plain values (f32, u32, ...), stored as their bytes.
    pub fn put<T: bytemuck::Pod>(&mut self, name: &str, values: &[T]) {
        self.sections
            .insert(name.to_string(), bytemuck::cast_slice(values).to_vec());
    }

    /// Reads a section back as plain values.
    pub fn get<T: bytemuck::Pod>(&self, name: &str) -> Result<Vec<T>, CheckpointError> {
        self.sections
            .get(name)
            .map(|bytes| bytemuck::pod_collect_to_vec(bytes))
            .ok_or_else(|| CheckpointError::MissingSection(name.to_string()))
    }

    pub fn to_bytes(&self) -> Result<Vec<u8>, CheckpointError> {
        let mut offset = 0u64;
        let mut layout = BTreeMap::new();
        for (name, bytes) in &self.sections {
            layout.insert(name.clone(), (offset, bytes.len() as u64));
            offset += bytes.len() as u64;
        }
        let header = serde_json::to_vec(&Header {
            meta: &self.meta,
            sections: layout,
        })?;
        let mut out = Vec::with_capacity(32 + header.len() + offset as usize + 32);
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&(header.len() as u64).to_le_bytes());
        out.extend_from_slice(&header);
        for bytes in self.sections.values() {
            out.extend_from_slice(bytes);
        }
        let digest = Sha256::digest(&out);
        out.extend_from_slice(&digest);
        Ok(out)
    }

    pub fn from_bytes(bytes: &[u8]) -> Result<Self, CheckpointError> {
        let prefix = MAGIC.len() + 4 + 8;
        if bytes.len() < prefix + 32 || &bytes[..MAGIC.len()] != MAGIC {
            return Err(CheckpointError::Format("unknown".to_string()));
        }
        let version = u32::from_le_bytes(read_array(&bytes[MAGIC.len()..]));
        if version != VERSION {
            return Err(CheckpointError::Format(version.to_string()));
        }
        let (body, digest) = bytes.split_at(bytes.len() - 32);
        if Sha256::digest(body)[..] != *digest {
            return Err(CheckpointError::Corrupt);
        }
        let header_len = u64::from_le_bytes(read_array(&bytes[MAGIC.len() + 4..])) as usize;
        let header_end = prefix
            .checked_add(header_len)
            .filter(|&end| end <= body.len())
            .ok_or(CheckpointError::Corrupt)?;
        let header: Header<M> = serde_json::from_slice(&body[prefix..header_end])?;
        let data = &body[header_end..];
        let mut sections = BTreeMap::new();
        for (name, (offset, length)) in header.sections {
            let start = offset as usize;
            let end = start
                .checked_add(length as usize)
                .ok_or(CheckpointError::Corrupt)?;
            let slice = data.get(start..end).ok_or(CheckpointError::Corrupt)?;
            sections.insert(name, slice.to_vec());
        }
        Ok(Self {
            meta: header.meta,
            sections,
        })
    }

    /// Writes atomically: temp file in the same directory, fsync, rename.
    pub fn save(&self, path: &Path) -> Result<(), CheckpointError> {
        let io = |source| CheckpointError::Io {
            path: path.display().to_string(),
            source,
        };
        let bytes = self.to_bytes()?;
        let directory = path.parent().unwrap_or(Path::new("."));
        let mut temp = tempfile::NamedTempFile::new_in(directory).map_err(io)?;
        temp.write_all(&bytes).map_err(io)?;
        temp.as_file().sync_all().map_err(io)?;
        temp.persist(path).map_err(|error| io(error.error))?;
        Ok(())
    }

    pub fn load(path: &Path) -> Result<Self, CheckpointError> {
        let bytes = std::fs::read(path).map_err(|source| CheckpointError::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_bytes(&bytes)
    }
}

fn read_array<const N: usize>(bytes: &[u8]) -> [u8; N] {
    let mut array = [0u8; N];
    array.copy_from_slice(&bytes[..N]);
    array
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
    struct Meta {
        step: u32,
        rng_word_pos: u128,
    }

    fn sample() -> Checkpoint<Meta> {
        let mut checkpoint = Checkpoint::new(Meta {
            step: 1234,
            rng_word_pos: u128::MAX - 5,
        });
        checkpoint.put(
            "means",
            &[1.0f32, f32::MIN_POSITIVE, -0.0, f32::NAN.copysign(-1.0)],
        );
        checkpoint.put("ids", &[7u32, u32::MAX]);
        checkpoint
    }

    #[test]
    fn round_trips_bit_for_bit() {
        let checkpoint = sample();
        let restored = Checkpoint::<Meta>::from_bytes(&checkpoint.to_bytes().unwrap()).unwrap();
        assert_eq!(restored.meta, checkpoint.meta);
        assert_eq!(restored.sections, checkpoint.sections);
        let means: Vec<f32> = restored.get("means").unwrap();
        assert_eq!(means[3].to_bits(), f32::NAN.copysign(-1.0).to_bits());
        assert!(matches!(
            restored.get::<f32>("absent"),
            Err(CheckpointError::MissingSection(_))
        ));
    }

    #[test]
    fn truncation_and_tampering_are_detected() {
        let bytes = sample().to_bytes().unwrap();
        assert!(Checkpoint::<Meta>::from_bytes(&bytes[..bytes.len() - 1]).is_err());
        let mut altered = bytes.clone();
        let middle = altered.len() / 2;
        altered[middle] ^= 1;
        assert!(matches!(
            Checkpoint::<Meta>::from_bytes(&altered),
            Err(CheckpointError::Corrupt)
        ));
        assert!(Checkpoint::<Meta>::from_bytes(b"not a checkpoint at all, clearly").is_err());
    }

    #[test]
    fn saves_atomically_to_disk() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("step.ckpt");
        sample().save(&path).unwrap();
        assert_eq!(Checkpoint::<Meta>::load(&path).unwrap(), sample());
    }
}
