"""The SAM-family stand-ins: the encoder packs cell colours, the decoder answers points by colour
and distance."""

import numpy as np
from onnx import TensorProto

from .constants import (
    SAM_CELL, SAM_CHANNEL_RADII, SAM_COLOUR_SLOPE, SAM_COLOUR_TOLERANCE, SAM_EMBED_GRID,
    SAM_IMAGE_SIZE, SAM_LOGIT_LIMIT, SAM_LOW_RES, SAM_MASK_INPUT_WEIGHT, SAM_NO_PROMPT_LOGIT,
    SAM_PACKED_CHANNELS, SAM_SPATIAL_SLOPE)
from .graph import GraphBuilder, tensor_info


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
