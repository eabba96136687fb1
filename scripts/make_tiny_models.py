#!/usr/bin/env python3
"""Write the tiny stand-in model directory and the CLIP fixtures used by CI.

Usage (from the repository root, in a venv with numpy, onnx, open_clip_torch, pillow;
onnxruntime and tokenizers are only needed for --check):

    python scripts/make_tiny_models.py            # writes the files below
    python scripts/make_tiny_models.py --check    # ... and verifies them with onnxruntime/tokenizers

Outputs:
  tests/fixtures/models/tiny/   manifest.json, tokenizer.json and four tiny ONNX models that have
                                exactly the signatures of docs/models.md but compute simple,
                                deterministic colour-based functions (see the builders below), so the
                                Rust runtime and the automatic mask generator can be tested without
                                real weights.
  tests/fixtures/clip/          tokenizer_cases.json (open_clip's ids for tricky texts) and a
                                preprocessing fixture (PNG images + open_clip's pixel_values as .npy).

The tiny models are built node by node with onnx.helper (no torch), IR version 8, opset 17, because
ONNX Runtime rejects the newer IR versions that onnx writes by default.
"""

import argparse
import gzip
import hashlib
import json
import os
import sys

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TINY_DIR = os.path.join(REPO_ROOT, "tests", "fixtures", "models", "tiny")
CLIP_FIXTURE_DIR = os.path.join(REPO_ROOT, "tests", "fixtures", "clip")

IR_VERSION = 8
OPSET = 17
EMBED_DIM = 512
CONTEXT_LENGTH = 77
CLIP_IMAGE_SIZE = 224
SAM_IMAGE_SIZE = 1024
SAM_EMBED_GRID = 64
SAM_LOW_RES = 256
SOT_TOKEN = 49406
EOT_TOKEN = 49407

CLIP_MEAN = [0.48145466, 0.4578275, 0.40821073]
CLIP_STD = [0.26862954, 0.26130258, 0.27577711]
SAM_MEAN = [123.675, 116.28, 103.53]
SAM_STD = [58.395, 57.12, 57.375]

# Prototype colours (RGB in 0..1) of the colour directions shared by the tiny CLIP towers.
# Each word is a single token in CLIP's BPE vocabulary ("cyan" is not, so it is left out).
COLOUR_PROTOTYPES = {
    "red": (0.90, 0.10, 0.10),
    "green": (0.10, 0.75, 0.15),
    "blue": (0.10, 0.15, 0.90),
    "yellow": (0.95, 0.90, 0.10),
    "orange": (0.95, 0.55, 0.10),
    "purple": (0.55, 0.15, 0.70),
    "pink": (0.95, 0.60, 0.75),
    "brown": (0.50, 0.30, 0.12),
    "white": (0.95, 0.95, 0.95),
    "gray": (0.50, 0.50, 0.50),
    "black": (0.05, 0.05, 0.05),
}
# Extra spellings that map onto an existing colour direction.
COLOUR_SYNONYMS = {"grey": "gray"}
# Softmax temperature over squared RGB distance: small, so the nearest prototype wins clearly.
COLOUR_TEMPERATURE = 0.01
# Weight of the shared "generic" direction: every text token that is not a colour word adds
# TEXT_GENERIC_WEIGHT of it (plus one for end-of-text), every image IMAGE_GENERIC_WEIGHT.
TEXT_GENERIC_WEIGHT = 0.1
IMAGE_GENERIC_WEIGHT = 0.1
# A pixel of a masked crop counts as object when its un-normalised R+G+B exceeds this.
NOT_BLACK_THRESHOLD = 0.05

# Tiny SAM: the encoder packs the mean colour of every 4x4-pixel cell of the 1024 frame (a 256x256
# grid, the decoder's low-res grid) into channels 0..47 with SpaceToDepth(4).
SAM_CELL = SAM_IMAGE_SIZE // SAM_LOW_RES  # 4 pixels per low-res cell
SAM_PACKED_CHANNELS = 3 * (SAM_LOW_RES // SAM_EMBED_GRID) ** 2  # 48
# Decoder radii (pixels of the 1024 frame) per output channel: 0 = single answer (middle),
# 1 small, 2 middle, 3 large.
SAM_CHANNEL_RADII = [384.0, 128.0, 384.0, 1024.0]
SAM_COLOUR_TOLERANCE = 0.5  # normalised-colour distance at which the colour logit crosses 0
SAM_COLOUR_SLOPE = 16.0  # logit per unit of normalised-colour distance
SAM_SPATIAL_SLOPE = 0.5  # logit per pixel (1024 frame) of distance beyond the radius
SAM_LOGIT_LIMIT = 20.0
SAM_NO_PROMPT_LOGIT = -10.0  # every cell, when the first point is not a positive point
SAM_MASK_INPUT_WEIGHT = 2.0


# ---------------------------------------------------------------------------------------------
# Graph building helpers
# ---------------------------------------------------------------------------------------------


class GraphBuilder:
    """Accumulates nodes and constant initialisers; every op returns its output tensor name."""

    def __init__(self):
        self.nodes = []
        self.initializers = []
        self._count = 0

    def _fresh(self, hint):
        self._count += 1
        return f"{hint}_{self._count}"

    def const(self, value, dtype=np.float32, hint="const"):
        name = self._fresh(hint)
        self.initializers.append(numpy_helper.from_array(np.asarray(value, dtype=dtype), name))
        return name

    def i64(self, value, hint="shape"):
        return self.const(value, np.int64, hint)

    def op(self, op_type, *inputs, output=None, **attrs):
        out = output or self._fresh(op_type.lower())
        self.nodes.append(helper.make_node(op_type, list(inputs), [out], **attrs))
        return out

    def reduce_sum(self, x, axes, keepdims):
        # opset 13+: ReduceSum takes axes as an input
        return self.op("ReduceSum", x, self.i64(axes), keepdims=keepdims)

    def l2_normalise(self, x, output):
        squared = self.reduce_sum(self.op("Mul", x, x), [1], keepdims=1)
        norm = self.op("Sqrt", self.op("Add", squared, self.const(1e-12)))
        return self.op("Div", x, norm, output=output)

    def model(self, name, inputs, outputs):
        graph = helper.make_graph(self.nodes, name, inputs, outputs, self.initializers)
        model = helper.make_model(
            graph,
            opset_imports=[helper.make_opsetid("", OPSET)],
            producer_name="segsplat make_tiny_models.py",
        )
        model.ir_version = IR_VERSION
        onnx.checker.check_model(model, full_check=True)
        return model


def tensor_info(name, elem_type, shape):
    """Value info with symbolic names for the dynamic (-1) dimensions."""
    dims = [f"{name}_dim{i}" if d == -1 else d for i, d in enumerate(shape)]
    return helper.make_tensor_value_info(name, elem_type, dims)


# ---------------------------------------------------------------------------------------------
# Colour directions shared by the two CLIP stand-ins
# ---------------------------------------------------------------------------------------------


def colour_directions():
    """Orthonormal 512-d directions: one per colour prototype plus a final 'generic' direction."""
    rng = np.random.default_rng(20240517)
    count = len(COLOUR_PROTOTYPES) + 1
    q, _ = np.linalg.qr(rng.standard_normal((EMBED_DIM, count)))
    return q.T.astype(np.float32)  # [K+1, 512]


def build_clip_image():
    """pixel_values f32[N,3,224,224] -> image_embeds f32[N,512].

    Undo CLIP's mean/std, average the RGB of the pixels that are not black (a masked crop is
    image x mask on black), pick the nearest colour prototype through a sharp softmax over squared
    distances, and emit that colour's direction (+ a little generic direction), L2-normalised.
    """
    g = GraphBuilder()
    directions = colour_directions()
    prototypes = np.array(list(COLOUR_PROTOTYPES.values()), dtype=np.float32)  # [K,3]

    std = g.const(np.reshape(CLIP_STD, (1, 3, 1, 1)))
    mean = g.const(np.reshape(CLIP_MEAN, (1, 3, 1, 1)))
    rgb = g.op("Add", g.op("Mul", "pixel_values", std), mean)
    brightness = g.reduce_sum(rgb, [1], keepdims=1)  # [N,1,H,W]
    is_object = g.op("Cast", g.op("Greater", brightness, g.const(NOT_BLACK_THRESHOLD)), to=TensorProto.FLOAT)
    colour_sum = g.reduce_sum(g.op("Mul", rgb, is_object), [2, 3], keepdims=0)  # [N,3]
    pixel_count = g.op("Add", g.reduce_sum(is_object, [2, 3], keepdims=0), g.const(1e-6))  # [N,1]
    mean_colour = g.op("Div", colour_sum, pixel_count)

    # -|c - p|^2 / T up to a per-row constant = (2 c.p - |p|^2) / T
    weights = (2.0 / COLOUR_TEMPERATURE) * prototypes.T  # [3,K]
    bias = -(prototypes**2).sum(axis=1) / COLOUR_TEMPERATURE  # [K]
    logits = g.op("Add", g.op("MatMul", mean_colour, g.const(weights)), g.const(bias))
    colour_weights = g.op("Softmax", logits, axis=-1)  # [N,K]
    embedding = g.op(
        "Add",
        g.op("MatMul", colour_weights, g.const(directions[:-1])),
        g.const(IMAGE_GENERIC_WEIGHT * directions[-1]),
    )
    g.l2_normalise(embedding, output="image_embeds")
    return g.model(
        "tiny_clip_image",
        [tensor_info("pixel_values", TensorProto.FLOAT, [-1, 3, CLIP_IMAGE_SIZE, CLIP_IMAGE_SIZE])],
        [tensor_info("image_embeds", TensorProto.FLOAT, [-1, EMBED_DIM])],
    )


def build_clip_text(colour_token_ids):
    """input_ids i64[N,77] -> text_embeds f32[N,512].

    Tokens strictly between start-of-text and the end-of-text position (argmax of the ids, as real
    CLIP finds it) count: colour words add their colour direction, every other token
    TEXT_GENERIC_WEIGHT of the generic direction; end-of-text adds one more generic share so an
    empty text still has a direction. The sum is L2-normalised.
    colour_token_ids: {token id: colour name}.
    """
    g = GraphBuilder()
    directions = colour_directions()
    colour_names = list(COLOUR_PROTOTYPES)
    token_ids = np.array(sorted(colour_token_ids), dtype=np.int64)  # [T]
    token_to_colour = np.zeros((len(token_ids), len(colour_names)), dtype=np.float32)  # [T,K]
    for row, token in enumerate(token_ids):
        token_to_colour[row, colour_names.index(colour_token_ids[token])] = 1.0

    eot_position = g.op("ArgMax", "input_ids", axis=1, keepdims=1)  # [N,1]
    positions = g.i64(np.arange(CONTEXT_LENGTH).reshape(1, CONTEXT_LENGTH), hint="positions")
    before_eot = g.op("Less", positions, eot_position)
    not_sot = g.op("Not", g.op("Equal", "input_ids", g.i64(SOT_TOKEN)))
    counted = g.op("Cast", g.op("And", before_eot, not_sot), to=TensorProto.FLOAT)  # [N,77]

    ids_column = g.op("Unsqueeze", "input_ids", g.i64([2]))  # [N,77,1]
    is_colour_token = g.op("Cast", g.op("Equal", ids_column, g.i64(token_ids)), to=TensorProto.FLOAT)
    counted_column = g.op("Unsqueeze", counted, g.i64([2]))
    token_counts = g.reduce_sum(g.op("Mul", is_colour_token, counted_column), [1], keepdims=0)  # [N,T]
    colour_counts = g.op("MatMul", token_counts, g.const(token_to_colour))  # [N,K]

    total = g.reduce_sum(counted, [1], keepdims=1)
    colour_total = g.reduce_sum(colour_counts, [1], keepdims=1)
    generic_count = g.op("Add", g.op("Sub", total, colour_total), g.const(1.0))  # +1: end-of-text
    generic = g.op("Mul", g.op("Mul", generic_count, g.const(TEXT_GENERIC_WEIGHT)), g.const(directions[-1:]))
    embedding = g.op("Add", g.op("MatMul", colour_counts, g.const(directions[:-1])), generic)
    g.l2_normalise(embedding, output="text_embeds")
    return g.model(
        "tiny_clip_text",
        [tensor_info("input_ids", TensorProto.INT64, [-1, CONTEXT_LENGTH])],
        [tensor_info("text_embeds", TensorProto.FLOAT, [-1, EMBED_DIM])],
    )


# ---------------------------------------------------------------------------------------------
# SAM stand-ins
# ---------------------------------------------------------------------------------------------


def build_sam_encoder():
    """image f32[1,3,1024,1024] -> image_embeddings f32[1,256,64,64].

    Channels 0..47 hold the normalised mean colour of each 4x4-pixel cell (the decoder's 256x256
    low-res grid), packed by SpaceToDepth(4): channel (dy*4 + dx)*3 + c of embedding cell (i, j) is
    colour c of low-res cell (4i + dy, 4j + dx). Channels 48..255 are a fixed random mix of those,
    so the tensor looks like an embedding (nothing reads them).
    """
    g = GraphBuilder()
    rng = np.random.default_rng(7)
    block = SAM_LOW_RES // SAM_EMBED_GRID
    cells = g.op("AveragePool", "image", kernel_shape=[SAM_CELL, SAM_CELL], strides=[SAM_CELL, SAM_CELL])
    packed = g.op("SpaceToDepth", cells, blocksize=block)  # [1,48,64,64]
    extra_channels = 256 - SAM_PACKED_CHANNELS
    mix = (0.1 * rng.standard_normal((extra_channels, SAM_PACKED_CHANNELS, 1, 1))).astype(np.float32)
    extra = g.op("Conv", packed, g.const(mix))
    g.op("Concat", packed, extra, axis=1, output="image_embeddings")
    return g.model(
        "tiny_sam_encoder",
        [tensor_info("image", TensorProto.FLOAT, [1, 3, SAM_IMAGE_SIZE, SAM_IMAGE_SIZE])],
        [tensor_info("image_embeddings", TensorProto.FLOAT, [1, 256, SAM_EMBED_GRID, SAM_EMBED_GRID])],
    )


def _decoder_cell_colours(g):
    """[1,3,256,256] normalised colour per low-res cell, unpacked from the embeddings."""
    packed = g.op("Slice", "image_embeddings", g.i64([0]), g.i64([SAM_PACKED_CHANNELS]), g.i64([1]))
    return g.op("DepthToSpace", packed, blocksize=SAM_LOW_RES // SAM_EMBED_GRID, mode="DCR")


def _decoder_first_point(g):
    """(xy [B,2], label [B]) of each prompt's first point."""
    xy = g.op("Squeeze", g.op("Slice", "point_coords", g.i64([0]), g.i64([1]), g.i64([1])), g.i64([1]))
    label = g.op("Squeeze", g.op("Slice", "point_labels", g.i64([0]), g.i64([1]), g.i64([1])), g.i64([1]))
    return xy, label


def _decoder_colour_logits(g, colours, xy):
    """[B,1,256,256]: SLOPE * (TOLERANCE - |cell colour - colour under the point|)."""
    cell_xy = g.op("Floor", g.op("Clip", g.op("Div", xy, g.const(float(SAM_CELL))), g.const(0.0), g.const(SAM_LOW_RES - 1.0)))
    cell_xy = g.op("Cast", cell_xy, to=TensorProto.INT64)  # [B,2] = (column, row)
    column = g.op("Squeeze", g.op("Slice", cell_xy, g.i64([0]), g.i64([1]), g.i64([1])), g.i64([1]))
    row = g.op("Squeeze", g.op("Slice", cell_xy, g.i64([1]), g.i64([2]), g.i64([1])), g.i64([1]))
    flat_index = g.op("Add", g.op("Mul", row, g.i64(SAM_LOW_RES)), column)  # [B]
    flat_colours = g.op("Reshape", colours, g.i64([3, SAM_LOW_RES * SAM_LOW_RES]))
    point_colour = g.op("Transpose", g.op("Gather", flat_colours, flat_index, axis=1), perm=[1, 0])  # [B,3]
    point_colour = g.op("Unsqueeze", point_colour, g.i64([2, 3]))  # [B,3,1,1]
    difference = g.op("Sub", colours, point_colour)  # [B,3,256,256]
    squared = g.reduce_sum(g.op("Mul", difference, difference), [1], keepdims=1)  # [B,1,256,256]
    distance = g.op("Sqrt", g.op("Add", squared, g.const(1e-8)))
    return g.op("Mul", g.op("Sub", g.const(SAM_COLOUR_TOLERANCE), distance), g.const(SAM_COLOUR_SLOPE))


def _decoder_spatial_logits(g, xy):
    """[B,4,256,256]: SLOPE * (radius of the channel - distance of the cell centre to the point)."""
    centres = ((np.arange(SAM_LOW_RES) + 0.5) * SAM_CELL).astype(np.float32)
    point_x = g.op("Unsqueeze", g.op("Slice", xy, g.i64([0]), g.i64([1]), g.i64([1])), g.i64([2, 3]))  # [B,1,1,1]
    point_y = g.op("Unsqueeze", g.op("Slice", xy, g.i64([1]), g.i64([2]), g.i64([1])), g.i64([2, 3]))
    dx = g.op("Sub", g.const(centres.reshape(1, 1, 1, SAM_LOW_RES)), point_x)
    dy = g.op("Sub", g.const(centres.reshape(1, 1, SAM_LOW_RES, 1)), point_y)
    distance = g.op("Sqrt", g.op("Add", g.op("Mul", dx, dx), g.op("Mul", dy, dy)))  # [B,1,256,256]
    radii = g.const(np.reshape(SAM_CHANNEL_RADII, (1, 4, 1, 1)))
    return g.op("Mul", g.op("Sub", radii, distance), g.const(SAM_SPATIAL_SLOPE))


def _decoder_iou_predictions(g, low_res):
    """[B,4]: 0.5 + 0.45 * stability, stability = area(logit > 1) / area(logit > -1)."""
    def area_above(threshold):
        above = g.op("Cast", g.op("Greater", low_res, g.const(threshold)), to=TensorProto.FLOAT)
        return g.reduce_sum(above, [2, 3], keepdims=0)

    stability = g.op("Div", area_above(1.0), g.op("Add", area_above(-1.0), g.const(1.0)))
    return g.op("Add", g.op("Mul", stability, g.const(0.45)), g.const(0.5), output="iou_predictions")


def _resize_bilinear(g, x, height_width_i64):
    """Resize [B,C,h,w] to [B,C,H,W] like torch's F.interpolate(bilinear, align_corners=False)."""
    sizes = g.op("Concat", g.op("Slice", g.op("Shape", x), g.i64([0]), g.i64([2])), height_width_i64, axis=0)
    return g.op("Resize", x, "", "", sizes, mode="linear", coordinate_transformation_mode="pytorch_half_pixel")


def _decoder_postprocess(g, low_res, baked_crop=None):
    """SAM's mask_postprocessing: upscale to 1024, crop the unpadded region, resize to orig_im_size.

    `baked_crop` = (height, width) crops to that fixed size whatever orig_im_size says, as
    segment-anything's own export does (683 x 1024, its example image's)."""
    full = _resize_bilinear(g, low_res, g.i64([SAM_IMAGE_SIZE, SAM_IMAGE_SIZE]))
    if baked_crop is not None:
        prepadded = g.i64(list(baked_crop))
    else:
        # prepadded size = floor(orig * 1024 / max(orig) + 0.5), in float32 as SamOnnxModel computes it
        scale = g.op("Div", g.const(float(SAM_IMAGE_SIZE)), g.op("ReduceMax", "orig_im_size", axes=[0], keepdims=1))
        prepadded = g.op("Floor", g.op("Add", g.op("Mul", "orig_im_size", scale), g.const(0.5)))
        prepadded = g.op("Cast", prepadded, to=TensorProto.INT64)
    cropped = g.op("Slice", full, g.i64([0, 0]), prepadded, g.i64([2, 3]))
    original = g.op("Cast", "orig_im_size", to=TensorProto.INT64)
    return g.op("Identity", _resize_bilinear(g, cropped, original), output="masks")


def build_sam_decoder(point_batch=-1, mask_batch=-1, sam2=False, object_score=False, baked_crop=None,
                      name="tiny_sam_decoder"):
    """The SAM decoder signature with a colour-and-distance segmenter.

    For each prompt, only its first point is used, and only when its label is 1: a low-res cell's
    logit is min(colour logit, spatial logit of the channel), so the mask is the region whose
    colour is within SAM_COLOUR_TOLERANCE of the colour under the point and within the channel's
    radius (small / middle / large; channel 0 = middle). A mask_input (has_mask_input = 1) adds
    SAM_MASK_INPUT_WEIGHT * tanh(mask_input / 4). Prompts whose first label is not 1 give
    SAM_NO_PROMPT_LOGIT everywhere.

    The keyword arguments give the official exporters' signatures: `point_batch=1` is
    segment-anything's own export (one prompt per run), `mask_batch=1` a mask_input /
    has_mask_input of batch 1 broadcast over the prompts, `sam2` adds the encoder's
    high_res_feats_* inputs and SAM 2.1's postprocessing (resize straight to orig_im_size), and
    `object_score` adds SAM 2's `object_score_logits` [B,1] (see _decoder_object_score below), and
    `baked_crop` fixes the crop before the final resize as segment-anything's export does.
    """
    g = GraphBuilder()
    colours = _decoder_cell_colours(g)
    xy, label = _decoder_first_point(g)
    colour_logits = _decoder_colour_logits(g, colours, xy)
    spatial_logits = _decoder_spatial_logits(g, xy)
    logits = g.op("Min", colour_logits, spatial_logits)  # [B,4,256,256]

    has_mask = g.op("Unsqueeze", "has_mask_input", g.i64([1, 2, 3]))
    mask_prior = g.op("Mul", g.op("Tanh", g.op("Div", "mask_input", g.const(4.0))), g.const(SAM_MASK_INPUT_WEIGHT))
    logits = g.op("Add", logits, g.op("Mul", has_mask, mask_prior))
    if sam2:
        # Read the high-resolution features (times 0) so they are real inputs of the graph.
        for feature in ["high_res_feats_0", "high_res_feats_1"]:
            mean = g.op("ReduceMean", feature, axes=[0, 1, 2, 3], keepdims=1)
            logits = g.op("Add", logits, g.op("Mul", mean, g.const(0.0)))
    logits = g.op("Clip", logits, g.const(-SAM_LOGIT_LIMIT), g.const(SAM_LOGIT_LIMIT))

    is_positive = g.op("Unsqueeze", g.op("Equal", label, g.const(1.0)), g.i64([1, 2, 3]))
    low_res = g.op("Where", is_positive, logits, g.const(SAM_NO_PROMPT_LOGIT), output="low_res_masks")
    _decoder_iou_predictions(g, low_res)
    if sam2:
        g.op("Identity", _resize_bilinear(g, low_res, g.op("Cast", "orig_im_size", to=TensorProto.INT64)), output="masks")
    else:
        _decoder_postprocess(g, low_res, baked_crop)
    if object_score:
        _decoder_object_score(g, colours, xy, label)

    f = TensorProto.FLOAT
    inputs = [
        tensor_info("image_embeddings", f, [1, 256, SAM_EMBED_GRID, SAM_EMBED_GRID]),
        tensor_info("point_coords", f, [point_batch, -1, 2]),
        tensor_info("point_labels", f, [point_batch, -1]),
        tensor_info("mask_input", f, [mask_batch, 1, SAM_LOW_RES, SAM_LOW_RES]),
        tensor_info("has_mask_input", f, [mask_batch]),
        tensor_info("orig_im_size", f, [2]),
    ]
    if sam2:
        inputs += [
            tensor_info("high_res_feats_0", f, [1, 32, SAM_LOW_RES, SAM_LOW_RES]),
            tensor_info("high_res_feats_1", f, [1, 64, SAM_LOW_RES // 2, SAM_LOW_RES // 2]),
        ]
    outputs = [
        tensor_info("masks", f, [point_batch, 4, -1, -1]),
        tensor_info("iou_predictions", f, [point_batch, 4]),
        tensor_info("low_res_masks", f, [point_batch, 4, SAM_LOW_RES, SAM_LOW_RES]),
    ]
    if object_score:
        outputs.append(tensor_info("object_score_logits", f, [point_batch, 1]))
    return g.model(name, inputs, outputs)


# SAM 2's object score of the stand-in: SLOPE * (colour range under the point - THRESHOLD), with
# the range max(c) - min(c) of the normalised colour. Saturated colours (the blobs of the test
# scenes: range ~3) score > 0, neutral ones (grey, white, black: range < 0.5) < 0: "no object".
SAM_OBJECT_SCORE_THRESHOLD = 1.0
SAM_OBJECT_SCORE_SLOPE = 4.0


def _decoder_object_score(g, colours, xy, label):
    """object_score_logits [B,1]; -10 for a prompt whose first label is not 1."""
    cell_xy = g.op("Floor", g.op("Clip", g.op("Div", xy, g.const(float(SAM_CELL))), g.const(0.0), g.const(SAM_LOW_RES - 1.0)))
    cell_xy = g.op("Cast", cell_xy, to=TensorProto.INT64)
    column = g.op("Squeeze", g.op("Slice", cell_xy, g.i64([0]), g.i64([1]), g.i64([1])), g.i64([1]))
    row = g.op("Squeeze", g.op("Slice", cell_xy, g.i64([1]), g.i64([2]), g.i64([1])), g.i64([1]))
    flat_index = g.op("Add", g.op("Mul", row, g.i64(SAM_LOW_RES)), column)
    flat_colours = g.op("Reshape", colours, g.i64([3, SAM_LOW_RES * SAM_LOW_RES]))
    point_colour = g.op("Transpose", g.op("Gather", flat_colours, flat_index, axis=1), perm=[1, 0])  # [B,3]
    spread = g.op("Sub", g.op("ReduceMax", point_colour, axes=[1], keepdims=1), g.op("ReduceMin", point_colour, axes=[1], keepdims=1))
    score = g.op("Mul", g.op("Sub", spread, g.const(SAM_OBJECT_SCORE_THRESHOLD)), g.const(SAM_OBJECT_SCORE_SLOPE))
    positive = g.op("Unsqueeze", g.op("Equal", label, g.const(1.0)), g.i64([1]))
    g.op("Where", positive, score, g.const(SAM_NO_PROMPT_LOGIT), output="object_score_logits")


def build_sam2_encoder():
    """The tiny encoder plus SAM 2.1's high_res_feats_0 [1,32,256,256] / _1 [1,64,128,128]
    (fixed random mixes of the 4x4 / 8x8 cell colours; the decoder reads them times 0)."""
    model = build_sam_encoder()
    g = GraphBuilder()
    g.nodes, g.initializers = list(model.graph.node), list(model.graph.initializer)
    g._count = 10_000
    rng = np.random.default_rng(11)
    for output, cell, channels in [("high_res_feats_0", 4, 32), ("high_res_feats_1", 8, 64)]:
        pooled = g.op("AveragePool", "image", kernel_shape=[cell, cell], strides=[cell, cell])
        mix = (0.1 * rng.standard_normal((channels, 3, 1, 1))).astype(np.float32)
        g.op("Conv", pooled, g.const(mix), output=output)
    return g.model(
        "tiny_sam2_encoder",
        [tensor_info("image", TensorProto.FLOAT, [1, 3, SAM_IMAGE_SIZE, SAM_IMAGE_SIZE])],
        [
            tensor_info("image_embeddings", TensorProto.FLOAT, [1, 256, SAM_EMBED_GRID, SAM_EMBED_GRID]),
            tensor_info("high_res_feats_0", TensorProto.FLOAT, [1, 32, SAM_LOW_RES, SAM_LOW_RES]),
            tensor_info("high_res_feats_1", TensorProto.FLOAT, [1, 64, SAM_LOW_RES // 2, SAM_LOW_RES // 2]),
        ],
    )


# ---------------------------------------------------------------------------------------------
# Tokenizer: HuggingFace tokenizers-format JSON built from open_clip's BPE file
# ---------------------------------------------------------------------------------------------


def bytes_to_unicode():
    """GPT-2/CLIP byte -> printable unicode character table (same as open_clip's)."""
    printable = list(range(ord("!"), ord("~") + 1)) + list(range(ord("¡"), ord("¬") + 1)) + list(range(ord("®"), ord("ÿ") + 1))
    codes = printable[:]
    extra = 0
    for byte in range(256):
        if byte not in printable:
            printable.append(byte)
            codes.append(256 + extra)
            extra += 1
    return dict(zip(printable, [chr(c) for c in codes]))


def clip_vocab_and_merges(bpe_path):
    """Vocabulary (token -> id) and merge list exactly as open_clip's SimpleTokenizer builds them."""
    lines = gzip.open(bpe_path).read().decode("utf-8").split("\n")
    merges = [tuple(line.split()) for line in lines[1 : 49152 - 256 - 2 + 1]]
    byte_chars = list(bytes_to_unicode().values())
    tokens = byte_chars + [c + "</w>" for c in byte_chars] + ["".join(m) for m in merges]
    tokens += ["<|startoftext|>", "<|endoftext|>"]
    assert len(tokens) == EOT_TOKEN + 1
    return {t: i for i, t in enumerate(tokens)}, [" ".join(m) for m in merges]


# open_clip's pre-tokenizer regex (without its special-token alternatives, which HF handles as
# added tokens).
CLIP_PRETOKENIZE_REGEX = r"'s|'t|'re|'ve|'m|'ll|'d|[\p{L}]+|[\p{N}]|[^\s\p{L}\p{N}]+"


def special_token(token_id, content):
    return {
        "id": token_id,
        "content": content,
        "single_word": False,
        "lstrip": False,
        "rstrip": False,
        "normalized": False,
        "special": True,
    }


def build_tokenizer_json(bpe_path):
    """CLIP's tokenizer as HF JSON: normalise (NFC, whitespace runs -> one space, strip, lower),
    split with CLIP's regex, byte-level map, BPE with '</w>' end-of-word suffix, wrap in
    <|startoftext|> ... <|endoftext|>, truncate to 77 (keeping end-of-text last) and pad with 0."""
    vocab, merges = clip_vocab_and_merges(bpe_path)
    return {
        "version": "1.0",
        "truncation": {"direction": "Right", "max_length": CONTEXT_LENGTH, "strategy": "LongestFirst", "stride": 0},
        "padding": {
            "strategy": {"Fixed": CONTEXT_LENGTH},
            "direction": "Right",
            "pad_to_multiple_of": None,
            "pad_id": 0,
            "pad_type_id": 0,
            "pad_token": "!",
        },
        "added_tokens": [special_token(SOT_TOKEN, "<|startoftext|>"), special_token(EOT_TOKEN, "<|endoftext|>")],
        "normalizer": {
            "type": "Sequence",
            "normalizers": [
                {"type": "NFC"},
                {"type": "Replace", "pattern": {"Regex": r"\s+"}, "content": " "},
                {"type": "Strip", "strip_left": True, "strip_right": True},
                {"type": "Lowercase"},
            ],
        },
        "pre_tokenizer": {
            "type": "Sequence",
            "pretokenizers": [
                {"type": "Split", "pattern": {"Regex": CLIP_PRETOKENIZE_REGEX}, "behavior": "Removed", "invert": True},
                {"type": "ByteLevel", "add_prefix_space": False, "trim_offsets": True, "use_regex": False},
            ],
        },
        "post_processor": {
            "type": "TemplateProcessing",
            "single": [
                {"SpecialToken": {"id": "<|startoftext|>", "type_id": 0}},
                {"Sequence": {"id": "A", "type_id": 0}},
                {"SpecialToken": {"id": "<|endoftext|>", "type_id": 0}},
            ],
            "pair": [
                {"SpecialToken": {"id": "<|startoftext|>", "type_id": 0}},
                {"Sequence": {"id": "A", "type_id": 0}},
                {"SpecialToken": {"id": "<|endoftext|>", "type_id": 0}},
                {"Sequence": {"id": "B", "type_id": 1}},
                {"SpecialToken": {"id": "<|endoftext|>", "type_id": 1}},
            ],
            "special_tokens": {
                "<|startoftext|>": {"id": "<|startoftext|>", "ids": [SOT_TOKEN], "tokens": ["<|startoftext|>"]},
                "<|endoftext|>": {"id": "<|endoftext|>", "ids": [EOT_TOKEN], "tokens": ["<|endoftext|>"]},
            },
        },
        "decoder": {"type": "BPEDecoder", "suffix": "</w>"},
        "model": {
            "type": "BPE",
            "dropout": None,
            "unk_token": "<|endoftext|>",
            "continuing_subword_prefix": None,
            "end_of_word_suffix": "</w>",
            "fuse_unk": False,
            "byte_fallback": False,
            "ignore_merges": False,
            "vocab": vocab,
            "merges": merges,
        },
    }


# Texts whose open_clip ids the fixture records. The long one exceeds 77 tokens.
TOKENIZER_TEXTS = [
    "",
    "a red mug",
    "A photo of a RED Mug.",
    "red",
    "the chair",
    "  lots   of\twhitespace \n\n here  ",
    "café crème brûlée, naïve façade",
    "Ünïcödé ÀÉÎÕÜ ß",
    "東京タワー と 猫",
    "한국어 텍스트",
    "🙂 happy face 🎉🎉",
    "👩‍👩‍👧 family emoji with ZWJ",
    "Hello, world! (parentheses) [brackets] {braces} <angle>",
    "it's they're we've I'm you'll he'd",
    "punctuation!!! ??? ... --- ;;; :::",
    "numbers 123 4567 3.14159 1,000,000 2024-05-17",
    "MiXeD CaSe WoRdS",
    "a_snake_case_identifier and CamelCaseIdentifier",
    "email@example.com http://example.org/path?q=1",
    "tab\tseparated\tvalues",
    "the quick brown fox jumps over the lazy dog " * 12,
    "word " * 80,
]
# Texts where open_clip's extra cleaning (ftfy.fix_text, html.unescape) changes the text before
# tokenising, so an HF tokenizer.json alone cannot reproduce the ids; recorded separately (the Rust
# ClipTokenizer cleans first and does; scripts/make_tokenizer_table.py writes many more).
TOKENIZER_CLEANING_TEXTS = [
    "fish &amp; chips",
    "&lt;b&gt;bold&lt;/b&gt;",
    "don’t “quote” me",
    "ﬁne ligature",
    "ＦＵＬＬＷＩＤＴＨ text",
]


def tokenizer_cases(texts):
    import open_clip

    tokenizer = open_clip.get_tokenizer("ViT-B-32")
    ids = tokenizer(texts).tolist()
    return [{"text": text, "ids": row} for text, row in zip(texts, ids)]


def hf_tokenizer_ids(tokenizer_path, texts):
    from tokenizers import Tokenizer

    tokenizer = Tokenizer.from_file(tokenizer_path)
    return [encoding.ids for encoding in tokenizer.encode_batch(texts)]


def colour_token_ids():
    """{CLIP BPE id: colour name} for every colour word and synonym (each a single token)."""
    import open_clip

    tokenizer = open_clip.get_tokenizer("ViT-B-32")
    words = {name: name for name in COLOUR_PROTOTYPES}
    words.update(COLOUR_SYNONYMS)
    table = {}
    for word, colour in words.items():
        ids = tokenizer.encode(word)
        assert len(ids) == 1, f"colour word {word!r} is not a single CLIP token: {ids}"
        table[ids[0]] = colour
    return table


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


def sha256_of(path):
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


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


OFFICIAL_DIR = os.path.join(REPO_ROOT, "tests", "fixtures", "models", "official")

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


def build_clip_text_of_width(width):
    """A CLIP text signature whose embedding width is `width` and dynamic in the graph
    (`text_embeds [-1, -1]`): a CLIP image model of another width must be refused as its pair,
    which needs a run to find out."""
    g = GraphBuilder()
    rng = np.random.default_rng(5)
    ids = g.op("Cast", "input_ids", to=TensorProto.FLOAT)
    weights = (rng.standard_normal((CONTEXT_LENGTH, width)) / CONTEXT_LENGTH).astype(np.float32)
    g.op("MatMul", ids, g.const(weights), output="text_embeds")
    return g.model(
        f"tiny_clip_text_{width}",
        [tensor_info("input_ids", TensorProto.INT64, [-1, CONTEXT_LENGTH])],
        [tensor_info("text_embeds", TensorProto.FLOAT, [-1, -1])],
    )


def write_official_dirs():
    mismatched = os.path.join(REPO_ROOT, "tests", "fixtures", "models", "mismatched")
    os.makedirs(mismatched, exist_ok=True)
    onnx.save(build_clip_text_of_width(256), os.path.join(mismatched, "clip-text-256.onnx"))
    for variant, files in OFFICIAL_VARIANTS.items():
        folder = os.path.join(OFFICIAL_DIR, variant)
        os.makedirs(folder, exist_ok=True)
        for file_name, build in files.items():
            onnx.save(build(), os.path.join(folder, file_name))


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


def write_tokenizer_fixtures():
    os.makedirs(CLIP_FIXTURE_DIR, exist_ok=True)
    for file_name, texts in [("tokenizer_cases.json", TOKENIZER_TEXTS),
                             ("tokenizer_cleaning_cases.json", TOKENIZER_CLEANING_TEXTS)]:
        # one case per line keeps the fixture readable and its diffs small
        lines = [json.dumps(case, ensure_ascii=False) for case in tokenizer_cases(texts)]
        with open(os.path.join(CLIP_FIXTURE_DIR, file_name), "w", encoding="utf-8") as f:
            f.write("[\n" + ",\n".join(lines) + "\n]\n")


# ---------------------------------------------------------------------------------------------
# --check: run the written files with onnxruntime / tokenizers
# ---------------------------------------------------------------------------------------------


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


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--check", action="store_true", help="verify the outputs with onnxruntime and tokenizers")
    parser.add_argument("--check-only", action="store_true", help="only verify, write nothing")
    args = parser.parse_args()
    if not args.check_only:
        write_tiny_model_dir()
        write_tokenizer_fixtures()
        write_preprocess_fixture()
        write_official_dirs()
        print(f"wrote {TINY_DIR}, {OFFICIAL_DIR} and {CLIP_FIXTURE_DIR}")
    if args.check or args.check_only:
        check_tokenizer()
        check_clip()
        check_sam()
        check_official()


if __name__ == "__main__":
    sys.exit(main())
