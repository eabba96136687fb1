//! Masks decoded from the service's answers (RLE JSON, PNG), and the true mask of an object in a
//! frame of the synthetic capture.

use base64::Engine;
use segsplat_scene::Level;
use segsplat_vision::segment::{BitMask, CompressedRle};

pub(crate) fn decode_mask(mask: &serde_json::Value) -> BitMask {
    let width = mask["width"].as_u64().unwrap() as u32;
    let height = mask["height"].as_u64().unwrap() as u32;
    let data = mask["data"].as_str().unwrap();
    match mask["format"].as_str().unwrap() {
        "coco_rle" => BitMask::from_coco_rle(&CompressedRle {
            size: [height, width],
            counts: data.to_string(),
        })
        .unwrap(),
        "png" => {
            let bytes = base64::engine::general_purpose::STANDARD
                .decode(data)
                .unwrap();
            png_mask(&bytes)
        }
        other => panic!("unknown mask format {other}"),
    }
}

pub(crate) fn png_mask(bytes: &[u8]) -> BitMask {
    let image = image::load_from_memory(bytes).unwrap().into_luma8();
    let values: Vec<bool> = image.pixels().map(|pixel| pixel.0[0] > 127).collect();
    BitMask::from_bools(image.width(), image.height(), &values).unwrap()
}

/// The true visible silhouette of `object_id` at `level` in `frame_name`, from the dataset's
/// instance-id masks.
pub(crate) fn true_mask(
    files: &[(String, Vec<u8>)],
    level: Level,
    frame_name: &str,
    object_id: u32,
) -> BitMask {
    let path = segsplat_scene::masks::mask_path(level, frame_name);
    let path = path.to_string_lossy();
    let (_, bytes) = files
        .iter()
        .find(|(name, _)| name.ends_with(path.as_ref()))
        .unwrap_or_else(|| panic!("no {path}"));
    // Instance ids are raw values in 8-bit or 16-bit PNGs, never rescaled.
    let (width, height, ids): (u32, u32, Vec<u32>) = match image::load_from_memory(bytes).unwrap() {
        image::DynamicImage::ImageLuma8(ids) => (
            ids.width(),
            ids.height(),
            ids.pixels().map(|p| u32::from(p.0[0])).collect(),
        ),
        image::DynamicImage::ImageLuma16(ids) => (
            ids.width(),
            ids.height(),
            ids.pixels().map(|p| u32::from(p.0[0])).collect(),
        ),
        other => panic!("unexpected mask pixel type {:?}", other.color()),
    };
    let values: Vec<bool> = ids.iter().map(|&id| id == object_id).collect();
    BitMask::from_bools(width, height, &values).unwrap()
}
