"""The SHA-256 a model directory's manifest records for each file (docs/models.md), shared by
scripts/export_models.py and scripts/make_tiny_models.py."""

import hashlib


def sha256_of(path):
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()
