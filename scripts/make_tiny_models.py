#!/usr/bin/env python3
"""Write the tiny stand-in model directory and the CLIP fixtures used by CI.

Usage (from the repository root, in a venv with numpy, onnx, open_clip_torch, pillow;
onnxruntime and tokenizers are only needed for --check):

    python scripts/make_tiny_models.py            # writes the files below
    python scripts/make_tiny_models.py --check    # ... and verifies them with onnxruntime/tokenizers

Outputs:
  tests/fixtures/models/tiny/   manifest.json, tokenizer.json and four tiny ONNX models that have
                                exactly the signatures of docs/models.md but compute simple,
                                deterministic colour-based functions (scripts/tiny_models/), so the
                                Rust runtime and the automatic mask generator can be tested without
                                real weights.
  tests/fixtures/clip/          tokenizer_cases.json (open_clip's ids for tricky texts) and a
                                preprocessing fixture (PNG images + open_clip's pixel_values as .npy).

The tiny models are built node by node with onnx.helper (no torch), IR version 8, opset 17, because
ONNX Runtime rejects the newer IR versions that onnx writes by default.
"""

import argparse
import sys

from tiny_models.checks import check_clip, check_official, check_sam, check_tokenizer
from tiny_models.constants import CLIP_FIXTURE_DIR, OFFICIAL_DIR, TINY_DIR
from tiny_models.fixtures import (
    write_official_dirs, write_preprocess_fixture, write_tiny_model_dir, write_tokenizer_fixtures)


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
