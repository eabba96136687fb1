#!/usr/bin/env python3
"""Export official CLIP / SAM-family checkpoints to a segsplat model directory (docs/models.md).

Writes ONNX files with exactly the signatures of docs/models.md, `tokenizer.json` (when a CLIP
model is exported) and `manifest.json` with sha256 sums. Every export is verified by default: the
ONNX file runs in onnxruntime and the eager torch module runs on the same inputs (a real-looking
image, `--image PATH` or a generated one), and the export fails when the error exceeds the
tolerance (see TOLERANCES below).

Usage (see scripts/README-models.md for installing the Python dependencies):

    python scripts/export_models.py --out models/ --models clip-vit-l-14-336,sam-vit-h \\
        --checkpoint clip-vit-l-14-336=ViT-L-14-336px.pt --checkpoint sam-vit-h=sam_vit_h_4b8939.pth
    python scripts/export_models.py --out /tmp/check --models mobilesam,sam2.1-tiny,clip-vit-b-32 \\
        --random-weights --reference-dir /tmp/check/reference

Models: clip-vit-b-32, clip-vit-b-16, clip-vit-l-14-336 (open_clip, OpenAI `-quickgelu` archs),
sam-vit-b, sam-vit-l, sam-vit-h (segment-anything), mobilesam (mobile_sam vit_t), sam2.1-tiny,
sam2.1-small, sam2.1-base-plus, sam2.1-large (sam2 1.1.0). A directory holds one model per role:
export at most one CLIP and one SAM-family model into one --out.

CLIP embeddings are exported WITHOUT L2 normalisation (the projected embedding as open_clip's
`encode_image/encode_text(normalize=False)` returns it); the manifest says so with
`"output_normalized": false` in `preprocess`. Normalise before taking cosines.

`--official-signature` exports the SAM-family decoders as users' own files come instead (the
encoders are the same): SAM 1 / MobileSAM through the package's own `SamOnnxModel(sam,
return_single_mask=False)` exported as segment-anything's scripts/export_onnx_model.py does
(batch 1, only the number of points dynamic), SAM 2.1 in the common form (prompt batch dynamic, one
mask_input [1,1,256,256] / has_mask_input [1] for the batch, plus `object_score_logits` [B,1]). No
manifest.json is written (`segsplat models init DIR` writes one); CLIP models are exported as usual.
The decoders are verified one prompt per run (and SAM 2.1 with 4 prompts in one batch) and the
reference files keep the normal mode's format (decoder outputs computed one prompt per run).

`--reference-dir DIR` saves, per model, what the Rust runtime needs to compare its own
preprocessing and ONNX outputs against PyTorch: the raw RGB image (PNG), the preprocessed input
tensors, the prompts and the torch outputs, all as .npy (little-endian, C order), plus an
index.json describing every file.
"""

import argparse
import json
import os
import sys
import time
from dataclasses import dataclass, field

import numpy as np

SCRIPT_DIR = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, SCRIPT_DIR)
from file_digest import sha256_of  # noqa: E402  (scripts/ is on the path from the line above)

IR_VERSION = 8
OPSET = 17
CONTEXT_LENGTH = 77
SAM_IMAGE_SIZE = 1024
SAM_LOW_RES = 256
SOT_TOKEN, EOT_TOKEN = 49406, 49407
SEED = 1234
VERIFY = True  # --no-verify clears it (and replaces verify() with a no-op)

# Max abs error allowed between onnxruntime and eager torch, relative to the largest magnitude of
# the torch output (max(|ref|, 1)): fp32 graphs with fused/reordered ops differ at ~1e-5 relative;
# 1e-3 catches every real export bug (wrong op, baked shape) while tolerating long ViT stacks.
# Mask logits use 2e-3: bilinear upsampling of large random-weight logits amplifies rounding.
TOLERANCES = {"default": 1e-3, "masks": 2e-3, "low_res_masks": 2e-3}

CLIP_MEAN = [0.48145466, 0.4578275, 0.40821073]
CLIP_STD = [0.26862954, 0.26130258, 0.27577711]
SAM_MEAN = [123.675, 116.28, 103.53]
SAM_STD = [58.395, 57.12, 57.375]
IMAGENET_MEAN = [0.485, 0.456, 0.406]
IMAGENET_STD = [0.229, 0.224, 0.225]


@dataclass
class ModelSpec:
    key: str  # CLI name
    family: str  # manifest family: clip, sam, mobile_sam, sam2
    architecture: str  # open_clip arch / registry key / sam2 config
    checkpoint_file: str  # official checkpoint file name (documentation and --checkpoint hint)
    image_size: int = SAM_IMAGE_SIZE
    extra: dict = field(default_factory=dict)


MODEL_SPECS = {
    spec.key: spec
    for spec in [
        ModelSpec("clip-vit-b-32", "clip", "ViT-B-32-quickgelu", "ViT-B-32.pt", 224),
        ModelSpec("clip-vit-b-16", "clip", "ViT-B-16-quickgelu", "ViT-B-16.pt", 224),
        ModelSpec("clip-vit-l-14-336", "clip", "ViT-L-14-336-quickgelu", "ViT-L-14-336px.pt", 336),
        ModelSpec("sam-vit-b", "sam", "vit_b", "sam_vit_b_01ec64.pth"),
        ModelSpec("sam-vit-l", "sam", "vit_l", "sam_vit_l_0b3195.pth"),
        ModelSpec("sam-vit-h", "sam", "vit_h", "sam_vit_h_4b8939.pth"),
        ModelSpec("mobilesam", "mobile_sam", "vit_t", "mobile_sam.pt"),
        ModelSpec("sam2.1-tiny", "sam2", "configs/sam2.1/sam2.1_hiera_t.yaml", "sam2.1_hiera_tiny.pt"),
        ModelSpec("sam2.1-small", "sam2", "configs/sam2.1/sam2.1_hiera_s.yaml", "sam2.1_hiera_small.pt"),
        ModelSpec("sam2.1-base-plus", "sam2", "configs/sam2.1/sam2.1_hiera_b+.yaml", "sam2.1_hiera_base_plus.pt"),
        ModelSpec("sam2.1-large", "sam2", "configs/sam2.1/sam2.1_hiera_l.yaml", "sam2.1_hiera_large.pt"),
    ]
}


def log(message):
    print(message, flush=True)


# ---------------------------------------------------------------------------------------------
# torch modules with the docs/models.md signatures
# ---------------------------------------------------------------------------------------------

import torch  # noqa: E402  (after the docstring/constants so --help stays readable on errors)
import torch.nn as nn  # noqa: E402
import torch.nn.functional as F  # noqa: E402


class ClipImageTower(nn.Module):
    """pixel_values [N,3,R,R] -> image_embeds [N,D] (projected, not normalised)."""

    def __init__(self, clip_model):
        super().__init__()
        self.clip = clip_model

    def forward(self, pixel_values):
        return self.clip.encode_image(pixel_values, normalize=False)


class ClipTextTower(nn.Module):
    """input_ids [N,77] -> text_embeds [N,D]; open_clip pools at argmax(ids) = end-of-text."""

    def __init__(self, clip_model):
        super().__init__()
        self.clip = clip_model

    def forward(self, input_ids):
        return self.clip.encode_text(input_ids, normalize=False)


class SamImageEncoder(nn.Module):
    """SAM 1 / MobileSAM: preprocessed image [1,3,1024,1024] -> image_embeddings [1,256,64,64]."""

    def __init__(self, sam):
        super().__init__()
        self.image_encoder = sam.image_encoder

    def forward(self, image):
        return self.image_encoder(image)


class Sam2ImageEncoder(nn.Module):
    """SAM 2.1: image [1,3,1024,1024] -> image_embeddings, high_res_feats_0, high_res_feats_1,
    computed exactly as SAM2ImagePredictor.set_image does (including no_mem_embed)."""

    FEATURE_SIZES = [(256, 256), (128, 128), (64, 64)]

    def __init__(self, sam2_model):
        super().__init__()
        self.model = sam2_model

    def forward(self, image):
        backbone_out = self.model.forward_image(image)
        _, vision_feats, _, _ = self.model._prepare_backbone_features(backbone_out)
        if self.model.directly_add_no_mem_embed:
            vision_feats[-1] = vision_feats[-1] + self.model.no_mem_embed
        feats = [
            feat.permute(1, 2, 0).reshape(1, -1, *size)
            for feat, size in zip(vision_feats, self.FEATURE_SIZES)
        ]
        return feats[2], feats[0], feats[1]


class DynamicMaskPostprocess(torch.autograd.Function):
    """SAM's mask postprocessing with the output size taken from the `orig_im_size` tensor.

    Tracing F.interpolate(size=(h, w)) and slicing with tensor bounds bakes the example image size
    into the graph (segment-anything 1.0's SamOnnxModel does exactly that), so the ONNX graph is
    written by hand in `symbolic`; `forward` is the eager reference (SamOnnxModel.mask_postprocessing
    for longest_side_pad, SAM2Transforms.postprocess_masks for stretch).
    """

    @staticmethod
    def forward(ctx, low_res, orig_im_size, pad_to_longest_side):
        height, width = int(orig_im_size[0]), int(orig_im_size[1])
        if not pad_to_longest_side:
            return F.interpolate(low_res, size=(height, width), mode="bilinear", align_corners=False)
        masks = F.interpolate(low_res, size=(SAM_IMAGE_SIZE, SAM_IMAGE_SIZE), mode="bilinear", align_corners=False)
        scale = SAM_IMAGE_SIZE / torch.max(orig_im_size.to(torch.float32))
        prepadded = torch.floor(scale * orig_im_size.to(torch.float32) + 0.5).to(torch.int64)
        masks = masks[..., : int(prepadded[0]), : int(prepadded[1])]
        return F.interpolate(masks, size=(height, width), mode="bilinear", align_corners=False)

    @staticmethod
    def symbolic(g, low_res, orig_im_size, pad_to_longest_side):
        def i64(values):
            return g.op("Constant", value_t=torch.tensor(values, dtype=torch.int64))

        def resize(x, height_width):
            batch_channels = g.op("Slice", g.op("Shape", x), i64([0]), i64([2]))
            sizes = g.op("Concat", batch_channels, height_width, axis_i=0)
            empty = g.op("Constant", value_t=torch.tensor([], dtype=torch.float32))
            return g.op("Resize", x, empty, empty, sizes, mode_s="linear",
                        coordinate_transformation_mode_s="pytorch_half_pixel")

        original = g.op("Cast", orig_im_size, to_i=7)  # 7 = INT64
        if not pad_to_longest_side:
            return resize(low_res, original)
        full = resize(low_res, i64([SAM_IMAGE_SIZE, SAM_IMAGE_SIZE]))
        size = g.op("Cast", orig_im_size, to_i=1)  # 1 = FLOAT
        scale = g.op("Div", g.op("Constant", value_t=torch.tensor(float(SAM_IMAGE_SIZE))),
                     g.op("ReduceMax", size, axes_i=[0], keepdims_i=1))
        prepadded = g.op("Floor", g.op("Add", g.op("Mul", size, scale), g.op("Constant", value_t=torch.tensor(0.5))))
        cropped = g.op("Slice", full, i64([0, 0]), g.op("Cast", prepadded, to_i=7), i64([2, 3]))
        return resize(cropped, original)


def embed_points(prompt_encoder, point_coords, point_labels):
    """Sparse prompt embeddings as SamOnnxModel._embed_points computes them (no automatic padding
    point: the caller appends (0,0) / -1). Works for SAM 1, MobileSAM and SAM 2 prompt encoders."""
    coords = (point_coords + 0.5) / SAM_IMAGE_SIZE
    embedding = prompt_encoder.pe_layer._pe_encoding(coords)
    labels = point_labels.unsqueeze(-1).expand_as(embedding)
    embedding = embedding * (labels != -1)
    embedding = embedding + prompt_encoder.not_a_point_embed.weight * (labels == -1)
    for index in range(prompt_encoder.num_point_embeddings):
        embedding = embedding + prompt_encoder.point_embeddings[index].weight * (labels == index)
    return embedding


def embed_masks(prompt_encoder, mask_input, has_mask_input):
    """Dense prompt embeddings: the downscaled mask where has_mask_input[b] = 1, else no_mask_embed."""
    has_mask = has_mask_input.reshape(-1, 1, 1, 1)
    no_mask = prompt_encoder.no_mask_embed.weight.reshape(1, -1, 1, 1)
    return has_mask * prompt_encoder.mask_downscaling(mask_input) + (1 - has_mask) * no_mask


class SamMaskDecoder(nn.Module):
    """SAM 1 / MobileSAM decoder with all four mask tokens (channel 0 = single-mask answer)."""

    def __init__(self, sam):
        super().__init__()
        self.prompt_encoder = sam.prompt_encoder
        self.mask_decoder = sam.mask_decoder

    def forward(self, image_embeddings, point_coords, point_labels, mask_input, has_mask_input, orig_im_size):
        sparse = embed_points(self.prompt_encoder, point_coords, point_labels)
        dense = embed_masks(self.prompt_encoder, mask_input, has_mask_input)
        low_res_masks, iou_predictions = self.mask_decoder.predict_masks(
            image_embeddings=image_embeddings,
            image_pe=self.prompt_encoder.get_dense_pe(),
            sparse_prompt_embeddings=sparse,
            dense_prompt_embeddings=dense,
        )
        masks = DynamicMaskPostprocess.apply(low_res_masks, orig_im_size, True)
        return masks, iou_predictions, low_res_masks


class Sam2MaskDecoder(nn.Module):
    """SAM 2.1 decoder with all four mask tokens; masks resized straight to orig_im_size."""

    def __init__(self, sam2_model):
        super().__init__()
        self.prompt_encoder = sam2_model.sam_prompt_encoder
        self.mask_decoder = sam2_model.sam_mask_decoder

    def forward(self, image_embeddings, high_res_feats_0, high_res_feats_1, point_coords, point_labels,
                mask_input, has_mask_input, orig_im_size):
        sparse = embed_points(self.prompt_encoder, point_coords, point_labels)
        dense = embed_masks(self.prompt_encoder, mask_input, has_mask_input)
        low_res_masks, iou_predictions, _, _ = self.mask_decoder.predict_masks(
            image_embeddings=image_embeddings,
            image_pe=self.prompt_encoder.get_dense_pe(),
            sparse_prompt_embeddings=sparse,
            dense_prompt_embeddings=dense,
            repeat_image=True,
            high_res_features=[high_res_feats_0, high_res_feats_1],
        )
        masks = DynamicMaskPostprocess.apply(low_res_masks, orig_im_size, False)
        return masks, iou_predictions, low_res_masks


# ---------------------------------------------------------------------------------------------
# Signatures (manifest inputs/outputs; -1 = dynamic)
# ---------------------------------------------------------------------------------------------


def io(name, shape, dtype="float32"):
    return {"name": name, "dtype": dtype, "shape": shape}


def clip_signatures(image_size, embed_dim):
    image = ([io("pixel_values", [-1, 3, image_size, image_size])], [io("image_embeds", [-1, embed_dim])])
    text = ([io("input_ids", [-1, CONTEXT_LENGTH], "int64")], [io("text_embeds", [-1, embed_dim])])
    return image, text


SAM_EMBEDDINGS = io("image_embeddings", [1, 256, 64, 64])
SAM2_HIGH_RES = [io("high_res_feats_0", [1, 32, 256, 256]), io("high_res_feats_1", [1, 64, 128, 128])]
PROMPT_INPUTS = [
    io("point_coords", [-1, -1, 2]),
    io("point_labels", [-1, -1]),
    io("mask_input", [-1, 1, SAM_LOW_RES, SAM_LOW_RES]),
    io("has_mask_input", [-1]),
    io("orig_im_size", [2]),
]
DECODER_OUTPUTS = [io("masks", [-1, 4, -1, -1]), io("iou_predictions", [-1, 4]), io("low_res_masks", [-1, 4, SAM_LOW_RES, SAM_LOW_RES])]


def sam_signatures(family):
    high_res = SAM2_HIGH_RES if family == "sam2" else []
    encoder = ([io("image", [1, 3, SAM_IMAGE_SIZE, SAM_IMAGE_SIZE])], [SAM_EMBEDDINGS] + high_res)
    decoder = ([SAM_EMBEDDINGS] + high_res + PROMPT_INPUTS, DECODER_OUTPUTS)
    return encoder, decoder


def dynamic_axes_of(inputs, outputs):
    """torch.onnx dynamic_axes with readable names for every -1 dimension."""
    readable = {("pixel_values", 0): "batch", ("image_embeds", 0): "batch", ("input_ids", 0): "batch",
                ("text_embeds", 0): "batch", ("masks", 2): "height", ("masks", 3): "width"}
    axes = {}
    for entry in inputs + outputs:
        for index, dim in enumerate(entry["shape"]):
            if dim == -1:
                default = "prompts" if index == 0 else "points"
                axes.setdefault(entry["name"], {})[index] = readable.get((entry["name"], index), default)
    return axes


# ---------------------------------------------------------------------------------------------
# Loading models (official checkpoint or seeded random weights)
# ---------------------------------------------------------------------------------------------


def load_clip(spec, checkpoint):
    import open_clip

    torch.backends.mha.set_fastpath_enabled(False)  # the fused attention fast path does not export
    model, _, preprocess = open_clip.create_model_and_transforms(spec.architecture, pretrained=checkpoint)
    return model.eval(), preprocess, open_clip.get_tokenizer(spec.architecture)


def load_sam(spec, checkpoint):
    if spec.family == "mobile_sam":
        from mobile_sam import sam_model_registry
    else:
        from segment_anything import sam_model_registry
    return sam_model_registry[spec.architecture](checkpoint=checkpoint).eval()


def load_sam2(spec, checkpoint):
    from sam2.build_sam import build_sam2

    return build_sam2(spec.architecture, ckpt_path=checkpoint, device="cpu", mode="eval")


# ---------------------------------------------------------------------------------------------
# Inputs: image, preprocessing (the official code paths) and prompts
# ---------------------------------------------------------------------------------------------


def load_or_generate_image(path):
    """uint8 RGB [H,W,3]: --image, or a generated real-looking 320x240 scene."""
    from PIL import Image

    if path:
        return np.asarray(Image.open(path).convert("RGB"))
    from tiny_models.fixtures import synthetic_image

    return synthetic_image(320, 240)


def sam_preprocess(family, model, image):
    """(input tensor [1,3,1024,1024], function mapping original xy -> 1024-frame xy)."""
    height, width = image.shape[:2]
    if family == "sam2":
        from sam2.utils.transforms import SAM2Transforms

        tensor = SAM2Transforms(resolution=SAM_IMAGE_SIZE, mask_threshold=0.0)(image)[None]
        scale = np.array([SAM_IMAGE_SIZE / width, SAM_IMAGE_SIZE / height], np.float32)
        return tensor, lambda xy: xy * scale
    if family == "mobile_sam":
        from mobile_sam.utils.transforms import ResizeLongestSide
    else:
        from segment_anything.utils.transforms import ResizeLongestSide
    transform = ResizeLongestSide(SAM_IMAGE_SIZE)
    resized = torch.as_tensor(transform.apply_image(image)).permute(2, 0, 1).contiguous()[None]
    tensor = model.preprocess(resized.float())
    return tensor, lambda xy: transform.apply_coords(xy, (height, width)).astype(np.float32)


def sam_prompts(image_shape, to_model_frame):
    """Three prompts, each one positive point + the padding point; the last also has a mask input."""
    height, width = image_shape[:2]
    original = np.array([[0.3 * width, 0.35 * height], [0.72 * width, 0.65 * height], [0.5 * width, 0.5 * height]], np.float32)
    coords = np.zeros((3, 2, 2), np.float32)
    coords[:, 0] = to_model_frame(original)
    labels = np.array([[1.0, -1.0]] * 3, np.float32)
    rng = np.random.default_rng(SEED)
    mask_input = np.zeros((3, 1, SAM_LOW_RES, SAM_LOW_RES), np.float32)
    mask_input[2, 0] = 4.0 * rng.standard_normal((SAM_LOW_RES // 16, SAM_LOW_RES // 16)).repeat(16, 0).repeat(16, 1)
    has_mask = np.array([0.0, 0.0, 1.0], np.float32)
    return {
        "point_coords_original": original,
        "point_coords": coords,
        "point_labels": labels,
        "mask_input": mask_input,
        "has_mask_input": has_mask,
        "orig_im_size": np.array([height, width], np.float32),
    }


CLIP_TEXTS = ["a red mug", "a photo of a wooden chair", "the sky", ""]


# ---------------------------------------------------------------------------------------------
# Export, verification, reference files
# ---------------------------------------------------------------------------------------------


def export_onnx(module, example_inputs, path, inputs, outputs):
    """torch.onnx (TorchScript exporter, opset 17), then pin IR version 8 for onnxruntime."""
    import onnx

    started = time.perf_counter()
    # Wrappers are created in training mode, and the exporter restores the mode it found, which
    # would leave BatchNorm/dropout in training mode for the eager comparison: force eval.
    module.eval()
    with torch.no_grad():
        torch.onnx.export(
            module, tuple(example_inputs), path,
            input_names=[entry["name"] for entry in inputs],
            output_names=[entry["name"] for entry in outputs],
            dynamic_axes=dynamic_axes_of(inputs, outputs),
            opset_version=OPSET, do_constant_folding=True, dynamo=False,
        )
    module.eval()
    model = onnx.load(path, load_external_data=False)  # large models keep their external data file
    model.ir_version = IR_VERSION
    onnx.save(model, path)
    check_graph_signature(model, inputs, outputs)
    seconds = time.perf_counter() - started
    log(f"  exported {os.path.basename(path)} in {seconds:.1f} s ({os.path.getsize(path) / 1e6:.1f} MB)")
    return seconds


def check_graph_signature(model, inputs, outputs):
    """The exported graph's input/output names and ranks must be exactly the declared ones."""
    def described(values):
        return [(v.name, len(v.type.tensor_type.shape.dim)) for v in values]

    want_inputs = [(e["name"], len(e["shape"])) for e in inputs]
    want_outputs = [(e["name"], len(e["shape"])) for e in outputs]
    got_inputs, got_outputs = described(model.graph.input), described(model.graph.output)
    if sorted(got_inputs) != sorted(want_inputs) or got_outputs != want_outputs:
        raise RuntimeError(f"exported signature {got_inputs} -> {got_outputs}, expected {want_inputs} -> {want_outputs}")


class VerificationError(RuntimeError):
    pass


def verify(path, feeds, torch_outputs, label=""):
    """Run the ONNX file with onnxruntime on `feeds`; compare with the eager torch outputs."""
    import onnxruntime as ort

    session = ort.InferenceSession(path, providers=["CPUExecutionProvider"])
    started = time.perf_counter()
    results = session.run(None, feeds)
    seconds = time.perf_counter() - started
    names = [output.name for output in session.get_outputs()]
    report = {}
    for name, got in zip(names, results):
        reference = torch_outputs[name]
        if got.shape != reference.shape:
            raise VerificationError(f"{path} {name}: shape {got.shape} != torch {reference.shape}")
        error = float(np.abs(got - reference).max()) if got.size else 0.0
        relative = error / max(1.0, float(np.abs(reference).max()) if reference.size else 1.0)
        tolerance = TOLERANCES.get(name, TOLERANCES["default"])
        report[name] = relative
        status = "ok" if relative <= tolerance else "FAIL"
        log(f"  verify {os.path.basename(path)}{label} {name}{list(got.shape)}: max abs err {error:.2e}, "
            f"relative {relative:.2e} (tolerance {tolerance:.0e}) {status}")
        if relative > tolerance:
            raise VerificationError(f"{path} {name}: relative error {relative:.2e} > {tolerance:.0e}")
    log(f"  onnxruntime {os.path.basename(path)}{label}: {seconds * 1000:.0f} ms")
    return seconds


def eager(module, named_inputs, output_names):
    """Run the torch module; returns ({name: np.ndarray}, seconds)."""
    started = time.perf_counter()
    with torch.no_grad():
        outputs = module(*[torch.from_numpy(np.ascontiguousarray(v)) for v in named_inputs.values()])
    seconds = time.perf_counter() - started
    if not isinstance(outputs, (tuple, list)):
        outputs = (outputs,)
    return {name: out.numpy() for name, out in zip(output_names, outputs)}, seconds


class ReferenceWriter:
    """Writes reference files for one model under DIR/<model key>/ plus an index.json."""

    def __init__(self, root, key):
        self.dir = os.path.join(root, key) if root else None
        self.index = {}
        if self.dir:
            os.makedirs(self.dir, exist_ok=True)

    def array(self, name, value, description):
        if not self.dir:
            return
        value = np.ascontiguousarray(value)
        value = value.astype(value.dtype.newbyteorder("<"))
        np.save(os.path.join(self.dir, name + ".npy"), value)
        self.index[name + ".npy"] = {"dtype": str(value.dtype), "shape": list(value.shape), "description": description}

    def image(self, image):
        if not self.dir:
            return
        from PIL import Image

        Image.fromarray(image).save(os.path.join(self.dir, "image.png"))
        self.index["image.png"] = {"shape": list(image.shape), "description": "raw RGB input image (uint8, H x W x 3)"}

    def finish(self, notes):
        if not self.dir:
            return
        with open(os.path.join(self.dir, "index.json"), "w") as f:
            json.dump({"notes": notes, "files": self.index}, f, indent=2)
            f.write("\n")


def compare_with_official_predictor(spec, model, image, prompts, decoder_outputs):
    """The wrappers must agree with the official predictor API (SamPredictor / SAM2ImagePredictor,
    which append the padding point themselves) on the prompts without a mask input: channels 1-3
    vs multimask_output=True, and for SAM 1 / MobileSAM channel 0 vs multimask_output=False.
    (SAM2ImagePredictor's single-mask answer falls back to the most stable multimask when token 0
    is unstable; the exported channel 0 is the raw token, so it is not compared for SAM 2.)"""
    if spec.family == "sam2":
        from sam2.sam2_image_predictor import SAM2ImagePredictor as Predictor
    elif spec.family == "mobile_sam":
        from mobile_sam import SamPredictor as Predictor
    else:
        from segment_anything import SamPredictor as Predictor
    predictor = Predictor(model)
    predictor.set_image(image)
    worst = 0.0
    for prompt in range(2):  # prompt 2 carries a mask input, which the predictor API takes differently
        kwargs = {"point_coords": prompts["point_coords_original"][prompt:prompt + 1],
                  "point_labels": np.array([1]), "return_logits": True}
        masks, scores, _ = predictor.predict(multimask_output=True, **kwargs)
        worst = max(worst, np.abs(masks - decoder_outputs["masks"][prompt, 1:]).max(),
                    np.abs(scores - decoder_outputs["iou_predictions"][prompt, 1:]).max())
        if spec.family != "sam2":
            single, _, _ = predictor.predict(multimask_output=False, **kwargs)
            worst = max(worst, np.abs(single[0] - decoder_outputs["masks"][prompt, 0]).max())
    scale = max(1.0, float(np.abs(decoder_outputs["masks"]).max()))
    log(f"  official predictor vs exported decoder module: max abs err {worst:.2e}")
    if worst / scale > TOLERANCES["masks"]:
        raise VerificationError(f"{spec.key}: decoder wrapper disagrees with the official predictor ({worst:.2e})")


# ---------------------------------------------------------------------------------------------
# Per-family exports; each returns manifest entries and a timing summary
# ---------------------------------------------------------------------------------------------


def manifest_entry(name, role, spec, out_dir, inputs, outputs, preprocess):
    file_name = name + ".onnx"
    return {
        "name": name,
        "role": role,
        "family": spec.family,
        "architecture": spec.architecture,
        "file": file_name,
        "sha256": sha256_of(os.path.join(out_dir, file_name)),
        "inputs": inputs,
        "outputs": outputs,
        "preprocess": preprocess,
    }


def export_clip(spec, checkpoint, image, out_dir, reference_root):
    from PIL import Image

    model, preprocess, tokenizer = load_clip(spec, checkpoint)
    embed_dim = int(model.text_projection.shape[1])
    (image_in, image_out), (text_in, text_out) = clip_signatures(spec.image_size, embed_dim)
    pixel_values = preprocess(Image.fromarray(image))[None].numpy()
    input_ids = tokenizer(CLIP_TEXTS).numpy()
    timings = {}
    reference = ReferenceWriter(reference_root, spec.key)
    reference.image(image)

    towers = [("image", ClipImageTower(model), {"pixel_values": pixel_values}, image_in, image_out),
              ("text", ClipTextTower(model), {"input_ids": input_ids}, text_in, text_out)]
    entries = []
    for part, tower, feeds, inputs, outputs in towers:
        name = f"{spec.key}-{part}"
        path = os.path.join(out_dir, name + ".onnx")
        timings[f"{part} export"] = export_onnx(tower, [torch.from_numpy(v) for v in feeds.values()], path, inputs, outputs)
        torch_out, timings[f"{part} torch"] = eager(tower, feeds, [o["name"] for o in outputs])
        timings[f"{part} onnxruntime"] = verify(path, feeds, torch_out)
        for key, value in {**feeds, **torch_out}.items():
            reference.array(key, value, f"{'input' if key in feeds else 'torch output'} of {name}.onnx")
        if part == "image":
            preprocess_keys = {"image_size": spec.image_size, "resize": "shortest_side_center_crop",
                               "interpolation": "bicubic", "pixel_scale": 1.0, "mean": CLIP_MEAN, "std": CLIP_STD}
        else:
            preprocess_keys = {"context_length": CONTEXT_LENGTH}
        preprocess_keys["output_normalized"] = False
        entries.append(manifest_entry(name, f"clip_{part}", spec, out_dir, inputs, outputs, preprocess_keys))
    reference.finish({"texts": CLIP_TEXTS, "embeddings": "projected, NOT L2-normalised",
                      "pixel_values": "open_clip preprocess_val of image.png"})
    return entries, timings


def export_sam_family(spec, checkpoint, image, out_dir, reference_root):
    sam2 = spec.family == "sam2"
    model = load_sam2(spec, checkpoint) if sam2 else load_sam(spec, checkpoint)
    (encoder_in, encoder_out), (decoder_in, decoder_out) = sam_signatures(spec.family)
    encoder = Sam2ImageEncoder(model) if sam2 else SamImageEncoder(model)
    decoder = Sam2MaskDecoder(model) if sam2 else SamMaskDecoder(model)
    timings = {}
    reference = ReferenceWriter(reference_root, spec.key)
    reference.image(image)

    with torch.no_grad():
        pixels, to_model_frame = sam_preprocess(spec.family, model, image)
    encoder_feeds = {"image": pixels.numpy().astype(np.float32)}
    encoder_name = f"{spec.key}-encoder"
    encoder_path = os.path.join(out_dir, encoder_name + ".onnx")
    timings["encoder export"] = export_onnx(encoder, [pixels], encoder_path, encoder_in, encoder_out)
    embeddings, timings["encoder torch"] = eager(encoder, encoder_feeds, [o["name"] for o in encoder_out])
    timings["encoder onnxruntime"] = verify(encoder_path, encoder_feeds, embeddings)

    prompts = sam_prompts(image.shape, to_model_frame)
    decoder_feeds = {entry["name"]: (embeddings | prompts)[entry["name"]] for entry in decoder_in}
    decoder_name = f"{spec.key}-decoder"
    decoder_path = os.path.join(out_dir, decoder_name + ".onnx")
    example = [torch.from_numpy(v) for v in decoder_feeds.values()]
    timings["decoder export"] = export_onnx(decoder, example, decoder_path, decoder_in, decoder_out)
    decoder_outputs, timings["decoder torch"] = eager(decoder, decoder_feeds, [o["name"] for o in decoder_out])
    timings["decoder onnxruntime"] = verify(decoder_path, decoder_feeds, decoder_outputs)
    compare_with_official_predictor(spec, model, image, prompts, decoder_outputs)
    # A second image size proves the output size is not baked into the graph.
    other_size = {**decoder_feeds, "orig_im_size": np.array([image.shape[1] // 2 + 7, image.shape[0] + 13], np.float32)}
    other_outputs, _ = eager(decoder, other_size, [o["name"] for o in decoder_out])
    verify(decoder_path, other_size, other_outputs, label=f" (orig_im_size {other_size['orig_im_size'].astype(int).tolist()})")

    for key, value in {**encoder_feeds, **embeddings, **prompts, **decoder_outputs}.items():
        role = "input" if key in encoder_feeds or key in prompts else "torch output"
        reference.array(key, value, f"{role} ({'encoder' if key in encoder_feeds or key in embeddings else 'decoder'})")
    reference.finish({
        "preprocess": "official code: ResizeLongestSide + Sam.preprocess" if not sam2 else "official SAM2Transforms",
        "point_coords": "1024-frame coordinates fed to the decoder; point_coords_original are in image.png pixels",
        "prompts": "3 prompts: one positive point + padding point (0,0)/-1 each; prompt 2 has has_mask_input=1",
    })

    encoder_preprocess = {"image_size": SAM_IMAGE_SIZE, "interpolation": "bilinear"}
    if sam2:
        encoder_preprocess.update(resize="stretch", pixel_scale=1.0, mean=IMAGENET_MEAN, std=IMAGENET_STD)
    else:
        encoder_preprocess.update(resize="longest_side_pad", pixel_scale=255.0, mean=SAM_MEAN, std=SAM_STD)
    decoder_preprocess = {"encoder": encoder_name, "multimask_channels": [1, 2, 3], "mask_threshold": 0.0}
    return [
        manifest_entry(encoder_name, "sam_encoder", spec, out_dir, encoder_in, encoder_out, encoder_preprocess),
        manifest_entry(decoder_name, "sam_decoder", spec, out_dir, decoder_in, decoder_out, decoder_preprocess),
    ], timings


# ---------------------------------------------------------------------------------------------
# --official-signature: the graphs users bring (segment-anything's own decoder export, the common
# SAM 2 export form), written without a manifest
# ---------------------------------------------------------------------------------------------

# segment-anything / MobileSAM scripts/export_onnx_model.py: batch fixed at 1, only the number of
# points dynamic; the exporter names the output dimensions itself (all four symbolic).
OFFICIAL_SAM1_DYNAMIC_AXES = {"point_coords": {1: "num_points"}, "point_labels": {1: "num_points"}}
OFFICIAL_SAM1_DECODER = (
    [io("image_embeddings", [1, 256, 64, 64]), io("point_coords", [1, -1, 2]), io("point_labels", [1, -1]),
     io("mask_input", [1, 1, SAM_LOW_RES, SAM_LOW_RES]), io("has_mask_input", [1]), io("orig_im_size", [2])],
    [io("masks", [1, 4, -1, -1]), io("iou_predictions", [1, 4]), io("low_res_masks", [1, 4, SAM_LOW_RES, SAM_LOW_RES])],
)
# The common SAM 2 form: prompt batch and points dynamic, one mask input shared by the batch, and
# the mask decoder's object score as a fourth output.
OFFICIAL_SAM2_DYNAMIC_AXES = {
    "point_coords": {0: "num_labels", 1: "num_points"},
    "point_labels": {0: "num_labels", 1: "num_points"},
    "masks": {0: "num_labels", 2: "height", 3: "width"},
    "iou_predictions": {0: "num_labels"},
    "low_res_masks": {0: "num_labels"},
    "object_score_logits": {0: "num_labels"},
}
OFFICIAL_SAM2_DECODER = (
    [SAM_EMBEDDINGS] + SAM2_HIGH_RES
    + [io("point_coords", [-1, -1, 2]), io("point_labels", [-1, -1]), io("mask_input", [1, 1, SAM_LOW_RES, SAM_LOW_RES]),
       io("has_mask_input", [1]), io("orig_im_size", [2])],
    DECODER_OUTPUTS + [io("object_score_logits", [-1, 1])],
)
# segment-anything's export dummy orig_im_size (scripts/export_onnx_model.py).
OFFICIAL_DUMMY_ORIG_IM_SIZE = [1500, 2250]


class Sam2OfficialDecoder(nn.Module):
    """SAM 2.1 decoder in the common export form: mask_input [1,1,256,256] / has_mask_input [1]
    shared by the prompt batch, all four mask tokens, plus object_score_logits [B,1]."""

    def __init__(self, sam2_model):
        super().__init__()
        self.prompt_encoder = sam2_model.sam_prompt_encoder
        self.mask_decoder = sam2_model.sam_mask_decoder

    def forward(self, image_embeddings, high_res_feats_0, high_res_feats_1, point_coords, point_labels,
                mask_input, has_mask_input, orig_im_size):
        sparse = embed_points(self.prompt_encoder, point_coords, point_labels)
        dense = embed_masks(self.prompt_encoder, mask_input, has_mask_input)  # [1,256,64,64], broadcast
        low_res_masks, iou_predictions, _, object_score_logits = self.mask_decoder.predict_masks(
            image_embeddings=image_embeddings,
            image_pe=self.prompt_encoder.get_dense_pe(),
            sparse_prompt_embeddings=sparse,
            dense_prompt_embeddings=dense,
            repeat_image=True,
            high_res_features=[high_res_feats_0, high_res_feats_1],
        )
        masks = DynamicMaskPostprocess.apply(low_res_masks, orig_im_size, False)
        return masks, iou_predictions, low_res_masks, object_score_logits


def official_decoder(spec, model):
    """(module, export dummy inputs, (inputs, outputs) declared, dynamic_axes)."""
    if spec.family == "sam2":
        module = Sam2OfficialDecoder(model)
        declared, axes, batch = OFFICIAL_SAM2_DECODER, OFFICIAL_SAM2_DYNAMIC_AXES, 2
    else:
        if spec.family == "mobile_sam":
            from mobile_sam.utils.onnx import SamOnnxModel
        else:
            from segment_anything.utils.onnx import SamOnnxModel
        module = SamOnnxModel(model, return_single_mask=False)
        declared, axes, batch = OFFICIAL_SAM1_DECODER, OFFICIAL_SAM1_DYNAMIC_AXES, 1
    # segment-anything's dummy inputs (batch 2 for the SAM 2 form so the prompt batch cannot be
    # confused with the image batch while tracing).
    dummy = {"image_embeddings": torch.randn(1, 256, 64, 64)}
    if spec.family == "sam2":
        dummy["high_res_feats_0"] = torch.randn(1, 32, 256, 256)
        dummy["high_res_feats_1"] = torch.randn(1, 64, 128, 128)
    dummy.update({
        "point_coords": torch.randint(low=0, high=1024, size=(batch, 5, 2), dtype=torch.float),
        "point_labels": torch.randint(low=0, high=4, size=(batch, 5), dtype=torch.float),
        "mask_input": torch.randn(1, 1, SAM_LOW_RES, SAM_LOW_RES, dtype=torch.float),
        "has_mask_input": torch.tensor([1], dtype=torch.float),
        "orig_im_size": torch.tensor(OFFICIAL_DUMMY_ORIG_IM_SIZE, dtype=torch.float),
    })
    return module.eval(), dummy, declared, axes


def export_official_onnx(module, dummy, path, output_names, dynamic_axes):
    """torch.onnx.export exactly as segment-anything's scripts/export_onnx_model.py calls it (plus
    dynamo=False: the TorchScript exporter that script was written for, the default before torch
    2.9). The file is left as torch wrote it (no IR-version rewrite)."""
    import warnings

    started = time.perf_counter()
    with torch.no_grad():
        _ = module(**dummy)  # the official script runs the model once before exporting
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=torch.jit.TracerWarning)
        warnings.filterwarnings("ignore", category=UserWarning)
        warnings.filterwarnings("ignore", category=DeprecationWarning)
        torch.onnx.export(
            module, tuple(dummy.values()), path,
            export_params=True, verbose=False, opset_version=OPSET, do_constant_folding=True,
            input_names=list(dummy.keys()), output_names=output_names, dynamic_axes=dynamic_axes,
            dynamo=False,
        )
    module.eval()
    seconds = time.perf_counter() - started
    log(f"  exported {os.path.basename(path)} in {seconds:.1f} s ({os.path.getsize(path) / 1e6:.1f} MB)")
    return seconds


def graph_signature(path):
    """[(kind, name, dtype, [dims])] of the ONNX graph; a dim is an int or its symbolic name."""
    import onnx

    model = onnx.load(path, load_external_data=False)
    rows = []
    for kind, values in (("input", model.graph.input), ("output", model.graph.output)):
        for value in values:
            tensor = value.type.tensor_type
            dtype = np.dtype(onnx.helper.tensor_dtype_to_np_dtype(tensor.elem_type)).name
            dims = [d.dim_value if d.HasField("dim_value") else (d.dim_param or "?") for d in tensor.shape.dim]
            rows.append((kind, value.name, dtype, dims))
    return model, rows


def log_graph_signature(path):
    model, rows = graph_signature(path)
    log(f"  signature of {os.path.basename(path)} (IR {model.ir_version}, opset "
        f"{max(o.version for o in model.opset_import if o.domain in ('', 'ai.onnx'))}):")
    for kind, name, dtype, dims in rows:
        log(f"    {kind:6} {name} {dtype}[{', '.join(str(d) for d in dims)}]")
    return model


def run_onnx(path, feeds):
    import onnxruntime as ort

    session = ort.InferenceSession(path, providers=["CPUExecutionProvider"])
    return dict(zip([o.name for o in session.get_outputs()], session.run(None, feeds)))


def baked_crop_postprocess(low_res_masks, orig_im_size, crop):
    """segment-anything 1.0 SamOnnxModel.mask_postprocessing as its traced graph computes it: the
    crop to the unpadded region is the export dummy's (int() of a tensor becomes a constant), the
    final resize follows orig_im_size."""
    masks = F.interpolate(torch.from_numpy(low_res_masks), size=(SAM_IMAGE_SIZE, SAM_IMAGE_SIZE),
                          mode="bilinear", align_corners=False)
    masks = masks[..., : crop[0], : crop[1]]
    height, width = int(orig_im_size[0]), int(orig_im_size[1])
    return F.interpolate(masks, size=(height, width), mode="bilinear", align_corners=False).numpy()


def relative_error(got, reference):
    return float(np.abs(got - reference).max()) / max(1.0, float(np.abs(reference).max()))


def probe_mask_crop(path, module, feeds, output_names):
    """How the official SAM 1 / MobileSAM graph crops the padded region: None when the crop
    follows orig_im_size, else the (rows, cols) baked in at export. Probed at a portrait size whose
    unpadded region differs from the export dummy's."""
    probe = {**feeds, "orig_im_size": np.array([600, 400], np.float32)}
    expected, _ = eager(module, probe, output_names)
    got = run_onnx(path, probe)["masks"]
    if got.shape == expected["masks"].shape and relative_error(got, expected["masks"]) <= TOLERANCES["masks"]:
        log("  official decoder mask postprocessing: the crop to the unpadded region follows orig_im_size")
        return None
    crop = type(module).resize_longest_image_size(torch.tensor(OFFICIAL_DUMMY_ORIG_IM_SIZE), SAM_IMAGE_SIZE).tolist()
    emulated = baked_crop_postprocess(expected["low_res_masks"], probe["orig_im_size"], crop)
    if got.shape == emulated.shape and relative_error(got, emulated) <= TOLERANCES["masks"]:
        log(f"  official decoder mask postprocessing: crop BAKED at {crop[0]} x {crop[1]} (export dummy orig_im_size "
            f"{OFFICIAL_DUMMY_ORIG_IM_SIZE[0]} x {OFFICIAL_DUMMY_ORIG_IM_SIZE[1]}); output size follows orig_im_size")
        return crop
    raise VerificationError(f"{path}: masks match neither the dynamic nor the baked-crop postprocessing")


def official_prompt_feeds(decoder_in, embeddings, prompts, index, orig_im_size=None):
    """Batch-1 decoder feeds for prompt `index` of sam_prompts (its own mask input / flag)."""
    values = {
        **embeddings,
        "point_coords": prompts["point_coords"][index:index + 1],
        "point_labels": prompts["point_labels"][index:index + 1],
        "mask_input": prompts["mask_input"][index:index + 1],
        "has_mask_input": prompts["has_mask_input"][index:index + 1],
        "orig_im_size": prompts["orig_im_size"] if orig_im_size is None else orig_im_size,
    }
    return {entry["name"]: np.ascontiguousarray(values[entry["name"]]) for entry in decoder_in}


def export_sam_family_official(spec, checkpoint, image, out_dir, reference_root):
    """Encoder as in the normal mode; decoder as the official / common exporters write it."""
    sam2 = spec.family == "sam2"
    model = load_sam2(spec, checkpoint) if sam2 else load_sam(spec, checkpoint)
    (encoder_in, encoder_out), _ = sam_signatures(spec.family)
    encoder = Sam2ImageEncoder(model) if sam2 else SamImageEncoder(model)
    timings = {}
    reference = ReferenceWriter(reference_root, spec.key)
    reference.image(image)

    with torch.no_grad():
        pixels, to_model_frame = sam_preprocess(spec.family, model, image)
    encoder_feeds = {"image": pixels.numpy().astype(np.float32)}
    encoder_name = f"{spec.key}-encoder"
    encoder_path = os.path.join(out_dir, encoder_name + ".onnx")
    timings["encoder export"] = export_onnx(encoder, [pixels], encoder_path, encoder_in, encoder_out)
    log_graph_signature(encoder_path)
    embeddings, timings["encoder torch"] = eager(encoder, encoder_feeds, [o["name"] for o in encoder_out])
    timings["encoder onnxruntime"] = verify(encoder_path, encoder_feeds, embeddings)

    decoder, dummy, (decoder_in, decoder_out), dynamic_axes = official_decoder(spec, model)
    names = [o["name"] for o in decoder_out]
    decoder_name = f"{spec.key}-decoder"
    decoder_path = os.path.join(out_dir, decoder_name + ".onnx")
    timings["decoder export"] = export_official_onnx(decoder, dummy, decoder_path, names, dynamic_axes)
    check_graph_signature(log_graph_signature(decoder_path), decoder_in, decoder_out)

    prompts = sam_prompts(image.shape, to_model_frame)
    crop = None
    if VERIFY and not sam2:
        crop = probe_mask_crop(decoder_path, decoder, official_prompt_feeds(decoder_in, embeddings, prompts, 0), names)

    def check(feeds, label):
        """eager torch vs onnxruntime on `feeds`; returns (torch outputs, graph outputs, seconds)."""
        torch_out, torch_seconds = eager(decoder, feeds, names)
        expected = dict(torch_out)
        if crop is not None:
            expected["masks"] = baked_crop_postprocess(torch_out["low_res_masks"], feeds["orig_im_size"], crop)
        seconds = verify(decoder_path, feeds, expected, label=label + (" [masks vs baked-crop postprocessing]" if crop else ""))
        return torch_out, expected, torch_seconds, seconds

    # The reference: one prompt per run (the graphs take one mask input for the whole batch).
    per_prompt, graph_masks = [], []
    timings["decoder torch"] = timings["decoder onnxruntime"] = 0.0
    for index in range(len(prompts["point_coords"])):
        feeds = official_prompt_feeds(decoder_in, embeddings, prompts, index)
        torch_out, expected, torch_seconds, seconds = check(feeds, f" (prompt {index})")
        per_prompt.append(torch_out)
        graph_masks.append(expected["masks"])
        timings["decoder torch"] += torch_seconds
        timings["decoder onnxruntime"] += seconds
    decoder_outputs = {name: np.concatenate([out[name] for out in per_prompt]) for name in names}
    if crop is not None:
        graph_masks = np.concatenate(graph_masks)
        log(f"  official graph masks vs true postprocessing at {image.shape[0]} x {image.shape[1]} (baked crop): "
            f"max abs err {np.abs(graph_masks - decoder_outputs['masks']).max():.2e}")
    compare_with_official_predictor(spec, model, image, prompts, decoder_outputs)

    height, width = image.shape[:2]
    other_size = np.array([width // 2 + 7, height + 13], np.float32)
    extra_points = to_model_frame(np.array([[0.3 * width, 0.35 * height], [0.72 * width, 0.65 * height],
                                            [0.15 * width, 0.8 * height], [0.85 * width, 0.2 * height]], np.float32))
    if sam2:
        # Four prompts in one batch (no mask input), then the same batch sharing prompt 2's mask
        # input at another output size; every batch row must equal the prompt run on its own.
        batch = {**embeddings,
                 "point_coords": np.stack([extra_points, np.zeros_like(extra_points)], axis=1),
                 "point_labels": np.array([[1.0, -1.0]] * 4, np.float32),
                 "mask_input": np.zeros((1, 1, SAM_LOW_RES, SAM_LOW_RES), np.float32),
                 "has_mask_input": np.zeros(1, np.float32), "orig_im_size": prompts["orig_im_size"]}
        batch = {entry["name"]: np.ascontiguousarray(batch[entry["name"]]) for entry in decoder_in}
        check(batch, " (4 prompts in one batch)")
        if VERIFY:
            got = run_onnx(decoder_path, batch)
            single = run_onnx(decoder_path, official_prompt_feeds(decoder_in, embeddings, prompts, 1))
            worst = max(relative_error(got[name][1:2], single[name]) for name in names)
            log(f"  batch row 1 vs prompt 1 alone (onnxruntime): relative {worst:.2e}")
            if worst > TOLERANCES["masks"]:
                raise VerificationError(f"{decoder_path}: a prompt decodes differently inside a batch ({worst:.2e})")
        masked = {**batch, "mask_input": prompts["mask_input"][2:3], "has_mask_input": np.ones(1, np.float32),
                  "orig_im_size": other_size}
        check(masked, f" (4 prompts + shared mask input, orig_im_size {other_size.astype(int).tolist()})")
    else:
        # Batch fixed at 1: one prompt per run; more points (3 + padding), a box (labels 2, 3, no
        # padding point), and prompt 2 (with mask input) at another output size.
        three = {**official_prompt_feeds(decoder_in, embeddings, prompts, 0),
                 "point_coords": np.concatenate([extra_points[None, :3], np.zeros((1, 1, 2), np.float32)], axis=1),
                 "point_labels": np.array([[1.0, 1.0, 0.0, -1.0]], np.float32)}
        check(three, " (3 points + padding)")
        box = {**official_prompt_feeds(decoder_in, embeddings, prompts, 0),
               "point_coords": to_model_frame(np.array([[0.2 * width, 0.25 * height], [0.6 * width, 0.7 * height]],
                                                       np.float32))[None],
               "point_labels": np.array([[2.0, 3.0]], np.float32)}
        check(box, " (box)")
        check(official_prompt_feeds(decoder_in, embeddings, prompts, 2, other_size),
              f" (prompt 2, orig_im_size {other_size.astype(int).tolist()})")

    for key, value in {**encoder_feeds, **embeddings, **prompts, **decoder_outputs}.items():
        role = "input" if key in encoder_feeds or key in prompts else "torch output"
        reference.array(key, value, f"{role} ({'encoder' if key in encoder_feeds or key in embeddings else 'decoder'})")
    if crop is not None:
        reference.array("masks_graph_baked_crop", graph_masks,
                        f"what {decoder_name}.onnx returns as masks: crop baked at {crop[0]} x {crop[1]}")
    reference.finish({
        "signature": "official (--official-signature): segment-anything SamOnnxModel decoder" if not sam2
                     else "official (--official-signature): common SAM 2 decoder form with object_score_logits",
        "preprocess": "official code: ResizeLongestSide + Sam.preprocess" if not sam2 else "official SAM2Transforms",
        "point_coords": "1024-frame coordinates fed to the decoder; point_coords_original are in image.png pixels",
        "prompts": "3 prompts: one positive point + padding point (0,0)/-1 each; prompt 2 has has_mask_input=1",
        "decoder_runs": "one prompt per decoder run (batch 1, that prompt's own mask_input / has_mask_input), stacked",
        "masks": "true postprocessing (what the eager module and the official predictor return)"
                 + (f"; the graph bakes the crop at {crop[0]} x {crop[1]}, see masks_graph_baked_crop.npy" if crop else ""),
    })
    log(f"  decoder signature: official ({'common SAM 2 form' if sam2 else 'SamOnnxModel, return_single_mask=False'})")
    return [], timings


# ---------------------------------------------------------------------------------------------
# Model directory: manifest + tokenizer
# ---------------------------------------------------------------------------------------------


def write_tokenizer(out_dir):
    import open_clip
    from tiny_models.tokenizer import build_tokenizer_json

    bpe_path = os.path.join(os.path.dirname(open_clip.__file__), "bpe_simple_vocab_16e6.txt.gz")
    path = os.path.join(out_dir, "tokenizer.json")
    with open(path, "w", encoding="utf-8") as f:
        json.dump(build_tokenizer_json(bpe_path), f, ensure_ascii=False, separators=(",", ":"))
    return {"file": "tokenizer.json", "sha256": sha256_of(path), "context_length": CONTEXT_LENGTH,
            "start_token": SOT_TOKEN, "end_token": EOT_TOKEN}


def write_manifest(out_dir, entries, tokenizer):
    """Merge into an existing manifest: new entries replace the old ones of the same role."""
    path = os.path.join(out_dir, "manifest.json")
    manifest = {"format_version": 1, "models": []}
    if os.path.exists(path):
        with open(path) as f:
            manifest = json.load(f)
    new_roles = {entry["role"] for entry in entries}
    manifest["models"] = [m for m in manifest["models"] if m["role"] not in new_roles] + entries
    if tokenizer:
        manifest["tokenizer"] = tokenizer
    with open(path, "w") as f:
        json.dump(manifest, f, indent=2)
        f.write("\n")


# ---------------------------------------------------------------------------------------------
# CLI
# ---------------------------------------------------------------------------------------------


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, help="model directory to write (created if missing)")
    parser.add_argument("--models", required=True, help="comma-separated: " + ", ".join(MODEL_SPECS))
    parser.add_argument("--checkpoint", action="append", default=[], metavar="NAME=PATH",
                        help="official checkpoint of model NAME (repeatable)")
    parser.add_argument("--random-weights", action="store_true", help="no checkpoints: seeded random weights")
    parser.add_argument("--image", help="RGB image for verification/reference (default: generated 320x240)")
    parser.add_argument("--reference-dir", help="save inputs and torch outputs here (one folder per model)")
    parser.add_argument("--no-verify", action="store_true", help="skip the onnxruntime comparison (not advised)")
    parser.add_argument("--official-signature", action="store_true",
                        help="SAM-family decoders as the official / common exporters write them (segment-anything's "
                             "SamOnnxModel; the common SAM 2 form with object_score_logits); no manifest.json")
    args = parser.parse_args(argv)
    args.models = [m.strip() for m in args.models.split(",") if m.strip()]
    unknown = [m for m in args.models if m not in MODEL_SPECS]
    if unknown:
        parser.error(f"unknown models {unknown}; known: {list(MODEL_SPECS)}")
    args.checkpoints = dict(item.split("=", 1) for item in args.checkpoint)
    missing = [m for m in args.models if m not in args.checkpoints]
    if missing and not args.random_weights:
        parser.error("no --checkpoint for " + ", ".join(f"{m} (official file {MODEL_SPECS[m].checkpoint_file})" for m in missing)
                     + "; or pass --random-weights")
    families = [MODEL_SPECS[m].family == "clip" for m in args.models]
    if families.count(True) > 1 or families.count(False) > 1:
        parser.error("a model directory holds one model per role: at most one CLIP and one SAM-family model")
    return args


def main(argv=None):
    args = parse_args(argv)
    if args.no_verify:
        global verify, VERIFY
        verify = lambda *a, **k: 0.0  # noqa: E731
        VERIFY = False
    os.makedirs(args.out, exist_ok=True)
    torch.set_grad_enabled(False)
    image = load_or_generate_image(args.image)
    summary = {}
    all_entries, tokenizer = [], None
    for key in args.models:
        spec = MODEL_SPECS[key]
        checkpoint = args.checkpoints.get(key)
        log(f"== {key} ({spec.architecture}; {'checkpoint ' + checkpoint if checkpoint else 'random weights, seed %d' % SEED})")
        torch.manual_seed(SEED)
        started = time.perf_counter()
        exporter = export_clip if spec.family == "clip" else export_sam_family
        if args.official_signature and spec.family != "clip":
            exporter = export_sam_family_official
        entries, timings = exporter(spec, checkpoint, image, args.out, args.reference_dir)
        if args.official_signature and spec.family == "clip":
            for entry in entries:
                log_graph_signature(os.path.join(args.out, entry["file"]))
        timings["total"] = time.perf_counter() - started
        summary[key] = timings
        all_entries += entries
        if spec.family == "clip":
            tokenizer = write_tokenizer(args.out)
    if args.official_signature:
        log(f"--official-signature: no manifest.json written in {args.out} (the user's files come without one; "
            f"`segsplat models init {args.out}` writes it)")
        if os.path.exists(os.path.join(args.out, "manifest.json")):
            log(f"warning: {os.path.join(args.out, 'manifest.json')} is left from an earlier run and no longer matches")
    else:
        write_manifest(args.out, all_entries, tokenizer)
        log(f"wrote {os.path.join(args.out, 'manifest.json')}")
    log("timings (s): " + json.dumps({k: {n: round(v, 3) for n, v in t.items()} for k, t in summary.items()}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
