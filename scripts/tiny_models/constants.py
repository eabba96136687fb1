"""Sizes, colour prototypes, the stand-ins' parameters and the fixture paths."""

import os

# scripts/tiny_models/constants.py -> the repository root
REPO_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

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

OFFICIAL_DIR = os.path.join(REPO_ROOT, "tests", "fixtures", "models", "official")
