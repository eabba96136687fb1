"""The two CLIP stand-ins: colour in, a colour direction out."""

import numpy as np
from onnx import TensorProto

from .constants import (
    CLIP_IMAGE_SIZE, CLIP_MEAN, CLIP_STD, COLOUR_PROTOTYPES, COLOUR_TEMPERATURE, CONTEXT_LENGTH,
    EMBED_DIM, IMAGE_GENERIC_WEIGHT, NOT_BLACK_THRESHOLD, SOT_TOKEN, TEXT_GENERIC_WEIGHT)
from .graph import GraphBuilder, tensor_info

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
