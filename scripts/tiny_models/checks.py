"""--check: run the written files with onnxruntime / tokenizers."""

import json
import os

import numpy as np

from .constants import (
    CLIP_FIXTURE_DIR, OFFICIAL_DIR, SAM_IMAGE_SIZE, SAM_LOW_RES, SAM_MEAN, SAM_STD, TINY_DIR)
from .tokenizer import hf_tokenizer_ids
from .fixtures import OFFICIAL_VARIANTS


def check_official():
    """Each official decoder answers a batch its signature allows, with the blob scene."""
    import onnxruntime as ort

    for variant, files in OFFICIAL_VARIANTS.items():
        folder = os.path.join(OFFICIAL_DIR, variant)
        encoder_file, decoder_file = list(files)
        encoder = ort.InferenceSession(os.path.join(folder, encoder_file))
        decoder = ort.InferenceSession(os.path.join(folder, decoder_file))
        image, blobs = blob_scene(160, 120)
        pixels, scale = sam_preprocess(image)
        features = dict(zip([o.name for o in encoder.get_outputs()], encoder.run(None, {"image": pixels})))
        batch = 1 if variant == "sam" else len(blobs) + 1
        centres = [np.argwhere(mask)[:, ::-1].mean(axis=0) for mask in blobs.values()] + [np.array([2.0, 2.0])]
        points = np.array([[centre * scale, [0.0, 0.0]] for centre in centres[:batch]], np.float32)
        feeds = {
            "point_coords": points,
            "point_labels": np.tile(np.array([[1.0, -1.0]], np.float32), (batch, 1)),
            "mask_input": np.zeros((1, 1, SAM_LOW_RES, SAM_LOW_RES), np.float32),
            "has_mask_input": np.zeros(1, np.float32),
            "orig_im_size": np.array([120, 160], np.float32),
        }
        feeds.update({name: value for name, value in features.items() if name in [i.name for i in decoder.get_inputs()]})
        outputs = dict(zip([o.name for o in decoder.get_outputs()], decoder.run(None, feeds)))
        assert outputs["masks"].shape == (batch, 4, 120, 160), outputs["masks"].shape
        line = f"official {variant}: {batch} prompt(s) in one run, masks {outputs['masks'].shape}"
        if "object_score_logits" in outputs:
            scores = outputs["object_score_logits"][:, 0]
            assert (scores[:-1] > 0).all() and scores[-1] < 0, scores  # blobs vs the grey corner
            line += f", object scores {np.round(scores, 2).tolist()}"
        print(line)

def check_tokenizer():
    """Every recorded case must match; the cleaning cases are reported, not required."""
    path = os.path.join(TINY_DIR, "tokenizer.json")
    for file_name, required in [("tokenizer_cases.json", True), ("tokenizer_cleaning_cases.json", False)]:
        with open(os.path.join(CLIP_FIXTURE_DIR, file_name), encoding="utf-8") as f:
            cases = json.load(f)
        got = hf_tokenizer_ids(path, [c["text"] for c in cases])
        mismatches = [c["text"] for c, ids in zip(cases, got) if ids != c["ids"]]
        print(f"tokenizer {file_name}: {len(cases) - len(mismatches)}/{len(cases)} match; mismatches: {mismatches}")
        if required:
            assert not mismatches, "tokenizer.json disagrees with open_clip"


def blob_scene(width, height):
    """uint8 RGB: flat grey background, a red disc, a blue rectangle, a yellow square."""
    image = np.full((height, width, 3), 128, dtype=np.uint8)
    y, x = np.mgrid[0:height, 0:width]
    disc = (x - 0.3 * width) ** 2 + (y - 0.35 * height) ** 2 < (0.18 * min(width, height)) ** 2
    rectangle = (x > 0.55 * width) & (x < 0.9 * width) & (y > 0.5 * height) & (y < 0.8 * height)
    square = (x > 0.1 * width) & (x < 0.3 * width) & (y > 0.7 * height) & (y < 0.9 * height)
    image[disc] = (220, 30, 30)
    image[rectangle] = (30, 40, 210)
    image[square] = (235, 220, 30)
    return image, {"red": disc, "blue": rectangle, "yellow": square}


def sam_preprocess(image):
    """Longest side to 1024 (bilinear), normalise with SAM's mean/std in 0..255, pad bottom/right."""
    from PIL import Image

    height, width = image.shape[:2]
    scale = SAM_IMAGE_SIZE / max(height, width)
    new_w, new_h = int(width * scale + 0.5), int(height * scale + 0.5)
    resized = np.asarray(Image.fromarray(image).resize((new_w, new_h), Image.BILINEAR), dtype=np.float32)
    normalised = (resized - np.array(SAM_MEAN, np.float32)) / np.array(SAM_STD, np.float32)
    padded = np.zeros((SAM_IMAGE_SIZE, SAM_IMAGE_SIZE, 3), np.float32)
    padded[:new_h, :new_w] = normalised
    return padded.transpose(2, 0, 1)[None], scale


def reference_postprocess(low_res, orig_hw):
    """segment_anything's SamOnnxModel.mask_postprocessing, in torch, for comparison."""
    import torch
    import torch.nn.functional as F

    masks = F.interpolate(torch.from_numpy(low_res), size=(SAM_IMAGE_SIZE, SAM_IMAGE_SIZE), mode="bilinear", align_corners=False)
    size = torch.tensor(orig_hw, dtype=torch.float32)
    prepadded = torch.floor(SAM_IMAGE_SIZE / size.max() * size + 0.5).to(torch.int64)
    masks = masks[..., : prepadded[0], : prepadded[1]]
    return F.interpolate(masks, size=tuple(int(v) for v in orig_hw), mode="bilinear", align_corners=False).numpy()


def check_sam():
    import onnxruntime as ort

    encoder = ort.InferenceSession(os.path.join(TINY_DIR, "tiny-sam-encoder.onnx"))
    decoder = ort.InferenceSession(os.path.join(TINY_DIR, "tiny-sam-decoder.onnx"))
    for width, height in [(160, 120), (120, 200)]:
        image, blobs = blob_scene(width, height)
        pixels, scale = sam_preprocess(image)
        (embeddings,) = encoder.run(None, {"image": pixels})
        centres = np.array([[np.argwhere(mask)[:, ::-1].mean(axis=0)] for mask in blobs.values()], np.float32)
        points = np.concatenate([centres * scale, np.zeros_like(centres)], axis=1)  # + padding point
        labels = np.tile(np.array([[1.0, -1.0]], np.float32), (len(blobs), 1))
        feeds = {
            "image_embeddings": embeddings,
            "point_coords": points,
            "point_labels": labels,
            "mask_input": np.zeros((len(blobs), 1, SAM_LOW_RES, SAM_LOW_RES), np.float32),
            "has_mask_input": np.zeros(len(blobs), np.float32),
            "orig_im_size": np.array([height, width], np.float32),
        }
        masks, iou, low_res = decoder.run(None, feeds)
        assert masks.shape == (len(blobs), 4, height, width), masks.shape
        postprocess_error = np.abs(masks - reference_postprocess(low_res, (height, width))).max()
        assert postprocess_error < 1e-3, postprocess_error
        for index, (name, truth) in enumerate(blobs.items()):
            for channel in range(4):
                predicted = masks[index, channel] > 0
                overlap = (predicted & truth).sum() / (predicted | truth).sum()
                print(f"  {width}x{height} {name} channel {channel}: IoU with blob {overlap:.3f}, "
                      f"area {predicted.sum()}/{truth.sum()}, iou_pred {iou[index, channel]:.3f}")
            assert ((masks[index, 0] > 0) & truth).sum() / ((masks[index, 0] > 0) | truth).sum() > 0.9
        print(f"sam {width}x{height}: postprocess max abs diff vs torch {postprocess_error:.2e}")


def check_clip():
    import onnxruntime as ort
    import open_clip
    from PIL import Image

    _, _, preprocess = open_clip.create_model_and_transforms("ViT-B-32", pretrained=None)
    tokenizer = open_clip.get_tokenizer("ViT-B-32")
    image_model = ort.InferenceSession(os.path.join(TINY_DIR, "tiny-clip-image.onnx"))
    text_model = ort.InferenceSession(os.path.join(TINY_DIR, "tiny-clip-text.onnx"))
    image, blobs = blob_scene(160, 120)
    crops = [Image.fromarray(image * mask[..., None].astype(np.uint8)) for mask in blobs.values()]
    pixel_values = np.stack([preprocess(crop).numpy() for crop in crops])
    (image_embeds,) = image_model.run(None, {"pixel_values": pixel_values})
    texts = ["red", "blue", "yellow", "a red mug", "a photo of a blue box", "a chair", ""]
    (text_embeds,) = text_model.run(None, {"input_ids": tokenizer(texts).numpy()})
    similarity = image_embeds @ text_embeds.T
    for row, name in enumerate(blobs):
        print(f"  {name} crop: " + ", ".join(f"{t!r} {s:.3f}" for t, s in zip(texts, similarity[row])))
    names = list(blobs)
    for row, name in enumerate(names):
        column = texts.index(name)
        assert similarity[row, column] > 0.9 and all(similarity[r, column] < 0.3 for r in range(len(names)) if r != row)
    print("clip: colour crops match their colour words")
