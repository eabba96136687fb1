"""The trained files through a client generated from the served document (issue 41, item 8).

scripts/contract.sh generates a Python client with openapi-python-client from the live server's
OpenAPI document, then runs this against the scene it trained: every file of a static scene's
trained version comes back as what it is (the JSON files parsed into the generated models or
dicts, the binary files as bytes with their format's magic), and the dynamic scene's deformation
files answer 404 on a static scene. Before issue 41 one operation served every file with JSON
listed first, so the generated `trained_file` parsed `scene.ply` as JSON and failed.

Usage: python3 trained_files_client.py CLIENT_DIR BASE_URL TOKEN SCENE_ID
(CLIENT_DIR holds the generated package `segsplat_client`).
"""

import sys


def main() -> int:
    client_dir, base, token, scene = sys.argv[1:5]
    sys.path.insert(0, client_dir)
    # The generated package: names follow the document's operation ids and schema names.
    from segsplat_client import AuthenticatedClient
    from segsplat_client.api.objects import (
        trained_cameras,
        trained_deformation,
        trained_file,
        trained_metrics,
        trained_objects,
        trained_skipped_pairs,
    )
    from segsplat_client.models import SkippedFramePair, TrainedCamera, TrainedObject
    from segsplat_client.models.trained_binary_file_name import TrainedBinaryFileName
    from segsplat_client.types import File

    client = AuthenticatedClient(base_url=base, token=token, raise_on_unexpected_status=True)
    checked = []

    def ok(name, response):
        assert response.status_code == 200, f"{name}: {response.status_code} {response.content[:200]!r}"
        assert response.parsed is not None, f"{name}: nothing parsed"
        checked.append(name)
        return response.parsed

    cameras = ok("cameras.json", trained_cameras.sync_detailed(scene, client=client))
    assert isinstance(cameras, list) and cameras, cameras
    assert all(isinstance(camera, TrainedCamera) for camera in cameras), cameras
    assert len(cameras[0].camera_to_world) == 4 and cameras[0].width > 0, cameras[0]

    objects = ok("objects.json", trained_objects.sync_detailed(scene, client=client))
    assert isinstance(objects, list) and objects, objects
    assert all(isinstance(found, TrainedObject) for found in objects), objects
    assert {str(found.level.value) for found in objects} <= {"small", "middle", "large"}, objects

    metrics = ok("metrics.json", trained_metrics.sync_detailed(scene, client=client))
    report = metrics.to_dict()
    assert report.get("steps", 0) > 0 and "gaussians" in report, report

    skipped = ok("skipped_pairs.json", trained_skipped_pairs.sync_detailed(scene, client=client))
    assert isinstance(skipped, list), skipped
    assert all(isinstance(pair, SkippedFramePair) for pair in skipped), skipped

    magic = {
        TrainedBinaryFileName.SCENE_PLY: b"ply\n",
        TrainedBinaryFileName.SCENE_SPZ: b"\x1f\x8b",  # gzip over the whole SPZ file
        TrainedBinaryFileName.LABELS_NPY: b"\x93NUMPY",
    }
    for name, start in magic.items():
        downloaded = ok(name.value, trained_file.sync_detailed(scene, name, client=client))
        assert isinstance(downloaded, File), f"{name.value}: {type(downloaded)}"
        payload = downloaded.payload.read()
        assert payload.startswith(start), f"{name.value}: starts {payload[:8]!r}"

    # A static scene has no deformation field: 404 in the error envelope, through both.
    # (The 404 is documented, so the client returns it instead of raising.)
    missing = [
        trained_deformation.sync_detailed(scene, client=client),
        trained_file.sync_detailed(scene, TrainedBinaryFileName.DEFORMATION_BIN, client=client),
    ]
    for response in missing:
        assert response.status_code == 404, response
        assert response.parsed.error.code == "not_found", response.parsed
    checked.append("deformation.json and deformation.bin: 404 on a static scene")

    print("generated client:", "; ".join(checked))
    return 0


if __name__ == "__main__":
    sys.exit(main())
