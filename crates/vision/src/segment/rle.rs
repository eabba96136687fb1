//! COCO run-length encoding, as pycocotools writes it: pixels in column-major (Fortran) order,
//! alternating run lengths starting with a run of zeros (possibly empty), and the compressed string
//! form of `counts` (`rleToString` / `rleFrString`).

use serde::{Deserialize, Serialize};

use super::mask::BitMask;

/// Why an RLE could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RleError {
    #[error("RLE counts sum to {found} pixels but size {height}x{width} has {expected}")]
    PixelCountMismatch {
        height: u32,
        width: u32,
        expected: u64,
        found: u64,
    },
    #[error(
        "RLE counts string has byte {byte:#04x} at offset {offset}; only '0'..='o' (48..=111) occur"
    )]
    InvalidCharacter { byte: u8, offset: usize },
    #[error("RLE counts string ends inside a number")]
    Truncated,
    #[error("RLE counts string has a number too large at offset {offset}")]
    Overflow { offset: usize },
    #[error("RLE counts string decodes to the negative run length {value} at run {run}")]
    NegativeRun { value: i64, run: usize },
}

/// Uncompressed COCO RLE: `size` is `[height, width]` as in COCO JSON.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CocoRle {
    pub size: [u32; 2],
    pub counts: Vec<u32>,
}

/// COCO RLE with `counts` in pycocotools' compressed string form, the shape the API sends.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CompressedRle {
    pub size: [u32; 2],
    pub counts: String,
}

impl CocoRle {
    /// Encodes a mask, walking columns left to right and each column top to bottom.
    pub fn encode(mask: &BitMask) -> CocoRle {
        let mut counts = Vec::new();
        let mut current = false;
        let mut run = 0u32;
        for x in 0..mask.width() {
            for y in 0..mask.height() {
                if mask.get(x, y) != current {
                    counts.push(run);
                    run = 0;
                    current = !current;
                }
                run += 1;
            }
        }
        counts.push(run);
        CocoRle {
            size: [mask.height(), mask.width()],
            counts,
        }
    }

    /// Decodes into a mask; the counts must cover exactly `height x width` pixels.
    pub fn decode(&self) -> Result<BitMask, RleError> {
        let [height, width] = self.size;
        let expected = u64::from(height) * u64::from(width);
        let found: u64 = self.counts.iter().map(|&count| u64::from(count)).sum();
        if found != expected {
            return Err(RleError::PixelCountMismatch {
                height,
                width,
                expected,
                found,
            });
        }
        let mut mask = BitMask::new(width, height);
        let mut position = 0u64;
        for (run_index, &count) in self.counts.iter().enumerate() {
            // Odd runs are ones.
            if run_index % 2 == 1 {
                for column_major in position..position + u64::from(count) {
                    let x = (column_major / u64::from(height)) as u32;
                    let y = (column_major % u64::from(height)) as u32;
                    mask.set(x, y, true);
                }
            }
            position += u64::from(count);
        }
        Ok(mask)
    }

    /// pycocotools' `rleToString`: each count (from the fourth on, as the difference to the count
    /// two before it) in a LEB128-like signed code of 5 data bits per character, bit 0x20 meaning
    /// "more follows", offset by 48 into printable ASCII.
    pub fn to_compressed(&self) -> CompressedRle {
        let mut text = String::new();
        for (index, &count) in self.counts.iter().enumerate() {
            let mut value = i64::from(count);
            if index > 2 {
                value -= i64::from(self.counts[index - 2]);
            }
            loop {
                let mut chunk = (value & 0x1f) as u8;
                value >>= 5;
                let more = if chunk & 0x10 != 0 {
                    value != -1
                } else {
                    value != 0
                };
                if more {
                    chunk |= 0x20;
                }
                text.push(char::from(chunk + 48));
                if !more {
                    break;
                }
            }
        }
        CompressedRle {
            size: self.size,
            counts: text,
        }
    }

    /// pycocotools' `rleFrString`, refusing characters, lengths and values it would silently
    /// misread. The pixel total is checked by [`decode`](CocoRle::decode).
    pub fn from_compressed(compressed: &CompressedRle) -> Result<CocoRle, RleError> {
        let bytes = compressed.counts.as_bytes();
        let mut counts: Vec<u32> = Vec::new();
        let mut offset = 0;
        while offset < bytes.len() {
            let mut value = 0i64;
            let mut shift = 0u32;
            loop {
                let Some(&byte) = bytes.get(offset) else {
                    return Err(RleError::Truncated);
                };
                if !(48..=111).contains(&byte) {
                    return Err(RleError::InvalidCharacter { byte, offset });
                }
                // Counts are u32 in pycocotools: more than 7 chunks cannot be one.
                if shift > 35 {
                    return Err(RleError::Overflow { offset });
                }
                let chunk = i64::from(byte - 48);
                value |= (chunk & 0x1f) << shift;
                shift += 5;
                offset += 1;
                if chunk & 0x20 == 0 {
                    if chunk & 0x10 != 0 {
                        value |= -1i64 << shift;
                    }
                    break;
                }
            }
            let run = counts.len();
            if run > 2 {
                value += i64::from(counts[run - 2]);
            }
            let count = u32::try_from(value).map_err(|_| {
                if value < 0 {
                    RleError::NegativeRun { value, run }
                } else {
                    RleError::Overflow { offset }
                }
            })?;
            counts.push(count);
        }
        Ok(CocoRle {
            size: compressed.size,
            counts,
        })
    }
}

impl BitMask {
    /// COCO RLE with compressed counts, as the API sends masks.
    pub fn to_coco_rle(&self) -> CompressedRle {
        CocoRle::encode(self).to_compressed()
    }

    /// Decodes a COCO RLE with compressed counts.
    pub fn from_coco_rle(compressed: &CompressedRle) -> Result<BitMask, RleError> {
        CocoRle::from_compressed(compressed)?.decode()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The 4x5 mask (rows) `00001 / 01110 / 01110 / 00000`.
    fn small_mask() -> BitMask {
        let rows = [
            [false, false, false, false, true],
            [false, true, true, true, false],
            [false, true, true, true, false],
            [false, false, false, false, false],
        ];
        let values: Vec<bool> = rows.iter().flatten().copied().collect();
        BitMask::from_bools(5, 4, &values).expect("20 values")
    }

    /// Expected values from pycocotools 2.0 `mask.encode` on the same arrays (Fortran order).
    #[test]
    fn matches_pycocotools_on_a_small_mask() {
        let rle = CocoRle::encode(&small_mask());
        assert_eq!(rle.size, [4, 5]);
        // Column-major: 5 zeros (column 0 and the top of column 1), then runs of 2, ...
        assert_eq!(rle.counts, vec![5, 2, 2, 2, 2, 2, 1, 1, 3]);
        assert_eq!(rle.to_compressed().counts, "522000OO2");
        assert_eq!(rle.decode(), Ok(small_mask()));
    }

    #[test]
    fn matches_pycocotools_on_large_counts_and_negative_differences() {
        // A 40x70 mask: rows 5..30 x columns 10..60, a 2x2 hole at rows 12..14, columns 20..22,
        // and the last pixel set.
        let (height, width) = (40u32, 70u32);
        let mut mask = BitMask::new(width, height);
        for y in 5..30 {
            for x in 10..60 {
                mask.set(x, y, !((12..14).contains(&y) && (20..22).contains(&x)));
            }
        }
        mask.set(69, 39, true);
        let compressed = mask.to_coco_rle();
        assert_eq!(
            compressed.counts,
            "e<i0?000000000000000000^OC9=GC9=9000000000000000000000000000000000000000000000000\
             00000000000000000000000000Z<XO"
        );
        assert_eq!(BitMask::from_coco_rle(&compressed), Ok(mask));
        // A full 300x300 mask is one empty zero run and one run of 90000.
        let full = CocoRle {
            size: [300, 300],
            counts: vec![0, 90000],
        };
        assert_eq!(full.to_compressed().counts, "0`lg2");
        assert_eq!(
            CocoRle {
                size: [3, 3],
                counts: vec![9]
            }
            .to_compressed()
            .counts,
            "9"
        );
    }

    #[test]
    fn round_trips_random_masks() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        for (width, height) in [(1, 1), (7, 3), (64, 2), (65, 9), (130, 47)] {
            let mut mask = BitMask::new(width, height);
            for y in 0..height {
                for x in 0..width {
                    state ^= state << 13;
                    state ^= state >> 7;
                    state ^= state << 17;
                    mask.set(x, y, state.is_multiple_of(3));
                }
            }
            let compressed = mask.to_coco_rle();
            assert_eq!(BitMask::from_coco_rle(&compressed).as_ref(), Ok(&mask));
            let json = serde_json::to_string(&compressed).expect("serialisable");
            let parsed: CompressedRle = serde_json::from_str(&json).expect("parses");
            assert_eq!(parsed, compressed);
        }
    }

    #[test]
    fn rejects_malformed_strings_and_counts() {
        let size = [4, 5];
        let bad_character = CompressedRle {
            size,
            counts: "52 2".to_string(),
        };
        assert_eq!(
            CocoRle::from_compressed(&bad_character),
            Err(RleError::InvalidCharacter {
                byte: b' ',
                offset: 2
            })
        );
        // 'P' = 48 + 0x20: "more follows" but the string ends.
        let truncated = CompressedRle {
            size,
            counts: "5P".to_string(),
        };
        assert_eq!(
            CocoRle::from_compressed(&truncated),
            Err(RleError::Truncated)
        );
        let too_long = CompressedRle {
            size,
            counts: "PPPPPPPPP0".to_string(),
        };
        assert!(matches!(
            CocoRle::from_compressed(&too_long),
            Err(RleError::Overflow { .. })
        ));
        // 'O' = 48 + 31: sign bit set, no continuation, so -1 as the first count.
        let negative = CompressedRle {
            size,
            counts: "O".to_string(),
        };
        assert!(matches!(
            CocoRle::from_compressed(&negative),
            Err(RleError::NegativeRun { value: -1, run: 0 })
        ));
        let short = CocoRle {
            size,
            counts: vec![5, 2],
        };
        assert!(matches!(
            short.decode(),
            Err(RleError::PixelCountMismatch {
                expected: 20,
                found: 7,
                ..
            })
        ));
    }
}
