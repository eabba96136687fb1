"""What is written where: the tiny model directory and its manifest, the official-signature folders,
the tokenizer and preprocessing fixtures."""

import json
import os

import numpy as np
import onnx
from onnx import TensorProto

from file_digest import sha256_of

from .constants import (
    CLIP_FIXTURE_DIR, CLIP_IMAGE_SIZE, CLIP_MEAN, CLIP_STD, CONTEXT_LENGTH, EOT_TOKEN,
    OFFICIAL_DIR, REPO_ROOT, SAM_IMAGE_SIZE, SAM_MEAN, SAM_STD, SOT_TOKEN, TINY_DIR)
from .clip_models import build_clip_image, build_clip_text, build_clip_text_of_width
from .sam_models import build_sam2_encoder, build_sam_decoder, build_sam_encoder
from .tokenizer import (
    TOKENIZER_CLEANING_TEXTS, TOKENIZER_TEXTS, build_tokenizer_json, colour_token_ids,
    tokenizer_cases)


# ---------------------------------------------------------------------------------------------
# Preprocessing fixture
# ---------------------------------------------------------------------------------------------

PREPROCESS_IMAGE_SIZES = [(97, 61), (300, 200)]  # (width, height)


def synthetic_image(width, height):
    """A deterministic, natural-looking RGB uint8 image: sky-to-ground gradients, a sun, a tilted
    box, a few stripes and mild texture, so resampling differences show up."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    u, v = x / max(width - 1, 1), y / max(height - 1, 1)
    red = 80 + 120 * v + 30 * np.sin(6.0 * u)
    green = 120 + 60 * (1 - v) + 20 * np.cos(9.0 * v + 3.0 * u)
    blue = 200 - 140 * v
    image = np.stack([red, green, blue], axis=-1)
    sun = (u - 0.75) ** 2 + (v - 0.25) ** 2 < 0.015
    image[sun] = (250, 220, 60)
    box = (np.abs((u - 0.3) + 0.3 * (v - 0.65)) < 0.12) & (np.abs(v - 0.65) < 0.18)
    image[box] = (180, 40, 40)
    stripes = (np.floor(u * 11) % 2 == 0) & (v > 0.9)
    image[stripes] = (20, 20, 20)
    texture = 12 * np.sin(x * 1.7) * np.cos(y * 2.3)
    image = image + texture[..., None]
    return np.clip(np.round(image), 0, 255).astype(np.uint8)


def write_preprocess_fixture():
    """PNG + open_clip preprocess_val(pixel_values) as .npy for each fixture size."""
    import open_clip
    from PIL import Image

    _, _, preprocess = open_clip.create_model_and_transforms("ViT-B-32", pretrained=None)
    cases = []
    for width, height in PREPROCESS_IMAGE_SIZES:
        stem = f"preprocess_{width}x{height}"
        Image.fromarray(synthetic_image(width, height)).save(os.path.join(CLIP_FIXTURE_DIR, stem + ".png"))
        reloaded = Image.open(os.path.join(CLIP_FIXTURE_DIR, stem + ".png"))
        pixel_values = preprocess(reloaded).unsqueeze(0).numpy().astype("<f4")
        np.save(os.path.join(CLIP_FIXTURE_DIR, stem + "_pixel_values.npy"), pixel_values)
        cases.append({"image": stem + ".png", "pixel_values": stem + "_pixel_values.npy",
                      "width": width, "height": height, "shape": list(pixel_values.shape)})
    with open(os.path.join(CLIP_FIXTURE_DIR, "preprocess_cases.json"), "w") as f:
        json.dump({"transform": repr(preprocess), "cases": cases}, f, indent=2)
        f.write("\n")


# ---------------------------------------------------------------------------------------------
# Manifest
# ---------------------------------------------------------------------------------------------


NUMPY_DTYPE_NAMES = {TensorProto.FLOAT: "float32", TensorProto.INT64: "int64"}


def io_entries(value_infos):
    """Manifest inputs/outputs from the graph's value infos (-1 for symbolic dimensions)."""
    entries = []
    for info in value_infos:
        tensor_type = info.type.tensor_type
        shape = [d.dim_value if d.HasField("dim_value") else -1 for d in tensor_type.shape.dim]
        entries.append({"name": info.name, "dtype": NUMPY_DTYPE_NAMES[tensor_type.elem_type], "shape": shape})
    return entries


def manifest_entry(name, role, family, model, file_name, preprocess):
    return {
        "name": name,
        "role": role,
        "family": family,
        "architecture": "tiny-colour",
        "file": file_name,
        "sha256": sha256_of(os.path.join(TINY_DIR, file_name)),
        "inputs": io_entries(model.graph.input),
        "outputs": io_entries(model.graph.output),
        "preprocess": preprocess,
    }


CLIP_IMAGE_PREPROCESS = {
    "image_size": CLIP_IMAGE_SIZE,
    "resize": "shortest_side_center_crop",
    "interpolation": "bicubic",
    "pixel_scale": 1.0,
    "mean": CLIP_MEAN,
    "std": CLIP_STD,
}
SAM_ENCODER_PREPROCESS = {
    "image_size": SAM_IMAGE_SIZE,
    "resize": "longest_side_pad",
    "interpolation": "bilinear",
    "pixel_scale": 255.0,
    "mean": SAM_MEAN,
    "std": SAM_STD,
}


def write_tiny_model_dir():
    os.makedirs(TINY_DIR, exist_ok=True)
    import open_clip

    bpe_path = os.path.join(os.path.dirname(open_clip.__file__), "bpe_simple_vocab_16e6.txt.gz")
    with open(os.path.join(TINY_DIR, "tokenizer.json"), "w", encoding="utf-8") as f:
        json.dump(build_tokenizer_json(bpe_path), f, ensure_ascii=False, separators=(",", ":"))

    specs = [
        ("tiny-clip-image", "clip_image", "clip", build_clip_image(), CLIP_IMAGE_PREPROCESS),
        ("tiny-clip-text", "clip_text", "clip", build_clip_text(colour_token_ids()), {"context_length": CONTEXT_LENGTH}),
        ("tiny-sam-encoder", "sam_encoder", "sam", build_sam_encoder(), SAM_ENCODER_PREPROCESS),
        ("tiny-sam-decoder", "sam_decoder", "sam", build_sam_decoder(),
         {"encoder": "tiny-sam-encoder", "multimask_channels": [1, 2, 3], "mask_threshold": 0.0}),
    ]
    entries = []
    for name, role, family, model, preprocess in specs:
        file_name = name + ".onnx"
        onnx.save(model, os.path.join(TINY_DIR, file_name))
        entries.append(manifest_entry(name, role, family, model, file_name, preprocess))

    manifest = {
        "format_version": 1,
        "models": entries,
        "tokenizer": {
            "file": "tokenizer.json",
            "sha256": sha256_of(os.path.join(TINY_DIR, "tokenizer.json")),
            "context_length": CONTEXT_LENGTH,
            "start_token": SOT_TOKEN,
            "end_token": EOT_TOKEN,
        },
    }
    with open(os.path.join(TINY_DIR, "manifest.json"), "w") as f:
        json.dump(manifest, f, indent=2)
        f.write("\n")

# Folders of tiny models with the signatures of the exports users bring, and no manifest.json
# (`segsplat models init` writes it): file name -> builder.
OFFICIAL_VARIANTS = {
    # segment-anything's own export script (SamOnnxModel): every prompt input has batch 1, and
    # the crop before the final resize is baked at its example image's 683 x 1024.
    "sam": {
        "sam_vit_b_encoder.onnx": build_sam_encoder,
        "sam_vit_b_decoder.onnx": lambda: build_sam_decoder(
            point_batch=1, mask_batch=1, baked_crop=(683, 1024), name="official_sam_decoder"),
    },
    # MobileSAM's export follows it; this one batches points but broadcasts the mask input.
    "mobilesam": {
        "mobile_sam_encoder.onnx": build_sam_encoder,
        "mobile_sam.onnx": lambda: build_sam_decoder(mask_batch=1, name="official_mobilesam_decoder"),
    },
    # Common SAM 2.1 exports: points batched, mask input broadcast, SAM 2's object score added.
    "sam2": {
        "sam2.1_hiera_tiny.encoder.onnx": build_sam2_encoder,
        "sam2.1_hiera_tiny.decoder.onnx": lambda: build_sam_decoder(
            mask_batch=1, sam2=True, object_score=True, name="official_sam2_decoder"),
    },
}

def write_official_dirs():
    mismatched = os.path.join(REPO_ROOT, "tests", "fixtures", "models", "mismatched")
    os.makedirs(mismatched, exist_ok=True)
    onnx.save(build_clip_text_of_width(256), os.path.join(mismatched, "clip-text-256.onnx"))
    for variant, files in OFFICIAL_VARIANTS.items():
        folder = os.path.join(OFFICIAL_DIR, variant)
        os.makedirs(folder, exist_ok=True)
        for file_name, build in files.items():
            onnx.save(build(), os.path.join(folder, file_name))

def write_tokenizer_fixtures():
    os.makedirs(CLIP_FIXTURE_DIR, exist_ok=True)
    for file_name, texts in [("tokenizer_cases.json", TOKENIZER_TEXTS),
                             ("tokenizer_cleaning_cases.json", TOKENIZER_CLEANING_TEXTS)]:
        # one case per line keeps the fixture readable and its diffs small
        lines = [json.dumps(case, ensure_ascii=False) for case in tokenizer_cases(texts)]
        with open(os.path.join(CLIP_FIXTURE_DIR, file_name), "w", encoding="utf-8") as f:
            f.write("[\n" + ",\n".join(lines) + "\n]\n")
