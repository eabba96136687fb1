"""The tiny stand-in models and CLIP fixtures of `scripts/make_tiny_models.py`, one concern a module:
constants (sizes, colours, paths), graph (the ONNX graph builder), clip_models and sam_models (the
stand-ins), tokenizer (tokenizer.json and its fixture texts), fixtures (what is written where) and
checks (--check)."""
